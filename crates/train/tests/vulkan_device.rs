//! The GPU build's device, tested without a GPU (issue: a GPU learner that builds offline and is
//! tested without one). Compiled only with the `vulkan` feature; the test command runs it on Mesa's
//! lavapipe, a Vulkan driver that runs on the CPU (`tests/vulkan_env.sh` installs it), through the
//! device `vulkan:cpu`. `EQUIARM_TEST_VULKAN=vulkan` runs the same tests on a GPU.
//!
//! - one SAC update (Equi and CNN, tiny networks) gives the CPU build's losses within a relative
//!   [`LOSS_TOL`] and its weights within [`STEP_TOL`] of the update's own step;
//! - a paper-size Equi actor on the device is D4-equivariant to < 1e-4;
//! - a short in-process run on the device writes a checkpoint that resumes on the CPU;
//! - device names: the adapter is described, a missing one is an error, not a panic.
#![cfg(feature = "vulkan")]

mod common;

use std::path::{Path, PathBuf};

use equiarm_nn::burn::tensor::Device;
use equiarm_sac::agent::{Agent, AgentConfig, Metrics, ModelKind};
use equiarm_sac::timing::random_batch;
use equiarm_train::inprocess::{RunOptions, run};
use equiarm_train::rundir::find_checkpoint;

/// Losses of one update may differ from the CPU's by this fraction (of the larger of the two, or
/// of 1 for losses near 0): the device sums in another order, and its `exp`, `tanh` and `log`
/// are not the CPU's to the last bit.
const LOSS_TOL: f64 = 1e-4;
/// After one update, ‖w_device − w_cpu‖ ≤ STEP_TOL · ‖w_cpu − w_initial‖ over all weights of the
/// actor and the critic: the two builds take the same step, up to rounding.
const STEP_TOL: f64 = 1e-3;

fn device_name() -> String {
    std::env::var("EQUIARM_TEST_VULKAN").unwrap_or_else(|_| "vulkan:cpu".to_string())
}

fn device() -> Device {
    let name = device_name();
    equiarm_nn::device::open(&name).unwrap_or_else(|e| {
        panic!("{e}\n(the test command installs Mesa's lavapipe through tests/vulkan_env.sh; EQUIARM_TEST_VULKAN names another device)")
    })
}

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("vulkan-{name}"));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Every tensor of the actor and the critic a saved agent holds, by file and name.
fn weights(dir: &Path) -> Vec<(String, Vec<f32>)> {
    let mut all = Vec::new();
    for file in ["actor.safetensors", "critic.safetensors"] {
        let mut t = equiarm_sac::tensorfile::read(&dir.join(file)).expect("read weights").tensors;
        t.sort_by(|a, b| a.0.cmp(&b.0));
        all.extend(t.into_iter().map(|(name, _, data)| (format!("{file}/{name}"), data)));
    }
    all
}

fn saved(agent: &Agent, dir: PathBuf) -> Vec<(String, Vec<f32>)> {
    std::fs::create_dir_all(&dir).unwrap();
    agent.save(&dir).unwrap();
    weights(&dir)
}

fn distance(a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut sum = 0.0;
    for ((na, va), (nb, vb)) in a.iter().zip(b) {
        assert_eq!(na, nb);
        assert_eq!(va.len(), vb.len(), "{na}");
        sum += va.iter().zip(vb).map(|(x, y)| (*x as f64 - *y as f64).powi(2)).sum::<f64>();
    }
    sum.sqrt()
}

fn losses(m: &Metrics) -> Vec<(&'static str, f64)> {
    m.named()
}

#[test]
fn one_update_on_the_device_matches_the_cpu() {
    let dev = device();
    let dir = scratch("update");
    for model in [ModelKind::Equi, ModelKind::Cnn] {
        let cfg = AgentConfig { model, hidden: 8, input_size: 16, ..AgentConfig::default() };
        let mut cpu = Agent::new(cfg.clone(), 5).unwrap();
        let mut gpu = Agent::new_on(cfg, 5, &dev).unwrap();
        let name = model.name();
        let w0 = saved(&cpu, dir.join(format!("{name}-cpu-0")));
        assert_eq!(w0, saved(&gpu, dir.join(format!("{name}-dev-0"))), "{name}: the initial weights differ");

        let batch = random_batch(8, 16, 9);
        let (m_cpu, p_cpu) = cpu.update(batch.clone()).unwrap();
        let (m_dev, p_dev) = gpu.update(batch).unwrap();
        let mut worst = 0.0f64;
        for ((n, a), (_, b)) in losses(&m_cpu).into_iter().zip(losses(&m_dev)) {
            let rel = (a - b).abs() / a.abs().max(b.abs()).max(1.0);
            worst = worst.max(rel);
            assert!(rel <= LOSS_TOL, "{name}: {n} is {a} on the CPU, {b} on {} (relative {rel:.2e})", device_name());
        }
        for (i, (a, b)) in p_cpu.iter().zip(&p_dev).enumerate() {
            let rel = ((a - b).abs() / a.abs().max(b.abs()).max(1.0)) as f64;
            assert!(rel <= LOSS_TOL, "{name}: priority {i} is {a} on the CPU, {b} on the device");
        }
        let w_cpu = saved(&cpu, dir.join(format!("{name}-cpu-1")));
        let w_dev = saved(&gpu, dir.join(format!("{name}-dev-1")));
        let step = distance(&w_cpu, &w0);
        let off = distance(&w_dev, &w_cpu);
        assert!(step > 0.0, "{name}: the update did not change the weights");
        println!("{name}: worst relative loss difference {worst:.2e}; weights off by {:.2e} of the step", off / step);
        assert!(off <= STEP_TOL * step, "{name}: weights differ by {off:.3e}, the step is {step:.3e}");
    }
}

#[test]
fn a_paper_size_equi_actor_is_equivariant_on_the_device() {
    use equiarm_nn::diagnostics::{NetKind, check_checkpoint};
    let errors = check_checkpoint(NetKind::EquiActor, &equiarm_nn::nets::NetConfig::paper(), None, 1, 3, &device())
        .expect("build the paper-size actor on the device");
    assert_eq!(errors.len(), 8, "D4 has 8 elements");
    let worst = errors.iter().map(|e| e.relative_error).fold(0.0, f64::max);
    println!("paper-size Equi actor on {}: worst relative equivariance error {worst:.2e}", device_name());
    assert!(worst < 1e-4, "equivariance error {worst:.3e} on the device");
}

#[test]
fn a_short_run_on_the_device_resumes_on_the_cpu() {
    let mut c = common::tiny_run(2, 8);
    c.eval_every = 4;
    c.eval_episodes = 1;
    c.checkpoint_every = 4;
    let never = || false;
    let dir = scratch("run");
    let on_device = RunOptions { run_dir: dir.clone(), stop_at: Some(4), device: device(), ..Default::default() };
    let first = run(c.clone(), &on_device, &never).unwrap();
    assert_eq!(first.updates, 4);
    assert_eq!(first.evals.len(), 1, "an evaluation at update 4");
    let ck = find_checkpoint(&dir).unwrap();
    assert!(ck.ends_with("step_0000004"), "{}", ck.display());
    let resumed = run(c, &RunOptions { run_dir: dir.clone(), resume: Some(ck), ..Default::default() }, &never).unwrap();
    assert_eq!(resumed.updates, 8);
    assert_eq!(resumed.evals.iter().map(|e| e.updates).collect::<Vec<_>>(), vec![4, 8]);
    assert!(find_checkpoint(&dir).unwrap().ends_with("step_0000008"));
}

#[test]
fn device_names_open_or_fail_with_a_reason() {
    let name = device_name();
    let dev = device();
    let described = equiarm_nn::device::describe(&dev);
    println!("{name}: {described}");
    assert!(!described.is_empty());
    // No machine this runs on has eight discrete GPUs: an error naming the device, not a panic.
    let e = equiarm_nn::device::open("vulkan:7").unwrap_err();
    assert!(e.to_string().contains("vulkan:7") && e.to_string().contains("not usable"), "{e}");
    assert!(equiarm_nn::device::open("cuda").unwrap_err().to_string().contains("--device vulkan"));
}
