//! Real representations of `C_n` / `D_n` and field types (direct sums of representations), the
//! way e2cnn's `FieldType` describes the channels of a feature map.
//!
//! Representations provided: trivial, regular, the irreducibles of `C_n` and `D_n` (including the
//! 2-dim standard rep `irrep(1,1)`), and permutation representations on the cosets of a subgroup
//! (quotient representations; `D_n / C_n` is e2cnn's `quotient_repr((None, n))`, which equals
//! trivial ⊕ sign). Matrices are stored densely in `f64`; fine for the small groups used here
//! (|G| ≤ 16 in practice), not meant for large groups.

use crate::group::{Element, Group};
use std::f64::consts::PI;

/// A real orthogonal representation `ρ: G → O(d)`, stored as one `d×d` row-major matrix per
/// group element (in [`Group::elements`] order).
#[derive(Clone, Debug)]
pub struct Representation {
    group: Group,
    name: String,
    dim: usize,
    /// Whether every matrix is a permutation matrix (then pointwise maps such as ReLU and
    /// max-pooling commute with the action).
    permutation: bool,
    mats: Vec<Vec<f64>>,
}

impl PartialEq for Representation {
    fn eq(&self, other: &Self) -> bool {
        self.group == other.group && self.name == other.name
    }
}

impl Representation {
    fn from_fn(group: Group, name: String, dim: usize, permutation: bool, f: impl Fn(Element) -> Vec<f64>) -> Self {
        let mats = group.elements().into_iter().map(f).collect();
        Representation { group, name, dim, permutation, mats }
    }

    /// The trivial representation (dimension 1).
    pub fn trivial(group: Group) -> Self {
        Self::from_fn(group, "trivial".into(), 1, true, |_| vec![1.0])
    }

    /// The regular representation (dimension |G|): `ρ(g) e_h = e_{gh}`, i.e. `(g·f)(h) = f(g⁻¹h)`.
    pub fn regular(group: Group) -> Self {
        let els = group.elements();
        let d = els.len();
        Self::from_fn(group, "regular".into(), d, true, |g| {
            let mut m = vec![0.0; d * d];
            for &h in &els {
                m[group.index(group.mul(g, h)) * d + group.index(h)] = 1.0;
            }
            m
        })
    }

    /// Permutation representation on the left cosets `gH` of the subgroup `H` given by its elements
    /// (which must form a subgroup containing the identity). Coset order: by first appearance in
    /// [`Group::elements`].
    pub fn quotient(group: Group, subgroup: &[Element], name: &str) -> Self {
        let els = group.elements();
        // coset representatives
        let mut coset_of = vec![usize::MAX; els.len()];
        let mut ncos = 0;
        for &g in &els {
            if coset_of[group.index(g)] != usize::MAX {
                continue;
            }
            for &h in subgroup {
                coset_of[group.index(group.mul(g, h))] = ncos;
            }
            ncos += 1;
        }
        let reps: Vec<Element> = (0..ncos).map(|c| els[coset_of.iter().position(|&x| x == c).unwrap()]).collect();
        Self::from_fn(group, format!("quotient({name})"), ncos, true, |g| {
            let mut m = vec![0.0; ncos * ncos];
            for (c, &r) in reps.iter().enumerate() {
                m[coset_of[group.index(group.mul(g, r))] * ncos + c] = 1.0;
            }
            m
        })
    }

    /// `D_n / C_n`: rotations act as the identity, mirrors swap the two channels (e2cnn's
    /// `quotient_repr((None, n))`, the paper's "signed" representation: trivial ⊕ sign).
    /// For a cyclic group this is the trivial action on 1 coset.
    pub fn quotient_by_rotations(group: Group) -> Self {
        let rots: Vec<Element> = (0..group.n()).map(|rot| Element { flip: 0, rot }).collect();
        Self::quotient(group, &rots, &format!("C{}", group.n()))
    }

    /// Irreducible representation. For `D_n`, `irrep(j, k)` with `j ∈ {0,1}` the flip frequency
    /// and `0 ≤ k ≤ n/2` the rotation frequency (e2cnn's naming): `(0,0)` trivial, `(1,0)` the
    /// sign rep (mirrors ↦ −1), `(1,k)` for `0<k<n/2` 2-dim with rotations ↦ `Rot(2πk·r/n)` and the
    /// mirror ↦ `diag(1,−1)`, and for even n the 1-dim `(j, n/2)`. For `C_n`, `j` must be 0:
    /// `(0,0)` trivial, `(0,k)` 2-dim rotation by `k`, `(0,n/2)` the alternating sign for even n.
    pub fn irrep(group: Group, j: u8, k: usize) -> Self {
        let n = group.n();
        assert!(k * 2 <= n, "irrep frequency k={k} must be at most n/2={}", n / 2);
        assert!(j <= 1 && (group.is_dihedral() || j == 0), "invalid irrep j={j} for {}", group.name());
        let name = format!("irrep({j},{k})");
        let one_dim = k == 0 || 2 * k == n;
        if one_dim {
            // 1-dim: rotation sign (−1)^r if k = n/2 > 0, mirror sign (−1)^j.
            Self::from_fn(group, name, 1, false, move |g| {
                let rot_sign = if k > 0 && g.rot % 2 == 1 { -1.0 } else { 1.0 };
                let flip_sign = if j == 1 && g.flip == 1 { -1.0 } else { 1.0 };
                vec![rot_sign * flip_sign]
            })
        } else {
            if group.is_dihedral() {
                assert!(j == 1, "2-dim irreps of D_n are irrep(1,k)");
            }
            Self::from_fn(group, name, 2, false, move |g| {
                let a = 2.0 * PI * (k * g.rot) as f64 / n as f64;
                let (s, c) = a.sin_cos();
                let f = if g.flip == 1 { -1.0 } else { 1.0 };
                // Rot(a) · diag(1, f)
                vec![c, -s * f, s, c * f]
            })
        }
    }

    /// The group.
    pub fn group(&self) -> Group {
        self.group
    }

    /// Name, e.g. `regular`, `irrep(1,1)`.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Dimension d.
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Whether all matrices are permutations (pointwise nonlinearities commute with them).
    pub fn is_permutation(&self) -> bool {
        self.permutation
    }

    /// `ρ(g)` as a `d×d` row-major matrix.
    pub fn matrix(&self, g: Element) -> &[f64] {
        &self.mats[self.group.index(g)]
    }

    /// Orthonormal basis (columns, `d×m` row-major) of the invariant vectors `{v: ρ(g)v = v ∀g}`;
    /// `m` is the multiplicity of the trivial irrep. Biases live in this subspace.
    pub fn invariant_basis(&self) -> (usize, Vec<f64>) {
        let d = self.dim;
        // Projector P = mean_g ρ(g); Gram–Schmidt on its columns.
        let mut p = vec![0.0; d * d];
        for m in &self.mats {
            for (a, b) in p.iter_mut().zip(m) {
                *a += b / self.mats.len() as f64;
            }
        }
        let cols: Vec<Vec<f64>> = (0..d).map(|j| (0..d).map(|i| p[i * d + j]).collect()).collect();
        let basis = crate::basis::gram_schmidt(cols, 1e-9);
        let m = basis.len();
        let mut out = vec![0.0; d * m];
        for (j, v) in basis.iter().enumerate() {
            for i in 0..d {
                out[i * m + j] = v[i];
            }
        }
        (m, out)
    }
}

/// A field type: a direct sum of representations of one group, one per field, in channel order.
#[derive(Clone, Debug, PartialEq)]
pub struct FieldType {
    group: Group,
    reps: Vec<Representation>,
}

/// A maximal run of consecutive fields with the same representation.
#[derive(Clone, Debug)]
pub struct FieldRun {
    /// The shared representation.
    pub rep: Representation,
    /// Number of fields in the run.
    pub count: usize,
    /// First channel of the run.
    pub offset: usize,
}

impl FieldType {
    /// A field type from a list of representations (all of `group`).
    pub fn new(group: Group, reps: Vec<Representation>) -> Self {
        assert!(reps.iter().all(|r| r.group == group), "all fields must share one group");
        FieldType { group, reps }
    }

    /// `count` copies of `rep`.
    pub fn repeat(rep: Representation, count: usize) -> Self {
        FieldType { group: rep.group, reps: vec![rep; count] }
    }

    /// `count` trivial fields.
    pub fn trivial(group: Group, count: usize) -> Self {
        Self::repeat(Representation::trivial(group), count)
    }

    /// `count` regular fields.
    pub fn regular(group: Group, count: usize) -> Self {
        Self::repeat(Representation::regular(group), count)
    }

    /// Direct sum (concatenation of fields): `self ⊕ other`.
    pub fn concat(&self, other: &FieldType) -> FieldType {
        assert_eq!(self.group, other.group, "field types of different groups");
        let mut reps = self.reps.clone();
        reps.extend(other.reps.iter().cloned());
        FieldType { group: self.group, reps }
    }

    /// The group.
    pub fn group(&self) -> Group {
        self.group
    }

    /// The representations, one per field.
    pub fn reps(&self) -> &[Representation] {
        &self.reps
    }

    /// Number of fields.
    pub fn num_fields(&self) -> usize {
        self.reps.len()
    }

    /// Number of channels (sum of field dimensions).
    pub fn size(&self) -> usize {
        self.reps.iter().map(|r| r.dim).sum()
    }

    /// Whether every field is a permutation representation.
    pub fn is_permutation(&self) -> bool {
        self.reps.iter().all(|r| r.permutation)
    }

    /// Maximal runs of identical consecutive representations.
    pub fn runs(&self) -> Vec<FieldRun> {
        let mut runs: Vec<FieldRun> = Vec::new();
        let mut offset = 0;
        for r in &self.reps {
            match runs.last_mut() {
                Some(last) if last.rep == *r => last.count += 1,
                _ => runs.push(FieldRun { rep: r.clone(), count: 1, offset }),
            }
            offset += r.dim;
        }
        runs
    }

    /// The block-diagonal matrix `⊕ρ_i(g)` on all channels (`size×size`, row major).
    pub fn matrix(&self, g: Element) -> Vec<f64> {
        let c = self.size();
        let mut m = vec![0.0; c * c];
        let mut off = 0;
        for r in &self.reps {
            let d = r.dim;
            let rm = r.matrix(g);
            for i in 0..d {
                for j in 0..d {
                    m[(off + i) * c + off + j] = rm[i * d + j];
                }
            }
            off += d;
        }
        m
    }

    /// Short description, e.g. `D4[64×regular, 2×trivial, 1×irrep(1,1)]`.
    pub fn describe(&self) -> String {
        let parts: Vec<String> = self.runs().iter().map(|r| format!("{}×{}", r.count, r.rep.name)).collect();
        format!("{}[{}]", self.group.name(), parts.join(", "))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn matmul(a: &[f64], b: &[f64], d: usize) -> Vec<f64> {
        let mut c = vec![0.0; d * d];
        for i in 0..d {
            for k in 0..d {
                for j in 0..d {
                    c[i * d + j] += a[i * d + k] * b[k * d + j];
                }
            }
        }
        c
    }

    fn all_reps(g: Group) -> Vec<Representation> {
        let mut v =
            vec![Representation::trivial(g), Representation::regular(g), Representation::quotient_by_rotations(g)];
        let n = g.n();
        for k in 0..=n / 2 {
            if g.is_dihedral() {
                if k == 0 || 2 * k == n {
                    v.push(Representation::irrep(g, 0, k));
                }
                v.push(Representation::irrep(g, 1, k));
            } else {
                v.push(Representation::irrep(g, 0, k));
            }
        }
        v
    }

    #[test]
    fn representations_are_orthogonal_homomorphisms() {
        for n in [1usize, 2, 4, 8] {
            for g in [Group::cyclic(n), Group::dihedral(n)] {
                for r in all_reps(g) {
                    let d = r.dim();
                    for a in g.elements() {
                        let ma = r.matrix(a);
                        // orthogonal: M Mᵀ = I
                        let mt: Vec<f64> = (0..d * d).map(|i| ma[(i % d) * d + i / d]).collect();
                        let id = matmul(ma, &mt, d);
                        for i in 0..d {
                            for j in 0..d {
                                let e = if i == j { 1.0 } else { 0.0 };
                                assert!((id[i * d + j] - e).abs() < 1e-12);
                            }
                        }
                        for b in g.elements() {
                            let lhs = r.matrix(g.mul(a, b));
                            let rhs = matmul(ma, r.matrix(b), d);
                            for (x, y) in lhs.iter().zip(&rhs) {
                                assert!((x - y).abs() < 1e-12, "{} {} {a:?} {b:?}", g.name(), r.name());
                            }
                        }
                    }
                }
            }
        }
    }

    /// Character orthogonality: the irreps listed are pairwise inequivalent and irreducible, and
    /// their dimensions satisfy Σ d² = |G| (the list is complete for absolutely irreducible reps).
    #[test]
    fn irreps_are_complete_and_irreducible() {
        for n in [1usize, 2, 4, 8] {
            for g in [Group::cyclic(n), Group::dihedral(n)] {
                let irreps: Vec<Representation> = all_reps(g).into_iter().skip(3).collect();
                let chi = |r: &Representation| -> Vec<f64> {
                    g.elements().iter().map(|&e| (0..r.dim()).map(|i| r.matrix(e)[i * r.dim() + i]).sum()).collect()
                };
                for (i, a) in irreps.iter().enumerate() {
                    for (j, b) in irreps.iter().enumerate() {
                        let ip: f64 = chi(a).iter().zip(chi(b)).map(|(x, y)| x * y).sum::<f64>() / g.order() as f64;
                        if i == j {
                            // real 2-dim irreps of C_n are not absolutely irreducible: ⟨χ,χ⟩ = 2
                            let expect = if !g.is_dihedral() && a.dim() == 2 { 2.0 } else { 1.0 };
                            assert!((ip - expect).abs() < 1e-9, "{} {}", g.name(), a.name());
                        } else {
                            assert!(ip.abs() < 1e-9, "{} {} {}", g.name(), a.name(), b.name());
                        }
                    }
                }
                if g.is_dihedral() {
                    let s: usize = irreps.iter().map(|r| r.dim() * r.dim()).sum();
                    assert_eq!(s, g.order(), "{}", g.name());
                }
            }
        }
    }

    #[test]
    fn quotient_of_d4_by_c4_is_trivial_plus_sign() {
        let g = Group::dihedral(4);
        let q = Representation::quotient_by_rotations(g);
        assert_eq!(q.dim(), 2);
        for e in g.elements() {
            let m = q.matrix(e);
            let expect = if e.flip == 1 { [0.0, 1.0, 1.0, 0.0] } else { [1.0, 0.0, 0.0, 1.0] };
            assert_eq!(m, &expect);
        }
        let (m, _) = q.invariant_basis();
        assert_eq!(m, 1);
        assert_eq!(Representation::regular(g).invariant_basis().0, 1);
        assert_eq!(Representation::irrep(g, 1, 1).invariant_basis().0, 0);
    }

    #[test]
    fn standard_irrep_matches_paper_action_convention() {
        // docs/paper.md §1.3: rot90 ⇒ (dx,dy) → (−dy,dx); mirror ⇒ (dx,dy) → (dx,−dy).
        let g = Group::dihedral(4);
        let r = Representation::irrep(g, 1, 1);
        let m = r.matrix(Element { flip: 0, rot: 1 });
        let v = [m[0] * 1.0 + m[1] * 2.0, m[2] * 1.0 + m[3] * 2.0];
        assert!((v[0] + 2.0).abs() < 1e-12 && (v[1] - 1.0).abs() < 1e-12);
        let m = r.matrix(Element { flip: 1, rot: 0 });
        let v = [m[0] * 1.0 + m[1] * 2.0, m[2] * 1.0 + m[3] * 2.0];
        assert!((v[0] - 1.0).abs() < 1e-12 && (v[1] + 2.0).abs() < 1e-12);
    }

    #[test]
    fn field_type_runs_and_sizes() {
        let g = Group::dihedral(4);
        let t = FieldType::regular(g, 3)
            .concat(&FieldType::trivial(g, 2))
            .concat(&FieldType::repeat(Representation::irrep(g, 1, 1), 1));
        assert_eq!(t.size(), 24 + 2 + 2);
        let runs = t.runs();
        assert_eq!(runs.len(), 3);
        assert_eq!((runs[1].count, runs[1].offset), (2, 24));
        assert_eq!(runs[2].offset, 26);
        assert!(!t.is_permutation());
    }
}
