//! Shared by the cross-language tests: finding the Python interpreter of the test environment
//! (the one `tests/run_all.sh` creates with the pinned third-party peers) and running its scripts.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Python of the test environment: `$EQUIARM_PYTHON`, else `.venv/bin/python` in the repository.
/// These tests need the real third-party peers (cyclonedds, rosbags, mcap); without them they fail
/// with instructions rather than pass vacuously.
pub fn python() -> PathBuf {
    if let Some(p) = std::env::var_os("EQUIARM_PYTHON") {
        return PathBuf::from(p);
    }
    let local = repo().join(".venv/bin/python");
    if local.exists() {
        return local;
    }
    panic!(
        "these tests need the Python peers (cyclonedds, rosbags, mcap): run `bash tests/run_all.sh`, \
         or set EQUIARM_PYTHON to a python with tests/python/requirements.txt installed"
    );
}

/// A `Command` running `tests/python/<script>` with the test environment's Python.
pub fn python_script(script: &str) -> Command {
    let mut c = Command::new(python());
    c.arg(repo().join("tests/python").join(script));
    c.env("PYTHONUNBUFFERED", "1");
    c
}

/// A fresh, empty scratch directory for one test.
pub fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Runs `cmd` and panics with its output unless it exits 0; returns stdout.
pub fn run_ok(mut cmd: Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("starting {cmd:?}: {e}"));
    let stdout = String::from_utf8_lossy(&out.stdout).to_string();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{cmd:?} failed ({}):\n{stdout}\n{stderr}", out.status);
    stdout
}
pub mod golden_values;
