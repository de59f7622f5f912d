//! Laser-line triangulation (paper section 3.1, Eq. 10–14, generalised): undistorted camera
//! rays from the OpenCV intrinsics, the laser plane from the projector pose and the motor
//! angle, ray–plane intersection, and the points carried to the robot's base frame.
//!
//! Frames: camera x right, y down, z forward. The light sheet is the plane `x_L = 0` of the
//! laser frame; the motor turns the projector about its own y axis, so
//! `T_camera_laser(θ) = T_camera_laser0 · Rot_y(θ)` and, with `T_camera_laser0 = I`, the plane
//! normal in the camera frame is `(cos θ, 0, −sin θ)` (Eq. 11).
//!
//! Speed: [`triangulate`] undistorts through a [`RayTable`] (rays on a 4-pixel grid, built once
//! per camera and cached) and one Newton step from the interpolated ray, so it agrees with the
//! exact [`Camera::ray`] to far below 1e-4 px at a fraction of the cost.

use crate::geometry::{Plane, Point};
use crate::{Error, Result};
use nalgebra::{Isometry3, Matrix3, Vector3};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// An OpenCV pinhole camera with the five-coefficient distortion `[k1, k2, p1, p2, k3]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Skew `K[0][1]`, pixels (0 for nearly every camera).
    pub skew: f64,
    /// Distortion `[k1, k2, p1, p2, k3]`.
    pub dist: [f64; 5],
}

/// Why a pixel gave no point.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum PointStatus {
    /// The point is valid.
    Valid = 0,
    /// The camera ray is parallel to the laser plane (within 1e-9 rad): no unique intersection.
    Parallel = 1,
    /// The intersection lies behind the camera: the pixel cannot show the lit surface.
    Behind = 2,
    /// The distortion could not be inverted at this pixel (far outside the calibrated field).
    NotUndistortable = 3,
}

/// The robot pose and motor angle of one frame of a scan.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FramePose {
    /// Motor angle, radians.
    pub angle: f64,
    /// Flange pose in the base frame at capture.
    pub t_base_flange: Isometry3<f64>,
}

/// The fixed geometry of the sensor: camera, projector pose at angle 0, hand-eye transform.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sensor {
    /// The camera's intrinsics and distortion.
    pub camera: Camera,
    /// Laser frame in the camera frame at motor angle 0.
    pub t_camera_laser0: Isometry3<f64>,
    /// Camera frame in the flange frame (hand-eye).
    pub t_flange_camera: Isometry3<f64>,
}

/// Points of a scan in the base frame, with a status per input pixel; invalid points are NaN.
#[derive(Debug, Clone, PartialEq)]
pub struct Triangulation {
    /// One point per input pixel, base frame, mm (NaN where `status` is not `Valid`).
    pub points: Vec<Point>,
    /// Why each point is or is not valid.
    pub status: Vec<PointStatus>,
}

const UNDISTORT_ITERATIONS: usize = 20;
const UNDISTORT_TOLERANCE: f64 = 1e-14;
/// Pixels between the nodes of a [`RayTable`].
const TABLE_STEP: f64 = 4.0;
/// Distortion residual (normalised units, about 0.01 px) below which one Newton step from a
/// table ray is final: the step leaves an error of order 1e-10 (quadratic in the residual,
/// plus the residual times the interpolation error of the inverse Jacobian, about 1e-5).
const TABLE_ACCEPT: f64 = 1e-5;
/// Cameras whose ray tables are kept by [`RayTable::shared`].
const TABLE_CACHE: usize = 4;
/// Pixels per work item of the parallel loops.
const CHUNK: usize = 4096;
/// Sine of the smallest angle between a ray and the laser plane that still gives a point.
const PARALLEL_SINE: f64 = 1e-9;

impl Camera {
    /// A camera from the 3×3 intrinsic matrix `k`, the distortion and the image size; checks
    /// that the focal lengths are positive, the last row is `0 0 1` and everything is finite.
    pub fn new(width: u32, height: u32, k: &Matrix3<f64>, dist: [f64; 5]) -> Result<Self> {
        if width < 2 || height < 2 {
            return Err(Error::invalid(
                "camera",
                format!("image size {width}×{height} is too small; pass the sensor's size in pixels"),
            ));
        }
        if k.iter().chain(dist.iter()).any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "camera",
                "K or dist holds NaN or inf; pass a calibrated camera",
            ));
        }
        if k[(0, 0)] <= 0.0 || k[(1, 1)] <= 0.0 {
            return Err(Error::invalid(
                "K",
                format!(
                    "focal lengths fx={}, fy={} must be positive pixels",
                    k[(0, 0)],
                    k[(1, 1)]
                ),
            ));
        }
        if k[(1, 0)] != 0.0 || k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 || k[(2, 2)] != 1.0 {
            return Err(Error::invalid("K", "must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"));
        }
        Ok(Camera {
            width,
            height,
            fx: k[(0, 0)],
            fy: k[(1, 1)],
            cx: k[(0, 2)],
            cy: k[(1, 2)],
            skew: k[(0, 1)],
            dist,
        })
    }

    /// Applies the distortion to normalised coordinates `(x, y)` (`z = 1`).
    pub fn distort(&self, x: f64, y: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.dist;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
        )
    }

    /// Projects a point of the camera frame to a pixel `(u, v)`; `None` when it is not in front.
    pub fn project(&self, p: &Point) -> Option<[f64; 2]> {
        if p.z <= 0.0 {
            return None;
        }
        let (xd, yd) = self.distort(p.x / p.z, p.y / p.z);
        Some([self.fx * xd + self.skew * yd + self.cx, self.fy * yd + self.cy])
    }

    /// The distorted normalised coordinates `(x_d, y_d)` of pixel `(u, v)` (`K⁻¹` applied).
    fn normalised(&self, u: f64, v: f64) -> (f64, f64) {
        let yd = (v - self.cy) / self.fy;
        ((u - self.cx - self.skew * yd) / self.fx, yd)
    }

    /// The undistorted normalised ray `(x, y, 1)` through pixel `(u, v)`, by Newton's method on
    /// the distortion model started at the distorted point, iterated to a residual of 1e-14;
    /// `None` if it does not converge (pixel far outside the model's range). The exact
    /// reference; [`RayTable::ray`] gives the same rays faster.
    pub fn ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        let (xd, yd) = self.normalised(u, v);
        if self.dist == [0.0; 5] {
            return Some(Vector3::new(xd, yd, 1.0));
        }
        self.undistort(xd, yd, xd, yd).map(|(x, y)| Vector3::new(x, y, 1.0))
    }

    /// `distort(x, y) − (xd, yd)`.
    #[inline(always)]
    fn residual(&self, x: f64, y: f64, xd: f64, yd: f64) -> (f64, f64) {
        let [k1, k2, p1, p2, k3] = self.dist;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        (
            x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd,
            y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd,
        )
    }

    /// The Jacobian of `distort` at `(x, y)`, symmetric: `(∂x_d/∂x, ∂x_d/∂y = ∂y_d/∂x, ∂y_d/∂y)`.
    #[inline(always)]
    fn jacobian(&self, x: f64, y: f64) -> (f64, f64, f64) {
        let [k1, k2, p1, p2, k3] = self.dist;
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
        let dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);
        (
            radial + 2.0 * x * x * dradial + 2.0 * p1 * y + 6.0 * p2 * x,
            2.0 * x * y * dradial + 2.0 * p1 * x + 2.0 * p2 * y,
            radial + 2.0 * y * y * dradial + 6.0 * p1 * y + 2.0 * p2 * x,
        )
    }

    /// Newton's method for the undistorted `(x, y)` with `distort(x, y) = (xd, yd)`, started at
    /// `(x, y)`; stops when the residual is below `UNDISTORT_TOLERANCE`.
    fn undistort(&self, xd: f64, yd: f64, mut x: f64, mut y: f64) -> Option<(f64, f64)> {
        for _ in 0..UNDISTORT_ITERATIONS {
            let (ex, ey) = self.residual(x, y, xd, yd);
            if ex * ex + ey * ey < UNDISTORT_TOLERANCE * UNDISTORT_TOLERANCE {
                return Some((x, y));
            }
            let (jxx, cross, jyy) = self.jacobian(x, y);
            let det = jxx * jyy - cross * cross;
            if !det.is_finite() || det.abs() < 1e-12 {
                return None;
            }
            x -= (jyy * ex - cross * ey) / det;
            y -= (jxx * ey - cross * ex) / det;
        }
        None
    }
}

/// One node of a [`RayTable`]: the undistorted ray `(x, y)` at the node's pixel and the inverse
/// `[[a, b], [b, c]]` of the distortion's Jacobian there. The Jacobian only scales a correction
/// of about 1e-6, so single precision is plenty, and a node fills half a cache line.
#[derive(Debug, Clone, Copy)]
#[repr(C, align(32))]
struct Node {
    x: f64,
    y: f64,
    a: f32,
    b: f32,
    c: f32,
}

/// Undistorted rays of one camera on a grid of nodes every 4 pixels over the image, for fast
/// undistortion of many pixels: the ray at a pixel is interpolated bilinearly between the four
/// nodes around it and finished by one Newton step on the distortion model, with the inverse
/// Jacobian interpolated from the nodes too (more steps where the interpolated ray is poor or a
/// node failed). It agrees with [`Camera::ray`] to about 1e-7 px. Building one costs about
/// 50 000 exact undistortions for a 1032×778 image; [`RayTable::shared`] builds it once per camera.
#[derive(Debug, Clone)]
pub struct RayTable {
    camera: Camera,
    inv_fx: f64,
    inv_fy: f64,
    cols: usize,
    rows: usize,
    /// The node at pixel `(−0.5 + i·STEP, −0.5 + j·STEP)` at `j·cols + i`; NaN where the
    /// distortion cannot be inverted.
    nodes: Vec<Node>,
}

impl RayTable {
    /// The table of `camera`'s rays (empty when it has no distortion). Runs on the current rayon pool.
    pub fn new(camera: &Camera) -> Self {
        let (inv_fx, inv_fy) = (1.0 / camera.fx, 1.0 / camera.fy);
        if camera.dist == [0.0; 5] {
            return RayTable {
                camera: *camera,
                inv_fx,
                inv_fy,
                cols: 0,
                rows: 0,
                nodes: Vec::new(),
            };
        }
        let nodes_along = |size: u32| ((size as f64 - 1.0) / TABLE_STEP).ceil() as usize + 1;
        let (cols, rows) = (nodes_along(camera.width), nodes_along(camera.height));
        let nodes = (0..rows * cols)
            .into_par_iter()
            .with_min_len(256)
            .map(|k| {
                let u = -0.5 + (k % cols) as f64 * TABLE_STEP;
                let v = -0.5 + (k / cols) as f64 * TABLE_STEP;
                let Some(r) = camera.ray(u, v) else {
                    return Node {
                        x: f64::NAN,
                        y: f64::NAN,
                        a: f32::NAN,
                        b: f32::NAN,
                        c: f32::NAN,
                    };
                };
                let (jxx, cross, jyy) = camera.jacobian(r.x, r.y);
                let det = jxx * jyy - cross * cross;
                Node {
                    x: r.x,
                    y: r.y,
                    a: (jyy / det) as f32,
                    b: (-cross / det) as f32,
                    c: (jxx / det) as f32,
                }
            })
            .collect();
        RayTable {
            camera: *camera,
            inv_fx,
            inv_fy,
            cols,
            rows,
            nodes,
        }
    }

    /// The table of `camera`, built on first use and kept for the last few cameras seen, so
    /// that every scan of a camera after the first skips the build.
    pub fn shared(camera: &Camera) -> Arc<RayTable> {
        static CACHE: Mutex<Vec<Arc<RayTable>>> = Mutex::new(Vec::new());
        let find = |cache: &[Arc<RayTable>]| cache.iter().find(|t| t.camera == *camera).cloned();
        if let Some(t) = find(&CACHE.lock().unwrap_or_else(|e| e.into_inner())) {
            return t;
        }
        // Built outside the lock: other cameras' lookups need not wait for it.
        let table = Arc::new(RayTable::new(camera));
        let mut cache = CACHE.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(t) = find(&cache) {
            return t;
        }
        if cache.len() == TABLE_CACHE {
            cache.remove(0);
        }
        cache.push(table.clone());
        table
    }

    /// The camera the table belongs to.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    /// The undistorted normalised ray `(x, y, 1)` through pixel `(u, v)`, as [`Camera::ray`]
    /// gives it; `None` where the distortion cannot be inverted.
    #[inline]
    pub fn ray(&self, u: f64, v: f64) -> Option<Vector3<f64>> {
        self.ray_xy(u, v).map(|(x, y)| Vector3::new(x, y, 1.0))
    }

    #[inline]
    fn ray_xy(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        let cam = &self.camera;
        let yd = (v - cam.cy) * self.inv_fy;
        let xd = (u - cam.cx - cam.skew * yd) * self.inv_fx;
        if self.nodes.is_empty() {
            return Some((xd, yd));
        }
        // Pixels outside the grid use its edge cells (the Newton iterations make up for it);
        // clamping at 0 first makes the cast a floor.
        let tu = ((u + 0.5) * (1.0 / TABLE_STEP)).max(0.0);
        let tv = ((v + 0.5) * (1.0 / TABLE_STEP)).max(0.0);
        let i = (tu as usize).min(self.cols - 2);
        let j = (tv as usize).min(self.rows - 2);
        let (fu, fv) = (tu - i as f64, tv - j as f64);
        let k = j * self.cols + i;
        let (n00, n01, n10, n11) = (
            &self.nodes[k],
            &self.nodes[k + 1],
            &self.nodes[k + self.cols],
            &self.nodes[k + self.cols + 1],
        );
        let lerp = |f: fn(&Node) -> f64| {
            let top = f(n00) + fu * (f(n01) - f(n00));
            let bottom = f(n10) + fu * (f(n11) - f(n10));
            top + fv * (bottom - top)
        };
        let (x, y) = (lerp(|n| n.x), lerp(|n| n.y));
        let (ex, ey) = cam.residual(x, y, xd, yd);
        // NaN (a failed node) fails the test too.
        if ex * ex + ey * ey < TABLE_ACCEPT * TABLE_ACCEPT {
            let (a, b, c) = (lerp(|n| n.a as f64), lerp(|n| n.b as f64), lerp(|n| n.c as f64));
            return Some((x - (a * ex + b * ey), y - (b * ex + c * ey)));
        }
        // A poor guess (a failed node nearby, or a pixel off the grid): the full iteration.
        let (xd, yd) = cam.normalised(u, v);
        let start = if x.is_finite() && y.is_finite() {
            (x, y)
        } else {
            (xd, yd)
        };
        cam.undistort(xd, yd, start.0, start.1)
    }
}

/// The laser plane in the camera frame at motor angle `angle`: the plane `x_L = 0` of
/// `T_camera_laser0 · Rot_y(angle)` (Eq. 9–12).
pub fn laser_plane(t_camera_laser0: &Isometry3<f64>, angle: f64) -> Plane {
    let (s, c) = angle.sin_cos();
    let normal = t_camera_laser0.rotation * Vector3::new(c, 0.0, -s);
    Plane {
        normal,
        offset: normal.dot(&t_camera_laser0.translation.vector),
    }
}

/// Intersects the ray `s · dir` (from the origin) with `plane`: the point, or why there is none.
pub fn intersect_ray_plane(dir: &Vector3<f64>, plane: &Plane) -> std::result::Result<Point, PointStatus> {
    let denom = plane.normal.dot(dir);
    if denom * denom <= PARALLEL_SINE * PARALLEL_SINE * dir.norm_squared() {
        return Err(PointStatus::Parallel);
    }
    let s = plane.offset / denom;
    if s <= 0.0 {
        return Err(PointStatus::Behind);
    }
    Ok(Point::from(dir * s))
}

/// Checks a pixel list: finite, inside the image (half a pixel of margin), frame indices valid.
fn check_pixels(camera: &Camera, pixels: &[[f64; 2]], frame_index: Option<(&[u32], usize)>) -> Result<()> {
    let (w, h) = (camera.width as f64 - 0.5, camera.height as f64 - 0.5);
    // A branch-free pass first (NaN fails every comparison); the loop below only names the culprit.
    let inside = pixels
        .iter()
        .fold(true, |ok, &[u, v]| ok & (u >= -0.5) & (u <= w) & (v >= -0.5) & (v <= h));
    for (i, &[u, v]) in pixels.iter().enumerate().filter(|_| !inside) {
        if !(u.is_finite() && v.is_finite()) {
            return Err(Error::NonFinite {
                arg: "pixels".into(),
                index: i,
                value: format!("({u}, {v})"),
            });
        }
        if !(-0.5..=w).contains(&u) || !(-0.5..=h).contains(&v) {
            return Err(Error::invalid(
                "pixels",
                format!(
                    "row {i} is ({u}, {v}), outside the {}×{} image; pixels are (u, v) = (column, row)",
                    camera.width, camera.height
                ),
            ));
        }
    }
    if let Some((index, frames)) = frame_index {
        if index.len() != pixels.len() {
            return Err(Error::invalid(
                "frame_index",
                format!(
                    "has {} entries for {} pixels; give one frame index per pixel",
                    index.len(),
                    pixels.len()
                ),
            ));
        }
        let largest = index.iter().copied().max().map_or(0, |f| f as usize);
        if let Some((i, &f)) = index
            .iter()
            .enumerate()
            .filter(|_| largest >= frames)
            .find(|(_, &f)| f as usize >= frames)
        {
            return Err(Error::invalid(
                "frame_index",
                format!("entry {i} is {f} but the scan has {frames} frames"),
            ));
        }
    }
    Ok(())
}

/// The undistorted normalised rays `(x, y, 1)` of `pixels`; `None` where the distortion
/// cannot be inverted.
pub fn pixel_rays(camera: &Camera, pixels: &[[f64; 2]]) -> Result<Vec<Option<Vector3<f64>>>> {
    check_pixels(camera, pixels, None)?;
    Ok(pixels
        .par_iter()
        .with_min_len(4096)
        .map(|&[u, v]| camera.ray(u, v))
        .collect())
}

/// Triangulates laser-line pixels of a whole scan into points of the base frame.
///
/// `pixels[i]` was seen in frame `frame_index[i]`, captured at motor angle `frames[f].angle`
/// with the flange at `frames[f].t_base_flange`. Pixels whose ray is parallel to the laser
/// plane, meets it behind the camera, or cannot be undistorted give NaN points and a status
/// saying why; malformed input (bad index, pixel outside the image, NaN) is an error.
/// Runs on the current rayon pool; see [`triangulate_into`] for the allocation-free form.
pub fn triangulate(
    sensor: &Sensor,
    frames: &[FramePose],
    pixels: &[[f64; 2]],
    frame_index: &[u32],
) -> Result<Triangulation> {
    let mut points = vec![[0.0; 3]; pixels.len()];
    let mut status = vec![PointStatus::Valid; pixels.len()];
    triangulate_into(sensor, frames, pixels, frame_index, &mut points, &mut status)?;
    Ok(Triangulation {
        points: points.into_iter().map(Point::from).collect(),
        status,
    })
}

/// [`triangulate`] writing `(x, y, z)` of each point into `points` and its status into
/// `status`, both as long as `pixels`. Undistorts through [`RayTable::shared`].
pub fn triangulate_into(
    sensor: &Sensor,
    frames: &[FramePose],
    pixels: &[[f64; 2]],
    frame_index: &[u32],
    points: &mut [[f64; 3]],
    status: &mut [PointStatus],
) -> Result<()> {
    check_pixels(&sensor.camera, pixels, Some((frame_index, frames.len())))?;
    if points.len() != pixels.len() || status.len() != pixels.len() {
        return Err(Error::invalid(
            "points",
            format!(
                "output buffers hold {} points and {} statuses for {} pixels; give one of each per pixel",
                points.len(),
                status.len(),
                pixels.len()
            ),
        ));
    }
    if let Some((i, f)) = frames.iter().enumerate().find(|(_, f)| !f.angle.is_finite()) {
        return Err(Error::NonFinite {
            arg: "angles".into(),
            index: i,
            value: f.angle.to_string(),
        });
    }
    let per_frame: Vec<FrameGeometry> = frames
        .iter()
        .map(|f| {
            let t_base_camera = f.t_base_flange * sensor.t_flange_camera;
            let plane = laser_plane(&sensor.t_camera_laser0, f.angle);
            FrameGeometry {
                plane,
                rotation: t_base_camera.rotation.to_rotation_matrix().into_inner(),
                translation: t_base_camera.translation.vector,
            }
        })
        .collect();
    let table = RayTable::shared(&sensor.camera);
    points
        .par_chunks_mut(CHUNK)
        .zip(status.par_chunks_mut(CHUNK))
        .zip(pixels.par_chunks(CHUNK).zip(frame_index.par_chunks(CHUNK)))
        .for_each(|((points, status), (pixels, frame_index))| {
            for (((out, st), &[u, v]), &f) in points.iter_mut().zip(status.iter_mut()).zip(pixels).zip(frame_index) {
                (*out, *st) = match table.ray_xy(u, v) {
                    Some((x, y)) => per_frame[f as usize].point(x, y),
                    None => ([f64::NAN; 3], PointStatus::NotUndistortable),
                };
            }
        });
    Ok(())
}

/// The laser plane and the camera pose in the base frame of one frame.
struct FrameGeometry {
    plane: Plane,
    rotation: Matrix3<f64>,
    translation: Vector3<f64>,
}

impl FrameGeometry {
    /// The base-frame point where the ray `(x, y, 1)` meets the plane, as
    /// [`intersect_ray_plane`] decides, written with selects instead of branches: singular
    /// rays among valid ones then cost no mispredicted jumps.
    #[inline(always)]
    fn point(&self, x: f64, y: f64) -> ([f64; 3], PointStatus) {
        let n = &self.plane.normal;
        let denom = n.x * x + n.y * y + n.z;
        let s = self.plane.offset / denom;
        let parallel = denom * denom <= PARALLEL_SINE * PARALLEL_SINE * (x * x + y * y + 1.0);
        let status = if parallel {
            PointStatus::Parallel
        } else if s <= 0.0 {
            PointStatus::Behind
        } else {
            PointStatus::Valid
        };
        let r = &self.rotation;
        let scale = if status == PointStatus::Valid { s } else { f64::NAN };
        let point = [
            self.translation.x + scale * (r[(0, 0)] * x + r[(0, 1)] * y + r[(0, 2)]),
            self.translation.y + scale * (r[(1, 0)] * x + r[(1, 1)] * y + r[(1, 2)]),
            self.translation.z + scale * (r[(2, 0)] * x + r[(2, 1)] * y + r[(2, 2)]),
        ];
        (point, status)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    fn camera(dist: [f64; 5]) -> Camera {
        let k = Matrix3::new(1200.0, 0.0, 516.0, 0.0, 1190.0, 389.0, 0.0, 0.0, 1.0);
        Camera::new(1032, 778, &k, dist).unwrap()
    }

    fn sensor() -> Sensor {
        Sensor {
            camera: camera([-0.12, 0.08, 0.001, -0.0007, -0.01]),
            t_camera_laser0: Isometry3::from_parts(
                Translation3::new(-150.0, 3.0, 10.0),
                UnitQuaternion::from_euler_angles(0.01, 0.02, -0.015),
            ),
            t_flange_camera: Isometry3::from_parts(
                Translation3::new(20.0, -5.0, 80.0),
                UnitQuaternion::from_euler_angles(0.1, -0.05, 0.3),
            ),
        }
    }

    #[test]
    fn undistortion_inverts_the_distortion_across_the_image() {
        let cam = camera([-0.12, 0.08, 0.001, -0.0007, -0.01]);
        for u in (0..1032).step_by(37) {
            for v in (0..778).step_by(29) {
                let ray = cam.ray(u as f64, v as f64).expect("converges");
                let back = cam.project(&Point::from(ray * 3.0)).unwrap();
                assert!(
                    (back[0] - u as f64).abs() < 1e-9 && (back[1] - v as f64).abs() < 1e-9,
                    "{u},{v} -> {back:?}"
                );
            }
        }
    }

    #[test]
    fn ray_table_agrees_with_newton_to_1e_4_px_over_the_whole_image() {
        // A wide-angle lens: at the image corners the distortion moves pixels by about 120 px.
        let k = Matrix3::new(900.0, 0.0, 530.0, 0.0, 905.0, 380.0, 0.0, 0.0, 1.0);
        let cam = Camera::new(1032, 778, &k, [-0.35, 0.2, 0.002, -0.0015, -0.05]).unwrap();
        let corner = cam.ray(-0.5, -0.5).unwrap();
        assert!((corner.x * cam.fx - (-0.5 - cam.cx)).abs() > 100.0, "{corner}");
        let table = RayTable::new(&cam);
        let mut worst = 0.0f64;
        let mut check = |u: f64, v: f64| {
            let exact = cam.ray(u, v).expect("exact converges");
            let fast = table.ray(u, v).expect("table converges");
            worst = worst
                .max(((fast.x - exact.x) * cam.fx).abs())
                .max(((fast.y - exact.y) * cam.fy).abs());
        };
        for v in 0..778 {
            for u in 0..1032 {
                check(u as f64 + 0.37, v as f64 - 0.21);
            }
        }
        for t in 0..=1000 {
            let (s, r) = (t as f64 / 1000.0 * 1031.0 - 0.5, t as f64 / 1000.0 * 777.0 - 0.5);
            for (u, v) in [(s, -0.5), (s, 777.5), (-0.5, r), (1031.5, r)] {
                check(u, v);
            }
        }
        assert!(worst < 1e-4, "worst difference {worst} px");
        // Not just within the bound: one Newton step from the table is as good as the loop.
        assert!(worst < 1e-7, "worst difference {worst} px");
    }

    #[test]
    fn ray_tables_are_built_once_per_camera() {
        let a = camera([-0.12, 0.08, 0.001, -0.0007, -0.01]);
        let b = camera([-0.1, 0.08, 0.001, -0.0007, -0.01]);
        let ta = RayTable::shared(&a);
        assert!(Arc::ptr_eq(&ta, &RayTable::shared(&a)));
        assert!(!Arc::ptr_eq(&ta, &RayTable::shared(&b)));
        assert_eq!(*RayTable::shared(&b).camera(), b);
        let plain = RayTable::new(&camera([0.0; 5]));
        assert!((plain.ray(100.0, 200.0).unwrap() - camera([0.0; 5]).ray(100.0, 200.0).unwrap()).norm() < 1e-15);
    }

    #[test]
    fn plane_normal_follows_eq_11() {
        for &theta in &[-0.7, 0.0, 0.3, 1.2] {
            let p = laser_plane(&Isometry3::identity(), theta);
            assert!((p.normal - Vector3::new(theta.cos(), 0.0, -theta.sin())).norm() < 1e-15);
            assert_eq!(p.offset, 0.0);
        }
    }

    #[test]
    fn triangulation_recovers_points_on_the_laser_plane() {
        let s = sensor();
        let frames: Vec<FramePose> = (0..5)
            .map(|i| FramePose {
                angle: 0.2 + 0.06 * i as f64,
                t_base_flange: Isometry3::from_parts(
                    Translation3::new(300.0 + i as f64, -40.0, 700.0),
                    UnitQuaternion::from_euler_angles(3.1, 0.05 * i as f64, 0.2),
                ),
            })
            .collect();
        let (mut pixels, mut index, mut truth) = (vec![], vec![], vec![]);
        for (f, fp) in frames.iter().enumerate() {
            let plane = laser_plane(&s.t_camera_laser0, fp.angle);
            let t_base_camera = fp.t_base_flange * s.t_flange_camera;
            for k in 0..40 {
                let y = -120.0 + 6.0 * k as f64;
                let z = 450.0 + 3.0 * k as f64;
                // Solve the plane equation for x so that the point lies on the sheet.
                let x = (plane.offset - plane.normal.y * y - plane.normal.z * z) / plane.normal.x;
                let pc = Point::new(x, y, z);
                if let Some(px) = s.camera.project(&pc) {
                    if px[0] >= 0.0 && px[0] <= 1031.0 && px[1] >= 0.0 && px[1] <= 777.0 {
                        pixels.push(px);
                        index.push(f as u32);
                        truth.push(t_base_camera * pc);
                    }
                }
            }
        }
        assert!(pixels.len() > 100);
        let out = triangulate(&s, &frames, &pixels, &index).unwrap();
        for ((p, t), st) in out.points.iter().zip(&truth).zip(&out.status) {
            assert_eq!(*st, PointStatus::Valid);
            assert!((p - t).norm() < 1e-8, "{p} vs {t}");
        }
    }

    #[test]
    fn singular_geometry_is_reported_per_point() {
        let s = Sensor {
            camera: camera([0.0; 5]),
            t_camera_laser0: Isometry3::identity(),
            t_flange_camera: Isometry3::identity(),
        };
        let frames = [FramePose {
            angle: 0.0,
            t_base_flange: Isometry3::identity(),
        }];
        // The laser plane x = 0 contains the optical centre: every ray is in the plane or misses it.
        let out = triangulate(&s, &frames, &[[516.0, 100.0], [700.0, 100.0]], &[0, 0]).unwrap();
        assert_eq!(out.status[0], PointStatus::Parallel);
        assert!(out.points[0].x.is_nan());
        let behind = Sensor {
            t_camera_laser0: Isometry3::translation(50.0, 0.0, 0.0),
            ..s
        };
        let out = triangulate(&behind, &frames, &[[300.0, 100.0], [700.0, 100.0]], &[0, 0]).unwrap();
        assert_eq!(out.status, vec![PointStatus::Behind, PointStatus::Valid]);
    }

    #[test]
    fn malformed_input_is_an_error_naming_the_argument() {
        let s = sensor();
        let frames = [FramePose {
            angle: 0.1,
            t_base_flange: Isometry3::identity(),
        }];
        let e = triangulate(&s, &frames, &[[10.0, 10.0]], &[1]).unwrap_err();
        assert!(e.to_string().starts_with("frame_index"), "{e}");
        let e = triangulate(&s, &frames, &[[2000.0, 10.0]], &[0]).unwrap_err();
        assert!(e.to_string().contains("outside"), "{e}");
        let e = triangulate(&s, &frames, &[[f64::NAN, 10.0]], &[0]).unwrap_err();
        assert!(matches!(e, Error::NonFinite { .. }));
        assert!(Camera::new(1032, 778, &Matrix3::zeros(), [0.0; 5]).is_err());
    }
}
