//! Checkpoints of a rotation-estimation run (`equiarm_rotest::resume`): a run stopped part-way and
//! continued from its checkpoint ends exactly as the same run trained straight through; a checkpoint
//! of another configuration or a damaged one is refused naming it; a run directory another process
//! trains in is refused (the grid skips it); a stopped grid continues the run it stopped.

mod common;

use std::path::{Path, PathBuf};
use std::time::Duration;

use equiarm_nn::burn::tensor::Device;
use equiarm_rotest::RotestError;
use equiarm_rotest::dataset::Dataset;
use equiarm_rotest::generate::generate;
use equiarm_rotest::resume::{RESUME_DIR, read_state};
use equiarm_rotest::train::{self, Checkpointing, ClassifierKind, Outcome, RotestConfig, RotestRecord};
use equiarm_sim::rotest::{Corruptions, PairConfig};

fn scratch(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rotest_resume").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn data(pairs: usize, seed: u64) -> Dataset {
    let cfg = PairConfig { size: 19, supersample: 1, corruptions: Corruptions::parse("none").unwrap() };
    generate(&cfg, pairs, seed).unwrap()
}

/// The tests' net on 16 px random crops of 19 px images, 6 epochs of 12 pairs.
fn tiny(model: ClassifierKind) -> RotestConfig {
    RotestConfig { lr: 1e-3, min_epochs: 6, max_epochs: 6, ..common::tiny(model, 12, 3) }
}

/// The record without the wall times, which differ between any two runs.
fn timeless(mut r: RotestRecord) -> RotestRecord {
    for e in &mut r.history {
        e.seconds = 0.0;
    }
    r
}

/// Stops `cfg`'s run in `dir` after `after` epochs (a checkpoint after every epoch).
fn stop_after(ds: &Dataset, cfg: &RotestConfig, dir: &Path, after: usize) -> Outcome {
    let asked = std::cell::Cell::new(0);
    let stop = || {
        asked.set(asked.get() + 1);
        asked.get() >= after
    };
    let ckpt = Checkpointing { every: Duration::ZERO, stop: &stop };
    train::run_with(ds, cfg, &Device::flex(), dir, Some(&ckpt), &mut |_| {}).unwrap()
}

#[test]
fn a_run_stopped_and_continued_ends_exactly_as_the_run_trained_straight() {
    let ds = data(20, 11);
    for model in [ClassifierKind::Cnn, ClassifierKind::Equi] {
        let cfg = tiny(model);
        let straight = scratch(&format!("straight_{model:?}"));
        let whole = train::run(&ds, &cfg, &Device::flex(), &straight, &mut |_| {}).unwrap();
        assert_eq!(whole.history.len(), 6);

        let parts = scratch(&format!("parts_{model:?}"));
        assert_eq!(stop_after(&ds, &cfg, &parts, 2), Outcome::Stopped { epoch: 2 });
        let state = read_state(&parts.join(RESUME_DIR)).unwrap();
        assert_eq!((state.epoch, state.history.len(), &state.config), (2, 2, &cfg));
        assert!(!parts.join("run.json").exists() && !parts.join("best.safetensors").exists());
        // a second stop, from the first checkpoint
        assert_eq!(stop_after(&ds, &cfg, &parts, 3), Outcome::Stopped { epoch: 5 });
        let rest = match train::run_with(&ds, &cfg, &Device::flex(), &parts, None, &mut |_| {}).unwrap() {
            Outcome::Finished(r) => r,
            o => panic!("{o:?}"),
        };
        assert_eq!(timeless(rest), timeless(whole.clone()), "{model:?}: the continued run differs");
        let weights = |d: &Path| std::fs::read(d.join("best.safetensors")).unwrap();
        assert_eq!(weights(&parts), weights(&straight), "{model:?}: the best weights differ");
        assert!(!parts.join(RESUME_DIR).exists(), "a finished run keeps its checkpoint");
    }
}

#[test]
fn a_checkpoint_of_another_configuration_or_a_damaged_one_is_refused_naming_it() {
    let ds = data(20, 12);
    let cfg = tiny(ClassifierKind::Cnn);
    let dir = scratch("refused");
    assert_eq!(stop_after(&ds, &cfg, &dir, 1), Outcome::Stopped { epoch: 1 });
    let other = RotestConfig { lr: 2e-3, ..cfg.clone() };
    let e = train::run(&ds, &other, &Device::flex(), &dir, &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains(RESUME_DIR) && e.contains("another configuration") && e.contains("lr 0.001"), "{e}");

    let state = dir.join(RESUME_DIR).join("state.json");
    let text = std::fs::read_to_string(&state).unwrap();
    std::fs::write(&state, &text[..text.len() / 2]).unwrap();
    let e = train::run(&ds, &cfg, &Device::flex(), &dir, &mut |_| {}).unwrap_err();
    assert!(matches!(e, RotestError::Format { .. }), "{e}");
    assert!(e.to_string().contains("state.json") && e.to_string().contains("not a rotest checkpoint"), "{e}");

    std::fs::write(&state, text).unwrap();
    std::fs::write(dir.join(RESUME_DIR).join("model.safetensors"), b"not weights").unwrap();
    let e = train::run(&ds, &cfg, &Device::flex(), &dir, &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains("model.safetensors"), "{e}");
    assert!(!dir.join("run.json").exists());
}

#[test]
fn a_checkpoint_whose_optimiser_state_is_damaged_or_from_before_is_refused_naming_the_file() {
    let ds = data(20, 12);
    let cfg = tiny(ClassifierKind::Cnn);
    let dir = scratch("optimiser");
    assert_eq!(stop_after(&ds, &cfg, &dir, 1), Outcome::Stopped { epoch: 1 });
    let adam = dir.join(RESUME_DIR).join("adam.safetensors");
    let saved = std::fs::read(&adam).unwrap();
    std::fs::write(&adam, &saved[..saved.len() / 2]).unwrap();
    let e = train::run(&ds, &cfg, &Device::flex(), &dir, &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains("adam.safetensors"), "{e}");
    // A checkpoint of an earlier equiarm held burn's optimiser record instead.
    std::fs::rename(&adam, dir.join(RESUME_DIR).join("adam.bpk")).unwrap();
    let e = train::run(&ds, &cfg, &Device::flex(), &dir, &mut |_| {}).unwrap_err().to_string();
    assert!(e.contains("adam.bpk") && e.contains("delete the run's `resume` directory"), "{e}");
    assert!(!dir.join("run.json").exists());
}

#[test]
fn a_run_directory_another_process_trains_in_is_refused() {
    let ds = data(20, 13);
    let dir = scratch("busy");
    let claim = equiarm_train::rundir::RunDirLock::acquire(&dir).unwrap();
    let e = train::run(&ds, &tiny(ClassifierKind::Cnn), &Device::flex(), &dir, &mut |_| {}).unwrap_err();
    assert!(matches!(e, RotestError::Busy { .. }), "{e}");
    assert!(e.to_string().contains("another process is training"), "{e}");
    drop(claim);
    assert!(train::run(&ds, &tiny(ClassifierKind::Cnn), &Device::flex(), &dir, &mut |_| {}).is_ok());
}

/// The grid stopped in the middle of a run: that run keeps a checkpoint, `rotest status` says
/// after which epoch, and the same command continues it, then skips a run another process holds
/// (which `rotest status` says is in training now).
#[test]
fn a_grid_stopped_inside_a_run_continues_it_from_its_checkpoint() {
    use equiarm_rotest::cli::{ClassifierVariant, RotestCommand, run};
    use equiarm_rotest::grid::status;
    const EPOCHS: usize = 1000;
    let root = scratch("grid");
    data(12, 7).write(&root.join("data").join("none")).unwrap();
    let args = common::grid_args(&root, vec![ClassifierVariant::Cnn], vec![0, 1], EPOCHS);
    let seed_dir = |s: u64| root.join("runs").join("none").join("cnn").join("4").join(format!("s{s}"));
    // the stop comes once seed 0 has started: it stops at the end of the epoch in training
    let stop = || seed_dir(0).exists();
    assert_eq!(run(RotestCommand::Grid(args.clone()), &stop).unwrap(), equiarm_train::STOPPED_EXIT);
    assert!(!seed_dir(0).join("run.json").exists() && !seed_dir(1).exists());
    let resume = equiarm_rotest::resume::find(&seed_dir(0)).expect("a checkpoint");
    let epoch = equiarm_rotest::resume::read_state(&resume).unwrap().epoch;
    assert!((1..EPOCHS).contains(&epoch), "stopped after epoch {epoch}");
    let text = status(&args).unwrap();
    let line = format!("unfinished, checkpoint after epoch {epoch}: {}\n", seed_dir(0).display());
    assert!(text.contains(&line), "{text}");

    // seed 1 is held by another process: the grid continues seed 0, skips seed 1 and writes the
    // report of what is finished
    let claim = equiarm_train::rundir::RunDirLock::acquire(&seed_dir(1)).unwrap();
    let text = status(&args).unwrap();
    assert!(text.contains(&format!("in training now: {}\n", seed_dir(1).display())), "{text}");
    assert_eq!(run(RotestCommand::Grid(args.clone()), &|| false).unwrap(), 0);
    let rec: RotestRecord = serde_json::from_slice(&std::fs::read(seed_dir(0).join("run.json")).unwrap()).unwrap();
    assert_eq!(rec.history.iter().map(|e| e.epoch).collect::<Vec<_>>(), (1..=EPOCHS).collect::<Vec<_>>());
    assert!(!seed_dir(1).join("run.json").exists());
    drop(claim);
    assert_eq!(run(RotestCommand::Grid(args.clone()), &|| false).unwrap(), 0);
    assert!(seed_dir(1).join("run.json").is_file());
}
