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
//! Limitations: envs are stepped one after another on the calling thread (stepping costs ~1 ms,
//! an update hundreds of ms on a CPU).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use equiarm_nn::burn::tensor::Device;
use equiarm_sac::agent::ActMode;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::learner::{Learner, read_json};
use equiarm_sac::replay::Stored;
use equiarm_sim::{Action, Env};
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::env::{collect_demos, env_config, episode_seed, frame_of, terminal};
use crate::evaluation::{EvalResult, evaluate, evaluate_filmed};
use crate::record::{RunRecord, RunSummary};
use equiarm_types::NormalizedAction;

/// The state file the loop writes beside each checkpoint.
pub const STATE_FILE: &str = "loop.json";

struct Slot {
    env: Env,
    index: u32,
    episode: u64,
    seed: u64,
    actions: Vec<NormalizedAction>,
    obs: Arc<StoredFrame>,
    ret: f64,
    disc: f64,
}

/// The in-process loop's state saved with a checkpoint ([`STATE_FILE`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LoopState {
    /// Per env: episode index, and the normalised actions taken so far in it (replayed on resume).
    pub envs: Vec<(u64, Vec<NormalizedAction>)>,
    /// Env steps so far (training envs).
    pub global_step: u64,
    /// Evaluations so far.
    pub evals: Vec<EvalResult>,
    /// Seconds of training before this checkpoint.
    pub wall_time: f64,
}

impl LoopState {
    /// The state saved in checkpoint directory `checkpoint`; an error names the file and what is wrong.
    pub fn read(checkpoint: &Path) -> Result<Self, TrainError> {
        let path = checkpoint.join(STATE_FILE);
        Ok(read_json(&path)?)
    }
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
    /// of being refused ([`crate::rundir::RunDirLock::acquire_new`]).
    pub force: bool,
    /// Also write a checkpoint whenever this many seconds of training passed since the last one
    /// (besides the config's `checkpoint_every` updates), so that a slow run loses little when it
    /// is killed. `None`: by update count only.
    pub checkpoint_secs: Option<f64>,
    /// Film every this many-th evaluation: one MP4 per episode in `RUN_DIR/videos/update_NNNNNNN/`.
    pub video_every: Option<u64>,
}

impl Default for RunOptions {
    fn default() -> Self {
        // Not `Device::default()`: that may be the GPU in the GPU build (`vulkan` feature).
        RunOptions {
            run_dir: PathBuf::new(),
            resume: None,
            stop_at: None,
            progress: false,
            device: equiarm_nn::device::cpu(),
            force: false,
            checkpoint_secs: None,
            video_every: None,
        }
    }
}

/// An evaluation, filmed into `run_dir/videos/update_NNNNNNN/episode_NN.mp4` when `film`.
fn evaluation(
    learner: &mut Learner,
    envs: &mut [Env],
    episodes: usize,
    film: bool,
    run_dir: &Path,
) -> Result<EvalResult, TrainError> {
    if !film {
        return evaluate(learner, envs, episodes);
    }
    let (e, films) = evaluate_filmed(learner, envs, episodes)?;
    let dir = run_dir.join("videos").join(format!("update_{:07}", learner.updates()));
    std::fs::create_dir_all(&dir).map_err(equiarm_types::files::at(&dir))?;
    let env = envs[0].config();
    let fps = (1e9 / crate::stepper::SimClock::new(env).step_ns.max(1) as f64).round().max(1.0) as u32;
    let size = (env.camera.height as u32, env.camera.width as u32);
    for (k, frames) in films.iter().enumerate() {
        crate::video::write(&dir.join(format!("episode_{k:02}.mp4")), frames, size, fps)?;
    }
    log::info!("{} evaluation video(s) in {}", films.len(), dir.display());
    Ok(e)
}

/// Run (or resume) a training run. `stop` is polled between steps (Ctrl-C): when it turns true
/// the loop writes a checkpoint and returns.
pub fn run(cfg: TrainConfig, opts: &RunOptions, stop: &dyn Fn() -> bool) -> Result<RunSummary, TrainError> {
    let started = Instant::now();
    let env_cfg = env_config(&cfg)?;
    let mut learner = Learner::with_device(cfg.clone(), opts.device.clone())?;
    let n = cfg.num_envs;
    let mut eval_envs: Vec<Env> = (0..n).map(|_| Env::new(env_cfg.clone())).collect::<Result<_, _>>()?;
    let mut global_step = 0u64;
    let mut wall_before = 0.0;
    let mut demos = (0, 0);
    let mut slots = Vec::with_capacity(n);
    let mut record;

    if let Some(dir) = &opts.resume {
        learner.resume(dir)?;
        let st = LoopState::read(dir)?;
        if st.envs.len() != n {
            return Err(TrainError::run_dir(dir, format!("{STATE_FILE} has {} envs, the config {n}", st.envs.len())));
        }
        record = RunRecord::open(&cfg, &opts.run_dir, Some((dir, st.global_step, st.evals)), opts.force)?;
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
        wall_before = st.wall_time;
    } else {
        record = RunRecord::open(&cfg, &opts.run_dir, None, opts.force)?;
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
    let wall = |started: &Instant| wall_before + started.elapsed().as_secs_f64();
    let state = |slots: &[Slot], global_step: u64, record: &RunRecord, wall_time: f64| LoopState {
        envs: slots.iter().map(|s| (s.episode, s.actions.clone())).collect(),
        global_step,
        evals: record.evals().to_vec(),
        wall_time,
    };
    let sps_start = (Instant::now(), global_step);
    let mut last_checkpoint = Instant::now();
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
            learner.push(Stored {
                obs: slot.obs.clone(),
                next_obs: next.clone(),
                action: a,
                reward: r.reward,
                done: terminal(&r.info, &cfg),
                expert: false,
            })?;
            if r.done {
                let len = slot.actions.len() as u32;
                record.episode(global_step, wall(&started), slot.ret, slot.disc, len, r.info.success)?;
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
        let sps = (global_step - sps_start.1) as f64 / sps_start.0.elapsed().as_secs_f64().max(1e-9);
        record.update(global_step, wall(&started), u, &m, sps)?;
        if cfg.eval_every > 0 && u % cfg.eval_every == 0 {
            let film = opts.video_every.is_some_and(|n| (u / cfg.eval_every).is_multiple_of(n));
            let e = evaluation(&mut learner, &mut eval_envs, cfg.eval_episodes, film, &opts.run_dir)?;
            record.evaluation(global_step, wall(&started), e)?;
        }
        let by_count = cfg.checkpoint_every > 0 && u % cfg.checkpoint_every == 0;
        let by_time = opts.checkpoint_secs.is_some_and(|s| last_checkpoint.elapsed().as_secs_f64() >= s);
        if (by_count || by_time) && u < total {
            record.checkpoint(&learner, STATE_FILE, &state(&slots, global_step, &record, wall(&started)))?;
            last_checkpoint = Instant::now();
        }
        if let Some(p) = progress.as_mut() {
            let mut fields = vec![("SPS", format!("{sps:.1}")), ("alpha", format!("{:.3}", m.alpha))];
            if let Some(e) = record.evals().last() {
                fields.push(("eval success", format!("{:.2} @{}", e.success_rate, e.updates)));
            }
            p.update(u, &fields);
        }
    }
    if let Some(p) = progress.as_mut() {
        p.finish();
    }
    let u = learner.updates();
    if u >= total && cfg.eval_every > 0 && record.evals().last().map(|e| e.updates) != Some(u) {
        let e = evaluation(&mut learner, &mut eval_envs, cfg.eval_episodes, opts.video_every.is_some(), &opts.run_dir)?;
        record.evaluation(global_step, wall(&started), e)?;
    }
    record.finish(&learner, STATE_FILE, &state(&slots, global_step, &record, wall(&started)))?;
    Ok(RunSummary {
        run_dir: opts.run_dir.clone(),
        evals: record.evals().to_vec(),
        global_step,
        updates: u,
        wall_s: started.elapsed().as_secs_f64(),
        last_checkpoint: record.last_checkpoint().map(PathBuf::from),
        demos,
    })
}
