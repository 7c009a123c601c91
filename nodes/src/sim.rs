//! `equiarm sim`: one simulated environment ([`equiarm_sim::Env`]) on the ROS 2 graph, in the
//! lock-step protocol of docs/architecture.md#the-loop-over-dds. The node only maps topics to library calls:
//!
//! - publishes an `Observation` (seq, env, episode, step, rgb8 colour, 32FC1 depth in metres, holding,
//!   the expert's action with `source = EXPERT` and `obs_seq = seq`) on `observation` (relative to the
//!   namespace; reliable keep-last 10) and the same frame on `camera/color/image_raw`,
//!   `camera/depth/image_raw` and `camera/camera_info` (best effort; one header stamp for all);
//! - waits for the `GripperCommand` on `gripper_cmd` whose `obs_seq` is that seq. A command for another
//!   seq is counted and ignored; one with NaN/inf is rejected (warned, rate-limited) and counted, and
//!   the node keeps waiting; no command within the timeout re-publishes the same Observation;
//! - steps the env (out-of-range values are clipped by the library), publishes the `Transition` on
//!   `/transitions` and, when the episode ends, the `EpisodeResult` on `/episodes`; then resets.
//!
//! `seq` counts the observations this env made, from 0. The terminal observation of an episode is
//! only the `next_obs` of its last Transition (and a camera frame): nothing answers it, so the
//! `observation` topic skips that one seq at each episode boundary.
//!
//! Stamps come from a simulated clock: one tick of [`SimClock::step_ns`] (the physics time of one env
//! step, `dt * substeps`) per observation made, from 0; wall time is never read. With `--clock` the
//! node also publishes that time on `/clock` (`rosgraph_msgs/msg/Clock`, reliable keep-last 10, which
//! matches rclpy's and rclcpp's best-effort clock subscriptions too) just before each publication of
//! an observation (again with a re-publication, so the clock never decreases) and at the terminal
//! one, so ROS tools with `use_sim_time` line up with the stamps. One sim per graph should do it:
//! each env has its own simulated time.
//!
//! ## Limitations
//! One env per process (run N processes in `/env0 … /envN-1` for N envs). Episodes are `eval` only
//! with `--eval`.

use std::time::Duration;

use anyhow::{Context as _, bail};
use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, Transition};
use equiarm_msgs::rosgraph_msgs::Clock;
use equiarm_msgs::sensor_msgs::{CameraInfo, Image};
use equiarm_msgs::std_msgs::Header;
use equiarm_sim::{Action, Env, EnvConfig, SimError, TaskKind, ViewPreset, rng::Rng};
use log::{debug, info, warn};

use crate::ros::{Publisher, RosNode, RosOptions, qos, shutdown_signal};

/// Frame of observations, transitions and commands.
pub const WORLD_FRAME: &str = "world";
/// Frame of the camera images and `CameraInfo` (optical convention: z forward, x right, y down).
pub const CAMERA_FRAME: &str = "camera_optical_frame";

/// Options of `equiarm sim` (the command line parses straight into this).
#[derive(Clone, Debug, clap::Args)]
pub struct SimArgs {
    /// Task: block_pulling, block_pushing, block_picking, drawer_opening or block_in_bowl
    /// (default: the config file's, else block_picking).
    #[arg(long)]
    pub task: Option<String>,
    /// Base seed. Episode k is reset with the k-th output (k = 0, 1, …) of a splitmix64 stream seeded
    /// with it (`equiarm_sim::rng::Rng::new(seed)`); each EpisodeResult carries the seed it used.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Namespace of the node and its relative topics; the env name is the namespace without '/'.
    #[arg(long, default_value = "/env0")]
    pub namespace: String,
    /// Camera preset: side (the paper's default view), angle15 … angle90 (the view-angle sweep).
    #[arg(long)]
    pub view: Option<String>,
    /// Camera elevation above the table plane, degrees in (0, 90] (overrides the preset).
    #[arg(long)]
    pub elevation_deg: Option<f64>,
    /// Camera eye-to-target distance, m (overrides the preset).
    #[arg(long)]
    pub distance: Option<f64>,
    /// Vertical field of view, degrees.
    #[arg(long)]
    pub fov_deg: Option<f64>,
    /// Image size in pixels (square).
    #[arg(long)]
    pub resolution: Option<usize>,
    /// EnvConfig as JSON (unknown keys are rejected; missing keys take the defaults). Flags override it.
    #[arg(long)]
    pub config: Option<std::path::PathBuf>,
    /// Stop after this many episodes (default: run until SIGINT/SIGTERM).
    #[arg(long)]
    pub episodes: Option<u32>,
    /// Re-publish the current Observation when no command for it came within this time.
    #[arg(long, default_value_t = 1000, value_parser = crate::cli_values::millis)]
    pub timeout_ms: u64,
    /// An evaluation env: its EpisodeResults have `eval` set (the trainer and `bag eval` count them
    /// as evaluation episodes, never as training data).
    #[arg(long)]
    pub eval: bool,
    /// Publish this env's simulated time on /clock (rosgraph_msgs/msg/Clock), equal to the stamp of
    /// each Observation, for nodes with use_sim_time. Give it to one sim per graph (train.sh: /env0).
    #[arg(long)]
    pub clock: bool,
}

/// The EnvConfig the arguments describe: the config file (or defaults), then the flags.
pub fn env_config(args: &SimArgs) -> anyhow::Result<EnvConfig> {
    let mut cfg = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
            serde_json::from_str(&text).with_context(|| format!("parsing {} as an EnvConfig", path.display()))?
        }
        None => EnvConfig::default(),
    };
    if let Some(t) = &args.task {
        cfg.task = parse_task(t)?;
    }
    if let Some(v) = &args.view {
        cfg.camera = parse_view(v)?.config();
    }
    let cam = &mut cfg.camera;
    cam.elevation_deg = args.elevation_deg.unwrap_or(cam.elevation_deg);
    cam.distance = args.distance.unwrap_or(cam.distance);
    cam.fov_y_deg = args.fov_deg.unwrap_or(cam.fov_y_deg);
    if let Some(r) = args.resolution {
        (cam.width, cam.height) = (r, r);
    }
    Ok(cfg)
}

/// A task by its command-line name; the error lists the names.
pub fn parse_task(name: &str) -> anyhow::Result<TaskKind> {
    TaskKind::from_name(name).with_context(|| {
        let names: Vec<_> = TaskKind::ALL.iter().map(|t| t.name()).collect();
        format!("unknown task '{name}'; tasks: {}", names.join(", "))
    })
}

/// A camera preset by name; the error lists the names.
pub fn parse_view(name: &str) -> anyhow::Result<ViewPreset> {
    ViewPreset::from_name(name).with_context(|| {
        let names: Vec<_> = ViewPreset::ALL.iter().map(|p| p.name()).collect();
        format!("unknown view '{name}'; views: {}", names.join(", "))
    })
}

/// Simulated time: `ticks * step_ns` nanoseconds.
#[derive(Clone, Copy, Debug)]
pub struct SimClock {
    /// Simulated time of one env step, ns: `dt * substeps` of the physics settings, rounded.
    pub step_ns: i64,
    /// Ticks taken so far (one per observation made); the next stamp is `ticks * step_ns`.
    pub ticks: i64,
}

impl SimClock {
    /// A clock at time 0 whose tick is one env step of `cfg`'s physics (`dt * substeps` seconds).
    pub fn new(cfg: &EnvConfig) -> Self {
        let step_s = cfg.params.dt as f64 * cfg.params.substeps as f64;
        Self { step_ns: (step_s * 1e9).round() as i64, ticks: 0 }
    }

    /// The stamp of the next frame; advances the clock.
    pub fn tick(&mut self) -> Time {
        let t = Time::from_nanos(self.ticks.saturating_mul(self.step_ns));
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

/// Runs the node until `args.episodes` episodes ended, or SIGINT/SIGTERM.
pub async fn run(args: &SimArgs, opts: &RosOptions) -> anyhow::Result<SimStats> {
    let cfg = env_config(args)?;
    let env_name = args.namespace.trim_matches('/').to_string();
    if env_name.is_empty() || env_name.contains('/') {
        bail!("--namespace '{}' must be one level, like /env0", args.namespace);
    }
    let mut env = Env::new(cfg.clone()).context("building the simulated env")?;
    let mut node = RosNode::new(&args.namespace, "sim", opts)?;
    let obs_pub = node.publisher::<Observation>("observation", qos::command())?;
    let transition_pub = node.publisher::<Transition>("/transitions", qos::stream(100))?;
    let episode_pub = node.publisher::<EpisodeResult>("/episodes", qos::stream(100))?;
    let cmd_sub = node.subscription::<GripperCommand>("gripper_cmd", qos::command())?;
    let clock_pub = if args.clock { Some(node.publisher::<Clock>("/clock", qos::command())?) } else { None };
    let publish_clock = async |stamp: &Time| -> anyhow::Result<()> {
        if let Some(p) = &clock_pub {
            p.publish(Clock { clock: stamp.clone() }).await?;
        }
        Ok(())
    };
    let camera = CameraPublishers::new(&mut node, &env)?;
    let timeout = Duration::from_millis(args.timeout_ms.max(1));
    let task = cfg.task.name();
    info!("{}: task {task}, seed {}, env '{env_name}', re-publish after {timeout:?}", node.name(), args.seed);

    let mut clock = SimClock::new(&cfg);
    let mut seeds = Rng::new(args.seed);
    let mut stats = SimStats::default();
    let mut seq = 0u64;
    let signal = shutdown_signal();
    tokio::pin!(signal);
    'episodes: for episode in 0..args.episodes.unwrap_or(u32::MAX) {
        let seed = seeds.next_u64();
        let first = env.reset(seed).with_context(|| format!("resetting {task} with seed {seed}"))?;
        let mut obs = observation(first, seq, &env_name, episode, clock.tick())?;
        let (mut ret, mut disc, mut discount, mut all_expert) = (0f32, 0f32, 1f32, true);
        loop {
            camera.publish(&node, &obs).await?;
            // Wait for the command naming this observation; re-publish on timeout.
            let cmd = loop {
                publish_clock(&obs.header.stamp).await?;
                obs_pub.publish(obs.clone()).await?;
                let deadline = tokio::time::Instant::now() + timeout;
                let got = loop {
                    let left = deadline.saturating_duration_since(tokio::time::Instant::now());
                    let r = tokio::select! {
                        s = &mut signal => { info!("{}: {} received, shutting down", node.name(), s?); break 'episodes; }
                        r = cmd_sub.recv_timeout(left) => r?,
                    };
                    let Some((cmd, _)) = r else { break None };
                    if cmd.obs_seq != obs.seq {
                        stats.wrong_seq += 1;
                        debug!("ignoring a command for obs_seq {} (waiting for {})", cmd.obs_seq, obs.seq);
                    } else if let Some(bad) = non_finite_fields(&cmd) {
                        stats.rejected += 1;
                        if stats.rejected.is_power_of_two() {
                            warn!(
                                "rejecting the command for obs_seq {}: non-finite {bad} ({} rejected so far)",
                                cmd.obs_seq, stats.rejected
                            );
                        }
                    } else {
                        break Some(cmd);
                    }
                };
                match got {
                    Some(cmd) => break cmd,
                    None => {
                        stats.republished += 1;
                        debug!("no command for obs_seq {} within {timeout:?}; re-publishing", obs.seq);
                    }
                }
            };
            let action = Action::new(cmd.open_ratio, cmd.dx, cmd.dy, cmd.dz, cmd.dtheta);
            let r = match env.step(&action) {
                Ok(r) => r,
                Err(SimError::Action(reason)) => {
                    // Unreachable after the finiteness check, but bad input must never end the node.
                    stats.rejected += 1;
                    warn!("rejecting the command for obs_seq {}: {reason}", cmd.obs_seq);
                    continue;
                }
                Err(e) => return Err(e).context("stepping the env"),
            };
            stats.steps += 1;
            all_expert &= cmd.source == GripperCommand::SOURCE_EXPERT;
            ret += r.reward;
            disc += discount * r.reward;
            discount *= equiarm_sac::agent::GAMMA as f32;
            seq += 1;
            let steps = r.observation.step;
            let next = observation(r.observation, seq, &env_name, episode, clock.tick())?;
            let ended_by_task = r.info.success || r.info.invalid;
            let expert = cmd.source == GripperCommand::SOURCE_EXPERT;
            let transition = Transition {
                header: next.header.clone(),
                obs,
                action: cmd,
                reward: r.reward,
                next_obs: next.clone(),
                done: ended_by_task,
                timeout: r.info.timeout && !ended_by_task,
                expert,
            };
            transition_pub.publish(transition).await?;
            obs = next;
            if r.done {
                publish_clock(&obs.header.stamp).await?;
                camera.publish(&node, &obs).await?;
                let result = EpisodeResult {
                    header: obs.header.clone(),
                    env: env_name.clone(),
                    task: task.to_string(),
                    seed,
                    episode,
                    steps,
                    success: r.info.success,
                    ret,
                    discounted_return: disc,
                    expert: all_expert,
                    eval: args.eval,
                };
                info!(
                    "{}: episode {episode} (seed {seed}) ended after {steps} steps, success {}",
                    node.name(),
                    r.info.success
                );
                episode_pub.publish(result).await?;
                stats.episodes += 1;
                seq += 1;
                continue 'episodes;
            }
        }
    }
    info!("{}: {stats:?}", node.name());
    // Give reliable readers a moment to acknowledge the last samples before the writers go away.
    tokio::time::sleep(Duration::from_millis(200)).await;
    Ok(stats)
}

/// The camera topics. Images are copied out of the Observation only while someone subscribes.
struct CameraPublishers {
    color: Publisher<Image>,
    depth: Publisher<Image>,
    info: Publisher<CameraInfo>,
    camera_info: CameraInfo,
}

impl CameraPublishers {
    fn new(node: &mut RosNode, env: &Env) -> anyhow::Result<Self> {
        let ci = env.camera().camera_info();
        let camera_info = CameraInfo {
            height: ci.height,
            width: ci.width,
            distortion_model: ci.distortion_model.to_string(),
            d: ci.d.to_vec(),
            k: ci.k,
            r: ci.r,
            p: ci.p,
            ..Default::default()
        };
        Ok(Self {
            color: node.publisher("camera/color/image_raw", qos::sensor_data())?,
            depth: node.publisher("camera/depth/image_raw", qos::sensor_data())?,
            info: node.publisher("camera/camera_info", qos::sensor_data())?,
            camera_info,
        })
    }

    /// Publishes the frame of `obs` (same header stamp as the Observation).
    async fn publish(&self, node: &RosNode, obs: &Observation) -> anyhow::Result<()> {
        if self.color.subscription_count(node) > 0 {
            self.color.publish(obs.color.clone()).await?;
        }
        if self.depth.subscription_count(node) > 0 {
            self.depth.publish(obs.depth.clone()).await?;
        }
        let header = obs.color.header.clone();
        self.info.publish(CameraInfo { header, ..self.camera_info.clone() }).await
    }
}

/// The Observation message of a library observation. Colour moves into its message; depth is
/// encoded once as little-endian float32.
fn observation(
    o: equiarm_sim::Observation,
    seq: u64,
    env: &str,
    episode: u32,
    stamp: Time,
) -> anyhow::Result<Observation> {
    let (h, w) = (o.height as u32, o.width as u32);
    let cam_header = Header::new(stamp.clone(), CAMERA_FRAME);
    let header = Header::new(stamp, WORLD_FRAME);
    let a = o.expert_action;
    Ok(Observation {
        seq,
        env: env.to_string(),
        episode,
        step: o.step,
        color: Image::rgb8(cam_header.clone(), h, w, o.color).context("colour image")?,
        depth: Image::float32(cam_header, h, w, &o.depth).context("depth image")?,
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
    })
}

/// `equiarm sim snapshot`: writes the colour, depth and segmentation PNGs of `task` after a reset with
/// `seed` and `steps` expert steps into `out`; returns the paths written.
pub fn snapshot(
    task: &str,
    seed: u64,
    steps: u32,
    view: Option<&str>,
    out: &std::path::Path,
) -> anyhow::Result<Vec<std::path::PathBuf>> {
    let mut cfg = EnvConfig::new(parse_task(task)?);
    if let Some(v) = view {
        cfg.camera = parse_view(v)?.config();
    }
    let files = equiarm_sim::snapshot::snapshot_task(cfg, seed, steps, out)
        .with_context(|| format!("writing the snapshot of {task} into {}", out.display()))?;
    Ok(vec![files.color, files.depth, files.segmentation])
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: SimArgs,
    }

    fn args(a: &[&str]) -> SimArgs {
        Cli::parse_from(std::iter::once("sim").chain(a.iter().copied())).args
    }

    #[test]
    fn flags_override_the_preset_and_bad_names_list_the_choices() {
        let cfg = env_config(&args(&["--task", "drawer_opening", "--view", "angle30", "--resolution", "96"])).unwrap();
        assert_eq!(cfg.task, TaskKind::DrawerOpening);
        assert_eq!((cfg.camera.elevation_deg, cfg.camera.width, cfg.camera.height), (30.0, 96, 96));
        let e = env_config(&args(&["--task", "stacking"])).unwrap_err().to_string();
        assert!(e.contains("'stacking'") && e.contains("block_in_bowl"), "{e}");
        let e = env_config(&args(&["--view", "top"])).unwrap_err().to_string();
        assert!(e.contains("angle90"), "{e}");
    }

    #[test]
    fn non_finite_commands_name_their_fields_and_the_clock_ticks_in_sim_time() {
        let c = GripperCommand { dy: f32::NAN, dtheta: f32::NEG_INFINITY, ..Default::default() };
        assert_eq!(non_finite_fields(&c).unwrap(), "dy=NaN, dtheta=-inf");
        assert_eq!(non_finite_fields(&GripperCommand::default()), None);
        let mut clock = SimClock::new(&EnvConfig::default());
        assert_eq!(clock.tick().as_nanos(), 0);
        assert_eq!(clock.tick().as_nanos(), clock.step_ns);
        assert!((clock.step_ns - 166_666_667).abs() < 100, "1/6 s up to f32 dt: {}", clock.step_ns);
    }
}
