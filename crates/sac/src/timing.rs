//! How long one SAC update and one greedy action take on a device: the update benchmark
//! (`benches/update.rs`) and `equiarm device-check` both measure with this, so their figures
//! mean the same thing.
//!
//! An update is timed from handing the batch over to having its metrics and priorities back on
//! the host, which waits for the device to finish. The first `warmup` updates are not timed (on a
//! GPU they compile the kernels). Peak device memory is the largest `bytes_reserved` the device's
//! allocator reported after any update (`None` on the CPU, whose backend does not report it).

use std::time::Instant;

use equiarm_nn::burn::tensor::Device;

use crate::agent::{ActMode, Agent, AgentConfig, AgentError, Batch};
use equiarm_types::{ACTION_DIM, OBS_PLANES};

/// A batch of `b` rows of random `s`×`s` observations (normal pixels, tanh actions, a reward every
/// 7th row, an expert every 3rd), from `seed`: the input of a timed update, whose values do not
/// matter for its time.
pub fn random_batch(b: usize, s: usize, seed: u64) -> Batch {
    let mut rng = crate::rng::stream(seed, 1);
    let obs = crate::rng::normals(&mut rng, b * OBS_PLANES * s * s);
    let next_obs = crate::rng::normals(&mut rng, b * OBS_PLANES * s * s);
    let action = crate::rng::normals(&mut rng, b * ACTION_DIM).iter().map(|x| x.tanh()).collect();
    Batch {
        rows: b,
        size: s,
        obs_copies: 1,
        next_copies: 1,
        obs,
        next_obs,
        action,
        reward: (0..b).map(|i| (i % 7 == 0) as u8 as f32).collect(),
        mask: (0..b).map(|i| (i % 7 != 0) as u8 as f32).collect(),
        expert: (0..b).map(|i| (i % 3 == 0) as u8 as f32).collect(),
        weight: vec![1.0; b],
        curl: None,
    }
}

/// The median of `v` (the upper one of an even count); NaN when empty.
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

/// What [`time_update`] measured.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdateTiming {
    /// Seconds of each timed update, in order.
    pub updates_s: Vec<f64>,
    /// Seconds of each batch-1 greedy action, in order.
    pub acts_s: Vec<f64>,
    /// The largest `bytes_reserved` of the device's allocator after an update, if it reports one.
    pub peak_device_bytes: Option<u64>,
}

impl UpdateTiming {
    /// Median seconds per update.
    pub fn update_median(&self) -> f64 {
        median(self.updates_s.clone())
    }

    /// Median seconds per batch-1 greedy action.
    pub fn act_median(&self) -> f64 {
        median(self.acts_s.clone())
    }
}

/// Builds an agent for `cfg` on `device` (seed 0), runs `warmup` untimed then `reps` timed updates
/// on copies of `batch`, then `act_reps` timed batch-1 greedy actions on the batch's first
/// observation. `on_update(i)` is called after each update (warm-up ones included), e.g. to count
/// FLOPs or print progress.
pub fn time_update(
    cfg: &AgentConfig,
    batch: &Batch,
    device: &Device,
    warmup: usize,
    reps: usize,
    act_reps: usize,
    mut on_update: impl FnMut(usize),
) -> Result<UpdateTiming, AgentError> {
    let mut agent = Agent::new_on(cfg.clone(), 0, device)?;
    let mut updates_s = Vec::with_capacity(reps);
    let mut peak: Option<u64> = None;
    for i in 0..warmup + reps {
        let copy = batch.clone();
        let t = Instant::now();
        agent.update(copy)?;
        let dt = t.elapsed().as_secs_f64();
        if i >= warmup {
            updates_s.push(dt);
        }
        if let Some(usage) = device.memory_pool_usage() {
            peak = Some(peak.unwrap_or(0).max(usage.bytes_reserved));
        }
        on_update(i);
    }
    let one = &batch.obs[..OBS_PLANES * batch.size * batch.size];
    let mut acts_s = Vec::with_capacity(act_reps);
    for _ in 0..act_reps {
        let t = Instant::now();
        agent.act(one, 1, ActMode::Greedy, None)?;
        acts_s.push(t.elapsed().as_secs_f64());
    }
    Ok(UpdateTiming { updates_s, acts_s, peak_device_bytes: peak })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::agent::ModelKind;

    #[test]
    fn median_of_odd_even_and_empty() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 3.0);
        assert!(median(vec![]).is_nan());
    }

    #[test]
    fn a_timed_update_counts_warmups_apart() {
        let cfg = AgentConfig { model: ModelKind::Cnn, hidden: 8, input_size: 16, ..AgentConfig::default() };
        let batch = random_batch(4, 16, 1);
        let mut calls = Vec::new();
        let t = time_update(&cfg, &batch, &equiarm_nn::device::cpu(), 2, 3, 4, |i| calls.push(i)).unwrap();
        assert_eq!(calls, vec![0, 1, 2, 3, 4]);
        assert_eq!(t.updates_s.len(), 3);
        assert_eq!(t.acts_s.len(), 4);
        assert!(t.update_median() > 0.0 && t.act_median() > 0.0);
        assert_eq!(batch.obs.len(), 4 * 5 * 16 * 16);
    }
}
