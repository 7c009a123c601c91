//! The `equiarm rotest` subcommands (clap derive): `data`, `snapshots`, `bound`, `train`, `grid`,
//! `status`, `invariance`, `report`.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::time::Instant;

use equiarm_nn::kernels::MatmulPrecision;
use equiarm_sim::rotest::{Corruptions, PAPER_SETTINGS, PairConfig};

use crate::bound::dataset_bound;
use crate::dataset::Dataset;
use crate::error::Result;
use crate::generate::{generate, setting_file_stem, write_snapshot};
use crate::grid::GridArgs;
use crate::train::{Checkpointing, ClassifierKind, Outcome, RotestConfig};

/// `equiarm rotest …`.
#[derive(Debug, clap::Subcommand)]
pub enum RotestCommand {
    /// Generate a dataset: DIR/pairs.rotest.
    #[command(
        after_help = "Example:\n  equiarm rotest data --corrupt grid,side --pairs 2000 --seed 0 -o data/rotest/side+grid"
    )]
    Data {
        /// PairCorruption setting: `none` or a comma-separated list of grid, occlusion,
        /// random_light_color, light_effect, two_light_color, two_specular, squeeze, reflect,
        /// condition_reverse (invert-label), side.
        #[arg(long, default_value = "none")]
        corrupt: String,
        /// Number of pairs.
        #[arg(long, default_value_t = 2000)]
        pairs: usize,
        /// Generator seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Stored image side, pixels (the paper's 152).
        #[arg(long, default_value_t = 152)]
        size: usize,
        /// Rendering supersampling factor (images are area-downsampled from size · supersample).
        #[arg(long, default_value_t = 2)]
        supersample: usize,
        /// Output directory.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Write snapshot PNGs of the first pairs of each of the 15 settings: `OUT/<setting>.png`.
    Snapshots {
        /// Pairs per setting (rows of each PNG).
        #[arg(long, default_value_t = 2)]
        pairs: usize,
        /// Generator seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Image side, pixels.
        #[arg(long, default_value_t = 152)]
        size: usize,
        /// Output directory.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Print the upper bound on the accuracy of a C8-invariant classifier on a dataset.
    Bound {
        /// Dataset directory (or its pairs.rotest file).
        data: PathBuf,
    },
    /// Train and evaluate one network on one dataset: OUT/run.json and OUT/best.safetensors. It
    /// writes a checkpoint to OUT/resume/ every --checkpoint-minutes and continues from one found
    /// there (of the same configuration). Ctrl-C (or SIGTERM) stops it at the end of the epoch with
    /// a checkpoint, exit status 3; a second one at once.
    #[command(
        after_help = "Examples:\n  equiarm rotest train --data data/rotest/none --model equi --train-pairs 400 --seed 0 -o runs/none/equi/400/s0\n  equiarm rotest train --data data/rotest/none --model cnn --train-pairs 400 --img-trans 400 -o runs/none/cnn+trans/400/s0\n  equiarm rotest train --paper --device vulkan --data data/rotest/none --model equi --train-pairs 1600 -o runs/paper/none/equi/1600/s0"
    )]
    Train {
        /// Dataset directory (or its pairs.rotest file).
        #[arg(long)]
        data: PathBuf,
        /// The network.
        #[arg(long, value_enum)]
        model: ClassifierKind,
        /// Training pairs N.
        #[arg(long)]
        train_pairs: usize,
        /// "+ image transformations": add all 8 rotations of the first N training pairs (0: off).
        #[arg(long, default_value_t = 0)]
        img_trans: usize,
        /// Seed of the split, the weights, the batch order and the crops.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// The schedule, the network size and the device.
        #[command(flatten)]
        opts: TrainOpts,
        /// Output directory.
        #[arg(short, long)]
        out: PathBuf,
    },
    /// Run the experiment: for each setting, generate its dataset if `DATA/<setting>` has none, then
    /// train Equi, CNN and CNN + image transformations (img-trans = N), or the `--variants` named,
    /// for each N and seed whose
    /// `RUNS/<setting>/<variant>/<N>/s<seed>/run.json` does not exist yet and that the report's
    /// archive (`REPORT/rotest_runs.json`) does not hold (so an interrupted grid continues where it
    /// stopped, on this machine or from a committed report), then write the report. A run cut short
    /// continues from its checkpoint (written every --checkpoint-minutes); a run another process is
    /// training is skipped. Ctrl-C (or SIGTERM) stops it at the end of the epoch in training, with
    /// a checkpoint and without the report, exit status 3; a second one at once (that run then
    /// continues from its last checkpoint).
    #[command(
        after_help = "Example (a short schedule for 2 cores):\n  equiarm rotest grid --data data/rotest --runs runs/rotest --sizes 100,400 --seeds 0,1,2,3 --lr 1e-3 --min-epochs 20 --patience 20 --max-epochs 100"
    )]
    Grid(GridArgs),
    /// Where each run of a grid stands (the same options as `grid`): per setting the runs finished
    /// here, archived in the report, unfinished and not started; then each run still to train.
    #[command(
        after_help = "Example:\n  equiarm rotest status --data data/rotest --runs runs/rotest --sizes 100,400 --seeds 0,1,2,3 --lr 1e-3 --min-epochs 20 --patience 20 --max-epochs 100"
    )]
    Status(GridArgs),
    /// Evaluate a finished run's best weights on its test split with both images rotated by k·45°:
    /// the fraction of predictions unchanged, and the accuracy, for each k.
    Invariance {
        /// The dataset the run was trained on.
        #[arg(long)]
        data: PathBuf,
        /// The run directory (run.json and best.safetensors).
        run: PathBuf,
        /// Also evaluate with every image masked to the disc inscribed in the crop, so that 45°
        /// rotations bring in no zero-filled corners.
        #[arg(long)]
        disc: bool,
    },
    /// Write the table (rotest.md), one figure per setting and the archive (rotest_runs.json) from
    /// every run.json below RUNS and the runs already archived in OUT.
    Report {
        /// Directory searched recursively for run.json files.
        runs: PathBuf,
        /// Directory of datasets, one subdirectory per setting (named as `data -o` was given),
        /// to draw each setting's invariant bound; optional.
        #[arg(long)]
        data: Option<PathBuf>,
        /// Output directory.
        #[arg(short, long, default_value = "docs/results")]
        out: PathBuf,
    },
}

/// One of the experiment's three networks, as `grid --variants` and the run directories name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ClassifierVariant {
    /// The C8-equivariant classifier.
    Equi,
    /// The plain CNN.
    Cnn,
    /// The plain CNN with all eight C8 rotations of its N training pairs ("+ image transformations").
    #[value(name = "cnn+trans")]
    CnnTrans,
}

impl ClassifierVariant {
    /// The directory name below `RUNS/<setting>/`.
    pub fn name(self) -> &'static str {
        match self {
            ClassifierVariant::Equi => "equi",
            ClassifierVariant::Cnn => "cnn",
            ClassifierVariant::CnnTrans => "cnn+trans",
        }
    }

    /// The network and the number of pairs rotated by the augmentation, at training-set size `n`.
    pub fn model(self, n: usize) -> (ClassifierKind, usize) {
        match self {
            ClassifierVariant::Equi => (ClassifierKind::Equi, 0),
            ClassifierVariant::Cnn => (ClassifierKind::Cnn, 0),
            ClassifierVariant::CnnTrans => (ClassifierKind::Cnn, n),
        }
    }
}

/// Training options shared by `train` and `grid`.
#[derive(Clone, Debug, clap::Args)]
pub struct TrainOpts {
    /// Use centre crops in training instead of random crops.
    #[arg(long)]
    pub no_crop: bool,
    /// The paper's network size (hidden 64, 128 px input) instead of the 2-core size.
    #[arg(long)]
    pub paper: bool,
    /// Hidden size (default: 16, or 64 with --paper).
    #[arg(long)]
    pub hidden: Option<usize>,
    /// Network input side after cropping: 16, 32, 64 or 128 (default: 64, or 128 with --paper).
    #[arg(long)]
    pub input: Option<usize>,
    /// Validation pairs.
    #[arg(long, default_value_t = 200)]
    pub val_pairs: usize,
    /// Test pairs.
    #[arg(long, default_value_t = 200)]
    pub test_pairs: usize,
    /// Adam learning rate.
    #[arg(long, default_value_t = 1e-4)]
    pub lr: f64,
    /// Mini-batch size.
    #[arg(long, default_value_t = 64)]
    pub batch: usize,
    /// Epochs always run.
    #[arg(long, default_value_t = 100)]
    pub min_epochs: usize,
    /// Stop after this many epochs without a better validation accuracy.
    #[arg(long, default_value_t = 100)]
    pub patience: usize,
    /// At most this many epochs.
    #[arg(long, default_value_t = 1000)]
    pub max_epochs: usize,
    /// Device: `cpu`, or `vulkan` / `vulkan:N` / `vulkan:cpu` in the GPU build (`--features vulkan`).
    #[arg(long, default_value = "cpu")]
    pub device: String,
    /// Precision of the convolutions' matrix products on the CPU: f32 (the paper's) or bf16 (Intel
    /// AMX: operands rounded to bfloat16, f32 sums). Recorded in each run's config.
    #[arg(long, default_value = "f32")]
    pub matmul: MatmulPrecision,
    /// Minutes between a run's checkpoints (RUN/resume/, written at the end of an epoch; not part
    /// of the run's config).
    #[arg(long, default_value_t = 5.0)]
    pub checkpoint_minutes: f64,
}

impl TrainOpts {
    /// The time between checkpoints, checked.
    pub fn checkpoint_every(&self) -> Result<std::time::Duration> {
        let m = self.checkpoint_minutes;
        if !(m.is_finite() && m > 0.0 && m <= 1e6) {
            return Err(crate::RotestError::Config {
                field: "--checkpoint-minutes",
                message: format!("{m} must be a number of minutes in (0, 1e6]"),
            });
        }
        Ok(std::time::Duration::from_secs_f64(m * 60.0))
    }

    /// The configuration of one run with these options.
    pub fn config(
        &self,
        model: ClassifierKind,
        train_pairs: usize,
        img_trans: usize,
        seed: u64,
    ) -> Result<RotestConfig> {
        let mut cfg = RotestConfig::paper(model, train_pairs, seed);
        cfg.hidden = self.hidden.unwrap_or(if self.paper { 64 } else { 16 });
        cfg.input = self.input.unwrap_or(if self.paper { 128 } else { 64 });
        cfg.val_pairs = self.val_pairs;
        cfg.test_pairs = self.test_pairs;
        cfg.img_trans = img_trans;
        cfg.crop = !self.no_crop;
        cfg.lr = self.lr;
        cfg.batch = self.batch;
        cfg.min_epochs = self.min_epochs;
        cfg.patience = self.patience;
        cfg.max_epochs = self.max_epochs;
        cfg.matmul = self.matmul;
        cfg.validate()?;
        Ok(cfg)
    }
}

fn print_epoch(e: &crate::train::EpochRecord) {
    eprintln!(
        "epoch {:4}  loss {:.4}  train {:.3}  val {:.3}  test {}  {:.1} s",
        e.epoch,
        e.loss,
        e.train_acc,
        e.val_acc,
        e.test_acc.map_or("  -  ".to_string(), |t| format!("{t:.3}")),
        e.seconds
    );
}

pub(crate) fn summary(r: &crate::train::RotestRecord) -> String {
    let secs: f64 = r.history.iter().map(|e| e.seconds).sum();
    // (an archived record keeps no history)
    let epochs = match r.history.len() {
        0 => String::new(),
        n => format!("; {n} epochs, {:.1} s/epoch", secs / n as f64),
    };
    format!(
        "{} {:?} N={} img-trans {} seed {}: test accuracy {:.4} at best validation epoch {} (val {:.4}){epochs}",
        r.corrupt,
        r.config.model,
        r.config.train_pairs,
        r.config.img_trans,
        r.config.seed,
        r.test_acc,
        r.best_epoch,
        r.best_val_acc,
    )
}

/// The invariant bound of each setting whose dataset is in `root` (as `grid` and `data -o` name them:
/// the setting with `+` for `,`), the paper's settings and any other (`condition_reverse,full_circle`).
pub(crate) fn bounds_of(root: &std::path::Path) -> Result<BTreeMap<String, f64>> {
    let mut bounds = BTreeMap::new();
    let Ok(entries) = std::fs::read_dir(root) else { return Ok(bounds) };
    for entry in entries.flatten() {
        let dir = entry.path();
        let Some(stem) = dir.file_name().and_then(|n| n.to_str()) else { continue };
        let Ok(c) = Corruptions::parse(&stem.replace('+', ",")) else { continue };
        if setting_file_stem(&c) == stem && dir.join(crate::dataset::FILE_NAME).is_file() {
            let h = Dataset::read_header(&dir)?;
            bounds.insert(c.name(), dataset_bound(&h.pairs, &c).uniform_rotation);
        }
    }
    Ok(bounds)
}

/// What `rotest train` and `grid` do on their first SIGINT or SIGTERM: `stop` turns true, and the
/// run in training writes a checkpoint at the end of its epoch and ends.
pub const TRAIN_STOP: &str = "stopping at the end of the epoch with a checkpoint (again to exit now: the run continues from its last checkpoint)";

impl RotestCommand {
    /// Whether this is `rotest train` or `grid`, the subcommands that stop with a checkpoint when
    /// asked ([`run`]'s `stop`); the others end at once on a signal, losing nothing finished.
    pub fn stops_with_checkpoint(&self) -> bool {
        matches!(self, RotestCommand::Train { .. } | RotestCommand::Grid { .. })
    }
}

/// Runs one subcommand, printing its results to stdout and progress to stderr. Returns the exit
/// status: 0, or [`STOPPED_EXIT`](equiarm_train::STOPPED_EXIT) when `rotest train` or `grid` saw
/// `stop()` before the end (the run in training writes a checkpoint; the grid keeps every finished
/// run and writes no report; the same command continues).
pub fn run(cmd: RotestCommand, stop: &dyn Fn() -> bool) -> Result<i32> {
    match cmd {
        RotestCommand::Data { corrupt, pairs, seed, size, supersample, out } => {
            let cfg = PairConfig { size, supersample, corruptions: Corruptions::parse(&corrupt)? };
            let t0 = Instant::now();
            let ds = generate(&cfg, pairs, seed)?;
            let gen_s = t0.elapsed().as_secs_f64();
            let path = ds.write(&out)?;
            let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
            println!(
                "{}: {pairs} pairs of {size} px, setting {}, in {gen_s:.1} s ({:.1} pairs/s on {} threads), {:.1} MB",
                path.display(),
                cfg.corruptions.name(),
                pairs as f64 / gen_s.max(1e-9),
                rayon::current_num_threads(),
                bytes as f64 / 1e6
            );
        }
        RotestCommand::Snapshots { pairs, seed, size, out } => {
            for s in PAPER_SETTINGS {
                let c = Corruptions::parse(s)?;
                let ds = generate(&PairConfig { size, supersample: 2, corruptions: c.clone() }, pairs.max(1), seed)?;
                let p = write_snapshot(&ds, pairs, &out, &setting_file_stem(&c))?;
                let labels: Vec<String> =
                    ds.header.pairs.iter().map(|m| format!("idx {} label {}", m.idx, m.label)).collect();
                println!("{}: {}", p.display(), labels.join("; "));
            }
        }
        RotestCommand::Bound { data } => {
            let h = Dataset::read_header(&data)?;
            let c = Corruptions::parse(&h.corrupt)?;
            let b = dataset_bound(&h.pairs, &c);
            println!("setting {}: {} pairs", h.corrupt, b.pairs);
            println!("bound (rotation uniform over the 8 angles, as generated): {:.4}", b.uniform_rotation);
            println!("bound (the rotations this dataset drew):                 {:.4}", b.drawn);
            let sub = [1, 2, 4].map(|o| crate::bound::subgroup_bound(&h.pairs, &c, o));
            println!(
                "bound of a classifier invariant only to C1 / C2 (180°) / C4 (90°): {:.4} / {:.4} / {:.4}",
                sub[0], sub[1], sub[2]
            );
        }
        RotestCommand::Train { data, model, train_pairs, img_trans, seed, opts, out } => {
            let cfg = opts.config(model, train_pairs, img_trans, seed)?;
            let ckpt = Checkpointing { every: opts.checkpoint_every()?, stop };
            let device = equiarm_nn::device::open(&opts.device)?;
            let t0 = Instant::now();
            let ds = Dataset::read(&data, None)?;
            eprintln!("{} pairs of {} px read in {:.2} s", ds.len(), ds.header.size, t0.elapsed().as_secs_f64());
            if let Some(dir) = crate::resume::find(&out) {
                eprintln!("continuing from the checkpoint in {}", dir.display());
            }
            match crate::train::run_with(&ds, &cfg, &device, &out, Some(&ckpt), &mut print_epoch)? {
                Outcome::Finished(r) => println!("{}", summary(&r)),
                Outcome::Stopped { epoch } => {
                    println!(
                        "stopped after epoch {epoch}, with a checkpoint in {}: the same command continues",
                        out.join(crate::resume::RESUME_DIR).display()
                    );
                    return Ok(equiarm_train::STOPPED_EXIT);
                }
            }
        }
        RotestCommand::Grid(args) => return crate::grid::run(&args, stop),
        RotestCommand::Status(args) => print!("{}", crate::grid::status(&args)?),
        RotestCommand::Invariance { data, run, disc } => {
            let ds = Dataset::read(&data, None)?;
            let cpu = equiarm_nn::device::cpu();
            let (rec, res) = crate::train::run_agreement(&ds, &run, &cpu, false)?;
            let masked = if disc { Some(crate::train::run_agreement(&ds, &run, &cpu, true)?.1) } else { None };
            println!(
                "{} {:?} N={} seed {}: {} test pairs",
                rec.corrupt, rec.config.model, rec.config.train_pairs, rec.config.seed, rec.config.test_pairs
            );
            for (k, (agree, acc)) in res.iter().enumerate() {
                let extra = masked
                    .as_ref()
                    .map(|m| format!("; disc-masked: unchanged {:.3}, accuracy {:.3}", m[k].0, m[k].1))
                    .unwrap_or_default();
                println!("rotation {:3}°: prediction unchanged {agree:.3}, accuracy {acc:.3}{extra}", 45 * k);
            }
        }
        RotestCommand::Report { runs, data, out } => {
            let bounds = match data {
                Some(root) => bounds_of(&root)?,
                None => BTreeMap::new(),
            };
            for f in crate::report::write(&runs, &out, &bounds)? {
                println!("{}", f.display());
            }
        }
    }
    Ok(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every dataset directory counts, the paper's settings and others (`condition_reverse,full_circle`
    /// as `condition_reverse+full_circle`); a directory whose name is no setting is skipped.
    #[test]
    fn bounds_come_from_every_dataset_directory() {
        let root = std::env::temp_dir().join(format!("equiarm_rotest_bounds_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        for setting in ["none", "condition_reverse,full_circle"] {
            let cfg = PairConfig { size: 16, supersample: 1, corruptions: Corruptions::parse(setting).unwrap() };
            let ds = crate::generate::generate(&cfg, 8, 1).unwrap();
            ds.write(&root.join(setting_file_stem(&cfg.corruptions))).unwrap();
        }
        std::fs::create_dir_all(root.join("not a setting")).unwrap();
        let b = bounds_of(&root).unwrap();
        assert_eq!(b.keys().cloned().collect::<Vec<_>>(), ["condition_reverse,full_circle", "none"]);
        assert_eq!(b["none"], 1.0);
        assert!((b["condition_reverse,full_circle"] - 0.625).abs() < 1e-9, "{b:?}");
        assert!(bounds_of(&root.join("missing")).unwrap().is_empty());
        std::fs::remove_dir_all(&root).unwrap();
    }
}
