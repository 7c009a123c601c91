//! `agent.matmul = "bf16"` (Intel AMX): the same SAC updates as in `f32` up to bfloat16's rounding,
//! and a clear refusal when an agent is built where the CPU has no AMX. One test in its own binary: the precision is
//! process-wide, so no other test may run beside it.

use equiarm_nn::kernels::{MatmulPrecision, matmul_precision};
use equiarm_sac::agent::{Agent, AgentConfig, ModelKind};
use equiarm_sac::config::TrainConfig;
use equiarm_sac::timing::random_batch;

/// Losses of three updates of a fresh agent (seed 3) on fixed random batches.
fn losses(model: ModelKind, matmul: MatmulPrecision) -> Vec<[f32; 3]> {
    let cfg = AgentConfig { model, hidden: 8, input_size: 16, matmul, ..AgentConfig::default() };
    let mut agent = Agent::new(cfg, 3).unwrap();
    assert_eq!(matmul_precision(), matmul, "building the agent sets the process's precision");
    (0..3)
        .map(|i| {
            let (m, _) = agent.update(random_batch(16, 16, 10 + i)).unwrap();
            [m.qf1_loss, m.qf2_loss, m.actor_loss]
        })
        .collect()
}

#[test]
fn bf16_updates_follow_the_f32_ones_or_are_refused_without_amx() {
    let mut cfg = TrainConfig::reduced16(equiarm_types::TaskKind::BlockPulling);
    cfg.agent.matmul = MatmulPrecision::Bf16;
    // The config is valid anywhere (a grid of bf16 runs reads and reports on any machine); the
    // machine is checked when an agent is built.
    cfg.validate().unwrap();
    if let Err(e) = MatmulPrecision::Bf16.supported() {
        // No AMX here: building the agent refuses, naming the field and the fix, and f32 stays.
        let a = Agent::new(cfg.agent.clone(), 0).err().expect("refused").to_string();
        assert!(a.contains("agent.matmul") && a.contains("AMX") && a.contains("use f32"), "{a}");
        assert_eq!(matmul_precision(), MatmulPrecision::F32);
        eprintln!("no AMX on this machine ({e}): only the refusal was checked");
        return;
    }
    for model in [ModelKind::Equi, ModelKind::Cnn] {
        let exact = losses(model, MatmulPrecision::F32);
        let rounded = losses(model, MatmulPrecision::Bf16);
        let again = losses(model, MatmulPrecision::Bf16);
        assert_eq!(rounded, again, "{model:?}: bf16 updates are repeatable");
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
