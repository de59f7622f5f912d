//! Scene clean-up and top-object segmentation (paper §3.3, Table 2).
//!
//! Bin removal keeps the points inside a given bin box above its floor and away from its walls,
//! or, with no box, finds support planes by RANSAC and removes those that are much larger than
//! the part (a part's own flat faces are never that large). Segmentation grows a region from
//! the highest point through neighbours closer than d*, as Table 2 does, with two additions
//! that keep touching parts apart: neighbours must have similar normals, and the region may not
//! reach farther from its seed than the part's diameter.

use crate::error::{Error, Result};
use crate::geometry::{covariance, extreme_axis, principal_axes, BinBox, Plane, Point};
use crate::rng::Rng;
use crate::search::KdIndex;
use nalgebra::Vector3;
use std::collections::VecDeque;

/// Median distance from a sample of points to their nearest other point (0 for < 2 points).
pub fn point_spacing(points: &[Point], index: &KdIndex) -> f64 {
    if points.len() < 2 {
        return 0.0;
    }
    let step = (points.len() / 512).max(1);
    let mut d: Vec<f64> = (0..points.len())
        .step_by(step)
        .filter_map(|i| index.nearest_other(i).map(|n| n.distance_squared.sqrt()))
        .filter(|d| *d > 0.0)
        .collect();
    if d.is_empty() {
        return 0.0;
    }
    let mid = d.len() / 2;
    *d.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
}

/// Sampling of a scan, which is often anisotropic: a laser-line scan is dense along each line
/// and sparse across lines.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanSpacing {
    /// Median distance to the nearest other point, mm (along a scan line).
    pub along: f64,
    /// Median distance to the nearest point off the local line direction, mm (across lines);
    /// equals `along` for an even sampling.
    pub across: f64,
}

/// Measures [`ScanSpacing`] on a sample of about 96 points from their 32 nearest neighbours.
pub fn scan_spacing(points: &[Point], index: &KdIndex) -> ScanSpacing {
    let along = point_spacing(points, index);
    if points.len() < 8 {
        return ScanSpacing { along, across: along };
    }
    let step = points.len().div_ceil(96);
    let mut across: Vec<f64> = (0..points.len())
        .step_by(step)
        .filter_map(|i| {
            let nb = index.knn(&points[i], 32);
            // The local line direction from the nearest few; "across" is the nearest neighbour
            // off it (for an even sampling that is close to the nearest neighbour anyway).
            let local: Vec<Point> = nb.iter().take(6).map(|n| points[n.index]).collect();
            let (_, cov) = covariance(&local);
            let line = extreme_axis(&cov, true).unwrap_or_else(|| principal_axes(&cov).1[0]);
            nb.iter()
                .skip(1)
                .map(|n| points[n.index] - points[i])
                .filter(|d| d.dot(&line).abs() < 0.5 * d.norm())
                .map(|d| d.norm())
                .fold(None, |m: Option<f64>, d| Some(m.map_or(d, |m| m.min(d))))
                .or_else(|| nb.last().map(|n| n.distance_squared.sqrt()))
        })
        .filter(|d| *d > 0.0)
        .collect();
    if across.is_empty() {
        return ScanSpacing { along, across: along };
    }
    let mid = across.len() / 2;
    let a = *across.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1;
    ScanSpacing {
        along,
        across: a.max(along),
    }
}

/// Indices of the points inside `bin`, at least `margin` mm above its floor and inside its walls.
/// The bin is open at the top: parts of a full pile stick out above its rim, so nothing is cut
/// above `max.z`.
pub fn crop_to_bin(points: &[Point], bin: &BinBox, margin: f64) -> Result<Vec<usize>> {
    if (0..3).any(|k| !(bin.max[k] > bin.min[k])) {
        return Err(Error::invalid(
            "bin",
            format!(
                "the box must have max > min on every axis, got min {:?} max {:?}",
                bin.min.coords.as_slice(),
                bin.max.coords.as_slice()
            ),
        ));
    }
    Ok(points
        .iter()
        .enumerate()
        .filter(|(_, p)| {
            p.x > bin.min.x + margin
                && p.x < bin.max.x - margin
                && p.y > bin.min.y + margin
                && p.y < bin.max.y - margin
                && p.z > bin.min.z + margin
        })
        .map(|(i, _)| i)
        .collect())
}

/// Whether the scene is wide enough to hold a support plane as [`remove_support_planes`] judges
/// one (inliers spanning more than 1.2 × the part): no plane spans more than the whole scene.
pub fn could_hold_support_plane(points: &[Point], model_diameter: f64) -> bool {
    let Some(first) = points.first() else { return false };
    let (lo, hi) = points
        .iter()
        .fold((*first, *first), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    (hi - lo).norm() >= 1.2 * model_diameter
}

/// Removes support planes (floor, walls, rims) found by RANSAC, largest first: a plane is
/// removed only when its inliers span more than `1.2 × model_diameter`, which no face of the
/// part can, so that the flat faces of parts stay. Returns the kept indices and the removed planes.
pub fn remove_support_planes(
    points: &[Point],
    model_diameter: f64,
    tolerance: f64,
    seed: u64,
) -> (Vec<usize>, Vec<Plane>) {
    let mut keep: Vec<usize> = (0..points.len()).collect();
    let mut planes = Vec::new();
    if !could_hold_support_plane(points, model_diameter) {
        return (keep, planes);
    }
    let mut rng = Rng::new(seed);
    for _ in 0..10 {
        if keep.len() < 50 {
            break;
        }
        let Some((plane, inliers)) = ransac_plane(points, &keep, tolerance, 300, &mut rng) else {
            break;
        };
        let pts: Vec<Point> = inliers.iter().map(|&i| points[i]).collect();
        let (_, cov) = covariance(&pts);
        let (_, axes) = principal_axes(&cov);
        let span = |axis: &Vector3<f64>| {
            let proj: Vec<f64> = pts.iter().map(|p| p.coords.dot(axis)).collect();
            // Robust span: 2nd to 98th percentile, so stray inliers on parts do not count.
            let mut s = proj.clone();
            s.sort_by(|a, b| a.total_cmp(b));
            s[(s.len() * 98) / 100] - s[(s.len() * 2) / 100]
        };
        if span(&axes[0]) < 1.2 * model_diameter {
            break;
        }
        let removed: std::collections::HashSet<usize> = inliers.into_iter().collect();
        keep.retain(|i| !removed.contains(i));
        planes.push(plane);
    }
    (keep, planes)
}

fn ransac_plane(
    points: &[Point],
    subset: &[usize],
    tol: f64,
    trials: usize,
    rng: &mut Rng,
) -> Option<(Plane, Vec<usize>)> {
    // Distances are taken from a point of the scene, not the origin: far from the origin
    // (1e12 mm and more) `n · p` alone has no digits left for a tolerance of a millimetre.
    let o = points[*subset.first()?].coords;
    let dist = |n: &Vector3<f64>, d: f64, p: &Point| (n.dot(&(p.coords - o)) - d).abs();
    let mut best: Option<(Vector3<f64>, f64, usize)> = None;
    let step = (subset.len() / 4000).max(1);
    for _ in 0..trials {
        let (a, b, c) = (
            points[subset[rng.below(subset.len())]],
            points[subset[rng.below(subset.len())]],
            points[subset[rng.below(subset.len())]],
        );
        let n = (b - a).cross(&(c - a));
        if !(n.norm() >= 1e-9) {
            continue;
        }
        let n = n.normalize();
        let d = n.dot(&(a.coords - o));
        let count = subset
            .iter()
            .step_by(step)
            .filter(|&&i| dist(&n, d, &points[i]) < tol)
            .count();
        if best.as_ref().is_none_or(|b| count > b.2) {
            best = Some((n, d, count));
        }
    }
    let (n, d, _) = best?;
    // Refit on the inliers for an unbiased plane, then collect them.
    let inl: Vec<Point> = subset
        .iter()
        .map(|&i| points[i])
        .filter(|p| dist(&n, d, p) < tol)
        .collect();
    if inl.len() < 3 {
        return None;
    }
    let (c, cov) = covariance(&inl);
    let (_, axes) = principal_axes(&cov);
    let n = axes[2];
    let d = n.dot(&(c.coords - o));
    let inliers: Vec<usize> = subset
        .iter()
        .copied()
        .filter(|&i| dist(&n, d, &points[i]) < tol)
        .collect();
    if inliers.len() < 3 {
        return None;
    }
    let refit = Plane {
        normal: n,
        offset: n.dot(&c.coords),
    };
    Some((refit, inliers))
}

/// Parameters of top-object segmentation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentConfig {
    /// d*: neighbours closer than this (mm) join the region.
    pub d_star: f64,
    /// Regions with fewer points are dropped and the next top point tried.
    pub min_points: usize,
    /// Neighbours join only if their normals differ by less than this (radians); π disables it.
    pub max_normal_angle: f64,
    /// The region may not reach farther than this from its seed (mm); infinity disables it.
    pub max_extent: f64,
    /// The "up" direction of the scene (toward the camera).
    pub up: Vector3<f64>,
}

/// Table 2: the region of the highest point that makes a whole object. Returns indices into
/// `points` (of the first region with at least `min_points`), or `NoObjectFound`. Points marked
/// in `excluded` (regions already tried) are neither seeds nor members. With `normal_of`, a
/// neighbour joins only if its normal (`normal_of(i)`, asked for as the growth reaches point `i`:
/// a caller may compute normals on demand, only for the points the regions reach) is within
/// `max_normal_angle` of its neighbour's.
pub fn segment_top(
    points: &[Point],
    mut normal_of: Option<&mut dyn FnMut(usize) -> Vector3<f64>>,
    index: &KdIndex,
    cfg: &SegmentConfig,
    excluded: Option<&[bool]>,
) -> Result<Vec<usize>> {
    if !(cfg.d_star.is_finite() && cfg.d_star > 0.0) {
        return Err(Error::invalid(
            "d_star",
            format!("must be a positive distance in mm, got {}", cfg.d_star),
        ));
    }
    let cos_limit = cfg.max_normal_angle.cos();
    let up = cfg.up.normalize();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[b].coords.dot(&up).total_cmp(&points[a].coords.dot(&up)));
    let mut label = excluded.map_or_else(|| vec![false; points.len()], |e| e.to_vec());
    if label.len() != points.len() {
        return Err(Error::invalid("excluded", "must mark every point"));
    }
    for &seed in &order {
        if label[seed] {
            continue;
        }
        let mut region = vec![seed];
        let mut queue = VecDeque::from([seed]);
        label[seed] = true;
        while let Some(g) = queue.pop_front() {
            for nb in index.within(&points[g], cfg.d_star) {
                let i = nb.index;
                if label[i] || (points[i] - points[seed]).norm() > cfg.max_extent {
                    continue;
                }
                if let Some(normal) = normal_of.as_deref_mut() {
                    if normal(i).dot(&normal(g)).abs() < cos_limit {
                        continue;
                    }
                }
                label[i] = true;
                region.push(i);
                queue.push_back(i);
            }
        }
        if region.len() >= cfg.min_points {
            return Ok(region);
        }
        // Too few points: noise or a sliver; they stay labelled and the next top point is tried.
    }
    Err(Error::NoObjectFound {
        reason: format!(
            "no region of at least {} points (d* = {:.2} mm) in {} points",
            cfg.min_points,
            cfg.d_star,
            points.len()
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_is_removed_but_a_box_top_is_kept() {
        let mut rng = Rng::new(1);
        let mut pts: Vec<Point> = (0..20000)
            .map(|_| Point::new(rng.range(0.0, 400.0), rng.range(0.0, 300.0), 0.05 * rng.normal()))
            .collect();
        // A 40 mm cube standing on the floor: its flat top must stay.
        let cube_top: Vec<Point> = (0..1600)
            .map(|i| Point::new(100.0 + (i % 40) as f64, 100.0 + (i / 40) as f64, 40.0))
            .collect();
        pts.extend(&cube_top);
        let (keep, planes) = remove_support_planes(&pts, 70.0, 0.5, 3);
        assert_eq!(planes.len(), 1);
        assert!(planes[0].normal.z.abs() > 0.999);
        assert_eq!(keep.len(), 1600);
        assert!(keep.iter().all(|&i| i >= 20000));
    }

    #[test]
    fn a_scene_far_from_the_origin_does_not_panic() {
        let mut rng = Rng::new(2);
        for offset in [1e16, 1e12, -1e16, 1e300] {
            let pts: Vec<Point> = (0..5000)
                .map(|i| {
                    let z = if i % 5 == 0 {
                        30.0 + rng.range(0.0, 10.0)
                    } else {
                        0.05 * rng.normal()
                    };
                    Point::new(
                        offset + rng.range(0.0, 400.0),
                        offset + rng.range(0.0, 300.0),
                        offset + z,
                    )
                })
                .collect();
            let (keep, _) = remove_support_planes(&pts, 70.0, 0.5, 3);
            assert!(keep.len() <= pts.len());
        }
    }

    #[test]
    fn top_region_stops_at_gaps_and_drops_slivers() {
        // Two patches 5 mm apart plus a 3-point sliver above them.
        let mut pts: Vec<Point> = Vec::new();
        for i in 0..400 {
            pts.push(Point::new((i % 20) as f64, (i / 20) as f64, 10.0));
            pts.push(Point::new(25.0 + (i % 20) as f64, (i / 20) as f64, 5.0));
        }
        pts.extend([
            Point::new(60.0, 60.0, 50.0),
            Point::new(60.5, 60.0, 50.0),
            Point::new(61.0, 60.0, 50.0),
        ]);
        let idx = KdIndex::new(&pts);
        let cfg = SegmentConfig {
            d_star: 1.5,
            min_points: 50,
            max_normal_angle: std::f64::consts::PI,
            max_extent: f64::INFINITY,
            up: Vector3::z(),
        };
        let region = segment_top(&pts, None, &idx, &cfg, None).unwrap();
        assert_eq!(region.len(), 400);
        assert!(region.iter().all(|&i| pts[i].z == 10.0));
        let cfg_big = SegmentConfig {
            min_points: 1000,
            ..cfg
        };
        assert!(matches!(
            segment_top(&pts, None, &idx, &cfg_big, None),
            Err(Error::NoObjectFound { .. })
        ));
    }

    #[test]
    fn normals_on_demand_give_the_region_of_every_normal_computed_first_from_few_of_them() {
        use crate::normals::{estimate_normals, normal_at, Orientation};
        // A 40 mm cube's top and one side wall (a crease the normals must stop at), on a wide
        // floor of scan lines: the top region is a small part of the cloud.
        let mut pts: Vec<Point> = Vec::new();
        for i in 0..120 {
            for j in 0..600 {
                pts.push(Point::new(2.0 * i as f64, 0.5 * j as f64, 0.0));
            }
        }
        for i in 0..20 {
            for j in 0..80 {
                pts.push(Point::new(100.0 + 2.0 * i as f64, 100.0 + 0.5 * j as f64, 40.0));
                pts.push(Point::new(140.0, 100.0 + 0.5 * j as f64, 2.0 * i as f64));
            }
        }
        let idx = KdIndex::new(&pts);
        let up = Orientation::TowardDirection(Vector3::z());
        let cfg = SegmentConfig {
            d_star: 2.5,
            min_points: 100,
            max_normal_angle: 0.5,
            max_extent: 120.0,
            up: Vector3::z(),
        };
        let all = estimate_normals(&pts, &idx, 24, up).unwrap();
        let eager = segment_top(&pts, Some(&mut |i: usize| all[i]), &idx, &cfg, None).unwrap();
        let mut memo: Vec<Option<Vector3<f64>>> = vec![None; pts.len()];
        let mut found = Vec::new();
        let mut on_demand =
            |i: usize| *memo[i].get_or_insert_with(|| normal_at(&pts[i], &pts, &idx, 24, up, &mut found));
        let lazy = segment_top(&pts, Some(&mut on_demand), &idx, &cfg, None).unwrap();
        assert_eq!(lazy, eager);
        assert_eq!(eager.len(), 1600, "the cube's top, not its wall or the floor");
        assert!(eager.iter().all(|&i| pts[i].z == 40.0));
        let computed = memo.iter().filter(|n| n.is_some()).count();
        assert!(
            computed < pts.len() / 10,
            "{computed} of {} normals computed",
            pts.len()
        );
    }
}
