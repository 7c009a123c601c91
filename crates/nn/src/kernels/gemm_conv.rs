//! Stride-1 2-D convolution on `f32` slices in NCHW layout, forward and backward, as large GEMMs
//! (the `gemm` crate, whose AVX-512 / AVX2 / SSE kernels are chosen at run time).
//!
//! Each call splits the batch into one contiguous range per rayon thread; a thread walks its range
//! in pieces small enough that their im2col matrix is still in cache when the GEMM packs it
//! (several small samples, one sample, or a band of output rows of a large one), and for each piece
//! runs one GEMM whose inner dimension is `C·k·k` (forward, input gradient) or the piece's output
//! pixels (weight gradient, accumulated over the pieces). Bias and ReLU are fused into the pass
//! that writes the GEMM's result into NCHW; the ReLU mask and the bias gradient into the pass that
//! gathers the output gradient. Partial weight and bias gradients are summed over the threads in
//! thread order, so results are bit-identical from run to run at a given thread count.

use super::MatmulPrecision;
use gemm::{Parallelism, gemm};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};

/// FLOPs (2 per multiply-add) of every GEMM these kernels ran in this process.
static FLOPS: AtomicU64 = AtomicU64::new(0);

/// FLOPs of the GEMMs run by the convolution kernels since the process started (or since
/// [`reset_flop_count`]): the work of forward, input-gradient and weight-gradient passes,
/// counted from their shapes (`2·m·n·k` per GEMM). For benchmarks.
pub fn flop_count() -> u64 {
    FLOPS.load(Ordering::Relaxed)
}

/// Sets [`flop_count`] back to zero.
pub fn reset_flop_count() {
    FLOPS.store(0, Ordering::Relaxed);
}

/// The shape of one stride-1 convolution: input `[batch, cin, h, w]`, kernel `[cout, cin, k, k]`,
/// zero padding `pad` on every side.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvShape {
    /// Samples.
    pub batch: usize,
    /// Input channels.
    pub cin: usize,
    /// Input height.
    pub h: usize,
    /// Input width.
    pub w: usize,
    /// Output channels.
    pub cout: usize,
    /// Kernel size (square).
    pub k: usize,
    /// Zero padding on each side.
    pub pad: usize,
}

/// Largest im2col chunk, in floats (1 MiB): small enough that the chunk is still in cache when
/// the GEMM packs it (measured: 4 MiB chunks 13 % and 16 MiB chunks 20 % slower per SAC update).
const CHUNK_FLOATS: usize = 1 << 18;

/// Output pixels per sample from which the passes work on one sample at a time (in bands of rows
/// when it is large) and the forward GEMM writes straight into the NCHW output (no scatter pass);
/// smaller maps are batched, several samples to one GEMM.
const DIRECT_PIXELS: usize = 256;

/// Fewest GEMM columns per piece of work: narrower GEMMs run far below the kernel's peak.
const MIN_COLUMNS: usize = 64;

thread_local! {
    /// Per-thread scratch buffers (im2col matrix, GEMM output), kept between calls so that each
    /// convolution does not allocate, zero and page-fault tens of megabytes afresh.
    static SCRATCH: std::cell::RefCell<(Vec<f32>, Vec<f32>)> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// Runs `f` on two scratch slices of `a` and `b` floats (contents unspecified: `f` must write
/// before it reads).
fn with_scratch<R>(a: usize, b: usize, f: impl FnOnce(&mut [f32], &mut [f32]) -> R) -> R {
    SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut bufs) => {
            let (x, y) = &mut *bufs;
            if x.len() < a {
                x.resize(a, 0.0);
            }
            if y.len() < b {
                y.resize(b, 0.0);
            }
            f(&mut x[..a], &mut y[..b])
        }
        // Re-entered on this thread (not done by these kernels): fresh buffers.
        Err(_) => f(&mut vec![0f32; a], &mut vec![0f32; b]),
    })
}

impl ConvShape {
    /// Output height `h + 2·pad − k + 1`.
    pub fn out_h(&self) -> usize {
        self.h + 2 * self.pad + 1 - self.k
    }

    /// Output width `w + 2·pad − k + 1`.
    pub fn out_w(&self) -> usize {
        self.w + 2 * self.pad + 1 - self.k
    }

    /// Whether the shape describes a convolution with a non-empty output.
    pub fn is_valid(&self) -> bool {
        self.k > 0 && self.h + 2 * self.pad >= self.k && self.w + 2 * self.pad >= self.k
    }

    /// GEMM inner dimension of the forward pass: `cin·k·k`.
    fn kdim(&self) -> usize {
        self.cin * self.k * self.k
    }

    fn in_len(&self) -> usize {
        self.cin * self.h * self.w
    }

    fn out_pixels(&self) -> usize {
        self.out_h() * self.out_w()
    }

    fn out_len(&self) -> usize {
        self.cout * self.out_pixels()
    }

    /// Multiply-adds of the forward pass, times two (FLOPs).
    pub fn forward_flops(&self) -> f64 {
        2.0 * (self.batch * self.cout * self.out_pixels() * self.kdim()) as f64
    }

    /// The pieces of work of samples `a..b`, each one im2col matrix and one GEMM: whole samples,
    /// several to a piece while a map has fewer than [`DIRECT_PIXELS`] pixels, or bands of output
    /// rows of one sample, so that each piece has about [`CHUNK_FLOATS`] im2col entries but at
    /// least [`MIN_COLUMNS`] columns.
    fn units(&self, a: usize, b: usize) -> Vec<Unit> {
        let (ho, wo) = (self.out_h(), self.out_w());
        let p = ho * wo;
        let target = (CHUNK_FLOATS / self.kdim().max(1)).max(MIN_COLUMNS);
        let mut units = Vec::new();
        if p < DIRECT_PIXELS {
            let n = (target / p.max(1)).max(1);
            let mut i0 = a;
            while i0 < b {
                let m = n.min(b - i0);
                units.push(Unit { i0, n: m, rows: (0, ho) });
                i0 += m;
            }
        } else {
            let band = (target / wo.max(1)).clamp(1, ho);
            for i0 in a..b {
                for oy0 in (0..ho).step_by(band) {
                    units.push(Unit { i0, n: 1, rows: (oy0, (oy0 + band).min(ho)) });
                }
            }
        }
        units
    }
}

/// One piece of work: `n` samples from `i0`, output rows `rows.0..rows.1` of each.
#[derive(Clone, Copy, Debug)]
struct Unit {
    i0: usize,
    n: usize,
    rows: (usize, usize),
}

impl Unit {
    /// Output columns of the piece's GEMM: samples × rows × output width.
    fn cols(&self, s: &ConvShape) -> usize {
        self.n * (self.rows.1 - self.rows.0) * s.out_w()
    }
}

/// The batch split into one contiguous range per thread (fewer when the batch is smaller).
fn thread_ranges(batch: usize) -> Vec<(usize, usize)> {
    let parts = rayon::current_num_threads().clamp(1, batch.max(1));
    (0..parts).map(|t| (batch * t / parts, batch * (t + 1) / parts)).filter(|(a, b)| b > a).collect()
}

/// Where kernel tap `(ky, kx)` reads inside the image, for output rows `rows`.
struct Spans {
    /// Output columns `lo..hi` whose input column `ox + kx − pad` lies in `[0, w)`.
    lo: usize,
    hi: usize,
    /// Output rows `ylo..yhi`, counted from `rows.0`, whose input row `oy + ky − pad` lies in `[0, h)`.
    ylo: usize,
    yhi: usize,
    /// Where the copied part starts in an input row (meaningful only when `hi > lo`).
    start: usize,
}

fn spans(s: &ConvShape, ky: usize, kx: usize, (r0, r1): (usize, usize)) -> Spans {
    let (pad, h, w, wo) = (s.pad, s.h, s.w, s.out_w());
    let lo = pad.saturating_sub(kx).min(wo);
    let hi = (w + pad).saturating_sub(kx).min(wo).max(lo);
    let ylo = pad.saturating_sub(ky).clamp(r0, r1) - r0;
    let yhi = (h + pad).saturating_sub(ky).clamp(r0, r1).max(ylo + r0) - r0;
    Spans { lo, hi, ylo, yhi, start: (lo + kx).saturating_sub(pad) }
}

/// The im2col matrix of output rows `rows` of samples `x` (`n` samples, contiguous NCHW):
/// `[cin·k·k, n·R·W']` for `R` rows, rows in the kernel's `(c, ky, kx)` order, columns in
/// `(sample, oy, ox)` order.
fn im2col(s: &ConvShape, x: &[f32], n: usize, rows: (usize, usize), cols: &mut [f32]) {
    let (k, pad, h, w) = (s.k, s.pad, s.h, s.w);
    let wo = s.out_w();
    let (r0, r1) = rows;
    let nr = r1 - r0;
    let ncols = n * nr * wo;
    debug_assert_eq!(cols.len(), s.kdim() * ncols);
    for c in 0..s.cin {
        for ky in 0..k {
            for kx in 0..k {
                let row = &mut cols[((c * k + ky) * k + kx) * ncols..][..ncols];
                let Spans { lo, hi, ylo, yhi, start } = spans(s, ky, kx, rows);
                for i in 0..n {
                    let plane = &x[(i * s.cin + c) * h * w..][..h * w];
                    let dst_rows = &mut row[i * nr * wo..][..nr * wo];
                    dst_rows[..ylo * wo].fill(0.0);
                    dst_rows[yhi * wo..].fill(0.0);
                    if lo == 0 && hi == wo && wo == w {
                        // Whole input rows, contiguous on both sides: one copy.
                        let src = &plane[(r0 + ylo + ky - pad) * w..(r0 + yhi + ky - pad) * w];
                        dst_rows[ylo * wo..yhi * wo].copy_from_slice(src);
                        continue;
                    }
                    for oy in ylo..yhi {
                        let dst = &mut dst_rows[oy * wo..][..wo];
                        let src = &plane[(r0 + oy + ky - pad) * w..][..w];
                        dst[..lo].fill(0.0);
                        dst[hi..].fill(0.0);
                        dst[lo..hi].copy_from_slice(&src[start..start + (hi - lo)]);
                    }
                }
            }
        }
    }
}

/// Adds the im2col-shaped `cols` of output rows `rows` back into the NCHW input gradient `dx` of
/// `n` samples (the adjoint of [`im2col`]).
fn col2im(s: &ConvShape, cols: &[f32], n: usize, rows: (usize, usize), dx: &mut [f32]) {
    let (k, pad, h, w) = (s.k, s.pad, s.h, s.w);
    let wo = s.out_w();
    let (r0, r1) = rows;
    let nr = r1 - r0;
    let ncols = n * nr * wo;
    for c in 0..s.cin {
        for ky in 0..k {
            for kx in 0..k {
                let row = &cols[((c * k + ky) * k + kx) * ncols..][..ncols];
                let Spans { lo, hi, ylo, yhi, start } = spans(s, ky, kx, rows);
                for i in 0..n {
                    let plane = &mut dx[(i * s.cin + c) * h * w..][..h * w];
                    for oy in ylo..yhi {
                        let src = &row[(i * nr + oy) * wo..][..wo];
                        let dst = &mut plane[(r0 + oy + ky - pad) * w + start..][..hi - lo];
                        for (d, v) in dst.iter_mut().zip(&src[lo..hi]) {
                            *d += v;
                        }
                    }
                }
            }
        }
    }
}

/// How [`matmul`] multiplies: in `f32` (the `gemm` crate), or in bf16 on AMX with the left operand
/// already packed when given.
#[derive(Clone, Copy)]
enum Mul<'a> {
    F32,
    Bf16(Option<&'a super::amx::PackedLhs>),
}

impl<'a> Mul<'a> {
    /// `Bf16(packed)` when `bf16`, else `F32`.
    fn new(bf16: bool, packed: Option<&'a super::amx::PackedLhs>) -> Self {
        if bf16 { Mul::Bf16(packed) } else { Mul::F32 }
    }
}

/// `dst (m×n) = [dst +] lhs (m×k) · rhs (k×n)` with explicit row and column strides (in floats), as
/// `mul` says.
#[allow(clippy::too_many_arguments)]
fn matmul(
    mul: Mul<'_>,
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    (dst_rs, dst_cs): (usize, usize),
    accumulate: bool,
    lhs: &[f32],
    (lhs_rs, lhs_cs): (usize, usize),
    rhs: &[f32],
    (rhs_rs, rhs_cs): (usize, usize),
) {
    if m == 0 || n == 0 {
        return;
    }
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                for c in 0..n {
                    dst[r * dst_rs + c * dst_cs] = 0.0;
                }
            }
        }
        return;
    }
    FLOPS.fetch_add(2 * (m * n * k) as u64, Ordering::Relaxed);
    if let Mul::Bf16(packed) = mul {
        match packed {
            Some(a) => super::amx::matmul_packed(a, n, dst, (dst_rs, dst_cs), accumulate, rhs, (rhs_rs, rhs_cs)),
            None => super::amx::matmul(
                m,
                n,
                k,
                dst,
                (dst_rs, dst_cs),
                accumulate,
                lhs,
                (lhs_rs, lhs_cs),
                rhs,
                (rhs_rs, rhs_cs),
            ),
        }
        return;
    }
    // The largest element each operand's strides reach must lie inside its slice.
    assert!((m - 1) * dst_rs + (n - 1) * dst_cs < dst.len(), "gemm dst out of bounds");
    assert!((m - 1) * lhs_rs + (k - 1) * lhs_cs < lhs.len(), "gemm lhs out of bounds");
    assert!((k - 1) * rhs_rs + (n - 1) * rhs_cs < rhs.len(), "gemm rhs out of bounds");
    // SAFETY: the three assertions above keep every element the strides address inside the
    // slices; `dst` is borrowed mutably and does not alias `lhs` or `rhs`.
    unsafe {
        gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            dst_cs as isize,
            dst_rs as isize,
            accumulate,
            lhs.as_ptr(),
            lhs_cs as isize,
            lhs_rs as isize,
            rhs.as_ptr(),
            rhs_cs as isize,
            rhs_rs as isize,
            1.0,
            1.0,
            false,
            false,
            false,
            Parallelism::None,
        );
    }
}

/// Forward: `y = act(conv(x, weight) + bias)`, `x` `[batch, cin, h, w]`, `weight`
/// `[cout, cin, k, k]`, `bias` `[cout]`, `y` `[batch, cout, h', w']` (overwritten). `act` is ReLU
/// when `relu`, else the identity. The GEMMs run in precision `precision`.
pub fn forward(
    s: &ConvShape,
    precision: MatmulPrecision,
    x: &[f32],
    weight: &[f32],
    bias: &[f32],
    relu: bool,
    y: &mut [f32],
) {
    assert!(s.is_valid(), "conv shape {s:?} has an empty output");
    assert_eq!(x.len(), s.batch * s.in_len(), "conv input length");
    assert_eq!(weight.len(), s.cout * s.kdim(), "conv weight length");
    assert_eq!(bias.len(), s.cout, "conv bias length");
    assert_eq!(y.len(), s.batch * s.out_len(), "conv output length");
    let (kd, p, o, wo) = (s.kdim(), s.out_pixels(), s.cout, s.out_w());
    let ranges = thread_ranges(s.batch);
    // bf16: the weights packed once for every piece.
    let bf16 = precision == MatmulPrecision::Bf16;
    let packed = bf16.then(|| super::amx::PackedLhs::new(o, kd, weight, (kd, 1)));
    let mul = Mul::new(bf16, packed.as_ref());
    // Hand each thread the output rows of its range.
    let mut parts: Vec<(usize, usize, &mut [f32])> = Vec::with_capacity(ranges.len());
    let mut rest = y;
    for &(a, b) in &ranges {
        let (head, tail) = rest.split_at_mut((b - a) * s.out_len());
        parts.push((a, b, head));
        rest = tail;
    }
    let act = |dst: &mut [f32], bv: f32| {
        if relu {
            dst.iter_mut().for_each(|d| *d = (*d + bv).max(0.0));
        } else {
            dst.iter_mut().for_each(|d| *d += bv);
        }
    };
    parts.into_par_iter().for_each(|(a, b, ypart)| {
        let units = s.units(a, b);
        let cap = units.iter().map(|u| u.cols(s)).max().unwrap_or(0);
        let batched = p < DIRECT_PIXELS;
        with_scratch(kd * cap, if batched { o * cap } else { 0 }, |cols, out| {
            for u in units {
                let nc = u.cols(s);
                let cols = &mut cols[..kd * nc];
                im2col(s, &x[u.i0 * s.in_len()..(u.i0 + u.n) * s.in_len()], u.n, u.rows, cols);
                if !batched {
                    // One sample's rows: [cout, rows·W'] is a strided block of its NCHW output.
                    let ys = &mut ypart[(u.i0 - a) * s.out_len()..][..s.out_len()];
                    let off = u.rows.0 * wo;
                    matmul(mul, o, nc, kd, &mut ys[off..], (p, 1), false, weight, (kd, 1), cols, (nc, 1));
                    for (oc, &bv) in bias.iter().enumerate() {
                        act(&mut ys[oc * p + off..][..nc], bv);
                    }
                } else {
                    let out = &mut out[..o * nc];
                    matmul(mul, o, nc, kd, out, (nc, 1), false, weight, (kd, 1), cols, (nc, 1));
                    // Scatter [cout, n·P] into NCHW with bias (and ReLU).
                    for i in 0..u.n {
                        let ys = &mut ypart[(u.i0 - a + i) * s.out_len()..][..s.out_len()];
                        for (oc, &bv) in bias.iter().enumerate() {
                            let dst = &mut ys[oc * p..][..p];
                            dst.copy_from_slice(&out[oc * nc + i * p..][..p]);
                            act(dst, bv);
                        }
                    }
                }
            }
        })
    });
}

/// The gradients of [`forward`] that were asked for.
#[derive(Debug, Default)]
pub struct Grads {
    /// `[batch, cin, h, w]`, when asked.
    pub x: Option<Vec<f32>>,
    /// `[cout, cin, k, k]`, when asked.
    pub weight: Option<Vec<f32>>,
    /// `[cout]`, when asked.
    pub bias: Option<Vec<f32>>,
}

/// Which gradients [`backward`] computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Wanted {
    /// The input gradient.
    pub x: bool,
    /// The weight gradient.
    pub weight: bool,
    /// The bias gradient.
    pub bias: bool,
}

/// Backward of [`forward`]: from the output gradient `dy` (and, when `relu`, the forward's output
/// `y` for the ReLU mask `y > 0`), the input, weight and bias gradients that `want` asks for, the
/// GEMMs in precision `precision`.
#[allow(clippy::too_many_arguments)]
pub fn backward(
    s: &ConvShape,
    precision: MatmulPrecision,
    x: &[f32],
    weight: &[f32],
    y: Option<&[f32]>,
    dy: &[f32],
    relu: bool,
    want: Wanted,
) -> Grads {
    assert!(s.is_valid(), "conv shape {s:?} has an empty output");
    assert_eq!(x.len(), s.batch * s.in_len(), "conv input length");
    assert_eq!(weight.len(), s.cout * s.kdim(), "conv weight length");
    assert_eq!(dy.len(), s.batch * s.out_len(), "conv output-gradient length");
    let mask = if relu {
        let y = y.expect("the ReLU mask needs the forward's output");
        assert_eq!(y.len(), dy.len(), "conv output length");
        Some(y)
    } else {
        None
    };
    let (kd, p, o, wo) = (s.kdim(), s.out_pixels(), s.cout, s.out_w());
    let ranges = thread_ranges(s.batch);
    let mut dx = want.x.then(|| vec![0f32; x.len()]);
    // Each thread's slice of dx.
    let mut dx_parts: Vec<Option<&mut [f32]>> = Vec::with_capacity(ranges.len());
    match dx.as_mut() {
        Some(d) => {
            let mut rest = d.as_mut_slice();
            for &(a, b) in &ranges {
                let (head, tail) = rest.split_at_mut((b - a) * s.in_len());
                dx_parts.push(Some(head));
                rest = tail;
            }
        }
        None => dx_parts.extend(ranges.iter().map(|_| None)),
    }
    let bf16 = precision == MatmulPrecision::Bf16;
    // bf16: the input gradient's left operand Wᵀ packed once for every piece.
    let packed_wt = (bf16 && want.x).then(|| super::amx::PackedLhs::new(kd, o, weight, (1, kd)));
    // Per thread: its partial weight and bias gradients.
    type Partial = (Option<Vec<f32>>, Option<Vec<f32>>);
    let partials: Vec<Partial> = ranges
        .par_iter()
        .zip(dx_parts.into_par_iter())
        .map(|(&(a, b), mut dx_part)| {
            let mut dw = want.weight.then(|| vec![0f32; o * kd]);
            // bf16: dWᵀ [kd, cout], transposed into dw after the last piece.
            let mut dwt = (want.weight && bf16).then(|| vec![0f32; kd * o]);
            let mut db = want.bias.then(|| vec![0f32; o]);
            let need_cols = want.weight || want.x;
            let units = s.units(a, b);
            let cap = units.iter().map(|u| u.cols(s)).max().unwrap_or(0);
            with_scratch(if need_cols { kd * cap } else { 0 }, o * cap, |cols, dz| {
                for (ui, u) in units.into_iter().enumerate() {
                    let nc = u.cols(s);
                    let (off, len) = (u.rows.0 * wo, (u.rows.1 - u.rows.0) * wo);
                    let dz = &mut dz[..o * nc];
                    // Gather dy (masked by ReLU) into [cout, n·rows·W']; sum the bias gradient.
                    for i in 0..u.n {
                        let base = (u.i0 + i) * s.out_len();
                        for oc in 0..o {
                            let src = &dy[base + oc * p + off..][..len];
                            let dst = &mut dz[oc * nc + i * len..][..len];
                            match mask {
                                Some(y) => {
                                    let ys = &y[base + oc * p + off..][..len];
                                    for ((d, &g), &yv) in dst.iter_mut().zip(src).zip(ys) {
                                        *d = if yv > 0.0 { g } else { 0.0 };
                                    }
                                }
                                None => dst.copy_from_slice(src),
                            }
                            if let Some(db) = db.as_mut() {
                                db[oc] += dst.iter().sum::<f32>();
                            }
                        }
                    }
                    let xs = &x[u.i0 * s.in_len()..(u.i0 + u.n) * s.in_len()];
                    if let Some(dw) = dw.as_mut() {
                        let cols = &mut cols[..kd * nc];
                        im2col(s, xs, u.n, u.rows, cols);
                        if let Some(dwt) = dwt.as_mut() {
                            // dWᵀ [kd, cout] += cols [kd, nc] · dzᵀ [nc, cout]: the im2col matrix,
                            // the larger, is AMX's left operand, packed without a transpose.
                            matmul(Mul::Bf16(None), kd, o, nc, dwt, (o, 1), ui > 0, cols, (nc, 1), dz, (1, nc));
                        } else {
                            // dW [cout, kd] += dz [cout, nc] · colsᵀ [nc, kd]
                            matmul(Mul::F32, o, kd, nc, dw, (kd, 1), ui > 0, dz, (nc, 1), cols, (1, nc));
                        }
                    }
                    if let Some(dxp) = dx_part.as_deref_mut() {
                        let dcols = &mut cols[..kd * nc];
                        // dcols [kd, nc] = Wᵀ [kd, cout] · dz [cout, nc]
                        matmul(
                            Mul::new(bf16, packed_wt.as_ref()),
                            kd,
                            nc,
                            o,
                            dcols,
                            (nc, 1),
                            false,
                            weight,
                            (1, kd),
                            dz,
                            (nc, 1),
                        );
                        let lo = (u.i0 - a) * s.in_len();
                        col2im(s, dcols, u.n, u.rows, &mut dxp[lo..lo + u.n * s.in_len()]);
                    }
                }
            });
            if let (Some(dw), Some(dwt)) = (dw.as_mut(), dwt) {
                for (r, row) in dwt.chunks_exact(o).enumerate() {
                    for (c, &v) in row.iter().enumerate() {
                        dw[c * kd + r] = v;
                    }
                }
            }
            (dw, db)
        })
        .collect();
    // Sum the threads' partial gradients in thread order.
    let mut grads = Grads { x: dx, weight: None, bias: None };
    for (dw, db) in partials {
        sum_into(&mut grads.weight, dw);
        sum_into(&mut grads.bias, db);
    }
    if want.weight && grads.weight.is_none() {
        grads.weight = Some(vec![0f32; o * kd]);
    }
    if want.bias && grads.bias.is_none() {
        grads.bias = Some(vec![0f32; o]);
    }
    grads
}

fn sum_into(acc: &mut Option<Vec<f32>>, part: Option<Vec<f32>>) {
    match (acc.as_mut(), part) {
        (None, p) => *acc = p,
        (Some(a), Some(p)) => a.iter_mut().zip(p).for_each(|(a, p)| *a += p),
        (Some(_), None) => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct (seven-loop) convolution, the reference for the GEMM kernels.
    fn naive(s: &ConvShape, x: &[f32], w: &[f32], b: &[f32]) -> Vec<f32> {
        let (ho, wo) = (s.out_h(), s.out_w());
        let mut y = vec![0f32; s.batch * s.cout * ho * wo];
        for n in 0..s.batch {
            for o in 0..s.cout {
                for oy in 0..ho {
                    for ox in 0..wo {
                        let mut acc = b[o] as f64;
                        for c in 0..s.cin {
                            for ky in 0..s.k {
                                for kx in 0..s.k {
                                    let (iy, ix) =
                                        ((oy + ky) as isize - s.pad as isize, (ox + kx) as isize - s.pad as isize);
                                    if iy < 0 || ix < 0 || iy >= s.h as isize || ix >= s.w as isize {
                                        continue;
                                    }
                                    let xv = x[((n * s.cin + c) * s.h + iy as usize) * s.w + ix as usize] as f64;
                                    acc += xv * w[((o * s.cin + c) * s.k + ky) * s.k + kx] as f64;
                                }
                            }
                        }
                        y[((n * s.cout + o) * ho + oy) * wo + ox] = acc as f32;
                    }
                }
            }
        }
        y
    }

    fn values(n: usize, seed: u32) -> Vec<f32> {
        let mut state = seed.wrapping_mul(2_654_435_761).wrapping_add(1);
        (0..n)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state as f32 / u32::MAX as f32) * 2.0 - 1.0
            })
            .collect()
    }

    #[test]
    fn forward_matches_the_direct_convolution_with_padding_and_odd_sizes() {
        for &(batch, cin, h, w, cout, k, pad) in &[
            (3, 5, 7, 5, 6, 3, 1),
            (2, 4, 6, 6, 3, 3, 0),
            (1, 3, 1, 1, 4, 3, 1),
            (4, 7, 3, 3, 5, 1, 0),
            (2, 2, 3, 4, 3, 3, 0),
        ] {
            let s = ConvShape { batch, cin, h, w, cout, k, pad };
            let x = values(batch * cin * h * w, 1);
            let wt = values(cout * cin * k * k, 2);
            let b = values(cout, 3);
            let want = naive(&s, &x, &wt, &b);
            let mut y = vec![f32::NAN; want.len()];
            forward(&s, MatmulPrecision::F32, &x, &wt, &b, false, &mut y);
            for (a, e) in y.iter().zip(&want) {
                assert!((a - e).abs() <= 1e-5 * (1.0 + e.abs()), "{s:?}: {a} vs {e}");
            }
            forward(&s, MatmulPrecision::F32, &x, &wt, &b, true, &mut y);
            for (a, e) in y.iter().zip(&want) {
                assert!((a - e.max(0.0)).abs() <= 1e-5 * (1.0 + e.abs()), "{s:?} relu: {a} vs {e}");
            }
        }
    }

    #[test]
    fn im2col_and_col2im_are_adjoint() {
        // <im2col(x), c> = <x, col2im(c)> for random x and c.
        let s = ConvShape { batch: 2, cin: 3, h: 5, w: 4, cout: 1, k: 3, pad: 1 };
        let x = values(2 * 3 * 5 * 4, 4);
        let n = s.kdim() * 2 * s.out_pixels();
        let c = values(n, 5);
        let mut cols = vec![0f32; n];
        im2col(&s, &x, 2, (0, s.out_h()), &mut cols);
        let mut back = vec![0f32; x.len()];
        col2im(&s, &c, 2, (0, s.out_h()), &mut back);
        let lhs: f64 = cols.iter().zip(&c).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        let rhs: f64 = x.iter().zip(&back).map(|(a, b)| (*a as f64) * (*b as f64)).sum();
        assert!((lhs - rhs).abs() < 1e-4 * (1.0 + lhs.abs()), "{lhs} vs {rhs}");
    }
}
