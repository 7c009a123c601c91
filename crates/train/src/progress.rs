//! The training binary's progress display on stderr, drawn by [`indicatif`], e.g.
//! `[#####...............]  24% 1234/5000 updates | 00:03:21 elapsed, ETA 00:10:02 | SPS 45.6 | eval 0.80`.
//!
//! When stderr is a terminal the bar is redrawn in place at most five times a second, and cut to
//! the terminal's width; otherwise (CI logs, files, `TERM=dumb`) indicatif draws nothing and a plain
//! line ([`log_line`]) is printed at most every ten seconds and once at [`Progress::finish`], so logs
//! stay short.
//!
//! Limitations: interleaved `log` output on stderr breaks the in-place bar until the next redraw;
//! the ETA is indicatif's estimate from the recent rate (the plain line's too).

use std::io::Write;
use std::time::{Duration, Instant};

use indicatif::{FormattedDuration, ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Number of characters inside the bar's brackets.
pub const BAR_WIDTH: usize = 20;

const TTY_HZ: u8 = 5;
const LOG_INTERVAL: Duration = Duration::from_secs(10);
const TEMPLATE: &str =
    "[{bar:20}] {percent:>3}% {pos}/{len} {prefix} | {elapsed_precise} elapsed, ETA {eta_precise}{wide_msg}";

/// Where the plain lines of the non-terminal mode go, and when the last one went.
struct LogLines {
    out: Box<dyn Write + Send>,
    last: Option<Instant>,
}

/// Progress of a run of `total` units (updates, steps, episodes…).
pub struct Progress {
    bar: ProgressBar,
    unit: String,
    fields: String,
    /// `Some` when the bar is not drawn (stderr is not a terminal): plain lines instead.
    log: Option<LogLines>,
    finished: bool,
}

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("position", &self.bar.position())
            .field("total", &self.bar.length())
            .field("unit", &self.unit)
            .field("interactive", &self.log.is_none())
            .field("finished", &self.finished)
            .finish()
    }
}

impl Progress {
    /// Starts the clock for a run of `total` units named `unit` (e.g. `"updates"`): an in-place bar
    /// when stderr is a terminal, plain lines otherwise.
    pub fn new(total: u64, unit: &str) -> Self {
        let target = ProgressDrawTarget::stderr_with_hz(TTY_HZ);
        let log = target.is_hidden().then(|| LogLines { out: Box::new(std::io::stderr()), last: None });
        Self::with_target(total, unit, target, log)
    }

    fn with_target(total: u64, unit: &str, target: ProgressDrawTarget, log: Option<LogLines>) -> Self {
        let style =
            ProgressStyle::with_template(TEMPLATE).expect("the progress template is valid").progress_chars("#.");
        let bar = ProgressBar::with_draw_target(Some(total), target).with_style(style).with_prefix(unit.to_string());
        Self { bar, unit: unit.to_string(), fields: String::new(), log, finished: false }
    }

    /// Records that `done` units are complete, with extra `(name, value)` fields shown as
    /// `name value` between `|` separators (an empty name shows the value alone), and redraws if the
    /// rate limit allows.
    pub fn update(&mut self, done: u64, fields: &[(&str, String)]) {
        self.fields = format_fields(fields);
        self.bar.set_message(self.fields.clone());
        self.bar.set_position(done);
        let now = Instant::now();
        if let Some(log) = &mut self.log
            && log.last.is_none_or(|t| now.duration_since(t) >= LOG_INTERVAL)
        {
            log.last = Some(now);
            self.write_line();
        }
    }

    /// Draws the final state (the last `update`, not a full bar) and ends the line; later calls do
    /// nothing.
    pub fn finish(&mut self) {
        if self.finished {
            return;
        }
        self.finished = true;
        self.bar.abandon();
        if self.log.is_some() {
            self.write_line();
        }
    }

    fn write_line(&mut self) {
        let total = self.bar.length().unwrap_or(0);
        let done = self.bar.position();
        let eta = (done > 0 && done < total).then(|| self.bar.eta());
        let line = log_line(done, total, &self.unit, &self.fields, self.bar.elapsed(), eta);
        if let Some(log) = &mut self.log {
            // Progress output is best effort: a closed stderr must not stop training.
            let _ = writeln!(log.out, "{line}");
            let _ = log.out.flush();
        }
    }
}

/// ` | name value` per field (` | value` for an empty name).
fn format_fields(fields: &[(&str, String)]) -> String {
    let mut s = String::new();
    for (name, value) in fields {
        if name.is_empty() {
            s.push_str(&format!(" | {value}"));
        } else {
            s.push_str(&format!(" | {name} {value}"));
        }
    }
    s
}

/// The plain line printed when stderr is not a terminal, without reading any clock: the floor of the
/// percentage, the count and unit, the elapsed time and the estimated time left (`--:--:--` when
/// `eta` is `None`; nothing once `done` reaches `total`), then the fields as formatted for
/// [`Progress::update`]. Durations are indicatif's `HH:MM:SS`. `done` above `total` counts as 100%;
/// `total == 0` as complete.
pub fn log_line(done: u64, total: u64, unit: &str, fields: &str, elapsed: Duration, eta: Option<Duration>) -> String {
    let percent = if total == 0 { 100 } else { (done.min(total) as u128 * 100 / total as u128) as u64 };
    let mut s = format!("{percent:>3}% {done}/{total} {unit} | {} elapsed", FormattedDuration(elapsed));
    if done < total {
        match eta {
            Some(eta) => s.push_str(&format!(", ETA {}", FormattedDuration(eta))),
            None => s.push_str(", ETA --:--:--"),
        }
    }
    s.push_str(fields);
    s
}

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use indicatif::InMemoryTerm;

    use super::*;

    /// A writer whose bytes the test can read back.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Shared {
        fn lines(&self) -> Vec<String> {
            String::from_utf8(self.0.lock().unwrap().clone()).unwrap().lines().map(String::from).collect()
        }
    }

    fn fields() -> Vec<(&'static str, String)> {
        vec![("SPS", "45.6".to_string()), ("eval", "0.80".to_string()), ("", "warm-up".into())]
    }

    #[test]
    fn terminal_bar_shows_fill_count_fields_and_eta() {
        let term = InMemoryTerm::new(4, 160);
        let target = ProgressDrawTarget::term_like(Box::new(term.clone()));
        let mut p = Progress::with_target(5000, "updates", target, None);
        p.update(2500, &fields());
        p.finish();
        let screen = term.contents();
        let line = screen.lines().find(|l| l.starts_with('[')).unwrap_or_else(|| panic!("no bar in {screen:?}"));
        assert!(line.starts_with("[##########..........]  50% 2500/5000 updates | "), "{line}");
        assert_eq!(line[1..line.find(']').unwrap()].chars().count(), BAR_WIDTH);
        assert!(line.contains(" elapsed, ETA "), "{line}");
        assert!(line.trim_end().ends_with("| SPS 45.6 | eval 0.80 | warm-up"), "{line}");
        // finish() keeps the last position: a run stopped early does not show a full bar.
        assert_eq!(p.bar.position(), 2500);
    }

    #[test]
    fn terminal_bar_is_cut_to_the_terminal_width() {
        let term = InMemoryTerm::new(4, 60);
        let target = ProgressDrawTarget::term_like(Box::new(term.clone()));
        let mut p = Progress::with_target(100, "episodes", target, None);
        p.update(10, &[("note", "x".repeat(200))]);
        p.finish();
        for line in term.contents().lines() {
            assert!(line.chars().count() <= 60, "{line:?}");
        }
        assert!(term.contents().contains("10/100 episodes"), "{}", term.contents());
    }

    #[test]
    fn without_a_terminal_plain_lines_are_rate_limited_and_end_at_finish() {
        let out = Shared::default();
        let log = LogLines { out: Box::new(out.clone()), last: None };
        let mut p = Progress::with_target(5000, "updates", ProgressDrawTarget::hidden(), Some(log));
        p.update(1, &[]);
        // Within ten seconds of the first line: no new line.
        for done in 2..=100 {
            p.update(done, &fields());
        }
        assert_eq!(out.lines().len(), 1, "{:?}", out.lines());
        assert!(out.lines()[0].starts_with("  0% 1/5000 updates | 00:00:00 elapsed, ETA "), "{:?}", out.lines());
        p.finish();
        p.finish();
        let lines = out.lines();
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[1].starts_with("  2% 100/5000 updates | "), "{lines:?}");
        assert!(lines[1].ends_with(" | SPS 45.6 | eval 0.80 | warm-up"), "{lines:?}");
        assert!(!lines.iter().any(|l| l.contains('\r') || l.contains('\x1b')), "{lines:?}");
    }

    #[test]
    fn plain_lines_format_counts_durations_and_eta() {
        let f = format_fields(&fields());
        assert_eq!(f, " | SPS 45.6 | eval 0.80 | warm-up");
        let line = log_line(1000, 5000, "updates", &f, Duration::from_secs(100), Some(Duration::from_secs(400)));
        assert_eq!(line, " 20% 1000/5000 updates | 00:01:40 elapsed, ETA 00:06:40 | SPS 45.6 | eval 0.80 | warm-up");
        assert_eq!(
            log_line(0, 5000, "updates", "", Duration::ZERO, None),
            "  0% 0/5000 updates | 00:00:00 elapsed, ETA --:--:--"
        );
        assert_eq!(
            log_line(5000, 5000, "updates", "", Duration::from_secs(201), None),
            "100% 5000/5000 updates | 00:03:21 elapsed"
        );
        assert!(log_line(4999, 5000, "updates", "", Duration::from_secs(1), None).starts_with(" 99% "));
        assert!(
            log_line(10, 100, "episodes", "", Duration::from_secs(3600), Some(Duration::from_secs(9 * 3600)))
                .ends_with("01:00:00 elapsed, ETA 09:00:00")
        );
        // Nothing to divide by.
        assert_eq!(log_line(0, 0, "updates", "", Duration::ZERO, None), "100% 0/0 updates | 00:00:00 elapsed");
        assert_eq!(
            log_line(7000, 5000, "updates", "", Duration::ZERO, None),
            "100% 7000/5000 updates | 00:00:00 elapsed"
        );
    }
}
