//! Parameter counts at the paper's settings equal PAPER_SPEC §1.7 and §4 exactly: the proof that
//! the function space matches e2cnn's (and the authors' CNNs). Networks are only built, not run.

mod common;

use common::device;
use equiarm_nn::burn::module::Module;
use equiarm_nn::init::Init;
use equiarm_nn::nets::*;

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
    let bad_size = NetConfig { hidden: 8, input_size: 100, in_channels: 5 };
    let err = EquiActor::new(&bad_size, &init, &dev).unwrap_err().to_string();
    assert!(err.contains("input size 100"), "{err}");
    let bad_hidden = NetConfig { hidden: 12, input_size: 128, in_channels: 5 };
    assert!(CnnActor::new(&bad_hidden, &init, &dev).is_err());
}
