//! What the rotest integration tests share.

use std::path::Path;

use equiarm_rotest::cli::{ClassifierVariant, TrainOpts};
use equiarm_rotest::grid::GridArgs;
use equiarm_rotest::train::{ClassifierKind, RotestConfig};

/// A net of hidden 8 on 16 px crops, trained on few pairs in batches of 8 (the tests' size).
pub fn tiny(model: ClassifierKind, train_pairs: usize, seed: u64) -> RotestConfig {
    RotestConfig {
        hidden: 8,
        input: 16,
        val_pairs: 4,
        test_pairs: 4,
        batch: 8,
        ..RotestConfig::paper(model, train_pairs, seed)
    }
}

/// A grid at toy sizes over `root/data` (one setting, `none`, of 12 pairs; N = 4; a net of hidden 8
/// on 16 px crops; `epochs` epochs exactly) into `root/runs`, its report into `root/report`.
pub fn grid_args(root: &Path, variants: Vec<ClassifierVariant>, seeds: Vec<u64>, epochs: usize) -> GridArgs {
    let opts = TrainOpts {
        no_crop: false,
        paper: false,
        hidden: Some(8),
        input: Some(16),
        val_pairs: 4,
        test_pairs: 4,
        lr: 1e-3,
        batch: 8,
        min_epochs: epochs,
        patience: epochs,
        max_epochs: epochs,
        device: "cpu".into(),
        matmul: Default::default(),
        checkpoint_minutes: 60.0,
    };
    GridArgs {
        data: root.join("data"),
        runs: root.join("runs"),
        settings: "none".into(),
        sizes: vec![4],
        seeds,
        variants,
        pairs: 12,
        opts,
        report: root.join("report"),
        parallel: 1,
    }
}
