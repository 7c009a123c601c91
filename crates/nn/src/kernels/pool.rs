//! 2×2 max-pooling with stride 2 on `f32` NCHW slices, forward (with the position of each
//! maximum) and backward, parallel over the channel planes. Odd sizes drop the last row or column,
//! as burn's `max_pool2d` does; ties go to the first position in row-major order. NaNs are not
//! propagated (the learner stops on non-finite losses before they could matter).

use rayon::prelude::*;

/// Planes per rayon task: enough work per task to amortise scheduling.
const PLANES_PER_TASK: usize = 16;

/// Output size of a 2×2, stride-2 pool over `h × w`.
pub fn out_size(h: usize, w: usize) -> (usize, usize) {
    (h / 2, w / 2)
}

/// Forward over `planes` planes of `h × w`: returns the pooled values `[planes, h/2, w/2]` and,
/// for each, which of the four inputs (0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right)
/// was the maximum.
pub fn forward(x: &[f32], planes: usize, h: usize, w: usize) -> (Vec<f32>, Vec<u8>) {
    assert_eq!(x.len(), planes * h * w, "max-pool input length");
    let (ho, wo) = out_size(h, w);
    let mut y = vec![0f32; planes * ho * wo];
    let mut idx = vec![0u8; planes * ho * wo];
    if ho == 0 || wo == 0 {
        return (y, idx);
    }
    y.par_chunks_mut(ho * wo * PLANES_PER_TASK)
        .zip(idx.par_chunks_mut(ho * wo * PLANES_PER_TASK))
        .enumerate()
        .for_each(|(t, (ys, is))| {
            for (p, (yp, ip)) in ys.chunks_mut(ho * wo).zip(is.chunks_mut(ho * wo)).enumerate() {
                let plane = &x[(t * PLANES_PER_TASK + p) * h * w..][..h * w];
                for oy in 0..ho {
                    let r0 = &plane[2 * oy * w..][..w];
                    let r1 = &plane[(2 * oy + 1) * w..][..w];
                    let (yr, ir) = (&mut yp[oy * wo..][..wo], &mut ip[oy * wo..][..wo]);
                    for (ox, (yv, iv)) in yr.iter_mut().zip(ir.iter_mut()).enumerate() {
                        let (a, b) = (r0[2 * ox], r0[2 * ox + 1]);
                        let (c, d) = (r1[2 * ox], r1[2 * ox + 1]);
                        // Strict comparisons: a tie keeps the earlier position.
                        let (top, ti) = if b > a { (b, 1u8) } else { (a, 0u8) };
                        let (bottom, bi) = if d > c { (d, 3u8) } else { (c, 2u8) };
                        (*yv, *iv) = if bottom > top { (bottom, bi) } else { (top, ti) };
                    }
                }
            }
        });
    (y, idx)
}

/// Backward: the input gradient `[planes, h, w]`, the output gradient `dy` routed to the
/// positions `idx` that [`forward`] recorded (zero elsewhere).
pub fn backward(dy: &[f32], idx: &[u8], planes: usize, h: usize, w: usize) -> Vec<f32> {
    let (ho, wo) = out_size(h, w);
    assert_eq!(dy.len(), planes * ho * wo, "max-pool output-gradient length");
    assert_eq!(idx.len(), dy.len(), "max-pool index length");
    let mut dx = vec![0f32; planes * h * w];
    if ho == 0 || wo == 0 {
        return dx;
    }
    dx.par_chunks_mut(h * w * PLANES_PER_TASK).enumerate().for_each(|(t, dxs)| {
        for (p, dxp) in dxs.chunks_mut(h * w).enumerate() {
            let base = (t * PLANES_PER_TASK + p) * ho * wo;
            let (gs, is) = (&dy[base..base + ho * wo], &idx[base..base + ho * wo]);
            for oy in 0..ho {
                for ox in 0..wo {
                    let j = is[oy * wo + ox] as usize;
                    dxp[(2 * oy + j / 2) * w + 2 * ox + j % 2] = gs[oy * wo + ox];
                }
            }
        }
    });
    dx
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn picks_the_maximum_and_routes_the_gradient_to_it() {
        // One 3×5 plane: the last row and column are dropped.
        let x = [1.0, 5.0, 2.0, 2.0, 9.0, 3.0, 4.0, 7.0, 1.0, 9.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let (y, idx) = forward(&x, 1, 3, 5);
        assert_eq!(y, vec![5.0, 7.0]);
        assert_eq!(idx, vec![1, 2]);
        let dx = backward(&[10.0, 20.0], &idx, 1, 3, 5);
        let mut want = vec![0.0; 15];
        want[1] = 10.0;
        want[7] = 20.0;
        assert_eq!(dx, want);
    }
}
