//! Episode metrics from recorded messages: per-episode success, return and discounted return, taken
//! from `EpisodeResult`s or, for bags without them, reconstructed from `Transition`s; success rates
//! with Wilson 95 % intervals, split by env, train/eval and expert/policy.

use std::collections::BTreeMap;

use equiarm_msgs::msg::{EpisodeResult, Transition};

/// One finished episode.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    /// Environment name, e.g. `env0`.
    pub env: String,
    /// Task name (empty when reconstructed from transitions).
    pub task: String,
    /// Episode index within the env.
    pub episode: u32,
    /// Steps taken.
    pub steps: u32,
    /// The task's success test held at the end.
    pub success: bool,
    /// Undiscounted return.
    pub ret: f64,
    /// Discounted return.
    pub discounted_return: f64,
    /// Every action came from the expert.
    pub expert: bool,
    /// An evaluation episode.
    pub eval: bool,
}

impl From<&EpisodeResult> for Episode {
    fn from(r: &EpisodeResult) -> Self {
        Self {
            env: r.env.clone(),
            task: r.task.clone(),
            episode: r.episode,
            steps: r.steps,
            success: r.success,
            ret: r.ret as f64,
            discounted_return: r.discounted_return as f64,
            expert: r.expert,
            eval: r.eval,
        }
    }
}

#[derive(Default)]
struct Partial {
    steps: u32,
    ret: f64,
    discounted: f64,
    expert: bool,
}

/// Collects episodes from the messages of a bag, in any interleaving of envs.
pub struct EpisodeCollector {
    gamma: f64,
    results: Vec<Episode>,
    from_transitions: Vec<Episode>,
    open: BTreeMap<(String, u32), Partial>,
}

impl EpisodeCollector {
    /// `gamma` discounts rewards of episodes reconstructed from transitions.
    pub fn new(gamma: f64) -> Self {
        Self { gamma, results: Vec::new(), from_transitions: Vec::new(), open: BTreeMap::new() }
    }

    /// Adds an `EpisodeResult`.
    pub fn add_result(&mut self, r: &EpisodeResult) {
        self.results.push(r.into());
    }

    /// Adds a `Transition`; an episode ends at a transition with `done` or `timeout`. Sparse tasks
    /// reward 1 exactly on success, so a final reward > 0 with `done` counts as success.
    pub fn add_transition(&mut self, t: &Transition) {
        let key = (t.env.clone(), t.episode);
        let p = self.open.entry(key.clone()).or_insert_with(|| Partial { expert: true, ..Default::default() });
        let r = t.reward as f64;
        p.ret += r;
        p.discounted += self.gamma.powi(t.step as i32) * r;
        p.steps = p.steps.max(t.step + 1);
        p.expert &= t.expert;
        if t.done || t.timeout {
            let p = self.open.remove(&key).expect("just inserted");
            self.from_transitions.push(Episode {
                env: key.0,
                task: String::new(),
                episode: key.1,
                steps: p.steps,
                success: t.done && t.reward > 0.0,
                ret: p.ret,
                discounted_return: p.discounted,
                expert: p.expert,
                eval: false,
            });
        }
    }

    /// The episodes: from `EpisodeResult`s when the bag had any, else from transitions. Returns also
    /// whether they were reconstructed, and how many episodes were still unfinished.
    pub fn finish(self) -> (Vec<Episode>, bool, usize) {
        if self.results.is_empty() { (self.from_transitions, true, self.open.len()) } else { (self.results, false, 0) }
    }
}

/// A success rate with its Wilson score interval.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rate {
    /// Successes.
    pub successes: u64,
    /// Trials.
    pub n: u64,
    /// successes / n (NaN when n = 0).
    pub rate: f64,
    /// Lower end of the 95 % Wilson interval.
    pub lo: f64,
    /// Upper end of the 95 % Wilson interval.
    pub hi: f64,
}

/// Wilson score interval at 95 % (z = 1.96) for `successes` of `n`.
pub fn wilson(successes: u64, n: u64) -> Rate {
    if n == 0 {
        return Rate { successes, n, rate: f64::NAN, lo: f64::NAN, hi: f64::NAN };
    }
    let z = 1.959_963_984_540_054_f64;
    let (k, n_f) = (successes as f64, n as f64);
    let p = k / n_f;
    let denom = 1.0 + z * z / n_f;
    let centre = (p + z * z / (2.0 * n_f)) / denom;
    let half = z * (p * (1.0 - p) / n_f + z * z / (4.0 * n_f * n_f)).sqrt() / denom;
    Rate { successes, n, rate: p, lo: (centre - half).max(0.0), hi: (centre + half).min(1.0) }
}

/// Statistics of one group of episodes.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupStats {
    /// Env name, or `*` for all envs.
    pub env: String,
    /// Evaluation episodes.
    pub eval: bool,
    /// Expert episodes.
    pub expert: bool,
    /// Success rate.
    pub success: Rate,
    /// Mean undiscounted return.
    pub mean_return: f64,
    /// Mean discounted return.
    pub mean_discounted_return: f64,
    /// Mean episode length in steps.
    pub mean_steps: f64,
}

/// Groups episodes by (env, eval, expert), plus the all-env totals per (eval, expert), sorted.
pub fn summarize(episodes: &[Episode]) -> Vec<GroupStats> {
    let mut groups: BTreeMap<(bool, bool, String), Vec<&Episode>> = BTreeMap::new();
    for e in episodes {
        groups.entry((e.eval, e.expert, e.env.clone())).or_default().push(e);
        groups.entry((e.eval, e.expert, "*".into())).or_default().push(e);
    }
    groups
        .into_iter()
        .map(|((eval, expert, env), eps)| {
            let n = eps.len() as f64;
            GroupStats {
                env,
                eval,
                expert,
                success: wilson(eps.iter().filter(|e| e.success).count() as u64, eps.len() as u64),
                mean_return: eps.iter().map(|e| e.ret).sum::<f64>() / n,
                mean_discounted_return: eps.iter().map(|e| e.discounted_return).sum::<f64>() / n,
                mean_steps: eps.iter().map(|e| e.steps as f64).sum::<f64>() / n,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_matches_known_values() {
        // 8 of 10: the textbook Wilson interval is [0.490, 0.943]
        let r = wilson(8, 10);
        assert!((r.lo - 0.4902).abs() < 1e-3 && (r.hi - 0.9433).abs() < 1e-3, "{r:?}");
        let r = wilson(0, 20);
        assert_eq!(r.lo, 0.0);
        assert!((r.hi - 0.1611).abs() < 1e-3, "{r:?}");
        assert!(wilson(0, 0).rate.is_nan());
    }

    fn tr(env: &str, episode: u32, step: u32, reward: f32, done: bool, timeout: bool) -> Transition {
        Transition { env: env.into(), episode, step, reward, done, timeout, expert: true, ..Default::default() }
    }

    #[test]
    fn transitions_of_interleaved_envs_make_episodes() {
        let mut c = EpisodeCollector::new(0.5);
        c.add_transition(&tr("env0", 0, 0, 0.0, false, false));
        c.add_transition(&tr("env1", 0, 0, 0.0, false, false));
        c.add_transition(&tr("env0", 0, 1, 1.0, true, false));
        c.add_transition(&tr("env1", 0, 1, 0.0, false, true));
        c.add_transition(&tr("env1", 1, 0, 0.0, false, false));
        let (eps, reconstructed, unfinished) = c.finish();
        assert!(reconstructed);
        assert_eq!(unfinished, 1);
        assert_eq!(eps.len(), 2);
        assert_eq!((eps[0].env.as_str(), eps[0].success, eps[0].steps), ("env0", true, 2));
        assert_eq!(eps[0].discounted_return, 0.5);
        assert!(!eps[1].success);
        let s = summarize(&eps);
        let all = s.iter().find(|g| g.env == "*").unwrap();
        assert_eq!((all.success.successes, all.success.n), (1, 2));
    }
}
