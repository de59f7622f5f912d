//! The pose pipeline: bin removal → top-object segmentation → coarse pose (CCP or the paper's
//! centroid baseline) → ICP of the scene points onto the dense model → verification.
//!
//! Frames: ICP registers the object's scene points onto the model (as the paper does, Eq. 6),
//! giving `T_model_scene`; the result reports its inverse `T_scene_model` (model → scene). A
//! result is returned only when enough of the object's points lie on the posed model;
//! otherwise the pipeline answers `NoObjectFound` rather than a guess.

use crate::cloud::{check_finite, Point};
use crate::detect::detect;
use crate::error::{Error, Result};
use crate::knn::KdIndex;
use crate::mesh::TriMesh;
use crate::model::{sample_surface, Density};
use crate::normals::{estimate_normals, Orientation};
use crate::registration::ccp::{ccp, BranchLayout, CcpConfig};
use crate::registration::ppf::{DetectConfig, PpfConfig, PpfModel};
use crate::registration::verify::{coarse_inlier_fraction, depth_evidence, inlier_stats, HeightMap};
use crate::registration::{icp, IcpConfig, IcpTarget, RobustKernel};
use crate::segment::{
    could_hold_support_plane, crop_to_bin, point_spacing, remove_support_planes, scan_spacing, segment_top, BinBox,
    SegmentConfig,
};
use crate::symmetry::{detect_symmetries, Symmetries, SymmetryConfig};
use crate::voxel::subsample;
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

/// The coarse checks' nearest field: cells of 1/64 of the part's diameter (coarser cells let
/// wrong readings of Table 3's case 6 win), over its box grown by 0.35 × the diameter (farther
/// than the coarse checks' correspondences reach for a densely sampled model).
const FIELD_CELLS: f64 = 64.0;
const FIELD_MARGIN: f64 = 0.35;

/// Regions tried, top first, before the pipeline gives up.
const MAX_REGIONS: usize = 8;

/// How the coarse pose is found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CoarseMethod {
    /// The paper's CCP (needs a branch layout).
    Ccp,
    /// The paper's baseline: ICP started from the centroids with the model's own orientation.
    Centroid,
    /// Point-pair-feature detection: any rigid part, every instance of a pile.
    Ppf,
    /// PPF, and CCP too where the model has a branch layout; the verified winner is kept.
    Auto,
}

impl CoarseMethod {
    /// The method's name as the Python API spells it.
    pub fn name(&self) -> &'static str {
        match self {
            CoarseMethod::Ccp => "ccp",
            CoarseMethod::Centroid => "centroid",
            CoarseMethod::Ppf => "ppf",
            CoarseMethod::Auto => "auto",
        }
    }
}

/// A model prepared for pose estimation: dense points with normals and their search structure,
/// its symmetries and (once built) its point-pair-feature table.
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
    /// The part's proper symmetries (about its surface centroid).
    pub symmetries: Symmetries,
    /// Largest distance of a surface point from the symmetry centre, mm.
    pub radius: f64,
    /// Smallest extent of the part along its principal axes, mm.
    pub thickness: f64,
    /// The point-pair-feature table, once built or loaded.
    pub ppf: Option<PpfModel>,
    /// The mesh surface sampled densely, when the samples are much sparser than that: the final
    /// refinement and its verification run against it.
    pub surface: Option<IcpTarget>,
}

impl PoseModel {
    /// Prepares a model from its surface samples (mm) and outward unit normals, and detects its
    /// symmetries.
    pub fn new(
        points: Vec<Point>,
        normals: Vec<Vector3<f64>>,
        diameter: f64,
        area: f64,
        layout: Option<BranchLayout>,
    ) -> Result<Self> {
        if !(diameter.is_finite() && diameter > 0.0) {
            return Err(Error::invalid("model", "the model's diameter must be positive"));
        }
        let spacing = point_spacing(&points, &KdIndex::new(&points));
        let symmetries = detect_symmetries(&points, &normals, &SymmetryConfig::default())?;
        let c = symmetries.center;
        let radius = points.iter().map(|p| (p - c).norm()).fold(0.0, f64::max);
        let (_, cov) = crate::cloud::covariance(&points);
        let (_, axes) = crate::cloud::principal_axes(&cov);
        let thickness = axes
            .iter()
            .map(|a| {
                let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                    let v = p.coords.dot(a);
                    (l.min(v), h.max(v))
                });
                hi - lo
            })
            .fold(f64::INFINITY, f64::min);
        // Only CCP's coarse checks use the nearest field: a model without branches does not pay for it.
        let mut target = IcpTarget::new(points, Some(normals))?;
        if layout.is_some() {
            target = target.with_field(diameter / FIELD_CELLS, FIELD_MARGIN * diameter);
        }
        Ok(PoseModel {
            target,
            diameter,
            area,
            layout,
            spacing,
            symmetries,
            radius,
            thickness,
            ppf: None,
            surface: None,
        })
    }

    /// The dense model as an ICP target.
    pub fn target(&self) -> &IcpTarget {
        &self.target
    }

    /// What the final refinement registers onto: the dense mesh surface when there is one,
    /// the samples otherwise.
    pub fn fine_target(&self) -> &IcpTarget {
        self.surface.as_ref().unwrap_or(&self.target)
    }

    /// Gives a model whose samples are sparser than 1.5 × 1/100 of the mesh's bounding-box
    /// diagonal (a paper-style 300-point model cloud) a dense sampling of the mesh for the final
    /// refinement, so its accuracy no longer depends on how sparse the samples are. The mesh
    /// must be the samples' surface, in the same frame; one that is not (samples farther than
    /// two sample spacings from it) is ignored.
    pub fn with_surface_of(mut self, mesh: &TriMesh) -> Result<Self> {
        let (lo, hi) = mesh.bounds();
        let spacing = (hi - lo).norm() / 100.0;
        if !(self.spacing > 1.5 * spacing) {
            return Ok(self);
        }
        let s = sample_surface(mesh, Density::Spacing(spacing), 0)?;
        let surface = IcpTarget::new(s.points, Some(s.normals))?;
        let pts = self.target.points();
        let reach = 2.0 * self.spacing;
        let probes: Vec<&Point> = pts.iter().step_by(pts.len().div_ceil(64)).collect();
        let on = probes
            .iter()
            .filter(|p| {
                surface
                    .search()
                    .nearest_within(&[p.x, p.y, p.z], reach * reach)
                    .is_some()
            })
            .count();
        if on * 10 >= 9 * probes.len() {
            self.surface = Some(surface);
        }
        Ok(self)
    }

    /// Builds the point-pair-feature table from an even subsample of the dense points.
    pub fn build_ppf(&mut self, config: PpfConfig) -> Result<()> {
        config.validate()?;
        let pts = self.target.points();
        let normals = self.target.normals().unwrap_or(&[]);
        let keep = subsample(pts, config.sampling_ratio * self.diameter);
        let ppf = PpfModel::new(
            keep.iter().map(|&i| pts[i]).collect(),
            keep.iter().map(|&i| normals[i]).collect(),
            self.diameter,
            config,
        )?;
        self.ppf = Some(ppf);
        Ok(())
    }

    /// Installs a table read from a cache; it must have been built for this model's diameter.
    pub fn set_ppf(&mut self, ppf: PpfModel) -> Result<()> {
        if (ppf.step() / ppf.config().sampling_ratio - self.diameter).abs() > 1e-6 * self.diameter {
            return Err(Error::invalid(
                "ppf_cache",
                "the cached table was built for another model; it will be rebuilt",
            ));
        }
        self.ppf = Some(ppf);
        Ok(())
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
    /// Smallest fraction of the object's points that must lie on the posed model (CCP, centroid).
    pub min_fitness: f64,
    /// PPF: smallest fraction of the posed model's sensor-facing surface, where the scan can judge
    /// it, that the scan confirms (the rest it sees through).
    pub min_coverage: f64,
    /// CCP tuning.
    pub ccp: CcpConfig,
    /// PPF detection tuning.
    pub detect: DetectConfig,
    /// The sensor's position in the scene frame, mm, when known (orients the scan's normals;
    /// otherwise they face `up`).
    pub viewpoint: Option<Point>,
    /// Instances returned by [`estimate_poses`].
    pub max_instances: usize,
    /// Worker threads; 0 = all cores.
    pub num_threads: usize,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            bin: None,
            up: Vector3::z(),
            method: CoarseMethod::Auto,
            d_star: None,
            min_points: None,
            max_normal_angle: 70f64.to_radians(),
            inlier_distance: None,
            min_fitness: 0.6,
            min_coverage: 0.8,
            ccp: CcpConfig::default(),
            detect: DetectConfig::default(),
            viewpoint: None,
            max_instances: 1,
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
    /// The coarse method that found it.
    pub method: CoarseMethod,
    /// Fraction of the model's sensor-facing surface that the scan confirms (NaN where not judged).
    pub visible_fraction: f64,
    /// Fraction of the model's sensor-facing surface under other objects (NaN where not judged).
    pub occluded_fraction: f64,
    /// Pickability in [0, 1] among the instances found (height, visible share, nothing on top).
    pub pickability: f64,
}

/// Estimates the pose of the top pickable object of `scene` (N×3, mm) against `model`.
pub fn estimate_pose(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<PoseEstimate> {
    let one = PoseConfig {
        max_instances: 1,
        ..cfg.clone()
    };
    let mut all = estimate_poses(scene, model, &one)?;
    Ok(all.swap_remove(0))
}

/// Estimates up to `cfg.max_instances` instances, most pickable first. CCP and the centroid
/// baseline find the top object only; PPF finds every instance it can confirm.
pub fn estimate_poses(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vec<PoseEstimate>> {
    crate::parallel::with_threads(cfg.num_threads, || dispatch(scene, model, cfg))
}

fn check_scene(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vector3<f64>> {
    check_finite("scene", scene)?;
    if scene.len() < 10 {
        return Err(Error::TooFewPoints {
            arg: "scene".into(),
            got: scene.len(),
            needed: 10,
            hint: "; pass the scan's points".into(),
        });
    }
    if !(cfg.up.norm() > 0.0) {
        return Err(Error::invalid("up", "must be a non-zero direction"));
    }
    let (lo, hi) = scene
        .iter()
        .fold((scene[0], scene[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
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
    Ok(cfg.up.normalize())
}

/// Scene indices inside the bin box (all without one), and — with `planes` and no box — without
/// the support planes wider than the part.
fn remove_bin(scene: &[Point], model: &PoseModel, cfg: &PoseConfig, planes: bool) -> Result<Vec<usize>> {
    let kept: Vec<usize> = match &cfg.bin {
        Some(bin) => crop_to_bin(scene, bin, 1.0)?,
        None if planes && could_hold_support_plane(scene, model.diameter) => {
            let idx = KdIndex::new(scene);
            let tol = (2.0 * point_spacing(scene, &idx)).max(0.5);
            remove_support_planes(scene, model.diameter, tol, 1).0
        }
        None => (0..scene.len()).collect(),
    };
    if kept.len() < 10 {
        return Err(Error::NoObjectFound {
            reason: format!(
                "only {} points remain after removing the bin; the bin is empty",
                kept.len()
            ),
        });
    }
    Ok(kept)
}

fn dispatch(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vec<PoseEstimate>> {
    check_scene(scene, model, cfg)?;
    let method = match (cfg.method, &model.layout, &model.ppf) {
        (CoarseMethod::Auto, None, _) => CoarseMethod::Ppf,
        (CoarseMethod::Auto, Some(_), None) => CoarseMethod::Ccp,
        (m, _, _) => m,
    };
    // Bin removal: PPF removes support planes itself, on its voxel grid.
    let clock = Instant::now();
    let kept = remove_bin(
        scene,
        model,
        cfg,
        matches!(method, CoarseMethod::Ccp | CoarseMethod::Centroid),
    )?;
    let bin_ms = clock.elapsed().as_secs_f64() * 1e3;
    let pts: Vec<Point> = kept.iter().map(|&i| scene[i]).collect();
    // Indices of the points a method saw (`kept` of the scene) become scene indices.
    let reindex = |mut e: PoseEstimate, kept: &[usize]| {
        e.indices = e.indices.iter().map(|&i| kept[i]).collect();
        e
    };
    let with_timings = |found: Vec<PoseEstimate>, timings: &[(&'static str, f64)]| -> Vec<PoseEstimate> {
        let mut all = vec![("bin_removal", bin_ms)];
        all.extend_from_slice(timings);
        found
            .into_iter()
            .map(|e| PoseEstimate {
                timings: all.clone(),
                ..e
            })
            .collect()
    };
    match method {
        CoarseMethod::Ccp | CoarseMethod::Centroid => {
            let mut timings = Vec::new();
            let e = run(scene, &pts, model, cfg, method, &mut timings)?;
            Ok(with_timings(vec![reindex(e, &kept)], &timings))
        }
        CoarseMethod::Ppf | CoarseMethod::Auto => {
            let ppf = model.ppf.as_ref().ok_or_else(|| {
                Error::invalid(
                    "model",
                    "PPF needs the model's feature table; prepare the model with PPF (binpick builds it on first use)",
                )
            })?;
            let mut timings = Vec::new();
            let detected = detect(scene, &pts, model, ppf, cfg, &mut timings).map(|(found, prepared)| {
                (
                    found.into_iter().map(|e| reindex(e, &kept)).collect::<Vec<_>>(),
                    prepared,
                )
            });
            if method == CoarseMethod::Ppf {
                return Ok(with_timings(detected?.0, &timings));
            }
            // Auto with a branch layout: CCP on the top object too; the verified winner leads.
            let clock = Instant::now();
            let ccp_kept = if cfg.bin.is_some() {
                kept.clone()
            } else {
                remove_bin(scene, model, cfg, true)?
            };
            timings.push(("ccp_bin_removal", clock.elapsed().as_secs_f64() * 1e3));
            let ccp_pts: Vec<Point> = ccp_kept.iter().map(|&i| scene[i]).collect();
            let mut ccp_timings = Vec::new();
            let by_ccp =
                run(scene, &ccp_pts, model, cfg, CoarseMethod::Ccp, &mut ccp_timings).map(|e| reindex(e, &ccp_kept));
            for (name, ms) in ccp_timings {
                timings.push((
                    match name {
                        "icp" => "ccp_icp",
                        "coarse" => "ccp_coarse",
                        "normals" => "ccp_normals",
                        "segmentation" => "ccp_segmentation",
                        "verification" => "ccp_verification",
                        other => other,
                    },
                    ms,
                ));
            }
            match (detected, by_ccp) {
                (Ok((mut found, prepared)), Ok(mut c)) => {
                    let e = prepared.judge(model, &c.t_scene_model);
                    let first = prepared.judge(model, &found[0].t_scene_model);
                    c.visible_fraction = e.visible_fraction();
                    c.occluded_fraction = e.occluded_fraction();
                    if e.quality() > first.quality() {
                        let gap = 0.5 * model.thickness;
                        let cc = c.t_scene_model * model.symmetries.center;
                        found.retain(|f| (f.t_scene_model * model.symmetries.center - cc).norm() > gap);
                        c.pickability = found.first().map_or(1.0, |f| f.pickability);
                        found.insert(0, c);
                        found.truncate(cfg.max_instances.max(1));
                    }
                    Ok(with_timings(found, &timings))
                }
                (Ok((found, _)), Err(_)) => Ok(with_timings(found, &timings)),
                (Err(_), Ok(c)) => Ok(with_timings(vec![c], &timings)),
                (Err(e), Err(_)) => Err(e),
            }
        }
    }
}

/// The paper's path on the points left after bin removal: top-object segmentation → CCP (or
/// the centroid baseline) → ICP → verification. Indices in the result refer to `pts`.
fn run(
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
            let (_, cov) = crate::cloud::covariance(&object);
            let (vals, axes) = crate::cloud::principal_axes(&cov);
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
                    let c_obj = crate::cloud::centroid(&object);
                    let c_model = crate::cloud::centroid(model.target.points());
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
            let c_model = crate::cloud::centroid(model.target.points()).coords;
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
            let indices = crate::detect::scene_indices(pts, model, &t_scene_model, tol);
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
