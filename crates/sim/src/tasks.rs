//! The five close-loop tasks of docs/paper.md §3.3 (scene, spawn randomisation, success and validity
//! tests) and their expert planners (§3.5).
//!
//! Planners are closed loop: every step they re-read the privileged state and aim at the current
//! waypoint with `getActionByGoalPose` semantics (each axis clamped to ±0.05 m, yaw to ±π/4; a waypoint
//! is reached when the clamped step lands on it, and then the planner advances). Deviations from the
//! paper, all documented where they are made: waypoints are clipped to the workspace (BulletArm does it
//! only for pushing), and target yaws are taken modulo the gripper's (π) or the cube's (π/2) symmetry
//! nearest to the current yaw, rather than wrapped to (−π/2, π/2].
//!
//! Limitations: the drawer's handle is part of the scene as its own body on a fixed impulse joint (as
//! in BulletArm, a separate body fixed to the drawer); the bowl is a box-built approximation of
//! BulletArm's bowl mesh (rim ≈ 0.155 m, 0.063 m tall).

use std::f32::consts::{FRAC_PI_2, PI};

use rapier3d::parry;
use rapier3d::prelude::*;

use crate::assets::{AssetKind, Assets};
use crate::error::Result;
use crate::gripper::{Action, Gripper, MAX_DPOS, MAX_DROT, WORKSPACE};
use crate::rng::Rng;
use crate::world::{Scene, yaw_of};

pub use equiarm_types::TaskKind;

/// Gripper reset pose (docs/paper.md §3.1): TCP (0.45, 0, 0.20), yaw 0, fully open.
pub const RESET_TCP: [f32; 3] = [0.45, 0.0, 0.20];
const CUBE_HALF: f32 = 0.025;
const BLOCK_HALF_HEIGHT: f32 = 0.025;
const GOAL_SIDE: f32 = 22.0 * 0.6 / 152.0;

/// Per-episode task state: the task's bodies and the planner's waypoint index.
#[derive(Clone, Debug)]
pub struct TaskState {
    /// The task: selects the meaning of `bodies`, the success and validity tests and the planner.
    pub kind: TaskKind,
    /// pulling: `[block 1 (moved), block 2]`; pushing, picking: `[cube]`; drawer: `[cabinet, drawer,
    /// handle]`; bowl: `[cube, bowl]`.
    pub bodies: Vec<RigidBodyHandle>,
    /// Pushing goal centre (xy).
    pub goal: Option<[f32; 2]>,
    /// Planner waypoint index.
    pub stage: usize,
    /// Yaw kept fixed during a contact stage (pulling and pushing sweep with a fixed yaw).
    pub locked_yaw: Option<f32>,
}

fn sample_xy(rng: &mut Rng, padding: f32, min_dist: f32, others: &[[f32; 2]]) -> [f32; 2] {
    let lo_x = WORKSPACE[0][0] + padding / 2.0;
    let hi_x = WORKSPACE[0][1] - padding / 2.0;
    let lo_y = WORKSPACE[1][0] + padding / 2.0;
    let hi_y = WORKSPACE[1][1] - padding / 2.0;
    let mut p = [0.0; 2];
    for _ in 0..100 {
        p = [rng.uniform(lo_x, hi_x), rng.uniform(lo_y, hi_y)];
        if others.iter().all(|o| ((o[0] - p[0]).powi(2) + (o[1] - p[1]).powi(2)).sqrt() > min_dist) {
            break;
        }
    }
    p
}

fn pose_xy(p: [f32; 2], z: f32, yaw: f32) -> Pose {
    Pose::from_parts(Vector::new(p[0], p[1], z), Rotation::from_rotation_z(yaw))
}

impl TaskState {
    /// Populates `scene` with the task's objects (the gripper is already in it).
    pub fn spawn(kind: TaskKind, scene: &mut Scene, assets: &Assets, rng: &mut Rng) -> Result<Self> {
        let fr = scene.params.object_friction;
        let mut bodies = Vec::new();
        let mut goal = None;
        match kind {
            TaskKind::BlockPulling => {
                let mut placed = Vec::new();
                for k in 0..2 {
                    let p = sample_xy(rng, 0.136, 0.136, &placed);
                    let yaw = rng.uniform(-FRAC_PI_2, FRAC_PI_2);
                    placed.push(p);
                    let h = scene.insert(
                        assets.get(AssetKind::FlatBlock),
                        &format!("block{}", k + 1),
                        pose_xy(p, BLOCK_HALF_HEIGHT + 1e-3, yaw),
                        false,
                        fr,
                    )?;
                    bodies.push(h.links[0].body);
                }
            }
            TaskKind::BlockPushing | TaskKind::BlockPicking => {
                let p = sample_xy(rng, 0.12, 0.0, &[]);
                let yaw = if kind == TaskKind::BlockPicking {
                    rng.uniform(-PI / 4.0, PI / 4.0)
                } else {
                    rng.uniform(-FRAC_PI_2, FRAC_PI_2)
                };
                let h =
                    scene.insert(assets.get(AssetKind::Cube), "cube", pose_xy(p, CUBE_HALF + 1e-3, yaw), false, fr)?;
                bodies.push(h.links[0].body);
                if kind == TaskKind::BlockPushing {
                    let g = sample_xy(rng, 0.13, 0.09, &[p]);
                    let half = GOAL_SIDE / 2.0;
                    scene.add_marker(
                        "goal",
                        pose_xy(g, 0.0025, 0.0),
                        Vector::new(half, half, 0.0025),
                        [0.1, 0.3, 0.95],
                    );
                    goal = Some(g);
                }
            }
            TaskKind::DrawerOpening => {
                let yaw = rng.uniform(0.0, 2.0 * PI);
                let a = rng.uniform(0.15, 0.20);
                let b = rng.uniform(-0.1, 0.1);
                let (s, c) = yaw.sin_cos();
                let centre = [0.45 + c * a - s * b, c * b + s * a];
                let asset = assets.get(AssetKind::Drawer);
                let h = scene.insert(asset, "drawer", pose_xy(centre, 0.0, yaw), true, fr)?;
                let missing = |element: String| crate::error::SimError::UrdfInvalid {
                    file: asset.file.clone(),
                    element,
                    message: "was not turned into a rapier body or joint".into(),
                };
                for name in ["cabinet", "drawer", "handle"] {
                    let i = asset.link_index(name)?;
                    bodies.push(h.links.get(i).ok_or_else(|| missing(format!("link `{name}`")))?.body);
                }
                let j = asset.joint_index("drawer_joint")?;
                let joint = h.joints.get(j).ok_or_else(|| missing("joint `drawer_joint`".into()))?.joint;
                let resist = scene.params.drawer_resistance;
                if let Some(jt) = scene.physics.impulse_joints.get_mut(joint, true) {
                    jt.data.set_motor_model(JointAxis::LinX, MotorModel::ForceBased);
                    jt.data.set_motor_velocity(JointAxis::LinX, 0.0, 1000.0);
                    jt.data.set_motor_max_force(JointAxis::LinX, resist);
                }
            }
            TaskKind::BlockInBowl => {
                let pc = sample_xy(rng, 0.12, 0.0, &[]);
                let yc = rng.uniform(-FRAC_PI_2, FRAC_PI_2);
                let pb = sample_xy(rng, 0.17, 0.17, &[pc]);
                let yb = rng.uniform(-FRAC_PI_2, FRAC_PI_2);
                let h =
                    scene.insert(assets.get(AssetKind::Cube), "cube", pose_xy(pc, CUBE_HALF + 1e-3, yc), false, fr)?;
                bodies.push(h.links[0].body);
                let h = scene.insert(assets.get(AssetKind::Bowl), "bowl", pose_xy(pb, 1e-3, yb), false, fr)?;
                bodies.push(h.links[0].body);
            }
        }
        Ok(Self { kind, bodies, goal, stage: 0, locked_yaw: None })
    }

    fn xy(scene: &Scene, b: RigidBodyHandle) -> [f32; 2] {
        let t = scene.physics.bodies[b].translation();
        [t.x, t.y]
    }

    /// How far the drawer is pulled out of the cabinet, m.
    pub fn drawer_opening(&self, scene: &Scene) -> f32 {
        let cab = scene.physics.bodies[self.bodies[0]].position();
        let drw = scene.physics.bodies[self.bodies[1]].translation();
        let x = cab.rotation * Vector::X;
        (cab.translation - drw).dot(x)
    }

    /// Whether two bodies' colliders are within `tol` metres of each other.
    fn touching(scene: &Scene, a: RigidBodyHandle, b: RigidBodyHandle, tol: f32) -> bool {
        let ca = scene.physics.bodies[a].colliders();
        let cb = scene.physics.bodies[b].colliders();
        for &x in ca {
            for &y in cb {
                let (cx, cy) = (&scene.physics.colliders[x], &scene.physics.colliders[y]);
                if let Ok(d) = parry::query::distance(cx.position(), cx.shape(), cy.position(), cy.shape())
                    && d.distance <= tol
                {
                    return true;
                }
            }
        }
        false
    }

    /// The task's success test (reward 1).
    pub fn success(&self, scene: &Scene, gripper: &Gripper, held: &[RigidBodyHandle]) -> bool {
        match self.kind {
            TaskKind::BlockPulling => Self::touching(scene, self.bodies[0], self.bodies[1], 0.002),
            TaskKind::BlockPushing => {
                let c = Self::xy(scene, self.bodies[0]);
                let g = self.goal.unwrap_or(c);
                ((c[0] - g[0]).powi(2) + (c[1] - g[1]).powi(2)).sqrt() < 0.05
            }
            TaskKind::BlockPicking => held.contains(&self.bodies[0]) && gripper.tcp.z > 0.15,
            TaskKind::DrawerOpening => self.drawer_opening(scene) > 0.15,
            TaskKind::BlockInBowl => {
                let bowl = scene.physics.bodies[self.bodies[1]].position();
                let up = (bowl.rotation * Vector::Z).z;
                let upright = up > (20.0f32).to_radians().cos();
                let c = Self::xy(scene, self.bodies[0]);
                let b = [bowl.translation.x, bowl.translation.y];
                let close = ((c[0] - b[0]).powi(2) + (c[1] - b[1]).powi(2)).sqrt() < 0.03;
                upright && close && Self::touching(scene, self.bodies[0], self.bodies[1], 0.002)
            }
        }
    }

    /// Validity (§3.2 item 5): every non-held movable object's centre stays inside the workspace in
    /// xy (pushing and bowl: a box 0.05 m larger). The drawer task has no validity test.
    pub fn valid(&self, scene: &Scene, held: &[RigidBodyHandle]) -> bool {
        let margin = match self.kind {
            TaskKind::DrawerOpening => return true,
            TaskKind::BlockPushing | TaskKind::BlockInBowl => 0.05,
            _ => 0.0,
        };
        self.bodies.iter().filter(|b| !held.contains(b)).all(|&b| {
            let p = Self::xy(scene, b);
            p[0] > WORKSPACE[0][0] - margin
                && p[0] < WORKSPACE[0][1] + margin
                && p[1] > WORKSPACE[1][0] - margin
                && p[1] < WORKSPACE[1][1] + margin
        })
    }

    /// The expert action for the current state; advances the waypoint index when a waypoint is reached.
    pub fn expert_action(&mut self, scene: &Scene, gripper: &Gripper, held: &[RigidBodyHandle]) -> Action {
        match self.kind {
            TaskKind::BlockPicking => {
                let cube = self.bodies[0];
                if held.contains(&cube) {
                    return Action::new(0.0, 0.0, 0.0, MAX_DPOS, 0.0);
                }
                let p = scene.physics.bodies[cube].position();
                let yaw = nearest_equivalent(yaw_of(p.rotation), gripper.yaw, FRAC_PI_2);
                let (a, reached) = toward(gripper, p.translation, yaw);
                Action { open_ratio: if reached { 0.0 } else { 1.0 }, ..a }
            }
            TaskKind::BlockPulling => {
                let b1 = Self::xy(scene, self.bodies[0]);
                let b2 = Self::xy(scene, self.bodies[1]);
                let (mut ux, mut uy) = (b1[0] - b2[0], b1[1] - b2[1]);
                let n = (ux * ux + uy * uy).sqrt().max(1e-6);
                ux /= n;
                uy /= n;
                let g = [b1[0] + 0.08 * ux, b1[1] + 0.08 * uy];
                let yaw = nearest_equivalent(uy.atan2(ux) + FRAC_PI_2, gripper.yaw, PI);
                let wps = [(g, 0.10), (g, 0.03), (b2, 0.03)];
                self.follow(gripper, &wps.map(|(p, z)| (Vector::new(p[0], p[1], z), 1.0, 1.0)), yaw)
            }
            TaskKind::BlockPushing => {
                let c = Self::xy(scene, self.bodies[0]);
                let g = self.goal.unwrap_or(c);
                let (mut rx, mut ry) = (g[0] - c[0], g[1] - c[1]);
                let n = (rx * rx + ry * ry).sqrt().max(1e-6);
                rx /= n;
                ry /= n;
                let p0 = [c[0] - 0.08 * rx, c[1] - 0.08 * ry];
                let gg = [g[0] - 0.035 * rx, g[1] - 0.035 * ry];
                let yaw = nearest_equivalent(ry.atan2(rx) + FRAC_PI_2, gripper.yaw, PI);
                let wps = [(p0, 0.11), (p0, 0.03), (gg, 0.03)];
                self.follow(gripper, &wps.map(|(p, z)| (Vector::new(p[0], p[1], z), 0.5, 0.5)), yaw)
            }
            TaskKind::DrawerOpening => {
                let cab = scene.physics.bodies[self.bodies[0]].position();
                let xd = cab.rotation * Vector::X;
                let handle = scene.physics.bodies[self.bodies[2]].translation();
                let h = handle + xd * 0.02 - Vector::Z * 0.02;
                let yaw = nearest_equivalent(yaw_of(cab.rotation) + FRAC_PI_2, gripper.yaw, PI);
                let wps = [(h + Vector::Z * 0.1, 0.0, 0.0), (h, 0.0, 0.0), (h - xd * 0.2, 0.0, 0.0)];
                self.follow(gripper, &wps, yaw)
            }
            TaskKind::BlockInBowl => {
                let cube = scene.physics.bodies[self.bodies[0]].position();
                let bowl = scene.physics.bodies[self.bodies[1]].translation();
                let yaw = nearest_equivalent(yaw_of(cube.rotation), gripper.yaw, FRAC_PI_2);
                let c = cube.translation;
                // NOTE: the lift waypoint is a fixed height above the table (cube rest height + 0.1 m)
                // rather than "cube + 0.1 m": once held, the cube moves with the gripper and a target
                // relative to it would recede forever.
                let lift = Vector::new(gripper.tcp.x, gripper.tcp.y, CUBE_HALF + 0.1);
                let wps = [
                    (c + Vector::Z * 0.1, 1.0, 1.0),
                    (c, 1.0, 0.0),
                    (lift, 0.0, 0.0),
                    (Vector::new(bowl.x, bowl.y, 0.1), 0.0, 1.0),
                ];
                self.follow(gripper, &wps, yaw)
            }
        }
    }

    /// Waypoint following: (position, p while moving, p on the arrival step). Cycles.
    ///
    /// NOTE: for pulling and pushing, the yaw is frozen during the last (sweeping) stage at the value
    /// it had when the stage began. Re-planning the yaw from the moving block every step (as the
    /// waypoint positions are) turned the gripper while it was in contact and flung the block.
    fn follow(&mut self, gripper: &Gripper, wps: &[(Vector, f32, f32)], yaw: f32) -> Action {
        let stage = self.stage % wps.len();
        let (pos, p_move, p_arrive) = wps[stage];
        let sweeping = matches!(self.kind, TaskKind::BlockPulling | TaskKind::BlockPushing) && stage + 1 == wps.len();
        let yaw = match (sweeping, self.locked_yaw) {
            (true, Some(y)) => y,
            (true, None) => {
                self.locked_yaw = Some(gripper.yaw);
                gripper.yaw
            }
            (false, _) => {
                self.locked_yaw = None;
                yaw
            }
        };
        let (a, reached) = toward(gripper, clip_to_workspace(pos), yaw);
        if reached {
            self.stage = (stage + 1) % wps.len();
            Action { open_ratio: p_arrive, ..a }
        } else {
            Action { open_ratio: p_move, ..a }
        }
    }
}

fn clip_to_workspace(p: Vector) -> Vector {
    Vector::new(
        p.x.clamp(WORKSPACE[0][0], WORKSPACE[0][1]),
        p.y.clamp(WORKSPACE[1][0], WORKSPACE[1][1]),
        p.z.clamp(WORKSPACE[2][0], WORKSPACE[2][1]),
    )
}

/// `getActionByGoalPose`: clamped delta toward the goal, and whether that step lands on it.
fn toward(gripper: &Gripper, goal: Vector, goal_yaw: f32) -> (Action, bool) {
    let d = goal - gripper.tcp;
    let dth = goal_yaw - gripper.yaw;
    let reached = d.x.abs() < MAX_DPOS && d.y.abs() < MAX_DPOS && d.z.abs() < MAX_DPOS && dth.abs() < MAX_DROT;
    let a = Action::new(
        0.0,
        d.x.clamp(-MAX_DPOS, MAX_DPOS),
        d.y.clamp(-MAX_DPOS, MAX_DPOS),
        d.z.clamp(-MAX_DPOS, MAX_DPOS),
        dth.clamp(-MAX_DROT, MAX_DROT),
    );
    (a, reached)
}

/// The angle congruent to `angle` modulo `period` that is nearest to `reference`.
pub fn nearest_equivalent(angle: f32, reference: f32, period: f32) -> f32 {
    angle + ((reference - angle) / period).round() * period
}

#[cfg(test)]
mod name_tests {
    use super::TaskKind;

    #[test]
    fn names_round_trip_and_all_selects_every_task() {
        for t in TaskKind::ALL {
            assert_eq!(TaskKind::from_name(t.name()), Some(t));
            assert_eq!(TaskKind::select(t.name()), Ok(vec![t]));
        }
        assert_eq!(TaskKind::from_name("close_loop_block_pulling"), Some(TaskKind::BlockPulling));
        assert_eq!(TaskKind::select("all").unwrap(), TaskKind::ALL.to_vec());
        let e = TaskKind::select("block_pullin").unwrap_err();
        let e = e.to_string();
        assert!(e.contains("block_pullin") && e.contains("drawer_opening") && e.contains("all"), "{e}");
    }
}
