//! What the trainer node makes of `/transitions` and `/episodes`, without DDS: replay rows with
//! each frame stored once (per env, the last `next_obs` is reused when the next Transition's `obs`
//! has its seq), expert demonstrations held per (env, episode) until the EpisodeResult says whether
//! the episode succeeded (the paper keeps only successful demos), the eval env never stored.
//! Topics are not ordered with respect to each other: a result may overtake its episode's last
//! transitions, and then decides them on arrival.

use std::collections::HashMap;
use std::sync::Arc;

use equiarm_msgs::msg::{EpisodeResult, Observation, Transition};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::replay::Stored;

use crate::policy::{BadFrame, action_of, frame_of};

/// What the trainer did with the transitions it received (N = stored + held + dropped + eval + bad).
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
    /// Malformed transitions (bad image, wrong size), skipped.
    pub bad: u64,
    /// Expert episodes decided, and kept (successful).
    pub expert_episodes: (usize, usize),
}

type Key = (String, u32);

/// Largest reward magnitude accepted from a peer: every task gives 0 or 1 (docs/paper.md §3.2), so a
/// larger one is a bug or an attack, and one such row would dominate the critic's loss.
pub const MAX_ABS_REWARD: f32 = 1000.0;

/// Why a Transition is refused (counted in [`Received::bad`], never stored).
#[derive(Debug, thiserror::Error)]
pub enum BadTransition {
    /// Its obs or next_obs makes no frame of the run's size.
    #[error(transparent)]
    Frame(#[from] BadFrame),
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
}

impl BadTransition {
    /// The kind of defect, for logging each kind once per sender.
    pub fn cause(&self) -> &'static str {
        match self {
            BadTransition::Frame(_) => "frame",
            BadTransition::Reward(_) => "reward",
            BadTransition::Action { .. } => "action",
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
    last_next: HashMap<String, (u64, Arc<StoredFrame>)>,
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
            last_next: HashMap::new(),
            held: HashMap::new(),
            decided: HashMap::new(),
            counts: Received::default(),
        }
    }

    /// Whether an env name is the eval env.
    pub fn is_eval(&self, env: &str) -> bool {
        env == self.eval_env
    }

    fn frame(&self, o: &Observation) -> Result<Arc<StoredFrame>, BadFrame> {
        if let Some((seq, f)) = self.last_next.get(&o.env)
            && *seq == o.seq
        {
            return Ok(f.clone());
        }
        let f = frame_of(o)?;
        if f.size() != self.image_size {
            return Err(BadFrame::Size { got: f.size(), want: self.image_size });
        }
        Ok(Arc::new(f))
    }

    /// The rows to store now for `t` (none for eval, held expert or malformed transitions).
    pub fn transition(&mut self, t: &Transition) -> Result<Vec<Stored>, BadTransition> {
        self.counts.transitions += 1;
        if self.is_eval(&t.obs.env) {
            self.counts.eval += 1;
            return Ok(vec![]);
        }
        if let Err(e) = check_values(t) {
            self.counts.bad += 1;
            return Err(e);
        }
        let frames = self.frame(&t.obs).and_then(|o| Ok((o, self.frame(&t.next_obs)?)));
        let (obs, next_obs) = frames.inspect_err(|_| self.counts.bad += 1)?;
        self.last_next.insert(t.next_obs.env.clone(), (t.next_obs.seq, next_obs.clone()));
        let action = action_of(&t.action).to_normalized();
        let done = t.done || (t.timeout && self.timeout_terminal);
        let row = Stored { obs, next_obs, action, reward: t.reward, done, expert: t.expert };
        if !t.expert {
            self.counts.stored += 1;
            return Ok(vec![row]);
        }
        let key = (t.obs.env.clone(), t.obs.episode);
        let last = t.done || t.timeout;
        let decided = if last { self.decided.remove(&key) } else { self.decided.get(&key).copied() };
        match decided {
            Some(true) => {
                self.counts.stored += 1;
                Ok(vec![row])
            }
            Some(false) => {
                self.counts.expert_dropped += 1;
                Ok(vec![])
            }
            None => {
                let h = self.held.entry(key).or_default();
                h.0.push(row);
                h.1 |= last;
                self.counts.expert_held += 1;
                Ok(vec![])
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
