//! The pose pipeline: bin removal → top-object segmentation → coarse pose (CCP or the paper's
//! centroid baseline) → ICP of the scene points onto the dense model → verification.
//!
//! Frames: ICP registers the object's scene points onto the model (as the paper does, Eq. 6),
//! giving `T_model_scene`; the result reports its inverse `T_scene_model` (model → scene). A
//! result is returned only when enough of the object's points lie on the posed model;
//! otherwise the pipeline answers `NoObjectFound` rather than a guess.

use crate::cloud::{check_finite, Point};
use crate::error::{Error, Result};
use crate::knn::KdIndex;
use crate::normals::{estimate_normals, Orientation};
use crate::registration::ccp::{ccp, BranchLayout, CcpConfig};
use crate::registration::{icp, IcpConfig, IcpMethod, IcpTarget, RobustKernel};
use crate::segment::{crop_to_bin, point_spacing, remove_support_planes, scan_spacing, segment_top, BinBox, SegmentConfig};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::time::Instant;

/// Regions tried, top first, before the pipeline gives up.
const MAX_REGIONS: usize = 8;

/// How the coarse pose is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoarseMethod {
    /// The paper's CCP (needs a branch layout).
    Ccp,
    /// The paper's baseline: ICP started from the centroids with the model's own orientation.
    Centroid,
}

/// A model prepared for pose estimation: dense points with normals and their search structure.
pub struct PoseModel {
    target: IcpTarget,
    /// Largest extent of the part, mm.
    pub diameter: f64,
    /// Surface area, mm².
    pub area: f64,
    /// Branch layout for CCP, if the part has one.
    pub layout: Option<BranchLayout>,
    /// Median spacing of the model's samples, mm.
    pub spacing: f64,
}

impl PoseModel {
    /// Prepares a model from its surface samples (mm) and outward unit normals.
    pub fn new(points: Vec<Point>, normals: Vec<Vector3<f64>>, diameter: f64, area: f64, layout: Option<BranchLayout>) -> Result<Self> {
        if !(diameter.is_finite() && diameter > 0.0) {
            return Err(Error::invalid("model", "the model's diameter must be positive"));
        }
        let spacing = point_spacing(&points, &KdIndex::new(&points));
        Ok(PoseModel { target: IcpTarget::new(points, Some(normals))?, diameter, area, layout, spacing })
    }
}

/// Parameters of [`estimate_pose`]; `None` fields take defaults derived from the scan's point
/// spacing and the model's size.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseConfig {
    /// The bin box in the scene frame; without it, support planes are found and removed.
    pub bin: Option<BinBox>,
    /// Direction toward the sensor (scene +z by default).
    pub up: Vector3<f64>,
    /// Coarse-pose method.
    pub method: CoarseMethod,
    /// d* of segmentation, mm (default: 3 × the scan's point spacing, at least 1.6 × the spacing
    /// across scan lines).
    pub d_star: Option<f64>,
    /// Smallest object region, points (default: a tenth of the points the model's visible half
    /// would give at the scan's sampling, at least 15).
    pub min_points: Option<usize>,
    /// Largest angle between neighbouring normals inside one object, radians.
    pub max_normal_angle: f64,
    /// Inlier distance for verification, mm (default: 2 × the model's sample spacing plus
    /// 1.5 × the scan's, at least 1 mm — it judges scan points against the dense model).
    pub inlier_distance: Option<f64>,
    /// Smallest fraction of the object's points that must lie on the posed model.
    pub min_fitness: f64,
    /// CCP tuning.
    pub ccp: CcpConfig,
    /// Worker threads; 0 = all cores.
    pub num_threads: usize,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            bin: None,
            up: Vector3::z(),
            method: CoarseMethod::Ccp,
            d_star: None,
            min_points: None,
            max_normal_angle: 70f64.to_radians(),
            inlier_distance: None,
            min_fitness: 0.6,
            ccp: CcpConfig::default(),
            num_threads: 0,
        }
    }
}

/// A verified pose.
#[derive(Debug, Clone)]
pub struct PoseEstimate {
    /// Model (mesh) frame → scene frame.
    pub t_scene_model: Isometry3<f64>,
    /// The coarse pose before ICP, model → scene.
    pub t_scene_model_coarse: Isometry3<f64>,
    /// Fraction of the object's points within the inlier distance of the posed model, in [0, 1].
    pub score: f64,
    /// RMS distance of those inliers, mm.
    pub rmse: f64,
    /// Scene indices of the points on the posed model.
    pub indices: Vec<usize>,
    /// Milliseconds per stage, in order.
    pub timings: Vec<(&'static str, f64)>,
    /// ICP iterations of the refinement.
    pub iterations: usize,
}

/// Estimates the pose of the top object of `scene` (N×3, mm) against `model`.
pub fn estimate_pose(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<PoseEstimate> {
    crate::parallel::with_threads(cfg.num_threads, || run(scene, model, cfg))
}

fn run(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<PoseEstimate> {
    let mut timings = Vec::new();
    let mut clock = Instant::now();
    let mut lap = |name: &'static str, timings: &mut Vec<(&'static str, f64)>| {
        timings.push((name, clock.elapsed().as_secs_f64() * 1e3));
        clock = Instant::now();
    };
    check_finite("scene", scene)?;
    if scene.len() < 10 {
        return Err(Error::TooFewPoints { arg: "scene".into(), got: scene.len(), needed: 10, hint: "; pass the scan's points".into() });
    }
    if !(cfg.up.norm() > 0.0) {
        return Err(Error::invalid("up", "must be a non-zero direction"));
    }
    let up = cfg.up.normalize();
    let (lo, hi) = scene.iter().fold((scene[0], scene[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let extent = (hi - lo).norm();
    if extent < 0.2 * model.diameter {
        return Err(Error::invalid(
            "scene",
            format!(
                "the scene is {extent:.3} mm across but the model is {:.1} mm: is the scene in metres? Pass millimetres (multiply by 1000) or load the model with the scene's unit",
                model.diameter
            ),
        ));
    }
    // Bin removal.
    let kept: Vec<usize> = match &cfg.bin {
        Some(bin) => crop_to_bin(scene, bin, 1.0)?,
        None => {
            let idx = KdIndex::new(scene);
            let tol = (2.0 * point_spacing(scene, &idx)).max(0.5);
            remove_support_planes(scene, model.diameter, tol, 1).0
        }
    };
    lap("bin_removal", &mut timings);
    if kept.len() < 10 {
        return Err(Error::NoObjectFound { reason: format!("only {} points remain after removing the bin; the bin is empty", kept.len()) });
    }
    let pts: Vec<Point> = kept.iter().map(|&i| scene[i]).collect();
    let index = KdIndex::new(&pts);
    let sampling = scan_spacing(&pts, &index);
    let spacing = sampling.along.max(1e-3);
    let across = sampling.across.max(spacing);
    // Normals need neighbours from more than one scan line.
    let k = ((12.0 * across / spacing).round() as usize).clamp(12, 64).min(pts.len());
    let normals = estimate_normals(&pts, &index, k, Orientation::TowardDirection(up))?;
    lap("normals", &mut timings);
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
        let (_, cov) = crate::cloud::covariance(&object);
        let (vals, axes) = crate::cloud::principal_axes(&cov);
        let along: Vec<f64> = object.iter().map(|p| p.coords.dot(&axes[0])).collect();
        let span = along.iter().cloned().fold(f64::NEG_INFINITY, f64::max) - along.iter().cloned().fold(f64::INFINITY, f64::min);
        if span > 1.05 * model.diameter && vals[2].sqrt() < 0.02 * model.diameter {
            return Err(Error::NoObjectFound { reason: format!("the top region is flat and {span:.0} mm wide, wider than the part ({:.0} mm)", model.diameter) });
        }

        // Coarse pose candidates, model → scene.
        let candidates: Vec<Isometry3<f64>> = match (cfg.method, &model.layout) {
            (CoarseMethod::Ccp, Some(layout)) => ccp(&object, layout, model.target.points(), model.target.normals().unwrap_or(&[]), Some(up), &cfg.ccp)?.candidates,
            (CoarseMethod::Ccp, None) => {
                return Err(Error::invalid("model", "CCP needs the model's branch layout (cylindrical branches from a junction); declare branches on the Model or use method=\"centroid\""));
            }
            (CoarseMethod::Centroid, _) => {
                let c_obj = crate::cloud::centroid(&object);
                let c_model = crate::cloud::centroid(model.target.points());
                vec![Isometry3::from_parts(Translation3::from(c_obj - c_model), UnitQuaternion::identity())]
            }
        };
        lap("coarse", timings);

        // Score every candidate cheaply (object points on the model × expected-visible model points
        // on the scene), check the best few with a short ICP, and refine the winner on all points.
        let tol = cfg.inlier_distance.unwrap_or((2.0 * model.spacing + 1.5 * spacing.min(2.0 * model.spacing)).max(1.0));
        let step = (object.len() / 600).max(1);
        let sample: Vec<Point> = object.iter().step_by(step).copied().collect();
        let heights = HeightMap::new(scene, &up, (1.5 * across).max(0.5));
        let model_step = (model.target.points().len() / 400).max(1);
        let fine_step = (model.target.points().len() / 4000).max(1);
        let score_with = |t_model_scene: &Isometry3<f64>, probe: &[Point], tol: f64, model_step: usize| -> f64 {
            let on_model = inlier_stats(probe, &model.target, t_model_scene, tol).0;
            on_model * coverage(model, &heights, &t_model_scene.inverse(), model_step, tol)
        };
        let score_of = |t: &Isometry3<f64>, probe: &[Point], tol: f64| score_with(t, probe, tol, model_step);
        let coarse_tol = (0.08 * model.diameter).max(2.0 * tol);
        let prescore_step = (object.len() / 150).max(1);
        let probe: Vec<Point> = object.iter().step_by(prescore_step).copied().collect();
        let mut ranked: Vec<(f64, Isometry3<f64>)> = candidates.iter().map(|c| (score_of(&c.inverse(), &probe, coarse_tol), *c)).collect();
        ranked.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Views of a part on its side leave the coarse pose ambiguous up to a quarter or half turn
        // about one of the part's axes; add those turns of the best two candidates before the ICP check.
        let c_model = crate::cloud::centroid(model.target.points()).coords;
        let with_turns = if cfg.method == CoarseMethod::Ccp { 2 } else { 0 };
        let flips: Vec<Isometry3<f64>> = ranked
            .iter()
            .take(with_turns)
            .flat_map(|(_, c)| {
                let turns = [1.0, 0.5, -0.5].map(|k| k * std::f64::consts::PI);
                [Vector3::x(), Vector3::y(), Vector3::z()].into_iter().flat_map(move |axis| {
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
            method: IcpMethod::PointToPlane,
            max_correspondence_distance: (0.25 * model.diameter).max(3.0 * tol),
            max_iterations: 20,
            rotation_tolerance: 1e-4,
            translation_tolerance: 1e-2,
            kernel: RobustKernel::Tukey((0.1 * model.diameter).max(3.0 * tol)),
            num_threads: 0,
            ..Default::default()
        };
        // Many readings give nearly the same rotation; keep the best-ranked of each 15° cluster.
        let mut distinct: Vec<(f64, Isometry3<f64>)> = Vec::with_capacity(ranked.len());
        for (sc, c) in ranked {
            if !distinct.iter().any(|(_, d)| d.rotation.angle_to(&c.rotation) < 15f64.to_radians()) {
                distinct.push((sc, c));
            }
        }
        let ranked = distinct;
        // Stage one: every hypothesis gets a few ICP steps on a small probe (a coarse pose tens of
        // degrees off still lands in the right basin, but cannot be judged before moving it).
        let quick = IcpConfig { max_iterations: 8, ..short.clone() };
        let mut tried: Vec<(f64, Isometry3<f64>, Isometry3<f64>)> = Vec::with_capacity(ranked.len());
        for (_, cand) in &ranked {
            let r = icp(&probe, &model.target, &cand.inverse(), &quick)?;
            tried.push((score_of(&r.t_target_source, &probe, coarse_tol), r.t_target_source, *cand));
        }
        tried.sort_by(|a, b| b.0.total_cmp(&a.0));
        // Stage two: the best three converge on a larger sample and are judged at the inlier distance.
        let mut best: Option<(f64, Isometry3<f64>, Isometry3<f64>)> = None;
        for (_, t0, cand) in tried.iter().take(3) {
            let r = icp(&sample, &model.target, t0, &short)?;
            let s = score_with(&r.t_target_source, &sample, tol, fine_step);
            if best.as_ref().map_or(true, |b| s > b.0) {
                best = Some((s, r.t_target_source, *cand));
            }
        }
        // A half turn about one of the part's axes can fit the seen surface almost as well (a tee
        // whose boss is hidden); judge the winner against its three half turns with the dense
        // depth test, which sees the surface each would put where the scan saw free space.
        if cfg.method == CoarseMethod::Ccp {
            let (s0, t0, cand) = best.expect("at least one candidate");
            let t_scene_model0 = t0.inverse();
            let mut winner = (s0, t0, cand);
            for axis in [Vector3::x(), Vector3::y(), Vector3::z()] {
                let r = UnitQuaternion::from_scaled_axis(axis * std::f64::consts::PI);
                let turned = t_scene_model0 * Isometry3::from_parts(Translation3::from(c_model - r * c_model), r);
                let fit = icp(&sample, &model.target, &turned.inverse(), &short)?;
                let s = score_with(&fit.t_target_source, &sample, tol, fine_step);
                if s > winner.0 + 0.01 {
                    winner = (s, fit.t_target_source, turned);
                }
            }
            best = Some(winner);
        }
        let (_, t_model_scene0, coarse) = best.expect("at least one candidate");
        let fine = IcpConfig {
            method: IcpMethod::PointToPlane,
            max_correspondence_distance: 3.0 * tol,
            max_iterations: 60,
            rotation_tolerance: 1e-7,
            translation_tolerance: 1e-5,
            kernel: RobustKernel::Tukey(3.0 * tol),
            num_threads: 0,
            ..Default::default()
        };
        let refined = icp(&object, &model.target, &t_model_scene0, &fine)?;
        let t_model_scene = refined.t_target_source;
        lap("icp", timings);

        let (score, rmse) = inlier_stats(&object, &model.target, &t_model_scene, tol);
        if score < cfg.min_fitness {
            return Err(Error::NoObjectFound {
                reason: format!("the best pose explains only {:.0} % of the top object's {} points within {tol:.2} mm (need {:.0} %)", 100.0 * score, object.len(), 100.0 * cfg.min_fitness),
            });
        }
        let t_scene_model = t_model_scene.inverse();
        let indices: Vec<usize> = kept
            .iter()
            .copied()
            .filter(|&i| {
                let q = t_model_scene * scene[i];
                model.target.search().nearest_within(&[q.x, q.y, q.z], tol * tol).is_some()
            })
            .collect();
        lap("verification", timings);
        Ok(PoseEstimate { t_scene_model, t_scene_model_coarse: coarse, score, rmse, indices, timings: timings.clone(), iterations: refined.iterations })
        };
        match fit(&mut timings) {
            Err(Error::NoObjectFound { reason }) => {
                for &i in &region {
                    excluded[i] = true;
                }
                last_failure = Some(Error::NoObjectFound { reason });
            }
            other => return other,
        }
    }
    Err(last_failure.unwrap_or(Error::NoObjectFound { reason: "no region could be matched".into() }))
}

fn inlier_stats(points: &[Point], target: &IcpTarget, t: &Isometry3<f64>, tol: f64) -> (f64, f64) {
    let mut n = 0usize;
    let mut sq = 0.0;
    for p in points {
        let q = t * p;
        if let Some((_, d)) = target.search().nearest_within(&[q.x, q.y, q.z], tol * tol) {
            n += 1;
            sq += d;
        }
    }
    let rmse = if n > 0 { (sq / n as f64).sqrt() } else { f64::INFINITY };
    (n as f64 / points.len().max(1) as f64, rmse)
}

/// The scan seen from the sensor's side: per cell of a grid across `up`, the height (along `up`)
/// of the highest scan point. Judging a predicted surface point against it is a depth test.
struct HeightMap {
    e1: Vector3<f64>,
    e2: Vector3<f64>,
    up: Vector3<f64>,
    inv_cell: f64,
    cells: std::collections::HashMap<(i64, i64), f64>,
}

impl HeightMap {
    fn new(points: &[Point], up: &Vector3<f64>, cell: f64) -> Self {
        let e1 = up.cross(&if up.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() }).normalize();
        let e2 = up.cross(&e1);
        let mut map = HeightMap { e1, e2, up: *up, inv_cell: 1.0 / cell, cells: std::collections::HashMap::with_capacity(points.len() / 2) };
        for p in points {
            let (k, h) = map.key(p);
            let e = map.cells.entry(k).or_insert(f64::NEG_INFINITY);
            *e = e.max(h);
        }
        map
    }

    fn key(&self, p: &Point) -> ((i64, i64), f64) {
        let v = p.coords;
        (((v.dot(&self.e1) * self.inv_cell).floor() as i64, (v.dot(&self.e2) * self.inv_cell).floor() as i64), v.dot(&self.up))
    }
}

/// How well the scan confirms the surface a pose predicts: of the model points the sensor should
/// see (facing `up`), those where the scan's surface is at the predicted height count as seen,
/// those where the scan saw deeper (through the predicted surface) as violations; occluded
/// (the scan is higher) or unscanned places do not count. Flipped and half-matched poses predict
/// surface where the scan saw free space, and lose here.
fn coverage(model: &PoseModel, heights: &HeightMap, t_scene_model: &Isometry3<f64>, step: usize, tol: f64) -> f64 {
    let up_model = t_scene_model.rotation.inverse() * heights.up;
    let normals = model.target.normals().unwrap_or(&[]);
    let (mut seen, mut violated) = (0usize, 0usize);
    for (p, n) in model.target.points().iter().zip(normals).step_by(step) {
        if n.dot(&up_model) < 0.3 {
            continue;
        }
        let (k, h) = heights.key(&(t_scene_model * p));
        match heights.cells.get(&k) {
            Some(&top) if (top - h).abs() <= tol => seen += 1,
            Some(&top) if top < h - tol => violated += 1,
            _ => {}
        }
    }
    if seen + violated == 0 { 0.0 } else { seen as f64 / (seen + violated) as f64 }
}
