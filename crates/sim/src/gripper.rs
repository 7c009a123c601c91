//! The floating parallel-jaw gripper: a kinematic palm (position-driven each physics step) carrying two
//! dynamic fingers on prismatic impulse joints with position motors. The controlled
//! point is the fingertip centre (TCP), 0.055 m below the palm centre; its yaw is about world z.
//!
//! Action semantics (docs/paper.md §3.2): the delta is clipped to ±0.05 m / ±π/4, the target TCP is
//! clamped to the workspace box, yaw is neither clipped nor wrapped, and the palm moves linearly over
//! the substeps; then the finger motors get the new open ratio (and, if it changed, a few more
//! substeps to close or open), as BulletArm moves the arm before it drives the gripper. Holding (§3.2 item 4): an object counts as held when both fingers touch it with
//! contact normals that are mostly horizontal (|n_z| < 0.3).
//!
//! Limitations: the palm is kinematic, so it pushes dynamic objects sideways with unlimited force and
//! passes through the fixed table (the TCP height clamp keeps it above). Moving down, it stops on the
//! top face of a movable object it does not hold, as BulletArm's force-limited arm stalls there
//! (see `descent_room`). The fingers open along the palm's local x axis.

use rapier3d::prelude::*;
use rapier3d_urdf::UrdfRobotHandles;

use crate::assets::{AssetKind, Assets};
use crate::error::Result;
use crate::world::Scene;

/// TCP (fingertip centre) below the palm centre, m.
pub const TCP_BELOW_PALM: f32 = 0.055;
/// Workspace box of the TCP (docs/paper.md §3.1): x, y, z ranges in metres.
pub const WORKSPACE: [[f32; 2]; 3] = [[0.25, 0.65], [-0.2, 0.2], [0.01, 0.25]];
pub use equiarm_types::{ACTION_DIM, Action, MAX_DPOS, MAX_DROT, NormalizedAction};

/// Handles and commanded state of the gripper in one scene.
#[derive(Clone, Debug)]
pub struct Gripper {
    /// The palm's rigid body (kinematic, position-based: moved by the simulator each physics step).
    pub palm: RigidBodyHandle,
    /// The finger bodies, [left, right] (dynamic).
    pub fingers: [RigidBodyHandle; 2],
    /// The first collider of each finger, [left, right]: their contacts decide what is held.
    pub finger_colliders: [ColliderHandle; 2],
    /// The prismatic palm–finger joints, [left, right], each driven by a position motor.
    pub finger_joints: [ImpulseJointHandle; 2],
    /// Commanded TCP position (the palm is kinematic, so this is where it is after a step).
    pub tcp: Vector,
    /// Commanded yaw, rad (not wrapped).
    pub yaw: f32,
    /// Last commanded open ratio.
    pub open_target: f32,
    /// Finger travel (half the maximum jaw gap), m, from the URDF limit.
    pub travel: f32,
    /// Finger half-thickness offset from the palm axis when closed, m.
    finger_offset: f32,
}

fn palm_pose(tcp: Vector, yaw: f32) -> Pose {
    Pose::from_parts(tcp + Vector::new(0.0, 0.0, TCP_BELOW_PALM), Rotation::from_rotation_z(yaw))
}

impl Gripper {
    /// Inserts the gripper with its TCP at `tcp`, yaw `yaw`, fingers commanded to `open_ratio`.
    pub fn insert(scene: &mut Scene, assets: &Assets, tcp: Vector, yaw: f32, open_ratio: f32) -> Result<Self> {
        let asset = assets.get(AssetKind::Gripper);
        let palm_i = asset.link_index("palm")?;
        let li = asset.link_index("left_finger")?;
        let ri = asset.link_index("right_finger")?;
        let lj = asset.joint_index("left_finger_joint")?;
        let rj = asset.joint_index("right_finger_joint")?;
        let travel = asset.robot.joints[lj].limit.upper as f32;
        let finger_offset = asset.robot.joints[lj].origin.xyz.0[0].abs() as f32;
        let friction = scene.params.finger_friction;
        let h: UrdfRobotHandles<ImpulseJointHandle> =
            scene.insert(asset, "gripper", palm_pose(tcp, yaw), false, friction)?;
        // Inserted links keep the URDF order (no link of the gripper is an empty frame to squeeze).
        let link_of = |urdf_index: usize| -> Result<&rapier3d_urdf::UrdfLinkHandle> {
            h.links.get(urdf_index).ok_or_else(|| crate::error::SimError::UrdfInvalid {
                file: asset.file.clone(),
                element: format!("link `{}`", asset.robot.links[urdf_index].name),
                message: "was not turned into a rigid body".into(),
            })
        };
        let palm = link_of(palm_i)?.body;
        let left = link_of(li)?;
        let right = link_of(ri)?;
        let joint_of = |urdf_index: usize| {
            h.joints.get(urdf_index).map(|j| j.joint).ok_or_else(|| crate::error::SimError::UrdfInvalid {
                file: asset.file.clone(),
                element: format!("joint `{}`", asset.robot.joints[urdf_index].name),
                message: "was not turned into a rapier joint".into(),
            })
        };
        let first_collider = |l: &rapier3d_urdf::UrdfLinkHandle, i: usize| {
            l.colliders.first().map(|c| c.handle).ok_or_else(|| crate::error::SimError::UrdfInvalid {
                file: asset.file.clone(),
                element: format!("link `{}`", asset.robot.links[i].name),
                message: "a finger needs a <collision> shape".into(),
            })
        };
        let finger_colliders = [first_collider(left, li)?, first_collider(right, ri)?];
        let mut g = Self {
            palm,
            fingers: [left.body, right.body],
            finger_colliders,
            finger_joints: [joint_of(lj)?, joint_of(rj)?],
            tcp,
            yaw,
            open_target: open_ratio,
            travel,
            finger_offset,
        };
        scene.physics.bodies[palm].set_body_type(RigidBodyType::KinematicPositionBased, true);
        let p = scene.params.clone();
        for j in g.finger_joints {
            if let Some(joint) = scene.physics.impulse_joints.get_mut(j, true) {
                joint.data.set_motor_model(JointAxis::LinX, MotorModel::ForceBased);
                joint.data.set_motor_max_force(JointAxis::LinX, p.grip_max_force);
            }
        }
        g.command_fingers(scene, open_ratio);
        Ok(g)
    }

    /// Sets both finger motors to `open_ratio` of their travel.
    pub fn command_fingers(&mut self, scene: &mut Scene, open_ratio: f32) {
        self.open_target = open_ratio.clamp(0.0, 1.0);
        let target = self.open_target * self.travel;
        for j in self.finger_joints {
            if let Some(joint) = scene.physics.impulse_joints.get_mut(j, true) {
                joint.data.set_motor_position(
                    JointAxis::LinX,
                    target,
                    scene.params.grip_stiffness,
                    scene.params.grip_damping,
                );
            }
        }
    }

    /// Executes one env step of `action` (already finite): clip, clamp, interpolate the palm over
    /// the substeps, then settle.
    pub fn apply(&mut self, scene: &mut Scene, action: Action) {
        let a = action.clipped();
        let start = self.tcp;
        let target = Vector::new(
            (start.x + a.dx).clamp(WORKSPACE[0][0], WORKSPACE[0][1]),
            (start.y + a.dy).clamp(WORKSPACE[1][0], WORKSPACE[1][1]),
            (start.z + a.dz).clamp(WORKSPACE[2][0], WORKSPACE[2][1]),
        );
        let yaw0 = self.yaw;
        let yaw1 = self.yaw + a.dtheta;
        let n = scene.params.substeps;
        // Only a descent needs the held objects (they do not stop it).
        let held = if target.z < start.z { self.held_bodies(scene) } else { Vec::new() };
        let mut z = start.z;
        for k in 1..=n {
            let s = k as f32 / n as f32;
            let mut p = start + (target - start) * s;
            if p.z < z {
                p.z = z - self.descent_room(scene, z - p.z, &held);
            }
            z = p.z;
            let y = yaw0 + (yaw1 - yaw0) * s;
            scene.physics.bodies[self.palm].set_next_kinematic_position(palm_pose(p, y));
            scene.step();
        }
        let target = Vector::new(target.x, target.y, z);
        self.tcp = target;
        self.yaw = yaw1;
        // As BulletArm's step: move first, then drive the fingers (with extra substeps only when the
        // jaw command changes, so a grasp closes where the arm arrived, not on the way down).
        let changed = (a.open_ratio - self.open_target).abs() > 1e-4;
        self.command_fingers(scene, a.open_ratio);
        let grip_steps = if changed { scene.params.grip_substeps } else { 0 };
        for _ in 0..scene.params.settle_substeps + grip_steps {
            scene.physics.bodies[self.palm].set_next_kinematic_position(palm_pose(target, yaw1));
            scene.step();
        }
    }

    /// How far (≤ `depth`, m) the gripper can move straight down from where it is before one of
    /// its colliders lands on top of a movable object that it does not hold.
    ///
    /// The palm is kinematic (unlimited force): without this it would press a block it lands on
    /// into the table until the solver ejects the block sideways, out of the workspace, at
    /// 1–2 m/s. BulletArm's arm is position-controlled with limited force (docs/paper.md §3.2): its
    /// IK stalls on top of the object instead. Side contacts (a finger against a block it sweeps)
    /// do not stop the descent; only surfaces facing up (outward normal z > 0.7) do.
    fn descent_room(&self, scene: &Scene, depth: f32, held: &[RigidBodyHandle]) -> f32 {
        /// Gap kept above the surface, m.
        const SKIN: f32 = 5e-4;
        let bodies = &scene.physics.bodies;
        let colliders = &scene.physics.colliders;
        let own = |b: RigidBodyHandle| b == self.palm || self.fingers.contains(&b);
        let down = Vector::new(0.0, 0.0, -1.0);
        let opts = rapier3d::parry::query::ShapeCastOptions {
            max_time_of_impact: depth + SKIN,
            target_distance: 0.0,
            stop_at_penetration: false,
            compute_impact_geometry_on_penetration: true,
        };
        let mut room = depth;
        for (_, gc) in colliders.iter().filter(|(_, c)| c.parent().is_some_and(own)) {
            for (_, oc) in colliders.iter() {
                let Some(ob) = oc.parent() else { continue };
                if own(ob) || held.contains(&ob) || !bodies[ob].is_dynamic() || oc.is_sensor() {
                    continue;
                }
                let hit = rapier3d::parry::query::cast_shapes(
                    oc.position(),
                    Vector::ZERO,
                    oc.shape(),
                    gc.position(),
                    down,
                    gc.shape(),
                    opts,
                );
                if let Ok(Some(hit)) = hit
                    && (oc.position().rotation * hit.normal1).z > 0.7
                {
                    room = room.min((hit.time_of_impact - SKIN).max(0.0));
                }
            }
        }
        room
    }

    /// Measured open ratio from the finger positions (mean of both fingers).
    pub fn open_ratio(&self, scene: &Scene) -> f32 {
        let palm = scene.physics.bodies[self.palm].position();
        let axis = palm.rotation * Vector::X;
        let mut q = 0.0;
        for (k, f) in self.fingers.iter().enumerate() {
            let d = scene.physics.bodies[*f].translation() - palm.translation;
            let sign = if k == 0 { -1.0 } else { 1.0 };
            q += sign * d.dot(axis) - self.finger_offset;
        }
        (q / (2.0 * self.travel)).clamp(0.0, 1.0)
    }

    /// The rigid bodies held between the fingers: touched by both fingers with contact normals
    /// |n_z| < 0.3.
    pub fn held_bodies(&self, scene: &Scene) -> Vec<RigidBodyHandle> {
        let touched = |finger: ColliderHandle| -> Vec<RigidBodyHandle> {
            let mut out = Vec::new();
            for pair in scene.physics.narrow_phase.contact_pairs_with(finger) {
                if !pair.has_any_active_contact() {
                    continue;
                }
                let horizontal =
                    pair.manifolds().iter().any(|m| !m.data.solver_contacts.is_empty() && m.data.normal.z.abs() < 0.3);
                if !horizontal {
                    continue;
                }
                let other = if pair.collider1 == finger { pair.collider2 } else { pair.collider1 };
                if let Some(b) = scene.physics.colliders.get(other).and_then(|c| c.parent())
                    && !self.fingers.contains(&b)
                    && b != self.palm
                {
                    out.push(b);
                }
            }
            out
        };
        let a = touched(self.finger_colliders[0]);
        let b = touched(self.finger_colliders[1]);
        let mut held: Vec<RigidBodyHandle> = a.into_iter().filter(|x| b.contains(x)).collect();
        held.dedup();
        held
    }
}
