//! Running a grid with the one grid runner ([`equiarm_train::grid`]): each cell is one child process
//! (`equiarm experiment run-one RUN_DIR`), a few at a time, each on its own threads, so that runs are as reproducible as `equiarm train --in-process`
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

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Instant;

use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, first_difference, read_json, write_json};
use equiarm_train::evaluation::{EvalResult, Stream, evaluate_on};
use equiarm_train::grid::{Grid as GridSpec, GridError, Job, JobEnd, Planned, RunState};
use equiarm_train::inprocess::RunOptions;
use equiarm_train::rundir::{RUN_FILES, RunDirLock, find_checkpoint};
use equiarm_types::files::at;
use serde::{Deserialize, Serialize};

use crate::error::{ExperimentError, Result};
use crate::grid::{Cell, Grid};
use crate::report::Archive;

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

/// A finished run's result with the given held-out success rate and discounted return (tests).
#[cfg(test)]
pub(crate) fn test_result(success_rate: f64, discounted_return: f64) -> RunResult {
    RunResult {
        updates: 10,
        env_steps: 50,
        train_seconds: 1.0,
        last_eval: None,
        heldout: EvalResult { episodes: 100, success_rate, discounted_return, ..EvalResult::default() },
        heldout_seconds: 1.0,
    }
}

/// The result file of a run directory.
pub const RESULT_FILE: &str = "result.json";
/// The log of a run's child processes (appended to by each part).
pub const LOG_FILE: &str = "log.txt";

/// Refuses a run directory whose `config.json` is not `cfg` (the grid file changed under its runs).
pub fn check_config(dir: &Path, cfg: &TrainConfig) -> Result<()> {
    let cfg_file = dir.join("config.json");
    if !cfg_file.is_file() {
        return Ok(());
    }
    let bad = |message: String| ExperimentError::Run { dir: dir.to_path_buf(), message };
    let old: TrainConfig = read_json(&cfg_file).map_err(|e| bad(format!("config.json: {e}")))?;
    if &old == cfg {
        return Ok(());
    }
    Err(bad(format!(
        "was started with another config than the grid gives now (first difference: `{}`); restore the grid file, or move the run away to start it afresh",
        first_difference(
            &serde_json::to_value(&old).unwrap_or_default(),
            &serde_json::to_value(cfg).unwrap_or_default(),
            ""
        )
    )))
}

/// The result of the run in `dir`, if it finished.
pub fn read_result(dir: &Path) -> Result<Option<RunResult>> {
    let path = dir.join(RESULT_FILE);
    if !path.is_file() {
        return Ok(None);
    }
    read_json(&path)
        .map(Some)
        .map_err(|e| ExperimentError::Run { dir: dir.to_path_buf(), message: format!("{RESULT_FILE}: {e}") })
}

/// The updates of the latest checkpoint of the run in `dir`, if it wrote one.
fn checkpoint_updates(dir: &Path) -> Result<Option<u64>> {
    if !dir.join("checkpoints").join("latest").is_file() {
        return Ok(None);
    }
    let ck = find_checkpoint(dir)?;
    let updates =
        ck.file_name().and_then(|n| n.to_str()).and_then(|n| n.strip_prefix("step_")).and_then(|n| n.parse().ok());
    updates.map(Some).ok_or_else(|| ExperimentError::Run {
        dir: dir.to_path_buf(),
        message: format!("checkpoint {} is not named step_N", ck.display()),
    })
}

/// A line of a finished run's result.
pub fn result_line(r: &RunResult) -> String {
    format!(
        "{} updates, held-out success {:.2} (discounted return {:.3}) over {} episodes",
        r.updates, r.heldout.success_rate, r.heldout.discounted_return, r.heldout.episodes
    )
}

/// Where the run of `cell` (config `cfg`) in `dir` stands; `archived` is its archived result.
fn state_of(dir: &Path, cfg: &TrainConfig, archived: Option<&RunResult>) -> Result<RunState> {
    check_config(dir, cfg)?;
    if let Some(r) = read_result(dir)? {
        return Ok(RunState::Finished(result_line(&r)));
    }
    if let Some(r) = archived {
        return Ok(RunState::Archived(result_line(r)));
    }
    if RunDirLock::is_held(dir) {
        return Ok(RunState::Unfinished("in training now".into()));
    }
    Ok(match checkpoint_updates(dir)? {
        Some(u) => RunState::Unfinished(format!("interrupted at {u} of {} updates", cfg.total_updates)),
        None => RunState::New,
    })
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
    let cfg = run_config(dir)?;
    check_config(dir, &cfg)?;
    if let Some(r) = read_result(dir)? {
        return Ok(Some(r));
    }
    let resume = checkpoint_updates(dir)?.map(|_| find_checkpoint(dir)).transpose()?;
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
    let heldout = heldout(&cfg, &find_checkpoint(dir)?, heldout_episodes)?;
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
    write_json(&path, &result)?;
    prune_checkpoints(dir)?;
    Ok(Some(result))
}

/// A run directory's `config.json`, checked (a grid's run, or any run of `equiarm train`).
pub fn run_config(dir: &Path) -> Result<TrainConfig> {
    let cfg: TrainConfig = read_json(&dir.join("config.json"))
        .map_err(|e| ExperimentError::Run { dir: dir.to_path_buf(), message: format!("config.json: {e}") })?;
    equiarm_train::config::check(&cfg).map_err(equiarm_train::TrainError::from)?;
    Ok(cfg)
}

/// The greedy policy of `checkpoint` (a run of `cfg`: in-process, a grid's or the trainer node's)
/// on `episodes` held-out episodes: seeds that no evaluation during training used, the same for
/// every run of a task, so that runs made either way compare on the same scenes.
pub fn heldout(cfg: &TrainConfig, checkpoint: &Path, episodes: usize) -> Result<EvalResult> {
    let mut learner = Learner::new(cfg.clone()).map_err(equiarm_train::TrainError::from)?;
    learner.resume(checkpoint).map_err(equiarm_train::TrainError::from)?;
    let env_cfg = equiarm_train::env::env_config(cfg)?;
    let mut envs: Vec<equiarm_sim::Env> = (0..cfg.num_envs.max(1))
        .map(|_| equiarm_sim::Env::new(env_cfg.clone()))
        .collect::<std::result::Result<_, _>>()
        .map_err(equiarm_train::TrainError::from)?;
    Ok(evaluate_on(&mut learner, &mut envs, episodes, Stream::HeldOut)?)
}

/// Removes every checkpoint of a finished run but the latest (the final weights, with the replay):
/// a grid's runs would otherwise keep one replay per `checkpoint_every` updates each.
fn prune_checkpoints(dir: &Path) -> Result<()> {
    let latest = find_checkpoint(dir)?;
    let root = dir.join("checkpoints");
    for e in std::fs::read_dir(&root).map_err(at(&root))? {
        let p = e.map_err(at(&root))?.path();
        let is_step = p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.starts_with("step_"));
        if p.is_dir() && is_step && p != latest {
            std::fs::remove_dir_all(&p).map_err(at(&p))?;
        }
    }
    Ok(())
}

/// A grid and where its runs are, as the one grid runner ([`equiarm_train::grid`]) drives it: each
/// run a child process `equiarm experiment run-one RUN_DIR`.
pub struct ExperimentGrid {
    /// The grid (its `--only` cells).
    pub grid: Grid,
    /// The runs directory.
    pub runs: PathBuf,
    /// Finished runs of earlier reports.
    pub archive: Archive,
    /// Where the archive was read from (as status names it).
    pub archive_dir: PathBuf,
    /// The `equiarm` executable the children run.
    pub exe: PathBuf,
    /// Threads per run (`RAYON_NUM_THREADS` of each child).
    pub threads: usize,
    /// Where the report goes when every run of `full` is finished, and the command quoted in it.
    pub report: Option<(Grid, PathBuf, String)>,
}

impl ExperimentGrid {
    /// Every run of the grid with where it stands.
    pub fn plan(&self) -> Result<Vec<Planned<(Cell, TrainConfig)>>> {
        let mut plan = Vec::new();
        for cell in self.grid.cells() {
            let cfg = self.grid.config(cell)?;
            let mut p = Planned {
                dir: self.runs.join(cell.rel_dir()),
                group: cell.task.to_string(),
                state: RunState::New,
                run: (cell.clone(), cfg),
            };
            p.state = GridSpec::state(self, &p)?;
            plan.push(p);
        }
        Ok(plan)
    }
}

impl GridSpec for ExperimentGrid {
    type Run = (Cell, TrainConfig);
    type Error = ExperimentError;

    fn title(&self) -> String {
        format!("experiment {}", self.grid.name)
    }

    fn archive(&self) -> &Path {
        &self.archive_dir
    }

    fn state(&self, p: &Planned<Self::Run>) -> Result<RunState> {
        let (cell, cfg) = &p.run;
        state_of(&p.dir, cfg, crate::report::archived(&self.archive, cell, cfg).map(|a| &a.result))
    }

    /// A new run's directory is cleared of whatever a start killed before its first checkpoint
    /// left, and gets the cell's `config.json`.
    fn start(&mut self, p: &Planned<Self::Run>, state: &RunState) -> Result<Box<dyn Job>> {
        if *state == RunState::New {
            for f in RUN_FILES.iter().chain(&["learning_curve.png"]) {
                let path = p.dir.join(f);
                if path.is_dir() {
                    std::fs::remove_dir_all(&path).map_err(at(&path))?;
                } else if path.exists() {
                    std::fs::remove_file(&path).map_err(at(&path))?;
                }
            }
            write_json(&p.dir.join("config.json"), &p.run.1)?;
        }
        let child = spawn(&self.exe, self.threads, &self.grid, &p.dir)?;
        Ok(Box::new(ChildJob { child, log: p.dir.join(LOG_FILE) }))
    }

    fn report(&mut self) -> Result<Vec<PathBuf>> {
        match &self.report {
            Some((full, out, command)) if crate::report::all_finished(full, &self.runs, &self.archive)? => {
                crate::report::write(full, &self.runs, &self.archive, out, command)
            }
            _ => Ok(Vec::new()),
        }
    }
}

/// A run's child process.
struct ChildJob {
    child: Child,
    log: PathBuf,
}

impl ChildJob {
    fn end(&self, status: std::process::ExitStatus) -> JobEnd {
        match status.code() {
            Some(0) => JobEnd::Done,
            Some(STOPPED_EXIT) => JobEnd::Stopped,
            _ => JobEnd::Failed(format!("{status}; the end of its {LOG_FILE}:\n{}", log_tail(&self.log, 8))),
        }
    }
}

impl Job for ChildJob {
    fn poll(&mut self) -> std::result::Result<Option<JobEnd>, GridError> {
        let status =
            self.child.try_wait().map_err(|e| GridError::Io { path: self.log.clone(), message: e.to_string() })?;
        Ok(status.map(|s| self.end(s)))
    }

    fn stop(&mut self) {
        signal(&self.child, libc::SIGINT);
    }

    fn wait(&mut self) -> std::result::Result<JobEnd, GridError> {
        let status = self.child.wait().map_err(|e| GridError::Io { path: self.log.clone(), message: e.to_string() })?;
        Ok(self.end(status))
    }
}

/// The exit status of a child stopped before its run finished (a checkpoint was written).
pub use equiarm_train::STOPPED_EXIT;

fn spawn(exe: &Path, threads: usize, grid: &Grid, dir: &Path) -> Result<Child> {
    let log_path = dir.join(LOG_FILE);
    let log = std::fs::OpenOptions::new().create(true).append(true).open(&log_path).map_err(at(&log_path))?;
    let err = log.try_clone().map_err(at(&log_path))?;
    Command::new(exe)
        .args(["experiment", "run-one"])
        .arg(dir)
        .args(["--heldout-episodes", &grid.heldout_episodes.to_string()])
        .args(["--checkpoint-minutes", &grid.checkpoint_minutes.to_string()])
        .env("RAYON_NUM_THREADS", threads.max(1).to_string())
        .stdin(Stdio::null())
        .stdout(log)
        .stderr(err)
        .spawn()
        .map_err(|e| at(exe)(e).into())
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
