//! The simulator side of a training run: the env config of a [`TrainConfig`], episode seeds, the
//! simulator's observations as the learner's frames, and the expert demonstrations.
//!
//! Episode seeds: training episode `e` of env `i` uses [`episode_seed`]`(seed, i, e)`; demos use
//! env index `u32::MAX`; evaluation episode `j` uses `episode_seed(seed ^ EVAL, 0, j)`, the same at
//! every evaluation.

use std::sync::Arc;

use equiarm_sac::config::TrainConfig;
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::learner::Learner;
use equiarm_sac::replay::Stored;
use equiarm_sim::{Action, CameraConfig, Env, EnvConfig, Observation};

use crate::TrainError;
use crate::config::check;

/// Mixed into the seed of evaluation episodes.
pub const EVAL: u64 = 0x6576_616c;

/// The seed of episode `episode` of env `env` in a run seeded `seed` (splitmix64 of a mix).
pub fn episode_seed(seed: u64, env: u32, episode: u64) -> u64 {
    let mut z = seed ^ ((env as u64) << 40) ^ episode.wrapping_mul(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The env config of a run, after [`check`].
pub fn env_config(cfg: &TrainConfig) -> Result<EnvConfig, TrainError> {
    check(cfg)?;
    let mut e = EnvConfig::new(cfg.task);
    e.camera = CameraConfig::from(cfg.view);
    e.camera.width = cfg.image_size;
    e.camera.height = cfg.image_size;
    e.max_steps = cfg.max_episode_steps;
    e.corruption = cfg.corruption;
    e.arm = cfg.arm;
    Ok(e)
}

/// Whether a step ends its episode for the learner (no bootstrap): success, an invalid state, or a
/// time limit when the config treats time limits as terminal.
pub fn terminal(info: &equiarm_sim::StepInfo, cfg: &TrainConfig) -> bool {
    info.success || info.invalid || (info.timeout && cfg.timeout_terminal)
}

/// A simulator observation as a stored frame.
pub fn frame_of(obs: &Observation) -> Result<Arc<StoredFrame>, TrainError> {
    if obs.width != obs.height {
        return Err(TrainError::NotSquare { width: obs.width, height: obs.height });
    }
    Ok(Arc::new(StoredFrame::new(obs.width, obs.color.clone(), &obs.depth, obs.holding)?))
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
            episode.push(Stored {
                obs: obs.clone(),
                next_obs: next.clone(),
                action: a,
                reward: r.reward,
                done: terminal(&r.info, &cfg),
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
