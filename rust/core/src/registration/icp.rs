//! KD-tree ICP: point-to-point (closed-form SVD) and point-to-plane (Gauss–Newton on SE(3)).
//!
//! Each iteration finds, for every source point moved by the current estimate, its nearest
//! target point within `max_correspondence_distance` ([`CorrespondenceTree`]); from the second
//! iteration on the search is bounded by the point's previous match distance plus how far the
//! point moved, which keeps it exact and cheap. Source points are visited in Z-order so that
//! consecutive searches touch nearby memory. The sums the solver needs are accumulated per
//! rayon task and merged, so the work splits across threads without locks. Sums are taken
//! about the target's centroid, which keeps them well conditioned far from the origin.

use super::config::{IcpConfig, IcpMethod, RobustKernel};
use crate::error::{Error, Result};
use crate::geometry::{centroid, check_count, check_finite, check_spread, kabsch, Point};
use crate::parallel::with_threads;
use crate::search::corr_tree::{spatial_order, CorrespondenceTree};
use crate::search::field::NearestField;
use nalgebra::{Isometry3, Matrix3, Matrix6, SymmetricEigen, Translation3, UnitQuaternion, Vector3, Vector6};
use rayon::prelude::*;

const CHUNK: usize = 2048;

/// A target cloud prepared for ICP: its points, optional unit normals and its search structure.
/// Build it once and reuse it across many registrations against the same target.
pub struct IcpTarget {
    points: Vec<Point>,
    normals: Option<Vec<Vector3<f64>>>,
    search: CorrespondenceTree,
    center: Point,
    field: Option<NearestField>,
    /// The samples' spacing, mm, where the maker of the target knows it ([`IcpTarget::with_spacing`]).
    spacing: Option<f64>,
}

impl IcpTarget {
    /// Validates the cloud (finite, at least 3 points, not all on one line) and builds the KD-tree.
    pub fn new(points: Vec<Point>, normals: Option<Vec<Vector3<f64>>>) -> Result<Self> {
        check_finite("target", &points)?;
        check_count("target", &points, 3, "ICP needs a target surface")?;
        check_spread(
            "target",
            &points,
            2,
            "ICP cannot fix a rotation against a line or a single point; pass a cloud that covers a surface",
        )?;
        if let Some(n) = &normals {
            if n.len() != points.len() {
                return Err(Error::invalid(
                    "target_normals",
                    format!("has {} rows but target has {}", n.len(), points.len()),
                ));
            }
            for (i, v) in n.iter().enumerate() {
                if !v.iter().all(|x| x.is_finite()) || (v.norm() - 1.0).abs() > 1e-3 {
                    return Err(Error::invalid("target_normals", format!("row {i} is not a finite unit vector ({v:?}); normalise the normals or let binpick estimate them")));
                }
            }
        }
        let search = CorrespondenceTree::new(&points);
        let center = centroid(&points);
        Ok(IcpTarget {
            points,
            normals,
            search,
            center,
            field: None,
            spacing: None,
        })
    }

    /// The target, knowing its samples lie about `spacing` mm apart (a surface sampled evenly).
    pub fn with_spacing(mut self, spacing: f64) -> Self {
        self.spacing = (spacing.is_finite() && spacing > 0.0).then_some(spacing);
        self
    }

    /// The samples' spacing, mm, where known.
    pub fn spacing(&self) -> Option<f64> {
        self.spacing
    }

    /// The target's points.
    pub fn points(&self) -> &[Point] {
        &self.points
    }

    /// The exact bounded nearest-neighbour search over the target.
    pub fn search(&self) -> &CorrespondenceTree {
        &self.search
    }

    /// Adds the approximate nearest field that coarse checks use (cells of about `cell` mm over
    /// the target's box grown by `margin` mm).
    pub fn with_field(mut self, cell: f64, margin: f64) -> Self {
        self.set_field(cell, margin);
        self
    }

    /// Builds (or rebuilds) the approximate nearest field in place; see [`IcpTarget::with_field`].
    pub fn set_field(&mut self, cell: f64, margin: f64) {
        self.field = NearestField::new(&self.points, cell, margin);
    }

    /// The approximate nearest field, when built.
    pub fn field(&self) -> Option<&NearestField> {
        self.field.as_ref()
    }

    /// The target's normals, if it has them.
    pub fn normals(&self) -> Option<&[Vector3<f64>]> {
        self.normals.as_deref()
    }
}

/// The outcome of one ICP run.
#[derive(Debug, Clone, PartialEq)]
pub struct IcpResult {
    /// The estimated transform taking source points into the target frame.
    pub t_target_source: Isometry3<f64>,
    /// True when the last update fell below both tolerances before `max_iterations`.
    pub converged: bool,
    /// Number of updates applied.
    pub iterations: usize,
    /// Fraction of source points that found a target point within the correspondence distance.
    pub fitness: f64,
    /// Root-mean-square distance of those pairs, mm.
    pub rmse: f64,
    /// Number of such pairs.
    pub num_inliers: usize,
}

/// Sums for the point-to-point closed form.
#[derive(Clone, Copy)]
struct PointSums {
    w: f64,
    q: Vector3<f64>,
    t: Vector3<f64>,
    qt: Matrix3<f64>,
}

/// Sums for the point-to-plane normal equations: the upper triangle of JᵀWJ row by row (the
/// matrix is symmetric; accumulating 21 entries instead of 36 is most of an iteration's work).
#[derive(Clone, Copy)]
struct PlaneSums {
    h: [f64; 21],
    g: Vector6<f64>,
    w: f64,
}

impl PlaneSums {
    fn matrix(&self) -> Matrix6<f64> {
        let mut m = Matrix6::zeros();
        let mut k = 0;
        for i in 0..6 {
            for j in i..6 {
                m[(i, j)] = self.h[k];
                m[(j, i)] = self.h[k];
                k += 1;
            }
        }
        m
    }
}

trait Sums: Copy + Send + Sync {
    fn zero() -> Self;
    /// `q` the moved source point, `t` its target match, both relative to the centre.
    fn add(&mut self, q: &Vector3<f64>, t: &Vector3<f64>, n: &Vector3<f64>, w: f64);
    fn merge(self, o: Self) -> Self;
    fn residual(q: &Vector3<f64>, t: &Vector3<f64>, n: &Vector3<f64>) -> f64;
    fn min_pairs() -> usize;
    /// The solver's step from the sums: (rotation vector, translation) about the centre.
    fn step(&self) -> Option<(Vector3<f64>, Vector3<f64>)>;
}

impl Sums for PointSums {
    fn zero() -> Self {
        PointSums {
            w: 0.0,
            q: Vector3::zeros(),
            t: Vector3::zeros(),
            qt: Matrix3::zeros(),
        }
    }
    #[inline(always)]
    fn add(&mut self, q: &Vector3<f64>, t: &Vector3<f64>, _n: &Vector3<f64>, w: f64) {
        self.w += w;
        self.q += w * q;
        self.t += w * t;
        self.qt += (w * q) * t.transpose();
    }
    fn merge(self, o: Self) -> Self {
        PointSums {
            w: self.w + o.w,
            q: self.q + o.q,
            t: self.t + o.t,
            qt: self.qt + o.qt,
        }
    }
    #[inline(always)]
    fn residual(q: &Vector3<f64>, t: &Vector3<f64>, _n: &Vector3<f64>) -> f64 {
        (q - t).norm()
    }
    fn min_pairs() -> usize {
        3
    }
    fn step(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        point_step(self)
    }
}

impl Sums for PlaneSums {
    fn zero() -> Self {
        PlaneSums {
            h: [0.0; 21],
            g: Vector6::zeros(),
            w: 0.0,
        }
    }
    #[inline(always)]
    fn add(&mut self, q: &Vector3<f64>, t: &Vector3<f64>, n: &Vector3<f64>, w: f64) {
        let r = n.dot(&(q - t));
        let c = q.cross(n);
        let j = [c.x, c.y, c.z, n.x, n.y, n.z];
        let mut k = 0;
        for (a, &ja) in j.iter().enumerate() {
            let wa = w * ja;
            for &jb in &j[a..] {
                self.h[k] += wa * jb;
                k += 1;
            }
        }
        self.g += (w * r) * Vector6::from(j);
        self.w += w;
    }
    fn merge(self, o: Self) -> Self {
        PlaneSums {
            h: std::array::from_fn(|k| self.h[k] + o.h[k]),
            g: self.g + o.g,
            w: self.w + o.w,
        }
    }
    #[inline(always)]
    fn residual(q: &Vector3<f64>, t: &Vector3<f64>, n: &Vector3<f64>) -> f64 {
        n.dot(&(q - t)).abs()
    }
    fn min_pairs() -> usize {
        6
    }
    fn step(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        plane_step(self)
    }
}

/// One pass's sums plus the statistics of all pairs within the correspondence distance.
#[derive(Clone, Copy)]
struct Pass<S> {
    sums: S,
    inliers: usize,
    sq_dist: f64,
}

impl<S: Sums> Pass<S> {
    fn zero() -> Self {
        Pass {
            sums: S::zero(),
            inliers: 0,
            sq_dist: 0.0,
        }
    }
    fn merge(self, o: Self) -> Self {
        Pass {
            sums: self.sums.merge(o.sums),
            inliers: self.inliers + o.inliers,
            sq_dist: self.sq_dist + o.sq_dist,
        }
    }
}

/// Registers `source` onto `target` starting from `init` (source → target).
///
/// Errors are for misuse (bad config, non-finite or degenerate source, point-to-plane without
/// normals); a registration that finds too few correspondences is an outcome, reported with
/// `converged = false`.
pub fn icp(source: &[Point], target: &IcpTarget, init: &Isometry3<f64>, config: &IcpConfig) -> Result<IcpResult> {
    config.validate()?;
    check_finite("source", source)?;
    let needed = match config.method {
        IcpMethod::PointToPoint => PointSums::min_pairs(),
        IcpMethod::PointToPlane => PlaneSums::min_pairs(),
    };
    check_count(
        "source",
        source,
        needed,
        "register more points, or use a coarser voxel size",
    )?;
    check_spread(
        "source",
        source,
        2,
        "ICP cannot fix a rotation from points on a line; pass a cloud that covers a surface",
    )?;
    match config.method {
        IcpMethod::PointToPoint => {
            let result = with_threads(config.num_threads, || run::<PointSums>(source, target, init, config));
            crate::cancel::check().map(|()| result)
        }
        IcpMethod::PointToPlane => {
            if target.normals.is_none() {
                return Err(Error::invalid("target_normals", "point-to-plane ICP needs target normals; estimate them first (binpick.estimate_normals) or use method=\"point_to_point\""));
            }
            let result = with_threads(config.num_threads, || run::<PlaneSums>(source, target, init, config));
            crate::cancel::check().map(|()| result)
        }
    }
}

/// What the correspondence search of one ICP run needs: the target, the coarse nearest field
/// when the search may be approximate, the squared distance bound, the target's centre.
struct Matcher<'a> {
    target: &'a IcpTarget,
    approx: Option<&'a NearestField>,
    max_sq: f64,
    c: Vector3<f64>,
}

/// The current and the previous pose of one iteration, as rotations and shifts about the
/// target's centre: a source point moves to `q_c = R p + (t − c)`.
struct Motion {
    rot: Matrix3<f64>,
    shift: Vector3<f64>,
    rot_prev: Matrix3<f64>,
    shift_prev: Vector3<f64>,
}

impl Motion {
    fn new(t_est: &Isometry3<f64>, t_prev: &Isometry3<f64>, c: &Vector3<f64>) -> Self {
        Motion {
            rot: t_est.rotation.to_rotation_matrix().into_inner(),
            shift: t_est.translation.vector - c,
            rot_prev: t_prev.rotation.to_rotation_matrix().into_inner(),
            shift_prev: t_prev.translation.vector - c,
        }
    }
}

impl Matcher<'_> {
    /// The match of source point `p`: its moved position (about the centre), the target index
    /// and the squared distance. `last` is the distance of `p`'s previous match and `hint` the
    /// match of the previous point in Z-order: being near, both bound the search.
    #[inline]
    fn find(
        &self,
        m: &Motion,
        p: &Point,
        last: &mut f64,
        hint: &mut Option<Point>,
    ) -> Option<(Vector3<f64>, usize, f64)> {
        let (target, c) = (self.target, self.c);
        let q = m.rot * p.coords + m.shift;
        let qw = Point::from(q + c);
        if let Some(field) = self.approx {
            let j = field.nearest(&[qw.x, qw.y, qw.z])?;
            let d = (target.points[j] - qw).norm_squared();
            return (d <= self.max_sq).then_some((q, j, d));
        }
        let moved = (q - (m.rot_prev * p.coords + m.shift_prev)).norm();
        // The previous match is at most `last + moved` away now, so nothing nearer is missed.
        let bound = (*last + moved) * (1.0 + 1e-9) + 1e-12;
        let mut bound_sq = if bound.is_finite() {
            (bound * bound).min(self.max_sq)
        } else {
            self.max_sq
        };
        if let Some(h) = hint {
            bound_sq = bound_sq.min((qw - *h).norm_squared() * (1.0 + 1e-9) + 1e-12);
        }
        match target.search.nearest_within(&[qw.x, qw.y, qw.z], bound_sq) {
            Some((j, d)) => {
                *last = d.sqrt();
                *hint = Some(target.points[j]);
                Some((q, j, d))
            }
            None => {
                *last = f64::INFINITY;
                None
            }
        }
    }

    /// The weighted sums of one correspondence.
    #[inline]
    fn add<S: Sums>(&self, s: &mut S, q: &Vector3<f64>, j: usize, kernel: RobustKernel) {
        let zero_normal = Vector3::zeros();
        let tq = self.target.points[j].coords - self.c;
        let n = self.target.normals.as_deref().map_or(&zero_normal, |ns| &ns[j]);
        s.add(q, &tq, n, kernel.weight(S::residual(q, &tq, n)));
    }

    /// One pass over every source point, each correspondence summed.
    fn full_pass<S: Sums>(
        &self,
        m: &Motion,
        source: &[Point],
        last_match: &mut [f64],
        kernel: RobustKernel,
    ) -> Pass<S> {
        let chunk_pass = |chunk: &[Point], lasts: &mut [f64]| {
            let mut acc = Pass::<S>::zero();
            let mut hint = None;
            for (p, l) in chunk.iter().zip(lasts.iter_mut()) {
                if let Some((q, j, d)) = self.find(m, p, l, &mut hint) {
                    self.add(&mut acc.sums, &q, j, kernel);
                    acc.inliers += 1;
                    acc.sq_dist += d;
                }
            }
            acc
        };
        // One chunk needs no task: a small source (a coarse check) skips rayon's overhead.
        if source.len() <= CHUNK {
            chunk_pass(source, last_match)
        } else {
            source
                .par_chunks(CHUNK)
                .zip(last_match.par_chunks_mut(CHUNK))
                .map(|(chunk, lasts)| chunk_pass(chunk, lasts))
                .reduce(Pass::zero, Pass::merge)
        }
    }

    /// One pass that sums only the nearest `1 − trim_fraction` of the correspondences (the
    /// counts and distances are of all of them).
    fn trimmed_pass<S: Sums>(
        &self,
        m: &Motion,
        source: &[Point],
        last_match: &mut [f64],
        kernel: RobustKernel,
        trim_fraction: f64,
    ) -> Pass<S> {
        let mut pairs: Vec<(u32, u32, f64)> = source
            .par_iter()
            .zip(last_match.par_iter_mut())
            .enumerate()
            .filter_map(|(i, (p, l))| self.find(m, p, l, &mut None).map(|(_, j, d)| (i as u32, j as u32, d)))
            .collect();
        let inliers = pairs.len();
        let sq_dist: f64 = pairs.iter().map(|x| x.2).sum();
        let keep = ((1.0 - trim_fraction) * inliers as f64).ceil() as usize;
        if keep > 0 && keep < inliers {
            pairs.select_nth_unstable_by(keep - 1, |a, b| a.2.total_cmp(&b.2));
            pairs.truncate(keep);
        }
        let sums = pairs
            .par_chunks(CHUNK)
            .map(|chunk| {
                let mut s = S::zero();
                for &(i, j, _) in chunk {
                    let q = m.rot * source[i as usize].coords + m.shift;
                    self.add(&mut s, &q, j as usize, kernel);
                }
                s
            })
            .reduce(S::zero, S::merge);
        Pass { sums, inliers, sq_dist }
    }
}

fn run<S: Sums>(source_in: &[Point], target: &IcpTarget, init: &Isometry3<f64>, config: &IcpConfig) -> IcpResult {
    let c = target.center.coords;
    let matcher = Matcher {
        target,
        approx: if config.approximate {
            target.field.as_ref()
        } else {
            None
        },
        max_sq: config.max_correspondence_distance * config.max_correspondence_distance,
        c,
    };
    let source: Vec<Point> = spatial_order(source_in, config.max_correspondence_distance.max(1e-3) * 0.25)
        .into_iter()
        .map(|i| source_in[i as usize])
        .collect();
    // Distance of each source point's last match (infinite when it had none).
    let mut last_match = vec![f64::INFINITY; source.len()];
    let (mut t_est, mut t_prev) = (*init, *init);
    let mut converged = false;
    let mut iterations = 0;
    let mut last = Pass::<S>::zero();
    for _ in 0..config.max_iterations {
        if crate::cancel::requested() {
            break;
        }
        let motion = Motion::new(&t_est, &t_prev, &c);
        let pass = if config.trim_fraction > 0.0 {
            matcher.trimmed_pass(&motion, &source, &mut last_match, config.kernel, config.trim_fraction)
        } else {
            matcher.full_pass(&motion, &source, &mut last_match, config.kernel)
        };
        last = pass;
        if pass.inliers < S::min_pairs() {
            break;
        }
        let Some((omega, v)) = pass.sums.step() else { break };
        if !(omega.iter().chain(v.iter()).all(|x| x.is_finite())) {
            break;
        }
        let r_inc = UnitQuaternion::from_scaled_axis(omega);
        // The increment acts about the centre: x ↦ R (x − c) + c + v.
        let inc = Isometry3::from_parts(Translation3::from(c + v - (r_inc * c)), r_inc);
        t_prev = t_est;
        t_est = inc * t_est;
        iterations += 1;
        if omega.norm() < config.rotation_tolerance && v.norm() < config.translation_tolerance {
            converged = true;
            break;
        }
    }
    t_est.rotation.renormalize();
    let fitness = last.inliers as f64 / source.len() as f64;
    let rmse = if last.inliers > 0 {
        (last.sq_dist / last.inliers as f64).sqrt()
    } else {
        f64::INFINITY
    };
    IcpResult {
        t_target_source: t_est,
        converged,
        iterations,
        fitness,
        rmse,
        num_inliers: last.inliers,
    }
}

/// Closed-form point-to-point step (Arun/Kabsch): the rotation from the SVD of the centred
/// cross-covariance with the reflection case fixed, then the translation between the means.
fn point_step(s: &PointSums) -> Option<(Vector3<f64>, Vector3<f64>)> {
    if s.w <= 0.0 {
        return None;
    }
    let qm = s.q / s.w;
    let tm = s.t / s.w;
    let h = s.qt - s.w * qm * tm.transpose();
    let rot = UnitQuaternion::from_rotation_matrix(&kabsch(&h)?);
    let omega = rot.scaled_axis();
    let v = tm - rot * qm;
    Some((omega, v))
}

/// Gauss–Newton step for point-to-plane, solved through the eigen-decomposition of the 6×6
/// normal matrix so that directions the geometry cannot observe (sliding along a plane) get no
/// motion instead of a huge one.
fn plane_step(sums: &PlaneSums) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let h = sums.matrix();
    let g = sums.g;
    // Well-conditioned systems (the usual case) are solved by Cholesky on the Jacobi-scaled
    // matrix, a tenth of the eigen-decomposition's cost. A small pivot there means a direction
    // the geometry barely observes; then the eigen path below decides.
    let d = h.diagonal().map(|x| if x > 0.0 { 1.0 / x.sqrt() } else { 0.0 });
    if d.iter().all(|x| *x > 0.0 && x.is_finite()) {
        let scaled = Matrix6::from_fn(|i, j| h[(i, j)] * d[i] * d[j]);
        if let Some(ch) = scaled.cholesky() {
            if (0..6).all(|i| ch.l_dirty()[(i, i)] * ch.l_dirty()[(i, i)] > 1e-4) {
                let x = ch.solve(&(-g.component_mul(&d))).component_mul(&d);
                return Some((Vector3::new(x[0], x[1], x[2]), Vector3::new(x[3], x[4], x[5])));
            }
        }
    }
    let eig = SymmetricEigen::new(h);
    let max = eig.eigenvalues.iter().cloned().fold(0.0, f64::max);
    if max <= 0.0 {
        return None;
    }
    let mut delta = Vector6::zeros();
    for k in 0..6 {
        let lambda = eig.eigenvalues[k];
        if lambda > 1e-10 * max {
            let e = eig.eigenvectors.column(k);
            delta -= e * (e.dot(&g) / lambda);
        }
    }
    Some((
        Vector3::new(delta[0], delta[1], delta[2]),
        Vector3::new(delta[3], delta[4], delta[5]),
    ))
}
