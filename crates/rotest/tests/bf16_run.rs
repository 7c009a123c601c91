//! A rotation-estimation run with `--matmul bf16` (Intel AMX): it trains, records the precision in
//! its run file, and follows the `f32` run's first epoch closely; without AMX it is refused naming
//! the flag.

use std::path::PathBuf;

use equiarm_nn::burn::tensor::Device;
use equiarm_nn::kernels::MatmulPrecision;
use equiarm_rotest::train::{self, ClassifierKind, RotestConfig, RotestRecord};
use equiarm_sim::rotest::{Corruptions, PairConfig};

fn scratch(name: &str) -> PathBuf {
    let d = scratch_path(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn a_bf16_run_trains_records_its_precision_and_follows_f32() {
    let ds = equiarm_rotest::generate::generate(
        &PairConfig { size: 19, supersample: 1, corruptions: Corruptions::parse("none").unwrap() },
        24,
        5,
    )
    .unwrap();
    let base = RotestConfig {
        hidden: 8,
        input: 16,
        val_pairs: 4,
        test_pairs: 4,
        batch: 8,
        min_epochs: 2,
        max_epochs: 2,
        lr: 1e-3,
        ..RotestConfig::paper(ClassifierKind::Equi, 16, 0)
    };
    let bf16 = RotestConfig { matmul: MatmulPrecision::Bf16, ..base.clone() };
    // The config is valid anywhere; the run checks the machine.
    bf16.validate().unwrap();
    let run = |cfg: &RotestConfig, name: &str| train::run(&ds, cfg, &Device::flex(), &scratch(name), &mut |_| {});
    if MatmulPrecision::Bf16.supported().is_err() {
        let e = run(&bf16, "refused").unwrap_err().to_string();
        assert!(e.contains("--matmul") && e.contains("AMX"), "{e}");
        eprintln!("no AMX on this machine: only the refusal was checked");
        return;
    }
    let exact = run(&base, "f32").unwrap();
    let rounded = run(&bf16, "bf16").unwrap();
    let saved: RotestRecord =
        serde_json::from_slice(&std::fs::read(scratch_path("bf16").join("run.json")).unwrap()).unwrap();
    assert_eq!(saved.config.matmul, MatmulPrecision::Bf16);
    assert!(rounded.history.iter().all(|e| e.loss.is_finite()));
    let (a, b) = (exact.history[0].loss, rounded.history[0].loss);
    // The first epoch starts from the same weights: its mean loss moves by bf16's rounding only.
    assert!((a - b).abs() <= 0.02 * a.abs(), "first-epoch loss f32 {a}, bf16 {b}");
    assert_ne!(a, b, "bf16 gave the f32 loss bit for bit: the AMX path did not run");
}

fn scratch_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("rotest_bf16").join(name)
}
