//! The pose pipeline's configuration and results: [`CoarseMethod`], [`PoseConfig`], [`PoseEstimate`],
//! [`Timings`].

use super::ccp_path::CcpPathParams;
use super::fit::FitQuality;
use super::trust::{Alternative, FeatureEvidence, TrustParams};
use crate::error::{Error, Result};
use crate::geometry::{BinBox, Point};
use crate::registration::ccp::CcpConfig;
use crate::registration::ppf::DetectConfig;
use nalgebra::{Isometry3, Vector3};

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
    /// Tunables of the CCP and centroid path's coarse checks and refinement.
    pub ccp_path: CcpPathParams,
    /// PPF detection tuning.
    pub detect: DetectConfig,
    /// Tunables of the disambiguation of near-symmetric poses and of the confidence.
    pub trust: TrustParams,
    /// The sensor's position in the scene frame, mm, when known (orients the scan's normals;
    /// otherwise they face `up`).
    pub viewpoint: Option<Point>,
    /// Instances returned by [`estimate_poses`].
    pub max_instances: usize,
    /// Instances the PPF search is sized for (hypotheses refined, poses polished) when more than
    /// `max_instances`: asking for fewer instances of the same search only truncates the answer.
    /// Default [`super::SEARCH_INSTANCES`].
    pub search_instances: usize,
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
            ccp_path: CcpPathParams::default(),
            detect: DetectConfig::default(),
            trust: TrustParams::default(),
            viewpoint: None,
            max_instances: 1,
            search_instances: super::SEARCH_INSTANCES,
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
        Ok(())
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
