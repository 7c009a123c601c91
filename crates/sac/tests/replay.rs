//! Behaviour of the prioritised expert replay (docs/paper.md §2) through its public API: sampling
//! frequencies (χ² goodness of fit), priority arithmetic, expert retention, importance weights, frame
//! sharing, and checkpoint round trips and failures.

use std::path::PathBuf;
use std::sync::Arc;

use equiarm_sac::frame::StoredFrame;
use equiarm_sac::replay::{Replay, ReplayConfig, ReplayError, Stored};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// χ² critical value at 99.9 % for 7 degrees of freedom.
const CHI2_999_DF7: f64 = 24.322;

fn frame(size: usize, seed: u64) -> Arc<StoredFrame> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Smooth content with a little noise, like a render: compresses, but not to nothing.
    let color = (0..size * size * 3).map(|i| ((i / 3) % size) as u8 / 4 + rng.random_range(0..3u8)).collect();
    let depth: Vec<f32> =
        (0..size * size).map(|i| 0.5 + (i / size) as f32 * 0.01 + rng.random_range(0.0..0.001)).collect();
    Arc::new(StoredFrame::new(size, color, &depth, seed.is_multiple_of(2)).unwrap())
}

fn stored(obs: &Arc<StoredFrame>, next_obs: &Arc<StoredFrame>, reward: f32, expert: bool) -> Stored {
    Stored {
        obs: obs.clone(),
        next_obs: next_obs.clone(),
        action: [reward / 100.0, -0.5, 0.25, 1.0, -1.0],
        reward,
        done: reward as i64 % 5 == 0,
        expert,
    }
}

fn replay(capacity: usize) -> Replay {
    Replay::new(ReplayConfig { capacity, ..ReplayConfig::default() }).unwrap()
}

fn tmp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("equiarm_sac_{name}_{}.rpl", std::process::id()))
}

fn chi2(counts: &[u64], probs: &[f64]) -> f64 {
    let n: u64 = counts.iter().sum();
    counts.iter().zip(probs).map(|(&c, &p)| (c as f64 - n as f64 * p).powi(2) / (n as f64 * p)).sum()
}

#[test]
fn per_sampling_frequencies_fit_p_to_the_alpha() {
    let mut r = replay(8);
    let f = frame(4, 0);
    for i in 0..8 {
        r.push(stored(&f, &f, i as f32, false)).unwrap();
    }
    let td = [0.1f32, 0.5, 1.0, 2.0, 3.0, 5.0, 8.0, 13.0];
    r.update_priorities(&[0, 1, 2, 3, 4, 5, 6, 7], &td).unwrap();
    let q: Vec<f64> = (0..8).map(|i| r.priority(i).powf(0.6)).collect();
    let total: f64 = q.iter().sum();
    let probs: Vec<f64> = q.iter().map(|x| x / total).collect();
    let uniform = vec![1.0 / 8.0; 8];

    let mut rng = ChaCha8Rng::seed_from_u64(42);
    // Independent draws (batch 1) and the stratified scheme (batch 128); the latter has less variance
    // than multinomial sampling, so the same critical value is conservative for it.
    for batch in [1usize, 128] {
        let mut counts = [0u64; 8];
        let mut drawn = 0;
        while drawn < 200_000 {
            let s = r.sample(batch, 0.4, &mut rng).unwrap();
            assert_eq!(s.slots.len(), batch);
            for &i in &s.slots {
                counts[i] += 1;
            }
            drawn += batch;
        }
        let fit = chi2(&counts, &probs);
        assert!(fit < CHI2_999_DF7, "batch {batch}: χ² {fit} against p^α/Σp^α; counts {counts:?}");
        let wrong = chi2(&counts, &uniform);
        assert!(wrong > CHI2_999_DF7, "batch {batch}: uniform not rejected, χ² {wrong}");
        // p without the ^α is wrong too.
        let raw: Vec<f64> = (0..8).map(|i| r.priority(i)).collect();
        let raw_total: f64 = raw.iter().sum();
        let raw: Vec<f64> = raw.iter().map(|x| x / raw_total).collect();
        assert!(chi2(&counts, &raw) > CHI2_999_DF7, "batch {batch}: p (no alpha) not rejected");
    }
}

#[test]
fn priority_updates_follow_the_formula_and_the_tree_sums() {
    let mut r = replay(64);
    let f = frame(4, 0);
    for i in 0..50 {
        let slot = r.push(stored(&f, &f, i as f32, i % 7 == 0)).unwrap();
        assert_eq!(r.priority(slot), 1.0, "new transitions get the initial max priority 1.0");
    }
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let mut max_seen = 1.0f64;
    for _ in 0..200 {
        let slots: Vec<usize> = (0..16).map(|_| rng.random_range(0..50)).collect();
        let td: Vec<f32> = (0..16).map(|_| rng.random_range(-3.0f32..3.0)).collect();
        r.update_priorities(&slots, &td).unwrap();
        // A repeated slot takes its last value.
        for (k, (&s, &t)) in slots.iter().zip(&td).enumerate() {
            let expert = if s % 7 == 0 { 1.0 } else { 0.0 };
            let p = f64::from(t.abs()) + expert + 1e-6;
            max_seen = max_seen.max(p);
            if !slots[k + 1..].contains(&s) {
                assert_eq!(r.priority(s), p, "slot {s}");
            }
        }
        let brute: f64 = (0..50).map(|i| r.priority(i).powf(0.6)).sum();
        assert!((r.total_mass() - brute).abs() <= 1e-12 * brute, "tree {} vs brute force {brute}", r.total_mass());
    }
    assert_eq!(r.max_priority(), max_seen);
    let slot = r.push(stored(&f, &f, 99.0, false)).unwrap();
    assert_eq!(r.priority(slot), max_seen, "a new transition gets the max priority");
    let brute: f64 = (0..51).map(|i| r.priority(i).powf(0.6)).sum();
    assert!((r.total_mass() - brute).abs() <= 1e-12 * brute);
    // An expert with zero TD still has priority 1 + 1e-6.
    r.update_priorities(&[7], &[0.0]).unwrap();
    assert_eq!(r.priority(7), 1.0 + 1e-6);
}

#[test]
fn update_errors_change_nothing() {
    let mut r = replay(8);
    let f = frame(4, 0);
    for i in 0..4 {
        r.push(stored(&f, &f, i as f32, false)).unwrap();
    }
    let before: Vec<f64> = (0..4).map(|i| r.priority(i)).collect();
    let mass = r.total_mass();
    match r.update_priorities(&[0, 2], &[0.5, f32::NAN]) {
        Err(ReplayError::BadTd { slot: 2, .. }) => {}
        other => panic!("expected BadTd for slot 2, got {other:?}"),
    }
    assert!(matches!(r.update_priorities(&[1, 4], &[0.5, 0.5]), Err(ReplayError::SlotOutOfRange { slot: 4, len: 4 })));
    assert!(matches!(r.update_priorities(&[1], &[0.5, 0.5]), Err(ReplayError::LengthMismatch { slots: 1, td: 2 })));
    assert!(matches!(r.update_priorities(&[1], &[f32::INFINITY]), Err(ReplayError::BadTd { slot: 1, .. })));
    let after: Vec<f64> = (0..4).map(|i| r.priority(i)).collect();
    assert_eq!(before, after);
    assert_eq!(mass, r.total_mass());
    assert_eq!(r.max_priority(), 1.0);
}

#[test]
fn push_rejects_non_finite_values() {
    let mut r = replay(8);
    let f = frame(4, 0);
    let mut t = stored(&f, &f, f32::NAN, false);
    assert!(matches!(r.push(t.clone()), Err(ReplayError::NonFinite { ref what, .. }) if what == "reward"));
    t.reward = 1.0;
    t.action[0] = 0.0; // the helper derived it from the NaN reward
    t.action[3] = f32::INFINITY;
    assert!(matches!(r.push(t), Err(ReplayError::NonFinite { ref what, .. }) if what == "action[3]"));
    assert!(r.is_empty());
}

#[test]
fn expert_transitions_are_never_evicted() {
    let mut r = replay(10);
    let f = frame(4, 0);
    let mut step = 0;
    let mut push = |r: &mut Replay, n: usize, expert: bool| {
        for _ in 0..n {
            r.push(stored(&f, &f, step as f32, expert)).unwrap();
            step += 1;
        }
    };
    push(&mut r, 2, false); // steps 0, 1
    push(&mut r, 3, true); // steps 2, 3, 4
    push(&mut r, 25, false); // steps 5..30
    push(&mut r, 1, true); // step 30
    push(&mut r, 10, false); // steps 31..41
    assert_eq!(r.len(), 10);
    assert_eq!(r.expert_len(), 4);
    let mut experts: Vec<f32> = (0..10).map(|i| r.get(i).unwrap()).filter(|t| t.expert).map(|t| t.reward).collect();
    let mut agents: Vec<f32> = (0..10).map(|i| r.get(i).unwrap()).filter(|t| !t.expert).map(|t| t.reward).collect();
    experts.sort_by(f32::total_cmp);
    agents.sort_by(f32::total_cmp);
    assert_eq!(experts, vec![2.0, 3.0, 4.0, 30.0]);
    assert_eq!(agents, vec![35.0, 36.0, 37.0, 38.0, 39.0, 40.0], "the non-expert slots hold the newest");
}

#[test]
fn a_buffer_full_of_experts_refuses_pushes_without_losing_anything() {
    let mut r = replay(3);
    let f = frame(4, 0);
    r.push(stored(&f, &f, 0.0, false)).unwrap();
    r.push(stored(&f, &f, 1.0, true)).unwrap();
    r.push(stored(&f, &f, 2.0, true)).unwrap();
    assert_eq!(r.push(stored(&f, &f, 3.0, true)).unwrap(), 0, "the only agent slot is overwritten");
    for expert in [true, false] {
        match r.push(stored(&f, &f, 4.0, expert)) {
            Err(ReplayError::AllExpert { capacity: 3 }) => {}
            other => panic!("expected AllExpert, got {other:?}"),
        }
    }
    let rewards: Vec<f32> = (0..3).map(|i| r.get(i).unwrap().reward).collect();
    assert_eq!(rewards, vec![3.0, 1.0, 2.0]);
    assert_eq!(r.expert_len(), 3);
}

#[test]
fn importance_weights_match_a_hand_computation() {
    // p = td + eps = 1, 4, 9, 16 exactly; with α = 0.5, p^α = 1, 2, 3, 4.
    let cfg = ReplayConfig { capacity: 4, alpha: 0.5, priority_eps: 0.5, ..ReplayConfig::default() };
    let mut r = Replay::new(cfg).unwrap();
    let f = frame(4, 0);
    for i in 0..4 {
        r.push(stored(&f, &f, i as f32, false)).unwrap();
    }
    r.update_priorities(&[0, 1, 2, 3], &[0.5, 3.5, 8.5, 15.5]).unwrap();
    assert_eq!((0..4).map(|i| r.priority(i)).collect::<Vec<_>>(), vec![1.0, 4.0, 9.0, 16.0]);
    // w_i = (N P_i)^-β / (N P_min)^-β = (q_i / q_min)^-β with q = p^α.
    let expected = [
        (0.5, [1.0, 1.0 / 2f64.sqrt(), 1.0 / 3f64.sqrt(), 0.5]),
        (1.0, [1.0, 0.5, 1.0 / 3.0, 0.25]),
        (0.0, [1.0, 1.0, 1.0, 1.0]),
    ];
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    for (beta, w) in expected {
        let s = r.sample(64, beta, &mut rng).unwrap();
        let mut seen = [false; 4];
        for (&slot, &weight) in s.slots.iter().zip(&s.weights) {
            seen[slot] = true;
            assert!((f64::from(weight) - w[slot]).abs() < 1e-6, "β {beta} slot {slot}: {weight} vs {}", w[slot]);
        }
        assert!(seen.iter().all(|&x| x), "64 stratified draws over mass 10 reach every slot");
    }
    // The normalisation uses the smallest priority even when slot 0 is not drawn.
    r.update_priorities(&[3], &[99.5]).unwrap(); // p = 100, q = 10; slot 3 takes most of the mass
    let s = r.sample(1, 1.0, &mut ChaCha8Rng::seed_from_u64(1)).unwrap();
    let q = [1.0, 2.0, 3.0, 10.0];
    assert!((f64::from(s.weights[0]) - 1.0 / q[s.slots[0]]).abs() < 1e-6);
}

#[test]
fn sample_errors() {
    let r = replay(4);
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    assert!(matches!(r.sample(8, 0.4, &mut rng), Err(ReplayError::Empty)));
    let mut r = r;
    let f = frame(4, 0);
    r.push(stored(&f, &f, 0.0, false)).unwrap();
    assert!(matches!(r.sample(8, 1.5, &mut rng), Err(ReplayError::BadBeta { .. })));
    assert!(matches!(r.sample(8, f64::NAN, &mut rng), Err(ReplayError::BadBeta { .. })));
    assert!(r.sample(0, 0.4, &mut rng).unwrap().slots.is_empty());
    assert_eq!(r.sample(5, 0.4, &mut rng).unwrap().slots, vec![0; 5]);
}

#[test]
fn config_defaults_validation_and_unknown_keys() {
    let d = ReplayConfig::default();
    assert_eq!(
        (d.capacity, d.alpha, d.beta_start, d.beta_end, d.priority_eps, d.expert_bonus),
        (100_000, 0.6, 0.4, 1.0, 1e-6, 1.0)
    );
    d.validate().unwrap();
    let partial: ReplayConfig = serde_json::from_str(r#"{"capacity": 10}"#).unwrap();
    assert_eq!(partial, ReplayConfig { capacity: 10, ..d.clone() });
    let e = serde_json::from_str::<ReplayConfig>(r#"{"capacty": 10}"#).unwrap_err();
    assert!(e.to_string().contains("capacty"), "{e}");
    for (cfg, field) in [
        (ReplayConfig { capacity: 0, ..d.clone() }, "capacity"),
        (ReplayConfig { alpha: -0.1, ..d.clone() }, "alpha"),
        (ReplayConfig { beta_start: 1.1, ..d.clone() }, "beta_start"),
        (ReplayConfig { beta_end: -0.1, ..d.clone() }, "beta_end"),
        (ReplayConfig { priority_eps: 0.0, ..d.clone() }, "priority_eps"),
        (ReplayConfig { expert_bonus: f64::NAN, ..d.clone() }, "expert_bonus"),
    ] {
        match Replay::new(cfg) {
            Err(ReplayError::Config { field: f, .. }) => assert_eq!(f, field),
            other => panic!("{field}: expected a config error, got {other:?}"),
        }
    }
    assert_eq!(d.beta(0.0), 0.4);
    assert_eq!(d.beta(2.0), 1.0);
    assert!((d.beta(0.5) - 0.7).abs() < 1e-12);
    assert_eq!(d.beta_schedule(5000).value(5000), 1.0);
}

#[test]
fn shared_frames_are_stored_and_counted_once() {
    let mut r = replay(2);
    let (f0, f1, f2) = (frame(8, 0), frame(8, 1), frame(8, 2));
    r.push(stored(&f0, &f1, 0.0, false)).unwrap();
    r.push(stored(&f1, &f2, 1.0, false)).unwrap();
    assert_eq!(r.unique_frames(), 3);
    assert_eq!(r.unique_frame_bytes(), 3 * f0.heap_bytes());
    assert_eq!(Arc::strong_count(&f1), 3);
    // Overwriting transition 0 frees f0 (only the test's handle is left).
    let f3 = frame(8, 3);
    r.push(stored(&f2, &f3, 2.0, false)).unwrap();
    assert_eq!(Arc::strong_count(&f0), 1);
    assert_eq!(r.unique_frames(), 3);
}

/// A buffer with a chain of shared frames, experts, wrapped ring and updated priorities.
fn busy_replay() -> Replay {
    let mut r = replay(16);
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut prev = frame(24, 100);
    for i in 0..40u64 {
        let next = frame(24, 200 + i);
        r.push(stored(&prev, &next, i as f32, i < 4 || i == 20)).unwrap();
        prev = next;
        let slots: Vec<usize> = (0..4).map(|_| rng.random_range(0..r.len())).collect();
        let td: Vec<f32> = (0..4).map(|_| rng.random_range(0.0f32..4.0)).collect();
        r.update_priorities(&slots, &td).unwrap();
    }
    r
}

#[test]
fn save_and_load_round_trip_exactly_and_keep_sharing() {
    let r = busy_replay();
    let path = tmp("roundtrip");
    let bytes = r.save(&path).unwrap();
    assert_eq!(bytes, std::fs::metadata(&path).unwrap().len());
    let mut tmp_name = path.as_os_str().to_owned();
    tmp_name.push(".tmp");
    assert!(!PathBuf::from(tmp_name).exists(), "the temporary file is renamed away");
    let l = Replay::load(&path).unwrap();
    std::fs::remove_file(&path).unwrap();

    assert_eq!(l.config(), r.config());
    assert_eq!((l.len(), l.expert_len(), l.ring_pointer()), (r.len(), r.expert_len(), r.ring_pointer()));
    assert_eq!(l.max_priority().to_bits(), r.max_priority().to_bits());
    assert_eq!(l.total_mass().to_bits(), r.total_mass().to_bits());
    for i in 0..r.len() {
        assert_eq!(l.priority(i).to_bits(), r.priority(i).to_bits(), "priority of slot {i}");
        let (a, b) = (r.get(i).unwrap(), l.get(i).unwrap());
        assert_eq!((a.action, a.reward, a.done, a.expert), (b.action, b.reward, b.done, b.expert));
        assert_eq!(*a.obs, *b.obs);
        assert_eq!(*a.next_obs, *b.next_obs);
        for j in 0..r.len() {
            let (c, d) = (r.get(j).unwrap(), l.get(j).unwrap());
            assert_eq!(Arc::ptr_eq(&a.next_obs, &c.obs), Arc::ptr_eq(&b.next_obs, &d.obs), "sharing {i}→{j}");
        }
    }
    assert_eq!(l.unique_frames(), r.unique_frames());
    assert_eq!(l.unique_frame_bytes(), r.unique_frame_bytes());
    assert!(r.unique_frames() < 2 * r.len(), "the chain shares frames");

    let (mut ra, mut rb) = (ChaCha8Rng::seed_from_u64(11), ChaCha8Rng::seed_from_u64(11));
    for beta in [0.4, 0.7, 1.0] {
        assert_eq!(r.sample(32, beta, &mut ra).unwrap(), l.sample(32, beta, &mut rb).unwrap());
    }
    let (mut r, mut l) = (r, l);
    let f = frame(24, 999);
    assert_eq!(r.push(stored(&f, &f, 1.0, false)).unwrap(), l.push(stored(&f, &f, 1.0, false)).unwrap());
}

#[test]
fn load_errors_name_the_file_and_the_problem() {
    let r = busy_replay();
    let path = tmp("corrupt_src");
    r.save(&path).unwrap();
    let good = std::fs::read(&path).unwrap();
    std::fs::remove_file(&path).unwrap();
    let name = |p: &PathBuf| p.file_name().unwrap().to_string_lossy().into_owned();

    let check = |label: &str, bytes: &[u8], want: &str| {
        let p = tmp(label);
        std::fs::write(&p, bytes).unwrap();
        let e = Replay::load(&p).expect_err(label).to_string();
        if std::env::var_os("SHOW_ERRORS").is_some() {
            eprintln!("{label}: {e}");
        }
        std::fs::remove_file(&p).unwrap();
        assert!(e.contains(&name(&p)), "{label}: error does not name the file: {e}");
        assert!(e.to_lowercase().contains(want), "{label}: expected {want:?} in: {e}");
    };
    check("truncated_half", &good[..good.len() / 2], "truncated");
    check("truncated_end", &good[..good.len() - 3], "");
    check("truncated_header", &good[..6], "truncated");
    check("empty", &[], "truncated");
    let mut magic = good.clone();
    magic[0] = b'X';
    check("magic", &magic, "not a replay checkpoint");
    let mut version = good.clone();
    version[8] = 99;
    check("version", &version, "version 99");
    for at in [good.len() / 3, good.len() / 2, good.len() - 8] {
        let mut flipped = good.clone();
        flipped[at] ^= 0x5a;
        check(&format!("flipped_{at}"), &flipped, "");
    }
    let mut extra = good.clone();
    extra.extend_from_slice(b"garbage!");
    check("trailing", &extra, "");

    // Well-compressed bodies that declare absurd lengths are refused before allocating.
    let body = |content: &[u8]| {
        let mut f = good[..12].to_vec();
        f.extend(zstd::encode_all(content, 1).unwrap());
        f
    };
    check("huge_config", &body(&u32::MAX.to_le_bytes()), "config length");
    let json = serde_json::to_vec(&ReplayConfig { capacity: 4, ..ReplayConfig::default() }).unwrap();
    let mut b = (json.len() as u32).to_le_bytes().to_vec();
    b.extend(&json);
    let mut huge_len = b.clone();
    huge_len.extend(u64::MAX.to_le_bytes());
    check("huge_len", &body(&huge_len), "transition count");
    let mut huge_frames = b.clone();
    for v in [2u64, 2, 0] {
        huge_frames.extend(v.to_le_bytes()); // 2 transitions, ring pointer 2, no experts: all valid
    }
    huge_frames.extend(1.0f64.to_le_bytes());
    huge_frames.extend(1_000_000u64.to_le_bytes());
    check("huge_frames", &body(&huge_frames), "frame count");

    let missing = tmp("missing");
    let e = Replay::load(&missing).unwrap_err();
    assert!(matches!(e, ReplayError::Io { .. }), "{e}");
    assert!(e.to_string().contains(&name(&missing)));
}
