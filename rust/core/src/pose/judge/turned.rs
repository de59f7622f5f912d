//! A pose the judge refuses for lying through the bin, turned about the axis its points leave
//! open. When the points a pose claims constrain its turn about one axis far less than about the
//! others (a tee standing on its run's end shows its run alone, a cylinder), every turn about
//! that axis fits them as well, and the scan cannot say where the rest of the part is. A reading
//! that swings the hidden rest through a wall is then refused though a turn of it is the truth:
//! each probed turn is refined on the claimed points and judged, and the one the judge passes that
//! explains the points as well is the pose. The trust stage weighs the turns that remain open
//! ([`crate::pose::trust`]'s unseen turns, which share the weak axis and the probed turns).

use super::Judge;
use crate::geometry::Point;
use crate::pose::model::{Constraints, PoseModel};
use crate::pose::surface::{plane_residuals, thin};
use crate::registration::verify::Evidence;
use crate::registration::{icp, Convergence, IcpConfig};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// The turn about the weakest axis is probed when the claimed points constrain it less than this
/// share of the next weakest: the seen surface is then nearly a surface of revolution about it.
pub(crate) const WEAK_SHARE: f64 = 0.3;
/// The turns probed, degrees (both ways, and the half turn).
pub(crate) const TURNS_DEG: [f64; 11] = [
    30.0, 60.0, 90.0, 120.0, 150.0, 180.0, -30.0, -60.0, -90.0, -120.0, -150.0,
];
/// Claimed points each turn is refined on, at most.
pub(crate) const REFINE_POINTS: usize = 300;
/// A turn explains the claimed points as well when it loses at most this many of them from the
/// judge's tolerance — twice the 15 points at which a feature counts as in view, as the trust
/// stage's margin — …
pub(crate) const MIN_MARGIN: f64 = 30.0;
/// … or this share of them, when more.
pub(crate) const MARGIN_SHARE: f64 = 0.02;

/// The turn by `angle` (radians) about the axis `axis` through `x`, model frame.
pub(crate) fn turn_about(axis: &Unit<Vector3<f64>>, x: &Point, angle: f64) -> Isometry3<f64> {
    Translation3::from(x.coords) * UnitQuaternion::from_axis_angle(axis, angle) * Translation3::from(-x.coords)
}

/// The weakest rotation axis of the point-to-plane constraints of `q` (model-frame points with
/// their model normals) and a point on it, model frame, when it is weak (see [`WEAK_SHARE`]).
pub(crate) fn weak_axis(q: &[(Point, Vector3<f64>)]) -> Option<(Unit<Vector3<f64>>, Point)> {
    let c = Constraints::of(q);
    let (values, vectors) = c.turns()?;
    let (w0, w1) = (values[0], values[1]);
    if !(w1 > 0.0) || w0 > WEAK_SHARE * w1 {
        return None;
    }
    Some((Unit::new_normalize(vectors[0]), c.axis_point(&vectors[0])?))
}

/// Claimed points within `reach` of the posed model, with its normals, model frame.
pub(crate) fn on_model(
    claimed: &[Point],
    model: &PoseModel,
    t: &Isometry3<f64>,
    reach: f64,
) -> Vec<(Point, Vector3<f64>)> {
    let target = model.fine_target();
    let Some(normals) = target.normals() else {
        return Vec::new();
    };
    let inv = t.inverse();
    claimed
        .iter()
        .filter_map(|p| {
            let q = inv * p;
            let (j, _) = target.search().nearest_within(&[q.x, q.y, q.z], reach * reach)?;
            Some((q, normals[j]))
        })
        .collect()
}

/// How many of `claimed` lie within `tol` of the model posed by `t`.
fn kept(claimed: &[Point], model: &PoseModel, t: &Isometry3<f64>, tol: f64) -> usize {
    plane_residuals(claimed, model, t, tol)
        .into_iter()
        .flatten()
        .filter(|r| r.abs() <= tol)
        .count()
}

impl Judge {
    /// The pose `t_scene_model`, refused for lying through the bin or a support, turned about
    /// the weak axis of the points it claims (`claimed`) by each of [`TURNS_DEG`] and refined on
    /// them: of the turns this judge passes that keep the claimed points within its tolerance
    /// as well (within [`MIN_MARGIN`]), the one that keeps most, with its evidence; None when no
    /// axis is weak or no turn passes.
    pub fn turned_clear(
        &self,
        claimed: &[Point],
        model: &PoseModel,
        t_scene_model: &Isometry3<f64>,
    ) -> Option<(Isometry3<f64>, Evidence)> {
        let tol = self.depth.tol;
        let sample = thin(claimed, REFINE_POINTS);
        let q = on_model(&sample, model, t_scene_model, tol);
        if q.len() < 30 {
            return None;
        }
        let (axis, x) = weak_axis(&q)?;
        let kept0 = kept(claimed, model, t_scene_model, tol) as f64;
        let least = kept0 - MIN_MARGIN.max(MARGIN_SHARE * kept0);
        let refine = IcpConfig::robust_plane(3.0 * tol, Convergence::UNSEEN_TURN);
        TURNS_DEG
            .iter()
            .filter_map(|deg| {
                let start = t_scene_model * turn_about(&axis, &x, deg.to_radians()).inverse();
                let r = icp(&sample, model.fine_target(), &start.inverse(), &refine).ok()?;
                let (t, e) = self.verdict(model, &r.t_target_source.inverse()).ok()?;
                let k = kept(claimed, model, &t, tol);
                (k as f64 >= least).then_some((k, t, e))
            })
            .max_by_key(|c| c.0)
            .map(|(_, t, e)| (t, e))
    }
}
