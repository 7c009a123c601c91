//! Image-space symmetry corruptions (docs/paper.md §5.2, §5.3): reflections and the single-camera
//! orthographic occlusion projection. Pure functions over the renderer's buffers.
//!
//! Limitations: the occlusion projection uses the env camera's resolution for both the point cloud and
//! the height map (the paper renders a 512² point cloud); it fills no holes, as in the paper.

use rapier3d::prelude::*;

use crate::camera::Camera;
use crate::gripper::Gripper;
use crate::render::Frame;
use crate::world::Scene;

/// Mirrors an H×W×`ch` image in place: columns (left↔right) and/or rows (up↔down).
pub fn reflect<T: Copy>(img: &mut [T], ch: usize, w: usize, h: usize, cols: bool, rows: bool) {
    if img.len() != w * h * ch {
        return;
    }
    if cols {
        for r in 0..h {
            for c in 0..w / 2 {
                for k in 0..ch {
                    img.swap((r * w + c) * ch + k, (r * w + (w - 1 - c)) * ch + k);
                }
            }
        }
    }
    if rows {
        for r in 0..h / 2 {
            for c in 0..w * ch {
                img.swap(r * w * ch + c, (h - 1 - r) * w * ch + c);
            }
        }
    }
}

/// Side of the projected square, m.
pub const PROJECTION_SIZE: f32 = 0.6;
/// Value of pixels no point fell into.
pub const MISSING: f32 = -0.1;

/// §5.3 height map: points from the camera's depth with z ≤ max(gripper z − 0.01, 0.10), projected
/// straight down onto a 0.6 m square centred at the gripper (rows toward +x, columns toward +y);
/// value = gripper height − point height (highest point wins), missing = −0.1; then the finger
/// footprint is painted 0 and, for pushing, +0.02 is added inside the goal square.
pub fn occlusion_projection(
    cam: &Camera,
    depth: &[f32],
    seg: &[u16],
    gripper: &Gripper,
    scene: &Scene,
    goal: Option<[f32; 2]>,
) -> Frame {
    let (w, h) = (cam.width(), cam.height());
    let mut out = Frame::new(w, h, MISSING);
    let gz = gripper.tcp.z;
    let zmax = (gz - 0.01).max(0.10);
    let far = cam.config.far as f32;
    let px = PROJECTION_SIZE / w as f32;
    let py = PROJECTION_SIZE / h as f32;
    let to_pixel = |x: f32, y: f32| -> Option<usize> {
        let r = ((x - gripper.tcp.x) / py + h as f32 / 2.0).floor();
        let c = ((y - gripper.tcp.y) / px + w as f32 / 2.0).floor();
        if r >= 0.0 && c >= 0.0 && (r as usize) < h && (c as usize) < w {
            Some(r as usize * w + c as usize)
        } else {
            None
        }
    };
    for row in 0..h {
        for col in 0..w {
            let i = row * w + col;
            if depth[i] >= far {
                continue;
            }
            let p = cam.unproject(row as f64, col as f64, depth[i] as f64);
            let (x, y, z) = (p.x as f32, p.y as f32, p.z as f32);
            if z > zmax {
                continue;
            }
            if let Some(j) = to_pixel(x, y) {
                let v = gz - z;
                if out.depth[j] == MISSING || v < out.depth[j] {
                    out.depth[j] = v;
                    out.segmentation[j] = seg[i];
                }
            }
        }
    }
    // Finger footprints (rectangles 0.012 × 0.02 m at their measured positions).
    for f in gripper.fingers {
        let pose = *scene.physics.bodies[f].position();
        let (hx, hy) = (0.006f32, 0.01f32);
        for row in 0..h {
            for col in 0..w {
                let x = gripper.tcp.x + (row as f32 + 0.5 - h as f32 / 2.0) * py;
                let y = gripper.tcp.y + (col as f32 + 0.5 - w as f32 / 2.0) * px;
                let local = pose.inverse_transform_point(Vector::new(x, y, pose.translation.z));
                if local.x.abs() <= hx && local.y.abs() <= hy {
                    out.depth[row * w + col] = 0.0;
                }
            }
        }
    }
    if let Some(g) = goal {
        let half = 22.0 * 0.6 / 152.0 / 2.0;
        for row in 0..h {
            for col in 0..w {
                let x = gripper.tcp.x + (row as f32 + 0.5 - h as f32 / 2.0) * py;
                let y = gripper.tcp.y + (col as f32 + 0.5 - w as f32 / 2.0) * px;
                if (x - g[0]).abs() <= half && (y - g[1]).abs() <= half {
                    out.depth[row * w + col] += 0.02;
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reflect_is_an_involution_and_mirrors() {
        let (w, h) = (3, 2);
        let orig: Vec<u8> = (0..(w * h * 3) as u8).collect();
        let mut img = orig.clone();
        reflect(&mut img, 3, w, h, true, false);
        assert_eq!(&img[0..3], &orig[6..9]);
        reflect(&mut img, 3, w, h, false, true);
        assert_eq!(&img[0..3], &orig[(w * 3 + 2 * 3)..(w * 3 + 2 * 3 + 3)]);
        reflect(&mut img, 3, w, h, true, true);
        assert_eq!(img, orig);
    }
}
