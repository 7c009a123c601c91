//! Benchmark: bag write throughput for a stream of 152x152 RGBD `Observation`s (what one env
//! publishes per step), uncompressed, lz4 and zstd, end to end (encode, write, finish, fsync);
//! median of rounds in MB/s of CDR payload, file size ratio, and the process's peak RSS.
//!
//! `cargo bench -p equiarm_bag --bench write [-- FRAMES ROUNDS]`

use std::hint::black_box;
use std::time::Instant;

use clap::Parser;
use equiarm_bag::qos::OfferedQos;
use equiarm_bag::{Compression, TopicInfo, Writer, WriterOptions};
use equiarm_msgs::msg::Observation;
use equiarm_msgs::std_msgs::Header;
use equiarm_msgs::{builtin_interfaces::Time, cdr};

/// Frames from the simulator itself (block picking driven by its expert), so compression ratios are
/// those of real observations.
fn sim_frames(n: usize) -> Vec<Observation> {
    use equiarm_sim::{Env, EnvConfig, TaskKind};
    let mut env = Env::new(EnvConfig::new(TaskKind::BlockPicking)).unwrap();
    let mut obs = env.reset(0).unwrap();
    let mut out = Vec::new();
    let mut seed = 0;
    while out.len() < n {
        let side = (obs.color.len() / 3) as f64;
        let side = side.sqrt() as u32;
        let h = Header { stamp: Time { sec: out.len() as i32, nanosec: 0 }, frame_id: "world".into() };
        let mut o = Observation {
            header: h,
            seq: out.len() as u64,
            env: "env0".into(),
            holding: obs.holding,
            ..Default::default()
        };
        o.set_frame(side, side, &obs.color, &obs.depth).unwrap();
        out.push(o);
        let r = env.step(&obs.expert_action).unwrap();
        obs = if r.done {
            seed += 1;
            env.reset(seed).unwrap()
        } else {
            r.observation
        };
    }
    out
}

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .map(|l| l.split_whitespace().nth(1).unwrap_or("0").parse::<f64>().unwrap_or(0.0))
        })
        .unwrap_or(0.0)
        / 1024.0
}

/// Bag write throughput on simulator frames: uncompressed, lz4 and zstd.
#[derive(Parser, Debug)]
#[command(name = "write")]
struct Args {
    /// Observations written per bag.
    #[arg(default_value_t = 600)]
    frames: u32,
    /// Bags written per compression; the median rate is reported.
    #[arg(default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..))]
    rounds: u32,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn main() {
    let args = Args::parse();
    let (frames, rounds) = (args.frames, args.rounds);
    let pool: Vec<Vec<u8>> = sim_frames(64).iter().map(|o| cdr::encode(o).unwrap()).collect();
    let per = pool[0].len();
    let dir = std::env::temp_dir().join(format!("equiarm_bag_bench_{}", std::process::id()));
    println!(
        "bag write: {frames} simulator Observations of {per} bytes (152x152 rgb8 + 32FC1 depth), median of {rounds} rounds, fsync included"
    );
    println!("{:<12} {:>10} {:>10} {:>8}", "compression", "MB/s", "frames/s", "ratio");
    for (name, compression) in [("none", Compression::None), ("lz4", Compression::Lz4), ("zstd-3", Compression::Zstd)] {
        let mut rates = Vec::new();
        let mut ratio = 0.0;
        for round in 0..rounds {
            let bag = dir.join(format!("{name}_{round}"));
            let t = Instant::now();
            let mut w = Writer::create(&bag, WriterOptions { compression, ..Default::default() }).unwrap();
            let id =
                w.add_topic(TopicInfo::of::<Observation>("/env0/observation", &[OfferedQos::reliable(10)])).unwrap();
            for k in 0..frames {
                // encode as the recorder does (re-encoding a received message), then write
                let data = &pool[k as usize % pool.len()];
                w.write(id, k as u64 * 20_000_000, k as u64 * 20_000_000, black_box(data)).unwrap();
                w.flush_if_due(t.elapsed().as_nanos() as u64).unwrap();
            }
            let s = w.finish().unwrap();
            let secs = t.elapsed().as_secs_f64();
            let size: u64 = s.files.iter().map(|f| std::fs::metadata(bag.join(f)).unwrap().len()).sum();
            ratio = (per as f64 * frames as f64) / size as f64;
            rates.push(per as f64 * frames as f64 / secs / 1e6);
            let _ = std::fs::remove_dir_all(&bag);
        }
        rates.sort_by(|a, b| a.total_cmp(b));
        let mbs = rates[rates.len() / 2];
        println!("{name:<12} {mbs:>10.0} {:>10.0} {ratio:>7.2}x", mbs * 1e6 / per as f64);
    }
    let _ = std::fs::remove_dir_all(&dir);
    println!("peak RSS: {:.0} MB", peak_rss_mb());
}
