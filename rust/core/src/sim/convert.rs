//! The one place where the core's nalgebra `f64` types become parry/rapier (glam, `f32`) math
//! types and back. Nothing else in `sim` converts between the two.
//!
//! The simulator runs parry and rapier in `f32`: their BVH traversal and solver are faster and
//! lighter in that precision, and single precision resolves 0.1 µm at a metre — far below the
//! 0.05 px (≈ 0.02 mm) and 0.5 mm tolerances the simulator is held to. Ray casts are done in each
//! part's own frame, where coordinates stay within the part's size.

use crate::geometry::Point;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use parry3d::math::{Pose, Rotation, Vector};

/// A rigid transform as a parry pose.
pub fn pose(t: &Isometry3<f64>) -> Pose {
    let q = t.rotation.quaternion();
    let rot = Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize();
    Pose::from_parts(vector(&t.translation.vector), rot)
}

/// A parry pose as a rigid transform.
pub fn isometry(p: &Pose) -> Isometry3<f64> {
    let r = p.rotation;
    let q = UnitQuaternion::from_quaternion(Quaternion::new(r.w as f64, r.x as f64, r.y as f64, r.z as f64));
    Isometry3::from_parts(Translation3::from(vector3(p.translation)), q)
}

/// A point as a parry vector.
#[inline]
pub fn point_vec(p: &Point) -> Vector {
    Vector::new(p.x as f32, p.y as f32, p.z as f32)
}

/// A vector as a parry vector.
#[inline]
pub fn vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

/// A parry vector as a nalgebra vector.
#[inline]
pub fn vector3(v: Vector) -> Vector3<f64> {
    Vector3::new(v.x as f64, v.y as f64, v.z as f64)
}

/// A parry vector as a point.
#[inline]
pub fn point(v: Vector) -> Point {
    Point::new(v.x as f64, v.y as f64, v.z as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_the_transform() {
        let t = Isometry3::new(Vector3::new(400.0, -12.5, 33.0), Vector3::new(0.3, -1.1, 2.0));
        let back = isometry(&pose(&t));
        assert!((back.translation.vector - t.translation.vector).norm() < 1e-4);
        assert!(back.rotation.angle_to(&t.rotation) < 1e-6);
        let p = Point::new(1.0, 2.0, 3.0);
        let a = t * p;
        let b = point(pose(&t).transform_point(point_vec(&p)));
        assert!((a - b).norm() < 1e-4);
    }
}
