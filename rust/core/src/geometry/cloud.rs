//! Point clouds: the point type, input validation, rigid transforms and simple statistics.

use crate::error::{Error, Result};
use nalgebra::{Isometry3, Matrix3, Matrix4, Point3, Rotation3, SymmetricEigen, Translation3, UnitQuaternion, Vector3};

/// A 3-D point in millimetres.
pub type Point = Point3<f64>;

/// Checks that every coordinate is finite; names the first bad row.
pub fn check_finite(arg: &str, points: &[Point]) -> Result<()> {
    for (i, p) in points.iter().enumerate() {
        for v in p.coords.iter() {
            if !v.is_finite() {
                return Err(Error::NonFinite {
                    arg: arg.into(),
                    index: i,
                    value: format!("{v}"),
                });
            }
        }
    }
    Ok(())
}

/// Checks that a cloud has at least `needed` points.
pub fn check_count(arg: &str, points: &[Point], needed: usize, hint: &str) -> Result<()> {
    if points.len() < needed {
        let hint = if hint.is_empty() {
            String::new()
        } else {
            format!("; {hint}")
        };
        return Err(Error::TooFewPoints {
            arg: arg.into(),
            got: points.len(),
            needed,
            hint,
        });
    }
    Ok(())
}

/// Mean of the points (the origin for an empty slice).
pub fn centroid(points: &[Point]) -> Point {
    if points.is_empty() {
        return Point::origin();
    }
    let sum = points.iter().fold(Vector3::zeros(), |acc, p| acc + p.coords);
    Point::from(sum / points.len() as f64)
}

/// Centroid and covariance (divided by n) of points given by an iterator (walked twice),
/// without collecting them; the origin and zero for no points.
pub fn covariance_of<'a>(points: impl Iterator<Item = &'a Point> + Clone) -> (Point, Matrix3<f64>) {
    let (n, sum) = points
        .clone()
        .fold((0usize, Vector3::zeros()), |(n, s), p| (n + 1, s + p.coords));
    if n == 0 {
        return (Point::origin(), Matrix3::zeros());
    }
    let c = sum / n as f64;
    let mut cov = Matrix3::zeros();
    for p in points {
        let d = p.coords - c;
        cov += d * d.transpose();
    }
    (Point::from(c), cov / n as f64)
}

/// Centroid and covariance (divided by n) of the points.
pub fn covariance(points: &[Point]) -> (Point, Matrix3<f64>) {
    covariance_of(points.iter())
}

/// The eigenvalues of a symmetric 3×3 matrix, smallest first, with their unit eigenvectors.
pub fn eigen_ascending(m: Matrix3<f64>) -> ([f64; 3], [Vector3<f64>; 3]) {
    let eig = m.symmetric_eigen();
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    (
        order.map(|i| eig.eigenvalues[i]),
        order.map(|i| eig.eigenvectors.column(i).into_owned()),
    )
}

/// Principal axes of a covariance: eigenvalues sorted descending with their unit eigenvectors.
pub fn principal_axes(cov: &Matrix3<f64>) -> ([f64; 3], [Vector3<f64>; 3]) {
    let eig = SymmetricEigen::new(*cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let vals = order.map(|i| eig.eigenvalues[i].max(0.0));
    let vecs = order.map(|i| eig.eigenvectors.column(i).into_owned());
    (vals, vecs)
}

/// The unit eigenvector of the smallest (`largest = false`) or largest eigenvalue of a
/// symmetric 3×3 matrix, in closed form: the eigenvalue by the trigonometric solution of the
/// characteristic cubic, the vector as the longest cross product of two rows of (A − λI). About
/// a fifth of the cost of the iterative decomposition; `None` when that eigenvalue is not
/// separated from the others (the vector is then not defined by the matrix alone), where
/// callers fall back to [`principal_axes`].
pub fn extreme_axis(a: &Matrix3<f64>, largest: bool) -> Option<Vector3<f64>> {
    let p1 = a[(0, 1)] * a[(0, 1)] + a[(0, 2)] * a[(0, 2)] + a[(1, 2)] * a[(1, 2)];
    let q = (a[(0, 0)] + a[(1, 1)] + a[(2, 2)]) / 3.0;
    let p2 = (a[(0, 0)] - q).powi(2) + (a[(1, 1)] - q).powi(2) + (a[(2, 2)] - q).powi(2) + 2.0 * p1;
    let p = (p2 / 6.0).sqrt();
    if !(p > 0.0) || !p.is_finite() {
        return None;
    }
    let b = (a - Matrix3::identity() * q) / p;
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let phi = r.acos() / 3.0;
    let lambda = if largest {
        q + 2.0 * p * phi.cos()
    } else {
        q + 2.0 * p * (phi + 2.0 * std::f64::consts::FRAC_PI_3).cos()
    };
    let m = a - Matrix3::identity() * lambda;
    let (r0, r1, r2) = (m.row(0).transpose(), m.row(1).transpose(), m.row(2).transpose());
    let candidates = [r0.cross(&r1), r0.cross(&r2), r1.cross(&r2)];
    let best = candidates
        .iter()
        .max_by(|x, y| x.norm_squared().total_cmp(&y.norm_squared()))?;
    // The rows of A − λI span a plane only when λ is a simple eigenvalue; then the longest cross
    // product is of the order of (spread of the others)². Demand a clear margin over rounding.
    let scale = p * p;
    if best.norm() <= 1e-6 * scale {
        return None;
    }
    Some(best.normalize())
}

/// How many dimensions a cloud spans: 0 all points equal, 1 collinear, 2 coplanar, 3 solid.
/// A direction counts when its standard deviation exceeds 1e-6 of the largest one (rounding in
/// the eigen-decomposition reaches about 1e-8), and the largest must exceed 1e-12 mm.
pub fn spanned_dimensions(points: &[Point]) -> usize {
    if points.len() < 2 {
        return 0;
    }
    let (_, cov) = covariance(points);
    let (vals, _) = principal_axes(&cov);
    let scale = vals[0].sqrt();
    if scale <= 1e-12 {
        return 0;
    }
    1 + vals[1..].iter().filter(|v| v.sqrt() > 1e-6 * scale).count()
}

/// Fails with [`Error::Degenerate`] when the cloud spans fewer than `needed` dimensions.
pub fn check_spread(arg: &str, points: &[Point], needed: usize, advice: &str) -> Result<()> {
    let dims = spanned_dimensions(points);
    if dims < needed {
        let what = match dims {
            0 => "all points are equal",
            1 => "all points lie on one line",
            _ => "all points lie in one plane",
        };
        return Err(Error::Degenerate {
            arg: arg.into(),
            what: what.into(),
            advice: advice.into(),
        });
    }
    Ok(())
}

/// Applies a rigid transform to every point.
pub fn transform_points(t: &Isometry3<f64>, points: &[Point]) -> Vec<Point> {
    points.iter().map(|p| t * p).collect()
}

/// Converts a 4×4 homogeneous matrix into a rigid transform, checking that it is one:
/// the rotation block orthonormal with determinant +1 (to 1e-6) and the last row `0 0 0 1`.
pub fn isometry_from_matrix(arg: &str, m: &Matrix4<f64>) -> Result<Isometry3<f64>> {
    if m.iter().any(|v| !v.is_finite()) {
        return Err(Error::invalid(
            arg,
            "the transform holds NaN or inf; pass a finite 4×4 rigid transform",
        ));
    }
    let last = m.row(3);
    if (last[0].abs() + last[1].abs() + last[2].abs() + (last[3] - 1.0).abs()) > 1e-9 {
        return Err(Error::invalid(
            arg,
            format!("the last row must be [0, 0, 0, 1], got {last}"),
        ));
    }
    let r: Matrix3<f64> = m.fixed_view::<3, 3>(0, 0).into_owned();
    let ortho_err = (r.transpose() * r - Matrix3::identity()).abs().max();
    if ortho_err > 1e-6 || r.determinant() < 0.0 {
        return Err(Error::invalid(
            arg,
            format!(
                "the upper-left 3×3 block is not a rotation (|RᵀR − I| = {ortho_err:.2e}, det = {:.6}); pass a rigid transform without scale or reflection",
                r.determinant()
            ),
        ));
    }
    let rot = Rotation3::from_matrix_eps(&r, 1e-12, 100, Rotation3::identity());
    let t = Translation3::new(m[(0, 3)], m[(1, 3)], m[(2, 3)]);
    Ok(Isometry3::from_parts(t, UnitQuaternion::from_rotation_matrix(&rot)))
}

/// The median distance (mm) of `points` from `eye`, read over at most about 2000 of them
/// (evenly thinned); None for no points.
pub fn median_range(points: &[Point], eye: &Point) -> Option<f64> {
    median(thin(points, 2000).iter().map(|p| (p - eye).norm()).collect(), 1)
}

/// Two unit vectors completing the unit vector `a` to a right-handed frame: (u, v = a × u).
pub fn perpendicular_basis(a: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if a.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let u = a.cross(&helper).normalize();
    (u, a.cross(&u))
}

/// Every `len / n`-th point of `v` (rounded up): at most about `n` points, evenly spread over
/// the slice's order.
pub fn thin(v: &[Point], n: usize) -> Vec<Point> {
    v.iter().step_by(v.len().div_ceil(n.max(1)).max(1)).copied().collect()
}

/// The median of `v` (the upper one of an even count), None when it holds fewer than `fewest`
/// values or none.
pub fn median(mut v: Vec<f64>, fewest: usize) -> Option<f64> {
    if v.is_empty() || v.len() < fewest {
        return None;
    }
    let mid = v.len() / 2;
    Some(*v.select_nth_unstable_by(mid, f64::total_cmp).1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_classifies_degenerate_sets() {
        let same = vec![Point::new(1.0, 2.0, 3.0); 10];
        assert_eq!(spanned_dimensions(&same), 0);
        let line: Vec<Point> = (0..10).map(|i| Point::new(i as f64, 2.0 * i as f64, 5.0)).collect();
        assert_eq!(spanned_dimensions(&line), 1);
        let plane: Vec<Point> = (0..100)
            .map(|i| Point::new((i % 10) as f64, (i / 10) as f64, 5.0))
            .collect();
        assert_eq!(spanned_dimensions(&plane), 2);
        let mut solid = plane.clone();
        solid.push(Point::new(0.0, 0.0, 9.0));
        assert_eq!(spanned_dimensions(&solid), 3);
        assert!(matches!(
            check_spread("x", &line, 2, "fix it"),
            Err(Error::Degenerate { .. })
        ));
    }

    #[test]
    fn finite_check_names_row() {
        let pts = vec![Point::new(0.0, 0.0, 0.0), Point::new(0.0, f64::NAN, 0.0)];
        match check_finite("scene", &pts) {
            Err(Error::NonFinite { index, .. }) => assert_eq!(index, 1),
            other => panic!("unexpected {other:?}"),
        }
    }

    #[test]
    fn isometry_check_rejects_scale_and_reflection() {
        let mut m = Matrix4::identity();
        assert!(isometry_from_matrix("init", &m).is_ok());
        m[(0, 0)] = 2.0;
        assert!(isometry_from_matrix("init", &m).is_err());
        let mut refl = Matrix4::identity();
        refl[(2, 2)] = -1.0;
        assert!(isometry_from_matrix("init", &refl).is_err());
    }

    #[test]
    fn closed_form_axes_match_the_iterative_decomposition() {
        let mut rng = crate::rng::Rng::new(5);
        for trial in 0..2000 {
            // Random rotations of diagonal spreads, from isotropic-ish to nearly flat and thin.
            let r = Rotation3::from_scaled_axis(Vector3::new(rng.normal(), rng.normal(), rng.normal()));
            let flat = 10f64.powf(-rng.range(0.0, 6.0));
            let d = Matrix3::from_diagonal(&Vector3::new(
                rng.range(1.0, 3.0) * 100.0,
                rng.range(0.2, 1.0) * 30.0,
                flat,
            ));
            let cov = r.matrix() * d * r.matrix().transpose();
            let (_, axes) = principal_axes(&cov);
            for (largest, want) in [(false, axes[2]), (true, axes[0])] {
                let got = extreme_axis(&cov, largest).unwrap_or_else(|| panic!("trial {trial}: no axis"));
                assert!(
                    got.dot(&want).abs() > 1.0 - 1e-9,
                    "trial {trial}, largest {largest}: {got} vs {want}"
                );
            }
        }
        // A line's smallest axis is not defined; an isotropic spread has none.
        let line = Matrix3::from_diagonal(&Vector3::new(5.0, 0.0, 0.0));
        assert!(extreme_axis(&line, false).is_none());
        assert!(extreme_axis(&Matrix3::identity(), true).is_none());
    }
}
