//! Registration: ICP (point-to-point and point-to-plane) and its configuration.

pub mod ccp;
pub mod config;
pub mod icp;
pub mod ppf;
pub mod verify;

pub use config::{Convergence, IcpConfig, IcpMethod, RobustKernel};
pub use icp::{icp, IcpResult, IcpTarget};
