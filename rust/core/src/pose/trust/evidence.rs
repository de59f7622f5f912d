//! The evidence the trust stage weighs candidate poses by: which scan points near a pose lie on
//! it within the scan's noise, the probes it puts where the sensor saw free space, and whether
//! the best candidate's lead over another is beyond what chance gives.

use crate::geometry::Point;
use crate::pose::judge::Judge;
use crate::pose::model::PoseModel;
use crate::pose::surface::{plane_residual, plane_residuals, robust_sigma};
use crate::pose::types::{FeatureEvidence, TrustParams};
use crate::symmetry::{NearSymmetry, Symmetries};
use nalgebra::Isometry3;

/// Confidence from the judge alone: how much of the surface the scan can judge confirms the
/// pose (0.6 at the acceptance threshold, 0.99 at 95 % and above).
pub(super) fn base_confidence(coverage: f64, min_coverage: f64) -> f64 {
    let span = (0.95 - min_coverage).max(1e-3);
    0.6 + 0.39 * ((coverage - min_coverage) / span).clamp(0.0, 1.0)
}

/// A refined candidate as the comparison weighs it.
pub(super) struct Scored {
    /// Its feature evidence.
    pub evidence: FeatureEvidence,
    /// Whether the judge accepts it.
    pub judged_ok: bool,
    /// Whether each judged point lies within the fine tolerance of it.
    pub fits: Vec<bool>,
}

/// The margin by which one candidate's feature evidence must lead another's to rule it out (see
/// [`TrustParams::margin_sigmas`]): from the judged points that fit one and not the other and the
/// difference of their probes seen through, `per_probe` scan points apiece. The d split points
/// spread the lead by 2√d points; a probe counts as `per_probe` points in the score but is one
/// observation, so k probes that differ spread it by `per_probe` √k (not √(`per_probe` k): on a
/// dense scan one probe stands for tens of points, and one probe more seen through is no
/// stronger evidence for that).
pub(super) fn margin_between(p: &TrustParams, a: &Scored, b: &Scored, per_probe: f64) -> f64 {
    let split = a.fits.iter().zip(&b.fits).filter(|(x, y)| x != y).count() as f64;
    let probes = a.evidence.seen_through.abs_diff(b.evidence.seen_through) as f64;
    p.min_margin
        .max(p.margin_sigmas * (4.0 * split + per_probe * per_probe * probes).sqrt())
}

/// How a candidate with feature score `score` stands against the pose kept (score `kept`):
/// `None` when it is ruled out — the judge refuses it (`judged_ok` false: a see-through patch,
/// say) and the feature does not favour it either; else whether the scan cannot rule it out:
/// its score is within `margin` of the kept pose's, or ahead of it. A turn the judge refuses
/// but the feature favours means the scan contradicts the pose kept where the two differ: the
/// pose is then in doubt, not confirmed.
pub(super) fn standing(score: f64, judged_ok: bool, kept: f64, margin: f64) -> Option<bool> {
    let ahead = score > kept;
    (judged_ok || ahead).then_some(ahead || kept - score < margin)
}

/// The fine tolerance: `noise_sigmas` robust standard deviations of the point-to-plane residuals
/// of `local` about the pose (at least `min_fine_tolerance`, at most the judge's tolerance).
pub(super) fn fine_tolerance(
    local: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    tol: f64,
    p: &TrustParams,
) -> f64 {
    let res = plane_residuals(local, model, t_scene_model, tol);
    match robust_sigma(res.into_iter().flatten(), 12) {
        Some(sigma) => (p.noise_sigmas * sigma).clamp(p.min_fine_tolerance.min(tol), tol),
        None => tol,
    }
}

/// Whether each of `judged` lies within `tol` of the posed model's surface.
pub(super) fn fit_flags(judged: &[Point], model: &PoseModel, t_scene_model: &Isometry3<f64>, tol: f64) -> Vec<bool> {
    let inv = t_scene_model.inverse();
    judged
        .iter()
        .map(|l| plane_residual(model, &(inv * *l), 3.0 * tol).is_some_and(|r| r.abs() <= tol))
        .collect()
}

/// The evidence of a pose from the fit of each judged point and its probes seen through.
pub(super) fn evidence_of(fit: &[bool], tol: f64, violated: usize, per_probe: f64) -> FeatureEvidence {
    let fits = fit.iter().filter(|&&f| f).count();
    let misfits = fit.len() - fits;
    FeatureEvidence {
        fits,
        misfits,
        seen_through: violated,
        tolerance: tol,
        score: fits as f64 - misfits as f64 - violated as f64 * per_probe,
    }
}

/// Whether two poses are pick-grade of each other (modulo the part's exact symmetries): the same
/// pose as a pick sees it.
pub(super) fn pick_grade_of(model: &PoseModel, p: &TrustParams, a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    let (r, d) = model.symmetries.pose_error(a, b);
    r < p.pick_rotation && d < p.pick_translation
}

/// Whether pose `a` is pose `b` turned about the part's continuous near axis `near` (modulo its
/// exact symmetries): its rotation is within a pick-grade rotation of one of those turns.
pub(super) fn turned_about(
    model: &PoseModel,
    p: &TrustParams,
    near: &NearSymmetry,
    a: &Isometry3<f64>,
    b: &Isometry3<f64>,
) -> bool {
    let turns = Symmetries {
        center: near.center,
        continuous_axis: Some(near.axis),
        rotations: model.symmetries.rotations.clone(),
    };
    turns.pose_error(a, b).0 < p.pick_rotation
}

/// The candidates (`poses`, scored as `scored`) that the scan cannot rule out against the best
/// (index `best`): those distinct from it (not pick-grade of each other) that [`standing`] leaves
/// open, one per pose; the smallest lead of the best over a distinct candidate, in that
/// candidate's margins (infinite with none); and the smallest lead over a distinct candidate
/// ruled out by its evidence and not the same as one left open (how sure the scan is that the
/// truth is among the pose and those left open; infinite with none).
pub(super) fn weigh(
    poses: &[Isometry3<f64>],
    scored: &[Scored],
    best: usize,
    model: &PoseModel,
    p: &TrustParams,
    per_probe: f64,
) -> (Vec<usize>, f64, f64) {
    let top = &scored[best];
    let kept = poses[best];
    let same = |t: &Isometry3<f64>, u: &Isometry3<f64>| pick_grade_of(model, p, t, u);
    let mut open: Vec<usize> = Vec::new();
    let mut ruled_out: Vec<(usize, f64)> = Vec::new();
    let mut lead = f64::INFINITY;
    for (i, t) in poses.iter().enumerate() {
        let s = scored[i].evidence.score;
        let margin = margin_between(p, top, &scored[i], per_probe);
        // One the judge refuses (and the feature does not favour) is ruled out, by its lead: a
        // few probes seen through on either side of the judge's limit once decided a keyed
        // shaft 24° off at 0.99, every other turn refused and none counted.
        let undecided = standing(s, scored[i].judged_ok, top.evidence.score, margin).unwrap_or(false);
        if i == best || same(t, &kept) {
            continue;
        }
        let ahead = (top.evidence.score - s) / margin;
        lead = lead.min(ahead);
        if !undecided {
            ruled_out.push((i, ahead));
        } else if !open.iter().any(|&j| same(t, &poses[j])) {
            open.push(i);
        }
    }
    let lead_out = ruled_out
        .into_iter()
        .filter(|&(i, _)| !open.iter().any(|&j| same(&poses[i], &poses[j])))
        .fold(f64::INFINITY, |m, (_, a)| m.min(a));
    (open, lead, lead_out)
}

/// The share of the confidence a lead of `lead` margins over the runner-up keeps: 1 margin
/// halves the confidence, each further margin shrinks the doubt e-fold; no runner-up, all of it.
pub(super) fn decisiveness(lead: f64) -> f64 {
    if lead.is_finite() {
        1.0 - 0.5 * (-(lead - 1.0).max(0.0)).exp()
    } else {
        1.0
    }
}

/// The scan points within reach of the posed part (its radius and twice the judge's tolerance
/// from its centre), off the supports: points on the floor or a wall lie in the plane of the
/// part's faces that rest on it and would confirm material wherever a pose puts it.
pub(super) fn local_points(points: &[Point], model: &PoseModel, judge: &Judge, t: &Isometry3<f64>) -> Vec<Point> {
    let center = t * model.symmetries.center;
    let reach = model.radius + 2.0 * judge.depth.tol;
    // One pass over the points beats building a tree for the few poses assessed.
    points
        .iter()
        .filter(|p| (*p - center).norm_squared() <= reach * reach)
        .filter(|p| judge.depth.off_supports(p))
        .copied()
        .collect()
}
