//! What the trainer node makes of the training envs' `observation` topics, `/transitions` and
//! `/episodes`, without DDS: each Observation's frame decoded once and kept until the Transitions
//! that name it (by env and seq) have arrived ([`Joined`]: a frame is shared by the row it ends and
//! the row it starts), replay rows, expert demonstrations held per (env, episode) until the
//! EpisodeResult says whether the episode succeeded (the paper keeps only successful demos), the
//! eval env never stored.
//!
//! Topics are not ordered with respect to each other: a Transition may arrive before the
//! Observations it names (it waits for them, up to [`MAX_WAITING`] per env), and a result may
//! overtake its episode's last transitions, and then decides them on arrival. Nor is one topic
//! ordered: a reliable RustDDS reader hands a sample over as soon as it arrives, so one lost on the
//! wire and sent again comes after the samples that followed it. A frame is therefore not let go
//! when a Transition that names it is joined (an earlier Transition may still want it); frames are
//! kept up to [`MAX_FRAMES`] per env, the oldest (lowest seq) dropped first. They cost little: the
//! replay holds the same frames.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::sync::Arc;

use equiarm_msgs::msg::{EpisodeResult, Observation, Transition};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::replay::Stored;

use crate::policy::{BadFrame, action_of, frame_of_size};

/// What the trainer did with the transitions it received (N = stored + held + dropped + eval + bad +
/// unmatched + [`Ingest::waiting`]).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Received {
    /// Transitions received (all envs).
    pub transitions: u64,
    /// Rows handed to the replay.
    pub stored: u64,
    /// Expert rows waiting for their episode's result now.
    pub expert_held: u64,
    /// Expert rows of failed episodes, dropped.
    pub expert_dropped: u64,
    /// Transitions of the eval env (never stored).
    pub eval: u64,
    /// Malformed transitions (bad values, or a frame of a bad Observation), skipped.
    pub bad: u64,
    /// Observations whose images make no frame of the run's size, skipped.
    pub bad_frames: u64,
    /// Transitions dropped because their Observations did not arrive in time.
    pub unmatched: u64,
    /// Expert episodes decided, and kept (successful).
    pub expert_episodes: (usize, usize),
}

type Key = (String, u32);

/// Frames kept per env for Transitions still to come (or late): a sample lost on the wire is sent
/// again after the writer's next heartbeat (RustDDS: within about 1 s), and an env makes well under
/// this many steps in that time.
pub const MAX_FRAMES: usize = 256;
/// Transitions per env that may wait for their Observations.
pub const MAX_WAITING: usize = 256;

/// A Transition with the frames of the two Observations it names.
#[derive(Clone, Debug)]
pub struct Joined {
    /// The Transition.
    pub t: Transition,
    /// The frame of Observation `t.obs_seq`.
    pub obs: Arc<StoredFrame>,
    /// The frame of Observation `t.next_obs_seq`.
    pub next_obs: Arc<StoredFrame>,
}

/// One env's frames and waiting Transitions.
#[derive(Default)]
struct EnvFrames {
    frames: BTreeMap<u64, Arc<StoredFrame>>,
    waiting: VecDeque<Transition>,
    /// Seqs of the Observations refused lately (at most [`MAX_FRAMES`]): the Transitions naming
    /// them are dropped as bad instead of waiting for a frame that will never come.
    refused: BTreeSet<u64>,
}

impl EnvFrames {
    /// The frames `t` names, if both are here.
    fn frames_of(&self, t: &Transition) -> Option<(Arc<StoredFrame>, Arc<StoredFrame>)> {
        Some((self.frames.get(&t.obs_seq)?.clone(), self.frames.get(&t.next_obs_seq)?.clone()))
    }
}

/// Largest reward magnitude accepted from a peer: every task gives 0 or 1 (docs/paper.md §3.2), so a
/// larger one is a bug or an attack, and one such row would dominate the critic's loss.
pub const MAX_ABS_REWARD: f32 = 1000.0;

/// Why a Transition is refused (counted in [`Received::bad`], never stored).
#[derive(Debug, thiserror::Error)]
pub enum BadTransition {
    /// It names an Observation that was refused (its frame was bad), so it can never be joined.
    #[error("it names Observation {seq}, whose frame was refused")]
    Orphan {
        /// The refused Observation's seq.
        seq: u64,
    },
    /// Its reward is NaN, infinite or beyond ±[`MAX_ABS_REWARD`].
    #[error("reward {0} is not finite and within ±{MAX_ABS_REWARD}")]
    Reward(f32),
    /// An action component is NaN or infinite.
    #[error("action {field} is {value}")]
    Action {
        /// The GripperCommand field.
        field: &'static str,
        /// Its value.
        value: f32,
    },
    /// It comes from an env that is not one of the run's (whose Observations the trainer never
    /// receives, so it could only wait, and its state grow with every name a peer makes up).
    #[error("env '{}' is not one of this run's", equiarm_msgs::shown(.0))]
    UnknownEnv(String),
}

impl BadTransition {
    /// The kind of defect, for logging each kind once per sender.
    pub fn cause(&self) -> &'static str {
        match self {
            BadTransition::Reward(_) => "reward",
            BadTransition::Action { .. } => "action",
            BadTransition::Orphan { .. } => "orphan",
            BadTransition::UnknownEnv(_) => "unknown env",
        }
    }
}

/// A Transition's reward and action as the replay accepts them.
fn check_values(t: &Transition) -> Result<(), BadTransition> {
    if !(t.reward.is_finite() && t.reward.abs() <= MAX_ABS_REWARD) {
        return Err(BadTransition::Reward(t.reward));
    }
    let a = &t.action;
    let fields = [("open_ratio", a.open_ratio), ("dx", a.dx), ("dy", a.dy), ("dz", a.dz), ("dtheta", a.dtheta)];
    match fields.into_iter().find(|(_, v)| !v.is_finite()) {
        Some((field, value)) => Err(BadTransition::Action { field, value }),
        None => Ok(()),
    }
}

/// Transitions and episode results → replay rows, without DDS.
pub struct Ingest {
    eval_env: String,
    image_size: usize,
    timeout_terminal: bool,
    envs: HashMap<String, EnvFrames>,
    /// The run's training envs, when known ([`Ingest::with_envs`]): Transitions of others are refused.
    known: Option<BTreeSet<String>>,
    held: HashMap<Key, (Vec<Stored>, bool)>,
    decided: HashMap<Key, bool>,
    /// What happened so far.
    pub counts: Received,
}

impl Ingest {
    /// For a run with `cfg`; `eval_namespace` names the eval env (`/eval` → `eval`).
    pub fn new(cfg: &TrainConfig, eval_namespace: &str) -> Self {
        let eval_env = eval_namespace.trim_matches('/').to_string();
        Ingest {
            eval_env,
            image_size: cfg.image_size,
            timeout_terminal: cfg.timeout_terminal,
            envs: HashMap::new(),
            known: None,
            held: HashMap::new(),
            decided: HashMap::new(),
            counts: Received::default(),
        }
    }

    /// The same ingest, taking Transitions only from these training envs (namespaces or names:
    /// `/env0` or `env0`) and the eval env; others are refused as [`BadTransition::UnknownEnv`].
    pub fn with_envs<S: AsRef<str>>(mut self, envs: &[S]) -> Self {
        self.known = Some(envs.iter().map(|e| e.as_ref().trim_matches('/').to_string()).collect());
        self
    }

    /// Transitions waiting for their Observations now (all envs): at the end of a run, those whose
    /// frames never came.
    pub fn waiting(&self) -> u64 {
        self.envs.values().map(|e| e.waiting.len() as u64).sum()
    }

    /// Whether an env name is the eval env.
    pub fn is_eval(&self, env: &str) -> bool {
        env == self.eval_env
    }

    /// An Observation of a training env: its frame is kept for the Transitions that name it; the
    /// Transitions that waited for it are returned, joined.
    pub fn observation(&mut self, o: &Observation) -> Result<Vec<Joined>, BadFrame> {
        if self.is_eval(&o.env) {
            return Ok(vec![]);
        }
        let env = self.envs.entry(o.env.clone()).or_default();
        if let std::collections::btree_map::Entry::Vacant(slot) = env.frames.entry(o.seq) {
            let f = match frame_of_size(o, self.image_size) {
                Ok(f) => f,
                Err(e) => {
                    self.counts.bad_frames += 1;
                    env.refused.insert(o.seq);
                    while env.refused.len() > MAX_FRAMES {
                        env.refused.pop_first();
                    }
                    let before = env.waiting.len();
                    env.waiting.retain(|t| t.obs_seq != o.seq && t.next_obs_seq != o.seq);
                    self.counts.bad += (before - env.waiting.len()) as u64;
                    return Err(e);
                }
            };
            slot.insert(Arc::new(f));
            while env.frames.len() > MAX_FRAMES {
                env.frames.pop_first();
            }
        }
        let mut joined = Vec::new();
        let mut still = VecDeque::new();
        for t in std::mem::take(&mut env.waiting) {
            match env.frames_of(&t) {
                Some((obs, next_obs)) => joined.push(Joined { t, obs, next_obs }),
                None => still.push_back(t),
            }
        }
        env.waiting = still;
        Ok(joined)
    }

    /// A Transition: joined with its frames now, or waiting for them (`None`; also for the eval
    /// env's, which are only counted).
    pub fn transition(&mut self, t: Transition) -> Result<Option<Joined>, BadTransition> {
        self.counts.transitions += 1;
        if self.is_eval(&t.env) {
            self.counts.eval += 1;
            return Ok(None);
        }
        if let Err(e) = check_values(&t) {
            self.counts.bad += 1;
            return Err(e);
        }
        if self.known.as_ref().is_some_and(|k| !k.contains(&t.env)) {
            self.counts.bad += 1;
            return Err(BadTransition::UnknownEnv(t.env));
        }
        let env = self.envs.entry(t.env.clone()).or_default();
        if let Some(&seq) = [t.obs_seq, t.next_obs_seq].iter().find(|s| env.refused.contains(s)) {
            self.counts.bad += 1;
            return Err(BadTransition::Orphan { seq });
        }
        match env.frames_of(&t) {
            Some((obs, next_obs)) => Ok(Some(Joined { t, obs, next_obs })),
            None => {
                env.waiting.push_back(t);
                if env.waiting.len() > MAX_WAITING {
                    env.waiting.pop_front();
                    self.counts.unmatched += 1;
                }
                Ok(None)
            }
        }
    }

    /// The rows to store now for a joined transition (none while an expert episode is undecided).
    pub fn rows(&mut self, j: Joined) -> Vec<Stored> {
        let Joined { t, obs, next_obs } = j;
        let action = action_of(&t.action).to_normalized();
        let done = t.done || (t.timeout && self.timeout_terminal);
        let row = Stored { obs, next_obs, action, reward: t.reward, done, expert: t.expert };
        if !t.expert {
            self.counts.stored += 1;
            return vec![row];
        }
        let key = (t.env.clone(), t.episode);
        let last = t.done || t.timeout;
        let decided = if last { self.decided.remove(&key) } else { self.decided.get(&key).copied() };
        match decided {
            Some(true) => {
                self.counts.stored += 1;
                vec![row]
            }
            Some(false) => {
                self.counts.expert_dropped += 1;
                vec![]
            }
            None => {
                let h = self.held.entry(key).or_default();
                h.0.push(row);
                h.1 |= last;
                self.counts.expert_held += 1;
                vec![]
            }
        }
    }

    /// The held expert rows `r` releases (its episode succeeded); drops them on failure.
    pub fn episode(&mut self, r: &EpisodeResult) -> Vec<Stored> {
        let key = (r.env.clone(), r.episode);
        let (rows, complete) = self.held.remove(&key).unwrap_or_default();
        if !complete && (r.expert || !rows.is_empty()) {
            self.decided.insert(key, r.success);
        }
        if r.expert || !rows.is_empty() {
            self.counts.expert_episodes.0 += 1;
            self.counts.expert_episodes.1 += r.success as usize;
        }
        self.counts.expert_held -= rows.len() as u64;
        if r.success {
            self.counts.stored += rows.len() as u64;
            rows
        } else {
            self.counts.expert_dropped += rows.len() as u64;
            vec![]
        }
    }
}

/// How many updates the trainer owes, as the paper's loop makes them: one per `num_envs` training
/// transitions (one vector step of the envs), counted once the replay holds `training_starts` rows.
///
/// Expert demonstrations are held until their episode's result, so they can be what brings the
/// replay to `training_starts` although the transitions that carried them owed nothing. Then one
/// update is owed at the release: the policies, held by `--max-lead` until the trainer updates, may
/// send no more transitions, and without it the run would wait for the idle timeout.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UpdateDebt {
    num_envs: usize,
    training_starts: usize,
    since: usize,
    owed: u64,
}

impl UpdateDebt {
    /// No update owed yet; `training_starts` below 1 counts as 1.
    pub fn new(num_envs: usize, training_starts: usize) -> Self {
        Self { num_envs: num_envs.max(1), training_starts: training_starts.max(1), since: 0, owed: 0 }
    }

    /// Whether `stored` rows (replay and queue) are enough to train.
    pub fn ready(&self, stored: usize) -> bool {
        stored >= self.training_starts
    }

    /// A training env's transition was ingested; `stored` rows are held now (replay and queue).
    pub fn transition(&mut self, stored: usize) {
        self.since += 1;
        if self.since >= self.num_envs {
            self.since = 0;
            self.owed += self.ready(stored) as u64;
        }
    }

    /// An episode result was ingested, taking the stored rows from `before` to `after` (the demos it
    /// released, if any).
    pub fn episode(&mut self, before: usize, after: usize) {
        if !self.ready(before) && self.ready(after) && self.owed == 0 {
            self.owed = 1;
        }
    }

    /// Updates owed now.
    pub fn owed(&self) -> u64 {
        self.owed
    }

    /// One owed update is being made; false if none was owed.
    pub fn pay(&mut self) -> bool {
        let some = self.owed > 0;
        self.owed = self.owed.saturating_sub(1);
        some
    }
}

#[cfg(test)]
mod debt_tests {
    use super::UpdateDebt;

    #[test]
    fn one_update_per_vector_step_once_the_replay_is_ready() {
        let mut d = UpdateDebt::new(2, 4);
        for stored in 1..=3 {
            d.transition(stored);
        }
        assert_eq!(d.owed(), 0, "not ready before 4 rows");
        d.transition(4); // the 2nd of the 2nd vector step: ready
        d.transition(5);
        d.transition(6);
        assert_eq!(d.owed(), 2);
        assert!(d.pay() && d.pay() && !d.pay());
        assert_eq!(d.owed(), 0);
    }

    #[test]
    fn demos_released_by_a_result_owe_one_update_even_after_the_learned_steps_came_first() {
        // One env, 5 held demo transitions and then the policy's one allowed learned step (max-lead
        // 1), all ingested before the episode's result: none of them found the replay ready.
        let mut d = UpdateDebt::new(1, 5);
        for _ in 0..6 {
            d.transition(0);
        }
        assert_eq!(d.owed(), 0);
        // The result releases the 5 demos (and the learned row was queued too): one update is owed,
        // else the policy, held until the trainer updates, and the trainer would wait for each other.
        d.episode(1, 6);
        assert_eq!(d.owed(), 1);
        // Results that release nothing, or that find the replay ready already, owe nothing more.
        d.episode(6, 6);
        d.episode(6, 11);
        assert_eq!(d.owed(), 1);
    }

    #[test]
    fn a_release_owes_nothing_extra_when_updates_are_owed_already() {
        let mut d = UpdateDebt::new(1, 2);
        d.transition(3);
        assert_eq!(d.owed(), 1);
        d.episode(1, 3);
        assert_eq!(d.owed(), 1);
    }
}

#[cfg(test)]
mod env_tests {
    use super::*;

    /// Regression (issue 61): a Transition of any env name was kept waiting for Observations the
    /// trainer never receives, so a peer inventing names grew the ingest's state without bound. With
    /// the run's envs known, others are refused and counted; the run's and the eval env's are taken.
    #[test]
    fn transitions_of_envs_outside_the_run_are_refused_and_counted() {
        let cfg = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
        let mut ingest = Ingest::new(&cfg, "/eval").with_envs(&["/env0", "/env1"]);
        for k in 0..1000 {
            let t = Transition { env: format!("made_up_{k}"), obs_seq: 0, next_obs_seq: 1, ..Default::default() };
            let e = ingest.transition(t).unwrap_err();
            assert!(matches!(e, BadTransition::UnknownEnv(_)) && e.cause() == "unknown env", "{e}");
        }
        assert_eq!((ingest.counts.bad, ingest.envs.len(), ingest.waiting()), (1000, 0, 0));
        let ok = |env: &str| Transition { env: env.into(), obs_seq: 0, next_obs_seq: 1, ..Default::default() };
        assert!(ingest.transition(ok("env1")).unwrap().is_none(), "waits for its Observations");
        assert!(ingest.transition(ok("eval")).unwrap().is_none(), "the eval env's are counted");
        assert_eq!((ingest.waiting(), ingest.counts.eval), (1, 1));
    }
}
