//! When the policy node may answer an Observation, without DDS: at once, under flow control
//! (`--max-lead`, on the trainer's update count from `/trainer/status`), in the deterministic
//! lock-step (`--deterministic`, on the version of the weights in use), or in evaluation windows
//! (`--eval-every`, on the update count of the weights in use).
//!
//! An Observation that may not be answered yet is held (one at a time: the sim waits for its answer,
//! and a re-publication of the same seq replaces it) and released when a TrainerStatus or new weights
//! arrive. A re-published seq that was already answered always passes: it gets the same command again.
//!
//! Lock-step: the k-th distinct Observation answered (k from 0, expert steps included) is answered
//! with weights version k + 1 exactly (version 1 is the trainer's initial actor). The trainer publishes
//! version k + 2 only after round k, which needs this env's k-th transition, so a newer version
//! cannot arrive first; if one did, the run is no longer deterministic and this is logged as an error.

use anyhow::bail;
use equiarm_msgs::msg::Observation;
use log::error;

use crate::policy::Policy;

/// Where a policy stands, as the gate needs it (see [`Policy::progress`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Standing {
    /// The Observation's seq is the last one answered (a re-publication).
    pub repeat: bool,
    /// Answering it is a learned/random policy step (not an expert step), counted by `--max-lead`.
    pub policy_step: bool,
    /// Policy steps answered so far.
    pub policy_steps: u64,
    /// Distinct Observations answered so far (expert steps included).
    pub answered: u64,
    /// Version of the weights in use (0: the node's own initial ones).
    pub version: u64,
    /// The Observation starts an episode (its step is 0).
    pub episode_start: bool,
    /// The trainer's update count when the weights in use were taken (None: the node's own).
    pub weights_updates: Option<u64>,
}

/// The gating rule of one policy node.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Rule {
    /// Answer every Observation at once.
    Open,
    /// `--max-lead`: once a TrainerStatus has been seen,
    /// `policy_steps − base < per_update × (updates − from) + max_lead`.
    Lead {
        /// Policy steps allowed beyond `per_update × updates`.
        max_lead: u64,
        /// Policy steps allowed per trainer update.
        per_update: u64,
        /// The trainer's update count (None until the first TrainerStatus).
        updates: Option<u64>,
        /// Policy steps not counted: when the trainer's count goes back (a trainer resumed from a
        /// checkpoint older than the updates it had made), the lead counts from there, so the node
        /// and the trainer never wait for each other.
        base: u64,
        /// The count went back; `base` is set at the next step.
        rebase: bool,
        /// Trainer updates not counted: when this node first hears of a trainer that is ahead of
        /// its policy steps (a resumed trainer, or a policy node started into a running suite), the
        /// lead counts from there instead of letting the node run free until it has caught up.
        from: u64,
        /// The first TrainerStatus arrived; `from` is set at the next step.
        anchor: bool,
    },
    /// `--deterministic`: the k-th distinct Observation waits for weights version k + 1.
    Lockstep,
    /// `--eval-every N --eval-episodes K`, the evaluation env's: episodes start only in evaluation
    /// windows, the trainer's: once the weights in use were taken at `next` updates or later (a
    /// multiple of N), K episodes start, all acted on by weights of the window (an episode under
    /// way is never held); the next window opens at the multiple of N after the weights that
    /// started the K-th. Between windows the env waits at an episode's first observation.
    Windows {
        /// Updates between evaluations.
        every: u64,
        /// Episodes per evaluation.
        episodes: u64,
        /// The update count the weights must have reached for the window to open.
        next: u64,
        /// Episodes started in the open window.
        started: u64,
    },
}

/// A [`Rule`] and the Observation it holds back.
#[derive(Debug)]
pub struct Gate {
    rule: Rule,
    held: Option<Observation>,
    newer_logged: bool,
}

impl Gate {
    /// The gate of the policy options: `deterministic` excludes `max_lead > 0` (flow control is the
    /// lock-step itself then) and needs a mode that takes weights (`learns`).
    pub fn new(max_lead: u64, steps_per_update: u64, deterministic: bool, learns: bool) -> anyhow::Result<Self> {
        let rule = match (deterministic, max_lead) {
            (true, m) if m > 0 => bail!(
                "--deterministic and --max-lead {m} exclude each other: in lock-step the k-th observation waits for weights version k + 1 instead"
            ),
            (true, _) if !learns => bail!(
                "--deterministic needs --mode sample or greedy (it paces the node by the trainer's weights versions)"
            ),
            (true, _) => Rule::Lockstep,
            (false, 0) => Rule::Open,
            (false, m) => Rule::Lead {
                max_lead: m,
                per_update: steps_per_update,
                updates: None,
                base: 0,
                rebase: false,
                from: 0,
                anchor: false,
            },
        };
        Ok(Gate { rule, held: None, newer_logged: false })
    }

    /// The evaluation env's gate: `episodes` episodes in a window every `every` updates (both at
    /// least 1), on weights from the trainer (`learns`).
    pub fn windows(every: u64, episodes: u64, learns: bool) -> anyhow::Result<Self> {
        if !learns {
            bail!("--eval-every needs --mode sample or greedy (its windows open on the trainer's weights)");
        }
        if every == 0 || episodes == 0 {
            bail!("--eval-every {every} --eval-episodes {episodes}: both must be at least 1");
        }
        let rule = Rule::Windows { every, episodes, next: every, started: 0 };
        Ok(Gate { rule, held: None, newer_logged: false })
    }

    /// The rule.
    pub fn rule(&self) -> &Rule {
        &self.rule
    }

    /// Whether the rule reads `/trainer/status`.
    pub fn needs_status(&self) -> bool {
        matches!(self.rule, Rule::Lead { .. })
    }

    /// A TrainerStatus said the trainer has made `n` updates.
    pub fn on_status(&mut self, n: u64) {
        if let Rule::Lead { updates, rebase, anchor, .. } = &mut self.rule {
            match *updates {
                Some(u) if n < u => {
                    log::warn!(
                        "the trainer's update count went back from {u} to {n} (a resumed trainer): the lead counts from here"
                    );
                    *rebase = true;
                }
                None => *anchor = true,
                Some(_) => {}
            }
            *updates = Some(n);
        }
    }

    /// Whether an Observation at progress `p` may be answered now.
    pub fn allows(&mut self, p: Standing, seq: u64) -> bool {
        if p.repeat {
            return true;
        }
        match &mut self.rule {
            Rule::Open => true,
            Rule::Lead { max_lead, per_update, updates, base, rebase, from, anchor } => {
                if let (true, Some(u)) = (*rebase, *updates) {
                    *base = p.policy_steps.saturating_sub(per_update.saturating_mul(u));
                    *from = 0;
                    *rebase = false;
                }
                let steps = p.policy_steps.saturating_sub(*base);
                if let (true, Some(u)) = (*anchor, *updates) {
                    // the updates this node's steps so far account for; the rest are not counted
                    let covered = steps.checked_div(*per_update).unwrap_or(u);
                    *from = u.saturating_sub(covered);
                    *anchor = false;
                }
                !p.policy_step
                    || updates.is_none_or(|u| {
                        steps < per_update.saturating_mul(u.saturating_sub(*from)).saturating_add(*max_lead)
                    })
            }
            Rule::Lockstep => {
                let want = p.answered + 1;
                if p.version > want && !self.newer_logged {
                    self.newer_logged = true;
                    error!(
                        "lock-step broken: observation {} (seq {seq}) is answered with weights version {}, expected {want}; this run is not deterministic",
                        p.answered, p.version
                    );
                }
                p.version >= want
            }
            Rule::Windows { every, episodes, next, started } => {
                if !p.episode_start {
                    return true;
                }
                match p.weights_updates {
                    Some(w) if w >= *next => {
                        *started += 1;
                        if *started == *episodes {
                            // The trainer's evaluation ends at its count when the K-th episode ends,
                            // at least `w`: its next is then at or after this one.
                            *next = (w / *every + 1) * *every;
                            *started = 0;
                        }
                        true
                    }
                    _ => false,
                }
            }
        }
    }

    /// An Observation arrived: returns it if it may be answered now, else holds it (replacing the
    /// one held).
    pub fn offer(&mut self, obs: Observation, policy: &Policy) -> Option<Observation> {
        // An episode's last frame is for the trainer and the recorder: nothing answers it.
        if obs.terminal {
            return None;
        }
        if self.allows(policy.progress(&obs), obs.seq) {
            return Some(obs);
        }
        self.held = Some(obs);
        None
    }

    /// After a TrainerStatus or new weights: the held Observation, if it may be answered now.
    pub fn release(&mut self, policy: &Policy) -> Option<Observation> {
        let obs = self.held.take()?;
        self.offer(obs, policy)
    }

    /// Whether an Observation is held back.
    pub fn holds(&self) -> bool {
        self.held.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(answered: u64, version: u64) -> Standing {
        Standing { answered, version, policy_step: true, policy_steps: answered, ..Standing::default() }
    }

    /// An evaluation env's observation: an episode's first or a later one, weights taken at `w`.
    fn eval(start: bool, w: Option<u64>) -> Standing {
        Standing { episode_start: start, weights_updates: w, policy_step: true, ..Standing::default() }
    }

    #[test]
    fn eval_windows_start_k_episodes_per_window_on_weights_of_the_window() {
        let mut g = Gate::windows(100, 2, true).unwrap();
        assert!(!g.needs_status());
        assert!(!g.allows(eval(true, None), 0), "the node's own weights open no window");
        assert!(!g.allows(eval(true, Some(50)), 0), "weights older than the first window");
        assert!(g.allows(eval(false, Some(50)), 0), "an episode under way is never held");
        assert!(g.allows(eval(true, Some(100)), 1), "the window at 100 opens");
        assert!(g.allows(eval(false, Some(100)), 2));
        assert!(g.allows(eval(true, Some(150)), 3), "its second episode");
        assert!(!g.allows(eval(true, Some(150)), 4), "the window is full");
        assert!(g.allows(Standing { repeat: true, ..eval(true, Some(150)) }, 3), "a re-publication passes");
        assert!(g.allows(eval(true, Some(200)), 5), "the next window");
        // a slow window: its second episode starts on weights of 350, so the next opens at 400
        assert!(g.allows(eval(true, Some(350)), 6));
        assert!(!g.allows(eval(true, Some(399)), 7) && g.allows(eval(true, Some(400)), 7));
        let e = Gate::windows(100, 20, false).unwrap_err().to_string();
        assert!(e.contains("sample or greedy"), "{e}");
        let e = Gate::windows(0, 20, true).unwrap_err().to_string();
        assert!(e.contains("at least 1"), "{e}");
    }

    #[test]
    fn lockstep_answers_observation_k_with_version_k_plus_1_only() {
        let mut g = Gate::new(0, 1, true, true).unwrap();
        assert_eq!(g.rule(), &Rule::Lockstep);
        assert!(!g.needs_status());
        assert!(!g.allows(p(0, 0), 0), "the node's own initial weights are not version 1");
        assert!(g.allows(p(0, 1), 0));
        assert!(!g.allows(p(1, 1), 1));
        assert!(g.allows(p(1, 2), 1));
        // Expert steps count too: the 5th observation (k = 4) waits for version 5.
        assert!(!g.allows(Standing { policy_step: false, ..p(4, 4) }, 9));
        // A re-publication of the seq just answered passes whatever the version.
        assert!(g.allows(Standing { repeat: true, ..p(5, 5) }, 9));
        // A newer version than expected is an error in the log, but the node keeps answering.
        assert!(g.allows(p(2, 7), 3));
    }

    #[test]
    fn lead_limits_policy_steps_once_a_status_was_seen() {
        let mut g = Gate::new(2, 3, false, true).unwrap();
        assert!(g.needs_status());
        assert!(g.allows(p(100, 0), 0), "no status yet");
        g.on_status(1);
        assert!(g.allows(p(4, 0), 0) && !g.allows(p(5, 0), 0));
        assert!(g.allows(Standing { policy_step: false, ..p(9, 0) }, 0), "expert steps are not limited");
        assert_eq!(Gate::new(0, 1, false, false).unwrap().rule(), &Rule::Open);
    }

    /// Regression (found by bench/soak.sh): after a trainer was killed and resumed from a checkpoint
    /// 10 updates older, its count (40) was below what the policies had run ahead on (50 + lead), so
    /// they waited for updates and the trainer for their transitions until its idle timeout.
    #[test]
    fn a_trainer_count_that_goes_back_restarts_the_lead_instead_of_stalling() {
        let mut g = Gate::new(10, 1, false, true).unwrap();
        g.on_status(50);
        assert!(!g.allows(p(60, 0), 0), "at the lead");
        g.on_status(40);
        assert!(g.allows(p(60, 0), 0), "the resumed trainer needs transitions to update at all");
        assert!(g.allows(p(69, 0), 0) && !g.allows(p(70, 0), 0), "a lead of 10 from there");
        g.on_status(41);
        assert!(g.allows(p(70, 0), 0) && !g.allows(p(71, 0), 0));
        // A count that only grows never moves the base.
        let mut h = Gate::new(10, 1, false, true).unwrap();
        h.on_status(5);
        h.on_status(6);
        assert!(!h.allows(p(16, 0), 0));
    }

    /// Regression (the main job resumed over DDS): a resumed trainer reported 5,232 updates to new
    /// policy nodes at 0 steps, which then ran their sims unthrottled (a lead of 5,232 × per_update
    /// steps) and starved the trainer of the CPU.
    #[test]
    fn a_trainer_ahead_of_a_new_policy_gives_it_the_lead_only() {
        let mut g = Gate::new(10, 1, false, true).unwrap();
        g.on_status(5232);
        assert!(g.allows(p(0, 0), 0) && g.allows(p(9, 0), 0));
        assert!(!g.allows(p(10, 0), 0), "a lead of 10 from where the node joined");
        g.on_status(5233);
        assert!(g.allows(p(10, 0), 0) && !g.allows(p(11, 0), 0));
        // per_update 4: a node with 8 steps joining at 10 updates has 2 updates' worth of steps behind it
        let mut h = Gate::new(3, 4, false, true).unwrap();
        h.on_status(10);
        assert!(h.allows(p(8, 0), 0) && h.allows(p(10, 0), 0) && !h.allows(p(11, 0), 0));
        // and a count that then goes back still rebases
        h.on_status(4);
        assert!(h.allows(p(11, 0), 0));
    }

    #[test]
    fn deterministic_refuses_flow_control_and_modes_without_weights() {
        let e = Gate::new(10, 1, true, true).unwrap_err().to_string();
        assert!(e.contains("--max-lead 10"), "{e}");
        let e = Gate::new(0, 1, true, false).unwrap_err().to_string();
        assert!(e.contains("sample or greedy"), "{e}");
    }
}
