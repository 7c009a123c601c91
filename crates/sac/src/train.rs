//! The transport-free training loop (`equiarm train --in-process`): N envs stepped in this
//! process, expert demonstrations first (successful episodes only), one update per vectorised
//! step (docs/paper.md §2: 1 update per N transitions), a greedy evaluation over fixed seeds every
//! `eval_every` updates, CleanRL-named metrics, a learning-curve PNG and checkpoints with exact
//! resume.
//!
//! Exact resume: a checkpoint also records, per env, the seed of its current episode and the
//! actions taken in it so far; resuming resets each env with that seed and replays the actions
//! (the simulator is deterministic), so K updates straight and K/2 + checkpoint + resume + K/2
//! give bit-identical weights on one machine (tested on the CPU; [`RunOptions::device`] picks a GPU).
//!
//! Episode seeds: training episode `e` of env `i` uses [`episode_seed`]`(seed, i, e)`; demos use
//! env index `u32::MAX`; evaluation episode `j` uses `episode_seed(seed ^ EVAL, 0, j)`, the same at
//! every evaluation.
//!
//! Limitations: envs are stepped one after another on the calling thread (stepping costs ~1 ms,
//! an update hundreds of ms on a CPU).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use equiarm_nn::burn::tensor::Device;
use equiarm_sim::{Action, Env, EnvConfig, Observation, TaskKind, ViewPreset};
use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::agent::ActMode;
use crate::config::TrainConfig;
use crate::frame::StoredFrame;
use crate::learner::{Learner, LearnerError, read_json, write_json};
use crate::metrics::MetricsWriter;
use crate::replay::Stored;

/// Mixed into the seed of evaluation episodes.
pub const EVAL: u64 = 0x6576_616c;

/// Training-loop errors.
#[derive(Debug, Error)]
pub enum TrainError {
    /// The learner failed.
    #[error(transparent)]
    Learner(#[from] LearnerError),
    /// The simulator failed.
    #[error("simulator: {0}")]
    Sim(#[from] equiarm_sim::SimError),
    /// A frame could not be stored.
    #[error("frame: {0}")]
    Frame(#[from] crate::frame::FrameError),
    /// Run-directory I/O.
    #[error("{path}: {message}")]
    Io {
        /// File or directory.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The expert did not produce enough successful demos.
    #[error("the expert succeeded in {got} of {tried} demo episodes; {want} needed")]
    Demos {
        /// Successes.
        got: usize,
        /// Episodes tried.
        tried: usize,
        /// Needed.
        want: usize,
    },
}

/// The seed of episode `episode` of env `env` in a run seeded `seed` (splitmix64 of a mix).
pub fn episode_seed(seed: u64, env: u32, episode: u64) -> u64 {
    let mut z = seed ^ ((env as u64) << 40) ^ episode.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The env config of a run.
pub fn env_config(cfg: &TrainConfig) -> EnvConfig {
    let task = TaskKind::from_name(&cfg.task).unwrap_or(TaskKind::BlockPulling);
    let mut e = EnvConfig::new(task);
    if let Some(v) = ViewPreset::from_name(&cfg.view) {
        e.camera = v.config();
    }
    e.camera.width = cfg.image_size;
    e.camera.height = cfg.image_size;
    e.max_steps = cfg.max_episode_steps;
    e
}

/// A simulator observation as a stored frame.
pub fn frame_of(obs: &Observation) -> Result<Arc<StoredFrame>, TrainError> {
    if obs.width != obs.height {
        return Err(TrainError::Io {
            path: PathBuf::new(),
            message: format!("frame is {}×{}, must be square", obs.width, obs.height),
        });
    }
    Ok(Arc::new(StoredFrame::new(obs.width, obs.color.clone(), &obs.depth, obs.holding)?))
}

/// Result of one greedy evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EvalResult {
    /// Updates made when evaluated.
    pub updates: u64,
    /// Episodes run.
    pub episodes: usize,
    /// Fraction of successful episodes.
    pub success_rate: f64,
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Mean discounted return (the paper's metric).
    pub discounted_return: f64,
    /// Mean episode length.
    pub mean_length: f64,
}

/// Evaluate the learner's greedy policy on `episodes` fixed-seed episodes, `n` envs at a time.
pub fn evaluate(learner: &mut Learner, envs: &mut [Env], episodes: usize) -> Result<EvalResult, TrainError> {
    let cfg = learner.config().clone();
    let gamma = cfg.agent.gamma;
    let (mut succ, mut ret, mut disc, mut len) = (0usize, 0.0, 0.0, 0.0);
    let mut next = 0usize;
    while next < episodes {
        let n = envs.len().min(episodes - next);
        let mut obs: Vec<Option<Arc<StoredFrame>>> = Vec::with_capacity(n);
        for (i, env) in envs.iter_mut().take(n).enumerate() {
            let o = env.reset(episode_seed(cfg.seed ^ EVAL, 0, (next + i) as u64))?;
            obs.push(Some(frame_of(&o)?));
        }
        let mut steps = vec![0u32; n];
        let mut ep_ret = vec![0.0f64; n];
        let mut ep_disc = vec![0.0f64; n];
        while obs.iter().any(|o| o.is_some()) {
            let live: Vec<usize> = (0..n).filter(|&i| obs[i].is_some()).collect();
            let frames: Vec<&StoredFrame> = live.iter().map(|&i| obs[i].as_deref().expect("live")).collect();
            let actions = learner.act(&frames, ActMode::Greedy)?;
            for (&i, a) in live.iter().zip(actions) {
                let r = envs[i].step(&Action::from_normalized(a))?;
                ep_ret[i] += r.reward as f64;
                ep_disc[i] += gamma.powi(steps[i] as i32) * r.reward as f64;
                steps[i] += 1;
                if r.done {
                    succ += r.info.success as usize;
                    ret += ep_ret[i];
                    disc += ep_disc[i];
                    len += steps[i] as f64;
                    obs[i] = None;
                } else {
                    obs[i] = Some(frame_of(&r.observation)?);
                }
            }
        }
        next += n;
    }
    let e = episodes.max(1) as f64;
    Ok(EvalResult {
        updates: learner.updates(),
        episodes,
        success_rate: succ as f64 / e,
        mean_return: ret / e,
        discounted_return: disc / e,
        mean_length: len / e,
    })
}

/// One training env with its episode bookkeeping.
struct Slot {
    env: Env,
    index: u32,
    episode: u64,
    seed: u64,
    actions: Vec<[f32; 5]>,
    obs: Arc<StoredFrame>,
    ret: f64,
    disc: f64,
}

/// Per-env state saved with a checkpoint (`loop.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LoopState {
    /// Per env: episode index, and the normalised actions taken so far in it.
    envs: Vec<(u64, Vec<[f32; 5]>)>,
    /// Env steps so far (training envs).
    global_step: u64,
    /// Evaluations so far.
    evals: Vec<EvalResult>,
    /// Seconds of training before this checkpoint.
    wall_time: f64,
}

/// What a finished (or stopped) run reports.
#[derive(Clone, Debug)]
pub struct RunSummary {
    /// Run directory.
    pub run_dir: PathBuf,
    /// Every evaluation.
    pub evals: Vec<EvalResult>,
    /// Training env steps.
    pub global_step: u64,
    /// Updates made.
    pub updates: u64,
    /// Wall time of this process's part of the run, seconds.
    pub wall_s: f64,
    /// The last checkpoint written.
    pub last_checkpoint: Option<PathBuf>,
    /// Demo episodes tried / kept.
    pub demos: (usize, usize),
}

/// Options of one invocation (not part of the config: a checkpoint resumes under other options).
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Run directory (created).
    pub run_dir: PathBuf,
    /// Resume from this checkpoint directory.
    pub resume: Option<PathBuf>,
    /// Stop after this many updates in total (for tests; default: the config's `total_updates`).
    pub stop_at: Option<u64>,
    /// Show a progress line on stderr.
    pub progress: bool,
    /// Where the agent's tensors live (default: the CPU, `flex`). A GPU's results are not
    /// bit-identical to the CPU's; exact resume is tested on the CPU.
    pub device: Device,
    /// A new run in a directory that holds a run moves that run aside (`RUN_DIR.old-N`) instead
    /// of being refused ([`RunDirLock::acquire_new`]).
    pub force: bool,
}

impl Default for RunOptions {
    fn default() -> Self {
        // Not `Device::default()`: that is the GPU in a build with the `cuda` feature.
        RunOptions {
            run_dir: PathBuf::new(),
            resume: None,
            stop_at: None,
            progress: false,
            device: equiarm_nn::device::cpu(),
            force: false,
        }
    }
}

/// Run (or resume) a training run. `stop` is polled between steps (Ctrl-C): when it turns true
/// the loop writes a checkpoint and returns.
pub fn run(cfg: TrainConfig, opts: &RunOptions, stop: &dyn Fn() -> bool) -> Result<RunSummary, TrainError> {
    let io = |path: &Path, e: &dyn std::fmt::Display| TrainError::Io { path: path.into(), message: e.to_string() };
    let _claim = RunDirLock::acquire_for(&opts.run_dir, opts.resume.as_deref(), opts.force)?;
    let started = Instant::now();
    let mut learner = Learner::with_device(cfg.clone(), opts.device.clone())?;
    let env_cfg = env_config(&cfg);
    let n = cfg.num_envs;
    let mut eval_envs: Vec<Env> = (0..n).map(|_| Env::new(env_cfg.clone())).collect::<Result<_, _>>()?;
    let mut global_step = 0u64;
    let mut evals = Vec::new();
    let mut wall_before = 0.0;
    let mut demos = (0, 0);
    let mut slots = Vec::with_capacity(n);
    let mut metrics;
    write_json(&opts.run_dir.join("config.json"), &cfg).map_err(|e| io(&opts.run_dir, &e))?;

    if let Some(dir) = &opts.resume {
        learner.resume(dir)?;
        let st: LoopState = read_json(&dir.join("loop.json")).map_err(|e| io(dir, &e))?;
        if st.envs.len() != n {
            return Err(io(dir, &format!("loop.json has {} envs, the config {n}", st.envs.len())));
        }
        for (i, (episode, actions)) in st.envs.into_iter().enumerate() {
            let mut env = Env::new(env_cfg.clone())?;
            let seed = episode_seed(cfg.seed, i as u32, episode);
            let mut o = env.reset(seed)?;
            let (mut ret, mut disc) = (0.0, 0.0);
            for (t, a) in actions.iter().enumerate() {
                let r = env.step(&Action::from_normalized(*a))?;
                ret += r.reward as f64;
                disc += cfg.agent.gamma.powi(t as i32) * r.reward as f64;
                o = r.observation;
            }
            slots.push(Slot { env, index: i as u32, episode, seed, actions, obs: frame_of(&o)?, ret, disc });
        }
        global_step = st.global_step;
        evals = st.evals;
        wall_before = st.wall_time;
        metrics = MetricsWriter::resume(&opts.run_dir, global_step).map_err(|e| io(&opts.run_dir, &e))?;
    } else {
        metrics = MetricsWriter::create(&opts.run_dir).map_err(|e| io(&opts.run_dir, &e))?;
        demos = collect_demos(&mut learner, &env_cfg)?;
        for i in 0..n {
            let mut env = Env::new(env_cfg.clone())?;
            let seed = episode_seed(cfg.seed, i as u32, 0);
            let o = env.reset(seed)?;
            slots.push(Slot {
                env,
                index: i as u32,
                episode: 0,
                seed,
                actions: Vec::new(),
                obs: frame_of(&o)?,
                ret: 0.0,
                disc: 0.0,
            });
        }
    }

    let total = opts.stop_at.unwrap_or(cfg.total_updates).min(cfg.total_updates);
    let mut progress = opts.progress.then(|| crate::progress::Progress::new(total, "updates"));
    let mut last_ck = None;
    let wall = |started: &Instant| wall_before + started.elapsed().as_secs_f64();
    let sps_start = (Instant::now(), global_step);
    while learner.updates() < total && !stop() {
        // Act in every env, step, store.
        let frames: Vec<&StoredFrame> = slots.iter().map(|s| &*s.obs).collect();
        let actions = learner.act(&frames, ActMode::Sample)?;
        for (slot, a) in slots.iter_mut().zip(actions) {
            let r = slot.env.step(&Action::from_normalized(a))?;
            let t = slot.actions.len();
            slot.actions.push(a);
            slot.ret += r.reward as f64;
            slot.disc += cfg.agent.gamma.powi(t as i32) * r.reward as f64;
            global_step += 1;
            let next = frame_of(&r.observation)?;
            let terminal = r.info.success || r.info.invalid || (r.info.timeout && cfg.timeout_terminal);
            learner.push(Stored {
                obs: slot.obs.clone(),
                next_obs: next.clone(),
                action: a,
                reward: r.reward,
                done: terminal,
                expert: false,
            })?;
            if r.done {
                let w = wall(&started);
                metrics
                    .log(
                        global_step,
                        w,
                        &[
                            ("charts/episodic_return", slot.ret),
                            ("charts/discounted_return", slot.disc),
                            ("charts/episodic_length", slot.actions.len() as f64),
                            ("charts/success", r.info.success as u8 as f64),
                        ],
                    )
                    .map_err(|e| io(&opts.run_dir, &e))?;
                slot.episode += 1;
                slot.seed = episode_seed(cfg.seed, slot.index, slot.episode);
                slot.actions.clear();
                slot.ret = 0.0;
                slot.disc = 0.0;
                slot.obs = frame_of(&slot.env.reset(slot.seed)?)?;
            } else {
                slot.obs = next;
            }
        }
        if !learner.ready() {
            continue;
        }
        let m = learner.update()?;
        let u = learner.updates();
        let w = wall(&started);
        let sps = (global_step - sps_start.1) as f64 / sps_start.0.elapsed().as_secs_f64().max(1e-9);
        if u % 10 == 0 || u == 1 {
            let mut named: Vec<(&str, f64)> = m.named().to_vec();
            named.push(("charts/SPS", sps));
            named.push(("charts/updates", u as f64));
            metrics.log(global_step, w, &named).map_err(|e| io(&opts.run_dir, &e))?;
        }
        if cfg.eval_every > 0 && u % cfg.eval_every == 0 {
            let e = evaluate(&mut learner, &mut eval_envs, cfg.eval_episodes)?;
            metrics
                .log(
                    global_step,
                    wall(&started),
                    &[
                        ("eval/success_rate", e.success_rate),
                        ("eval/discounted_return", e.discounted_return),
                        ("eval/episodic_return", e.mean_return),
                        ("eval/episodic_length", e.mean_length),
                        ("eval/updates", u as f64),
                    ],
                )
                .map_err(|e| io(&opts.run_dir, &e))?;
            evals.push(e);
            write_curve(&opts.run_dir, &cfg, &evals)?;
        }
        if cfg.checkpoint_every > 0 && u % cfg.checkpoint_every == 0 {
            last_ck = Some(checkpoint(&learner, &slots, global_step, &evals, wall(&started), &opts.run_dir)?);
        }
        if let Some(p) = progress.as_mut() {
            let mut fields = vec![("SPS", format!("{sps:.1}")), ("alpha", format!("{:.3}", m.alpha))];
            if let Some(e) = evals.last() {
                fields.push(("eval success", format!("{:.2} @{}", e.success_rate, e.updates)));
            }
            let refs: Vec<(&str, String)> = fields.into_iter().collect();
            p.update(u, &refs);
        }
    }
    if let Some(p) = progress.as_mut() {
        p.finish();
    }
    let u = learner.updates();
    if u >= total && cfg.eval_every > 0 && evals.last().map(|e| e.updates) != Some(u) {
        let e = evaluate(&mut learner, &mut eval_envs, cfg.eval_episodes)?;
        metrics
            .log(
                global_step,
                wall(&started),
                &[
                    ("eval/success_rate", e.success_rate),
                    ("eval/discounted_return", e.discounted_return),
                    ("eval/updates", u as f64),
                ],
            )
            .map_err(|e| io(&opts.run_dir, &e))?;
        evals.push(e);
        write_curve(&opts.run_dir, &cfg, &evals)?;
    }
    if last_ck.as_ref().map(|p: &PathBuf| !p.ends_with(step_dir_name(u))).unwrap_or(true) {
        last_ck = Some(checkpoint(&learner, &slots, global_step, &evals, wall(&started), &opts.run_dir)?);
    }
    write_json(&opts.run_dir.join("evals.json"), &evals).map_err(|e| io(&opts.run_dir, &e))?;
    Ok(RunSummary {
        run_dir: opts.run_dir.clone(),
        evals,
        global_step,
        updates: u,
        wall_s: started.elapsed().as_secs_f64(),
        last_checkpoint: last_ck,
        demos,
    })
}

/// Run the expert in one env until `demo_episodes` episodes succeeded; store their transitions
/// (expert = true). Returns (tried, kept).
pub fn collect_demos(learner: &mut Learner, env_cfg: &EnvConfig) -> Result<(usize, usize), TrainError> {
    let cfg = learner.config().clone();
    let want = cfg.demo_episodes;
    let mut env = Env::new(env_cfg.clone())?;
    let (mut tried, mut kept) = (0usize, 0usize);
    let limit = want * 3 + 10;
    while kept < want {
        if tried >= limit {
            return Err(TrainError::Demos { got: kept, tried, want });
        }
        let mut o = env.reset(episode_seed(cfg.seed, u32::MAX, tried as u64))?;
        tried += 1;
        let mut obs = frame_of(&o)?;
        let mut episode = Vec::new();
        loop {
            let a = o.expert_action.to_normalized();
            let r = env.step(&Action::from_normalized(a))?;
            let next = frame_of(&r.observation)?;
            let terminal = r.info.success || r.info.invalid || (r.info.timeout && cfg.timeout_terminal);
            episode.push(Stored {
                obs: obs.clone(),
                next_obs: next.clone(),
                action: a,
                reward: r.reward,
                done: terminal,
                expert: true,
            });
            if r.done {
                if r.info.success {
                    kept += 1;
                    for t in episode {
                        learner.push(t)?;
                    }
                }
                break;
            }
            obs = next;
            o = r.observation;
        }
    }
    Ok((tried, kept))
}

/// Checkpoint directory name for `updates`.
pub fn step_dir_name(updates: u64) -> String {
    format!("step_{updates:07}")
}

fn checkpoint(
    learner: &Learner,
    slots: &[Slot],
    global_step: u64,
    evals: &[EvalResult],
    wall_time: f64,
    run_dir: &Path,
) -> Result<PathBuf, TrainError> {
    let root = run_dir.join("checkpoints");
    let dir = root.join(step_dir_name(learner.updates()));
    learner.save(&dir)?;
    let st = LoopState {
        envs: slots.iter().map(|s| (s.episode, s.actions.clone())).collect(),
        global_step,
        evals: evals.to_vec(),
        wall_time,
    };
    write_json(&dir.join("loop.json"), &st)
        .map_err(|e| TrainError::Io { path: dir.clone(), message: e.to_string() })?;
    write_latest(run_dir, learner.updates())?;
    Ok(dir)
}

/// Point `run_dir/checkpoints/latest` at the checkpoint of `updates` (call it last, once the
/// checkpoint is complete: the file is replaced atomically).
pub fn write_latest(run_dir: &Path, updates: u64) -> Result<(), TrainError> {
    let root = run_dir.join("checkpoints");
    let io = |e: std::io::Error| TrainError::Io { path: root.clone(), message: e.to_string() };
    let tmp = root.join("latest.tmp");
    std::fs::write(&tmp, format!("{}\n", step_dir_name(updates))).map_err(io)?;
    std::fs::rename(&tmp, root.join("latest")).map_err(io)
}

/// The run directory a checkpoint directory belongs to (`RUN/checkpoints/step_N` → `RUN`), or
/// `path` itself when it is a run directory. `None` for a checkpoint outside a run's
/// `checkpoints/` folder.
pub fn run_dir_of(path: &Path) -> Option<PathBuf> {
    if !path.join("manifest.json").is_file() {
        return Some(path.to_path_buf());
    }
    let parent = path.parent()?;
    (parent.file_name()? == "checkpoints").then(|| parent.parent().map(Path::to_path_buf)).flatten()
}

/// An exclusive claim on a run directory for as long as it lives: a second training process
/// pointed at the same directory is refused instead of interleaving its metrics and checkpoints
/// with the first one's. An advisory lock on `RUN/.lock` (which holds the owner's pid), released
/// by the OS when the process ends, so a killed run leaves no stale claim. On a filesystem without
/// file locks the run goes on unguarded, with a warning.
#[derive(Debug)]
pub struct RunDirLock {
    _file: std::fs::File,
}

impl RunDirLock {
    /// Create `run_dir` if needed and claim it.
    pub fn acquire(run_dir: &Path) -> Result<Self, TrainError> {
        let io = |path: &Path, message: String| TrainError::Io { path: path.into(), message };
        std::fs::create_dir_all(run_dir).map_err(|e| io(run_dir, e.to_string()))?;
        let path = run_dir.join(".lock");
        let mut file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(&path)
            .map_err(|e| io(&path, e.to_string()))?;
        match file.try_lock() {
            Ok(()) => {}
            Err(std::fs::TryLockError::WouldBlock) => {
                let owner = std::fs::read_to_string(&path).unwrap_or_default();
                let owner = owner.trim();
                let who = if owner.is_empty() { String::new() } else { format!(" (pid {owner})") };
                return Err(io(
                    run_dir,
                    format!(
                        "the run directory is in use by another training process{who}: wait for it to end or choose another --run-dir"
                    ),
                ));
            }
            // A filesystem without file locks (some network mounts): run unguarded, as before.
            Err(std::fs::TryLockError::Error(e)) if e.kind() == std::io::ErrorKind::Unsupported => {
                log::warn!(
                    "{}: file locks are not supported here ({e}); not guarding the run directory",
                    path.display()
                );
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(io(&path, format!("cannot lock: {e}"))),
        }
        use std::io::Write;
        file.set_len(0).and_then(|_| writeln!(file, "{}", std::process::id())).map_err(|e| io(&path, e.to_string()))?;
        Ok(RunDirLock { _file: file })
    }

    /// Claim `run_dir` for a run that starts there: a new run ([`RunDirLock::acquire_new`]), or
    /// one that resumes `resume` in its own run directory, which may hold that run.
    pub fn acquire_for(run_dir: &Path, resume: Option<&Path>, force: bool) -> Result<Self, TrainError> {
        let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
            (Ok(a), Ok(b)) => a == b,
            _ => a == b,
        };
        match resume.and_then(run_dir_of) {
            Some(resumed) if same(&resumed, run_dir) => Self::acquire(run_dir),
            _ => Self::acquire_new(run_dir, force),
        }
    }

    /// Claim `run_dir` for a new run. A directory that already holds a run (any of
    /// [`RUN_FILES`]) is refused, with the ways out, so that no run is overwritten by accident;
    /// with `force` the old directory is first moved aside to `RUN_DIR.old-N` (the first free N).
    /// Other files (a `config.json` written by a launch script) do not count.
    pub fn acquire_new(run_dir: &Path, force: bool) -> Result<Self, TrainError> {
        let claim = Self::acquire(run_dir)?;
        let found: Vec<&str> = RUN_FILES.iter().copied().filter(|f| run_dir.join(f).exists()).collect();
        if found.is_empty() {
            return Ok(claim);
        }
        if !force {
            return Err(TrainError::Io {
                path: run_dir.into(),
                message: format!(
                    "holds a run already ({}): continue it with --resume {}, choose another --run-dir, or pass --force to move it aside",
                    found.join(", "),
                    run_dir.display()
                ),
            });
        }
        let aside = (1u32..)
            .map(|n| PathBuf::from(format!("{}.old-{n}", run_dir.display())))
            .find(|p| !p.exists())
            .expect("a free name");
        drop(claim);
        std::fs::rename(run_dir, &aside).map_err(|e| TrainError::Io {
            path: run_dir.into(),
            message: format!("cannot move the previous run aside to {}: {e}", aside.display()),
        })?;
        log::warn!("{}: the previous run was moved aside to {}", run_dir.display(), aside.display());
        Self::acquire(run_dir)
    }
}

/// What a run leaves in its directory that a new run there would overwrite or mix with its own.
pub const RUN_FILES: [&str; 4] = ["metrics.csv", "metrics.jsonl", "evals.json", "checkpoints"];

/// Whether `path` names a checkpoint as [`find_checkpoint`] reads it: a checkpoint or run
/// directory, or a run's `checkpoints/latest` pointer file.
pub fn names_checkpoint(path: &Path) -> bool {
    path.is_dir() || is_latest_pointer(path)
}

fn is_latest_pointer(path: &Path) -> bool {
    path.is_file() && path.file_name().is_some_and(|n| n == "latest")
}

/// The newest checkpoint of a run directory (from `checkpoints/latest`), the checkpoint a
/// `checkpoints/latest` pointer file names, or `path` itself if it is a checkpoint directory.
pub fn find_checkpoint(path: &Path) -> Result<PathBuf, TrainError> {
    if path.join("manifest.json").is_file() {
        return Ok(path.to_path_buf());
    }
    if is_latest_pointer(path) {
        let name = std::fs::read_to_string(path)
            .map_err(|e| TrainError::Io { path: path.to_path_buf(), message: e.to_string() })?;
        let dir = path.parent().unwrap_or(Path::new(".")).join(name.trim());
        if !dir.join("manifest.json").is_file() {
            return Err(TrainError::Io {
                path: dir,
                message: format!("named by {} but not a checkpoint directory", path.display()),
            });
        }
        return Ok(dir);
    }
    let latest = path.join("checkpoints").join("latest");
    let name = std::fs::read_to_string(&latest).map_err(|e| TrainError::Io {
        path: latest.clone(),
        message: format!("{e} (not a checkpoint directory nor a run directory with checkpoints)"),
    })?;
    Ok(path.join("checkpoints").join(name.trim()))
}

/// Write `learning_curve.png`: evaluation success rate and discounted return against updates.
pub fn write_curve(run_dir: &Path, cfg: &TrainConfig, evals: &[EvalResult]) -> Result<(), TrainError> {
    use crate::plot::{Chart, Series, palette, write_png};
    let series = vec![
        Series {
            label: "success rate".into(),
            color: palette(0),
            points: evals.iter().map(|e| (e.updates as f64, e.success_rate)).collect(),
            band: None,
        },
        Series {
            label: "discounted return".into(),
            color: palette(1),
            points: evals.iter().map(|e| (e.updates as f64, e.discounted_return)).collect(),
            band: None,
        },
    ];
    let chart = Chart {
        title: format!("{} SAC, {} ({} eval episodes)", cfg.agent.model.name(), cfg.task, cfg.eval_episodes),
        x_label: "gradient updates".into(),
        y_label: "greedy evaluation".into(),
        y_range: Some((0.0, 1.0)),
        ..Chart::default()
    };
    let path = run_dir.join("learning_curve.png");
    write_png(&path, &chart, &series).map_err(|e| TrainError::Io { path, message: e.to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_run_directory_is_claimed_by_one_process_at_a_time() {
        let dir = crate::scratch::Scratch::new("run_lock");
        let first = RunDirLock::acquire(&dir).unwrap();
        let text = std::fs::read_to_string(dir.join(".lock")).unwrap();
        assert_eq!(text.trim(), std::process::id().to_string());
        // A second claim (another open file, as another process would have) is refused, naming
        // the directory, the owner and the fix.
        let e = RunDirLock::acquire(&dir).unwrap_err().to_string();
        assert!(e.contains(&*dir.to_string_lossy()) && e.contains("in use by another training process"), "{e}");
        assert!(e.contains(&format!("pid {}", std::process::id())) && e.contains("--run-dir"), "{e}");
        drop(first);
        let again = RunDirLock::acquire(&dir).unwrap();
        drop(again);
    }

    #[test]
    fn a_new_run_never_overwrites_a_run_directory_that_holds_a_run() {
        let root = crate::scratch::Scratch::new("run_new");
        let dir = root.join("run");
        // Empty, or holding only a launch script's config.json: a new run may start there.
        drop(RunDirLock::acquire_new(&dir, false).unwrap());
        std::fs::write(dir.join("config.json"), "{}").unwrap();
        drop(RunDirLock::acquire_new(&dir, false).unwrap());
        // Metrics or checkpoints: refused, naming what is there and the ways out.
        std::fs::write(dir.join("metrics.csv"), "global_step,wall_time,name,value\n").unwrap();
        std::fs::create_dir_all(dir.join("checkpoints")).unwrap();
        let e = RunDirLock::acquire_new(&dir, false).unwrap_err().to_string();
        assert!(
            e.contains(&*dir.to_string_lossy()) && e.contains("holds a run already (metrics.csv, checkpoints)"),
            "{e}"
        );
        assert!(e.contains("--resume") && e.contains("--run-dir") && e.contains("--force"), "{e}");
        assert!(dir.join("metrics.csv").is_file(), "the refused run touched nothing");
        // Resuming that run in its own directory is allowed; a new run from another run's
        // checkpoint is not.
        let ck = dir.join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        std::fs::write(ck.join("manifest.json"), "{}").unwrap();
        drop(RunDirLock::acquire_for(&dir, Some(&ck), false).unwrap());
        drop(RunDirLock::acquire_for(&dir, Some(&dir), false).unwrap());
        let other = root.join("other");
        std::fs::create_dir_all(other.join("checkpoints")).unwrap();
        assert!(RunDirLock::acquire_for(&other, Some(&ck), false).is_err());
        // --force moves the old run aside, whole, and starts in an empty directory.
        let claim = RunDirLock::acquire_new(&dir, true).unwrap();
        assert!(root.join("run.old-1").join("metrics.csv").is_file());
        assert!(root.join("run.old-1").join("checkpoints").join("step_0000010").is_dir());
        assert!(!dir.join("metrics.csv").exists() && !dir.join("checkpoints").exists());
        drop(claim);
        std::fs::write(dir.join("metrics.csv"), "").unwrap();
        drop(RunDirLock::acquire_new(&dir, true).unwrap());
        assert!(root.join("run.old-2").join("metrics.csv").is_file(), "the next free name");
    }

    #[test]
    fn a_checkpoint_knows_its_run_directory() {
        let dir = crate::scratch::Scratch::new("run_dir_of");
        let ck = dir.join("run").join("checkpoints").join("step_0000010");
        std::fs::create_dir_all(&ck).unwrap();
        std::fs::write(ck.join("manifest.json"), "{}").unwrap();
        assert_eq!(run_dir_of(&ck), Some(dir.join("run")));
        assert_eq!(run_dir_of(&dir.join("run")), Some(dir.join("run")));
        let loose = dir.join("loose");
        std::fs::create_dir_all(&loose).unwrap();
        std::fs::write(loose.join("manifest.json"), "{}").unwrap();
        assert_eq!(run_dir_of(&loose), None);
    }
}
