//! The pose pipeline's plain data: its configuration ([`CoarseMethod`], [`PoseConfig`] and the
//! tunables of each stage, [`CcpPathParams`], [`TrustParams`]), its results ([`PoseEstimate`]
//! with its [`Alternative`]s, [`FeatureEvidence`] and [`FitQuality`]) and its [`Timings`].
//! The bottom floor of the pose room: it imports nothing of it.

use crate::error::{Error, Result};
use crate::geometry::{BinBox, Point};
use crate::registration::ccp::CcpConfig;
use crate::registration::ppf::DetectConfig;
use crate::registration::verify::Evidence;
use crate::registration::Convergence;
use nalgebra::{Isometry3, Vector3};
use std::time::Instant;

/// Milliseconds per stage, in order; a stage that runs more than once (CCP's, once per region
/// it tries) has an entry per run.
pub type Timings = Vec<(&'static str, f64)>;

/// Total milliseconds per stage, in the order the stages first ran.
pub fn stage_totals(timings: &[(&'static str, f64)]) -> Timings {
    let mut totals: Timings = Vec::new();
    for &(name, ms) in timings {
        match totals.iter_mut().find(|(n, _)| *n == name) {
            Some((_, total)) => *total += ms,
            None => totals.push((name, ms)),
        }
    }
    totals
}

/// Stage timings: each lap is the time since the previous one.
pub(super) struct Laps<'a> {
    clock: Instant,
    timings: &'a mut Timings,
}

impl<'a> Laps<'a> {
    pub(super) fn new(timings: &'a mut Timings) -> Self {
        Laps {
            clock: Instant::now(),
            timings,
        }
    }

    pub(super) fn lap(&mut self, name: &'static str) {
        self.timings.push((name, self.clock.elapsed().as_secs_f64() * 1e3));
        self.clock = Instant::now();
    }
}

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
    /// No search: a pose given to [`verify_pose`](super::verify_pose), judged as found ones are.
    Given,
}

impl CoarseMethod {
    /// The method's name as the Python API spells it.
    pub fn name(&self) -> &'static str {
        match self {
            CoarseMethod::Ccp => "ccp",
            CoarseMethod::Centroid => "centroid",
            CoarseMethod::Ppf => "ppf",
            CoarseMethod::Auto => "auto",
            CoarseMethod::Given => "given",
        }
    }

    /// The method of a name as [`CoarseMethod::name`] spells it (any case).
    pub fn from_name(name: &str) -> Result<Self> {
        match name.to_ascii_lowercase().as_str() {
            "ccp" => Ok(CoarseMethod::Ccp),
            "centroid" => Ok(CoarseMethod::Centroid),
            "ppf" => Ok(CoarseMethod::Ppf),
            "auto" => Ok(CoarseMethod::Auto),
            _ => Err(Error::invalid(
                "method",
                format!("unknown method {name:?}; use \"auto\", \"ppf\", \"ccp\" or \"centroid\""),
            )),
        }
    }
}

/// The search (hypotheses voted, poses polished) is sized for at least this many instances by
/// default ([`PoseConfig::search_instances`]), so that asking for fewer only truncates the answer.
pub const SEARCH_INSTANCES: usize = 5;

/// The sensor's depth noise, which every tolerance of the judge derives from (its depth test,
/// the inliers of a pose, the reach of its refinement, the scale of the scan's normals).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SensorModel {
    /// Standard deviation of the depth noise along the sensor's rays, mm (at range 0 when it
    /// grows with range); `None`: read from the scan itself ([`crate::scan_noise`]).
    pub noise_mm: Option<f64>,
    /// Growth of the noise with the range r from the viewpoint:
    /// σ(r) = `noise_mm` + `noise_per_m2` · (r / 1000 mm)², in mm per square metre (a triangulating
    /// depth camera's noise grows as the square of its range). Needs `noise_mm` and a viewpoint;
    /// the judge takes σ at the median range of the scan. Default 0.
    pub noise_per_m2: f64,
}

impl SensorModel {
    /// Checks the values (and that a growth comes with a noise and a viewpoint).
    pub fn validate(&self, viewpoint: Option<&Point>) -> Result<()> {
        if let Some(v) = self.noise_mm {
            if !(v.is_finite() && v > 0.0 && v <= MAX_NOISE_MM) {
                return Err(Error::invalid(
                    "noise_mm",
                    format!("must be a positive number of mm up to {MAX_NOISE_MM}, got {v}; leave it out to read the noise from the scan"),
                ));
            }
        }
        let g = self.noise_per_m2;
        if !(g.is_finite() && (0.0..=MAX_NOISE_MM).contains(&g)) {
            return Err(Error::invalid(
                "noise_per_m2",
                format!("must be a number of mm per m² in [0, {MAX_NOISE_MM}], got {g}"),
            ));
        }
        if g > 0.0 && (self.noise_mm.is_none() || viewpoint.is_none()) {
            return Err(Error::invalid(
                "noise_per_m2",
                "a noise growing with range needs noise_mm (the noise at the sensor) and the viewpoint its range is measured from",
            ));
        }
        Ok(())
    }

    /// The declared noise at range `range` (mm), or `None` where the noise is to be read from the scan.
    pub fn sigma_at(&self, range: f64) -> Option<f64> {
        self.noise_mm.map(|s| s + self.noise_per_m2 * (range / 1000.0).powi(2))
    }
}

/// The judge's tolerance, in standard deviations of the scan's depth noise (the depth test, the
/// inliers of a pose, the bin's crop and the support planes' band): a cell's top is
/// the nearest of its points, on average a standard deviation or more nearer than the surface,
/// and a confirmed surface must stay confirmed nearly everywhere (3σ leaves one point in 370 out).
pub const NOISE_SIGMAS: f64 = 3.0;

/// The largest depth noise binpick takes, mm (a depth camera at the end of its range reads tens).
pub const MAX_NOISE_MM: f64 = 100.0;

/// Parameters of [`estimate_pose`](super::estimate_pose); `None` fields take defaults derived from the scan's point
/// spacing and the model's size.
#[derive(Debug, Clone, PartialEq)]
pub struct PoseConfig {
    /// The bin box in the scene frame; without it, support planes are found and removed.
    pub bin: Option<BinBox>,
    /// What is up in the bin: the direction out of it, toward the sensor. `None` (the default):
    /// scene +z, unless the viewpoint lies on the far side of the scene along +z (a scene in the
    /// camera's frame, whose +z points away from the camera), then the direction toward it.
    pub up: Option<Vector3<f64>>,
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
    /// Tunables of the CCP and centroid path's coarse checks and refinement.
    pub ccp_path: CcpPathParams,
    /// PPF detection tuning.
    pub detect: DetectConfig,
    /// Tunables of the disambiguation of near-symmetric poses and of the confidence.
    pub trust: TrustParams,
    /// The sensor's optical centre in the scene frame, mm, when known: the depth test then looks
    /// along the sensor's own rays (an oblique camera, a scene in the camera's frame), and the
    /// scan's normals face it; otherwise both look along `up`.
    pub viewpoint: Option<Point>,
    /// With a viewpoint, whether the depth test looks along the sensor's rays (the default: a
    /// depth camera's image, a fixed camera at an angle, a scene in the camera's frame) or along
    /// `up` (a laser-line scan swept over the bin by a camera looking down on it, whose lines,
    /// several millimetres apart, alias a grid of the camera's rays); the normals face the
    /// viewpoint either way.
    pub along_rays: bool,
    /// Where the light that made the scan comes from, mm, when the sensor lights the scene from
    /// elsewhere than its camera (a laser-line projector's origin): a point the scan holds must
    /// have been lit as well as seen, so a pose that stands between it and the light is
    /// contradicted by it too. Without it the depth test asks the camera's line of sight alone.
    pub light: Option<Point>,
    /// The sensor's depth noise (declared, or read from the scan).
    pub sensor: SensorModel,
    /// Instances returned by [`estimate_poses`](super::estimate_poses).
    pub max_instances: usize,
    /// Instances the PPF search is sized for (hypotheses refined, poses polished) when more than
    /// `max_instances`: asking for fewer instances of the same search only truncates the answer.
    /// Default [`SEARCH_INSTANCES`].
    pub search_instances: usize,
    /// Worker threads; 0 = all cores.
    pub num_threads: usize,
}

impl Default for PoseConfig {
    fn default() -> Self {
        PoseConfig {
            bin: None,
            up: None,
            method: CoarseMethod::Auto,
            d_star: None,
            min_points: None,
            max_normal_angle: 70f64.to_radians(),
            inlier_distance: None,
            min_fitness: 0.6,
            min_coverage: 0.8,
            ccp: CcpConfig::default(),
            ccp_path: CcpPathParams::default(),
            detect: DetectConfig::default(),
            trust: TrustParams::default(),
            viewpoint: None,
            light: None,
            along_rays: true,
            sensor: SensorModel::default(),
            max_instances: 1,
            search_instances: SEARCH_INSTANCES,
            num_threads: 0,
        }
    }
}

impl PoseConfig {
    /// Checks every value; the error names the field and the allowed range. The bin box is
    /// checked where it is used ([`crate::segment::crop_to_bin`]), `up` by the scene check.
    pub fn validate(&self) -> Result<()> {
        let positive = |name: &str, v: Option<f64>| match v {
            Some(v) if !(v.is_finite() && v > 0.0) => Err(Error::invalid(
                name,
                format!("must be a positive finite number, got {v}"),
            )),
            _ => Ok(()),
        };
        let fraction = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(name, format!("must be a finite number ≥ 0, got {v}")))
            }
        };
        let at_least_one = |name: &str, v: Option<usize>| match v {
            Some(0) => Err(Error::invalid(name, "must be at least 1, got 0")),
            _ => Ok(()),
        };
        positive("d_star", self.d_star)?;
        at_least_one("min_points", self.min_points)?;
        positive("max_normal_angle", Some(self.max_normal_angle))?;
        positive("inlier_distance", self.inlier_distance)?;
        fraction("min_fitness", self.min_fitness)?;
        fraction("min_coverage", self.min_coverage)?;
        positive("ccp_closer_radius", self.ccp.closer_radius)?;
        positive("ccp_tau", self.ccp.tau)?;
        let r = self.detect.reference_fraction;
        if !(r > 0.0 && r <= 1.0) {
            return Err(Error::invalid(
                "reference_fraction",
                format!("must be in (0, 1], got {r}"),
            ));
        }
        at_least_one("max_hypotheses", Some(self.detect.max_hypotheses))?;
        at_least_one("max_instances", Some(self.max_instances))?;
        at_least_one("search_instances", Some(self.search_instances))?;
        if let Some(v) = self.viewpoint {
            if !v.coords.iter().all(|c| c.is_finite()) {
                return Err(Error::invalid("viewpoint", "must be a finite point"));
            }
        }
        if let Some(v) = self.light {
            if !v.coords.iter().all(|c| c.is_finite()) {
                return Err(Error::invalid("light", "must be a finite point"));
            }
        }
        self.sensor.validate(self.viewpoint.as_ref())
    }
}

/// Tunables of the CCP and centroid path; the defaults are those the paper's tables were
/// measured with.
#[derive(Debug, Clone, PartialEq)]
pub struct CcpPathParams {
    /// Regions tried, top first, before the path gives up. Default 8.
    pub max_regions: usize,
    /// Object points the coarse checks judge a pose by (the probe; fewer than about 100 cannot
    /// tell a wrong reading of a partial view from the right one). Default 150.
    pub probe_points: usize,
    /// Model points the coarse checks' depth test probes. Default 100.
    pub model_probes: usize,
    /// Object points the candidates that survive the quick check converge on. Default 160.
    pub sample_points: usize,
    /// Model points (about) the stage-two depth test probes. Default 4000.
    pub fine_model_probes: usize,
    /// Readings the cheap first tier of scoring (a third of the probe) passes on to the second
    /// (the whole probe). Default 32.
    pub second_tier: usize,
    /// Distinct rotations, best-prescored first, that get the stage-one ICP check. Default 8.
    pub stage_one: usize,
    /// Stage-one leaders that converge in stage two. Default 3.
    pub stage_two: usize,
    /// A stage-one result converges in stage two only when it scores at least this fraction
    /// of the leader's. Default 0.7.
    pub stage_two_ratio: f64,
    /// Tolerance of the coarse checks, as a fraction of the part's diameter (at least twice the
    /// inlier distance). Default 0.08.
    pub coarse_tolerance_ratio: f64,
    /// Readings whose rotations differ by less than this, rad, and whose translations differ by
    /// less than [`CcpPathParams::same_reading_shift`] are scored once. Default 5° (0.0873).
    pub same_reading_angle: f64,
    /// Translation part of the same-reading test, as a fraction of the diameter. Default 0.05.
    pub same_reading_shift: f64,
    /// Of the readings whose rotations lie within this angle, rad, only the best-ranked gets
    /// the ICP checks. Default 15° (0.262).
    pub cluster_angle: f64,
    /// CCP: the best-ranked readings whose quarter and half turns about the model's axes join
    /// the ICP checks (views of a part on its side are ambiguous up to such a turn). Default 2.
    pub turned_readings: usize,
    /// CCP: a half turn of the winner whose quick score is below this fraction of the winner's
    /// is not converged. Default 0.8.
    pub half_turn_drop: f64,
    /// CCP: a half turn replaces the winner only when it scores this much more. Default 0.01.
    pub half_turn_margin: f64,
    /// ICP of the coarse checks.
    pub check_icp: CheckIcpParams,
    /// ICP of the final refinement.
    pub fine_icp: FineIcpParams,
}

impl Default for CcpPathParams {
    fn default() -> Self {
        CcpPathParams {
            max_regions: 8,
            probe_points: 150,
            model_probes: 100,
            sample_points: 160,
            fine_model_probes: 4000,
            second_tier: 32,
            stage_one: 8,
            stage_two: 3,
            stage_two_ratio: 0.7,
            coarse_tolerance_ratio: 0.08,
            same_reading_angle: 5f64.to_radians(),
            same_reading_shift: 0.05,
            cluster_angle: 15f64.to_radians(),
            turned_readings: 2,
            half_turn_drop: 0.8,
            half_turn_margin: 0.01,
            check_icp: CheckIcpParams::default(),
            fine_icp: FineIcpParams::default(),
        }
    }
}

/// The short point-to-plane ICP of the coarse checks (Tukey kernel, approximate search).
#[derive(Debug, Clone, PartialEq)]
pub struct CheckIcpParams {
    /// Correspondence distance as a fraction of the diameter (at least `min_tolerances` inlier
    /// distances). Default 0.25.
    pub reach_ratio: f64,
    /// Tukey kernel width as a fraction of the diameter (at least `min_tolerances` inlier
    /// distances). Default 0.1.
    pub kernel_ratio: f64,
    /// Lower bound of the distance and the kernel, in inlier distances. Default 3.
    pub min_tolerances: f64,
    /// When the ICP of stage two and of the half turns stops. Default [`Convergence::CHECK`]:
    /// 12 iterations, or an update under 1e-4 rad and 1e-2 mm.
    pub convergence: Convergence,
    /// Iterations of the quick checks (stage one, the half turns' first look). Default 6.
    pub quick_iterations: usize,
}

impl Default for CheckIcpParams {
    fn default() -> Self {
        CheckIcpParams {
            reach_ratio: 0.25,
            kernel_ratio: 0.1,
            min_tolerances: 3.0,
            convergence: Convergence::CHECK,
            quick_iterations: 6,
        }
    }
}

/// The final point-to-plane refinement on all of the object's points.
#[derive(Debug, Clone, PartialEq)]
pub struct FineIcpParams {
    /// Correspondence distance and Tukey width, in inlier distances. Default 3.
    pub reach_tolerances: f64,
    /// When the refinement stops. Default [`Convergence::FINE`]: 60 iterations, or an update
    /// under 1e-5 rad (about 0.0006°) and 1e-3 mm, far below what the scan can resolve.
    pub convergence: Convergence,
}

impl Default for FineIcpParams {
    fn default() -> Self {
        FineIcpParams {
            reach_tolerances: 3.0,
            convergence: Convergence::FINE,
        }
    }
}

/// Tunables of the disambiguation and the confidence.
#[derive(Debug, Clone, PartialEq)]
pub struct TrustParams {
    /// Turns tried about a continuous near axis (evenly spaced). Default 24 (every 15°).
    pub continuous_turns: usize,
    /// A continuous near axis's turns (every discrete near turn is compared in full, up to
    /// `max_discrete`): with more than this, a quick look picks this many finalists. Default 3.
    pub finalists: usize,
    /// Discrete near turns compared in full, at most; with more (a part whose small feature
    /// breaks a large group), they join the quick look. Default 8.
    pub max_discrete: usize,
    /// Scan points of the quick look's refinement, at most (its comparison uses as many as a
    /// refinement). Default 400.
    pub quick_points: usize,
    /// ICP iterations of the quick look. Default 6.
    pub quick_iterations: usize,
    /// Scan points each alternative is refined on, and the quick look compares on, at most.
    /// Default 1500.
    pub refine_points: usize,
    /// ICP iterations of each alternative's refinement. Default 15.
    pub iterations: usize,
    /// Fine tolerance in standard deviations of the scan's noise about the pose. Default 4.
    pub noise_sigmas: f64,
    /// Smallest fine tolerance, mm. Default 0.3.
    pub min_fine_tolerance: f64,
    /// An alternative whose evidence trails the best by less than this many scan points cannot
    /// be ruled out: twice the 15 points beyond 4σ at which the bench calls a feature in view,
    /// so that one chance cluster of misfits does not decide. Default 30.
    pub min_margin: f64,
    /// ... nor by less than this many standard deviations of the lead that chance alone gives
    /// two equally good poses: with d scan points that fit one of them and not the other, each
    /// falls to either side, so the lead (2 × the difference) spreads by 2√d; k probes one of them
    /// puts where the sensor saw free space spread it by √k probes' worth of points (see the
    /// trust stage's `margin_between`). The points both poses fit or both miss —
    /// most of a feature region as wide as a flange's whole face — say nothing of which is
    /// right. Default 3.
    pub margin_sigmas: f64,
    /// Poses closer than this rotation (rad, default 5°) ...
    pub pick_rotation: f64,
    /// ... and this translation (mm, default 3) are one pose (pick-grade of each other).
    pub pick_translation: f64,
}

impl Default for TrustParams {
    fn default() -> Self {
        TrustParams {
            continuous_turns: 24,
            finalists: 3,
            max_discrete: 8,
            quick_points: 400,
            quick_iterations: 6,
            refine_points: 1500,
            iterations: Convergence::ALTERNATIVE.iterations,
            noise_sigmas: 4.0,
            min_fine_tolerance: 0.3,
            min_margin: 30.0,
            margin_sigmas: 3.0,
            pick_rotation: 5f64.to_radians(),
            pick_translation: 3.0,
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
    pub timings: Timings,
    /// ICP iterations of the refinement.
    pub iterations: usize,
    /// The coarse method that found it.
    pub method: CoarseMethod,
    /// Fraction of the model's sensor-facing surface that the scan confirms; `None` where the
    /// depth test did not judge the pose (the CCP and centroid path alone).
    pub visible_fraction: Option<f64>,
    /// Fraction of the model's sensor-facing surface under other objects; `None` where not judged.
    pub occluded_fraction: Option<f64>,
    /// Pickability in [0, 1] among the instances found (height, visible share, nothing on top);
    /// `None` when the pose was not ranked against other instances (a single CCP or centroid
    /// result, which is the most pickable by default).
    pub pickability: Option<f64>,
    /// In [0, 1]: how likely the pose is pick-grade (calibrated: of the poses reported at
    /// confidence ≥ c, at least a fraction c are).
    pub confidence: f64,
    /// In [0, 1]: how likely the pose or one of its `alternatives` (any turn about a `free_axis`)
    /// is pick-grade — what a grasp the same on every one of them stakes; `confidence` where
    /// there are none.
    pub confidence_any: f64,
    /// Whether the scan cannot rule out a distinct alternative (a near-symmetric flip, a free axis).
    pub ambiguous: bool,
    /// The distinct poses the scan cannot rule out, each with its evidence.
    pub alternatives: Vec<Alternative>,
    /// The unit axis (scene frame, through the part's symmetry centre) of a continuous
    /// near-symmetry the scan cannot fix, when there is one: the turn about it is unknown.
    pub free_axis: Option<Vector3<f64>>,
    /// The evidence in the feature regions of the pose kept (`None` without near-symmetries).
    pub feature_evidence: Option<FeatureEvidence>,
    /// How well the pose's points lie on the posed model against the scan's own noise (`None`
    /// where too few points judge it); its factor is part of `confidence`.
    pub fit: Option<FitQuality>,
}

impl PoseEstimate {
    /// A pose `method` found and the judge passed with depth evidence `e`, before ranking and
    /// trust: `(score, rmse)` as the method measures its fit, the ICP `iterations` that refined
    /// it, the `indices` of the points on it. It is unranked (`pickability` None); its confidence,
    /// alternatives and fit are the trust stage's to fill in, its timings the pipeline's.
    pub(crate) fn verified(
        method: CoarseMethod,
        t_scene_model: Isometry3<f64>,
        t_scene_model_coarse: Isometry3<f64>,
        e: &Evidence,
        (score, rmse): (f64, f64),
        iterations: usize,
        indices: Vec<usize>,
    ) -> Self {
        PoseEstimate {
            t_scene_model,
            t_scene_model_coarse,
            score,
            rmse,
            indices,
            timings: Vec::new(),
            iterations,
            method,
            visible_fraction: Some(e.visible_fraction()),
            occluded_fraction: Some(e.occluded_fraction()),
            pickability: None,
            confidence: 0.0,
            confidence_any: 0.0,
            ambiguous: false,
            alternatives: Vec::new(),
            free_axis: None,
            feature_evidence: None,
            fit: None,
        }
    }
}

/// What the scan says about one pose in the feature regions.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FeatureEvidence {
    /// Scan points in the feature regions within the fine tolerance of the posed model.
    pub fits: usize,
    /// Scan points in the feature regions farther than the fine tolerance from it.
    pub misfits: usize,
    /// Probe points of the posed model (judge's depth test) where the sensor saw free space.
    pub seen_through: usize,
    /// The fine tolerance, mm.
    pub tolerance: f64,
    /// fits − misfits − seen-through (in scan points): higher is better supported.
    pub score: f64,
}

/// A distinct pose the scan cannot rule out.
#[derive(Debug, Clone, PartialEq)]
pub struct Alternative {
    /// Model → scene.
    pub t_scene_model: Isometry3<f64>,
    /// Its evidence.
    pub evidence: FeatureEvidence,
}

/// How well a pose's points lie on the posed model, against the scan's own noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitQuality {
    /// Robust standard deviation of the point-to-plane residuals of the pose's points about the
    /// posed model's dense surface, mm.
    pub residual_sigma: f64,
    /// The scan's noise where the part lies (see the module notes), mm.
    pub noise_floor: f64,
    /// `residual_sigma / noise_floor`.
    pub ratio: f64,
    /// The factor the confidence is multiplied by, in (0, 1].
    pub factor: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn method_names_round_trip_and_unknown_names_are_named() {
        for m in [
            CoarseMethod::Ccp,
            CoarseMethod::Centroid,
            CoarseMethod::Ppf,
            CoarseMethod::Auto,
        ] {
            assert_eq!(CoarseMethod::from_name(m.name()), Ok(m));
            assert_eq!(CoarseMethod::from_name(&m.name().to_uppercase()), Ok(m));
        }
        assert!(matches!(CoarseMethod::from_name("fpfh"), Err(Error::InvalidInput { arg, .. }) if arg == "method"));
    }

    #[test]
    fn the_default_is_valid_and_each_bad_value_is_named() {
        assert_eq!(PoseConfig::default().validate(), Ok(()));
        let d = PoseConfig::default;
        let cases = [
            (
                "min_fitness",
                PoseConfig {
                    min_fitness: -0.1,
                    ..d()
                },
            ),
            (
                "min_coverage",
                PoseConfig {
                    min_coverage: f64::NAN,
                    ..d()
                },
            ),
            (
                "d_star",
                PoseConfig {
                    d_star: Some(0.0),
                    ..d()
                },
            ),
            (
                "min_points",
                PoseConfig {
                    min_points: Some(0),
                    ..d()
                },
            ),
            (
                "max_instances",
                PoseConfig {
                    max_instances: 0,
                    ..d()
                },
            ),
            (
                "search_instances",
                PoseConfig {
                    search_instances: 0,
                    ..d()
                },
            ),
            (
                "reference_fraction",
                PoseConfig {
                    detect: DetectConfig {
                        reference_fraction: 1.5,
                        ..DetectConfig::default()
                    },
                    ..d()
                },
            ),
        ];
        for (name, cfg) in cases {
            assert!(
                matches!(cfg.validate(), Err(Error::InvalidInput { ref arg, .. }) if arg == name),
                "{name}"
            );
        }
    }
}
