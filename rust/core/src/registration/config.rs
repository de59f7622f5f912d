//! ICP configuration: method, correspondence bound, stopping criteria, robust weighting.

use crate::error::{Error, Result};

/// The error ICP minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum IcpMethod {
    /// Σ‖R p + t − q‖², solved in closed form by SVD (Arun et al.), as in the paper.
    PointToPoint,
    /// Σ (n_q · (R p + t − q))², solved by Gauss–Newton on SE(3); needs target normals.
    PointToPlane,
}

/// Iteratively-reweighted least-squares kernel applied to each correspondence's residual.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RobustKernel {
    /// Plain least squares: every inlier weighs 1.
    None,
    /// Huber: weight 1 up to `k` mm, `k/|r|` beyond.
    Huber(f64),
    /// Tukey biweight: `(1 − (r/k)²)²` inside `k` mm, 0 beyond.
    Tukey(f64),
    /// Cauchy: `1 / (1 + (r/k)²)`.
    Cauchy(f64),
}

impl RobustKernel {
    /// The IRLS weight of a residual of magnitude `r` (mm).
    #[inline]
    pub fn weight(&self, r: f64) -> f64 {
        match *self {
            RobustKernel::None => 1.0,
            RobustKernel::Huber(k) => {
                if r <= k {
                    1.0
                } else {
                    k / r
                }
            }
            RobustKernel::Tukey(k) => {
                if r >= k {
                    0.0
                } else {
                    let u = r / k;
                    (1.0 - u * u) * (1.0 - u * u)
                }
            }
            RobustKernel::Cauchy(k) => 1.0 / (1.0 + (r / k) * (r / k)),
        }
    }

    fn scale(&self) -> Option<f64> {
        match *self {
            RobustKernel::None => None,
            RobustKernel::Huber(k) | RobustKernel::Tukey(k) | RobustKernel::Cauchy(k) => Some(k),
        }
    }
}

/// Parameters of one ICP run.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpConfig {
    /// Point-to-point or point-to-plane.
    pub method: IcpMethod,
    /// Pairs farther apart than this (mm) are not correspondences.
    pub max_correspondence_distance: f64,
    /// Upper bound on iterations.
    pub max_iterations: usize,
    /// Stop when an iteration rotates less than this (radians)…
    pub rotation_tolerance: f64,
    /// …and translates less than this (mm).
    pub translation_tolerance: f64,
    /// Robust weighting of residuals.
    pub kernel: RobustKernel,
    /// Fraction in [0, 0.9] of the farthest correspondences dropped each iteration (0 = off).
    pub trim_fraction: f64,
    /// Worker threads; 0 = all cores.
    pub num_threads: usize,
    /// Take correspondences from the target's approximate nearest field when it has one (coarse
    /// checks of poses still far off; see [`crate::search::field::NearestField`]).
    pub approximate: bool,
}

impl Default for IcpConfig {
    fn default() -> Self {
        IcpConfig {
            method: IcpMethod::PointToPlane,
            max_correspondence_distance: 10.0,
            max_iterations: 50,
            rotation_tolerance: 1e-6,
            translation_tolerance: 1e-4,
            kernel: RobustKernel::None,
            trim_fraction: 0.0,
            num_threads: 0,
            approximate: false,
        }
    }
}

impl IcpConfig {
    /// Point-to-plane with a Tukey kernel as wide as the correspondence distance `reach` (mm):
    /// the robust refinement the pose pipelines run, stopping after `max_iterations` or once an
    /// update rotates less than `rotation_tolerance` (rad) and moves less than
    /// `translation_tolerance` (mm).
    pub fn robust_plane(
        reach: f64,
        max_iterations: usize,
        rotation_tolerance: f64,
        translation_tolerance: f64,
    ) -> Self {
        IcpConfig {
            method: IcpMethod::PointToPlane,
            max_correspondence_distance: reach,
            max_iterations,
            rotation_tolerance,
            translation_tolerance,
            kernel: RobustKernel::Tukey(reach),
            ..Default::default()
        }
    }

    /// Checks every field; the error names the field and the allowed range.
    pub fn validate(&self) -> Result<()> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(
                    name,
                    format!("must be a positive finite number, got {v}"),
                ))
            }
        };
        positive("max_correspondence_distance", self.max_correspondence_distance)?;
        if !(self.rotation_tolerance.is_finite() && self.rotation_tolerance >= 0.0) {
            return Err(Error::invalid(
                "rotation_tolerance",
                format!("must be ≥ 0 radians, got {}", self.rotation_tolerance),
            ));
        }
        if !(self.translation_tolerance.is_finite() && self.translation_tolerance >= 0.0) {
            return Err(Error::invalid(
                "translation_tolerance",
                format!("must be ≥ 0 mm, got {}", self.translation_tolerance),
            ));
        }
        if self.max_iterations == 0 {
            return Err(Error::invalid("max_iterations", "must be at least 1"));
        }
        if let Some(k) = self.kernel.scale() {
            positive("kernel scale", k)?;
        }
        if !(self.trim_fraction.is_finite() && (0.0..=0.9).contains(&self.trim_fraction)) {
            return Err(Error::invalid(
                "trim_fraction",
                format!("must be in [0, 0.9], got {}", self.trim_fraction),
            ));
        }
        Ok(())
    }
}
