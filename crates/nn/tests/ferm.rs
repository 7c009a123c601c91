//! FERM's networks (docs/paper.md §1.10): CURL's contrastive loss on a hand-made batch, the
//! encoder's LayerNorm, and the actor's detached convs.

mod common;

use common::{device, randn, values};
use equiarm_nn::burn::module::{Module, Param};
use equiarm_nn::burn::tensor::{Tensor, TensorData};
use equiarm_nn::init::Init;
use equiarm_nn::nets::{Actor, CurlBilinear, FERM_Z_DIM, FermActor, FermCritic, LayerNorm, NetConfig};
use equiarm_types::OBS_PLANES;

/// With W = 2·I and features one-hot in distinct dimensions, the logits are 2 on the diagonal and 0
/// elsewhere; with a positive that matches the anchor only for rows 0 and 1 (row 2's positive is row
/// 0's feature), the loss is the mean of −log softmax, by hand.
#[test]
fn curl_loss_on_a_hand_made_batch() {
    let dev = device();
    let z = FERM_Z_DIM;
    let mut w = vec![0f32; z * z];
    for i in 0..z {
        w[i * z + i] = 2.0;
    }
    let curl = CurlBilinear { w: Param::from_tensor(Tensor::from_data(TensorData::new(w, [z, z]), &dev)) };
    let onehot = |rows: &[usize]| {
        let mut v = vec![0f32; rows.len() * z];
        for (r, &d) in rows.iter().enumerate() {
            v[r * z + d] = 1.0;
        }
        Tensor::<2>::from_data(TensorData::new(v, [rows.len(), z]), &dev)
    };
    // All three matched: every row is [2, 0, 0] up to order: loss = −log(e²/(e² + 2)).
    let l = values(curl.loss(onehot(&[0, 1, 2]), onehot(&[0, 1, 2])))[0] as f64;
    let e2 = 2f64.exp();
    let matched = -(e2 / (e2 + 2.0)).ln();
    assert!((l - matched).abs() < 1e-6, "{l} vs {matched}");
    // Row 2's positive is dimension 0: row 0's logits [2, 0, 2] (target col 0), row 1's [0, 2, 0]
    // (target 1), row 2's [0, 0, 0] (target 2).
    let l = values(curl.loss(onehot(&[0, 1, 2]), onehot(&[0, 1, 0])))[0] as f64;
    let row0 = -(e2 / (2.0 * e2 + 1.0)).ln();
    let row1 = matched;
    let row2 = -(1f64 / 3.0).ln();
    let want = (row0 + row1 + row2) / 3.0;
    assert!((l - want).abs() < 1e-6, "{l} vs {want}");
    // Subtracting each row's maximum changes nothing but the range of the exponentials.
    let big = values(curl.loss(onehot(&[0, 1, 2]).mul_scalar(40.0), onehot(&[0, 1, 2]).mul_scalar(40.0)))[0];
    assert!(big.is_finite() && big < 1e-6, "logits of 3200 still give a finite loss: {big}");
}

#[test]
fn layer_norm_normalises_each_row() {
    let dev = device();
    let x = randn(3, "x", [4, 50], &dev).mul_scalar(7.0).add_scalar(3.0);
    let y = values(LayerNorm::new(50, &dev).forward(x));
    for row in y.chunks(50) {
        let m: f32 = row.iter().sum::<f32>() / 50.0;
        let v: f32 = row.iter().map(|a| (a - m).powi(2)).sum::<f32>() / 50.0;
        assert!(m.abs() < 1e-5 && (v - 1.0).abs() < 1e-3, "mean {m}, variance {v}");
    }
}

/// The actor's loss reaches its own head and MLPs, never the convs (they are the critic's).
#[test]
fn the_actor_trains_its_head_not_the_convs() {
    let dev = device().autodiff();
    let cfg = NetConfig::new(8, 16, OBS_PLANES);
    let actor = FermActor::new(&cfg, &Init::new(0), &dev).unwrap();
    let x = randn(1, "obs", [2, 5, 16, 16], &dev);
    let (mean, log_std) = actor.forward(x);
    let grads = (mean.sum() + log_std.sum()).backward();
    let conv_w = &actor.enc.convs.convs[0].weight;
    assert!(conv_w.val().grad(&grads).is_none(), "no gradient reaches the tied convs");
    assert!(actor.enc.head.fc.weight.val().grad(&grads).is_some());
    assert!(actor.mean.layers[0].weight.val().grad(&grads).is_some());
    // the critic's encoder does get gradients from its Q values
    let critic = FermCritic::new(&cfg, &Init::new(0), &dev).unwrap();
    let (q1, _) =
        equiarm_nn::nets::Critic::forward(&critic, randn(2, "obs", [2, 5, 16, 16], &dev), randn(3, "a", [2, 5], &dev));
    let grads = q1.sum().backward();
    assert!(critic.enc.convs.convs[0].weight.val().grad(&grads).is_some());
    assert_eq!(
        actor.num_params(),
        critic.num_params() - 2 * (55 * 64 + 64 + 64 * 64 + 64 + 65) + 2 * (50 * 64 + 64 + 64 * 64 + 64 + 64 * 5 + 5)
    );
}
