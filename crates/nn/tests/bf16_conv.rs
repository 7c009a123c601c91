//! The convolution kernels in `bf16` (Intel AMX, [`equiarm_nn::kernels::MatmulPrecision::Bf16`])
//! against the same kernels in `f32`: forward, input, weight and bias gradients within bfloat16's
//! rounding, on shapes that take each of the kernels' paths (batched small maps, bands of rows of a
//! large one, 1×1 and 3×3, odd sizes).

use equiarm_nn::init::Init;
use equiarm_nn::kernels::MatmulPrecision;
use equiarm_nn::kernels::gemm_conv::{self, ConvShape, Wanted};

/// `n` values from the project's seeded initialiser (uniform in [−1, 1]).
fn values(n: usize, seed: u64) -> Vec<f32> {
    Init::new(seed).uniform("bf16_conv", n, 1.0)
}

/// ‖a − b‖ / ‖b‖.
fn rel(a: &[f32], b: &[f32]) -> f64 {
    let d: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    let n: f64 = b.iter().map(|y| (*y as f64).powi(2)).sum();
    (d / n.max(1e-30)).sqrt()
}

type Results = (Vec<f32>, Vec<f32>, Vec<f32>, Vec<f32>);

/// The forward's output in precision `p`, and the gradients in `p` from the `f32` forward's output
/// (so that both precisions' backward passes see the same ReLU mask: a mask flipped where `y` is
/// near 0 moves a masked sum far more than the rounding of a product).
fn run(s: &ConvShape, relu: bool, p: MatmulPrecision) -> Results {
    let x = values(s.batch * s.cin * s.h * s.w, 1);
    let w = values(s.cout * s.cin * s.k * s.k, 2);
    let b = values(s.cout, 3);
    let forward = |p| {
        let mut y = vec![0f32; s.batch * s.cout * s.out_h() * s.out_w()];
        gemm_conv::forward(s, p, &x, &w, &b, relu, &mut y);
        y
    };
    let y_exact = forward(MatmulPrecision::F32);
    let y = forward(p);
    let dy = values(y.len(), 4);
    let g = gemm_conv::backward(s, p, &x, &w, Some(&y_exact), &dy, relu, Wanted { x: true, weight: true, bias: true });
    (y, g.x.unwrap(), g.weight.unwrap(), g.bias.unwrap())
}

#[test]
fn bf16_kernels_match_the_f32_ones_within_bfloat16_rounding() {
    if let Err(e) = MatmulPrecision::Bf16.supported() {
        eprintln!("no AMX on this machine ({e}): not run");
        return;
    }
    // (batch, cin, cout, size, k, pad, relu)
    for (batch, cin, cout, size, k, pad, relu) in [
        (64, 5, 16, 32, 3, 1, true),
        (4, 8, 24, 64, 3, 1, true),
        (64, 32, 64, 8, 3, 0, false),
        (3, 7, 9, 5, 3, 0, true),
        (16, 40, 8, 4, 1, 0, false),
    ] {
        let s = ConvShape { batch, cin, h: size, w: size, cout, k, pad };
        let exact = run(&s, relu, MatmulPrecision::F32);
        let rounded = run(&s, relu, MatmulPrecision::Bf16);
        let errs = [
            rel(&rounded.0, &exact.0),
            rel(&rounded.1, &exact.1),
            rel(&rounded.2, &exact.2),
            rel(&rounded.3, &exact.3),
        ];
        eprintln!(
            "{s:?}: relative error of y, dx, dw, db in bf16: {:.1e} {:.1e} {:.1e} {:.1e}",
            errs[0], errs[1], errs[2], errs[3]
        );
        // Each bf16 operand is within 2^-9 relative; random signs average the errors of a sum, so
        // its relative L2 error stays near that. The bias gradient multiplies no matrices.
        for (e, what) in errs[..3].iter().zip(["y", "dx", "dw"]) {
            assert!(*e < 5e-3, "{s:?}: {what} off by {e:.2e} relative");
            assert!(*e > 0.0, "{s:?}: {what} identical to f32: the AMX path did not run");
        }
        assert_eq!(errs[3], 0.0, "{s:?}: the bias gradient changed");
    }
}
