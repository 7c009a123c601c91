//! CleanRL-style scalar logs of a training run, written as two files in the run directory:
//!
//! - `metrics.jsonl`: one JSON object per record,
//!   `{"global_step": 1000, "wall_time": 12.5, "losses/qf1_loss": 0.03, ...}`, where `wall_time` is
//!   seconds since the run started (supplied by the caller);
//! - `metrics.csv`: the same data in long format, header `global_step,wall_time,name,value`, one
//!   row per scalar (long because evaluation records and loss records carry different names);
//! - `events.out.tfevents.<unix seconds>.equiarm`: the same scalars as a TensorBoard event file
//!   (tag = name, step = `global_step`, value as f32, wall time = the Unix time it was written), so
//!   `tensorboard --logdir RUNS` shows every run under `RUNS` side by side. One event file per run
//!   directory: a new run removes the old ones, and a resumed run rewrites it from the records it
//!   keeps (their wall times then read the time of the resume).
//!
//! Names are free-form, but the learner uses CleanRL's: `charts/episodic_return`,
//! `charts/episodic_length`, `charts/SPS`, `losses/qf1_loss`, `losses/qf2_loss`,
//! `losses/qf1_values`, `losses/qf2_values`, `losses/actor_loss`, `losses/alpha`,
//! `losses/alpha_loss`, `eval/discounted_return`, `eval/success_rate`, and FERM's
//! `losses/curl_loss` (every update) and `losses/curl_pretrain_loss` (once, after the pre-training).
//!
//! Non-finite values (NaN, ±inf) are written as `null` in JSONL and `nan` in CSV; [`read_series`]
//! reads `null` back as NaN. Each record is written with one `write` call per file and flushed, so a
//! crash loses at most the record being written; a final line without its newline (such a torn
//! record) is ignored by [`read_series`] and dropped by [`MetricsWriter::resume`]. The event file is
//! flushed on the same schedule (TensorBoard's reader ignores a torn final event).
//!
//! Limitations: no fsync per record (the OS may still lose recent records on power loss); the
//! writer does not enforce increasing steps; `read_series` reads the whole JSONL file, which is fine
//! for the thousands of records of a run but not meant for streaming huge logs.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

use equiarm_types::files::{FileError, at};

/// File name of the JSON-lines log inside a run directory.
pub const JSONL_FILE: &str = "metrics.jsonl";
/// File name of the long-format CSV log inside a run directory.
pub const CSV_FILE: &str = "metrics.csv";
/// File names of TensorBoard event files start with this (TensorBoard looks for `tfevents`).
pub const EVENTS_PREFIX: &str = "events.out.tfevents.";
/// Header line of [`CSV_FILE`].
pub const CSV_HEADER: &str = "global_step,wall_time,name,value";

/// What can go wrong while writing or reading metrics.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// Reading, writing, creating or renaming a file or directory failed (the file, and the cause).
    #[error(transparent)]
    Io(#[from] FileError),
    /// A line of a metrics file could not be parsed.
    #[error("{path}:{line}: {reason}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        reason: String,
    },
    /// A scalar name is empty, or is `global_step` / `wall_time` (reserved for the record's keys).
    #[error("scalar name {name:?} is empty or reserved (global_step, wall_time)")]
    BadName {
        /// The offending name.
        name: String,
    },
    /// The same scalar name appears twice in one record.
    #[error("scalar name {name:?} appears twice in the record for global_step {global_step}")]
    DuplicateName {
        /// The repeated name.
        name: String,
        /// The record's step.
        global_step: u64,
    },
}

/// Appends scalar records to `metrics.jsonl`, `metrics.csv` and the TensorBoard event file in a run
/// directory.
pub struct MetricsWriter {
    dir: PathBuf,
    jsonl: File,
    csv: File,
    events: Events,
    last: Option<(u64, f64)>,
}

impl std::fmt::Debug for MetricsWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MetricsWriter").field("dir", &self.dir).field("events", &self.events.path).finish()
    }
}

/// The run's TensorBoard event file.
struct Events {
    path: PathBuf,
    writer: syntaxdot_summary::SummaryWriter<BufWriter<File>>,
}

impl Events {
    /// Removes the event files in `dir` and starts one holding `records` (flushed after each
    /// scalar). It is written under a temporary name and renamed once complete, so an interrupted
    /// start leaves the old files or the new one.
    fn start(dir: &Path, records: &[(u64, Vec<(String, f64)>)]) -> Result<Self, MetricsError> {
        let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
        let path = dir.join(format!("{EVENTS_PREFIX}{secs}.equiarm"));
        let partial = dir.join(".events.partial");
        let file = File::create(&partial).map_err(at(&partial))?;
        let mut writer = syntaxdot_summary::SummaryWriter::new(BufWriter::new(file)).map_err(at(&partial))?;
        for (step, scalars) in records {
            for (name, value) in scalars {
                writer.write_scalar(name.as_str(), *step as i64, *value as f32).map_err(at(&partial))?;
            }
        }
        for old in std::fs::read_dir(dir).map_err(at(dir))? {
            let old = old.map_err(at(dir))?.path();
            if old.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with(EVENTS_PREFIX)) {
                std::fs::remove_file(&old).map_err(at(&old))?;
            }
        }
        std::fs::rename(&partial, &path).map_err(at(&path))?;
        Ok(Self { path, writer })
    }

    fn log(&mut self, step: u64, scalars: &[(&str, f64)]) -> Result<(), MetricsError> {
        for (name, value) in scalars {
            self.writer.write_scalar(*name, step as i64, *value as f32).map_err(at(&self.path))?;
        }
        Ok(())
    }
}

impl MetricsWriter {
    /// Starts fresh logs in `dir` (created if missing, with its parents), truncating any existing
    /// `metrics.jsonl` / `metrics.csv` there.
    pub fn create(dir: &Path) -> Result<Self, MetricsError> {
        std::fs::create_dir_all(dir).map_err(at(dir))?;
        let jsonl_path = dir.join(JSONL_FILE);
        let csv_path = dir.join(CSV_FILE);
        let jsonl = File::create(&jsonl_path).map_err(at(&jsonl_path))?;
        let mut csv = File::create(&csv_path).map_err(at(&csv_path))?;
        csv.write_all(format!("{CSV_HEADER}\n").as_bytes()).and_then(|_| csv.flush()).map_err(at(&csv_path))?;
        let events = Events::start(dir, &[])?;
        Ok(Self { dir: dir.to_path_buf(), jsonl, csv, events, last: None })
    }

    /// Continues the logs in `dir` after a restart from the checkpoint taken at `up_to_step`: keeps
    /// only the records with `global_step <= up_to_step` (so steps logged after that checkpoint are
    /// not duplicated), rewrites both files atomically (temporary file, then rename) and appends to
    /// them; the event file is rewritten from the kept records. Missing files are started fresh. A torn final line (no newline) is dropped; any other
    /// malformed line is an error naming the file and line.
    pub fn resume(dir: &Path, up_to_step: u64) -> Result<Self, MetricsError> {
        std::fs::create_dir_all(dir).map_err(at(dir))?;
        let jsonl_path = dir.join(JSONL_FILE);
        let csv_path = dir.join(CSV_FILE);

        let mut last: Option<(u64, f64)> = None;
        let mut kept_json = String::new();
        let mut kept_events = Vec::new();
        if let Some(text) = read_optional(&jsonl_path)? {
            for (line_no, line) in complete_lines(&text) {
                if line.trim().is_empty() {
                    continue;
                }
                let record = parse_json_record(&jsonl_path, line_no, line)?;
                let (step, wall) = record.keys;
                if step <= up_to_step {
                    kept_events.push((step, record.scalars(&jsonl_path, line_no)?));
                    kept_json.push_str(line);
                    kept_json.push('\n');
                    if last.is_none_or(|(s, _)| step >= s) {
                        last = Some((step, wall));
                    }
                }
            }
        }
        let mut kept_csv = format!("{CSV_HEADER}\n");
        if let Some(text) = read_optional(&csv_path)? {
            for (line_no, line) in complete_lines(&text) {
                if line_no == 1 {
                    if line != CSV_HEADER {
                        return Err(MetricsError::Malformed {
                            path: csv_path,
                            line: 1,
                            reason: format!("expected header {CSV_HEADER:?}, found {line:?}"),
                        });
                    }
                    continue;
                }
                if line.trim().is_empty() {
                    continue;
                }
                let step_field = line.split(',').next().unwrap_or("");
                let step: u64 = step_field.parse().map_err(|_| MetricsError::Malformed {
                    path: csv_path.clone(),
                    line: line_no,
                    reason: format!("global_step {step_field:?} is not an unsigned integer"),
                })?;
                if step <= up_to_step {
                    kept_csv.push_str(line);
                    kept_csv.push('\n');
                }
            }
        }
        equiarm_types::files::replace(&jsonl_path, &kept_json)?;
        equiarm_types::files::replace(&csv_path, &kept_csv)?;
        let events = Events::start(dir, &kept_events)?;
        let open = |p: &Path| OpenOptions::new().append(true).open(p).map_err(at(p));
        Ok(Self { dir: dir.to_path_buf(), jsonl: open(&jsonl_path)?, csv: open(&csv_path)?, events, last })
    }

    /// The run directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// `(global_step, wall_time)` of the latest record written or kept by [`Self::resume`]; a
    /// resumed run can add this `wall_time` to its own clock so that `wall_time` keeps increasing.
    /// A non-finite `wall_time` reads back as NaN.
    pub fn last_record(&self) -> Option<(u64, f64)> {
        self.last
    }

    /// Appends one record: `scalars` are `(name, value)` pairs (see the module docs for the names
    /// in use) logged at `global_step`, `wall_time` seconds after the run started. Both files are
    /// flushed before returning. An empty `scalars` writes a JSONL record with only the two keys and
    /// no CSV rows.
    pub fn log(&mut self, global_step: u64, wall_time: f64, scalars: &[(&str, f64)]) -> Result<(), MetricsError> {
        for (i, (name, _)) in scalars.iter().enumerate() {
            if name.is_empty() || *name == "global_step" || *name == "wall_time" {
                return Err(MetricsError::BadName { name: name.to_string() });
            }
            if scalars[..i].iter().any(|(n, _)| n == name) {
                return Err(MetricsError::DuplicateName { name: name.to_string(), global_step });
            }
        }
        let mut json = format!("{{\"global_step\":{global_step},\"wall_time\":{}", json_number(wall_time));
        let mut csv = String::new();
        let wall_csv = csv_number(wall_time);
        for (name, value) in scalars {
            // A &str always serialises to a JSON string.
            let key = serde_json::to_string(name).unwrap_or_default();
            json.push_str(&format!(",{key}:{}", json_number(*value)));
            csv.push_str(&format!("{global_step},{wall_csv},{},{}\n", csv_field(name), csv_number(*value)));
        }
        json.push_str("}\n");
        let jsonl_path = self.dir.join(JSONL_FILE);
        let csv_path = self.dir.join(CSV_FILE);
        self.jsonl.write_all(json.as_bytes()).and_then(|_| self.jsonl.flush()).map_err(at(&jsonl_path))?;
        if !csv.is_empty() {
            self.csv.write_all(csv.as_bytes()).and_then(|_| self.csv.flush()).map_err(at(&csv_path))?;
        }
        self.events.log(global_step, scalars)?;
        self.last = Some((global_step, if wall_time.is_finite() { wall_time } else { f64::NAN }));
        Ok(())
    }
}

fn json_number(v: f64) -> String {
    if v.is_finite() {
        // Shortest representation that reads back to the same f64.
        serde_json::to_string(&v).unwrap_or_else(|_| "null".into())
    } else {
        "null".into()
    }
}

fn csv_number(v: f64) -> String {
    if v.is_finite() { format!("{v}") } else { "nan".into() }
}

/// Quotes a CSV field when it contains a separator, a quote or a line break (RFC 4180).
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) { format!("\"{}\"", s.replace('"', "\"\"")) } else { s.to_string() }
}

fn read_optional(path: &Path) -> Result<Option<String>, MetricsError> {
    match std::fs::read_to_string(path) {
        Ok(t) => Ok(Some(t)),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(at(path)(e).into()),
    }
}

/// Newline-terminated lines with their 1-based numbers; a final line without a newline (a record
/// torn by a crash) is left out.
fn complete_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    let complete = match text.rfind('\n') {
        Some(i) => &text[..i + 1],
        None => "",
    };
    complete.lines().enumerate().map(|(i, l)| (i + 1, l.strip_suffix('\r').unwrap_or(l)))
}

struct JsonRecord {
    keys: (u64, f64),
    object: serde_json::Map<String, serde_json::Value>,
}

fn parse_json_record(path: &Path, line_no: usize, line: &str) -> Result<JsonRecord, MetricsError> {
    let bad = |reason: String| MetricsError::Malformed { path: path.to_path_buf(), line: line_no, reason };
    let value: serde_json::Value = serde_json::from_str(line).map_err(|e| bad(format!("invalid JSON: {e}")))?;
    let serde_json::Value::Object(object) = value else {
        return Err(bad("not a JSON object".into()));
    };
    let step = object
        .get("global_step")
        .and_then(serde_json::Value::as_u64)
        .ok_or_else(|| bad("missing or non-integer \"global_step\"".into()))?;
    let wall = match object.get("wall_time") {
        Some(serde_json::Value::Null) => f64::NAN,
        Some(v) => v.as_f64().ok_or_else(|| bad("\"wall_time\" is not a number".into()))?,
        None => return Err(bad("missing \"wall_time\"".into())),
    };
    Ok(JsonRecord { keys: (step, wall), object })
}

impl JsonRecord {
    /// The record's scalars (every key but the two record keys); `null` reads as NaN.
    fn scalars(&self, path: &Path, line_no: usize) -> Result<Vec<(String, f64)>, MetricsError> {
        let mut out = Vec::new();
        for (name, value) in self.object.iter().filter(|(k, _)| *k != "global_step" && *k != "wall_time") {
            out.push((name.clone(), json_value(path, line_no, name, value)?));
        }
        Ok(out)
    }
}

/// A scalar of a JSONL record: a number, or `null` for NaN.
fn json_value(path: &Path, line_no: usize, name: &str, value: &serde_json::Value) -> Result<f64, MetricsError> {
    match value {
        serde_json::Value::Null => Ok(f64::NAN),
        v => v.as_f64().ok_or_else(|| MetricsError::Malformed {
            path: path.to_path_buf(),
            line: line_no,
            reason: format!("{name:?} is not a number"),
        }),
    }
}

/// The `(global_step, value)` pairs of scalar `name` in `dir/metrics.jsonl`, in file order; records
/// without `name` are skipped and a `null` value reads as NaN. A torn final line (no newline, e.g.
/// while the run is writing it) is ignored; any other malformed line is an error naming the file
/// and the 1-based line number.
pub fn read_series(dir: &Path, name: &str) -> Result<Vec<(u64, f64)>, MetricsError> {
    let path = dir.join(JSONL_FILE);
    let text = std::fs::read_to_string(&path).map_err(at(&path))?;
    let mut out = Vec::new();
    for (line_no, line) in complete_lines(&text) {
        if line.trim().is_empty() {
            continue;
        }
        let rec = parse_json_record(&path, line_no, line)?;
        let Some(value) = rec.object.get(name) else { continue };
        let value = json_value(&path, line_no, name, value)?;
        out.push((rec.keys.0, value));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resume_truncates_after_the_checkpoint_and_appends() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut w = MetricsWriter::create(dir).unwrap();
        for step in [100u64, 200, 300, 400] {
            w.log(step, step as f64 / 100.0, &[("losses/qf1_loss", 1.0 / step as f64)]).unwrap();
        }
        w.log(200, 2.5, &[("eval/success_rate", 0.5)]).unwrap();
        drop(w);
        let mut w = MetricsWriter::resume(dir, 250).unwrap();
        assert_eq!(w.last_record(), Some((200, 2.5)));
        w.log(300, 3.7, &[("losses/qf1_loss", 0.25)]).unwrap();
        drop(w);
        let qf1 = read_series(dir, "losses/qf1_loss").unwrap();
        assert_eq!(qf1, vec![(100, 0.01), (200, 0.005), (300, 0.25)]);
        assert_eq!(read_series(dir, "eval/success_rate").unwrap(), vec![(200, 0.5)]);
        let csv = std::fs::read_to_string(dir.join(CSV_FILE)).unwrap();
        let rows: Vec<&str> = csv.lines().collect();
        assert_eq!(
            rows,
            vec![
                CSV_HEADER,
                "100,1,losses/qf1_loss,0.01",
                "200,2,losses/qf1_loss,0.005",
                "200,2.5,eval/success_rate,0.5",
                "300,3.7,losses/qf1_loss,0.25",
            ]
        );
        assert!(!dir.join("metrics.jsonl.tmp").exists());
        // Resuming where nothing was logged starts fresh files.
        let empty_tmp = tempfile::tempdir().unwrap();
        let empty = empty_tmp.path();
        MetricsWriter::resume(empty, 10).unwrap();
        assert_eq!(std::fs::read_to_string(empty.join(CSV_FILE)).unwrap(), format!("{CSV_HEADER}\n"));
    }

    #[test]
    fn csv_has_header_and_one_row_per_scalar() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut w = MetricsWriter::create(dir).unwrap();
        w.log(1000, 12.25, &[("charts/SPS", 80.0), ("losses/alpha", f64::NAN), ("odd,name", 1.5)]).unwrap();
        let csv = std::fs::read_to_string(dir.join(CSV_FILE)).unwrap();
        assert_eq!(
            csv,
            format!(
                "{CSV_HEADER}\n1000,12.25,charts/SPS,80\n1000,12.25,losses/alpha,nan\n1000,12.25,\"odd,name\",1.5\n"
            )
        );
        let jsonl = std::fs::read_to_string(dir.join(JSONL_FILE)).unwrap();
        assert_eq!(
            jsonl,
            "{\"global_step\":1000,\"wall_time\":12.25,\"charts/SPS\":80.0,\"losses/alpha\":null,\"odd,name\":1.5}\n"
        );
        let alpha = read_series(dir, "losses/alpha").unwrap();
        assert_eq!(alpha.len(), 1);
        assert!(alpha[0].1.is_nan());
    }

    #[test]
    fn malformed_jsonl_line_is_reported_with_its_number() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        std::fs::create_dir_all(dir).unwrap();
        std::fs::write(
            dir.join(JSONL_FILE),
            "{\"global_step\":1,\"wall_time\":0.1,\"a\":1}\n\n{\"global_step\":2,\"wall_time\":0.2,\"a\":2\n{\"global_step\":3,\"wall_time\":0.3,\"a\":3}\n",
        )
        .unwrap();
        let err = read_series(dir, "a").unwrap_err();
        match &err {
            MetricsError::Malformed { path, line, .. } => {
                assert_eq!(*line, 3);
                assert!(path.ends_with(JSONL_FILE));
            }
            other => panic!("unexpected {other:?}"),
        }
        assert!(err.to_string().contains("metrics.jsonl:3"), "{err}");
        assert!(matches!(MetricsWriter::resume(dir, 10), Err(MetricsError::Malformed { line: 3, .. })));
    }

    #[test]
    fn torn_last_line_is_ignored() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut w = MetricsWriter::create(dir).unwrap();
        w.log(1, 0.5, &[("a", 1.0)]).unwrap();
        drop(w);
        let mut f = OpenOptions::new().append(true).open(dir.join(JSONL_FILE)).unwrap();
        f.write_all(b"{\"global_step\":2,\"wall").unwrap();
        drop(f);
        assert_eq!(read_series(dir, "a").unwrap(), vec![(1, 1.0)]);
        let mut w = MetricsWriter::resume(dir, 5).unwrap();
        w.log(2, 1.0, &[("a", 2.0)]).unwrap();
        assert_eq!(read_series(dir, "a").unwrap(), vec![(1, 1.0), (2, 2.0)]);
    }

    #[test]
    fn bad_names_are_rejected() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        let mut w = MetricsWriter::create(dir).unwrap();
        assert!(matches!(w.log(1, 0.0, &[("", 1.0)]), Err(MetricsError::BadName { .. })));
        assert!(matches!(w.log(1, 0.0, &[("global_step", 1.0)]), Err(MetricsError::BadName { .. })));
        assert!(matches!(w.log(1, 0.0, &[("a", 1.0), ("a", 2.0)]), Err(MetricsError::DuplicateName { .. })));
        let missing = read_series(&dir.join("nothing_here"), "a").unwrap_err();
        assert!(missing.to_string().contains("nothing_here"), "{missing}");
    }

    /// The run directory's event files (their names).
    fn event_files(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains("tfevents") || n.contains("events."))
            .collect();
        names.sort();
        names
    }

    #[test]
    fn one_event_file_per_run_directory_growing_with_each_record() {
        let dir_tmp = tempfile::tempdir().unwrap();
        let dir = dir_tmp.path();
        std::fs::write(dir.join("events.out.tfevents.1.old"), b"old").unwrap();
        let mut w = MetricsWriter::create(dir).unwrap();
        let files = event_files(dir);
        assert_eq!(files.len(), 1, "{files:?}");
        assert!(files[0].starts_with(EVENTS_PREFIX) && files[0] != "events.out.tfevents.1.old", "{files:?}");
        let size = |w: &MetricsWriter| std::fs::metadata(&w.events.path).unwrap().len();
        let empty = size(&w);
        w.log(1, 0.0, &[("a", 1.0), ("b", 2.0)]).unwrap();
        let one = size(&w);
        assert!(one > empty, "flushed with the record");
        w.log(2, 0.0, &[("a", 3.0)]).unwrap();
        drop(w);
        // Resumed at step 1: the event file is rewritten with the kept record (two scalars) only.
        let w = MetricsWriter::resume(dir, 1).unwrap();
        assert_eq!(event_files(dir).len(), 1, "{:?}", event_files(dir));
        assert_eq!(size(&w), one);
    }
}
