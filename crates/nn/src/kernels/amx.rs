//! `f32` GEMM through Intel AMX's bf16 tile multiply (`TDPBF16PS`), for the convolution kernels'
//! [`crate::kernels::MatmulPrecision::Bf16`].
//!
//! The operands are rounded to bfloat16 (round to nearest even: 8 significant bits, `f32`'s
//! exponent range) and multiplied with `f32` accumulation, as PyTorch's bf16 autocast does on the
//! same CPUs. Each call packs the left operand row-major `[M', K']` (or takes it packed beforehand,
//! [`PackedLhs`]: a convolution's weights, once for all the pieces of a batch) and the right one in
//! AMX's pair layout `[K'/2, N', 2]` (`M'`, `N'` rounded up to 16, `K'` to 32, zero-padded), with
//! AVX-512 BF16 conversions, multiplies 32×32 blocks with four accumulator tiles, and adds or
//! writes the result into the strided destination. Buffers are per thread and kept between calls.
//!
//! AMX needs the CPU (Sapphire Rapids or later: `CPUID.(7,0):EDX` bits 22 and 24) and the Linux
//! kernel's permission for the tile state (`arch_prctl(ARCH_REQ_XCOMP_PERM, XTILEDATA)`, Linux
//! 5.16+), both checked once by [`available`]. Without them nothing here runs.

use std::sync::OnceLock;

/// Rows of a tile, and its `f32` columns.
const T: usize = 16;
/// bf16 values along the inner dimension of one tile multiply.
const TK: usize = 32;

/// Whether this CPU and kernel let this process use AMX's bf16 tiles (asked once, then cached).
pub fn available() -> bool {
    static OK: OnceLock<bool> = OnceLock::new();
    *OK.get_or_init(detect)
}

#[cfg(all(target_arch = "x86_64", target_os = "linux"))]
fn detect() -> bool {
    use std::arch::x86_64::__cpuid_count;
    // Leaf 7 must exist before it is asked.
    let max_leaf = __cpuid_count(0, 0).eax;
    if max_leaf < 7 {
        return false;
    }
    let edx = __cpuid_count(7, 0).edx;
    let (bf16, tile) = (edx & (1 << 22) != 0, edx & (1 << 24) != 0);
    // The packing converts with AVX-512 BF16, which every AMX CPU has.
    let convert = std::arch::is_x86_feature_detected!("avx512bf16") && std::arch::is_x86_feature_detected!("avx512bw");
    if !(bf16 && tile && convert) {
        return false;
    }
    const ARCH_REQ_XCOMP_PERM: libc::c_long = 0x1023;
    const XFEATURE_XTILEDATA: libc::c_long = 18;
    // SAFETY: arch_prctl with ARCH_REQ_XCOMP_PERM only asks the kernel to allow the tile state for
    // this process; it reads and writes no memory of ours.
    let r = unsafe { libc::syscall(libc::SYS_arch_prctl, ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA) };
    r == 0
}

#[cfg(not(all(target_arch = "x86_64", target_os = "linux")))]
fn detect() -> bool {
    false
}

/// `f32` to bfloat16, rounding to nearest even (NaN stays NaN).
#[inline]
pub fn bf16(x: f32) -> u16 {
    let b = x.to_bits();
    if x.is_nan() {
        return ((b >> 16) | 0x40) as u16;
    }
    ((b + 0x7fff + ((b >> 16) & 1)) >> 16) as u16
}

/// bfloat16 back to `f32` (exact).
#[inline]
pub fn f32_of(h: u16) -> f32 {
    f32::from_bits((h as u32) << 16)
}

fn round_up(x: usize, to: usize) -> usize {
    x.div_ceil(to) * to
}

thread_local! {
    /// The packed left operand of [`matmul`], per thread.
    static LHS: std::cell::RefCell<Vec<u16>> = const { std::cell::RefCell::new(Vec::new()) };
    /// Packed right operand and the padded `f32` result, per thread.
    static BUFS: std::cell::RefCell<(Vec<u16>, Vec<f32>)> = const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

/// `lhs` (`m×k`, strides `(rs, cs)`) as bf16 row-major `[mp, kp]`, zero-padded.
fn pack_lhs(m: usize, k: usize, lhs: &[f32], (rs, cs): (usize, usize), kp: usize, out: &mut [u16]) {
    for r in 0..m {
        let row = &mut out[r * kp..][..kp];
        if cs == 1 {
            convert(&lhs[r * rs..][..k], &mut row[..k]);
        } else {
            for (c, d) in row[..k].iter_mut().enumerate() {
                *d = bf16(lhs[r * rs + c * cs]);
            }
        }
        row[k..].fill(0);
    }
    out[m * kp..].fill(0);
}

/// `src` to bf16 in `dst` (same length).
fn convert(src: &[f32], dst: &mut [u16]) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if available() {
        // SAFETY: available() checked AVX-512 BF16 and BW; the lengths are equal.
        done = unsafe { simd::convert(src, dst) };
    }
    for (d, &v) in dst[done..].iter_mut().zip(&src[done..]) {
        *d = bf16(v);
    }
}

/// `rhs` (`k×n`, strides `(rs, cs)`) in AMX's pair layout `[kp/2, np, 2]`: element `(kk, j)` at
/// `(kk/2)·2·np + 2·j + kk%2`, zero-padded.
fn pack_rhs(k: usize, n: usize, rhs: &[f32], (rs, cs): (usize, usize), np: usize, out: &mut [u16]) {
    let pairs = k / 2;
    if cs == 1 {
        // Row-major: rows 2p and 2p + 1 interleaved.
        for p in 0..pairs {
            let dst = &mut out[p * 2 * np..][..2 * np];
            interleave(&rhs[2 * p * rs..][..n], &rhs[(2 * p + 1) * rs..][..n], &mut dst[..2 * n]);
            dst[2 * n..].fill(0);
        }
    } else if rs == 1 {
        // Column-major: each column's consecutive pairs, transposed in blocks of 16 columns.
        let mut block = [0u32; 16 * 16];
        let mut col = [0u16; 32];
        for j0 in (0..n).step_by(16) {
            let w = (n - j0).min(16);
            for p0 in (0..pairs).step_by(16) {
                let h = (pairs - p0).min(16);
                for jj in 0..w {
                    convert(&rhs[(j0 + jj) * cs + 2 * p0..][..2 * h], &mut col[..2 * h]);
                    for t in 0..h {
                        block[t * 16 + jj] = col[2 * t] as u32 | (col[2 * t + 1] as u32) << 16;
                    }
                }
                for t in 0..h {
                    let dst = &mut out[(p0 + t) * 2 * np + 2 * j0..][..2 * w];
                    for (jj, d) in dst.chunks_exact_mut(2).enumerate() {
                        let v = block[t * 16 + jj];
                        d[0] = v as u16;
                        d[1] = (v >> 16) as u16;
                    }
                }
            }
        }
        for p in 0..pairs {
            out[p * 2 * np + 2 * n..][..2 * (np - n)].fill(0);
        }
    } else {
        for p in 0..pairs {
            for j in 0..n {
                out[p * 2 * np + 2 * j] = bf16(rhs[2 * p * rs + j * cs]);
                out[p * 2 * np + 2 * j + 1] = bf16(rhs[(2 * p + 1) * rs + j * cs]);
            }
            out[p * 2 * np + 2 * n..][..2 * (np - n)].fill(0);
        }
    }
    // An odd last row pairs with zeros; the pairs past k/2 are all zero.
    let rest = &mut out[pairs * 2 * np..];
    rest.fill(0);
    if k % 2 == 1 {
        for j in 0..n {
            rest[2 * j] = bf16(rhs[(k - 1) * rs + j * cs]);
        }
    }
}

/// `dst[2j] = bf16(a[j])`, `dst[2j + 1] = bf16(b[j])`.
fn interleave(a: &[f32], b: &[f32], dst: &mut [u16]) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if available() {
        // SAFETY: available() checked AVX-512 BF16 and BW; dst holds 2·a.len() values.
        done = unsafe { simd::interleave(a, b, dst) };
    }
    for j in done..a.len() {
        dst[2 * j] = bf16(a[j]);
        dst[2 * j + 1] = bf16(b[j]);
    }
}

/// AVX-512 BF16 conversions (`VCVTNE2PS2BF16`: round to nearest even; it treats denormal inputs as
/// zero, which the scalar [`bf16`] does not).
#[cfg(target_arch = "x86_64")]
mod simd {
    use std::arch::x86_64::*;

    /// Converts the first multiple of 32 of `src` into `dst`; returns how many.
    ///
    /// # Safety
    /// The CPU has AVX-512 F, BW and BF16; `dst.len() >= src.len()`.
    #[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
    pub unsafe fn convert(src: &[f32], dst: &mut [u16]) -> usize {
        let n = src.len() / 32 * 32;
        let mut i = 0;
        while i < n {
            // SAFETY: i + 32 <= n <= both lengths.
            unsafe {
                let lo = _mm512_loadu_ps(src.as_ptr().add(i));
                let hi = _mm512_loadu_ps(src.as_ptr().add(i + 16));
                let h = _mm512_cvtne2ps_pbh(hi, lo);
                _mm512_storeu_si512(
                    dst.as_mut_ptr().add(i) as *mut __m512i,
                    std::mem::transmute::<__m512bh, __m512i>(h),
                );
            }
            i += 32;
        }
        n
    }

    /// Interleaves the first multiple of 16 of `a` and `b` into `dst`; returns how many of each.
    ///
    /// # Safety
    /// The CPU has AVX-512 F, BW and BF16; `b.len() >= a.len()`, `dst.len() >= 2·a.len()`.
    #[target_feature(enable = "avx512f,avx512bw,avx512bf16")]
    pub unsafe fn interleave(a: &[f32], b: &[f32], dst: &mut [u16]) -> usize {
        let n = a.len() / 16 * 16;
        let idx = _mm512_set_epi16(
            31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17,
            1, 16, 0,
        );
        let mut j = 0;
        while j < n {
            // SAFETY: j + 16 <= n <= a.len() <= b.len(), and 2j + 32 <= dst.len().
            unsafe {
                let x = _mm512_loadu_ps(a.as_ptr().add(j));
                let y = _mm512_loadu_ps(b.as_ptr().add(j));
                let h = std::mem::transmute::<__m512bh, __m512i>(_mm512_cvtne2ps_pbh(y, x));
                _mm512_storeu_si512(dst.as_mut_ptr().add(2 * j) as *mut __m512i, _mm512_permutexvar_epi16(idx, h));
            }
            j += 16;
        }
        n
    }
}

/// The 64-byte tile configuration (palette 1): every one of the 8 tiles 16 rows of 64 bytes.
#[repr(C, align(64))]
struct TileConfig {
    palette: u8,
    start_row: u8,
    reserved: [u8; 14],
    colsb: [u16; 16],
    rows: [u8; 16],
}

const CONFIG: TileConfig = {
    let mut c = TileConfig { palette: 1, start_row: 0, reserved: [0; 14], colsb: [0; 16], rows: [0; 16] };
    let mut t = 0;
    while t < 8 {
        c.colsb[t] = 64;
        c.rows[t] = 16;
        t += 1;
    }
    c
};

/// `c [mp, np] = a [mp, kp] · b` with `b` packed by [`pack_rhs`]; `mp`, `np` multiples of 16, `kp`
/// of 32.
///
/// # Safety
/// AMX must be [`available`]; `a`, `b` and `c` must hold `mp·kp`, `kp·np` and `mp·np` values.
#[cfg(target_arch = "x86_64")]
unsafe fn tile_gemm(mp: usize, np: usize, kp: usize, a: &[u16], b: &[u16], c: &mut [f32]) {
    use std::arch::asm;
    debug_assert!(a.len() >= mp * kp && b.len() >= kp * np && c.len() >= mp * np);
    let (a_stride, b_stride, c_stride) = (kp * 2, np * 4, np * 4);
    // SAFETY (whole block): every tile load reads 16 rows of 64 bytes at the given stride from
    // inside `a` (rows i..i+16 of kp ≥ kk+32 columns) or `b` (pair-rows kk/2..kk/2+16 of np ≥ j+16
    // columns); every store writes 16 rows of 64 bytes inside `c`. The caller guarantees AMX.
    unsafe {
        asm!("ldtilecfg [{0}]", in(reg) &CONFIG as *const TileConfig, options(nostack, readonly));
        let mut i = 0;
        while i < mp {
            let two_m = i + 2 * T <= mp;
            let mut j = 0;
            while j < np {
                let two_n = j + 2 * T <= np;
                let a0 = a.as_ptr().add(i * kp);
                let a1 = a0.add(T * kp);
                let b0 = b.as_ptr().add(2 * j);
                let b1 = b0.add(2 * T);
                asm!("tilezero tmm0", "tilezero tmm1", "tilezero tmm2", "tilezero tmm3", options(nostack, nomem));
                // The inner loop over the inner dimension, 32 values a step, for the tiles given.
                macro_rules! steps {
                    ($kk:ident; $($line:literal),+; $($op:ident = $ptr:expr),+) => {{
                        let mut $kk = 0;
                        while $kk < kp {
                            asm!(
                                $($line),+,
                                $($op = in(reg) $ptr),+,
                                sa = in(reg) a_stride,
                                sb = in(reg) b_stride,
                                options(nostack, readonly),
                            );
                            $kk += TK;
                        }
                    }};
                }
                match (two_m, two_n) {
                    (true, true) => steps!(
                        kk;
                        "tileloadd tmm4, [{a0} + {sa}]",
                        "tileloadd tmm6, [{b0} + {sb}]",
                        "tileloadd tmm7, [{b1} + {sb}]",
                        "tdpbf16ps tmm0, tmm4, tmm6",
                        "tileloadd tmm5, [{a1} + {sa}]",
                        "tdpbf16ps tmm1, tmm4, tmm7",
                        "tdpbf16ps tmm2, tmm5, tmm6",
                        "tdpbf16ps tmm3, tmm5, tmm7";
                        a0 = a0.add(kk), a1 = a1.add(kk), b0 = b0.add(kk * np), b1 = b1.add(kk * np)
                    ),
                    (true, false) => steps!(
                        kk;
                        "tileloadd tmm4, [{a0} + {sa}]",
                        "tileloadd tmm6, [{b0} + {sb}]",
                        "tdpbf16ps tmm0, tmm4, tmm6",
                        "tileloadd tmm5, [{a1} + {sa}]",
                        "tdpbf16ps tmm2, tmm5, tmm6";
                        a0 = a0.add(kk), a1 = a1.add(kk), b0 = b0.add(kk * np)
                    ),
                    (false, true) => steps!(
                        kk;
                        "tileloadd tmm4, [{a0} + {sa}]",
                        "tileloadd tmm6, [{b0} + {sb}]",
                        "tileloadd tmm7, [{b1} + {sb}]",
                        "tdpbf16ps tmm0, tmm4, tmm6",
                        "tdpbf16ps tmm1, tmm4, tmm7";
                        a0 = a0.add(kk), b0 = b0.add(kk * np), b1 = b1.add(kk * np)
                    ),
                    (false, false) => steps!(
                        kk;
                        "tileloadd tmm4, [{a0} + {sa}]",
                        "tileloadd tmm6, [{b0} + {sb}]",
                        "tdpbf16ps tmm0, tmm4, tmm6";
                        a0 = a0.add(kk), b0 = b0.add(kk * np)
                    ),
                }
                let c00 = c.as_mut_ptr().add(i * np + j);
                asm!("tilestored [{c} + {s}], tmm0", c = in(reg) c00, s = in(reg) c_stride, options(nostack));
                if two_n {
                    asm!("tilestored [{c} + {s}], tmm1", c = in(reg) c00.add(T), s = in(reg) c_stride, options(nostack));
                }
                if two_m {
                    let c10 = c00.add(T * np);
                    asm!("tilestored [{c} + {s}], tmm2", c = in(reg) c10, s = in(reg) c_stride, options(nostack));
                    if two_n {
                        asm!("tilestored [{c} + {s}], tmm3", c = in(reg) c10.add(T), s = in(reg) c_stride, options(nostack));
                    }
                }
                j += if two_n { 2 * T } else { T };
            }
            i += if two_m { 2 * T } else { T };
        }
        asm!("tilerelease", options(nostack, nomem));
    }
}

#[cfg(not(target_arch = "x86_64"))]
unsafe fn tile_gemm(_: usize, _: usize, _: usize, _: &[u16], _: &[u16], _: &mut [f32]) {
    unreachable!("AMX is x86_64 only");
}

/// A left operand packed once for several products (a convolution's weights, the same for every
/// piece of a batch).
#[derive(Clone, Debug)]
pub struct PackedLhs {
    m: usize,
    k: usize,
    data: Vec<u16>,
}

impl PackedLhs {
    /// `lhs` (`m×k`, strides `(rs, cs)` in floats) packed for [`matmul_packed`].
    ///
    /// # Panics
    /// When a stride reaches outside `lhs`.
    pub fn new(m: usize, k: usize, lhs: &[f32], strides: (usize, usize)) -> Self {
        Self::new_in(Vec::new(), m, k, lhs, strides)
    }

    /// [`PackedLhs::new`] in the storage of `data` (its contents are overwritten).
    fn new_in(mut data: Vec<u16>, m: usize, k: usize, lhs: &[f32], strides: (usize, usize)) -> Self {
        if m > 0 && k > 0 {
            assert!((m - 1) * strides.0 + (k - 1) * strides.1 < lhs.len(), "amx lhs out of bounds");
        }
        let (mp, kp) = (round_up(m.max(1), T), round_up(k.max(1), TK));
        data.resize(mp * kp, 0);
        data.truncate(mp * kp);
        pack_lhs(m, k, lhs, strides, kp, &mut data);
        PackedLhs { m, k, data }
    }
}

/// `dst (m×n) = [dst +] lhs (m×k) · rhs (k×n)` in bf16 with `f32` accumulation, strides in floats
/// as [`crate::kernels::gemm_conv`]'s GEMM takes them.
///
/// # Panics
/// When AMX is not [`available`], or a stride reaches outside its slice.
#[allow(clippy::too_many_arguments)]
pub fn matmul(
    m: usize,
    n: usize,
    k: usize,
    dst: &mut [f32],
    dst_strides: (usize, usize),
    accumulate: bool,
    lhs: &[f32],
    lhs_strides: (usize, usize),
    rhs: &[f32],
    rhs_strides: (usize, usize),
) {
    // The packed operand's storage is this thread's, kept between calls.
    let buf = LHS.with(|cell| std::mem::take(&mut *cell.borrow_mut()));
    let a = PackedLhs::new_in(buf, m, k, lhs, lhs_strides);
    matmul_packed(&a, n, dst, dst_strides, accumulate, rhs, rhs_strides);
    LHS.with(|cell| *cell.borrow_mut() = a.data);
}

/// [`matmul`] with a left operand packed beforehand.
///
/// # Panics
/// When AMX is not [`available`], or a stride reaches outside its slice.
pub fn matmul_packed(
    a: &PackedLhs,
    n: usize,
    dst: &mut [f32],
    (dst_rs, dst_cs): (usize, usize),
    accumulate: bool,
    rhs: &[f32],
    rhs_strides: (usize, usize),
) {
    assert!(available(), "AMX bf16 GEMM called on a CPU or kernel without AMX");
    let (m, k) = (a.m, a.k);
    if m == 0 || n == 0 {
        return;
    }
    assert!((m - 1) * dst_rs + (n - 1) * dst_cs < dst.len(), "amx dst out of bounds");
    if k > 0 {
        assert!((k - 1) * rhs_strides.0 + (n - 1) * rhs_strides.1 < rhs.len(), "amx rhs out of bounds");
    }
    let (mp, np, kp) = (round_up(m, T), round_up(n, T), round_up(k.max(1), TK));
    BUFS.with(|cell| {
        let mut bufs = cell.borrow_mut();
        let (b, c) = &mut *bufs;
        if b.len() < kp * np {
            b.resize(kp * np, 0);
        }
        if c.len() < mp * np {
            c.resize(mp * np, 0.0);
        }
        let (b, c) = (&mut b[..kp * np], &mut c[..mp * np]);
        pack_rhs(k, n, rhs, rhs_strides, np, b);
        // SAFETY: available() was asserted; the buffers have the sizes tile_gemm reads and writes.
        unsafe { tile_gemm(mp, np, kp, &a.data, b, c) };
        for r in 0..m {
            let src = &c[r * np..][..n];
            if dst_cs == 1 {
                let d = &mut dst[r * dst_rs..][..n];
                if accumulate {
                    d.iter_mut().zip(src).for_each(|(d, s)| *d += s);
                } else {
                    d.copy_from_slice(src);
                }
            } else {
                for (j, &v) in src.iter().enumerate() {
                    let d = &mut dst[r * dst_rs + j * dst_cs];
                    *d = if accumulate { *d + v } else { v };
                }
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bf16_rounds_to_nearest_even() {
        assert_eq!(bf16(1.0), 0x3f80);
        assert_eq!(f32_of(bf16(1.0)), 1.0);
        // 1 + 2^-8 is halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1.0).
        assert_eq!(f32_of(bf16(1.0 + 2f32.powi(-8))), 1.0);
        // 1 + 3·2^-8 is halfway between 1 + 2^-7 and 1 + 2^-6: to 1 + 2^-6 (even).
        assert_eq!(f32_of(bf16(1.0 + 3.0 * 2f32.powi(-8))), 1.0 + 2f32.powi(-6));
        assert_eq!(f32_of(bf16(-2.5)), -2.5);
        assert!(f32_of(bf16(f32::NAN)).is_nan());
        assert_eq!(f32_of(bf16(f32::INFINITY)), f32::INFINITY);
    }

    /// `dst = [dst +] lhs · rhs` in f64 over the operands rounded to bf16, and Σ|a·b| per entry.
    #[allow(clippy::too_many_arguments)]
    fn reference(
        m: usize,
        n: usize,
        k: usize,
        lhs: &[f32],
        (lrs, lcs): (usize, usize),
        rhs: &[f32],
        (rrs, rcs): (usize, usize),
    ) -> (Vec<f64>, Vec<f64>) {
        let (mut out, mut mag) = (vec![0f64; m * n], vec![0f64; m * n]);
        for r in 0..m {
            for c in 0..n {
                for i in 0..k {
                    let p = f32_of(bf16(lhs[r * lrs + i * lcs])) as f64 * f32_of(bf16(rhs[i * rrs + c * rcs])) as f64;
                    out[r * n + c] += p;
                    mag[r * n + c] += p.abs();
                }
            }
        }
        (out, mag)
    }

    #[test]
    fn matmul_matches_the_bf16_reference_for_every_layout_and_edge() {
        if !available() {
            eprintln!("no AMX on this machine: the tile GEMM is not run (the packing tests still are)");
            return;
        }
        let init = crate::init::Init::new(7);
        // Shapes below, at and above the 16 / 32 tile edges, and k below one tile step.
        for &(m, n, k) in
            &[(1, 1, 1), (16, 16, 32), (17, 33, 31), (32, 32, 64), (48, 20, 100), (5, 70, 300), (64, 144, 37)]
        {
            let lhs = init.uniform(&format!("lhs{m}x{k}"), m * k + 3, 1.0);
            let rhs = init.uniform(&format!("rhs{k}x{n}"), k * n + 3, 1.0);
            for (ls, rs) in [((k, 1), (n, 1)), ((1, m), (1, k)), ((k, 1), (1, k))] {
                let (want, mag) = reference(m, n, k, &lhs, ls, &rhs, rs);
                // Row-major with two spare columns, and column-major with two spare rows.
                for (accumulate, transposed) in [(false, false), (true, false), (false, true), (true, true)] {
                    let (ds, len) = if transposed { ((1, m + 2), (m + 2) * n) } else { ((n + 2, 1), m * (n + 2)) };
                    let mut dst: Vec<f32> = (0..len).map(|i| i as f32 * 0.5).collect();
                    let before = dst.clone();
                    matmul(m, n, k, &mut dst, ds, accumulate, &lhs, ls, &rhs, rs);
                    // The same product with the left operand packed beforehand, used twice.
                    let packed = PackedLhs::new(m, k, &lhs, ls);
                    for _ in 0..2 {
                        let mut again = before.clone();
                        matmul_packed(&packed, n, &mut again, ds, accumulate, &rhs, rs);
                        assert_eq!(again, dst, "({m}, {n}, {k}) {ls:?} {rs:?} {ds:?}: packed beforehand");
                    }
                    for (i, (&got, &was)) in dst.iter().zip(&before).enumerate() {
                        let (r, c) = if transposed { (i % (m + 2), i / (m + 2)) } else { (i / (n + 2), i % (n + 2)) };
                        let (got, was) = (got as f64, was as f64);
                        if r >= m || c >= n {
                            assert_eq!(got, was, "padding of the destination touched");
                            continue;
                        }
                        let base = if accumulate { was } else { 0.0 };
                        let e = (got - base - want[r * n + c]).abs();
                        // Products of bf16 values are exact in f32; only the f32 sums round.
                        let tol = 1e-6 * (mag[r * n + c] + base.abs()) + 1e-6;
                        assert!(
                            e <= tol,
                            "({m}, {n}, {k}) {ls:?} {rs:?} {ds:?} acc {accumulate}: ({r}, {c}) off by {e:e}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn packing_puts_each_element_where_the_tiles_read_it() {
        // Small (scalar paths) and past 16 / 32 (the vector and blocked paths), odd k.
        for (m, k, n, mp, kp, np) in [(3, 5, 4, 16, 32, 16), (18, 37, 35, 32, 64, 48)] {
            // Distinct values that bf16 holds exactly (8 significant bits).
            let exact = |i: usize| (i % 128) as f32 * 2f32.powi((i / 128) as i32);
            let lhs: Vec<f32> = (0..m * k).map(exact).collect();
            for strides in [(1, m), (k, 1)] {
                let mut a = vec![7u16; mp * kp];
                pack_lhs(m, k, &lhs, strides, kp, &mut a);
                for r in 0..mp {
                    for c in 0..kp {
                        let want = if r < m && c < k { lhs[r * strides.0 + c * strides.1] } else { 0.0 };
                        assert_eq!(f32_of(a[r * kp + c]), want, "lhs ({r}, {c}) {strides:?}");
                    }
                }
            }
            let rhs: Vec<f32> = (0..k * n).map(exact).collect();
            for strides in [(n, 1), (1, k)] {
                let mut b = vec![7u16; kp * np];
                pack_rhs(k, n, &rhs, strides, np, &mut b);
                for kk in 0..kp {
                    for j in 0..np {
                        let want = if kk < k && j < n { rhs[kk * strides.0 + j * strides.1] } else { 0.0 };
                        assert_eq!(f32_of(b[(kk / 2) * 2 * np + 2 * j + kk % 2]), want, "rhs ({kk}, {j}) {strides:?}");
                    }
                }
            }
        }
    }
}
