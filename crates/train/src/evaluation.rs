//! Greedy evaluation: one result type for both ways a run evaluates its policy: in this process over
//! fixed-seed episodes ([`evaluate`]), or from the episode results an evaluation env publishes
//! ([`EvalResult::from_episodes`], the trainer node). Its metric names are [`EvalResult::named`].

use std::sync::Arc;

use equiarm_sac::agent::ActMode;
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::learner::Learner;
use equiarm_sim::{Action, Env};
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::env::{EVAL, episode_seed, frame_of};
use crate::video::Frame;

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

/// How one evaluation episode ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpisodeOutcome {
    /// Whether the task was done.
    pub success: bool,
    /// Undiscounted return.
    pub ret: f64,
    /// Discounted return.
    pub discounted: f64,
    /// Steps.
    pub length: u32,
}

impl EvalResult {
    /// The evaluation of `updates` from its episodes.
    pub fn from_episodes(updates: u64, episodes: &[EpisodeOutcome]) -> Self {
        let n = episodes.len().max(1) as f64;
        let mean = |f: &dyn Fn(&EpisodeOutcome) -> f64| episodes.iter().map(f).sum::<f64>() / n;
        EvalResult {
            updates,
            episodes: episodes.len(),
            success_rate: mean(&|e| e.success as u8 as f64),
            mean_return: mean(&|e| e.ret),
            discounted_return: mean(&|e| e.discounted),
            mean_length: mean(&|e| e.length as f64),
        }
    }

    /// The metrics of an evaluation, by their CleanRL-style names.
    pub fn named(&self) -> [(&'static str, f64); 5] {
        [
            ("eval/success_rate", self.success_rate),
            ("eval/discounted_return", self.discounted_return),
            ("eval/episodic_return", self.mean_return),
            ("eval/episodic_length", self.mean_length),
            ("eval/updates", self.updates as f64),
        ]
    }
}

/// Evaluate the learner's greedy policy on `episodes` fixed-seed episodes, `n` envs at a time: the
/// evaluations during training ([`Stream::Training`]).
pub fn evaluate(learner: &mut Learner, envs: &mut [Env], episodes: usize) -> Result<EvalResult, TrainError> {
    evaluate_on(learner, envs, episodes, Stream::Training)
}

/// Which fixed episode seeds an evaluation uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stream {
    /// The episodes every evaluation during training sees (the learning curve).
    Training,
    /// Episodes no evaluation during training saw: the final held-out figure of a run, so that no
    /// choice made by watching the learning curve can favour it.
    HeldOut,
}

/// [`evaluate`] on the episode seeds of `stream`.
pub fn evaluate_on(
    learner: &mut Learner,
    envs: &mut [Env],
    episodes: usize,
    stream: Stream,
) -> Result<EvalResult, TrainError> {
    Ok(evaluate_inner(learner, envs, episodes, stream, false)?.0)
}

/// [`evaluate`], keeping every episode's frames for a video: each Observation with a caption (step,
/// the reward of the step taken from it), and the last with the outcome.
pub fn evaluate_filmed(
    learner: &mut Learner,
    envs: &mut [Env],
    episodes: usize,
) -> Result<(EvalResult, Vec<Vec<Frame>>), TrainError> {
    evaluate_inner(learner, envs, episodes, Stream::Training, true)
}

fn shot(o: &equiarm_sim::Observation, k: usize, caption: String) -> Frame {
    Frame {
        color: o.color.clone(),
        depth: o.depth.clone(),
        caption: format!("eval ep {k}  step {}  {caption}", o.step),
    }
}

fn evaluate_inner(
    learner: &mut Learner,
    envs: &mut [Env],
    episodes: usize,
    stream: Stream,
    film: bool,
) -> Result<(EvalResult, Vec<Vec<Frame>>), TrainError> {
    let mut films: Vec<Vec<Frame>> = Vec::new();
    let cfg = learner.config().clone();
    let stream_index = match stream {
        Stream::Training => 0,
        Stream::HeldOut => 1,
    };
    let gamma = cfg.agent.gamma;
    let mut ended = Vec::with_capacity(episodes);
    let mut next = 0usize;
    while next < episodes {
        let n = envs.len().min(episodes - next);
        let mut obs: Vec<Option<Arc<StoredFrame>>> = Vec::with_capacity(n);
        for (i, env) in envs.iter_mut().take(n).enumerate() {
            let o = env.reset(episode_seed(cfg.seed ^ EVAL, stream_index, (next + i) as u64))?;
            obs.push(Some(frame_of(&o)?));
            if film {
                films.push(vec![shot(&o, next + i, String::new())]);
            }
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
                if let Some(f) = films.get_mut(next + i).and_then(|f| f.last_mut()) {
                    f.caption.push_str(&format!("reward {}", r.reward));
                }
                if film {
                    let end = if !r.done {
                        String::new()
                    } else if r.info.success {
                        "success".into()
                    } else {
                        "failure".into()
                    };
                    films[next + i].push(shot(&r.observation, next + i, end));
                }
                ep_ret[i] += r.reward as f64;
                ep_disc[i] += gamma.powi(steps[i] as i32) * r.reward as f64;
                steps[i] += 1;
                if r.done {
                    ended.push(EpisodeOutcome {
                        success: r.info.success,
                        ret: ep_ret[i],
                        discounted: ep_disc[i],
                        length: steps[i],
                    });
                    obs[i] = None;
                } else {
                    obs[i] = Some(frame_of(&r.observation)?);
                }
            }
        }
        next += n;
    }
    Ok((EvalResult::from_episodes(learner.updates(), &ended), films))
}
