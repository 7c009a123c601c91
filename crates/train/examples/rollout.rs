//! Diagnostic: greedy rollouts of a checkpoint, printing per step the gripper position, the
//! greedy action and the expert's action for the same observation; where each object started and
//! where it was at the episode's end (xy of every body that is neither the table nor the gripper);
//! each episode's end (success, invalid or timeout) and, last, the counts.
//!
//! `cargo run -p equiarm_train --example rollout -- RUN_DIR [EPISODES]`
use clap::Parser;
use equiarm_sac::agent::ActMode;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::{Learner, read_json};
use equiarm_sim::Action;

/// Greedy rollouts of a run's newest checkpoint, step by step beside the expert.
#[derive(Parser, Debug)]
#[command(name = "rollout")]
struct Args {
    /// Training run directory (with `config.json` and `checkpoints/`).
    run_dir: std::path::PathBuf,
    /// Evaluation episodes to roll out.
    #[arg(default_value_t = 3)]
    episodes: u64,
}

fn main() {
    let args = Args::parse();
    if let Err(e) = run(&args.run_dir, args.episodes) {
        eprintln!("rollout: {}: {e}", args.run_dir.display());
        std::process::exit(1);
    }
}

fn run(dir: &std::path::Path, episodes: u64) -> Result<(), Box<dyn std::error::Error>> {
    let cfg: TrainConfig = read_json(&dir.join("config.json"))?;
    let mut l = Learner::new(cfg.clone())?;
    l.resume(&equiarm_train::rundir::find_checkpoint(dir)?)?;
    let mut env = equiarm_sim::Env::new(equiarm_train::env::env_config(&cfg)?)?;
    let (mut wins, mut invalid) = (0, 0);
    for ep in 0..episodes {
        let mut o = env.reset(equiarm_train::env::episode_seed(cfg.seed ^ equiarm_train::env::EVAL, 0, ep))?;
        println!("episode {ep}");
        if let Some(scene) = env.scene() {
            println!("  start objects{}", object_positions(scene));
        }
        for t in 0..cfg.max_episode_steps {
            let f = equiarm_train::env::frame_of(&o)?;
            let g = l.act(&[&f], ActMode::Greedy)?[0];
            let e = o.expert_action.to_normalized();
            println!(
                "  t{t:02} tcp [{:.3} {:.3} {:.3}] greedy [{:+.2} {:+.2} {:+.2} {:+.2} {:+.2}] expert [{:+.2} {:+.2} {:+.2} {:+.2} {:+.2}]",
                o.tcp[0], o.tcp[1], o.tcp[2], g[0], g[1], g[2], g[3], g[4], e[0], e[1], e[2], e[3], e[4]
            );
            let r = env.step(&Action::from_normalized(g))?;
            if r.done {
                println!("  done success {} invalid {} timeout {}", r.info.success, r.info.invalid, r.info.timeout);
                if let Some(scene) = env.scene() {
                    println!("  objects{}", object_positions(scene));
                }
                wins += r.info.success as u32;
                invalid += r.info.invalid as u32;
                break;
            }
            o = r.observation;
        }
    }
    println!("{wins}/{episodes} successes, {invalid} ended early (invalid: an object left the workspace)");
    Ok(())
}

/// ` name [x y]` for each body of the scene that is neither the table nor the gripper (one entry per
/// segmentation id, i.e. per rigid body).
fn object_positions(scene: &equiarm_sim::world::Scene) -> String {
    let mut out = String::new();
    let mut seen = std::collections::BTreeSet::new();
    for v in &scene.visuals {
        let name = scene.seg_names.get(v.seg as usize).map(String::as_str).unwrap_or("?");
        if name.starts_with("table") || name.starts_with("gripper") || !seen.insert(v.seg) {
            continue;
        }
        let Some(body) = scene.physics.colliders.get(v.collider).and_then(|c| c.parent()) else {
            continue;
        };
        let p = scene.physics.bodies[body].translation();
        out.push_str(&format!(" {name} [{:.3} {:.3}]", p.x, p.y));
    }
    out
}
