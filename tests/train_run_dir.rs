//! `equiarm train` never overwrites a run: a second new run in a run directory that holds one is
//! refused (the first run's files untouched), `--force` moves the old run aside, `--resume`
//! continues in place.

mod support;

use std::process::Command;

fn train(run_dir: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_equiarm"));
    cmd.args(["train", "--in-process", "--image", "19:16", "--hidden", "8", "--batch-size", "8", "--num-envs", "1"]);
    cmd.args(["--demo-episodes", "0", "--training-starts", "8", "--eval-every", "0", "--checkpoint-every", "0", "-q"]);
    cmd.arg("--run-dir").arg(run_dir).args(extra);
    cmd.output().unwrap()
}

#[test]
fn a_second_run_in_the_same_directory_is_refused_unless_forced_or_resumed() {
    let root = support::scratch("train_run_dir");
    let run = root.join("run");
    let first = train(&run, &["--total-updates", "2"]);
    assert!(first.status.success(), "{}", String::from_utf8_lossy(&first.stderr));
    let metrics = std::fs::read(run.join("metrics.csv")).unwrap();

    let again = train(&run, &["--total-updates", "2"]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(!again.status.success() && err.contains("holds a run already") && err.contains("--force"), "{err}");
    assert_eq!(
        std::fs::read(run.join("metrics.csv")).unwrap(),
        metrics,
        "the refused run changed the first one's metrics"
    );

    let resumed = train(&run, &["--total-updates", "3", "--resume"]);
    assert!(!resumed.status.success(), "--resume needs its directory");
    let resumed = train(&run, &["--total-updates", "3", "--resume", run.to_str().unwrap()]);
    assert!(resumed.status.success(), "{}", String::from_utf8_lossy(&resumed.stderr));

    let forced = train(&run, &["--total-updates", "2", "--force"]);
    assert!(forced.status.success(), "{}", String::from_utf8_lossy(&forced.stderr));
    assert!(root.join("run.old-1").join("checkpoints").join("step_0000003").is_dir(), "the old run, moved aside whole");
    assert!(
        run.join("checkpoints").join("step_0000002").is_dir() && !run.join("checkpoints").join("step_0000003").exists()
    );
    std::fs::remove_dir_all(&root).ok();
}
