//! The camera and laser renderer of the simulated cell: parry3d ray casting over each mesh's BVH.
//!
//! Rendering is split the way a scan is: [`Scene::view`] casts one ray per pixel for a robot
//! pose (surface point, normal, instance id, ambient shading — the expensive part, done once),
//! then [`View::frame`] lights the laser line for one motor angle (cheap: shadow rays only near
//! the line) and adds sensor noise. Frames are RGB, 8 bits, row-major.
//!
//! Conventions: the one camera model ([`crate::Camera`]: OpenCV pinhole with skew and distortion
//! `[k1, k2, p1, p2, k3]`), camera frame x right, y down, z forward. The laser sheet is the
//! plane x = 0 of the laser frame, light travelling along +z; the motor turns the projector about its own y axis:
//! `T_camera_laser(θ) = T_camera_laser0 · Rot_y(θ)`.

mod checkerboard;
mod optics;
mod scene;
#[cfg(test)]
mod tests;
mod view;

pub use checkerboard::{render_checkerboard, Checkerboard};
pub use optics::{Laser, Lighting, Material, SensorNoise};
pub use scene::Scene;
pub use view::View;

use super::convert;
use crate::error::{Error, Result};
use crate::geometry::{Camera, Point};
use crate::mesh::TriMesh;
use crate::rng::Rng;
use nalgebra::{Isometry3, Vector3};
use optics::pixel_ray_grid;
use parry3d::bounding_volume::Aabb;
use parry3d::query::{PointQuery, Ray, RayCast};
use rayon::prelude::*;
use scene::{cast, v3, Hit, Placed};
use std::sync::Arc;
use view::quantise;
