//! Training and evaluation of the rotation classifiers (docs/rotest.md, "Training"): inputs are the
//! two RGBD images stacked into 8 channels, cross-entropy over the 8 rotations, Adam, mini-batches,
//! a train / validation / test split drawn per seed, test accuracy at the epoch of best validation
//! accuracy, early stopping, random or centre crops, and the "+ image transformations" augmentation.

use std::path::Path;
use std::time::{Duration, Instant};

use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::optim::GradientsParams;
use equiarm_nn::burn::tensor::activation::log_softmax;
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::kernels::MatmulPrecision;
use equiarm_nn::layers::Numerics;
use equiarm_nn::nets::{NetConfig, RotCnnNet, RotEquiNet};
use equiarm_sac::optim::{Adam, AdamParams};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::dataset::Dataset;
use crate::error::{Result, RotestError};
use crate::resume;
use equiarm_types::files::at;

/// Input channels: RGBD of the first image, then of the second.
pub const CHANNELS: usize = 8;
/// Number of classes (rotations by k·45°).
pub const CLASSES: usize = 8;

/// The network trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum ClassifierKind {
    /// The C8-equivariant classifier ([`RotEquiNet`]): invariant logits.
    Equi,
    /// The plain CNN ([`RotCnnNet`]).
    Cnn,
}

/// A classifier of stacked image pairs: `[B, 8, S, S] → logits [B, 8]`.
pub trait Classifier: Module {
    /// Class logits.
    fn logits(&self, x: Tensor<4>) -> Tensor<2>;
}

impl Classifier for RotEquiNet {
    fn logits(&self, x: Tensor<4>) -> Tensor<2> {
        self.forward(x)
    }
}

impl Classifier for RotCnnNet {
    fn logits(&self, x: Tensor<4>) -> Tensor<2> {
        self.forward(x)
    }
}

/// Everything a training run is configured by.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RotestConfig {
    /// The network.
    pub model: ClassifierKind,
    /// Hidden size of the network (paper 64; a multiple of 8).
    pub hidden: usize,
    /// Network input side after cropping, pixels: 16, 32, 64 or 128 (paper 128). The stored images
    /// are first area-downsampled to `input · 152 / 128` (the paper's 152 → 128 crop ratio).
    pub input: usize,
    /// Training pairs N (the first N of the seed's permutation).
    pub train_pairs: usize,
    /// Validation pairs (paper 200), after the training pairs.
    pub val_pairs: usize,
    /// Test pairs (paper 200), after the validation pairs.
    pub test_pairs: usize,
    /// "+ image transformations": all 8 rotations of each of the first `img_trans` training pairs are
    /// added to the training set, with the label unchanged (0 = off).
    pub img_trans: usize,
    /// Random crops in training (`false`: the centre crop, as in evaluation).
    pub crop: bool,
    /// Adam learning rate (paper 1e-4).
    pub lr: f64,
    /// Mini-batch size (paper 64).
    pub batch: usize,
    /// Epochs always run before early stopping may stop (paper 100).
    pub min_epochs: usize,
    /// Stop when validation accuracy has not improved for this many epochs (paper 100).
    pub patience: usize,
    /// Hard limit on epochs (paper 1000).
    pub max_epochs: usize,
    /// Seed of the split, the initial weights, the batch order and the crops.
    pub seed: u64,
    /// Precision of the convolutions' matrix products: `f32` (the paper's) or `bf16` (Intel AMX,
    /// docs/backends.md). Process-wide: [`run`] sets it, and refuses `bf16` on a machine without
    /// AMX (the config itself is valid anywhere, so a report reads it anywhere).
    #[serde(default, skip_serializing_if = "MatmulPrecision::is_f32")]
    pub matmul: MatmulPrecision,
}

impl RotestConfig {
    /// The paper's settings for `model` with N = `train_pairs`: hidden 64, 128 px, 200/200 split, lr
    /// 1e-4, batch 64, at least 100 epochs, patience 100, at most 1000, random crops.
    pub fn paper(model: ClassifierKind, train_pairs: usize, seed: u64) -> Self {
        Self {
            model,
            hidden: 64,
            input: 128,
            train_pairs,
            val_pairs: 200,
            test_pairs: 200,
            img_trans: 0,
            crop: true,
            lr: 1e-4,
            batch: 64,
            min_epochs: 100,
            patience: 100,
            max_epochs: 1000,
            seed,
            matmul: MatmulPrecision::F32,
        }
    }

    /// Side of the images before cropping: `input · 152 / 128`.
    pub fn full_side(&self) -> usize {
        self.input * 19 / 16
    }

    /// Checks the domains; the first value out of its domain is a [`RotestError::Config`] naming the
    /// command-line flag.
    pub fn validate(&self) -> Result<()> {
        let bad = |field: &'static str, message: String| Err(RotestError::Config { field, message });
        if ![16, 32, 64, 128].contains(&self.input) {
            return bad("--input", format!("{} must be 16, 32, 64 or 128", self.input));
        }
        if self.hidden == 0 || !self.hidden.is_multiple_of(8) || self.hidden > 512 {
            return bad("--hidden", format!("{} must be a multiple of 8 in 8..=512", self.hidden));
        }
        if self.train_pairs == 0 {
            return bad("--train-pairs", "must be at least 1".into());
        }
        if self.val_pairs == 0 || self.test_pairs == 0 {
            return bad("--val-pairs/--test-pairs", "must be at least 1".into());
        }
        if self.img_trans > self.train_pairs {
            return bad(
                "--img-trans",
                format!("{} is more than the {} training pairs", self.img_trans, self.train_pairs),
            );
        }
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad("--lr", format!("{} must be finite and > 0", self.lr));
        }
        if self.batch == 0 {
            return bad("--batch", "must be at least 1".into());
        }
        if self.max_epochs == 0 || self.min_epochs > self.max_epochs {
            return bad(
                "--max-epochs",
                format!("{} must be >= 1 and >= --min-epochs ({})", self.max_epochs, self.min_epochs),
            );
        }
        Ok(())
    }
}

/// Stacked network inputs before cropping: `n` samples of `[8, side, side]` f32 and their labels.
#[derive(Clone, Debug, PartialEq)]
pub struct Samples {
    /// Image side before cropping.
    pub side: usize,
    /// `n · 8 · side²` values: R, G, B in [0, 1], then the depth channel, for image 1 then image 2.
    pub x: Vec<f32>,
    /// Labels 0..8.
    pub y: Vec<u8>,
}

/// The depth channel: (1 m − planar depth) · 5, i.e. 0 at the table seen from the top-down
/// camera, 0.5 at 10 cm above it.
pub fn depth_channel(depth_m: f32) -> f32 {
    (1.0 - depth_m) * 5.0
}

impl Samples {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y.len()
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.y.is_empty()
    }

    fn one(&self, i: usize) -> &[f32] {
        let n = CHANNELS * self.side * self.side;
        &self.x[i * n..(i + 1) * n]
    }

    /// The pairs `indices` of `ds`, area-downsampled to `side` (which must divide the stored size).
    pub fn from_dataset(ds: &Dataset, indices: &[usize], side: usize) -> Result<Self> {
        Self::from_dataset_rotated(ds, indices, side, 0)
    }

    /// The pairs `indices` of `ds` with both images rotated by `k`·45° ([`rotate`]) at the stored
    /// resolution, then area-downsampled to `side` (which must divide the stored size). `k` = 0 is
    /// [`Samples::from_dataset`].
    pub fn from_dataset_rotated(ds: &Dataset, indices: &[usize], side: usize, k: usize) -> Result<Self> {
        let mut out = Samples { side, x: Vec::new(), y: Vec::new() };
        out.append_from_dataset(ds, indices, k)?;
        Ok(out)
    }

    /// Appends the pairs `indices` of `ds` rotated by `k`·45° as [`Samples::from_dataset_rotated`]
    /// makes them (at this set's side), reserving the memory they need first.
    pub fn append_from_dataset(&mut self, ds: &Dataset, indices: &[usize], k: usize) -> Result<()> {
        let side = self.side;
        let s = ds.header.size;
        if side == 0 || !s.is_multiple_of(side) {
            return Err(RotestError::Config {
                field: "--input",
                message: format!(
                    "needs images of a multiple of {side} px (input · 152/128) but the dataset's are {s} px; \
                     generate it with `--size` a multiple of {side}"
                ),
            });
        }
        let f = s / side;
        let area = (f * f) as f32;
        // One pair: the 8 planes at the stored resolution, rotated, area-downsampled.
        let one = |i: usize| -> Vec<f32> {
            let p = &ds.pairs[i];
            let mut full = Vec::with_capacity(CHANNELS * s * s);
            for img in [&p.before, &p.after] {
                for ch in 0..3 {
                    full.extend(img.color.chunks_exact(3).map(|px| px[ch] as f32 / 255.0));
                }
                full.extend(img.depth.iter().map(|d| depth_channel(d.to_f32())));
            }
            if !k.is_multiple_of(8) {
                full = rotate(&full, CHANNELS, s, k);
            }
            let mut out = Vec::with_capacity(CHANNELS * side * side);
            for plane in full.chunks_exact(s * s) {
                let mut small = vec![0f32; side * side];
                for r in 0..s {
                    for c in 0..s {
                        small[(r / f) * side + c / f] += plane[r * s + c];
                    }
                }
                out.extend(small.iter().map(|v| v / area));
            }
            out
        };
        self.x.reserve_exact(indices.len() * CHANNELS * side * side);
        self.y.reserve_exact(indices.len());
        // In parallel over pairs, in blocks of 256 to bound the memory held at once.
        for block in indices.chunks(256) {
            let done: Vec<Vec<f32>> = block.par_iter().map(|&i| one(i)).collect();
            for (v, &i) in done.into_iter().zip(block) {
                self.x.extend(v);
                self.y.push(ds.header.pairs[i].label);
            }
        }
        Ok(())
    }

    /// Sets every pixel farther than `radius` pixels from the image centre to 0, in every channel.
    /// With `radius` = half the crop, a centre crop of a sample rotated by 45° (whose corners are
    /// zero-filled) and of the unrotated sample then show the same disc of the scene.
    pub fn mask_disc(&mut self, radius: f32) {
        let c = (self.side as f32 - 1.0) / 2.0;
        let side = self.side;
        let outside: Vec<usize> =
            (0..side * side).filter(|i| ((i / side) as f32 - c).hypot((i % side) as f32 - c) > radius).collect();
        for plane in self.x.chunks_exact_mut(side * side) {
            for &i in &outside {
                plane[i] = 0.0;
            }
        }
    }

    /// Appends `other`'s samples (of the same side).
    pub fn extend(&mut self, other: Samples) {
        debug_assert_eq!(self.side, other.side);
        self.x.extend(other.x);
        self.y.extend(other.y);
    }

    /// "+ image transformations": the rotations by k·45°, k = 1…7, of the pairs `indices` of `ds`
    /// (both images, at the stored resolution, label unchanged), downsampled to `side`.
    pub fn rotated_copies(ds: &Dataset, indices: &[usize], side: usize) -> Result<Self> {
        let mut out = Samples { side, x: Vec::new(), y: Vec::new() };
        out.append_rotated_copies(ds, indices)?;
        Ok(out)
    }

    /// Appends [`Samples::rotated_copies`] of `indices` to this set (one allocation).
    pub fn append_rotated_copies(&mut self, ds: &Dataset, indices: &[usize]) -> Result<()> {
        self.x.reserve_exact(7 * indices.len() * CHANNELS * self.side * self.side);
        for k in 1..8 {
            self.append_from_dataset(ds, indices, k)?;
        }
        Ok(())
    }

    /// A batch `[len, 8, size, size]` of `indices`, each cropped at its `(row, col)` offset.
    fn batch(&self, indices: &[usize], offsets: &[(usize, usize)], size: usize, device: &Device) -> Tensor<4> {
        let mut data = Vec::with_capacity(indices.len() * CHANNELS * size * size);
        for (&i, &(r0, c0)) in indices.iter().zip(offsets) {
            let img = self.one(i);
            for ch in 0..CHANNELS {
                for r in 0..size {
                    let s = (ch * self.side + r0 + r) * self.side + c0;
                    data.extend_from_slice(&img[s..s + size]);
                }
            }
        }
        Tensor::from_data(TensorData::new(data, [indices.len(), CHANNELS, size, size]), device)
    }
}

/// `ch` planes of `side`² rotated counter-clockwise (as displayed, rows down) by `k`·45° about the
/// image centre. Multiples of 90° are exact pixel permutations; others are bilinear with zero fill.
pub fn rotate(img: &[f32], ch: usize, side: usize, k: usize) -> Vec<f32> {
    let k = k % 8;
    let mut out = vec![0f32; img.len()];
    let c = (side as f32 - 1.0) / 2.0;
    // Inverse map: output (r, q) reads the input at the point rotated by −θ.
    let (s, co) = if k.is_multiple_of(2) {
        [(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0)][k / 2]
    } else {
        (k as f32 * std::f32::consts::FRAC_PI_4).sin_cos()
    };
    for r in 0..side {
        for q in 0..side {
            let (dy, dx) = (r as f32 - c, q as f32 - c);
            // Counter-clockwise on screen (y down) by θ: the source is rotated clockwise.
            let sx = c + co * dx - s * dy;
            let sy = c + s * dx + co * dy;
            for p in 0..ch {
                let plane = &img[p * side * side..(p + 1) * side * side];
                out[p * side * side + r * side + q] = if k.is_multiple_of(2) {
                    let (x, y) = (sx.round() as usize, sy.round() as usize);
                    plane[y * side + x]
                } else {
                    bilinear(plane, side, sy, sx)
                };
            }
        }
    }
    out
}

fn bilinear(plane: &[f32], side: usize, y: f32, x: f32) -> f32 {
    let (y0, x0) = (y.floor(), x.floor());
    let (fy, fx) = (y - y0, x - x0);
    let at = |yy: f32, xx: f32| {
        if yy < 0.0 || xx < 0.0 || yy >= side as f32 || xx >= side as f32 {
            0.0
        } else {
            plane[yy as usize * side + xx as usize]
        }
    };
    at(y0, x0) * (1.0 - fy) * (1.0 - fx)
        + at(y0, x0 + 1.0) * (1.0 - fy) * fx
        + at(y0 + 1.0, x0) * fy * (1.0 - fx)
        + at(y0 + 1.0, x0 + 1.0) * fy * fx
}

/// The split of a dataset of `len` pairs for `cfg`: a permutation seeded by `cfg.seed`, its first
/// `train_pairs` for training, the next `val_pairs` for validation, the next `test_pairs` for test.
pub fn split(len: usize, cfg: &RotestConfig) -> Result<[Vec<usize>; 3]> {
    let need = cfg.train_pairs + cfg.val_pairs + cfg.test_pairs;
    if need > len {
        return Err(RotestError::Config {
            field: "--train-pairs",
            message: format!(
                "{} training + {} validation + {} test pairs need {need} pairs; the dataset has {len}",
                cfg.train_pairs, cfg.val_pairs, cfg.test_pairs
            ),
        });
    }
    let mut order: Vec<usize> = (0..len).collect();
    order.shuffle(&mut ChaCha8Rng::seed_from_u64(cfg.seed));
    let t = cfg.train_pairs;
    let v = t + cfg.val_pairs;
    Ok([order[..t].to_vec(), order[t..v].to_vec(), order[v..need].to_vec()])
}

/// One epoch's numbers.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EpochRecord {
    /// Epoch, from 1.
    pub epoch: usize,
    /// Mean training cross-entropy.
    pub loss: f64,
    /// Training accuracy (on the augmented, cropped batches as trained).
    pub train_acc: f64,
    /// Validation accuracy (centre crop).
    pub val_acc: f64,
    /// Test accuracy (centre crop), measured only in epochs whose validation accuracy is a new
    /// best (the reported number is the test accuracy of the best validation epoch, so the other
    /// epochs' would only cost time: at N = 100 the test split was a quarter of an epoch).
    #[serde(default)]
    pub test_acc: Option<f64>,
    /// Wall time of the epoch including evaluation, s.
    pub seconds: f64,
}

/// A finished run: what `run.json` holds.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RotestRecord {
    /// The configuration.
    pub config: RotestConfig,
    /// The dataset's corruption setting.
    pub corrupt: String,
    /// The dataset's generator seed.
    pub data_seed: u64,
    /// Every epoch.
    pub history: Vec<EpochRecord>,
    /// Epoch of the best validation accuracy (the first, on ties).
    pub best_epoch: usize,
    /// Best validation accuracy.
    pub best_val_acc: f64,
    /// Test accuracy at the best validation epoch: the reported number.
    pub test_acc: f64,
    /// Training samples per epoch (with the image-transformation copies).
    pub train_samples: usize,
}

/// Accuracy of `model` on `s` (centre crop), evaluated in batches of `batch`.
pub fn accuracy<M: Classifier>(model: &M, s: &Samples, input: usize, batch: usize, device: &Device) -> f64 {
    let off = (s.side - input) / 2;
    let mut right = 0usize;
    let idx: Vec<usize> = (0..s.len()).collect();
    for chunk in idx.chunks(batch.max(1)) {
        let x = s.batch(chunk, &vec![(off, off); chunk.len()], input, device);
        let pred = argmax_rows(model.logits(x));
        right += chunk.iter().zip(&pred).filter(|(i, p)| s.y[**i] as usize == **p).count();
    }
    right as f64 / s.len().max(1) as f64
}

/// Agreement under rotation: `rotated[k]` holds the samples rotated by k·45° (k = 0…7, e.g. from
/// [`Samples::from_dataset_rotated`]); for each k, the fraction of samples whose predicted class is
/// the same as for `rotated[0]`, and the accuracy on `rotated[k]` (centre crops).
pub fn rotation_agreement<M: Classifier>(
    model: &M,
    rotated: &[Samples],
    input: usize,
    device: &Device,
) -> Vec<(f64, f64)> {
    let predict = |t: &Samples| -> Vec<usize> {
        let off = (t.side - input) / 2;
        let all: Vec<usize> = (0..t.len()).collect();
        all.chunks(64)
            .flat_map(|c| argmax_rows(model.logits(t.batch(c, &vec![(off, off); c.len()], input, device))))
            .collect()
    };
    let Some(first) = rotated.first() else { return Vec::new() };
    let base = predict(first);
    let n = first.len().max(1) as f64;
    rotated
        .iter()
        .map(|t| {
            let p = predict(t);
            let agree = p.iter().zip(&base).filter(|(a, b)| a == b).count() as f64 / n;
            let acc = p.iter().zip(&t.y).filter(|(a, b)| **a == **b as usize).count() as f64 / n;
            (agree, acc)
        })
        .collect()
}

/// The test split of a finished run and its best weights, evaluated by [`rotation_agreement`]; with
/// `disc`, every sample is first masked to the disc inscribed in the crop ([`Samples::mask_disc`]),
/// so that 45° rotations add no zero-filled corners.
pub fn run_agreement(
    ds: &Dataset,
    run_dir: &Path,
    device: &Device,
    disc: bool,
) -> Result<(RotestRecord, Vec<(f64, f64)>)> {
    let path = run_dir.join("run.json");
    let text = std::fs::read(&path).map_err(at(&path))?;
    let rec: RotestRecord = serde_json::from_slice(&text)
        .map_err(|e| RotestError::Format { path: path.clone(), message: format!("not a run file: {e}") })?;
    let cfg = &rec.config;
    cfg.validate()?;
    let [_, _, te] = split(ds.len(), cfg)?;
    let mut rotated: Vec<Samples> =
        (0..8).map(|k| Samples::from_dataset_rotated(ds, &te, cfg.full_side(), k)).collect::<Result<_>>()?;
    if disc {
        for r in &mut rotated {
            r.mask_disc(cfg.input as f32 / 2.0);
        }
    }
    let ncfg = net_config(cfg);
    let init = Init::new(cfg.seed);
    let weights = run_dir.join("best.safetensors");
    let res = match cfg.model {
        ClassifierKind::Equi => {
            let m = equiarm_nn::checkpoint::load(RotEquiNet::new(&ncfg, &init, device)?, &weights)?;
            rotation_agreement(&m, &rotated, cfg.input, device)
        }
        ClassifierKind::Cnn => {
            let m = equiarm_nn::checkpoint::load(RotCnnNet::new(&ncfg, &init, device)?, &weights)?;
            rotation_agreement(&m, &rotated, cfg.input, device)
        }
    };
    Ok((rec, res))
}

/// The index of the largest value of each row (the first, on ties).
pub fn argmax_rows(logits: Tensor<2>) -> Vec<usize> {
    let [_, c] = logits.dims();
    let v = logits.into_data().try_to_vec::<f32>().unwrap_or_default();
    v.chunks(c.max(1))
        .map(|row| row.iter().enumerate().fold((0, f32::NEG_INFINITY), |b, (i, &x)| if x > b.1 { (i, x) } else { b }).0)
        .collect()
}

/// How a run writes checkpoints and stops: options of the invocation, not of the run's config
/// (a run resumes under other ones).
#[derive(Clone, Copy)]
pub struct Checkpointing<'a> {
    /// Time between checkpoints (written at the end of the first epoch past it).
    pub every: Duration,
    /// Polled after each epoch: once true, the run writes a checkpoint and stops.
    pub stop: &'a dyn Fn() -> bool,
}

/// How [`run_with`] ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// The run finished: its record (also in `run.json`).
    Finished(RotestRecord),
    /// Stopped when asked, after `epoch` epochs, with a checkpoint in `RUN/resume/`: the same call
    /// continues it.
    Stopped {
        /// Epochs finished.
        epoch: usize,
    },
}

/// Where training stands: the network, the optimiser, the random stream, the epochs so far and the
/// best validation epoch with its weights (on the plain device).
struct Progress<M> {
    model: M,
    optim: Adam,
    rng: ChaCha8Rng,
    history: Vec<EpochRecord>,
    best: Option<(f64, usize, M)>,
}

impl<M: Classifier> Progress<M> {
    fn new(model: M, cfg: &RotestConfig) -> Self {
        Progress {
            model,
            optim: Adam::new(adam_params(cfg)),
            rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x7261_696e),
            history: Vec::new(),
            best: None,
        }
    }

    /// Writes the checkpoint of `run_dir`.
    fn save(&self, run_dir: &Path, cfg: &RotestConfig) -> Result<()> {
        let state = resume::ResumeState {
            config: cfg.clone(),
            epoch: self.history.len(),
            rng: resume::rng_state(&self.rng),
            history: self.history.clone(),
            best: self.best.as_ref().map(|b| (b.0, b.1)),
        };
        resume::write(run_dir, &state, &self.optim, |files| {
            equiarm_nn::checkpoint::save(&self.model, &files.model())?;
            if let Some(b) = &self.best {
                equiarm_nn::checkpoint::save(&b.2, &files.best())?;
            }
            Ok(())
        })
    }

    /// The progress of `run_dir`'s checkpoint, or a fresh start when it has none. `build` makes the
    /// network on a device (`device` is the plain one; training runs on its autodiff twin).
    fn start(
        run_dir: &Path,
        cfg: &RotestConfig,
        device: &Device,
        build: &dyn Fn(&Device) -> Result<M>,
    ) -> Result<Self> {
        let train_device = device.clone().autodiff();
        let Some(dir) = resume::find(run_dir) else {
            return Ok(Progress::new(build(&train_device)?, cfg));
        };
        let state = resume::read_state(&dir)?;
        if state.config != *cfg {
            return Err(RotestError::Format {
                path: dir,
                message: format!(
                    "this checkpoint is of another configuration ({:?} N={} img-trans {} seed {}, lr {}, \
                     epochs {}..{} patience {}, hidden {}, input {}): run with that configuration to \
                     continue it, or delete the directory to start this one over",
                    state.config.model,
                    state.config.train_pairs,
                    state.config.img_trans,
                    state.config.seed,
                    state.config.lr,
                    state.config.min_epochs,
                    state.config.max_epochs,
                    state.config.patience,
                    state.config.hidden,
                    state.config.input
                ),
            });
        }
        if state.history.len() != state.epoch || state.epoch == 0 || state.best.is_none() {
            return Err(RotestError::Format {
                path: dir,
                message: format!(
                    "damaged checkpoint: {} epochs finished but {} in its history{}",
                    state.epoch,
                    state.history.len(),
                    if state.best.is_none() { ", and no best epoch" } else { "" }
                ),
            });
        }
        let files = resume::Files::at(&dir);
        let model = equiarm_nn::checkpoint::load(build(&train_device)?, &files.model())?;
        let best = match state.best {
            Some((val, epoch)) => Some((val, epoch, equiarm_nn::checkpoint::load(build(device)?, &files.best())?)),
            None => None,
        };
        let optim = files.load_optim(adam_params(cfg), &model, device)?;
        let rng = resume::rng_from(&state.rng, &dir)?;
        Ok(Progress { model, optim, rng, history: state.history, best })
    }
}

/// Adam with the run's learning rate and burn's `epsilon` of 1e-5, which every run of this
/// experiment so far trained with (before it shared the SAC learner's optimiser; PyTorch's default,
/// and the authors', is 1e-8).
fn adam_params(cfg: &RotestConfig) -> AdamParams {
    AdamParams { eps: 1e-5, ..AdamParams::new(cfg.lr) }
}

/// How [`fit`] ended.
enum Fitted<M> {
    Done(M, Vec<EpochRecord>),
    Stopped(usize),
}

/// Trains the network of `p` (a fresh start or a checkpoint; on an autodiff device) on `train`,
/// evaluating on `val` and `test` after each epoch, and keeps the weights of the best validation
/// epoch; `on_epoch` sees each epoch's record. Writes checkpoints into the run directory with `ckpt`
/// (none without), and stops when it says.
#[allow(clippy::too_many_arguments)]
fn fit<M: Classifier>(
    mut p: Progress<M>,
    cfg: &RotestConfig,
    train: &Samples,
    val: &Samples,
    test: &Samples,
    device: &Device,
    ckpt: Option<(&Path, &Checkpointing)>,
    on_epoch: &mut dyn FnMut(&EpochRecord),
) -> Result<Fitted<M>> {
    let span = train.side - cfg.input;
    let centre = span / 2;
    let mut last_checkpoint = Instant::now();
    for epoch in p.history.len() + 1..=cfg.max_epochs {
        let t0 = Instant::now();
        let mut order: Vec<usize> = (0..train.len()).collect();
        order.shuffle(&mut p.rng);
        let (mut loss_sum, mut right) = (0.0f64, 0usize);
        for chunk in order.chunks(cfg.batch) {
            let offsets: Vec<(usize, usize)> = chunk
                .iter()
                .map(|_| {
                    if cfg.crop {
                        use rand::Rng;
                        (p.rng.random_range(0..=span), p.rng.random_range(0..=span))
                    } else {
                        (centre, centre)
                    }
                })
                .collect();
            let x = train.batch(chunk, &offsets, cfg.input, device);
            let mut onehot = vec![0f32; chunk.len() * CLASSES];
            for (r, &i) in chunk.iter().enumerate() {
                onehot[r * CLASSES + train.y[i] as usize] = 1.0;
            }
            let target = Tensor::<2>::from_data(TensorData::new(onehot, [chunk.len(), CLASSES]), device);
            let logits = p.model.logits(x);
            let pred = argmax_rows(logits.clone().detach());
            right += chunk.iter().zip(&pred).filter(|(i, p)| train.y[**i] as usize == **p).count();
            let loss = (log_softmax(logits, 1) * target).sum_dim(1).mean().neg();
            loss_sum += loss.clone().into_data().try_to_vec::<f32>().map(|v| v[0] as f64).unwrap_or(f64::NAN)
                * chunk.len() as f64;
            let grads = GradientsParams::from_grads(loss.backward(), &p.model);
            p.model = p.optim.step(p.model, grads);
        }
        let eval = p.model.valid();
        let plain = device.clone().inner();
        let val_acc = accuracy(&eval, val, cfg.input, cfg.batch, &plain);
        let improved = p.best.as_ref().is_none_or(|b| val_acc > b.0);
        let test_acc = improved.then(|| accuracy(&eval, test, cfg.input, cfg.batch, &plain));
        let rec = EpochRecord {
            epoch,
            loss: loss_sum / train.len().max(1) as f64,
            train_acc: right as f64 / train.len().max(1) as f64,
            val_acc,
            test_acc,
            seconds: t0.elapsed().as_secs_f64(),
        };
        on_epoch(&rec);
        p.history.push(rec);
        if improved {
            p.best = Some((val_acc, epoch, eval));
        }
        let best_epoch = p.best.as_ref().map_or(epoch, |b| b.1);
        if epoch >= cfg.min_epochs && epoch - best_epoch >= cfg.patience {
            break;
        }
        if let Some((run_dir, c)) = ckpt
            && epoch < cfg.max_epochs
        {
            let stop = (c.stop)();
            if stop || last_checkpoint.elapsed() >= c.every {
                p.save(run_dir, cfg)?;
                last_checkpoint = Instant::now();
            }
            if stop {
                return Ok(Fitted::Stopped(epoch));
            }
        }
    }
    let best_model = p.best.map(|b| b.2).unwrap_or_else(|| p.model.valid());
    Ok(Fitted::Done(best_model, p.history))
}

/// Trains the network `build` makes on the train, validation and test `splits`, from the checkpoint
/// in `out` if there is one, and saves its best weights to `out/best.safetensors` when it finishes.
fn train_net<M: Classifier>(
    build: &dyn Fn(&Device) -> Result<M>,
    cfg: &RotestConfig,
    [train, val, test]: [&Samples; 3],
    device: &Device,
    out: &Path,
    ckpt: Option<&Checkpointing>,
    on_epoch: &mut dyn FnMut(&EpochRecord),
) -> Result<Fitted<()>> {
    let start = Progress::start(out, cfg, device, build)?;
    match fit(start, cfg, train, val, test, &device.clone().autodiff(), ckpt.map(|c| (out, c)), on_epoch)? {
        Fitted::Done(m, history) => {
            equiarm_nn::checkpoint::save(&m, &out.join("best.safetensors"))?;
            Ok(Fitted::Done((), history))
        }
        Fitted::Stopped(epoch) => Ok(Fitted::Stopped(epoch)),
    }
}

/// Builds the network of `cfg` on `device`.
fn net_config(cfg: &RotestConfig) -> NetConfig {
    NetConfig::new(cfg.hidden, cfg.input, CHANNELS).with_numerics(Numerics::kernels(cfg.matmul))
}

/// The whole run on `device` (a plain device, e.g. from `equiarm_nn::device::open`; autodiff is
/// added here): split `ds`, prepare the samples (with the image-transformation copies), build the
/// network from `cfg.seed`, train it, write `out/run.json` and the best weights
/// `out/best.safetensors`. Returns the record. Continues from the checkpoint in `out` if there is
/// one, and writes none ([`run_with`] does).
pub fn run(
    ds: &Dataset,
    cfg: &RotestConfig,
    device: &Device,
    out: &Path,
    on_epoch: &mut dyn FnMut(&EpochRecord),
) -> Result<RotestRecord> {
    match run_with(ds, cfg, device, out, None, on_epoch)? {
        Outcome::Finished(r) => Ok(r),
        Outcome::Stopped { .. } => unreachable!("a run without checkpoints does not stop"),
    }
}

/// [`run`] with checkpoints (`crate::resume`) as `ckpt` says: every `ckpt.every`, and when
/// `ckpt.stop()` turns true, after which it returns [`Outcome::Stopped`]. A run that finishes
/// removes its checkpoint. Only one process trains in `out` at a time: a second is refused
/// ([`RotestError::Busy`]).
pub fn run_with(
    ds: &Dataset,
    cfg: &RotestConfig,
    device: &Device,
    out: &Path,
    ckpt: Option<&Checkpointing>,
    on_epoch: &mut dyn FnMut(&EpochRecord),
) -> Result<Outcome> {
    cfg.validate()?;
    cfg.matmul.supported().map_err(|message| RotestError::Config { field: "--matmul", message })?;
    let [tr, va, te] = split(ds.len(), cfg)?;
    let side = cfg.full_side();
    let mut train = Samples::from_dataset(ds, &tr, side)?;
    train.append_rotated_copies(ds, &tr[..cfg.img_trans])?;
    let val = Samples::from_dataset(ds, &va, side)?;
    let test = Samples::from_dataset(ds, &te, side)?;
    let _claim = match equiarm_train::rundir::RunDirLock::try_acquire(out) {
        Ok(Some(claim)) => claim,
        Ok(None) => return Err(RotestError::Busy { path: out.to_path_buf() }),
        // creating the directory or its lock file failed
        Err(e) => return Err(e.into()),
    };
    let init = Init::new(cfg.seed);
    let ncfg = net_config(cfg);
    let splits = [&train, &val, &test];
    let fitted = match cfg.model {
        ClassifierKind::Equi => {
            train_net(&|d| Ok(RotEquiNet::new(&ncfg, &init, d)?), cfg, splits, device, out, ckpt, on_epoch)?
        }
        ClassifierKind::Cnn => {
            train_net(&|d| Ok(RotCnnNet::new(&ncfg, &init, d)?), cfg, splits, device, out, ckpt, on_epoch)?
        }
    };
    let history = match fitted {
        Fitted::Done((), h) => h,
        Fitted::Stopped(epoch) => return Ok(Outcome::Stopped { epoch }),
    };
    let best = history
        .iter()
        .fold(None::<&EpochRecord>, |b, e| if b.is_none_or(|b| e.val_acc > b.val_acc) { Some(e) } else { b });
    let (best_epoch, best_val_acc, test_acc) =
        best.map_or((0, 0.0, 0.0), |b| (b.epoch, b.val_acc, b.test_acc.unwrap_or(f64::NAN)));
    let record = RotestRecord {
        config: cfg.clone(),
        corrupt: ds.header.corrupt.clone(),
        data_seed: ds.header.seed,
        history,
        best_epoch,
        best_val_acc,
        test_acc,
        train_samples: train.len(),
    };
    let path = out.join("run.json");
    let json = serde_json::to_vec_pretty(&record)
        .map_err(|e| RotestError::Format { path: path.clone(), message: e.to_string() })?;
    std::fs::write(&path, json).map_err(at(&path))?;
    resume::remove(out)?;
    Ok(Outcome::Finished(record))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::{Header, StoredImage, StoredPair};
    use equiarm_sim::rotest::{DuckPose, PairMeta};
    use half::f16;

    /// A 4 px pair whose pixel (r, c) has colour (r, c, 10·k) for image k and depth 0.9 + 0.01·(r + c).
    fn tiny() -> Dataset {
        let img = |k: u8| StoredImage {
            color: (0..16).flat_map(|i| [(i / 4) as u8, (i % 4) as u8, 10 * k]).collect(),
            depth: (0..16).map(|i| f16::from_f32(0.9 + 0.01 * ((i / 4) + (i % 4)) as f32)).collect(),
        };
        let pose = DuckPose { x: 0.45, y: 0.0, z: 0.0, yaw: 0.0 };
        let meta = PairMeta { idx: 3, label: 5, before: [pose; 3], after: [pose; 3], light_color: [1.0; 3] };
        Dataset {
            header: Header {
                size: 4,
                supersample: 1,
                corrupt: "none".into(),
                seed: 0,
                pairs: vec![meta],
                chunks: vec![],
            },
            pairs: vec![StoredPair { before: img(1), after: img(2) }],
        }
    }

    #[test]
    fn samples_stack_rgbd_of_both_images_area_averaged_and_batches_crop() {
        let ds = tiny();
        let s = Samples::from_dataset(&ds, &[0], 2).unwrap();
        assert_eq!((s.side, s.len(), s.y[0]), (2, 1, 5));
        let at = |ch: usize, r: usize, c: usize| s.x[ch * 4 + r * 2 + c];
        // R channel = row index averaged over the 2×2 block, /255: rows 0,1 → 0.5; rows 2,3 → 2.5
        assert!((at(0, 0, 1) - 0.5 / 255.0).abs() < 1e-7 && (at(0, 1, 0) - 2.5 / 255.0).abs() < 1e-7);
        // G channel = column index
        assert!((at(1, 1, 0) - 0.5 / 255.0).abs() < 1e-7 && (at(1, 0, 1) - 2.5 / 255.0).abs() < 1e-7);
        // B channel tells the images apart: 10 for image 1 (channel 2), 20 for image 2 (channel 6)
        assert!((at(2, 0, 0) - 10.0 / 255.0).abs() < 1e-7 && (at(6, 0, 0) - 20.0 / 255.0).abs() < 1e-7);
        // depth channel: block (0, 0) averages depths 0.90, 0.91, 0.91, 0.92 → (1 − 0.91)·5 = 0.45
        assert!((at(3, 0, 0) - 0.45).abs() < 2e-3, "{}", at(3, 0, 0));
        assert_eq!(at(7, 1, 1), at(3, 1, 1));
        assert!(Samples::from_dataset(&ds, &[0], 3).unwrap_err().to_string().contains("--input"));
        // a 1 px crop at (1, 0) of every channel
        let full = Samples::from_dataset(&ds, &[0], 4).unwrap();
        let b = full.batch(&[0], &[(1, 0)], 1, &Device::flex());
        let v = b.into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(v.len(), 8);
        assert!((v[0] - 1.0 / 255.0).abs() < 1e-7 && v[1] == 0.0, "{v:?}");
    }
}
