//! The sensor's depth noise read from a scan, without a model of the part.
//!
//! Every 3-D sensor binpick serves (laser-line triangulation, structured light, stereo and
//! Kinect-like depth cameras, time of flight) measures depth along its rays: the noise lies
//! along the direction toward the sensor. Fitted as a height field along that direction, a
//! small patch of the scan is a regression of depth on the two lateral coordinates, whose
//! residuals are the noise itself — unbiased however large the noise is against the spacing of
//! the points, which a plane fitted by PCA is not (it tilts toward the noise). The patch is a
//! quadric (curvature does not count as noise) or, where the neighbours lie along one line (a
//! laser line's own samples, much closer than the lines), a parabola along that line.
//!
//! Neighbours are chosen by their lateral distance, with depth counting a fraction `1/λ` as
//! much: picked in full 3-D, points whose noise happens to lie near the sample's would be
//! preferred and noise larger than the points' spacing read low; picked laterally alone, a patch
//! at an occluding edge would mix the near and far surfaces. A first pass picks plain 3-D
//! neighbours; where the noise it reads is large against the spacing, a second pass weighs depth
//! less. The scan's noise is the median over patches (edges, flying pixels and corners are a
//! minority).

use crate::geometry::{median, perpendicular_basis, thin, Point};
use crate::normals::Orientation;
use crate::search::KdIndex;
use nalgebra::{Matrix2, SMatrix, SVector, Vector3};

/// Points the estimate is read from, at most (the scan is evenly thinned).
const MAX_POINTS: usize = 20_000;
/// Patches fitted, at most.
const PATCHES: usize = 600;
/// Neighbours of a patch (its sample included).
const NEIGHBOURS: usize = 24;
/// The fewest fitted patches for an estimate.
const MIN_PATCHES: usize = 20;
/// Residual degrees of freedom a patch needs beyond its parameters.
const MIN_DOF: usize = 8;
/// Neighbours whose lateral spread across is below this share of the spread along lie on a line.
const LINEAR_SHARE: f64 = 0.04;
/// Patches steeper than this slope (45°) are not fitted: a height field that steep is ill
/// conditioned, and it is mostly where surfaces meet.
const MAX_SLOPE: f64 = 1.0;
/// λ of the first pass (plain 3-D neighbours: a closed surface, or a cloud merged from many
/// views, keeps its far side out of a patch), and the noise-to-spacing factor of the second.
const FIRST_LAMBDA: f64 = 1.0;
const LAMBDA_PER_NOISE: f64 = 8.0;

/// The standard deviation (mm) of the depth noise of `points` along the direction toward the
/// sensor, read from the scan alone; `None` with too few points (under `4 × MIN_PATCHES`) or
/// fitted patches (under `MIN_PATCHES`: a scan with no surface within 45° of facing the sensor).
pub fn scan_noise(points: &[Point], toward: Orientation) -> Option<f64> {
    let pts = thin(points, MAX_POINTS);
    if pts.len() < MIN_PATCHES * 4 {
        return None;
    }
    let centre = pts.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / pts.len() as f64;
    let w = match toward {
        Orientation::TowardDirection(d) => d,
        Orientation::TowardPoint(c) => c.coords - centre,
    };
    if !(w.norm() > 0.0) || !w.iter().all(|v| v.is_finite()) {
        return None;
    }
    let frame = Frame::new(w.normalize());
    let (first, spacing) = pass(&pts, &frame, toward, FIRST_LAMBDA)?;
    let lambda = LAMBDA_PER_NOISE * first / spacing.max(1e-9);
    if lambda <= 1.5 * FIRST_LAMBDA {
        return Some(first);
    }
    pass(&pts, &frame, toward, lambda).map(|(sigma, _)| sigma)
}

/// An orthonormal frame whose third axis is `w`.
struct Frame {
    e1: Vector3<f64>,
    e2: Vector3<f64>,
    w: Vector3<f64>,
}

impl Frame {
    fn new(w: Vector3<f64>) -> Self {
        let (e1, e2) = perpendicular_basis(&w);
        Frame { e1, e2, w }
    }
}

/// One pass at depth weight `1/lambda`: the median patch noise and the median lateral distance
/// of a sample to its nearest neighbour.
fn pass(pts: &[Point], frame: &Frame, toward: Orientation, lambda: f64) -> Option<(f64, f64)> {
    let squeezed: Vec<Point> = pts
        .iter()
        .map(|p| {
            Point::new(
                p.coords.dot(&frame.e1),
                p.coords.dot(&frame.e2),
                p.coords.dot(&frame.w) / lambda,
            )
        })
        .collect();
    let index = KdIndex::new(&squeezed);
    let stride = pts.len().div_ceil(PATCHES).max(1);
    let mut sigmas = Vec::with_capacity(PATCHES);
    let mut spacings = Vec::with_capacity(PATCHES);
    let mut found = Vec::with_capacity(NEIGHBOURS);
    for i in (0..pts.len()).step_by(stride) {
        found.clear();
        index.knn_into(&squeezed[i], NEIGHBOURS, &mut found);
        let w = match toward {
            Orientation::TowardDirection(_) => frame.w,
            Orientation::TowardPoint(c) => match (c - pts[i]).try_normalize(1e-12) {
                Some(w) => w,
                None => continue,
            },
        };
        let local = Frame::new(w);
        let patch: Vec<[f64; 3]> = found
            .iter()
            .map(|&(_, j)| {
                let d = pts[j as usize] - pts[i];
                [d.dot(&local.e1), d.dot(&local.e2), d.dot(&local.w)]
            })
            .collect();
        if let Some(s) = patch
            .iter()
            .map(|q| q[0] * q[0] + q[1] * q[1])
            .filter(|&d| d > 1e-18)
            .min_by(f64::total_cmp)
        {
            spacings.push(s.sqrt());
        }
        if let Some(sigma) = patch_noise(&patch) {
            sigmas.push(sigma);
        }
    }
    if sigmas.len() < MIN_PATCHES {
        return None;
    }
    Some((median(sigmas, 1)?, median(spacings, 1)?))
}

/// The residual standard deviation of a height field fitted to `patch` (lateral `a`, `b` and
/// depth `h` about the sample): a quadric, or a parabola along the line the patch lies on.
fn patch_noise(patch: &[[f64; 3]]) -> Option<f64> {
    let n = patch.len();
    let (mut saa, mut sab, mut sbb) = (0.0, 0.0, 0.0);
    let (ma, mb) = (
        patch.iter().map(|q| q[0]).sum::<f64>() / n as f64,
        patch.iter().map(|q| q[1]).sum::<f64>() / n as f64,
    );
    for q in patch {
        let (a, b) = (q[0] - ma, q[1] - mb);
        saa += a * a;
        sab += a * b;
        sbb += b * b;
    }
    let eig = Matrix2::new(saa, sab, sab, sbb).symmetric_eigen();
    let (lo, hi) = if eig.eigenvalues[0] < eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    if !(eig.eigenvalues[hi] > 0.0) {
        return None;
    }
    if eig.eigenvalues[lo] < LINEAR_SHARE * eig.eigenvalues[hi] {
        let dir = eig.eigenvectors.column(hi);
        let rows = patch.iter().map(|q| {
            let t = q[0] * dir[0] + q[1] * dir[1];
            (SVector::<f64, 3>::new(1.0, t, t * t), q[2])
        });
        fit(rows, n).filter(|(_, c)| c[1].abs() <= MAX_SLOPE).map(|(s, _)| s)
    } else {
        let rows = patch.iter().map(|q| {
            (
                SVector::<f64, 6>::new(1.0, q[0], q[1], q[0] * q[0], q[0] * q[1], q[1] * q[1]),
                q[2],
            )
        });
        fit(rows, n)
            .filter(|(_, c)| c[1].hypot(c[2]) <= MAX_SLOPE)
            .map(|(s, _)| s)
    }
}

/// Least squares of `h` on the rows' regressors: the residual standard deviation and the
/// coefficients, when the `n` rows leave [`MIN_DOF`] degrees of freedom and the fit is determined.
fn fit<const K: usize>(
    rows: impl Iterator<Item = (SVector<f64, K>, f64)> + Clone,
    n: usize,
) -> Option<(f64, SVector<f64, K>)> {
    if n < K + MIN_DOF {
        return None;
    }
    let mut ata = SMatrix::<f64, K, K>::zeros();
    let mut atb = SVector::<f64, K>::zeros();
    for (x, h) in rows.clone() {
        ata += x * x.transpose();
        atb += x * h;
    }
    let coef = ata.cholesky()?.solve(&atb);
    let rss: f64 = rows.map(|(x, h)| (h - x.dot(&coef)).powi(2)).sum();
    let sigma = (rss / (n - K) as f64).sqrt();
    sigma.is_finite().then_some((sigma, coef))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A bumpy surface z = f(x, y) over `size` mm, sampled on a jittered grid `step` apart (an
    /// area scan) or in lines `line_gap` apart with samples `step` apart along them (a laser
    /// scan), with noise of σ `sigma` along +z.
    fn scanned(size: f64, step: f64, line_gap: Option<f64>, sigma: f64, seed: u64) -> Vec<Point> {
        let mut rng = Rng::new(seed);
        let f = |x: f64, y: f64| 8.0 * (x / 23.0).sin() * (y / 31.0).cos() + 0.2 * x;
        let mut out = Vec::new();
        let gap = line_gap.unwrap_or(step);
        let mut y = 0.0;
        while y < size {
            let mut x = 0.0;
            while x < size {
                let (px, py) = match line_gap {
                    Some(_) => (x, y),
                    None => (x + step * (rng.uniform() - 0.5), y + step * (rng.uniform() - 0.5)),
                };
                out.push(Point::new(px, py, f(px, py) + sigma * rng.normal()));
                x += step;
            }
            y += gap;
        }
        out
    }

    #[test]
    fn an_area_scans_noise_is_read_however_large_against_its_spacing() {
        // Spacing 0.5 mm; noise from a tenth of it to ten times it.
        for &sigma in &[0.05, 0.3, 1.0, 3.0, 5.0] {
            let pts = scanned(120.0, 0.5, None, sigma, 3);
            let read = scan_noise(&pts, Orientation::TowardDirection(Vector3::z())).unwrap();
            assert!((read / sigma - 1.0).abs() < 0.12, "σ {sigma}: read {read:.3}");
        }
    }

    #[test]
    fn a_laser_scans_noise_is_read_along_its_lines() {
        for &sigma in &[0.03, 0.15, 0.6] {
            let pts = scanned(150.0, 0.4, Some(6.0), sigma, 5);
            let read = scan_noise(&pts, Orientation::TowardDirection(Vector3::z())).unwrap();
            assert!((read / sigma - 1.0).abs() < 0.15, "σ {sigma}: read {read:.3}");
        }
    }

    #[test]
    fn noise_along_the_rays_of_a_sensor_at_a_point_is_read_along_them() {
        // The bumpy surface seen from a sensor 600 mm above and 300 mm aside; each point moved
        // along its ray by the noise.
        let eye = Point::new(-300.0, 60.0, 600.0);
        let sigma = 1.5;
        let mut rng = Rng::new(11);
        let pts: Vec<Point> = scanned(120.0, 0.8, None, 0.0, 2)
            .into_iter()
            .map(|p| {
                let ray = (p - eye).normalize();
                p + ray * (sigma * rng.normal())
            })
            .collect();
        let read = scan_noise(&pts, Orientation::TowardPoint(eye)).unwrap();
        assert!((read / sigma - 1.0).abs() < 0.15, "read {read:.3}");
    }

    #[test]
    fn a_closed_surface_sampled_all_round_reads_no_noise() {
        // A sphere 40 mm across sampled evenly all round (a model, or a cloud merged from many
        // views): each lateral place holds two surfaces, which a patch must not mix.
        let mut rng = Rng::new(2);
        let pts: Vec<Point> = (0..4000)
            .map(|_| {
                let v = Vector3::new(rng.normal(), rng.normal(), rng.normal()).normalize();
                Point::from(v * 20.0)
            })
            .collect();
        let read = scan_noise(&pts, Orientation::TowardDirection(Vector3::z())).unwrap();
        assert!(read < 0.05, "read {read:.3}");
    }

    #[test]
    fn too_few_points_or_no_direction_give_no_estimate() {
        let pts = scanned(7.0, 1.0, None, 0.1, 1);
        assert!(scan_noise(&pts, Orientation::TowardDirection(Vector3::z())).is_none());
        let pts = scanned(60.0, 0.5, None, 0.1, 1);
        assert!(scan_noise(&pts, Orientation::TowardDirection(Vector3::zeros())).is_none());
        assert!(scan_noise(&pts, Orientation::TowardDirection(Vector3::new(f64::NAN, 0.0, 1.0))).is_none());
    }
}
