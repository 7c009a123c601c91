//! Benchmark: the recorder under the suite's load. N simulated env nodes (default 10, each its own
//! DDS participant in namespace /envK) publish 152x152 RGBD `Observation`s at R Hz (default 50) for
//! S seconds (default 10) while `equiarm record --all` records them; prints published vs recorded
//! counts per env (drops), the recorder's peak RSS and the data rate.
//!
//! Run on loopback in a private network namespace: `bash bench/recorder_load.sh [N R S]`.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use clap::Parser;
use equiarm_bag::{ReadMode, Reader};
use equiarm_msgs::msg::Observation;
use equiarm_nodes::ros::{RosNode, RosOptions, qos};

fn vm(pid: u32, key: &str) -> f64 {
    std::fs::read_to_string(format!("/proc/{pid}/status"))
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with(key)).and_then(|l| l.split_whitespace().nth(1)?.parse().ok()))
        .unwrap_or(0.0)
        / 1024.0
}

/// The recorder under N simulated envs publishing RGBD observations at R Hz for S seconds.
#[derive(Parser, Debug)]
#[command(name = "record_load")]
struct Args {
    /// Simulated env nodes.
    #[arg(default_value_t = 10, value_parser = clap::value_parser!(u64).range(1..))]
    envs: u64,
    /// Observations per second per env.
    #[arg(default_value_t = 50.0)]
    hz: f64,
    /// Seconds of publishing.
    #[arg(default_value_t = 10.0)]
    secs: f64,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn main() {
    let args = Args::parse();
    let (envs, hz, secs) = (args.envs as usize, args.hz, args.secs);
    let domain = 90;
    let dir = std::env::temp_dir().join(format!("equiarm_record_load_{}", std::process::id()));
    let bag = dir.join("load");
    let mut rec = Command::new(env!("CARGO_BIN_EXE_equiarm"))
        .args(["record", "-q", "--all", "--compression", "zstd", "-o"])
        .arg(&bag)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("RUST_LOG", "warn")
        .stderr(Stdio::inherit())
        .spawn()
        .expect("starting equiarm record");

    let rt = tokio::runtime::Builder::new_multi_thread().worker_threads(2).enable_all().build().unwrap();
    let published: Vec<u64> = rt.block_on(async {
        let opts = RosOptions { domain_id: domain, localhost_only: false };
        let n = 152u32;
        let color: Vec<u8> = (0..n * n * 3).map(|i| (i % 251) as u8).collect();
        let depth: Vec<f32> = (0..n * n).map(|i| 0.5 + (i % 97) as f32 * 1e-3).collect();
        let mut tasks = Vec::new();
        for e in 0..envs {
            let mut node = RosNode::new(&format!("/env{e}"), "sim", &opts).unwrap();
            let publ = node.publisher::<Observation>("observation", qos::command()).unwrap();
            let mut obs = Observation { env: format!("env{e}"), ..Default::default() };
            obs.set_frame(n, n, &color, &depth).unwrap();
            tasks.push(tokio::spawn(async move {
                // wait until the recorder (which discovers topics every second) has matched us
                assert!(node.wait_for_subscription(&publ, Duration::from_secs(20)).await, "recorder never subscribed");
                tokio::time::sleep(Duration::from_millis(500)).await;
                let start = Instant::now();
                let mut k = 0u64;
                while start.elapsed().as_secs_f64() < secs {
                    let mut o = obs.clone();
                    o.seq = k;
                    publ.publish(o).await.unwrap();
                    k += 1;
                    let next = Duration::from_secs_f64(k as f64 / hz);
                    if let Some(w) = next.checked_sub(start.elapsed()) {
                        tokio::time::sleep(w).await;
                    }
                }
                tokio::time::sleep(Duration::from_secs(2)).await; // let reliable delivery finish
                drop(node);
                k
            }));
        }
        let mut out = Vec::new();
        for t in tasks {
            out.push(t.await.unwrap());
        }
        out
    });
    let rss = vm(rec.id(), "VmHWM:");
    Command::new("kill").args(["-INT", &rec.id().to_string()]).status().unwrap();
    let status = rec.wait().unwrap();
    assert!(status.success(), "recorder exit: {status}");

    let mut recorded = vec![0u64; envs];
    let mut bytes = 0u64;
    Reader::open(&bag)
        .unwrap()
        .for_each(ReadMode::Strict, |m| {
            if let Some(e) = m.topic.strip_prefix("/env").and_then(|t| t.strip_suffix("/observation")) {
                recorded[e.parse::<usize>().unwrap()] += 1;
                bytes += m.data.len() as u64;
            }
            Ok::<(), ()>(())
        })
        .unwrap()
        .unwrap();
    let disk: u64 = std::fs::read_dir(&bag).unwrap().map(|e| e.unwrap().metadata().unwrap().len()).sum();
    let (p, r): (u64, u64) = (published.iter().sum(), recorded.iter().sum());
    println!(
        "recorder load: {envs} envs x {hz} Hz x {secs} s of 152x152 RGBD Observations ({:.1} MB/s offered)",
        envs as f64 * hz * 161_929.0 / 1e6
    );
    for e in 0..envs {
        println!(
            "  /env{e}/observation: published {:>6}, recorded {:>6}, dropped {}",
            published[e],
            recorded[e],
            published[e] as i64 - recorded[e] as i64
        );
    }
    println!(
        "total: published {p}, recorded {r}, dropped {}; {:.1} MB of CDR, {:.1} MB on disk (zstd)",
        p as i64 - r as i64,
        bytes as f64 / 1e6,
        disk as f64 / 1e6
    );
    println!("recorder peak RSS: {rss:.0} MB (budget 300 MB)");
    let _ = std::fs::remove_dir_all(&dir);
}
