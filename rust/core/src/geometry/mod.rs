//! Geometry every stage shares: the point type and its checks, statistics of clouds, rigid
//! transforms, the one [`Plane`], the bin box, the one Kabsch solver and the one camera model.

mod camera;
mod cloud;
mod gripper;
mod kabsch;
mod plane;

pub(crate) use camera::PerCamera;
pub use camera::{Camera, RayTable};
pub use cloud::{
    centroid, check_count, check_finite, check_spread, covariance, covariance_of, eigen_ascending, extreme_axis,
    isometry_from_matrix, median, median_range, perpendicular_basis, principal_axes, thin, transform_points, Point,
};
pub use gripper::{Clearance, GripperShape, PointGrid, Sweep};
pub use kabsch::kabsch;
pub use plane::{BinBox, Plane};
