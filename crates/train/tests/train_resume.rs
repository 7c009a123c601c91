//! Regression test for exact resume of the in-process training loop (issue: learning, acceptance
//! "K updates straight give bit-identical weights to K/2 updates + checkpoint + resume + K/2").
//!
//! The checkpoint holds the agent (weights, Adam moments, α, noise RNG), the replay (frames,
//! priorities, ring state), the sampling RNG, and per env the current episode's seed index and
//! actions; resuming replays those actions in the deterministic simulator. If any piece were
//! missing or inexact, the resumed run's weights would differ from the straight run's.

mod common;

use std::path::{Path, PathBuf};

use equiarm_sac::config::TrainConfig;
use equiarm_train::inprocess::{RunOptions, run};
use equiarm_train::rundir::find_checkpoint;

fn tiny() -> TrainConfig {
    common::tiny_run(11, 12)
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("resume-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn tensors(p: &Path) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let mut t = equiarm_sac::tensorfile::read(p).expect("read weights").tensors;
    t.sort_by(|a, b| a.0.cmp(&b.0));
    t
}

#[test]
fn k_updates_straight_equal_half_checkpoint_resume_half() {
    let never = || false;
    let straight_dir = scratch("straight");
    let straight = run(tiny(), &RunOptions { run_dir: straight_dir.clone(), ..Default::default() }, &never).unwrap();
    assert_eq!(straight.updates, 12);

    let split_dir = scratch("split");
    let half = run(tiny(), &RunOptions { run_dir: split_dir.clone(), stop_at: Some(6), ..Default::default() }, &never)
        .unwrap();
    assert_eq!(half.updates, 6);
    let ck = find_checkpoint(&split_dir).unwrap();
    assert!(ck.ends_with("step_0000006"), "{}", ck.display());
    // The run's `checkpoints/latest` pointer file names the same checkpoint (users pass it too).
    let pointer = split_dir.join("checkpoints").join("latest");
    assert!(equiarm_train::rundir::names_checkpoint(&pointer) && equiarm_train::rundir::names_checkpoint(&split_dir));
    assert_eq!(find_checkpoint(&pointer).unwrap(), ck);
    assert!(!equiarm_train::rundir::names_checkpoint(&ck.join("actor.safetensors")));
    let resumed =
        run(tiny(), &RunOptions { run_dir: split_dir.clone(), resume: Some(ck), ..Default::default() }, &never)
            .unwrap();
    assert_eq!(resumed.updates, 12);
    assert_eq!(resumed.global_step, straight.global_step);

    let a = find_checkpoint(&straight_dir).unwrap();
    let b = find_checkpoint(&split_dir).unwrap();
    for file in ["actor.safetensors", "critic.safetensors", "critic_target.safetensors", "actor_optim.safetensors"] {
        assert!(tensors(&a.join(file)) == tensors(&b.join(file)), "{file} differs after resume");
    }
    assert_eq!(std::fs::read(a.join("agent.json")).unwrap(), std::fs::read(b.join("agent.json")).unwrap());

    // A checkpoint of another config is refused, naming the differing field.
    let mut other = tiny();
    other.batch_size = 4;
    let e = match run(
        other,
        &RunOptions { run_dir: scratch("other"), resume: Some(b.clone()), ..Default::default() },
        &never,
    ) {
        Ok(_) => panic!("config mismatch must fail"),
        Err(e) => e.to_string(),
    };
    assert!(e.contains("batch_size"), "{e}");
    for d in [straight_dir, split_dir, scratch("other")] {
        let _ = std::fs::remove_dir_all(d);
    }
}

/// `checkpoint_secs` writes a checkpoint whenever that much training time passed since the last
/// one, besides `checkpoint_every` (0 here): with 0 s, after every update before the last; the last
/// update's checkpoint is the one written at the end.
#[test]
fn checkpoints_by_training_time() {
    let never = || false;
    let dir = scratch("by_time");
    let opts = RunOptions { run_dir: dir.clone(), stop_at: Some(4), checkpoint_secs: Some(0.0), ..Default::default() };
    assert_eq!(run(tiny(), &opts, &never).unwrap().updates, 4);
    let mut steps: Vec<String> = std::fs::read_dir(dir.join("checkpoints"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("step_"))
        .collect();
    steps.sort();
    assert_eq!(steps, ["step_0000001", "step_0000002", "step_0000003", "step_0000004"]);
    // without it, only the end's
    let dir = scratch("by_count_only");
    let opts = RunOptions { run_dir: dir.clone(), stop_at: Some(4), ..Default::default() };
    run(tiny(), &opts, &never).unwrap();
    let n = std::fs::read_dir(dir.join("checkpoints")).unwrap().filter(|e| e.as_ref().unwrap().path().is_dir()).count();
    assert_eq!(n, 1);
}
