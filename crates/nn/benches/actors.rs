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

use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::optim::{AdamConfig, GradientsParams};
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::nets::{Actor, CnnActor, EquiActor, NetConfig};
use std::process::Command;
use std::time::Instant;

struct Args {
    reps: usize,
    configs: Vec<&'static str>,
    nets: Vec<&'static str>,
    modes: Vec<&'static str>,
    peer: bool,
    python: String,
    threads: usize,
}

fn parse() -> Args {
    let mut a = Args {
        reps: 3,
        configs: vec!["reduced", "paper"],
        nets: vec!["equi", "cnn"],
        modes: vec!["fwd_b1", "fwd_b128", "train_b128"],
        peer: true,
        python: "python3".into(),
        threads: 2,
    };
    let argv: Vec<String> = std::env::args().skip(1).collect();
    let mut i = 0;
    let pick = |v: &str, all: &[&'static str]| -> Vec<&'static str> {
        if v == "all" { all.to_vec() } else { all.iter().copied().filter(|x| *x == v).collect() }
    };
    while i < argv.len() {
        let val = argv.get(i + 1).cloned().unwrap_or_default();
        match argv[i].as_str() {
            "--reps" => {
                a.reps = val.parse().expect("--reps N");
                i += 1;
            }
            "--config" => {
                a.configs = pick(&val, &["reduced", "paper"]);
                i += 1;
            }
            "--net" => {
                a.nets = pick(&val, &["equi", "cnn"]);
                i += 1;
            }
            "--mode" => {
                a.modes = pick(&val, &["fwd_b1", "fwd_b128", "train_b128"]);
                i += 1;
            }
            "--threads" => {
                a.threads = val.parse().expect("--threads N");
                i += 1;
            }
            "--python" => {
                a.python = val;
                i += 1;
            }
            "--no-peer" => a.peer = false,
            "--bench" => {}
            other => panic!("unknown argument {other}"),
        }
        i += 1;
    }
    a
}

fn config(name: &str) -> NetConfig {
    match name {
        "paper" => NetConfig::paper(),
        _ => NetConfig::reduced_cpu(),
    }
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
    if std::env::var("EQUIARM_CONV").as_deref() == Ok("unfold") {
        equiarm_nn::layers::set_conv_algo(equiarm_nn::layers::ConvAlgo::Unfold);
        println!("convolution: unfold + matmul");
    } else {
        println!("convolution: burn conv2d");
    }
    println!("{:<6} {:<8} {:<11} {:>12} {:>12} {:>8}", "net", "config", "mode", "burn-flex s", "torch s", "ratio");
    for &cfg_name in &args.configs {
        let cfg = config(cfg_name);
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
