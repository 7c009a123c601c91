//! Parameter counts at the paper's settings equal docs/paper.md §1.7 and §4 exactly: the proof that
//! the function space matches e2cnn's (and the authors' CNNs). Networks are only built, not run.

mod common;

use common::device;
use equiarm_nn::burn::module::Module;
use equiarm_nn::init::Init;
use equiarm_nn::nets::*;
use equiarm_types::OBS_PLANES;

#[test]
fn equi_sac_counts() {
    let (dev, init, cfg) = (device(), Init::new(0), NetConfig::paper());
    let actor = EquiActor::new(&cfg, &init, &dev).unwrap();
    let per_layer: Vec<usize> = actor.enc.convs.iter().map(|c| c.num_params()).collect();
    assert_eq!(per_layer, [248, 6_160, 24_608, 98_368, 393_344, 393_280, 196_672]);
    assert_eq!(actor.head.num_params(), 712);
    assert_eq!(actor.num_params(), 1_113_392);
    assert_eq!(EquiCritic::new(&cfg, &init, &dev).unwrap().num_params(), 1_179_242);
}

#[test]
fn cnn_sac_counts() {
    let (dev, init, cfg) = (device(), Init::new(0), NetConfig::paper());
    assert_eq!(CnnActor::new(&cfg, &init, &dev).unwrap().num_params(), 1_133_130);
    assert_eq!(CnnCritic::new(&cfg, &init, &dev).unwrap().num_params(), 1_265_218);
}

#[test]
fn sen_fc2_counts() {
    let (dev, init, cfg) = (device(), Init::new(0), NetConfig::paper_sen());
    assert_eq!(SenActor::new(&cfg, &init, &dev).unwrap().num_params(), 1_220_712);
    assert_eq!(SenCritic::new(&cfg, &init, &dev).unwrap().num_params(), 1_237_250);
}

#[test]
fn rotation_estimation_counts() {
    let (dev, init, cfg) = (device(), Init::new(0), NetConfig::paper_rotation());
    assert_eq!(RotEquiNet::new(&cfg, &init, &dev).unwrap().num_params(), 1_113_344);
    assert_eq!(RotCnnNet::new(&cfg, &init, &dev).unwrap().num_params(), 1_279_480);
}

#[test]
fn invalid_configs_are_refused() {
    let (dev, init) = (device(), Init::new(0));
    let bad_size = NetConfig::new(8, 100, OBS_PLANES);
    let err = EquiActor::new(&bad_size, &init, &dev).unwrap_err().to_string();
    assert!(err.contains("input size 100"), "{err}");
    let bad_hidden = NetConfig::new(12, 128, OBS_PLANES);
    assert!(CnnActor::new(&bad_hidden, &init, &dev).is_err());
}

/// A smaller input keeps the paper encoder's layers from that resolution on (the authors'
/// `EquivariantEncoder64` rule): at 32 px the Equi encoder is layers 3–7 (n/2, n, 2n, n, n
/// regular D4 fields), the CNN encoder layers 3–7 (n, 2n, 2n, 4n, 4n channels), each from the
/// 5 input planes, and every map still ends at 1×1.
#[test]
fn smaller_inputs_drop_the_leading_layers() {
    let (dev, init) = (device(), Init::new(0));
    let cfg = NetConfig::new(8, 32, OBS_PLANES);
    let actor = EquiActor::new(&cfg, &init, &dev).unwrap();
    let widths: Vec<(usize, usize)> = actor.enc.convs.iter().map(|c| (c.in_channels(), c.out_channels())).collect();
    assert_eq!(widths, [(5, 32), (32, 64), (64, 128), (128, 64), (64, 64)]);
    let cnn = CnnActor::new(&cfg, &init, &dev).unwrap();
    assert_eq!(cnn.enc.convs.len(), 5);
    let x = equiarm_nn::burn::tensor::Tensor::<4>::zeros([2, 5, 32, 32], &dev);
    let (m, s) = actor.forward(x.clone());
    assert_eq!((m.dims(), s.dims()), ([2, 5], [2, 5]));
    let (m, _) = cnn.forward(x);
    assert_eq!(m.dims(), [2, 5]);
    for (size, layers) in [(8, 3), (16, 4), (64, 6), (128, 7)] {
        let c = NetConfig { input_size: size, ..cfg };
        assert_eq!(EquiActor::new(&c, &init, &dev).unwrap().enc.convs.len(), layers, "{size} px");
    }
}

#[test]
fn ferm_counts() {
    let (dev, init, cfg) = (device(), Init::new(0), NetConfig::paper());
    // docs/paper.md §1.7: the actor 1,794,912 (the paper's 1.79M), the critic 1,795,928 (derived;
    // the paper prints 1.90M, treated as an erratum there).
    let actor = FermActor::new(&cfg, &init, &dev).unwrap();
    assert_eq!(actor.enc.convs.num_params(), 392_896);
    assert_eq!(actor.enc.head.num_params(), 16_384 * 50 + 50 + 100);
    assert_eq!(actor.num_params(), 1_794_912);
    assert_eq!(FermCritic::new(&cfg, &init, &dev).unwrap().num_params(), 1_795_928);
}
