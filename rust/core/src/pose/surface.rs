//! The posed model's surface as the judge's checks, the fit and the trust stage read it:
//! point-to-plane residuals against the dense model and their robust σ, even thinning, and the
//! eigen decomposition the constraint analyses share. A leaf: it imports only the model.

use super::model::PoseModel;
use crate::geometry::Point;
pub(super) use crate::geometry::{median, thin};
use nalgebra::Isometry3;

/// Distance of a model-frame point from the tangent plane of its nearest dense model point,
/// when that point lies within `reach`.
pub(super) fn plane_residual(model: &PoseModel, q: &Point, reach: f64) -> Option<f64> {
    let target = model.fine_target();
    let at = [q.x, q.y, q.z];
    // Most points asked about lie on the surface, within the model's sample spacing (no less
    // than the fine surface's) of their nearest sample: a search that narrow finds it (nothing
    // nearer lies outside it) at a fraction of the cost of one out to `reach`, which only the
    // points it misses need.
    let near = model.spacing.min(reach);
    let (j, _) = target.search().nearest_within(&at, near * near).or_else(|| {
        (reach > near)
            .then(|| target.search().nearest_within(&at, reach * reach))
            .flatten()
    })?;
    let n = target.normals().map(|n| n[j]);
    Some(match n {
        Some(n) => n.dot(&(q - target.points()[j])),
        None => (q - target.points()[j]).norm(),
    })
}

/// The point-to-plane residual of each of `points` about the posed model (`None` where no
/// dense model point lies within `reach`).
pub(super) fn plane_residuals(
    points: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    reach: f64,
) -> Vec<Option<f64>> {
    let inv = t_scene_model.inverse();
    points
        .iter()
        .map(|p| plane_residual(model, &(inv * p), reach))
        .collect()
}

/// 1.4826 × the median of the absolute `residuals` (a robust σ), when there are at least `fewest`.
pub(super) fn robust_sigma(residuals: impl Iterator<Item = f64>, fewest: usize) -> Option<f64> {
    median(residuals.map(f64::abs).collect(), fewest).map(|m| 1.4826 * m)
}
