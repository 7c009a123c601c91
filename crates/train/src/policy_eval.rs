//! `equiarm bag eval BAG --policy CKPT`: runs an actor over the observations a bag's `Transition`s
//! name (joined with the recorded `Observation`s on env and seq) and reports, per action dimension, how its greedy action (tanh of the mean) agrees
//! with the action that was recorded, both in the agent's normalised [-1, 1] units
//! (`Action::to_normalized`, docs/paper.md §1.2).
//!
//! Network input: the one acting uses (`equiarm_sac::augment::centre_input` of the Observation's
//! frame as the replay stores it, depth in f16), so the actor sees what it saw in training.
//!
//! ## Limitations
//! The architecture is given on the command line (`--net`, `--config`): the checkpoint file holds
//! only tensors. Observations smaller than the network's input are an error.

use std::collections::HashMap;
use std::path::Path;

use anyhow::{Context as _, bail};
use equiarm_bag::{ReadMode, Reader};
use equiarm_msgs::RosMessage;
use equiarm_msgs::msg::{GripperCommand, Observation, Transition};
use equiarm_nn::burn::tensor::{Device, Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::nets::{Actor, CnnActor, EquiActor, NetConfig};
use equiarm_sac::augment::centre_input;

use crate::policy::{action_of, frame_of};
use equiarm_types::{ACTION_DIM, NormalizedAction, OBS_PLANES};

/// Transitions evaluated per forward pass.
const BATCH: usize = 32;

/// Action dimension names, in the network's order.
pub const DIMS: [&str; 5] = ["p", "dx", "dy", "dz", "dtheta"];

/// The recorded action in the agent's normalised units.
pub fn normalised(c: &GripperCommand) -> NormalizedAction {
    action_of(c).to_normalized()
}

/// The 5 × S × S network input of an observation (centre crop to `size`), as acting builds it.
pub fn network_input(obs: &Observation, size: usize) -> anyhow::Result<Vec<f32>> {
    let frame = frame_of(obs)?;
    if frame.size() < size {
        bail!("observation of {0}x{0} px is smaller than the network's {size}x{size} input", frame.size());
    }
    Ok(centre_input(&[&frame], size)?)
}

/// Per-dimension agreement between the policy and the recorded actions.
#[derive(Clone, Debug, Default)]
pub struct Agreement {
    /// Transitions evaluated.
    pub n: usize,
    /// Mean |policy − recorded| per dimension (normalised units).
    pub mae: [f64; 5],
    /// Fraction with the same sign per dimension.
    pub sign: [f64; 5],
    /// Pearson correlation per dimension (NaN when either side is constant).
    pub corr: [f64; 5],
}

impl Agreement {
    /// The agreement as a text table (one row per action dimension).
    pub fn table(&self) -> String {
        let mut out = format!("{} transitions; policy (tanh of mean) vs recorded action, normalised units\n", self.n);
        out += &format!("{:<8} {:>10} {:>14} {:>12}\n", "dim", "mean |d|", "same sign", "correlation");
        for (d, name) in DIMS.iter().enumerate() {
            out += &format!("{name:<8} {:>10.4} {:>14.3} {:>12.3}\n", self.mae[d], self.sign[d], self.corr[d]);
        }
        out
    }

    /// The agreement as JSON: `{"transitions", "dims": [{"dim", "mae", "sign_agreement", "correlation"}]}`.
    pub fn json(&self) -> serde_json::Value {
        let dims: Vec<_> = DIMS
            .iter()
            .enumerate()
            .map(|(d, name)| {
                serde_json::json!({"dim": name, "mae": self.mae[d], "sign_agreement": self.sign[d], "correlation": self.corr[d]})
            })
            .collect();
        serde_json::json!({"transitions": self.n, "dims": dims})
    }
}

fn agreement(pairs: &[(NormalizedAction, NormalizedAction)]) -> Agreement {
    let n = pairs.len();
    let mut a = Agreement { n, ..Default::default() };
    for d in 0..5 {
        let (xs, ys): (Vec<f64>, Vec<f64>) = pairs.iter().map(|(p, r)| (p[d] as f64, r[d] as f64)).unzip();
        let nf = n as f64;
        a.mae[d] = xs.iter().zip(&ys).map(|(x, y)| (x - y).abs()).sum::<f64>() / nf;
        a.sign[d] = xs.iter().zip(&ys).filter(|(x, y)| x.signum() == y.signum()).count() as f64 / nf;
        let (mx, my) = (xs.iter().sum::<f64>() / nf, ys.iter().sum::<f64>() / nf);
        let cov: f64 = xs.iter().zip(&ys).map(|(x, y)| (x - mx) * (y - my)).sum();
        let vx: f64 = xs.iter().map(|x| (x - mx).powi(2)).sum();
        let vy: f64 = ys.iter().map(|y| (y - my).powi(2)).sum();
        a.corr[d] = cov / (vx * vy).sqrt();
    }
    a
}

/// Runs the actor in `checkpoint` (`net`: `equi` or `cnn`; `cfg` its architecture) over every
/// `Transition` in `bag`.
pub fn evaluate(bag: &Path, checkpoint: &Path, net: &str, cfg: &NetConfig) -> anyhow::Result<Agreement> {
    let device = Device::flex();
    let init = Init::new(0);
    let actor: Box<dyn Actor> = match net {
        "equi" => {
            Box::new(equiarm_nn::checkpoint::load(EquiActor::new(cfg, &init, &device)?, checkpoint)?.cache_kernels())
        }
        "cnn" => Box::new(equiarm_nn::checkpoint::load(CnnActor::new(cfg, &init, &device)?, checkpoint)?),
        other => bail!("unknown --net '{other}': use equi or cnn"),
    };
    let s = cfg.input_size;
    let (mut inputs, mut recorded, mut pairs) = (Vec::new(), Vec::new(), Vec::new());
    let mut run = |inputs: &mut Vec<f32>, recorded: &mut Vec<NormalizedAction>| -> anyhow::Result<()> {
        let b = recorded.len();
        if b == 0 {
            return Ok(());
        }
        let x = Tensor::<4>::from_data(TensorData::new(std::mem::take(inputs), [b, OBS_PLANES, s, s]), &device);
        let (mean, _) = actor.forward(x);
        let out = mean.tanh().into_data().try_to_vec::<f32>().map_err(|e| anyhow::anyhow!("reading actions: {e:?}"))?;
        for (i, r) in recorded.drain(..).enumerate() {
            let mut p = [0f32; ACTION_DIM];
            p.copy_from_slice(&out[ACTION_DIM * i..ACTION_DIM * (i + 1)]);
            pairs.push((p, r));
        }
        Ok(())
    };
    let reader = Reader::open(bag)?;
    // First the recorded actions by the observation they answered, then those observations' inputs
    // (a re-published observation counts once).
    let mut actions: HashMap<(String, u64), NormalizedAction> = HashMap::new();
    reader
        .for_each(ReadMode::Salvage, |m| {
            if m.type_name == Transition::TYPE_NAME {
                let t = m.decode::<Transition>()?;
                actions.insert((t.env, t.obs_seq), normalised(&t.action));
            }
            Ok::<(), equiarm_bag::DecodeError>(())
        })?
        .with_context(|| bag.display().to_string())?;
    let mut failure = None;
    reader
        .for_each(ReadMode::Salvage, |m| {
            if m.type_name != Observation::TYPE_NAME {
                return Ok(());
            }
            let step = (|| -> anyhow::Result<()> {
                let o = m.decode::<Observation>()?;
                let Some(action) = actions.remove(&(o.env.clone(), o.seq)) else { return Ok(()) };
                inputs.extend(network_input(&o, s).with_context(|| format!("{} seq {}", m.topic, o.seq))?);
                recorded.push(action);
                if recorded.len() == BATCH {
                    run(&mut inputs, &mut recorded)?;
                }
                Ok(())
            })();
            step.map_err(|e| failure = Some(e))
        })?
        .ok();
    if let Some(e) = failure {
        return Err(e);
    }
    run(&mut inputs, &mut recorded)?;
    if pairs.is_empty() {
        bail!("{}: no Transition with its recorded Observation to evaluate the policy on", bag.display());
    }
    Ok(agreement(&pairs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorded_actions_normalise_like_the_paper() {
        let c = GripperCommand {
            open_ratio: 1.0,
            dx: 0.05,
            dy: -0.025,
            dz: 0.0,
            dtheta: -std::f32::consts::FRAC_PI_4,
            ..Default::default()
        };
        assert_eq!(normalised(&c), [1.0, 1.0, -0.5, 0.0, -1.0]);
    }

    #[test]
    fn identical_actions_agree_fully() {
        let pairs = vec![
            ([0.5, -0.2, 0.1, 0.3, -0.9], [0.5, -0.2, 0.1, 0.3, -0.9]),
            ([-0.5, 0.2, -0.1, -0.3, 0.9], [-0.5, 0.2, -0.1, -0.3, 0.9]),
        ];
        let a = agreement(&pairs);
        assert_eq!(a.mae, [0.0; 5]);
        assert_eq!(a.sign, [1.0; 5]);
        assert!(a.corr.iter().all(|c| (c - 1.0).abs() < 1e-12));
    }

    #[test]
    fn the_table_and_the_json_show_every_dimension() {
        let a = agreement(&[([0.5, -0.2, 0.1, 0.3, -0.9], [0.4, -0.2, 0.1, 0.3, -0.9]), ([0.1; 5], [0.0; 5])]);
        let table = a.table();
        let lines: Vec<&str> = table.lines().collect();
        assert!(lines[0].starts_with("2 transitions"));
        assert_eq!(lines.len(), 2 + DIMS.len());
        for (line, dim) in lines[2..].iter().zip(DIMS) {
            assert!(line.starts_with(dim), "{line}");
        }
        let json = a.json();
        assert_eq!(json["transitions"], 2);
        assert_eq!(json["dims"][0]["dim"], "p");
        assert!((json["dims"][0]["mae"].as_f64().unwrap() - 0.1).abs() < 1e-6);
    }
}
