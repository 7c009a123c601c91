//! Weights round-trip through safetensors with readable names; a file of another architecture is
//! refused naming the first mismatching tensor; initialisation and training steps are
//! deterministic; gradients flow through the kernel expansion and equivariance survives Adam.

mod common;

use common::{device, randn, values};
use equiarm_nn::burn::module::Module;
use equiarm_nn::burn::optim::{AdamConfig, GradientsParams};
use equiarm_nn::checkpoint::{CheckpointError, load, load_bytes, parameter_shapes, save, to_bytes};
use equiarm_nn::diagnostics::equivariance_errors;
use equiarm_nn::init::Init;
use equiarm_nn::nets::{Actor, CnnActor, EquiActor, NetConfig};
use equiarm_types::OBS_PLANES;

fn cfg() -> NetConfig {
    NetConfig::new(8, 32, OBS_PLANES)
}

fn tmpfile(name: &str) -> std::path::PathBuf {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("checkpoint_and_training");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn parameter_names_are_readable_paths() {
    let actor = EquiActor::new(&cfg(), &Init::new(0), &device()).unwrap();
    let names: Vec<String> = parameter_shapes(&actor).into_iter().map(|(n, _)| n).collect();
    assert!(names.contains(&"enc.convs.0.weight.0".to_string()), "{names:?}");
    assert!(names.contains(&"enc.convs.0.bias.0".to_string()), "{names:?}");
    assert!(names.contains(&"head.weight.0".to_string()), "{names:?}");
}

#[test]
fn save_load_round_trip_is_exact() {
    let dev = device();
    let a = EquiActor::new(&cfg(), &Init::new(1), &dev).unwrap();
    let path = tmpfile("actor.safetensors");
    save(&a, &path).unwrap();
    let b = load(EquiActor::new(&cfg(), &Init::new(2), &dev).unwrap(), &path).unwrap();
    let obs = randn::<4>(1, "obs", [2, 5, 32, 32], &dev);
    let (ma, sa) = a.forward(obs.clone());
    let (mb, sb) = b.forward(obs);
    assert_eq!(values(ma), values(mb));
    assert_eq!(values(sa), values(sb));
}

/// Regression: burn's default safetensors metadata is a HashMap written in random order, so saves of
/// the same weights differed in their header bytes and two deterministic runs' checkpoints could not
/// be compared file by file.
#[test]
fn the_same_weights_always_give_the_same_bytes() {
    let a = EquiActor::new(&cfg(), &Init::new(1), &device()).unwrap();
    let first = to_bytes(&a).unwrap();
    for i in 0..8 {
        assert_eq!(to_bytes(&a).unwrap(), first, "to_bytes {i}");
        let path = tmpfile(&format!("same{i}.safetensors"));
        save(&a, &path).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), first, "file {i}");
    }
}

#[test]
fn loading_another_architecture_names_the_first_mismatch() {
    let dev = device();
    let path = tmpfile("cnn.safetensors");
    save(&CnnActor::new(&cfg(), &Init::new(1), &dev).unwrap(), &path).unwrap();
    let err = load(EquiActor::new(&cfg(), &Init::new(1), &dev).unwrap(), &path).unwrap_err();
    assert!(matches!(&err, CheckpointError::Missing { name, .. } if name == "enc.convs.0.weight.0"), "{err}");
    assert!(err.to_string().contains("enc.convs.0.weight.0"), "{err}");

    // same architecture, other hidden size: a shape mismatch on the first layer
    let path = tmpfile("equi16.safetensors");
    let wide = NetConfig { hidden: 16, ..cfg() };
    save(&EquiActor::new(&wide, &Init::new(1), &dev).unwrap(), &path).unwrap();
    let err = load(EquiActor::new(&cfg(), &Init::new(1), &dev).unwrap(), &path).unwrap_err();
    assert!(matches!(&err, CheckpointError::Shape { name, .. } if name == "enc.convs.0.weight.0"), "{err}");

    // a missing file is an error, not a panic
    assert!(load(EquiActor::new(&cfg(), &Init::new(1), &dev).unwrap(), &tmpfile("nope.safetensors")).is_err());
}

/// Regression (issue 28): a policy node loaded weights full of NaN and then commanded NaN.
#[test]
fn weights_holding_nan_or_infinity_are_refused_naming_the_tensor() {
    let dev = device();
    let bytes = to_bytes(&EquiActor::new(&cfg(), &Init::new(1), &dev).unwrap()).unwrap();
    // safetensors: an 8-byte little-endian header length, the JSON header, then the data; put a
    // bad value into the 3rd element of `head.weight.0`.
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = std::str::from_utf8(&bytes[8..8 + n]).unwrap();
    let entry = &header[header.find("\"head.weight.0\"").expect("head.weight.0 in the header")..];
    let offsets = &entry[entry.find("\"data_offsets\":[").unwrap() + 16..];
    let start: usize = offsets[..offsets.find(',').unwrap()].trim().parse().unwrap();
    for bad in [f32::NAN, f32::INFINITY] {
        let mut b = bytes.clone();
        let at = 8 + n + start + 2 * 4;
        b[at..at + 4].copy_from_slice(&bad.to_le_bytes());
        let fresh = EquiActor::new(&cfg(), &Init::new(2), &dev).unwrap();
        let err = load_bytes(fresh, b, "PolicyWeights version 3").unwrap_err();
        assert!(matches!(&err, CheckpointError::NonFinite { name, index: 2, .. } if name == "head.weight.0"), "{err}");
        assert!(err.to_string().contains("PolicyWeights version 3") && err.to_string().contains("head.weight.0"));
    }
    // the untouched bytes still load
    assert!(load_bytes(EquiActor::new(&cfg(), &Init::new(2), &dev).unwrap(), bytes, "ok").is_ok());
}

#[test]
fn same_seed_gives_identical_weights_and_outputs() {
    let dev = device();
    let a = EquiActor::new(&cfg(), &Init::new(7), &dev).unwrap();
    let b = EquiActor::new(&cfg(), &Init::new(7), &dev).unwrap();
    let c = EquiActor::new(&cfg(), &Init::new(8), &dev).unwrap();
    let obs = randn::<4>(7, "obs", [1, 5, 32, 32], &dev);
    let (ma, _) = a.forward(obs.clone());
    let (mb, _) = b.forward(obs.clone());
    let (mc, _) = c.forward(obs);
    assert_eq!(values(ma.clone()), values(mb));
    assert_ne!(values(ma), values(mc));
}

/// Adam steps (at SAC's learning rate, 1e-3) through the kernel expansion: the loss decreases, the runs are bitwise repeatable,
/// and the trained network is still equivariant.
#[test]
fn adam_steps_are_deterministic_and_keep_equivariance() {
    let run = || {
        let dev = device().autodiff();
        let mut actor = EquiActor::new(&cfg(), &Init::new(3), &dev).unwrap();
        let mut optim = AdamConfig::new().init();
        let obs = randn::<4>(3, "obs", [4, 5, 32, 32], &dev);
        let target = randn::<2>(3, "target", [4, 5], &dev);
        let mut losses = Vec::new();
        for _ in 0..3 {
            let (mean, _) = actor.forward(obs.clone());
            let loss = (mean - target.clone()).powf_scalar(2.0).mean();
            losses.push(values(loss.clone())[0]);
            let grads = GradientsParams::from_grads(loss.backward(), &actor);
            actor = optim.step(1e-3, actor, grads);
        }
        (losses, actor)
    };
    let (l1, actor) = run();
    let (l2, _) = run();
    assert_eq!(l1, l2, "training is bitwise repeatable");
    assert!(l1[2] < l1[0], "loss decreases: {l1:?}");
    let actor = actor.valid();
    let dev = device();
    for e in equivariance_errors(&actor, vec![randn::<4>(4, "obs", [1, 5, 32, 32], &dev)]) {
        assert!(e.relative_error < 1e-4, "{:?}: {}", e.element, e.relative_error);
    }
    // and the cached-kernel inference copy agrees with the plain one
    let obs = randn::<4>(5, "obs", [1, 5, 32, 32], &dev);
    let (m1, _) = actor.forward(obs.clone());
    let cached = actor.cache_kernels();
    let (m2, _) = cached.forward(obs);
    let (v1, v2) = (values(m1), values(m2));
    assert!(v1.iter().zip(&v2).all(|(a, b)| (a - b).abs() <= 1e-5 * (1.0 + a.abs())), "{v1:?} {v2:?}");
}
