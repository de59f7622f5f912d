//! Laser-line triangulation (paper section 3.1, Eq. 10–14, generalised): undistorted camera
//! rays from the one camera model ([`Camera`], `geometry/camera.rs`, which the simulator's
//! renderer uses too), the laser plane from the projector pose and the motor angle, ray–plane
//! intersection, and the points carried to the robot's base frame.
//!
//! Frames: camera x right, y down, z forward. The light sheet is the plane `x_L = 0` of the
//! laser frame; the motor turns the projector about its own y axis, so
//! `T_camera_laser(θ) = T_camera_laser0 · Rot_y(θ)` and, with `T_camera_laser0 = I`, the plane
//! normal in the camera frame is `(cos θ, 0, −sin θ)` (Eq. 11).
//!
//! Speed: [`triangulate`] undistorts through a [`RayTable`] (rays on a 4-pixel grid, built once
//! per camera and cached) and one Newton step from the interpolated ray, so it agrees with the
//! exact [`Camera::ray`] to far below 1e-4 px at a fraction of the cost.

use crate::geometry::{Camera, Plane, Point, RayTable};
use crate::{Error, Result};
use nalgebra::{Isometry3, Matrix3, Vector3};
use rayon::prelude::*;

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

/// Pixels per work item of the parallel loops.
const CHUNK: usize = 4096;
/// Sine of the smallest angle between a ray and the laser plane that still gives a point.
const PARALLEL_SINE: f64 = 1e-9;

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
    // The fields are public: a camera built without Camera::new is checked (its size sets the ray table).
    camera.validate()?;
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
