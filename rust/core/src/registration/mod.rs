//! Registration: ICP (point-to-point and point-to-plane) and its configuration.

pub mod ccp;
pub mod corr_tree;
pub mod criteria;
pub mod field;
pub mod icp;
pub mod ppf;
pub mod verify;

pub use criteria::{IcpConfig, IcpMethod, RobustKernel};
pub use icp::{icp, IcpResult, IcpTarget};
