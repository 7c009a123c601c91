//! The camera model (docs/paper.md §3.4): a pinhole camera looking at the workspace centre from an
//! elevation angle, oriented so that **image rows increase toward world +x and columns toward +y**
//! (BulletArm's up vector (−1, 0, 0)). Depth is planar (along the optical axis) in metres.
//!
//! Conventions: the optical frame is ROS's (x right = +column, y down = +row, z forward). Pixel
//! (row i, column j) has its centre at image coordinates (u, v) = (j, i); the principal point is the
//! image centre ((W−1)/2, (H−1)/2), so [`Camera::camera_info_k`] can fill `sensor_msgs/CameraInfo`
//! directly. Geometry uses nalgebra (f64); the renderers convert to f32.
//!
//! Limitations: no lens distortion; square pixels; the azimuth is fixed (the camera is in the x-z
//! plane on the +x side, as in the paper).

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

use crate::error::{Result, SimError};

pub use equiarm_types::ViewPreset;

/// Camera configuration. The eye is at `target + distance·(cos e, 0, sin e)`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Point looked at, world metres.
    pub target: [f64; 3],
    /// Elevation of the eye above the table plane, degrees, in (0, 90].
    pub elevation_deg: f64,
    /// Eye-to-target distance, m.
    pub distance: f64,
    /// Vertical field of view, degrees.
    pub fov_y_deg: f64,
    /// Image width, pixels, in 1..=8192 (152 in the paper).
    pub width: usize,
    /// Image height, pixels, in 1..=8192 (152 in the paper).
    pub height: usize,
    /// Near and far clipping distances (planar depth), m. Background pixels get depth `far`.
    pub near: f64,
    /// Far clipping distance (planar depth), m, greater than `near`; also the depth of background pixels.
    pub far: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        // Eye (1, 0, 0.6), target (0.45, 0, 0).
        let (dx, dz) = (0.55f64, 0.6f64);
        Self {
            target: [0.45, 0.0, 0.0],
            elevation_deg: dz.atan2(dx).to_degrees(),
            distance: (dx * dx + dz * dz).sqrt(),
            fov_y_deg: 40.0,
            width: 152,
            height: 152,
            near: 0.1,
            far: 3.0,
        }
    }
}

/// Distance of the angle presets' camera from the target, m (BulletArm's `camera_side_rgbd_N`).
pub const ANGLE_PRESET_DISTANCE: f64 = 0.81;

impl From<ViewPreset> for CameraConfig {
    /// The camera configuration of a preset. The angle presets change only the elevation and the
    /// distance ([`ANGLE_PRESET_DISTANCE`]) of [`CameraConfig::default`]: same target, field of
    /// view, size and clipping.
    fn from(view: ViewPreset) -> Self {
        let base = CameraConfig::default();
        match view.angle_deg() {
            None => base,
            Some(deg) => CameraConfig { elevation_deg: deg, distance: ANGLE_PRESET_DISTANCE, ..base },
        }
    }
}

/// The fields of `sensor_msgs/CameraInfo` (without header and ROI).
#[derive(Clone, Debug, PartialEq)]
pub struct CameraInfoData {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Distortion model: always `plumb_bob`.
    pub distortion_model: &'static str,
    /// Distortion coefficients (k1, k2, t1, t2, k3): all zero (no lens distortion).
    pub d: [f64; 5],
    /// Intrinsic matrix, row-major 3×3 ([`Camera::camera_info_k`]).
    pub k: [f64; 9],
    /// Rectification matrix, row-major 3×3: the identity (monocular).
    pub r: [f64; 9],
    /// Projection matrix, row-major 3×4 ([`Camera::camera_info_p`]).
    pub p: [f64; 12],
}

/// A validated camera: intrinsics and extrinsics.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// The configuration it was built from.
    pub config: CameraConfig,
    /// Focal length along image columns (u), pixels; equal to `fy` (square pixels).
    pub fx: f64,
    /// Focal length along image rows (v), pixels: (height / 2) / tan(fov_y / 2).
    pub fy: f64,
    /// Principal point, column coordinate u, pixels: (width − 1) / 2.
    pub cx: f64,
    /// Principal point, row coordinate v, pixels: (height − 1) / 2.
    pub cy: f64,
    /// Eye position in the world.
    pub eye: Point3<f64>,
    /// Rotation world → optical frame (rows are the optical x, y, z axes in world coordinates).
    pub world_to_optical: Rotation3<f64>,
}

impl Camera {
    /// Validates `config` and computes the intrinsics and the pose. A value out of its domain is a
    /// [`SimError::Config`] naming the field: elevation in (0, 90]°, distance > 0 and between near and
    /// far, field of view in (1, 170)°, width and height in 1..=8192, 0 < near < far, finite target.
    pub fn new(config: CameraConfig) -> Result<Self> {
        let c = &config;
        let bad = |field: &'static str, message: String| Err(SimError::Config { field, message });
        if !(c.elevation_deg.is_finite() && c.elevation_deg > 0.0 && c.elevation_deg <= 90.0) {
            return bad("elevation_deg", format!("{} must be in (0, 90]", c.elevation_deg));
        }
        if !(c.distance.is_finite() && c.distance > 0.0) {
            return bad("distance", format!("{} must be > 0", c.distance));
        }
        if !(c.fov_y_deg.is_finite() && c.fov_y_deg > 1.0 && c.fov_y_deg < 170.0) {
            return bad("fov_y_deg", format!("{} must be in (1, 170)", c.fov_y_deg));
        }
        if c.width == 0 || c.height == 0 || c.width > 8192 || c.height > 8192 {
            return bad("width/height", format!("{}x{} must be 1..=8192", c.width, c.height));
        }
        if !(c.near.is_finite() && c.far.is_finite() && c.near > 0.0 && c.far > c.near) {
            return bad("near/far", format!("need 0 < near ({}) < far ({})", c.near, c.far));
        }
        if !c.target.iter().all(|x| x.is_finite()) {
            return bad("target", "must be finite".into());
        }
        // the target (the workspace's centre) must be in front of the near plane and before the far
        // one, or every pixel is clipped: a blank image of depth `far`
        if !(c.distance > c.near && c.distance < c.far) {
            return bad(
                "distance",
                format!(
                    "{} m must be between near ({}) and far ({}): the target would be clipped",
                    c.distance, c.near, c.far
                ),
            );
        }
        let e = c.elevation_deg.to_radians();
        let target = Point3::from(c.target);
        let eye = target + Vector3::new(e.cos(), 0.0, e.sin()) * c.distance;
        let forward = (target - eye).normalize();
        // Up vector (−1, 0, 0) as in BulletArm; at 90° elevation it is still orthogonal to forward.
        let up_hint = Vector3::new(-1.0, 0.0, 0.0);
        let right = forward.cross(&up_hint).normalize();
        let up = right.cross(&forward).normalize();
        let down = -up;
        let world_to_optical = Rotation3::from_matrix_unchecked(Matrix3::from_rows(&[
            right.transpose(),
            down.transpose(),
            forward.transpose(),
        ]));
        let fy = (c.height as f64 / 2.0) / (c.fov_y_deg.to_radians() / 2.0).tan();
        Ok(Self {
            fx: fy,
            fy,
            cx: (c.width as f64 - 1.0) / 2.0,
            cy: (c.height as f64 - 1.0) / 2.0,
            eye,
            world_to_optical,
            config,
        })
    }

    /// Image width, pixels.
    pub fn width(&self) -> usize {
        self.config.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> usize {
        self.config.height
    }

    /// World → optical-frame transform (ROS: the camera's `tf` is the inverse of this).
    pub fn extrinsics(&self) -> Isometry3<f64> {
        let r = UnitQuaternion::from_rotation_matrix(&self.world_to_optical);
        let t = -(self.world_to_optical * self.eye.coords);
        Isometry3::from_parts(Translation3::from(t), r)
    }

    /// Pose of the optical frame in the world (translation = eye).
    pub fn optical_pose_in_world(&self) -> Isometry3<f64> {
        self.extrinsics().inverse()
    }

    /// CameraInfo `K` (row-major 3×3).
    pub fn camera_info_k(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }

    /// CameraInfo `P` (row-major 3×4, monocular: no baseline).
    pub fn camera_info_p(&self) -> [f64; 12] {
        [self.fx, 0.0, self.cx, 0.0, 0.0, self.fy, self.cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    }

    /// Everything a `sensor_msgs/CameraInfo` needs (no distortion: `plumb_bob` with zero D, R = I).
    pub fn camera_info(&self) -> CameraInfoData {
        CameraInfoData {
            width: self.config.width as u32,
            height: self.config.height as u32,
            distortion_model: "plumb_bob",
            d: [0.0; 5],
            k: self.camera_info_k(),
            r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            p: self.camera_info_p(),
        }
    }

    /// Projects a world point to (u, v, planar depth); `None` behind the camera.
    pub fn project(&self, p: Point3<f64>) -> Option<(f64, f64, f64)> {
        let c = self.world_to_optical * (p - self.eye);
        if c.z <= 0.0 {
            return None;
        }
        Some((self.fx * c.x / c.z + self.cx, self.fy * c.y / c.z + self.cy, c.z))
    }

    /// World direction of the ray through pixel (row, col), scaled so its optical-axis component is 1
    /// (so `eye + t·dir` has planar depth t).
    pub fn pixel_ray(&self, row: f64, col: f64) -> Vector3<f64> {
        let d = Vector3::new((col - self.cx) / self.fx, (row - self.cy) / self.fy, 1.0);
        self.world_to_optical.inverse() * d
    }

    /// World point seen at pixel (row, col) with planar depth `depth`.
    pub fn unproject(&self, row: f64, col: f64, depth: f64) -> Point3<f64> {
        self.eye + self.pixel_ray(row, col) * depth
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_camera_matches_bulletarm() {
        let cam = Camera::new(CameraConfig::default()).unwrap();
        assert!((cam.eye - Point3::new(1.0, 0.0, 0.6)).norm() < 1e-9);
        assert!((cam.fy - 208.8).abs() < 0.1, "fy {}", cam.fy);
        // The target projects to the image centre.
        let (u, v, _) = cam.project(Point3::new(0.45, 0.0, 0.0)).unwrap();
        assert!((u - cam.cx).abs() < 1e-9 && (v - cam.cy).abs() < 1e-9);
        // Rows grow toward +x, columns toward +y.
        let (_, v1, _) = cam.project(Point3::new(0.55, 0.0, 0.0)).unwrap();
        assert!(v1 > cam.cy);
        let (u2, _, _) = cam.project(Point3::new(0.45, 0.1, 0.0)).unwrap();
        assert!(u2 > cam.cx);
    }

    #[test]
    fn unproject_inverts_project_and_extrinsics_agree() {
        let cam = Camera::new(ViewPreset::Angle30.into()).unwrap();
        let p = Point3::new(0.5, -0.07, 0.03);
        let (u, v, z) = cam.project(p).unwrap();
        assert!((cam.unproject(v, u, z) - p).norm() < 1e-9);
        let q = cam.extrinsics() * p;
        assert!((q.z - z).abs() < 1e-9);
        assert!((cam.fx * q.x / q.z + cam.cx - u).abs() < 1e-9);
    }

    #[test]
    fn presets_and_bad_config() {
        for p in ViewPreset::ALL {
            assert_eq!(ViewPreset::from_name(p.name()), Some(p));
            Camera::new(p.into()).unwrap();
        }
        let bad = CameraConfig { fov_y_deg: f64::NAN, ..Default::default() };
        assert!(Camera::new(bad).unwrap_err().to_string().contains("fov_y_deg"));
        let bad = CameraConfig { elevation_deg: 0.0, ..Default::default() };
        assert!(Camera::new(bad).unwrap_err().to_string().contains("elevation_deg"));
    }

    /// Regression (issue 61): a camera distance of 1e12 m was accepted and rendered a blank image
    /// (everything beyond the far plane). The target must lie between the clipping planes.
    #[test]
    fn a_camera_distance_that_clips_the_target_is_refused() {
        for d in [1e12, 3.0, 0.05] {
            let e = Camera::new(CameraConfig { distance: d, ..Default::default() }).unwrap_err().to_string();
            assert!(e.contains("`distance`") && e.contains("clipped"), "{d}: {e}");
        }
        Camera::new(CameraConfig { distance: 2.9, ..Default::default() }).unwrap();
    }
}
