//! The closed-form best rotation between two centred point sets (Kabsch; Arun et al.).

use nalgebra::{Matrix3, Rotation3};

/// The proper rotation `R` that maximises `tr(R H)` for the cross-covariance `H = Σ a bᵀ` of
/// centred pairs (`a` from the set to be rotated, `b` from the fixed set), so that `R a ≈ b`:
/// from the SVD of `H`, with the reflection case turned into the nearest rotation. `None` when
/// the SVD does not converge.
pub fn kabsch(h: &Matrix3<f64>) -> Option<Rotation3<f64>> {
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u?, svd.v_t?);
    let mut d = Matrix3::identity();
    if (vt.transpose() * u.transpose()).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    Some(Rotation3::from_matrix_unchecked(vt.transpose() * d * u.transpose()))
}
