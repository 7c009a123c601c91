//! Benchmark: CDR encode + decode of a 152x152 RGBD `Observation` (what the simulator publishes every
//! step; its frame is noise here, which does not compress, so the message is as large as a 152 px
//! one gets: about 115 kB of zstd planes), in MB/s (median of runs), beside the same decode and encode in
//! Cyclone DDS Python (the rclpy/rmw_cyclonedds peer), measured in the same run.
//!
//! Run with `bash bench/cdr.sh` (sets up the Python peer), or `cargo bench -p equiarm_msgs --bench cdr`
//! with `EQUIARM_PYTHON` pointing at a Python that has `cyclonedds` (else only the Rust side runs).

use equiarm_msgs::msg::{GripperCommand, Observation};
use equiarm_msgs::std_msgs::Header;
use equiarm_msgs::{builtin_interfaces::Time, cdr};
use std::hint::black_box;
use std::time::Instant;

const SIDE: u32 = 152;

/// CDR encode + decode of a 152 px RGBD Observation, beside Cyclone DDS Python.
#[derive(clap::Parser)]
struct Args {
    /// Rounds; the median is reported.
    #[arg(long, default_value_t = 15, value_parser = clap::value_parser!(u64).range(1..=10_000))]
    rounds: u64,
    /// Calls per round.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    iters: u64,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn observation() -> Observation {
    let header = Header::new(Time { sec: 12, nanosec: 345 }, "world");
    let n = (SIDE * SIDE) as usize;
    let noise = |i: usize| ((i as u32).wrapping_mul(2_654_435_761) >> 13) as u8;
    let color: Vec<u8> = (0..n * 3).map(noise).collect();
    let depth: Vec<f32> = (0..n).map(|i| 0.5 + noise(i + 7) as f32 * 1e-3).collect();
    let mut o = Observation {
        header: header.clone(),
        seq: 1,
        env: "env0".into(),
        expert_action: GripperCommand { header, obs_seq: 1, open_ratio: 1.0, ..Default::default() },
        ..Default::default()
    };
    o.set_frame(SIDE, SIDE, &color, &depth).unwrap();
    o
}

/// Median over `rounds` of MB/s for `iters` calls of `f` on `bytes` bytes each.
fn median_mbps(bytes: usize, (rounds, iters): (usize, usize), mut f: impl FnMut()) -> f64 {
    for _ in 0..iters / 4 {
        f();
    }
    let mut rates: Vec<f64> = (0..rounds)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..iters {
                f();
            }
            (bytes * iters) as f64 / t.elapsed().as_secs_f64() / 1e6
        })
        .collect();
    rates.sort_by(|a, b| a.total_cmp(b));
    rates[rounds / 2]
}

fn main() {
    let args = <Args as clap::Parser>::parse();
    let (rounds, iters) = (args.rounds as usize, args.iters as usize);
    let obs = observation();
    let bytes = cdr::encode(&obs).unwrap();
    let n = bytes.len();
    let mut buf = Vec::with_capacity(n);
    let enc = median_mbps(n, (rounds, iters), || {
        buf.clear();
        cdr::encode_into(black_box(&obs), &mut buf).unwrap();
        black_box(&buf);
    });
    let dec = median_mbps(n, (rounds, iters), || {
        black_box(cdr::decode::<Observation>(black_box(&bytes)).unwrap());
    });
    println!("CDR of a {SIDE}x{SIDE} RGBD Observation ({n} bytes), median of {rounds} rounds x {iters}:");
    println!("{:<34} {:>12} {:>12}", "implementation", "encode MB/s", "decode MB/s");
    println!("{:<34} {:>12.0} {:>12.0}", "equiarm_msgs (Rust, cdr-encoding)", enc, dec);

    let Some(python) = std::env::var_os("EQUIARM_PYTHON") else {
        println!("(set EQUIARM_PYTHON, or run bash bench/cdr.sh, for the Cyclone DDS Python peer)");
        return;
    };
    let path = std::env::temp_dir().join(format!("equiarm_bench_obs_{}.cdr", std::process::id()));
    std::fs::write(&path, &bytes).unwrap();
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../bench/cdr_peer.py");
    let out = std::process::Command::new(python).arg(script).arg(&path).arg(rounds.to_string()).output();
    let _ = std::fs::remove_file(&path);
    let out = out.expect("running bench/cdr_peer.py");
    if !out.status.success() {
        eprintln!("{}", String::from_utf8_lossy(&out.stderr));
        panic!("bench/cdr_peer.py failed");
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let mut peer = text.split_whitespace().map(|v| v.parse::<f64>().unwrap());
    let (penc, pdec) = (peer.next().unwrap(), peer.next().unwrap());
    println!("{:<34} {:>12.0} {:>12.0}", "Cyclone DDS Python 11.0.1 (bytes)", penc, pdec);
    println!("{:<34} {:>11.1}x {:>11.1}x", "ratio Rust / Python", enc / penc, dec / pdec);
}
