//! Regression (found by fuzzing `resume` at 10^6 inputs, whose worker grew by ~16 MB/s): loading
//! weights into a trainable (autodiff) module kept about 20 kB per load, because burn's autodiff
//! forgets the graph nodes of replaced parameters only during a backward pass. A policy node loads
//! every weights message the trainer publishes and never trains. Alone in its test binary so that
//! the process's resident memory is this test's.

use equiarm_nn::burn::tensor::Device;
use equiarm_nn::init::Init;
use equiarm_nn::nets::{EquiActor, NetConfig};

fn rss_kib() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    status.lines().find(|l| l.starts_with("VmRSS:"))?.split_whitespace().nth(1)?.parse().ok()
}

#[test]
fn loading_weights_again_and_again_into_a_trainable_actor_does_not_grow_the_process() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("actor.safetensors");
    let mut actor = EquiActor::new(&NetConfig::reduced_cpu(), &Init::new(3), &Device::flex().autodiff()).unwrap();
    equiarm_nn::checkpoint::save(&actor, &path).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    for _ in 0..200 {
        actor = equiarm_nn::checkpoint::load(actor, &path).unwrap();
    }
    let Some(before) = rss_kib() else { return }; // not Linux: nothing to measure
    for k in 0..2000 {
        actor = if k % 2 == 0 {
            equiarm_nn::checkpoint::load(actor, &path).unwrap()
        } else {
            equiarm_nn::checkpoint::load_bytes(actor, bytes.clone(), "weights").unwrap()
        };
    }
    let grown = rss_kib().unwrap().saturating_sub(before);
    // Before the fix: ~40 MB over these 2,000 loads; after it, about 1 MB of allocator noise.
    assert!(grown < 10 * 1024, "2,000 loads grew the process by {grown} KiB");
}
