//! The rotation-estimation pairs: the label is the rotation the object poses show, and each
//! corruption changes what it should and nothing else (same seed, same scene and rotation).

use equiarm_sim::Assets;
use equiarm_sim::rotest::{Corruptions, Pair, PairConfig, generate_pair, recover_idx};

const SIZE: usize = 32;

fn pair(setting: &str, seed: u64) -> Pair {
    let cfg = PairConfig { size: SIZE, supersample: 1, corruptions: Corruptions::parse(setting).unwrap() };
    generate_pair(&Assets::bundled().unwrap(), &cfg, seed).unwrap()
}

fn wrap(a: f32) -> f32 {
    let t = std::f32::consts::TAU;
    (a + t / 2.0).rem_euclid(t) - t / 2.0
}

#[test]
fn the_label_is_the_rotation_recovered_from_the_object_poses() {
    let mut seen = [false; 8];
    for seed in 0..12 {
        let p = pair("none", seed);
        let m = &p.meta;
        assert_eq!(m.label, m.idx);
        assert_eq!(recover_idx(&m.before, &m.after), m.idx, "seed {seed}");
        seen[m.idx as usize] = true;
        let theta = m.idx as f32 * std::f32::consts::FRAC_PI_4;
        for (b, a) in m.before.iter().zip(&m.after) {
            // positions rotate about the centre, yaws turn by the same angle; settling barely moves them
            let (s, c) = theta.sin_cos();
            let (dx, dy) = (b.x - 0.45, b.y);
            let (x, y) = (0.45 + c * dx - s * dy, s * dx + c * dy);
            assert!((x - a.x).hypot(y - a.y) < 0.01, "seed {seed}: ({x}, {y}) vs ({}, {})", a.x, a.y);
            assert!(wrap(a.yaw - b.yaw - theta).abs() < 0.05, "seed {seed}: yaw {} -> {}", b.yaw, a.yaw);
        }
        // the ducks rest on the table, pairwise apart
        for d in &m.before {
            assert!(d.z.abs() < 0.005, "seed {seed}: z {}", d.z);
        }
        if m.idx != 0 {
            assert_ne!(p.before, p.after, "seed {seed}: the scene moved, so the image changes");
        }
    }
    assert!(seen.iter().filter(|s| **s).count() >= 5, "labels spread: {seen:?}");
}

#[test]
fn the_same_seed_gives_the_same_pair() {
    assert_eq!(pair("grid", 3), pair("grid", 3));
    assert_ne!(pair("grid", 3).before, pair("grid", 4).before);
}

#[test]
fn reflect_mirrors_both_images_exactly_and_changes_nothing_else() {
    for seed in 0..3 {
        let clean = pair("none", seed);
        let r = pair("reflect", seed);
        assert_eq!(r.meta, clean.meta);
        for (mut c, m) in [(clean.before.clone(), &r.before), (clean.after.clone(), &r.after)] {
            assert_ne!(&c, m);
            c.reflect();
            assert_eq!(&c, m);
        }
    }
}

#[test]
fn invert_label_flips_the_label_exactly_when_duck0_is_left_of_duck1() {
    let (mut flipped, mut kept) = (0, 0);
    for seed in 0..16 {
        let clean = pair("none", seed);
        let inv = pair("condition_reverse", seed);
        assert_eq!((&inv.before, &inv.after), (&clean.before, &clean.after), "images unchanged");
        let m = &inv.meta;
        assert_eq!((m.idx, &m.before, &m.after), (clean.meta.idx, &clean.meta.before, &clean.meta.after));
        if m.before[0].y < m.before[1].y {
            assert_eq!(m.label, (8 - m.idx) % 8, "seed {seed}");
            flipped += 1;
        } else {
            assert_eq!(m.label, m.idx, "seed {seed}");
            kept += 1;
        }
    }
    assert!(flipped > 0 && kept > 0, "both arrangements occur: {flipped} flipped, {kept} kept");
}

/// Colour-only corruptions leave the scene, the label and every depth value as they are.
#[test]
fn lighting_and_floor_corruptions_change_colour_only() {
    let seed = 5;
    let clean = pair("none", seed);
    for setting in ["grid", "random_light_color", "light_effect", "two_light_color", "two_specular"] {
        let p = pair(setting, seed);
        assert_eq!(p.meta.idx, clean.meta.idx, "{setting}");
        assert_eq!(p.meta.label, clean.meta.label, "{setting}");
        assert_eq!(p.meta.before, clean.meta.before, "{setting}");
        assert_eq!(p.before.depth, clean.before.depth, "{setting}: depth unchanged");
        assert_eq!(p.after.depth, clean.after.depth, "{setting}: depth unchanged");
        assert_ne!(p.before.color, clean.before.color, "{setting}: colour changed");
        if setting == "random_light_color" {
            assert!(p.meta.light_color.iter().all(|c| (0.2..1.0).contains(c)), "{:?}", p.meta.light_color);
        } else {
            assert_eq!(p.meta.light_color, [1.0; 3]);
        }
    }
    // two_specular: the left half (specular 0) is the clean image, the right half is not
    let p = pair("two_specular", seed);
    let half = |img: &[u8], right: bool| -> Vec<u8> {
        img.chunks(SIZE * 3)
            .flat_map(|row| if right { &row[SIZE * 3 / 2..] } else { &row[..SIZE * 3 / 2] })
            .copied()
            .collect()
    };
    assert_eq!(half(&p.before.color, false), half(&clean.before.color, false));
    assert_ne!(half(&p.before.color, true), half(&clean.before.color, true));
    // two_light_color: the left half is reddish, the right half bluish, on the white ground
    let p = pair("two_light_color", seed);
    let row = &p.before.color[..SIZE * 3];
    let (l, r) = (&row[..3], &row[row.len() - 3..]);
    assert!(l[0] > l[2] && r[2] > r[0], "left {l:?} right {r:?}");
    // grid: only ground pixels change colour (the ducks are drawn the same)
    let g = pair("grid", seed);
    let duck = |d: f32| d < 0.99;
    for i in 0..SIZE * SIZE {
        if duck(clean.before.depth[i]) {
            assert_eq!(g.before.color[i * 3..i * 3 + 3], clean.before.color[i * 3..i * 3 + 3], "pixel {i}");
        }
    }
}

/// The slab is seen from above: it covers some pixels (nearer depth) and leaves the others as they were.
#[test]
fn occlusion_covers_a_patch_and_leaves_the_rest() {
    let seed = 6;
    let clean = pair("none", seed);
    let o = pair("occlusion", seed);
    assert_eq!(o.meta.idx, clean.meta.idx);
    let mut covered = 0;
    for i in 0..SIZE * SIZE {
        if o.before.depth[i] < clean.before.depth[i] - 1e-4 {
            covered += 1;
            assert!((o.before.depth[i] - 0.8).abs() < 0.01, "slab at 0.2 m: depth {}", o.before.depth[i]);
        } else {
            assert!((o.before.depth[i] - clean.before.depth[i]).abs() < 1e-3, "pixel {i}");
        }
    }
    // 0.05 × 0.10 m of a 0.6 m square view: about 1.4 % of the pixels
    assert!((5..40).contains(&covered), "{covered} covered pixels");
}

/// Squeeze halves the horizontal focal length and the side view looks from 45°: the images change,
/// the scene and labels do not.
#[test]
fn camera_corruptions_change_the_view_only() {
    let seed = 7;
    let clean = pair("none", seed);
    for setting in ["squeeze", "side", "side,grid", "side,light_effect", "side,squeeze", "side,reflect"] {
        let p = pair(setting, seed);
        assert_eq!((p.meta.idx, p.meta.label), (clean.meta.idx, clean.meta.label), "{setting}");
        assert_eq!(p.meta.before, clean.meta.before, "{setting}");
        assert_ne!(p.before.depth, clean.before.depth, "{setting}");
    }
    // the side view sees the ground farther at the top rows than at the bottom rows
    let s = pair("side", seed);
    assert!(s.before.depth[0] > s.before.depth[SIZE * SIZE - 1] + 0.3);
    // squeeze: the view is twice as wide, so the ground spans the whole image and the ducks look narrower
    let q = pair("squeeze", seed);
    let width = |img: &[f32]| img.iter().filter(|d| **d < 0.99).count();
    assert!(width(&q.before.depth) < width(&clean.before.depth), "squeezed ducks cover fewer pixels");
}
