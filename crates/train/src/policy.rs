//! The policy node's acting, without DDS: it answers each `Observation` with a `GripperCommand`
//! naming its seq, and in the learning modes (`sample`, `greedy`) takes new actor weights.
//!
//! Modes: `sample` (tanh(mean + std·ε), exploration), `greedy` (tanh(mean), evaluation), `expert`
//! (sends back the Observation's `expert_action`, source EXPERT), `random` (uniform in [-1, 1]^5 from
//! the seeded RNG, source RANDOM). A re-published Observation (same seq) gets the identical command.
//! When to answer (at once, `--max-lead` flow control, `--deterministic` lock-step) is [`crate::gate`]'s.
//! The sampling noise comes from the actor's RNG seeded with `--seed` (5 normals per sampled action),
//! so the same observations answered in the same order give the same actions.
//!
//! ## Limitations
//! One env per node. Acting is on the runtime thread (batch 1), so a slow actor delays weights too.

use std::collections::VecDeque;
use std::path::Path;
use std::time::Instant;

use anyhow::Context as _;
use equiarm_msgs::ObsFrameError;
use equiarm_msgs::msg::{GripperCommand, Observation, PolicyWeights};
use equiarm_sac::agent::{ActMode, Agent, AgentConfig, ModelKind};
use equiarm_sac::frame::{FrameError, StoredFrame};
use equiarm_sim::{Action, rng::Rng};

use crate::gate::Standing;

/// How the node acts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PolicyMode {
    /// Sampled actions of the actor (training envs).
    Sample,
    /// The actor's mean action (evaluation envs).
    Greedy,
    /// The Observation's expert action (demonstrations).
    Expert,
    /// Uniform random actions.
    Random,
}

/// Why an Observation's images make no frame (or, at the trainer, not one of the run's size).
#[derive(Debug, thiserror::Error)]
pub enum BadFrame {
    /// A plane is not the zstd frame of its stated size (`equiarm_msgs::obs_frame`).
    #[error(transparent)]
    Planes(#[from] ObsFrameError),
    /// Not square, too large, or a depth that is not finite.
    #[error(transparent)]
    Frame(#[from] FrameError),
    /// A frame of another size than the reader's (the trainer's `image_size`, the policy's
    /// `--image`), refused before its planes are decompressed.
    #[error("frame of {height} x {width} px, {want} x {want} expected")]
    Size {
        /// The frame's rows, as the Observation states them.
        height: u32,
        /// Its columns.
        width: u32,
        /// The side the reader takes.
        want: usize,
    },
}

/// How many (sender, cause) pairs of refused messages a node logs once each; beyond them refusals
/// are only counted (a peer inventing env names cannot grow the set or the log).
pub const MAX_LOGGED_SENDERS: usize = 256;

/// Why the policy could not answer an Observation.
#[derive(Debug, thiserror::Error)]
pub enum AnswerError {
    /// Its images make no frame.
    #[error(transparent)]
    Frame(#[from] BadFrame),
    /// The actor failed on it.
    #[error("acting: {0}")]
    Act(equiarm_sac::learner::LearnerError),
}

impl AnswerError {
    /// The kind of defect, one word, for logging each sender's defects once per kind.
    pub fn cause(&self) -> &'static str {
        match self {
            AnswerError::Frame(BadFrame::Size { .. }) => "frame size",
            AnswerError::Frame(BadFrame::Planes(_)) => "frame planes",
            AnswerError::Frame(BadFrame::Frame(_)) => "frame",
            AnswerError::Act(_) => "acting",
        }
    }
}

// By hand, not `#[from]`: the message shows the cause, so it is not also chained as a source
// (docs/conventions.md, "Errors").
impl From<equiarm_sac::learner::LearnerError> for AnswerError {
    fn from(e: equiarm_sac::learner::LearnerError) -> Self {
        AnswerError::Act(e)
    }
}

/// The physical action a GripperCommand (or a Transition's action) carries.
pub fn action_of(c: &GripperCommand) -> Action {
    Action::new(c.open_ratio, c.dx, c.dy, c.dz, c.dtheta)
}

/// The frame of an Observation of `want` × `want` pixels: one of another size is refused from its
/// stated sides, before anything is decompressed (a 10 kB message can announce 8192 × 8192 pixels,
/// about 460 MB of planes).
pub fn frame_of_size(obs: &Observation, want: usize) -> Result<StoredFrame, BadFrame> {
    size_is(obs, want)?;
    frame_of(obs)
}

/// Whether an Observation states a `want` × `want` frame (its sides only; nothing is read).
fn size_is(obs: &Observation, want: usize) -> Result<(), BadFrame> {
    if (obs.height as usize, obs.width as usize) != (want, want) {
        return Err(BadFrame::Size { height: obs.height, width: obs.width, want });
    }
    Ok(())
}

/// The frame of an Observation (rgb8 colour, half-float depth, holding), as the replay stores it;
/// the error says what is wrong.
pub fn frame_of(obs: &Observation) -> Result<StoredFrame, BadFrame> {
    let (width, height) = (obs.width as usize, obs.height as usize);
    if width != height {
        return Err(FrameError::NotSquare { width, height }.into());
    }
    Ok(StoredFrame::from_f16(width, obs.color_rgb8()?, obs.depth_f16()?, obs.holding)?)
}

/// What became of a PolicyWeights sample.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum WeightsOutcome {
    /// Loaded: the node now acts with this version.
    Loaded,
    /// Loaded, from another run than the weights before (a trainer started afresh, or another
    /// trainer on the domain): its versions count from here.
    NewRun {
        /// The run the node followed.
        was: String,
    },
    /// The version in use again (a re-delivery); ignored.
    Stale,
    /// Older than the version in use within the same run: versions only grow within a run, so it
    /// is ignored (and worth a warning: something republishes old weights).
    Older {
        /// The version in use.
        current: u64,
    },
    /// Another model or format: refused (the reason, logged once per reason).
    Refused(String),
    /// The payload did not load; the old weights stay.
    Failed(String),
}

/// The acting logic, without DDS.
pub struct Policy {
    mode: PolicyMode,
    agent: Option<Agent>,
    frame_size: usize,
    rng: Rng,
    last: Option<(u64, GripperCommand)>,
    version: u64,
    /// The run the weights in use come from (None: the initial weights).
    run: Option<String>,
    latencies: VecDeque<f64>,
    actions: u64,
    expert_episodes: u32,
    policy_steps: u64,
    answered: u64,
    /// The trainer's update count when the weights in use were taken (their `updates`).
    weights_updates: Option<u64>,
    /// The trainer's update count as last heard (its TrainerStatus).
    trainer_updates: Option<u64>,
    /// Per learned action: how many updates the weights acted on were behind the trainer.
    lags: Vec<u64>,
}

/// How old the weights behind the learned actions were: the trainer's update count as the node last
/// heard it (TrainerStatus, once a second) minus the update count of the weights acted on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Staleness {
    /// Learned actions with both counts known.
    pub actions: usize,
    /// Mean lag in updates.
    pub mean: f64,
    /// Median lag.
    pub median: u64,
    /// 95th percentile.
    pub p95: u64,
    /// Largest lag.
    pub max: u64,
}

impl Policy {
    /// A policy acting in `mode`; the learning modes build an actor of `agent` (seeded with `seed`),
    /// loaded from `actor` if given.
    pub fn new(
        mode: PolicyMode,
        agent: AgentConfig,
        frame_size: usize,
        actor: Option<&Path>,
        seed: u64,
    ) -> anyhow::Result<Self> {
        let agent = match mode {
            PolicyMode::Sample | PolicyMode::Greedy => {
                let mut a = Agent::new(agent, seed).context("building the actor")?;
                if let Some(p) = actor {
                    a.load_actor(p).with_context(|| format!("loading the actor {}", p.display()))?;
                }
                Some(a)
            }
            _ => None,
        };
        Ok(Policy {
            mode,
            agent,
            frame_size,
            rng: Rng::new(seed),
            last: None,
            version: 0,
            run: None,
            latencies: VecDeque::new(),
            actions: 0,
            expert_episodes: 0,
            policy_steps: 0,
            answered: 0,
            weights_updates: None,
            trainer_updates: None,
            lags: Vec::new(),
        })
    }

    /// Answer episodes `0..k` of the env with the expert.
    pub fn with_expert_episodes(mut self, k: u32) -> Self {
        self.expert_episodes = k;
        self
    }

    /// Where the node stands if it answered `obs` now (what [`crate::gate::Gate`] decides on).
    pub fn progress(&self, obs: &Observation) -> Standing {
        let repeat = self.last.as_ref().is_some_and(|(seq, _)| *seq == obs.seq);
        let policy_step = !repeat && self.mode != PolicyMode::Expert && obs.episode >= self.expert_episodes;
        Standing {
            repeat,
            policy_step,
            policy_steps: self.policy_steps,
            answered: self.answered,
            version: self.version,
            episode_start: obs.step == 0,
            weights_updates: self.weights_updates,
        }
    }

    /// Whether this mode takes weights from the trainer.
    pub fn learns(&self) -> bool {
        self.agent.is_some()
    }

    /// Version of the weights in use (0: the initial ones).
    pub fn version(&self) -> u64 {
        self.version
    }

    /// Refuses an Observation the actor would have to read whose frame is of another size than the
    /// actor's, from its stated sides only (nothing is decompressed): the node screens each
    /// Observation so before the gate may hold it, so that a stream of bad ones neither displaces a
    /// good one held back nor counts as policy steps.
    pub fn screen(&self, obs: &Observation) -> Result<(), AnswerError> {
        let acts = obs.episode >= self.expert_episodes
            && self.agent.is_some()
            && matches!(self.mode, PolicyMode::Sample | PolicyMode::Greedy);
        if acts {
            size_is(obs, self.frame_size)?;
        }
        Ok(())
    }

    /// The command answering `obs` (the same one again for a re-published seq).
    pub fn answer(&mut self, obs: &Observation) -> Result<GripperCommand, AnswerError> {
        if let Some((seq, cmd)) = &self.last
            && *seq == obs.seq
        {
            return Ok(cmd.clone());
        }
        let expert = obs.episode < self.expert_episodes;
        let (u, source) = match (if expert { PolicyMode::Expert } else { self.mode }, self.agent.as_mut()) {
            (PolicyMode::Expert, _) => {
                let source = GripperCommand::SOURCE_EXPERT;
                return Ok(self.remember(GripperCommand {
                    header: obs.header.clone(),
                    obs_seq: obs.seq,
                    source,
                    ..obs.expert_action.clone()
                }));
            }
            (PolicyMode::Random, _) | (_, None) => {
                ([(); 5].map(|_| self.rng.uniform(-1.0, 1.0)), GripperCommand::SOURCE_RANDOM)
            }
            (mode, Some(agent)) => {
                let frame = frame_of_size(obs, self.frame_size)?;
                let (act, s) = (
                    if mode == PolicyMode::Greedy { ActMode::Greedy } else { ActMode::Sample },
                    agent.config().input_size,
                );
                let t0 = Instant::now();
                let u = equiarm_sac::learner::act_on(agent, &[&frame], s, act)?;
                self.record_latency(t0.elapsed().as_secs_f64());
                if let (Some(t), Some(w)) = (self.trainer_updates, self.weights_updates) {
                    self.lags.push(t.saturating_sub(w));
                }
                (u[0], GripperCommand::SOURCE_POLICY)
            }
        };
        // (the expert's answers returned above; an Observation refused above is no policy step)
        self.policy_steps += 1;
        let a = Action::from_normalized(u);
        let (header, obs_seq) = (obs.header.clone(), obs.seq);
        let cmd = GripperCommand {
            header,
            obs_seq,
            open_ratio: a.open_ratio,
            dx: a.dx,
            dy: a.dy,
            dz: a.dz,
            dtheta: a.dtheta,
            source,
        };
        Ok(self.remember(cmd))
    }

    fn remember(&mut self, cmd: GripperCommand) -> GripperCommand {
        self.last = Some((cmd.obs_seq, cmd.clone()));
        self.answered += 1;
        cmd
    }

    fn record_latency(&mut self, s: f64) {
        if self.latencies.len() == 100 {
            self.latencies.pop_front();
        }
        self.latencies.push_back(s);
        self.actions += 1;
    }

    /// Median and p95 of the last 100 actor latencies in ms, once every 100 actions.
    pub fn latency_report(&self) -> Option<(f64, f64)> {
        if self.actions == 0 || !self.actions.is_multiple_of(100) {
            return None;
        }
        let mut v: Vec<f64> = self.latencies.iter().copied().collect();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize] * 1e3;
        Some((at(0.5), at(0.95)))
    }

    /// A TrainerStatus said the trainer has made `updates` updates.
    pub fn on_trainer_status(&mut self, updates: u64) {
        self.trainer_updates = Some(updates);
    }

    /// How far behind the trainer the weights of the learned actions so far were; None before any
    /// learned action with both counts known.
    pub fn staleness(&self) -> Option<Staleness> {
        let mut v = self.lags.clone();
        v.sort_unstable();
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        (!v.is_empty()).then(|| Staleness {
            actions: v.len(),
            mean: v.iter().sum::<u64>() as f64 / v.len() as f64,
            median: at(0.5),
            p95: at(0.95),
            max: v[v.len() - 1],
        })
    }

    /// Takes new weights if they are ours (model, format, finite values) and newer within their run
    /// (the payload moves into the actor, uncopied). Weights of another run are taken too, and
    /// say so ([`WeightsOutcome::NewRun`]): a stray message can never make the node ignore its
    /// trainer's later versions without a word.
    pub fn on_weights(&mut self, w: PolicyWeights) -> WeightsOutcome {
        let Some(agent) = self.agent.as_mut() else {
            return WeightsOutcome::Refused(format!("mode {:?} takes no weights", self.mode));
        };
        let ours = agent.config().model.name();
        if ModelKind::from_name(&w.model) != Some(agent.config().model) {
            return WeightsOutcome::Refused(format!("model '{}' is not this node's '{ours}'", w.model));
        }
        if w.format != "safetensors" {
            return WeightsOutcome::Refused(format!("format '{}' is not 'safetensors'", w.format));
        }
        let same_run = self.run.as_deref().is_none_or(|r| r == w.run_id);
        if same_run && w.version == self.version {
            return WeightsOutcome::Stale;
        }
        if same_run && w.version < self.version {
            return WeightsOutcome::Older { current: self.version };
        }
        let label = format!("PolicyWeights version {} of run '{}'", w.version, w.run_id);
        match agent.load_actor_bytes(w.data, &label).map_err(|e| e.to_string()) {
            Ok(()) => {
                self.version = w.version;
                self.weights_updates = Some(w.updates);
                match self.run.replace(w.run_id) {
                    Some(was) if !same_run => WeightsOutcome::NewRun { was },
                    _ => WeightsOutcome::Loaded,
                }
            }
            Err(e) => WeightsOutcome::Failed(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ingest::Ingest;
    use equiarm_sac::config::TrainConfig;

    /// An Observation announcing `side` × `side` pixels whose planes are 16 bytes of garbage: a
    /// reader that decompressed them would fail on the planes, one that checks the sides first
    /// fails on the size.
    fn announcing(side: u32) -> Observation {
        Observation {
            env: "env0".into(),
            height: side,
            width: side,
            color: vec![7; 16],
            depth: vec![7; 16],
            ..Default::default()
        }
    }

    /// A small CNN actor reading 16 px crops.
    fn tiny_cnn() -> AgentConfig {
        AgentConfig { model: equiarm_sac::agent::ModelKind::Cnn, hidden: 8, input_size: 16, ..AgentConfig::default() }
    }

    /// Regression (issue 61): a 10 kB Observation announcing 8192 × 8192 pixels was decompressed in
    /// full (about 460 MB, 2.3 s) by the policy and by the trainer before it was refused, and a frame
    /// of another size than the policy's was answered on its centre crop without a word.
    #[test]
    fn frames_of_another_size_are_refused_from_their_sides_before_decompression() {
        let arch = tiny_cnn();
        let mut policy = Policy::new(PolicyMode::Greedy, arch, 19, None, 1).unwrap();
        for side in [8192, 38, 16] {
            let e = policy.answer(&announcing(side)).unwrap_err();
            assert!(matches!(e, AnswerError::Frame(BadFrame::Size { want: 19, .. })), "{side}: {e}");
            assert_eq!(e.to_string(), format!("frame of {side} x {side} px, 19 x 19 expected"));
        }
        // of the right size, the same garbage is read, and refused for what it is
        let e = policy.answer(&announcing(19)).unwrap_err();
        assert!(matches!(e, AnswerError::Frame(BadFrame::Planes(_))), "{e}");

        let cfg = TrainConfig { image_size: 19, ..TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling) };
        let mut ingest = Ingest::new(&cfg, "/eval");
        let e = ingest.observation(&announcing(8192)).unwrap_err();
        assert!(matches!(e, BadFrame::Size { height: 8192, width: 8192, want: 19 }), "{e}");
        assert_eq!(ingest.counts.bad_frames, 1);
    }

    /// Regression (issue 61): a peer's stream of oversized frames at 10 Hz cut the policy node's
    /// answers to the real env by more than half (188 commands in a minute, against 425 without the
    /// peer and 423 with it after this fix; `bench/oversized_frames.sh`): each bad one was held back
    /// by the gate in place of the real one waiting there, and counted as a policy step. The node
    /// now screens an Observation before the gate sees it, and a refused one is no step.
    #[test]
    fn a_bad_frame_is_screened_before_the_gate_and_is_no_policy_step() {
        let arch = tiny_cnn();
        let mut policy = Policy::new(PolicyMode::Sample, arch.clone(), 19, None, 1).unwrap();
        let e = policy.screen(&announcing(8192)).unwrap_err();
        assert!(matches!(e, AnswerError::Frame(BadFrame::Size { want: 19, .. })), "{e}");
        policy.screen(&announcing(19)).unwrap(); // the sides only: its planes are read when answered
        for side in [8192, 19] {
            policy.answer(&announcing(side)).unwrap_err();
        }
        assert_eq!(policy.progress(&announcing(19)).policy_steps, 0);
        // the expert's episodes and the random policy read no frame
        let expert = Policy::new(PolicyMode::Sample, arch.clone(), 19, None, 1).unwrap().with_expert_episodes(1);
        expert.screen(&announcing(8192)).unwrap();
        Policy::new(PolicyMode::Random, arch, 19, None, 1).unwrap().screen(&announcing(8192)).unwrap();
    }

    /// The staleness of the acting weights (issue 59): each learned action records how many updates
    /// its weights were behind the trainer's last status; expert answers and actions before both
    /// counts are known record nothing.
    #[test]
    fn learned_actions_record_how_far_behind_the_trainer_their_weights_were() {
        let arch = tiny_cnn();
        let mut policy = Policy::new(PolicyMode::Sample, arch.clone(), 16, None, 1).unwrap().with_expert_episodes(1);
        let obs = |seq: u64, episode: u32| {
            let mut o = Observation { seq, episode, env: "env0".into(), ..Default::default() };
            o.set_frame(16, 16, &[90; 16 * 16 * 3], &[0.5; 16 * 16]).unwrap();
            o
        };
        let trainer = Agent::new(arch, 2).unwrap();
        let weights = |version: u64, updates: u64| PolicyWeights {
            run_id: "r".into(),
            version,
            updates,
            model: "cnn".into(),
            format: "safetensors".into(),
            data: trainer.actor_bytes().unwrap(),
            ..Default::default()
        };
        policy.answer(&obs(0, 1)).unwrap(); // nothing known yet
        policy.on_trainer_status(120);
        policy.answer(&obs(1, 1)).unwrap(); // initial weights: their update count is not known
        assert_eq!(policy.staleness(), None);
        assert!(matches!(policy.on_weights(weights(2, 100)), WeightsOutcome::Loaded));
        policy.answer(&obs(2, 0)).unwrap(); // an expert answer
        for (seq, status) in [(3, 120), (4, 130), (5, 150)] {
            policy.on_trainer_status(status);
            policy.answer(&obs(seq, 1)).unwrap();
        }
        policy.answer(&obs(5, 1)).unwrap(); // a repeat of seq 5: the same command, no new action
        assert!(matches!(policy.on_weights(weights(3, 150)), WeightsOutcome::Loaded));
        policy.answer(&obs(6, 1)).unwrap();
        let s = policy.staleness().unwrap();
        assert_eq!((s.actions, s.median, s.p95, s.max), (4, 30, 50, 50));
        assert!((s.mean - 25.0).abs() < 1e-9, "{s:?}");
    }
}
