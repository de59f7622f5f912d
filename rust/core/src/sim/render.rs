//! The camera and laser renderer of the simulated cell: parry3d ray casting over each mesh's BVH.
//!
//! Rendering is split the way a scan is: [`Scene::view`] casts one ray per pixel for a robot
//! pose (surface point, normal, instance id, ambient shading — the expensive part, done once),
//! then [`View::frame`] lights the laser line for one motor angle (cheap: shadow rays only near
//! the line) and adds sensor noise. Frames are RGB, 8 bits, row-major.
//!
//! Conventions: OpenCV pinhole camera with distortion `[k1, k2, p1, p2, k3]`, camera frame x
//! right, y down, z forward. The laser sheet is the plane x = 0 of the laser frame, light
//! travelling along +z; the motor turns the projector about its own y axis:
//! `T_camera_laser(θ) = T_camera_laser0 · Rot_y(θ)`.

use super::convert;
use crate::cloud::Point;
use crate::error::{Error, Result};
use crate::mesh::TriMesh;
use crate::rng::Rng;
use nalgebra::{Isometry3, Vector3};
use parry3d::bounding_volume::Aabb;
use parry3d::query::{PointQuery, Ray, RayCast};
use rayon::prelude::*;
use std::sync::Arc;

/// An OpenCV pinhole camera with radial-tangential distortion.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// Image width, px.
    pub width: usize,
    /// Image height, px.
    pub height: usize,
    /// Focal length along x, px.
    pub fx: f64,
    /// Focal length along y, px.
    pub fy: f64,
    /// Principal point x, px (pixel centres at integer coordinates).
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Distortion `[k1, k2, p1, p2, k3]`.
    pub dist: [f64; 5],
}

impl Default for Camera {
    /// The paper's camera (AVT Guppy F-080C, 1032 × 778) with an 8 mm-class lens, no distortion.
    fn default() -> Self {
        Camera {
            width: 1032,
            height: 778,
            fx: 1600.0,
            fy: 1600.0,
            cx: 515.5,
            cy: 388.5,
            dist: [0.0; 5],
        }
    }
}

impl Camera {
    /// Checks sizes, focal lengths and distortion.
    pub fn validate(&self) -> Result<()> {
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return Err(Error::invalid(
                "camera",
                format!(
                    "image size {}×{} must be between 1 and 16384 px",
                    self.width, self.height
                ),
            ));
        }
        for (name, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(name, format!("focal length must be positive, got {v}")));
            }
        }
        if !(self.cx.is_finite() && self.cy.is_finite() && self.dist.iter().all(|d| d.is_finite())) {
            return Err(Error::invalid(
                "camera",
                "principal point and distortion must be finite",
            ));
        }
        Ok(())
    }

    /// Applies lens distortion to normalised image coordinates.
    #[inline]
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.dist;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Removes lens distortion from normalised image coordinates (fixed-point iteration).
    pub fn undistort(&self, xd: f64, yd: f64) -> (f64, f64) {
        if self.dist.iter().all(|d| *d == 0.0) {
            return (xd, yd);
        }
        let [k1, k2, p1, p2, k3] = self.dist;
        let (mut x, mut y) = (xd, yd);
        for _ in 0..100 {
            let r2 = x * x + y * y;
            let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
            let dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x);
            let dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y;
            let (nx, ny) = ((xd - dx) / radial, (yd - dy) / radial);
            let step = (nx - x).abs() + (ny - y).abs();
            x = nx;
            y = ny;
            if step < 1e-14 {
                break;
            }
        }
        (x, y)
    }

    /// The pixel where a point in the camera frame appears, or `None` behind the camera.
    pub fn project(&self, p: &Point) -> Option<(f64, f64)> {
        if p.z <= 1e-9 {
            return None;
        }
        let (x, y) = self.distort(p.x / p.z, p.y / p.z);
        Some((self.fx * x + self.cx, self.fy * y + self.cy))
    }

    /// Undistorted normalised coordinates of every pixel centre, row-major.
    fn ray_table(&self) -> Vec<[f64; 2]> {
        (0..self.height)
            .into_par_iter()
            .flat_map_iter(|v| {
                (0..self.width).map(move |u| {
                    let (x, y) = self.undistort((u as f64 - self.cx) / self.fx, (v as f64 - self.cy) / self.fy);
                    [x, y]
                })
            })
            .collect()
    }
}

/// The laser line projector on the flange, turned by the motor about its own y axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Laser {
    /// Pose of the laser frame in the camera frame at motor angle 0.
    pub t_camera_laser0: Isometry3<f64>,
    /// Gaussian σ of the light sheet's thickness, mm.
    pub sheet_sigma: f64,
    /// Peak brightness on a white surface facing the laser at `reference_distance`, DN.
    pub power: f64,
    /// Full opening angle of the fan of light within the sheet, rad.
    pub fan_angle: f64,
    /// Relative response of the camera's R, G, B channels to the laser's light.
    pub color: [f64; 3],
    /// Distance at which `power` applies, mm; the sheet spreads as 1 / distance.
    pub reference_distance: f64,
}

impl Default for Laser {
    /// A red line laser 130 mm to the camera's right (+x), aimed at the optical axis 520 mm out.
    /// The single definition of the default projector: `binpick.sim.Laser` reads it through
    /// `binpick._core.sim_default_laser`.
    fn default() -> Self {
        let aim = (-130.0f64).atan2(520.0);
        Laser {
            t_camera_laser0: Isometry3::new(Vector3::new(130.0, 0.0, 0.0), Vector3::y() * aim),
            sheet_sigma: 0.35,
            power: 400.0,
            fan_angle: 60f64.to_radians(),
            color: [1.0, 0.12, 0.05],
            reference_distance: 500.0,
        }
    }
}

impl Laser {
    /// Pose of the laser frame in the camera frame at motor angle `theta` (rad).
    pub fn t_camera_laser(&self, theta: f64) -> Isometry3<f64> {
        self.t_camera_laser0 * Isometry3::rotation(Vector3::y() * theta)
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<()> {
        let ok = self.sheet_sigma.is_finite()
            && self.sheet_sigma > 0.0
            && self.power.is_finite()
            && self.power >= 0.0
            && self.fan_angle > 0.0
            && self.fan_angle < std::f64::consts::PI
            && self.reference_distance > 0.0
            && self.color.iter().all(|c| c.is_finite() && *c >= 0.0);
        if !ok {
            return Err(Error::invalid(
                "laser",
                "sheet_sigma and reference_distance must be positive, power and colour ≥ 0, fan_angle in (0, π)",
            ));
        }
        Ok(())
    }
}

/// How a surface reflects light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Diffuse reflectance of R, G, B in [0, 1].
    pub albedo: [f64; 3],
    /// Strength of the specular (glossy) highlight of the laser, ≥ 0.
    pub specular: f64,
    /// Phong exponent of the highlight.
    pub shininess: f64,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            albedo: [0.7, 0.7, 0.68],
            specular: 0.0,
            shininess: 20.0,
        }
    }
}

/// Ambient illumination of the cell (what the camera sees without the laser).
#[derive(Debug, Clone, PartialEq)]
pub struct Lighting {
    /// Brightness of a white surface under diffuse ambient light, DN.
    pub ambient: f64,
    /// Extra brightness of a white surface facing the ceiling lamp, DN.
    pub lamp: f64,
    /// Direction towards the lamp in the robot's base frame.
    pub lamp_direction: Vector3<f64>,
    /// Brightness where no surface is hit, DN.
    pub background: f64,
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            ambient: 55.0,
            lamp: 45.0,
            lamp_direction: Vector3::new(0.3, -0.2, 1.0),
            background: 6.0,
        }
    }
}

/// What the sensor and optics add to an ideal image.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorNoise {
    /// Read noise σ, DN.
    pub read_noise: f64,
    /// Shot noise: the variance grows by this many DN² per DN of signal.
    pub shot_noise: f64,
    /// Laser speckle contrast (σ / mean of the laser's brightness per pixel), 0 for none.
    pub speckle: f64,
    /// Strength of laser light mirrored once off glossy surfaces onto others, 0 for none.
    pub reflections: f64,
    /// Optical blur σ, px, widening the line.
    pub blur: f64,
}

impl Default for SensorNoise {
    fn default() -> Self {
        SensorNoise {
            read_noise: 1.5,
            shot_noise: 0.08,
            speckle: 0.0,
            reflections: 0.0,
            blur: 0.6,
        }
    }
}

impl SensorNoise {
    /// An ideal sensor (no noise, no speckle, no reflections) with the default optics blur.
    pub fn none() -> Self {
        SensorNoise {
            read_noise: 0.0,
            shot_noise: 0.0,
            speckle: 0.0,
            reflections: 0.0,
            ..Default::default()
        }
    }

    fn validate(&self) -> Result<()> {
        let v = [
            self.read_noise,
            self.shot_noise,
            self.speckle,
            self.reflections,
            self.blur,
        ];
        if !v.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(Error::invalid(
                "noise",
                "read_noise, shot_noise, speckle, reflections and blur must be finite and ≥ 0",
            ));
        }
        Ok(())
    }
}

struct SceneMesh {
    shape: parry3d::shape::TriMesh,
    aabb: Aabb,
    material: Material,
}

#[derive(Clone)]
struct Instance {
    mesh: usize,
    t_base_object: Isometry3<f64>,
    id: i32,
}

/// Meshes and their placed instances, in the robot's base frame. Instance ids are the caller's
/// (parts use their pile ids ≥ 0; by convention −2 is the bin and −3 the table); −1 means "no
/// surface" in id images and cannot be used.
#[derive(Default, Clone)]
pub struct Scene {
    meshes: Vec<Arc<SceneMesh>>,
    instances: Vec<Instance>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("meshes", &self.meshes.len())
            .field("instances", &self.instances.len())
            .finish()
    }
}

impl Scene {
    /// An empty scene.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a mesh (mm, its own frame) with its material and returns its index. The mesh's BVH
    /// is built once and shared by all its instances.
    pub fn add_mesh(&mut self, mesh: &TriMesh, material: Material) -> Result<usize> {
        if mesh.faces.is_empty() {
            return Err(Error::invalid("faces", "the mesh has no faces"));
        }
        if !material.albedo.iter().all(|a| a.is_finite() && (0.0..=1.0).contains(a))
            || !(material.specular.is_finite() && material.specular >= 0.0)
            || !(material.shininess.is_finite() && material.shininess > 0.0)
        {
            return Err(Error::invalid(
                "material",
                "albedo must be in [0, 1], specular ≥ 0 and shininess > 0",
            ));
        }
        let mut m = mesh.clone();
        m.drop_degenerate_faces();
        if m.faces.is_empty() {
            return Err(Error::invalid("faces", "every face of the mesh is degenerate"));
        }
        let verts = m.vertices.iter().map(convert::point_vec).collect();
        let shape = parry3d::shape::TriMesh::new(verts, m.faces)
            .map_err(|e| Error::invalid("mesh", format!("cannot build a ray-casting mesh: {e}")))?;
        let aabb = shape.local_aabb();
        self.meshes.push(Arc::new(SceneMesh { shape, aabb, material }));
        Ok(self.meshes.len() - 1)
    }

    /// Places mesh `mesh` at `t_base_object` under instance id `id`.
    pub fn add_instance(&mut self, mesh: usize, t_base_object: Isometry3<f64>, id: i32) -> Result<()> {
        if mesh >= self.meshes.len() {
            return Err(Error::invalid(
                "mesh",
                format!("no mesh {mesh}; the scene has {}", self.meshes.len()),
            ));
        }
        if id == -1 {
            return Err(Error::invalid("id", "−1 is reserved for 'no surface'; use another id"));
        }
        if self.instances.iter().any(|i| i.id == id) {
            return Err(Error::invalid("id", format!("an instance with id {id} already exists")));
        }
        self.instances.push(Instance {
            mesh,
            t_base_object,
            id,
        });
        Ok(())
    }

    /// Moves instance `id`.
    pub fn set_pose(&mut self, id: i32, t_base_object: Isometry3<f64>) -> Result<()> {
        let inst = self
            .instances
            .iter_mut()
            .find(|i| i.id == id)
            .ok_or_else(|| Error::invalid("id", format!("no instance {id}")))?;
        inst.t_base_object = t_base_object;
        Ok(())
    }

    /// Removes instance `id`.
    pub fn remove_instance(&mut self, id: i32) -> Result<()> {
        let n = self.instances.len();
        self.instances.retain(|i| i.id != id);
        if self.instances.len() == n {
            return Err(Error::invalid("id", format!("no instance {id}")));
        }
        Ok(())
    }

    /// Ids of the placed instances, in insertion order.
    pub fn instance_ids(&self) -> Vec<i32> {
        self.instances.iter().map(|i| i.id).collect()
    }

    /// Distance (mm) from each point (base frame) to the nearest surface of the scene, and the id
    /// of the instance that surface belongs to; `(∞, −1)` in an empty scene. Exact point-to-mesh
    /// distances: the ground truth a reconstructed cloud is measured against.
    pub fn nearest_surface(&self, points: &[Point]) -> Vec<(f64, i32)> {
        let placed = self.placed(&Isometry3::identity());
        points
            .par_iter()
            .map(|p| {
                let mut bounds: Vec<(f64, usize)> = placed
                    .iter()
                    .enumerate()
                    .map(|(k, pl)| (box_distance(p, &pl.lo, &pl.hi), k))
                    .collect();
                bounds.sort_by(|a, b| a.0.total_cmp(&b.0));
                let mut best = (f64::INFINITY, -1);
                for (lower, k) in bounds {
                    if lower >= best.0 {
                        break;
                    }
                    let pl = &placed[k];
                    let local = convert::point_vec(&(pl.t_object_camera * p));
                    // The f32 projection is refined in f64 below; the slack keeps a surface that
                    // is nearer only within f32 rounding from being skipped.
                    let limit = if best.0.is_finite() {
                        best.0 as f32 + 1e-3
                    } else {
                        f32::MAX
                    };
                    if let Some(proj) = pl.mesh.shape.project_local_point_with_max_dist(local, false, limit) {
                        let d = (convert::point(proj.point) - pl.t_object_camera * p).norm();
                        if d < best.0 {
                            best = (d, pl.id);
                        }
                    }
                }
                best
            })
            .collect()
    }

    fn placed(&self, t_base_camera: &Isometry3<f64>) -> Vec<Placed> {
        let t_camera_base = t_base_camera.inverse();
        self.instances
            .iter()
            .map(|inst| {
                let mesh = self.meshes[inst.mesh].clone();
                let t_camera_object = t_camera_base * inst.t_base_object;
                let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                for c in mesh.aabb.vertices() {
                    let p = t_camera_object * convert::point(c);
                    for k in 0..3 {
                        lo[k] = lo[k].min(p[k]);
                        hi[k] = hi[k].max(p[k]);
                    }
                }
                Placed {
                    t_object_camera: t_camera_object.inverse(),
                    t_camera_object,
                    lo,
                    hi,
                    id: inst.id,
                    mesh,
                }
            })
            .collect()
    }

    /// Casts one ray per pixel of `camera` at pose `t_base_camera`: the geometry every laser
    /// frame of this robot pose is lit from.
    pub fn view(&self, camera: &Camera, t_base_camera: &Isometry3<f64>, lighting: &Lighting) -> Result<View> {
        camera.validate()?;
        let placed = self.placed(t_base_camera);
        let table = camera.ray_table();
        let (w, h) = (camera.width, camera.height);
        let lamp = (t_base_camera.inverse().rotation * lighting.lamp_direction)
            .try_normalize(1e-12)
            .unwrap_or_else(Vector3::z);
        let ray_at = |u: usize, v: usize| {
            let [x, y] = table[v * w + u];
            Vector3::new(x, y, 1.0)
        };
        let rows: Vec<(Vec<Hit>, Vec<[f32; 3]>)> = (0..h)
            .into_par_iter()
            .map(|v| {
                let mut hits = Vec::with_capacity(w);
                let mut shade = Vec::with_capacity(w);
                for u in 0..w {
                    let r = ray_at(u, v);
                    let dir = r.normalize();
                    match cast(&placed, &Point::origin(), &dir, f64::INFINITY) {
                        None => {
                            hits.push(Hit::NONE);
                            let b = lighting.background as f32;
                            shade.push([b, b, b]);
                        }
                        Some((t, mut n, k)) => {
                            if n.dot(&dir) > 0.0 {
                                n = -n;
                            }
                            let p = dir * t;
                            // Where the neighbouring pixels' rays meet the tangent plane: the
                            // surface's footprint, to integrate the line profile over the pixel.
                            let at = |uu: usize, vv: usize| {
                                let rr = ray_at(uu, vv);
                                let den = n.dot(&rr);
                                if den.abs() < 1e-9 {
                                    p
                                } else {
                                    rr * (n.dot(&p) / den)
                                }
                            };
                            let diff = |a: Vector3<f64>, b: Vector3<f64>, span: f64| {
                                let d = (a - b) / span;
                                if d.norm() > 50.0 {
                                    Vector3::zeros()
                                } else {
                                    d
                                }
                            };
                            let (u0, u1) = (u.saturating_sub(1), (u + 1).min(w - 1));
                            let (v0, v1) = (v.saturating_sub(1), (v + 1).min(h - 1));
                            let dpdu = diff(at(u1, v), at(u0, v), (u1 - u0).max(1) as f64);
                            let dpdv = diff(at(u, v1), at(u, v0), (v1 - v0).max(1) as f64);
                            let m = &placed[k].mesh.material;
                            let lit = lighting.ambient + lighting.lamp * n.dot(&lamp).max(0.0);
                            shade.push([
                                (m.albedo[0] * lit) as f32,
                                (m.albedo[1] * lit) as f32,
                                (m.albedo[2] * lit) as f32,
                            ]);
                            hits.push(Hit {
                                t: t as f32,
                                p: f3(&p),
                                n: f3(&n),
                                dpdu: f3(&dpdu),
                                dpdv: f3(&dpdv),
                                id: placed[k].id,
                                placed: k as u32,
                            });
                        }
                    }
                }
                (hits, shade)
            })
            .collect();
        let mut hits = Vec::with_capacity(w * h);
        let mut shade = Vec::with_capacity(w * h);
        for (a, b) in rows {
            hits.extend(a);
            shade.extend(b);
        }
        Ok(View {
            camera: camera.clone(),
            t_base_camera: *t_base_camera,
            placed,
            hits,
            shade,
        })
    }
}

struct Placed {
    mesh: Arc<SceneMesh>,
    t_object_camera: Isometry3<f64>,
    t_camera_object: Isometry3<f64>,
    lo: [f64; 3],
    hi: [f64; 3],
    id: i32,
}

#[inline]
fn f3(v: &Vector3<f64>) -> [f32; 3] {
    [v.x as f32, v.y as f32, v.z as f32]
}

#[inline]
fn v3(a: &[f32; 3]) -> Vector3<f64> {
    Vector3::new(a[0] as f64, a[1] as f64, a[2] as f64)
}

/// Distance from a point to an axis-aligned box (0 inside).
#[inline]
fn box_distance(p: &Point, lo: &[f64; 3], hi: &[f64; 3]) -> f64 {
    let mut s = 0.0;
    for k in 0..3 {
        let e = (lo[k] - p[k]).max(p[k] - hi[k]).max(0.0);
        s += e * e;
    }
    s.sqrt()
}

/// Entry distance of a ray into a box, if it enters before `max_t`.
#[inline]
fn slab(o: &Point, d: &Vector3<f64>, lo: &[f64; 3], hi: &[f64; 3], max_t: f64) -> Option<f64> {
    let (mut t0, mut t1) = (0.0f64, max_t);
    for k in 0..3 {
        let inv = 1.0 / d[k];
        let (mut a, mut b) = ((lo[k] - o[k]) * inv, (hi[k] - o[k]) * inv);
        if a > b {
            std::mem::swap(&mut a, &mut b);
        }
        if a.is_nan() || b.is_nan() {
            if o[k] < lo[k] || o[k] > hi[k] {
                return None;
            }
            continue;
        }
        t0 = t0.max(a);
        t1 = t1.min(b);
        if t0 > t1 {
            return None;
        }
    }
    Some(t0)
}

/// The first surface along a ray (camera frame, unit `dir`) before `max_t`: distance, normal
/// (camera frame, unoriented) and index of the placed instance.
fn cast(placed: &[Placed], origin: &Point, dir: &Vector3<f64>, max_t: f64) -> Option<(f64, Vector3<f64>, usize)> {
    let mut best: Option<(f64, Vector3<f64>, usize)> = None;
    let mut limit = max_t;
    for (k, pl) in placed.iter().enumerate() {
        if slab(origin, dir, &pl.lo, &pl.hi, limit).is_none() {
            continue;
        }
        let o = pl.t_object_camera * origin;
        let d = pl.t_object_camera.rotation * dir;
        let ray = Ray::new(convert::point_vec(&o), convert::vector(&d));
        let lim = if limit.is_finite() { limit as f32 } else { f32::MAX };
        if let Some(hit) = pl.mesh.shape.cast_local_ray_and_get_normal(&ray, lim, true) {
            let t = hit.time_of_impact as f64;
            if t < limit {
                limit = t;
                best = Some((t, pl.t_camera_object.rotation * convert::vector3(hit.normal), k));
            }
        }
    }
    best
}

#[derive(Clone, Copy)]
struct Hit {
    t: f32,
    p: [f32; 3],
    n: [f32; 3],
    dpdu: [f32; 3],
    dpdv: [f32; 3],
    id: i32,
    placed: u32,
}

impl Hit {
    const NONE: Hit = Hit {
        t: f32::INFINITY,
        p: [0.0; 3],
        n: [0.0; 3],
        dpdu: [0.0; 3],
        dpdv: [0.0; 3],
        id: -1,
        placed: u32::MAX,
    };
}

/// The geometry a camera sees from one robot pose: per pixel the first surface, its normal and
/// instance id, and its ambient shading. Lit by the laser per motor angle with [`View::frame`].
pub struct View {
    camera: Camera,
    t_base_camera: Isometry3<f64>,
    placed: Vec<Placed>,
    hits: Vec<Hit>,
    shade: Vec<[f32; 3]>,
}

impl std::fmt::Debug for View {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("View")
            .field("camera", &self.camera)
            .field("t_base_camera", &self.t_base_camera)
            .finish()
    }
}

/// Approximately standard-normal number from one 64-bit draw (sum of four 16-bit uniforms):
/// ample for sensor noise, several times cheaper than Box–Muller.
#[inline]
fn fast_normal(rng: &mut Rng) -> f32 {
    let x = rng.next_u64();
    let s = (x & 0xFFFF) + ((x >> 16) & 0xFFFF) + ((x >> 32) & 0xFFFF) + (x >> 48);
    ((s as f32 + 2.0) / 65536.0 - 2.0) * 1.732_050_8
}

fn mix_seed(seed: u64, a: u64, b: u64) -> u64 {
    let mut z = seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xD1B5_4A32_D192_ED03);
    z = (z ^ (z >> 31)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z ^ (z >> 29)
}

/// Adds sensor noise to a float image and quantises it to 8 bits, rows in parallel, each row's
/// noise seeded from (`seed`, `salt`, row) so the result does not depend on the thread count.
fn quantise(img: &[[f32; 3]], width: usize, noise: &SensorNoise, seed: u64, salt: u64) -> Vec<u8> {
    let mut out = vec![0u8; img.len() * 3];
    let noisy = noise.read_noise > 0.0 || noise.shot_noise > 0.0;
    let (read2, shot) = ((noise.read_noise * noise.read_noise) as f32, noise.shot_noise as f32);
    out.par_chunks_mut(width * 3).enumerate().for_each(|(row, buf)| {
        let mut rng = Rng::new(mix_seed(seed, salt, row as u64));
        for (u, px) in img[row * width..(row + 1) * width].iter().enumerate() {
            for c in 0..3 {
                let mut v = px[c];
                if noisy {
                    v += (read2 + shot * v.max(0.0)).sqrt() * fast_normal(&mut rng);
                }
                buf[u * 3 + c] = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    });
    out
}

impl View {
    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// Pose of the camera in the base frame.
    pub fn t_base_camera(&self) -> Isometry3<f64> {
        self.t_base_camera
    }

    /// Depth image: z of the surface point in the camera frame, mm; NaN where nothing is hit.
    pub fn depth(&self) -> Vec<f32> {
        self.hits
            .iter()
            .map(|h| if h.id == -1 { f32::NAN } else { h.p[2] })
            .collect()
    }

    /// Instance-id image: the id of the surface each pixel sees, −1 for none.
    pub fn ids(&self) -> Vec<i32> {
        self.hits.iter().map(|h| h.id).collect()
    }

    /// Surface point of every pixel in the camera frame, mm (NaN where nothing is hit).
    pub fn points(&self) -> Vec<[f32; 3]> {
        self.hits
            .iter()
            .map(|h| if h.id == -1 { [f32::NAN; 3] } else { h.p })
            .collect()
    }

    /// Camera-facing unit normal of every pixel's surface in the camera frame (0 where none).
    pub fn normals(&self) -> Vec<[f32; 3]> {
        self.hits.iter().map(|h| h.n).collect()
    }

    /// The image under ambient light alone, with sensor noise.
    pub fn ambient_frame(&self, noise: &SensorNoise, seed: u64) -> Result<Vec<u8>> {
        noise.validate()?;
        Ok(quantise(&self.shade, self.camera.width, noise, seed, u64::MAX))
    }

    /// The RGB frame the camera grabs with the laser at motor angle `theta` (rad): the scene
    /// under ambient light plus the laser line where the sheet meets the first surface it
    /// reaches from the projector, with sensor noise. `seed` fixes the noise.
    pub fn frame(&self, laser: &Laser, theta: f64, noise: &SensorNoise, seed: u64) -> Result<Vec<u8>> {
        laser.validate()?;
        noise.validate()?;
        if !theta.is_finite() {
            return Err(Error::invalid("angle", format!("must be finite, got {theta}")));
        }
        let w = self.camera.width;
        let t = laser.t_camera_laser(theta);
        let o = Point::from(t.translation.vector);
        let r = t.rotation.to_rotation_matrix();
        let (xl, yl, zl) = (
            r.matrix().column(0).into_owned(),
            r.matrix().column(1).into_owned(),
            r.matrix().column(2).into_owned(),
        );
        let tan_half_fan = (laser.fan_angle / 2.0).tan();
        let sigma2 = laser.sheet_sigma * laser.sheet_sigma;
        let pixel_var = 1.0 / 12.0 + noise.blur * noise.blur;
        let salt = theta.to_bits();
        let mut img = self.shade.clone();
        let lit: Vec<(usize, f64)> = img
            .par_chunks_mut(w)
            .enumerate()
            .flat_map_iter(|(row, buf)| {
                let mut rng = Rng::new(mix_seed(seed ^ 0x5EC1_E000, salt, row as u64));
                let mut lit_here = Vec::new();
                for (u, px) in buf.iter_mut().enumerate() {
                    let h = &self.hits[row * w + u];
                    if h.id == -1 {
                        continue;
                    }
                    let p = Point::from(v3(&h.p));
                    let wv = p - o;
                    let d = xl.dot(&wv);
                    let (a, b) = (xl.dot(&v3(&h.dpdu)), xl.dot(&v3(&h.dpdv)));
                    let s2 = sigma2 + (a * a + b * b) * pixel_var;
                    if d * d > 25.0 * s2 {
                        continue;
                    }
                    let along = zl.dot(&wv);
                    if along <= 0.0 || yl.dot(&wv).abs() > tan_half_fan * along {
                        continue;
                    }
                    let dist = wv.norm();
                    let to_laser = -wv / dist;
                    let n = v3(&h.n);
                    let cos_i = n.dot(&to_laser);
                    if cos_i <= 0.0 {
                        continue;
                    }
                    // Laser shadow: something between the projector and this point.
                    let margin = 0.05 + 1e-4 * dist;
                    if cast(&self.placed, &o, &(wv / dist), dist - margin).is_some() {
                        continue;
                    }
                    let profile = (sigma2 / s2).sqrt() * (-0.5 * d * d / s2).exp();
                    let irradiance = laser.power * profile * laser.reference_distance / dist;
                    let m = &self.placed[h.placed as usize].mesh.material;
                    let view_dir = -p.coords / p.coords.norm();
                    let half = (to_laser + view_dir).normalize();
                    let spec = m.specular * n.dot(&half).max(0.0).powf(m.shininess);
                    let mut gain = 1.0;
                    if noise.speckle > 0.0 {
                        gain = (1.0 + noise.speckle * fast_normal(&mut rng) as f64).max(0.0);
                    }
                    for c in 0..3 {
                        px[c] += (irradiance * gain * laser.color[c] * (m.albedo[c] * cos_i + spec)) as f32;
                    }
                    if noise.reflections > 0.0 && m.specular > 0.0 {
                        lit_here.push((row * w + u, irradiance * gain));
                    }
                }
                lit_here
            })
            .collect();
        if noise.reflections > 0.0 {
            self.add_reflections(&mut img, &lit, laser, &o, noise.reflections);
        }
        Ok(quantise(&img, w, noise, seed, salt))
    }

    /// One mirror bounce of the laser off glossy surfaces: the reflected light lands on another
    /// surface and shows there as a stray spot or line, as on shiny real parts.
    fn add_reflections(&self, img: &mut [[f32; 3]], lit: &[(usize, f64)], laser: &Laser, o: &Point, strength: f64) {
        let (w, h) = (self.camera.width, self.camera.height);
        for &(i, irradiance) in lit {
            let hit = &self.hits[i];
            let p = Point::from(v3(&hit.p));
            let n = v3(&hit.n);
            let m = &self.placed[hit.placed as usize].mesh.material;
            let incoming = (p - o).normalize();
            let out = incoming - n * (2.0 * incoming.dot(&n));
            let start = p + n * 0.05;
            let Some((t, n2, k)) = cast(&self.placed, &start, &out, 2000.0) else {
                continue;
            };
            let q = start + out * t;
            let Some((qu, qv)) = self.camera.project(&q) else {
                continue;
            };
            let (ui, vi) = (qu.round(), qv.round());
            if ui < 0.0 || vi < 0.0 || ui >= w as f64 || vi >= h as f64 {
                continue;
            }
            let j = vi as usize * w + ui as usize;
            // Only where the camera itself sees that surface point (not hidden behind another).
            if (self.hits[j].t as f64 - q.coords.norm()).abs() > 1.0 {
                continue;
            }
            let cos2 = n2.dot(&out).abs();
            let albedo = self.placed[k].mesh.material.albedo;
            let e = strength * m.specular * irradiance * cos2;
            for c in 0..3 {
                img[j][c] += (e * laser.color[c] * albedo[c]) as f32;
            }
        }
    }
}

/// A printed calibration checkerboard. Its frame follows OpenCV: the origin at the first inner
/// corner, x along the `cols` direction, y along `rows`, z into the board; inner corners at
/// `(i·square, j·square, 0)` for `i < cols − 1`, `j < rows − 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkerboard {
    /// Squares along x.
    pub cols: usize,
    /// Squares along y.
    pub rows: usize,
    /// Square edge, mm.
    pub square: f64,
    /// White border around the squares, mm.
    pub margin: f64,
}

impl Default for Checkerboard {
    fn default() -> Self {
        Checkerboard {
            cols: 10,
            rows: 7,
            square: 20.0,
            margin: 15.0,
        }
    }
}

/// Renders a checkerboard at `t_camera_board` under `lighting` with `supersample`² samples per
/// pixel, optionally with the laser line at an angle on it, and sensor noise: the images the
/// camera and laser calibrations are computed from.
pub fn render_checkerboard(
    camera: &Camera,
    board: &Checkerboard,
    t_camera_board: &Isometry3<f64>,
    lighting: &Lighting,
    laser: Option<(&Laser, f64)>,
    noise: &SensorNoise,
    supersample: usize,
    seed: u64,
) -> Result<Vec<u8>> {
    camera.validate()?;
    noise.validate()?;
    if board.cols < 2 || board.rows < 2 || !(board.square > 0.0) || !(board.margin >= 0.0) {
        return Err(Error::invalid(
            "board",
            "needs at least 2 × 2 squares, a positive square size and a margin ≥ 0",
        ));
    }
    if supersample == 0 || supersample > 16 {
        return Err(Error::invalid(
            "supersample",
            format!("must be in 1..=16, got {supersample}"),
        ));
    }
    if let Some((l, th)) = laser {
        l.validate()?;
        if !th.is_finite() {
            return Err(Error::invalid("angle", "must be finite"));
        }
    }
    let (w, h) = (camera.width, camera.height);
    let table = camera.ray_table();
    let n = t_camera_board.rotation * Vector3::z();
    let p0 = Point::from(t_camera_board.translation.vector);
    let t_board_camera = t_camera_board.inverse();
    let lamp = lighting.lamp_direction.try_normalize(1e-12).unwrap_or_else(Vector3::z);
    let shade = lighting.ambient + lighting.lamp * n.dot(&lamp).abs();
    let (xmin, ymin) = (-board.square - board.margin, -board.square - board.margin);
    let (xmax, ymax) = (
        (board.cols - 1) as f64 * board.square + board.margin,
        (board.rows - 1) as f64 * board.square + board.margin,
    );
    let laser_frame = laser.map(|(l, th)| {
        let t = l.t_camera_laser(th);
        let r = t.rotation.to_rotation_matrix().into_inner();
        (
            l,
            Point::from(t.translation.vector),
            r.column(0).into_owned(),
            r.column(1).into_owned(),
            r.column(2).into_owned(),
        )
    });
    let k = supersample;
    let img: Vec<[f32; 3]> = (0..h)
        .into_par_iter()
        .flat_map_iter(|v| {
            let table = &table;
            let laser_frame = &laser_frame;
            (0..w).map(move |u| {
                let at = |uu: usize, vv: usize| table[vv * w + uu];
                let c = at(u, v);
                let (u0, u1) = (u.saturating_sub(1), (u + 1).min(w - 1));
                let (v0, v1) = (v.saturating_sub(1), (v + 1).min(h - 1));
                let du = [
                    (at(u1, v)[0] - at(u0, v)[0]) / (u1 - u0).max(1) as f64,
                    (at(u1, v)[1] - at(u0, v)[1]) / (u1 - u0).max(1) as f64,
                ];
                let dv = [
                    (at(u, v1)[0] - at(u, v0)[0]) / (v1 - v0).max(1) as f64,
                    (at(u, v1)[1] - at(u, v0)[1]) / (v1 - v0).max(1) as f64,
                ];
                let mut acc = [0.0f64; 3];
                for i in 0..k {
                    for j in 0..k {
                        let (su, sv) = ((i as f64 + 0.5) / k as f64 - 0.5, (j as f64 + 0.5) / k as f64 - 0.5);
                        let r = Vector3::new(c[0] + su * du[0] + sv * dv[0], c[1] + su * du[1] + sv * dv[1], 1.0);
                        let den = n.dot(&r);
                        let tt = if den.abs() > 1e-12 {
                            n.dot(&p0.coords) / den
                        } else {
                            -1.0
                        };
                        if tt <= 0.0 {
                            for a in acc.iter_mut() {
                                *a += lighting.background;
                            }
                            continue;
                        }
                        let x = Point::from(r * tt);
                        let b = t_board_camera * x;
                        if b.x < xmin || b.x > xmax || b.y < ymin || b.y > ymax {
                            for a in acc.iter_mut() {
                                *a += lighting.background;
                            }
                            continue;
                        }
                        let inside = b.x >= -board.square
                            && b.x < (board.cols - 1) as f64 * board.square
                            && b.y >= -board.square
                            && b.y < (board.rows - 1) as f64 * board.square;
                        let black = inside
                            && ((b.x / board.square).floor() as i64 + (b.y / board.square).floor() as i64)
                                .rem_euclid(2)
                                == 0;
                        let albedo = if black { 0.08 } else { 0.85 };
                        let mut rgb = [albedo * shade; 3];
                        if let Some((l, o, xl, yl, zl)) = laser_frame {
                            let wv = x - o;
                            let along = zl.dot(&wv);
                            if along > 0.0 && yl.dot(&wv).abs() <= (l.fan_angle / 2.0).tan() * along {
                                let d = xl.dot(&wv);
                                let dist = wv.norm();
                                let cos_i = n.dot(&(wv / dist)).abs();
                                let e = l.power
                                    * (-0.5 * d * d / (l.sheet_sigma * l.sheet_sigma)).exp()
                                    * l.reference_distance
                                    / dist
                                    * cos_i
                                    * albedo;
                                for ch in 0..3 {
                                    rgb[ch] += e * l.color[ch];
                                }
                            }
                        }
                        for ch in 0..3 {
                            acc[ch] += rgb[ch];
                        }
                    }
                }
                let s = (k * k) as f64;
                [(acc[0] / s) as f32, (acc[1] / s) as f32, (acc[2] / s) as f32]
            })
        })
        .collect();
    Ok(quantise(&img, w, noise, seed, 0xB0A2D))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane_mesh(z: f64, half: f64) -> TriMesh {
        TriMesh {
            vertices: vec![
                Point::new(-half, -half, z),
                Point::new(half, -half, z),
                Point::new(half, half, z),
                Point::new(-half, half, z),
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        }
    }

    fn small_camera() -> Camera {
        Camera {
            width: 160,
            height: 120,
            fx: 200.0,
            fy: 200.0,
            cx: 79.5,
            cy: 59.5,
            dist: [0.0; 5],
        }
    }

    #[test]
    fn undistort_inverts_distort() {
        let cam = Camera {
            dist: [-0.2, 0.05, 0.001, -0.002, 0.01],
            ..Default::default()
        };
        for &(x, y) in &[(0.1, -0.2), (0.3, 0.25), (-0.31, 0.0)] {
            let (xd, yd) = cam.distort(x, y);
            let (xu, yu) = cam.undistort(xd, yd);
            assert!((xu - x).abs() < 1e-10 && (yu - y).abs() < 1e-10);
        }
    }

    #[test]
    fn depth_of_a_plane_is_its_distance() {
        let mut scene = Scene::new();
        let m = scene.add_mesh(&plane_mesh(0.0, 1000.0), Material::default()).unwrap();
        scene
            .add_instance(m, Isometry3::translation(0.0, 0.0, 400.0), 5)
            .unwrap();
        let view = scene
            .view(&small_camera(), &Isometry3::identity(), &Lighting::default())
            .unwrap();
        let depth = view.depth();
        assert!(depth.iter().all(|d| (d - 400.0).abs() < 1e-3), "{:?}", &depth[..4]);
        assert!(view.ids().iter().all(|&i| i == 5));
    }

    #[test]
    fn laser_line_lands_where_the_sheet_meets_the_plane() {
        let mut scene = Scene::new();
        let m = scene
            .add_mesh(
                &plane_mesh(0.0, 1000.0),
                Material {
                    albedo: [0.8; 3],
                    ..Default::default()
                },
            )
            .unwrap();
        scene
            .add_instance(m, Isometry3::translation(0.0, 0.0, 500.0), 0)
            .unwrap();
        let cam = small_camera();
        let view = scene.view(&cam, &Isometry3::identity(), &Lighting::default()).unwrap();
        let laser = Laser {
            sheet_sigma: 1.5,
            power: 150.0,
            ..Default::default()
        };
        let on = view.frame(&laser, 0.02, &SensorNoise::none(), 1).unwrap();
        let off = view
            .frame(
                &Laser {
                    power: 0.0,
                    ..laser.clone()
                },
                0.02,
                &SensorNoise::none(),
                1,
            )
            .unwrap();
        // The sheet x_L = 0 meets z = 500 along a line of constant camera x (the laser's y axis is
        // the camera's); find it and compare with the red centroid of the middle row.
        let t = laser.t_camera_laser(0.02);
        let (o, xl) = (t.translation.vector, t.rotation * Vector3::x());
        // x such that xl · ((x, 0, 500) − o) = 0
        let x = (xl.dot(&o) - xl.z * 500.0) / xl.x;
        let u_expected = cam.fx * x / 500.0 + cam.cx;
        let row = 60;
        let (mut s, mut sw) = (0.0, 0.0);
        for u in 0..cam.width {
            let i = (row * cam.width + u) * 3;
            let e = on[i] as f64 - off[i] as f64;
            s += e * u as f64;
            sw += e;
        }
        assert!(sw > 100.0, "the line is missing");
        assert!((s / sw - u_expected).abs() < 0.05, "{} vs {u_expected}", s / sw);
    }

    #[test]
    fn nearest_surface_is_the_exact_mesh_distance() {
        let mut scene = Scene::new();
        assert_eq!(scene.nearest_surface(&[Point::origin()]), vec![(f64::INFINITY, -1)]);
        let m = scene.add_mesh(&plane_mesh(0.0, 100.0), Material::default()).unwrap();
        scene
            .add_instance(m, Isometry3::translation(400.0, 0.0, 0.0), 7)
            .unwrap();
        scene
            .add_instance(m, Isometry3::translation(400.0, 0.0, 30.0), 8)
            .unwrap();
        let got = scene.nearest_surface(&[
            Point::new(410.0, 5.0, 3.25),
            Point::new(390.0, 0.0, 20.0),
            Point::new(650.0, 0.0, 0.0),
        ]);
        assert_eq!((got[0].1, got[1].1, got[2].1), (7, 8, 7));
        assert!(
            (got[0].0 - 3.25).abs() < 1e-4 && (got[1].0 - 10.0).abs() < 1e-4 && (got[2].0 - 150.0).abs() < 1e-3,
            "{got:?}"
        );
    }

    #[test]
    fn an_occluder_casts_a_laser_shadow() {
        let mut scene = Scene::new();
        let floor = scene.add_mesh(&plane_mesh(0.0, 1000.0), Material::default()).unwrap();
        scene
            .add_instance(floor, Isometry3::translation(0.0, 0.0, 500.0), 0)
            .unwrap();
        let cam = small_camera();
        let laser = Laser {
            sheet_sigma: 1.0,
            ..Default::default()
        };
        let clear = scene
            .view(&cam, &Isometry3::identity(), &Lighting::default())
            .unwrap()
            .frame(&laser, 0.0, &SensorNoise::none(), 0)
            .unwrap();
        // A small plate in front of the projector, out of the camera's view, hides the line.
        let block = scene.add_mesh(&plane_mesh(0.0, 10.0), Material::default()).unwrap();
        let t = laser.t_camera_laser(0.0);
        scene
            .add_instance(
                block,
                Isometry3::from_parts(
                    (t.translation.vector + t.rotation * Vector3::new(0.0, 0.0, 30.0)).into(),
                    t.rotation,
                ),
                1,
            )
            .unwrap();
        let shadowed = scene
            .view(&cam, &Isometry3::identity(), &Lighting::default())
            .unwrap()
            .frame(&laser, 0.0, &SensorNoise::none(), 0)
            .unwrap();
        let red = |img: &[u8]| img.chunks(3).map(|p| p[0] as u64).sum::<u64>();
        assert!(
            red(&clear) > red(&shadowed) + 1000,
            "{} {}",
            red(&clear),
            red(&shadowed)
        );
    }
}
