//! Running a target: the parent process starts a worker process (this same program with
//! `--worker`), which runs inputs `from..to` and, before each, stores the input's index in a file
//! both processes map. A panic is caught in the worker (`catch_unwind`), reported on its standard
//! output and the worker goes on. When the worker dies (an abort: allocation failure, stack
//! overflow, a signal) or stops moving (the same index for longer than the time limit: a hang,
//! and the parent kills it), the parent reads the index of the input it was running, rebuilds that
//! input from the seed, saves it and starts a new worker after it.

use std::collections::VecDeque;
use std::io::{BufRead, BufReader, Write as _};
use std::panic::AssertUnwindSafe;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

use crate::mutate::Mutator;
use crate::targets::{SetupError, Target};

/// How a run goes.
#[derive(Clone, Debug)]
pub struct Options {
    /// Inputs to run per target.
    pub execs: u64,
    /// Seed of the mutations: the same seed gives the same inputs.
    pub seed: u64,
    /// Longest one input may run before it counts as a hang.
    pub time_limit: Duration,
    /// Address-space limit of a worker, MiB: an allocation beyond it aborts the worker (and the
    /// input is reported) instead of taking the machine's memory.
    pub memory_mb: u64,
    /// Where failing inputs are written.
    pub crash_dir: PathBuf,
}

/// How an input failed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FailureKind {
    /// The code under test panicked (the message, with its location).
    Panic(String),
    /// The worker process died (its exit status and the last line it wrote to stderr).
    Abort(String),
    /// The input ran longer than the time limit.
    Hang,
}

impl std::fmt::Display for FailureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FailureKind::Panic(m) => write!(f, "panic: {m}"),
            FailureKind::Abort(m) => write!(f, "abort: {m}"),
            FailureKind::Hang => write!(f, "hang: over the time limit"),
        }
    }
}

/// One failing input.
#[derive(Clone, Debug)]
pub struct Failure {
    /// Its index in the run.
    pub index: u64,
    /// What happened.
    pub kind: FailureKind,
    /// Where the input was saved.
    pub path: PathBuf,
}

/// What a target's run did.
#[derive(Clone, Debug)]
pub struct Outcome {
    /// The target.
    pub target: &'static str,
    /// Inputs run.
    pub execs: u64,
    /// Inputs the code under test accepted (returned `Ok` for).
    pub accepted: u64,
    /// Wall time of the run, seconds (set-up of the workers included).
    pub secs: f64,
    /// Failing inputs.
    pub failures: Vec<Failure>,
}

/// A run could not be carried out (as opposed to an input that failed).
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The target's seeds or harness could not be made.
    #[error("target {target}: {cause}")]
    Setup {
        /// The target.
        target: &'static str,
        /// The cause.
        cause: SetupError,
    },
    /// A file of the run could not be made or written.
    #[error("{}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        cause: std::io::Error,
    },
    /// A worker misbehaved outside any input (died while setting up, or its seeds differ from
    /// the parent's, which would make saved inputs wrong).
    #[error("target {target}: worker {what}")]
    Worker {
        /// The target.
        target: &'static str,
        /// What went wrong.
        what: String,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RunError + '_ {
    move |cause| RunError::Io { path: path.to_path_buf(), cause }
}

/// FNV-1a over the seeds: the worker's must equal the parent's.
fn seeds_hash(seeds: &[Vec<u8>]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for s in seeds {
        for &b in (s.len() as u64).to_le_bytes().iter().chain(s) {
            h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

fn mutator(target: &Target, scratch: &Path) -> Result<Mutator, RunError> {
    let seeds = target.seeds(scratch).map_err(|cause| RunError::Setup { target: target.name, cause })?;
    Ok(Mutator::new(seeds, target.dictionary, target.shape, target.max_len))
}

/// Slots of the file shared with a worker.
const SLOT_RUNNING: usize = 0; // index + 1 of the input being run; 0 while setting up
const SLOT_ACCEPTED: usize = 1; // inputs accepted so far by this worker
const SLOTS: usize = 2;

/// A file of [`SLOTS`] u64 mapped shared by the parent and a worker.
struct Progress {
    map: memmap2::MmapMut,
}

impl Progress {
    fn open(path: &Path, create: bool) -> Result<Progress, RunError> {
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(create)
            .truncate(create)
            .open(path)
            .map_err(io_err(path))?;
        if create {
            f.set_len((SLOTS * 8) as u64).map_err(io_err(path))?;
        }
        // SAFETY: the file is private to this run (a temporary file named only to our worker);
        // both processes access it through the atomics below only.
        let map = unsafe { memmap2::MmapMut::map_mut(&f) }.map_err(io_err(path))?;
        if map.len() < SLOTS * 8 {
            return Err(RunError::Io { path: path.into(), cause: std::io::ErrorKind::UnexpectedEof.into() });
        }
        Ok(Progress { map })
    }

    fn slot(&self, i: usize) -> &AtomicU64 {
        assert!(i < SLOTS);
        // SAFETY: the map is page-aligned, at least SLOTS * 8 bytes long (checked in `open`) and
        // lives as long as `self`; u64 slots at multiples of 8 are aligned for AtomicU64.
        unsafe { &*(self.map.as_ptr().add(i * 8) as *const AtomicU64) }
    }

    fn get(&self, i: usize) -> u64 {
        self.slot(i).load(Ordering::Acquire)
    }

    fn set(&self, i: usize, v: u64) {
        self.slot(i).store(v, Ordering::Release)
    }
}

/// What a worker writes on its standard output, one line each.
enum Report {
    Ready(u64),
    Panic(u64, String),
    Done,
}

fn parse_report(line: &str) -> Option<Report> {
    let mut parts = line.splitn(3, ' ');
    match (parts.next()?, parts.next(), parts.next()) {
        ("READY", Some(h), None) => h.parse().ok().map(Report::Ready),
        ("PANIC", Some(i), Some(m)) => i.parse().ok().map(|i| Report::Panic(i, m.to_string())),
        ("DONE", None, None) => Some(Report::Done),
        _ => None,
    }
}

/// Runs `target` in workers as `opts` says, printing each failing input as it is found.
pub fn run_target(target: &Target, opts: &Options, exe: &Path) -> Result<Outcome, RunError> {
    let start = Instant::now();
    let scratch = tempfile::tempdir().map_err(io_err(Path::new("a temporary directory")))?;
    let mutator = mutator(target, scratch.path())?;
    let hash = seeds_hash(mutator.seeds());
    let progress_path = scratch.path().join("progress");
    let progress = Progress::open(&progress_path, true)?;
    let mut failures = Vec::new();
    let mut accepted = 0;
    let mut next = 0;
    let mut fail = |index: u64, kind: FailureKind| -> Result<(), RunError> {
        std::fs::create_dir_all(&opts.crash_dir).map_err(io_err(&opts.crash_dir))?;
        let path = opts.crash_dir.join(format!("{}-{index}.bin", target.name));
        std::fs::write(&path, mutator.input(opts.seed, target.name, index)).map_err(io_err(&path))?;
        println!("CRASH {} input {index}: {kind} -> {}", target.name, path.display());
        failures.push(Failure { index, kind, path });
        Ok(())
    };
    while next < opts.execs {
        progress.set(SLOT_RUNNING, 0);
        progress.set(SLOT_ACCEPTED, 0);
        let mut child = Command::new(exe)
            .args(["--worker", target.name])
            .args(["--seed", &opts.seed.to_string(), "--from", &next.to_string()])
            .args(["--execs", &opts.execs.to_string(), "--memory-mb", &opts.memory_mb.to_string()])
            .arg("--progress")
            .arg(&progress_path)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            // the abort's own message is what we report, not a backtrace
            .env("RUST_BACKTRACE", "0")
            .spawn()
            .map_err(io_err(exe))?;
        let lines = read_lines(&mut child);
        let stderr_tail = keep_tail(&mut child);
        let spawned = Instant::now();
        let mut seen = (0u64, Instant::now());
        let mut hang = None;
        let mut done = false;
        let mut handle = |r: Report, fail: &mut dyn FnMut(u64, FailureKind) -> Result<(), RunError>| match r {
            Report::Ready(h) if h != hash => Err(RunError::Worker {
                target: target.name,
                what: "built other seeds than the parent (seeds must be deterministic)".into(),
            }),
            Report::Ready(_) => Ok(()),
            Report::Panic(i, m) => fail(i, FailureKind::Panic(m)),
            Report::Done => {
                done = true;
                Ok(())
            }
        };
        let status = loop {
            while let Ok(r) = lines.try_recv() {
                handle(r, &mut fail)?;
            }
            if let Some(status) = child.try_wait().map_err(io_err(exe))? {
                break status;
            }
            let running = progress.get(SLOT_RUNNING);
            if running != seen.0 {
                seen = (running, Instant::now());
            } else if running > 0 && seen.1.elapsed() > opts.time_limit {
                hang = Some(running - 1);
                let _ = child.kill();
                break child.wait().map_err(io_err(exe))?;
            } else if running == 0 && spawned.elapsed() > SETUP_LIMIT {
                let _ = child.kill();
                let _ = child.wait();
                return Err(RunError::Worker {
                    target: target.name,
                    what: format!("did not set up within {SETUP_LIMIT:?}"),
                });
            }
            std::thread::sleep(Duration::from_millis(5));
        };
        // the reader thread ends with the worker's stdout: every line it wrote is in the channel
        for r in lines.iter() {
            handle(r, &mut fail)?;
        }
        accepted += progress.get(SLOT_ACCEPTED);
        let running = progress.get(SLOT_RUNNING);
        if let Some(i) = hang {
            fail(i, FailureKind::Hang)?;
            next = i + 1;
        } else if done && status.success() {
            next = opts.execs;
        } else if running == 0 {
            let tail =
                stderr_tail.lock().map(|t| t.iter().cloned().collect::<Vec<_>>().join(" | ")).unwrap_or_default();
            return Err(RunError::Worker {
                target: target.name,
                what: format!("died while setting up ({status}): {tail}"),
            });
        } else {
            // give the stderr reader a moment to take the last lines
            std::thread::sleep(Duration::from_millis(20));
            let last = stderr_tail
                .lock()
                .ok()
                .and_then(|t| {
                    t.iter().rev().find(|l| !l.starts_with(char::is_whitespace) && !l.starts_with("note:")).cloned()
                })
                .unwrap_or_default();
            fail(running - 1, FailureKind::Abort(format!("{status}; stderr: {last}")))?;
            next = running;
        }
    }
    Ok(Outcome { target: target.name, execs: opts.execs, accepted, secs: start.elapsed().as_secs_f64(), failures })
}

/// Longest a worker may take to build its seeds and harness.
const SETUP_LIMIT: Duration = Duration::from_secs(300);

fn read_lines(child: &mut Child) -> mpsc::Receiver<Report> {
    let (tx, rx) = mpsc::channel();
    if let Some(out) = child.stdout.take() {
        std::thread::spawn(move || {
            for line in BufReader::new(out).lines().map_while(Result::ok) {
                if let Some(r) = parse_report(&line)
                    && tx.send(r).is_err()
                {
                    break;
                }
            }
        });
    }
    rx
}

fn keep_tail(child: &mut Child) -> Arc<Mutex<VecDeque<String>>> {
    let tail = Arc::new(Mutex::new(VecDeque::new()));
    if let Some(err) = child.stderr.take() {
        let t = tail.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                if let Ok(mut t) = t.lock() {
                    if t.len() == 16 {
                        t.pop_front();
                    }
                    t.push_back(line);
                }
            }
        });
    }
    tail
}

/// The message of the last panic, set by the worker's panic hook.
static LAST_PANIC: Mutex<String> = Mutex::new(String::new());

fn quiet_panics() {
    std::panic::set_hook(Box::new(|info| {
        let message = info.to_string().replace('\n', " ");
        if let Ok(mut last) = LAST_PANIC.lock() {
            *last = message;
        }
    }));
}

/// Limits the address space of this process to `mb` MiB.
fn limit_memory(mb: u64) -> std::io::Result<()> {
    let bytes = mb.saturating_mul(1 << 20) as libc::rlim_t;
    let limit = libc::rlimit { rlim_cur: bytes, rlim_max: bytes };
    // SAFETY: setrlimit reads the struct we pass and has no other effect on memory.
    if unsafe { libc::setrlimit(libc::RLIMIT_AS, &limit) } != 0 {
        return Err(std::io::Error::last_os_error());
    }
    Ok(())
}

/// The worker: runs inputs `from..execs` of `target`, storing each index in the progress file
/// before it runs, reporting panics on standard output.
pub fn worker(
    target: &Target,
    seed: u64,
    from: u64,
    execs: u64,
    memory_mb: u64,
    progress: &Path,
) -> Result<(), RunError> {
    let progress = Progress::open(progress, false)?;
    limit_memory(memory_mb).map_err(io_err(Path::new("setrlimit")))?;
    let scratch = tempfile::tempdir().map_err(io_err(Path::new("a temporary directory")))?;
    let mutator = mutator(target, scratch.path())?;
    let mut harness = target.harness(scratch.path()).map_err(|cause| RunError::Setup { target: target.name, cause })?;
    let stdout = std::io::stdout();
    let say = |line: String| {
        let mut out = stdout.lock();
        let _ = writeln!(out, "{line}");
        let _ = out.flush();
    };
    say(format!("READY {}", seeds_hash(mutator.seeds())));
    quiet_panics();
    let mut accepted = 0;
    for i in from..execs {
        let input = mutator.input(seed, target.name, i);
        progress.set(SLOT_RUNNING, i + 1);
        match std::panic::catch_unwind(AssertUnwindSafe(|| harness.run(&input))) {
            Ok(true) => {
                accepted += 1;
                progress.set(SLOT_ACCEPTED, accepted);
            }
            Ok(false) => {}
            Err(_) => {
                let message = LAST_PANIC.lock().map(|m| m.clone()).unwrap_or_default();
                say(format!("PANIC {i} {message}"));
            }
        }
    }
    say("DONE".into());
    Ok(())
}

/// Runs one saved input in this process (for reproducing a crash under a debugger): whether the
/// code under test accepted it. A panic propagates.
pub fn run_file(target: &Target, input: &Path) -> Result<bool, RunError> {
    let bytes = std::fs::read(input).map_err(io_err(input))?;
    let scratch = tempfile::tempdir().map_err(io_err(Path::new("a temporary directory")))?;
    let mut harness = target.harness(scratch.path()).map_err(|cause| RunError::Setup { target: target.name, cause })?;
    Ok(harness.run(&bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reports_parse_and_keep_spaces_in_messages() {
        assert!(matches!(parse_report("READY 42"), Some(Report::Ready(42))));
        assert!(
            matches!(parse_report("PANIC 7 panicked at a.rs:1:2: x y"), Some(Report::Panic(7, m)) if m == "panicked at a.rs:1:2: x y")
        );
        assert!(matches!(parse_report("DONE"), Some(Report::Done)));
        assert!(parse_report("noise from a library").is_none());
    }

    #[test]
    fn the_seeds_hash_sees_boundaries() {
        assert_ne!(seeds_hash(&[b"ab".to_vec(), b"c".to_vec()]), seeds_hash(&[b"a".to_vec(), b"bc".to_vec()]));
    }
}
