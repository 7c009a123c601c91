//! Rendering: a CPU z-buffer rasteriser producing colour (rgb8), planar depth (f32, metres) and
//! segmentation (u16 body ids) in one pass, and a per-pixel ray cast kept as its test oracle.
//!
//! The rasteriser tessellates every collider once per scene ([`MeshCache`]), transforms the vertices
//! by the collider pose each frame, clips triangles at the near plane, and tests pixel centres with
//! edge functions. Depth is computed exactly per pixel from the triangle's plane (ray–plane
//! intersection), so on planar faces it equals the ray-cast depth to float precision. Shading is flat
//! Lambert (0.35 ambient + 0.65 n·l) with one fixed directional light; faces are lit from the side that
//! faces the camera. The table top can be painted with BulletArm's floor: pybullet_data's
//! `plane.urdf` (`plane100.obj`, `checker_blue.png`), i.e. 1 m tiles in world xy, light blue
//! (173, 199, 239) where ⌊x⌋ + ⌊y⌋ is odd and white where it is even. In the paper's oblique view the
//! edge at y = 0 runs down the middle of the image (light blue on the left, y < 0), and the x = 0 edge
//! crosses its top rows: a symmetry breaker, measured against pybullet's TinyRenderer.
//!
//! [`rasterize_with`] takes [`RenderOptions`]: the light's direction and colour, ambient, diffuse and
//! specular (Blinn–Phong, evaluated once per face) coefficients, hard shadows (one ray cast toward the
//! light per visible pixel) and the checkerboard's tile size. [`rasterize`] uses
//! [`RenderOptions::default`], the fixed light above.
//!
//! Limitations: curved shapes (cylinders, balls, capsules) are tessellated (32 segments), so they
//! deviate from the ray cast by up to ~0.5 % of their radius, and in depth by up to ~5 mm where a ray
//! grazes a facet; the task assets use boxes only, the arm ([`crate::arm`]) cylinders and spheres.
//! No shadows, no textures, no anti-aliasing.

use rapier3d::prelude::*;

use crate::camera::Camera;
use crate::world::{Scene, Visual};

/// One rendered image set. All buffers are row-major, `height` rows of `width` pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Image width, pixels.
    pub width: usize,
    /// Image height, pixels.
    pub height: usize,
    /// rgb8, `height × width × 3`.
    pub color: Vec<u8>,
    /// Planar depth (along the optical axis), metres; background = the camera's `far`.
    pub depth: Vec<f32>,
    /// Segmentation: the scene's body id ([`Scene::seg_names`]), 0 = background.
    pub segmentation: Vec<u16>,
}

impl Frame {
    /// A blank `width`×`height` frame: black colour, every depth `far` (m), segmentation 0 (background).
    pub fn new(width: usize, height: usize, far: f32) -> Self {
        let n = width * height;
        Self { width, height, color: vec![0; n * 3], depth: vec![far; n], segmentation: vec![0; n] }
    }
}

impl Frame {
    /// The `size`×`size` window whose top-left pixel is (row0, col0) (docs/paper.md §1.1: random crops
    /// of 128 from 152 in training, the centre crop (12, 12) when acting). `None` if it does not fit.
    pub fn crop(&self, row0: usize, col0: usize, size: usize) -> Option<Frame> {
        if row0 + size > self.height || col0 + size > self.width {
            return None;
        }
        let mut out = Frame::new(size, size, 0.0);
        for r in 0..size {
            let src = (row0 + r) * self.width + col0;
            out.depth[r * size..(r + 1) * size].copy_from_slice(&self.depth[src..src + size]);
            out.segmentation[r * size..(r + 1) * size].copy_from_slice(&self.segmentation[src..src + size]);
            out.color[r * size * 3..(r + 1) * size * 3].copy_from_slice(&self.color[src * 3..(src + size) * 3]);
        }
        Some(out)
    }

    /// The centred `size`×`size` crop.
    pub fn center_crop(&self, size: usize) -> Option<Frame> {
        if size > self.width || size > self.height {
            return None;
        }
        self.crop((self.height - size) / 2, (self.width - size) / 2, size)
    }
}

/// Background colour (rgb8).
pub const BACKGROUND: [u8; 3] = [170, 180, 190];
const AMBIENT: f32 = 0.35;
const DIFFUSE: f32 = 0.65;
/// Tile size of BulletArm's floor: `plane100.obj` maps its 2 m × 2 m texture (2 × 2 tiles) 100 times.
const CHECKER_TILE: f32 = 1.0;

fn light_dir() -> Vector {
    Vector::new(0.3, 0.2, 1.0).normalize()
}

fn shade(color: [f32; 3], normal: Vector) -> [u8; 3] {
    let k = AMBIENT + DIFFUSE * normal.dot(light_dir()).max(0.0);
    color.map(|c| (c * k * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// How [`rasterize_with`] lights and paints the scene. The default is the fixed light of
/// [`rasterize`]: white, from (0.3, 0.2, 1), ambient 0.35, diffuse 0.65, no specular, no shadows,
/// 1 m checker tiles.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderOptions {
    /// Direction from the scene toward the (directional) light, world frame; need not be unit length.
    pub light_dir: [f32; 3],
    /// Light colour, RGB in [0, 1]; it scales the diffuse and specular terms, not the ambient one.
    pub light_color: [f32; 3],
    /// Ambient coefficient (of the surface colour).
    pub ambient: f32,
    /// Diffuse (Lambert) coefficient.
    pub diffuse: f32,
    /// Specular coefficient (Blinn–Phong, white highlights tinted by the light colour); 0 disables it.
    pub specular: f32,
    /// Specular exponent.
    pub shininess: f32,
    /// Hard shadows: a visible point from which a ray toward the light hits a collider gets the
    /// ambient term only.
    pub shadows: bool,
    /// Side of one checkerboard tile, m (BulletArm's floor: 1 m; its `globalScaling` scales it).
    pub checker_tile: f32,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            light_dir: [0.3, 0.2, 1.0],
            light_color: [1.0; 3],
            ambient: AMBIENT,
            diffuse: DIFFUSE,
            specular: 0.0,
            shininess: 32.0,
            shadows: false,
            checker_tile: CHECKER_TILE,
        }
    }
}

/// [`RenderOptions`] in the form the inner loops use.
struct Light {
    dir: Vector,
    color: [f32; 3],
    ambient: f32,
    diffuse: f32,
    specular: f32,
    shininess: f32,
    shadows: bool,
    tile: f32,
    /// The default light: shade exactly as [`shade`] does.
    fixed: bool,
}

impl Light {
    fn new(o: &RenderOptions) -> Self {
        let d = Vector::new(o.light_dir[0], o.light_dir[1], o.light_dir[2]);
        let dir = if d.length() > 1e-9 { d.normalize() } else { Vector::Z };
        Self {
            dir,
            color: o.light_color,
            ambient: o.ambient,
            diffuse: o.diffuse,
            specular: o.specular,
            shininess: o.shininess,
            shadows: o.shadows,
            tile: if o.checker_tile > 0.0 { o.checker_tile } else { CHECKER_TILE },
            fixed: *o == RenderOptions::default(),
        }
    }

    /// Shaded colour of a face with albedo `color`, normal `n` (toward the viewer) and unit vector
    /// `to_eye`; `lit` false gives the ambient term only (a shadowed point).
    fn shade(&self, color: [f32; 3], n: Vector, to_eye: Vector, lit: bool) -> [u8; 3] {
        if self.fixed && lit {
            return shade(color, n);
        }
        let ndl = if lit { n.dot(self.dir).max(0.0) } else { 0.0 };
        let spec = if lit && self.specular > 0.0 && ndl > 0.0 {
            let h = (self.dir + to_eye).normalize_or_zero();
            self.specular * n.dot(h).max(0.0).powf(self.shininess)
        } else {
            0.0
        };
        let mut out = [0u8; 3];
        for k in 0..3 {
            let v = color[k] * (self.ambient + self.diffuse * ndl * self.color[k]) + spec * self.color[k];
            out[k] = (v * 255.0).round().clamp(0.0, 255.0) as u8;
        }
        out
    }
}

/// The blue tiles of pybullet_data's `checker_blue.png`: (173, 199, 239) / 255.
const CHECKER_DARK: [f32; 3] = [173.0 / 255.0, 199.0 / 255.0, 239.0 / 255.0];

fn checker_odd(p: Vector) -> bool {
    checker_odd_tile(p, CHECKER_TILE)
}

fn checker_odd_tile(p: Vector, tile: f32) -> bool {
    let i = (p.x / tile).floor() as i64 + (p.y / tile).floor() as i64;
    i.rem_euclid(2) == 1
}

fn checker_color(color: [f32; 3], p: Vector) -> [f32; 3] {
    if checker_odd(p) { CHECKER_DARK } else { color }
}

/// How a triangle is painted: one flat colour, or the checkerboard's two shaded colours.
#[derive(Clone, Copy)]
enum Paint {
    Flat([u8; 3]),
    Checker([u8; 3], [u8; 3]),
}

/// Triangles of every visual collider in its local frame, built once per scene.
pub struct MeshCache {
    items: Vec<MeshItem>,
}

struct MeshItem {
    collider: ColliderHandle,
    seg: u16,
    color: [f32; 3],
    checker: bool,
    /// A convex solid centred on the collider origin (box, cylinder, ball, capsule): faces that look
    /// away from the camera are culled.
    convex_centred: bool,
    vertices: Vec<Vector>,
    triangles: Vec<[u32; 3]>,
}

impl MeshCache {
    /// Tessellates every collider of `scene.visuals` (cuboids, cylinders, balls, capsules, convex
    /// polyhedra; other shapes are not drawn). Valid for that scene only.
    pub fn new(scene: &Scene) -> Self {
        let mut items = Vec::new();
        for v in &scene.visuals {
            let Some(col) = scene.physics.colliders.get(v.collider) else {
                continue;
            };
            let shape = col.shape();
            let convex_centred = shape.as_cuboid().is_some()
                || shape.as_cylinder().is_some()
                || shape.as_ball().is_some()
                || shape.as_capsule().is_some();
            let mesh = if let Some(c) = shape.as_cuboid() {
                Some(c.to_trimesh())
            } else if let Some(c) = shape.as_cylinder() {
                Some(c.to_trimesh(32))
            } else if let Some(b) = shape.as_ball() {
                Some(b.to_trimesh(16, 32))
            } else if let Some(c) = shape.as_capsule() {
                Some(c.to_trimesh(16, 32))
            } else {
                shape.as_convex_polyhedron().map(|c| c.to_trimesh())
            };
            if let Some((vertices, triangles)) = mesh {
                items.push(MeshItem {
                    collider: v.collider,
                    seg: v.seg,
                    color: v.color,
                    checker: v.checker,
                    convex_centred,
                    vertices,
                    triangles,
                });
            }
        }
        Self { items }
    }

    /// Total number of triangles over all cached colliders.
    pub fn triangle_count(&self) -> usize {
        self.items.iter().map(|i| i.triangles.len()).sum()
    }
}

/// Camera parameters in f32 for the inner loops.
struct Cam32 {
    r: [Vector; 3],
    eye: Vector,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    near: f32,
    far: f32,
    w: usize,
    h: usize,
}

impl Cam32 {
    fn new(cam: &Camera) -> Self {
        let m = cam.world_to_optical.matrix();
        let row = |i: usize| Vector::new(m[(i, 0)] as f32, m[(i, 1)] as f32, m[(i, 2)] as f32);
        Self {
            r: [row(0), row(1), row(2)],
            eye: Vector::new(cam.eye.x as f32, cam.eye.y as f32, cam.eye.z as f32),
            fx: cam.fx as f32,
            fy: cam.fy as f32,
            cx: cam.cx as f32,
            cy: cam.cy as f32,
            near: cam.config.near as f32,
            far: cam.config.far as f32,
            w: cam.width(),
            h: cam.height(),
        }
    }

    fn to_optical(&self, p: Vector) -> Vector {
        let d = p - self.eye;
        Vector::new(self.r[0].dot(d), self.r[1].dot(d), self.r[2].dot(d))
    }

    fn to_world_dir(&self, d: Vector) -> Vector {
        self.r[0] * d.x + self.r[1] * d.y + self.r[2] * d.z
    }
}

/// Rasterises the scene into `frame` (which must have the camera's size).
pub fn rasterize(scene: &Scene, meshes: &MeshCache, cam: &Camera, frame: &mut Frame) {
    rasterize_with(scene, meshes, cam, &RenderOptions::default(), frame);
}

/// Rasterises the scene into `frame` (which must have the camera's size) with the light, shadows and
/// checker tiles of `options`. With [`RenderOptions::default`] it is [`rasterize`].
pub fn rasterize_with(scene: &Scene, meshes: &MeshCache, cam: &Camera, options: &RenderOptions, frame: &mut Frame) {
    let light = Light::new(options);
    let c = Cam32::new(cam);
    // With shadows, each pixel also keeps the colour it would have in shadow (filled by raster_2d).
    let mut shadowed: Vec<[u8; 3]> = if light.shadows { vec![[0; 3]; c.w * c.h] } else { Vec::new() };
    assert_eq!((frame.width, frame.height), (c.w, c.h), "frame size must match the camera");
    for (i, px) in frame.color.chunks_exact_mut(3).enumerate() {
        px.copy_from_slice(&BACKGROUND);
        frame.depth[i] = c.far;
        frame.segmentation[i] = 0;
    }
    let mut world = Vec::new();
    for item in &meshes.items {
        let Some(col) = scene.physics.colliders.get(item.collider) else {
            continue;
        };
        let pose = *col.position();
        world.clear();
        world.extend(item.vertices.iter().map(|v| pose * *v));
        let centre = pose.translation;
        for t in &item.triangles {
            let w = [world[t[0] as usize], world[t[1] as usize], world[t[2] as usize]];
            if item.convex_centred {
                // Back-face culling: the outward normal points away from the centre.
                let mut n = (w[1] - w[0]).cross(w[2] - w[0]);
                if n.dot(w[0] - centre) < 0.0 {
                    n = -n;
                }
                if n.dot(c.eye - w[0]) <= 0.0 {
                    continue;
                }
            }
            draw_triangle(&c, &light, item, w, frame, &mut shadowed);
        }
    }
    if light.shadows {
        cast_shadows(scene, &c, &light, frame, &shadowed);
    }
}

/// Replaces the colour of every visible pixel whose point does not see the light by its shadowed
/// colour: a ray from the point (lifted 1 mm toward the light) toward the light that hits any collider.
fn cast_shadows(scene: &Scene, c: &Cam32, light: &Light, frame: &mut Frame, shadowed: &[[u8; 3]]) {
    let qp = scene.physics.query_pipeline();
    for row in 0..c.h {
        let yh = (row as f32 - c.cy) / c.fy;
        for col in 0..c.w {
            let i = row * c.w + col;
            let z = frame.depth[i];
            if frame.segmentation[i] == 0 || z >= c.far {
                continue;
            }
            let xh = (col as f32 - c.cx) / c.fx;
            let p = c.eye + c.to_world_dir(Vector::new(xh * z, yh * z, z));
            let ray = Ray::new(p + light.dir * 1e-3, light.dir);
            if qp.cast_ray(&ray, 10.0, true).is_some() {
                frame.color[i * 3..i * 3 + 3].copy_from_slice(&shadowed[i]);
            }
        }
    }
}

fn draw_triangle(
    c: &Cam32,
    light: &Light,
    item: &MeshItem,
    w: [Vector; 3],
    frame: &mut Frame,
    shadowed: &mut [[u8; 3]],
) {
    let mut n = (w[1] - w[0]).cross(w[2] - w[0]);
    let len = n.length();
    // Also rejects NaN lengths.
    if len.is_nan() || len <= 1e-12 {
        return;
    }
    n /= len;
    if n.dot(c.eye - w[0]) < 0.0 {
        n = -n;
    }
    let to_eye = (c.eye - (w[0] + w[1] + w[2]) / 3.0).normalize_or_zero();
    let paint_of = |lit: bool| {
        if item.checker {
            Paint::Checker(light.shade(item.color, n, to_eye, lit), light.shade(CHECKER_DARK, n, to_eye, lit))
        } else {
            Paint::Flat(light.shade(item.color, n, to_eye, lit))
        }
    };
    let paint = paint_of(true);
    let dark = if light.shadows { Some(paint_of(false)) } else { None };
    let o = w.map(|p| c.to_optical(p));
    // Plane in optical coordinates: n_c · x = d; along the pixel ray x = z·(x̂, ŷ, 1).
    let n_c = Vector::new(c.r[0].dot(n), c.r[1].dot(n), c.r[2].dot(n));
    let d = n_c.dot(o[0]);
    // Near-plane clipping (Sutherland–Hodgman on z >= near).
    let mut poly: [Vector; 4] = [Vector::ZERO; 4];
    let mut np = 0;
    for k in 0..3 {
        let a = o[k];
        let b = o[(k + 1) % 3];
        let ain = a.z >= c.near;
        let bin = b.z >= c.near;
        if ain {
            poly[np] = a;
            np += 1;
        }
        if ain != bin {
            let s = (c.near - a.z) / (b.z - a.z);
            poly[np] = a + (b - a) * s;
            np += 1;
        }
    }
    if np < 3 {
        return;
    }
    let proj = |p: Vector| [c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy];
    let pts: Vec<[f32; 2]> = poly[..np].iter().map(|p| proj(*p)).collect();
    for k in 1..np - 1 {
        let paints = Paints { lit: paint, dark, tile: light.tile };
        raster_2d(c, item.seg, paints, n_c, d, [pts[0], pts[k], pts[k + 1]], frame, shadowed);
    }
}

/// A triangle's paint in light and, with shadows on, in shadow; the checker tile size.
#[derive(Clone, Copy)]
struct Paints {
    lit: Paint,
    dark: Option<Paint>,
    tile: f32,
}

#[allow(clippy::too_many_arguments)]
fn raster_2d(
    c: &Cam32,
    seg: u16,
    paints: Paints,
    n_c: Vector,
    d: f32,
    p: [[f32; 2]; 3],
    frame: &mut Frame,
    shadowed: &mut [[u8; 3]],
) {
    let edge = |a: [f32; 2], b: [f32; 2], q: [f32; 2]| (b[0] - a[0]) * (q[1] - a[1]) - (b[1] - a[1]) * (q[0] - a[0]);
    let area = edge(p[0], p[1], p[2]);
    if area.abs() < 1e-12 {
        return;
    }
    let sign = area.signum();
    let minx = p.iter().map(|q| q[0]).fold(f32::INFINITY, f32::min).ceil().max(0.0);
    let maxx = p.iter().map(|q| q[0]).fold(f32::NEG_INFINITY, f32::max).floor().min(c.w as f32 - 1.0);
    let miny = p.iter().map(|q| q[1]).fold(f32::INFINITY, f32::min).ceil().max(0.0);
    let maxy = p.iter().map(|q| q[1]).fold(f32::NEG_INFINITY, f32::max).floor().min(c.h as f32 - 1.0);
    if minx > maxx || miny > maxy {
        return;
    }
    for row in miny as usize..=maxy as usize {
        let y = row as f32;
        let yh = (y - c.cy) / c.fy;
        for col in minx as usize..=maxx as usize {
            let x = col as f32;
            let q = [x, y];
            let e0 = edge(p[1], p[2], q) * sign;
            let e1 = edge(p[2], p[0], q) * sign;
            let e2 = edge(p[0], p[1], q) * sign;
            if e0 < 0.0 || e1 < 0.0 || e2 < 0.0 {
                continue;
            }
            let xh = (x - c.cx) / c.fx;
            let denom = n_c.x * xh + n_c.y * yh + n_c.z;
            if denom.abs() < 1e-12 {
                continue;
            }
            let z = d / denom;
            if !(z >= c.near && z <= c.far) {
                continue;
            }
            let i = row * c.w + col;
            if z < frame.depth[i] {
                frame.depth[i] = z;
                frame.segmentation[i] = seg;
                let pick = |paint: Paint| match paint {
                    Paint::Flat(rgb) => rgb,
                    Paint::Checker(light, dark) => {
                        let pw = c.eye + c.to_world_dir(Vector::new(xh * z, yh * z, z));
                        if checker_odd_tile(pw, paints.tile) { dark } else { light }
                    }
                };
                frame.color[i * 3..i * 3 + 3].copy_from_slice(&pick(paints.lit));
                if let Some(dark) = paints.dark {
                    shadowed[i] = pick(dark);
                }
            }
        }
    }
}

/// The ray-cast oracle: one ray per pixel centre against every drawn collider's shape (parry's ray
/// casts, no acceleration structure: slow); used by tests and to check the rasteriser.
pub fn raycast(scene: &Scene, cam: &Camera) -> Frame {
    let c = Cam32::new(cam);
    let mut frame = Frame::new(c.w, c.h, c.far);
    // every drawn collider, enabled or not (the arm's are drawn only), each ray tested against all
    let drawn: Vec<(&Collider, &Visual)> =
        scene.visuals.iter().filter_map(|v| Some((scene.physics.colliders.get(v.collider)?, v))).collect();
    for row in 0..c.h {
        for col in 0..c.w {
            let i = row * c.w + col;
            frame.color[i * 3..i * 3 + 3].copy_from_slice(&BACKGROUND);
            let dir_o = Vector::new((col as f32 - c.cx) / c.fx, (row as f32 - c.cy) / c.fy, 1.0);
            let dir = c.to_world_dir(dir_o);
            let ray = Ray::new(c.eye, dir);
            let nearest = drawn
                .iter()
                .filter_map(|(col, v)| {
                    Some((col.shape().cast_ray_and_get_normal(col.position(), &ray, c.far, true)?, v))
                })
                .min_by(|a, b| a.0.time_of_impact.total_cmp(&b.0.time_of_impact));
            if let Some((hit, v)) = nearest {
                let z = hit.time_of_impact;
                if z < c.near {
                    continue;
                }
                let (seg, color, checker) = (v.seg, v.color, v.checker);
                frame.depth[i] = z;
                frame.segmentation[i] = seg;
                let mut n = hit.normal;
                if n.dot(dir) > 0.0 {
                    n = -n;
                }
                let color = if checker { checker_color(color, c.eye + dir * z) } else { color };
                frame.color[i * 3..i * 3 + 3].copy_from_slice(&shade(color, n));
            }
        }
    }
    frame
}

/// Agreement between two frames: fraction of pixels with equal segmentation, and the largest depth
/// difference over those pixels; `None` when the frames differ in size (nothing to compare pixel by
/// pixel).
pub fn agreement(a: &Frame, b: &Frame) -> Option<(f64, f32)> {
    if (a.width, a.height, a.segmentation.len(), a.depth.len())
        != (b.width, b.height, b.segmentation.len(), b.depth.len())
    {
        return None;
    }
    let mut same = 0usize;
    let mut max_dz = 0.0f32;
    for i in 0..a.segmentation.len() {
        if a.segmentation[i] == b.segmentation[i] {
            same += 1;
            max_dz = max_dz.max((a.depth[i] - b.depth[i]).abs());
        }
    }
    Some((same as f64 / a.segmentation.len().max(1) as f64, max_dz))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 10 cm box on the table seen from above, lit from the side: with shadows, ground pixels on
    /// the far side of the box from the light turn to the ambient colour; the default options give
    /// exactly what `rasterize` gives.
    #[test]
    fn shadows_darken_the_ground_behind_a_box_and_default_options_change_nothing() {
        let assets = crate::Assets::bundled().unwrap();
        let mut scene = Scene::new(&crate::SimParams::default(), &assets, false).unwrap();
        scene.add_marker(
            "box",
            Pose::from_translation(Vector::new(0.45, 0.0, 0.05)),
            Vector::new(0.05, 0.05, 0.05),
            [0.5, 0.5, 0.5],
        );
        scene.step();
        let cam = crate::camera::Camera::new(crate::camera::CameraConfig {
            elevation_deg: 90.0,
            distance: 1.0,
            width: 64,
            height: 64,
            ..Default::default()
        })
        .unwrap();
        let meshes = MeshCache::new(&scene);
        let render = |o: &RenderOptions| {
            let mut f = Frame::new(64, 64, 3.0);
            rasterize_with(&scene, &meshes, &cam, o, &mut f);
            f
        };
        let mut plain = Frame::new(64, 64, 3.0);
        rasterize(&scene, &meshes, &cam, &mut plain);
        assert_eq!(render(&RenderOptions::default()), plain);
        // light from −y (low): the shadow falls toward +y, i.e. to the right of the box
        let lit = RenderOptions { light_dir: [0.0, -1.0, 0.5], ..RenderOptions::default() };
        let shadowed = RenderOptions { shadows: true, ..lit.clone() };
        let (a, b) = (render(&lit), render(&shadowed));
        assert_eq!(a.depth, b.depth);
        let table = |f: &Frame, row: usize, col: usize| f.color[(row * 64 + col) * 3];
        // row 32 crosses the box (columns ~27..37 at this field of view); column 45 is beside it on +y
        assert!(table(&b, 32, 45) < table(&a, 32, 45), "shadow right of the box");
        assert_eq!(table(&b, 32, 15), table(&a, 32, 15), "no shadow on the lit side");
    }

    /// Regression: frames of two sizes made `agreement` index out of bounds.
    #[test]
    fn agreement_of_frames_of_two_sizes_is_none_not_a_panic() {
        let (a, b) = (Frame::new(4, 4, 2.0), Frame::new(4, 3, 2.0));
        assert_eq!(agreement(&a, &b), None);
        assert_eq!(agreement(&a, &a), Some((1.0, 0.0)));
    }

    #[test]
    fn crop_takes_the_window() {
        let mut f = Frame::new(4, 3, 1.0);
        for i in 0..12 {
            f.depth[i] = i as f32;
            f.segmentation[i] = i as u16;
            f.color[i * 3] = i as u8;
        }
        let c = f.crop(1, 2, 2).unwrap();
        assert_eq!(c.segmentation, vec![6, 7, 10, 11]);
        assert_eq!(c.depth, vec![6.0, 7.0, 10.0, 11.0]);
        assert_eq!(c.color[3], 7);
        assert!(f.crop(2, 0, 2).is_none());
        let big = Frame::new(152, 152, 1.0);
        let cc = big.center_crop(128).unwrap();
        assert_eq!((cc.width, cc.height), (128, 128));
    }
}
