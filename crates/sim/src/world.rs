//! The rapier world: every physics setting in one place ([`SimParams`]), the table, and the insertion
//! of URDF assets with the per-collider colour and segmentation id the renderers need.
//!
//! A fresh [`Scene`] is built on every reset (rapier's handles, warm-start caches and
//! BVH carry history, so reusing a world would make episodes depend on the past).
//!
//! Limitations: kinematic-vs-fixed contacts are off (rapier's default), so the kinematic palm passes
//! through the table; the gripper clamps its height so only the dynamic fingers meet the table.

use rapier3d::prelude::*;
use rapier3d_urdf::{UrdfLoaderOptions, UrdfRobot, UrdfRobotHandles};

use crate::assets::{Asset, AssetKind, Assets};
use crate::error::{Result, SimError};

/// Physics settings (defaults in `SimParams::default`; the load-bearing ones say why on their field).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimParams {
    /// Physics time step, s.
    pub dt: f32,
    /// Physics steps per env step (the palm is interpolated over them).
    ///
    /// NOTE: 20 × 1/120 s = 0.167 s per step, so a full 5 cm step moves at 0.3 m/s. 12
    /// substeps (0.5 m/s) gave the pulling expert 91/100: the swept block hit the other one hard
    /// enough to bounce off or knock it out of the workspace; 20 gives 99/100. BulletArm's own step
    /// is quasi-static (it waits for the arm to converge), so slower is also closer to the paper.
    pub substeps: u32,
    /// Extra physics steps after the motion, with the palm still, so objects settle.
    pub settle_substeps: u32,
    /// Extra physics steps after the motion when the jaw command changed (the fingers close or open).
    pub grip_substeps: u32,
    /// Physics steps run at reset so spawned objects settle (BulletArm: 50 steps at 1/240 s).
    pub reset_settle_substeps: u32,
    /// Constraint solver iterations per physics step (rapier's `num_solver_iterations`), >= 1.
    pub solver_iterations: usize,
    /// Contact prediction distance, m (rapier's default is 0.02). NOTE: rapier applies speculative
    /// contact impulses within this distance; at 0.02 a cube carried 1 cm above the bowl rim dragged the
    /// bowl along with it, so it is kept small.
    pub prediction_distance: f32,
    /// NOTE: contact softness is load-bearing. rapier's default (30 Hz, ζ = 10) lets motor-driven
    /// fingers sink 1-1.3 cm into a light cube and misaligned grasps fail; 240 Hz, ζ = 1 keeps the
    /// penetration near 0.5 mm.
    pub contact_softness_hz: f32,
    /// Damping ratio ζ of the contact spring whose natural frequency is `contact_softness_hz`
    /// (dimensionless, > 0).
    pub contact_damping_ratio: f32,
    /// Gravity magnitude (along -z), m/s². BulletArm uses 10.
    pub gravity: f32,
    /// Friction coefficient of the gripper's colliders (fingers and palm), >= 0.
    pub finger_friction: f32,
    /// Friction coefficient of the task objects (blocks, cube, bowl, drawer cabinet, tray and handle), >= 0.
    pub object_friction: f32,
    /// Friction coefficient of the table, >= 0.
    pub table_friction: f32,
    /// Finger position motor: stiffness N/m, damping N·s/m, force limit N.
    pub grip_stiffness: f32,
    /// Damping of each finger's position motor, N·s/m, >= 0.
    pub grip_damping: f32,
    /// Force limit of each finger's position motor, N, > 0.
    pub grip_max_force: f32,
    /// Force that holds the drawer shut (a velocity-0 motor with this force limit), N.
    pub drawer_resistance: f32,
}

impl Default for SimParams {
    fn default() -> Self {
        Self {
            dt: 1.0 / 120.0,
            substeps: 20,
            settle_substeps: 2,
            grip_substeps: 8,
            reset_settle_substeps: 25,
            solver_iterations: 4,
            prediction_distance: 0.002,
            contact_softness_hz: 240.0,
            contact_damping_ratio: 1.0,
            gravity: 10.0,
            finger_friction: 1.0,
            object_friction: 0.8,
            table_friction: 0.5,
            grip_stiffness: 2000.0,
            grip_damping: 100.0,
            grip_max_force: 20.0,
            drawer_resistance: 0.5,
        }
    }
}

/// Largest count accepted for each of the `*substeps` fields: physics steps per action (the defaults
/// are 2–25; a typo of a few more zeros would make one step take minutes and the node look hung).
pub const MAX_SUBSTEPS: u32 = 1000;
/// Largest `solver_iterations` accepted (the default is 4).
pub const MAX_SOLVER_ITERATIONS: usize = 100;

impl SimParams {
    /// Checks the domains: `dt`, `prediction_distance`, `contact_softness_hz`, `contact_damping_ratio`,
    /// `grip_stiffness` and `grip_max_force` finite and > 0; gravity, frictions, `grip_damping` and
    /// `drawer_resistance` finite and >= 0; `substeps` 1..=[`MAX_SUBSTEPS`], the other `*substeps`
    /// 0..=[`MAX_SUBSTEPS`], `solver_iterations` 1..=[`MAX_SOLVER_ITERATIONS`]. The first value out
    /// of its domain is a [`SimError::Config`] naming the field.
    pub fn validate(&self) -> Result<()> {
        let pos = |field: &'static str, v: f32| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SimError::Config { field, message: format!("{v} must be finite and > 0") })
            }
        };
        pos("dt", self.dt)?;
        pos("prediction_distance", self.prediction_distance)?;
        pos("contact_softness_hz", self.contact_softness_hz)?;
        pos("contact_damping_ratio", self.contact_damping_ratio)?;
        pos("grip_stiffness", self.grip_stiffness)?;
        pos("grip_max_force", self.grip_max_force)?;
        for (f, v) in [
            ("gravity", self.gravity),
            ("finger_friction", self.finger_friction),
            ("object_friction", self.object_friction),
            ("table_friction", self.table_friction),
            ("grip_damping", self.grip_damping),
            ("drawer_resistance", self.drawer_resistance),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(SimError::Config { field: f, message: format!("{v} must be finite and >= 0") });
            }
        }
        if self.substeps == 0 {
            return Err(SimError::Config { field: "substeps", message: "must be >= 1".into() });
        }
        for (field, v) in [
            ("substeps", self.substeps),
            ("settle_substeps", self.settle_substeps),
            ("grip_substeps", self.grip_substeps),
            ("reset_settle_substeps", self.reset_settle_substeps),
        ] {
            if v > MAX_SUBSTEPS {
                return Err(SimError::Config {
                    field,
                    message: format!("{v} is above {MAX_SUBSTEPS} physics steps per action (the default is 2–25)"),
                });
            }
        }
        if !(1..=MAX_SOLVER_ITERATIONS).contains(&self.solver_iterations) {
            return Err(SimError::Config {
                field: "solver_iterations",
                message: format!("{} must be 1..={MAX_SOLVER_ITERATIONS} (the default is 4)", self.solver_iterations),
            });
        }
        Ok(())
    }
}

/// What the renderers know about one collider.
#[derive(Clone, Debug)]
pub struct Visual {
    /// The collider drawn; its shape and pose are read from the physics world at render time.
    pub collider: ColliderHandle,
    /// Segmentation id: one per rigid body, 1-based (0 is background).
    pub seg: u16,
    /// Colour, RGB in [0, 1]: the link's URDF material (with `checker`, the colour of the even tiles).
    pub color: [f32; 3],
    /// Painted with a checkerboard in world xy (the table top, when enabled).
    pub checker: bool,
}

/// A rapier world plus the render registry.
pub struct Scene {
    /// The rapier world (bodies, colliders, joints, contacts), z up, gravity along −z.
    pub physics: PhysicsWorld,
    /// One entry per visible collider, in insertion order: what the renderers draw.
    pub visuals: Vec<Visual>,
    /// Name of each segmentation id (index = id; index 0 is "background").
    pub seg_names: Vec<String>,
    /// The physics settings the world was built with; the gripper and tasks read theirs from here.
    pub params: SimParams,
}

/// Where the table is: centred under the workspace centre, top face at z = 0.
pub const TABLE_CENTRE: [f32; 2] = [0.45, 0.0];

impl Scene {
    /// An empty world with the table.
    pub fn new(params: &SimParams, assets: &Assets, checker_floor: bool) -> Result<Self> {
        params.validate()?;
        // NOTE: rapier's default world is Y-up; URDF and the paper are Z-up.
        let mut physics = PhysicsWorld { gravity: Vector::new(0.0, 0.0, -params.gravity), ..Default::default() };
        let ip = &mut physics.integration_parameters;
        ip.dt = params.dt;
        ip.num_solver_iterations = params.solver_iterations;
        ip.length_unit = 1.0;
        ip.normalized_prediction_distance = params.prediction_distance;
        ip.contact_softness = SpringCoefficients::new(params.contact_softness_hz, params.contact_damping_ratio);
        let mut scene =
            Self { physics, visuals: Vec::new(), seg_names: vec!["background".to_string()], params: params.clone() };
        let table = scene.insert(
            assets.get(AssetKind::Table),
            "table",
            Pose::from_translation(Vector::new(TABLE_CENTRE[0], TABLE_CENTRE[1], 0.0)),
            true,
            params.table_friction,
        )?;
        if checker_floor {
            let body = table.links[0].body;
            for v in scene.visuals.iter_mut() {
                if scene.physics.colliders[v.collider].parent() == Some(body) {
                    v.checker = true;
                }
            }
        }
        Ok(scene)
    }

    /// Inserts an asset at `pose` (roots fixed if `fixed`), with impulse joints. Every link becomes
    /// one rigid body with its own segmentation id named `name/link`.
    pub fn insert(
        &mut self,
        asset: &Asset,
        name: &str,
        pose: Pose,
        fixed: bool,
        friction: f32,
    ) -> Result<UrdfRobotHandles<ImpulseJointHandle>> {
        let opts = UrdfLoaderOptions {
            collider_blueprint: ColliderBuilder::default().density(0.0).friction(friction),
            rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
            make_roots_fixed: fixed,
            ..Default::default()
        };
        let mut robot = UrdfRobot::from_robot(&asset.robot, opts, std::path::Path::new("."));
        robot.append_transform(&pose);
        let link_names: Vec<(String, [f32; 3])> = robot
            .links
            .iter()
            .map(|l| {
                let i = l.urdf_link_index;
                (asset.robot.links[i].name.clone(), asset.link_colors[i])
            })
            .collect();
        let handles = robot.insert_using_impulse_joints(
            &mut self.physics.bodies,
            &mut self.physics.colliders,
            &mut self.physics.impulse_joints,
        );
        for (link, (lname, color)) in handles.links.iter().zip(link_names) {
            let seg = u16::try_from(self.seg_names.len())
                .map_err(|_| SimError::Config { field: "scene", message: "more than 65535 bodies".into() })?;
            self.seg_names.push(if lname == name { name.to_string() } else { format!("{name}/{lname}") });
            for c in &link.colliders {
                self.visuals.push(Visual { collider: c.handle, seg, color, checker: false });
            }
        }
        Ok(handles)
    }

    /// Adds a fixed, visual-only box (a sensor collider: it is seen by the renderers and by ray casts
    /// but touches nothing). Used for the pushing goal square.
    pub fn add_marker(&mut self, name: &str, pose: Pose, half_extents: Vector, color: [f32; 3]) -> ColliderHandle {
        let body = self.physics.bodies.insert(RigidBodyBuilder::fixed().pose(pose));
        let col = ColliderBuilder::cuboid(half_extents.x, half_extents.y, half_extents.z).sensor(true).build();
        let handle = self.physics.colliders.insert_with_parent(col, body, &mut self.physics.bodies);
        let seg = self.seg_names.len() as u16;
        self.seg_names.push(name.to_string());
        self.visuals.push(Visual { collider: handle, seg, color, checker: false });
        handle
    }

    /// One physics step.
    pub fn step(&mut self) {
        self.physics.step();
    }

    /// Segmentation id of a rigid body (of its first collider), if it is registered.
    pub fn seg_of_body(&self, body: RigidBodyHandle) -> Option<u16> {
        self.visuals
            .iter()
            .find(|v| self.physics.colliders.get(v.collider).and_then(|c| c.parent()) == Some(body))
            .map(|v| v.seg)
    }
}

/// Yaw (rotation about world z) of a rotation, in (-π, π].
pub fn yaw_of(q: Rotation) -> f32 {
    let x = q * Vector::X;
    x.y.atan2(x.x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Regression (issue 28): a sim config with a huge settle-substep or solver iteration count
    /// passed validation, and the node never published nor logged.
    #[test]
    fn step_counts_beyond_their_bounds_are_refused_naming_the_field() {
        assert!(SimParams::default().validate().is_ok());
        let d = SimParams::default();
        let cases = [
            ("substeps", SimParams { substeps: 1_000_000, ..d.clone() }),
            ("settle_substeps", SimParams { settle_substeps: MAX_SUBSTEPS + 1, ..d.clone() }),
            ("grip_substeps", SimParams { grip_substeps: u32::MAX, ..d.clone() }),
            ("reset_settle_substeps", SimParams { reset_settle_substeps: 4_000_000_000, ..d.clone() }),
            ("solver_iterations", SimParams { solver_iterations: 1 << 40, ..d.clone() }),
        ];
        for (field, p) in cases {
            match p.validate() {
                Err(SimError::Config { field: f, message }) => {
                    assert_eq!(f, field);
                    assert!(message.contains("default"), "{message}");
                }
                other => panic!("{field}: {other:?}"),
            }
        }
        let edge = SimParams { settle_substeps: MAX_SUBSTEPS, ..d };
        assert!(edge.validate().is_ok(), "the bound itself is accepted");
    }
}
