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

    let out = equiarm().args(["nn", "check-equivariance", "--config", "reduced", "--hidden", "24"]).arg(&file).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("actor.safetensors"), "{err}");

    let out = equiarm().args(["nn", "check-equivariance"]).output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8(out.stderr).unwrap().contains("--fresh"));
}
