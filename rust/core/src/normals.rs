//! Surface normals from k-nearest-neighbour PCA, oriented toward a viewpoint.

use crate::error::{Error, Result};
use crate::geometry::{check_count, check_finite, covariance_of, extreme_axis, principal_axes, Point};
use crate::search::KdIndex;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Where normals should face.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Orientation {
    /// Toward a point, e.g. the camera centre of the scan (mm).
    TowardPoint(Point),
    /// Along a direction, e.g. `+z` for a scene seen from above.
    TowardDirection(Vector3<f64>),
}

/// The most neighbours [`estimate_normals`] fits a plane to: the work grows with `k` per point
/// and a local plane needs far fewer.
pub const MAX_NORMALS_K: usize = 256;

/// Estimates a unit normal per point from the PCA of its `k` nearest neighbours (itself included),
/// flipped to face `orientation`. `index` must be built over `points`.
pub fn estimate_normals(
    points: &[Point],
    index: &KdIndex,
    k: usize,
    orientation: Orientation,
) -> Result<Vec<Vector3<f64>>> {
    if k < 3 {
        return Err(Error::invalid(
            "k",
            format!("must be at least 3 to fit a plane, got {k}"),
        ));
    }
    if k > MAX_NORMALS_K {
        return Err(Error::invalid(
            "k",
            format!("{k} neighbours is over the ceiling of {MAX_NORMALS_K}; 10 to 50 fit a plane well"),
        ));
    }
    check_finite("points", points)?;
    check_count("points", points, 3, "normals need at least 3 points")?;
    // More neighbours than points is the whole cloud.
    let k = k.min(points.len());
    if let Orientation::TowardDirection(d) = orientation {
        if !(d.norm() > 0.0) || d.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid(
                "orientation",
                "the direction must be finite and non-zero",
            ));
        }
    }
    let normals = normals_at(points, points, index, k, orientation);
    crate::cancel::check()?;
    Ok(normals)
}

/// Unit normals at `queries` from the PCA of their `k` nearest points of `cloud` (`index` built
/// over `cloud`), flipped to face `orientation`. Inputs are not checked (see [`estimate_normals`]).
pub fn normals_at(
    queries: &[Point],
    cloud: &[Point],
    index: &KdIndex,
    k: usize,
    orientation: Orientation,
) -> Vec<Vector3<f64>> {
    surfaces_at(queries, cloud, index, k, orientation)
        .into_iter()
        .map(|(_, n)| n)
        .collect()
}

/// The unit normal at `p` from the PCA of its `k` nearest points of `cloud` (`index` built over
/// `cloud`), flipped to face `orientation`; `found` is a reused buffer. One query of
/// [`normals_at`], for callers that need the normals of only some points, as they come.
pub fn normal_at(
    p: &Point,
    cloud: &[Point],
    index: &KdIndex,
    k: usize,
    orientation: Orientation,
    found: &mut Vec<(f64, u32)>,
) -> Vector3<f64> {
    surface_at(p, cloud, index, k, orientation, found).1
}

/// `p` moved onto the plane fitted to its `k` nearest points of `cloud` (through their centroid),
/// and that plane's unit normal facing `orientation`, for each of `queries`: on a noisy scan the
/// points of a smooth surface with their noise averaged over the neighbourhood.
pub fn surfaces_at(
    queries: &[Point],
    cloud: &[Point],
    index: &KdIndex,
    k: usize,
    orientation: Orientation,
) -> Vec<(Point, Vector3<f64>)> {
    let cancel = crate::cancel::current();
    queries
        .par_iter()
        .map_init(Vec::new, |found, p| {
            if cancel.requested() {
                return (*p, Vector3::z());
            }
            surface_at(p, cloud, index, k, orientation, found)
        })
        .collect()
}

/// One query of [`surfaces_at`].
fn surface_at(
    p: &Point,
    cloud: &[Point],
    index: &KdIndex,
    k: usize,
    orientation: Orientation,
    found: &mut Vec<(f64, u32)>,
) -> (Point, Vector3<f64>) {
    index.knn_into(p, k, found);
    let (c, cov) = covariance_of(found.iter().map(|f| &cloud[f.1 as usize]));
    let n = extreme_axis(&cov, false).unwrap_or_else(|| principal_axes(&cov).1[2]);
    let on_plane = p - n * n.dot(&(p - c));
    let facing = match orientation {
        Orientation::TowardPoint(v) => v - p,
        Orientation::TowardDirection(d) => d,
    };
    (on_plane, if n.dot(&facing) < 0.0 { -n } else { n })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k_is_capped_at_the_cloud_and_refused_over_the_ceiling() {
        let pts: Vec<Point> = (0..50)
            .map(|i| Point::new((i % 10) as f64, (i / 10) as f64, 0.0))
            .collect();
        let idx = KdIndex::new(&pts);
        let up = Orientation::TowardDirection(Vector3::z());
        let ns = estimate_normals(&pts, &idx, 200, up).unwrap();
        assert!(ns.iter().all(|n| (n - Vector3::z()).norm() < 1e-9));
        for k in [MAX_NORMALS_K + 1, 5000, usize::MAX] {
            let err = estimate_normals(&pts, &idx, k, up).unwrap_err();
            assert!(err.to_string().contains("ceiling"), "{err}");
        }
    }

    #[test]
    fn plane_normals_face_the_viewpoint() {
        let pts: Vec<Point> = (0..400)
            .map(|i| Point::new((i % 20) as f64, (i / 20) as f64, 0.3 * (i % 20) as f64))
            .collect();
        let idx = KdIndex::new(&pts);
        let ns = estimate_normals(&pts, &idx, 10, Orientation::TowardPoint(Point::new(0.0, 0.0, 100.0))).unwrap();
        let expect = Vector3::new(-0.3, 0.0, 1.0).normalize();
        for n in ns {
            assert!((n - expect).norm() < 1e-9, "{n}");
        }
    }
}
