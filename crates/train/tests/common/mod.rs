//! What the in-process run tests share.

use equiarm_sac::config::TrainConfig;

/// A block-pulling run small enough for a test (16 px crops, hidden 8, batch 8, two envs, two demo
/// episodes), with neither evaluations nor periodic checkpoints: a test turns on what it checks.
pub fn tiny_run(seed: u64, total_updates: u64) -> TrainConfig {
    let mut c = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    c.image_size = 19;
    c.agent.input_size = 16;
    c.agent.hidden = 8;
    c.num_envs = 2;
    c.demo_episodes = 2;
    c.batch_size = 8;
    c.training_starts = 30;
    c.total_updates = total_updates;
    c.eval_every = 0;
    c.checkpoint_every = 0;
    c.seed = seed;
    c
}
