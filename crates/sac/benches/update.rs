//! Benchmark: one SAC update (critic → actor → α → target, docs/paper.md §2) on random batches, for
//! each network family and preset (`reduced16`: hidden 16, 32 px, batch 64; `paper`: hidden 64,
//! 128 px, batch 128), at each thread count, beside PyTorch + e2cnn running the same update on the
//! authors' networks (`bench/sac_update_peer.py`, which installs torch and e2cnn into its own venv
//! on first use), measured in the same run. Also the batch-1 greedy action.
//!
//! Prints, per case: our median time per update (of `--reps` after one warm-up), the peer's, their
//! ratio, the FLOPs of one update (the GEMMs of our convolution kernels, counted from the layer
//! shapes: forward, and the input and weight gradients that the update needs), our GFLOP/s and its
//! fraction of the sgemm peak at that thread count (a single-thread 1024³ sgemm on the `gemm`
//! crate, best of 10 at the start of the run, times the threads), and the batch-1 greedy action time;
//! then one `csv,` line per case and the peak RSS.
//!
//! `cargo bench -p equiarm_sac --bench update -- [--reps 5] [--config reduced16|paper|all]
//!   [--model equi|cnn|sen|all] [--threads 1,2] [--no-peer] [--device cpu|vulkan[:N|:cpu]]`
//! (the bench profile builds everything in release; `--profile dev` gives close figures from the
//! test build's target directory). Threads: one rayon pool per thread count for our side,
//! `torch.set_num_threads` for the peer.

use std::process::Command;
use std::time::Instant;

use clap::{Parser, ValueEnum};
use equiarm_nn::kernels::MatmulPrecision;
use equiarm_sac::agent::{AgentConfig, ModelKind};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::timing::{random_batch, time_update};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Preset {
    Reduced16,
    Paper,
    All,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Model {
    Equi,
    Cnn,
    Sen,
    All,
}

/// One SAC update, ours beside PyTorch + e2cnn's.
#[derive(Parser, Debug)]
#[command(name = "update")]
struct Args {
    /// Timed updates per case (after one warm-up); the median is reported.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u32).range(1..=1000))]
    reps: u32,
    /// Which preset's networks and batch.
    #[arg(long, value_enum, default_value_t = Preset::All)]
    config: Preset,
    /// Which network family (`all`: Equi and CNN, the peer's two).
    #[arg(long, value_enum, default_value_t = Model::All)]
    model: Model,
    /// Thread counts, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "1,2", value_parser = clap::value_parser!(u32).range(1..=256))]
    threads: Vec<u32>,
    /// Skip the PyTorch + e2cnn peer.
    #[arg(long)]
    no_peer: bool,
    /// Our device (`cpu` is the default build's flex backend with our kernels).
    #[arg(long, default_value = "cpu")]
    device: String,
    /// Matrix-product precisions of the convolutions to time, comma-separated: `f32`, `bf16`
    /// (Intel AMX; `agent.matmul` of the config).
    #[arg(long, value_delimiter = ',', default_value = "f32", value_parser = matmul_precision)]
    matmul: Vec<MatmulPrecision>,
    /// Hidden size instead of the preset's.
    #[arg(long)]
    hidden: Option<usize>,
    /// Batch size instead of the preset's (not passed to the peer: `--no-peer` with it).
    #[arg(long)]
    batch: Option<usize>,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn matmul_precision(name: &str) -> Result<MatmulPrecision, String> {
    let p: MatmulPrecision = name.parse()?;
    p.supported().map(|()| p)
}

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

/// Single-thread sgemm GFLOP/s of the `gemm` crate on 1024³ (the best of 10, after a warm-up):
/// this CPU's fp32 peak as the convolution kernels can reach it.
fn sgemm_peak() -> f64 {
    let n = 1024;
    let a: Vec<f32> = (0..n * n).map(|i| (i % 13) as f32 * 0.01).collect();
    let b: Vec<f32> = (0..n * n).map(|i| (i % 7) as f32 * 0.01).collect();
    let mut c = vec![0f32; n * n];
    let mut times = Vec::new();
    for _ in 0..11 {
        let t = Instant::now();
        // SAFETY: a, b and c are n×n row-major buffers; the strides address only their elements.
        unsafe {
            gemm::gemm(
                n,
                n,
                n,
                c.as_mut_ptr(),
                1,
                n as isize,
                false,
                a.as_ptr(),
                1,
                n as isize,
                b.as_ptr(),
                1,
                n as isize,
                1.0f32,
                1.0f32,
                false,
                false,
                false,
                gemm::Parallelism::None,
            );
        }
        times.push(t.elapsed().as_secs_f64());
    }
    let best = times[1..].iter().copied().fold(f64::INFINITY, f64::min);
    2.0 * (n * n * n) as f64 / best / 1e9
}

#[derive(Debug, Default)]
struct Peer {
    update_s: f64,
    act_b1_s: f64,
}

/// Runs `bench/sac_update_peer.py`; `None` (with the reason on stderr) if it fails.
fn peer(model: ModelKind, preset: &str, threads: u32, reps: u32) -> Option<Peer> {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../bench/sac_update_peer.py");
    let out = Command::new("python3")
        .args([script, "--model", model.name(), "--config", preset])
        .args(["--threads", &threads.to_string(), "--reps", &reps.to_string()])
        .env("OMP_NUM_THREADS", threads.to_string())
        .output();
    let out = match out {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            eprintln!(
                "peer failed ({}): {}",
                o.status,
                String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or("")
            );
            return None;
        }
        Err(e) => {
            eprintln!("peer: cannot run python3: {e}");
            return None;
        }
    };
    let line = String::from_utf8_lossy(&out.stdout).lines().rfind(|l| l.starts_with('{'))?.to_string();
    let v: serde_json::Value = serde_json::from_str(&line).ok()?;
    Some(Peer { update_s: v["update_s"].as_f64()?, act_b1_s: v["act_b1_s"].as_f64()? })
}

fn main() {
    let args = Args::parse();
    let presets = match args.config {
        Preset::Reduced16 => vec!["reduced16"],
        Preset::Paper => vec!["paper"],
        Preset::All => vec!["reduced16", "paper"],
    };
    let models = match args.model {
        Model::Equi => vec![ModelKind::Equi],
        Model::Cnn => vec![ModelKind::Cnn],
        Model::Sen => vec![ModelKind::Sen],
        Model::All => vec![ModelKind::Equi, ModelKind::Cnn],
    };
    let device = equiarm_nn::device::open(&args.device).unwrap_or_else(|e| {
        eprintln!("--device: {e}");
        std::process::exit(2)
    });
    let peak = sgemm_peak();
    println!("device {} ({device:?}); sgemm peak (gemm crate, 1 thread, 1024³): {peak:.1} GFLOP/s", args.device);
    println!(
        "model  config    mm   thr batch  px | update s  peer s  ratio | GFLOP  GFLOP/s  of peak | act b1 ms  peer ms"
    );
    let mut csv = Vec::new();
    // One pool per thread count for the whole run (pools made and dropped per case left later
    // cases up to 1.9x slower, from threads of dropped pools still winding down).
    let pools: Vec<rayon::ThreadPool> = args
        .threads
        .iter()
        .map(|&t| rayon::ThreadPoolBuilder::new().num_threads(t as usize).build().expect("thread pool"))
        .collect();
    for preset_name in &presets {
        for &model in &models {
            let preset = TrainConfig::preset(
                equiarm_sac::config::Preset::from_name(preset_name).expect("preset"),
                equiarm_types::TaskKind::BlockPulling,
            );
            // SEN's paper hidden size is 32 (docs/paper.md §1.9).
            let hidden = if model == ModelKind::Sen && *preset_name == "paper" { 32 } else { preset.agent.hidden };
            let hidden = args.hidden.unwrap_or(hidden);
            let (s, b) = (preset.agent.input_size, args.batch.unwrap_or(preset.batch_size));
            let cfg = AgentConfig { model, hidden, input_size: s, ..AgentConfig::default() };
            for (&threads, pool) in args.threads.iter().zip(&pools) {
                let p = if args.no_peer || args.hidden.is_some() || args.batch.is_some() || model == ModelKind::Sen {
                    None
                } else {
                    peer(model, preset_name, threads, args.reps)
                };
                for &mm in &args.matmul {
                    // The agent's networks convolve in its config's precision.
                    let cfg = AgentConfig { matmul: mm, ..cfg.clone() };
                    let (u, a, flops) = pool.install(|| {
                        let data = random_batch(b, s, 3);
                        let mut flops = 0;
                        equiarm_nn::kernels::gemm_conv::reset_flop_count();
                        let reps = args.reps as usize;
                        let t = time_update(&cfg, &data, &device, 1, reps, (5 * reps).max(5), |_| {
                            flops = equiarm_nn::kernels::gemm_conv::flop_count();
                            equiarm_nn::kernels::gemm_conv::reset_flop_count();
                        })
                        .expect("update");
                        (t.update_median(), t.act_median(), flops)
                    });
                    let gflop = flops as f64 / 1e9;
                    let rate = gflop / u;
                    let of_peak = rate / (peak * threads as f64);
                    let (pu, pa) = p.as_ref().map_or((f64::NAN, f64::NAN), |p| (p.update_s, p.act_b1_s));
                    println!(
                        "{:<6} {:<9} {:<4} {:>3} {:>5} {:>3} | {:>8.3} {:>7.3} {:>6.2} | {:>5.1} {:>8.1} {:>7.0}% | {:>9.2} {:>8.2}",
                        model.name(),
                        preset_name,
                        mm.name(),
                        threads,
                        b,
                        s,
                        u,
                        pu,
                        u / pu,
                        gflop,
                        rate,
                        100.0 * of_peak,
                        1e3 * a,
                        1e3 * pa
                    );
                    let figures = [u, pu, u / pu, gflop, rate, of_peak, a, pa].map(|v| format!("{v:.6}")).join(",");
                    csv.push(format!("csv,{},{preset_name},{},{threads},{b},{s},{figures}", model.name(), mm.name()));
                }
            }
        }
    }
    println!(
        "csv,model,config,matmul,threads,batch,px,update_s,peer_update_s,ratio,gflop,gflops,of_peak,act_b1_s,peer_act_b1_s"
    );
    for line in csv {
        println!("{line}");
    }
    println!("peak RSS {:.0} MB", peak_rss_mb());
}
