//! Fit quality: whether the scan points a pose claims lie on the posed model at the scanner's
//! own noise, or only within the judge's tolerance.
//!
//! The judge's tolerance (1 mm and more) is wide enough for voxel means on curved faces and for
//! any scanner the pipeline serves, so a pose that lays a part across the tubes of its
//! neighbours, or one leg of an elbow along the other, can pass it with most of its points
//! 0.3–1 mm off the surface. The scan itself says what "on the surface" means: the spread of a
//! point about the chord of its two nearest neighbours on either side (no model involved) is
//! the sensor's noise, and a right pose leaves residuals at that noise. A pose whose residuals
//! are several times the noise is a wrong pose (or a part unlike its CAD model): its confidence
//! falls with the ratio.

use crate::geometry::eigen_ascending;
use crate::geometry::Point;
use crate::pose::model::PoseModel;
use crate::pose::surface::{median, plane_residuals, robust_sigma, thin};
use crate::pose::types::FitQuality;
use crate::search::KdIndex;
use nalgebra::{Isometry3, Matrix3, Vector3};

/// The fewest residuals (and noise samples) for a verdict; with fewer the fit is not judged.
const MIN_SAMPLES: usize = 30;
/// Residuals evaluated per pose, at most (evenly thinned).
const RESIDUAL_POINTS: usize = 1500;
/// Noise samples per pose, at most.
const NOISE_POINTS: usize = 400;
/// The noise tree is built over at most this many of the pose's points: denser sets are
/// thinned, which spaces neighbours further and can only raise the floor (curvature adds to it).
const TREE_POINTS: usize = 8000;
/// Neighbours a point is compared with.
const NEIGHBOURS: usize = 8;
/// Neighbours whose second spread is below this share of their first lie along a line.
const LINEAR_SHARE: f64 = 0.2;
/// The noise floor is at least this share of the judge's tolerance: the finest noise that
/// tolerance is built for (a scanner that smooths its depth hides its noise from the chords).
const FLOOR_SHARE_OF_TOLERANCE: f64 = 0.1;
/// Residuals up to this many times the noise floor cost no confidence: the floor is an estimate,
/// and real parts differ a little from their CAD models (right poses read 0.5–1.4 on the
/// project's simulator and on the reference sample, wrong ones that pass the judge 3–8).
pub(super) const FREE_RATIO: f64 = 2.0;
/// Beyond it, each further this-many noise floors shrinks the confidence e-fold.
const DECAY_RATIO: f64 = 0.5;
/// Residuals beyond this many noise floors (one decay past the free ratio) say the points are not
/// the part, or not a part like its CAD model: the pose is not reported. Right poses read at most
/// 1.54 over the near-symmetric bench's views and piles (78 poses, session 19), a rod read on a
/// pile of tees 3.2.
pub(super) const MAX_RATIO: f64 = FREE_RATIO + DECAY_RATIO;

/// The fit quality of `t_scene_model` from the scene points it claims (`points`), with the
/// judge's tolerance `tol` (mm); `None` when too few points judge it.
pub(super) fn fit_quality(
    points: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    tol: f64,
    scene_noise: f64,
) -> Option<FitQuality> {
    let sigma = residual_sigma(points, model, t_scene_model, tol)?;
    // The chords read noise larger than the points' spacing low; the scan's own noise, read along
    // the sensor's rays ([`crate::scan_noise`]), does not.
    let floor = noise_floor(points)?
        .max(scene_noise)
        .max(FLOOR_SHARE_OF_TOLERANCE * tol);
    let ratio = sigma / floor;
    Some(FitQuality {
        residual_sigma: sigma,
        noise_floor: floor,
        ratio,
        factor: confidence_factor(ratio),
    })
}

impl FitQuality {
    /// Whether the residuals are within [`MAX_RATIO`] noise floors.
    pub fn acceptable(&self) -> bool {
        self.ratio <= MAX_RATIO
    }
}

/// 1 up to [`FREE_RATIO`], then an exponential fall.
pub(super) fn confidence_factor(ratio: f64) -> f64 {
    (-((ratio - FREE_RATIO).max(0.0) / DECAY_RATIO)).exp()
}

/// The robust σ of the residuals of `points` within `tol` of the posed model, on at most
/// [`RESIDUAL_POINTS`] of them.
pub(super) fn residual_sigma(
    points: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    tol: f64,
) -> Option<f64> {
    thinned_sigma(&plane_residuals(
        &thin(points, RESIDUAL_POINTS),
        model,
        t_scene_model,
        tol,
    ))
}

/// [`residual_sigma`] from the residuals of all the points (as [`plane_residuals`] gives them),
/// thinned as it thins the points.
pub(super) fn thinned_sigma(residuals: &[Option<f64>]) -> Option<f64> {
    let stride = residuals.len().div_ceil(RESIDUAL_POINTS).max(1);
    robust_sigma(residuals.iter().step_by(stride).flatten().copied(), MIN_SAMPLES)
}

/// The sensor's noise among `points` (mm), from no model. Each sampled point is compared with
/// its nearest neighbours. Where they lie along a line (a laser line's own samples, much closer
/// than the lines are to each other), the distance of the point from the chord through its
/// nearest neighbour and the nearest one on the other side; where they spread over a surface (an
/// area scan, or lines as close as their samples), its distance from the plane fitted through
/// them. On a smooth surface sampled finely that distance is noise (plus a curvature term of
/// spacing² / radius, which only raises the floor); with the noise along the viewing ray, as a
/// triangulating scanner has it, its median is 0.6745·√1.5 σ on a chord and 0.6745·√(1 + 1/k) σ
/// off a plane through k neighbours. Noise as large as the spacing tilts the chords and reads up
/// to a third low.
pub(super) fn noise_floor(points: &[Point]) -> Option<f64> {
    if points.len() < MIN_SAMPLES {
        return None;
    }
    let tree_points = thin(points, TREE_POINTS);
    let index = KdIndex::new(&tree_points);
    let mut found = Vec::with_capacity(NEIGHBOURS + 1);
    let mut sigmas = Vec::with_capacity(NOISE_POINTS);
    for p in &thin(&tree_points, NOISE_POINTS) {
        found.clear();
        index.knn_into(p, NEIGHBOURS + 1, &mut found);
        found.sort_by(|x, y| x.0.total_cmp(&y.0));
        let near: Vec<Point> = found
            .iter()
            .map(|&(_, i)| tree_points[i as usize])
            .filter(|q| (q - p).norm_squared() > 1e-18)
            .collect();
        if near.len() < 3 {
            continue;
        }
        let k = near.len() as f64;
        let mean = near.iter().fold(Vector3::zeros(), |s, q| s + q.coords) / k;
        let cov = near.iter().fold(Matrix3::zeros(), |s, q| {
            let d = q.coords - mean;
            s + d * d.transpose()
        });
        let (values, vectors) = eigen_ascending(cov);
        let (mid, max) = (values[1], values[2]);
        if !(max > 0.0) {
            continue;
        }
        if mid < LINEAR_SHARE * max {
            let a = near[0];
            let Some(b) = near.iter().find(|q| (*q - p).dot(&(a - p)) < 0.0) else {
                continue;
            };
            let chord = b - a;
            let len2 = chord.norm_squared();
            if len2 <= 1e-18 {
                continue;
            }
            let s = (p - a).dot(&chord) / len2;
            sigmas.push((p - (a + chord * s)).norm() / (0.6745 * 1.5f64.sqrt()));
        } else {
            let d = (p.coords - mean).dot(&vectors[0]).abs();
            sigmas.push(d / (0.6745 * (1.0 + 1.0 / k).sqrt()));
        }
    }
    median(sigmas, MIN_SAMPLES)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A cylinder's surface sampled as a laser scanner does (lines `line_gap` apart along the
    /// axis, points `step` apart along each line), with noise of σ `sigma` along z.
    fn scanned_cylinder(radius: f64, line_gap: f64, step: f64, sigma: f64, seed: u64) -> Vec<Point> {
        let mut rng = Rng::new(seed);
        let mut out = Vec::new();
        let mut x = -20.0;
        while x <= 20.0 {
            let mut y = -0.8 * radius;
            while y <= 0.8 * radius {
                let z = (radius * radius - y * y).sqrt() + sigma * rng.normal();
                out.push(Point::new(x, y, z));
                y += step;
            }
            x += line_gap;
        }
        out
    }

    #[test]
    fn the_noise_floor_reads_the_scanners_noise_without_a_model() {
        // Noise up to half the point spacing: read within 20 % (plus the curvature term).
        for &sigma in &[0.03, 0.1, 0.2] {
            let pts = scanned_cylinder(12.0, 2.0, 0.4, sigma, 7);
            let floor = noise_floor(&pts).unwrap();
            assert!(
                floor > 0.8 * sigma && floor < 1.2 * sigma + 0.02,
                "σ {sigma}: floor {floor:.3}"
            );
        }
        // Noise as large as the spacing tilts the chords and reads low, but a right pose's
        // residuals (σ) stay inside the ratio that costs no confidence.
        let floor = noise_floor(&scanned_cylinder(12.0, 2.0, 0.4, 0.4, 7)).unwrap();
        assert!(0.4 / floor < 0.8 * FREE_RATIO, "σ 0.4: floor {floor:.3}");
    }

    #[test]
    fn the_noise_floor_of_an_area_scan_reads_its_noise_too() {
        // A plane sampled on a jittered 0.8 mm grid (an area scan), noise along its normal.
        for &sigma in &[0.05, 0.1, 0.3] {
            let mut rng = Rng::new(1);
            let mut pts = Vec::new();
            for i in 0..60 {
                for j in 0..60 {
                    let (x, y) = (0.8 * (i as f64 + rng.uniform()), 0.8 * (j as f64 + rng.uniform()));
                    pts.push(Point::new(x, y, 0.3 * x + sigma * rng.normal()));
                }
            }
            let floor = noise_floor(&pts).unwrap();
            assert!(
                floor > 0.8 * sigma && floor < 1.25 * sigma,
                "σ {sigma}: floor {floor:.3}"
            );
        }
    }

    #[test]
    fn the_factor_spares_residuals_near_the_noise_and_falls_beyond() {
        assert_eq!(confidence_factor(1.0), 1.0);
        assert_eq!(confidence_factor(FREE_RATIO), 1.0);
        assert!(confidence_factor(2.5) < 0.4 && confidence_factor(2.5) > 0.3);
        assert!(confidence_factor(3.0) < 0.15);
    }

    #[test]
    fn too_few_points_give_no_verdict() {
        let pts = scanned_cylinder(12.0, 10.0, 5.0, 0.1, 1);
        assert!(pts.len() < MIN_SAMPLES);
        assert!(noise_floor(&pts).is_none());
    }
}
