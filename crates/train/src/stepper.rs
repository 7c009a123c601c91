//! The sim node's logic without DDS: an env stepped by `GripperCommand`s, as messages. Each
//! observation becomes an `Observation` (seq, env, episode, step, the compressed frame of
//! `equiarm_msgs::obs_frame`: rgb8 colour and half-float depth in metres, holding, the expert's action with `source = EXPERT` and `obs_seq = seq`); each step a
//! `Transition`; each episode's end an `EpisodeResult`.
//!
//! `seq` counts the observations this env made, from 0. A Transition names its two observations by
//! seq; an episode's last observation (`terminal` set) is published like the others, and nothing
//! answers it.
//!
//! Stamps come from a simulated clock: one tick of [`SimClock::step_ns`] (the physics time of one env
//! step, `dt * substeps`) per observation made, from a [`StampOrigin`] the caller passes in (0 unless
//! told otherwise); wall time is never read here.

use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::geometry_msgs::{Quaternion, Transform, TransformStamped, Vector3};
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, Transition};
use equiarm_msgs::std_msgs::Header;
use equiarm_msgs::tf2_msgs::TFMessage;
use equiarm_sim::{Env, EnvConfig, SimError, rng::Rng};
use nalgebra::Isometry3;

use crate::policy::action_of;

/// Frame of observations, transitions and commands.
pub const WORLD_FRAME: &str = "world";
/// Frame of the camera images and `CameraInfo` (optical convention: z forward, x right, y down).
pub const CAMERA_FRAME: &str = "camera_optical_frame";

/// The frame of env `env`'s gripper on `/tf`: `<env>/gripper` (every env has its own gripper, while
/// the camera, the same in every env of a run, is one frame).
pub fn gripper_frame(env: &str) -> String {
    format!("{env}/gripper")
}

/// A transform from `parent` to `child` at `stamp`: the pose of `child` in `parent`.
fn transform(parent: &str, child: String, pose: &Isometry3<f64>, stamp: Time) -> TransformStamped {
    let (t, q) = (pose.translation.vector, pose.rotation.quaternion().coords);
    TransformStamped {
        header: Header::new(stamp, parent),
        child_frame_id: child,
        transform: Transform {
            translation: Vector3 { x: t.x, y: t.y, z: t.z },
            rotation: Quaternion { x: q.x, y: q.y, z: q.z, w: q.w },
        },
    }
}

/// What the sim publishes once on `/tf_static`: the camera's optical frame in the world
/// ([`WORLD_FRAME`] → [`CAMERA_FRAME`], the camera's extrinsics inverted), stamped `stamp` (the sim
/// stamps it at the start of its clock, [`Stepper::origin`]).
pub fn tf_static(env: &Env, stamp: Time) -> TFMessage {
    let pose = env.camera().optical_pose_in_world();
    TFMessage { transforms: vec![transform(WORLD_FRAME, CAMERA_FRAME.to_string(), &pose, stamp)] }
}

/// What the sim publishes on `/tf` with each observation: the gripper's TCP in the world
/// ([`WORLD_FRAME`] → [`gripper_frame`]) at the observation's `stamp`; `None` before the first reset.
pub fn tf_gripper(env: &Env, name: &str, stamp: Time) -> Option<TFMessage> {
    let pose = env.gripper_pose()?;
    Some(TFMessage { transforms: vec![transform(WORLD_FRAME, gripper_frame(name), &pose, stamp)] })
}

/// Why the stepper stopped.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// The simulator failed (resetting or stepping).
    #[error("{what}: {cause}")]
    Sim {
        /// What was being done.
        what: String,
        /// The simulator's error.
        cause: SimError,
    },
    /// The camera frame did not fit its message.
    #[error("the camera frame: {0}")]
    Frame(equiarm_msgs::ObsFrameError),
}

// By hand, not `#[from]`: the message shows the cause, so it is not also chained as a source
// (docs/conventions.md, "Errors").
impl From<equiarm_msgs::ObsFrameError> for StepError {
    fn from(e: equiarm_msgs::ObsFrameError) -> Self {
        StepError::Frame(e)
    }
}

/// Where a sim's clock starts: the stamp of its first observation and of `/tf_static`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum StampOrigin {
    /// Time 0 (1970-01-01 in a viewer): the same stamps, so the same message bytes, every run.
    #[default]
    Zero,
    /// The wall clock when the sim starts (read by the node, the edge), so a viewer shows the run's
    /// date; the stamps still advance by simulated time, not wall time.
    Now,
    /// This many nanoseconds after the UNIX epoch (e.g. one launch time shared by a suite's sims).
    At(i64),
}

/// The largest origin accepted, in seconds: the last second a ROS 2 `builtin_interfaces/Time` holds
/// (`sec` is an int32).
pub const MAX_STAMP_ORIGIN_S: i64 = i32::MAX as i64;

impl StampOrigin {
    /// The origin in nanoseconds since the UNIX epoch; `now` gives the wall clock for [`StampOrigin::Now`].
    pub fn nanos(self, now: impl FnOnce() -> i64) -> i64 {
        match self {
            StampOrigin::Zero => 0,
            StampOrigin::Now => now(),
            StampOrigin::At(ns) => ns,
        }
    }
}

impl std::str::FromStr for StampOrigin {
    type Err = String;

    /// `zero`, `now`, or seconds since the UNIX epoch (`1796000000`, `1796000000.25`), 0 ..=
    /// [`MAX_STAMP_ORIGIN_S`].
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "zero" => Ok(StampOrigin::Zero),
            "now" => Ok(StampOrigin::Now),
            _ => {
                // exactly, as decimal digits: an f64 holds whole nanoseconds since 1970 only to 256 ns
                let not =
                    || format!("'{s}' is not zero, now or a number of seconds since 1970-01-01 (e.g. 1796000000)");
                let (whole, frac) = s.split_once('.').unwrap_or((s, ""));
                let digits = |d: &str| d.bytes().all(|b| b.is_ascii_digit());
                if whole.is_empty() || !digits(whole) || !digits(frac) || frac.len() > 9 {
                    return Err(not());
                }
                let secs = whole.parse::<i64>().ok().filter(|&v| v <= MAX_STAMP_ORIGIN_S).ok_or_else(|| {
                    format!("{s} s is outside 0 ..= {MAX_STAMP_ORIGIN_S} s (the seconds a ROS 2 Time holds)")
                })?;
                let nanos = format!("{frac:0<9}").parse::<i64>().map_err(|_| not())?;
                Ok(StampOrigin::At(secs * 1_000_000_000 + nanos))
            }
        }
    }
}

/// Simulated time: `origin_ns + ticks * step_ns` nanoseconds.
#[derive(Clone, Copy, Debug)]
pub struct SimClock {
    /// Simulated time of one env step, ns: `dt * substeps` of the physics settings, rounded.
    pub step_ns: i64,
    /// Ticks taken so far (one per observation made); the next stamp is `origin_ns + ticks * step_ns`.
    pub ticks: i64,
    /// The first stamp, ns since the UNIX epoch.
    pub origin_ns: i64,
}

impl SimClock {
    /// A clock at time 0 whose tick is one env step of `cfg`'s physics (`dt * substeps` seconds).
    pub fn new(cfg: &EnvConfig) -> Self {
        let step_s = cfg.params.dt as f64 * cfg.params.substeps as f64;
        Self { step_ns: (step_s * 1e9).round() as i64, ticks: 0, origin_ns: 0 }
    }

    /// The stamp of the next frame; advances the clock.
    pub fn tick(&mut self) -> Time {
        let t = Time::from_nanos(self.origin_ns.saturating_add(self.ticks.saturating_mul(self.step_ns)));
        self.ticks += 1;
        t
    }
}

/// What a run did (also logged at shutdown).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SimStats {
    /// Env steps taken (commands applied).
    pub steps: u64,
    /// Episodes that ended (and had their `EpisodeResult` published).
    pub episodes: u64,
    /// Times an Observation was published again because no command for it came within the timeout.
    pub republished: u64,
    /// Commands ignored because their `obs_seq` was not that of the Observation waited on.
    pub wrong_seq: u64,
    /// Commands for the awaited Observation rejected because a field was NaN or infinite.
    pub rejected: u64,
}

/// The names of the non-finite fields of a command, e.g. `dx=NaN, dtheta=inf`; None if all are finite.
pub fn non_finite_fields(c: &GripperCommand) -> Option<String> {
    let fields = [("open_ratio", c.open_ratio), ("dx", c.dx), ("dy", c.dy), ("dz", c.dz), ("dtheta", c.dtheta)];
    let bad: Vec<String> = fields.iter().filter(|(_, v)| !v.is_finite()).map(|(n, v)| format!("{n}={v}")).collect();
    (!bad.is_empty()).then(|| bad.join(", "))
}

/// A step the env took: the next Observation and the Transition to publish (in that order, so a
/// reader usually has the frame before the Transition naming it) and, when the episode ended, its
/// EpisodeResult ([`Stepper::reset`] then starts the next).
#[derive(Debug)]
pub struct Step {
    /// The observation after the step (`terminal` when the episode ended).
    pub next: Observation,
    /// The transition.
    pub transition: Transition,
    /// The episode's result, when it ended.
    pub result: Option<EpisodeResult>,
}

/// One env, its episodes and its messages.
pub struct Stepper {
    env: Env,
    name: String,
    eval: bool,
    seeds: Rng,
    clock: SimClock,
    seq: u64,
    episode: u32,
    next_episode: u32,
    seed: u64,
    /// The observation waiting for its command.
    obs: Option<Observation>,
    ret: f32,
    disc: f32,
    discount: f32,
    all_expert: bool,
    /// Counts so far.
    pub stats: SimStats,
}

impl Stepper {
    /// The env `name` of `cfg`, its episodes seeded from `seed` (episode k is reset with the k-th output
    /// of `Rng::new(seed)`); `eval` marks its EpisodeResults.
    pub fn new(cfg: EnvConfig, name: &str, seed: u64, eval: bool) -> Result<Self, SimError> {
        Ok(Stepper {
            clock: SimClock::new(&cfg),
            env: Env::new(cfg)?,
            name: name.to_string(),
            eval,
            seeds: Rng::new(seed),
            seq: 0,
            episode: 0,
            next_episode: 0,
            seed: 0,
            obs: None,
            ret: 0.0,
            disc: 0.0,
            discount: 1.0,
            all_expert: true,
            stats: SimStats::default(),
        })
    }

    /// The same stepper with its clock starting at `origin_ns` (ns since the UNIX epoch) instead of 0.
    pub fn with_stamp_origin(mut self, origin_ns: i64) -> Self {
        self.clock.origin_ns = origin_ns;
        self
    }

    /// The first stamp of this env's clock (the stamp of `/tf_static`).
    pub fn origin(&self) -> Time {
        Time::from_nanos(self.clock.origin_ns)
    }

    /// The env.
    pub fn env(&self) -> &Env {
        &self.env
    }

    /// Episodes started so far.
    pub fn episodes_started(&self) -> u32 {
        self.next_episode
    }

    /// Start the next episode; its first observation.
    pub fn reset(&mut self) -> Result<&Observation, StepError> {
        self.episode = self.next_episode;
        self.next_episode += 1;
        self.seed = self.seeds.next_u64();
        let task = self.env.config().task.name();
        let first = self.env.reset(self.seed).map_err(|source| StepError::Sim {
            what: format!("resetting {task} with seed {}", self.seed),
            cause: source,
        })?;
        let obs = observation(first, self.seq, &self.name, self.episode, self.clock.tick())?;
        (self.ret, self.disc, self.discount, self.all_expert) = (0.0, 0.0, 1.0, true);
        Ok(self.obs.insert(obs))
    }

    /// The observation waiting for its command.
    pub fn observation(&self) -> Option<&Observation> {
        self.obs.as_ref()
    }

    /// Apply `cmd` if it answers the waiting observation and is finite (out-of-range values are
    /// clipped by the simulator). `None`: not for the observation waited on, or with a non-finite
    /// field: counted, the wait goes on.
    pub fn command(&mut self, cmd: GripperCommand) -> Result<Option<Step>, StepError> {
        let Some(obs) = self.obs.as_ref() else { return Ok(None) };
        if cmd.obs_seq != obs.seq {
            self.stats.wrong_seq += 1;
            log::debug!("ignoring a command for obs_seq {} (waiting for {})", cmd.obs_seq, obs.seq);
            return Ok(None);
        }
        if let Some(bad) = non_finite_fields(&cmd) {
            self.reject(&cmd, &format!("non-finite {bad}"));
            return Ok(None);
        }
        let r = match self.env.step(&action_of(&cmd)) {
            Ok(r) => r,
            // Unreachable after the finiteness check, but bad input must never end the node.
            Err(SimError::Action(reason)) => {
                self.reject(&cmd, &reason.to_string());
                return Ok(None);
            }
            Err(source) => return Err(StepError::Sim { what: "stepping the env".into(), cause: source }),
        };
        let obs = self.obs.take().expect("checked");
        self.stats.steps += 1;
        let expert = cmd.source == GripperCommand::SOURCE_EXPERT;
        self.all_expert &= expert;
        self.ret += r.reward;
        self.disc += self.discount * r.reward;
        self.discount *= equiarm_sac::agent::GAMMA as f32;
        self.seq += 1;
        let steps = r.observation.step;
        let mut next = observation(r.observation, self.seq, &self.name, self.episode, self.clock.tick())?;
        next.terminal = r.done;
        let ended_by_task = r.info.success || r.info.invalid;
        let transition = Transition {
            header: next.header.clone(),
            env: self.name.clone(),
            episode: self.episode,
            step: obs.step,
            obs_seq: obs.seq,
            next_obs_seq: next.seq,
            action: cmd,
            reward: r.reward,
            done: ended_by_task,
            timeout: r.info.timeout && !ended_by_task,
            expert,
        };
        if !r.done {
            self.obs = Some(next.clone());
            return Ok(Some(Step { next, transition, result: None }));
        }
        let result = EpisodeResult {
            header: next.header.clone(),
            env: self.name.clone(),
            task: self.env.config().task.name().to_string(),
            seed: self.seed,
            episode: self.episode,
            steps,
            success: r.info.success,
            ret: self.ret,
            discounted_return: self.disc,
            expert: self.all_expert,
            eval: self.eval,
        };
        self.stats.episodes += 1;
        self.seq += 1;
        Ok(Some(Step { next, transition, result: Some(result) }))
    }

    fn reject(&mut self, cmd: &GripperCommand, why: &str) {
        self.stats.rejected += 1;
        if self.stats.rejected.is_power_of_two() {
            log::warn!(
                "rejecting the command for obs_seq {}: {why} ({} rejected so far)",
                cmd.obs_seq,
                self.stats.rejected
            );
        }
    }
}

/// The Observation message of a library observation (its frame compressed once, here).
pub fn observation(
    o: equiarm_sim::Observation,
    seq: u64,
    env: &str,
    episode: u32,
    stamp: Time,
) -> Result<Observation, StepError> {
    let header = Header::new(stamp, WORLD_FRAME);
    let a = o.expert_action;
    let mut msg = Observation {
        seq,
        env: env.to_string(),
        episode,
        step: o.step,
        holding: o.holding,
        expert_action: GripperCommand {
            header: header.clone(),
            obs_seq: seq,
            open_ratio: a.open_ratio,
            dx: a.dx,
            dy: a.dy,
            dz: a.dz,
            dtheta: a.dtheta,
            source: GripperCommand::SOURCE_EXPERT,
        },
        header,
        terminal: false,
        ..Default::default()
    };
    msg.set_frame(o.height as u32, o.width as u32, &o.color, &o.depth)?;
    Ok(msg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_commands_name_their_fields_and_the_clock_ticks_in_sim_time() {
        let c = GripperCommand { dy: f32::NAN, dtheta: f32::NEG_INFINITY, ..Default::default() };
        assert_eq!(non_finite_fields(&c).unwrap(), "dy=NaN, dtheta=-inf");
        assert_eq!(non_finite_fields(&GripperCommand::default()), None);
        let mut clock = SimClock::new(&EnvConfig::default());
        assert_eq!(clock.tick().as_nanos(), 0);
        assert_eq!(clock.tick().as_nanos(), clock.step_ns);
        assert!((clock.step_ns - 166_666_667).abs() < 100, "1/6 s up to f32 dt: {}", clock.step_ns);
        clock.origin_ns = 1_796_000_000_250_000_000;
        assert_eq!(clock.tick().as_nanos(), clock.origin_ns + 2 * clock.step_ns, "the origin shifts every stamp");
    }

    /// A point given in a TransformStamped's child frame, in its parent frame.
    fn apply(t: &TransformStamped, p: [f64; 3]) -> nalgebra::Point3<f64> {
        let (v, q) = (&t.transform.translation, &t.transform.rotation);
        let rot = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w, q.x, q.y, q.z));
        rot * nalgebra::Point3::from(p) + nalgebra::Vector3::new(v.x, v.y, v.z)
    }

    #[test]
    fn stamp_origins_parse_and_refuse_what_a_ros_time_cannot_hold() {
        let parse = |s: &str| s.parse::<StampOrigin>();
        assert_eq!(parse("zero"), Ok(StampOrigin::Zero));
        assert_eq!(parse("now"), Ok(StampOrigin::Now));
        assert_eq!(parse("1796000000.25"), Ok(StampOrigin::At(1_796_000_000_250_000_000)));
        assert_eq!(StampOrigin::Now.nanos(|| 42), 42);
        assert_eq!(StampOrigin::Zero.nanos(|| 42), 0);
        assert_eq!(parse("1796000000.000000001"), Ok(StampOrigin::At(1_796_000_000_000_000_001)), "exact to 1 ns");
        for bad in ["-1", "inf", "NaN", "3e9", "yesterday", "", "3000000000", "1.0000000001", ".5"] {
            let e = parse(bad).unwrap_err();
            assert!(e.contains(bad) && (e.contains("outside") || e.contains("not zero, now")), "{bad}: {e}");
        }
    }

    #[test]
    fn tf_places_the_camera_where_it_projects_from_and_the_gripper_at_its_tcp() {
        let mut env = Env::new(EnvConfig::new(equiarm_types::TaskKind::BlockPulling)).unwrap();
        assert!(tf_gripper(&env, "env3", Time::default()).is_none(), "no gripper before a reset");
        let cam = tf_static(&env, Time { sec: 7, nanosec: 0 }).transforms;
        assert_eq!(cam[0].header.stamp, Time { sec: 7, nanosec: 0 });
        assert_eq!(
            (cam.len(), cam[0].header.frame_id.as_str(), cam[0].child_frame_id.as_str()),
            (1, WORLD_FRAME, CAMERA_FRAME)
        );
        // A point given in the optical frame (x right, y down, z forward) projects as the pinhole
        // model of CameraInfo's K says: u = fx x / z + cx, v = fy y / z + cy, at planar depth z.
        let p = apply(&cam[0], [0.1, -0.05, 0.5]);
        let (u, v, depth) = env.camera().project(p).unwrap();
        let k = env.camera().camera_info_k();
        assert!(
            (u - (k[0] * 0.2 + k[2])).abs() < 1e-6 && (v - (k[4] * -0.1 + k[5])).abs() < 1e-6,
            "({u}, {v}), K {k:?}"
        );
        assert!((depth - 0.5).abs() < 1e-9, "{depth}");
        let q = &cam[0].transform.rotation;
        assert!((q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w - 1.0).abs() < 1e-12, "a unit quaternion");

        env.reset(7).unwrap();
        let stamp = Time { sec: 2, nanosec: 5 };
        let g = tf_gripper(&env, "env3", stamp.clone()).unwrap().transforms;
        assert_eq!((g[0].header.frame_id.as_str(), g[0].child_frame_id.as_str()), (WORLD_FRAME, "env3/gripper"));
        assert_eq!(g[0].header.stamp, stamp);
        let tcp = env.gripper_pose().unwrap().translation.vector;
        assert_eq!(apply(&g[0], [0.0; 3]).coords, tcp);
        assert!(tcp.z > 0.0 && tcp.z < 0.3, "above the table, inside the workspace: {tcp:?}");
    }
}
