//! The paper's path: top-object segmentation (Table 2) → CCP (or the centroid baseline) →
//! ICP → verification.

use super::scene::scene_indices;
use super::{CoarseMethod, PoseConfig, PoseEstimate, PoseModel};
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::normals::{estimate_normals, Orientation};
use crate::registration::ccp::ccp;
use crate::registration::verify::{coarse_inlier_fraction, depth_evidence, inlier_stats, HeightMap};
use crate::registration::{icp, IcpConfig, RobustKernel};
use crate::search::KdIndex;
use crate::segment::{scan_spacing, segment_top, SegmentConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::time::Instant;

/// CCP candidates (the best-prescored of distinct rotations) that get the stage-one ICP check.
const STAGE_ONE: usize = 8;

/// Readings the first, cheap tier of scoring passes on to the second.
const SECOND_TIER: usize = 32;

/// Object points the coarse checks judge a pose by (fewer than about 100 cannot tell a wrong
/// reading of a partial view from the right one), and model points their depth test probes.
const PROBE_POINTS: usize = 150;
const MODEL_PROBES: usize = 100;

/// Object points the candidates that survive the quick check converge on.
const SAMPLE_POINTS: usize = 160;

/// Regions tried, top first, before the pipeline gives up.
const MAX_REGIONS: usize = 8;

/// The paper's path on the points left after bin removal: top-object segmentation → CCP (or
/// the centroid baseline) → ICP → verification. Indices in the result refer to `pts`.
pub(super) fn run(
    scene: &[Point],
    pts: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    method: CoarseMethod,
    timings: &mut Vec<(&'static str, f64)>,
) -> Result<PoseEstimate> {
    let mut clock = Instant::now();
    let mut lap = |name: &'static str, timings: &mut Vec<(&'static str, f64)>| {
        timings.push((name, clock.elapsed().as_secs_f64() * 1e3));
        clock = Instant::now();
    };
    let up = cfg.up.normalize();
    let index = KdIndex::new(pts);
    let sampling = scan_spacing(pts, &index);
    let spacing = sampling.along.max(1e-3);
    let across = sampling.across.max(spacing);
    // Normals need neighbours from more than one scan line.
    let k = ((8.0 * across / spacing).round() as usize).clamp(12, 64).min(pts.len());
    let normals = estimate_normals(pts, &index, k, Orientation::TowardDirection(up))?;
    lap("normals", timings);
    let visible_points = (0.5 * model.area / (spacing * across)).max(1.0);
    let seg_cfg = SegmentConfig {
        d_star: cfg.d_star.unwrap_or((3.0 * spacing).max(1.6 * across)),
        min_points: cfg.min_points.unwrap_or(((0.1 * visible_points) as usize).max(15)),
        max_normal_angle: cfg.max_normal_angle,
        max_extent: 1.1 * model.diameter,
        up,
    };
    // Table 2 with one addition: a region that no pose explains (a bin rim, a sliver of a part
    // deep below others) is set aside and the next top region tried.
    let mut excluded = vec![false; pts.len()];
    let mut last_failure: Option<Error> = None;
    for _ in 0..MAX_REGIONS {
        let region = match segment_top(&pts, Some(&normals), &index, &seg_cfg, Some(&excluded)) {
            Ok(r) => r,
            Err(e) => return Err(last_failure.unwrap_or(e)),
        };
        let mut fit = |timings: &mut Vec<(&'static str, f64)>| -> Result<PoseEstimate> {
            let object: Vec<Point> = region.iter().map(|&i| pts[i]).collect();
            lap("segmentation", timings);
            // A flat region wider than the part (a bin rim, a wall left in the scan) is not the part.
            let (_, cov) = crate::geometry::covariance(&object);
            let (vals, axes) = crate::geometry::principal_axes(&cov);
            let along: Vec<f64> = object.iter().map(|p| p.coords.dot(&axes[0])).collect();
            let span = along.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
                - along.iter().cloned().fold(f64::INFINITY, f64::min);
            if span > 1.05 * model.diameter && vals[2].sqrt() < 0.02 * model.diameter {
                return Err(Error::NoObjectFound {
                    reason: format!(
                        "the top region is flat and {span:.0} mm wide, wider than the part ({:.0} mm)",
                        model.diameter
                    ),
                });
            }

            // Coarse pose candidates, model → scene.
            let candidates: Vec<Isometry3<f64>> = match (method, &model.layout) {
                (CoarseMethod::Ccp, Some(layout)) => {
                    ccp(
                        &object,
                        layout,
                        model.target.points(),
                        model.target.normals().unwrap_or(&[]),
                        Some(up),
                        &cfg.ccp,
                    )?
                    .candidates
                }
                (CoarseMethod::Ccp, None) => {
                    return Err(Error::invalid("model", "CCP needs the model's branch layout (cylindrical branches from a junction); declare branches on the Model or use method=\"centroid\""));
                }
                _ => {
                    let c_obj = crate::geometry::centroid(&object);
                    let c_model = crate::geometry::centroid(model.target.points());
                    vec![Isometry3::from_parts(
                        Translation3::from(c_obj - c_model),
                        UnitQuaternion::identity(),
                    )]
                }
            };
            lap("coarse", timings);

            // Score every candidate cheaply (object points on the model × expected-visible model points
            // on the scene), check the best few with a short ICP, and refine the winner on all points.
            let tol = cfg
                .inlier_distance
                .unwrap_or((2.0 * model.spacing + 1.5 * spacing.min(2.0 * model.spacing)).max(1.0));
            let step = object.len().div_ceil(SAMPLE_POINTS);
            let sample: Vec<Point> = object.iter().step_by(step).copied().collect();
            let heights = HeightMap::new(scene, &up, (1.5 * across).max(0.5));
            let coarse_model_step = model.target.points().len().div_ceil(MODEL_PROBES);
            let fine_step = (model.target.points().len() / 4000).max(1);
            let score_with = |t_model_scene: &Isometry3<f64>, probe: &[Point], tol: f64, model_step: usize| -> f64 {
                let on_model = inlier_stats(probe, &model.target, t_model_scene, tol).0;
                on_model
                    * depth_evidence(
                        &model.target,
                        &heights,
                        &t_model_scene.inverse(),
                        model_step,
                        tol,
                        false,
                    )
                    .coverage()
            };
            let score_of = |t: &Isometry3<f64>, probe: &[Point], tol: f64| {
                coarse_inlier_fraction(probe, &model.target, t, tol)
                    * depth_evidence(&model.target, &heights, &t.inverse(), coarse_model_step, tol, false).coverage()
            };
            let coarse_tol = (0.08 * model.diameter).max(2.0 * tol);
            let probe: Vec<Point> = object
                .iter()
                .step_by(object.len().div_ceil(PROBE_POINTS))
                .copied()
                .collect();
            // Readings that give the same pose (within 5° and 5 % of the part) are scored once.
            let same = 2.5f64.to_radians().cos();
            let mut unique: Vec<Isometry3<f64>> = Vec::with_capacity(candidates.len());
            for c in &candidates {
                if !unique.iter().any(|u| {
                    u.rotation.coords.dot(&c.rotation.coords).abs() > same
                        && (u.translation.vector - c.translation.vector).norm() < 0.05 * model.diameter
                }) {
                    unique.push(*c);
                }
            }
            // Two tiers: a third of the probe sorts out the readings that are plainly wrong, the
            // whole probe ranks the rest.
            let glance: Vec<Point> = probe.iter().step_by(3).copied().collect();
            let mut ranked: Vec<(f64, Isometry3<f64>)> = unique
                .iter()
                .map(|c| (score_of(&c.inverse(), &glance, coarse_tol), *c))
                .collect();
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            ranked.truncate(SECOND_TIER);
            for r in ranked.iter_mut() {
                r.0 = score_of(&r.1.inverse(), &probe, coarse_tol);
            }
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            // Views of a part on its side leave the coarse pose ambiguous up to a quarter or half turn
            // about one of the part's axes; add those turns of the best two candidates before the ICP check.
            let c_model = crate::geometry::centroid(model.target.points()).coords;
            let with_turns = if method == CoarseMethod::Ccp { 2 } else { 0 };
            let flips: Vec<Isometry3<f64>> = ranked
                .iter()
                .take(with_turns)
                .flat_map(|(_, c)| {
                    let turns = [1.0, 0.5, -0.5].map(|k| k * std::f64::consts::PI);
                    [Vector3::x(), Vector3::y(), Vector3::z()]
                        .into_iter()
                        .flat_map(move |axis| {
                            turns.map(|angle| {
                                let r = UnitQuaternion::from_scaled_axis(axis * angle);
                                c * Isometry3::from_parts(Translation3::from(c_model - r * c_model), r)
                            })
                        })
                })
                .collect();
            for f in flips {
                ranked.push((score_of(&f.inverse(), &probe, coarse_tol), f));
            }
            ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
            let short = IcpConfig {
                kernel: RobustKernel::Tukey((0.1 * model.diameter).max(3.0 * tol)),
                approximate: true,
                ..IcpConfig::robust_plane((0.25 * model.diameter).max(3.0 * tol), 12, 1e-4, 1e-2)
            };
            // Many readings give nearly the same rotation; keep the best-ranked of each 15° cluster.
            let mut distinct: Vec<(f64, Isometry3<f64>)> = Vec::with_capacity(ranked.len());
            // Rotations within 15° have unit quaternions with |q₁·q₂| > cos 7.5°.
            let near = 7.5f64.to_radians().cos();
            for (sc, c) in ranked {
                if !distinct
                    .iter()
                    .any(|(_, d)| d.rotation.coords.dot(&c.rotation.coords).abs() > near)
                {
                    distinct.push((sc, c));
                }
            }
            let ranked = distinct;
            // Stage one: the best-prescored hypotheses get a few ICP steps on a small probe (a coarse
            // pose tens of degrees off still lands in the right basin, but cannot be judged before moving it).
            let quick = IcpConfig {
                max_iterations: 6,
                ..short.clone()
            };
            let mut tried: Vec<(f64, Isometry3<f64>, Isometry3<f64>)> = Vec::with_capacity(ranked.len());
            for (_, cand) in ranked.iter().take(STAGE_ONE) {
                let r = icp(&probe, &model.target, &cand.inverse(), &quick)?;
                tried.push((
                    score_of(&r.t_target_source, &probe, coarse_tol),
                    r.t_target_source,
                    *cand,
                ));
            }
            tried.sort_by(|a, b| b.0.total_cmp(&a.0));
            let mut best: Option<(f64, Isometry3<f64>, Isometry3<f64>)> = None;
            // Stage two: the best three converge on a larger sample and are judged at the inlier
            // distance (those far behind the leader after stage one are not worth it).
            let lead = tried[0].0;
            for (_, t0, cand) in tried.iter().take(3).filter(|t| t.0 >= 0.7 * lead) {
                let r = icp(&sample, &model.target, t0, &short)?;
                let s = score_with(&r.t_target_source, &sample, tol, fine_step);
                if best.as_ref().map_or(true, |b| s > b.0) {
                    best = Some((s, r.t_target_source, *cand));
                }
            }
            // A half turn about one of the part's axes can fit the seen surface almost as well (a tee
            // whose boss is hidden); judge the winner against its three half turns with the dense
            // depth test, which sees the surface each would put where the scan saw free space.
            if method == CoarseMethod::Ccp {
                let (s0, t0, cand) = best.expect("at least one candidate");
                let t_scene_model0 = t0.inverse();
                let mut winner = (s0, t0, cand);
                // A turn that the quick check on the probe already puts well behind is dropped.
                let quick_winner = score_of(&t0, &probe, coarse_tol);
                for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
                    let r = UnitQuaternion::from_scaled_axis(axis * std::f64::consts::PI);
                    let turned = t_scene_model0 * Isometry3::from_parts(Translation3::from(c_model - r * c_model), r);
                    let rough = icp(&probe, &model.target, &turned.inverse(), &quick)?;
                    if score_of(&rough.t_target_source, &probe, coarse_tol) < 0.8 * quick_winner {
                        continue;
                    }
                    let fit = icp(&sample, &model.target, &rough.t_target_source, &short)?;
                    let s = score_with(&fit.t_target_source, &sample, tol, fine_step);
                    if s > winner.0 + 0.01 {
                        winner = (s, fit.t_target_source, turned);
                    }
                }
                best = Some(winner);
            }
            let (_, t_model_scene0, coarse) = best.expect("at least one candidate");
            // Stops at 0.0006° and a micrometre: far below what the scan can resolve.
            let fine = IcpConfig::robust_plane(3.0 * tol, 60, 1e-5, 1e-3);
            let refined = icp(&object, model.fine_target(), &t_model_scene0, &fine)?;
            let t_model_scene = refined.t_target_source;
            lap("icp", timings);

            let (score, rmse) = inlier_stats(&object, model.fine_target(), &t_model_scene, tol);
            if score < cfg.min_fitness {
                return Err(Error::NoObjectFound {
                reason: format!("the best pose explains only {:.0} % of the top object's {} points within {tol:.2} mm (need {:.0} %)", 100.0 * score, object.len(), 100.0 * cfg.min_fitness),
            });
            }
            let t_scene_model = t_model_scene.inverse();
            let indices = scene_indices(pts, model, &t_scene_model, tol);
            lap("verification", timings);
            Ok(PoseEstimate {
                t_scene_model: model.symmetries.canonical(&t_scene_model),
                t_scene_model_coarse: coarse,
                score,
                rmse,
                indices,
                timings: Vec::new(),
                iterations: refined.iterations,
                method,
                visible_fraction: f64::NAN,
                occluded_fraction: f64::NAN,
                pickability: 1.0,
            })
        };
        match fit(timings) {
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
