//! Proper symmetries of a rigid part — the rotations about its surface centroid that map its
//! surface onto itself — found from an even surface sample, and their use for canonical poses
//! and symmetry-aware pose errors (as the BOP benchmark scores a pose).
//!
//! Detection ([`detect_symmetries`]):
//! 1. Every symmetry axis of a surface is a principal axis of its evenly sampled covariance, and
//!    an axis of order n ≥ 3 makes the two eigenvalues across it equal. So the candidates are the
//!    principal axes; where two eigenvalues nearly agree, the distinct axis is tested for n-fold
//!    and continuous symmetry and the degenerate plane is swept for a 180° flip; where all three
//!    agree (a cube, a tetrahedron), clustered sample normals and the directions of the samples
//!    farthest from the centre are candidates too.
//! 2. A rotation is tested by mapping a subsample and counting the points that land within the
//!    tolerance of the surface (the tangent plane of the nearest sample) with agreeing normals.
//!    A soft score on a small subsample screens candidates; survivors get their axis line
//!    (direction and position) refined by point-to-plane least squares, then face the full test.
//!    An n-fold axis must pass every divisor of n as well, and an axis passing four incommensurate
//!    angles (7°, 23°, 61°, 131°) is continuous. The group found is then checked for features:
//!    where one of its generators (or its axis's turns) maps a patch of samples off the surface —
//!    a detail too small for the count to notice — the search runs again with every rotation held
//!    to that check as well (a part with such a feature takes about twice as long).
//! 3. The accepted rotations are closed into a group, which is recognised (cyclic, dihedral,
//!    tetrahedral, octahedral, icosahedral) and rebuilt exactly from its axes, so that products
//!    of elements are again elements to rounding — [`Symmetries::canonical`] relies on that. A
//!    group of no known kind (it takes inconsistent findings) is kept as closed from them.
//!
//! Limits: symmetry is judged at the tolerance, so a polygonal prism whose flats stay within it
//! of a circle is continuous, and a box 40 × 41 mm across is square at a 2 mm tolerance. Only
//! proper rotations count (mirror images are other parts). A sphere is reported with one
//! continuous axis and a flip, which is all the structure [`Symmetries`] can hold.

use crate::error::{Error, Result};
use crate::geometry::{
    check_count, check_finite, check_spread, covariance, perpendicular_basis, principal_axes, Point,
};
use crate::rng::Rng;
use crate::search::corr_tree::CorrespondenceTree;
use crate::search::KdIndex;
use nalgebra::{Isometry3, Matrix3, Matrix5, Rotation3, Translation3, Unit, UnitQuaternion, Vector3, Vector5};
use std::f64::consts::{PI, TAU};

mod groups;
mod matcher;
mod near;
#[cfg(test)]
mod tests;

use matcher::Matcher;
pub use near::{detect_near_symmetries, NearSymmetry, NEAR_AGREEMENT};

type V3 = Vector3<f64>;
type Rot = UnitQuaternion<f64>;

/// The default [`SymmetryConfig::tolerance`] as a multiple of the median nearest-neighbour
/// spacing of the samples.
pub const TOLERANCE_PER_SPACING: f64 = 1.0;
/// A rotated sample looks for its nearest sample within this multiple of the 90th-percentile
/// nearest-neighbour spacing (at least the tolerance): far enough that gaps in the sampling do not
/// fail a point that lies on the surface, also for independent uniform samples.
const REACH_PER_SPACING: f64 = 2.5;
/// A rotated normal agrees with the nearest sample's normal when their dot product exceeds this.
const MIN_NORMAL_DOT: f64 = 0.8;
/// Two covariance eigenvalues whose relative difference is below this (or which are within
/// [`EQUAL_NOISE`] standard errors) count as equal.
const EQUAL_EIGENVALUES: f64 = 0.05;
/// Angles that all pass only for a continuous symmetry (none is near a multiple of 2π/n for the
/// same small n), degrees.
const CONTINUOUS_ANGLES_DEG: [f64; 4] = [7.0, 23.0, 61.0, 131.0];
/// Eigenvalues this many noise standard errors apart may still be equal.
const EQUAL_NOISE: f64 = 4.0;
/// Eigenvalues this many noise standard errors apart give eigenvectors within a few degrees.
const RESOLVED_NOISE: f64 = 20.0;
/// Random halvings of the sample that estimate the eigenvalue noise.
const EIGEN_SPLITS: usize = 4;
/// Points of the screening subsample.
const SCREEN_POINTS: usize = 128;
/// Smallest soft score (in [0, 1]) of a candidate worth refining.
const SCREEN_MIN: f64 = 0.5;
/// Flip directions (the best-screened, at least 2° apart) refined and tested in full: a part whose
/// small feature leaves one of a prism's flips leaves the others nearly passing too, and they
/// screen alike, so a few peaks are not enough.
const MAX_FLIP_PEAKS: usize = 12;
/// Points used to refine an axis line.
const REFINE_POINTS: usize = 400;
const REFINE_ITERATIONS: usize = 6;
/// Neighbours examined when the nearest sample disagrees (near an edge it may lie on the
/// neighbouring face).
const FALLBACK_NEIGHBOURS: usize = 8;
/// Rotations closer than this are one element, radians (1°).
const SAME_ROTATION: f64 = PI / 180.0;
/// Axis lines closer than this are one line, radians (2°).
const SAME_AXIS: f64 = PI / 90.0;
/// A closure growing past this many elements (or 8 × `max_order`) is inconsistent: the
/// icosahedral group has 60.
const MAX_GROUP: usize = 240;
/// Axes taken from the sample itself when the covariance is isotropic or its eigenvectors are
/// poorly resolved.
const MAX_SAMPLE_AXES: usize = 32;
/// A rebuilt group element may differ this much from the one found, radians (2°).
const MAX_REBUILD_SHIFT: f64 = PI / 90.0;
const SEED: u64 = 0x5EED_5E77;

/// How [`detect_symmetries`] judges a candidate rotation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SymmetryConfig {
    /// Largest distance, mm, from a rotated sample to the surface (the tangent plane of its
    /// nearest sample) for it to count as mapped onto the surface. `None` (the default) takes
    /// [`TOLERANCE_PER_SPACING`] (1.0) × the median nearest-neighbour spacing of the samples:
    /// about 0.8 × s for `model::sample_surface(.., Density::Spacing(s), ..)`, and about
    /// 0.5 × √(area / n) for `Density::Count(n)`.
    /// Features of the part smaller than this (chamfers, facets of a tessellated cylinder whose
    /// sagitta is below it) do not break a symmetry.
    pub tolerance: Option<f64>,
    /// Fraction of the tested samples that must map onto the surface, in (0, 1]. Edges and
    /// sampling gaps cost a percent or so. A rotation that passes must also leave no feature: a
    /// patch of a few samples across that it maps where the part has no surface (see
    /// `Matcher::feature_free`), so that a detail covering less than `1 − min_agreement` of the
    /// surface still breaks the symmetries that move it (they become near-symmetries).
    pub min_agreement: f64,
    /// Highest n-fold symmetry tested about an axis (at least 2). A polygonal prism with more
    /// sides whose flats stay within the tolerance of a circle is reported as continuous.
    pub max_order: usize,
    /// Samples used to test a rotation (a seeded subsample when there are more; at least 64).
    pub max_points: usize,
}

impl Default for SymmetryConfig {
    fn default() -> Self {
        SymmetryConfig {
            tolerance: None,
            min_agreement: 0.98,
            max_order: 12,
            max_points: 2000,
        }
    }
}

/// The proper symmetry group of a part about its surface centroid.
///
/// With a continuous axis the group is `{ R · Rot(axis, φ) : R in rotations, φ real }`; without,
/// it is `rotations`. Every element acts about `center`: `x ↦ center + R (x − center)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Symmetries {
    /// The point every symmetry axis passes through, model frame, mm: the surface centroid,
    /// refined onto the axes found (they are fitted as lines).
    pub center: Point,
    /// Unit axis of a continuous rotational symmetry (a shaft, a cylinder), if any.
    pub continuous_axis: Option<Vector3<f64>>,
    /// The finite set of symmetry rotations about `center`, identity first. With a continuous
    /// axis, the discrete ones that are not about it (at most the identity and one 180° flip
    /// across the axis, since the other flips differ from it by a turn about the axis).
    pub rotations: Vec<UnitQuaternion<f64>>,
}

impl Symmetries {
    /// The trivial group (identity only) about `center`.
    pub fn none(center: Point) -> Self {
        Symmetries {
            center,
            continuous_axis: None,
            rotations: vec![Rot::identity()],
        }
    }

    /// True when the identity is the only symmetry.
    pub fn is_trivial(&self) -> bool {
        self.continuous_axis.is_none() && self.rotations.len() <= 1
    }

    /// Number of elements of a finite group; `None` with a continuous axis.
    pub fn order(&self) -> Option<usize> {
        self.continuous_axis.is_none().then_some(self.rotations.len().max(1))
    }

    /// The model-frame transform `x ↦ center + r (x − center)` of a rotation about the centre.
    pub fn about_center(&self, r: &UnitQuaternion<f64>) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::from(self.center.coords - r * self.center.coords), *r)
    }

    /// Every symmetry as a model-frame transform `x ↦ center + R (x − center)`, identity first;
    /// a continuous axis sampled every `continuous_step` radians or a little less (so the turn
    /// closes; the step is taken to be at least 0.001 rad and is unused without a continuous axis).
    pub fn transforms(&self, continuous_step: f64) -> Vec<Isometry3<f64>> {
        let spins: Vec<Rot> = match self.continuous_axis {
            None => vec![Rot::identity()],
            Some(a) => {
                let k = (TAU / continuous_step.max(1e-3) * (1.0 - 1e-12)).ceil().max(1.0) as usize;
                (0..k).map(|i| rot(&a, TAU * i as f64 / k as f64)).collect()
            }
        };
        self.elements()
            .iter()
            .flat_map(|r| spins.iter().map(move |s| r * s))
            .map(|r| self.about_center(&r))
            .collect()
    }

    /// The representative of `t_scene_model · S` (S over the group) whose rotation is closest to
    /// the identity (smallest angle); exact for a continuous axis. It is the same for any two poses
    /// that differ only by a symmetry (to rounding, for the exactly closed groups
    /// [`detect_symmetries`] rebuilds, and up to ties, which have measure zero), so it serves as
    /// the canonical form of a reported pose.
    pub fn canonical(&self, t_scene_model: &Isometry3<f64>) -> Isometry3<f64> {
        t_scene_model * self.about_center(&self.closest(&t_scene_model.rotation))
    }

    /// (rotation error, radians; translation error, mm) of `estimate` against `truth`, both
    /// `T_scene_model`, minimised over the group as the BOP benchmark does: the angle of
    /// `R_estᵀ R_gt R_S` and `|t_est − t_(gt·S)|` with S acting about `center`, for the S that
    /// minimises the angle (exactly, for a continuous axis).
    pub fn pose_error(&self, estimate: &Isometry3<f64>, truth: &Isometry3<f64>) -> (f64, f64) {
        let s = self.closest(&(estimate.rotation.inverse() * truth.rotation));
        let t = truth * self.about_center(&s);
        (
            (estimate.rotation.inverse() * t.rotation).angle(),
            (estimate.translation.vector - t.translation.vector).norm(),
        )
    }

    fn elements(&self) -> Vec<Rot> {
        if self.rotations.is_empty() {
            vec![Rot::identity()]
        } else {
            self.rotations.clone()
        }
    }

    /// The group element S minimising the angle of `q · S`.
    fn closest(&self, q: &Rot) -> Rot {
        let mut best = (f64::NEG_INFINITY, Rot::identity());
        for r in self.elements() {
            let qr = q * r;
            // The angle of a unit quaternion falls as |w| grows; over a turn φ about `a`,
            // w(qr · (cos φ/2, a sin φ/2)) = w cos φ/2 − (v·a) sin φ/2 peaks in closed form.
            let (s, w) = match self.continuous_axis {
                None => (r, qr.scalar().abs()),
                Some(a) => {
                    let a = a.normalize();
                    let (w, va) = (qr.scalar(), qr.imag().dot(&a));
                    (r * rot(&a, 2.0 * (-va).atan2(w)), w.hypot(va))
                }
            };
            if w > best.0 {
                best = (w, s);
            }
        }
        best.1
    }
}

/// Detects the proper symmetries of a part from its surface samples (mm, model frame) and their
/// outward normals, as given by `model::sample_surface`. The sample should be even (area-uniform)
/// and dense enough to resolve the details that break symmetries; a few thousand points suffice
/// for most parts, and detection then takes milliseconds to tens of milliseconds (about twice as
/// long for a part whose small feature breaks a turn the count alone lets pass).
pub fn detect_symmetries(points: &[Point], normals: &[Vector3<f64>], cfg: &SymmetryConfig) -> Result<Symmetries> {
    let unit = unit_normals(points, normals, cfg)?;
    Ok(detect_groups(points, unit, cfg)?.proper)
}

/// The proper symmetries and the near-symmetries of a part (see [`detect_symmetries`] and
/// [`detect_near_symmetries`]), sharing the work the two have in common.
pub fn detect_all_symmetries(
    points: &[Point],
    normals: &[Vector3<f64>],
    cfg: &SymmetryConfig,
) -> Result<(Symmetries, Vec<NearSymmetry>)> {
    let unit = unit_normals(points, normals, cfg)?;
    let groups = detect_groups(points, unit.clone(), cfg)?;
    let near = near::near_symmetries(points, unit, &groups, cfg)?;
    Ok((groups.proper, near))
}

/// The proper group of a part and, when a feature made it smaller, the group the agreement
/// alone gives: the rotations it holds beyond the proper ones are near-symmetries.
pub(super) struct Groups {
    pub proper: Symmetries,
    pub lenient: Option<Symmetries>,
}

fn detect_groups(points: &[Point], unit: Vec<V3>, cfg: &SymmetryConfig) -> Result<Groups> {
    let mut matcher = Matcher::new(points, unit, cfg)?;
    let group = matcher.detect();
    if !matcher.group_has_feature(&group) {
        return Ok(Groups {
            proper: group,
            lenient: None,
        });
    }
    // A rotation that maps nearly all of the surface but leaves a feature is a near-symmetry
    // (see `near`), not a symmetry: the search runs again with every rotation checked for one.
    matcher.strict = true;
    Ok(Groups {
        proper: matcher.detect(),
        lenient: Some(group),
    })
}

/// Checks the inputs and configuration of a detection; the unit normals.
fn unit_normals(points: &[Point], normals: &[Vector3<f64>], cfg: &SymmetryConfig) -> Result<Vec<V3>> {
    check_finite("points", points)?;
    check_count(
        "points",
        points,
        32,
        "sample the part's surface more densely (model::sample_surface)",
    )?;
    if normals.len() != points.len() {
        return Err(Error::invalid(
            "normals",
            format!(
                "has {} rows but points has {}; pass one normal per point",
                normals.len(),
                points.len()
            ),
        ));
    }
    check_spread("points", points, 2, "symmetries need a sampled surface, not a curve")?;
    let mut unit = Vec::with_capacity(normals.len());
    for (i, n) in normals.iter().enumerate() {
        let len = n.norm();
        if !(len.is_finite() && len > 0.0) {
            return Err(Error::invalid(
                "normals",
                format!("row {i} is {n:?}; pass finite non-zero normals"),
            ));
        }
        unit.push(n / len);
    }
    if !(cfg.min_agreement > 0.0 && cfg.min_agreement <= 1.0) {
        return Err(Error::invalid(
            "min_agreement",
            format!("must be in (0, 1], got {}", cfg.min_agreement),
        ));
    }
    if cfg.max_order < 2 {
        return Err(Error::invalid(
            "max_order",
            format!("must be at least 2, got {}", cfg.max_order),
        ));
    }
    if cfg.max_points < 64 {
        return Err(Error::invalid(
            "max_points",
            format!("must be at least 64, got {}", cfg.max_points),
        ));
    }
    if let Some(t) = cfg.tolerance {
        if !(t.is_finite() && t > 0.0) {
            return Err(Error::invalid(
                "tolerance",
                format!("must be a positive length in mm, got {t}"),
            ));
        }
    }
    Ok(unit)
}

/// Patches of at least this many samples that a rotation maps off the surface make it no
/// symmetry ([`Matcher::feature_free`]): about three samples across, a patch the even sampling
/// does not leave by chance (none of the parts measured, the built-in fittings, shapes and
/// meshes of 4k–135k samples, leaves more than 4 where the turn is a symmetry), and a feature
/// of about 8 spacings² — 5 mm² at the built-in parts' 0.8 mm samples — that a scan can show
/// (up to [`FEATURE_SAMPLES`] samples; coarser beyond).
const MIN_FEATURE_SAMPLES: usize = 8;

/// A discrete turn's feature check asks for surface within this share of the tolerance (see
/// [`feature_share`] for a continuous axis's turns). A turn about a centre
/// that the feature itself displaced (the surface centroid, and the axis line refined onto the
/// surface) shows the feature at about half its depth either way: on a 60 mm D-shaft at the
/// default samples (tolerance 0.51 mm) the half turn about the axis moved the 1 mm flat to
/// 0.51 mm from the round side, and passed at the full tolerance. At half of it, none of the
/// parts measured leaves a single sample off the surface where the turn is a symmetry (the
/// built-in shapes and fittings, the reference CAD parts, a 24-tooth gear, a box, a turned
/// candlestick, a 16-sided cylinder).
const FEATURE_TOLERANCE: f64 = 0.5;

/// The share of the tolerance a feature check asks surface within: [`FEATURE_TOLERANCE`] for a
/// discrete turn, the whole of it for a turn of a continuous axis. Such a turn maps the facets of
/// a tessellated round between each other's vertices, up to their sagitta, which a finer check
/// would take for a feature: a 12-sided cylinder 30 mm across (sagitta 0.51 mm, tolerance
/// 0.53 mm) lost its axis at half the tolerance, and a 10-sided one came back with an
/// inconsistent group. A discrete turn of a regularly tessellated round maps the tessellation
/// onto itself, and the reference CAD parts' irregular ones left nothing off at half the
/// tolerance either.
fn feature_share(continuous: bool) -> f64 {
    if continuous {
        1.0
    } else {
        FEATURE_TOLERANCE
    }
}

/// Samples a feature check looks at, at most (an even subsample beyond).
const FEATURE_SAMPLES: usize = 40_000;

/// Whether some group of at least `min` of `points`, linked by steps of at most `link`, exists.
fn has_patch(points: &[Point], link: f64, min: usize) -> bool {
    if points.len() < min {
        return false;
    }
    let index = KdIndex::new(points);
    let mut seen = vec![false; points.len()];
    for start in 0..points.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let (mut stack, mut size) = (vec![start], 0);
        while let Some(i) = stack.pop() {
            size += 1;
            if size >= min {
                return true;
            }
            for nb in index.within(&points[i], link) {
                if !seen[nb.index] {
                    seen[nb.index] = true;
                    stack.push(nb.index);
                }
            }
        }
    }
    false
}

/// Rotation by `angle` about `axis` (any length but zero).
fn rot(axis: &V3, angle: f64) -> Rot {
    Rot::from_axis_angle(&Unit::new_normalize(*axis), angle)
}

fn same_line(a: &V3, b: &V3, angle: f64) -> bool {
    a.dot(b).abs() >= angle.cos()
}

/// Comparisons modulo the group, for clustering pose hypotheses.
impl Symmetries {
    /// The smallest angle (radians) between rotation `a` and rotation `b` composed with any
    /// element of the group: how far apart two orientations of the part really are.
    pub fn rotation_distance(&self, a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
        let d = a.inverse() * b;
        (d * self.closest(&d)).angle()
    }

    /// `t · S` for the group element S that brings `t`'s rotation nearest to `reference`'s.
    pub fn nearest_equivalent(&self, t: &Isometry3<f64>, reference: &Isometry3<f64>) -> Isometry3<f64> {
        t * self.about_center(&self.closest(&(reference.rotation.inverse() * t.rotation)))
    }
}
