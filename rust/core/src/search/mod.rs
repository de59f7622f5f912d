//! Nearest-neighbour search: the kiddo-backed [`KdIndex`] (k-NN, radius and nearest-within
//! queries), the bounded [`corr_tree::CorrespondenceTree`] ICP's correspondences use, and the
//! precomputed [`field::NearestField`] of the coarse checks.

pub mod corr_tree;
pub mod field;
mod knn;

pub use knn::{KdIndex, Neighbour};
