//! Our convolution kernels ([`equiarm_nn::kernels`]) against burn's reference `conv2d` (+ `relu`):
//! forward, input gradient, weight gradient and bias gradient within 1e-5 relative (L2) on random
//! shapes (batch 1 and 64, channels 5–256, sizes 1–48, padding 0 and 1, odd sizes, 1×1 and 3×3,
//! maps large enough to be worked on in bands of rows),
//! also through `EquivariantConv` and `Conv` (two layers with the same weights, one per algorithm, in
//! one process: the algorithm is the layer's own); and their results are the same from run to run.

mod common;

use common::{device, randn, rel_err, values};
use equiarm_nn::burn::tensor::Tensor;
use equiarm_nn::burn::tensor::module::conv2d;
use equiarm_nn::burn::tensor::ops::ConvOptions;
use equiarm_nn::group::Group;
use equiarm_nn::init::Init;
use equiarm_nn::kernels::{MatmulPrecision, conv2d_fused};
use equiarm_nn::layers::{ConvAlgo, EquivariantConv, Numerics};
use equiarm_nn::plain::Conv;
use equiarm_nn::repr::FieldType;

const TOL: f64 = 1e-5;
const F32: MatmulPrecision = MatmulPrecision::F32;

fn reference(x: Tensor<4>, w: Tensor<4>, b: Tensor<1>, pad: usize, relu: bool) -> Tensor<4> {
    let y = conv2d(x, w, Some(b), ConvOptions::new([1, 1], [pad, pad], [1, 1], 1));
    if relu { equiarm_nn::burn::tensor::activation::relu(y) } else { y }
}

/// `(batch, cin, cout, size, k, pad, relu)`.
const SHAPES: &[(usize, usize, usize, usize, usize, usize, bool)] = &[
    (1, 5, 16, 38, 3, 1, true),
    (64, 5, 64, 32, 3, 1, true),
    (64, 64, 128, 16, 3, 1, true),
    (64, 128, 256, 8, 3, 1, false),
    (64, 256, 128, 8, 3, 0, true),
    (1, 256, 256, 3, 3, 0, true),
    (64, 128, 128, 1, 3, 1, true),
    (3, 7, 9, 5, 3, 0, false),
    (64, 13, 11, 7, 3, 1, true),
    (2, 9, 6, 1, 3, 1, false),
    (64, 133, 128, 1, 1, 0, true),
    (5, 6, 7, 9, 1, 0, false),
    // Large maps, worked on in bands of output rows.
    (2, 16, 8, 48, 3, 1, true),
    (3, 64, 8, 40, 3, 0, true),
];

#[test]
fn kernels_match_burn_conv2d_forward_and_gradients() {
    let dev = device().autodiff();
    for (i, &(batch, cin, cout, size, k, pad, relu)) in SHAPES.iter().enumerate() {
        let seed = 100 + i as u64;
        let x = randn::<4>(seed, "x", [batch, cin, size, size], &dev).require_grad();
        let w = randn::<4>(seed, "w", [cout, cin, k, k], &dev).mul_scalar(0.1).require_grad();
        let b = randn::<1>(seed, "b", [cout], &dev).require_grad();
        let y_ref = reference(x.clone(), w.clone(), b.clone(), pad, relu);
        let y = conv2d_fused(x.clone(), w.clone(), b.clone(), pad, relu, F32);
        let case = format!("batch {batch}, {cin}→{cout}, {size}×{size}, k {k}, pad {pad}, relu {relu}");
        assert_eq!(y.dims(), y_ref.dims(), "{case}: output shape");
        assert!(rel_err(y.clone(), y_ref.clone()) < TOL, "{case}: forward {}", rel_err(y.clone(), y_ref.clone()));
        // A loss with a random weight per output, so that every gradient entry is exercised.
        let r = randn::<4>(seed, "r", y.dims(), &device().autodiff());
        let g_ref = (y_ref * r.clone()).sum().backward();
        let g = (y * r).sum().backward();
        for (what, a, e) in [
            ("input", x.grad(&g).unwrap(), x.grad(&g_ref).unwrap()),
            ("weight", w.grad(&g).unwrap(), w.grad(&g_ref).unwrap()),
        ] {
            let err = rel_err(a, e);
            assert!(err < TOL, "{case}: {what} gradient relative error {err}");
        }
        let err = rel_err(b.grad(&g).unwrap(), b.grad(&g_ref).unwrap());
        assert!(err < TOL, "{case}: bias gradient relative error {err}");
    }
}

#[test]
fn untracked_inputs_get_no_gradient_and_plain_tensors_run_forward() {
    let dev = device().autodiff();
    // The observation (not tracked) gets no gradient; the weight still does.
    let x = randn::<4>(7, "x", [4, 5, 8, 8], &dev);
    let w = randn::<4>(7, "w", [6, 5, 3, 3], &dev).require_grad();
    let b = randn::<1>(7, "b", [6], &dev).require_grad();
    let g = conv2d_fused(x.clone(), w.clone(), b.clone(), 1, true, F32).sum().backward();
    assert!(x.grad(&g).is_none());
    assert!(w.grad(&g).is_some() && b.grad(&g).is_some());
    // Without autodiff: the same forward values.
    let plain = device();
    let (xp, wp, bp) = (x.inner(), w.inner(), b.inner());
    let y = conv2d_fused(xp.clone(), wp.clone(), bp.clone(), 1, true, F32);
    let e = reference(xp, wp, bp, 1, true);
    assert_eq!(y.device(), plain);
    assert!(rel_err(y, e) < TOL);
}

#[test]
fn kernels_are_bit_identical_from_run_to_run() {
    let dev = device().autodiff();
    let run = || {
        let x = randn::<4>(9, "x", [64, 64, 16, 16], &dev).require_grad();
        let w = randn::<4>(9, "w", [128, 64, 3, 3], &dev).require_grad();
        let b = randn::<1>(9, "b", [128], &dev).require_grad();
        let y = conv2d_fused(x.clone(), w.clone(), b.clone(), 1, true, F32);
        let g = y.clone().powf_scalar(2.0).sum().backward();
        (values(y), values(x.grad(&g).unwrap()), values(w.grad(&g).unwrap()), values(b.grad(&g).unwrap()))
    };
    let (a, b) = (run(), run());
    assert!(a.0 == b.0 && a.1 == b.1 && a.2 == b.2 && a.3 == b.3, "two runs differ");
}

/// A layer's output and input gradient.
fn layer_run<F: Fn(Tensor<4>) -> Tensor<4>>(f: F, x: Tensor<4>) -> (Tensor<4>, Tensor<4>) {
    let y = f(x.clone());
    let g = y.clone().powf_scalar(2.0).sum().backward();
    (y, x.grad(&g).unwrap())
}

#[test]
fn equivariant_and_plain_convs_give_burns_results_through_the_kernels() {
    let dev = device().autodiff();
    let g = Group::dihedral(4);
    let (burn, ours) = (Numerics::algo(ConvAlgo::Burn), Numerics::DEFAULT);
    for (tin, tout, k, pad, size, batch) in [
        (FieldType::trivial(g, 5), FieldType::regular(g, 8), 3, 1, 16, 64),
        (FieldType::regular(g, 16), FieldType::regular(g, 32), 3, 1, 8, 64),
        (FieldType::regular(g, 32), FieldType::regular(g, 16), 3, 0, 8, 1),
        (FieldType::regular(g, 16), FieldType::regular(g, 16), 1, 0, 1, 64),
    ] {
        // The same weights (one seed), one layer per algorithm.
        let layer = |n| EquivariantConv::new("c", &tin, &tout, k, pad, n, &Init::new(4), &dev).unwrap();
        let (reference, conv) = (layer(burn), layer(ours));
        assert_eq!((reference.numerics(), conv.numerics()), (burn, ours));
        let x = randn::<4>(5, "x", [batch, tin.size(), size, size], &dev).require_grad();
        let case = format!("{} → {}, k {k}, {size}×{size}, batch {batch}", tin.describe(), tout.describe());
        for relu in [false, true] {
            let act = |c: &EquivariantConv, x: Tensor<4>| if relu { c.forward_relu(x) } else { c.forward(x) };
            let (y_ref, dx_ref) = layer_run(|x| act(&reference, x), x.clone());
            let (y, dx) = layer_run(|x| act(&conv, x), x.clone());
            assert!(rel_err(y, y_ref) < TOL, "{case} relu {relu}: forward");
            assert!(rel_err(dx, dx_ref) < TOL, "{case} relu {relu}: input gradient");
        }
        // The free weights' gradients (through the kernel expansion).
        let weight_grads = |c: &EquivariantConv| {
            let grads = c.forward_relu(x.clone()).powf_scalar(2.0).sum().backward();
            c.weight.iter().map(|w| w.val().grad(&grads).unwrap()).collect::<Vec<_>>()
        };
        for (a, e) in weight_grads(&conv).into_iter().zip(weight_grads(&reference)) {
            assert!(rel_err(a, e) < TOL, "{case}: free-weight gradient");
        }
    }
    let plain = |n| Conv::new("p", 7, 12, 3, 1, n, &Init::new(6), &dev);
    let (reference, conv) = (plain(burn), plain(ours));
    let x = randn::<4>(6, "x", [64, 7, 11, 11], &dev).require_grad();
    let (y_ref, dx_ref) = layer_run(|x| reference.forward_relu(x), x.clone());
    let (y, dx) = layer_run(|x| conv.forward_relu(x), x.clone());
    assert!(rel_err(y, y_ref) < TOL && rel_err(dx, dx_ref) < TOL, "plain Conv");
}

#[test]
fn max_pool_matches_burn_forward_and_gradient() {
    use equiarm_nn::burn::tensor::module::max_pool2d;
    use equiarm_nn::burn::tensor::ops::MaxPoolOptions;
    use equiarm_nn::kernels::max_pool2x2;
    let dev = device().autodiff();
    for (i, &(b, c, h, w)) in [(64, 128, 16, 16), (2, 3, 7, 5), (64, 256, 6, 6), (1, 4, 1, 3)].iter().enumerate() {
        let x = randn::<4>(30 + i as u64, "x", [b, c, h, w], &dev).require_grad();
        let e = max_pool2d(x.clone(), MaxPoolOptions::new([2, 2]));
        let y = max_pool2x2(x.clone());
        assert_eq!(y.dims(), e.dims(), "{b}×{c}×{h}×{w}: shape");
        if y.dims().iter().product::<usize>() == 0 {
            continue;
        }
        assert_eq!(values(y.clone()), values(e.clone()), "{b}×{c}×{h}×{w}: forward");
        let r = randn::<4>(40 + i as u64, "r", y.dims(), &device().autodiff());
        let (g, g_ref) = ((y * r.clone()).sum().backward(), (e * r).sum().backward());
        assert_eq!(values(x.grad(&g).unwrap()), values(x.grad(&g_ref).unwrap()), "{b}×{c}×{h}×{w}: gradient");
    }
}
