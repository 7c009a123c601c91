//! The equivariant kernel basis solver: one generic construction for every pair of
//! representations and kernel sizes 1 and 3 (docs/paper.md §1.6, docs/architecture.md#equivariant-layers).
//!
//! A kernel `K: Z² → R^{d_out×d_in}` is equivariant when `K(g·x) = ρ_out(g) K(x) ρ_in(g)⁻¹` for all
//! `g`. We start from the band-limited template space `T` of scalar filters (3×3: the 6 functions
//! `δ_centre, R, R·cosφ, R·sinφ, R·cos2φ, R·sin2φ` with e2cnn's ring profile; 1×1: the centre only),
//! take `T ⊗ Hom(R^{d_in}, R^{d_out})` in template-coefficient coordinates, project it onto the
//! equivariant subspace with the group average
//! `Π(C) = 1/|G| Σ_g A(g) ⊗ ρ_out(g) C ρ_in(g)⁻¹` (`A(g)` = exact action on harmonic coefficients),
//! sample the image at the pixels and orthonormalise. This reproduces e2cnn's basis sizes (6 per
//! trivial→regular 3×3 pair, 48 per regular→regular 3×3 pair, intertwiners for 1×1).
//!
//! Limitations: kernel sizes 1 and 3 only (the template space of larger kernels is not defined
//! here); for groups with elements off the pixel grid (`C_8`'s 45° rotations) the constraint holds
//! exactly on the harmonic coefficients and the sampled kernel inherits it only approximately,
//! as in e2cnn.

use crate::repr::Representation;
use thiserror::Error;

/// Errors of the basis solver.
#[derive(Debug, Error)]
pub enum BasisError {
    /// Only 1×1 and 3×3 template spaces are defined.
    #[error("unsupported kernel size {0}: only 1 and 3 are implemented (docs/paper.md §1.6)")]
    KernelSize(usize),
    /// Input and output representations belong to different groups.
    #[error("representations of different groups: {0} and {1}")]
    GroupMismatch(String, String),
}

/// e2cnn's ring-1 Gaussian width σ = 0.4: the corner pixels (radius √2) get weight
/// `exp(−(√2−1)²/(2σ²))` relative to the edge pixels (radius 1).
const RING_SIGMA: f64 = 0.4;

/// An orthonormal basis of equivariant `k×k` kernels between two representations.
#[derive(Clone, Debug)]
pub struct KernelBasis {
    /// Kernel size k.
    pub size: usize,
    /// Output representation dimension.
    pub dim_out: usize,
    /// Input representation dimension.
    pub dim_in: usize,
    /// Number of basis elements.
    pub len: usize,
    /// Basis elements, `len × (dim_out·dim_in·k·k)`, element layout `[o][i][row][col]`.
    pub data: Vec<f64>,
}

impl KernelBasis {
    /// Size of one basis element.
    pub fn element_len(&self) -> usize {
        self.dim_out * self.dim_in * self.size * self.size
    }
}

/// Template sampling matrix `S[t][pixel]` for kernel size k (row-major pixels, row 0 on top).
fn templates(k: usize) -> Result<Vec<Vec<f64>>, BasisError> {
    match k {
        1 => Ok(vec![vec![1.0]]),
        3 => {
            let mut s = vec![vec![0.0; 9]; 6];
            s[0][4] = 1.0;
            for row in 0..3 {
                for col in 0..3 {
                    let x = col as f64 - 1.0;
                    let y = 1.0 - row as f64;
                    let r = (x * x + y * y).sqrt();
                    if r == 0.0 {
                        continue;
                    }
                    let ring = (-(r - 1.0).powi(2) / (2.0 * RING_SIGMA * RING_SIGMA)).exp();
                    let phi = y.atan2(x);
                    let p = row * 3 + col;
                    s[1][p] = ring;
                    s[2][p] = ring * phi.cos();
                    s[3][p] = ring * phi.sin();
                    s[4][p] = ring * (2.0 * phi).cos();
                    s[5][p] = ring * (2.0 * phi).sin();
                }
            }
            Ok(s)
        }
        other => Err(BasisError::KernelSize(other)),
    }
}

/// Modified Gram–Schmidt (applied twice for stability); drops vectors whose residual norm is
/// below the absolute tolerance `tol` (inputs are expected to be of order 1, e.g. projections of
/// unit vectors). Returns orthonormal vectors.
pub fn gram_schmidt(vectors: Vec<Vec<f64>>, tol: f64) -> Vec<Vec<f64>> {
    let mut out: Vec<Vec<f64>> = Vec::new();
    for mut v in vectors {
        for _ in 0..2 {
            for q in &out {
                let d: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
                for (a, b) in v.iter_mut().zip(q) {
                    *a -= d * b;
                }
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if norm > tol {
            v.iter_mut().for_each(|x| *x /= norm);
            out.push(v);
        }
    }
    out
}

type CacheKey = (crate::group::Group, String, String, usize);

/// Solve for an orthonormal basis of the equivariant `k×k` kernels from `rep_in` to `rep_out`.
/// Results are memoised per (group, representations, k) for the life of the process, so a
/// network with many layers of the same types solves each pair once.
pub fn kernel_basis(rep_in: &Representation, rep_out: &Representation, k: usize) -> Result<KernelBasis, BasisError> {
    use std::collections::HashMap;
    use std::sync::{Arc, Mutex, OnceLock};
    static CACHE: OnceLock<Mutex<HashMap<CacheKey, Arc<KernelBasis>>>> = OnceLock::new();
    let key = (rep_in.group(), rep_in.name().to_string(), rep_out.name().to_string(), k);
    let cache = CACHE.get_or_init(|| Mutex::new(HashMap::new()));
    if let Some(b) = cache.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
        return Ok((**b).clone());
    }
    let b = solve(rep_in, rep_out, k)?;
    cache.lock().unwrap_or_else(|e| e.into_inner()).insert(key, Arc::new(b.clone()));
    Ok(b)
}

fn solve(rep_in: &Representation, rep_out: &Representation, k: usize) -> Result<KernelBasis, BasisError> {
    if rep_in.group() != rep_out.group() {
        return Err(BasisError::GroupMismatch(rep_in.group().name(), rep_out.group().name()));
    }
    let group = rep_in.group();
    let samp = templates(k)?;
    let nt = samp.len();
    let (di, dout) = (rep_in.dim(), rep_out.dim());
    let dim = nt * dout * di;
    let els = group.elements();
    // Harmonic action restricted to the template space in use.
    let actions: Vec<Vec<f64>> = els
        .iter()
        .map(|&g| {
            let a = group.harmonic_action(g);
            (0..nt * nt).map(|x| a[x / nt][x % nt]).collect()
        })
        .collect();
    let inv_in: Vec<Vec<f64>> = els.iter().map(|&g| rep_in.matrix(group.inv(g)).to_vec()).collect();
    // Columns of the projector: Π e_(t', o', i').
    let inv_order = 1.0 / els.len() as f64;
    let mut cols = Vec::with_capacity(dim);
    for t2 in 0..nt {
        for o2 in 0..dout {
            for i2 in 0..di {
                let mut col = vec![0.0; dim];
                for (gi, &g) in els.iter().enumerate() {
                    let a = &actions[gi];
                    let ro = rep_out.matrix(g);
                    let ri = &inv_in[gi];
                    for t in 0..nt {
                        let at = a[t * nt + t2];
                        if at == 0.0 {
                            continue;
                        }
                        for o in 0..dout {
                            let ao = at * ro[o * dout + o2];
                            if ao == 0.0 {
                                continue;
                            }
                            let base = (t * dout + o) * di;
                            for i in 0..di {
                                col[base + i] += inv_order * ao * ri[i2 * di + i];
                            }
                        }
                    }
                }
                cols.push(col);
            }
        }
    }
    let coeff_basis = gram_schmidt(cols, 1e-8);
    // Sample at the pixels: K[o][i][p] = Σ_t S[t][p] C[t][o][i].
    let kk = k * k;
    let sampled: Vec<Vec<f64>> = coeff_basis
        .iter()
        .map(|c| {
            let mut kern = vec![0.0; dout * di * kk];
            for t in 0..nt {
                for oi in 0..dout * di {
                    let ct = c[t * dout * di + oi];
                    if ct != 0.0 {
                        for p in 0..kk {
                            kern[oi * kk + p] += ct * samp[t][p];
                        }
                    }
                }
            }
            kern
        })
        .collect();
    let n_coeff = sampled.len();
    let ortho = gram_schmidt(sampled, 1e-8);
    debug_assert_eq!(ortho.len(), n_coeff, "template sampling must be injective");
    Ok(KernelBasis { size: k, dim_out: dout, dim_in: di, len: ortho.len(), data: ortho.concat() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::group::{Group, act_pixel};

    fn count(a: &Representation, b: &Representation, k: usize) -> usize {
        kernel_basis(a, b, k).unwrap().len
    }

    #[test]
    fn basis_sizes_match_e2cnn() {
        for g in [Group::dihedral(4), Group::cyclic(8)] {
            let triv = Representation::trivial(g);
            let reg = Representation::regular(g);
            assert_eq!(count(&triv, &reg, 3), 6, "{} trivial→regular 3×3", g.name());
            assert_eq!(count(&reg, &reg, 3), 48, "{} regular→regular 3×3", g.name());
            assert_eq!(count(&reg, &reg, 1), g.order(), "{} regular→regular 1×1", g.name());
            assert_eq!(count(&triv, &triv, 1), 1);
            assert_eq!(count(&reg, &triv, 1), 1);
        }
        let g = Group::dihedral(4);
        let reg = Representation::regular(g);
        let std = Representation::irrep(g, 1, 1);
        let quo = Representation::quotient_by_rotations(g);
        let triv = Representation::trivial(g);
        // 1×1: regular → ρ has dim(ρ) params, ρ → regular dim(ρ); trivial → irrep(1,1) none.
        assert_eq!(count(&reg, &std, 1), 2);
        assert_eq!(count(&reg, &quo, 1), 2);
        assert_eq!(count(&std, &reg, 1), 2);
        assert_eq!(count(&quo, &reg, 1), 2);
        assert_eq!(count(&triv, &std, 1), 0);
        assert_eq!(count(&triv, &reg, 1), 1);
        // A 3×3 trivial→trivial D4-invariant kernel: centre, ring, and nothing else.
        assert_eq!(count(&triv, &triv, 3), 2);
        assert!(matches!(kernel_basis(&triv, &triv, 5), Err(BasisError::KernelSize(5))));
    }

    /// Every basis element satisfies `K(g·x) = ρ_out(g) K(x) ρ_in(g)⁻¹` on the pixel grid, and
    /// the elements are orthonormal.
    #[test]
    fn basis_elements_are_equivariant_and_orthonormal() {
        for g in [Group::dihedral(4), Group::cyclic(4), Group::dihedral(2), Group::cyclic(8)] {
            let reps = [
                Representation::trivial(g),
                Representation::regular(g),
                Representation::quotient_by_rotations(g),
                Representation::irrep(g, if g.is_dihedral() { 1 } else { 0 }, 1),
            ];
            for ri in &reps {
                for ro in &reps {
                    for k in [1, 3] {
                        let b = kernel_basis(ri, ro, k).unwrap();
                        let (di, dout, el) = (b.dim_in, b.dim_out, b.element_len());
                        for x in 0..b.len {
                            for y in 0..b.len {
                                let d: f64 = (0..el).map(|z| b.data[x * el + z] * b.data[y * el + z]).sum();
                                assert!((d - if x == y { 1.0 } else { 0.0 }).abs() < 1e-9);
                            }
                        }
                        for e in g.grid_elements() {
                            let rho_o = ro.matrix(e);
                            let rho_i_inv = ri.matrix(g.inv(e));
                            for x in 0..b.len {
                                let kern = &b.data[x * el..(x + 1) * el];
                                let at = |o: usize, i: usize, r: usize, c: usize| kern[((o * di + i) * k + r) * k + c];
                                for r in 0..k {
                                    for c in 0..k {
                                        let (r2, c2) = act_pixel(&g, e, k, r, c);
                                        for o in 0..dout {
                                            for i in 0..di {
                                                let lhs = at(o, i, r2, c2);
                                                let mut rhs = 0.0;
                                                for a in 0..dout {
                                                    for bb in 0..di {
                                                        rhs += rho_o[o * dout + a]
                                                            * at(a, bb, r, c)
                                                            * rho_i_inv[bb * di + i];
                                                    }
                                                }
                                                assert!(
                                                    (lhs - rhs).abs() < 1e-9,
                                                    "{} {} → {} k={k} {e:?}",
                                                    g.name(),
                                                    ri.name(),
                                                    ro.name()
                                                );
                                            }
                                        }
                                    }
                                }
                            }
                        }
                    }
                }
            }
        }
    }
}
