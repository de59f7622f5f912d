//! Hypothesis verification: how well the scan explains a posed model, and how much of the
//! model's predicted visible surface lies where the sensor saw free space.
//!
//! The scan seen from the sensor's side is a height map: per cell of a grid across `up`, the
//! highest scan point. A model point facing the sensor is *seen* where the scan's surface is at
//! its predicted height, *violated* where the scan saw deeper (through the predicted surface:
//! the pose puts material where there is free space), *occluded* where the scan is higher and
//! that higher point is not on the posed model itself (something lies on top of it), *hidden*
//! where the higher point is on the posed model (its own surface hides it), and *missing* where
//! the cell holds no scan point. Flipped and half-matched poses predict surface where the scan saw
//! free space and lose; a pose that hangs over empty cells predicts surface nothing confirms;
//! buried instances show as occluded.

use super::icp::IcpTarget;
use crate::geometry::{median_range, perpendicular_basis, Point};
use crate::normals::Orientation;
use nalgebra::{Isometry3, Vector3};

/// The scan as a height map seen from the sensor, on a dense grid: orthographic along a
/// direction toward the sensor (a sensor far above, or a scan merged from many poses), or
/// perspective from the sensor's optical centre, each cell a bundle of rays. A point's *height*
/// grows toward the sensor: its distance along the direction, or minus its range from the
/// centre; each cell keeps its highest scan point, the first surface the sensor saw there.
pub struct HeightMap {
    e1: Vector3<f64>,
    e2: Vector3<f64>,
    /// Unit direction toward the sensor (the optical axis reversed, for a perspective map).
    pub up: Vector3<f64>,
    /// The optical centre of a perspective map.
    eye: Option<Point>,
    /// Where the sensor's lines of sight come from, where known: a perspective map's centre, or
    /// the viewpoint given to an orthographic map ([`HeightMap::seen_from`]).
    sensor: Option<Point>,
    /// Where the light that lit the scan comes from, when not from the sensor (a laser-line
    /// projector's origin, [`HeightMap::lit_from`]).
    light: Option<Point>,
    /// A perspective map's lateral coordinates are those at this range, mm (its cells' size there).
    focal: f64,
    cell: f64,
    origin: (f64, f64),
    size: (usize, usize),
    /// Per cell: the highest scan point (NaN height where empty).
    top: Vec<[f32; 3]>,
    height: Vec<f32>,
}

impl HeightMap {
    /// The height map of `points` seen as `view` says (along a direction, or from an optical
    /// centre), with cells of `cell` mm (enlarged if the grid would exceed 4 million cells).
    pub fn new(points: &[Point], view: Orientation, cell: f64) -> Self {
        HeightMap::layout(points, view, cell).filled(points)
    }

    /// This grid (from [`HeightMap::layout`]) with the highest of `points` in each cell.
    fn filled(self, points: &[Point]) -> Self {
        let mut map = self;
        map.top = vec![[0.0; 3]; map.size.0 * map.size.1];
        map.height = vec![f32::NAN; map.size.0 * map.size.1];
        for p in points {
            let (Some(k), h) = map.key(p) else { continue };
            let h = h as f32;
            if !(map.height[k] >= h) {
                map.height[k] = h;
                map.top[k] = [p.x as f32, p.y as f32, p.z as f32];
            }
        }
        map
    }

    /// The grid of a map of `points` with cells of `cell` mm (its frame, origin, cell and size),
    /// holding no cell yet. A perspective map looks along the direction from its centre to the
    /// points' centroid, its lateral coordinates scaled to the points' median range.
    fn layout(points: &[Point], view: Orientation, cell: f64) -> Self {
        let (up, eye, focal) = match view {
            Orientation::TowardDirection(d) => (d.try_normalize(1e-12).unwrap_or(Vector3::z()), None, 1.0),
            Orientation::TowardPoint(eye) => {
                let n = points.len().max(1) as f64;
                let centroid = points.iter().fold(Vector3::zeros(), |s, p| s + p.coords) / n;
                let up = (eye.coords - centroid).try_normalize(1e-12).unwrap_or(Vector3::z());
                let focal = median_range(points, &eye).unwrap_or(1.0);
                (
                    up,
                    Some(eye),
                    if focal.is_finite() && focal > 1e-9 { focal } else { 1.0 },
                )
            }
        };
        let (e1, e2) = perpendicular_basis(&up);
        let mut map = HeightMap {
            e1,
            e2,
            up,
            eye,
            sensor: eye,
            light: None,
            focal,
            cell: 1.0,
            origin: (0.0, 0.0),
            size: (1, 1),
            top: Vec::new(),
            height: Vec::new(),
        };
        let (mut lo, mut hi) = ((f64::INFINITY, f64::INFINITY), (f64::NEG_INFINITY, f64::NEG_INFINITY));
        for p in points {
            let Some((a, b, _)) = map.project(p) else { continue };
            lo = (lo.0.min(a), lo.1.min(b));
            hi = (hi.0.max(a), hi.1.max(b));
        }
        // An empty scan, or one whose extent overflows an f64, gets a one-cell map that covers
        // nothing beyond its first cell.
        if !((hi.0 - lo.0).is_finite() && (hi.1 - lo.1).is_finite()) {
            lo = (0.0, 0.0);
            hi = (0.0, 0.0);
        }
        let mut cell = cell.max(1e-3);
        while ((hi.0 - lo.0) / cell + 1.0) * ((hi.1 - lo.1) / cell + 1.0) > 4e6 {
            cell *= 1.5;
        }
        map.cell = cell;
        map.origin = lo;
        map.size = (((hi.0 - lo.0) / cell) as usize + 1, ((hi.1 - lo.1) / cell) as usize + 1);
        map
    }

    /// The height map with the smallest cell, from `cell` up, at which the scan covers its
    /// surfaces without holes (a laser-line scan is sparse across its lines): cells grow by 1.5×
    /// while more than a fifth of the occupied cells have empty cells on both sides along a grid
    /// axis (a line pattern; the edge of a surface has them on one side only), up to 8 × `cell`.
    /// The cells tried are judged on which of them hold a point; only the map kept is filled.
    pub fn fitted(points: &[Point], view: Orientation, cell: f64) -> Self {
        let mut c = cell;
        loop {
            let grid = HeightMap::layout(points, view, c);
            let mut occupied = vec![false; grid.size.0 * grid.size.1];
            for p in points {
                if let (Some(k), _) = grid.key(p) {
                    occupied[k] = true;
                }
            }
            if gaps(&occupied, grid.size) <= 0.2 || c >= 8.0 * cell {
                return grid.filled(points);
            }
            c *= 1.5;
        }
    }

    /// `p`'s lateral coordinates on the map's plane (mm; at the reference range for a perspective
    /// map) and its height; `None` behind a perspective map's centre.
    #[inline]
    fn project(&self, p: &Point) -> Option<(f64, f64, f64)> {
        match self.eye {
            None => {
                let v = p.coords;
                Some((v.dot(&self.e1), v.dot(&self.e2), v.dot(&self.up)))
            }
            Some(eye) => {
                let d = p - eye;
                let z = -d.dot(&self.up);
                if !(z > 1e-9) {
                    return None;
                }
                let s = self.focal / z;
                Some((s * d.dot(&self.e1), s * d.dot(&self.e2), -d.norm()))
            }
        }
    }

    #[inline]
    fn key(&self, p: &Point) -> (Option<usize>, f64) {
        let Some((a, b, h)) = self.project(p) else {
            return (None, f64::NAN);
        };
        let a = (a - self.origin.0) / self.cell;
        let b = (b - self.origin.1) / self.cell;
        if !(a >= 0.0 && b >= 0.0 && a < self.size.0 as f64 && b < self.size.1 as f64) {
            return (None, h);
        }
        (Some(a as usize * self.size.1 + b as usize), h)
    }

    /// The height of `p` on this map: its distance along [`HeightMap::up`], or minus its range
    /// from a perspective map's centre (higher is nearer the sensor).
    #[inline]
    pub fn height(&self, p: &Point) -> f64 {
        match self.eye {
            None => p.coords.dot(&self.up),
            Some(eye) => -(p - eye).norm(),
        }
    }

    /// Unit direction from `p` toward the sensor: [`HeightMap::up`], or toward a perspective
    /// map's centre.
    #[inline]
    pub fn toward(&self, p: &Point) -> Vector3<f64> {
        match self.eye {
            None => self.up,
            Some(eye) => (eye - p).try_normalize(1e-12).unwrap_or(self.up),
        }
    }

    /// Whether the map looks along one direction (no optical centre).
    pub fn is_orthographic(&self) -> bool {
        self.eye.is_none()
    }

    /// This map, knowing that the scan was seen from `viewpoint` (an orthographic map's cells
    /// stay columns along `up`; the sight lines of [`HeightMap::sight_blocked`] run to the
    /// viewpoint). A perspective map keeps its own centre.
    pub fn seen_from(mut self, viewpoint: Option<Point>) -> Self {
        if self.eye.is_none() {
            self.sensor = viewpoint;
        }
        self
    }

    /// This map, knowing that the scan was lit from `light` (see [`HeightMap::sight_blocked`]).
    pub fn lit_from(mut self, light: Option<Point>) -> Self {
        self.light = light;
        self
    }

    /// Whether the line of sight to the scan point `at` — or its line of light, where the map
    /// knows where the light came from — passes through the part whose surface is
    /// `target` (posed by `t_model_scene`, scene → model) before it rises to height `until`:
    /// walked from `at` toward the sensor (along `up` where it is not known) in half steps of
    /// `r` (of the target's sample spacing where that is larger), it is blocked where a point of
    /// it lies behind the surface of the sample nearest to it, within a step (inside the part).
    /// A sight line that only passes near the surface — past a silhouette, within the pose's
    /// tolerance — is not blocked. A scan point whose sight line misses the posed part was seen
    /// beside it, not through it: a coarse cell can hold the floor beside a steep side together
    /// with probes on that side. Without the target's normals, a point near it blocks.
    pub fn sight_blocked(
        &self,
        target: &IcpTarget,
        t_model_scene: &Isometry3<f64>,
        at: &Point,
        until: f64,
        r: f64,
    ) -> bool {
        let sight = match self.sensor {
            Some(s) => (s - at).try_normalize(1e-12).unwrap_or(self.up),
            None => self.up,
        };
        let lit = self.light.and_then(|l| (l - at).try_normalize(1e-12));
        std::iter::once(sight)
            .chain(lit)
            .any(|dir| self.line_blocked(target, t_model_scene, at, &dir, until, r))
    }

    /// Whether the line from `at` along `dir` passes inside the posed part before it rises to
    /// height `until` (see [`HeightMap::sight_blocked`]).
    fn line_blocked(
        &self,
        target: &IcpTarget,
        t_model_scene: &Isometry3<f64>,
        at: &Point,
        dir: &Vector3<f64>,
        until: f64,
        r: f64,
    ) -> bool {
        // Height gained per millimetre along the line (a perspective map's height is minus the
        // range from its centre).
        let rise = match self.eye {
            Some(eye) => dir.dot(&(eye - at).try_normalize(1e-12).unwrap_or(self.up)),
            None => dir.dot(&self.up),
        };
        let r = r.max(target.spacing().unwrap_or(0.0));
        if !(rise > 0.05 && r > 0.0) {
            return true;
        }
        let step = 0.5 * r;
        let steps = ((until - self.height(at)) / rise / step).ceil().min(MAX_SIGHT_STEPS);
        let (points, normals) = (target.points(), target.normals());
        // From two steps out: the samples of the surface `at` itself lies on are within reach.
        (2..=steps as usize).any(|i| {
            let m = t_model_scene * (at + dir * (i as f64 * step));
            match (target.search().nearest_within(&[m.x, m.y, m.z], r * r), normals) {
                (None, _) => false,
                (Some((k, _)), Some(n)) => (m - points[k]).dot(&n[k]) < 0.0,
                (Some(_), None) => true,
            }
        })
    }

    /// The grid's size in cells along its two axes.
    pub fn size(&self) -> (usize, usize) {
        self.size
    }

    /// The grid cell (along the two axes) holding `p`, if inside the grid.
    pub fn cell_of(&self, p: &Point) -> Option<(usize, usize)> {
        let k = self.key(p).0?;
        Some((k / self.size.1, k % self.size.1))
    }

    /// The highest scan point of cell (`a`, `b`), or `None` where nothing was scanned.
    pub fn top_of(&self, a: usize, b: usize) -> Option<Point> {
        let k = a * self.size.1 + b;
        if a >= self.size.0 || b >= self.size.1 || self.height[k].is_nan() {
            return None;
        }
        let t = self.top[k];
        Some(Point::new(t[0] as f64, t[1] as f64, t[2] as f64))
    }

    /// Edge of a cell at `p`, mm: the map's cell, scaled by `p`'s range for a perspective map.
    #[inline]
    pub fn cell_at(&self, p: &Point) -> f64 {
        match self.eye {
            None => self.cell,
            Some(eye) => self.cell * (p - eye).norm() / self.focal,
        }
    }

    /// How far a cell's top may lie from a probe at `p` of surface whose normal has share `c`
    /// toward the sensor and still confirm it: `tol`, widened by the cell's rise on that slope
    /// (the top of a cell lies up to a cell × tan(slope) above the probe).
    #[inline]
    pub fn slack(&self, tol: f64, c: f64, p: &Point) -> f64 {
        tol + self.cell_at(p) * (1.0 - c * c).sqrt() / c
    }

    /// Height of the scan's top surface over `p`'s cell, or `None` where nothing was scanned.
    #[inline]
    pub fn top_at(&self, p: &Point) -> Option<(f64, Point)> {
        let (Some(k), _) = self.key(p) else { return None };
        let h = self.height[k];
        if h.is_nan() {
            return None;
        }
        let t = self.top[k];
        Some((h as f64, Point::new(t[0] as f64, t[1] as f64, t[2] as f64)))
    }
}

/// The most steps [`HeightMap::sight_blocked`] walks (a sight line that long has left any part).
const MAX_SIGHT_STEPS: f64 = 400.0;

/// What the scan says about one posed model.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Evidence {
    /// Probe points facing the sensor.
    pub facing: usize,
    /// ... confirmed by the scan at their predicted height.
    pub seen: usize,
    /// ... where the scan saw through them (free space where the pose puts material).
    pub violated: usize,
    /// ... under scan points that are not on the posed model (something on top).
    pub occluded: usize,
    /// ... under scan points on the posed model itself (its own surface hides them).
    pub hidden: usize,
    /// ... within 45° of facing the sensor, over cells where the scan holds nothing.
    pub missing: usize,
}

impl Evidence {
    /// Seen over seen + violated: 1 for a pose the scan confirms wherever it can judge.
    pub fn coverage(&self) -> f64 {
        if self.seen + self.violated == 0 {
            0.0
        } else {
            self.seen as f64 / (self.seen + self.violated) as f64
        }
    }

    /// Fraction of the surface the sensor should see (facing, not hidden by the part itself)
    /// that the scan confirms.
    pub fn visible_fraction(&self) -> f64 {
        self.seen as f64 / (self.facing - self.hidden).max(1) as f64
    }

    /// Fraction of the surface the sensor should see that lies under other objects.
    pub fn occluded_fraction(&self) -> f64 {
        self.occluded as f64 / (self.facing - self.hidden).max(1) as f64
    }

    /// Of the surface that nothing else covers, the fraction the scan confirms (the rest is
    /// seen through, or over cells without data).
    pub fn supported_fraction(&self) -> f64 {
        self.seen as f64 / (self.seen + self.violated + self.missing).max(1) as f64
    }

    /// The ranking quality of a hypothesis: confirmed surface, discounted for violations.
    pub fn quality(&self) -> f64 {
        let c = self.coverage();
        self.seen as f64 * c * c
    }
}

/// Judges `t_scene_model` against the scan: every `step`-th point of `target` (the model) with
/// its normal is a probe; `tol` is the height tolerance, mm, widened on slopes by the cell's
/// rise. With `check_occluders`, a higher scan point is looked up on the posed model to tell
/// hidden (under the part's own surface) from occluded (under something else); without, both
/// count as occluded.
pub fn depth_evidence(
    target: &IcpTarget,
    heights: &HeightMap,
    t_scene_model: &Isometry3<f64>,
    step: usize,
    tol: f64,
    check_occluders: bool,
) -> Evidence {
    depth_evidence_with(target, heights, t_scene_model, step, tol, check_occluders, |_| {})
}

/// [`depth_evidence`], calling `on_violated` with each probe (scene frame) where the sensor saw
/// through the predicted surface.
pub fn depth_evidence_with(
    target: &IcpTarget,
    heights: &HeightMap,
    t_scene_model: &Isometry3<f64>,
    step: usize,
    tol: f64,
    check_occluders: bool,
    mut on_violated: impl FnMut(Point),
) -> Evidence {
    let normals = target.normals().unwrap_or(&[]);
    let t_model_scene = t_scene_model.inverse();
    let mut e = Evidence::default();
    let rot = t_scene_model.rotation.to_rotation_matrix().into_inner();
    let shift = t_scene_model.translation.vector;
    // Looking along one direction, it is one direction in the model's frame too.
    let up_model = heights
        .is_orthographic()
        .then(|| t_scene_model.rotation.inverse() * heights.up);
    for (p, n) in target.points().iter().zip(normals).step_by(step.max(1)) {
        let q = Point::from(rot * p.coords + shift);
        let c = match &up_model {
            Some(u) => n.dot(u),
            None => (rot * n).dot(&heights.toward(&q)),
        };
        if c < 0.3 {
            continue;
        }
        e.facing += 1;
        let h = heights.height(&q);
        let slack = heights.slack(tol, c, &q);
        match heights.top_at(&q) {
            // Steep faces go unscanned for many reasons (perspective, laser shadows); only
            // surface within 45° of facing the sensor is expected to be in the scan.
            None if c >= 0.7 => e.missing += 1,
            None => {}
            Some((top, _)) if (top - h).abs() <= slack => e.seen += 1,
            // The sensor saw below the predicted surface: through it, where its line of sight
            // to what it saw crosses the posed part; else beside it, which says nothing here.
            Some((top, at)) if top < h - slack => {
                if !heights.sight_blocked(target, &t_model_scene, &at, h + slack, tol) {
                    continue;
                }
                e.violated += 1;
                on_violated(q);
            }
            Some((_, at)) => {
                let m = t_model_scene * at;
                let own = check_occluders
                    && target
                        .search()
                        .nearest_within(&[m.x, m.y, m.z], 4.0 * tol * tol)
                        .is_some();
                if own {
                    e.hidden += 1;
                } else {
                    e.occluded += 1;
                }
            }
        }
    }
    e
}

/// Fraction of `points` within `tol` of the posed model (`t_model_scene` maps scene → model)
/// and the RMS distance of those.
pub fn inlier_stats(points: &[Point], target: &IcpTarget, t_model_scene: &Isometry3<f64>, tol: f64) -> (f64, f64) {
    let mut n = 0usize;
    let mut sq = 0.0;
    for p in points {
        let q = t_model_scene * p;
        if let Some((_, d)) = target.search().nearest_within(&[q.x, q.y, q.z], tol * tol) {
            n += 1;
            sq += d;
        }
    }
    let rmse = if n > 0 { (sq / n as f64).sqrt() } else { f64::INFINITY };
    (n as f64 / points.len().max(1) as f64, rmse)
}

/// Fraction of `points` within about `tol` of the posed model by the target's approximate
/// nearest field (exact search without one): the cheap score of coarse checks.
pub fn coarse_inlier_fraction(points: &[Point], target: &IcpTarget, t_model_scene: &Isometry3<f64>, tol: f64) -> f64 {
    let Some(field) = target.field() else {
        return inlier_stats(points, target, t_model_scene, tol).0;
    };
    let model = target.points();
    let r = t_model_scene.rotation.to_rotation_matrix().into_inner();
    let t = t_model_scene.translation.vector;
    let n = points
        .iter()
        .filter(|p| {
            let q = Point::from(r * p.coords + t);
            field
                .nearest(&[q.x, q.y, q.z])
                .is_some_and(|j| (model[j] - q).norm_squared() <= tol * tol)
        })
        .count();
    n as f64 / points.len().max(1) as f64
}

/// Fraction of the occupied cells (of a `size.0` × `size.1` grid, `occupied` per cell in map
/// order) whose two neighbours along a grid axis are both empty.
fn gaps(occupied: &[bool], size: (usize, usize)) -> f64 {
    let (w, h) = size;
    let empty = |k: usize| !occupied[k];
    let (mut gapped, mut count) = (0usize, 0usize);
    for a in 1..w.saturating_sub(1) {
        for b in 1..h.saturating_sub(1) {
            if empty(a * h + b) {
                continue;
            }
            count += 1;
            let across = empty((a - 1) * h + b) && empty((a + 1) * h + b);
            let along = empty(a * h + b - 1) && empty(a * h + b + 1);
            gapped += (across || along) as usize;
        }
    }
    if count == 0 {
        0.0
    } else {
        gapped as f64 / count as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    #[test]
    fn a_height_map_of_points_far_apart_is_bounded_and_does_not_hang() {
        let far = [
            Point::new(-1e308, 0.0, 0.0),
            Point::new(1e308, 0.0, 0.0),
            Point::new(0.0, 0.0, 1.0),
        ];
        let map = HeightMap::new(&far, Orientation::TowardDirection(Vector3::z()), 1.0);
        assert!(map.height.len() <= 4_000_000);
        let offset = [Point::new(1e16, 1e16, 0.0), Point::new(1e16 + 400.0, 1e16 + 300.0, 0.0)];
        let map = HeightMap::new(&offset, Orientation::TowardDirection(Vector3::z()), 1.0);
        assert!(map.height.len() <= 4_000_000);
        assert!(map.top_at(&offset[0]).is_some());
    }

    /// A 40 × 40 mm plate at z = 10 seen from above, judged as a model of itself.
    #[test]
    fn a_true_pose_is_seen_a_lifted_one_violates_and_a_covered_one_is_occluded() {
        let plate: Vec<Point> = (0..1600)
            .map(|i| Point::new((i % 40) as f64, (i / 40) as f64, 0.0))
            .collect();
        let normals = vec![Vector3::z(); plate.len()];
        let target = IcpTarget::new(plate.clone(), Some(normals)).unwrap();
        let at = |z: f64| Isometry3::from_parts(Translation3::new(0.0, 0.0, z), UnitQuaternion::identity());
        let scan: Vec<Point> = plate.iter().map(|p| at(10.0) * p).collect();
        let map = HeightMap::new(&scan, Orientation::TowardDirection(Vector3::z()), 1.0);
        let e = depth_evidence(&target, &map, &at(10.0), 1, 0.5, true);
        assert_eq!(e.facing, 1600);
        assert_eq!(e.seen, 1600);
        assert_eq!(e.coverage(), 1.0);
        // Below the scanned surface: a pose that would be hidden by it is occluded, not violated.
        let e = depth_evidence(&target, &map, &at(5.0), 1, 0.5, true);
        assert_eq!((e.seen, e.violated, e.occluded, e.hidden), (0, 0, 1600, 0));
        // Above it: the sensor saw through the predicted surface.
        let e = depth_evidence(&target, &map, &at(15.0), 1, 0.5, true);
        assert_eq!((e.seen, e.violated), (0, 1600));
        assert_eq!(e.coverage(), 0.0);
        // Beside the scan: nothing confirms it.
        let beside = Isometry3::from_parts(Translation3::new(100.0, 0.0, 10.0), UnitQuaternion::identity());
        let e = depth_evidence(&target, &map, &beside, 1, 0.5, true);
        assert_eq!((e.seen, e.missing), (0, 1600));
        assert_eq!(e.supported_fraction(), 0.0);
        // Two stacked plates of one part: the lower one is hidden by the upper, not occluded.
        let mut two = plate.clone();
        two.extend(plate.iter().map(|p| p + Vector3::new(0.0, 0.0, -5.0)));
        let stacked = IcpTarget::new(two, Some(vec![Vector3::z(); 3200])).unwrap();
        let e = depth_evidence(&stacked, &map, &at(10.0), 1, 0.5, true);
        assert_eq!((e.seen, e.hidden, e.occluded), (1600, 1600, 0));
        assert_eq!(e.visible_fraction(), 1.0);
        // A sparse scan (every third row) gets a coarser map without holes.
        let sparse: Vec<Point> = scan.iter().filter(|p| (p.y as i64) % 3 == 0).copied().collect();
        let fitted = HeightMap::fitted(&sparse, Orientation::TowardDirection(Vector3::z()), 1.0);
        assert!(fitted.cell > 2.0, "{}", fitted.cell);
        let (fit, rmse) = inlier_stats(&scan, &target, &at(10.0).inverse(), 0.5);
        assert_eq!(fit, 1.0);
        assert!(rmse < 1e-9);
    }
}

#[cfg(test)]
mod perspective_tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion};

    /// A 40 × 40 mm plate at z = 10 on a floor at z = 0, seen by a sensor at `eye`: the points
    /// where the sensor's rays first meet the plate or the floor.
    fn seen_from(eye: &Point) -> Vec<Point> {
        let mut out = Vec::new();
        for i in -200..200 {
            for j in -200..200 {
                let floor = Point::new(i as f64 * 0.5, j as f64 * 0.5, 0.0);
                let ray = floor - eye;
                // Where the ray to this floor point crosses the plate's plane.
                let s = (10.0 - eye.z) / ray.z;
                let at = eye + ray * s;
                let on_plate = (0.0..40.0).contains(&at.x) && (0.0..40.0).contains(&at.y);
                out.push(if on_plate { at } else { floor });
            }
        }
        out
    }

    #[test]
    fn a_perspective_map_judges_along_the_sensors_rays() {
        // A sensor 300 mm up and 200 mm aside: a plate's top as it sees it, and the floor past it.
        let eye = Point::new(-200.0, 20.0, 300.0);
        let scan = seen_from(&eye);
        let plate: Vec<Point> = (0..1600)
            .map(|i| Point::new((i % 40) as f64, (i / 40) as f64, 0.0))
            .collect();
        let target = IcpTarget::new(plate, Some(vec![Vector3::z(); 1600])).unwrap();
        let at = |x: f64, z: f64| Isometry3::from_parts(Translation3::new(x, 0.0, z), UnitQuaternion::identity());
        let map = HeightMap::new(&scan, Orientation::TowardPoint(eye), 0.5);
        assert!(!map.is_orthographic());
        let e = depth_evidence(&target, &map, &at(0.0, 10.0), 1, 0.5, true);
        assert!(e.seen > 1500 && e.violated <= 16, "{e:?}"); // cells straddling the edge
                                                             // Lifted toward the sensor: it sees through it along its rays.
        let e = depth_evidence(&target, &map, &at(0.0, 20.0), 1, 0.5, true);
        assert!(e.violated > 1000, "{e:?}");
        // Sunk below the plate: under it along the rays (occluded), but for a strip along the edge
        // nearest the sensor, whose rays pass under the plate's edge (it is a sheet, not a block).
        let e = depth_evidence(&target, &map, &at(0.0, 4.0), 1, 0.5, true);
        assert!(e.occluded > 1000 && e.violated < e.occluded / 5, "{e:?}");
        // Looked at straight down instead, the oblique scan's floor points past the plate's far
        // edge lie where a vertical column meets the plate: the rays are what decide.
        let down = HeightMap::new(&scan, Orientation::TowardDirection(Vector3::z()), 0.5);
        let e = depth_evidence(&target, &down, &at(0.0, 10.0), 1, 0.5, true);
        assert!(e.violated > 0 || e.missing > 0, "{e:?}");
    }

    /// A tube of radius 10 lying along y (0..40) on a floor at z = 0, seen by a sensor at
    /// `eye`: where the sensor's rays to the floor first meet the tube or the floor, without the
    /// tube's flanks steeper than 37° (a laser's shadow leaves them unscanned).
    fn tube_seen_from(eye: &Point) -> Vec<Point> {
        let mut out = Vec::new();
        for i in -60..60 {
            for j in 0..80 {
                let floor = Point::new(i as f64 * 0.5, j as f64 * 0.5, 0.0);
                let d = floor - eye;
                // (ex + s dx)² + (ez + s dz − 10)² = 100: the first s in [0, 1].
                let (ox, oz) = (eye.x, eye.z - 10.0);
                let (a, b, c) = (
                    d.x * d.x + d.z * d.z,
                    2.0 * (ox * d.x + oz * d.z),
                    ox * ox + oz * oz - 100.0,
                );
                let disc = b * b - 4.0 * a * c;
                let s = (disc >= 0.0)
                    .then(|| (-b - disc.sqrt()) / (2.0 * a))
                    .filter(|s| (0.0..1.0).contains(s));
                match s.map(|s| eye + d * s) {
                    Some(hit) if (hit.z - 10.0) / 10.0 >= 0.8 => out.push(hit),
                    Some(_) => {}
                    None => out.push(floor),
                }
            }
        }
        out
    }

    #[test]
    fn columns_told_where_the_sensor_is_count_only_what_it_saw_through_the_part() {
        // In vertical columns of 4 mm (a sparse laser-line scan's), the floor the sensor saw
        // under the tube's near side shares cells with the tube's unscanned flank and lies
        // below it there.
        let eye = Point::new(-200.0, 20.0, 300.0);
        let scan = tube_seen_from(&eye);
        let (mut tube, mut normals) = (Vec::new(), Vec::new());
        for k in 0..126 {
            let phi = k as f64 * 0.05;
            for y in 0..40 {
                tube.push(Point::new(10.0 * phi.sin(), y as f64, 10.0 + 10.0 * phi.cos()));
                normals.push(Vector3::new(phi.sin(), 0.0, phi.cos()));
            }
        }
        let target = IcpTarget::new(tube, Some(normals)).unwrap();
        let at = |z: f64| Isometry3::from_parts(Translation3::new(0.0, 0.0, z), UnitQuaternion::identity());
        let columns = || HeightMap::new(&scan, Orientation::TowardDirection(Vector3::z()), 4.0);
        let blind = depth_evidence(&target, &columns(), &at(0.0), 1, 0.5, true);
        // Told where the sensor is: its sight lines to that floor pass beside the tube.
        let told = columns().seen_from(Some(eye));
        let e = depth_evidence(&target, &told, &at(0.0), 1, 0.5, true);
        assert!(blind.violated > 200 && e.violated == 0, "{blind:?} {e:?}");
        assert_eq!(e.seen, blind.seen);
        // The tube lifted 10 mm: the sight lines to what the sensor saw under it cross it.
        let lifted = depth_evidence(&target, &told, &at(10.0), 1, 0.5, true);
        assert!(lifted.violated > 1000, "{lifted:?}");
        // Without a sensor position the sight lines run along up: the columns' verdict.
        assert_eq!(
            depth_evidence(&target, &columns().seen_from(None), &at(0.0), 1, 0.5, true),
            blind
        );
        // Straight up from the floor: through the tube under its axis, past it 1 mm beside its
        // widest point (within any pose's tolerance of its surface, but outside it).
        let up = columns().seen_from(None);
        let pose = at(0.0).inverse();
        assert!(up.sight_blocked(&target, &pose, &Point::new(3.0, 20.0, 0.0), 30.0, 1.0));
        assert!(!up.sight_blocked(&target, &pose, &Point::new(-11.0, 20.0, 0.0), 30.0, 1.0));
        assert!(!up.sight_blocked(&target, &pose, &Point::new(11.0, 20.0, 0.0), 30.0, 1.0));
        // Lit from up and aside (a laser beside the camera): the floor beside the tube was in its
        // shadow, and a point the scan holds there says the tube is not where the pose has it.
        let lit = columns().seen_from(None).lit_from(Some(Point::new(300.0, 20.0, 300.0)));
        assert!(lit.sight_blocked(&target, &pose, &Point::new(-11.0, 20.0, 0.0), 30.0, 1.0));
        assert!(!lit.sight_blocked(&target, &pose, &Point::new(11.0, 20.0, 0.0), 30.0, 1.0));
        // The oblique scan's floor seen under the tube's near side was lit from the sensor's side;
        // a light on the far side could not have reached it past the tube as posed.
        let far = columns()
            .seen_from(Some(eye))
            .lit_from(Some(Point::new(200.0, 20.0, 300.0)));
        assert!(depth_evidence(&target, &far, &at(0.0), 1, 0.5, true).violated > 200);
        let near = columns().seen_from(Some(eye)).lit_from(Some(eye));
        assert_eq!(depth_evidence(&target, &near, &at(0.0), 1, 0.5, true), e);
    }
}
