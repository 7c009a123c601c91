//! Env step + 152 px RGBD render per task (median, p95), beside the PyBullet BulletArm-like peer
//! (`bench/pybullet_peer.py`, three modes from cheapest to most faithful: floating gripper, Kuka with
//! 100 fixed substeps, Kuka with BulletArm's moveTo loops) measured in the same run, rounds
//! interleaved. Prints the ratio PyBullet step / our step (issue 3 target: ≥ 5×, goal 10×).
//!
//!     cargo bench -p equiarm_sim --bench step_render -- --steps 300 --rounds 2 --peer python3
//!
//! Our step: the expert's action, physics (20 substeps at 1/120 s, plus grip substeps when the jaw
//! command changes), holding/success tests, the expert planner, and a 152×152 colour + depth +
//! segmentation raster, single thread. Episodes are reset (not timed) when done. The table is for
//! the default scene (the arm in view); the same steps with the arm hidden are measured in the same
//! rounds, and the arm's cost per step is printed as their ratio (issue 58 goal: at most +30 %).

use std::path::PathBuf;
use std::process::Command;
use std::time::Instant;

use clap::Parser;
use equiarm_sim::env::ArmView;
use equiarm_sim::{Action, Env, EnvConfig, TaskKind, VecEnv};

fn pct(xs: &mut [f64], q: f64) -> f64 {
    xs.sort_by(|a, b| a.total_cmp(b));
    xs[((xs.len() - 1) as f64 * q).round() as usize]
}

struct Stats {
    step: Vec<f64>,
    physics: Vec<f64>,
    render: Vec<f64>,
}

fn measure(task: TaskKind, steps: usize, seed0: u64, arm: ArmView) -> Stats {
    let mut st = Stats { step: Vec::new(), physics: Vec::new(), render: Vec::new() };
    for render in [true, false] {
        let mut cfg = EnvConfig::new(task);
        cfg.render = render;
        cfg.arm = arm;
        let mut env = Env::new(cfg).expect("env");
        let mut seed = seed0;
        let mut obs = env.reset(seed).expect("reset");
        for _ in 0..steps {
            let t = Instant::now();
            let r = env.step(&obs.expert_action).expect("step");
            let ms = t.elapsed().as_secs_f64() * 1e3;
            if render {
                st.step.push(ms);
                let t = Instant::now();
                std::hint::black_box(env.render());
                st.render.push(t.elapsed().as_secs_f64() * 1e3);
            } else {
                st.physics.push(ms);
            }
            obs = r.observation;
            if r.done {
                seed += 1;
                obs = env.reset(seed).expect("reset");
            }
        }
    }
    st
}

fn peer(python: &str, mode: &str, steps: usize) -> Option<(f64, f64, f64, f64)> {
    let script = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../bench/pybullet_peer.py");
    let out = Command::new(python).arg(&script).args(["--steps", &steps.to_string(), "--mode", mode]).output().ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text.lines().find(|l| l.starts_with('{'))?;
    let num = |key: &str| -> Option<f64> {
        let i = line.find(&format!("\"{key}\": "))? + key.len() + 4;
        line[i..].split([',', '}']).next()?.trim().parse().ok()
    };
    Some((num("median_ms")?, num("p95_ms")?, num("physics_median_ms")?, num("render_median_ms")?))
}

/// Env step + 152 px RGBD render per task, beside the PyBullet BulletArm-like peer.
#[derive(Parser, Debug)]
#[command(name = "step_render")]
struct Args {
    /// Timed steps per task and round (with rendering, and again without).
    #[arg(long, default_value_t = 300, value_parser = clap::value_parser!(u64).range(1..))]
    steps: u64,
    /// Rounds, ours and the peer's interleaved.
    #[arg(long, default_value_t = 2)]
    rounds: usize,
    /// Python interpreter with pybullet that runs `bench/pybullet_peer.py` (no peer without it).
    #[arg(long, value_name = "PYTHON")]
    peer: Option<String>,
    /// Steps per peer mode and round.
    #[arg(long, default_value_t = 100)]
    peer_steps: usize,
    /// Envs of the VecEnv throughput run (block picking, one rayon task per env).
    #[arg(long, default_value_t = 8, value_parser = clap::value_parser!(u64).range(1..))]
    envs: u64,
    /// Steps of the VecEnv throughput run (every env steps this many times).
    #[arg(long, default_value_t = 100, value_parser = clap::value_parser!(u64).range(1..))]
    vec_steps: u64,
    /// Passed by `cargo bench` to every bench program; ignored.
    #[arg(long, hide = true)]
    bench: bool,
}

fn main() {
    let args = Args::parse();
    let (steps, rounds, python, peer_steps) = (args.steps as usize, args.rounds, args.peer.clone(), args.peer_steps);

    let mut ours: Vec<Vec<f64>> = vec![Vec::new(); TaskKind::ALL.len()];
    let mut phys: Vec<Vec<f64>> = vec![Vec::new(); TaskKind::ALL.len()];
    let mut rend: Vec<Vec<f64>> = vec![Vec::new(); TaskKind::ALL.len()];
    let mut hidden: Vec<Vec<f64>> = vec![Vec::new(); TaskKind::ALL.len()];
    let mut peers: Vec<(String, (f64, f64, f64, f64))> = Vec::new();
    for round in 0..rounds {
        for (k, task) in TaskKind::ALL.into_iter().enumerate() {
            let s = measure(task, steps, 1000 * round as u64, ArmView::Visible);
            hidden[k].extend(measure(task, steps, 1000 * round as u64, ArmView::Hidden).step);
            ours[k].extend(s.step);
            phys[k].extend(s.physics);
            rend[k].extend(s.render);
        }
        if let Some(py) = &python {
            for mode in ["floating", "fixed", "bulletarm"] {
                match peer(py, mode, peer_steps) {
                    Some(r) => peers.push((mode.to_string(), r)),
                    None => eprintln!("PyBullet peer ({mode}) did not run: is pybullet installed for {py}?"),
                }
            }
        }
    }

    println!("equiarm_sim env step + 152 px RGBD render, {rounds} round(s) x {steps} steps per task, 1 thread");
    println!("{:<16} {:>12} {:>10} {:>14} {:>12}", "task", "step med ms", "p95 ms", "physics med", "render med");
    let mut all = Vec::new();
    for (k, task) in TaskKind::ALL.into_iter().enumerate() {
        all.extend_from_slice(&ours[k]);
        println!(
            "{:<16} {:>12.3} {:>10.3} {:>14.3} {:>12.3}",
            task.name(),
            pct(&mut ours[k], 0.5),
            pct(&mut ours[k], 0.95),
            pct(&mut phys[k], 0.5),
            pct(&mut rend[k], 0.5)
        );
    }
    let our_med = pct(&mut all, 0.5);
    println!("{:<16} {:>12.3} {:>10.3}", "all tasks", our_med, pct(&mut all, 0.95));
    println!("\nthe arm's cost: step median with the arm hidden, in view, ratio (same rounds)");
    let mut all_hidden = Vec::new();
    for (k, task) in TaskKind::ALL.into_iter().enumerate() {
        all_hidden.extend_from_slice(&hidden[k]);
        let (h, v) = (pct(&mut hidden[k], 0.5), pct(&mut ours[k], 0.5));
        println!("{:<16} {:>12.3} {:>10.3} {:>8.3}", task.name(), h, v, v / h);
    }
    let h = pct(&mut all_hidden, 0.5);
    println!("{:<16} {:>12.3} {:>10.3} {:>8.3}", "all tasks", h, our_med, our_med / h);

    // Throughput of VecEnv (one rayon task per env), block picking, expert actions, images on.
    let n_envs = args.envs as usize;
    let mut venv = VecEnv::new(EnvConfig::new(TaskKind::BlockPicking), n_envs).expect("vec env");
    let seeds: Vec<u64> = (0..n_envs as u64).collect();
    let mut obs = venv.reset(&seeds).expect("reset");
    let mut next_seed = n_envs as u64;
    let vec_steps = args.vec_steps as usize;
    let mut reset_secs = 0.0;
    let t = Instant::now();
    for _ in 0..vec_steps {
        let actions: Vec<Action> = obs.iter().map(|o| o.expert_action).collect();
        let results = venv.step(&actions).expect("step");
        // An ended episode is reset (not timed), as every consumer of an env must: stepping on
        // after the end is refused (SimError::EpisodeOver).
        let tr = Instant::now();
        obs = results
            .into_iter()
            .zip(venv.envs.iter_mut())
            .map(|(r, env)| {
                if r.done {
                    next_seed += 1;
                    env.reset(next_seed).expect("reset")
                } else {
                    r.observation
                }
            })
            .collect();
        reset_secs += tr.elapsed().as_secs_f64();
    }
    let secs = t.elapsed().as_secs_f64() - reset_secs;
    println!(
        "VecEnv {n_envs} envs x {vec_steps} steps on {} rayon threads: {:.0} env steps/s (single env at the median: {:.0}/s)",
        rayon::current_num_threads(),
        (n_envs * vec_steps) as f64 / secs,
        1e3 / our_med
    );
    if !peers.is_empty() {
        println!(
            "\nPyBullet peer, same run (each step ends with 2x getCameraImage 152 px, TinyRenderer, as BulletArm's RGBD):"
        );
        println!(
            "  floating = our gripper URDF on a constraint, 24 steps at 1/240 s; fixed = Kuka + 1 IK + 100 steps;"
        );
        println!("  bulletarm = Kuka + BulletArm's moveTo/gripper loops (IK retries, converge or 100 steps)");
        for mode in ["floating", "fixed", "bulletarm"] {
            let mut med: Vec<f64> = peers.iter().filter(|(m, _)| m == mode).map(|(_, r)| r.0).collect();
            let mut p95: Vec<f64> = peers.iter().filter(|(m, _)| m == mode).map(|(_, r)| r.1).collect();
            let mut ph: Vec<f64> = peers.iter().filter(|(m, _)| m == mode).map(|(_, r)| r.2).collect();
            let mut re: Vec<f64> = peers.iter().filter(|(m, _)| m == mode).map(|(_, r)| r.3).collect();
            if med.is_empty() {
                continue;
            }
            let m = pct(&mut med, 0.5);
            println!(
                "  {mode:<10} step median {m:.3} ms (p95 {:.3}; physics {:.3}, render {:.3})  ratio PyBullet/ours = {:.1}x",
                pct(&mut p95, 0.5),
                pct(&mut ph, 0.5),
                pct(&mut re, 0.5),
                m / our_med
            );
        }
    }
}
