//! Every layer kind satisfies `f(g·x) = g·f(x)` (docs/paper.md §1.3) for every group element acting
//! on the pixel grid, random inputs and random weights and biases, to relative error < 1e-4.

mod common;

use common::{device, randn, rel_err};
use equiarm_nn::burn::module::Param;
use equiarm_nn::group::Group;
use equiarm_nn::init::Init;
use equiarm_nn::layers::{EquivariantConv, Numerics, concat, group_pool, max_pool2, relu, transform};
use equiarm_nn::repr::{FieldType, Representation};

const TOL: f64 = 1e-4;

fn mixed(g: Group, regular: usize) -> FieldType {
    let std = Representation::irrep(g, if g.is_dihedral() { 1 } else { 0 }, 1);
    FieldType::regular(g, regular)
        .concat(&FieldType::trivial(g, 2))
        .concat(&FieldType::new(g, vec![std, Representation::quotient_by_rotations(g)]))
}

/// Random non-zero biases, so that the bias placement is tested too.
fn randomise_bias(mut conv: EquivariantConv, seed: u64) -> EquivariantConv {
    let dev = device();
    conv.bias = conv
        .bias
        .iter()
        .enumerate()
        .map(|(i, b)| Param::from_tensor(randn::<2>(seed, &format!("bias{i}"), b.val().dims(), &dev)))
        .collect();
    conv
}

fn check_conv(g: Group, tin: &FieldType, tout: &FieldType, k: usize, pad: usize, size: usize, seed: u64) {
    let dev = device();
    let conv = EquivariantConv::new("conv", tin, tout, k, pad, Numerics::DEFAULT, &Init::new(seed), &dev).unwrap();
    let conv = randomise_bias(conv, seed);
    let x = randn::<4>(seed, "x", [2, tin.size(), size, size], &dev);
    let y = conv.forward(x.clone());
    for e in g.grid_elements() {
        let lhs = conv.forward(transform(x.clone(), tin, e));
        let rhs = transform(y.clone(), tout, e);
        let err = rel_err(lhs, rhs);
        assert!(err < TOL, "{}: {} → {} k={k}: element {e:?} error {err}", g.name(), tin.describe(), tout.describe());
    }
}

#[test]
fn conv_is_equivariant_for_all_type_pairs() {
    for g in [Group::dihedral(4), Group::cyclic(4), Group::cyclic(8), Group::dihedral(2), Group::dihedral(8)] {
        let triv = FieldType::trivial(g, 3);
        let reg = FieldType::regular(g, 2);
        let mix = mixed(g, 1);
        check_conv(g, &triv, &reg, 3, 1, 8, 1);
        check_conv(g, &reg, &reg, 3, 1, 8, 2);
        check_conv(g, &reg, &reg, 3, 0, 7, 3);
        check_conv(g, &mix, &mix, 3, 1, 6, 4);
        check_conv(g, &mix, &mix, 1, 0, 5, 5);
        check_conv(g, &reg, &mixed(g, 2), 1, 0, 4, 6);
    }
}

#[test]
fn conv_is_not_trivially_zero_and_breaks_for_wrong_action() {
    // Guard against a vacuous test: the output is non-zero, and transforming the output with
    // the wrong representation is detected.
    let g = Group::dihedral(4);
    let dev = device();
    let tin = FieldType::trivial(g, 2);
    let tout = FieldType::regular(g, 2);
    let conv = EquivariantConv::new("c", &tin, &tout, 3, 1, Numerics::DEFAULT, &Init::new(9), &dev).unwrap();
    let x = randn::<4>(9, "x", [1, 2, 8, 8], &dev);
    let y = conv.forward(x.clone());
    assert!(common::values(y.clone()).iter().any(|v| v.abs() > 1e-3));
    let e = g.elements()[1]; // quarter turn
    let lhs = conv.forward(transform(x, &tin, e));
    let wrong = transform(y, &FieldType::trivial(g, 16), e); // ignores the fibre permutation
    assert!(rel_err(lhs, wrong) > 1e-2);
}

#[test]
fn pointwise_layers_are_equivariant() {
    let dev = device();
    for g in [Group::dihedral(4), Group::cyclic(8)] {
        let t = FieldType::regular(g, 3).concat(&FieldType::repeat(Representation::quotient_by_rotations(g), 1));
        let x = randn::<4>(11, "x", [2, t.size(), 8, 8], &dev);
        for e in g.grid_elements() {
            let gx = transform(x.clone(), &t, e);
            let err = rel_err(relu(gx.clone()), transform(relu(x.clone()), &t, e));
            assert!(err < TOL, "relu {e:?} {err}");
            let err = rel_err(max_pool2(gx), transform(max_pool2(x.clone()), &t, e));
            assert!(err < TOL, "max_pool2 {e:?} {err}");
        }
        // group pooling: regular → trivial (invariant per field)
        let treg = FieldType::regular(g, 3);
        let x = randn::<4>(12, "x", [2, treg.size(), 6, 6], &dev);
        let y = group_pool(x.clone(), 3, g.order());
        assert_eq!(y.dims(), [2, 3, 6, 6]);
        let tout = FieldType::trivial(g, 3);
        for e in g.grid_elements() {
            let err = rel_err(group_pool(transform(x.clone(), &treg, e), 3, g.order()), transform(y.clone(), &tout, e));
            assert!(err < TOL, "group_pool {e:?} {err}");
        }
        // concatenation: the direct sum transforms blockwise
        let ta = FieldType::regular(g, 1);
        let tb = mixed(g, 1);
        let a = randn::<4>(13, "a", [1, ta.size(), 4, 4], &dev);
        let b = randn::<4>(13, "b", [1, tb.size(), 4, 4], &dev);
        let tab = ta.concat(&tb);
        for e in g.grid_elements() {
            let lhs = concat(vec![transform(a.clone(), &ta, e), transform(b.clone(), &tb, e)]);
            let rhs = transform(concat(vec![a.clone(), b.clone()]), &tab, e);
            assert!(rel_err(lhs, rhs) < TOL);
        }
    }
}

#[test]
fn cached_kernel_gives_the_same_output() {
    let g = Group::dihedral(4);
    let dev = device();
    let (tin, tout) = (FieldType::regular(g, 2), mixed(g, 1));
    let conv = EquivariantConv::new("c", &tin, &tout, 3, 1, Numerics::DEFAULT, &Init::new(3), &dev).unwrap();
    let x = randn::<4>(3, "x", [1, tin.size(), 6, 6], &dev);
    let y = conv.forward(x.clone());
    assert!(!conv.uses_cached_kernel());
    let cached = conv.cache_kernel();
    assert!(cached.uses_cached_kernel());
    assert_eq!(common::values(cached.forward(x)), common::values(y));
    // a module tracked by autodiff never uses a (possibly stale) cache
    let tracked =
        EquivariantConv::new("c", &tin, &tout, 3, 1, Numerics::DEFAULT, &Init::new(3), &dev.clone().autodiff())
            .unwrap()
            .cache_kernel();
    assert!(!tracked.uses_cached_kernel());
}

/// The unfold + matmul convolution equals burn's conv2d (forward and gradients), with and
/// without padding, for 3×3 and 1×1 kernels.
#[test]
fn unfold_convolution_matches_burn_conv2d() {
    use equiarm_nn::burn::tensor::module::conv2d;
    use equiarm_nn::burn::tensor::ops::ConvOptions;
    use equiarm_nn::layers::conv2d_unfold;
    let dev = device().autodiff();
    for (k, p) in [(3, 1), (3, 0), (1, 0)] {
        let x = randn::<4>(21, "x", [2, 3, 6, 6], &dev).require_grad();
        let w = randn::<4>(21, "w", [4, 3, k, k], &dev).require_grad();
        let b = randn::<1>(21, "b", [4], &dev).require_grad();
        let y1 = conv2d(x.clone(), w.clone(), Some(b.clone()), ConvOptions::new([1, 1], [p, p], [1, 1], 1));
        let y2 = conv2d_unfold(x.clone(), w.clone(), Some(b.clone()), p);
        assert!(rel_err(y2.clone(), y1.clone()) < 1e-5, "forward k={k} p={p}");
        let g1 = y1.powf_scalar(2.0).sum().backward();
        let g2 = y2.powf_scalar(2.0).sum().backward();
        assert!(rel_err(w.grad(&g2).unwrap(), w.grad(&g1).unwrap()) < 1e-5, "weight grad k={k} p={p}");
        assert!(rel_err(x.grad(&g2).unwrap(), x.grad(&g1).unwrap()) < 1e-5, "input grad k={k} p={p}");
        assert!(rel_err(b.grad(&g2).unwrap(), b.grad(&g1).unwrap()) < 1e-5, "bias grad k={k} p={p}");
    }
}
