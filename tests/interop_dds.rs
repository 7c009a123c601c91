//! Interop over DDS on loopback with a real third-party peer: Cyclone DDS's Python binding (the DDS
//! under ROS 2's rmw_cyclonedds, same wire protocol as rclpy), using ROS 2's topic and type naming
//! and rclpy's QoS profiles. Proves that what our nodes publish is exactly what a ROS 2 user sees, that
//! what they publish reaches us bit-exact, that bad payloads are dropped without harm, and that the
//! Cyclone tooling lists our topics under their ROS 2 names.
//!
//! Run inside a private network namespace by `tests/run_all.sh` (only `lo`, multicast on), so DDS
//! traffic never leaves the machine. Each test uses its own DDS domain; every loop is bounded in count
//! and time.

mod support;

use std::io::{BufRead, BufReader};
use std::process::{Child, Stdio};
use std::sync::{Mutex, Once};
use std::time::{Duration, Instant};

use equiarm_msgs::cdr;
use equiarm_msgs::msg::{GripperCommand, Observation};
use equiarm_msgs::sensor_msgs::Image;
use equiarm_nodes::ros::{RosNode, RosOptions, qos};
use support::golden_values::*;

/// Captures log lines (and still prints them) so a test can check what was logged.
struct CaptureLog;
static LOG_LINES: Mutex<Vec<String>> = Mutex::new(Vec::new());

impl log::Log for CaptureLog {
    fn enabled(&self, m: &log::Metadata) -> bool {
        m.level() <= log::Level::Warn || m.target().starts_with("equiarm")
    }
    fn log(&self, r: &log::Record) {
        if self.enabled(r.metadata()) && !r.target().starts_with("rustdds") {
            let line = format!("{} {}: {}", r.level(), r.target(), r.args());
            eprintln!("{line}");
            LOG_LINES.lock().unwrap().push(line);
        }
    }
    fn flush(&self) {}
}

fn capture_logs() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        log::set_boxed_logger(Box::new(CaptureLog)).unwrap();
        log::set_max_level(log::LevelFilter::Info);
    });
}

fn options(domain_id: u16) -> RosOptions {
    RosOptions { domain_id, ..Default::default() }
}

/// Starts the Python peer; its stdout is JSON lines.
fn peer(mode: &str, domain: u16, seconds: u32) -> Child {
    let mut c = support::python_script("dds_peer.py");
    c.args([mode, &domain.to_string(), &seconds.to_string()]).stdout(Stdio::piped());
    c.spawn().unwrap_or_else(|e| panic!("starting dds_peer.py: {e}"))
}

fn json_lines(child: Child) -> Vec<serde_json::Value> {
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "dds_peer.py failed: {}", out.status);
    BufReader::new(&out.stdout[..]).lines().map(|l| serde_json::from_str(&l.unwrap()).unwrap()).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rust_images_and_observations_reach_cyclonedds_bit_exact() {
    capture_logs();
    let mut node = RosNode::new("/", "interop_pub", &options(71)).unwrap();
    let color_pub = node.publisher::<Image>("/interop/color/image_raw", qos::sensor_data()).unwrap();
    let depth_pub = node.publisher::<Image>("/interop/depth/image_raw", qos::sensor_data()).unwrap();
    let obs_pub = node.publisher::<Observation>("/interop/observation", qos::command()).unwrap();
    let color = rgb8(152, 152, "camera_color_optical_frame");
    let depth = depth(152, 152, TEXT, 1);
    let obs = observation(u64::MAX - 1, 152, 2);
    assert_eq!((color.encoding.as_str(), color.height, color.width), ("rgb8", 152, 152));
    assert_eq!((depth.encoding.as_str(), depth.height, depth.width), ("32FC1", 152, 152));

    let mut child = peer("receive", 71, 20);
    let start = Instant::now();
    // Publish at 20 Hz until the peer has what it wants (it exits), at most 25 s.
    while child.try_wait().unwrap().is_none() {
        assert!(start.elapsed() < Duration::from_secs(25), "the Cyclone DDS peer did not finish");
        color_pub.publish(color.clone()).await.unwrap();
        depth_pub.publish(depth.clone()).await.unwrap();
        obs_pub.publish(obs.clone()).await.unwrap();
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let lines = json_lines(child);
    let done = lines.iter().find(|l| l["event"] == "done").expect("peer reported no result");
    for topic in ["rt/interop/color/image_raw", "rt/interop/depth/image_raw", "rt/interop/observation"] {
        assert!(done["counts"][topic].as_u64().unwrap() >= 3, "too few samples on {topic}: {done}");
    }
    let samples: Vec<_> = lines.iter().filter(|l| l["event"] == "sample").collect();
    for s in &samples {
        assert_eq!(s["exact"], true, "a sample differs from the golden value: {s}");
    }
    assert!(samples.len() >= 9);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cyclonedds_gripper_commands_with_rclpy_default_qos_reach_rust_bit_exact() {
    capture_logs();
    let mut node = RosNode::new("/", "interop_sub", &options(72)).unwrap();
    let sub = node.subscription::<GripperCommand>("/interop/gripper_cmd", qos::command()).unwrap();
    let mut child = peer("send", 72, 15);
    let expected = [cdr::encode(&command_special()).unwrap(), cdr::encode(&command_typical()).unwrap()];
    let mut seen = [0usize; 2];
    let start = Instant::now();
    while seen.iter().sum::<usize>() < 6 && start.elapsed() < Duration::from_secs(20) {
        let Some((cmd, _info)) = sub.recv_timeout(Duration::from_secs(1)).await.unwrap() else { continue };
        let bytes = cdr::encode(&cmd).unwrap();
        let which = expected.iter().position(|e| *e == bytes);
        assert!(which.is_some(), "received a command that is neither golden value: {cmd:?}");
        seen[which.unwrap()] += 1;
    }
    let _ = child.kill();
    let _ = child.wait();
    assert!(seen[0] >= 1 && seen[1] >= 1 && seen.iter().sum::<usize>() >= 6, "received {seen:?}");
    // the special one, spot-checked field by field
    assert_eq!(command_special().open_ratio.to_bits(), 0x7fc0_0001);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn payloads_that_do_not_decode_are_counted_logged_once_and_dropped() {
    capture_logs();
    let mut node = RosNode::new("/", "interop_bad", &options(73)).unwrap();
    let topic = "/interop/bad_cmd";
    let sub = node.subscription::<GripperCommand>(topic, qos::command()).unwrap();
    let child = peer("send-bad", 73, 10);
    let good = cdr::encode(&command_typical()).unwrap();
    let mut received = 0;
    let start = Instant::now();
    while received < 5 && start.elapsed() < Duration::from_secs(15) {
        if let Some((cmd, _)) = sub.recv_timeout(Duration::from_secs(1)).await.unwrap() {
            assert_eq!(cdr::encode(&cmd).unwrap(), good, "a bad payload came through as {cmd:?}");
            received += 1;
        }
    }
    let lines = json_lines(child);
    let sent = lines.iter().find(|l| l["event"] == "sent").expect("peer reported nothing");
    assert_eq!(sent["bad"], 6, "{sent}");
    assert!(received >= 5, "good commands after bad ones: {received}");
    let dropped = sub.bad_input_count();
    assert!(dropped >= 2, "bad payloads counted: {dropped}");
    assert_eq!(node.bad_input_counts().get(topic).copied(), Some(dropped));
    let warnings: Vec<_> = LOG_LINES
        .lock()
        .unwrap()
        .iter()
        .filter(|l| l.contains("does not decode") && l.contains(topic))
        .cloned()
        .collect();
    assert_eq!(warnings.len(), 1, "expected exactly one warning for {topic}: {warnings:?}");
    assert!(warnings[0].contains("equiarm_msgs/msg/GripperCommand"), "{}", warnings[0]);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cyclonedds_ls_lists_our_topics_under_ros2_names() {
    capture_logs();
    let mut node = RosNode::new("/interop", "lister", &options(74)).unwrap();
    let _obs = node.publisher::<Observation>("/interop/ls_observation", qos::command()).unwrap();
    let _cmd = node.subscription::<GripperCommand>("ls_gripper_cmd", qos::command()).unwrap();
    let cli = support::python().parent().unwrap().join("cyclonedds");
    let out = tokio::task::spawn_blocking(move || {
        let mut c = std::process::Command::new(cli);
        c.args(["ls", "-i", "74", "-r", "3s", "--suppress-progress-bar", "--color", "none"]);
        support::run_ok(c)
    })
    .await
    .unwrap();
    for needle in [
        "rt/interop/ls_observation",
        "equiarm_msgs::msg::dds_::Observation_",
        "rt/interop/ls_gripper_cmd",
        "equiarm_msgs::msg::dds_::GripperCommand_",
    ] {
        assert!(out.contains(needle), "`cyclonedds ls` does not show {needle}:\n{out}");
    }
}

/// `equiarm sim --clock`, driven by the Cyclone DDS peer as an expert policy: the peer receives
/// `/clock` (rosgraph_msgs/msg/Clock) never decreasing (a re-published Observation repeats its time),
/// each value the stamp of an Observation (or of the episode's terminal observation), and every
/// Observation's stamp on it. The same run's frames, as tf2 listeners see them: `/tf_static` holds
/// the camera's pose (`world` → `camera_optical_frame`) equal to the simulator's camera, and `/tf`
/// holds the gripper (`world` → `clk/gripper`) at every Observation's stamp.
#[test]
fn sim_clock_and_tf_reach_cyclonedds_with_the_observation_stamps() {
    const DOMAIN: u16 = 76;
    let mut sim = std::process::Command::new(env!("CARGO_BIN_EXE_equiarm"))
        .args(["sim", "--clock", "--task", "block_pulling", "--namespace", "/clk", "--seed", "3"])
        .args(["--stamp-origin", "1796000000.5"])
        .args(["--resolution", "38", "--episodes", "1"])
        .env("ROS_DOMAIN_ID", DOMAIN.to_string())
        .env("RUST_LOG", "warn,rustdds=off,ros2_client=off")
        .stdout(Stdio::null())
        .spawn()
        .expect("spawning equiarm sim");
    let lines = json_lines(peer("clock", DOMAIN, 60));
    let status = sim.wait().unwrap();
    assert!(status.success(), "equiarm sim failed: {status}");
    let nanos = |l: &serde_json::Value| l["sec"].as_i64().unwrap() * 1_000_000_000 + l["nanosec"].as_i64().unwrap();
    let of = |event: &str| lines.iter().filter(|l| l["event"] == event).map(nanos).collect::<Vec<i64>>();
    let (clock, obs, episode) = (of("clock"), of("obs"), of("episode"));
    assert_eq!(episode.len(), 1, "the peer saw no EpisodeResult: {lines:?}");
    assert!(obs.len() >= 2, "too few observations: {obs:?}");
    assert!(clock.windows(2).all(|w| w[0] <= w[1]), "/clock decreases: {clock:?}");
    for t in &obs {
        assert!(clock.contains(t), "observation stamp {t} ns never on /clock: {clock:?}");
    }
    // Every /clock value is an observation's stamp: the answered ones and the terminal one, which is
    // the EpisodeResult's stamp.
    for t in &clock {
        assert!(obs.contains(t) || *t == episode[0], "/clock {t} ns is no observation's stamp");
    }
    assert_eq!(clock.last(), Some(&episode[0]), "/clock ends at the terminal observation");
    let mut distinct = clock.clone();
    distinct.dedup();
    assert_eq!(distinct.len(), obs.len() + 1, "one /clock time per observation and the terminal one");

    // /tf_static: the camera, bit-exact as the simulator computes it for this config.
    let env = equiarm_sim::Env::new(equiarm_sim::EnvConfig {
        task: equiarm_types::TaskKind::BlockPulling,
        ..Default::default()
    })
    .unwrap();
    let origin = 1_796_000_000_500_000_000_i64;
    let want = &equiarm_train::stepper::tf_static(&env, Default::default()).transforms[0];
    let (v, q) = (&want.transform.translation, &want.transform.rotation);
    let camera: Vec<_> = lines.iter().filter(|l| l["event"] == "tf_static").collect();
    assert_eq!(camera.len(), 1, "one camera transform on /tf_static: {lines:?}");
    assert_eq!(
        (camera[0]["parent"].as_str(), camera[0]["child"].as_str()),
        (Some("world"), Some("camera_optical_frame"))
    );
    assert_eq!(camera[0]["translation"], serde_json::json!([v.x, v.y, v.z]));
    assert_eq!(camera[0]["rotation"], serde_json::json!([q.x, q.y, q.z, q.w]));
    // --stamp-origin: the camera and the first observation at the origin, the clock on from there.
    assert_eq!(nanos(camera[0]), origin, "/tf_static is stamped at the clock's start");
    assert_eq!(obs.iter().min(), Some(&origin), "the first observation is stamped at the origin");
    // /tf: the gripper at each observation's stamp (and the terminal one's), above the table.
    let gripper: Vec<_> = lines.iter().filter(|l| l["event"] == "tf").collect();
    assert!(gripper.iter().all(|l| l["parent"] == "world" && l["child"] == "clk/gripper"), "{gripper:?}");
    assert!(gripper.iter().all(|l| (0.0..0.3).contains(&l["translation"][2].as_f64().unwrap())), "{gripper:?}");
    let tf: Vec<i64> = gripper.iter().map(|l| nanos(l)).collect();
    for t in obs.iter().chain(&episode) {
        assert!(tf.contains(t), "no /tf at the observation stamp {t} ns: {tf:?}");
    }
}
