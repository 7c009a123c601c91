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
            return Err(TrainError::RunDir {
                path: run_dir.into(),
                message: format!(
                    "holds a run already ({}): continue it with --resume {}, choose another --run-dir, or pass --force to move it aside",
                    found.join(", "),
                    run_dir.display()
                ),
            });
        }
        let aside = (1u32..)
            .map(|n| PathBuf::from(format!("{}.old-{n}", run_dir.display())))
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
    Ok(path.join("checkpoints").join(name.trim()))
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
        assert!(e.contains("--resume") && e.contains("--run-dir") && e.contains("--force"), "{e}");
        assert!(dir.join("metrics.csv").is_file(), "the refused run touched nothing");
        // Resuming that run in its own directory is allowed; a new run from another run's
        // checkpoint is not.
        let ck = dir.join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        std::fs::write(ck.join("manifest.json"), "{}").unwrap();
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
