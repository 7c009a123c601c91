//! Prioritised experience replay with expert retention, as the authors' `PrioritizedQLearningBuffer`
//! over `QLearningBufferExpert` (docs/paper.md §2): proportional PER with a sum tree and a min tree over
//! the slots (OpenAI baselines' scheme: stratified sampling, p^α in the trees, max-priority insertion,
//! importance weights normalised by the largest weight), a ring buffer whose write pointer skips
//! expert slots so demonstrations are never evicted, and checkpoint persistence.
//!
//! Frames are shared by [`Arc`]: transition t's `next_obs` is transition t+1's `obs`, so a frame is
//! stored once and freed when no transition refers to it (docs/architecture.md#memory-budget).
//!
//! ## Limitations
//!
//! - Single-threaded; the learner owns the buffer (wrap it in a lock to share it).
//! - The importance weights are computed as baselines does; the paper's training does not use them
//!   (docs/paper.md §7.5), so using them is the caller's choice.
//! - The checkpoint format ([`Replay::save`]) is this crate's own (versioned, little-endian, zstd);
//!   it is not the authors' pickle. Capacity is limited to [`MAX_CAPACITY`] slots.

use std::collections::HashMap;
use std::fs::File;
use std::io::{self, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use half::f16;
use serde::{Deserialize, Serialize};

use crate::frame::StoredFrame;
use crate::schedule::LinearSchedule;
use equiarm_types::NormalizedAction;
use equiarm_types::files::{FileError, write_atomically};

/// The largest capacity accepted (2²⁴ slots); keeps a corrupted config from asking for a huge tree.
pub const MAX_CAPACITY: usize = 1 << 24;

/// Errors from the replay buffer and its checkpoint files.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// Writing a checkpoint failed (the file, and the cause).
    #[error(transparent)]
    File(#[from] FileError),
    /// A configuration field has an invalid value.
    #[error("replay config: `{field}` = {value} is invalid: {reason}")]
    Config {
        /// The field's name as in the config file.
        field: &'static str,
        /// The value given.
        value: String,
        /// What is allowed.
        reason: &'static str,
    },
    /// The buffer is full and every slot holds an expert transition, so nothing may be evicted.
    #[error("replay buffer is full of expert transitions ({capacity} slots); nothing can be overwritten")]
    AllExpert {
        /// The buffer's capacity.
        capacity: usize,
    },
    /// A pushed transition has a non-finite reward or action component.
    #[error("transition {what} is not finite: {value}")]
    NonFinite {
        /// `"reward"` or `"action[k]"`.
        what: String,
        /// The offending value.
        value: f32,
    },
    /// Sampling from an empty buffer.
    #[error("cannot sample from an empty replay buffer")]
    Empty,
    /// β outside [0, 1] or not finite.
    #[error("PER beta {beta} is outside [0, 1]")]
    BadBeta {
        /// The β given.
        beta: f64,
    },
    /// The sum of the priorities is zero or not finite (for example after an overflow of p^α).
    #[error("total priority mass {total} cannot be sampled")]
    BadMass {
        /// The sum tree's total.
        total: f64,
    },
    /// A slot index is not filled.
    #[error("slot {slot} is out of range (buffer holds {len})")]
    SlotOutOfRange {
        /// The slot given.
        slot: usize,
        /// Slots filled.
        len: usize,
    },
    /// `slots` and `td_abs` of a priority update differ in length.
    #[error("{slots} slots but {td} TD errors")]
    LengthMismatch {
        /// Number of slots.
        slots: usize,
        /// Number of TD errors.
        td: usize,
    },
    /// A priority update's TD error is not finite, or makes p^α not finite.
    #[error("priority update for slot {slot}: TD error {td} gives an unusable priority")]
    BadTd {
        /// The slot concerned.
        slot: usize,
        /// The TD error given.
        td: f32,
    },
    /// Reading or writing a checkpoint file failed at the OS level.
    #[error("{op} {}: {cause}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What was being done (`"creating"`, `"opening"`, ...).
        op: &'static str,
        /// The OS error.
        cause: io::Error,
    },
    /// A checkpoint file is not a replay checkpoint, is of another version, or is truncated or corrupt.
    #[error("replay checkpoint {}: {reason}", path.display())]
    Format {
        /// The file.
        path: PathBuf,
        /// What was wrong.
        reason: String,
    },
}

/// Replay buffer settings (docs/paper.md §2 defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReplayConfig {
    /// Number of transition slots (paper: 100,000). Expert transitions are never evicted.
    pub capacity: usize,
    /// PER exponent α: sampling probability ∝ p^α (paper: 0.6; 0 is uniform).
    pub alpha: f64,
    /// Importance-sampling exponent β at the start of training (paper: 0.4).
    pub beta_start: f64,
    /// β at the end of training, reached linearly (paper: 1.0).
    pub beta_end: f64,
    /// Added to every priority so no transition has zero probability (paper: 1e-6).
    pub priority_eps: f64,
    /// Added to the priority of expert transitions (paper: 1.0).
    pub expert_bonus: f64,
}

impl Default for ReplayConfig {
    fn default() -> Self {
        ReplayConfig {
            capacity: 100_000,
            alpha: 0.6,
            beta_start: 0.4,
            beta_end: 1.0,
            priority_eps: 1e-6,
            expert_bonus: 1.0,
        }
    }
}

impl ReplayConfig {
    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ReplayError> {
        let bad = |field, value: String, reason| Err(ReplayError::Config { field, value, reason });
        if self.capacity == 0 || self.capacity > MAX_CAPACITY {
            return bad("capacity", self.capacity.to_string(), "must be in 1..=16777216");
        }
        if !(self.alpha.is_finite() && self.alpha >= 0.0) {
            return bad("alpha", self.alpha.to_string(), "must be finite and >= 0");
        }
        for (field, v) in [("beta_start", self.beta_start), ("beta_end", self.beta_end)] {
            if !(0.0..=1.0).contains(&v) {
                return bad(field, v.to_string(), "must be in [0, 1]");
            }
        }
        if !(self.priority_eps.is_finite() && self.priority_eps > 0.0) {
            return bad("priority_eps", self.priority_eps.to_string(), "must be finite and > 0");
        }
        if !(self.expert_bonus.is_finite() && self.expert_bonus >= 0.0) {
            return bad("expert_bonus", self.expert_bonus.to_string(), "must be finite and >= 0");
        }
        Ok(())
    }

    /// β at training progress `progress` ∈ [0, 1] (clamped; NaN counts as 0), linear from
    /// `beta_start` to `beta_end`.
    pub fn beta(&self, progress: f64) -> f64 {
        let p = if progress.is_nan() { 0.0 } else { progress.clamp(0.0, 1.0) };
        self.beta_start + (self.beta_end - self.beta_start) * p
    }

    /// The β schedule over `steps` training steps as a [`LinearSchedule`].
    pub fn beta_schedule(&self, steps: u64) -> LinearSchedule {
        LinearSchedule { start: self.beta_start, end: self.beta_end, steps }
    }
}

/// One stored transition. Frames are shared with neighbouring transitions through [`Arc`].
#[derive(Debug, Clone)]
pub struct Stored {
    /// Observation at time t.
    pub obs: Arc<StoredFrame>,
    /// Observation at time t+1.
    pub next_obs: Arc<StoredFrame>,
    /// Normalised action in [-1, 1], order (p, dx, dy, dz, dθ) (docs/paper.md §1.2).
    pub action: NormalizedAction,
    /// Reward received.
    pub reward: f32,
    /// Terminal for the bootstrap (the caller decides whether timeouts count; the paper's do).
    pub done: bool,
    /// Whether the transition comes from a planner demonstration.
    pub expert: bool,
}

/// A sampled batch: slot indices and their normalised importance weights.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Sampled slots (may repeat).
    pub slots: Vec<usize>,
    /// Importance weights `(N·P(i))^(−β) / max_j (N·P(j))^(−β)`, in (0, 1].
    pub weights: Vec<f32>,
}

/// Sum and min segment trees over a power-of-two number of leaves (1-indexed heap layout).
#[derive(Debug, Clone)]
struct Trees {
    leaves: usize,
    sum: Vec<f64>,
    min: Vec<f64>,
}

impl Trees {
    fn new(capacity: usize) -> Trees {
        let leaves = capacity.next_power_of_two();
        Trees { leaves, sum: vec![0.0; 2 * leaves], min: vec![f64::INFINITY; 2 * leaves] }
    }

    fn set(&mut self, slot: usize, value: f64) {
        let mut n = self.leaves + slot;
        self.sum[n] = value;
        self.min[n] = value;
        while n > 1 {
            n /= 2;
            self.sum[n] = self.sum[2 * n] + self.sum[2 * n + 1];
            self.min[n] = self.min[2 * n].min(self.min[2 * n + 1]);
        }
    }

    fn get(&self, slot: usize) -> f64 {
        self.sum[self.leaves + slot]
    }

    fn total(&self) -> f64 {
        self.sum[1]
    }

    fn min(&self) -> f64 {
        self.min[1]
    }

    /// The leaf where the prefix sum passes `mass`. Never lands on a zero-mass leaf when the total
    /// is positive, even if rounding puts `mass` at or past the total.
    fn find(&self, mut mass: f64) -> usize {
        let mut n = 1;
        while n < self.leaves {
            let left = self.sum[2 * n];
            if mass < left || self.sum[2 * n + 1] <= 0.0 {
                n *= 2;
            } else {
                mass -= left;
                n = 2 * n + 1;
            }
        }
        n - self.leaves
    }
}

/// Prioritised replay buffer with expert retention (see the module documentation).
#[derive(Debug, Clone)]
pub struct Replay {
    cfg: ReplayConfig,
    slots: Vec<Stored>,
    /// Raw priority p of each filled slot (the trees hold p^α).
    priorities: Vec<f64>,
    /// Where the search for the next slot to write starts.
    next: usize,
    expert_len: usize,
    max_priority: f64,
    trees: Trees,
}

impl Replay {
    /// An empty buffer; errors if the config is invalid.
    pub fn new(cfg: ReplayConfig) -> Result<Replay, ReplayError> {
        cfg.validate()?;
        Ok(Replay {
            trees: Trees::new(cfg.capacity),
            slots: Vec::new(),
            priorities: Vec::new(),
            next: 0,
            expert_len: 0,
            max_priority: 1.0,
            cfg,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &ReplayConfig {
        &self.cfg
    }

    /// Stores a transition at the current maximum priority and returns its slot. When full, the
    /// oldest non-expert slot is overwritten (the ring pointer skips expert slots).
    ///
    /// Errors: a non-finite reward or action ([`ReplayError::NonFinite`]); a full buffer holding
    /// only expert transitions ([`ReplayError::AllExpert`]). Nothing changes on error.
    pub fn push(&mut self, t: Stored) -> Result<usize, ReplayError> {
        if !t.reward.is_finite() {
            return Err(ReplayError::NonFinite { what: "reward".into(), value: t.reward });
        }
        if let Some(k) = t.action.iter().position(|a| !a.is_finite()) {
            return Err(ReplayError::NonFinite { what: format!("action[{k}]"), value: t.action[k] });
        }
        let cap = self.cfg.capacity;
        let p = self.max_priority;
        let expert = t.expert;
        let slot = if self.slots.len() < cap {
            self.slots.push(t);
            self.priorities.push(p);
            self.slots.len() - 1
        } else {
            if self.expert_len >= cap {
                return Err(ReplayError::AllExpert { capacity: cap });
            }
            let slot = (0..cap)
                .map(|k| (self.next + k) % cap)
                .find(|&i| !self.slots[i].expert)
                .ok_or(ReplayError::AllExpert { capacity: cap })?;
            self.slots[slot] = t;
            self.priorities[slot] = p;
            slot
        };
        if expert {
            self.expert_len += 1;
        }
        self.trees.set(slot, p.powf(self.cfg.alpha));
        self.next = (slot + 1) % cap;
        Ok(slot)
    }

    /// Draws `batch` slots with probability p^α / Σp^α by baselines' stratified scheme (the total
    /// mass split into `batch` equal segments, one uniform draw in each) and their importance
    /// weights for exponent `beta`. `batch = 0` gives an empty sample.
    ///
    /// Errors: empty buffer, β outside [0, 1], or a total mass that is zero or not finite.
    pub fn sample(&self, batch: usize, beta: f64, rng: &mut impl rand::Rng) -> Result<Sample, ReplayError> {
        if self.slots.is_empty() {
            return Err(ReplayError::Empty);
        }
        if !(0.0..=1.0).contains(&beta) {
            return Err(ReplayError::BadBeta { beta });
        }
        let total = self.trees.total();
        if !(total.is_finite() && total > 0.0) {
            return Err(ReplayError::BadMass { total });
        }
        let n = self.slots.len() as f64;
        let segment = total / batch as f64;
        let max_weight = (self.trees.min() / total * n).powf(-beta);
        let mut slots = Vec::with_capacity(batch);
        let mut weights = Vec::with_capacity(batch);
        for i in 0..batch {
            let mass = rng.random::<f64>() * segment + i as f64 * segment;
            let slot = self.trees.find(mass);
            debug_assert!(slot < self.slots.len());
            let w = (self.trees.get(slot) / total * n).powf(-beta) / max_weight;
            slots.push(slot);
            weights.push(w as f32);
        }
        Ok(Sample { slots, weights })
    }

    /// Sets p = |td| + expert_bonus·expert + priority_eps for each slot (the trees store p^α) and
    /// raises the maximum priority. A repeated slot takes its last value.
    ///
    /// Errors (nothing is updated): lengths differ, a slot is not filled, or a TD error is not
    /// finite or gives a non-finite p^α.
    pub fn update_priorities(&mut self, slots: &[usize], td_abs: &[f32]) -> Result<(), ReplayError> {
        if slots.len() != td_abs.len() {
            return Err(ReplayError::LengthMismatch { slots: slots.len(), td: td_abs.len() });
        }
        let mut new = Vec::with_capacity(slots.len());
        for (&slot, &td) in slots.iter().zip(td_abs) {
            let stored = self.slots.get(slot).ok_or(ReplayError::SlotOutOfRange { slot, len: self.slots.len() })?;
            let p = self.raw_priority(td, stored.expert);
            let pa = p.powf(self.cfg.alpha);
            if !(td.is_finite() && p.is_finite() && pa.is_finite()) {
                return Err(ReplayError::BadTd { slot, td });
            }
            new.push((slot, p, pa));
        }
        for (slot, p, pa) in new {
            self.priorities[slot] = p;
            self.trees.set(slot, pa);
            self.max_priority = self.max_priority.max(p);
        }
        Ok(())
    }

    fn raw_priority(&self, td: f32, expert: bool) -> f64 {
        let bonus = if expert { self.cfg.expert_bonus } else { 0.0 };
        f64::from(td.abs()) + bonus + self.cfg.priority_eps
    }

    /// The transition in `slot`, if filled.
    pub fn get(&self, slot: usize) -> Option<&Stored> {
        self.slots.get(slot)
    }

    /// Number of filled slots.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether no slot is filled.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }

    /// Number of slots holding expert transitions.
    pub fn expert_len(&self) -> usize {
        self.expert_len
    }

    /// Number of slots.
    pub fn capacity(&self) -> usize {
        self.cfg.capacity
    }

    /// The raw priority p of `slot` (before ^α); 0 for a slot not filled.
    pub fn priority(&self, slot: usize) -> f64 {
        self.priorities.get(slot).copied().unwrap_or(0.0)
    }

    /// The largest priority seen (initially 1.0); new transitions get it.
    pub fn max_priority(&self) -> f64 {
        self.max_priority
    }

    /// Σ p^α over the filled slots (the sum tree's root).
    pub fn total_mass(&self) -> f64 {
        self.trees.total()
    }

    /// The slot where the ring search for the next overwrite starts (equals `len()` until full).
    pub fn ring_pointer(&self) -> usize {
        self.next
    }

    /// β at training progress ∈ [0, 1]; see [`ReplayConfig::beta`].
    pub fn beta(&self, progress: f64) -> f64 {
        self.cfg.beta(progress)
    }

    /// Number of distinct frames referred to (by `Arc` pointer).
    pub fn unique_frames(&self) -> usize {
        self.frame_set().len()
    }

    /// Heap bytes of the distinct frames referred to, each counted once (by `Arc` pointer).
    pub fn unique_frame_bytes(&self) -> usize {
        self.frame_set().values().map(|f| f.heap_bytes()).sum()
    }

    fn frame_set(&self) -> HashMap<*const StoredFrame, &StoredFrame> {
        let mut set = HashMap::new();
        for t in &self.slots {
            for f in [&t.obs, &t.next_obs] {
                set.insert(Arc::as_ptr(f), &**f);
            }
        }
        set
    }

    /// Writes a checkpoint of the whole buffer to `path` (via `path.tmp` and a rename) and returns
    /// its size in bytes. Each distinct frame is written once; the body is zstd-compressed with a
    /// checksum. See the format notes on [`Replay::load`].
    pub fn save(&self, path: &Path) -> Result<u64, ReplayError> {
        write_atomically(path, |w| self.write_to(w))?;
        let bytes = std::fs::metadata(path)
            .map_err(|cause| ReplayError::Io { path: path.to_owned(), op: "reading metadata of", cause })?
            .len();
        Ok(bytes)
    }

    fn write_to(&self, w: &mut impl Write) -> io::Result<()> {
        w.write_all(MAGIC)?;
        w.write_all(&VERSION.to_le_bytes())?;
        let mut z = zstd::Encoder::new(w, ZSTD_LEVEL)?;
        z.include_checksum(true)?;
        let json = serde_json::to_vec(&self.cfg).map_err(io::Error::other)?;
        put_u32(&mut z, json.len() as u32)?;
        z.write_all(&json)?;
        put_u64(&mut z, self.slots.len() as u64)?;
        put_u64(&mut z, self.next as u64)?;
        put_u64(&mut z, self.expert_len as u64)?;
        z.write_all(&self.max_priority.to_le_bytes())?;

        // Frames, each once, in order of first reference.
        let mut index: HashMap<*const StoredFrame, u32> = HashMap::new();
        let mut order: Vec<&StoredFrame> = Vec::new();
        let mut refs: Vec<(u32, u32)> = Vec::with_capacity(self.slots.len());
        for t in &self.slots {
            let mut pair = [0u32; 2];
            for (k, f) in [&t.obs, &t.next_obs].into_iter().enumerate() {
                let fresh = order.len() as u32;
                let id = *index.entry(Arc::as_ptr(f)).or_insert(fresh);
                if id == fresh {
                    order.push(&**f);
                }
                pair[k] = id;
            }
            refs.push((pair[0], pair[1]));
        }
        put_u64(&mut z, order.len() as u64)?;
        let mut depth_bytes = Vec::new();
        for f in order {
            put_u32(&mut z, f.size() as u32)?;
            z.write_all(&[u8::from(f.holding())])?;
            z.write_all(f.color())?;
            depth_bytes.clear();
            depth_bytes.extend(f.depth().iter().flat_map(|d| d.to_bits().to_le_bytes()));
            z.write_all(&depth_bytes)?;
        }
        for ((t, &(obs, next_obs)), &p) in self.slots.iter().zip(&refs).zip(&self.priorities) {
            put_u32(&mut z, obs)?;
            put_u32(&mut z, next_obs)?;
            for a in t.action {
                z.write_all(&a.to_le_bytes())?;
            }
            z.write_all(&t.reward.to_le_bytes())?;
            z.write_all(&[u8::from(t.done), u8::from(t.expert)])?;
            z.write_all(&p.to_le_bytes())?;
        }
        z.write_all(TRAILER)?;
        z.finish()?;
        Ok(())
    }

    /// Loads a checkpoint written by [`Replay::save`]; frame sharing is restored, and the
    /// priorities, trees, ring pointer and maximum priority are exactly as saved.
    ///
    /// Format (version 1, little-endian): `MAGIC` (8 bytes) and a `u32` version, then one zstd
    /// stream holding: config JSON (`u32` length + bytes), `u64` len, `u64` ring pointer, `u64`
    /// expert count, `f64` max priority, `u64` frame count, the frames (`u32` size, `u8` holding,
    /// rgb8, `f16` depth bits), the transitions in slot order (`u32` obs and next_obs frame
    /// indices, 5 `f32` action, `f32` reward, `u8` done, `u8` expert, `f64` priority) and a trailer.
    ///
    /// Errors name the file and what was wrong: wrong magic, unsupported version, truncation,
    /// checksum or decompression failure, or a value out of range.
    pub fn load(path: &Path) -> Result<Replay, ReplayError> {
        let file = File::open(path).map_err(|cause| ReplayError::Io { path: path.to_owned(), op: "opening", cause })?;
        let mut r = BufReader::with_capacity(1 << 20, file);
        let fmt = |reason: Corrupt| ReplayError::Format { path: path.to_owned(), reason: reason.0 };
        let mut head = [0u8; 12];
        read_exact(&mut r, &mut head, "header").map_err(fmt)?;
        if &head[..8] != MAGIC {
            return Err(fmt(Corrupt(format!("not a replay checkpoint (magic bytes {:02x?})", &head[..8]))));
        }
        let version = u32::from_le_bytes([head[8], head[9], head[10], head[11]]);
        if version != VERSION {
            return Err(fmt(Corrupt(format!(
                "format version {version} is not supported (this build reads {VERSION})"
            ))));
        }
        let z = zstd::Decoder::with_buffer(r).map_err(|e| fmt(Corrupt(format!("starting zstd: {e}"))))?;
        read_body(z).map_err(fmt)
    }
}

const MAGIC: &[u8; 8] = b"EQARMRPL";
const TRAILER: &[u8; 8] = b"RPL-END\0";
const VERSION: u32 = 1;
const ZSTD_LEVEL: i32 = 1;
const MAX_CONFIG_JSON: usize = 1 << 16;

fn put_u32(w: &mut impl Write, v: u32) -> io::Result<()> {
    w.write_all(&v.to_le_bytes())
}

fn put_u64(w: &mut impl Write, v: u64) -> io::Result<()> {
    w.write_all(&v.to_le_bytes())
}

/// Why a replay checkpoint's body cannot be read (becomes [`ReplayError::Format`], which names the file).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Corrupt(String);

impl From<String> for Corrupt {
    fn from(reason: String) -> Self {
        Corrupt(reason)
    }
}

fn read_exact(r: &mut impl Read, buf: &mut [u8], what: &str) -> Result<(), Corrupt> {
    r.read_exact(buf).map_err(|e| {
        Corrupt(if e.kind() == io::ErrorKind::UnexpectedEof {
            format!("truncated while reading {what}")
        } else {
            format!("reading {what}: {e}")
        })
    })
}

fn get<const N: usize>(r: &mut impl Read, what: &str) -> Result<[u8; N], Corrupt> {
    let mut b = [0u8; N];
    read_exact(r, &mut b, what)?;
    Ok(b)
}

fn get_u64(r: &mut impl Read, what: &str) -> Result<u64, Corrupt> {
    get::<8>(r, what).map(u64::from_le_bytes)
}

fn get_u32(r: &mut impl Read, what: &str) -> Result<u32, Corrupt> {
    get::<4>(r, what).map(u32::from_le_bytes)
}

fn get_f32(r: &mut impl Read, what: &str) -> Result<f32, Corrupt> {
    get::<4>(r, what).map(f32::from_le_bytes)
}

fn get_f64(r: &mut impl Read, what: &str) -> Result<f64, Corrupt> {
    get::<8>(r, what).map(f64::from_le_bytes)
}

fn get_bool(r: &mut impl Read, what: &str) -> Result<bool, Corrupt> {
    match get::<1>(r, what)?[0] {
        0 => Ok(false),
        1 => Ok(true),
        b => Err(format!("{what} is {b}, not 0 or 1").into()),
    }
}

/// Reads a count and checks it against `max` before anything is allocated for it.
fn get_count(r: &mut impl Read, what: &str, max: u64) -> Result<usize, Corrupt> {
    let n = get_u64(r, what)?;
    if n > max {
        return Err(format!("{what} {n} exceeds its limit {max}").into());
    }
    Ok(n as usize)
}

fn read_body(mut r: impl Read) -> Result<Replay, Corrupt> {
    let json_len = get_u32(&mut r, "config length")? as usize;
    if json_len > MAX_CONFIG_JSON {
        return Err(format!("config length {json_len} exceeds {MAX_CONFIG_JSON}").into());
    }
    let mut json = vec![0u8; json_len];
    read_exact(&mut r, &mut json, "config")?;
    let cfg: ReplayConfig = serde_json::from_slice(&json).map_err(|e| format!("config JSON: {e}"))?;
    let mut replay = Replay::new(cfg).map_err(|e| Corrupt(e.to_string()))?;
    let cap = replay.cfg.capacity;

    let len = get_count(&mut r, "transition count", cap as u64)?;
    let next = get_count(&mut r, "ring pointer", cap as u64 - 1)?;
    if len < cap && next != len {
        return Err(format!("ring pointer {next} with {len} of {cap} slots filled").into());
    }
    let expert_len = get_count(&mut r, "expert count", len as u64)?;
    let max_priority = get_f64(&mut r, "max priority")?;
    if !(max_priority.is_finite() && max_priority >= 1.0) {
        return Err(format!("max priority {max_priority} is not finite and >= 1").into());
    }

    let n_frames = get_count(&mut r, "frame count", 2 * len as u64)?;
    let mut frames = Vec::new();
    let mut depth_bytes = Vec::new();
    for i in 0..n_frames {
        let size = get_u32(&mut r, "frame size")? as usize;
        if size == 0 || size > StoredFrame::MAX_SIZE {
            return Err(format!("frame {i}: size {size} outside 1..={}", StoredFrame::MAX_SIZE).into());
        }
        let holding = get_bool(&mut r, "frame holding flag")?;
        let mut color = vec![0u8; size * size * 3];
        read_exact(&mut r, &mut color, "frame colour")?;
        depth_bytes.resize(size * size * 2, 0);
        read_exact(&mut r, &mut depth_bytes, "frame depth")?;
        let depth = depth_bytes.chunks_exact(2).map(|b| f16::from_bits(u16::from_le_bytes([b[0], b[1]]))).collect();
        let frame = StoredFrame::from_f16(size, color, depth, holding).map_err(|e| format!("frame {i}: {e}"))?;
        frames.push(Arc::new(frame));
    }

    let mut seen_expert = 0;
    for slot in 0..len {
        let mut frame = |what| -> Result<Arc<StoredFrame>, Corrupt> {
            let k = get_u32(&mut r, what)? as usize;
            frames
                .get(k)
                .cloned()
                .ok_or_else(|| Corrupt(format!("slot {slot}: {what} index {k} >= frame count {n_frames}")))
        };
        let obs = frame("obs frame")?;
        let next_obs = frame("next_obs frame")?;
        let mut action = [0.0f32; 5];
        for a in &mut action {
            *a = get_f32(&mut r, "action")?;
        }
        let reward = get_f32(&mut r, "reward")?;
        let done = get_bool(&mut r, "done flag")?;
        let expert = get_bool(&mut r, "expert flag")?;
        let p = get_f64(&mut r, "priority")?;
        if !(p.is_finite() && p > 0.0 && p <= max_priority) {
            return Err(format!("slot {slot}: priority {p} not in (0, max priority {max_priority}]").into());
        }
        seen_expert += usize::from(expert);
        let t = Stored { obs, next_obs, action, reward, done, expert };
        replay.push(t).map_err(|e| format!("slot {slot}: {e}"))?;
        replay.priorities[slot] = p;
        replay.trees.set(slot, p.powf(replay.cfg.alpha));
    }
    if seen_expert != expert_len {
        return Err(format!("expert count {expert_len} but {seen_expert} expert transitions").into());
    }
    let trailer: [u8; 8] = get(&mut r, "trailer")?;
    if &trailer != TRAILER {
        return Err(Corrupt::from("bad trailer (corrupt body)".to_string()));
    }
    // Read to the end of the zstd frame so its checksum is verified and nothing follows.
    let mut extra = [0u8; 1];
    match r.read(&mut extra) {
        Ok(0) => {}
        Ok(_) => return Err(Corrupt::from("unexpected data after the trailer".to_string())),
        Err(e) => return Err(format!("checking the end of the compressed stream: {e}").into()),
    }
    replay.next = next;
    replay.max_priority = max_priority;
    Ok(replay)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn every_tree_node_is_the_sum_and_min_of_its_leaves() {
        let mut t = Trees::new(13);
        assert_eq!(t.leaves, 16);
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut leaf = [0.0f64; 16];
        let mut leaf_min = [f64::INFINITY; 16];
        for _ in 0..500 {
            let i = rand::Rng::random_range(&mut rng, 0..13);
            let v: f64 = rand::Rng::random(&mut rng);
            t.set(i, v);
            leaf[i] = v;
            leaf_min[i] = v;
        }
        for n in 1..16usize {
            // The leaves under node n.
            let depth = n.ilog2();
            let width = 16 >> depth;
            let first = (n - (1 << depth)) * width;
            let s: f64 = leaf[first..first + width].iter().sum();
            assert!((t.sum[n] - s).abs() <= 1e-12 * s.max(1.0), "sum at node {n}: {} vs {s}", t.sum[n]);
            let m = leaf_min[first..first + width].iter().copied().fold(f64::INFINITY, f64::min);
            assert_eq!(t.min[n], m, "min at node {n}");
        }
    }

    #[test]
    fn find_never_returns_an_empty_leaf() {
        let mut t = Trees::new(8);
        t.set(0, 1.0);
        t.set(2, 2.0);
        assert_eq!(t.find(0.0), 0);
        assert_eq!(t.find(0.999), 0);
        assert_eq!(t.find(1.0), 2);
        assert_eq!(t.find(3.0), 2); // at the total (rounding): last filled leaf
        assert_eq!(t.find(1e9), 2);
    }
}
