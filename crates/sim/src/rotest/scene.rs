//! The rotation-estimation scene: no robot, a white ground, three "ducks" (rigid compounds of boxes
//! with a body, a head, a beak and a tail, so no rotation maps one onto itself) in the paper's colours,
//! placed in the 0.3 × 0.3 m workspace and settled; the top-down and side cameras.

use rapier3d::prelude::*;

use crate::assets::Assets;
use crate::camera::{Camera, CameraConfig};
use crate::error::Result;
use crate::rng::Rng;
use crate::world::{Scene, SimParams, Visual};

/// Workspace centre (x, y), m: the scene is rotated about it.
pub const CENTRE: [f32; 2] = [0.45, 0.0];
/// Half side of the square workspace the ducks are placed in, m.
pub const HALF_SIDE: f32 = 0.15;
/// Smallest distance between two ducks' origins at placement, m.
pub const MIN_DISTANCE: f32 = 0.20;
/// Height of a duck's base above the table at placement, m.
pub const SPAWN_Z: f32 = 0.01;
/// Physics steps to settle after placing or rotating (at [`SETTLE_DT`]).
pub const SETTLE_STEPS: u32 = 100;
/// Physics time step while settling, s (PyBullet's 1/240).
pub const SETTLE_DT: f32 = 1.0 / 240.0;
/// Mass of one duck, kg.
pub const DUCK_MASS: f32 = 1.0;

/// Colours of the three ducks: yellow, orange (1, 0.647, 0), grey (0.677, 0.41, 0.41).
pub const DUCK_COLORS: [[f32; 3]; 3] = [[0.95, 0.80, 0.10], [1.0, 0.647, 0.0], [0.677, 0.41, 0.41]];
/// Colour of every beak.
pub const BEAK_COLOR: [f32; 3] = [0.55, 0.12, 0.08];
/// Colour of the occlusion slab (dark grey).
pub const OCCLUDER_COLOR: [f32; 3] = [0.25, 0.25, 0.25];

/// One box of a duck, in the duck's frame (x forward toward the beak, z up, origin at the base
/// centre): half extents, centre, and whether it is the beak.
const PARTS: [([f32; 3], [f32; 3], bool); 4] = [
    // body 0.12 × 0.08 × 0.06
    ([0.06, 0.04, 0.03], [-0.01, 0.0, 0.03], false),
    // head 0.05 cube, forward and up
    ([0.025, 0.025, 0.025], [0.03, 0.0, 0.085], false),
    // beak 0.03 × 0.025 × 0.012 in front of the head
    ([0.015, 0.0125, 0.006], [0.07, 0.0, 0.08], true),
    // tail, raised at the back
    ([0.015, 0.02, 0.012], [-0.075, 0.0, 0.07], false),
];

/// Pose of a duck on the table: position of its base centre and yaw.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DuckPose {
    /// World x, m.
    pub x: f32,
    /// World y, m.
    pub y: f32,
    /// World z of the base centre, m.
    pub z: f32,
    /// Yaw (rotation about world z of the beak direction), rad, in (−π, π].
    pub yaw: f32,
}

/// The scene of one pair: the world and the three ducks' bodies.
pub struct RotScene {
    /// The rapier world with ground, ducks and (with occlusion) the slab.
    pub scene: Scene,
    /// Duck 0 (yellow), 1 (orange), 2 (grey).
    pub ducks: [RigidBodyHandle; 3],
}

/// Samples three positions uniformly in the workspace, pairwise more than [`MIN_DISTANCE`] apart
/// (rejection sampling, redrawing all three when a draw fails), and three yaws in [0, π); with
/// `full_circle`, positions uniformly in the disc inscribed in the workspace (radius
/// [`HALF_SIDE`]) and yaws in [0, 2π), a distribution that every rotation about [`CENTRE`] maps
/// onto itself.
pub fn sample_placement(rng: &mut Rng, full_circle: bool) -> [([f32; 2], f32); 3] {
    loop {
        let mut p: Vec<[f32; 2]> = Vec::with_capacity(3);
        for _ in 0..100 {
            let q = [
                rng.uniform(CENTRE[0] - HALF_SIDE, CENTRE[0] + HALF_SIDE),
                rng.uniform(CENTRE[1] - HALF_SIDE, CENTRE[1] + HALF_SIDE),
            ];
            if full_circle && (q[0] - CENTRE[0]).hypot(q[1] - CENTRE[1]) > HALF_SIDE {
                continue;
            }
            if p.iter().all(|o| ((o[0] - q[0]).powi(2) + (o[1] - q[1]).powi(2)).sqrt() > MIN_DISTANCE) {
                p.push(q);
                if p.len() == 3 {
                    break;
                }
            }
        }
        if p.len() == 3 {
            let turn = if full_circle { std::f32::consts::TAU } else { std::f32::consts::PI };
            let yaws = [0; 3].map(|_| rng.uniform(0.0, turn));
            return [(p[0], yaws[0]), (p[1], yaws[1]), (p[2], yaws[2])];
        }
    }
}

impl RotScene {
    /// A world with a white ground (a 20 m visual slab whose top is the table top; with `grid`, a
    /// checkerboard — the tile size is a render option), the three ducks at `placement` (base
    /// [`SPAWN_Z`] above the table), and with `occlusion` the floating slab. Not yet settled.
    pub fn new(assets: &Assets, placement: &[([f32; 2], f32); 3], grid: bool, occlusion: bool) -> Result<Self> {
        let params = SimParams { dt: SETTLE_DT, ..SimParams::default() };
        let mut scene = Scene::new(&params, assets, false)?;
        // The table collides; a larger visual ground replaces its visual, so the side view sees no edge.
        scene.visuals.clear();
        let ground = scene.add_marker(
            "ground",
            Pose::from_translation(Vector::new(CENTRE[0], CENTRE[1], -0.02)),
            Vector::new(10.0, 10.0, 0.02),
            [1.0, 1.0, 1.0],
        );
        if grid {
            for v in scene.visuals.iter_mut().filter(|v| v.collider == ground) {
                v.checker = true;
            }
        }
        let volume: f32 = PARTS.iter().map(|(h, _, _)| 8.0 * h[0] * h[1] * h[2]).sum();
        let density = DUCK_MASS / volume;
        let friction = params.object_friction;
        let mut ducks = Vec::with_capacity(3);
        for (k, (p, yaw)) in placement.iter().enumerate() {
            let pose = Pose::from_parts(Vector::new(p[0], p[1], SPAWN_Z), Rotation::from_rotation_z(*yaw));
            let body = scene.physics.bodies.insert(RigidBodyBuilder::dynamic().pose(pose).can_sleep(false));
            let seg = scene.seg_names.len() as u16;
            scene.seg_names.push(format!("duck{k}"));
            for (half, centre, beak) in PARTS {
                let col = ColliderBuilder::cuboid(half[0], half[1], half[2])
                    .translation(Vector::new(centre[0], centre[1], centre[2]))
                    .density(density)
                    .friction(friction)
                    .build();
                let handle = scene.physics.colliders.insert_with_parent(col, body, &mut scene.physics.bodies);
                let color = if beak { BEAK_COLOR } else { DUCK_COLORS[k] };
                scene.visuals.push(Visual { collider: handle, seg, color, checker: false });
            }
            ducks.push(body);
        }
        if occlusion {
            scene.add_marker(
                "occluder",
                Pose::from_translation(Vector::new(0.50, -0.05, 0.20)),
                Vector::new(0.025, 0.05, 0.005),
                OCCLUDER_COLOR,
            );
        }
        Ok(Self { scene, ducks: [ducks[0], ducks[1], ducks[2]] })
    }

    /// Runs [`SETTLE_STEPS`] physics steps.
    pub fn settle(&mut self) {
        for _ in 0..SETTLE_STEPS {
            self.scene.step();
        }
    }

    /// The ducks' poses now.
    pub fn poses(&self) -> [DuckPose; 3] {
        self.ducks.map(|h| {
            let b = &self.scene.physics.bodies[h];
            let t = b.translation();
            DuckPose { x: t.x, y: t.y, z: t.z, yaw: crate::world::yaw_of(*b.rotation()) }
        })
    }

    /// Rotates every duck about the vertical axis through [`CENTRE`] by `theta` (rad): position
    /// rotated, orientation pre-multiplied by the yaw `theta`; velocities zeroed.
    pub fn rotate_scene(&mut self, theta: f32) {
        let r = Rotation::from_rotation_z(theta);
        for h in self.ducks {
            let b = &mut self.scene.physics.bodies[h];
            let t = b.translation();
            let (s, c) = theta.sin_cos();
            let (dx, dy) = (t.x - CENTRE[0], t.y - CENTRE[1]);
            let pos = Vector::new(CENTRE[0] + c * dx - s * dy, CENTRE[1] + s * dx + c * dy, t.z);
            let rot = r * *b.rotation();
            b.set_position(Pose::from_parts(pos, rot), true);
            b.set_linvel(Vector::ZERO, true);
            b.set_angvel(Vector::ZERO, true);
        }
    }
}

/// The top-down camera: eye 1 m above the workspace centre looking straight down, rows toward +x and
/// columns toward +y, field of view 2·atan(0.3) ≈ 33.4° (a 0.6 m square on the table), `size`² pixels.
pub fn top_down_camera(size: usize) -> CameraConfig {
    CameraConfig {
        target: [CENTRE[0] as f64, CENTRE[1] as f64, 0.0],
        elevation_deg: 90.0,
        distance: 1.0,
        fov_y_deg: 2.0 * 0.3f64.atan().to_degrees(),
        width: size,
        height: size,
        near: 0.1,
        far: 3.0,
    }
}

/// The side camera: eye (1.05, 0, 0.6) looking at the workspace centre (45° elevation, 0.849 m),
/// field of view 40°, `size`² pixels.
pub fn side_camera(size: usize) -> CameraConfig {
    CameraConfig { elevation_deg: 45.0, distance: 0.6 * 2f64.sqrt(), fov_y_deg: 40.0, ..top_down_camera(size) }
}

/// The camera for a setting: [`side_camera`] or [`top_down_camera`]; with `squeeze`, the horizontal
/// focal length is halved (projection aspect 2).
pub fn camera(size: usize, side: bool, squeeze: bool) -> Result<Camera> {
    let mut cam = Camera::new(if side { side_camera(size) } else { top_down_camera(size) })?;
    if squeeze {
        cam.fx = cam.fy / 2.0;
    }
    Ok(cam)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts per 45° sector of `angles` (radians), for a check that a distribution is C8-symmetric.
    fn sectors(angles: impl Iterator<Item = f32>) -> [usize; 8] {
        let mut n = [0; 8];
        for a in angles {
            n[((a.rem_euclid(std::f32::consts::TAU) / std::f32::consts::FRAC_PI_4) as usize).min(7)] += 1;
        }
        n
    }

    /// Issue 58: the invariant classifier's bound holds only where every rotation of a scene is as
    /// likely as the scene; the paper's placement (yaws in [0, π)) is not, `full_circle`'s is.
    #[test]
    fn a_full_circle_placement_is_spread_evenly_over_every_direction() {
        let mut rng = Rng::new(7);
        let draws: Vec<_> = (0..3000).flat_map(|_| sample_placement(&mut rng, true)).collect();
        for (p, yaw) in &draws {
            assert!((p[0] - CENTRE[0]).hypot(p[1] - CENTRE[1]) <= HALF_SIDE, "{p:?} outside the disc");
            assert!((0.0..std::f32::consts::TAU).contains(yaw), "{yaw}");
        }
        let expect = draws.len() as f64 / 8.0;
        let bearing = sectors(draws.iter().map(|(p, _)| (p[1] - CENTRE[1]).atan2(p[0] - CENTRE[0])));
        let yaw = sectors(draws.iter().map(|(_, y)| *y));
        for n in bearing.iter().chain(&yaw) {
            // 9,000 draws: a sector's count has a standard deviation of about 31
            assert!((*n as f64 - expect).abs() < 0.1 * expect, "sectors {bearing:?} / {yaw:?}, expected {expect}");
        }
        let mut rng = Rng::new(7);
        let paper: Vec<_> = (0..300).flat_map(|_| sample_placement(&mut rng, false)).collect();
        assert!(paper.iter().all(|(_, y)| *y < std::f32::consts::PI), "the paper's yaws stay in [0, π)");
        assert!(sectors(paper.iter().map(|(_, y)| *y))[4..].iter().all(|n| *n == 0));
    }
}
