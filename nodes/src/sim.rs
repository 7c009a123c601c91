//! `equiarm sim`: one simulated environment ([`equiarm_sim::Env`]) on the ROS 2 graph, in the
//! lock-step protocol of docs/architecture.md#the-loop-over-dds. The node only maps topics to library
//! calls ([`equiarm_train::stepper`] makes the messages):
//!
//! - publishes an `Observation` (seq, env, episode, step, rgb8 colour, 32FC1 depth in metres, holding,
//!   the expert's action with `source = EXPERT` and `obs_seq = seq`) on `observation` (relative to the
//!   namespace; reliable keep-last 10) and the same frame on `camera/color/image_raw`,
//!   `camera/depth/image_raw` and `camera/camera_info` (best effort; one header stamp for all; a
//!   subscriber that matched after the frame went out gets it while the sim waits: [`crate::camera`]), and
//!   the gripper's pose on `/tf` (`world` → `<env>/gripper`, reliable keep-last 100) at that stamp
//!   (again with a re-publication);
//!   once at start, the camera's pose on `/tf_static` (`world` → `camera_optical_frame`, latched);
//! - waits for the `GripperCommand` on `gripper_cmd` whose `obs_seq` is that seq. A command for another
//!   seq is counted and ignored; one with NaN/inf is rejected (warned, rate-limited) and counted, and
//!   the node keeps waiting; no command within the timeout re-publishes the same Observation;
//! - steps the env (out-of-range values are clipped by the library), publishes the next Observation
//!   (`terminal` at an episode's end), then the `Transition` naming both by seq on `/transitions`
//!   (each frame crosses the graph once) and, when the episode ends, the `EpisodeResult` on
//!   `/episodes`; then resets.
//!
//! `seq` counts the observations this env made, from 0; nothing answers a terminal one.
//!
//! Stamps come from a simulated clock: one tick of [`equiarm_train::stepper::SimClock::step_ns`] (the physics time of one env
//! step, `dt * substeps`) per observation made, from `--stamp-origin` (0 by default; `now` reads the
//! wall clock once, at start, and never again). With `--clock` the
//! node also publishes that time on `/clock` (`rosgraph_msgs/msg/Clock`, reliable keep-last 10, which
//! matches rclpy's and rclcpp's best-effort clock subscriptions too) just before each publication of
//! an observation (again with a re-publication, so the clock never decreases), so ROS tools with `use_sim_time` line up with the stamps. One sim per graph should do it:
//! each env has its own simulated time.
//!
//! ## Limitations
//! One env per process (run N processes in `/env0 … /envN-1` for N envs). Episodes are `eval` only
//! with `--eval`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context as _;
use equiarm_msgs::builtin_interfaces::Time;
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, Transition};
use equiarm_msgs::rosgraph_msgs::Clock;
use equiarm_msgs::tf2_msgs::TFMessage;
use equiarm_sim::{CameraConfig, EnvConfig};
use equiarm_train::stepper::{SimStats, StampOrigin, Step, Stepper, tf_gripper, tf_static};
use equiarm_types::{ArmView, Corruption, TaskKind, ViewPreset};
use log::{debug, info, warn};

use crate::camera::{CATCH_UP_POLL, CameraPublishers};
use crate::ros::{Publisher, RosNode, RosOptions, qos, shutdown_signal};

/// Options of `equiarm sim` (the command line parses straight into this).
#[derive(Clone, Debug, clap::Args)]
pub struct SimArgs {
    /// Task (default: the config file's, else block_picking).
    #[arg(long, value_enum)]
    pub task: Option<TaskKind>,
    /// Base seed. Episode k is reset with the k-th output (k = 0, 1, …) of a splitmix64 stream seeded
    /// with it (`equiarm_sim::rng::Rng::new(seed)`); each EpisodeResult carries the seed it used.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Namespace of the node and its relative topics; the env name is the namespace without '/'.
    #[arg(long, default_value = "/env0", value_parser = crate::cli_values::env_namespace)]
    pub namespace: String,
    /// Camera preset: side (the paper's default view), angle15 … angle90 (the view-angle sweep).
    #[arg(long, value_enum)]
    pub view: Option<ViewPreset>,
    /// Symmetry corruptions of the observations (the training config's `corruption`, which the
    /// launch scripts pass on).
    #[arg(long, value_name = "none|NAME,…", help = crate::cli_values::corruption_help())]
    pub corrupt: Option<Corruption>,
    /// Whether the arm carrying the gripper is drawn (default: the config's, visible; the training
    /// config's `arm`, which the launch scripts pass on).
    #[arg(long, value_enum)]
    pub arm: Option<ArmView>,
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
    /// Where the stamps' clock starts: zero (1970 in a viewer; the same bytes every run), now (the wall
    /// clock at start) or seconds since 1970 (train.sh gives a run's sims its launch time). Stamps then
    /// advance by simulated time.
    #[arg(long, default_value = "zero", value_name = "zero|now|UNIX_SECONDS")]
    pub stamp_origin: StampOrigin,
    /// Before the first step, wait until N subscribers have matched /transitions and /episodes
    /// (train.sh: the trainer, and the recorder when it records). What a sim writes before a reader
    /// has matched never reaches that reader; under DDS Security matching takes seconds.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub wait_subscribers: usize,
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
    if let Some(t) = args.task {
        cfg.task = t;
    }
    if let Some(v) = args.view {
        cfg.camera = CameraConfig::from(v);
    }
    if let Some(c) = args.corrupt {
        cfg.corruption = c;
    }
    cfg.arm = args.arm.unwrap_or(cfg.arm);
    let cam = &mut cfg.camera;
    cam.elevation_deg = args.elevation_deg.unwrap_or(cam.elevation_deg);
    cam.distance = args.distance.unwrap_or(cam.distance);
    cam.fov_y_deg = args.fov_deg.unwrap_or(cam.fov_y_deg);
    if let Some(r) = args.resolution {
        (cam.width, cam.height) = (r, r);
    }
    Ok(cfg)
}

/// Runs the node until `args.episodes` episodes ended, or SIGINT/SIGTERM.
pub async fn run(args: &SimArgs, opts: &RosOptions) -> anyhow::Result<SimStats> {
    crate::signals::install()?; // first: a signal during start-up is then not lost
    let cfg = env_config(args)?;
    let namespace =
        crate::cli_values::env_namespace(&args.namespace).map_err(|e| anyhow::anyhow!("--namespace: {e}"))?;
    let env_name = namespace.trim_matches('/').to_string();
    let task = cfg.task.name();
    let scene = format!(
        "camera elevation {}°, {} px, corruption {}, arm {}",
        cfg.camera.elevation_deg, cfg.camera.width, cfg.corruption, cfg.arm
    );
    let origin = args.stamp_origin.nanos(|| {
        let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        i64::try_from(now.as_nanos()).unwrap_or(i64::MAX)
    });
    let sim = Stepper::new(cfg, &env_name, args.seed, args.eval).context("building the simulated env")?;
    let mut sim = sim.with_stamp_origin(origin);
    let mut node = RosNode::new(&namespace, "sim", opts)?;
    // the scene first, right after joining: a run stopped early still shows what this sim rendered
    let timeout = Duration::from_millis(args.timeout_ms.max(1));
    info!("{}: task {task}, {scene}, seed {}, env '{env_name}', re-publish after {timeout:?}", node.name(), args.seed);
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
    let mut camera = CameraPublishers::new(&mut node, sim.env())?;
    // the frames: the camera's once (latched), the gripper's with each observation
    let tf_static_pub = node.publisher::<TFMessage>("/tf_static", qos::latched())?;
    tf_static_pub.publish(tf_static(sim.env(), sim.origin())).await?;
    let tf_pub = node.publisher::<TFMessage>("/tf", qos::stream(100))?;
    let signal = shutdown_signal();
    tokio::pin!(signal);
    let n = args.wait_subscribers;
    tokio::select! {
        s = &mut signal => { info!("{}: {} received before the first step, shutting down", node.name(), s?); return Ok(sim.stats); }
        () = async {
            transition_pub.wait_for_subscriptions(&node, n).await;
            episode_pub.wait_for_subscriptions(&node, n).await;
        } => {}
    }
    'episodes: while sim.episodes_started() < args.episodes.unwrap_or(u32::MAX) {
        let mut obs = sim.reset()?.clone();
        publish_clock(&obs.header.stamp).await?;
        publish_tf(&tf_pub, &sim, &env_name, &obs).await?;
        camera.publish(&node, &obs).await?;
        obs_pub.publish(obs.clone()).await?;
        loop {
            // Wait for the command naming this observation; re-publish on timeout.
            let Step { next, transition, result } = loop {
                let deadline = tokio::time::Instant::now() + timeout;
                let got = loop {
                    let left = deadline.saturating_duration_since(tokio::time::Instant::now());
                    // a camera subscriber that matched late still gets the frame waiting for its command
                    let wait = if camera.pending() { left.min(CATCH_UP_POLL) } else { left };
                    let r = tokio::select! {
                        s = &mut signal => { info!("{}: {} received, shutting down", node.name(), s?); break 'episodes; }
                        r = cmd_sub.recv_timeout(wait) => r?,
                    };
                    let Some((cmd, _)) = r else {
                        if tokio::time::Instant::now() < deadline {
                            camera.catch_up(&node, &obs).await?;
                            continue;
                        }
                        break None;
                    };
                    if let Some(step) = sim.command(cmd)? {
                        break Some(step);
                    }
                };
                match got {
                    Some(step) => break step,
                    None => {
                        sim.stats.republished += 1;
                        debug!("no command for obs_seq {} within {timeout:?}; re-publishing", obs.seq);
                        publish_clock(&obs.header.stamp).await?;
                        publish_tf(&tf_pub, &sim, &env_name, &obs).await?;
                        obs_pub.publish(obs.clone()).await?;
                    }
                }
            };
            // The next frame first, then the Transition that names it.
            publish_clock(&next.header.stamp).await?;
            publish_tf(&tf_pub, &sim, &env_name, &next).await?;
            camera.publish(&node, &next).await?;
            obs_pub.publish(next.clone()).await?;
            transition_pub.publish(transition).await?;
            if let Some(result) = result {
                info!(
                    "{}: episode {} (seed {}) ended after {} steps, success {}",
                    node.name(),
                    result.episode,
                    result.seed,
                    result.steps,
                    result.success
                );
                episode_pub.publish(result).await?;
                continue 'episodes;
            }
            obs = next;
        }
    }
    info!("{}: {:?}", node.name(), sim.stats);
    // Reliable readers get the last samples before the writers go: a lost one is sent again after
    // the writer's next heartbeat (RustDDS: every 1 s once all was acknowledged).
    tokio::time::sleep(Duration::from_millis(1200)).await;
    Ok(sim.stats)
}

/// The gripper's pose on `/tf` at the stamp of `obs`, the observation the env is at now.
async fn publish_tf(tf: &Publisher<TFMessage>, sim: &Stepper, env: &str, obs: &Observation) -> anyhow::Result<()> {
    match tf_gripper(sim.env(), env, obs.header.stamp.clone()) {
        Some(m) => tf.publish(m).await,
        None => Ok(()),
    }
}

/// `equiarm sim snapshot`: writes the colour, depth and segmentation PNGs of `task` after a reset with
/// `seed` and `steps` expert steps into `out`; returns the paths written.
pub fn snapshot(
    task: TaskKind,
    seed: u64,
    steps: u32,
    view: Option<ViewPreset>,
    arm: Option<ArmView>,
    out: &Path,
) -> anyhow::Result<Vec<PathBuf>> {
    let mut cfg = EnvConfig::new(task);
    cfg.arm = arm.unwrap_or(cfg.arm);
    if let Some(v) = view {
        cfg.camera = CameraConfig::from(v);
    }
    let files = equiarm_sim::snapshot::snapshot_task(cfg, seed, steps, out)
        .with_context(|| format!("writing the snapshot of {task} into {}", out.display()))?;
    if files.steps < steps {
        warn!(
            "the episode ended after {} of the {steps} steps asked for: the pictures show its last state",
            files.steps
        );
    }
    Ok(vec![files.color, files.depth, files.segmentation])
}
