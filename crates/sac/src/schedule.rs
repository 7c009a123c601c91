//! Small schedule types in the style of DrQ-v2's `utils.py`: [`LinearSchedule`] interpolation
//! (PER β annealed 0.4 → 1.0 over training, docs/paper.md §2) and the [`Every`] predicate (evaluate
//! every 200 training steps).
//!
//! ## Limitations
//!
//! - Steps are whole numbers (`u64`); there is no exponential or piecewise schedule.

use serde::{Deserialize, Serialize};

/// Linear interpolation from `start` at step 0 to `end` at step `steps`, constant afterwards.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LinearSchedule {
    /// Value at step 0.
    pub start: f64,
    /// Value at step `steps` and after.
    pub end: f64,
    /// Steps to go from `start` to `end`; 0 means `end` from the first step.
    pub steps: u64,
}

impl LinearSchedule {
    /// The value at step `t`: `start + (end - start) · min(t, steps) / steps`.
    pub fn value(&self, t: u64) -> f64 {
        if self.steps == 0 || t >= self.steps {
            return self.end;
        }
        let frac = t as f64 / self.steps as f64;
        self.start + (self.end - self.start) * frac
    }
}

/// Half-cosine annealing from `start` at step 0 to `end` at step `steps`, constant afterwards:
/// `end + (start − end) · (1 + cos(π · min(t, steps) / steps)) / 2` (SGDR's schedule without
/// restarts). The learning-rate schedule of [`crate::agent::AgentConfig::lr_final`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CosineSchedule {
    /// Value at step 0.
    pub start: f64,
    /// Value at step `steps` and after.
    pub end: f64,
    /// Steps to go from `start` to `end`; 0 means `end` from the first step.
    pub steps: u64,
}

impl CosineSchedule {
    /// The value at step `t`.
    pub fn value(&self, t: u64) -> f64 {
        if self.steps == 0 || t >= self.steps {
            return self.end;
        }
        let frac = t as f64 / self.steps as f64;
        self.end + (self.start - self.end) * 0.5 * (1.0 + (std::f64::consts::PI * frac).cos())
    }
}

/// "Every `n` steps": due at each positive multiple of `n`; `Every(0)` is never due.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Every(pub u64);

impl Every {
    /// Whether `step` (the number of steps completed) is a positive multiple of `n`. Step 0 is not
    /// due: a caller who wants an evaluation before training does it explicitly.
    pub fn is_due(&self, step: u64) -> bool {
        self.0 != 0 && step != 0 && step.is_multiple_of(self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_anneals_then_clamps() {
        let lr = CosineSchedule { start: 3e-3, end: 3e-4, steps: 5000 };
        assert_eq!(lr.value(0), 3e-3);
        assert!((lr.value(2500) - 1.65e-3).abs() < 1e-12);
        assert!(lr.value(1000) > lr.value(1001) && lr.value(4999) > 3e-4);
        assert_eq!(lr.value(5000), 3e-4);
        assert_eq!(lr.value(9000), 3e-4);
        assert_eq!(CosineSchedule { start: 1.0, end: 0.5, steps: 0 }.value(0), 0.5);
    }

    #[test]
    fn linear_interpolates_then_clamps() {
        let beta = LinearSchedule { start: 0.4, end: 1.0, steps: 5000 };
        assert_eq!(beta.value(0), 0.4);
        assert!((beta.value(2500) - 0.7).abs() < 1e-12);
        assert_eq!(beta.value(5000), 1.0);
        assert_eq!(beta.value(1_000_000), 1.0);
        assert_eq!(LinearSchedule { start: 0.4, end: 1.0, steps: 0 }.value(0), 1.0);
        let down = LinearSchedule { start: 1.0, end: 0.0, steps: 4 };
        assert_eq!(down.value(1), 0.75);
    }

    #[test]
    fn every_is_due_at_positive_multiples() {
        let e = Every(200);
        assert!(!e.is_due(0));
        assert!(!e.is_due(199));
        assert!(e.is_due(200));
        assert!(!e.is_due(201));
        assert!(e.is_due(400));
        assert!(!Every(0).is_due(0));
        assert!(!Every(0).is_due(200));
        assert!((1..10).all(|s| Every(1).is_due(s)));
    }
}
