//! Pushing a pile with a tool: a kinematic body made of boxes (a closed gripper's fingers and
//! palm, say) moved along a path of tool poses at a given speed. Parts it touches are shoved by
//! the solver like any contact; when the path ends the tool is taken away and the pile settles.

use super::convert;
use super::pile::{Pile, SettleReport};
use crate::error::{Error, Result};
use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::{ColliderBuilder, RigidBodyBuilder};

/// One box of a pushing tool: its pose in the tool frame and its half extents, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolBox {
    /// Pose of the box's centre and axes in the tool frame (T_tool_box).
    pub pose_in_tool: Isometry3<f64>,
    /// Half extents along the box's own x, y and z axes, mm.
    pub half_extents: Vector3<f64>,
}

/// What a push did.
#[derive(Debug, Clone, PartialEq)]
pub struct PushReport {
    /// Simulation steps the tool moved for.
    pub push_steps: usize,
    /// The settling after the tool was taken away.
    pub settle: SettleReport,
    /// Ids of the parts that moved more than [`MOVED_DISTANCE`] or turned more than
    /// [`MOVED_ANGLE`], from before the push to after the settling.
    pub moved: Vec<usize>,
}

/// A part counts as moved past this displacement, mm.
pub const MOVED_DISTANCE: f64 = 1.0;
/// ... or past this rotation, rad (2°).
pub const MOVED_ANGLE: f64 = 2.0 * std::f64::consts::PI / 180.0;
/// Most boxes in one tool.
pub const MAX_TOOL_BOXES: usize = 64;
/// Largest half extent of a tool box, mm.
pub const MAX_HALF_EXTENT: f64 = 1000.0;
/// Most poses in one path.
pub const MAX_PATH_POSES: usize = 10_000;
/// Longest push, simulated seconds: the path at the given speed must fit in it.
pub const MAX_PUSH_TIME: f64 = 120.0;
/// Slowest and fastest tool speed, mm/s.
pub const SPEED_RANGE: (f64, f64) = (0.1, 5000.0);

fn check_inputs(boxes: &[ToolBox], path: &[Isometry3<f64>], speed: f64) -> Result<()> {
    if boxes.is_empty() || boxes.len() > MAX_TOOL_BOXES {
        return Err(Error::invalid(
            "boxes",
            format!("a tool needs 1 to {MAX_TOOL_BOXES} boxes, got {}", boxes.len()),
        ));
    }
    for (i, b) in boxes.iter().enumerate() {
        let h = b.half_extents;
        if !h.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= MAX_HALF_EXTENT) {
            return Err(Error::invalid(
                "boxes",
                format!("box {i}: half extents must be in (0, {MAX_HALF_EXTENT}] mm, got {h:?}"),
            ));
        }
        if !finite_pose(&b.pose_in_tool) {
            return Err(Error::invalid("boxes", format!("box {i}: the pose is not finite")));
        }
    }
    if path.len() < 2 || path.len() > MAX_PATH_POSES {
        return Err(Error::invalid(
            "path",
            format!("a push needs 2 to {MAX_PATH_POSES} tool poses, got {}", path.len()),
        ));
    }
    if let Some(i) = path.iter().position(|t| !finite_pose(t)) {
        return Err(Error::invalid("path", format!("pose {i} is not finite")));
    }
    if !(speed.is_finite() && speed >= SPEED_RANGE.0 && speed <= SPEED_RANGE.1) {
        return Err(Error::invalid(
            "speed",
            format!("must be in [{}, {}] mm/s, got {speed}", SPEED_RANGE.0, SPEED_RANGE.1),
        ));
    }
    Ok(())
}

fn finite_pose(t: &Isometry3<f64>) -> bool {
    t.translation.vector.iter().all(|v| v.is_finite()) && t.rotation.coords.iter().all(|v| v.is_finite())
}

/// Furthest a point of the tool lies from the tool origin, mm: a turn of θ moves it θ·reach.
fn reach(boxes: &[ToolBox]) -> f64 {
    boxes
        .iter()
        .map(|b| b.pose_in_tool.translation.vector.norm() + b.half_extents.norm())
        .fold(0.0, f64::max)
}

/// The tool poses of each simulation step: every segment of `path` cut so that no point of the
/// tool moves faster than `speed`.
fn schedule(path: &[Isometry3<f64>], speed: f64, reach: f64, dt: f64) -> Result<Vec<Isometry3<f64>>> {
    let max_steps = (MAX_PUSH_TIME / dt).ceil() as usize;
    let mut out = vec![path[0]];
    for w in path.windows(2) {
        let (a, b) = (w[0], w[1]);
        let travel = (b.translation.vector - a.translation.vector).norm() + a.rotation.angle_to(&b.rotation) * reach;
        let n = ((travel / speed / dt).ceil() as usize).max(1);
        if out.len() + n > max_steps {
            return Err(Error::invalid(
                "path",
                format!(
                    "the push would take more than {MAX_PUSH_TIME} s at {speed} mm/s; shorten the path or speed up"
                ),
            ));
        }
        for k in 1..=n {
            let s = k as f64 / n as f64;
            let t = a.translation.vector.lerp(&b.translation.vector, s);
            let r = a.rotation.slerp(&b.rotation, s);
            out.push(Isometry3::from_parts(t.into(), r));
        }
    }
    Ok(out)
}

impl Pile {
    /// Moves a tool of `boxes` along `path` (`T_base_tool` poses) at `speed` mm/s, one physics
    /// step at a time, then removes the tool and lets the pile settle.
    pub fn push(&mut self, boxes: &[ToolBox], path: &[Isometry3<f64>], speed: f64) -> Result<PushReport> {
        check_inputs(boxes, path, speed)?;
        let steps = schedule(path, speed, reach(boxes), self.params.time_step)?;
        let before = self.poses();
        let tool = self.world.insert_body(
            RigidBodyBuilder::kinematic_position_based()
                .pose(convert::pose(&steps[0]))
                .build(),
        );
        for b in boxes {
            let h = b.half_extents;
            let collider = ColliderBuilder::cuboid(h.x as f32, h.y as f32, h.z as f32)
                .position(convert::pose(&b.pose_in_tool))
                .friction(self.params.friction as f32)
                .restitution(self.params.restitution as f32)
                .build();
            self.world.insert_collider(collider, Some(tool));
        }
        self.world.wake_up_all(true);
        let mut outcome = Ok(());
        for (k, t) in steps.iter().enumerate().skip(1) {
            if k % 64 == 0 {
                if let Err(e) = crate::cancel::check() {
                    outcome = Err(e);
                    break;
                }
            }
            if let Some(body) = self.world.bodies.get_mut(tool) {
                body.set_next_kinematic_position(convert::pose(t));
            }
            self.world.step();
        }
        self.world.remove_body(tool);
        self.world.wake_up_all(true);
        outcome?;
        let settle = self.settle();
        let after: std::collections::HashMap<usize, Isometry3<f64>> = self.poses().into_iter().collect();
        let moved = before
            .iter()
            .filter(|(id, t0)| {
                after.get(id).is_some_and(|t1| {
                    (t1.translation.vector - t0.translation.vector).norm() > MOVED_DISTANCE
                        || t1.rotation.angle_to(&t0.rotation) > MOVED_ANGLE
                })
            })
            .map(|(id, _)| *id)
            .collect();
        Ok(PushReport {
            push_steps: steps.len() - 1,
            settle,
            moved,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sim::pile::tests::{assert_inside_bin, small_tee};
    use crate::sim::{BinSpec, PileParams};
    use nalgebra::{Translation3, UnitQuaternion};

    /// A finger-sized block: 20 × 20 × 40 mm, centred on the tool origin.
    fn block() -> Vec<ToolBox> {
        vec![ToolBox {
            pose_in_tool: Isometry3::identity(),
            half_extents: Vector3::new(10.0, 10.0, 20.0),
        }]
    }

    fn at(x: f64, y: f64, z: f64) -> Isometry3<f64> {
        Isometry3::from_parts(Translation3::new(x, y, z), UnitQuaternion::identity())
    }

    #[test]
    fn a_push_through_a_part_moves_it_and_the_pile_stays_in_the_bin() {
        let m = small_tee();
        let mut pile = Pile::drop(&m, 1, &BinSpec::default(), &PileParams::default()).unwrap();
        let (_, t0) = pile.poses()[0];
        let c = t0 * nalgebra::center(&m.bounds().0, &m.bounds().1);
        // Sweep the block along x through the part's centre, 8 mm above the floor.
        let path = [at(c.x - 80.0, c.y, 28.0), at(c.x + 40.0, c.y, 28.0)];
        let report = pile.push(&block(), &path, 60.0).unwrap();
        assert!(report.push_steps >= 200, "{report:?}");
        assert_eq!(report.moved, vec![0], "{report:?}");
        let (_, t1) = pile.poses()[0];
        assert!(
            t1.translation.vector.x - t0.translation.vector.x > 10.0,
            "pushed along +x: {} -> {}",
            t0.translation.vector,
            t1.translation.vector
        );
        assert_inside_bin(&pile, &m, 1.0);
        // Pushed hard into the +x wall: the part stops there and stays in the bin.
        let (_, t1) = pile.poses()[0];
        let c = t1 * nalgebra::center(&m.bounds().0, &m.bounds().1);
        let hi = pile.bin().inner_bounds().1;
        pile.push(&block(), &[at(c.x - 80.0, c.y, 28.0), at(hi.x - 12.0, c.y, 28.0)], 60.0)
            .unwrap();
        assert_inside_bin(&pile, &m, 1.0);
    }

    #[test]
    fn a_push_that_touches_nothing_leaves_the_pile_as_it_was() {
        let m = small_tee();
        let mut pile = Pile::drop(&m, 3, &BinSpec::default(), &PileParams::default()).unwrap();
        let before = pile.poses();
        let path = [at(400.0, 0.0, 200.0), at(300.0, 50.0, 220.0), at(450.0, -50.0, 200.0)];
        let report = pile.push(&block(), &path, 200.0).unwrap();
        assert!(report.moved.is_empty(), "{report:?}");
        for ((_, a), (_, b)) in before.iter().zip(pile.poses()) {
            assert!((a.translation.vector - b.translation.vector).norm() < 0.5);
        }
    }

    #[test]
    fn pushes_are_validated() {
        let m = small_tee();
        let mut pile = Pile::drop(&m, 1, &BinSpec::default(), &PileParams::default()).unwrap();
        let path = [at(0.0, 0.0, 200.0), at(10.0, 0.0, 200.0)];
        assert!(pile.push(&[], &path, 10.0).is_err());
        assert!(pile.push(&block(), &path[..1], 10.0).is_err());
        assert!(pile.push(&block(), &path, 0.0).is_err());
        assert!(pile.push(&block(), &path, f64::NAN).is_err());
        let mut bad = block();
        bad[0].half_extents.x = -1.0;
        assert!(pile.push(&bad, &path, 10.0).is_err());
        assert!(pile
            .push(&block(), &[path[0], at(f64::INFINITY, 0.0, 0.0)], 10.0)
            .is_err());
        // 1e6 mm at 1 mm/s would step for days: refused before a step is taken.
        assert!(pile.push(&block(), &[path[0], at(1e6, 0.0, 200.0)], 1.0).is_err());
        assert_eq!(pile.remaining(), 1);
    }
}
