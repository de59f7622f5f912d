//! The matcher: tests rotations of a sample against itself and assembles the group it finds.

use super::groups::*;
use super::*;

/// A symmetry axis found by [`Matcher::examine`]: its line and its order.
#[derive(Debug, Clone, Copy)]
pub(super) struct AxisFinding {
    axis: V3,
    point: Point,
    /// n of the n-fold symmetry (2 and up); 0 when continuous.
    order: usize,
    continuous: bool,
    agreement: f64,
}

/// Tests rotations of the sample against itself.
pub(super) struct Matcher<'a> {
    points: &'a [Point],
    normals: Vec<V3>,
    tree: CorrespondenceTree,
    kd: KdIndex,
    tol: f64,
    /// Median nearest-neighbour spacing of the samples, mm.
    spacing: f64,
    /// Whether a rotation must also leave no feature (see [`Matcher::feature_free`]) to pass:
    /// set once the group found at the agreement alone turned out to hold one.
    pub(super) strict: bool,
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
    pub(super) fn new(points: &'a [Point], normals: Vec<V3>, cfg: &SymmetryConfig) -> Result<Self> {
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
            spacing: median,
            strict: false,
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
    /// distance is within `tol` and its normal agrees with `nr` (any normal for `None`). With
    /// `fallback`, a few further neighbours are tried when the nearest disagrees.
    #[inline]
    fn correspond(&self, m: &Point, nr: Option<&V3>, tol: f64, fallback: bool) -> Option<(usize, f64)> {
        let q = [m.x, m.y, m.z];
        let (j, _) = self
            .tree
            .nearest_within(&q, self.near2)
            .or_else(|| self.tree.nearest_within(&q, self.reach2))?;
        let agrees = |j: usize| {
            let r = self.normals[j].dot(&(m - self.points[j]));
            let facing = nr.is_none_or(|n| n.dot(&self.normals[j]) > MIN_NORMAL_DOT);
            (facing && r.abs() <= tol).then_some((j, r))
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
            if self
                .correspond(&m, Some(&(r * self.normals[i])), self.tol, true)
                .is_none()
            {
                fails += 1;
                if fails > allowed {
                    return 0.0;
                }
            }
        }
        (n - fails) as f64 / n as f64
    }

    /// Per sample (all of them, not the test subsample): whether `r` about `c` fails to map it
    /// onto the surface.
    pub(super) fn failures(&self, r: &Rot, c: &Point) -> Vec<bool> {
        self.points
            .iter()
            .zip(&self.normals)
            .map(|(p, n)| {
                let m = c + r * (p - c);
                self.correspond(&m, Some(&(r * n)), self.tol, true).is_none()
            })
            .collect()
    }

    fn passes(&self, r: &Rot, c: &Point) -> bool {
        self.passes_as(r, c, false)
    }

    /// [`Matcher::passes`] for a discrete turn, or (`continuous`) one of a continuous axis's.
    fn passes_as(&self, r: &Rot, c: &Point, continuous: bool) -> bool {
        self.accepts_as(r, c, self.agreement(r, c), continuous)
    }

    /// Whether `r` about `c`, mapping `agreement` of the test subsample, is a symmetry.
    fn accepts(&self, r: &Rot, c: &Point, agreement: f64) -> bool {
        self.accepts_as(r, c, agreement, false)
    }

    /// [`Matcher::accepts`] for a discrete turn, or (`continuous`) one of a continuous axis's.
    fn accepts_as(&self, r: &Rot, c: &Point, agreement: f64, continuous: bool) -> bool {
        agreement >= self.min_agreement && (!self.strict || self.feature_free_as(r, c, continuous))
    }

    /// Whether `r` about `c` leaves no feature: no patch of [`MIN_FEATURE_SAMPLES`] samples
    /// (linked within two spacings) that `r` or its inverse maps where the part has no surface
    /// (no sample among the nearest within reach whose tangent plane passes within
    /// [`FEATURE_TOLERANCE`] of the tolerance;
    /// normals are not asked, so a sample turned onto an edge or a facet of a tessellated round
    /// is never absent). The agreement alone lets a feature pass that covers less than
    /// `1 − min_agreement` of the surface — a 3 mm cut corner on a 100 mm plate is 0.3 % of it —
    /// however plainly a scan shows it. Beyond [`FEATURE_SAMPLES`] samples every k-th is tested
    /// (sampled surfaces come in random order) with links k^½ times longer, so the smallest
    /// patch found grows k-fold in area.
    pub(super) fn feature_free(&self, r: &Rot, c: &Point) -> bool {
        self.feature_free_as(r, c, false)
    }

    /// [`Matcher::feature_free`] for a discrete turn, or (`continuous`) one of a continuous
    /// axis's (see [`feature_share`]).
    fn feature_free_as(&self, r: &Rot, c: &Point, continuous: bool) -> bool {
        let n = self.points.len();
        let stride = n.div_ceil(FEATURE_SAMPLES).max(1);
        let off: Vec<Point> = self
            .points
            .iter()
            .step_by(stride)
            .filter(|p| self.absent(r, c, p, continuous))
            .copied()
            .collect();
        let link = 2.0 * self.spacing * (stride as f64).sqrt();
        !has_patch(&off, link, MIN_FEATURE_SAMPLES)
    }

    /// Whether `r` about `c`, or its inverse, maps `p` where the part has no surface within
    /// [`feature_share`] of the tolerance (the test of [`Matcher::feature_free`]; `continuous`
    /// for a turn of a continuous axis).
    pub(super) fn absent(&self, r: &Rot, c: &Point, p: &Point, continuous: bool) -> bool {
        let tol = feature_share(continuous) * self.tol;
        let gone = |m: Point| self.correspond(&m, None, tol, true).is_none();
        gone(c + r * (p - c)) || gone(c + r.inverse() * (p - c))
    }

    /// Whether every turn by [`CONTINUOUS_ANGLES_DEG`] about the axis `a` through `c` leaves no
    /// feature (see [`Matcher::feature_free`]).
    pub(super) fn axis_feature_free(&self, a: &V3, c: &Point) -> bool {
        CONTINUOUS_ANGLES_DEG
            .iter()
            .all(|d| self.feature_free_as(&rot(a, d.to_radians()), c, true))
    }

    /// Whether the rotations of `group` (and turns about its continuous axis) leave a feature:
    /// checked on generators of the group, whose products keep the surface when they do.
    pub(super) fn group_has_feature(&self, group: &Symmetries) -> bool {
        let c = group.center;
        let mut generators: Vec<Rot> = Vec::new();
        let mut spanned = vec![Rot::identity()];
        for r in group.rotations.iter().skip(1) {
            if spanned.iter().any(|e| e.angle_to(r) < SAME_ROTATION) {
                continue;
            }
            generators.push(*r);
            spanned = close(&generators, self.max_group()).unwrap_or_else(|| group.rotations.clone());
        }
        generators.into_iter().any(|r| !self.feature_free(&r, &c))
            || group.continuous_axis.is_some_and(|a| !self.axis_feature_free(&a, &c))
    }

    /// Mean over the screening subsample of `1 − (d / 2 tol)²` (0 for points beyond 2 tol or with
    /// disagreeing normals); stops early once `floor` is out of reach, answering below it.
    fn soft_score(&self, r: &Rot, c: &Point, floor: f64) -> f64 {
        let n = self.screen as f64;
        let wide = 2.0 * self.tol;
        let mut sum = 0.0;
        for (k, &i) in self.test[..self.screen].iter().enumerate() {
            let m = c + r * (self.points[i] - c);
            if let Some((_, d)) = self.correspond(&m, Some(&(r * self.normals[i])), wide, false) {
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
                    let Some((j, res)) = self.correspond(&m, Some(&(r * self.normals[i])), 3.0 * self.tol, false)
                    else {
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
        let mut trials: Vec<(f64, Vec<f64>, bool)> = (2..=self.max_order)
            .map(|n| (soft(axis, point, TAU / n as f64), vec![TAU / n as f64], false))
            .collect();
        let mut all_continuous = f64::INFINITY;
        for &angle in &continuous {
            all_continuous = all_continuous.min(soft(axis, point, angle));
            if all_continuous < SCREEN_MIN {
                break;
            }
        }
        trials.push((all_continuous, continuous[..2].to_vec(), true));
        trials.retain(|t| t.0 >= SCREEN_MIN);
        // The best scores first; among near-equal ones the larger angle pins the axis better.
        trials.sort_by(|x, y| (y.0 + 0.02 * y.1[0]).total_cmp(&(x.0 + 0.02 * x.1[0])));
        let (mut a, mut c) = trials.iter().take(3).find_map(|(_, angles, continuous)| {
            let (a, c) = self.refine(axis, point, angles);
            self.passes_as(&rot(&a, angles[0]), &c, *continuous).then_some((a, c))
        })?;
        if known.iter().any(|f| same_line(&f.axis, &a, SAME_AXIS)) {
            return None;
        }
        // The soft score rejects most wrong angles in a fraction of the cost of the full test.
        let holds = |a: &V3, c: &Point, angle: f64, cont: bool| {
            soft(a, c, angle) >= SCREEN_MIN && self.passes_as(&rot(a, angle), c, cont)
        };
        let (order, angles) = if continuous.iter().all(|&angle| holds(&a, &c, angle, true)) {
            (0, continuous.clone())
        } else {
            let mut passing: Vec<usize> = (2..=self.max_order)
                .filter(|&n| holds(&a, &c, TAU / n as f64, false))
                .collect();
            let l = passing.iter().fold(1, |l, &n| lcm(l, n));
            if l > self.max_order && l <= 4 * self.max_order && holds(&a, &c, TAU / l as f64, false) {
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
        if self.accepts_as(&rot(&a2, angles[0]), &c2, agreement, order == 0) {
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
                if peaks.len() == MAX_FLIP_PEAKS {
                    break;
                }
            }
        }
        peaks.into_iter().find_map(|k| {
            let (u, c) = self.refine(&dir(k), point, &[PI]);
            let agreement = self.agreement(&rot(&u, PI), &c);
            self.accepts(&rot(&u, PI), &c, agreement).then_some(AxisFinding {
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

    pub(super) fn detect(&self) -> Symmetries {
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
            self.passes_as(&rot(&a, CONTINUOUS_ANGLES_DEG[3].to_radians()), c, true)
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
