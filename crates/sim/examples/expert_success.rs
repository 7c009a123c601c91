//! Runs each task's expert planner for seeds 0..N (default 100) and prints the success counts.
//! Acceptance (issue 3): at least 95 of 100 per task.
//!
//! cargo run --release -p equiarm_sim --example expert_success -- [N] [task]
//!
//! Environment: `VERBOSE=1` lists the failed seeds, `SUBSTEPS=K` and `DT_HZ=F` override the physics
//! substeps per step and the substep rate.

use clap::Parser;
use equiarm_sim::{Env, EnvConfig, TaskKind};

/// Each task's expert planner over seeds 0..N: success counts.
#[derive(Parser, Debug)]
#[command(name = "expert_success")]
struct Args {
    /// Seeds (episodes) per task.
    #[arg(default_value_t = 100)]
    n: u64,
    /// Only this task (`all`: every task, the default).
    #[arg(default_value = "all")]
    task: String,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let n = args.n;
    let tasks = TaskKind::select(&args.task)?;
    let verbose = std::env::var_os("VERBOSE").is_some();
    println!("task             successes / episodes   mean steps (successes)");
    for task in tasks {
        let mut cfg = EnvConfig::new(task);
        cfg.render = false;
        if let Some(v) = std::env::var("SUBSTEPS").ok().and_then(|v| v.parse().ok()) {
            cfg.params.substeps = v;
        }
        if let Some(v) = std::env::var("DT_HZ").ok().and_then(|v| v.parse::<f32>().ok()) {
            cfg.params.dt = 1.0 / v;
        }
        let mut env = Env::new(cfg)?;
        let (mut ok, mut steps) = (0u64, 0u64);
        let mut failed = Vec::new();
        for seed in 0..n {
            let r = env.run_expert_episode(seed)?;
            if r.info.success {
                ok += 1;
                steps += r.observation.step as u64;
            } else {
                failed.push((seed, r.info.invalid));
            }
        }
        println!("{:<16} {:>4} / {:<4}            {:.1}", task.name(), ok, n, steps as f64 / ok.max(1) as f64);
        if verbose && !failed.is_empty() {
            println!("  failed seeds (seed, invalid): {failed:?}");
        }
    }
    Ok(())
}
