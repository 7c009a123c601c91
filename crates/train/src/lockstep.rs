//! The trainer's rounds in `--deterministic` mode, without DDS: `/transitions` and `/episodes` of
//! the training envs are collected per env and handed on in an order that does not depend on
//! arrival times.
//!
//! Round r is every training env's r-th transition (counted from 0 per env). It is complete when
//! `num_envs` distinct envs (discovered by name) have delivered their r-th transition and, for each
//! of those transitions that ends an episode (`done` or `timeout`), that env's `EpisodeResult` of the
//! episode has arrived too. A complete round comes out in env-name order (byte order: `env10` sorts
//! before `env2`), each transition followed by its episode's result when it ends one.
//!
//! Bad input never panics: a transition or result from an env beyond `num_envs`, a transition whose
//! seq does not follow the env's last one, or a second result for one episode is refused with an
//! error naming it; [`Lockstep::waiting_for`] says what an incomplete round lacks.
//!
//! ## Limitations
//! Rounds only complete while every env keeps going: one env that stops (or one lost transition)
//! stalls them all. The eval env is not part of the rounds (the caller routes it elsewhere).

use std::collections::{BTreeMap, VecDeque};

use equiarm_msgs::msg::EpisodeResult;

use crate::ingest::Joined;

/// A message the rounds refused, and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// A message from an env beyond the run's `num_envs` training envs.
    #[error("{what} from env '{env}' ignored: the run has num_envs = {num_envs} training envs ({known})")]
    ExtraEnv {
        /// The message, e.g. `transition (seq 4)`.
        what: String,
        /// Its env.
        env: String,
        /// The run's training envs.
        num_envs: usize,
        /// The envs known, comma-separated.
        known: String,
    },
    /// A transition whose seq does not follow its env's last one.
    #[error(
        "transition of env '{env}' with seq {seq} ignored: it does not follow seq {last} (a repeat, or a restarted sim)"
    )]
    OutOfOrder {
        /// Its env.
        env: String,
        /// Its seq.
        seq: u64,
        /// The env's last seq.
        last: u64,
    },
    /// A second result for one episode.
    #[error("a second EpisodeResult of env '{env}' episode {episode} ignored")]
    SecondResult {
        /// Its env.
        env: String,
        /// The episode.
        episode: u32,
    },
}

/// One message of a round, in processing order.
#[derive(Clone, Debug)]
pub enum Item {
    /// An env's transition of this round, with its frames.
    Transition(Box<Joined>),
    /// The result of the episode that transition ended.
    Episode(EpisodeResult),
}

/// What one training env has delivered and what is still waiting.
#[derive(Debug, Default)]
struct Lane {
    transitions: VecDeque<Joined>,
    results: BTreeMap<u32, EpisodeResult>,
    last_seq: Option<u64>,
    /// The results of the episodes below this one were handed on.
    closed_below: u32,
}

/// Collects the training envs' messages and hands them on round by round.
#[derive(Debug)]
pub struct Lockstep {
    num_envs: usize,
    lanes: BTreeMap<String, Lane>,
    rounds: u64,
}

fn ends_episode(j: &Joined) -> bool {
    j.t.done || j.t.timeout
}

impl Lockstep {
    /// Rounds of `num_envs` training envs (at least 1).
    pub fn new(num_envs: usize) -> Self {
        Lockstep { num_envs: num_envs.max(1), lanes: BTreeMap::new(), rounds: 0 }
    }

    /// Rounds handed on so far.
    pub fn rounds(&self) -> u64 {
        self.rounds
    }

    /// The lane of `env`, creating it while fewer than `num_envs` envs are known.
    fn lane(&mut self, env: &str, what: &str) -> Result<&mut Lane, Refused> {
        if !self.lanes.contains_key(env) {
            if self.lanes.len() >= self.num_envs {
                let known: Vec<&str> = self.lanes.keys().map(String::as_str).collect();
                return Err(Refused::ExtraEnv {
                    what: what.to_string(),
                    env: env.to_string(),
                    num_envs: self.num_envs,
                    known: known.join(", "),
                });
            }
            self.lanes.insert(env.to_string(), Lane::default());
        }
        Ok(self.lanes.get_mut(env).expect("inserted above"))
    }

    /// Takes a training env's transition.
    pub fn transition(&mut self, t: Joined) -> Result<(), Refused> {
        let (env, seq) = (t.t.env.clone(), t.t.obs_seq);
        let lane = self.lane(&env, &format!("transition (seq {seq})"))?;
        if let Some(last) = lane.last_seq.filter(|&last| seq <= last) {
            return Err(Refused::OutOfOrder { env, seq, last });
        }
        lane.last_seq = Some(seq);
        lane.transitions.push_back(t);
        Ok(())
    }

    /// Takes a training env's episode result.
    pub fn episode(&mut self, r: EpisodeResult) -> Result<(), Refused> {
        let (env, episode) = (r.env.clone(), r.episode);
        let lane = self.lane(&env, &format!("EpisodeResult (episode {episode})"))?;
        if episode < lane.closed_below || lane.results.contains_key(&episode) {
            return Err(Refused::SecondResult { env, episode });
        }
        lane.results.insert(episode, r);
        Ok(())
    }

    /// Whether the next round is complete.
    pub fn ready(&self) -> bool {
        self.lanes.len() >= self.num_envs
            && self.lanes.values().all(|l| {
                l.transitions.front().is_some_and(|t| !ends_episode(t) || l.results.contains_key(&t.t.episode))
            })
    }

    /// The next round's messages in processing order, if it is complete.
    pub fn next_round(&mut self) -> Option<Vec<Item>> {
        if !self.ready() {
            return None;
        }
        let mut items = Vec::with_capacity(self.lanes.len() + 1);
        for lane in self.lanes.values_mut() {
            let t = lane.transitions.pop_front().expect("ready checked it");
            let result = if ends_episode(&t) { lane.results.remove(&t.t.episode) } else { None };
            items.push(Item::Transition(Box::new(t)));
            if let Some(r) = result {
                lane.closed_below = r.episode.saturating_add(1);
                items.push(Item::Episode(r));
            }
        }
        self.rounds += 1;
        Some(items)
    }

    /// What the next round is waiting for, e.g. `["transition 7 of env1", "EpisodeResult of env0 episode 2"]`.
    pub fn waiting_for(&self) -> Vec<String> {
        let mut w = Vec::new();
        if self.lanes.len() < self.num_envs {
            let known: Vec<&str> = self.lanes.keys().map(String::as_str).collect();
            w.push(format!(
                "{} more training env(s) (num_envs = {}; known: {})",
                self.num_envs - self.lanes.len(),
                self.num_envs,
                known.join(", ")
            ));
        }
        for (env, l) in &self.lanes {
            match l.transitions.front() {
                None => w.push(format!("transition {} of {env}", self.rounds)),
                Some(t) if ends_episode(t) && !l.results.contains_key(&t.t.episode) => {
                    w.push(format!("EpisodeResult of {env} episode {}", t.t.episode))
                }
                Some(_) => {}
            }
        }
        w
    }

    /// Messages received but not handed on (transitions, results).
    pub fn pending(&self) -> (usize, usize) {
        self.lanes.values().fold((0, 0), |(t, r), l| (t + l.transitions.len(), r + l.results.len()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tr(env: &str, episode: u32, seq: u64, last: bool) -> Joined {
        let mut t = equiarm_msgs::msg::Transition::default();
        (t.env, t.episode, t.obs_seq, t.next_obs_seq, t.done) = (env.into(), episode, seq, seq + 1, last);
        let frame = std::sync::Arc::new(
            equiarm_sac::frame::StoredFrame::new(8, vec![0; 8 * 8 * 3], &[0.0; 64], false).unwrap(),
        );
        Joined { t, obs: frame.clone(), next_obs: frame }
    }

    fn res(env: &str, episode: u32) -> EpisodeResult {
        EpisodeResult { env: env.into(), episode, ..Default::default() }
    }

    fn names(items: &[Item]) -> Vec<String> {
        items
            .iter()
            .map(|i| match i {
                Item::Transition(t) => format!("{}:{}", t.t.env, t.t.obs_seq),
                Item::Episode(r) => format!("{}:ep{}", r.env, r.episode),
            })
            .collect()
    }

    #[test]
    fn a_round_needs_every_env_and_comes_out_in_env_order_whatever_the_arrival_order() {
        let mut a = Lockstep::new(2);
        a.transition(tr("env1", 0, 0, false)).unwrap();
        a.transition(tr("env1", 0, 1, false)).unwrap();
        assert!(a.next_round().is_none());
        assert!(a.waiting_for()[0].contains("1 more training env"), "{:?}", a.waiting_for());
        a.transition(tr("env0", 0, 0, false)).unwrap();
        assert_eq!(names(&a.next_round().unwrap()), ["env0:0", "env1:0"]);
        assert_eq!(a.waiting_for(), ["transition 1 of env0"]);
        assert!(a.next_round().is_none());
        a.transition(tr("env0", 0, 1, false)).unwrap();
        assert_eq!(names(&a.next_round().unwrap()), ["env0:1", "env1:1"]);
        assert_eq!((a.rounds(), a.pending()), (2, (0, 0)));
    }

    #[test]
    fn an_episode_end_waits_for_its_result_which_follows_its_transition() {
        let mut a = Lockstep::new(2);
        a.transition(tr("env0", 0, 0, true)).unwrap();
        a.transition(tr("env1", 3, 40, false)).unwrap();
        assert!(!a.ready());
        assert_eq!(a.waiting_for(), ["EpisodeResult of env0 episode 0"]);
        // A result may arrive early (for an episode still running): it waits for its transition.
        a.episode(res("env1", 3)).unwrap();
        a.episode(res("env0", 0)).unwrap();
        assert_eq!(names(&a.next_round().unwrap()), ["env0:0", "env0:ep0", "env1:40"]);
        a.transition(tr("env0", 1, 2, false)).unwrap();
        a.transition(tr("env1", 3, 41, true)).unwrap();
        assert_eq!(names(&a.next_round().unwrap()), ["env0:2", "env1:41", "env1:ep3"]);
    }

    #[test]
    fn bad_input_is_refused_with_its_name_and_never_panics() {
        let mut a = Lockstep::new(1);
        a.transition(tr("env0", 0, 5, true)).unwrap();
        let e = a.transition(tr("env9", 0, 0, false)).unwrap_err().to_string();
        assert!(e.contains("'env9'") && e.contains("num_envs = 1") && e.contains("env0"), "{e}");
        let e = a.episode(res("env9", 0)).unwrap_err().to_string();
        assert!(e.contains("EpisodeResult") && e.contains("'env9'"), "{e}");
        let e = a.transition(tr("env0", 0, 5, false)).unwrap_err().to_string();
        assert!(e.contains("seq 5") && e.contains("does not follow"), "{e}");
        a.episode(res("env0", 0)).unwrap();
        assert!(
            a.episode(res("env0", 0)).unwrap_err().to_string().contains("second EpisodeResult of env 'env0' episode 0")
        );
        assert_eq!(a.next_round().map(|r| r.len()), Some(2));
        assert!(a.episode(res("env0", 0)).unwrap_err().to_string().contains("second"), "a result of a closed episode");
        assert_eq!(Lockstep::new(0).num_envs, 1);
    }
}
