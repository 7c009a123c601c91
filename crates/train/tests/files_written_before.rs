//! Files written before the domain types (issue 55) still load: a run directory and checkpoint made by
//! `equiarm train` at the commit before `equiarm_types` (tests/fixtures/run_before_types: CNN, hidden 8,
//! view angle60, corruption written "gripper_only,random_reflection", 2 updates), an env config with
//! the corruption as a map of flags, and every training config archived by the experiment reports.

use std::path::{Path, PathBuf};

use equiarm_sac::config::TrainConfig;
use equiarm_sim::EnvConfig;
use equiarm_train::inprocess::{RunOptions, run};
use equiarm_types::{Corruption, CorruptionKind, ModelKind, TaskKind, ViewPreset};

fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/run_before_types")
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let target = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &target);
        } else {
            std::fs::copy(e.path(), &target).unwrap();
        }
    }
}

#[test]
fn a_run_written_before_the_domain_types_reads_and_resumes() {
    let text = std::fs::read_to_string(fixture().join("config.json")).unwrap();
    let cfg = TrainConfig::from_json(&text).unwrap();
    assert_eq!((cfg.task, cfg.view, cfg.agent.model), (TaskKind::BlockPulling, ViewPreset::Angle60, ModelKind::Cnn));
    let both = Corruption::of(&[CorruptionKind::RandomReflection, CorruptionKind::GripperOnly]);
    assert_eq!(cfg.corruption, both);
    let ck = fixture().join("checkpoints/step_0000002");
    assert_eq!(equiarm_sac::learner::read_manifest(&ck).unwrap().config, cfg);

    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("resume-before-types");
    let _ = std::fs::remove_dir_all(&dir);
    copy_dir(&fixture(), &dir);
    let more = TrainConfig { total_updates: 4, ..cfg };
    let never = || false;
    let opts =
        RunOptions { run_dir: dir.clone(), resume: Some(dir.join("checkpoints/step_0000002")), ..Default::default() };
    let summary = run(more, &opts, &never).unwrap();
    assert_eq!(summary.updates, 4);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_env_config_with_corruption_flags_still_loads() {
    let old = r#"{"task": "block_in_bowl", "corruption": {"random_reflection": true, "gripper_only": false}}"#;
    let cfg: EnvConfig = serde_json::from_str(old).unwrap();
    assert_eq!(cfg.corruption, Corruption::of(&[CorruptionKind::RandomReflection]));
    let again: EnvConfig = serde_json::from_str(&serde_json::to_string(&cfg).unwrap()).unwrap();
    assert_eq!(again, cfg);
}

#[test]
fn every_archived_experiment_config_loads() {
    let results = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/results");
    let mut configs = 0;
    for grid in std::fs::read_dir(&results).unwrap() {
        let archive = grid.unwrap().path().join("runs.json");
        let Ok(text) = std::fs::read_to_string(&archive) else { continue };
        let runs: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
        for r in runs {
            let cfg: TrainConfig = serde_json::from_value(r["config"].clone())
                .unwrap_or_else(|e| panic!("{}: {}: {e}", archive.display(), r["run"]));
            // The typed config writes back what was read (names are the same strings).
            let back = serde_json::to_value(&cfg).unwrap();
            assert_eq!(back["task"], r["config"]["task"]);
            assert_eq!(back["view"], r["config"]["view"]);
            configs += 1;
        }
    }
    assert!(configs >= 40, "only {configs} archived configs found under {}", results.display());
}
