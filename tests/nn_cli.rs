//! `equiarm nn check-equivariance`: the per-element equivariance error of a saved network, and a clear
//! error for a file made for another architecture.

mod support;

use std::process::Command;

use equiarm_nn::burn::tensor::Device;
use equiarm_nn::init::Init;
use equiarm_nn::nets::{EquiActor, NetConfig};

fn equiarm() -> Command {
    Command::new(env!("CARGO_BIN_EXE_equiarm"))
}

#[test]
fn a_saved_equivariant_actor_checks_equivariant_and_a_mismatched_one_fails_clearly() {
    let dir = support::scratch("nn_cli");
    let file = dir.join("actor.safetensors");
    let actor = EquiActor::new(&NetConfig::reduced_cpu(), &Init::new(7), &Device::flex()).unwrap();
    equiarm_nn::checkpoint::save(&actor, &file).unwrap();

    let out = equiarm().args(["nn", "check-equivariance", "--config", "reduced"]).arg(&file).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    let errors: Vec<f64> =
        text.lines().skip(1).map(|l| l.split_whitespace().last().unwrap().parse().unwrap()).collect();
    assert_eq!(errors.len(), 8, "D4 has 8 elements:\n{text}");
    assert!(errors.iter().all(|e| *e < 1e-4), "{text}");
    assert!(errors[1..].iter().any(|e| *e > 0.0), "a non-trivial element has some float error:\n{text}");

    let out = equiarm()
        .args(["nn", "check-equivariance", "--config", "reduced", "--hidden", "24"])
        .arg(&file)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("actor.safetensors"), "{err}");

    let out = equiarm().args(["nn", "check-equivariance"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8(out.stderr).unwrap().contains("--fresh"));
}

/// A bag whose recorded actions are exactly the greedy actions of an actor: `bag eval --policy` with
/// that actor agrees to float precision, with another actor it does not.
#[test]
fn bag_eval_policy_measures_agreement_with_the_recorded_actions() {
    use equiarm_bag::qos::OfferedQos;
    use equiarm_bag::{TopicInfo, Writer, WriterOptions};
    use equiarm_msgs::msg::{GripperCommand, Observation, Transition};
    use equiarm_nn::burn::tensor::{Tensor, TensorData};
    use equiarm_nn::nets::Actor;
    use equiarm_train::policy_eval::network_input;

    let dir = support::scratch("nn_cli_policy");
    let cfg = NetConfig::reduced_cpu();
    let device = Device::flex();
    let actor = EquiActor::new(&cfg, &Init::new(3), &device).unwrap();
    let (same, other) = (dir.join("same.safetensors"), dir.join("other.safetensors"));
    equiarm_nn::checkpoint::save(&actor, &same).unwrap();
    equiarm_nn::checkpoint::save(&EquiActor::new(&cfg, &Init::new(4), &device).unwrap(), &other).unwrap();

    // 40 observations of 76 px (the reduced net crops 64), pseudo-random pixels
    let side = 76u32;
    let obs: Vec<Observation> = (0..40u32)
        .map(|k| {
            let n = (side * side) as usize;
            let rgb: Vec<u8> = (0..3 * n)
                .map(|i| ((i as u32).wrapping_mul(2654435761) ^ (k * 40503)).rotate_left(k % 31) as u8)
                .collect();
            let depth: Vec<f32> = (0..n).map(|i| 0.4 + ((i as u32 * 7 + k * 13) % 100) as f32 * 2e-3).collect();
            let mut o = Observation { seq: k as u64, env: "env0".into(), holding: k % 2 == 0, ..Default::default() };
            o.set_frame(side, side, &rgb, &depth).unwrap();
            o
        })
        .collect();
    let s = cfg.input_size;
    let x: Vec<f32> = obs.iter().flat_map(|o| network_input(o, s).unwrap()).collect();
    let (mean, _) = actor.forward(Tensor::<4>::from_data(TensorData::new(x, [obs.len(), 5, s, s]), &device));
    let a = mean.tanh().into_data().try_to_vec::<f32>().unwrap();

    let bag = dir.join("bag");
    let mut w = Writer::create(&bag, WriterOptions::default()).unwrap();
    let t = w.add_topic(TopicInfo::of::<Transition>("/transitions", &[OfferedQos::reliable(100)])).unwrap();
    let ot = w.add_topic(TopicInfo::of::<Observation>("/env0/observation", &[OfferedQos::reliable(10)])).unwrap();
    for (i, o) in obs.iter().enumerate() {
        // Each frame once in its Observation (the first one re-published, as a sim does on a
        // timeout), then the Transition that names it.
        for _ in 0..1 + (i == 0) as usize {
            w.write(ot, i as u64, i as u64, &equiarm_msgs::cdr::encode(o).unwrap()).unwrap();
        }
        let u = &a[5 * i..5 * i + 5];
        let action = GripperCommand {
            obs_seq: o.seq,
            open_ratio: (u[0] + 1.0) / 2.0,
            dx: 0.05 * u[1],
            dy: 0.05 * u[2],
            dz: 0.05 * u[3],
            dtheta: std::f32::consts::FRAC_PI_4 * u[4],
            ..Default::default()
        };
        let tr =
            Transition { env: "env0".into(), obs_seq: o.seq, next_obs_seq: o.seq + 1, action, ..Default::default() };
        w.write(t, i as u64, i as u64, &equiarm_msgs::cdr::encode(&tr).unwrap()).unwrap();
    }
    w.finish().unwrap();

    let eval = |ckpt: &std::path::Path| -> serde_json::Value {
        let out = equiarm()
            .args(["bag", "eval", "--net", "equi", "--config", "reduced", "--json", "--policy"])
            .arg(ckpt)
            .arg(&bag)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let v = eval(&same);
    assert_eq!(v["transitions"], 40);
    for d in v["dims"].as_array().unwrap() {
        assert!(d["mae"].as_f64().unwrap() < 1e-5, "{d}");
        assert!(d["correlation"].as_f64().unwrap() > 0.9999, "{d}");
    }
    let v = eval(&other);
    let worst = v["dims"].as_array().unwrap().iter().map(|d| d["mae"].as_f64().unwrap()).fold(0.0, f64::max);
    assert!(worst > 1e-3, "another actor cannot agree to float precision: {v}");

    // a checkpoint of another architecture is an error naming the file
    let out = equiarm()
        .args(["bag", "eval", "--net", "equi", "--config", "paper", "--policy"])
        .arg(&same)
        .arg(&bag)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("same.safetensors"));
}
