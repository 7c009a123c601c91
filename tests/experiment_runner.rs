//! `equiarm experiment`: a tiny grid of two runs, the runner killed (SIGKILL) while they train, run
//! again to the end, and reported.

mod support;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn equiarm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_equiarm"))
}

/// Two runs (Equi and CNN SAC on block pulling) of 200 updates at hidden 8 on 16 px frames, a
/// checkpoint every 10 updates, an evaluation every 50.
const GRID: &str = r#"
description = "test grid"
preset = "reduced"
tasks = ["block_pulling"]
variants = ["equi", "cnn"]
seeds = [3]
heldout_episodes = 3
[updates]
block_pulling = 200
[config]
image_size = 16
batch_size = 8
num_envs = 1
demo_episodes = 1
training_starts = 10
eval_every = 50
eval_episodes = 2
checkpoint_every = 10
max_episode_steps = 20
agent = { hidden = 8, input_size = 16 }
[paper]
"block_pulling/equi" = 0.87
"#;

fn updates_of_latest(run: &Path) -> Option<u64> {
    let name = std::fs::read_to_string(run.join("checkpoints/latest")).ok()?;
    name.trim().strip_prefix("step_")?.parse().ok()
}

#[test]
fn a_killed_grid_resumes_to_the_same_updates_and_reports() {
    let dir = support::scratch("experiment_runner");
    let grid = dir.join("tiny.toml");
    std::fs::write(&grid, GRID).unwrap();
    let runs = dir.join("runs");
    let reports = dir.join("reports");
    let out = reports.join("tiny");
    let at = |cmd: &str| {
        let mut c = equiarm();
        c.args(["experiment", cmd, "tiny", "--file"])
            .arg(&grid)
            .arg("--runs")
            .arg(&runs)
            .arg("--archive")
            .arg(&reports);
        c
    };
    // (the preset's scene, the arm in view: `-arm` in the VIEW part of the path)
    let equi = runs.join("block_pulling/equi/side-arm/none/s3");
    let cnn = runs.join("block_pulling/cnn/side-arm/none/s3");

    // Start, and kill the runner once a run has a checkpoint but has not finished.
    let mut runner = at("run").args(["--parallel", "2"]).stdout(Stdio::null()).stderr(Stdio::null()).spawn().unwrap();
    let t0 = Instant::now();
    loop {
        let partial = [&equi, &cnn].iter().any(|r| updates_of_latest(r).is_some_and(|u| u < 200));
        if partial {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "no checkpoint within 5 minutes");
        assert!(runner.try_wait().unwrap().is_none(), "the runner ended before it could be interrupted");
        std::thread::sleep(Duration::from_millis(20));
    }
    runner.kill().unwrap();
    runner.wait().unwrap();
    let interrupted: Vec<u64> = [&equi, &cnn].iter().filter_map(|r| updates_of_latest(r)).collect();
    assert!(interrupted.iter().any(|&u| u < 200), "{interrupted:?}");

    // The status names the interrupted run; the same command continues both to the end.
    let status = at("status").output().unwrap();
    assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    let text = String::from_utf8_lossy(&status.stdout).into_owned();
    // (a run whose child is still writing its last checkpoint is in training now)
    assert!(text.contains("interrupted at") || text.contains("in training now"), "{text}");

    let done = at("run").args(["--parallel", "2", "--report", "--out"]).arg(&out).output().unwrap();
    let err = String::from_utf8_lossy(&done.stderr);
    assert!(done.status.success(), "{err}");
    assert!(err.contains("continues (interrupted at"), "{err}");
    for run in [&equi, &cnn] {
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(run.join("result.json")).unwrap()).unwrap();
        assert_eq!(r["updates"], 200, "{}", run.display());
        assert_eq!(r["heldout"]["episodes"], 3);
        let evals: Vec<serde_json::Value> =
            serde_json::from_slice(&std::fs::read(run.join("evals.json")).unwrap()).unwrap();
        let at: Vec<u64> = evals.iter().map(|e| e["updates"].as_u64().unwrap()).collect();
        assert_eq!(at, [50, 100, 150, 200], "{}: each evaluation once across the interruption", run.display());
        let steps: Vec<String> = std::fs::read_dir(run.join("checkpoints"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("step_"))
            .collect();
        assert_eq!(steps, ["step_0000200"], "a finished run keeps its final checkpoint only");
    }

    // A third run has nothing to do; the report has a row per variant and the figures.
    let again = at("run").output().unwrap();
    assert!(again.status.success());
    assert!(String::from_utf8_lossy(&again.stdout).contains("2 finished before, 0 finished now"));
    let md = std::fs::read_to_string(out.join("README.md")).unwrap();
    assert!(md.contains("| block_pulling | side | none | Equi SAC + RAD | 1 of 1 | 200 |"), "{md}");
    assert!(md.contains("| block_pulling | side | none | CNN SAC + RAD | 1 of 1 | 200 |"), "{md}");
    assert!(md.contains("| 0.87 |"), "the paper's figure: {md}");
    for f in ["block_pulling-side-none-success.png", "block_pulling-side-none-return.png"] {
        assert!(std::fs::metadata(out.join(f)).unwrap().len() > 1000, "{f}");
    }

    // `experiment heldout` evaluates a finished run's weights on the grid's held-out episodes: the
    // same figures as its result.json at the runs' thread count (one); a directory that is no run
    // is named with what it lacks.
    let held = equiarm()
        .env("RAYON_NUM_THREADS", "1")
        .args(["experiment", "heldout", "--episodes", "3"])
        .arg(&equi)
        .output()
        .unwrap();
    assert!(held.status.success(), "{}", String::from_utf8_lossy(&held.stderr));
    let h: serde_json::Value = serde_json::from_slice(&std::fs::read(equi.join("heldout.json")).unwrap()).unwrap();
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(equi.join("result.json")).unwrap()).unwrap();
    assert_eq!(h, r["heldout"], "held-out of the final weights, again");
    let none = equiarm().args(["experiment", "heldout"]).arg(&dir).output().unwrap();
    let err = String::from_utf8_lossy(&none.stderr);
    assert!(!none.status.success() && err.contains("config.json") && !err.contains("panicked"), "{err}");

    // The report archived both runs: without the run directories they still count as done and
    // the report is drawn again from the archive.
    std::fs::remove_dir_all(&runs).unwrap();
    let again = at("run").output().unwrap();
    assert!(String::from_utf8_lossy(&again.stdout).contains("2 finished before, 0 finished now"));
    let status = String::from_utf8_lossy(&at("status").output().unwrap().stdout).into_owned();
    assert_eq!(status.matches("finished (archived").count(), 2, "{status}");
    std::fs::remove_file(out.join("README.md")).unwrap();
    assert!(at("report").arg("--out").arg(&out).output().unwrap().status.success());
    assert_eq!(std::fs::read_to_string(out.join("README.md")).unwrap(), md);
    equiarm().args(["experiment", "run", "tiny", "--file"]).arg(&grid).arg("--runs").arg(&runs).output().unwrap();

    // A grid changed under its runs is refused, naming the run and the field.
    std::fs::write(&grid, GRID.replace("batch_size = 8", "batch_size = 16")).unwrap();
    let changed = at("status").output().unwrap();
    assert!(!changed.status.success());
    let err = String::from_utf8_lossy(&changed.stderr);
    assert!(err.contains("batch_size") && err.contains("s3"), "{err}");
}

/// Regression (issue 61): a runs directory that cannot be made was reported as "another runner works
/// on grid … here"; the error now says the directory cannot be made, and why.
#[test]
fn an_uncreatable_runs_directory_is_not_reported_as_a_busy_grid() {
    let dir = support::scratch("experiment_uncreatable_runs");
    let grid = dir.join("tiny.toml");
    std::fs::write(&grid, GRID).unwrap();
    let file = dir.join("a_file");
    std::fs::write(&file, "").unwrap();
    let out = equiarm()
        .args(["experiment", "run", "tiny", "--file"])
        .arg(&grid)
        .arg("--runs")
        .arg(file.join("runs"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("cannot claim grid tiny") && err.contains("Not a directory"), "{err}");
    assert!(!err.contains("another runner"), "{err}");
}

/// Issue 58: the claims table on docs/results/README.md is what `equiarm experiment claims` makes
/// from the committed claims file and archives, and nothing else on the page changes.
#[test]
fn the_committed_claims_table_regenerates_from_the_committed_archives() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let committed = std::fs::read_to_string(root.join("docs/results/README.md")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let page = dir.path().join("README.md");
    std::fs::write(&page, &committed).unwrap();
    let out = equiarm().current_dir(root).args(["experiment", "claims", "--out"]).arg(&page).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let made = std::fs::read_to_string(&page).unwrap();
    assert_eq!(made, committed, "run `equiarm experiment claims` and commit docs/results/README.md");
    assert!(made.contains("| Equi SAC beats CNN SAC: block in bowl (10,000 updates) |"));

    // a claims file that does not parse is named, with the line
    let bad = dir.path().join("claims.toml");
    std::fs::write(&bad, "[[claim]]\nclaim = \"x\"\ntest = \"better\"\n").unwrap();
    let out = equiarm()
        .current_dir(root)
        .args(["experiment", "claims", "--file"])
        .arg(&bad)
        .arg("--out")
        .arg(&page)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("claims.toml") && err.contains("better"), "{err}");
    assert_eq!(std::fs::read_to_string(&page).unwrap(), made, "the page is left as it was");
}
