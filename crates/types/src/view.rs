//! Named camera views: the paper's oblique view and the view-angle sweep of docs/paper.md §5.1. The
//! camera geometry of each lives with the camera (`equiarm_sim::CameraConfig::from`).

crate::named_enum! {
    /// A camera preset.
    pub enum ViewPreset: "view" {
        /// BulletArm `camera_side`: eye (1, 0, 0.6), target (0.45, 0, 0): elevation ≈ 47.5°, distance ≈ 0.814 m.
        Side = "side",
        /// `camera_side_rgbd_15`: elevation 15°, distance 0.81 m.
        Angle15 = "angle15",
        /// `camera_side_rgbd_30`: elevation 30°, distance 0.81 m.
        Angle30 = "angle30",
        /// `camera_side_rgbd_45`: elevation 45°, distance 0.81 m (close to, not the same as, [`ViewPreset::Side`]).
        Angle45 = "angle45",
        /// `camera_side_rgbd_60`: elevation 60°, distance 0.81 m.
        Angle60 = "angle60",
        /// `camera_side_rgbd_75`: elevation 75°, distance 0.81 m.
        Angle75 = "angle75",
        /// `camera_side_rgbd_90`: looking straight down from 0.81 m above the target (top-down view).
        Angle90 = "angle90",
    }
}

impl ViewPreset {
    /// The elevation of an angle preset in degrees; `None` for [`ViewPreset::Side`], which is given
    /// by its eye and target instead.
    pub fn angle_deg(self) -> Option<f64> {
        match self {
            ViewPreset::Side => None,
            ViewPreset::Angle15 => Some(15.0),
            ViewPreset::Angle30 => Some(30.0),
            ViewPreset::Angle45 => Some(45.0),
            ViewPreset::Angle60 => Some(60.0),
            ViewPreset::Angle75 => Some(75.0),
            ViewPreset::Angle90 => Some(90.0),
        }
    }
}

crate::named_enum! {
    /// Whether the scene shows the 7-DoF arm that carries the gripper (BulletArm's name for a hidden
    /// arm is a transparent robot). The arm is drawn only; it touches nothing.
    pub enum ArmView: "arm" {
        /// Drawn, its joints set by inverse kinematics to follow the gripper: the paper's scene, where
        /// the arm is one of the three symmetry breakers (camera angle, arm, floor).
        Visible = "visible",
        /// Not drawn: the gripper floats (the scene of every run before the arm existed).
        Hidden = "hidden",
    }
}

impl Default for ArmView {
    /// [`ArmView::Visible`], what the paper shows.
    fn default() -> Self {
        ArmView::Visible
    }
}
