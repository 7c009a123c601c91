//! A run directory and its checkpoints: one training process at a time ([`RunDirLock`]), never a
//! new run over an old one, and the checkpoint layout:
//!
//! ```text
//! RUN/config.json                    the run's config
//! RUN/metrics.jsonl, metrics.csv     CleanRL-style scalars (crate::metrics)
//! RUN/evals.json, learning_curve.png the evaluations so far
//! RUN/checkpoints/step_0001000/      the learner's state (equiarm_sac::learner) and the transport's
//!                                    state file (loop.json in-process, trainer.json over DDS)
//! RUN/checkpoints/latest             the name of the newest complete checkpoint
//! ```

use std::path::{Path, PathBuf};

use equiarm_types::files::{at, replace};

use crate::TrainError;

/// Checkpoint directory name for `updates`.
pub fn step_dir_name(updates: u64) -> String {
    format!("step_{updates:07}")
}

/// checkpoint is complete: the file is replaced atomically).
pub fn write_latest(run_dir: &Path, updates: u64) -> Result<(), TrainError> {
    let root = run_dir.join("checkpoints");
    Ok(replace(&root.join("latest"), format!("{}\n", step_dir_name(updates)))?)
}

/// The run directory a checkpoint directory belongs to (`RUN/checkpoints/step_N` → `RUN`), or
/// `path` itself when it is a run directory. `None` for a checkpoint outside a run's
/// `checkpoints/` folder.
pub fn run_dir_of(path: &Path) -> Option<PathBuf> {
    if !path.join("manifest.json").is_file() {
        return Some(path.to_path_buf());
    }
    let parent = path.parent()?;
    (parent.file_name()? == "checkpoints").then(|| parent.parent().map(Path::to_path_buf)).flatten()
}

/// An exclusive claim on a run directory for as long as it lives: a second training process
/// pointed at the same directory is refused instead of interleaving its metrics and checkpoints
/// with the first one's. An advisory lock on `RUN/.lock` (which holds the owner's pid), released
/// by the OS when the process ends, so a killed run leaves no stale claim. On a filesystem without
/// file locks the run goes on unguarded, with a warning.
#[derive(Debug)]
pub struct RunDirLock {
    _file: std::fs::File,
}

impl RunDirLock {
    /// Create `run_dir` if needed and claim it.
    pub fn acquire(run_dir: &Path) -> Result<Self, TrainError> {
        match Self::try_acquire(run_dir)? {
            Some(claim) => Ok(claim),
            None => {
                let owner = std::fs::read_to_string(run_dir.join(".lock")).unwrap_or_default();
                let owner = owner.trim();
                let who = if owner.is_empty() { String::new() } else { format!(" (pid {owner})") };
                Err(TrainError::RunDir {
                    path: run_dir.into(),
                    message: format!(
                        "the run directory is in use by another training process{who}: wait for it to end or choose another --run-dir"
                    ),
                })
            }
        }
    }

    /// [`RunDirLock::acquire`], but `None` when another process holds the claim (instead of an
    /// error), for a caller that moves on to other work.
    pub fn try_acquire(run_dir: &Path) -> Result<Option<Self>, TrainError> {
        std::fs::create_dir_all(run_dir).map_err(at(run_dir))?;
        let path = run_dir.join(".lock");
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(at(&path))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => return Ok(None),
            // A filesystem without file locks (some network mounts): run unguarded, as before.
            Err(std::fs::TryLockError::Error(e)) if e.kind() == std::io::ErrorKind::Unsupported => {
                log::warn!(
                    "{}: file locks are not supported here ({e}); not guarding the run directory",
                    path.display()
                );
            }
            Err(std::fs::TryLockError::Error(e)) => {
                return Err(TrainError::run_dir(&path, format!("cannot lock: {e}")));
            }
        }
        use std::io::Write;
        file.set_len(0).and_then(|_| writeln!(file, "{}", std::process::id())).map_err(at(&path))?;
        Ok(Some(RunDirLock { _file: file }))
    }

    /// Whether a process holds the claim on `run_dir` now (it is training there), without claiming
    /// it or creating anything: false for a directory without `.lock` or where locks are not
    /// supported.
    pub fn is_held(run_dir: &Path) -> bool {
        let Ok(file) = std::fs::OpenOptions::new().read(true).write(true).open(run_dir.join(".lock")) else {
            return false;
        };
        matches!(file.try_lock(), Err(std::fs::TryLockError::WouldBlock))
    }

    /// Claim `run_dir` for a run that starts there: a new run ([`RunDirLock::acquire_new`]), or
    /// one that resumes `resume` in its own run directory, which may hold that run.
    pub fn acquire_for(run_dir: &Path, resume: Option<&Path>, force: bool) -> Result<Self, TrainError> {
        let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => a == b,
        };
        match resume.and_then(run_dir_of) {
            Some(resumed) if same(&resumed, run_dir) => Self::acquire(run_dir),
            _ => Self::acquire_new(run_dir, force),
        }
    }

    /// Claim `run_dir` for a new run. A directory that already holds a run (any of
    /// [`RUN_FILES`]) is refused, with the ways out, so that no run is overwritten by accident;
    /// with `force` the old directory is first moved aside to `RUN_DIR.old-N` (the first free N).
    /// Other files (a `config.json` written by a launch script) do not count.
    pub fn acquire_new(run_dir: &Path, force: bool) -> Result<Self, TrainError> {
        let claim = Self::acquire(run_dir)?;
        let found: Vec<&str> = RUN_FILES.iter().copied().filter(|f| run_dir.join(f).exists()).collect();
        if found.is_empty() {
            return Ok(claim);
        }
        if !force {
            // --resume only where there is a checkpoint to continue from
            let resume = match find_checkpoint(run_dir) {
                Ok(_) => format!("continue it with --resume {}, ", run_dir.display()),
                Err(_) => "it has no checkpoint to continue from: ".to_string(),
            };
            return Err(TrainError::RunDir {
                path: run_dir.into(),
                message: format!(
                    "holds a run already ({}): {resume}choose another --run-dir, or pass --force to move it aside",
                    found.join(", "),
                ),
            });
        }
        // (by its components: `run/` names `run`, and `run/.old-1` would be inside it)
        let base: PathBuf = run_dir.components().collect();
        let aside = (1u32..)
            .map(|n| PathBuf::from(format!("{}.old-{n}", base.display())))
            .find(|p| !p.exists())
            .expect("a free name");
        drop(claim);
        std::fs::rename(run_dir, &aside).map_err(|e| TrainError::RunDir {
            path: run_dir.into(),
            message: format!("cannot move the previous run aside to {}: {e}", aside.display()),
        })?;
        log::warn!("{}: the previous run was moved aside to {}", run_dir.display(), aside.display());
        Self::acquire(run_dir)
    }
}

/// What a run leaves in its directory that a new run there would overwrite or mix with its own.
pub const RUN_FILES: [&str; 4] = ["metrics.csv", "metrics.jsonl", "evals.json", "checkpoints"];

/// Whether `path` names a checkpoint as [`find_checkpoint`] reads it: a checkpoint or run
/// directory, or a run's `checkpoints/latest` pointer file.
pub fn names_checkpoint(path: &Path) -> bool {
    path.is_dir() || is_latest_pointer(path)
}

fn is_latest_pointer(path: &Path) -> bool {
    path.is_file() && path.file_name().is_some_and(|n| n == "latest")
}

/// The newest checkpoint of a run directory (from `checkpoints/latest`), the checkpoint a
/// `checkpoints/latest` pointer file names, or `path` itself if it is a checkpoint directory.
pub fn find_checkpoint(path: &Path) -> Result<PathBuf, TrainError> {
    if path.join("manifest.json").is_file() {
        return Ok(path.to_path_buf());
    }
    if is_latest_pointer(path) {
        let name = std::fs::read_to_string(path).map_err(at(path))?;
        let dir = path.parent().unwrap_or(Path::new(".")).join(name.trim());
        if !dir.join("manifest.json").is_file() {
            return Err(TrainError::RunDir {
                path: dir,
                message: format!("named by {} but not a checkpoint directory", path.display()),
            });
        }
        return Ok(dir);
    }
    let latest = path.join("checkpoints").join("latest");
    let name = std::fs::read_to_string(&latest).map_err(|e| TrainError::RunDir {
        path: latest.clone(),
        message: format!("{e} (not a checkpoint directory nor a run directory with checkpoints)"),
    })?;
    newest_intact(&path.join("checkpoints"), name.trim())
}

/// The files every checkpoint holds (the agent's, the replay, the counters, the manifest, which is
/// written last).
const CHECKPOINT_FILES: [&str; 9] = [
    "actor.safetensors",
    "critic.safetensors",
    "critic_target.safetensors",
    "actor_optim.safetensors",
    "critic_optim.safetensors",
    "agent.json",
    "replay.bin.zst",
    "learner.json",
    "manifest.json",
];

/// What checkpoint `ck` lacks: of the files every checkpoint holds, and of those the run's older
/// checkpoint `older` holds (a run writes the same files each time: a loop state, CURL's weights).
fn lacks(ck: &Path, older: Option<&Path>) -> Vec<String> {
    let names = |d: &Path| -> Vec<String> {
        std::fs::read_dir(d)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect()
    };
    let mut want: Vec<String> = CHECKPOINT_FILES.iter().map(|f| f.to_string()).collect();
    for f in older.map(names).unwrap_or_default() {
        if !want.contains(&f) && !f.ends_with(".tmp") {
            want.push(f);
        }
    }
    want.into_iter().filter(|f| !ck.join(f).is_file()).collect()
}

/// The checkpoint `latest` of `root` (a run's `checkpoints/`) if it is whole, else the newest older
/// one that is, with a warning saying what the newer ones lack; an error if none is whole.
fn newest_intact(root: &Path, latest: &str) -> Result<PathBuf, TrainError> {
    let step = |n: &str| n.strip_prefix("step_").and_then(|k| k.parse::<u64>().ok());
    let newest = step(latest).unwrap_or(u64::MAX);
    let mut steps: Vec<(u64, String)> = std::fs::read_dir(root)
        .map_err(at(root))?
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter_map(|n| step(&n).filter(|&k| k <= newest && root.join(&n).is_dir()).map(|k| (k, n)))
        .collect();
    steps.sort_unstable_by(|a, b| b.cmp(a));
    let mut steps: Vec<String> = steps.into_iter().map(|(_, n)| n).collect();
    if steps.first().map(String::as_str) != Some(latest) {
        steps.insert(0, latest.to_string()); // (named but gone: it lacks everything)
    }
    let mut skipped = Vec::new();
    for (k, name) in steps.iter().enumerate() {
        let ck = root.join(name);
        let missing = lacks(&ck, steps.get(k + 1).map(|o| root.join(o)).as_deref());
        if missing.is_empty() {
            if !skipped.is_empty() {
                log::warn!(
                    "{}: resuming from {name}, the newest whole checkpoint ({})",
                    root.display(),
                    skipped.join("; ")
                );
            }
            return Ok(ck);
        }
        skipped.push(format!("{name} lacks {}", missing.join(", ")));
    }
    Err(TrainError::RunDir { path: root.into(), message: format!("no whole checkpoint ({})", skipped.join("; ")) })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_directory_is_claimed_by_one_process_at_a_time() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path();
        let first = RunDirLock::acquire(dir).unwrap();
        let text = std::fs::read_to_string(dir.join(".lock")).unwrap();
        assert_eq!(text.trim(), std::process::id().to_string());
        // A second claim (another open file, as another process would have) is refused, naming
        // the directory, the owner and the fix.
        let e = RunDirLock::acquire(dir).unwrap_err().to_string();
        assert!(e.contains(&*dir.to_string_lossy()) && e.contains("in use by another training process"), "{e}");
        assert!(e.contains(&format!("pid {}", std::process::id())) && e.contains("--run-dir"), "{e}");
        assert!(RunDirLock::is_held(dir));
        drop(first);
        assert!(!RunDirLock::is_held(dir), "a released claim is free");
        assert!(!RunDirLock::is_held(&dir.join("missing")) && !dir.join("missing").exists());
        let again = RunDirLock::acquire(dir).unwrap();
        drop(again);
    }

    #[test]
    fn a_new_run_never_overwrites_a_run_directory_that_holds_a_run() {
        let root = tempfile::tempdir().unwrap();
        let root = root.path();
        let dir = root.join("run");
        // Empty, or holding only a launch script's config.json: a new run may start there.
        drop(RunDirLock::acquire_new(&dir, false).unwrap());
        std::fs::write(dir.join("config.json"), "{}").unwrap();
        drop(RunDirLock::acquire_new(&dir, false).unwrap());
        // Metrics or checkpoints: refused, naming what is there and the ways out.
        std::fs::write(dir.join("metrics.csv"), "global_step,wall_time,name,value\n").unwrap();
        std::fs::create_dir_all(dir.join("checkpoints")).unwrap();
        let e = RunDirLock::acquire_new(&dir, false).unwrap_err().to_string();
        assert!(
            e.contains(&*dir.to_string_lossy()) && e.contains("holds a run already (metrics.csv, checkpoints)"),
            "{e}"
        );
        // Regression (issue 61): the refusal suggested --resume for a run without a checkpoint.
        assert!(e.contains("no checkpoint to continue from") && !e.contains("--resume"), "{e}");
        assert!(e.contains("--run-dir") && e.contains("--force"), "{e}");
        assert!(dir.join("metrics.csv").is_file(), "the refused run touched nothing");
        // Resuming that run in its own directory is allowed; a new run from another run's
        // checkpoint is not.
        let ck = dir.join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        for f in CHECKPOINT_FILES {
            std::fs::write(ck.join(f), "{}").unwrap();
        }
        std::fs::write(dir.join("checkpoints").join("latest"), "step_0000010\n").unwrap();
        let e = RunDirLock::acquire_new(&dir, false).unwrap_err().to_string();
        assert!(e.contains(&format!("--resume {}", dir.display())), "with a checkpoint, --resume is the way on: {e}");
        drop(RunDirLock::acquire_for(&dir, Some(&ck), false).unwrap());
        drop(RunDirLock::acquire_for(&dir, Some(&dir), false).unwrap());
        let other = root.join("other");
        std::fs::create_dir_all(other.join("checkpoints")).unwrap();
        assert!(RunDirLock::acquire_for(&other, Some(&ck), false).is_err());
        // --force moves the old run aside, whole, and starts in an empty directory.
        let claim = RunDirLock::acquire_new(&dir, true).unwrap();
        assert!(root.join("run.old-1").join("metrics.csv").is_file());
        assert!(root.join("run.old-1").join("checkpoints").join("step_0000010").is_dir());
        assert!(!dir.join("metrics.csv").exists() && !dir.join("checkpoints").exists());
        drop(claim);
        std::fs::write(dir.join("metrics.csv"), "").unwrap();
        drop(RunDirLock::acquire_new(&dir, true).unwrap());
        assert!(root.join("run.old-2").join("metrics.csv").is_file(), "the next free name");
        // Regression (issue 61): `--run-dir run/ --force` failed, moving `run/` into `run/.old-1`.
        std::fs::write(dir.join("metrics.csv"), "").unwrap();
        let mut slashed = dir.clone().into_os_string();
        slashed.push("/");
        drop(RunDirLock::acquire_new(Path::new(&slashed), true).unwrap());
        assert!(root.join("run.old-3").join("metrics.csv").is_file(), "a trailing slash names the same directory");
    }

    /// Regression (issue 61): resume took the newest checkpoint even when it lacked a file, and
    /// failed; it now falls back to the newest whole one, saying so, and fails only when none is.
    #[test]
    fn resume_falls_back_to_the_newest_whole_checkpoint() {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path();
        let root = run.join("checkpoints");
        for step in [10u64, 20, 30] {
            let ck = root.join(step_dir_name(step));
            std::fs::create_dir_all(&ck).unwrap();
            for f in CHECKPOINT_FILES.iter().chain(&["loop.json"]) {
                std::fs::write(ck.join(f), "{}").unwrap();
            }
        }
        write_latest(run, 30).unwrap();
        assert_eq!(find_checkpoint(run).unwrap(), root.join("step_0000030"));
        // the newest lacks the run's loop state (a file its older checkpoints have): step 20
        std::fs::remove_file(root.join("step_0000030").join("loop.json")).unwrap();
        assert_eq!(find_checkpoint(run).unwrap(), root.join("step_0000020"));
        // and when that lacks its replay too: step 10
        std::fs::remove_file(root.join("step_0000020").join("replay.bin.zst")).unwrap();
        assert_eq!(find_checkpoint(run).unwrap(), root.join("step_0000010"));
        // a pointer to a checkpoint that is gone falls back as well
        std::fs::remove_dir_all(root.join("step_0000030")).unwrap();
        assert_eq!(find_checkpoint(run).unwrap(), root.join("step_0000010"));
        std::fs::remove_file(root.join("step_0000010").join("manifest.json")).unwrap();
        let e = find_checkpoint(run).unwrap_err().to_string();
        assert!(e.contains("no whole checkpoint") && e.contains("step_0000010 lacks manifest.json"), "{e}");
    }

    #[test]
    fn a_checkpoint_knows_its_run_directory() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path();
        let ck = dir.join("run").join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        std::fs::write(ck.join("manifest.json"), "{}").unwrap();
        assert_eq!(run_dir_of(&ck), Some(dir.join("run")));
        assert_eq!(run_dir_of(&dir.join("run")), Some(dir.join("run")));
        let loose = dir.join("loose");
        std::fs::create_dir_all(&loose).unwrap();
        std::fs::write(loose.join("manifest.json"), "{}").unwrap();
        assert_eq!(run_dir_of(&loose), None);
    }
}
