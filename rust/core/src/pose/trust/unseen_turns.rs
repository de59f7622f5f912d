//! Turns and slides the scan cannot see. When the points a pose claims constrain its turn about
//! one axis far less than about the others — one leg of an elbow seen alone is a cylinder — other
//! turns about that axis fit them as well, with the rest of the part swung into places the scan
//! does not show (under its neighbours); a shaft whose ends are hidden slides along its axis the
//! same way. No mesh analysis finds these: they come from what the view
//! happens to show. Each turn is posed about the weak axis (each slide along the weak direction),
//! refined on the claimed points and judged; a move the judge passes that explains the claimed points as well is an alternative
//! the scan cannot rule out, and the pose is reported ambiguous rather than confidently wrong.
//! A move that puts the part deeper into the bin's floor or a wall than the pose is taken back
//! towards the pose until it no longer does: a part at rest lies against what bounds its unseen
//! turn (a tee with its stem hidden, leaning in the corner of floor and wall), so the turn that
//! just touches the bin is the one the scan cannot rule out, and a probe a few degrees past it
//! is refused; a slide of a long shaft a few millimetres into the floor, which the judge's
//! tolerance would let pass, is no alternative either.

use super::fit::{thinned_sigma, FREE_RATIO};
use crate::geometry::Point;
use crate::pose::judge::Judge;
use crate::pose::model::{near_turns, Constraints, PoseModel};
use crate::pose::surface::{plane_residuals, thin};
use crate::pose::types::{Alternative, FeatureEvidence, TrustParams};
use crate::registration::{icp, Convergence, IcpConfig};
use nalgebra::{Isometry3, Translation3, Unit, UnitQuaternion, Vector3};

/// The turn about the weakest axis is probed when the claimed points constrain it less than this
/// share of the next weakest: the seen surface is then nearly a surface of revolution about it.
const WEAK_SHARE: f64 = 0.3;
/// A weak axis within about 10° of the axis of a near-symmetry of the part, or of its continuous
/// symmetry, is that axis.
const AXIS_COS: f64 = 0.985;
/// The turns probed, degrees (both ways, and the half turn).
const TURNS_DEG: [f64; 11] = [
    30.0, 60.0, 90.0, 120.0, 150.0, 180.0, -30.0, -60.0, -90.0, -120.0, -150.0,
];
/// The slides probed along a weak slide, as shares of the part's diameter (both ways).
const SLIDES: [f64; 3] = [0.05, 0.1, 0.2];
/// A move the bin refuses is halved back towards the pose this many times (a 30° turn comes
/// within 2° of where the part touches the bin).
const BIN_HALVINGS: usize = 4;
/// A move may put this much more of the part's surface through the bin than the pose does:
/// about two of the judge's 500 bin probes, the refinement's own jitter.
pub(super) const BIN_SLACK: f64 = 0.005;
/// Claimed points each turn is refined on, at most.
const REFINE_POINTS: usize = 300;
/// Claimed points and ICP iterations of the quick look that drops, before the full
/// refinement, a move that falls back onto the pose or onto a known alternative.
const QUICK_POINTS: usize = 150;
const QUICK_ITERATIONS: usize = 5;
/// A turn explains the claimed points as well when it loses at most this many of them from the
/// judge's tolerance — twice the 15 points at which a feature counts as in view, as the trust
/// stage's margin — …
const MIN_MARGIN: f64 = 30.0;
/// … or this share of them, when more …
const MARGIN_SHARE: f64 = 0.02;
/// … with residuals at most this many times the pose's own (or [`FREE_RATIO`] noise floors) …
const SIGMA_SLACK: f64 = 1.5;
/// … and it puts hardly more surface where the sensor saw free space: at most this share of
/// the pose's judged probes more …
const SEEN_THROUGH_SHARE: f64 = 0.01;
/// … or this many, when more.
const SEEN_THROUGH_MARGIN: usize = 3;

/// A move probed from the pose: a turn (radians) about an axis through a point, or a slide.
#[derive(Clone, Copy)]
enum Move {
    Turn(Unit<Vector3<f64>>, Point, f64),
    Slide(Vector3<f64>),
}

impl Move {
    /// The move scaled by `s` (the same axis, `s` times the angle; `s` times the slide), model frame.
    fn scaled(&self, s: f64) -> Isometry3<f64> {
        match *self {
            Move::Turn(axis, x, angle) => {
                Translation3::from(x.coords)
                    * UnitQuaternion::from_axis_angle(&axis, s * angle)
                    * Translation3::from(-x.coords)
            }
            Move::Slide(v) => Isometry3::from_parts(Translation3::from(s * v), UnitQuaternion::identity()),
        }
    }
}

/// Whether poses `a` and `b` are one pick-grade pose of `model` (modulo its symmetries).
fn same_pose(model: &PoseModel, trust: &TrustParams, a: &Isometry3<f64>, b: &Isometry3<f64>) -> bool {
    let (r, d) = model.symmetries.pose_error(a, b);
    r < trust.pick_rotation && d < trust.pick_translation
}

/// The weakest slide of the point-to-plane constraints of `q` (model-frame points with their
/// model normals), model frame, when it is weak (see [`WEAK_SHARE`]): along a cylinder seen
/// without its ends, say.
pub(super) fn weak_slide(q: &[(Point, Vector3<f64>)]) -> Option<Unit<Vector3<f64>>> {
    let (values, vectors) = Constraints::of(q).slides();
    (values[1] > 0.0 && values[0] <= WEAK_SHARE * values[1]).then(|| Unit::new_normalize(vectors[0]))
}

/// The weakest rotation axis of the point-to-plane constraints of `q` (model-frame points with
/// their model normals) and a point on it, model frame, when it is weak (see [`WEAK_SHARE`]).
pub(super) fn weak_axis(q: &[(Point, Vector3<f64>)]) -> Option<(Unit<Vector3<f64>>, Point)> {
    let c = Constraints::of(q);
    let (values, vectors) = c.turns()?;
    let (w0, w1) = (values[0], values[1]);
    if !(w1 > 0.0) || w0 > WEAK_SHARE * w1 {
        return None;
    }
    Some((Unit::new_normalize(vectors[0]), c.axis_point(&vectors[0])?))
}

/// Claimed points within `reach` of the posed model, with its normals, model frame.
fn on_model(claimed: &[Point], model: &PoseModel, t: &Isometry3<f64>, reach: f64) -> Vec<(Point, Vector3<f64>)> {
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

/// In one pass over the claimed points: how many lie within `tol` of the posed model, and the
/// robust σ of their residuals (that of [`super::fit::residual_sigma`]).
fn kept_and_sigma(claimed: &[Point], model: &PoseModel, t: &Isometry3<f64>, tol: f64) -> (usize, Option<f64>) {
    let res = plane_residuals(claimed, model, t, tol);
    let kept = res.iter().flatten().filter(|r| r.abs() <= tol).count();
    (kept, thinned_sigma(&res))
}

/// The turns of `t_scene_model` about the weak axis of its claimed points that the scan cannot
/// rule out (empty when no axis is weak), beyond the `known` alternatives. `noise_floor` is the
/// scan's noise (mm) where known.
pub(super) fn unseen_turns(
    claimed: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    judge: &Judge,
    trust: &TrustParams,
    noise_floor: Option<f64>,
    known: &[Alternative],
) -> Vec<Alternative> {
    unseen_turns_from(
        claimed,
        model,
        t_scene_model,
        t_scene_model,
        judge,
        trust,
        noise_floor,
        known,
    )
}

/// [`unseen_turns`] of the pose `start`, each turn explaining the claimed points and the scan
/// as well as `baseline` does (its fits, residuals, free space and bin): the turns of a flip the
/// scan rules out are measured against the pose it is a flip of.
#[allow(clippy::too_many_arguments)]
fn unseen_turns_from(
    claimed: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    baseline: &Isometry3<f64>,
    judge: &Judge,
    trust: &TrustParams,
    noise_floor: Option<f64>,
    known: &[Alternative],
) -> Vec<Alternative> {
    let tol = judge.depth.tol;
    let sample = thin(claimed, REFINE_POINTS);
    let q = on_model(&sample, model, t_scene_model, tol);
    if q.len() < 30 {
        return Vec::new();
    }
    // Turns about the axis of one of the part's near-symmetries are the trust stage's to weigh,
    // on the feature that breaks it; about a continuous symmetry's, they change nothing.
    let trusts_axis = |axis: &Vector3<f64>| {
        let along = |a: &Vector3<f64>| a.norm() > 0.0 && a.normalize().dot(axis).abs() > AXIS_COS;
        let continuous = model.symmetries.continuous_axis.iter();
        let near = model.near_symmetries.iter().map(|n| &n.axis);
        continuous.chain(near).any(along)
    };
    let turn_axis = weak_axis(&q).filter(|(axis, _)| !trusts_axis(axis));
    let mut moves: Vec<Move> = Vec::new();
    if let Some((axis, x)) = turn_axis {
        moves.extend(TURNS_DEG.iter().map(|deg| Move::Turn(axis, x, deg.to_radians())));
    }
    if let Some(u) = weak_slide(&q) {
        let slides = SLIDES.iter().flat_map(|s| [*s, -*s]);
        moves.extend(slides.map(|s| Move::Slide(u.into_inner() * s * model.diameter)));
    }
    if moves.is_empty() {
        return Vec::new();
    }
    let (kept0, Some(sigma0)) = kept_and_sigma(claimed, model, baseline, tol) else {
        return Vec::new();
    };
    let sigma_ok = (SIGMA_SLACK * sigma0).max(FREE_RATIO * noise_floor.unwrap_or(0.0));
    let e0 = judge.depth.evidence(model, baseline);
    let seen_through_ok =
        e0.violated + SEEN_THROUGH_MARGIN.max((SEEN_THROUGH_SHARE * (e0.seen + e0.violated) as f64).round() as usize);
    let refine = IcpConfig::robust_plane(3.0 * tol, Convergence::UNSEEN_TURN);
    let same = |a: &Isometry3<f64>, b: &Isometry3<f64>| same_pose(model, trust, a, b);
    let known_pose = |t: &Isometry3<f64>, found: &[Alternative]| {
        same(t, t_scene_model) || same(t, baseline) || found.iter().chain(known).any(|a| same(&a.t_scene_model, t))
    };
    // The near-symmetric turns of the baseline are the trust stage's to weigh, on the feature
    // that tells them apart (a plate's cut corner, 0.3 % of its surface, fits the claimed points
    // "as well" wherever it is put).
    let near_poses: Vec<Isometry3<f64>> = near_turns(model, trust)
        .iter()
        .map(|(turn, _)| baseline * turn)
        .collect();
    let few = thin(&sample, QUICK_POINTS);
    let quick = IcpConfig {
        max_iterations: QUICK_ITERATIONS,
        ..refine.clone()
    };
    let refined = |motion: &Isometry3<f64>| {
        let start = t_scene_model * motion.inverse();
        icp(&sample, model.fine_target(), &start.inverse(), &refine)
            .ok()
            .map(|r| r.t_target_source.inverse())
    };
    let through0 = judge.depth.through_supports(model, baseline);
    let mut found: Vec<Alternative> = Vec::new();
    for probe in moves {
        if crate::cancel::requested() {
            break;
        }
        let start = t_scene_model * probe.scaled(1.0).inverse();
        let Ok(q) = icp(&few, model.fine_target(), &start.inverse(), &quick) else {
            continue;
        };
        let glance = q.t_target_source.inverse();
        if known_pose(&glance, &found) {
            continue;
        }
        let Ok(r) = icp(&sample, model.fine_target(), &q.t_target_source, &refine) else {
            continue;
        };
        let mut t = r.t_target_source.inverse();
        if judge.depth.through_supports(model, &t) > through0 + BIN_SLACK {
            // Deeper into the bin: halve the move back towards the pose, keeping the largest
            // share of it that goes no deeper than the pose.
            let (mut clear, mut through) = (0.0, 1.0);
            let mut last_clear = None;
            for _ in 0..BIN_HALVINGS {
                let mid = 0.5 * (clear + through);
                match refined(&probe.scaled(mid)) {
                    Some(m) if judge.depth.through_supports(model, &m) <= through0 + BIN_SLACK => {
                        clear = mid;
                        last_clear = Some(m);
                    }
                    _ => through = mid,
                }
            }
            let Some(m) = last_clear else {
                continue;
            };
            t = m;
        }
        if known_pose(&t, &found) || near_poses.iter().any(|n| same(&t, n)) {
            continue;
        }
        // A slide refined into a turn about a near-symmetry's axis is the trust stage's too.
        let turned = (baseline.inverse() * t).rotation;
        if turned.angle() >= trust.pick_rotation && turned.axis().is_some_and(|a| trusts_axis(&a)) {
            continue;
        }
        let e = judge.depth.evidence(model, &t);
        if e.violated > seen_through_ok || judge.check(&e, model, &t).is_err() {
            continue;
        }
        let (kept, sigma) = kept_and_sigma(claimed, model, &t, tol);
        if (kept as f64) < kept0 as f64 - MIN_MARGIN.max(MARGIN_SHARE * kept0 as f64) {
            continue;
        }
        if !sigma.is_some_and(|s| s <= sigma_ok) {
            continue;
        }
        found.push(Alternative {
            t_scene_model: model.symmetries.canonical(&t),
            evidence: FeatureEvidence {
                fits: kept,
                misfits: claimed.len().saturating_sub(kept),
                seen_through: e.violated,
                tolerance: tol,
                score: kept as f64 - (claimed.len().saturating_sub(kept)) as f64 - e.violated as f64,
            },
        });
    }
    found
}

/// The unseen turns (see [`unseen_turns`]) of the pose `t_scene_model` and of each of its
/// near-symmetric `alternatives`, each new one beyond the pose, the alternatives and those
/// already found: the truth may be a flip of the pose turned about
/// the axis the view leaves open (a tee leaning on a wall, its boss and stem hidden, read
/// flipped and turned about its run), which no turn of the pose itself reaches. The part's
/// half turns the scan rules out as they stand (a flip that puts the boss where the scan sees
/// free space) are turned too, each turn measured against the pose: a tee whose run alone is in
/// full view, read flipped and turned about its run (its stem where the boss is, the boss at the
/// stem's root), fits the scan a hair worse than the truth (0.964 against 0.974 of the claimed
/// points in the judge's tolerance, on a simulated pile) and was reported sure (0.91), its truth
/// reachable only by the flip and a turn.
pub(super) fn unseen_turns_of_all(
    claimed: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    alternatives: &[Alternative],
    judge: &Judge,
    trust: &TrustParams,
    noise_floor: Option<f64>,
) -> Vec<Alternative> {
    let mut unseen = unseen_turns(claimed, model, t_scene_model, judge, trust, noise_floor, alternatives);
    let mut known = alternatives.to_vec();
    known.extend(unseen.iter().cloned());
    // Only the poses of the known alternatives are compared.
    known.push(Alternative {
        t_scene_model: *t_scene_model,
        evidence: FeatureEvidence::default(),
    });
    let flips: Vec<Isometry3<f64>> = near_turns(model, trust)
        .into_iter()
        .filter(|(_, continuous)| !continuous)
        .map(|(turn, _)| t_scene_model * turn)
        .filter(|f| {
            !alternatives
                .iter()
                .any(|a| same_pose(model, trust, &a.t_scene_model, f))
        })
        .collect();
    let starts = alternatives.iter().map(|a| (a.t_scene_model, a.t_scene_model));
    for (start, baseline) in starts.chain(flips.into_iter().map(|f| (f, *t_scene_model))) {
        let more = unseen_turns_from(claimed, model, &start, &baseline, judge, trust, noise_floor, &known);
        known.extend(more.iter().cloned());
        unseen.extend(more);
    }
    unseen
}
