//! Finite planar symmetry groups: cyclic `C_n` and dihedral `D_n`, their action on the plane, on
//! harmonic template coefficients and on the pixel grid.
//!
//! Conventions (docs/paper.md §1.3, §1.6): plane coordinates are x = column → right, y = up. An element
//! is `(f, k)` with `f ∈ {0, 1}` (always 0 for `C_n`) and `k ∈ Z_n`; it acts on the plane as
//! `Rot(2πk/n) ∘ Flip^f`, where `Flip` mirrors about the vertical image axis (x → −x, e2cnn's
//! `axis = π/2`). Multiplication: `(f₁,k₁)(f₂,k₂) = (f₁⊕f₂, k₁ + (−1)^{f₁} k₂ mod n)`.
//!
//! Limitations: only rotations by multiples of 90° and the mirror map the square pixel grid onto
//! itself, so [`Group::acts_on_grid`] is false for elements such as the 45° rotation of `C_8`; such
//! elements act exactly on template coefficients (see [`Group::harmonic_action`]) but not on images.

use std::f64::consts::PI;

/// A group element `(flip, rot)`: the plane map `Rot(2π·rot/n) ∘ Flip^flip`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Element {
    /// 1 if the element contains the mirror, else 0.
    pub flip: u8,
    /// Rotation index in `0..n`.
    pub rot: usize,
}

/// Cyclic `C_n` (rotations only) or dihedral `D_n` (rotations and mirrors), `n ≥ 1`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Group {
    n: usize,
    dihedral: bool,
}

impl Group {
    /// The cyclic group `C_n` of order n.
    pub fn cyclic(n: usize) -> Self {
        assert!(n >= 1, "C_n needs n >= 1");
        Group { n, dihedral: false }
    }

    /// The dihedral group `D_n` of order 2n.
    pub fn dihedral(n: usize) -> Self {
        assert!(n >= 1, "D_n needs n >= 1");
        Group { n, dihedral: true }
    }

    /// Number of rotations n.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Whether the group contains mirrors.
    pub fn is_dihedral(&self) -> bool {
        self.dihedral
    }

    /// Group order |G|.
    pub fn order(&self) -> usize {
        if self.dihedral { 2 * self.n } else { self.n }
    }

    /// Short name, e.g. `D4` or `C8`.
    pub fn name(&self) -> String {
        format!("{}{}", if self.dihedral { 'D' } else { 'C' }, self.n)
    }

    /// All elements in a fixed order: rotations `(0,0..n)` first, then mirrors `(1,0..n)`.
    /// The position of an element in this list is its [`Group::index`].
    pub fn elements(&self) -> Vec<Element> {
        let flips: &[u8] = if self.dihedral { &[0, 1] } else { &[0] };
        flips.iter().flat_map(|&flip| (0..self.n).map(move |rot| Element { flip, rot })).collect()
    }

    /// Index of an element in [`Group::elements`].
    pub fn index(&self, g: Element) -> usize {
        g.flip as usize * self.n + g.rot
    }

    /// The identity.
    pub fn identity(&self) -> Element {
        Element { flip: 0, rot: 0 }
    }

    /// Group product `a·b`.
    pub fn mul(&self, a: Element, b: Element) -> Element {
        let n = self.n as i64;
        let sign = if a.flip == 1 { -1 } else { 1 };
        let rot = (a.rot as i64 + sign * b.rot as i64).rem_euclid(n) as usize;
        Element { flip: a.flip ^ b.flip, rot }
    }

    /// Inverse `a⁻¹`.
    pub fn inv(&self, a: Element) -> Element {
        if a.flip == 1 {
            a // mirrors are involutions
        } else {
            Element { flip: 0, rot: (self.n - a.rot) % self.n }
        }
    }

    /// Rotation angle of the element in radians.
    pub fn angle(&self, g: Element) -> f64 {
        2.0 * PI * g.rot as f64 / self.n as f64
    }

    /// The 2×2 matrix of `g` acting on plane coordinates (x right, y up), row major.
    pub fn plane_matrix(&self, g: Element) -> [[f64; 2]; 2] {
        let (s, c) = self.angle(g).sin_cos();
        let fx = if g.flip == 1 { -1.0 } else { 1.0 };
        // Rot · diag(fx, 1)
        [[c * fx, -s], [s * fx, c]]
    }

    /// Apply `g` to a plane point.
    pub fn act_plane(&self, g: Element, p: [f64; 2]) -> [f64; 2] {
        let m = self.plane_matrix(g);
        [m[0][0] * p[0] + m[0][1] * p[1], m[1][0] * p[0] + m[1][1] * p[1]]
    }

    /// Whether `g` maps the pixel grid onto itself (rotation by a multiple of 90°, possibly mirrored).
    pub fn acts_on_grid(&self, g: Element) -> bool {
        (4 * g.rot).is_multiple_of(self.n)
    }

    /// Number of quarter turns of `g` if it acts on the pixel grid.
    pub fn quarter_turns(&self, g: Element) -> Option<usize> {
        self.acts_on_grid(g).then(|| (4 * g.rot / self.n) % 4)
    }

    /// The elements that map the pixel grid onto itself (the subgroup testable on images).
    pub fn grid_elements(&self) -> Vec<Element> {
        self.elements().into_iter().filter(|&g| self.acts_on_grid(g)).collect()
    }

    /// The action `κ ↦ κ∘g⁻¹` of `g` on the coefficients of the harmonic template basis
    /// `[δ_centre, R·1, R·cosφ, R·sinφ, R·cos2φ, R·sin2φ]` (docs/paper.md §1.6), as a 6×6 matrix `A`
    /// with `coeff(κ∘g⁻¹) = A · coeff(κ)`. Exact for every element, on or off the grid.
    pub fn harmonic_action(&self, g: Element) -> [[f64; 6]; 6] {
        let mut a = [[0.0; 6]; 6];
        a[0][0] = 1.0;
        a[1][1] = 1.0;
        let alpha = self.angle(g);
        for (freq, base) in [(1usize, 2usize), (2, 4)] {
            // κ(x) = c·cos(mφ) + s·sin(mφ). Mirror first (φ → π − φ under x → −x), then rotate.
            // With g = Rot(α)∘Flip^f, (κ∘g⁻¹)(φ) = κ(Flip^f(φ − α)).
            // Flip: cos(m(π−φ)) = (−1)^m cos(mφ), sin(m(π−φ)) = −(−1)^m sin(mφ).
            let m = freq as f64;
            let (sa, ca) = (m * alpha).sin_cos();
            // Rotation part: cos(m(φ−α)) = cos(mα)cos(mφ) + sin(mα) sin(mφ);
            //                sin(m(φ−α)) = cos(mα) sin(mφ) − sin(mα) cos(mφ).
            // f(φ) = κ'(φ − α) where κ' = κ∘Flip^f.
            let sign = if freq % 2 == 1 { -1.0 } else { 1.0 };
            let (fc, fs) = if g.flip == 1 { (sign, -sign) } else { (1.0, 1.0) };
            // κ' has coefficients (fc·c, fs·s); then rotation.
            // new_c = ca·(fc c) − sa·(fs s); new_s = sa·(fc c) + ca·(fs s)
            a[base][base] = ca * fc;
            a[base][base + 1] = -sa * fs;
            a[base + 1][base] = sa * fc;
            a[base + 1][base + 1] = ca * fs;
        }
        a
    }
}

/// Where a pixel offset goes: the pixel `(row, col)` of a `size×size` grid mapped by `g`
/// (centre of rotation is the grid centre). Panics if `g` does not act on the grid.
pub fn act_pixel(group: &Group, g: Element, size: usize, row: usize, col: usize) -> (usize, usize) {
    let t = group.quarter_turns(g).expect("element does not act on the pixel grid");
    let c = (size as f64 - 1.0) / 2.0;
    let mut x = col as f64 - c;
    let mut y = c - row as f64;
    if g.flip == 1 {
        x = -x;
    }
    for _ in 0..t {
        let (nx, ny) = (-y, x);
        x = nx;
        y = ny;
    }
    ((c - y).round() as usize, (x + c).round() as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn groups() -> Vec<Group> {
        [1, 2, 3, 4, 8].iter().flat_map(|&n| [Group::cyclic(n), Group::dihedral(n)]).collect()
    }

    fn matmul2(a: [[f64; 2]; 2], b: [[f64; 2]; 2]) -> [[f64; 2]; 2] {
        let mut c = [[0.0; 2]; 2];
        for i in 0..2 {
            for j in 0..2 {
                c[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j];
            }
        }
        c
    }

    #[test]
    fn group_axioms_hold() {
        for g in groups() {
            let els = g.elements();
            assert_eq!(els.len(), g.order());
            for (i, &a) in els.iter().enumerate() {
                assert_eq!(g.index(a), i);
                assert_eq!(g.mul(a, g.inv(a)), g.identity());
                assert_eq!(g.mul(g.identity(), a), a);
                for &b in &els {
                    for &c in &els {
                        assert_eq!(g.mul(g.mul(a, b), c), g.mul(a, g.mul(b, c)));
                    }
                }
            }
        }
    }

    #[test]
    fn plane_action_is_a_homomorphism() {
        for g in groups() {
            for a in g.elements() {
                for b in g.elements() {
                    let lhs = g.plane_matrix(g.mul(a, b));
                    let rhs = matmul2(g.plane_matrix(a), g.plane_matrix(b));
                    for i in 0..2 {
                        for j in 0..2 {
                            assert!((lhs[i][j] - rhs[i][j]).abs() < 1e-12, "{} {a:?} {b:?}", g.name());
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn mirror_is_about_the_vertical_axis_and_rotation_is_ccw() {
        let d4 = Group::dihedral(4);
        let p = d4.act_plane(Element { flip: 1, rot: 0 }, [1.0, 2.0]);
        assert!((p[0] + 1.0).abs() < 1e-12 && (p[1] - 2.0).abs() < 1e-12);
        let p = d4.act_plane(Element { flip: 0, rot: 1 }, [1.0, 0.0]);
        assert!(p[0].abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12);
    }

    #[test]
    fn pixel_action_matches_plane_action() {
        for g in groups() {
            for e in g.grid_elements() {
                for size in [3usize, 4, 5] {
                    let c = (size as f64 - 1.0) / 2.0;
                    for r in 0..size {
                        for col in 0..size {
                            let (r2, c2) = act_pixel(&g, e, size, r, col);
                            let p = g.act_plane(e, [col as f64 - c, c - r as f64]);
                            assert!((c2 as f64 - c - p[0]).abs() < 1e-9);
                            assert!((c - r2 as f64 - p[1]).abs() < 1e-9);
                        }
                    }
                }
            }
        }
        assert_eq!(Group::cyclic(8).grid_elements().len(), 4);
        assert_eq!(Group::dihedral(4).grid_elements().len(), 8);
    }

    /// The coefficient action must agree with evaluating `κ(g⁻¹x)` on arbitrary plane points.
    #[test]
    fn harmonic_action_matches_function_composition() {
        let eval = |c: &[f64; 6], p: [f64; 2]| {
            let phi = p[1].atan2(p[0]);
            c[1] + c[2] * phi.cos() + c[3] * phi.sin() + c[4] * (2.0 * phi).cos() + c[5] * (2.0 * phi).sin()
        };
        let coeff = [0.0, 0.3, -1.2, 0.7, 0.4, -0.9];
        for g in groups() {
            for e in g.elements() {
                let a = g.harmonic_action(e);
                let mut new = [0.0; 6];
                for i in 0..6 {
                    for j in 0..6 {
                        new[i] += a[i][j] * coeff[j];
                    }
                }
                for p in [[0.3, 0.8], [-1.0, 0.2], [0.5, -0.5]] {
                    let q = g.act_plane(g.inv(e), p);
                    assert!((eval(&new, p) - eval(&coeff, q)).abs() < 1e-12, "{} {e:?}", g.name());
                }
            }
        }
    }
}
