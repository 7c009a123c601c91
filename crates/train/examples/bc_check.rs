//! Diagnostic: how well the actor imitates the demos (set CENTER=1 for centre crops; prints the
//! greedy action's squared error per dimension on the demos every 40 updates, and its spread across
//! the demo observations). Loads `demo_episodes` expert episodes into
//! the replay and runs SAC updates on them alone, printing the expert L2 loss, with the config's
//! expert weight (first argument: a multiplier, default 1).
//!
//! `cargo run -p equiarm_train --example bc_check -- [WEIGHT] [UPDATES] [FRAME:INPUT] [HIDDEN] [MODEL]`
//!
//! Environment: `DEMOS=K` demo episodes (default the config's), `VIEW=angle90` another camera
//! preset (default the paper's oblique `side`), `EVAL_EVERY=U` also runs the greedy
//! policy on the config's evaluation episodes in the simulator every U updates (the success rate
//! a policy fitted to the demos alone reaches).
use clap::Parser;
use equiarm_sac::agent::ModelKind;
use equiarm_sac::config::TrainConfig;
use equiarm_sac::learner::Learner;
use equiarm_types::NormalizedAction;

/// SAC updates on the expert demos alone: how well the actor imitates them.
#[derive(Parser, Debug)]
#[command(name = "bc_check")]
struct Args {
    /// Weight of the actor's expert (behaviour-cloning) loss, `agent.expert_weight` (the preset's is 1).
    #[arg(default_value_t = 1.0)]
    weight: f64,
    /// SAC updates to run.
    #[arg(default_value_t = 200)]
    updates: u64,
    /// Frame size and network input size, `FRAME:INPUT` (default the reduced preset's).
    #[arg(value_name = "FRAME:INPUT", value_parser = parse_sizes)]
    sizes: Option<(usize, usize)>,
    /// Hidden size (default the reduced preset's).
    hidden: Option<usize>,
    /// Network family (default the reduced preset's).
    #[arg(value_enum)]
    model: Option<ModelKind>,
}

fn parse_sizes(s: &str) -> anyhow::Result<(usize, usize)> {
    let bad = || anyhow::anyhow!("expected FRAME:INPUT (two pixel sizes, e.g. 38:32), got `{s}`");
    let (f, i) = s.split_once(':').ok_or_else(bad)?;
    Ok((f.parse().map_err(|_| bad())?, i.parse().map_err(|_| bad())?))
}

fn main() {
    let args = Args::parse();
    let (w, n) = (args.weight, args.updates);
    let mut cfg = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    if let Some((f, i)) = args.sizes {
        cfg.image_size = f;
        cfg.agent.input_size = i;
    }
    if let Some(h) = args.hidden {
        cfg.agent.hidden = h;
    }
    if let Some(m) = args.model {
        cfg.agent.model = m;
    }
    cfg.agent.expert_weight = w;
    if let Some(k) = std::env::var("DEMOS").ok().and_then(|v| v.parse().ok()) {
        cfg.demo_episodes = k;
    }
    if let Ok(v) = std::env::var("VIEW") {
        match v.parse() {
            Ok(view) => cfg.view = view,
            Err(e) => {
                eprintln!("VIEW: {e}");
                std::process::exit(2);
            }
        }
    }
    let eval_every: u64 = std::env::var("EVAL_EVERY").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let mut l = Learner::new(cfg.clone()).unwrap();
    let env_cfg = equiarm_train::env::env_config(&cfg).unwrap();
    let (tried, kept) = equiarm_train::env::collect_demos(&mut l, &env_cfg).unwrap();
    println!("demos {kept}/{tried}, transitions {}", l.replay().len());
    let n_t = l.replay().len();
    let acts: Vec<NormalizedAction> = (0..n_t).filter_map(|i| l.replay().get(i).map(|t| t.action)).collect();
    for d in 0..5 {
        let m = acts.iter().map(|a| a[d] as f64).sum::<f64>() / acts.len() as f64;
        let v = acts.iter().map(|a| (a[d] as f64 - m).powi(2)).sum::<f64>() / acts.len() as f64;
        println!("dim {d}: mean {m:.3} var {v:.3}");
    }
    if std::env::var("CENTER").is_ok() {
        l = {
            let mut c = cfg.clone();
            c.augmentation = equiarm_sac::config::Augmentation::Center;
            let mut l2 = Learner::new(c).unwrap();
            equiarm_train::env::collect_demos(&mut l2, &env_cfg).unwrap();
            l2
        };
    }
    // Greedy squared error per dimension on the replay's rows, and the spread (standard deviation)
    // of the greedy action across those observations: a spread near 0 means the actor ignores its
    // input (only biases have learned).
    let greedy = |l: &mut Learner| {
        let rows: Vec<(std::sync::Arc<equiarm_sac::frame::StoredFrame>, NormalizedAction)> =
            (0..l.replay().len()).filter_map(|i| l.replay().get(i).map(|t| (t.obs.clone(), t.action))).collect();
        let frames: Vec<&equiarm_sac::frame::StoredFrame> = rows.iter().map(|r| &*r.0).collect();
        let acts = l.act(&frames, equiarm_sac::agent::ActMode::Greedy).unwrap();
        let n = rows.len() as f64;
        let mut se = [0f64; 5];
        let mut mean = [0f64; 5];
        for (a, r) in acts.iter().zip(&rows) {
            for d in 0..5 {
                se[d] += ((a[d] - r.1[d]) as f64).powi(2);
                mean[d] += a[d] as f64 / n;
            }
        }
        let mut var = [0f64; 5];
        for a in &acts {
            for d in 0..5 {
                var[d] += (a[d] as f64 - mean[d]).powi(2) / n;
            }
        }
        let r3 = |x: f64| (x * 1000.0).round() / 1000.0;
        (se.map(|x| r3(x / n)), var.map(|v| r3(v.sqrt())))
    };
    let (se, sd) = greedy(&mut l);
    println!("greedy mse per dim before {se:?}, spread {sd:?}");
    let mut envs: Vec<equiarm_sim::Env> =
        (0..cfg.num_envs).map(|_| equiarm_sim::Env::new(env_cfg.clone()).unwrap()).collect();
    for u in 1..=n {
        let m = l.update().unwrap();
        if eval_every > 0 && u % eval_every == 0 {
            let e = equiarm_train::evaluation::evaluate(&mut l, &mut envs, cfg.eval_episodes).unwrap();
            println!(
                "{u} eval success {:.2} over {} episodes, mean length {:.1}",
                e.success_rate, e.episodes, e.mean_length
            );
        }
        if u % 20 == 0 || u == 1 {
            if u % 40 == 0 {
                let (se, sd) = greedy(&mut l);
                println!("greedy mse per dim {se:?}, spread {sd:?}");
            }
            println!(
                "{u} expert {:.3} actor {:.3} q {:.3} qloss {:.3} entropy {:.1}",
                m.expert_loss, m.actor_loss, m.qf1_values, m.qf1_loss, m.entropy
            );
        }
    }
}
