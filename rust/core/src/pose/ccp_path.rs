//! The paper's path: top-object segmentation (Table 2) → CCP (or the centroid baseline) →
//! coarse checks → ICP → verification.
//!
//! The coarse checks score every reading cheaply (object points on the model × expected-visible
//! model points on the scene), give the best few a short ICP, and the winner is refined on all
//! of the object's points. Their tunables are [`CcpPathParams`].

use super::judge::Judge;
use super::model::PoseModel;
use super::scene::{scene_indices, Context};
use super::types::NOISE_SIGMAS;
use super::types::{CcpPathParams, CoarseMethod, Laps, PoseConfig, PoseEstimate, Timings};
use crate::error::{Error, Result};
use crate::geometry::{centroid, check_count, covariance, principal_axes, Point};
use crate::normals::{normal_at, Orientation};
use crate::registration::ccp::ccp;
use crate::registration::verify::{coarse_inlier_fraction, depth_evidence, inlier_stats, HeightMap};
use crate::registration::{icp, IcpConfig, RobustKernel};
use crate::search::KdIndex;
use crate::segment::{scan_spacing, segment_top, SegmentConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::PI;

/// The scan's sampling: spacing along and across the scan lines, mm.
#[derive(Clone, Copy)]
struct Sampling {
    along: f64,
    across: f64,
}

/// A scored reading: score, `T_model_scene` it reached, and the coarse `T_scene_model` it came from.
type Tried = (f64, Isometry3<f64>, Isometry3<f64>);

/// The paper's path on the points left after bin removal: top-object segmentation → CCP (or
/// the centroid baseline) → ICP → verification. Indices in the result refer to `pts`.
///
/// Table 2 with one addition: a region that no pose explains (a bin rim, a sliver of a part
/// deep below others) is set aside and the next top region tried.
pub(super) fn run(
    ctx: &Context<'_>,
    method: CoarseMethod,
    judge: &Judge,
    timings: &mut Timings,
) -> Result<PoseEstimate> {
    let (pts, up) = (ctx.pts, ctx.up);
    let mut laps = Laps::new(timings);
    let index = KdIndex::new(pts);
    let spacing = scan_spacing(pts, &index);
    let sampling = Sampling {
        along: spacing.along.max(1e-3),
        across: spacing.across.max(spacing.along.max(1e-3)),
    };
    // The normals are computed as the segmentation reaches each point (and kept): the regions
    // tried touch a small part of a bin's scan, and a normal is tens of neighbours' PCA.
    let k = normals_k(pts, sampling)?;
    let mut memo: Vec<Option<Vector3<f64>>> = vec![None; pts.len()];
    let mut found = Vec::new();
    let mut normal_of = |i: usize| -> Vector3<f64> {
        *memo[i].get_or_insert_with(|| normal_at(&pts[i], pts, &index, k, Orientation::TowardDirection(up), &mut found))
    };
    laps.lap("normals");
    let seg_cfg = segment_config(ctx, sampling);
    let mut excluded = vec![false; pts.len()];
    let mut last_failure: Option<Error> = None;
    for _ in 0..ctx.cfg.ccp_path.max_regions {
        let region = match segment_top(pts, Some(&mut normal_of), &index, &seg_cfg, Some(&excluded)) {
            Ok(r) => r,
            Err(e) => return Err(last_failure.unwrap_or(e)),
        };
        let object: Vec<Point> = region.iter().map(|&i| pts[i]).collect();
        laps.lap("segmentation");
        match fit_region(ctx, &object, method, sampling, judge, &mut laps) {
            Err(Error::NoObjectFound { reason }) => {
                for &i in &region {
                    excluded[i] = true;
                }
                last_failure = Some(Error::NoObjectFound { reason });
            }
            other => return other,
        }
    }
    Err(last_failure.unwrap_or(Error::NoObjectFound {
        reason: "no region could be matched".into(),
    }))
}

/// How many neighbours a scan normal is fitted to: enough to span more than one scan line
/// (the points lie far closer along a line than across lines).
fn normals_k(pts: &[Point], s: Sampling) -> Result<usize> {
    check_count("points", pts, 3, "normals need at least 3 points")?;
    Ok(((8.0 * s.across / s.along).round() as usize)
        .clamp(12, 64)
        .min(pts.len()))
}

/// Table 2's parameters, defaults derived from the scan's sampling and the model's size.
fn segment_config(ctx: &Context<'_>, s: Sampling) -> SegmentConfig {
    let (model, cfg) = (ctx.model, ctx.cfg);
    let visible_points = (0.5 * model.area / (s.along * s.across)).max(1.0);
    SegmentConfig {
        d_star: cfg.d_star.unwrap_or((3.0 * s.along).max(1.6 * s.across)),
        min_points: cfg.min_points.unwrap_or(((0.1 * visible_points) as usize).max(15)),
        max_normal_angle: cfg.max_normal_angle,
        max_extent: 1.1 * model.diameter,
        up: ctx.up,
    }
}

/// The pose of one segmented region: coarse readings → coarse checks → refinement →
/// verification; `NoObjectFound` when the region is not the part.
fn fit_region(
    ctx: &Context<'_>,
    object: &[Point],
    method: CoarseMethod,
    sampling: Sampling,
    judge: &Judge,
    laps: &mut Laps<'_>,
) -> Result<PoseEstimate> {
    let (model, cfg) = (ctx.model, ctx.cfg);
    reject_flat_region(object, model)?;
    let candidates = coarse_readings(object, ctx, method)?;
    laps.lap("coarse");
    let checks = Checks::new(ctx, object, sampling);
    let ranked = checks.rank(&candidates, method);
    let mut best = checks.converge(&ranked)?;
    if method == CoarseMethod::Ccp {
        best = checks.resolve_half_turns(best)?;
    }
    let (_, t_model_scene0, coarse) = best;
    let fine = &cfg.ccp_path.fine_icp;
    let fine_cfg = IcpConfig::robust_plane(fine.reach_tolerances * checks.tol, fine.convergence);
    let refined = icp(object, model.fine_target(), &t_model_scene0, &fine_cfg)?;
    laps.lap("icp");
    let t_model_scene = refined.t_target_source;
    let (score, rmse) = verify(object, model, cfg, &t_model_scene, checks.tol)?;
    let t_scene_model = t_model_scene.inverse();
    // The one judge every method passes: a pose the scan sees through, that shows too little of
    // itself or that lies through the bin is no pose, and the next region is tried.
    let (t_scene_model, evidence) = judge.verdict(model, &t_scene_model)?;
    let indices = scene_indices(ctx.pts, model, &t_scene_model, checks.tol);
    laps.lap("verification");
    Ok(PoseEstimate::verified(
        method,
        model.symmetries.canonical(&t_scene_model),
        coarse,
        &evidence,
        (score, rmse),
        refined.iterations,
        indices,
    ))
}

/// A flat region wider than the part (a bin rim, a wall left in the scan) is not the part.
fn reject_flat_region(object: &[Point], model: &PoseModel) -> Result<()> {
    let (_, cov) = covariance(object);
    let (vals, axes) = principal_axes(&cov);
    let along: Vec<f64> = object.iter().map(|p| p.coords.dot(&axes[0])).collect();
    let span =
        along.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - along.iter().cloned().fold(f64::INFINITY, f64::min);
    if span > 1.05 * model.diameter && vals[2].sqrt() < 0.02 * model.diameter {
        return Err(Error::NoObjectFound {
            reason: format!(
                "the top region is flat and {span:.0} mm wide, wider than the part ({:.0} mm)",
                model.diameter
            ),
        });
    }
    Ok(())
}

/// Coarse pose readings, model → scene: CCP's, or the centroid baseline's one.
fn coarse_readings(object: &[Point], ctx: &Context<'_>, method: CoarseMethod) -> Result<Vec<Isometry3<f64>>> {
    let model = ctx.model;
    match (method, &model.layout) {
        (CoarseMethod::Ccp, Some(layout)) => {
            let (points, normals) = (model.target.points(), model.target.normals().unwrap_or(&[]));
            Ok(ccp(object, layout, points, normals, Some(ctx.up), &ctx.cfg.ccp)?.candidates)
        }
        (CoarseMethod::Ccp, None) => Err(Error::invalid(
            "model",
            "CCP needs the model's branch layout (cylindrical branches from a junction); declare branches on the Model or use method=\"centroid\"",
        )),
        _ => {
            let shift = centroid(object) - centroid(model.target.points());
            Ok(vec![Isometry3::from_parts(Translation3::from(shift), UnitQuaternion::identity())])
        }
    }
}

/// What the coarse checks of one region judge a pose by.
struct Checks<'a> {
    model: &'a PoseModel,
    params: &'a CcpPathParams,
    heights: HeightMap,
    /// Object points of the quick checks, and the larger sample stage two converges on.
    probe: Vec<Point>,
    sample: Vec<Point>,
    /// Inlier distance and the coarse checks' wider tolerance, mm.
    tol: f64,
    coarse_tol: f64,
    coarse_model_step: usize,
    fine_step: usize,
    short: IcpConfig,
    quick: IcpConfig,
    /// The model's centroid, about which the turns are taken.
    c_model: Vector3<f64>,
}

impl<'a> Checks<'a> {
    fn new(ctx: &Context<'a>, object: &[Point], s: Sampling) -> Self {
        let (model, cfg) = (ctx.model, ctx.cfg);
        let p = &cfg.ccp_path;
        let tol = cfg.inlier_distance.unwrap_or(
            (2.0 * model.spacing + 1.5 * s.along.min(2.0 * model.spacing))
                .max(1.0)
                .max(NOISE_SIGMAS * ctx.noise),
        );
        let sample = object
            .iter()
            .step_by(object.len().div_ceil(p.sample_points))
            .copied()
            .collect();
        let probe = object
            .iter()
            .step_by(object.len().div_ceil(p.probe_points))
            .copied()
            .collect();
        let n_model = model.target.points().len();
        let c = &p.check_icp;
        let short = IcpConfig {
            kernel: RobustKernel::Tukey((c.kernel_ratio * model.diameter).max(c.min_tolerances * tol)),
            approximate: true,
            ..IcpConfig::robust_plane(
                (c.reach_ratio * model.diameter).max(c.min_tolerances * tol),
                c.convergence,
            )
        };
        let quick = IcpConfig {
            max_iterations: c.quick_iterations,
            ..short.clone()
        };
        Checks {
            model,
            params: p,
            heights: HeightMap::new(ctx.scene, ctx.view, (1.5 * s.across).max(0.5))
                .seen_from(ctx.cfg.viewpoint)
                .lit_from(ctx.cfg.light),
            probe,
            sample,
            tol,
            coarse_tol: (p.coarse_tolerance_ratio * model.diameter).max(2.0 * tol),
            coarse_model_step: n_model.div_ceil(p.model_probes),
            fine_step: (n_model / p.fine_model_probes).max(1),
            short,
            quick,
            c_model: centroid(model.target.points()).coords,
        }
    }

    /// The coarse score of `T_model_scene` on `probe`: object points near the model × model
    /// points the scan confirms, both at the coarse tolerance.
    fn coarse_score(&self, t: &Isometry3<f64>, probe: &[Point]) -> f64 {
        let target = &self.model.target;
        coarse_inlier_fraction(probe, target, t, self.coarse_tol)
            * depth_evidence(
                target,
                &self.heights,
                &t.inverse(),
                self.coarse_model_step,
                self.coarse_tol,
                false,
            )
            .coverage()
    }

    /// The stage-two score of `T_model_scene`: the same product on the sample, at the inlier
    /// distance, with the denser depth test.
    fn fine_score(&self, t: &Isometry3<f64>) -> f64 {
        let target = &self.model.target;
        inlier_stats(&self.sample, target, t, self.tol).0
            * depth_evidence(target, &self.heights, &t.inverse(), self.fine_step, self.tol, false).coverage()
    }

    /// `t_scene_model` turned by `angle` about `axis` through the model's centroid.
    fn turned(&self, t_scene_model: &Isometry3<f64>, axis: Vector3<f64>, angle: f64) -> Isometry3<f64> {
        let r = UnitQuaternion::from_scaled_axis(axis * angle);
        t_scene_model * Isometry3::from_parts(Translation3::from(self.c_model - r * self.c_model), r)
    }

    /// The readings worth an ICP check, best first: duplicates scored once, two tiers of
    /// coarse scores, CCP's turned readings added, one per rotation cluster.
    fn rank(&self, candidates: &[Isometry3<f64>], method: CoarseMethod) -> Vec<(f64, Isometry3<f64>)> {
        let p = self.params;
        let unique = unique_readings(
            candidates,
            p.same_reading_angle,
            p.same_reading_shift * self.model.diameter,
        );
        // A third of the probe sorts out the readings that are plainly wrong, the whole probe
        // ranks the rest.
        let glance: Vec<Point> = self.probe.iter().step_by(3).copied().collect();
        let mut ranked: Vec<(f64, Isometry3<f64>)> = unique
            .iter()
            .map(|c| (self.coarse_score(&c.inverse(), &glance), *c))
            .collect();
        sort_best_first(&mut ranked);
        ranked.truncate(p.second_tier);
        for r in ranked.iter_mut() {
            r.0 = self.coarse_score(&r.1.inverse(), &self.probe);
        }
        sort_best_first(&mut ranked);
        let with_turns = if method == CoarseMethod::Ccp {
            p.turned_readings
        } else {
            0
        };
        let turns: Vec<Isometry3<f64>> = ranked
            .iter()
            .take(with_turns)
            .flat_map(|(_, c)| {
                [Vector3::x(), Vector3::y(), Vector3::z()]
                    .into_iter()
                    .flat_map(move |axis| [1.0, 0.5, -0.5].map(|k| self.turned(c, axis, k * PI)))
            })
            .collect();
        for t in turns {
            ranked.push((self.coarse_score(&t.inverse(), &self.probe), t));
        }
        sort_best_first(&mut ranked);
        distinct_rotations(ranked, p.cluster_angle)
    }

    /// Stage one: the best-ranked readings get a few ICP steps on the probe (a coarse pose tens
    /// of degrees off still lands in the right basin, but cannot be judged before moving it).
    /// Stage two: the leaders converge on the sample and are judged at the inlier distance.
    fn converge(&self, ranked: &[(f64, Isometry3<f64>)]) -> Result<Tried> {
        let target = &self.model.target;
        let mut tried: Vec<Tried> = Vec::with_capacity(ranked.len());
        for (_, cand) in ranked.iter().take(self.params.stage_one) {
            let r = icp(&self.probe, target, &cand.inverse(), &self.quick)?;
            tried.push((
                self.coarse_score(&r.t_target_source, &self.probe),
                r.t_target_source,
                *cand,
            ));
        }
        tried.sort_by(|a, b| b.0.total_cmp(&a.0));
        let lead = tried[0].0;
        let mut best: Option<Tried> = None;
        let leaders = tried
            .iter()
            .take(self.params.stage_two)
            .filter(|t| t.0 >= self.params.stage_two_ratio * lead);
        for (_, t0, cand) in leaders {
            let r = icp(&self.sample, target, t0, &self.short)?;
            let s = self.fine_score(&r.t_target_source);
            if best.as_ref().is_none_or(|b| s > b.0) {
                best = Some((s, r.t_target_source, *cand));
            }
        }
        Ok(best.expect("at least one candidate"))
    }

    /// A half turn about one of the part's axes can fit the seen surface almost as well (a tee
    /// whose boss is hidden): the winner is judged against its three half turns with the dense
    /// depth test, which sees the surface each would put where the scan saw free space.
    fn resolve_half_turns(&self, best: Tried) -> Result<Tried> {
        let target = &self.model.target;
        let t_scene_model0 = best.1.inverse();
        // A turn that the quick check on the probe already puts well behind is dropped.
        let quick_winner = self.coarse_score(&best.1, &self.probe);
        let mut winner = best;
        for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
            let turned = self.turned(&t_scene_model0, axis, PI);
            let rough = icp(&self.probe, target, &turned.inverse(), &self.quick)?;
            if self.coarse_score(&rough.t_target_source, &self.probe) < self.params.half_turn_drop * quick_winner {
                continue;
            }
            let fit = icp(&self.sample, target, &rough.t_target_source, &self.short)?;
            let s = self.fine_score(&fit.t_target_source);
            if s > winner.0 + self.params.half_turn_margin {
                winner = (s, fit.t_target_source, turned);
            }
        }
        Ok(winner)
    }
}

/// Sorts scored readings, highest score first.
fn sort_best_first(ranked: &mut [(f64, Isometry3<f64>)]) {
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
}

/// The readings with duplicates removed: rotations within `angle` (rad) and translations
/// within `shift` (mm) of a kept one are the same pose.
fn unique_readings(candidates: &[Isometry3<f64>], angle: f64, shift: f64) -> Vec<Isometry3<f64>> {
    // Rotations within θ have unit quaternions with |q₁·q₂| > cos θ/2.
    let same = (angle / 2.0).cos();
    let mut unique: Vec<Isometry3<f64>> = Vec::with_capacity(candidates.len());
    for c in candidates {
        if !unique.iter().any(|u| {
            u.rotation.coords.dot(&c.rotation.coords).abs() > same
                && (u.translation.vector - c.translation.vector).norm() < shift
        }) {
            unique.push(*c);
        }
    }
    unique
}

/// The best-ranked reading of each cluster of rotations within `angle` (rad) of each other.
fn distinct_rotations(ranked: Vec<(f64, Isometry3<f64>)>, angle: f64) -> Vec<(f64, Isometry3<f64>)> {
    let near = (angle / 2.0).cos();
    let mut distinct: Vec<(f64, Isometry3<f64>)> = Vec::with_capacity(ranked.len());
    for (sc, c) in ranked {
        if !distinct
            .iter()
            .any(|(_, d)| d.rotation.coords.dot(&c.rotation.coords).abs() > near)
        {
            distinct.push((sc, c));
        }
    }
    distinct
}

/// Fitness and inlier RMS of the refined pose, or `NoObjectFound` when too little of the
/// object lies on the posed model.
fn verify(
    object: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    t_model_scene: &Isometry3<f64>,
    tol: f64,
) -> Result<(f64, f64)> {
    let (score, rmse) = inlier_stats(object, model.fine_target(), t_model_scene, tol);
    if score < cfg.min_fitness {
        return Err(Error::NoObjectFound {
            reason: format!(
                "the best pose explains only {:.0} % of the top object's {} points within {tol:.2} mm (need {:.0} %)",
                100.0 * score,
                object.len(),
                100.0 * cfg.min_fitness
            ),
        });
    }
    Ok((score, rmse))
}
