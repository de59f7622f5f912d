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

impl IcpMethod {
    /// The method's name as the Python API spells it.
    pub fn name(&self) -> &'static str {
        match self {
            IcpMethod::PointToPoint => "point_to_point",
            IcpMethod::PointToPlane => "point_to_plane",
        }
    }

    /// The method of a name as [`IcpMethod::name`] spells it.
    pub fn from_name(name: &str) -> Result<Self> {
        match name {
            "point_to_point" => Ok(IcpMethod::PointToPoint),
            "point_to_plane" => Ok(IcpMethod::PointToPlane),
            _ => Err(Error::invalid(
                "method",
                format!("unknown method {name:?}; use \"point_to_point\" or \"point_to_plane\""),
            )),
        }
    }
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

    /// The kernel of a name as [`RobustKernel::name`] spells it (any case), at `scale` mm; without
    /// a scale, a third of the correspondence distance `reach` (mm).
    pub fn from_name(name: &str, scale: Option<f64>, reach: f64) -> Result<Self> {
        let k = scale.unwrap_or(reach / 3.0);
        match name.to_ascii_lowercase().as_str() {
            "none" => Ok(RobustKernel::None),
            "huber" => Ok(RobustKernel::Huber(k)),
            "tukey" => Ok(RobustKernel::Tukey(k)),
            "cauchy" => Ok(RobustKernel::Cauchy(k)),
            _ => Err(Error::invalid(
                "kernel",
                format!("unknown kernel {name:?}; use \"none\", \"huber\", \"tukey\" or \"cauchy\""),
            )),
        }
    }

    /// The kernel's name as the Python API spells it.
    pub fn name(&self) -> &'static str {
        match self {
            RobustKernel::None => "none",
            RobustKernel::Huber(_) => "huber",
            RobustKernel::Tukey(_) => "tukey",
            RobustKernel::Cauchy(_) => "cauchy",
        }
    }

    /// The kernel's scale, mm (`None` for plain least squares).
    pub fn scale(&self) -> Option<f64> {
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

/// When an ICP run stops: after `iterations`, or once an update rotates less than `rotation`
/// (rad) and moves less than `translation` (mm). The named settings are those the pose pipeline
/// runs, so that no two call sites can swap their numbers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Convergence {
    /// Upper bound on iterations.
    pub iterations: usize,
    /// Stop when an update rotates less than this, rad ...
    pub rotation: f64,
    /// ... and moves less than this, mm.
    pub translation: f64,
}

impl Convergence {
    /// The PPF screen: a few loose steps that bring a hypothesis near enough to be judged cheaply.
    pub const SCREEN: Convergence = Convergence {
        iterations: 8,
        rotation: 1e-3,
        translation: 5e-2,
    };
    /// A screened PPF hypothesis converged on its whole neighbourhood.
    pub const POLISH: Convergence = Convergence {
        iterations: 20,
        rotation: 1e-6,
        translation: 1e-4,
    };
    /// The coarse checks of the CCP path (stage two and the half turns): short, loose.
    pub const CHECK: Convergence = Convergence {
        iterations: 12,
        rotation: 1e-4,
        translation: 1e-2,
    };
    /// A near-symmetric alternative refined on the scan points of the pose it turns.
    pub const ALTERNATIVE: Convergence = Convergence {
        iterations: 15,
        rotation: 1e-5,
        translation: 1e-3,
    };
    /// A turn or slide the view leaves open, refined on the points the pose claims.
    pub const UNSEEN_TURN: Convergence = Convergence {
        iterations: 12,
        rotation: 1e-5,
        translation: 1e-3,
    };
    /// The CCP path's final refinement on all of the object's points: stops far below what the
    /// scan can resolve (about 0.0006° and 1 µm).
    pub const FINE: Convergence = Convergence {
        iterations: 60,
        rotation: 1e-5,
        translation: 1e-3,
    };
}

impl IcpConfig {
    /// Point-to-plane with a Tukey kernel as wide as the correspondence distance `reach` (mm):
    /// the robust refinement the pose pipelines run, stopping as `convergence` says.
    pub fn robust_plane(reach: f64, convergence: Convergence) -> Self {
        IcpConfig {
            method: IcpMethod::PointToPlane,
            max_correspondence_distance: reach,
            max_iterations: convergence.iterations,
            rotation_tolerance: convergence.rotation,
            translation_tolerance: convergence.translation,
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
            positive("kernel_scale", k)?;
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_the_kernel_scale_defaults_to_a_third_of_the_reach() {
        for m in [IcpMethod::PointToPoint, IcpMethod::PointToPlane] {
            assert_eq!(IcpMethod::from_name(m.name()), Ok(m));
        }
        assert_eq!(
            RobustKernel::from_name("Tukey", None, 9.0),
            Ok(RobustKernel::Tukey(3.0))
        );
        assert_eq!(
            RobustKernel::from_name("huber", Some(2.0), 9.0),
            Ok(RobustKernel::Huber(2.0))
        );
        assert_eq!(RobustKernel::from_name("none", None, 9.0).map(|k| k.scale()), Ok(None));
        assert!(RobustKernel::from_name("gaussian", None, 9.0).is_err());
        assert!(IcpMethod::from_name("nearest").is_err());
    }
}
