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
//!    angles (7°, 23°, 61°, 131°) is continuous.
//! 3. The accepted rotations are closed into a group, which is recognised (cyclic, dihedral,
//!    tetrahedral, octahedral, icosahedral) and rebuilt exactly from its axes, so that products
//!    of elements are again elements to rounding — [`Symmetries::canonical`] relies on that. A
//!    group of no known kind (it takes inconsistent findings) is kept as closed from them.
//!
//! Limits: symmetry is judged at the tolerance, so a polygonal prism whose flats stay within it
//! of a circle is continuous, and a box 40 × 41 mm across is square at a 2 mm tolerance. Only
//! proper rotations count (mirror images are other parts). A sphere is reported with one
//! continuous axis and a flip, which is all the structure [`Symmetries`] can hold.

use crate::cloud::{check_count, check_finite, check_spread, covariance, principal_axes, Point};
use crate::error::{Error, Result};
use crate::knn::KdIndex;
use crate::registration::corr_tree::CorrespondenceTree;
use crate::rng::Rng;
use nalgebra::{Isometry3, Matrix3, Matrix5, Rotation3, Translation3, Unit, UnitQuaternion, Vector3, Vector5};
use std::f64::consts::{PI, TAU};

type V3 = Vector3<f64>;
type Rot = UnitQuaternion<f64>;

/// The default [`SymmetryConfig::tolerance`] as a multiple of the median nearest-neighbour
/// spacing of the samples.
pub const TOLERANCE_PER_SPACING: f64 = 1.5;
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
    /// [`TOLERANCE_PER_SPACING`] (1.5) × the median nearest-neighbour spacing of the samples:
    /// about 1.2 × s for `model::sample_surface(.., Density::Spacing(s), ..)`, and about
    /// 0.7 × √(area / n) for `Density::Count(n)`.
    /// Features of the part smaller than this (chamfers, facets of a tessellated cylinder whose
    /// sagitta is below it) do not break a symmetry.
    pub tolerance: Option<f64>,
    /// Fraction of the tested samples that must map onto the surface, in (0, 1]. Edges and
    /// sampling gaps cost a percent or so; details breaking a symmetry must cover more of the
    /// surface than `1 − min_agreement` (about half that area when they are raised bumps, since
    /// both the detail and the place it maps to fail).
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
/// for most parts, and detection then takes milliseconds to tens of milliseconds.
pub fn detect_symmetries(points: &[Point], normals: &[Vector3<f64>], cfg: &SymmetryConfig) -> Result<Symmetries> {
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
    let matcher = Matcher::new(points, unit, cfg)?;
    Ok(matcher.detect())
}

/// Rotation by `angle` about `axis` (any length but zero).
fn rot(axis: &V3, angle: f64) -> Rot {
    Rot::from_axis_angle(&Unit::new_normalize(*axis), angle)
}

/// Two unit vectors completing `a` (unit) to a right-handed frame: (u, v = a × u).
fn perpendicular_basis(a: &V3) -> (V3, V3) {
    let helper = if a.x.abs() < 0.6 { V3::x() } else { V3::y() };
    let u = a.cross(&helper).normalize();
    (u, a.cross(&u))
}

fn same_line(a: &V3, b: &V3, angle: f64) -> bool {
    a.dot(b).abs() >= angle.cos()
}

/// A symmetry axis found by [`Matcher::examine`]: its line and its order.
#[derive(Debug, Clone, Copy)]
struct AxisFinding {
    axis: V3,
    point: Point,
    /// n of the n-fold symmetry (2 and up); 0 when continuous.
    order: usize,
    continuous: bool,
    agreement: f64,
}

/// Tests rotations of the sample against itself.
struct Matcher<'a> {
    points: &'a [Point],
    normals: Vec<V3>,
    tree: CorrespondenceTree,
    kd: KdIndex,
    tol: f64,
    /// Squared first-stage and full search radii.
    near2: f64,
    reach2: f64,
    min_agreement: f64,
    max_order: usize,
    /// Seeded subsamples: all tests use `test`; `screen` and `refine` are its prefixes.
    test: Vec<usize>,
    screen: usize,
    refine: usize,
    centroid: Point,
    r_max: f64,
}

impl<'a> Matcher<'a> {
    fn new(points: &'a [Point], normals: Vec<V3>, cfg: &SymmetryConfig) -> Result<Self> {
        let kd = KdIndex::new(points);
        let step = (points.len() / 512).max(1);
        let mut d: Vec<f64> = (0..points.len())
            .step_by(step)
            .filter_map(|i| {
                kd.knn(&points[i], 4)
                    .iter()
                    .map(|n| n.distance_squared)
                    .find(|&d2| d2 > 0.0)
            })
            .map(f64::sqrt)
            .collect();
        if d.is_empty() {
            return Err(Error::Degenerate {
                arg: "points".into(),
                what: "all points are equal".into(),
                advice: "pass a sampled surface".into(),
            });
        }
        d.sort_by(f64::total_cmp);
        let median = d[d.len() / 2];
        let q90 = d[(d.len() * 9 / 10).min(d.len() - 1)];
        let tol = cfg.tolerance.unwrap_or(TOLERANCE_PER_SPACING * median);
        let reach = (REACH_PER_SPACING * q90).max(tol);
        let near = (1.2 * median).min(reach);

        let mut order: Vec<usize> = (0..points.len()).collect();
        let mut rng = Rng::new(SEED);
        let m = cfg.max_points.min(points.len());
        for i in 0..m {
            let j = i + rng.below(points.len() - i);
            order.swap(i, j);
        }
        order.truncate(m);
        let centroid = covariance(points).0;
        let r_max = order.iter().map(|&i| (points[i] - centroid).norm()).fold(0.0, f64::max);
        Ok(Matcher {
            points,
            normals,
            tree: CorrespondenceTree::new(points),
            kd,
            tol,
            near2: near * near,
            reach2: reach * reach,
            min_agreement: cfg.min_agreement,
            max_order: cfg.max_order,
            screen: SCREEN_POINTS.min(m),
            refine: REFINE_POINTS.min(m),
            test: order,
            centroid,
            r_max,
        })
    }

    /// The sample nearest `m` and the signed distance of `m` from its tangent plane, when that
    /// distance is within `tol` and its normal agrees with `nr`. With `fallback`, a few further
    /// neighbours are tried when the nearest disagrees.
    #[inline]
    fn correspond(&self, m: &Point, nr: &V3, tol: f64, fallback: bool) -> Option<(usize, f64)> {
        let q = [m.x, m.y, m.z];
        let (j, _) = self
            .tree
            .nearest_within(&q, self.near2)
            .or_else(|| self.tree.nearest_within(&q, self.reach2))?;
        let agrees = |j: usize| {
            let r = self.normals[j].dot(&(m - self.points[j]));
            (nr.dot(&self.normals[j]) > MIN_NORMAL_DOT && r.abs() <= tol).then_some((j, r))
        };
        if let Some(hit) = agrees(j) {
            return Some(hit);
        }
        if !fallback {
            return None;
        }
        self.kd
            .knn(m, FALLBACK_NEIGHBOURS)
            .iter()
            .take_while(|n| n.distance_squared <= self.reach2)
            .find_map(|n| agrees(n.index))
    }

    /// Fraction of the test subsample mapped onto the surface by `r` about `c`; stops early (and
    /// answers below the threshold) once `min_agreement` is out of reach.
    fn agreement(&self, r: &Rot, c: &Point) -> f64 {
        let n = self.test.len();
        let allowed = ((1.0 - self.min_agreement) * n as f64 + 1e-9).floor() as usize;
        let mut fails = 0;
        for &i in &self.test {
            let m = c + r * (self.points[i] - c);
            if self.correspond(&m, &(r * self.normals[i]), self.tol, true).is_none() {
                fails += 1;
                if fails > allowed {
                    return 0.0;
                }
            }
        }
        (n - fails) as f64 / n as f64
    }

    fn passes(&self, r: &Rot, c: &Point) -> bool {
        self.agreement(r, c) >= self.min_agreement
    }

    /// Mean over the screening subsample of `1 − (d / 2 tol)²` (0 for points beyond 2 tol or with
    /// disagreeing normals); stops early once `floor` is out of reach, answering below it.
    fn soft_score(&self, r: &Rot, c: &Point, floor: f64) -> f64 {
        let n = self.screen as f64;
        let wide = 2.0 * self.tol;
        let mut sum = 0.0;
        for (k, &i) in self.test[..self.screen].iter().enumerate() {
            let m = c + r * (self.points[i] - c);
            if let Some((_, d)) = self.correspond(&m, &(r * self.normals[i]), wide, false) {
                let e = d / wide;
                sum += 1.0 - e * e;
            }
            if sum + ((self.screen - k - 1) as f64) < floor * n {
                return sum / n;
            }
        }
        sum / n
    }

    /// Refines the line (direction `axis` through `point`) of rotations by `angles` so that they
    /// map the sample onto itself: Gauss–Newton on point-to-plane residuals over the axis tilt
    /// (2 parameters) and the line's position (3, the component along the axis held).
    fn refine(&self, axis: &V3, point: &Point, angles: &[f64]) -> (V3, Point) {
        let (mut a, mut c) = (axis.normalize(), *point);
        for _ in 0..REFINE_ITERATIONS {
            let (u, v) = perpendicular_basis(&a);
            let mut h = Matrix5::<f64>::zeros();
            let mut g = Vector5::<f64>::zeros();
            let mut used = 0usize;
            for &theta in angles {
                let r = rot(&a, theta);
                let rm = r.to_rotation_matrix().into_inner();
                let i_minus_r = Matrix3::identity() - rm;
                let (s, k) = (theta.sin(), 1.0 - theta.cos());
                // A tilt δ = αu + βv of the axis turns R into exp([η]) R with
                // η = sin θ δ + (1 − cos θ) a × δ (the left Jacobian of the exponential map).
                let (eta_a, eta_b) = (s * u + k * v, s * v - k * u);
                for &i in &self.test[..self.refine] {
                    let d = rm * (self.points[i] - c);
                    let m = c + d;
                    let Some((j, res)) = self.correspond(&m, &(r * self.normals[i]), 3.0 * self.tol, false) else {
                        continue;
                    };
                    let nj = self.normals[j];
                    let dn = d.cross(&nj);
                    let pc = i_minus_r.transpose() * nj;
                    let jac = Vector5::new(eta_a.dot(&dn), eta_b.dot(&dn), pc.x, pc.y, pc.z);
                    h += jac * jac.transpose();
                    g += jac * res;
                    used += 1;
                }
            }
            if used < 10 {
                break;
            }
            let damping = 1e-9 * (0..5).map(|i| h[(i, i)]).fold(0.0, f64::max) + 1e-12;
            for i in 0..5 {
                h[(i, i)] += damping;
            }
            let Some(x) = h.cholesky().map(|ch| ch.solve(&(-g))) else {
                break;
            };
            let tilt = x[0] * u + x[1] * v;
            let shift = V3::new(x[2], x[3], x[4]);
            a = (a + tilt).normalize();
            c += shift - a * a.dot(&shift);
            if tilt.norm() < 1e-7 && shift.norm() < 1e-6 * self.tol.max(1e-9) {
                break;
            }
        }
        (a, c)
    }

    /// Finds the symmetry order of the line through `point` along `axis`: screens every n-fold
    /// rotation and (together) the continuous-test angles, refines the line on the best
    /// candidates, then tests in full. The order is the largest n that passes with all its
    /// divisors (or the lcm of those passing, up to 4 × `max_order`). Lines that refine onto one
    /// of the `known` axes are not tested again.
    fn examine(&self, axis: &V3, point: &Point, known: &[AxisFinding]) -> Option<AxisFinding> {
        // Largest first: small turns barely move a compact part, so they only count together.
        let continuous: Vec<f64> = CONTINUOUS_ANGLES_DEG.iter().rev().map(|d| d.to_radians()).collect();
        let soft = |a: &V3, c: &Point, angle: f64| self.soft_score(&rot(a, angle), c, SCREEN_MIN);
        let mut trials: Vec<(f64, Vec<f64>)> = (2..=self.max_order)
            .map(|n| (soft(axis, point, TAU / n as f64), vec![TAU / n as f64]))
            .collect();
        let mut all_continuous = f64::INFINITY;
        for &angle in &continuous {
            all_continuous = all_continuous.min(soft(axis, point, angle));
            if all_continuous < SCREEN_MIN {
                break;
            }
        }
        trials.push((all_continuous, continuous[..2].to_vec()));
        trials.retain(|t| t.0 >= SCREEN_MIN);
        // The best scores first; among near-equal ones the larger angle pins the axis better.
        trials.sort_by(|x, y| (y.0 + 0.02 * y.1[0]).total_cmp(&(x.0 + 0.02 * x.1[0])));
        let (mut a, mut c) = trials.iter().take(3).find_map(|(_, angles)| {
            let (a, c) = self.refine(axis, point, angles);
            self.passes(&rot(&a, angles[0]), &c).then_some((a, c))
        })?;
        if known.iter().any(|f| same_line(&f.axis, &a, SAME_AXIS)) {
            return None;
        }
        // The soft score rejects most wrong angles in a fraction of the cost of the full test.
        let holds = |a: &V3, c: &Point, angle: f64| soft(a, c, angle) >= SCREEN_MIN && self.passes(&rot(a, angle), c);
        let (order, angles) = if continuous.iter().all(|&angle| holds(&a, &c, angle)) {
            (0, continuous.clone())
        } else {
            let mut passing: Vec<usize> = (2..=self.max_order)
                .filter(|&n| holds(&a, &c, TAU / n as f64))
                .collect();
            let l = passing.iter().fold(1, |l, &n| lcm(l, n));
            if l > self.max_order && l <= 4 * self.max_order && holds(&a, &c, TAU / l as f64) {
                passing.push(l);
            }
            // The powers of a true 2π/n turn are symmetries too, so every divisor of n must pass;
            // a round-ish part can pass a fine turn within the tolerance without its powers.
            let order = passing
                .iter()
                .copied()
                .filter(|&n| (2..=n).filter(|d| n % d == 0).all(|d| passing.contains(&d)))
                .max()?;
            let mut angles = vec![TAU / order as f64];
            if order >= 4 {
                angles.push(TAU * (order / 2) as f64 / order as f64);
            }
            (order, angles)
        };
        // A last refinement on every angle that holds, kept when it still passes.
        let (a2, c2) = self.refine(&a, &c, &angles);
        let mut agreement = self.agreement(&rot(&a2, angles[0]), &c2);
        if agreement >= self.min_agreement {
            (a, c) = (a2, c2);
        } else {
            agreement = self.agreement(&rot(&a, angles[0]), &c);
        }
        Some(AxisFinding {
            axis: a,
            point: c,
            order,
            continuous: order == 0,
            agreement,
        })
    }

    /// Sweeps the lines through `point` perpendicular to `axis` for a 180° flip; returns the
    /// refined flip line when one passes. The flips across an n-fold axis repeat every π/n, so
    /// that range is enough (`order` 1 when the axis has no symmetry of its own); across a
    /// continuous axis (`None`) all flips are equivalent and a few directions are tried.
    fn flip_across(&self, axis: &V3, point: &Point, order: Option<usize>) -> Option<AxisFinding> {
        let (e1, e2) = perpendicular_basis(&axis.normalize());
        let (range, count) = match order {
            None => (PI, 8),
            Some(n) => {
                let range = PI / n.max(1) as f64;
                // Fine enough that the farthest point moves by under half the tolerance between
                // neighbouring directions.
                let step = (0.5 * self.tol / self.r_max.max(1e-9)).clamp(0.1f64.to_radians(), 1f64.to_radians());
                (range, (range / step).ceil() as usize)
            }
        };
        let dir = |k: usize| {
            let phi = range * k as f64 / count as f64;
            phi.cos() * e1 + phi.sin() * e2
        };
        let mut scored: Vec<(f64, usize)> = (0..count)
            .map(|k| (self.soft_score(&rot(&dir(k), PI), point, SCREEN_MIN), k))
            .filter(|(s, _)| *s >= SCREEN_MIN)
            .collect();
        scored.sort_by(|x, y| y.0.total_cmp(&x.0));
        let apart = (2.0f64.to_radians() / (range / count as f64)).ceil() as usize;
        let mut peaks: Vec<usize> = Vec::new();
        for &(_, k) in &scored {
            if peaks.iter().all(|&p| {
                let d = k.abs_diff(p);
                d.min(count - d) >= apart
            }) {
                peaks.push(k);
                if peaks.len() == 3 {
                    break;
                }
            }
        }
        peaks.into_iter().find_map(|k| {
            let (u, c) = self.refine(&dir(k), point, &[PI]);
            let agreement = self.agreement(&rot(&u, PI), &c);
            (agreement >= self.min_agreement).then_some(AxisFinding {
                axis: u,
                point: c,
                order: 2,
                continuous: false,
                agreement,
            })
        })
    }

    /// Candidate axes from the sample itself: clustered normals and the directions of the
    /// farthest samples.
    fn sample_axes(&self) -> Vec<V3> {
        let mut clusters: Vec<(V3, usize)> = Vec::new();
        let close = 5f64.to_radians().cos();
        for &i in &self.test {
            let n = self.normals[i];
            match clusters.iter().position(|(s, _)| n.dot(&s.normalize()).abs() >= close) {
                Some(k) => {
                    let (s, count) = &mut clusters[k];
                    *s += if n.dot(s) >= 0.0 { n } else { -n };
                    *count += 1;
                }
                None if clusters.len() < 200 => clusters.push((n, 1)),
                None => {}
            }
        }
        let least = (self.test.len() / 100).max(3);
        clusters.retain(|c| c.1 >= least);
        clusters.sort_by_key(|c| std::cmp::Reverse(c.1));
        let mut axes: Vec<V3> = clusters
            .iter()
            .take(MAX_SAMPLE_AXES / 2)
            .map(|c| c.0.normalize())
            .collect();
        let mut far: Vec<(f64, usize)> = self
            .test
            .iter()
            .map(|&i| ((self.points[i] - self.centroid).norm(), i))
            .collect();
        far.sort_by(|x, y| y.0.total_cmp(&x.0));
        let take = (self.test.len() / 50).max(8);
        let mut far_axes: Vec<V3> = Vec::new();
        for &(d, i) in far.iter().take(take) {
            if d <= 0.0 {
                continue;
            }
            let dir = (self.points[i] - self.centroid) / d;
            if !far_axes.iter().any(|a| same_line(a, &dir, 10f64.to_radians())) {
                far_axes.push(dir);
            }
        }
        axes.extend(far_axes.into_iter().take(MAX_SAMPLE_AXES / 2));
        axes
    }

    /// Standard error of the covariance eigenvalues (mm²), from how much they differ between
    /// random halves of the sample. That is the error of independent samples, about 1% at a few
    /// thousand points; an even (blue-noise) sample is better than that, so for it the estimate
    /// errs toward treating gaps as unresolved, which only adds candidate axes.
    fn eigenvalue_noise(&self) -> f64 {
        let mut rng = Rng::new(SEED ^ 0x4A1F);
        let mut sum_sq = 0.0;
        for _ in 0..EIGEN_SPLITS {
            let mut halves = [
                (0usize, V3::zeros(), Matrix3::zeros()),
                (0usize, V3::zeros(), Matrix3::zeros()),
            ];
            for p in self.points {
                let h = &mut halves[(rng.next_u64() >> 63) as usize];
                let d = p - self.centroid;
                h.0 += 1;
                h.1 += d;
                h.2 += d * d.transpose();
            }
            let vals = halves.map(|(n, s, ss)| {
                let n = n.max(1) as f64;
                let mean = s / n;
                principal_axes(&(ss / n - mean * mean.transpose())).0
            });
            // Each half's error is √2 that of the whole; their difference is 2× the whole's.
            sum_sq += (0..3).map(|i| ((vals[0][i] - vals[1][i]) / 2.0).powi(2)).sum::<f64>() / 3.0;
        }
        (sum_sq / EIGEN_SPLITS as f64).sqrt()
    }

    fn detect(&self) -> Symmetries {
        let c0 = self.centroid;
        let (_, cov) = covariance(self.points);
        let (vals, vecs) = principal_axes(&cov);
        let noise = self.eigenvalue_noise();
        let gap = |i: usize, j: usize| (vals[i] - vals[j]).abs();
        let equal =
            |i: usize, j: usize| gap(i, j) <= (EQUAL_EIGENVALUES * vals[i].max(vals[j])).max(EQUAL_NOISE * noise);
        let (e01, e12) = (equal(0, 1), equal(1, 2));
        let distinct = match (e01, e12) {
            (true, false) => Some(2),
            (false, true) => Some(0),
            _ => None,
        };
        let mut candidates: Vec<V3> = match distinct {
            Some(i) => vec![vecs[i]],
            None => vecs.to_vec(),
        };
        // Eigenvectors are only as sure as their gaps are large against the noise; with an
        // isotropic or barely resolved covariance the sample itself proposes axes too.
        let resolved = |i: usize, j: usize| equal(i, j) || gap(i, j) >= RESOLVED_NOISE * noise;
        let from_sample = (e01 && e12) || !(resolved(0, 1) && resolved(1, 2) && resolved(0, 2));
        if from_sample {
            for a in self.sample_axes() {
                if !candidates.iter().any(|b| same_line(&a, b, SAME_AXIS)) {
                    candidates.push(a);
                }
            }
        }
        let mut findings: Vec<AxisFinding> = Vec::new();
        let mut known_lines: Vec<V3> = Vec::new();
        let across = 3f64.to_radians().sin();
        for a in &candidates {
            if known_lines.iter().any(|l| same_line(l, a, 5f64.to_radians())) {
                continue;
            }
            // Beside a continuous axis only flips across it remain, all equivalent (or the part is
            // a sphere, which keeps the first axis): other lines are not worth testing.
            let spin = findings.iter().find(|f| f.continuous);
            if let Some(sp) = spin {
                let flipped = findings
                    .iter()
                    .any(|f| !f.continuous && f.axis.dot(&sp.axis).abs() < across);
                if flipped || sp.axis.dot(a).abs() >= across {
                    continue;
                }
            }
            let ex = self.examine(a, &c0, &findings);
            if let Some(f) = ex {
                if f.continuous && spin.is_some() {
                    break;
                }
                findings.push(f);
                // Every rotation axis of the group found so far is settled.
                let found: Vec<Rot> = findings
                    .iter()
                    .filter(|f| !f.continuous)
                    .map(|f| rot(&f.axis, TAU / f.order as f64))
                    .collect();
                known_lines = findings.iter().map(|f| f.axis).collect();
                if let Some(g) = close(&found, self.max_group()) {
                    known_lines.extend(axis_lines(&g).into_iter().map(|l| l.0));
                }
            }
        }
        // Flips across an axis of order ≥ 3 (or across the distinct axis) are not principal axes
        // of their own: sweep for one unless the rotations found already reverse the axis.
        let mut sweeps: Vec<(V3, Point, Option<usize>)> = Vec::new();
        if let Some(i) = distinct {
            match findings
                .iter()
                .find(|f| same_line(&f.axis, &vecs[i], 5f64.to_radians()))
            {
                Some(f) => sweeps.push((f.axis, f.point, (!f.continuous).then_some(f.order))),
                // An unreliable eigenvector that is no symmetry axis is not worth a sweep.
                None if !from_sample => sweeps.push((vecs[i], c0, Some(1))),
                None => {}
            }
        }
        let first_spin = findings.iter().position(|f| f.continuous);
        for (k, f) in findings.iter().enumerate() {
            if f.continuous && Some(k) != first_spin {
                continue;
            }
            if (f.continuous || f.order >= 3) && !sweeps.iter().any(|(s, _, _)| same_line(s, &f.axis, SAME_AXIS)) {
                sweeps.push((f.axis, f.point, (!f.continuous).then_some(f.order)));
            }
        }
        for (a, p, order) in sweeps {
            let found: Vec<Rot> = findings
                .iter()
                .filter(|f| !f.continuous)
                .map(|f| rot(&f.axis, TAU / f.order as f64))
                .collect();
            let reversed = close(&found, self.max_group())
                .is_some_and(|g| g.iter().any(|r| (r * a).dot(&a) < -(3f64.to_radians().cos())));
            if !reversed {
                if let Some(f) = self.flip_across(&a, &p, order) {
                    findings.push(f);
                }
            }
        }
        match first_spin {
            Some(k) => self.continuous_group(&findings[k], &findings),
            None => self.discrete_group(findings),
        }
    }

    /// Largest consistent group: the icosahedral fits, and so does the dihedral group of any
    /// order an axis can be given (up to 4 × `max_order`, see [`Matcher::examine`]).
    fn max_group(&self) -> usize {
        MAX_GROUP.max(8 * self.max_order)
    }

    /// The least-squares point nearest the lines (pulled weakly toward the centroid, which fixes
    /// the directions the lines leave free).
    fn center_of(&self, lines: &[(V3, Point)]) -> Point {
        let weak = 1e-3;
        let mut m = Matrix3::identity() * weak;
        let mut b = self.centroid.coords * weak;
        for (a, p) in lines {
            let proj = Matrix3::identity() - a * a.transpose();
            m += proj;
            b += proj * p.coords;
        }
        m.lu().solve(&b).map(Point::from).unwrap_or(self.centroid)
    }

    fn continuous_group(&self, cont: &AxisFinding, findings: &[AxisFinding]) -> Symmetries {
        let a = cont.axis.normalize();
        let across = 3f64.to_radians().sin();
        let flip = findings
            .iter()
            .filter(|f| !f.continuous && f.order % 2 == 0 && f.axis.dot(&a).abs() < across)
            .max_by(|x, y| x.agreement.total_cmp(&y.agreement));
        let mut lines = vec![(a, cont.point)];
        let mut rotations = vec![Rot::identity()];
        if let Some(f) = flip {
            let u = (f.axis - a * a.dot(&f.axis)).normalize();
            lines.push((u, f.point));
            rotations.push(rot(&u, PI));
        }
        let check = |c: &Point| {
            self.passes(&rot(&a, CONTINUOUS_ANGLES_DEG[3].to_radians()), c)
                && rotations.iter().skip(1).all(|r| self.passes(r, c))
        };
        let mut center = self.center_of(&lines);
        if !check(&center) {
            center = cont.point;
            if rotations.len() > 1 && !check(&center) {
                rotations.truncate(1);
            }
        }
        Symmetries {
            center,
            continuous_axis: Some(a),
            rotations,
        }
    }

    fn discrete_group(&self, mut findings: Vec<AxisFinding>) -> Symmetries {
        findings.sort_by(|x, y| y.agreement.total_cmp(&x.agreement));
        let mut generators: Vec<Rot> = Vec::new();
        let mut used: Vec<AxisFinding> = Vec::new();
        let mut group = vec![Rot::identity()];
        for f in findings {
            let g = rot(&f.axis, TAU / f.order as f64);
            if group.iter().any(|e| e.angle_to(&g) < SAME_ROTATION) {
                used.push(f);
                continue;
            }
            generators.push(g);
            match close(&generators, self.max_group()) {
                Some(next) => {
                    group = next;
                    used.push(f);
                }
                None => {
                    generators.pop();
                }
            }
        }
        if group.len() == 1 {
            return Symmetries::none(self.centroid);
        }
        let lines: Vec<(V3, Point)> = used.iter().map(|f| (f.axis, f.point)).collect();
        let center = self.center_of(&lines);
        if let Some((exact, gens)) = exact_group(&group) {
            for c in [center, self.centroid] {
                if gens.iter().all(|g| self.passes(g, &c)) {
                    return Symmetries {
                        center: c,
                        continuous_axis: None,
                        rotations: exact,
                    };
                }
            }
        }
        // Inconsistent or unrecognised: keep the closure of the accepted rotations as found.
        let center = if generators.iter().all(|g| self.passes(g, &center)) {
            center
        } else {
            self.centroid
        };
        Symmetries {
            center,
            continuous_axis: None,
            rotations: group,
        }
    }
}

fn lcm(a: usize, b: usize) -> usize {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    a / gcd(a, b) * b
}

/// The group generated by `generators` (identity first), or `None` past `limit` elements.
fn close(generators: &[Rot], limit: usize) -> Option<Vec<Rot>> {
    let mut group = vec![Rot::identity()];
    let mut k = 0;
    while k < group.len() {
        let e = group[k];
        for g in generators {
            let p = g * e;
            if !group.iter().any(|x| x.angle_to(&p) < SAME_ROTATION) {
                group.push(p);
                if group.len() > limit {
                    return None;
                }
            }
        }
        k += 1;
    }
    Some(group)
}

/// Rotation axes of a group as lines (sign-aligned mean direction, order = elements about the
/// line + 1), highest order first.
fn axis_lines(group: &[Rot]) -> Vec<(V3, usize)> {
    let mut lines: Vec<(V3, usize)> = Vec::new();
    for q in group {
        let Some(axis) = q.axis() else { continue };
        if q.angle() < SAME_ROTATION {
            continue;
        }
        let axis = axis.into_inner();
        match lines
            .iter_mut()
            .find(|(s, _)| same_line(&s.normalize(), &axis, SAME_AXIS))
        {
            Some((s, n)) => {
                *s += if axis.dot(s) >= 0.0 { axis } else { -axis };
                *n += 1;
            }
            None => lines.push((axis, 1)),
        }
    }
    let mut lines: Vec<(V3, usize)> = lines.into_iter().map(|(s, n)| (s.normalize(), n + 1)).collect();
    lines.sort_by_key(|l| std::cmp::Reverse(l.1));
    lines
}

/// Recognises an approximate finite rotation group and rebuilds it exactly from its axes:
/// (elements, identity first; a generating set). `None` when it is none of the known kinds or
/// the rebuilt group strays more than 2° from the one found.
fn exact_group(approx: &[Rot]) -> Option<(Vec<Rot>, Vec<Rot>)> {
    let size = approx.len();
    let lines = axis_lines(approx);
    let top = lines.first()?.1;
    let perpendicular = |a: &V3, order: usize| {
        lines
            .iter()
            .find(|(b, n)| *n == order && a.dot(b).abs() < 3f64.to_radians().sin())
            .map(|l| l.0)
    };
    let frame = |x: &V3, y: &V3| {
        let y = (y - x * x.dot(y)).normalize();
        let m = Matrix3::from_columns(&[*x, y, x.cross(&y)]);
        Rot::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m))
    };
    let conjugate = |f: &Rot, std: &[Rot]| std.iter().map(|s| f * s * f.inverse()).collect::<Vec<_>>();
    let candidates: Vec<(Vec<Rot>, Vec<Rot>)> = if lines.len() == 1 && size == top {
        let a = lines[0].0;
        let gens = vec![rot(&a, TAU / top as f64)];
        vec![((0..top).map(|k| rot(&a, TAU * k as f64 / top as f64)).collect(), gens)]
    } else if size == 2 * top {
        let a = lines[0].0;
        let u = perpendicular(&a, 2)?;
        let u = (u - a * a.dot(&u)).normalize();
        let spins: Vec<Rot> = (0..top).map(|k| rot(&a, TAU * k as f64 / top as f64)).collect();
        let flip = rot(&u, PI);
        let elements = spins.iter().copied().chain(spins.iter().map(|s| s * flip)).collect();
        vec![(elements, vec![rot(&a, TAU / top as f64), flip])]
    } else if (size, top) == (12, 3) || (size, top) == (60, 5) {
        let x = lines.iter().find(|l| l.1 == 2)?.0;
        let y = perpendicular(&x, 2)?;
        let f = frame(&x, &y);
        let variants = if size == 12 { vec![tetrahedral()] } else { icosahedral() };
        variants
            .iter()
            .map(|(elements, gens)| (conjugate(&f, elements), conjugate(&f, gens)))
            .collect()
    } else if (size, top) == (24, 4) {
        let x = lines[0].0;
        let y = perpendicular(&x, 4)?;
        let f = frame(&x, &y);
        let (elements, gens) = octahedral();
        vec![(conjugate(&f, &elements), conjugate(&f, &gens))]
    } else {
        return None;
    };
    candidates.into_iter().find(|(elements, _)| {
        elements.len() == size
            && elements
                .iter()
                .all(|e| approx.iter().any(|q| q.angle_to(e) < MAX_REBUILD_SHIFT))
    })
}

/// A finite rotation group in its standard frame: (elements, identity first; generators).
type StandardGroup = (Vec<Rot>, Vec<Rot>);

fn standard(generators: Vec<Rot>) -> Option<StandardGroup> {
    close(&generators, MAX_GROUP).map(|g| (g, generators))
}

/// The rotations of a regular tetrahedron whose 2-fold axes are x, y, z.
fn tetrahedral() -> StandardGroup {
    standard(vec![
        rot(&V3::x(), PI),
        rot(&V3::y(), PI),
        rot(&V3::new(1.0, 1.0, 1.0), TAU / 3.0),
    ])
    .expect("12 elements")
}

/// The rotations of a cube with faces across x, y, z.
fn octahedral() -> StandardGroup {
    standard(vec![rot(&V3::x(), PI / 2.0), rot(&V3::y(), PI / 2.0)]).expect("24 elements")
}

/// The two icosahedral groups containing [`tetrahedral`]: 5-fold axes along the cyclic
/// permutations of (0, ±1, ±φ), or of (0, ±φ, ±1).
fn icosahedral() -> Vec<StandardGroup> {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    [V3::new(0.0, 1.0, phi), V3::new(0.0, phi, 1.0)]
        .iter()
        .filter_map(|v| {
            standard(vec![
                rot(&V3::x(), PI),
                rot(&V3::y(), PI),
                rot(&V3::new(1.0, 1.0, 1.0), TAU / 3.0),
                rot(v, TAU / 5.0),
            ])
        })
        .filter(|g| g.0.len() == 60)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::TriMesh;
    use crate::model::{sample_surface, Density};

    type Mesh = (Vec<Point>, Vec<[u32; 3]>);

    fn cuboid(half: [f64; 3], offset: V3) -> Mesh {
        let v = (0..8)
            .map(|i| {
                let s = |bit: usize, h: f64| if (i >> bit) & 1 == 1 { h } else { -h };
                Point::from(V3::new(s(0, half[0]), s(1, half[1]), s(2, half[2])) + offset)
            })
            .collect();
        let faces = vec![
            [0, 2, 1],
            [1, 2, 3],
            [4, 5, 6],
            [5, 7, 6],
            [0, 1, 4],
            [1, 5, 4],
            [2, 6, 3],
            [3, 6, 7],
            [0, 4, 2],
            [2, 4, 6],
            [1, 3, 5],
            [3, 7, 5],
        ];
        (v, faces)
    }

    /// A right prism over a regular `sides`-gon with a vertex on +x, axis z, centred at the origin.
    fn prism(sides: usize, radius: f64, half_height: f64) -> Mesh {
        let mut v = vec![Point::new(0.0, 0.0, -half_height), Point::new(0.0, 0.0, half_height)];
        for z in [-half_height, half_height] {
            for k in 0..sides {
                let a = TAU * k as f64 / sides as f64;
                v.push(Point::new(radius * a.cos(), radius * a.sin(), z));
            }
        }
        let n = sides as u32;
        let (b, t) = (|k: u32| 2 + k % n, |k: u32| 2 + n + k % n);
        let mut f = Vec::new();
        for k in 0..n {
            f.push([0, b(k + 1), b(k)]);
            f.push([1, t(k), t(k + 1)]);
            f.push([b(k), b(k + 1), t(k + 1)]);
            f.push([b(k), t(k + 1), t(k)]);
        }
        (v, f)
    }

    fn merge(meshes: &[Mesh]) -> Mesh {
        let (mut v, mut f) = (Vec::new(), Vec::new());
        for (mv, mf) in meshes {
            let base = v.len() as u32;
            v.extend_from_slice(mv);
            f.extend(mf.iter().map(|t| [t[0] + base, t[1] + base, t[2] + base]));
        }
        (v, f)
    }

    /// The part posed in its model frame by a seeded rotation and translation, sampled evenly.
    struct Case {
        sym: Symmetries,
        pose: Isometry3<f64>,
    }

    fn detect(mesh: Mesh, spacing: f64, seed: u64) -> Case {
        let mut rng = Rng::new(seed);
        let pose = Isometry3::from_parts(
            Translation3::new(
                rng.range(-100.0, 100.0),
                rng.range(-100.0, 100.0),
                rng.range(-100.0, 100.0),
            ),
            rng.rotation(),
        );
        let mesh = TriMesh::new(mesh.0.iter().map(|p| pose.transform_point(p)).collect(), mesh.1).unwrap();
        assert!(mesh.volume() > 0.0);
        let s = sample_surface(&mesh, Density::Spacing(spacing), seed).unwrap();
        let sym = detect_symmetries(&s.points, &s.normals, &SymmetryConfig::default()).unwrap();
        Case { sym, pose }
    }

    /// The detected group equals `expected` (in the part's own frame), element by element within 1°.
    fn assert_group(case: &Case, expected: &[Rot]) {
        let q = case.pose.rotation;
        let got = &case.sym.rotations;
        assert_eq!(got.len(), expected.len(), "group size; got {got:?}");
        assert!(got[0].angle() < 1e-12, "identity first");
        for e in expected {
            let e = q * e * q.inverse();
            let best = got.iter().map(|g| g.angle_to(&e)).fold(f64::INFINITY, f64::min);
            assert!(
                best < 1f64.to_radians(),
                "missing {:?} by {:.3}°",
                e.axis_angle(),
                best.to_degrees()
            );
        }
        // Exactly closed: every product is an element to rounding.
        for a in got {
            for b in got {
                let p = a * b;
                assert!(got.iter().any(|g| g.angle_to(&p) < 1e-9));
            }
        }
    }

    fn dihedral(n: usize) -> Vec<Rot> {
        let spins: Vec<Rot> = (0..n).map(|k| rot(&V3::z(), TAU * k as f64 / n as f64)).collect();
        let flip = rot(&V3::x(), PI);
        spins.iter().copied().chain(spins.iter().map(|s| s * flip)).collect()
    }

    fn random_pose(rng: &mut Rng) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(
                rng.range(-500.0, 500.0),
                rng.range(-500.0, 500.0),
                rng.range(0.0, 800.0),
            ),
            rng.rotation(),
        )
    }

    fn assert_same_pose(a: &Isometry3<f64>, b: &Isometry3<f64>) {
        assert!(
            a.rotation.angle_to(&b.rotation) < 1e-9,
            "rotations differ by {:e}",
            a.rotation.angle_to(&b.rotation)
        );
        assert!((a.translation.vector - b.translation.vector).norm() < 1e-7);
    }

    /// `canonical` is the same for T and T·S, and `pose_error` of T·S against T is zero, for every
    /// symmetry S (plus, with a continuous axis, turns by random angles); a 3° perturbation about
    /// the centre reads as 3° (at most 3° with a continuous axis, where other turns may come closer).
    fn check_poses(sym: &Symmetries, seed: u64) {
        let mut rng = Rng::new(seed);
        let mut all = sym.transforms(0.3);
        if let Some(a) = sym.continuous_axis {
            for r in &sym.rotations {
                for _ in 0..20 {
                    all.push(sym.about_center(&(r * rot(&a, rng.range(-PI, PI)))));
                }
            }
        }
        for _ in 0..5 {
            let t = random_pose(&mut rng);
            let canon = sym.canonical(&t);
            assert!(canon.rotation.angle() <= t.rotation.angle() + 1e-12);
            let wobble = sym.about_center(&rot(
                &V3::new(rng.normal(), rng.normal(), rng.normal()),
                3f64.to_radians(),
            ));
            for s in &all {
                let ts = t * s;
                assert_same_pose(&sym.canonical(&ts), &canon);
                let (r, d) = sym.pose_error(&ts, &t);
                assert!(r < 1e-7 && d < 1e-6, "error {r} rad, {d} mm");
                let (r, _) = sym.pose_error(&(ts * wobble), &t);
                if sym.continuous_axis.is_some() {
                    assert!(r <= 3f64.to_radians() + 1e-9);
                } else {
                    assert!((r - 3f64.to_radians()).abs() < 1e-9, "{}", r.to_degrees());
                }
            }
        }
    }

    #[test]
    fn box_with_three_sides_has_the_d2_group() {
        let case = detect(cuboid([30.0, 20.0, 12.0], V3::zeros()), 1.8, 1);
        assert!(case.sym.continuous_axis.is_none());
        assert_group(
            &case,
            &[Rot::identity(), rot(&V3::x(), PI), rot(&V3::y(), PI), rot(&V3::z(), PI)],
        );
        assert!(
            (case.sym.center - case.pose.translation.vector).coords.norm() < 0.3,
            "{:?}",
            case.sym.center
        );
        check_poses(&case.sym, 11);
    }

    #[test]
    fn square_prism_has_the_d4_group() {
        let case = detect(prism(4, 20.0 * 2f64.sqrt(), 35.0), 2.2, 2);
        assert_group(&case, &dihedral(4));
        assert!((case.sym.center - case.pose.translation.vector).coords.norm() < 0.3);
        check_poses(&case.sym, 12);
    }

    #[test]
    fn hexagonal_prism_has_the_d6_group() {
        let case = detect(prism(6, 25.0, 25.0), 1.8, 3);
        assert_group(&case, &dihedral(6));
        assert!((case.sym.center - case.pose.translation.vector).coords.norm() < 0.3);
        check_poses(&case.sym, 13);
    }

    #[test]
    fn cylinder_has_a_continuous_axis_and_a_flip() {
        let case = detect(prism(128, 20.0, 30.0), 1.8, 4);
        let sym = &case.sym;
        let axis = sym.continuous_axis.expect("continuous axis");
        let z = case.pose.rotation * V3::z();
        assert!(same_line(&axis, &z, 1f64.to_radians()), "axis {axis:?}, expected {z:?}");
        assert_eq!(sym.rotations.len(), 2);
        let flip = sym.rotations[1];
        assert!((flip.angle() - PI).abs() < 1e-9 && flip.axis().unwrap().dot(&axis).abs() < 1e-9);
        assert_eq!(sym.order(), None);
        assert!((sym.center - case.pose.translation.vector).coords.norm() < 0.3);
        assert_eq!(sym.transforms(TAU / 90.0).len(), 180);
        check_poses(sym, 14);
    }

    #[test]
    fn cube_has_the_octahedral_group() {
        let case = detect(cuboid([20.0; 3], V3::zeros()), 1.8, 5);
        assert_group(&case, &octahedral().0);
        check_poses(&case.sym, 15);
    }

    #[test]
    fn box_with_an_off_centre_bump_is_asymmetric() {
        let part = merge(&[
            cuboid([30.0, 20.0, 12.0], V3::zeros()),
            cuboid([6.0, 6.0, 3.5], V3::new(14.0, 7.0, 15.0)),
        ]);
        let case = detect(part, 1.8, 6);
        let sym = &case.sym;
        assert!(sym.is_trivial(), "{sym:?}");
        assert_eq!(sym.order(), Some(1));
        let mut rng = Rng::new(16);
        for _ in 0..20 {
            let (est, truth) = (random_pose(&mut rng), random_pose(&mut rng));
            let (r, d) = sym.pose_error(&est, &truth);
            assert!((r - est.rotation.angle_to(&truth.rotation)).abs() < 1e-12);
            assert!((d - (est.translation.vector - truth.translation.vector).norm()).abs() < 1e-9);
            assert_same_pose(&sym.canonical(&est), &est);
        }
    }

    /// A convex polyhedron from its vertices: every triple at the edge length whose plane has all
    /// vertices on one side, wound outward.
    fn polyhedron(v: Vec<Point>, edge: f64) -> Mesh {
        let n = v.len();
        let is_edge = |i: usize, j: usize| ((v[i] - v[j]).norm() - edge).abs() < 1e-9;
        let mut f = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                for k in j + 1..n {
                    if is_edge(i, j) && is_edge(j, k) && is_edge(i, k) {
                        let normal = (v[j] - v[i]).cross(&(v[k] - v[i]));
                        let t = if normal.dot(&(v[i].coords)) > 0.0 {
                            [i, j, k]
                        } else {
                            [i, k, j]
                        };
                        f.push(t.map(|x| x as u32));
                    }
                }
            }
        }
        (v, f)
    }

    #[test]
    fn tetrahedron_has_the_tetrahedral_group() {
        let s = 18.0;
        let v = [(1.0, 1.0, 1.0), (1.0, -1.0, -1.0), (-1.0, 1.0, -1.0), (-1.0, -1.0, 1.0)]
            .map(|(x, y, z)| Point::new(s * x, s * y, s * z));
        let mesh = polyhedron(v.to_vec(), s * 8f64.sqrt());
        assert_eq!(mesh.1.len(), 4);
        let case = detect(mesh, 1.8, 7);
        assert_group(&case, &tetrahedral().0);
        check_poses(&case.sym, 17);
    }

    #[test]
    fn icosahedron_has_the_icosahedral_group() {
        let (s, phi) = (14.0, (1.0 + 5f64.sqrt()) / 2.0);
        let mut v = Vec::new();
        for a in [-1.0, 1.0] {
            for b in [-phi, phi] {
                v.extend([
                    Point::new(0.0, s * a, s * b),
                    Point::new(s * a, s * b, 0.0),
                    Point::new(s * b, 0.0, s * a),
                ]);
            }
        }
        let mesh = polyhedron(v, 2.0 * s);
        assert_eq!(mesh.1.len(), 20);
        let case = detect(mesh, 1.8, 8);
        assert_group(&case, &icosahedral()[0].0);
        check_poses(&case.sym, 18);
    }

    #[test]
    fn a_centred_boss_leaves_a_cyclic_group() {
        // A square prism with a square boss centred on one end keeps only its 4-fold turns.
        let part = merge(&[
            prism(4, 20.0 * 2f64.sqrt(), 35.0),
            cuboid([6.0, 6.0, 3.5], V3::new(0.0, 0.0, 38.0)),
        ]);
        let case = detect(part, 2.2, 9);
        assert_group(
            &case,
            &(0..4).map(|k| rot(&V3::z(), TAU * k as f64 / 4.0)).collect::<Vec<_>>(),
        );
        check_poses(&case.sym, 19);
    }

    #[test]
    fn independent_uniform_samples_work_with_the_default_tolerance() {
        let mut rng = Rng::new(10);
        let pose = Isometry3::from_parts(Translation3::new(5.0, 6.0, 7.0), rng.rotation());
        let (v, f) = prism(4, 20.0 * 2f64.sqrt(), 35.0);
        let mesh = TriMesh::new(v.iter().map(|p| pose.transform_point(p)).collect(), f).unwrap();
        let s = sample_surface(&mesh, Density::Count(3000), 10).unwrap();
        let sym = detect_symmetries(&s.points, &s.normals, &SymmetryConfig::default()).unwrap();
        assert_group(&Case { sym, pose }, &dihedral(4));
    }

    #[test]
    fn standard_groups_are_complete() {
        assert_eq!(tetrahedral().0.len(), 12);
        assert_eq!(octahedral().0.len(), 24);
        let ico = icosahedral();
        assert_eq!(ico.len(), 2);
        assert!(ico.iter().all(|g| g.0.len() == 60));
    }

    #[test]
    fn bad_input_is_rejected() {
        let (v, f) = cuboid([30.0, 20.0, 12.0], V3::zeros());
        let s = sample_surface(&TriMesh::new(v, f).unwrap(), Density::Spacing(3.0), 1).unwrap();
        let cfg = SymmetryConfig::default();
        assert!(matches!(
            detect_symmetries(&s.points[..10], &s.normals[..10], &cfg),
            Err(Error::TooFewPoints { .. })
        ));
        assert!(matches!(
            detect_symmetries(&s.points, &s.normals[1..], &cfg),
            Err(Error::InvalidInput { .. })
        ));
        let mut zero = s.normals.clone();
        zero[3] = V3::zeros();
        assert!(matches!(
            detect_symmetries(&s.points, &zero, &cfg),
            Err(Error::InvalidInput { .. })
        ));
        for bad in [
            SymmetryConfig {
                tolerance: Some(-1.0),
                ..cfg
            },
            SymmetryConfig {
                min_agreement: 0.0,
                ..cfg
            },
            SymmetryConfig { max_order: 1, ..cfg },
            SymmetryConfig { max_points: 10, ..cfg },
        ] {
            assert!(
                matches!(
                    detect_symmetries(&s.points, &s.normals, &bad),
                    Err(Error::InvalidInput { .. })
                ),
                "{bad:?}"
            );
        }
        let none = Symmetries::none(Point::new(1.0, 2.0, 3.0));
        assert!(none.is_trivial());
        assert_eq!(none.transforms(0.1).len(), 1);
    }
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
