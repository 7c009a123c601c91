//! The trainer node's logic without DDS: one [`Learner`] fed from the training envs'
//! `observation` topics, `/transitions` and `/episodes` through [`Ingest`] (which joins each
//! Transition with the frames of the Observations it names) (frames stored once, demos only from successful episodes, never the eval env),
//! evaluations from the eval env's episode results, actor snapshots ([`PolicyWeights`]) and a
//! [`TrainerStatus`] once per second. The node (`equiarm_nodes::trainer`) moves messages in and out
//! and runs updates on a blocking thread; [`Trainer`] decides everything else.
//!
//! - One update per `num_envs` non-eval transitions once the replay holds `training_starts`
//!   (docs/paper.md §2); updates owed while one runs are caught up ([`UpdateDebt`]).
//! - Weights: version 1 (the initial actor) at start, then after the first update, every
//!   `weights_every` updates and at every multiple of `eval_every` (where the eval policy's windows
//!   open), all with the run's id (made at a fresh start, kept in checkpoints), so
//!   a policy can tell a new run from an old version.
//! - Evaluations as in the paper: the eval env's episodes that end once the update count has
//!   reached the next multiple of `eval_every`, `eval_episodes` of them; the ones in between are
//!   dropped.
//! - `deterministic` (lock-step): the training envs' messages are taken in rounds ([`Lockstep`]):
//!   round r is every env's r-th transition, in env-name order, each followed by its episode's
//!   result when it ends one. After each round: its rows into the replay, one update once the
//!   replay is ready, then the next weights version (version r + 2; the policies answer their r-th
//!   observation with version r + 1). No weights go out after the round that reaches
//!   `total_updates`, so the envs stop there and two runs with one seed record the same transitions
//!   and end with the same weights. The eval pair is not part of the rounds.
//!
//! ## Limitations
//! EpisodeResults count as evaluation when `eval` is set (`equiarm sim --eval`) or their env is the
//! eval env; transitions only by their env. Resume restores the learner, metrics, evaluations and
//! weights version, not held demos; `deterministic` refuses resume. In lock-step a lost transition or
//! an env that stops stalls the rounds (logged with what the round waits for).

use std::collections::HashSet;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{EpisodeResult, PolicyWeights, TrainerStatus, Transition};
use equiarm_msgs::std_msgs::Header;
use equiarm_nn::burn::tensor::Device;
use equiarm_sac::agent::Metrics;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, LearnerError, read_json};
use equiarm_sac::replay::{ReplayError, Stored};
use log::{info, warn};
use serde::{Deserialize, Serialize};

use crate::TrainError;
use crate::evaluation::{EpisodeOutcome, EvalResult};
use crate::ingest::{Ingest, Joined, UpdateDebt};
use crate::lockstep::{Item, Lockstep, Refused};
use crate::progress::Progress;
use crate::record::{RunRecord, RunSummary};
use crate::rundir::find_checkpoint;

/// The state file the trainer node writes beside each checkpoint.
pub const STATE_FILE: &str = "trainer.json";

/// Saved beside each checkpoint ([`STATE_FILE`]).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
struct NodeState {
    /// The message schema the run's transport used ([`equiarm_msgs::SCHEMA_VERSION`]; absent: 1).
    #[serde(default = "schema_v1")]
    message_schema: u32,
    /// The run's id in its weights messages (kept when it resumes; absent in checkpoints written
    /// before weights carried run ids: such a run is given a new id when it resumes).
    #[serde(default)]
    run_id: String,
    global_step: u64,
    evals: Vec<EvalResult>,
    version: u64,
}

fn schema_v1() -> u32 {
    1
}

/// How a trainer runs (not part of the config: a checkpoint resumes under other options).
#[derive(Clone, Debug)]
pub struct TrainerOptions {
    /// The run directory.
    pub run_dir: PathBuf,
    /// Resume from this checkpoint (or run directory).
    pub resume: Option<PathBuf>,
    /// Move a run already in `run_dir` aside instead of refusing it.
    pub force: bool,
    /// The eval env's namespace: its transitions are never stored, its results are evaluations.
    pub eval_namespace: String,
    /// The training envs' namespaces: Transitions of other envs are refused (empty: any env's are
    /// taken).
    pub envs: Vec<String>,
    /// Lock-step rounds.
    pub deterministic: bool,
    /// Where the learner's tensors live.
    pub device: Device,
    /// Publish weights every this many updates (0: only the first update's).
    pub weights_every: u64,
    /// Show a progress line.
    pub progress: bool,
}

/// What the node is to do once the learner is home ([`Trainer::with_learner`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Next {
    /// Start an update.
    pub update: bool,
    /// Publish the next weights ([`Trainer::weights`]).
    pub weights: bool,
}

/// The trainer's state between messages.
pub struct Trainer {
    cfg: TrainConfig,
    opts: TrainerOptions,
    record: RunRecord,
    ingest: Ingest,
    lockstep: Option<Lockstep>,
    debt: UpdateDebt,
    pending_eval: Vec<EpisodeResult>,
    queue: Vec<Stored>,
    bad_logged: HashSet<(String, &'static str)>,
    refused: u64,
    /// Rows the replay had no room for: it was full of expert transitions, which are never
    /// overwritten (an expert policy that never hands over can fill it).
    no_room: u64,
    run_id: String,
    global_step: u64,
    version: u64,
    /// While the learner is away (an update running): its updates, replay length, expert rows and
    /// last metrics when it was last home.
    known: (u64, usize, usize, Metrics),
    started: Instant,
    last_round: Instant,
    stall_logged: Option<u64>,
    last_transition: Option<Instant>,
    last_status: (Instant, u64, u64),
    progress: Option<Progress>,
}

/// A new run's id: its task, model and seed, and the wall clock at its start (hex ns), so two
/// fresh runs never share one.
fn new_run_id(cfg: &TrainConfig) -> String {
    let ns = wall_stamp().stamp.as_nanos();
    format!("{}-{}-s{}-{ns:x}", cfg.task, cfg.agent.model.name(), cfg.seed)
}

/// A wall-clock header stamp.
fn wall_stamp() -> Header {
    let ns =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_nanos() as i64).unwrap_or(0);
    Header::new(Time::from_nanos(ns), "")
}

impl Trainer {
    /// Claim the run directory and build (or resume) the learner.
    pub fn open(cfg: TrainConfig, opts: TrainerOptions) -> Result<(Self, Learner), TrainError> {
        if opts.deterministic && opts.resume.is_some() {
            return Err(TrainError::run_dir(
                &opts.run_dir,
                "--deterministic does not resume (--resume): the policies count rounds from the first weights version of a fresh run",
            ));
        }
        crate::config::check(&cfg)?;
        let mut learner = Learner::with_device(cfg.clone(), opts.device.clone())?;
        let mut st = NodeState::default();
        let record = match &opts.resume {
            Some(p) => {
                let ck = find_checkpoint(p)?;
                learner.resume(&ck)?;
                st = read_json(&ck.join(STATE_FILE)).map_err(|e| {
                    TrainError::run_dir(
                        &ck,
                        format!("{e} (not a checkpoint of the trainer node: resume it with the in-process loop)"),
                    )
                })?;
                if st.message_schema != equiarm_msgs::SCHEMA_VERSION {
                    return Err(TrainError::run_dir(
                        &ck,
                        format!(
                            "written by a trainer with message schema {}, this one speaks {}: resume it with the equiarm that wrote it",
                            st.message_schema,
                            equiarm_msgs::SCHEMA_VERSION
                        ),
                    ));
                }
                info!("resumed {} at {} updates", ck.display(), learner.updates());
                RunRecord::open(
                    &cfg,
                    &opts.run_dir,
                    Some((&ck, st.global_step, std::mem::take(&mut st.evals))),
                    opts.force,
                )?
            }
            None => RunRecord::open(&cfg, &opts.run_dir, None, opts.force)?,
        };
        let now = Instant::now();
        let known = (learner.updates(), learner.replay().len(), learner.replay().expert_len(), Metrics::default());
        let trainer = Trainer {
            ingest: match opts.envs.is_empty() {
                true => Ingest::new(&cfg, &opts.eval_namespace),
                false => Ingest::new(&cfg, &opts.eval_namespace).with_envs(&opts.envs),
            },
            lockstep: opts.deterministic.then(|| Lockstep::new(cfg.num_envs)),
            debt: UpdateDebt::new(cfg.num_envs, cfg.training_starts),
            pending_eval: Vec::new(),
            queue: Vec::new(),
            bad_logged: HashSet::new(),
            refused: 0,
            no_room: 0,
            run_id: if st.run_id.is_empty() { new_run_id(&cfg) } else { st.run_id },
            global_step: st.global_step,
            version: st.version,
            started: now,
            last_round: now,
            stall_logged: None,
            last_transition: None,
            last_status: (now, known.0, 0),
            progress: opts.progress.then(|| Progress::new(cfg.total_updates, "updates")),
            known,
            record,
            cfg,
            opts,
        };
        Ok((trainer, learner))
    }

    /// Whether the rounds are lock-step.
    pub fn deterministic(&self) -> bool {
        self.lockstep.is_some()
    }

    fn wall(&self) -> f64 {
        self.started.elapsed().as_secs_f64()
    }

    /// Why the run is to stop now, if it is: a `signal`, `total_updates`, or no transition for `idle`.
    pub fn stop_reason(&self, signal: bool, idle: Duration) -> Option<&'static str> {
        if signal {
            Some("signal")
        } else if self.known.0 >= self.cfg.total_updates {
            Some("total_updates reached")
        } else {
            self.last_transition.is_some_and(|t| t.elapsed() > idle).then_some("idle timeout")
        }
    }

    /// Whether an update or a lock-step round could start if the learner were home.
    pub fn has_work(&self) -> bool {
        let ready = self.debt.ready(self.known.1 + self.queue.len());
        (self.debt.owed() > 0 && ready) || self.lockstep.as_ref().is_some_and(Lockstep::ready)
    }

    /// An Observation of a training env: its frame, kept for the Transitions that name it (those
    /// that waited for it go on now).
    pub fn observation(&mut self, o: &equiarm_msgs::msg::Observation) {
        match self.ingest.observation(o) {
            Ok(joined) => joined.into_iter().for_each(|j| self.joined(j)),
            Err(e) => self.log_bad(&o.env, o.seq, "observation", &e),
        }
    }

    /// A Transition from the graph: once joined with its frames, into the rows waiting for the
    /// learner, or (lock-step) into its round.
    pub fn transition(&mut self, t: Transition) {
        self.last_transition = Some(Instant::now());
        let (env, seq) = (t.env.clone(), t.obs_seq);
        match self.ingest.transition(t) {
            Ok(Some(j)) => self.joined(j),
            Ok(None) => {}
            Err(e) => self.log_bad(&env, seq, e.cause(), &e),
        }
    }

    /// Logs a refused message once per env and cause.
    /// (At most [`crate::policy::MAX_LOGGED_SENDERS`] pairs are remembered: a peer inventing env names cannot grow it.)
    fn log_bad(&mut self, env: &str, seq: u64, cause: &'static str, e: &dyn std::fmt::Display) {
        if self.bad_logged.len() < crate::policy::MAX_LOGGED_SENDERS && self.bad_logged.insert((env.to_string(), cause))
        {
            let env = equiarm_msgs::shown(env);
            warn!(
                "skipping a message of '{env}' (seq {seq}): {e} (further {cause} defects of this env are counted, not logged)"
            );
        }
    }

    /// A training env's transition with its frames.
    fn joined(&mut self, j: Joined) {
        match self.lockstep.as_mut() {
            Some(ls) => {
                let r = ls.transition(j);
                self.count_refused(r);
            }
            None => {
                self.take_transition(j);
                self.debt.transition(self.known.1 + self.queue.len());
            }
        }
    }

    fn take_transition(&mut self, j: Joined) {
        let rows = self.ingest.rows(j);
        self.queue.extend(rows);
        self.global_step += 1;
    }

    fn take_episode(&mut self, r: &EpisodeResult) -> Result<(), TrainError> {
        self.queue.extend(self.ingest.episode(r));
        let (step, wall) = (self.global_step, self.wall());
        self.record.episode(step, wall, r.ret as f64, r.discounted_return as f64, r.steps, r.success)
    }

    /// Lock-step: counts a message the rounds refused and logs it (the 1st, 2nd, 4th, 8th, …).
    fn count_refused(&mut self, r: Result<(), Refused>) {
        if let Err(e) = r {
            self.refused += 1;
            if self.refused.is_power_of_two() {
                warn!("{e} ({} refused so far)", self.refused);
            }
        }
    }

    /// An EpisodeResult from the graph: an evaluation episode, or a training env's (its metrics, and
    /// the demos it decides).
    pub fn episode(&mut self, r: EpisodeResult) -> Result<(), TrainError> {
        if r.eval || self.ingest.is_eval(&r.env) {
            let every = self.cfg.eval_every;
            let last = self.record.evals().last().map_or(0, |e| e.updates);
            let due = every > 0 && self.known.0 >= (last / every + 1) * every;
            if due {
                self.pending_eval.push(r);
            }
            if due && self.pending_eval.len() >= self.cfg.eval_episodes.max(1) {
                let episodes: Vec<_> = self
                    .pending_eval
                    .drain(..)
                    .map(|r| EpisodeOutcome {
                        success: r.success,
                        ret: r.ret as f64,
                        discounted: r.discounted_return as f64,
                        length: r.steps,
                    })
                    .collect();
                let e = EvalResult::from_episodes(self.known.0, &episodes);
                info!(
                    "evaluation at {} updates: success rate {:.2}, discounted return {:.3}",
                    e.updates, e.success_rate, e.discounted_return
                );
                let (step, wall) = (self.global_step, self.wall());
                self.record.evaluation(step, wall, e)?;
            }
            return Ok(());
        }
        match self.lockstep.as_mut() {
            Some(ls) => {
                let refused = ls.episode(r);
                self.count_refused(refused);
            }
            None => {
                let before = self.known.1 + self.queue.len();
                self.take_episode(&r)?;
                self.debt.episode(before, self.known.1 + self.queue.len());
            }
        }
        Ok(())
    }

    /// The learner is home: the next complete lock-step round (unless `stopping`), the waiting rows
    /// into the replay, and whether to update or publish weights now.
    pub fn with_learner(&mut self, learner: &mut Learner, stopping: bool) -> Result<Next, TrainError> {
        let round = match self.lockstep.as_mut().filter(|_| !stopping).and_then(Lockstep::next_round) {
            Some(items) => {
                for item in items {
                    match item {
                        Item::Transition(j) => self.take_transition(*j),
                        Item::Episode(r) => self.take_episode(&r)?,
                    }
                }
                true
            }
            None => false,
        };
        self.store_queue(learner)?;
        let total = self.cfg.total_updates;
        let mut next = Next::default();
        if round {
            self.last_round = Instant::now();
            next.update = learner.ready() && learner.updates() < total;
            next.weights = !next.update;
        }
        self.known = (learner.updates(), learner.replay().len(), learner.replay().expert_len(), self.known.3);
        if self.lockstep.is_none() && !stopping && self.debt.owed() > 0 && learner.ready() && learner.updates() < total
        {
            self.debt.pay();
            next.update = true;
        }
        Ok(next)
    }

    /// The waiting rows into the replay. A replay full of expert transitions (never overwritten)
    /// has no room for more: such rows are counted and dropped, once logged, and training goes on
    /// on what it holds.
    fn store_queue(&mut self, learner: &mut Learner) -> Result<(), TrainError> {
        for row in self.queue.drain(..) {
            match learner.push(row) {
                Ok(()) => {}
                Err(LearnerError::Replay(ReplayError::AllExpert { capacity })) => {
                    if self.no_room == 0 {
                        warn!(
                            "the replay is full of expert transitions ({capacity} slots, never overwritten): further transitions are dropped and counted, training goes on (a larger replay.capacity keeps more)"
                        );
                    }
                    self.no_room += 1;
                }
                Err(e) => return Err(e.into()),
            }
        }
        Ok(())
    }

    /// Rows dropped so far because the replay was full of expert transitions.
    pub fn dropped_no_room(&self) -> u64 {
        self.no_room
    }

    /// An update finished with metrics `m`: logged, checkpointed when due; returns whether to
    /// publish weights now.
    pub fn updated(&mut self, learner: &Learner, m: Metrics) -> Result<bool, TrainError> {
        let u = learner.updates();
        let sps = self.ingest.counts.transitions as f64 / self.wall().max(1e-9);
        let (step, wall) = (self.global_step, self.wall());
        self.record.update(step, wall, u, &m, sps)?;
        // Lock-step: the round's weights, except after the last update (the envs stop there).
        let weights = match self.lockstep {
            Some(_) => u < self.cfg.total_updates,
            // (and at every evaluation's update count: the eval policy's windows open on them)
            None => {
                u == 1
                    || (self.opts.weights_every > 0 && u.is_multiple_of(self.opts.weights_every))
                    || (self.cfg.eval_every > 0 && u.is_multiple_of(self.cfg.eval_every))
            }
        };
        if self.cfg.checkpoint_every > 0 && u.is_multiple_of(self.cfg.checkpoint_every) {
            self.checkpoint(learner)?;
        }
        if let Some(p) = self.progress.as_mut() {
            let (name, n) = self.lockstep.as_ref().map_or(("owed", self.debt.owed()), |l| ("rounds", l.rounds()));
            let fields = [
                ("alpha", format!("{:.3}", m.alpha)),
                ("transitions", self.ingest.counts.transitions.to_string()),
                (name, n.to_string()),
            ];
            p.update(u, &fields);
        }
        self.known.3 = m;
        Ok(weights)
    }

    fn state(&self) -> NodeState {
        NodeState {
            message_schema: equiarm_msgs::SCHEMA_VERSION,
            run_id: self.run_id.clone(),
            global_step: self.global_step,
            evals: self.record.evals().to_vec(),
            version: self.version,
        }
    }

    fn checkpoint(&mut self, learner: &Learner) -> Result<PathBuf, TrainError> {
        let st = self.state();
        self.record.checkpoint(learner, STATE_FILE, &st)
    }

    /// The next weights message: the learner's actor, one version up.
    pub fn weights(&mut self, learner: &Learner) -> Result<PolicyWeights, TrainError> {
        self.version += 1;
        Ok(PolicyWeights {
            header: wall_stamp(),
            run_id: self.run_id.clone(),
            version: self.version,
            updates: learner.updates(),
            model: self.cfg.agent.model.name().to_string(),
            format: "safetensors".into(),
            data: learner.agent().actor_bytes().map_err(equiarm_sac::learner::LearnerError::from)?,
        })
    }

    /// Lock-step: log a round that has waited 10 s (once per round), while the learner is `idle`.
    pub fn check_stall(&mut self, idle: bool) {
        if let Some(ls) = &self.lockstep
            && idle
            && self.last_round.elapsed() >= Duration::from_secs(10)
            && self.stall_logged != Some(ls.rounds())
        {
            self.stall_logged = Some(ls.rounds());
            warn!(
                "deterministic: round {} has waited {:.0} s for {}",
                ls.rounds(),
                self.last_round.elapsed().as_secs_f64(),
                ls.waiting_for().join(", ")
            );
        }
    }

    /// The status message, once a second (`None` in between).
    pub fn status(&mut self) -> Option<TrainerStatus> {
        let (at, updates, transitions) = self.last_status;
        if at.elapsed() < Duration::from_secs(1) {
            return None;
        }
        let dt = at.elapsed().as_secs_f32();
        let (m, last, now) = (self.known.3, self.record.evals().last(), self.ingest.counts.transitions);
        let status = TrainerStatus {
            header: wall_stamp(),
            updates: self.known.0,
            transitions: now,
            buffer_size: self.known.1 as u64,
            expert_transitions: self.known.2 as u64,
            critic_loss: (m.qf1_loss + m.qf2_loss) / 2.0,
            actor_loss: m.actor_loss,
            alpha: m.alpha,
            updates_per_s: (self.known.0 - updates) as f32 / dt,
            transitions_per_s: (now - transitions) as f32 / dt,
            last_eval_return: last.map_or(f32::NAN, |e| e.mean_return as f32),
            last_eval_success_rate: last.map_or(f32::NAN, |e| e.success_rate as f32),
            last_eval_episodes: last.map_or(0, |e| e.episodes as u32),
        };
        self.last_status = (Instant::now(), self.known.0, now);
        Some(status)
    }

    /// The end of the run (`why` it stops): a checkpoint, the evaluations and the counts.
    pub fn finish(mut self, learner: &mut Learner, why: &str) -> Result<RunSummary, TrainError> {
        if let Some(p) = self.progress.as_mut() {
            p.finish();
        }
        // Rows taken since the learner was last home (an Observation can release waiting Transitions
        // on the last turn) are stored too: the checkpoint holds everything received.
        self.store_queue(learner)?;
        info!("stopping ({why}) at {} updates", learner.updates());
        let st = self.state();
        self.record.finish(learner, STATE_FILE, &st)?;
        if let Some(ls) = &self.lockstep {
            let (t, r) = ls.pending();
            info!(
                "deterministic: {} rounds; left outside a round: {t} transitions, {r} episode results; {} refused",
                ls.rounds(),
                self.refused
            );
        }
        let c = &self.ingest.counts;
        info!(
            "received {} transitions (stored {}, expert held {}, eval {})",
            c.transitions, c.stored, c.expert_held, c.eval
        );
        info!(
            "expert transitions dropped (failed episodes) {}, malformed {} (observations {}), without their observations {} (still waiting for them {}), no room (replay full of expert transitions) {}; replay {}",
            c.expert_dropped,
            c.bad,
            c.bad_frames,
            c.unmatched,
            self.ingest.waiting(),
            self.no_room,
            learner.replay().len()
        );
        Ok(RunSummary {
            run_dir: self.opts.run_dir.clone(),
            evals: self.record.evals().to_vec(),
            global_step: self.global_step,
            updates: learner.updates(),
            wall_s: self.wall(),
            last_checkpoint: self.record.last_checkpoint().map(PathBuf::from),
            demos: c.expert_episodes,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_trainer_state_written_before_run_ids_still_reads() {
        // trainer.json as a schema-2 trainer wrote it before weights carried a run id
        let old = r#"{"message_schema": 2, "global_step": 26369, "evals": [], "version": 5232}"#;
        let st: NodeState = serde_json::from_str(old).unwrap();
        assert_eq!((st.message_schema, st.global_step, st.version), (2, 26369, 5232));
        assert!(st.run_id.is_empty(), "an absent run id reads as empty, and Trainer::open draws a new one");
        let older: NodeState = serde_json::from_str(r#"{"global_step": 1, "evals": [], "version": 1}"#).unwrap();
        assert_eq!(older.message_schema, 1);
    }
}
