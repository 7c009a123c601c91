//! One grid runner for every grid of runs: the paper's RL comparisons (`equiarm experiment run`,
//! each run a child process) and the rotation experiment (`equiarm rotest grid`, each run a thread
//! of the runner's process). A grid says which runs it has and where each stands ([`Grid`]); the
//! runner starts the unfinished ones a few at a time, forwards a stop to them, counts how they
//! ended, asks the grid for its report, and decides the exit code; [`status`] prints where every
//! run stands, the same way for both.
//!
//! A run is a directory. Its lock ([`RunDirLock`]) says a process trains in it now: the runner
//! starts only runs whose lock is free, tries the others first, and waits at most
//! [`RunnerOptions::wait_for_locked`] for the rest (children of a runner that was killed, writing
//! their last checkpoint) before leaving them to the process that holds them.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::STOPPED_EXIT;
use crate::rundir::RunDirLock;

/// Where one run of a grid stands.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RunState {
    /// Not started (nothing of it kept).
    New,
    /// Started and not finished: cut short, or in training now. What it says of itself (e.g.
    /// "interrupted at 1000 of 5000 updates", "in training now").
    Unfinished(String),
    /// Finished in the runs directory: a line of its result.
    Finished(String),
    /// Not in the runs directory, but the report's archive holds it with the same configuration
    /// (finished on another machine): a line of its result.
    Archived(String),
}

impl RunState {
    /// Whether the grid still has to train it.
    pub fn to_train(&self) -> bool {
        matches!(self, RunState::Unfinished(_) | RunState::New)
    }
}

/// One run of a grid, as planned.
#[derive(Clone, Debug)]
pub struct Planned<R> {
    /// The run's directory.
    pub dir: PathBuf,
    /// The group it is counted in by [`status`] (a task, a setting).
    pub group: String,
    /// Where it stood when planned.
    pub state: RunState,
    /// What the grid needs to start it.
    pub run: R,
}

/// How a started run ended, as its process or thread says.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum JobEnd {
    /// It ran to its end (the grid's [`Grid::state`] then says whether it left a result).
    Done,
    /// Asked to stop, it stopped with a checkpoint.
    Stopped,
    /// It failed: why (the error, or the last lines of its log).
    Failed(String),
}

/// A started run.
pub trait Job {
    /// How it ended, if it has (without waiting).
    fn poll(&mut self) -> Result<Option<JobEnd>, GridError>;
    /// Asks it to stop with a checkpoint (it may take a while).
    fn stop(&mut self);
    /// Waits for its end.
    fn wait(&mut self) -> Result<JobEnd, GridError>;
}

/// A run trained on a thread of this process. The work gets a stop flag it polls (it then
/// checkpoints and returns [`JobEnd::Stopped`]).
pub struct ThreadJob {
    stop: Arc<AtomicBool>,
    handle: Option<std::thread::JoinHandle<JobEnd>>,
}

impl ThreadJob {
    /// Starts `work` on a new thread.
    pub fn spawn(work: impl FnOnce(&dyn Fn() -> bool) -> JobEnd + Send + 'static) -> Self {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        let handle = std::thread::spawn(move || work(&|| flag.load(Ordering::Relaxed)));
        ThreadJob { stop, handle: Some(handle) }
    }

    fn join(&mut self) -> JobEnd {
        match self.handle.take().map(|h| h.join()) {
            Some(Ok(end)) => end,
            Some(Err(_)) => JobEnd::Failed("its thread panicked".into()),
            None => JobEnd::Failed("waited for twice".into()),
        }
    }
}

impl Job for ThreadJob {
    fn poll(&mut self) -> Result<Option<JobEnd>, GridError> {
        Ok(match &self.handle {
            Some(h) if !h.is_finished() => None,
            _ => Some(self.join()),
        })
    }

    fn stop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }

    fn wait(&mut self) -> Result<JobEnd, GridError> {
        Ok(self.join())
    }
}

/// The runner's own errors (a grid's errors convert from it).
#[derive(Debug, thiserror::Error)]
pub enum GridError {
    /// A run's directory could not be locked, or its process not watched.
    #[error("{path}: {message}")]
    Io {
        /// The run directory.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// What a grid tells the runner.
pub trait Grid {
    /// What it needs to start a run.
    type Run;
    /// Its errors.
    type Error: From<GridError>;
    /// How the runner's lines name it ("experiment tasks", "rotest grid").
    fn title(&self) -> String;
    /// Where its report's archive is, as [`status`] names it.
    fn archive(&self) -> &Path;
    /// Where `run` stands now (read again after it ends, or before it starts: another runner on the
    /// same runs directory may have finished it).
    fn state(&self, run: &Planned<Self::Run>) -> Result<RunState, Self::Error>;
    /// Starts `run`, which stands at `state` (read just now; its directory's lock is free and the
    /// job takes it).
    fn start(&mut self, run: &Planned<Self::Run>, state: &RunState) -> Result<Box<dyn Job>, Self::Error>;
    /// Writes the report, when the runner ends without a stop or a failure; the files written.
    fn report(&mut self) -> Result<Vec<PathBuf>, Self::Error>;
}

/// How the runner runs.
#[derive(Clone, Debug)]
pub struct RunnerOptions {
    /// Runs at a time.
    pub parallel: usize,
    /// How long to wait for runs another process holds once nothing else is left: the children of
    /// a runner that was killed outlive it until their checkpoint; a run trained on a thread ends
    /// with its process (zero).
    pub wait_for_locked: Duration,
}

/// What a runner invocation did.
#[derive(Clone, Debug, Default)]
pub struct Summary {
    /// Runs finished (or archived) before it.
    pub before: usize,
    /// Runs it finished.
    pub finished: usize,
    /// Runs that failed: directory and why.
    pub failed: Vec<(PathBuf, String)>,
    /// Runs left unfinished because it was stopped.
    pub stopped: usize,
    /// Runs left to another process that held them.
    pub held: Vec<PathBuf>,
    /// The report's files, if it wrote one.
    pub report: Vec<PathBuf>,
}

impl Summary {
    /// The exit code: 1 when a run failed, [`STOPPED_EXIT`] when stopped, else 0.
    pub fn exit_code(&self) -> i32 {
        if !self.failed.is_empty() {
            1
        } else if self.stopped > 0 {
            STOPPED_EXIT
        } else {
            0
        }
    }

    /// What it says at the end, a line each: the counts, each failed run, each run left to another
    /// process, each file of the report.
    pub fn lines(&self, title: &str) -> Vec<String> {
        let mut lines = vec![format!(
            "{title}: {} finished before, {} finished now, {} failed, {} left unfinished",
            self.before,
            self.finished,
            self.failed.len(),
            self.stopped + self.held.len()
        )];
        lines.extend(self.failed.iter().map(|(dir, why)| format!("failed: {} ({why})", dir.display())));
        lines.extend(self.held.iter().map(|dir| format!("left to the process training it: {}", dir.display())));
        lines.extend(self.report.iter().map(|f| f.display().to_string()));
        lines
    }
}

struct Running<R> {
    run: Planned<R>,
    job: Box<dyn Job>,
    started: Instant,
}

/// Runs every run of `plan` still to train, `opts.parallel` at a time, until all have ended or
/// `stop` turns true (then the running ones are asked to stop and are waited for); then, unless it
/// was stopped or a run failed, the grid's report. Progress goes to stderr, a line a start and an
/// end.
pub fn run<G: Grid>(
    grid: &mut G,
    plan: Vec<Planned<G::Run>>,
    opts: &RunnerOptions,
    stop: &dyn Fn() -> bool,
) -> Result<Summary, G::Error> {
    let total = plan.len();
    let (left, done): (Vec<_>, Vec<_>) = plan.into_iter().partition(|p| p.state.to_train());
    let mut summary = Summary { before: done.len(), ..Summary::default() };
    let mut queue: VecDeque<Planned<G::Run>> = left.into();
    let title = grid.title();
    let parallel = opts.parallel.max(1);
    eprintln!(
        "{title}: {total} runs, {} finished before, {} to run, {parallel} at a time",
        summary.before,
        queue.len()
    );
    let mut running: Vec<Running<G::Run>> = Vec::new();
    let mut locked_since: Option<Instant> = None;
    while !stop() {
        start_while_room(grid, &mut queue, &mut running, &mut summary, parallel, total)?;
        if running.is_empty() && queue.is_empty() {
            break;
        }
        if running.is_empty() {
            // everything left is held by other processes
            if locked_since.get_or_insert_with(Instant::now).elapsed() >= opts.wait_for_locked {
                summary.held.extend(queue.drain(..).map(|p| p.dir));
                break;
            }
        } else {
            locked_since = None;
        }
        std::thread::sleep(Duration::from_millis(50));
        let mut i = 0;
        while i < running.len() {
            match running[i].job.poll()? {
                None => i += 1,
                Some(end) => {
                    let r = running.swap_remove(i);
                    ended(grid, r, end, &mut summary)?;
                }
            }
        }
    }
    for r in &mut running {
        r.job.stop();
    }
    for mut r in running {
        let end = r.job.wait()?;
        ended(grid, r, end, &mut summary)?;
    }
    summary.stopped += queue.len();
    if summary.stopped == 0 && summary.failed.is_empty() {
        summary.report = grid.report()?;
    }
    Ok(summary)
}

/// Starts queued runs while fewer than `parallel` run; a run another process holds goes to the
/// back of the queue, one another runner finished meanwhile counts as finished.
fn start_while_room<G: Grid>(
    grid: &mut G,
    queue: &mut VecDeque<Planned<G::Run>>,
    running: &mut Vec<Running<G::Run>>,
    summary: &mut Summary,
    parallel: usize,
    total: usize,
) -> Result<(), G::Error> {
    let mut tried = 0;
    while running.len() < parallel && tried < queue.len() {
        let Some(run) = queue.pop_front() else { break };
        let lock = RunDirLock::try_acquire(&run.dir)
            .map_err(|e| GridError::Io { path: run.dir.clone(), message: e.to_string() })?;
        if lock.is_none() {
            queue.push_back(run);
            tried += 1;
            continue;
        }
        drop(lock);
        let state = grid.state(&run)?;
        let from = match &state {
            RunState::Finished(_) | RunState::Archived(_) => {
                summary.finished += 1;
                continue;
            }
            RunState::Unfinished(what) => format!("continues ({what})"),
            RunState::New => "started".to_string(),
        };
        let job = grid.start(&run, &state)?;
        eprintln!("{} {from} ({} of {total} left)", run.dir.display(), queue.len() + running.len() + 1);
        running.push(Running { run, job, started: Instant::now() });
    }
    Ok(())
}

/// Counts a run that ended: finished if the grid finds its result, else stopped or failed.
fn ended<G: Grid>(grid: &G, r: Running<G::Run>, end: JobEnd, summary: &mut Summary) -> Result<(), G::Error> {
    let dir = r.run.dir.display();
    match (grid.state(&r.run)?, end) {
        (RunState::Finished(line), _) => {
            summary.finished += 1;
            eprintln!("{dir} finished: {line}, {:.0} s", r.started.elapsed().as_secs_f64());
        }
        (_, JobEnd::Stopped) => summary.stopped += 1,
        (_, JobEnd::Failed(why)) => {
            eprintln!("{dir} failed: {why}");
            summary.failed.push((r.run.dir, why));
        }
        (_, JobEnd::Done) => summary.failed.push((r.run.dir, "ended without its result".into())),
    }
    Ok(())
}

/// Where every run of `plan` stands, a line each (`LABEL: DIR`), then the counts of each group and
/// of the whole grid. `archive` names where archived runs are.
pub fn status<R>(plan: &[Planned<R>], archive: &Path) -> String {
    let mut s = String::new();
    for p in plan {
        let label = match &p.state {
            RunState::New => "not started".to_string(),
            RunState::Unfinished(what) => what.clone(),
            RunState::Finished(line) => format!("finished: {line}"),
            RunState::Archived(line) => format!("finished (archived in {}): {line}", archive.display()),
        };
        s += &format!("{label}: {}\n", p.dir.display());
    }
    let counts = |runs: &[&Planned<R>]| {
        let n = |f: fn(&RunState) -> bool| runs.iter().filter(|r| f(&r.state)).count();
        format!(
            "{} finished here, {} archived in {}, {} unfinished (cut short, or in training now), {} not started",
            n(|s| matches!(s, RunState::Finished(_))),
            n(|s| matches!(s, RunState::Archived(_))),
            archive.display(),
            n(|s| matches!(s, RunState::Unfinished(_))),
            n(|s| matches!(s, RunState::New))
        )
    };
    let mut groups: Vec<&str> = Vec::new();
    for p in plan {
        if !groups.contains(&p.group.as_str()) {
            groups.push(&p.group);
        }
    }
    for g in groups {
        let runs: Vec<&Planned<R>> = plan.iter().filter(|p| p.group == g).collect();
        s += &format!("{g}: {}\n", counts(&runs));
    }
    let all: Vec<&Planned<R>> = plan.iter().collect();
    s += &format!("all {} runs: {}\n", plan.len(), counts(&all));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grid of runs that each write `done` on a thread after `ms` milliseconds, or fail.
    struct Toy {
        fail: Vec<PathBuf>,
        reports: usize,
    }

    fn plan(root: &Path, n: usize) -> Vec<Planned<u64>> {
        (0..n)
            .map(|i| Planned {
                dir: root.join(format!("s{i}")),
                group: format!("g{}", i % 2),
                state: RunState::New,
                run: 30,
            })
            .collect()
    }

    impl Grid for Toy {
        type Run = u64;
        type Error = GridError;
        fn title(&self) -> String {
            "toy".into()
        }
        fn archive(&self) -> &Path {
            Path::new("archive")
        }
        fn state(&self, run: &Planned<u64>) -> Result<RunState, GridError> {
            Ok(if run.dir.join("done").is_file() { RunState::Finished("ok".into()) } else { RunState::New })
        }
        fn start(&mut self, run: &Planned<u64>, _: &RunState) -> Result<Box<dyn Job>, GridError> {
            let (dir, ms, fail) = (run.dir.clone(), run.run, self.fail.contains(&run.dir));
            Ok(Box::new(ThreadJob::spawn(move |stop| {
                let _lock = RunDirLock::acquire(&dir).expect("free");
                let t0 = Instant::now();
                while t0.elapsed() < Duration::from_millis(ms) {
                    if stop() {
                        return JobEnd::Stopped;
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
                if fail {
                    return JobEnd::Failed("told to".into());
                }
                std::fs::write(dir.join("done"), "").expect("writes");
                JobEnd::Done
            })))
        }
        fn report(&mut self) -> Result<Vec<PathBuf>, GridError> {
            self.reports += 1;
            Ok(vec![PathBuf::from("report.md")])
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("equiarm-grid-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    const OPTS: RunnerOptions = RunnerOptions { parallel: 2, wait_for_locked: Duration::ZERO };

    #[test]
    fn runs_every_run_then_reports_and_skips_them_the_next_time() {
        let root = scratch("all");
        let mut g = Toy { fail: vec![], reports: 0 };
        let s = run(&mut g, plan(&root, 3), &OPTS, &|| false).unwrap();
        assert_eq!((s.before, s.finished, s.stopped, s.exit_code(), g.reports), (0, 3, 0, 0, 1));
        let again: Vec<_> = plan(&root, 3).into_iter().map(|p| Planned { state: g.state(&p).unwrap(), ..p }).collect();
        let s = run(&mut g, again, &OPTS, &|| false).unwrap();
        assert_eq!((s.before, s.finished, g.reports), (3, 0, 2));
        assert_eq!(s.lines("toy")[0], "toy: 3 finished before, 0 finished now, 0 failed, 0 left unfinished");
    }

    #[test]
    fn a_failed_run_is_named_and_the_others_finish_without_a_report() {
        let root = scratch("fail");
        let mut g = Toy { fail: vec![root.join("s1")], reports: 0 };
        let s = run(&mut g, plan(&root, 3), &OPTS, &|| false).unwrap();
        assert_eq!((s.finished, s.exit_code(), g.reports), (2, 1, 0));
        assert_eq!(s.failed, vec![(root.join("s1"), "told to".to_string())]);
    }

    #[test]
    fn a_stop_stops_the_running_runs_and_starts_no_other() {
        let root = scratch("stop");
        let mut g = Toy { fail: vec![], reports: 0 };
        let long: Vec<_> = plan(&root, 3).into_iter().map(|p| Planned { run: 60_000, ..p }).collect();
        let t0 = Instant::now();
        let s = run(&mut g, long, &OPTS, &|| root.join("s1").is_dir()).unwrap();
        assert_eq!((s.finished, s.stopped, s.exit_code(), g.reports), (0, 3, STOPPED_EXIT, 0));
        assert!(!root.join("s2").exists(), "a run started after the stop");
        assert!(t0.elapsed() < Duration::from_secs(30), "the running runs were not stopped");
    }

    #[test]
    fn a_run_another_process_holds_is_left_to_it() {
        let root = scratch("held");
        let held = RunDirLock::acquire(&root.join("s0")).unwrap();
        let mut g = Toy { fail: vec![], reports: 0 };
        let s = run(&mut g, plan(&root, 2), &OPTS, &|| false).unwrap();
        assert_eq!((s.finished, s.held.clone(), s.exit_code()), (1, vec![root.join("s0")], 0));
        drop(held);
        let text = status(
            &plan(&root, 2).into_iter().map(|p| Planned { state: g.state(&p).unwrap(), ..p }).collect::<Vec<_>>(),
            Path::new("a"),
        );
        assert!(text.contains(&format!("not started: {}\n", root.join("s0").display())), "{text}");
        assert!(text.contains(&format!("finished: ok: {}\n", root.join("s1").display())), "{text}");
        assert!(
            text.contains(
                "g0: 0 finished here, 0 archived in a, 0 unfinished (cut short, or in training now), 1 not started\n"
            ),
            "{text}"
        );
        assert!(text.ends_with("all 2 runs: 1 finished here, 0 archived in a, 0 unfinished (cut short, or in training now), 1 not started\n"), "{text}");
    }
}
