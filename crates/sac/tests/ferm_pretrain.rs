//! FERM's schedule (docs/paper.md §1.10): the contrastive pre-training runs once, before the first
//! SAC update, for `curl_pretrain_steps` steps; then one contrastive step per update; a checkpoint
//! remembers that it was done; and the config refuses FERM with shared crops.

use std::sync::Arc;

use equiarm_sac::agent::ModelKind;
use equiarm_sac::config::{Augmentation, TrainConfig};
use equiarm_sac::frame::StoredFrame;
use equiarm_sac::learner::Learner;
use equiarm_sac::replay::Stored;

fn cfg() -> TrainConfig {
    let mut c = TrainConfig::reduced(equiarm_types::TaskKind::BlockPulling);
    c.agent.model = ModelKind::Ferm;
    c.augmentation = Augmentation::Drq { k: 1, m: 1 };
    c.agent.hidden = 8;
    c.agent.input_size = 8;
    c.agent.curl_pretrain_steps = 7;
    c.image_size = 10;
    c.batch_size = 4;
    c.training_starts = 1;
    c
}

fn frame(v: u8) -> Arc<StoredFrame> {
    let n = 10 * 10;
    let color: Vec<u8> = (0..3 * n).map(|i| (i as u8).wrapping_mul(7).wrapping_add(v)).collect();
    let depth: Vec<f32> = (0..n).map(|i| 0.5 + (i % 10) as f32 * 0.01 + v as f32 * 1e-3).collect();
    Arc::new(StoredFrame::new(10, color, &depth, false).unwrap())
}

fn fill(l: &mut Learner) {
    for i in 0..8u8 {
        l.push(Stored {
            obs: frame(i),
            next_obs: frame(i + 1),
            action: [0.1, -0.2, 0.3, 0.0, 0.5],
            reward: (i % 2) as f32,
            done: i == 7,
            expert: i < 3,
        })
        .unwrap();
    }
}

#[test]
fn pretraining_runs_once_before_the_first_update_and_survives_a_checkpoint() {
    let mut l = Learner::new(cfg()).unwrap();
    fill(&mut l);
    assert!(l.agent().needs_curl_pretraining());
    assert_eq!(l.agent().curl_steps(), 0);
    let first = l.update().unwrap();
    assert_eq!(l.agent().curl_steps(), 7 + 1, "7 pre-training steps, then the update's own");
    assert!(!l.agent().needs_curl_pretraining());
    let second = l.update().unwrap();
    assert_eq!(l.agent().curl_steps(), 9);

    // The contrastive losses reach the metrics: the pre-training's once, the update's own each time.
    let names = |m: &equiarm_sac::agent::Metrics| m.named().into_iter().map(|(n, _)| n).collect::<Vec<_>>();
    assert!(first.curl_pretrain_loss.is_some_and(|v| v.is_finite() && v > 0.0), "{first:?}");
    assert!(first.curl_loss.is_some_and(|v| v.is_finite() && v > 0.0), "{first:?}");
    assert!(names(&first).contains(&"losses/curl_pretrain_loss"));
    assert_eq!(second.curl_pretrain_loss, None);
    assert!(second.curl_loss.is_some());
    assert!(names(&second).contains(&"losses/curl_loss"));
    assert!(!names(&second).contains(&"losses/curl_pretrain_loss"));

    let dir = tempfile::tempdir().unwrap();
    l.save(dir.path()).unwrap();
    let mut resumed = Learner::new(cfg()).unwrap();
    resumed.resume(dir.path()).unwrap();
    assert!(!resumed.agent().needs_curl_pretraining());
    let after = resumed.update().unwrap();
    assert_eq!(resumed.agent().curl_steps(), 10, "no second pre-training after a resume");
    assert_eq!(after.curl_pretrain_loss, None);
}

#[test]
fn other_models_log_no_contrastive_loss() {
    let mut c = cfg();
    c.agent.model = ModelKind::Cnn;
    let mut l = Learner::new(c).unwrap();
    fill(&mut l);
    let m = l.update().unwrap();
    assert_eq!((m.curl_loss, m.curl_pretrain_loss), (None, None));
    assert!(m.named().iter().all(|(n, _)| !n.contains("curl")), "{:?}", m.named());
}

#[test]
fn ferm_needs_independent_crops() {
    let mut c = cfg();
    c.augmentation = Augmentation::Rad;
    let e = c.validate().unwrap_err();
    assert_eq!(e.field, "augmentation");
    assert!(e.message.contains("FERM"), "{}", e.message);
}
