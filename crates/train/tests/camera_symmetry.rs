//! The Equi networks act on images by D4 (rotations by quarter turns, mirror about the image's
//! vertical axis) and on the action's (dx, dy) by the representation `irrep(1,1)`, whose mirror is
//! `diag(1, −1)`. That pairing is right only for one family of camera orientations: a world
//! symmetry `W` must show in the image as a grid element `g` with `ρ(g) = W`. If the camera were
//! turned or mirrored the other way, the four mirrors of D4 would pair an image with the wrong
//! action (an "incorrect" symmetry in the paper's terms) while every per-network equivariance test
//! still passed. These tests pin the simulator's cameras to the orientation the networks assume.
use equiarm_nn::group::Group;
use equiarm_nn::repr::Representation;
use equiarm_sim::gripper::WORKSPACE;
use equiarm_sim::{Camera, ViewPreset};
use nalgebra::{Matrix2, Point3};

/// The image-plane displacement (x = column, y = −row, as the networks' grid action uses) of a
/// 1 cm move of a point on the table at the workspace centre along world +x and +y: the columns
/// of the world → image map, linearised there.
fn plane_map(view: ViewPreset) -> Matrix2<f64> {
    let cam = Camera::new(view.into()).expect("camera");
    let at = |x: f64, y: f64| {
        let (u, v, _) = cam.project(Point3::new(x, y, 0.0)).expect("table point in front of the camera");
        (u, -v)
    };
    let (cx, cy) = ((WORKSPACE[0][0] + WORKSPACE[0][1]) as f64 / 2.0, (WORKSPACE[1][0] + WORKSPACE[1][1]) as f64 / 2.0);
    let o = at(cx, cy);
    let ex = at(cx + 0.01, cy);
    let ey = at(cx, cy + 0.01);
    Matrix2::new(ex.0 - o.0, ey.0 - o.0, ex.1 - o.1, ey.1 - o.1)
}

#[test]
fn top_down_camera_pairs_every_d4_image_element_with_its_action_representation() {
    let d4 = Group::dihedral(4);
    let rho = Representation::irrep(d4, 1, 1);
    let flips = Representation::quotient_by_rotations(d4);
    let m = plane_map(ViewPreset::Angle90);
    let m_inv = m.try_inverse().expect("invertible camera map");
    for g in d4.elements() {
        // The world map that shows as the grid element g: W = M⁻¹ P(g) M.
        let p = d4.plane_matrix(g);
        let w = m_inv * Matrix2::new(p[0][0], p[0][1], p[1][0], p[1][1]) * m;
        let r = Matrix2::from_row_slice(rho.matrix(g));
        assert!(
            (w - r).abs().max() < 1e-6,
            "{g:?}: the image element moves the world by {w:?}, but the networks map (dx, dy) by {r:?}"
        );
        // A world mirror flips the yaw: (dθ, −dθ) swap exactly for the mirrors.
        let det = w.determinant();
        let swaps = flips.matrix(g)[0] == 0.0;
        assert_eq!(det < 0.0, swaps, "{g:?}: world determinant {det} against the dθ representation");
    }
}

#[test]
fn oblique_camera_only_foreshortens_the_top_down_axes() {
    // The paper's oblique view breaks D4 by foreshortening world x (and by parallax), not by
    // turning or mirroring the image: its axes point where the top-down camera's do.
    let axes = |m: Matrix2<f64>| Matrix2::from_columns(&[m.column(0).normalize(), m.column(1).normalize()]);
    let top = axes(plane_map(ViewPreset::Angle90));
    for view in [ViewPreset::Side, ViewPreset::Angle30, ViewPreset::Angle60] {
        let m = plane_map(view);
        let n = axes(m);
        assert!((n - top).abs().max() < 1e-6, "{}: axes {n:?}, top-down {top:?}", view.name());
        let (sx, sy) = (m.column(0).norm(), m.column(1).norm());
        assert!(sx < sy, "{}: world x ({sx} px/cm) is the foreshortened axis, not y ({sy})", view.name());
    }
}

#[test]
fn rendered_frames_put_blocks_where_the_camera_projects_them() {
    // The maps above come from `Camera::project`, (column, row); the networks see the rendered
    // frame. A block's segmentation centroid must sit where its top face's centre projects.
    let mut cfg = equiarm_sim::EnvConfig::new(equiarm_sim::TaskKind::BlockPulling);
    cfg.camera = ViewPreset::Angle90.into();
    // the arm, seen from straight above, covers parts of the blocks: its pixels are not the block's
    cfg.arm = equiarm_sim::env::ArmView::Hidden;
    let mut env = equiarm_sim::Env::new(cfg).expect("env");
    // The largest distance, over the seeds, between the centroid and where a transposed or
    // mirrored frame would put it: the blocks must sit off the image's diagonals and centre lines
    // in at least one scene for the check to tell those layouts apart.
    let mut alternatives = [0.0f64; 3];
    for seed in 0..4 {
        let obs = env.reset(seed).expect("reset");
        let scene = env.scene().expect("scene after reset");
        let seg = env
            .segmentation_names()
            .iter()
            .position(|n| n == "block1" || n.starts_with("block1/"))
            .expect("block1 in the segmentation") as u16;
        let visual = scene.visuals.iter().find(|v| v.seg == seg).expect("block1 visual");
        let t = scene.physics.colliders[visual.collider].translation();
        // The block rests on the table, so its top face is at twice its centre's height.
        let (u, v, _) =
            env.camera().project(Point3::new(t.x as f64, t.y as f64, 2.0 * t.z as f64)).expect("block in view");
        let (mut n, mut sr, mut sc) = (0.0, 0.0, 0.0);
        for (i, &s) in obs.segmentation.iter().enumerate() {
            if s == seg {
                n += 1.0;
                sr += (i / obs.width) as f64;
                sc += (i % obs.width) as f64;
            }
        }
        assert!(n > 100.0, "seed {seed}: block1 covers {n} pixels");
        let (r, c) = (sr / n, sc / n);
        // Tolerance: the gripper, above the workspace centre, hides part of some blocks.
        let last = (obs.width - 1) as f64;
        for (k, (ar, ac)) in [(u, v), (v, last - u), (last - v, u)].into_iter().enumerate() {
            alternatives[k] = alternatives[k].max((r - ar).hypot(c - ac));
        }
        assert!(
            (r - v).abs() < 3.0 && (c - u).abs() < 3.0,
            "seed {seed}: block1's pixels centre on (row {r:.1}, col {c:.1}), its top projects to (row {v:.1}, col {u:.1})"
        );
    }
    assert!(alternatives.iter().all(|&d| d > 10.0), "scenes too symmetric to tell the layouts apart: {alternatives:?}");
}
