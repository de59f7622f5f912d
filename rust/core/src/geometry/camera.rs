//! THE camera model of binpick: an OpenCV pinhole camera (`K` with skew, distortion
//! `[k1, k2, p1, p2, k3]`), its projection, its undistortion (Newton's method) and the
//! [`RayTable`] that undistorts many pixels fast. Triangulation turns pixels into rays with it
//! and the simulator's renderer casts its rays and projects its points with it, so the images
//! the simulator makes and the points the measuring chain reads from them use one model.
//!
//! Frames: camera x right, y down, z forward; pixel centres at integer `(u, v)` = (column, row).

use crate::geometry::Point;
use crate::{Error, Result};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use std::sync::{Arc, Mutex};

/// The widest or tallest image binpick reads, pixels (as `MAX_IMAGE_SIDE` in
/// `python/binpick/_validate.py`).
pub const MAX_IMAGE_SIDE: u32 = 65_536;

/// The most pixels of an image binpick reads (2^28, as `MAX_IMAGE_PIXELS` in
/// `python/binpick/_validate.py`): ray tables and rendered images scale with it.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

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

impl Default for Camera {
    /// The paper's camera (AVT Guppy F-080C, 1032 × 778) with an 8 mm-class lens, no skew and
    /// no distortion.
    fn default() -> Self {
        Camera {
            width: 1032,
            height: 778,
            fx: 1600.0,
            fy: 1600.0,
            cx: 515.5,
            cy: 388.5,
            skew: 0.0,
            dist: [0.0; 5],
        }
    }
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

/// Values built from a camera (a ray table, a renderer's ray grid), kept for the last `cap`
/// cameras seen: the one cache of per-camera work.
pub(crate) struct PerCamera<T> {
    slots: Mutex<Vec<(Camera, Arc<T>)>>,
    cap: usize,
}

impl<T> PerCamera<T> {
    /// An empty cache keeping `cap` cameras' values (usable in a `static`).
    pub(crate) const fn new(cap: usize) -> Self {
        PerCamera {
            slots: Mutex::new(Vec::new()),
            cap,
        }
    }

    /// The value of `camera`, from the cache or made by `build` (outside the lock: other
    /// cameras' lookups need not wait for it) and kept, the oldest camera's dropped.
    pub(crate) fn get_or_build(&self, camera: &Camera, build: impl FnOnce() -> T) -> Arc<T> {
        let find = |slots: &[(Camera, Arc<T>)]| slots.iter().find(|(c, _)| c == camera).map(|(_, v)| v.clone());
        if let Some(v) = find(&self.slots.lock().unwrap_or_else(|e| e.into_inner())) {
            return v;
        }
        let value = Arc::new(build());
        let mut slots = self.slots.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(v) = find(&slots) {
            return v;
        }
        if slots.len() >= self.cap {
            slots.remove(0);
        }
        slots.push((*camera, value.clone()));
        value
    }
}

impl Camera {
    /// A camera from the 3×3 intrinsic matrix `k = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]`, the
    /// distortion and the image size, checked by [`Camera::validate`].
    pub fn new(width: u32, height: u32, k: &Matrix3<f64>, dist: [f64; 5]) -> Result<Self> {
        if k.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "camera",
                "K or dist holds NaN or inf; pass a calibrated camera",
            ));
        }
        if k[(1, 0)] != 0.0 || k[(2, 0)] != 0.0 || k[(2, 1)] != 0.0 || k[(2, 2)] != 1.0 {
            return Err(Error::invalid("K", "must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]]"));
        }
        let camera = Camera {
            width,
            height,
            fx: k[(0, 0)],
            fy: k[(1, 1)],
            cx: k[(0, 2)],
            cy: k[(1, 2)],
            skew: k[(0, 1)],
            dist,
        };
        camera.validate()?;
        Ok(camera)
    }

    /// Checks that the image is at least 2×2 and at most [`MAX_IMAGE_SIDE`] a side and
    /// [`MAX_IMAGE_PIXELS`] in all, everything is finite and the focal lengths
    /// are positive: what every user of the model (ray tables, triangulation, the renderer) needs.
    pub fn validate(&self) -> Result<()> {
        let (width, height) = (self.width, self.height);
        if width < 2 || height < 2 {
            return Err(Error::invalid(
                "camera",
                format!("image size {width}×{height} is too small; pass the sensor's size in pixels"),
            ));
        }
        let pixels = width as u64 * height as u64;
        if width > MAX_IMAGE_SIDE || height > MAX_IMAGE_SIDE || pixels > MAX_IMAGE_PIXELS {
            return Err(Error::invalid(
                "camera",
                format!(
                    "image size {width}×{height} ({pixels} pixels) is over binpick's ceiling of \
                     {MAX_IMAGE_SIDE} pixels a side and {MAX_IMAGE_PIXELS} in all; pass the sensor's size in pixels"
                ),
            ));
        }
        let numbers = [self.fx, self.fy, self.cx, self.cy, self.skew];
        if numbers.iter().chain(self.dist.iter()).any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "camera",
                "K or dist holds NaN or inf; pass a calibrated camera",
            ));
        }
        if self.fx <= 0.0 || self.fy <= 0.0 {
            return Err(Error::invalid(
                "K",
                format!("focal lengths fx={}, fy={} must be positive pixels", self.fx, self.fy),
            ));
        }
        Ok(())
    }

    /// Applies the distortion to normalised coordinates `(x, y)` (`z = 1`).
    #[inline(always)]
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
        let (dx, dy) = self.distort(x, y);
        (dx - xd, dy - yd)
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
    pub(crate) fn undistort(&self, xd: f64, yd: f64, mut x: f64, mut y: f64) -> Option<(f64, f64)> {
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
        static CACHE: PerCamera<RayTable> = PerCamera::new(TABLE_CACHE);
        CACHE.get_or_build(camera, || RayTable::new(camera))
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
    pub(crate) fn ray_xy(&self, u: f64, v: f64) -> Option<(f64, f64)> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(dist: [f64; 5]) -> Camera {
        let k = Matrix3::new(1200.0, 0.0, 516.0, 0.0, 1190.0, 389.0, 0.0, 0.0, 1.0);
        Camera::new(1032, 778, &k, dist).unwrap()
    }

    #[test]
    fn undistort_inverts_distort() {
        let cam = Camera {
            dist: [-0.2, 0.05, 0.001, -0.002, 0.01],
            ..Default::default()
        };
        for &(x, y) in &[(0.1, -0.2), (0.3, 0.25), (-0.31, 0.0)] {
            let (xd, yd) = cam.distort(x, y);
            let (xu, yu) = cam.undistort(xd, yd, xd, yd).expect("converges");
            assert!((xu - x).abs() < 1e-10 && (yu - y).abs() < 1e-10);
        }
    }

    #[test]
    fn skew_shifts_u_by_skew_times_y() {
        let plain = Camera::default();
        let skewed = Camera { skew: 2.5, ..plain };
        let p = Point::new(30.0, -40.0, 500.0);
        let (a, b) = (plain.project(&p).unwrap(), skewed.project(&p).unwrap());
        assert!((b[0] - a[0] - 2.5 * p.y / p.z).abs() < 1e-12 && a[1] == b[1]);
        let r = skewed.ray(b[0], b[1]).unwrap();
        assert!((r * p.z - p.coords).norm() < 1e-9, "{r}");
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
    fn validate_names_what_is_wrong() {
        assert!(Camera::default().validate().is_ok());
        let e = Camera {
            width: 1,
            ..Default::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("too small"), "{e}");
        let e = Camera {
            fy: 0.0,
            ..Default::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().starts_with("K"), "{e}");
        let e = Camera {
            dist: [f64::NAN, 0.0, 0.0, 0.0, 0.0],
            ..Default::default()
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("NaN"), "{e}");
        assert!(Camera::new(1032, 778, &Matrix3::zeros(), [0.0; 5]).is_err());
        for (width, height) in [(200_000, 200_000), (65_537, 2), (40_000, 40_000), (u32::MAX, u32::MAX)] {
            let e = Camera {
                width,
                height,
                ..Default::default()
            }
            .validate()
            .unwrap_err();
            assert!(e.to_string().contains("ceiling"), "{e}");
        }
        let widest = Camera {
            width: 65_536,
            height: 4096,
            ..Default::default()
        };
        assert!(widest.validate().is_ok());
    }
}
