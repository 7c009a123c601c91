//! The paper's upper bound on the accuracy of an invariant classifier (docs/rotest.md, "The bound").
//!
//! A C8-invariant classifier gives one answer to every member of an orbit (a pair of images and its
//! rotations by k·45°, both images together). If the members of an orbit carry different labels, the
//! best it can do on that orbit is to answer the most frequent label, right on a fraction `p` of the
//! orbit (the majority fraction). With the members of each orbit equally likely,
//! acc(f) ≤ Σ_p c_p·p, where c_p is the probability of orbits with majority fraction p: the mean of
//! the majority fraction over orbits ([`bound`]).
//!
//! For a generated dataset the orbit of a pair is known exactly: rotating both images of a top-down
//! pair by h about the image centre shows the same scene rotated by h about the workspace centre,
//! with the same rotation between the images, so its label is the labelling rule applied to the
//! rotated first-image poses ([`orbit_labels`]). Only invert-label's rule depends on the poses;
//! under every other setting an orbit has one label and the bound is 1.

use equiarm_sim::rotest::{Corruptions, PairCorruption, PairMeta};

/// Labels of the 8 members of the orbit of a pair whose first image shows `meta.before` and whose
/// scene was rotated by `idx`·45°: member k is the pair rotated by k·45° (ducks' positions rotated
/// about the workspace centre), labelled by `setting`.
pub fn orbit_labels(meta: &PairMeta, idx: u8, setting: &Corruptions) -> [u8; 8] {
    let c = equiarm_sim::rotest::scene::CENTRE;
    std::array::from_fn(|k| {
        let (s, co) = (k as f32 * std::f32::consts::FRAC_PI_4).sin_cos();
        let y = |i: usize| {
            let (dx, dy) = (meta.before[i].x - c[0], meta.before[i].y - c[1]);
            c[1] + s * dx + co * dy
        };
        if setting.has(PairCorruption::InvertLabel) { setting.label(idx, y(0), y(1)) } else { idx }
    })
}

/// Fraction of the labels equal to the most frequent one.
pub fn majority_fraction(labels: &[u8]) -> f64 {
    if labels.is_empty() {
        return 0.0;
    }
    let mut count = [0usize; 256];
    for &l in labels {
        count[l as usize] += 1;
    }
    *count.iter().max().unwrap_or(&0) as f64 / labels.len() as f64
}

/// The bound Σ_p c_p·p over equally weighted orbits, each given by its members' labels: the mean
/// majority fraction (0 for no orbit).
pub fn bound<L: AsRef<[u8]>>(orbits: &[L]) -> f64 {
    if orbits.is_empty() {
        return 0.0;
    }
    orbits.iter().map(|o| majority_fraction(o.as_ref())).sum::<f64>() / orbits.len() as f64
}

/// The bound for a classifier invariant only to the subgroup of C8 of `order` (1, 2, 4 or 8: the
/// rotations by multiples of 360°/`order`), with the rotation drawn uniformly: each pair's scene
/// under each of the 8 rotations, its orbit the `order` members that subgroup reaches. Under
/// invert-label already C2 (the 180° turn alone, which swaps "duck 0 left of duck 1") gives 0.625:
/// that bound binds every network exactly invariant to 180°, as the C8 network on pixels is.
pub fn subgroup_bound(metas: &[PairMeta], setting: &Corruptions, order: usize) -> f64 {
    let step = 8 / order.clamp(1, 8);
    let orbits: Vec<Vec<u8>> = metas
        .iter()
        .flat_map(|m| (0..8u8).map(move |idx| orbit_labels(m, idx, setting)))
        .map(|o| o.iter().step_by(step).copied().collect())
        .collect();
    bound(&orbits)
}

/// The bound of a dataset, two ways.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DatasetBound {
    /// With the rotation drawn uniformly, as the generator draws it: every pair's scene with each of
    /// the 8 rotations (the paper's construction: 0.625 for invert-label, 1 otherwise).
    pub uniform_rotation: f64,
    /// With the rotations the dataset's pairs actually drew (close to the above; sampling noise).
    pub drawn: f64,
    /// Orbits (pairs) counted.
    pub pairs: usize,
}

/// The bound of the pairs `metas` labelled by `setting`.
pub fn dataset_bound(metas: &[PairMeta], setting: &Corruptions) -> DatasetBound {
    let drawn: Vec<[u8; 8]> = metas.iter().map(|m| orbit_labels(m, m.idx, setting)).collect();
    let uniform: Vec<[u8; 8]> =
        metas.iter().flat_map(|m| (0..8u8).map(move |idx| orbit_labels(m, idx, setting))).collect();
    DatasetBound { uniform_rotation: bound(&uniform), drawn: bound(&drawn), pairs: metas.len() }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn majority_fraction_and_bound() {
        assert_eq!(majority_fraction(&[1, 1, 1, 1, 1, 1, 1, 1]), 1.0);
        assert_eq!(majority_fraction(&[1, 7, 1, 7, 1, 7, 1, 7]), 0.5);
        assert_eq!(majority_fraction(&[0, 1, 2, 3, 4, 5, 6, 7]), 0.125);
        assert_eq!(bound(&[[0u8, 0], [0, 1]]), 0.75);
        assert_eq!(bound::<[u8; 2]>(&[]), 0.0);
    }

    /// The 180° turn alone already caps an invariant classifier at 62.5 % under invert-label; the
    /// trivial group does not cap it.
    #[test]
    fn invert_label_is_capped_by_the_half_turn_alone() {
        use equiarm_sim::rotest::DuckPose;
        let c = equiarm_sim::rotest::scene::CENTRE;
        let duck = |x: f32, y: f32| DuckPose { x: c[0] + x, y: c[1] + y, z: 0.0, yaw: 0.0 };
        let metas: Vec<PairMeta> = [(0.1, 0.05), (-0.07, 0.12), (0.02, -0.11)]
            .iter()
            .map(|&(x, y)| PairMeta {
                idx: 3,
                label: 3,
                before: [duck(x, y), duck(-y, x), duck(0.0, 0.0)],
                after: [duck(x, y), duck(-y, x), duck(0.0, 0.0)],
                light_color: [1.0; 3],
            })
            .collect();
        let inv = Corruptions::parse("condition_reverse").unwrap();
        for order in [2, 4, 8] {
            assert_eq!(subgroup_bound(&metas, &inv, order), 0.625, "C{order}");
        }
        assert_eq!(subgroup_bound(&metas, &inv, 1), 1.0);
        assert_eq!(subgroup_bound(&metas, &Corruptions::none(), 2), 1.0);
    }
}
