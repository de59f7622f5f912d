//! The PPF path: point-pair-feature voting → pose clustering → ICP refinement of every
//! hypothesis → verification against the scan → non-maximum suppression → ranking by
//! pickability; finds every instance it can confirm.
//!
//! The scene is taken at three resolutions: the points left after bin removal (the depth test's
//! height map and the reported indices), a voxel grid at a third of the PPF step (normals and
//! ICP), and an even subsample at the PPF step (voting).

use super::judge::{probe_step, voxel_size, Judge};
use super::model::{PoseModel, SCREEN_REACH};
use super::scene::{scene_indices, Context};
use super::types::{CoarseMethod, Laps, PoseConfig, PoseEstimate, Timings, NOISE_SIGMAS};
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::normals::{normals_at, surfaces_at, MAX_NORMALS_K};
use crate::registration::ppf::{DetectConfig, Hypothesis, PpfModel};
use crate::registration::verify::{depth_evidence, Evidence};
use crate::registration::{icp, Convergence, IcpConfig};
use crate::search::KdIndex;
use crate::segment::remove_support_planes;
use crate::voxel::{subsample, voxel_downsample};
use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;
use std::f64::consts::FRAC_PI_2;

/// The scene prepared for detection and judging.
pub(crate) struct DetectionScene {
    /// Voxel-grid points (mean of each voxel) and their KD-tree.
    pub fine: Vec<Point>,
    pub fine_index: KdIndex,
    /// The judge every pose passes.
    pub judge: Judge,
}

impl DetectionScene {
    /// Voxel grid and normals of the context's points (the scene without the bin) for `ppf`, and
    /// the judge of the whole scene. Without a bin box, support planes wider than the part are
    /// removed from the voxel grid.
    pub fn new(ctx: &Context<'_>, ppf: &PpfModel) -> Result<Self> {
        let step = ppf.step();
        let voxel = voxel_size(step);
        let mut fine = voxel_downsample(ctx.pts, None, voxel)?.points;
        let mut removed = Vec::new();
        if ctx.cfg.bin.is_none() && fine.len() >= 50 {
            let band = (0.5 * voxel).max(1.0).max(NOISE_SIGMAS * ctx.noise);
            let (keep, planes) = remove_support_planes(&fine, ctx.model.diameter, band, 1);
            fine = keep.iter().map(|&i| fine[i]).collect();
            removed = planes;
        }
        if fine.len() < 10 {
            return Err(Error::NoObjectFound {
                reason: format!(
                    "only {} occupied {voxel:.1} mm voxels remain after removing the bin; the bin is empty",
                    fine.len()
                ),
            });
        }
        let fine_index = KdIndex::new(&fine);
        let judge = Judge::new(ctx, &fine, removed);
        Ok(DetectionScene {
            fine,
            fine_index,
            judge,
        })
    }
}

/// A refined, judged hypothesis.
#[derive(Debug, Clone)]
pub(super) struct Judged {
    pub t_scene_model: Isometry3<f64>,
    pub coarse: Isometry3<f64>,
    pub evidence: Evidence,
    pub rmse: f64,
    pub iterations: usize,
    /// Voxel points within the tolerance of the posed model (after polishing).
    pub support: Vec<usize>,
}

impl Judged {
    fn center(&self, model: &PoseModel) -> Point {
        self.t_scene_model * model.symmetries.center
    }
}

impl DetectionScene {
    /// Indices of the voxel points within the model's reach around `t_scene_model`, at most
    /// `limit` of them (evenly thinned).
    fn local(&self, model: &PoseModel, step: f64, t_scene_model: &Isometry3<f64>, limit: usize) -> Vec<usize> {
        let c = t_scene_model * model.symmetries.center;
        let mut idx: Vec<usize> = self
            .fine_index
            .within(&c, model.radius + step)
            .iter()
            .map(|n| n.index)
            .collect();
        idx.sort_unstable();
        let stride = idx.len().div_ceil(limit.max(1)).max(1);
        idx.into_iter().step_by(stride).collect()
    }

    /// A few ICP steps on a thinned neighbourhood and a cheap judgement: the screen every
    /// hypothesis passes through.
    fn screen(&self, model: &PoseModel, step: f64, start: &Isometry3<f64>) -> Option<Judged> {
        let local: Vec<Point> = self
            .local(model, step, start, 200)
            .iter()
            .map(|&i| self.fine[i])
            .collect();
        if local.len() < 12 {
            return None;
        }
        // The nearest field answers these steps where it is the screen's (see `SCREEN_REACH`).
        let quick = IcpConfig {
            approximate: model.screens_on_field(),
            ..IcpConfig::robust_plane(SCREEN_REACH * step, Convergence::SCREEN)
        };
        let r = icp(&local, model.target(), &start.inverse(), &quick).ok()?;
        let t_scene_model = r.t_target_source.inverse();
        let evidence = depth_evidence(
            model.target(),
            &self.judge.depth.heights,
            &t_scene_model,
            probe_step(model, 300),
            self.judge.depth.tol,
            false,
        );
        Some(Judged {
            t_scene_model,
            coarse: *start,
            evidence,
            rmse: f64::NAN,
            iterations: r.iterations,
            support: Vec::new(),
        })
    }

    /// Converges a screened pose on the full neighbourhood, judges it with the dense probe and
    /// collects the voxel points it explains.
    fn polish(&self, model: &PoseModel, step: f64, j: &Judged) -> Option<Judged> {
        let idx = self.local(model, step, &j.t_scene_model, 1200);
        let local: Vec<Point> = idx.iter().map(|&i| self.fine[i]).collect();
        if local.len() < 12 {
            return None;
        }
        let fine = IcpConfig::robust_plane((3.0 * self.judge.depth.tol).max(0.5 * step), Convergence::POLISH);
        let r = icp(&local, model.target(), &j.t_scene_model.inverse(), &fine).ok()?;
        let t_scene_model = r.t_target_source.inverse();
        let evidence = self.judge.depth.evidence(model, &t_scene_model);
        let tol2 = self.judge.depth.tol * self.judge.depth.tol;
        let mut sq = 0.0;
        // Every voxel point in reach, not the thinned ICP sample: supports are compared as sets.
        let support: Vec<usize> = self
            .local(model, step, &t_scene_model, usize::MAX)
            .into_iter()
            .filter_map(|i| {
                let q = r.t_target_source * self.fine[i];
                model
                    .target()
                    .search()
                    .nearest_within(&[q.x, q.y, q.z], tol2)
                    .map(|(_, d)| {
                        sq += d;
                        i
                    })
            })
            .collect();
        let rmse = if support.is_empty() {
            f64::INFINITY
        } else {
            (sq / support.len() as f64).sqrt()
        };
        Some(Judged {
            t_scene_model,
            coarse: j.coarse,
            evidence,
            rmse,
            iterations: j.iterations + r.iterations,
            support,
        })
    }
}

/// The instances the search is sized for: as many as asked, and never fewer than
/// `cfg.search_instances`, so that asking for fewer only truncates the answer.
fn search_instances(cfg: &PoseConfig) -> usize {
    cfg.max_instances.max(cfg.search_instances)
}

/// All instances found by PPF, most pickable first (at most `cfg.max_instances`), and the
/// prepared scene (for judging other methods' poses on the same terms).
pub(super) fn detect(
    ctx: &Context<'_>,
    ppf: &PpfModel,
    timings: &mut Timings,
) -> Result<(Vec<PoseEstimate>, DetectionScene)> {
    let (model, cfg) = (ctx.model, ctx.cfg);
    let mut laps = Laps::new(timings);
    let scene = DetectionScene::new(ctx, ppf)?;
    laps.lap("voxels");
    let hypotheses = vote(&scene, ctx, ppf, &mut laps)?;
    let judged = screen_and_polish(&scene, model, ppf.step(), &hypotheses, cfg, &mut laps);
    let instances = one_pose_per_instance(judged, &scene, model);
    if instances.is_empty() {
        return Err(Error::NoObjectFound {
            reason: format!(
                "none of {} pose hypotheses was confirmed by the scan (need {:.0} % of the predicted visible surface seen, most of it over scanned cells, and no pose through the bin)",
                hypotheses.len(),
                100.0 * cfg.min_coverage
            ),
        });
    }
    let out = estimates(instances, ctx, scene.judge.depth.tol);
    laps.lap("verification");
    Ok((out, scene))
}

/// Neighbours a voting sample's normal is fitted to, at least.
const NORMAL_NEIGHBOURS: usize = 10;
/// A voting sample's normal may tilt by noise this much (radians, a standard deviation): under
/// the 6° of one angle bin of the feature table.
const NORMAL_TILT: f64 = 0.08;

/// Neighbours a voting normal is fitted to on voxels `voxel` mm apart with depth noise σ `noise`
/// mm: a plane through k points of a disc (radius about voxel·√(k/π)) tilts by about
/// 2σ / (r √k) = 2√π σ / (voxel k), so k ≥ 2√π σ / (voxel · [`NORMAL_TILT`]); at least
/// [`NORMAL_NEIGHBOURS`], at most [`MAX_NORMALS_K`].
fn normal_neighbours(noise: f64, voxel: f64) -> usize {
    let k = 2.0 * std::f64::consts::PI.sqrt() * noise / (voxel * NORMAL_TILT);
    if k.is_finite() {
        (k.ceil() as usize).clamp(NORMAL_NEIGHBOURS, MAX_NORMALS_K)
    } else {
        NORMAL_NEIGHBOURS
    }
}

/// Pose hypotheses from the votes of the voxel grid's even subsample at the PPF step.
fn vote(scene: &DetectionScene, ctx: &Context<'_>, ppf: &PpfModel, laps: &mut Laps<'_>) -> Result<Vec<Hypothesis>> {
    let cfg = ctx.cfg;
    let keep = subsample(&scene.fine, ppf.step());
    let mut sparse: Vec<Point> = keep.iter().map(|&i| scene.fine[i]).collect();
    // Only the voting samples need normals (ICP uses the model's). Where the noise widens their
    // neighbourhoods, the samples move onto the fitted surface too: a pair's distance is a
    // feature, quantised in PPF steps not much larger than the noise.
    let k = normal_neighbours(ctx.noise, voxel_size(ppf.step()));
    let sparse_normals = if k > NORMAL_NEIGHBOURS {
        let fitted = surfaces_at(&sparse, &scene.fine, &scene.fine_index, k, ctx.facing);
        sparse = fitted.iter().map(|f| f.0).collect();
        fitted.into_iter().map(|f| f.1).collect()
    } else {
        normals_at(&sparse, &scene.fine, &scene.fine_index, k, ctx.facing)
    };
    let sparse_index = KdIndex::new(&sparse);
    laps.lap("normals");
    let detect_cfg = DetectConfig {
        max_hypotheses: cfg.detect.max_hypotheses.max(8 * search_instances(cfg)),
        ..cfg.detect
    };
    let votes = ppf.vote(&sparse, &sparse_normals, &sparse_index, &detect_cfg);
    laps.lap("voting");
    let hypotheses = ppf.cluster(&votes, &ctx.model.symmetries, &detect_cfg);
    laps.lap("clustering");
    if hypotheses.is_empty() {
        return Err(Error::NoObjectFound {
            reason: format!("no point pair of the {} scene samples matched the model", sparse.len()),
        });
    }
    Ok(hypotheses)
}

/// Screened poses closer than this (rad, and a PPF step apart at most) are one pose.
const SAME_POSE_ANGLE: f64 = 0.05;

/// Screens every hypothesis and converges the most promising few, spread over distinct places
/// (a pile's best hypotheses crowd on one part).
fn screen_and_polish(
    scene: &DetectionScene,
    model: &PoseModel,
    step: f64,
    hypotheses: &[Hypothesis],
    cfg: &PoseConfig,
    laps: &mut Laps<'_>,
) -> Vec<Judged> {
    let mut screened: Vec<Judged> = hypotheses
        .par_iter()
        .filter_map(|h| scene.screen(model, step, &h.t_scene_model))
        .collect();
    screened.sort_by(|a, b| b.evidence.quality().total_cmp(&a.evidence.quality()));
    let polish_count = 2 * search_instances(cfg) + 1;
    let min_gap = 0.5 * model.thickness;
    let mut chosen: Vec<&Judged> = Vec::with_capacity(polish_count);
    for j in &screened {
        if chosen.len() >= polish_count {
            break;
        }
        // (distance, angle) to each chosen pose at this place.
        let near: Vec<(f64, f64)> = chosen
            .iter()
            .map(|k| {
                let d = (k.center(model) - j.center(model)).norm();
                (d, k.t_scene_model.rotation.angle_to(&j.t_scene_model.rotation))
            })
            .filter(|&(d, _)| d < min_gap)
            .collect();
        // Many hypotheses screen onto one pose: a copy of a chosen pose would take a slot from a
        // distinct one. Two slots per place, and a third for another side of the part, more
        // than a quarter turn from both chosen there: a near-symmetric part's flip can outscore
        // the truth at screening (a tee standing against a wall, its flip through the wall).
        let copy = near.iter().any(|&(d, a)| d < step && a < SAME_POSE_ANGLE);
        let other_side = near.len() == 2 && near.iter().all(|&(_, a)| a > FRAC_PI_2);
        if !copy && (near.len() < 2 || other_side) {
            chosen.push(j);
        }
    }
    laps.lap("screening");
    let judged = chosen.par_iter().filter_map(|j| scene.polish(model, step, j)).collect();
    laps.lap("icp");
    judged
}

/// The accepted, physically possible poses, one per instance: the pose that explains most of
/// the scan (discounted for violations and for surface over cells without data) claims its
/// points first, and a pose whose points are mostly claimed already is the same instance (or
/// a ghost made of its points).
fn one_pose_per_instance(mut judged: Vec<Judged>, scene: &DetectionScene, model: &PoseModel) -> Vec<Judged> {
    let claim = |j: &Judged| j.support.len() as f64 * (j.evidence.coverage() * j.evidence.supported_fraction()).powi(2);
    judged.sort_by(|a, b| claim(b).total_cmp(&claim(a)));
    let mut owner = vec![false; scene.fine.len()];
    let mut instances: Vec<Judged> = Vec::new();
    for j in judged {
        // The claim test first: it is cheap, and a hypothesis whose points are claimed already
        // is no new instance whatever the judge says of it.
        let shared = j.support.iter().filter(|&&i| owner[i]).count();
        if j.support.len() < 12 || shared as f64 > 0.3 * j.support.len() as f64 {
            continue;
        }
        let Ok((t_scene_model, evidence)) = scene.judge.accept(j.evidence, model, &j.t_scene_model) else {
            continue;
        };
        let j = Judged {
            t_scene_model,
            evidence,
            ..j
        };
        for &i in &j.support {
            owner[i] = true;
        }
        instances.push(j);
    }
    instances
}

/// The most pickable instances as estimates, with the indices of the context's points on each.
fn estimates(instances: Vec<Judged>, ctx: &Context<'_>, tol: f64) -> Vec<PoseEstimate> {
    let (points, model) = (ctx.pts, ctx.model);
    rank(instances, model, &ctx.up)
        .into_iter()
        .take(ctx.cfg.max_instances.max(1))
        .map(|(j, pick)| {
            let t_scene_model = model.symmetries.canonical(&j.t_scene_model);
            let indices = scene_indices(points, model, &t_scene_model, tol);
            let score = j.evidence.coverage();
            PoseEstimate {
                pickability: Some(pick),
                ..PoseEstimate::verified(
                    CoarseMethod::Ppf,
                    t_scene_model,
                    j.coarse,
                    &j.evidence,
                    (score, j.rmse),
                    j.iterations,
                    indices,
                )
            }
        })
        .collect()
}

/// An instance with more than this share of its facing surface under other objects is covered.
const COVERED: f64 = 0.1;

/// Pickability in [0, 1]: height among the instances (half), the confirmed share of the facing
/// surface (a third) and freedom from parts on top (a sixth). Returns the instances with their
/// pickability, uncovered instances first (a covered part is not picked while an uncovered one
/// lies free), then most pickable first. `up` is the unit direction toward the sensor.
fn rank(instances: Vec<Judged>, model: &PoseModel, up: &Vector3<f64>) -> Vec<(Judged, f64)> {
    let heights: Vec<f64> = instances.iter().map(|j| j.center(model).coords.dot(up)).collect();
    let (lo, hi) = heights
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| (l.min(v), h.max(v)));
    let span = (hi - lo).max(0.25 * model.diameter);
    let mut ranked: Vec<(Judged, f64)> = instances
        .into_iter()
        .zip(heights)
        .map(|(j, h)| {
            let e = &j.evidence;
            let pick = 0.5 * (1.0 - (hi - h) / span).max(0.0)
                + (1.0 / 3.0) * e.visible_fraction().min(1.0)
                + (1.0 / 6.0) * (1.0 - e.occluded_fraction().min(1.0));
            (j, pick)
        })
        .collect();
    let key = |(j, pick): &(Judged, f64)| pick + f64::from(u8::from(j.evidence.occluded_fraction() <= COVERED));
    ranked.sort_by(|a, b| key(b).total_cmp(&key(a)));
    ranked
}
