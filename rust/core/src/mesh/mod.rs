//! Meshes: the triangle mesh type and units ([`TriMesh`]), file readers and writers ([`io`]),
//! even surface sampling ([`sample`]), signed-distance modelling ([`sdf`]) and the built-in
//! parts ([`parts`]).

pub mod io;
pub mod lzf;
pub mod parts;
pub mod sample;
pub mod sdf;
mod trimesh;
#[cfg(test)]
pub(crate) use trimesh::test_box;

pub use sample::{sample_surface, Density, SurfaceSamples};
pub use trimesh::{unit_scale, TriMesh};
