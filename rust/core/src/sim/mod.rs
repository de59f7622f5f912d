//! The simulated cell: physics piles of parts in a bin (`pile`, rapier3d), pushed by a kinematic tool (`push`), and an eye-in-hand
//! camera with a swept laser line projector, rendered by ray casting (`render`, parry3d).
//!
//! Default cell layout (base frame, +z up, mm): the bin's inner floor at z = 0, centred at
//! (400, 0); the camera about 500 mm above the pile looking down; the laser projector beside the
//! camera on the flange, turned about its own y axis by the motor.

mod convert;
mod hulls;
mod pile;
mod push;
mod render;

pub use hulls::{convex_decomposition, Hull};
pub use pile::{max_interpenetration, BinSpec, Pile, PileParams, SettleReport, MAX_PARTS};
pub use push::{
    PushReport, ToolBox, MAX_PATH_POSES, MAX_PUSH_TIME, MAX_TOOL_BOXES, MOVED_ANGLE, MOVED_DISTANCE, SPEED_RANGE,
};
pub use render::{render_checkerboard, Checkerboard, Laser, Lighting, Material, Scene, SensorNoise, View};
