//! The gripper action (docs/paper.md §1.2): physical units for the simulator, the normalised vector
//! in [-1, 1]^[`ACTION_DIM`] for the agent, and the one mapping between them.

/// Components of an action: (p, dx, dy, dz, dθ).
pub const ACTION_DIM: usize = 5;

/// An action as the agent sees it: each component in [-1, 1], in the order (p, dx, dy, dz, dθ).
pub type NormalizedAction = [f32; ACTION_DIM];

/// Largest TCP displacement per step along each axis, metres (docs/paper.md §1.2).
pub const MAX_DPOS: f32 = 0.05;
/// Largest yaw change per step, radians (π/4).
pub const MAX_DROT: f32 = std::f32::consts::FRAC_PI_4;

/// A gripper command in physical units (docs/paper.md §1.2): target open ratio in [0, 1]
/// (0 closed, 1 open), TCP position deltas in metres, yaw delta in radians.
#[derive(Clone, Copy, Debug, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Action {
    /// Target jaw opening p: 0 closed, 1 open to the full finger travel; clipped to [0, 1].
    pub open_ratio: f32,
    /// TCP displacement along world x, m, clipped to ±[`MAX_DPOS`] (0.05 m).
    pub dx: f32,
    /// TCP displacement along world y, m, clipped to ±[`MAX_DPOS`] (0.05 m).
    pub dy: f32,
    /// TCP displacement along world z, m, clipped to ±[`MAX_DPOS`] (0.05 m).
    pub dz: f32,
    /// Yaw change about world z, rad, clipped to ±[`MAX_DROT`] (π/4).
    pub dtheta: f32,
}

impl Action {
    /// An action from its components, as given (clipping happens in [`Action::clipped`] and when it is applied).
    pub fn new(open_ratio: f32, dx: f32, dy: f32, dz: f32, dtheta: f32) -> Self {
        Self { open_ratio, dx, dy, dz, dtheta }
    }

    /// Components in the order (p, dx, dy, dz, dθ), physical units.
    pub fn to_array(self) -> [f32; ACTION_DIM] {
        [self.open_ratio, self.dx, self.dy, self.dz, self.dtheta]
    }

    /// Whether all components are finite (no NaN or ±inf); the simulator rejects the other actions.
    pub fn is_finite(&self) -> bool {
        self.to_array().iter().all(|x| x.is_finite())
    }

    /// Clipped to the action ranges: p ∈ [0, 1], |d| ≤ 0.05, |dθ| ≤ π/4.
    pub fn clipped(self) -> Self {
        Self {
            open_ratio: self.open_ratio.clamp(0.0, 1.0),
            dx: self.dx.clamp(-MAX_DPOS, MAX_DPOS),
            dy: self.dy.clamp(-MAX_DPOS, MAX_DPOS),
            dz: self.dz.clamp(-MAX_DPOS, MAX_DPOS),
            dtheta: self.dtheta.clamp(-MAX_DROT, MAX_DROT),
        }
    }

    /// The agent's normalised action of this physical action, after clipping (docs/paper.md §1.2).
    pub fn to_normalized(self) -> NormalizedAction {
        let a = self.clipped();
        [a.open_ratio * 2.0 - 1.0, a.dx / MAX_DPOS, a.dy / MAX_DPOS, a.dz / MAX_DPOS, a.dtheta / MAX_DROT]
    }

    /// Decodes a normalised action (values outside [-1, 1] are clipped).
    pub fn from_normalized(u: NormalizedAction) -> Self {
        let u = u.map(|x| x.clamp(-1.0, 1.0));
        Self::new((u[0] + 1.0) / 2.0, u[1] * MAX_DPOS, u[2] * MAX_DPOS, u[3] * MAX_DPOS, u[4] * MAX_DROT)
    }
}
