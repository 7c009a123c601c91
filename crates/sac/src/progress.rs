//! A one-line progress display for the training binary, written to stderr, e.g.
//! `[#####...............]  24% 1234/5000 updates | SPS 45.6 | eval 0.80 | 03:21 elapsed, ETA 10:02`.
//!
//! When stderr is a terminal the line is rewritten in place (`\r`) at most five times a second;
//! otherwise (CI logs, files) a full line is printed at most every ten seconds and once at
//! [`Progress::finish`], so logs stay short. The formatting is the pure function
//! [`Progress::render`]; only [`Progress::update`] and [`Progress::finish`] read the clock.
//!
//! Limitations: the ETA assumes a constant rate since the start; the line is not truncated to the
//! terminal width (a line longer than the terminal wraps, and the `\r` rewrite then only replaces
//! its last row); interleaved `log` output on stderr breaks the in-place line until the next redraw.

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

/// Number of characters inside the bar's brackets.
pub const BAR_WIDTH: usize = 20;

const TTY_INTERVAL: Duration = Duration::from_millis(200);
const LOG_INTERVAL: Duration = Duration::from_secs(10);

/// Progress of a run of `total` units (updates, steps, episodes…).
#[derive(Debug)]
pub struct Progress {
    total: u64,
    unit: String,
    start: Instant,
    last_draw: Option<Instant>,
    interactive: bool,
    last_len: usize,
    done: u64,
    fields: Vec<(String, String)>,
    finished: bool,
}

impl Progress {
    /// Starts the clock for a run of `total` units named `unit` (e.g. `"updates"`); interactive
    /// (in-place) mode is chosen when stderr is a terminal.
    pub fn new(total: u64, unit: &str) -> Self {
        Self {
            total,
            unit: unit.to_string(),
            start: Instant::now(),
            last_draw: None,
            interactive: std::io::stderr().is_terminal(),
            last_len: 0,
            done: 0,
            fields: Vec::new(),
            finished: false,
        }
    }

    /// Records that `done` units are complete, with extra `(name, value)` fields shown as
    /// `name value` between `|` separators (an empty name shows the value alone), and redraws if the
    /// rate limit allows.
    pub fn update(&mut self, done: u64, fields: &[(&str, String)]) {
        self.done = done;
        self.fields = fields.iter().map(|(k, v)| (k.to_string(), v.clone())).collect();
        let now = Instant::now();
        let interval = if self.interactive { TTY_INTERVAL } else { LOG_INTERVAL };
        if self.last_draw.is_none_or(|t| now.duration_since(t) >= interval) {
            self.last_draw = Some(now);
            self.draw(false);
        }
    }

    /// Draws the final state (the last `update`) and ends the line; later calls do nothing.
    pub fn finish(&mut self) {
        if !self.finished {
            self.finished = true;
            self.draw(true);
        }
    }

    fn draw(&mut self, last: bool) {
        let fields: Vec<(&str, String)> = self.fields.iter().map(|(k, v)| (k.as_str(), v.clone())).collect();
        let line = self.render(self.done, &fields, self.start.elapsed());
        let mut err = std::io::stderr().lock();
        // Progress output is best effort: a closed stderr must not stop training.
        let _ = if self.interactive {
            let pad = self.last_len.saturating_sub(line.chars().count());
            self.last_len = line.chars().count();
            let end = if last { "\n" } else { "" };
            write!(err, "\r{line}{:pad$}{end}", "")
        } else {
            writeln!(err, "{line}")
        };
        let _ = err.flush();
    }

    /// Formats the progress line for `done` units after `elapsed`, without reading any clock: the
    /// bar ([`BAR_WIDTH`] characters, `#` done, `.` to do), the floor of the percentage, the count
    /// and unit, the fields, the elapsed time and, while `0 < done < total`, the estimated time
    /// left assuming a constant rate (`ETA --:--` at `done == 0`). Durations are `MM:SS`, or
    /// `H:MM:SS` from one hour on. `done` above `total` shows a full bar; `total == 0` counts as
    /// complete.
    pub fn render(&self, done: u64, fields: &[(&str, String)], elapsed: Duration) -> String {
        let total = self.total;
        let filled = if total == 0 {
            BAR_WIDTH
        } else {
            ((done.min(total) as u128 * BAR_WIDTH as u128) / total as u128) as usize
        };
        let percent = if total == 0 { 100 } else { (done.min(total) as u128 * 100 / total as u128) as u64 };
        let mut s = format!(
            "[{}{}] {percent:>3}% {done}/{total} {}",
            "#".repeat(filled),
            ".".repeat(BAR_WIDTH - filled),
            self.unit
        );
        for (name, value) in fields {
            if name.is_empty() {
                s.push_str(&format!(" | {value}"));
            } else {
                s.push_str(&format!(" | {name} {value}"));
            }
        }
        s.push_str(&format!(" | {} elapsed", format_duration(elapsed.as_secs())));
        if done == 0 && total > 0 {
            s.push_str(", ETA --:--");
        } else if done < total {
            let left = elapsed.as_secs_f64() * (total - done) as f64 / done as f64;
            if left.is_finite() && left < 1e9 {
                s.push_str(&format!(", ETA {}", format_duration(left.round() as u64)));
            } else {
                s.push_str(", ETA --:--");
            }
        }
        s
    }
}

/// `MM:SS` below an hour, `H:MM:SS` from one hour on.
fn format_duration(secs: u64) -> String {
    let (h, m, s) = (secs / 3600, secs / 60 % 60, secs % 60);
    if h > 0 { format!("{h}:{m:02}:{s:02}") } else { format!("{m:02}:{s:02}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bar(line: &str) -> &str {
        let end = line.find(']').unwrap();
        &line[1..end]
    }

    #[test]
    fn bar_has_fixed_width_and_fills_proportionally() {
        let p = Progress::new(5000, "updates");
        for done in [0, 1, 1234, 2500, 4999, 5000, 7000] {
            let line = p.render(done, &[], Duration::from_secs(10));
            assert_eq!(bar(&line).chars().count(), BAR_WIDTH, "{line}");
        }
        let line = p.render(2500, &[], Duration::from_secs(10));
        assert_eq!(bar(&line), "##########..........");
        assert_eq!(bar(&p.render(7000, &[], Duration::ZERO)), "#".repeat(BAR_WIDTH));
    }

    #[test]
    fn percentages_at_zero_and_total() {
        let p = Progress::new(5000, "updates");
        let start = p.render(0, &[], Duration::ZERO);
        assert_eq!(start, "[....................]   0% 0/5000 updates | 00:00 elapsed, ETA --:--");
        let end = p.render(5000, &[], Duration::from_secs(201));
        assert_eq!(end, "[####################] 100% 5000/5000 updates | 03:21 elapsed");
        assert!(p.render(4999, &[], Duration::from_secs(1)).contains(" 99% "));
    }

    #[test]
    fn fields_and_eta_are_formatted() {
        let p = Progress::new(5000, "updates");
        let fields = [("SPS", "45.6".to_string()), ("eval", "0.80".to_string()), ("", "warm-up".into())];
        let line = p.render(1000, &fields, Duration::from_secs(100));
        assert_eq!(
            line,
            "[####................]  20% 1000/5000 updates | SPS 45.6 | eval 0.80 | warm-up | 01:40 elapsed, ETA 06:40"
        );
        // ETA in hours: 10 units in 1 h of a 100-unit run leaves 9 h.
        let p = Progress::new(100, "episodes");
        let line = p.render(10, &[], Duration::from_secs(3600));
        assert!(line.ends_with("1:00:00 elapsed, ETA 9:00:00"), "{line}");
        assert_eq!(format_duration(3600 * 12 + 61), "12:01:01");
    }

    #[test]
    fn no_division_by_zero() {
        let p = Progress::new(5000, "updates");
        // done = 0, elapsed = 0.
        assert!(p.render(0, &[], Duration::ZERO).contains("ETA --:--"));
        // done > 0, elapsed = 0: nothing left to estimate but no NaN either.
        assert!(p.render(1, &[], Duration::ZERO).ends_with("ETA 00:00"));
        let empty = Progress::new(0, "updates");
        let line = empty.render(0, &[], Duration::ZERO);
        assert!(line.starts_with("[####################] 100% 0/0 updates"), "{line}");
        assert!(!line.contains("NaN") && !line.contains("inf"));
    }
}
