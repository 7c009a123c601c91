//! Running a grid: each cell is one child process (`equiarm experiment run-one RUN_DIR`), a few at a
//! time, each on its own threads, so that runs are as reproducible as `equiarm train --in-process`
//! alone and one failing run does not take the others down.
//!
//! A run's directory tells its state: `result.json` — finished (training and the held-out
//! evaluation; only the final checkpoint is kept); `checkpoints/latest` — interrupted, resumed from that checkpoint; neither — started
//! afresh (whatever a run killed before its first checkpoint left is removed). The runner writes
//! the cell's config as `config.json` before the first start and refuses a directory whose
//! `config.json` differs from what the grid now says (the grid file changed under its runs).
//!
//! Grids may share a runs directory (the default, `runs/experiments`): a run's directory is named by
//! its cell alone, so a run two grids have in common (the same config) is made once.
//!
//! Interruptions: Ctrl-C, SIGTERM or SIGKILL of the runner. A child writes a checkpoint and stops
//! when it gets SIGINT/SIGTERM or when its parent is gone; the runner forwards SIGINT to its
//! children when it is stopped. Children checkpoint at least every `checkpoint_minutes` of
//! training. Run the same command again to continue: finished runs are skipped, interrupted ones
//! resume, and a run whose directory is still locked by an exiting child is waited for.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, first_difference, read_json, write_json};
use equiarm_train::evaluation::{EvalResult, Stream, evaluate_on};
use equiarm_train::inprocess::RunOptions;
use equiarm_train::rundir::{RUN_FILES, RunDirLock, find_checkpoint};
use serde::{Deserialize, Serialize};

use crate::error::{ExperimentError, Result, io};
use crate::grid::{Cell, Grid};

/// A finished run's summary, `RUN/result.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunResult {
    /// Updates trained.
    pub updates: u64,
    /// Training env steps.
    pub env_steps: u64,
    /// Seconds of training (all parts of an interrupted run), without the held-out evaluation.
    pub train_seconds: f64,
    /// The last evaluation during training.
    pub last_eval: Option<EvalResult>,
    /// The held-out evaluation of the final weights (episodes no evaluation during training saw).
    pub heldout: EvalResult,
    /// Seconds the held-out evaluation took.
    pub heldout_seconds: f64,
}

/// The result file of a run directory.
pub const RESULT_FILE: &str = "result.json";
/// The log of a run's child processes (appended to by each part).
pub const LOG_FILE: &str = "log.txt";

/// A run's state, from its directory.
#[derive(Clone, Debug, PartialEq)]
pub enum RunState {
    /// Nothing yet (or nothing worth keeping).
    New,
    /// Interrupted at this many updates.
    Partial(u64),
    /// Finished.
    Done(Box<RunResult>),
}

/// The state of the run in `dir`, whose config must be `cfg` if it has one.
pub fn run_state(dir: &Path, cfg: &TrainConfig) -> Result<RunState> {
    let bad = |message: String| ExperimentError::Run { dir: dir.to_path_buf(), message };
    let cfg_file = dir.join("config.json");
    if cfg_file.is_file() {
        let old: TrainConfig = read_json(&cfg_file).map_err(|e| bad(format!("config.json: {e}")))?;
        if &old != cfg {
            return Err(bad(format!(
                "was started with another config than the grid gives now (first difference: `{}`); restore the grid file, or move the run away to start it afresh",
                first_difference(
                    &serde_json::to_value(&old).unwrap_or_default(),
                    &serde_json::to_value(cfg).unwrap_or_default(),
                    ""
                )
            )));
        }
    }
    let result = dir.join(RESULT_FILE);
    if result.is_file() {
        let r: RunResult = read_json(&result).map_err(|e| bad(format!("{RESULT_FILE}: {e}")))?;
        return Ok(RunState::Done(Box::new(r)));
    }
    if dir.join("checkpoints").join("latest").is_file() {
        let ck = find_checkpoint(dir)?;
        let updates = ck
            .file_name()
            .and_then(|n| n.to_str())
            .and_then(|n| n.strip_prefix("step_"))
            .and_then(|n| n.parse().ok())
            .ok_or_else(|| bad(format!("checkpoint {} is not named step_N", ck.display())))?;
        return Ok(RunState::Partial(updates));
    }
    Ok(RunState::New)
}

/// The child's side: train the run in `dir` (its `config.json`) from scratch or from its latest
/// checkpoint, then evaluate the final weights on `heldout_episodes` held-out episodes and write
/// `result.json`. `stop` is polled between steps: when it turns true the run checkpoints and
/// returns `Ok(None)`.
pub fn run_one(
    dir: &Path,
    heldout_episodes: usize,
    checkpoint_secs: f64,
    stop: &dyn Fn() -> bool,
) -> Result<Option<RunResult>> {
    let cfg: TrainConfig = read_json(&dir.join("config.json"))
        .map_err(|e| ExperimentError::Run { dir: dir.to_path_buf(), message: format!("config.json: {e}") })?;
    equiarm_train::config::check(&cfg).map_err(equiarm_train::TrainError::from)?;
    let resume = match run_state(dir, &cfg)? {
        RunState::Done(r) => return Ok(Some(*r)),
        RunState::Partial(_) => Some(find_checkpoint(dir)?),
        RunState::New => None,
    };
    let opts = RunOptions {
        run_dir: dir.to_path_buf(),
        resume,
        checkpoint_secs: Some(checkpoint_secs),
        ..RunOptions::default()
    };
    let summary = equiarm_train::inprocess::run(cfg.clone(), &opts, stop)?;
    if summary.updates < cfg.total_updates {
        return Ok(None);
    }
    let t0 = Instant::now();
    let mut learner = Learner::new(cfg.clone()).map_err(equiarm_train::TrainError::from)?;
    learner.resume(&find_checkpoint(dir)?).map_err(equiarm_train::TrainError::from)?;
    let env_cfg = equiarm_train::env::env_config(&cfg)?;
    let mut envs: Vec<equiarm_sim::Env> = (0..cfg.num_envs.max(1))
        .map(|_| equiarm_sim::Env::new(env_cfg.clone()))
        .collect::<Result<_, _>>()
        .map_err(equiarm_train::TrainError::from)?;
    let heldout = evaluate_on(&mut learner, &mut envs, heldout_episodes, Stream::HeldOut)?;
    let state = equiarm_train::inprocess::LoopState::read(&find_checkpoint(dir)?)
        .map_err(|e| ExperimentError::Run { dir: dir.to_path_buf(), message: e.to_string() })?;
    let result = RunResult {
        updates: summary.updates,
        env_steps: summary.global_step,
        train_seconds: state.wall_time,
        last_eval: summary.evals.last().cloned(),
        heldout,
        heldout_seconds: t0.elapsed().as_secs_f64(),
    };
    let path = dir.join(RESULT_FILE);
    write_json(&path, &result).map_err(|e| ExperimentError::Io { path: path.clone(), message: e.to_string() })?;
    prune_checkpoints(dir)?;
    Ok(Some(result))
}

/// Removes every checkpoint of a finished run but the latest (the final weights, with the replay):
/// a grid's runs would otherwise keep one replay per `checkpoint_every` updates each.
fn prune_checkpoints(dir: &Path) -> Result<()> {
    let latest = find_checkpoint(dir)?;
    let root = dir.join("checkpoints");
    for e in std::fs::read_dir(&root).map_err(io(&root))? {
        let p = e.map_err(io(&root))?.path();
        let is_step = p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("step_"));
        if p.is_dir() && is_step && p != latest {
            std::fs::remove_dir_all(&p).map_err(io(&p))?;
        }
    }
    Ok(())
}

/// How the runner runs.
#[derive(Clone, Debug)]
pub struct RunnerOptions {
    /// The `equiarm` executable the children run.
    pub exe: PathBuf,
    /// Runs at a time.
    pub parallel: usize,
    /// Threads per run (`RAYON_NUM_THREADS` of each child).
    pub threads: usize,
    /// Print a line per start and end on stderr.
    pub verbose: bool,
}

/// What a runner invocation did.
#[derive(Clone, Debug, Default)]
pub struct RunnerSummary {
    /// Runs finished before this invocation.
    pub already_done: usize,
    /// Runs finished by this invocation.
    pub finished: usize,
    /// Runs whose child failed: directory and the last lines of its log.
    pub failed: Vec<(PathBuf, String)>,
    /// Runs left unfinished because the runner was stopped.
    pub stopped: usize,
}

struct Running {
    dir: PathBuf,
    child: Child,
    started: Instant,
}

/// Run every unfinished cell of `grid` below `runs` (a run `archive` has with the same config counts
/// as finished), `opts.parallel` at a time, until all are
/// finished or `stop` turns true (then the children are sent SIGINT, which makes them checkpoint,
/// and are waited for).
pub fn run(
    grid: &Grid,
    runs: &Path,
    archive: &crate::report::Archive,
    opts: &RunnerOptions,
    stop: &dyn Fn() -> bool,
) -> Result<RunnerSummary> {
    // One runner per grid; grids may share a runs directory (and the runs they have in common:
    // a run's directory is named by its cell, and its config must agree).
    let claim_dir = runs.join(".grids").join(&grid.name);
    let _claim = RunDirLock::acquire(&claim_dir).map_err(|e| ExperimentError::Run {
        dir: runs.to_path_buf(),
        message: format!("another runner works on grid {} here ({e})", grid.name),
    })?;
    let mut summary = RunnerSummary::default();
    let mut queue: VecDeque<(Cell, TrainConfig)> = VecDeque::new();
    for cell in grid.cells() {
        let cfg = grid.config(cell)?;
        match run_state(&runs.join(cell.rel_dir()), &cfg)? {
            RunState::Done(_) => summary.already_done += 1,
            _ if crate::report::archived(archive, cell, &cfg).is_some() => summary.already_done += 1,
            _ => queue.push_back((cell.clone(), cfg)),
        }
    }
    let total = grid.cells().len();
    if opts.verbose {
        eprintln!(
            "experiment {}: {total} runs, {} finished before, {} to run, {} at a time",
            grid.name,
            summary.already_done,
            queue.len(),
            opts.parallel
        );
    }
    let mut running: Vec<Running> = Vec::new();
    let mut waiting_since: Option<Instant> = None;
    loop {
        if stop() {
            break;
        }
        // Start runs while there is room; a run still locked (a child of an earlier runner
        // writing its last checkpoint) goes to the back of the queue.
        let mut tried = 0;
        while running.len() < opts.parallel.max(1) && tried < queue.len() {
            let Some((cell, cfg)) = queue.pop_front() else { break };
            let dir = runs.join(cell.rel_dir());
            match RunDirLock::acquire(&dir) {
                Ok(lock) => drop(lock),
                Err(_) => {
                    queue.push_back((cell, cfg));
                    tried += 1;
                    continue;
                }
            }
            let state = run_state(&dir, &cfg)?;
            if let RunState::Done(_) = state {
                summary.finished += 1;
                continue;
            }
            if state == RunState::New {
                for f in RUN_FILES.iter().chain(&["learning_curve.png"]) {
                    let p = dir.join(f);
                    if p.is_dir() {
                        std::fs::remove_dir_all(&p).map_err(io(&p))?;
                    } else if p.exists() {
                        std::fs::remove_file(&p).map_err(io(&p))?;
                    }
                }
                write_json(&dir.join("config.json"), &cfg)
                    .map_err(|e| ExperimentError::Io { path: dir.join("config.json"), message: e.to_string() })?;
            }
            let child = spawn(opts, grid, &dir)?;
            if opts.verbose {
                let from = match state {
                    RunState::Partial(u) => format!("resumed at {u} updates"),
                    _ => "started".into(),
                };
                eprintln!("{} {from} ({} of {total} left)", dir.display(), queue.len() + running.len() + 1);
            }
            running.push(Running { dir, child, started: Instant::now() });
        }
        if running.is_empty() && queue.is_empty() {
            break;
        }
        if running.is_empty() {
            // Everything left is locked by exiting children of an earlier runner: wait a while.
            let since = *waiting_since.get_or_insert_with(Instant::now);
            if since.elapsed() > Duration::from_secs(600) {
                let dirs: Vec<String> =
                    queue.iter().map(|(c, _)| runs.join(c.rel_dir()).display().to_string()).collect();
                return Err(ExperimentError::Run {
                    dir: runs.to_path_buf(),
                    message: format!("runs still locked by another process after 10 minutes: {}", dirs.join(", ")),
                });
            }
        } else {
            waiting_since = None;
        }
        std::thread::sleep(Duration::from_millis(200));
        let mut i = 0;
        while i < running.len() {
            match running[i].child.try_wait().map_err(io(&running[i].dir))? {
                None => i += 1,
                Some(status) => {
                    let r = running.swap_remove(i);
                    finished(&r, status, &mut summary, opts.verbose);
                }
            }
        }
    }
    // Stopped (or done): forward SIGINT and wait for the children's checkpoints.
    for r in &running {
        signal(&r.child, libc::SIGINT);
    }
    for mut r in running {
        let status = r.child.wait().map_err(io(&r.dir))?;
        let done = r.dir.join(RESULT_FILE).is_file();
        if done {
            finished(&r, status, &mut summary, opts.verbose);
        } else {
            summary.stopped += 1;
        }
    }
    summary.stopped += queue.len();
    Ok(summary)
}

fn finished(r: &Running, status: std::process::ExitStatus, summary: &mut RunnerSummary, verbose: bool) {
    let result: Option<RunResult> = if status.success() { read_json(&r.dir.join(RESULT_FILE)).ok() } else { None };
    match result {
        Some(res) => {
            summary.finished += 1;
            if verbose {
                eprintln!(
                    "{} finished: {} updates, held-out success {:.2} (discounted return {:.3}) over {} episodes, {:.0} s",
                    r.dir.display(),
                    res.updates,
                    res.heldout.success_rate,
                    res.heldout.discounted_return,
                    res.heldout.episodes,
                    r.started.elapsed().as_secs_f64()
                );
            }
        }
        None if status.code() == Some(STOPPED_EXIT) => summary.stopped += 1,
        None => {
            let tail = log_tail(&r.dir.join(LOG_FILE), 8);
            if verbose {
                eprintln!("{} failed ({status}):\n{tail}", r.dir.display());
            }
            summary.failed.push((r.dir.clone(), tail));
        }
    }
}

/// The exit status of a child stopped before its run finished (a checkpoint was written).
pub use equiarm_train::STOPPED_EXIT;

fn spawn(opts: &RunnerOptions, grid: &Grid, dir: &Path) -> Result<Child> {
    let log_path = dir.join(LOG_FILE);
    let log = std::fs::OpenOptions::new().create(true).append(true).open(&log_path).map_err(io(&log_path))?;
    let err = log.try_clone().map_err(io(&log_path))?;
    Command::new(&opts.exe)
        .args(["experiment", "run-one"])
        .arg(dir)
        .args(["--heldout-episodes", &grid.heldout_episodes.to_string()])
        .args(["--checkpoint-minutes", &grid.checkpoint_minutes.to_string()])
        .env("RAYON_NUM_THREADS", opts.threads.max(1).to_string())
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| ExperimentError::Io { path: opts.exe.clone(), message: format!("starting a run: {e}") })
}

fn signal(child: &Child, sig: libc::c_int) {
    if let Ok(pid) = libc::pid_t::try_from(child.id()) {
        // SAFETY: kill(2) with the pid of a child we have not yet waited for (so the pid is not
        // reused) and a valid signal number; it touches no memory of ours.
        unsafe {
            libc::kill(pid, sig);
        }
    }
}

/// The last `n` lines of a text file ("" if it does not read).
pub fn log_tail(path: &Path, n: usize) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}
