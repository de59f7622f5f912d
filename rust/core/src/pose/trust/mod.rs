//! Trust: how sure a verified pose is. Every near-symmetric alternative of the pose (a flip that
//! only a boss tells apart, any turn about a shaft whose keyway decides) is posed, refined and
//! compared with it on evidence fine enough to see the feature; the pose the scan supports is
//! kept, the alternatives it cannot rule out are reported, and the confidence says how likely
//! the pose is pick-grade.
//!
//! The comparison runs on the scan points near the places the near-symmetries' features can be
//! (in the model frame: each feature and its images under the turns tried). There, a pose that
//! puts the feature where the scan shows the base shape — or the base shape where the scan shows
//! the feature, a hole or a cut corner — leaves points beyond the scan's noise; the judge's depth
//! test adds the surface a pose predicts where the sensor saw free space.
//!
//! [`trusted`] gives every verified pose its trust: [`assess`] here, then the fit of its points
//! against the scan's own noise ([`fit`]) and the turns and slides the view leaves open
//! ([`unseen_turns`]), the children of this module.

mod evidence;
mod fit;
#[cfg(test)]
mod tests;
mod unseen_turns;
#[cfg(test)]
mod unseen_turns_tests;

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::pose::judge::Judge;
use crate::pose::model::{turns_of, PoseModel, Turn};
use crate::pose::scene::{scene_indices, Context};
use crate::pose::surface::thin;
use crate::pose::types::{Alternative, FeatureEvidence, FitQuality, PoseEstimate, TrustParams};
use crate::registration::{icp, Convergence, IcpConfig};
use evidence::{
    base_confidence, decisiveness, evidence_of, fine_tolerance, fit_flags, local_points, margin_between, pick_grade_of,
    standing, turned_about, weigh, Scored,
};
use nalgebra::{Isometry3, Vector3};
use std::f64::consts::TAU;

/// The verdict of [`assess`] on one pose.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trust {
    /// In [0, 1]: how likely the pose is pick-grade.
    pub confidence: f64,
    /// In [0, 1]: how likely the pose or one of its alternatives is pick-grade.
    pub confidence_any: f64,
    /// Whether the scan cannot rule out a distinct alternative.
    pub ambiguous: bool,
    /// Those alternatives.
    pub alternatives: Vec<Alternative>,
    /// The unit axis (scene frame, through the part's symmetry centre) of a continuous
    /// near-symmetry the scan cannot fix: the part's turn about it is unknown.
    pub free_axis: Option<Vector3<f64>>,
    /// The evidence of the pose kept (`None` for a part without near-symmetries).
    pub evidence: Option<FeatureEvidence>,
}

impl Trust {
    /// The trust of a pose no alternative was compared with: the judge's `confidence` alone.
    fn undecided(confidence: f64) -> Self {
        Trust {
            confidence,
            confidence_any: confidence,
            ..Trust::default()
        }
    }
}

/// Steps between two turns about a continuous near axis at which the best candidate is tried
/// turned (every 2.5° for 24 turns; up to half the gap either way).
const FINE_TURNS: usize = 6;

/// A near turn and its side (see [`Candidate`]).
type SidedTurn = (Turn, usize);

/// A candidate pose, refined, and where it came from: a continuous turn, and its side (0: the
/// pose's own, turned about a continuous near axis or not at all; k: the k-th discrete near
/// turn, a flip, and its compositions with the continuous turns).
struct Candidate {
    t_scene_model: Isometry3<f64>,
    continuous: bool,
    side: usize,
}

/// Every estimate with its trust (see [`assess`]): a pose the scan shows to be a near-symmetric
/// alternative of the truth is replaced by the one it supports; the confidence also carries
/// the fit of the pose's points against the scan's own noise (see [`fit`]), and the turns and
/// slides the view leaves open are alternatives too (see [`unseen_turns`]).
/// A pose whose points lie further off the model than [`fit::MAX_RATIO`] noise floors is not
/// reported; `NoObjectFound` when no pose is left.
/// The context's points, those left after bin removal, are what the comparison runs on.
pub(super) fn trusted(found: Vec<PoseEstimate>, ctx: &Context<'_>, judge: &Judge) -> Result<Vec<PoseEstimate>> {
    let (scene, pts, model, p) = (ctx.scene, ctx.pts, ctx.model, &ctx.cfg.trust);
    let region = Region::new(model, judge, p);
    let mut misfit: Option<FitQuality> = None;
    let kept: Vec<PoseEstimate> = found
        .into_iter()
        .filter_map(|mut e| {
            let (t, kept) = assess(&e, pts, model, judge, p, &region);
            if kept != e.t_scene_model {
                e.t_scene_model = model.symmetries.canonical(&kept);
                let idx = scene_indices(scene, model, &e.t_scene_model, judge.depth.tol);
                e.indices = idx;
            }
            // The part's own points: those on the floor or a wall fit a face resting on it
            // whatever the pose (and a wall is not where the part's noise is read).
            let claimed: Vec<Point> = e
                .indices
                .iter()
                .map(|&i| scene[i])
                .filter(|p| judge.depth.off_supports(p))
                .collect();
            e.fit = fit::fit_quality(&claimed, model, &e.t_scene_model, judge.depth.tol, ctx.noise);
            if let Some(f) = e.fit.filter(|f| !f.acceptable()) {
                misfit.get_or_insert(f);
                return None;
            }
            e.confidence = t.confidence * e.fit.map_or(1.0, |f| f.factor);
            e.confidence_any = t.confidence_any * e.fit.map_or(1.0, |f| f.factor);
            e.ambiguous = t.ambiguous;
            e.alternatives = t.alternatives;

            // A free axis already says the turn is unknown.
            let noise = e.fit.map(|f| f.noise_floor);
            let unseen = match t.free_axis {
                None => unseen_turns::unseen_turns_of_all(
                    &claimed,
                    model,
                    &e.t_scene_model,
                    &e.alternatives,
                    judge,
                    p,
                    noise,
                ),
                Some(_) => Vec::new(),
            };
            if !unseen.is_empty() {
                // As with near-symmetric alternatives: each one the scan cannot rule out is as
                // likely as the pose.
                e.confidence /= (1 + unseen.len()) as f64;
                e.ambiguous = true;
                e.alternatives.extend(unseen);
            }
            e.free_axis = t.free_axis;
            e.feature_evidence = t.evidence;
            if !model.degenerate.is_empty() {
                // The part's surface cannot fix its pose along a free motion (one face of a box):
                // whatever the scan shows, the pose is one of many.
                e.confidence = 0.0;
                e.confidence_any = 0.0;
                e.ambiguous = true;
            }
            Some(e)
        })
        .collect();
    match misfit {
        Some(f) if kept.is_empty() => Err(Error::NoObjectFound {
            reason: format!(
                "the pose's points lie {:.1} noise floors off the model (residual σ {:.2} mm, scan noise {:.2} mm; \
                 at most {:.1}): not this part, or a part unlike its CAD model",
                f.ratio,
                f.residual_sigma,
                f.noise_floor,
                fit::MAX_RATIO
            ),
        }),
        _ => Ok(kept),
    }
}

/// Assesses `est` (a verified pose whose points are among `points`): with
/// near-symmetries, poses and compares their alternatives and may replace the pose by the one
/// the scan supports; returns the trust and the pose kept.
pub(super) fn assess(
    est: &PoseEstimate,
    points: &[Point],
    model: &PoseModel,
    judge: &Judge,
    p: &TrustParams,
    region: &Region,
) -> (Trust, Isometry3<f64>) {
    let e0 = judge.depth.evidence(model, &est.t_scene_model);
    let base = base_confidence(e0.coverage(), judge.min_coverage);
    let local: Vec<Point> = if model.near_symmetries.is_empty() {
        Vec::new()
    } else {
        local_points(points, model, judge, &est.t_scene_model)
    };
    if local.len() < 12 {
        return (Trust::undecided(base), est.t_scene_model);
    }
    let turns: Vec<SidedTurn> = region.turns.iter().copied().zip(region.sides.iter().copied()).collect();
    let sample = thin(&local, p.refine_points);
    let refine = IcpConfig::robust_plane(
        3.0 * judge.depth.tol,
        Convergence {
            iterations: p.iterations,
            ..Convergence::ALTERNATIVE
        },
    );
    let polish = |turn: &Isometry3<f64>, pts: &[Point], cfg: &IcpConfig| {
        let start = est.t_scene_model * turn;
        icp(pts, model.fine_target(), &start.inverse(), cfg)
            .ok()
            .map(|r| r.t_target_source.inverse())
    };
    // Every candidate is `est` turned by a near-symmetry, so its feature and the place it turns
    // the feature to both lie in the region posed by `est`: the scan points there judge them all.
    let to_model = est.t_scene_model.inverse();
    let judged: Vec<Point> = local
        .iter()
        .filter(|l| region.contains(&(to_model * *l)))
        .copied()
        .collect();
    let tol0 = fine_tolerance(&sample, model, &est.t_scene_model, judge.depth.tol, p);
    let glance = thin(&judged, p.refine_points);
    // Every discrete near turn gets the full refinement and comparison. The many turns of a
    // continuous near axis get a quick look on a thinned sample, which picks the finalists among
    // them: with the discrete turns among them too, a thin plate's turns about its face normal
    // (its faces map onto themselves at any angle) once took all three places from the quarter
    // turn that was the truth.
    let (mut turns, mut discrete): (Vec<SidedTurn>, Vec<SidedTurn>) = turns.into_iter().partition(|t| t.0 .1);
    if discrete.len() > p.max_discrete {
        turns.append(&mut discrete);
    }
    // The glance points a pose fits at the quick look's tolerance (the fine turns below use the
    // tolerance of the refined pose).
    let quick_fits = |t: &Isometry3<f64>| fit_flags(&glance, model, t, tol0).into_iter().filter(|&f| f).count();
    type Finalist = (SidedTurn, Option<Isometry3<f64>>);
    // The turns the quick look could not tell from the best of them (within a margin of its
    // fits) and did not make finalists: judged on the whole evidence below.
    let mut tied: Vec<(SidedTurn, Isometry3<f64>)> = Vec::new();
    let turns: Vec<Finalist> = if turns.len() > p.finalists {
        let quick_cfg = IcpConfig {
            max_iterations: p.quick_iterations,
            ..refine.clone()
        };
        // Each turn is scored by how many judged points it fits, on as many as a refinement
        // uses: a flange's notch is a few dozen of them, and among 400 it was left to chance.
        let few = thin(&sample, p.quick_points);
        let mut quick: Vec<(usize, SidedTurn, Isometry3<f64>)> = turns
            .into_iter()
            .filter_map(|(turn, side)| {
                let t = polish(&turn.0, &few, &quick_cfg)?;
                Some((quick_fits(&t), (turn, side), t))
            })
            .collect();
        quick.sort_by_key(|q| std::cmp::Reverse(q.0));
        // The best of every side is a finalist too: a pinned flange's flip at the turn that
        // lands its pin on the scan's pin fitted fewer of the glance than three turns of the
        // wrong face, and the truth was never compared (1 wrong-pose lift in 38 on four piles).
        let top = quick.first().map_or(0, |q| q.0);
        let mut finalists: Vec<Finalist> = Vec::new();
        for (rank, (fits, q, t)) in quick.into_iter().enumerate() {
            if rank < p.finalists || finalists.iter().all(|f| f.0 .1 != q.1) {
                finalists.push((q, Some(t)));
            } else if ((top - fits) as f64) < p.min_margin {
                tied.push((q, t));
            }
        }
        finalists
    } else {
        turns.into_iter().map(|t| (t, None)).collect()
    };
    // A finalist is refined from where its quick look left it (a refinement from the turn itself
    // drifted a flange's pin 8 mm off the scan's, the face's points outweighing the pin's), and
    // keeps that pose where the refinement fits less.
    let from_quick = |q: &Isometry3<f64>| {
        let r = icp(&sample, model.fine_target(), &q.inverse(), &refine)
            .ok()
            .map(|r| r.t_target_source.inverse());
        match r {
            Some(r) if quick_fits(&r) >= quick_fits(q) => r,
            _ => *q,
        }
    };
    let mut candidates: Vec<Candidate> = std::iter::once(((Isometry3::identity(), false), 0))
        .chain(discrete)
        .map(|t| (t, None))
        .chain(turns)
        .filter_map(|(((turn, continuous), side), quick)| {
            let t = match quick {
                None => polish(&turn, &sample, &refine)?,
                Some(q) => from_quick(&q),
            };
            Some(Candidate {
                t_scene_model: t,
                continuous,
                side,
            })
        })
        .collect();
    if candidates.is_empty() {
        return (Trust::undecided(base), est.t_scene_model);
    }
    let tol = fine_tolerance(&sample, model, &candidates[0].t_scene_model, judge.depth.tol, p);
    let per_probe = local.len() as f64 / e0.seen.max(1) as f64;
    let score_of = |t: &Isometry3<f64>| {
        let e = judge.depth.evidence(model, t);
        let fits = fit_flags(&judged, model, t, tol);
        Scored {
            evidence: evidence_of(&fits, tol, e.violated, per_probe),
            judged_ok: judge.check(&e, model, t).is_ok(),
            fits,
        }
    };
    let mut scored: Vec<Scored> = candidates.iter().map(|c| score_of(&c.t_scene_model)).collect();
    let pick = |scored: &[Scored]| {
        (0..scored.len())
            .filter(|&i| scored[i].judged_ok || i == 0)
            .max_by(|&a, &b| scored[a].evidence.score.total_cmp(&scored[b].evidence.score))
            .unwrap_or(0)
    };
    // The quick look only orders the turns: where it cannot tell them apart (a D-shaft whose flat
    // the scan does not show fits all 24 turns within a few glance points), the three it happened
    // to rank first once all lost to the pose on the depth test, the turn that was the truth was
    // never compared, and a pose 17° off was decided at 0.99. Every tied turn is judged on the
    // whole evidence, best quick fits first; one the scan cannot rule out is refined and compared
    // too, until its side has a turn left open.
    let mut opened: Vec<usize> = Vec::new();
    for (((_, continuous), side), q) in tied {
        if opened.contains(&side) {
            continue;
        }
        let best = pick(&scored);
        let open_against = |s: &Scored| {
            let margin = margin_between(p, &scored[best], s, per_probe);
            standing(s.evidence.score, s.judged_ok, scored[best].evidence.score, margin) == Some(true)
        };
        if !open_against(&score_of(&q)) {
            continue;
        }
        let t = from_quick(&q);
        let s = score_of(&t);
        if open_against(&s) && !pick_grade_of(model, p, &t, &candidates[best].t_scene_model) {
            opened.push(side);
        }
        candidates.push(Candidate {
            t_scene_model: t,
            continuous,
            side,
        });
        scored.push(s);
    }
    // About a continuous near axis the turns lie 15° apart, and a small feature (a 3 mm slot in
    // a 50 mm disc, a 6 mm pin on a 50 mm circle) pulls the refinement too weakly to bring the
    // nearest turn all the way onto it: the best candidate of each side (the pose's own face, and
    // each flip) is turned by finer steps either way, and the turn that fits more of the glance
    // is refined and compared too.
    if let Some(axis) = model.near_symmetries.iter().find(|n| n.angle.is_none()) {
        let glanced = |t: &Isometry3<f64>| fit_flags(&glance, model, t, tol).into_iter().filter(|&f| f).count();
        let step = TAU / (FINE_TURNS * p.continuous_turns.max(2)) as f64;
        let mut sides: Vec<usize> = candidates.iter().map(|c| c.side).collect();
        sides.sort_unstable();
        sides.dedup();
        for side in sides {
            let Some(lead) = (0..scored.len())
                .filter(|&i| candidates[i].side == side && (scored[i].judged_ok || i == 0))
                .max_by(|&a, &b| scored[a].evidence.score.total_cmp(&scored[b].evidence.score))
            else {
                continue;
            };
            let around = candidates[lead].t_scene_model;
            let finer = (1..FINE_TURNS / 2 + 1)
                .flat_map(|k| [k as f64, -(k as f64)])
                .map(|k| around * axis.transform(k * step))
                .map(|t| (glanced(&t), t))
                .max_by_key(|g| g.0);
            if let Some((_, t)) = finer.filter(|g| g.0 > glanced(&around)) {
                if let Ok(r) = icp(&sample, model.fine_target(), &t.inverse(), &refine) {
                    let t = r.t_target_source.inverse();
                    candidates.push(Candidate {
                        t_scene_model: t,
                        continuous: true,
                        side,
                    });
                    scored.push(score_of(&t));
                }
            }
        }
    }
    let best = pick(&scored);
    let top = &scored[best];
    let kept = candidates[best].t_scene_model;
    let poses: Vec<Isometry3<f64>> = candidates.iter().map(|c| c.t_scene_model).collect();
    let (open, lead, lead_out) = weigh(&poses, &scored, best, model, p, per_probe);
    // The turn is open when a turn about the continuous near axis is left open: a candidate of
    // those turns, or any other the scan cannot tell from the pose but by such a turn (a bossed
    // rod's own pose, 33° from the turn kept, was left open as a plain alternative, and a rod
    // 65° off was reported with confidence_any 0.99 and no free axis).
    let near_axis = model.near_symmetries.iter().find(|n| n.angle.is_none());
    let free = open.iter().any(|&i| {
        candidates[i].continuous
            || near_axis.is_some_and(|n| turned_about(model, p, n, &candidates[i].t_scene_model, &kept))
    });
    let alternatives: Vec<Alternative> = open
        .into_iter()
        .map(|i| Alternative {
            t_scene_model: model.symmetries.canonical(&candidates[i].t_scene_model),
            evidence: scored[i].evidence,
        })
        .collect();
    let base = if best == 0 {
        base
    } else {
        base_confidence(judge.depth.evidence(model, &kept).coverage(), judge.min_coverage)
    };
    // How likely the truth is among the pose and the alternatives left open: as sure as the
    // judge and the lead over the nearest candidate ruled out. In a pile of cut plates a quarter
    // turn that was the truth was ruled out by about one margin, and the pose and its half turn
    // were staked at 0.99; that lead now stakes them at about 0.5.
    let any = base * decisiveness(lead_out);
    let confidence = if alternatives.is_empty() {
        base * decisiveness(lead)
    } else if free {
        // The turn about the free axis is unknown: a pick-grade turn is as likely as its share
        // of the circle.
        any * (2.0 * p.pick_rotation / TAU)
    } else {
        any / (1 + alternatives.len()) as f64
    };
    let axis = model.near_symmetries.iter().find(|n| n.angle.is_none()).map(|n| n.axis);
    let trust = Trust {
        confidence,
        // The truth is one of the pose and the alternatives the scan could not rule out (a turn
        // about the free axis) as often as the judge confirms the pose and the scan rules out
        // the rest.
        confidence_any: if alternatives.is_empty() { confidence } else { any },
        ambiguous: !alternatives.is_empty(),
        alternatives,
        free_axis: axis.filter(|_| free).map(|a| kept.rotation * a),
        evidence: Some(top.evidence),
    };
    (trust, kept)
}

/// The most cells of the feature region's grid (one byte each).
const MAX_REGION_CELLS: usize = 1 << 22;

/// The turns of every near-symmetry (model frame; `true` for a continuous axis's) and the
/// model-frame region where the features can lie (each feature under the identity and every
/// turn), as grid cells: within about one cell of it. The same for every pose of one call.
pub(super) struct Region {
    turns: Vec<(Isometry3<f64>, bool)>,
    /// The side of each turn (see [`Candidate`]).
    sides: Vec<usize>,
    cell: f64,
    /// Key of the grid's first cell and its size in cells (the region's keys grown by one).
    lo: [i64; 3],
    dims: [usize; 3],
    /// Whether each grid cell (x fastest) lies within one cell of the region.
    cells: Vec<bool>,
}

impl Region {
    pub(super) fn new(model: &PoseModel, judge: &Judge, p: &TrustParams) -> Self {
        let mut turns = Vec::new();
        let mut sides = Vec::new();
        let mut region = Vec::new();
        // Sides matter where a continuous near axis turns them (a flip at every turn); a part
        // with only discrete near turns (a flange's twelve bolt-hole turns) keeps one side.
        let continuous = model.near_symmetries.iter().any(|n| n.angle.is_none());
        for n in &model.near_symmetries {
            let own = turns_of(n, p);
            region.extend(n.feature.iter().copied());
            for (t, turning) in &own {
                region.extend(n.feature.iter().map(|q| t * q));
                region.extend(n.feature.iter().map(|q| t.inverse() * q));
                // A discrete turn opens a side of its own; a continuous one stays on the pose's.
                sides.push(if *turning || !continuous {
                    0
                } else {
                    sides.iter().max().map_or(1, |m| m + 1)
                });
            }
            turns.extend(own);
        }
        // A part with a continuous near axis and a discrete near turn (a flange with one pin:
        // its flip, and its turn about its axis): the truth may be the discrete turn at any turn
        // about the axis, so each discrete turn is tried at every continuous one too. Tried only
        // at the pose's own turn, the flip rarely lands on the pin: on six camera piles of pinned
        // flanges 11 poses had their truth outside the pose and its alternatives (5 with these),
        // and the simulated cell lifted 7 such parts in two piles (1 with these).
        let composed: Vec<SidedTurn> = turns
            .iter()
            .zip(&sides)
            .filter(|(t, _)| !t.1)
            .flat_map(|(d, &side)| turns.iter().filter(|c| c.1).map(move |c| ((d.0 * c.0, true), side)))
            .collect();
        for ((t, _), _) in &composed {
            for n in &model.near_symmetries {
                region.extend(n.feature.iter().map(|q| t * q));
                region.extend(n.feature.iter().map(|q| t.inverse() * q));
            }
        }
        for (turn, side) in composed {
            turns.push(turn);
            sides.push(side);
        }
        let mut cell = (2.0 * model.spacing).max(judge.depth.tol).max(1e-3);
        // A dense grid over the region's keys grown by one cell: the region lies in the part's
        // box, a few thousand cells for the parts measured, and the comparison asks about every
        // judged point. Cells grow where a large part would need more than MAX_REGION_CELLS.
        let (own, lo, dims) = loop {
            let own: Vec<[i64; 3]> = region.iter().map(|q| key(q, cell)).collect();
            let (mut lo, mut hi) = ([0i64; 3], [-1i64; 3]);
            if let Some(first) = own.first() {
                (lo, hi) = (*first, *first);
            }
            for k in &own {
                for d in 0..3 {
                    lo[d] = lo[d].min(k[d]);
                    hi[d] = hi[d].max(k[d]);
                }
            }
            // Grown by one cell on every side.
            lo = lo.map(|v| v.saturating_sub(1));
            let dims: [usize; 3] = std::array::from_fn(|d| {
                usize::try_from(hi[d].saturating_add(1).saturating_sub(lo[d]).saturating_add(1)).unwrap_or(0)
            });
            if dims
                .iter()
                .try_fold(1usize, |a, &b| a.checked_mul(b))
                .is_some_and(|n| n <= MAX_REGION_CELLS)
            {
                break (own, lo, dims);
            }
            cell *= 1.5;
        };
        let mut r = Region {
            turns,
            sides,
            cell,
            lo,
            dims,
            cells: vec![false; dims.iter().product()],
        };
        for k in own {
            // The cell and its 26 neighbours.
            let near: [Option<usize>; 27] = std::array::from_fn(|n| {
                r.index(&[
                    k[0] + n as i64 % 3 - 1,
                    k[1] + n as i64 / 3 % 3 - 1,
                    k[2] + n as i64 / 9 - 1,
                ])
            });
            for i in near.into_iter().flatten() {
                r.cells[i] = true;
            }
        }
        r
    }

    /// The grid index of cell key `k`, if the grid holds it.
    fn index(&self, k: &[i64; 3]) -> Option<usize> {
        let mut i = 0;
        for d in (0..3).rev() {
            let o = usize::try_from(k[d].checked_sub(self.lo[d])?).ok()?;
            if o >= self.dims[d] {
                return None;
            }
            i = i * self.dims[d] + o;
        }
        Some(i)
    }

    /// The grid's cell edge, mm.
    #[cfg(test)]
    pub(super) fn cell(&self) -> f64 {
        self.cell
    }

    /// Whether the model-frame point `q` lies within about one cell of the region.
    pub(super) fn contains(&self, q: &Point) -> bool {
        self.index(&key(q, self.cell)).is_some_and(|i| self.cells[i])
    }
}

/// The grid cell of `p`, its key bounded well inside i64 so that neighbours' keys cannot
/// overflow.
fn key(p: &Point, cell: f64) -> [i64; 3] {
    [p.x, p.y, p.z].map(|v| (v / cell).floor().clamp(-1e15, 1e15) as i64)
}
