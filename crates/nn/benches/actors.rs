//! Benchmark: the Equi and CNN SAC actors on burn (flex backend) beside PyTorch + e2cnn
//! (`bench/e2cnn_peer.py`), measured in the same run, ratios printed.
//!
//! Cases: forward at batch 1 (policy node; Equi uses cached kernels), forward at batch 128,
//! forward + backward + Adam at batch 128; paper config (hidden 64, 128 px) and reduced CPU
//! config (hidden 16, 64 px). Medians of `--reps` runs (5× as many at batch 1) after one
//! warm-up. The bench profile builds burn in release (a cold build takes ~20 min); the dev
//! profile also optimises dependencies, so `cargo build -p equiarm_nn --benches` and running
//! the binary from `target/debug/deps/actors-*` gives close figures much sooner.
//!
//! `cargo bench -p equiarm_nn --bench actors -- [--reps N] [--config paper|reduced|all]
//!   [--net equi|cnn|all] [--mode fwd_b1|fwd_b128|train_b128|all] [--no-peer] [--python PY]`
//! Threads: flex uses rayon's pool (set `RAYON_NUM_THREADS`); the peer gets `--threads`
//! (default 2). Prints a table and one CSV line per case (prefixed `csv,`).

use clap::{Parser, ValueEnum};
use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::optim::{AdamConfig, GradientsParams};
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::layers::{ConvAlgo, Numerics};
use equiarm_nn::nets::{Actor, CnnActor, EquiActor, NetConfig};
use std::process::Command;
use std::time::Instant;

/// What the run measures, from the command line.
struct Args {
    reps: usize,
    configs: Vec<&'static str>,
    nets: Vec<&'static str>,
    modes: Vec<&'static str>,
    peer: bool,
    python: String,
    threads: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum ConfigArg {
    Reduced,
    Paper,
    All,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum NetArg {
    Equi,
    Cnn,
    All,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum ModeArg {
    #[value(name = "fwd_b1")]
    FwdB1,
    #[value(name = "fwd_b128")]
    FwdB128,
    #[value(name = "train_b128")]
    TrainB128,
    All,
}

/// The Equi and CNN SAC actors on burn, beside PyTorch + e2cnn.
#[derive(Parser, Debug)]
#[command(name = "actors")]
struct Cli {
    /// Timed runs per case after one warm-up (5× as many, at least 10, at batch 1); the median is
    /// reported.
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(1..))]
    reps: u32,
    /// Which network configuration (`reduced`: hidden 16, 64 px; `paper`: hidden 64, 128 px).
    #[arg(long, value_enum, default_value_t = ConfigArg::All)]
    config: ConfigArg,
    /// Which actor.
    #[arg(long, value_enum, default_value_t = NetArg::All)]
    net: NetArg,
    /// Which case: forward at batch 1, forward at batch 128, forward + backward + Adam at batch 128.
    #[arg(long, value_enum, default_value_t = ModeArg::All)]
    mode: ModeArg,
    /// Skip the PyTorch + e2cnn peer.
    #[arg(long)]
    no_peer: bool,
    /// Python interpreter that runs the peer (`bench/e2cnn_peer.py`).
    #[arg(long, default_value = "python3")]
    python: String,
    /// Threads of the peer (ours: set `RAYON_NUM_THREADS`).
    #[arg(long, default_value_t = 2)]
    threads: usize,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn parse() -> Args {
    let cli = Cli::parse();
    let configs = match cli.config {
        ConfigArg::Reduced => vec!["reduced"],
        ConfigArg::Paper => vec!["paper"],
        ConfigArg::All => vec!["reduced", "paper"],
    };
    let nets = match cli.net {
        NetArg::Equi => vec!["equi"],
        NetArg::Cnn => vec!["cnn"],
        NetArg::All => vec!["equi", "cnn"],
    };
    let modes = match cli.mode {
        ModeArg::FwdB1 => vec!["fwd_b1"],
        ModeArg::FwdB128 => vec!["fwd_b128"],
        ModeArg::TrainB128 => vec!["train_b128"],
        ModeArg::All => vec!["fwd_b1", "fwd_b128", "train_b128"],
    };
    Args { reps: cli.reps as usize, configs, nets, modes, peer: !cli.no_peer, python: cli.python, threads: cli.threads }
}

/// The preset `name`, convolving as `numerics` says.
fn config(name: &str, numerics: Numerics) -> NetConfig {
    let cfg = match name {
        "paper" => NetConfig::paper(),
        _ => NetConfig::reduced_cpu(),
    };
    cfg.with_numerics(numerics)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn input(batch: usize, cfg: &NetConfig, device: &Device) -> Tensor<4> {
    let s = cfg.input_size;
    let len = batch * cfg.in_channels * s * s;
    Tensor::from_data(TensorData::new(Init::new(1).normal("x", len, 1.0), [batch, cfg.in_channels, s, s]), device)
}

fn sync<const D: usize>(t: Tensor<D>) {
    let _ = t.into_data();
}

fn time_n(reps: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..reps)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64()
            })
            .collect(),
    )
}

fn bench_forward<A: Actor>(actor: &A, cfg: &NetConfig, batch: usize, reps: usize) -> f64 {
    let dev = Device::flex();
    let x = input(batch, cfg, &dev);
    time_n(reps, || {
        let (m, s) = actor.forward(x.clone());
        sync(m);
        sync(s);
    })
}

fn run_train<A: Actor + Module>(actor: A, cfg: &NetConfig, reps: usize) -> f64 {
    let dev = Device::flex().autodiff();
    let x = input(128, cfg, &dev);
    let target = Tensor::<2>::zeros([128, 5], &dev);
    let mut optim = AdamConfig::new().init();
    let mut slot = Some(actor);
    time_n(reps, || {
        let a = slot.take().expect("actor");
        let (m, s) = a.forward(x.clone());
        let loss = (m - target.clone()).powf_scalar(2.0).mean() + s.mean();
        let grads = GradientsParams::from_grads(loss.backward(), &a);
        slot = Some(optim.step(1e-4, a, grads));
    })
}

fn peer(args: &Args, net: &str, cfg: &str, mode: &str, reps: usize) -> Option<f64> {
    if !args.peer {
        return None;
    }
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../../bench/e2cnn_peer.py");
    let out = Command::new(&args.python)
        .args([
            script,
            "--net",
            net,
            "--config",
            cfg,
            "--mode",
            mode,
            "--threads",
            &args.threads.to_string(),
            "--reps",
            &reps.to_string(),
        ])
        .output()
        .ok()?;
    if !out.status.success() {
        eprintln!("peer failed: {}", String::from_utf8_lossy(&out.stderr));
        return None;
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().rev().find(|l| l.contains("median_s"))?;
    let v = line.split("\"median_s\":").nth(1)?.split([',', '}']).next()?.trim().parse().ok()?;
    Some(v)
}

fn main() {
    let args = parse();
    // EQUIARM_CONV=unfold: convolutions as unfold + matmul (see equiarm_nn::layers::ConvAlgo).
    let numerics = if std::env::var("EQUIARM_CONV").as_deref() == Ok("unfold") {
        println!("convolution: unfold + matmul");
        Numerics::algo(ConvAlgo::Unfold)
    } else {
        println!("convolution: our kernels");
        Numerics::DEFAULT
    };
    println!("{:<6} {:<8} {:<11} {:>12} {:>12} {:>8}", "net", "config", "mode", "burn-flex s", "torch s", "ratio");
    for &cfg_name in &args.configs {
        let cfg = config(cfg_name, numerics);
        for &net in &args.nets {
            for &mode in &args.modes {
                // batch 1 is cheap and noisy: take more runs
                let reps = if mode == "fwd_b1" { (args.reps * 5).max(10) } else { args.reps };
                let ours = match (net, mode) {
                    ("equi", "train_b128") => {
                        run_train(EquiActor::new(&cfg, &Init::new(0), &Device::flex().autodiff()).unwrap(), &cfg, reps)
                    }
                    ("cnn", "train_b128") => {
                        run_train(CnnActor::new(&cfg, &Init::new(0), &Device::flex().autodiff()).unwrap(), &cfg, reps)
                    }
                    ("equi", m) => {
                        let a = EquiActor::new(&cfg, &Init::new(0), &Device::flex()).unwrap().cache_kernels();
                        bench_forward(&a, &cfg, if m == "fwd_b1" { 1 } else { 128 }, reps)
                    }
                    (_, m) => {
                        let a = CnnActor::new(&cfg, &Init::new(0), &Device::flex()).unwrap();
                        bench_forward(&a, &cfg, if m == "fwd_b1" { 1 } else { 128 }, reps)
                    }
                };
                let theirs = peer(&args, net, cfg_name, mode, reps);
                let ratio = theirs.map(|t| format!("{:.2}", ours / t)).unwrap_or_else(|| "-".into());
                let t = theirs.map(|t| format!("{t:.4}")).unwrap_or_else(|| "-".into());
                println!("{net:<6} {cfg_name:<8} {mode:<11} {ours:>12.4} {t:>12} {ratio:>8}");
                println!("csv,{net},{cfg_name},{mode},{ours},{}", theirs.map(|t| t.to_string()).unwrap_or_default());
            }
        }
    }
}
