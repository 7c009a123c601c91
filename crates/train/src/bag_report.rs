//! `equiarm bag info | eval | recover`: the bag tools' terminal output (the work is in `equiarm_bag`).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context as _;
use equiarm_bag::eval::{EpisodeCollector, GroupStats, summarize};
use equiarm_bag::{BagInfo, DecodeError, ReadMode, Reader};
use equiarm_msgs::RosMessage;
use equiarm_msgs::msg::{EpisodeResult, Transition};

fn secs(ns: u64) -> f64 {
    ns as f64 / 1e9
}

/// `ros2 bag info`-style text of a bag.
pub fn info_text(path: &Path, info: &BagInfo) -> String {
    let mut s = String::new();
    let size: u64 = info.files.iter().map(|f| f.size).sum();
    let _ = writeln!(s, "Bag:          {}", path.display());
    let _ = writeln!(s, "Files:        {}", info.files.len());
    for f in &info.files {
        let damaged = info.lost.iter().filter(|l| l.path == f.path).count();
        let state = match (f.complete, damaged) {
            (true, 0) => "complete".to_string(),
            (true, n) => format!("DAMAGED: {n} unreadable chunk(s) skipped (run `equiarm bag recover`)"),
            (false, 0) => "TRUNCATED (run `equiarm bag recover`)".to_string(),
            (false, n) => format!("TRUNCATED, {n} unreadable chunk(s) skipped (run `equiarm bag recover`)"),
        };
        let comp = if f.compression.is_empty() { "none" } else { &f.compression };
        let _ = writeln!(
            s,
            "              {} ({:.1} MiB, {} messages, compression {comp}, {state})",
            f.path.file_name().unwrap_or_default().to_string_lossy(),
            f.size as f64 / (1 << 20) as f64,
            f.messages
        );
    }
    let _ = writeln!(s, "Size:         {:.1} MiB", size as f64 / (1 << 20) as f64);
    let _ = writeln!(s, "Duration:     {:.3} s", secs(info.end.saturating_sub(info.start)));
    let _ = writeln!(s, "Start:        {:.3} s since the epoch", secs(info.start));
    let _ = writeln!(s, "End:          {:.3} s since the epoch", secs(info.end));
    let _ = writeln!(s, "Messages:     {}", info.messages);
    for d in damage_lines(info) {
        let _ = writeln!(s, "Damage:       {d}");
    }
    match &info.metadata {
        Some(m) if m.ok() => {
            let _ = writeln!(s, "Metadata:     metadata.yaml matches the files");
        }
        Some(m) => {
            for p in &m.problems {
                let _ = writeln!(s, "Metadata:     METADATA MISMATCH: metadata.yaml {p}");
            }
        }
        None => {}
    }
    let _ = writeln!(s, "Topics:");
    for (name, t) in &info.topics {
        let _ =
            writeln!(s, "  {name:<40} {:<34} {:>8} msgs {:>10.1} KiB", t.type_name, t.count, t.bytes as f64 / 1024.0);
    }
    s
}

/// One line on a chunk that could not be read: file, place, time range, messages lost, reason.
/// What a read of the bag lost, one line per truncated file and per damaged chunk (empty: nothing).
pub fn damage_lines(info: &BagInfo) -> Vec<String> {
    let ends = info
        .truncated
        .iter()
        .map(|(p, why)| format!("{} ends early ({why})", p.file_name().unwrap_or_default().to_string_lossy()));
    ends.chain(info.lost.iter().map(lost_text)).collect()
}

/// Warns each of [`damage_lines`] (naming the bag); with `strict`, damage is an error instead.
pub fn warn_damage(path: &Path, info: &BagInfo, strict: bool) -> anyhow::Result<()> {
    let damage = damage_lines(info);
    for d in &damage {
        log::warn!("{}: {d}", path.display());
    }
    if strict && !damage.is_empty() {
        anyhow::bail!(
            "{}: the bag is damaged ({} problem(s) above): `equiarm bag recover` it, or play it without --strict",
            path.display(),
            damage.len()
        );
    }
    Ok(())
}

/// One damaged chunk: where, which times, why, and how many messages it took with it.
pub fn lost_text(l: &equiarm_bag::LostChunk) -> String {
    let at = l.offset.map(|o| format!(" at byte {o}")).unwrap_or_default();
    let n = l.messages.map_or("an unknown number of".to_string(), |n| n.to_string());
    format!(
        "{}: the chunk{at} holding {:.3}–{:.3} s is damaged ({}); {n} messages lost",
        l.path.file_name().unwrap_or_default().to_string_lossy(),
        secs(l.start),
        secs(l.end),
        l.reason
    )
}

/// Reads a bag's episodes (`EpisodeResult`s, or reconstructed from `Transition`s) and summarises them.
pub fn eval(path: &Path, gamma: f64) -> anyhow::Result<EvalReport> {
    let reader = Reader::open(path)?;
    let mut c = EpisodeCollector::new(gamma);
    let mut bad = 0u64;
    // A payload that does not decode is counted; a type recorded under another definition stops
    // the read (every message of it would be misread).
    let count = |r: Result<(), DecodeError>, bad: &mut u64| match r {
        Err(e @ DecodeError::OtherDefinition { .. }) => Err(e),
        Err(DecodeError::Cdr { .. }) => {
            *bad += 1;
            Ok(())
        }
        Ok(()) => Ok(()),
    };
    let report = reader.for_each(ReadMode::Salvage, |m| {
        if m.type_name == EpisodeResult::TYPE_NAME {
            count(m.decode::<EpisodeResult>().map(|r| c.add_result(&r)), &mut bad)
        } else if m.type_name == Transition::TYPE_NAME {
            count(m.decode::<Transition>().map(|t| c.add_transition(&t)), &mut bad)
        } else {
            Ok(())
        }
    })?;
    let report = report.with_context(|| path.display().to_string())?;
    let (episodes, reconstructed, unfinished) = c.finish();
    Ok(EvalReport {
        groups: summarize(&episodes),
        episodes: episodes.len(),
        reconstructed,
        unfinished,
        undecodable: bad,
        truncated: report.truncated.iter().map(|(p, r)| format!("{}: {r}", p.display())).collect(),
        lost: report.lost.iter().map(lost_text).collect(),
    })
}

/// What `equiarm bag eval` reports.
pub struct EvalReport {
    /// Per (env, eval, expert) groups and all-env totals (`env == "*"`).
    pub groups: Vec<GroupStats>,
    /// Episodes found.
    pub episodes: usize,
    /// Episodes were reconstructed from transitions (the bag had no `EpisodeResult`).
    pub reconstructed: bool,
    /// Episodes still running when the recording ended (reconstruction only).
    pub unfinished: usize,
    /// Messages that did not decode as their type.
    pub undecodable: u64,
    /// Damaged files (read as far as possible).
    pub truncated: Vec<String>,
    /// Damaged chunks skipped (their messages are not in the figures).
    pub lost: Vec<String>,
}

impl EvalReport {
    /// A table for the terminal.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let src = if self.reconstructed { "reconstructed from Transition" } else { "from EpisodeResult" };
        let _ = writeln!(s, "{} episodes ({src})", self.episodes);
        let _ = writeln!(
            s,
            "{:<8} {:<6} {:<7} {:>5} {:>8} {:>17} {:>9} {:>10} {:>7}",
            "env", "mode", "actor", "n", "success", "95% CI (Wilson)", "return", "disc.ret", "steps"
        );
        for g in &self.groups {
            let _ = writeln!(
                s,
                "{:<8} {:<6} {:<7} {:>5} {:>8.3} {:>8.3}..{:<7.3} {:>9.3} {:>10.3} {:>7.1}",
                g.env,
                if g.eval { "eval" } else { "train" },
                if g.expert { "expert" } else { "policy" },
                g.success.n,
                g.success.rate,
                g.success.lo,
                g.success.hi,
                g.mean_return,
                g.mean_discounted_return,
                g.mean_steps
            );
        }
        if self.unfinished > 0 {
            let _ = writeln!(s, "({} unfinished episodes not counted)", self.unfinished);
        }
        if self.undecodable > 0 {
            let _ = writeln!(s, "({} messages did not decode and were skipped)", self.undecodable);
        }
        for t in &self.truncated {
            let _ = writeln!(s, "(damaged file read up to its last complete chunk: {t})");
        }
        for l in &self.lost {
            let _ = writeln!(s, "(episodes in it are not counted: {l})");
        }
        s
    }

    /// The same as JSON (NaN rates of empty groups become null).
    pub fn json(&self) -> anyhow::Result<String> {
        let groups: Vec<_> = self
            .groups
            .iter()
            .map(|g| {
                serde_json::json!({
                    "env": g.env, "eval": g.eval, "expert": g.expert, "episodes": g.success.n,
                    "successes": g.success.successes, "success_rate": g.success.rate,
                    "success_ci95": [g.success.lo, g.success.hi], "mean_return": g.mean_return,
                    "mean_discounted_return": g.mean_discounted_return, "mean_steps": g.mean_steps,
                })
            })
            .collect();
        let v = serde_json::json!({
            "episodes": self.episodes, "reconstructed_from_transitions": self.reconstructed,
            "unfinished": self.unfinished, "undecodable": self.undecodable, "truncated": self.truncated, "lost_chunks": self.lost,
            "groups": groups,
        });
        serde_json::to_string_pretty(&v).context("formatting JSON")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (issue 61): `bag play` played a damaged or truncated bag with exit 0 and "0 skipped"
    /// while `bag info` said DAMAGED. Both now take their lines from `damage_lines`; play warns them,
    /// and refuses with --strict.
    #[test]
    fn damage_is_said_by_play_as_by_info_and_refused_when_strict() {
        let bag = Path::new("runs/x/bag");
        let mut info = BagInfo::default();
        warn_damage(bag, &info, true).unwrap();
        info.truncated.push(("runs/x/bag/bag_1.mcap".into(), "no footer".into()));
        info.lost.push(equiarm_bag::LostChunk {
            path: "runs/x/bag/bag_0.mcap".into(),
            offset: Some(4096),
            start: 2_000_000_000,
            end: 3_500_000_000,
            messages: Some(17),
            reason: "CRC mismatch".into(),
        });
        let lines = damage_lines(&info);
        assert_eq!(lines[0], "bag_1.mcap ends early (no footer)");
        assert_eq!(
            lines[1],
            "bag_0.mcap: the chunk at byte 4096 holding 2.000–3.500 s is damaged (CRC mismatch); 17 messages lost"
        );
        let text = info_text(bag, &info);
        assert!(lines.iter().all(|l| text.contains(&format!("Damage:       {l}"))), "{text}");
        warn_damage(bag, &info, false).unwrap();
        let e = warn_damage(bag, &info, true).unwrap_err().to_string();
        assert!(e.contains("runs/x/bag: the bag is damaged (2 problem(s) above)"), "{e}");
    }
}
