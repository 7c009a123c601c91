//! The arm that carries the gripper in view (docs/arm.md): the 7-DoF arm of `urdf/arm.urdf`, standing
//! at BulletArm's Kuka base (−0.2, 0, 0), its joints set by inverse kinematics each time the scene is
//! observed so that its `tool` frame is the gripper's palm. It is drawn, not simulated: its colliders
//! are disabled (rapier treats them as removed: no contacts, no ray casts) and have no rigid body,
//! and they are added after everything else, so the bodies, contacts and segmentation ids of the
//! rest of the scene are the same with the arm as without it. The renderers draw them like any
//! other collider, so the arm occludes what lies behind it.
//!
//! Inverse kinematics is closed-form for the chain's layout (checked when the URDF is read, [`Chain::of`]):
//! joint axes z, y, z, y, z, y, z, every joint on the arm's centre line, so that joints 5–7 form a
//! spherical wrist at joint 6. The redundancy is resolved by holding joint 3 at 0 (the elbow in the
//! vertical plane through the base and the wrist), elbow up; the wrist's two solutions are told apart
//! by the smaller turn of joint 5.
//!
//! Limitations: joint limits are not enforced (the arm only has to be seen where the gripper is); a
//! pose out of reach leaves the arm stretched toward it ([`Ik::reached`] false), which no gripper pose
//! of the workspace is; the arm casts no shadow (ray casts do not see disabled colliders).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;
use rapier3d_urdf::{UrdfLoaderOptions, UrdfRobot};

use crate::assets::{Asset, AssetKind, Assets};
use crate::error::{Result, SimError};
use crate::world::{Scene, Visual};

/// Where the arm's base stands, world metres (BulletArm's Kuka iiwa).
pub const BASE: [f64; 3] = [-0.2, 0.0, 0.0];

/// Number of revolute joints.
pub const JOINTS: usize = 7;

/// The axis each joint must turn about, in its own frame (0 = x, 1 = y, 2 = z).
const AXES: [usize; JOINTS] = [2, 1, 2, 1, 2, 1, 2];

/// The arm's kinematic chain, read from its URDF and checked: the links from `base_link` to `tool`,
/// each joint's fixed transform and axis, and the lengths the inverse kinematics uses.
#[derive(Clone, Debug)]
pub struct Chain {
    /// URDF link index of each chain link: base, the seven moving links, the tool frame.
    links: Vec<usize>,
    /// Each joint's fixed transform from its parent link's frame (seven revolute joints, then the tool's).
    origins: Vec<Isometry3<f64>>,
    /// Height of joint 2 (the shoulder) above the base, m.
    shoulder: f64,
    /// Joint 2 to joint 4 (upper arm), m.
    upper: f64,
    /// Joint 4 to joint 6 (forearm, to the wrist centre), m.
    fore: f64,
    /// Joint 6 to the tool frame, m.
    wrist: f64,
}

/// A solution of the inverse kinematics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ik {
    /// Joint angles, rad.
    pub q: [f64; JOINTS],
    /// Whether the wrist centre was within reach (otherwise the arm points at it, stretched).
    pub reached: bool,
}

fn iso(o: &rapier3d_urdf::urdf_rs::Pose) -> Isometry3<f64> {
    let [x, y, z] = o.xyz.0;
    let [r, p, yaw] = o.rpy.0;
    Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::from_euler_angles(r, p, yaw))
}

impl Chain {
    /// Reads the chain of `asset` (`arm.urdf`), refusing a file whose layout the inverse kinematics
    /// does not solve, with an error naming the joint.
    pub fn of(asset: &Asset) -> Result<Self> {
        let bad =
            |element: String, message: String| SimError::UrdfInvalid { file: asset.file.clone(), element, message };
        let mut links = vec![asset.link_index("base_link")?];
        let mut origins = Vec::new();
        let mut lengths = Vec::new();
        for k in 0..=JOINTS {
            let name = if k < JOINTS { format!("joint{}", k + 1) } else { "tool_joint".to_string() };
            let j = &asset.robot.joints[asset.joint_index(&name)?];
            let el = format!("joint `{name}`");
            let parent = asset.link_index(&j.parent.link)?;
            if parent != links[k] {
                return Err(bad(el, format!("must follow link `{}`", asset.robot.links[links[k]].name)));
            }
            let [x, y, z] = j.origin.xyz.0;
            if x != 0.0 || y != 0.0 || z < 0.0 {
                return Err(bad(el, "must lie on the arm's centre line (origin 0 0 d, d >= 0)".into()));
            }
            use rapier3d_urdf::urdf_rs::JointType;
            if k < JOINTS {
                let axis = j.axis.xyz.0;
                let want: [f64; 3] = std::array::from_fn(|i| if i == AXES[k] { 1.0 } else { 0.0 });
                if j.joint_type != JointType::Revolute || axis != want || j.origin.rpy.0 != [0.0; 3] {
                    return Err(bad(el, format!("must be revolute about {:?} with no rotation in its origin", want)));
                }
            } else {
                let rpy = j.origin.rpy.0;
                if j.joint_type != JointType::Fixed
                    || (rpy[0] - std::f64::consts::PI).abs() > 1e-9
                    || rpy[1] != 0.0
                    || rpy[2] != 0.0
                {
                    return Err(bad(el, "must be fixed, turned half a turn about x (rpy π 0 0)".into()));
                }
            }
            links.push(asset.link_index(&j.child.link)?);
            origins.push(iso(&j.origin));
            lengths.push(z);
        }
        Ok(Self {
            links,
            origins,
            shoulder: lengths[0] + lengths[1],
            upper: lengths[2] + lengths[3],
            fore: lengths[4] + lengths[5],
            wrist: lengths[6] + lengths[7],
        })
    }

    /// The pose of every chain link (base, the seven moving links, the tool frame) for joint angles
    /// `q` with the base at `base`.
    pub fn link_poses(&self, base: &Isometry3<f64>, q: &[f64; JOINTS]) -> Vec<Isometry3<f64>> {
        let mut out = Vec::with_capacity(JOINTS + 2);
        out.push(*base);
        for (k, o) in self.origins.iter().enumerate() {
            let mut t = out[k] * o;
            if k < JOINTS {
                let axis = Vector3::ith_axis(AXES[k]);
                t *= UnitQuaternion::from_axis_angle(&axis, q[k]);
            }
            out.push(t);
        }
        out
    }

    /// The tool frame for joint angles `q` (forward kinematics).
    pub fn tool(&self, base: &Isometry3<f64>, q: &[f64; JOINTS]) -> Isometry3<f64> {
        self.link_poses(base, q)[JOINTS + 1]
    }

    /// Joint angles that put the tool frame at `tool` (closed form, see the module's text).
    pub fn ik(&self, base: &Isometry3<f64>, tool: &Isometry3<f64>) -> Ik {
        use std::f64::consts::PI;
        let t = base.inverse() * tool;
        // The wrist centre: from the tool back along the chain's last two links (the tool frame's z
        // points back up the arm).
        let w = t.translation.vector + t.rotation * Vector3::z() * self.wrist;
        let q1 = w.y.atan2(w.x);
        let (r, h) = (w.x.hypot(w.y), w.z - self.shoulder);
        let (u, f) = (self.upper, self.fore);
        let c = (r * r + h * h - u * u - f * f) / (2.0 * u * f);
        let reached = (-1.0..=1.0).contains(&c);
        let q4 = c.clamp(-1.0, 1.0).acos();
        let q2 = r.atan2(h) - (f * q4.sin()).atan2(u + f * q4.cos());
        let mut q = [q1, q2, 0.0, q4, 0.0, 0.0, 0.0];
        // The wrist: link 4's frame with q5..q7 = 0, and link 7's frame the tool asks for.
        let r4 = self.link_poses(base, &q)[4].rotation;
        let r7 = tool.rotation * self.origins[JOINTS].rotation.inverse();
        let m = (r4.inverse() * r7).to_rotation_matrix().into_inner();
        // m = Rz(q5) · Ry(q6) · Rz(q7)
        let s6 = m[(0, 2)].hypot(m[(1, 2)]);
        let (mut q5, mut q6, mut q7) = if s6 > 1e-9 {
            (m[(1, 2)].atan2(m[(0, 2)]), s6.atan2(m[(2, 2)]), m[(2, 1)].atan2(-m[(2, 0)]))
        } else {
            (0.0, s6.atan2(m[(2, 2)]), m[(1, 0)].atan2(m[(0, 0)]))
        };
        if q5.abs() > PI / 2.0 {
            // the other solution (q5 + π, −q6, q7 + π), with the smaller turn of joint 5
            let wrap = |a: f64| (a + PI).rem_euclid(2.0 * PI) - PI;
            (q5, q6, q7) = (wrap(q5 + PI), -q6, wrap(q7 + PI));
        }
        q[4..7].copy_from_slice(&[q5, q6, q7]);
        Ik { q, reached }
    }
}

fn to_pose(t: &Isometry3<f64>) -> Pose {
    let v = t.translation.vector;
    let q = t.rotation.quaternion();
    Pose::from_parts(
        Vector::new(v.x as f32, v.y as f32, v.z as f32),
        Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize(),
    )
}

fn to_iso(p: &Pose) -> Isometry3<f64> {
    let (v, q) = (p.translation, p.rotation);
    Isometry3::from_parts(
        Translation3::new(v.x as f64, v.y as f64, v.z as f64),
        UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q.w as f64, q.x as f64, q.y as f64, q.z as f64)),
    )
}

/// The arm in one scene: its chain, where it stands, and its drawn parts.
#[derive(Clone, Debug)]
pub struct Arm {
    chain: Chain,
    base: Isometry3<f64>,
    /// Each drawn collider: its chain link, its handle and its pose in the link's frame.
    parts: Vec<(usize, ColliderHandle, Pose)>,
    /// The joint angles of the last [`Arm::follow`], rad.
    q: [f64; JOINTS],
}

impl Arm {
    /// Adds the arm's links to `scene` as drawn-only colliders (segmentation names `arm/LINK`), in
    /// the zero configuration until the first [`Arm::follow`]. Call it after every other body is in.
    pub fn insert(scene: &mut Scene, assets: &Assets) -> Result<Self> {
        let asset = assets.get(AssetKind::Arm);
        let chain = Chain::of(asset)?;
        let opts = UrdfLoaderOptions {
            collider_blueprint: ColliderBuilder::default().density(0.0).enabled(false),
            ..Default::default()
        };
        let robot = UrdfRobot::from_robot(&asset.robot, opts, std::path::Path::new("."));
        let base = Isometry3::translation(BASE[0], BASE[1], BASE[2]);
        let mut parts = Vec::new();
        for link in robot.links {
            let Some(k) = chain.links.iter().position(|&i| i == link.urdf_link_index) else { continue };
            if link.colliders.is_empty() {
                continue;
            }
            let seg = u16::try_from(scene.seg_names.len())
                .map_err(|_| SimError::Config { field: "scene", message: "more than 65535 bodies".into() })?;
            scene.seg_names.push(format!("arm/{}", asset.robot.links[link.urdf_link_index].name));
            let color = asset.link_colors[link.urdf_link_index];
            for c in link.colliders {
                let local = *c.collider.position();
                let handle = scene.physics.colliders.insert(c.collider);
                scene.visuals.push(Visual { collider: handle, seg, color, checker: false });
                parts.push((k, handle, local));
            }
        }
        let arm = Self { chain, base, parts, q: [0.0; JOINTS] };
        arm.place(scene);
        Ok(arm)
    }

    /// Sets the joints by inverse kinematics so that the tool frame is `palm` (the gripper palm's
    /// pose), and moves the drawn parts there.
    pub fn follow(&mut self, scene: &mut Scene, palm: &Pose) {
        self.q = self.chain.ik(&self.base, &to_iso(palm)).q;
        self.place(scene);
    }

    fn place(&self, scene: &mut Scene) {
        let poses = self.chain.link_poses(&self.base, &self.q);
        for (k, handle, local) in &self.parts {
            if let Some(c) = scene.physics.colliders.get_mut(*handle) {
                c.set_position(to_pose(&poses[*k]) * *local);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gripper::{TCP_BELOW_PALM, WORKSPACE};

    /// Issue 58: the joint angles the inverse kinematics gives put the tool frame on the gripper's
    /// palm within 1 mm and 1° over the whole workspace and any yaw.
    #[test]
    fn ik_reaches_every_gripper_pose_of_the_workspace_within_1_mm_and_1_degree() {
        let assets = Assets::bundled().unwrap();
        let chain = Chain::of(assets.get(AssetKind::Arm)).unwrap();
        let base = Isometry3::translation(BASE[0], BASE[1], BASE[2]);
        let mut rng = crate::rng::Rng::new(58);
        let (mut worst_mm, mut worst_deg) = (0.0f64, 0.0f64);
        for i in 0..2000 {
            let mut p = [0.0f64; 3];
            for (j, (a, r)) in p.iter_mut().zip(WORKSPACE).enumerate() {
                // the eight corners first, then uniform draws
                *a = if i < 8 { r[(i >> j) & 1] as f64 } else { rng.uniform(r[0], r[1]) as f64 };
            }
            let yaw = if i < 8 { (i as f64) * 0.9 } else { rng.uniform(-7.0, 7.0) as f64 };
            let palm = Isometry3::from_parts(
                Translation3::new(p[0], p[1], p[2] + TCP_BELOW_PALM as f64),
                UnitQuaternion::from_euler_angles(0.0, 0.0, yaw),
            );
            let ik = chain.ik(&base, &palm);
            assert!(ik.reached, "{palm:?}");
            let got = chain.tool(&base, &ik.q);
            worst_mm = worst_mm.max((got.translation.vector - palm.translation.vector).norm() * 1e3);
            worst_deg = worst_deg.max(got.rotation.angle_to(&palm.rotation).to_degrees());
        }
        assert!(worst_mm < 1.0 && worst_deg < 1.0, "worst {worst_mm} mm, {worst_deg}°");
    }

    #[test]
    fn a_chain_the_ik_cannot_solve_is_refused_naming_the_joint() {
        let text = AssetKind::Arm.bundled_text().replace(
            r#"<child link="link4"/><origin xyz="0 0 0.25"/><axis xyz="0 1 0"/>"#,
            r#"<child link="link4"/><origin xyz="0.1 0 0.25"/><axis xyz="0 1 0"/>"#,
        );
        let asset = crate::assets::parse_urdf("arm.urdf", &text).unwrap();
        let e = Chain::of(&asset).unwrap_err().to_string();
        assert!(e.contains("joint4") && e.contains("centre line"), "{e}");
    }
}
