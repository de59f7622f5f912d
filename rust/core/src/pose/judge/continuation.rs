//! Where a posed part's surface is confirmed, the scan's surface must not run on past the part in
//! the same surface. The outline test ([`mod@super::outline`]) looks at the edges of faces turned
//! toward the sensor; a tilted piece of a larger shape slips past it — a plate read on the run of
//! a tee standing at 60°, a short rod along a longer one at 45°. Here the scan is followed from
//! every cell of the height map where it confirms the posed part (within the tolerance of the
//! part's tangent plane there), in that tangent plane, across neighbouring cells whose scan point
//! stays in it; what is reached off the part is surface that continues the part's own.
//!
//! The plane is the part's, not the scan's: a curved surface is followed only as far as it stays
//! within the tolerance of the plane it was entered from (an elbow read on a tee's run reaches
//! only a strip of the run that goes on past the elbow's corner).
//!
//! A face parallel to a support (the bin's floor or a wall, or a removed support plane) is not
//! followed: parts resting on the floor have their top faces at one height, and a neighbour's
//! flush face is common in a pile; the outline test weighs those.

use super::depth::{probe_step, share, DepthTest, JUDGE_PROBES};
use crate::geometry::Point;
use crate::pose::model::PoseModel;
use crate::pose::surface::plane_residual;
use nalgebra::{Isometry3, Vector3};
use std::collections::{HashMap, VecDeque};

/// The least share of a normal along the sensor's direction for a probe to seed the test.
const MIN_FACING: f64 = 0.3;
/// A face whose normal lies within this cosine (about 10°) of a support's normal is not followed.
const PARALLEL_TO_SUPPORT: f64 = 0.985;
/// How far past the confirmed surface the scan is followed, as a share of the part's diameter.
const REACH: f64 = 0.5;

/// The continuation test of one pose.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Continuation {
    /// Height-map cells the scan confirms the posed part in (in 3-D, in the tangent plane).
    pub confirmed: usize,
    /// Cells off the part reached from them in the tangent plane of the part's surface (the
    /// search stops once they outnumber the confirmed cells).
    pub beyond: usize,
}

impl Continuation {
    /// Beyond over confirmed (0 with nothing confirmed).
    pub fn beyond_fraction(&self) -> f64 {
        share(self.beyond, self.confirmed)
    }
}

/// A cell reached by the search: the plane it is followed in and its distance in cells.
#[derive(Clone, Copy)]
struct Reached {
    anchor: Point,
    normal: Vector3<f64>,
    depth: usize,
}

/// The continuation test of `model` at `t_scene_model` against the judge's scan.
pub(crate) fn continuation(depth: &DepthTest, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Continuation {
    let map = &depth.heights;
    let target = model.target();
    let Some(normals) = target.normals() else {
        return Continuation::default();
    };
    let (w, h) = map.size();
    let tol = depth.tol;
    let max_depth =
        ((REACH * model.diameter) / map.cell_at(&(t_scene_model * model.symmetries.center))).ceil() as usize;
    let parallel = |n: &Vector3<f64>| {
        depth
            .supports
            .iter()
            .any(|s| s.normal.dot(n).abs() >= PARALLEL_TO_SUPPORT)
    };
    // Cells the posed part's surface is confirmed in, each seeded with the part's tangent plane.
    let mut state: HashMap<(usize, usize), Option<Reached>> = HashMap::new();
    let mut queue = VecDeque::new();
    let step = probe_step(model, JUDGE_PROBES);
    for (p, n) in target.points().iter().zip(normals).step_by(step) {
        let q = t_scene_model * p;
        let n = t_scene_model.rotation * n;
        if n.dot(&map.toward(&q)) < MIN_FACING {
            continue;
        }
        let Some(cell) = map.cell_of(&q) else { continue };
        let Some(top) = map.top_of(cell.0, cell.1) else {
            continue;
        };
        if n.dot(&(top - q)).abs() > tol || state.contains_key(&cell) {
            continue;
        }
        let seed = (!parallel(&n) && depth.off_supports(&top)).then_some(Reached {
            anchor: q,
            normal: n,
            depth: 0,
        });
        state.insert(cell, seed);
        if seed.is_some() {
            queue.push_back(cell);
        }
    }
    let confirmed = state.len();
    let to_model = t_scene_model.inverse();
    // Off the part: no point of its dense surface within twice the tolerance (the probes'
    // sampling is too coarse to tell).
    let off_part = |p: &Point| plane_residual(model, &(to_model * p), 2.0 * tol).is_none();
    let mut beyond = 0;
    // Past as many cells as confirm the pose the verdict is decided: the search stops there, so
    // that a wide tilted plane (a box's side, a tilted floor) costs no more than the part.
    while let Some((a, b)) = queue.pop_front() {
        if beyond > confirmed {
            break;
        }
        let Some(Some(r)) = state.get(&(a, b)).copied() else {
            continue;
        };
        if r.depth >= max_depth {
            continue;
        }
        for (da, db) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (na, nb) = (a as i64 + da, b as i64 + db);
            if na < 0 || nb < 0 || na as usize >= w || nb as usize >= h {
                continue;
            }
            let cell = (na as usize, nb as usize);
            if state.contains_key(&cell) {
                continue;
            }
            let Some(top) = map.top_of(cell.0, cell.1) else {
                continue;
            };
            if r.normal.dot(&(top - r.anchor)).abs() > tol || !depth.off_supports(&top) {
                continue;
            }
            let off = off_part(&top);
            beyond += off as usize;
            state.insert(
                cell,
                Some(Reached {
                    depth: r.depth + usize::from(off),
                    ..r
                }),
            );
            queue.push_back(cell);
        }
    }
    Continuation { confirmed, beyond }
}
