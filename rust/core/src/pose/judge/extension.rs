//! A part with declared cylindrical branches (a pipe fitting) ends where its branches end. Where
//! the scan's surface carries a branch's own cylinder on past the end face, or back through the
//! junction where the part has no branch, the pose has read a piece of a larger part: an elbow
//! read on a tee (its corner is where the tee's run goes on), a tee on a cross. The outline and
//! continuation tests follow flat faces and tangent planes, which a cylinder leaves within a
//! few millimetres of the line it is entered on; here the cylinder itself is carried on.
//!
//! Every branch is probed at the layout's radius (its largest): a thinner branch's surface does
//! not lie on that cylinder, so its ends are not judged.
//!
//! For each end of each branch the model holds probes on the cylinder carried past it (with
//! their distance from the part's surface: only those farther than twice the judge's tolerance
//! count) and probes on the branch's own surface over a stretch just inside the end. The scan
//! confirms a probe where its height map's top lies at the probe's height (the depth test's
//! rule) and the scan point topping the cell lies on the cylinder (and, past the end, off the
//! part). An end whose carried-on cylinder the scan confirms nearly as widely as the branch's
//! own stretch goes on past it.

use super::depth::DepthTest;
use crate::geometry::Point;
use crate::pose::model::PoseModel;
use crate::pose::surface::plane_residual;
use nalgebra::{Isometry3, Vector3};

/// The least share of a normal along the sensor's direction for a probe to be judged: within 60°
/// of facing the sensor. The depth test's 0.3 lets in probes whose height-map cell (several mm
/// wide) rises by several times the tolerance across it, and true fittings in piles then read
/// up to 0.64 of an end carried on; facing within 45° (0.7) misses a fitting standing steeply,
/// whose cylinders then show few probes.
const MIN_FACING: f64 = 0.5;

/// The least share of an end's inside stretch that the scan must confirm on the carried-on
/// cylinder past it for the branch to go on there. Where the part read is a piece of a larger
/// one (an elbow on a tee's corner) the run goes on unbroken and the two stretches read alike:
/// 0.74–1.12 for 37 of the 39 elbows read on eight simulated piles of tees (the other two had
/// the run past the corner covered: 0.07 and 0.34). A real fitting's neighbour lying in line
/// with a branch end covers less of it: at most 0.51 over 119 instances of 24 piles of tees,
/// elbows and crosses.
pub(crate) const MAX_CARRIED: f64 = 0.6;
/// The least surface, mm², the scan must confirm inside an end for its reading to count (30
/// probes where they lie a millimetre apart): a sliver of a branch says little of whether the
/// cylinder past it is the branch's own.
pub(crate) const MIN_INSIDE_AREA: f64 = 30.0;

impl EndReading {
    /// Whether the branch goes on past this end.
    pub fn carried_on(&self) -> bool {
        self.inside as f64 * self.probe_area >= MIN_INSIDE_AREA && self.past as f64 >= MAX_CARRIED * self.inside as f64
    }
}

/// What the scan shows at one end of a posed branch.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct EndReading {
    /// Probes past the end (off the part) the scan confirms.
    pub past: usize,
    /// Probes inside the end the scan confirms.
    pub inside: usize,
    /// The surface each probe stands for, mm².
    pub probe_area: f64,
}

/// What the scan shows at every branch end of `model` posed at `t_scene_model`. A probe past an
/// end counts when the scan point that tops its cell lies on the carried-on cylinder and off the
/// part (the map's cells are coarser than the probes: a cell straddling the end face is topped
/// by the part itself).
pub(crate) fn read_ends(depth: &DepthTest, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Vec<EndReading> {
    let map = &depth.heights;
    let tol = depth.tol;
    let Some(layout) = &model.layout else {
        return Vec::new();
    };
    let to_model = t_scene_model.inverse();
    // The scan point topping the probe's cell, when it lies at the probe's height.
    let topped = |p: &Point, n: &Vector3<f64>| {
        let n = t_scene_model.rotation * n;
        let q = t_scene_model * p;
        let c = n.dot(&map.toward(&q));
        if c < MIN_FACING {
            return None;
        }
        let h = map.height(&q);
        map.top_at(&q)
            .filter(|(top, _)| (top - h).abs() <= map.slack(tol, c, &q))
            .map(|(_, at)| to_model * at)
    };
    // Off the part as the continuation test has it: nothing of the dense surface within twice
    // the tolerance.
    let off_part = |m: &Point| plane_residual(model, m, 2.0 * tol).is_none();
    let r = layout.radius;
    if model.branch_ends.len() != 2 * layout.directions.len() {
        return Vec::new(); // probes of another layout: nothing to judge by
    }
    model
        .branch_ends
        .iter()
        .zip(layout.directions.iter().flat_map(|u| [u.normalize(), u.normalize()]))
        .map(|(end, u)| {
            let on_cylinder = |m: &Point| {
                let t = m.coords.dot(&u);
                ((m.coords - u * t).norm() - r).abs() <= 2.0 * tol
            };
            EndReading {
                probe_area: end.probe_area,
                past: end
                    .past
                    .iter()
                    .filter(|(_, _, d)| *d > 2.0 * tol)
                    .filter_map(|(p, n, _)| topped(p, n))
                    .filter(|m| on_cylinder(m) && off_part(m))
                    .count(),
                inside: end
                    .inside
                    .iter()
                    .filter_map(|(p, n)| topped(p, n))
                    .filter(|m| on_cylinder(m))
                    .count(),
            }
        })
        .collect()
}
