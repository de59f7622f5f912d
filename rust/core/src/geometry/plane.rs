//! Planes and the bin box: the flat shapes of the cell (support planes, laser sheets, bin walls).

use super::Point;
use nalgebra::Vector3;

/// A plane `normal · x = offset` with unit `normal`: a support plane of the scene, a laser
/// sheet in the camera frame, a wall of the bin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    /// Unit normal.
    pub normal: Vector3<f64>,
    /// Signed distance of the plane from the origin along `normal`, mm.
    pub offset: f64,
}

/// An axis-aligned bin box in the scene frame, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BinBox {
    /// Minimum corner (the floor is at `min.z`).
    pub min: Point,
    /// Maximum corner.
    pub max: Point,
}
