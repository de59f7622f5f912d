//! Where a posed part ends, the scan's surface must end too. A pose that fits a piece of a
//! larger shape (a rod along the run of a tee, a plate on a bigger flat) is confirmed wherever
//! the depth test looks; what gives it away is its outline: past the edges of its sensor-facing
//! faces the scan goes on, at the height the face would have if it went on.
//!
//! The posed part's top surface is rasterised on the judge's height-map axes; at each outline
//! cell of a face turned toward the sensor (a silhouette where the surface turns away says
//! nothing) that the scan confirms, the face's tangent plane is followed two and three cells
//! outward and the scan's top there compared with it. Support surfaces (the bin's floor and
//! walls) do not count: a thin part lying on the floor meets the floor at its edges.

use super::depth::{share, DepthTest};
use crate::geometry::{perpendicular_basis, Point};
use crate::pose::model::PoseModel;
use nalgebra::{Isometry3, Vector3};

/// The smallest share of a normal along the sensor's direction for an outline cell to count
/// (cos 30°): a face the sensor looks at, whose plane can be followed past its edge. Cells of a
/// curved side nearer its silhouette turn away and say nothing.
const MIN_FACING: f64 = 0.87;
/// Most cells of the part's own footprint grid (a guard; a part spans a few hundred cells).
const MAX_FOOTPRINT_CELLS: usize = 1 << 22;

/// The outline test of one pose.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Outline {
    /// Outline cells of sensor-facing faces that the scan confirms.
    pub counted: usize,
    /// ... past which the scan's surface goes on in the face's plane.
    pub continued: usize,
}

impl Outline {
    /// Continued over counted (0 with nothing counted).
    pub fn continued_fraction(&self) -> f64 {
        share(self.continued, self.counted)
    }
}

/// One posed surface sample: its point and normal in the scene, its footprint cell, its height.
struct Posed {
    q: Point,
    n: Vector3<f64>,
    key: (i64, i64),
    h: f64,
}

/// The top surface of a posed part on a grid: per cell the highest posed point and its normal.
struct Footprint {
    origin: (i64, i64),
    size: (usize, usize),
    top: Vec<Option<(Point, Vector3<f64>, f64)>>,
}

impl Footprint {
    fn cell_of(&self, a: i64, b: i64) -> Option<usize> {
        let (i, j) = (a - self.origin.0, b - self.origin.1);
        if i < 0 || j < 0 || i as usize >= self.size.0 || j as usize >= self.size.1 {
            return None;
        }
        Some(i as usize * self.size.1 + j as usize)
    }

    fn occupied(&self, a: i64, b: i64) -> bool {
        self.cell_of(a, b).is_some_and(|k| self.top[k].is_some())
    }
}

/// The outline test of `model` at `t_scene_model` against the judge's scan.
pub(crate) fn outline(depth: &DepthTest, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Outline {
    let map = &depth.heights;
    // The footprint is drawn looking at the part from the sensor (for a perspective map, along
    // the ray to the part's centre: the rays spread by a few degrees across one part).
    let up = map.toward(&(t_scene_model * model.symmetries.center));
    let (e1, e2) = perpendicular_basis(&up);
    let target = model.target();
    let Some(normals) = target.normals() else {
        return Outline::default();
    };
    // Cells no finer than the samples, so that the footprint has no holes between them.
    let g = map
        .cell_at(&(t_scene_model * model.symmetries.center))
        .max(1.5 * model.spacing);
    let posed: Vec<Posed> = target
        .points()
        .iter()
        .zip(normals)
        .map(|(p, n)| {
            let q = t_scene_model * p;
            let key = (
                (q.coords.dot(&e1) / g).floor() as i64,
                (q.coords.dot(&e2) / g).floor() as i64,
            );
            Posed {
                q,
                n: t_scene_model.rotation * n,
                key,
                h: q.coords.dot(&up),
            }
        })
        .collect();
    let (lo, hi) = posed
        .iter()
        .fold(((i64::MAX, i64::MAX), (i64::MIN, i64::MIN)), |(l, h), x| {
            (
                (l.0.min(x.key.0), l.1.min(x.key.1)),
                (h.0.max(x.key.0), h.1.max(x.key.1)),
            )
        });
    if posed.is_empty() {
        return Outline::default();
    }
    let size = ((hi.0 - lo.0 + 1) as usize, (hi.1 - lo.1 + 1) as usize);
    if size.0.saturating_mul(size.1) > MAX_FOOTPRINT_CELLS {
        return Outline::default();
    }
    let mut fp = Footprint {
        origin: lo,
        size,
        top: vec![None; size.0 * size.1],
    };
    for x in &posed {
        let k = fp.cell_of(x.key.0, x.key.1).expect("inside the bounds just taken");
        if fp.top[k].is_none_or(|(_, _, top)| x.h > top) {
            fp.top[k] = Some((x.q, x.n, x.h));
        }
    }
    let tol = depth.tol;
    let on_support = |p: &Point| {
        depth
            .supports
            .iter()
            .any(|s| (s.normal.dot(&p.coords) - s.offset).abs() < 2.0 * tol)
    };
    let mut out = Outline::default();
    for a in lo.0..=hi.0 {
        for b in lo.1..=hi.1 {
            let Some((q, _, _)) = fp.cell_of(a, b).and_then(|k| fp.top[k]) else {
                continue;
            };
            // Outward: toward the empty neighbours of the footprint.
            let mut dir = (0.0, 0.0);
            for (da, db) in [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)] {
                if !fp.occupied(a + da, b + db) {
                    dir = (dir.0 + da as f64, dir.1 + db as f64);
                }
            }
            let len = (dir.0 * dir.0 + dir.1 * dir.1).sqrt();
            if len < 1e-9 {
                continue;
            }
            let Some((hs, _)) = map.top_at(&q) else { continue };
            if (hs - map.height(&q)).abs() > tol {
                continue; // not confirmed here (covered, or not seen): the edge says nothing
            }
            // The face's plane from two cells inward: the edge's own normals are those of its bevel.
            let inward = |k: f64| {
                (
                    a - (k * dir.0 / len).round() as i64,
                    b - (k * dir.1 / len).round() as i64,
                )
            };
            let (ia, ib) = inward(2.0);
            let Some((p0, n0, _)) = fp.cell_of(ia, ib).and_then(|k| fp.top[k]) else {
                continue;
            };
            if n0.dot(&up) < MIN_FACING {
                continue;
            }
            // On a face's edge the edge lies in the face's plane; near a silhouette the surface
            // has already curved away from it.
            let off_plane = |x: &Point| n0.dot(&(x - p0)) / n0.dot(&up);
            if off_plane(&q).abs() > tol {
                continue;
            }
            out.counted += 1;
            let d = (dir.0 / len) * e1 + (dir.1 / len) * e2;
            // Along the face's tangent plane: the height changes by −(n·d)/(n·up) per mm.
            let slope = -n0.dot(&d) / n0.dot(&up);
            let goes_on = [2.0, 3.0].iter().any(|k| {
                let reach = (q - p0).dot(&d) + k * g;
                let probe = p0 + reach * d + (reach * slope) * up;
                let (pa, pb) = (
                    (probe.coords.dot(&e1) / g).floor() as i64,
                    (probe.coords.dot(&e2) / g).floor() as i64,
                );
                if fp.occupied(pa, pb) {
                    return false; // the part itself is there (a concave outline)
                }
                // The scan's top in the probe's cell must itself lie off the part's footprint: a
                // coarse cell at the edge also holds the part's own points.
                map.top_at(&probe).is_some_and(|(hp, top)| {
                    let own = fp.occupied(
                        (top.coords.dot(&e1) / g).floor() as i64,
                        (top.coords.dot(&e2) / g).floor() as i64,
                    );
                    (hp - map.height(&probe)).abs() < tol && !own && !on_support(&top)
                })
            });
            out.continued += goes_on as usize;
        }
    }
    out
}
