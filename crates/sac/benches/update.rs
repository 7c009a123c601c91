//! Benchmark: one SAC update (critic → actor → α → target, PAPER_SPEC §2) on random batches, for
//! each network family at the paper size (hidden 64, 128 px, batch 128) and at the reduced CPU
//! config (`TrainConfig::reduced`: hidden 8, 32 px, batch 64), medians of `--reps` updates after one warm-up, plus the batch-1 greedy action time.
//! Prints a table, one `csv,` line per case and the peak RSS.
//!
//! `cargo bench -p equiarm_sac --bench update -- [--reps N] [--config paper|reduced|all]
//!   [--model equi|cnn|sen|all] [--batch B] [--device cpu|cuda[:N]|torch] [--hidden H] [--px S]`
//! (the bench profile builds burn in release; `--profile dev` gives close figures from the test
//! build's target directory). Threads: burn-flex uses rayon's pool (`RAYON_NUM_THREADS`), libtorch
//! `OMP_NUM_THREADS`. `--device cuda` needs `--features cuda`, `--device torch` `--features tch`
//! (README); each timed update reads its losses back, so GPU figures include the synchronisation.

use std::time::Instant;

use equiarm_sac::agent::{ActMode, Agent, AgentConfig, Batch, ModelKind};

fn arg(args: &[String], name: &str) -> Option<String> {
    args.iter().position(|a| a == name).and_then(|i| args.get(i + 1).cloned())
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("VmHWM:")).and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok()))
        .map(|kb| kb / 1024.0)
        .unwrap_or(f64::NAN)
}

fn batch(b: usize, s: usize, seed: u64) -> Batch {
    let mut rng = equiarm_sac::rng::stream(seed, 1);
    let img = |n: usize, rng: &mut _| equiarm_sac::rng::normals(rng, n * 5 * s * s);
    let obs = img(b, &mut rng);
    let next_obs = img(b, &mut rng);
    let action = equiarm_sac::rng::normals(&mut rng, b * 5).iter().map(|x| x.tanh()).collect();
    Batch {
        b,
        s,
        m: 1,
        k: 1,
        obs,
        next_obs,
        action,
        reward: (0..b).map(|i| (i % 7 == 0) as u8 as f32).collect(),
        mask: (0..b).map(|i| (i % 7 != 0) as u8 as f32).collect(),
        expert: (0..b).map(|i| (i % 3 == 0) as u8 as f32).collect(),
        weight: vec![1.0; b],
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let reps: usize = arg(&args, "--reps").and_then(|s| s.parse().ok()).unwrap_or(3);
    let configs = match arg(&args, "--config").as_deref() {
        Some("paper") => vec!["paper"],
        Some("reduced") => vec!["reduced"],
        _ => vec!["reduced", "paper"],
    };
    let models = match arg(&args, "--model").as_deref() {
        Some(m) if m != "all" => vec![ModelKind::parse(m).expect("--model equi|cnn|sen|all")],
        _ => vec![ModelKind::Equi, ModelKind::Cnn],
    };
    let batch_override: Option<usize> = arg(&args, "--batch").and_then(|s| s.parse().ok());
    let device_name = arg(&args, "--device").unwrap_or_else(|| "cpu".into());
    let device = equiarm_nn::device::open(&device_name).unwrap_or_else(|e| panic!("--device: {e}"));
    println!("device {device_name} ({device:?})");
    println!("model  config   batch  px   update s (median of {reps})   act b1 s");
    for cfg_name in &configs {
        for &model in &models {
            // The presets of `TrainConfig` (SEN's paper hidden size is 32).
            let preset = equiarm_sac::config::TrainConfig::preset(cfg_name, "block_pulling").expect("preset");
            let hidden = if model == ModelKind::Sen && *cfg_name == "paper" { 32 } else { preset.agent.hidden };
            let (s, b) = (preset.agent.input_size, preset.batch_size);
            let b = batch_override.unwrap_or(b);
            let hidden = arg(&args, "--hidden").and_then(|v| v.parse().ok()).unwrap_or(hidden);
            let s = arg(&args, "--px").and_then(|v| v.parse().ok()).unwrap_or(s);
            let cfg = AgentConfig { model, hidden, input_size: s, ..AgentConfig::default() };
            let mut agent = Agent::new_on(cfg, 0, &device).expect("agent");
            let data = batch(b, s, 3);
            let mut times = Vec::new();
            for i in 0..=reps {
                let copy = data.clone();
                let t = Instant::now();
                agent.update(copy).expect("update");
                if i > 0 {
                    times.push(t.elapsed().as_secs_f64());
                }
            }
            let one = &data.obs[..5 * s * s];
            let mut acts = Vec::new();
            for _ in 0..(5 * reps).max(5) {
                let t = Instant::now();
                agent.act(one, 1, ActMode::Greedy, None).expect("act");
                acts.push(t.elapsed().as_secs_f64());
            }
            let (u, a) = (median(times), median(acts));
            println!("{:<6} {:<8} {:>5} {:>4}   {:>10.3}                  {:>8.4}", model.name(), cfg_name, b, s, u, a);
            println!("csv,{},{},{},{},{:.6},{:.6}", model.name(), cfg_name, b, s, u, a);
        }
    }
    println!("peak RSS {:.0} MB", peak_rss_mb());
}
