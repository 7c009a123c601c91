//! Throughput and peak memory of the `equiarm sim` node (docs/architecture.md#memory-budget: a sim node stays under
//! 150 MB). Spawns the `equiarm` binary built beside this example, drives it over DDS with an
//! in-process expert policy (echoes `expert_action` with the right `obs_seq`) for N steps, and prints
//! steps/s, episodes, successes and the node's peak RSS (`VmHWM` of `/proc/PID/status`, Linux only).
//!
//! ```text
//! cargo build --release --bin equiarm --example sim_node_bench
//! ROS_DOMAIN_ID=99 target/release/examples/sim_node_bench [STEPS=500] [TASK=block_picking] [--camera] [--delay-ms=D]
//! ```
//! `--delay-ms=D` makes the driver think D ms per step (a policy's inference time).
//!
//! NOTE: RustDDS 0.15 keeps acked samples of a reliable writer until its cache-cleaning timer, which
//! runs every 6 s (`rtps/writer.rs`, not configurable), so up to ~12 s of samples are held: the
//! node's peak RSS is about 22 MB + 12 s × steps/s × the bytes it publishes per step. The bench prints
//! those bytes per step, per topic, as its reader received them (docs/architecture.md#memory-budget
//! has the figures of each message schema: 0.49 MB per step at 152 px in schema 1, 185 kB in schema
//! 2, about 2 kB since schema 3 compresses the frame).
//! `--camera` also subscribes to the camera topics (the node decodes images for them only while someone does).
//! Run it where DDS multicast works (e.g. inside `unshare -n` with loopback multicast, as the tests do).

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use clap::Parser;
use equiarm_msgs::cdr;
use equiarm_msgs::msg::{EpisodeResult, GripperCommand, Observation, Transition};
use equiarm_msgs::sensor_msgs::Image;
use equiarm_nodes::ros::{RosNode, RosOptions, qos};

fn vm_kib(pid: u32, key: &str) -> Option<u64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

/// Throughput and peak memory of the `equiarm sim` node, driven over DDS by an in-process expert.
#[derive(Parser, Debug)]
#[command(name = "sim_node_bench")]
struct Args {
    /// Steps to drive.
    #[arg(default_value_t = 500)]
    steps: u64,
    /// The sim node's task.
    #[arg(default_value = "block_picking")]
    task: String,
    /// Also subscribe to the camera topics (the node decodes images for them only while someone does).
    #[arg(long)]
    camera: bool,
    /// Milliseconds the driver thinks per step (a policy's inference time).
    #[arg(long, value_name = "D", default_value_t = 0)]
    delay_ms: u64,
}

fn main() -> anyhow::Result<()> {
    let args = Args::parse();
    let (camera, delay_ms, steps) = (args.camera, args.delay_ms, args.steps);
    let task = args.task.as_str();
    let exe = std::env::current_exe()?;
    let bin = exe.parent().and_then(|p| p.parent()).map(|p| p.join("equiarm")).filter(|p| p.exists());
    let bin = bin.ok_or_else(|| anyhow::anyhow!("build the equiarm binary first (cargo build --bin equiarm)"))?;
    let opts = RosOptions::from_env()?;

    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let mut node = RosNode::new("/", "sim_node_bench", &opts)?;
        let obs_sub = node.subscription::<Observation>("/bench/observation", qos::command())?;
        let tr_sub = node.subscription::<Transition>("/transitions", qos::stream(100))?;
        let ep_sub = node.subscription::<EpisodeResult>("/episodes", qos::stream(100))?;
        let cam_sub = if camera {
            Some(node.subscription::<Image>("/bench/camera/color/image_raw", qos::sensor_data())?)
        } else {
            None
        };
        let cmd_pub = node.publisher::<GripperCommand>("/bench/gripper_cmd", qos::command())?;
        let mut child = Command::new(&bin)
            .args(["sim", "--task", task, "--namespace", "/bench", "--timeout-ms", "500"])
            .env("ROS_DOMAIN_ID", opts.domain_id.to_string())
            .stderr(Stdio::null())
            .spawn()?;
        let pid = child.id();
        let (mut done, mut episodes, mut successes, mut frames) = (0u64, 0u64, 0u64, 0u64);
        // Payload bytes received per topic (every publication, re-publications included).
        let (mut obs_bytes, mut tr_bytes, mut ep_bytes) = (0usize, 0usize, 0usize);
        let mut start = None;
        let deadline = Instant::now() + Duration::from_secs(600);
        while done < steps && Instant::now() < deadline {
            tokio::select! {
                Ok(Some((o, _))) = obs_sub.recv_timeout(Duration::from_millis(50)) => {
                    obs_bytes += cdr::encode(&o)?.len();
                    // An episode's terminal frame is for the trainer and the recorder: no answer.
                    if o.terminal {
                        continue;
                    }
                    start.get_or_insert_with(Instant::now);
                    if delay_ms > 0 {
                        tokio::time::sleep(Duration::from_millis(delay_ms)).await;
                    }
                    cmd_pub.publish(GripperCommand { obs_seq: o.seq, ..o.expert_action }).await?;
                }
                Ok(Some((t, _))) = tr_sub.recv_timeout(Duration::from_millis(50)) => {
                    tr_bytes += cdr::encode(&t)?.len();
                    done += 1;
                }
                Ok(Some((r, _))) = ep_sub.recv_timeout(Duration::from_millis(50)) => {
                    ep_bytes += cdr::encode(&r)?.len();
                    episodes += 1;
                    successes += r.success as u64;
                }
                Some(Ok(Some(_))) = async { match &cam_sub { Some(s) => Some(s.recv_timeout(Duration::from_millis(50)).await), None => None } } => frames += 1,
                else => {}
            }
        }
        let secs = start.map(|s| s.elapsed().as_secs_f64()).unwrap_or(f64::NAN);
        let hwm = vm_kib(pid, "VmHWM:");
        let rss = vm_kib(pid, "VmRSS:");
        let _ = Command::new("kill").args(["-TERM", &pid.to_string()]).status();
        let _ = child.wait();
        println!("task {task}: {done} steps in {secs:.2} s = {:.1} steps/s (lock-step over DDS, expert driver)", done as f64 / secs);
        println!("episodes {episodes}, successes {successes}, camera frames received {frames}");
        let per = |b: usize| b as f64 / done.max(1) as f64 / 1e3;
        println!(
            "payload per env step and reader: observation {:.1} kB, transitions {:.2} kB, episodes {:.3} kB, total {:.1} kB",
            per(obs_bytes),
            per(tr_bytes),
            per(ep_bytes),
            per(obs_bytes + tr_bytes + ep_bytes)
        );
        println!(
            "sim node peak RSS (VmHWM) {:.1} MB, RSS at end {:.1} MB (budget 150 MB)",
            hwm.unwrap_or(0) as f64 / 1024.0,
            rss.unwrap_or(0) as f64 / 1024.0
        );
        anyhow::Ok(())
    })
}
