//! `agent.matmul = "bf16"` (Intel AMX): the same SAC updates as in `f32` up to bfloat16's rounding,
//! and a clear refusal when an agent is built where the CPU has no AMX. The precision is the agent's
//! own (its networks' config): an `f32` and a `bf16` agent live side by side in one process.

use equiarm_nn::kernels::MatmulPrecision;
use equiarm_sac::agent::{Agent, AgentConfig, ModelKind};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::timing::random_batch;

/// A fresh agent (seed 3).
fn agent(model: ModelKind, matmul: MatmulPrecision) -> Agent {
    Agent::new(AgentConfig { model, hidden: 8, input_size: 16, matmul, ..AgentConfig::default() }, 3).unwrap()
}

/// The losses of update `i` on a fixed random batch.
fn update(agent: &mut Agent, i: u64) -> [f32; 3] {
    let (m, _) = agent.update(random_batch(16, 16, 10 + i)).unwrap();
    [m.qf1_loss, m.qf2_loss, m.actor_loss]
}

/// Losses of three updates of a fresh agent.
fn losses(model: ModelKind, matmul: MatmulPrecision) -> Vec<[f32; 3]> {
    let mut a = agent(model, matmul);
    (0..3).map(|i| update(&mut a, i)).collect()
}

#[test]
fn bf16_updates_follow_the_f32_ones_or_are_refused_without_amx() {
    let mut cfg = TrainConfig::reduced16(equiarm_types::TaskKind::BlockPulling);
    cfg.agent.matmul = MatmulPrecision::Bf16;
    // The config is valid anywhere (a grid of bf16 runs reads and reports on any machine); the
    // machine is checked when an agent is built.
    cfg.validate().unwrap();
    if let Err(e) = MatmulPrecision::Bf16.supported() {
        // No AMX here: building the agent refuses, naming the field and the fix.
        let a = Agent::new(cfg.agent.clone(), 0).err().expect("refused").to_string();
        assert!(a.contains("agent.matmul") && a.contains("AMX") && a.contains("use f32"), "{a}");
        eprintln!("no AMX on this machine ({e}): only the refusal was checked");
        return;
    }
    for model in [ModelKind::Equi, ModelKind::Cnn] {
        // An f32 and a bf16 agent side by side, their updates interleaved: each keeps its precision.
        let (mut f, mut b) = (agent(model, MatmulPrecision::F32), agent(model, MatmulPrecision::Bf16));
        let (exact, rounded): (Vec<_>, Vec<_>) = (0..3).map(|i| (update(&mut f, i), update(&mut b, i))).unzip();
        assert_eq!(exact, losses(model, MatmulPrecision::F32), "{model:?}: the f32 agent ran in f32 beside bf16");
        assert_eq!(rounded, losses(model, MatmulPrecision::Bf16), "{model:?}: bf16 updates are repeatable");
        let mut largest = 0f32;
        for (e, r) in exact.iter().flatten().zip(rounded.iter().flatten()) {
            let rel = (e - r).abs() / e.abs().max(1e-3);
            largest = largest.max(rel);
        }
        eprintln!("{model:?}: largest relative loss difference, bf16 against f32: {largest:.2e}");
        // bf16 keeps 8 significant bits (a relative step of 2^-8 = 0.4 %) per operand; over three
        // updates the losses move by a few per cent at most, and they do move.
        assert!(largest < 0.05, "{model:?}: bf16 losses {rounded:?} against f32 {exact:?}");
        assert!(largest > 0.0, "{model:?}: bf16 gave the f32 losses bit for bit: the AMX path did not run");
    }
}
