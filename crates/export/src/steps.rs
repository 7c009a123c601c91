//! A bag's steps, episode by episode: each Transition joined with the two Observations it names (by
//! env and seq), as the trainer joins them, and grouped by (env, episode) with the episode's
//! EpisodeResult.
//!
//! The bag is read once, in file order, with bounded memory: per env the compressed Observations of
//! the last [`WINDOW`] seqs (a re-published copy of one already held is counted and ignored), and the
//! Transitions still waiting for theirs; an episode is handed over as soon as its EpisodeResult has
//! come and all its steps are joined, the rest (episodes cut off by the end of the recording, or
//! missing a step) at the end, in (env, episode) order. Damaged chunks and truncated files are
//! skipped and reported as `equiarm bag info` reports them.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use equiarm_bag::{DecodeError, ReadMode, Reader};
use equiarm_msgs::RosMessage;
use equiarm_msgs::msg::{EpisodeResult, Observation, Transition};

use crate::ExportError;

/// Frames kept per env below the newest seq seen there; a Transition naming an older frame that is
/// not held is unmatched (the same bound as `launch_scripts/bag_transitions.py`'s default window).
pub const WINDOW: u64 = 200;
/// Episodes per env held while incomplete; past this the oldest is handed over as it is.
const MAX_OPEN_EPISODES: usize = 8;

/// One step: the Observation the action was chosen from and the Transition that took it.
#[derive(Clone, Debug)]
pub struct Step {
    /// The Observation `t.obs_seq` (images still compressed).
    pub obs: Observation,
    /// The Transition.
    pub t: Transition,
    /// The Observation `t.next_obs_seq` when the step ends the episode (done or timeout): its last frame.
    pub last: Option<Observation>,
}

/// One episode of one env, its steps in step order.
#[derive(Clone, Debug)]
pub struct Episode {
    /// The env, e.g. `env0`.
    pub env: String,
    /// The episode's index in that env.
    pub episode: u32,
    /// Its EpisodeResult, when the bag holds it.
    pub result: Option<EpisodeResult>,
    /// The joined steps.
    pub steps: Vec<Step>,
}

impl Episode {
    /// Every step from 0 to the result's step count is here.
    pub fn complete(&self) -> bool {
        self.result.as_ref().is_some_and(|r| r.steps as usize == self.steps.len())
    }
}

/// What reading the bag found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StepReport {
    /// Transitions joined with both their Observations.
    pub joined: u64,
    /// Transitions whose Observations were not in the bag (within the window).
    pub unmatched: u64,
    /// Observations recorded more than once (the sim re-publishes an unanswered one): the copies.
    pub duplicates: u64,
    /// Messages that did not decode (counted, skipped).
    pub undecodable: u64,
    /// Episodes handed over complete, and incomplete (cut off, or missing steps or a result).
    pub episodes: (u64, u64),
    /// Damage: files that end early and chunks lost, one line each (as `bag info` words them).
    pub damage: Vec<String>,
}

#[derive(Default)]
struct EnvState {
    frames: BTreeMap<u64, Observation>,
    newest: u64,
    waiting: Vec<Transition>,
    open: BTreeMap<u32, Episode>,
}

/// Reads `bag` and calls `out` with each episode (see the module docs for the order).
pub fn episodes(
    bag: &Path,
    mut out: impl FnMut(Episode) -> Result<(), ExportError>,
) -> Result<StepReport, ExportError> {
    let reader = Reader::open(bag)?;
    let mut envs: HashMap<String, EnvState> = HashMap::new();
    let mut results: HashMap<(String, u32), EpisodeResult> = HashMap::new();
    let mut report = StepReport::default();
    let read = reader.for_each(ReadMode::Salvage, |m| -> Result<(), ExportError> {
        let decoded = match m.type_name {
            Observation::TYPE_NAME => m.decode::<Observation>().map(|o| observation(&mut envs, o, &mut report)),
            Transition::TYPE_NAME => m.decode::<Transition>().map(|t| {
                let env = t.env.clone();
                envs.entry(env.clone()).or_default().waiting.push(t);
                join(&env, &mut envs, &mut report)
            }),
            EpisodeResult::TYPE_NAME => m.decode::<EpisodeResult>().map(|r| {
                let env = r.env.clone();
                results.insert((r.env.clone(), r.episode), r);
                envs.entry(env).or_default();
            }),
            _ => return Ok(()),
        };
        match decoded {
            Err(cause @ DecodeError::OtherDefinition { .. }) => {
                return Err(ExportError::Decode { bag: bag.to_path_buf(), cause });
            }
            Err(DecodeError::Cdr { .. }) => report.undecodable += 1,
            Ok(()) => {}
        }
        // checked on Transitions and results only (Observations are most messages): an episode
        // completed by a late Observation goes out with the next one, or at the end
        if m.type_name == Observation::TYPE_NAME {
            return Ok(());
        }
        hand_over(&mut envs, &mut results, &mut report, false, &mut out)
    })??;
    // the Transitions still waiting name frames the bag does not hold
    for s in envs.values_mut() {
        report.unmatched += s.waiting.len() as u64;
        s.waiting.clear();
    }
    hand_over(&mut envs, &mut results, &mut report, true, &mut out)?;
    let info = equiarm_bag::BagInfo { truncated: read.truncated, lost: read.lost, ..Default::default() };
    report.damage = equiarm_train::bag_report::damage_lines(&info);
    Ok(report)
}

fn observation(envs: &mut HashMap<String, EnvState>, o: Observation, report: &mut StepReport) {
    let env = o.env.clone();
    let s = envs.entry(env.clone()).or_default();
    if s.frames.contains_key(&o.seq) {
        report.duplicates += 1;
        return;
    }
    s.newest = s.newest.max(o.seq);
    s.frames.insert(o.seq, o);
    let keep_from = s.newest.saturating_sub(WINDOW);
    s.frames = s.frames.split_off(&keep_from);
    join(&env, envs, report);
}

/// Joins what can be joined of `env`'s waiting Transitions; those naming frames below the window are
/// unmatched.
fn join(env: &str, envs: &mut HashMap<String, EnvState>, report: &mut StepReport) {
    let Some(s) = envs.get_mut(env) else { return };
    let keep_from = s.newest.saturating_sub(WINDOW);
    let mut still = Vec::new();
    for t in std::mem::take(&mut s.waiting) {
        match (s.frames.get(&t.obs_seq), s.frames.contains_key(&t.next_obs_seq)) {
            (Some(obs), true) => {
                report.joined += 1;
                let e = s.open.entry(t.episode).or_insert_with(|| Episode {
                    env: env.to_string(),
                    episode: t.episode,
                    result: None,
                    steps: Vec::new(),
                });
                let last = (t.done || t.timeout).then(|| s.frames[&t.next_obs_seq].clone());
                e.steps.push(Step { obs: obs.clone(), t, last });
            }
            _ if t.obs_seq < keep_from => report.unmatched += 1,
            _ => still.push(t),
        }
    }
    s.waiting = still;
}

/// Hands over the episodes that are complete (all of them with `all`), and the oldest open ones of an
/// env past [`MAX_OPEN_EPISODES`].
fn hand_over(
    envs: &mut HashMap<String, EnvState>,
    results: &mut HashMap<(String, u32), EpisodeResult>,
    report: &mut StepReport,
    all: bool,
    out: &mut impl FnMut(Episode) -> Result<(), ExportError>,
) -> Result<(), ExportError> {
    let mut names: Vec<&String> = envs.keys().collect();
    names.sort();
    let names: Vec<String> = names.into_iter().cloned().collect();
    for env in names {
        let s = envs.get_mut(&env).expect("a listed env");
        let mut ready = Vec::new();
        for (&episode, e) in s.open.iter_mut() {
            if e.result.is_none() {
                e.result = results.remove(&(env.clone(), episode));
            }
            if all || e.complete() {
                ready.push(episode);
            }
        }
        while s.open.len() - ready.len() > MAX_OPEN_EPISODES {
            let oldest = s.open.keys().find(|k| !ready.contains(k)).copied().expect("more open than ready");
            ready.push(oldest);
        }
        ready.sort();
        for episode in ready {
            let mut e = s.open.remove(&episode).expect("a ready episode");
            e.steps.sort_by_key(|st| st.t.step);
            if e.complete() {
                report.episodes.0 += 1;
            } else {
                report.episodes.1 += 1;
            }
            out(e)?;
        }
    }
    Ok(())
}
