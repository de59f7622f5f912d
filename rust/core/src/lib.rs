//! binpick-core: the computational core of binpick, an eye-in-hand laser-line bin-picking stack.
//!
//! Lengths are millimetres, angles radians; rigid transforms are `Isometry3<f64>` named
//! `t_to_from` in code (a point `p_from` maps to `t_to_from * p_from`).
//!
//! # Map of the crate
//!
//! The modules follow the path of one pick; each depends only on those listed above it.
//!
//! | module | what it holds |
//! |---|---|
//! | `error` | the one [`Error`] enum and [`Result`] |
//! | `rng`, `parallel`, `cancel` | the seeded [`Rng`]; thread-count control ([`with_threads`]); cooperative cancellation ([`CancelFlag`], [`cancel_scope`]) |
//! | `geometry` | [`Point`] and its checks, cloud statistics, rigid transforms, the one [`Plane`], [`BinBox`], the one Kabsch, THE camera model ([`Camera`], [`RayTable`]) |
//! | `search` | nearest-neighbour structures: [`KdIndex`], the bounded correspondence tree, the coarse nearest field |
//! | `voxel`, `normals`, `noise` | voxel grids and even subsampling; normal estimation; the sensor's depth noise read from a scan ([`scan_noise`]) |
//! | `mesh` | [`TriMesh`], file readers and writers, surface sampling, SDF modelling, the built-in [`parts`] |
//! | `triangulate` | the measuring chain: laser planes, ray–plane intersection, scans to base-frame points |
//! | `segment` | scan spacing, bin cropping, support-plane removal, top-object segmentation (Table 2) |
//! | `symmetry` | proper symmetries of a part, canonical poses, symmetry-aware pose errors |
//! | `registration` | ICP and its configuration, CCP, verification evidence, point-pair features |
//! | `pose` | [`estimate_poses`]: bin removal → coarse pose (CCP, PPF, centroid) → ICP → the one judge |
//! | `sim` (feature `sim`) | rapier3d piles and the parry3d ray-cast renderer of the simulated cell |
//!
//! The names below are the crate's front door; the modules behind them are internal.
#![warn(missing_docs)]

mod cancel;
mod error;
mod geometry;
mod mesh;
mod noise;
mod normals;
mod parallel;
mod pose;
mod registration;
mod rng;
mod search;
mod segment;
#[cfg(feature = "sim")]
pub mod sim;
mod symmetry;
mod triangulate;
mod voxel;

pub use cancel::{scope as cancel_scope, CancelFlag, Token as CancelToken};
pub use error::{Error, Result};
pub use geometry::{centroid, isometry_from_matrix, transform_points, BinBox, Camera, Plane, Point, RayTable};
pub use geometry::{Clearance, GripperShape, PointGrid, Sweep};
pub use mesh::io::{read_mesh, read_ply, write_ply, PlyData};
pub use mesh::lzf::{lzf_decompress, LZF_MAX_RATIO};
pub use mesh::parts::{self, Part};
pub use mesh::{sample_surface, unit_scale, Density, SurfaceSamples, TriMesh};
pub use noise::scan_noise;
pub use normals::{estimate_normals, Orientation};
pub use parallel::with_threads;
pub use pose::{
    estimate_pose, estimate_poses, estimate_poses_excluding, stage_totals, verify_pose, Alternative, CcpPathParams,
    CheckIcpParams, CoarseMethod, FeatureEvidence, FineIcpParams, FitQuality, FreeMotion, PoseConfig, PoseEstimate,
    PoseModel, SensorModel, Timings, TrustParams, MAX_NOISE_MM,
};
pub use registration::ccp::{ccp, BranchLayout, CcpConfig, CcpResult};
pub use registration::ppf::{DetectConfig, PpfConfig, PpfModel};
pub use registration::{icp, Convergence, IcpConfig, IcpMethod, IcpResult, IcpTarget, RobustKernel};
pub use rng::Rng;
pub use search::{KdIndex, Neighbour};
pub use symmetry::{
    detect_all_symmetries, detect_near_symmetries, detect_symmetries, NearSymmetry, Symmetries, SymmetryConfig,
    NEAR_AGREEMENT,
};
pub use triangulate::{
    intersect_ray_plane, laser_plane, pixel_rays, triangulate, triangulate_into, FramePose, PointStatus, Sensor,
    Triangulation,
};
pub use voxel::{subsample, voxel_downsample, Downsampled};
