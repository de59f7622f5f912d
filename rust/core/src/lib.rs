//! binpick-core: the computational core of binpick, an eye-in-hand laser-line bin-picking stack.
//!
//! Lengths are millimetres, angles radians; rigid transforms are `Isometry3<f64>` named
//! `t_to_from` in code (a point `p_from` maps to `t_to_from * p_from`).
#![warn(missing_docs)]

pub mod cloud;
pub mod error;
pub mod knn;

pub use error::{Error, Result};
pub mod detect;
pub mod mesh;
pub mod mesh_io;
pub mod model;
pub mod normals;
pub mod parallel;
pub mod parts;
pub mod pose;
pub mod registration;
pub mod rng;
pub mod sdf;
pub mod segment;
pub mod sim;
pub mod symmetry;
pub mod triangulate;
pub mod voxel;
