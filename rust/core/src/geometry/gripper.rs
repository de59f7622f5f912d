//! The parallel gripper's occupied volume — two finger boxes and a cylindrical body above them —
//! and how many scene points lie in it at each of a batch of poses (the grasp planner's
//! collision count, asked for thousands of poses a pick).

use nalgebra::{Isometry3, Vector3};
use rayon::prelude::*;

use super::Point;

/// The gripper in its own frame (z = the approach into the part, x = the fingers' closing
/// direction, origin = the TCP between the fingertips), lengths in mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GripperShape {
    /// How far the fingertips reach past the TCP along +z.
    pub tip_depth: f64,
    /// The fingers' length along z.
    pub finger_length: f64,
    /// A finger's width along y.
    pub finger_width: f64,
    /// A finger's thickness along x.
    pub finger_thickness: f64,
    /// The body's radius about z.
    pub body_radius: f64,
    /// The body's length along z, above the fingers.
    pub body_length: f64,
}

/// How a point is tested against the volume: `margin` — only points more than that far inside
/// count (a surface grazing the gripper is not in it); `grow` — the gripper grown by that much on
/// every side but below the fingertips (a clearance round it).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Clearance {
    /// mm a point must lie inside to count.
    pub margin: f64,
    /// mm the volume grows on every side but below the tips.
    pub grow: f64,
}

/// The motion a pick sweeps the gripper through, for the planner's count of the scene points in
/// its way: `back` — it comes in along its own +z from `back` mm behind the pose (the straight
/// approach); `floor` — each point stands for everything straight below it (base −z) down to this
/// height (base z). No scan sees under a surface, so a finger may not reach in under a seen one;
/// and the same test is the gripper's rise straight up from anywhere on its approach (the
/// descent from above and the lift), which meets whatever lies above it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sweep {
    /// mm the gripper travels along its own +z to reach the pose.
    pub back: f64,
    /// The height (base z, mm) down to which each point stands for what lies below it; None: the
    /// points stand for themselves.
    pub floor: Option<f64>,
}

impl GripperShape {
    /// Whether `p` (gripper frame) lies inside a finger, the fingers `opening` mm apart, or the body.
    #[inline]
    pub fn occupied(&self, p: &Point, opening: f64, clearance: Clearance) -> bool {
        Volume::new(self, opening, opening, clearance, 0.0).holds(p.x, p.y, p.z)
    }

    /// How many of `points` (base frame) lie inside the gripper at each pose `T_base_gripper`,
    /// its fingers `openings[k]` apart (one opening per pose). Poses are counted in parallel
    /// (rayon's current pool).
    pub fn hits(
        &self,
        points: &[Point],
        poses: &[Isometry3<f64>],
        openings: &[f64],
        clearance: Clearance,
    ) -> Vec<usize> {
        self.hits_swept(points, poses, openings, clearance, Sweep::default())
    }

    /// [`hits`](Self::hits) along the motion `sweep`: how many of `points` the gripper meets
    /// coming in to each pose along its axis, each point standing for what lies straight below it
    /// down to `sweep.floor`.
    pub fn hits_swept(
        &self,
        points: &[Point],
        poses: &[Isometry3<f64>],
        openings: &[f64],
        clearance: Clearance,
        sweep: Sweep,
    ) -> Vec<usize> {
        self.hits_in(
            &PointGrid::new(points),
            poses,
            openings,
            &[],
            clearance,
            sweep,
            usize::MAX,
        )
    }

    /// [`hits_swept`](Self::hits_swept) of points bucketed once ([`PointGrid`]): for a planner
    /// that counts the same scene at batch after batch of poses. Each pose looks only at the
    /// points over its volume's footprint (a tilted gripper covers a part of the bin). `closed`:
    /// empty, or for each pose the width its fingers close to from `openings` (the fingers then
    /// sweep every width between; the clearance grows that sweep but for its inner face, which
    /// closes onto the part). A pose's count stops at `limit` (`limit` means at least that
    /// many): a planner that refuses a pose past some number of points need not count the rest
    /// of a pile it would plunge into.
    #[allow(clippy::too_many_arguments)]
    pub fn hits_in(
        &self,
        grid: &PointGrid,
        poses: &[Isometry3<f64>],
        openings: &[f64],
        closed: &[f64],
        clearance: Clearance,
        sweep: Sweep,
        limit: usize,
    ) -> Vec<usize> {
        poses
            .par_iter()
            .zip(openings.par_iter())
            .enumerate()
            .map(|(k, (pose, &opening))| {
                let moving = Volume::new(self, opening, opening, clearance, sweep.back.max(0.0));
                // The fingers' sweep as they close, at the pose only (none when they do not). Its
                // inner face is not grown: the fingers close onto the part's own surface there (a
                // width the grown open fingers reach already adds nothing).
                let shut = closed
                    .get(k)
                    .map_or(opening, |&w| (w + 2.0 * clearance.grow).min(opening));
                let closing = (shut < opening).then(|| Volume::new(self, opening, shut, clearance, 0.0));
                // Gripper-frame coordinates: R's columns dotted with p − t (Rᵀ (p − t)).
                let r = pose.rotation.to_rotation_matrix().into_inner();
                let t = pose.translation.vector;
                let (ax, ay, az) = (
                    r.column(0).into_owned(),
                    r.column(1).into_owned(),
                    r.column(2).into_owned(),
                );
                // The base-frame box round the volumes' own boxes: no point outside it (in x, y,
                // and below it; above it too for points that stand for themselves) is met.
                let frame = (t, [ax, ay, az]);
                let none = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
                let [shut_plus, shut_minus, _] = closing.as_ref().map_or([none; 3], Volume::pieces);
                let [finger_plus, finger_minus, body] = moving.pieces();
                let boxes = [finger_plus, finger_minus, body, shut_plus, shut_minus];
                let (base_lo, base_hi) = base_box(&frame, union(&boxes));
                let cells = grid.cells(base_lo, base_hi);
                match sweep.floor {
                    // Branch-free within a cell (every test evaluated, `&` not `&&`): the points
                    // come in no order, and a mispredicted branch costs more than the arithmetic
                    // it would skip.
                    None => count_upto(cells, limit, |cell| {
                        cell.iter()
                            .map(|p| {
                                let d = p.coords - t;
                                let q = (ax.dot(&d), ay.dot(&d), az.dot(&d));
                                let shut_in = closing.as_ref().is_some_and(|c| c.holds(q.0, q.1, q.2));
                                usize::from(moving.holds(q.0, q.1, q.2) | shut_in)
                            })
                            .sum::<usize>()
                    }),
                    Some(floor) => {
                        // Base −z in the gripper frame: the way each point's column runs.
                        let down = Column::new([-ax.z, -ay.z, -az.z]);
                        // Each piece's own base box: a column can meet a piece only from over
                        // its footprint and no lower than its lowest point (most points are below
                        // the body, and beside the fingers).
                        let pieces = boxes.map(|b| base_box(&frame, b));
                        count_upto(cells, limit, |cell| {
                            cell.iter()
                                .filter(|p| {
                                    let over = pieces.map(|(lo, hi)| {
                                        (p.x >= lo[0])
                                            & (p.x <= hi[0])
                                            & (p.y >= lo[1])
                                            & (p.y <= hi[1])
                                            & (p.z >= lo[2])
                                    });
                                    (over[0] | over[1] | over[2] | over[3] | over[4]) && {
                                        let d = p.coords - t;
                                        let q = [ax.dot(&d), ay.dot(&d), az.dot(&d)];
                                        let len = (p.z - floor).max(0.0);
                                        let shut_meets = |side: f64| {
                                            closing.as_ref().is_some_and(|c| c.meets_finger(q, &down, len, side))
                                        };
                                        (over[0] && moving.meets_finger(q, &down, len, 1.0))
                                            || (over[1] && moving.meets_finger(q, &down, len, -1.0))
                                            || (over[2] && moving.meets_body(q, &down, len))
                                            || (over[3] && shut_meets(1.0))
                                            || (over[4] && shut_meets(-1.0))
                                    }
                                })
                                .count()
                        })
                    }
                }
            })
            .collect()
    }

    /// For each pose `T_gripper_object` of a part whose `points` (object frame) are given: the
    /// farthest |x| (mm) of the points inside the slab the fingers sweep when `open_width` mm
    /// apart — more than `graze` mm inside it along y and z (a finger's edge may graze the part),
    /// out to the open fingers' outer faces — or −1 when no point lies in it. Half the part's
    /// width across the fingers at that grasp.
    pub fn widest_between(&self, points: &[Point], poses: &[Isometry3<f64>], open_width: f64, graze: f64) -> Vec<f64> {
        let outer = open_width / 2.0 + self.finger_thickness;
        let (lo_z, hi_z) = (self.tip_depth - self.finger_length + graze, self.tip_depth - graze);
        let half_y = self.finger_width / 2.0 - graze;
        poses
            .par_iter()
            .map(|pose| {
                let r = pose.rotation.to_rotation_matrix().into_inner();
                let t = pose.translation.vector;
                let (rx, ry, rz) = (r.row(0).transpose(), r.row(1).transpose(), r.row(2).transpose());
                points.iter().fold(-1.0_f64, |widest, p| {
                    let x = (rx.dot(&p.coords) + t.x).abs();
                    let y = (ry.dot(&p.coords) + t.y).abs();
                    let z = rz.dot(&p.coords) + t.z;
                    let inside = (y < half_y) & (z > lo_z) & (z < hi_z) & (x <= outer);
                    if inside {
                        widest.max(x)
                    } else {
                        widest
                    }
                })
            })
            .collect()
    }
}

/// Points (base frame) bucketed by their (x, y) on a square grid, each cell's points stored
/// together: built once for a scene that many poses of the gripper are counted against.
#[derive(Debug, Clone)]
pub struct PointGrid {
    origin: [f64; 2],
    cell: f64,
    size: [usize; 2],
    /// Where each cell's points start in `points` (one more entry than cells).
    start: Vec<usize>,
    points: Vec<Point>,
}

impl PointGrid {
    /// Cells of `CELL_MM`, or larger where the points spread so far that there would be more
    /// than `MAX_SIDE` a side.
    const CELL_MM: f64 = 10.0;
    const MAX_SIDE: usize = 256;

    /// The grid of `points`.
    pub fn new(points: &[Point]) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in points {
            lo = [lo[0].min(p.x), lo[1].min(p.y)];
            hi = [hi[0].max(p.x), hi[1].max(p.y)];
        }
        if points.is_empty() {
            (lo, hi) = ([0.0; 2], [0.0; 2]);
        }
        let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell = Self::CELL_MM.max(extent / (Self::MAX_SIDE - 1) as f64);
        let size = [0, 1].map(|k| ((hi[k] - lo[k]) / cell) as usize + 1);
        let mut grid = Self {
            origin: lo,
            cell,
            size,
            start: vec![0; size[0] * size[1] + 1],
            points: Vec::with_capacity(points.len()),
        };
        let index: Vec<usize> = points.iter().map(|p| grid.index(p.x, p.y)).collect();
        for &i in &index {
            grid.start[i + 1] += 1;
        }
        for i in 1..grid.start.len() {
            grid.start[i] += grid.start[i - 1];
        }
        let mut next = grid.start.clone();
        let mut sorted = vec![Point::origin(); points.len()];
        for (p, &i) in points.iter().zip(&index) {
            sorted[next[i]] = *p;
            next[i] += 1;
        }
        grid.points = sorted;
        grid
    }

    /// How many points the grid holds.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the grid holds no point.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    fn column(&self, v: f64, k: usize) -> usize {
        (((v - self.origin[k]) / self.cell).max(0.0) as usize).min(self.size[k] - 1)
    }

    fn index(&self, x: f64, y: f64) -> usize {
        self.column(y, 1) * self.size[0] + self.column(x, 0)
    }

    /// The points of every cell that overlaps the box from `lo` to `hi` (x, y), row by row.
    fn cells(&self, lo: [f64; 3], hi: [f64; 3]) -> impl Iterator<Item = &[Point]> + '_ {
        let outside = self.points.is_empty()
            || hi[0] < self.origin[0]
            || hi[1] < self.origin[1]
            || lo[0] > self.origin[0] + self.cell * self.size[0] as f64
            || lo[1] > self.origin[1] + self.cell * self.size[1] as f64;
        let (x0, x1) = (self.column(lo[0], 0), self.column(hi[0], 0));
        let (y0, y1) = (self.column(lo[1], 1), self.column(hi[1], 1));
        let rows = if outside { 0..0 } else { y0..y1 + 1 };
        rows.map(move |y| {
            let row = y * self.size[0];
            &self.points[self.start[row + x0]..self.start[row + x1 + 1]]
        })
    }
}

/// The volume at one opening and clearance, its bounds worked out once.
struct Volume {
    finger_z: (f64, f64),
    finger_half_y: f64,
    finger_offset: f64,
    finger_half_x: f64,
    body_z: (f64, f64),
    /// The body's radius squared; −1 when the clearance leaves no body (no point is within).
    body_radius_sq: f64,
}

impl Volume {
    /// The gripper's volume at `opening` and `clearance`, drawn out `back` mm along −z (the
    /// volume it sweeps coming in along its axis), its fingers closing from `opening` to `closed`
    /// (each finger then the box it sweeps: from the closed inner face to the open outer one).
    fn new(shape: &GripperShape, opening: f64, closed: f64, clearance: Clearance, back: f64) -> Self {
        let m = clearance.margin;
        let side = m - clearance.grow;
        let top = shape.tip_depth - shape.finger_length;
        let finger_z = (top + side - back, shape.tip_depth - m);
        let body_z = (top - shape.body_length + side - back, top - side);
        let radius = shape.body_radius - side;
        Self {
            finger_z,
            finger_half_y: shape.finger_width / 2.0 - side,
            finger_offset: (closed / 2.0 + opening / 2.0 + shape.finger_thickness) / 2.0,
            finger_half_x: (opening / 2.0 - closed / 2.0 + shape.finger_thickness) / 2.0 - side,
            body_z,
            body_radius_sq: if radius >= 0.0 { radius * radius } else { -1.0 },
        }
    }

    /// Whether the gripper-frame point (x, y, z) lies in a finger (z within the fingers' closed
    /// range) or the body (z within its half-open range: the body ends where the fingers start).
    #[inline]
    fn holds(&self, x: f64, y: f64, z: f64) -> bool {
        let finger = (z <= self.finger_z.1)
            & (z >= self.finger_z.0)
            & (y.abs() <= self.finger_half_y)
            & (((x - self.finger_offset).abs() <= self.finger_half_x)
                | ((x + self.finger_offset).abs() <= self.finger_half_x));
        let body = (z < self.body_z.1) & (z >= self.body_z.0) & (x * x + y * y <= self.body_radius_sq);
        finger | body
    }

    /// The boxes (gripper frame) of the +x finger, the −x finger and the body; an empty piece
    /// (a clearance that leaves none of it) gets a box no point is over.
    fn pieces(&self) -> [([f64; 3], [f64; 3]); 3] {
        let none = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        let (hx, hy, (z0, z1)) = (self.finger_half_x, self.finger_half_y, self.finger_z);
        let finger = |cx: f64| {
            if hx >= 0.0 && hy >= 0.0 && z0 <= z1 {
                ([cx - hx, -hy, z0], [cx + hx, hy, z1])
            } else {
                none
            }
        };
        let body = if self.body_radius_sq >= 0.0 && self.body_z.0 <= self.body_z.1 {
            let r = self.body_radius_sq.sqrt();
            ([-r, -r, self.body_z.0], [r, r, self.body_z.1])
        } else {
            none
        };
        [finger(self.finger_offset), finger(-self.finger_offset), body]
    }

    /// Whether the segment from `q` (gripper frame) `len` mm along the column meets the finger
    /// on the `side` (±1) of x (exactly: a box).
    #[inline]
    fn meets_finger(&self, q: [f64; 3], column: &Column, len: f64, side: f64) -> bool {
        let (hx, hy, (z0, z1)) = (self.finger_half_x, self.finger_half_y, self.finger_z);
        if hx < 0.0 || hy < 0.0 || z0 > z1 {
            return false;
        }
        let cx = side * self.finger_offset;
        let span = slab((0.0, len), q[1], column.inv[1], -hy, hy);
        let span = slab(span, q[2], column.inv[2], z0, z1);
        let span = slab(span, q[0], column.inv[0], cx - hx, cx + hx);
        span.0 <= span.1
    }

    /// Whether the segment from `q` (gripper frame) `len` mm along the column meets the body
    /// (exactly: a cylinder about z).
    #[inline]
    fn meets_body(&self, q: [f64; 3], column: &Column, len: f64) -> bool {
        if self.body_radius_sq < 0.0 || self.body_z.0 > self.body_z.1 {
            return false;
        }
        let (s0, s1) = slab((0.0, len), q[2], column.inv[2], self.body_z.0, self.body_z.1);
        if s0 > s1 {
            return false;
        }
        // The nearest approach of the segment's part within the body's length to its axis.
        let d = column.dir;
        let s = if column.along > 1e-12 {
            (-(q[0] * d[0] + q[1] * d[1]) / column.along).clamp(s0, s1)
        } else {
            s0
        };
        let (x, y) = (q[0] + s * d[0], q[1] + s * d[1]);
        x * x + y * y <= self.body_radius_sq
    }
}

/// The box (low corner, high corner) round `boxes` (an empty box adds nothing).
fn union(boxes: &[([f64; 3], [f64; 3])]) -> ([f64; 3], [f64; 3]) {
    boxes
        .iter()
        .fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(lo, hi), (a, b)| {
            ([0, 1, 2].map(|k| lo[k].min(a[k])), [0, 1, 2].map(|k| hi[k].max(b[k])))
        })
}

/// The sum of `count` over `cells`, stopping once it reaches `limit` (then `limit`).
fn count_upto<'a>(cells: impl Iterator<Item = &'a [Point]>, limit: usize, count: impl Fn(&[Point]) -> usize) -> usize {
    let mut n = 0usize;
    for cell in cells {
        n = n.saturating_add(count(cell));
        if n >= limit {
            return limit;
        }
    }
    n
}

/// The base-frame box round the gripper-frame box (`lo`, `hi`) of a pose (`t`, the gripper's
/// axes in the base frame).
fn base_box(frame: &(Vector3<f64>, [Vector3<f64>; 3]), (lo, hi): ([f64; 3], [f64; 3])) -> ([f64; 3], [f64; 3]) {
    let (t, axes) = frame;
    let mut base_lo = [f64::INFINITY; 3];
    let mut base_hi = [f64::NEG_INFINITY; 3];
    if (0..3).any(|k| lo[k] > hi[k]) {
        return (base_lo, base_hi);
    }
    for corner in 0..8 {
        let c = [0, 1, 2].map(|k| if corner >> k & 1 == 0 { lo[k] } else { hi[k] });
        let b = t + axes[0] * c[0] + axes[1] * c[1] + axes[2] * c[2];
        for k in 0..3 {
            base_lo[k] = base_lo[k].min(b[k]);
            base_hi[k] = base_hi[k].max(b[k]);
        }
    }
    (base_lo, base_hi)
}

/// A column's direction in the gripper frame (base −z turned into it), with what the segment
/// tests need of it worked out once per pose.
struct Column {
    dir: [f64; 3],
    /// 1 / dir (±∞ along an axis the column does not move along).
    inv: [f64; 3],
    /// dir's length squared across the gripper's axis.
    along: f64,
}

impl Column {
    fn new(dir: [f64; 3]) -> Self {
        Self {
            dir,
            inv: dir.map(|v| if v.abs() < 1e-12 { f64::INFINITY } else { 1.0 / v }),
            along: dir[0] * dir[0] + dir[1] * dir[1],
        }
    }
}

/// The part of `span` (a range of s) where `q + s·dir` lies in `[lo, hi]` along one axis, given
/// `inv` = 1 / dir; empty (start > end) where none does. Along an axis the segment does not move
/// (inv infinite), all of `span` or none.
#[inline]
fn slab(span: (f64, f64), q: f64, inv: f64, lo: f64, hi: f64) -> (f64, f64) {
    if inv.is_infinite() {
        return if q >= lo && q <= hi { span } else { (1.0, 0.0) };
    }
    let (a, b) = ((lo - q) * inv, (hi - q) * inv);
    (span.0.max(a.min(b)), span.1.min(a.max(b)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    const SHAPE: GripperShape = GripperShape {
        tip_depth: 10.0,
        finger_length: 45.0,
        finger_width: 20.0,
        finger_thickness: 8.0,
        body_radius: 45.0,
        body_length: 60.0,
    };

    /// `n` points uniform in x, y within ±`half` and z in [0, `height`).
    fn random_points(rng: &mut crate::Rng, n: usize, half: f64, height: f64) -> Vec<Point> {
        (0..n)
            .map(|_| {
                Point::new(
                    rng.uniform() * 2.0 * half - half,
                    rng.uniform() * 2.0 * half - half,
                    rng.uniform() * height,
                )
            })
            .collect()
    }

    /// A gripper pose pointing down (gripper z = base −z) tilted up to `tilt` rad about a random
    /// horizontal axis, shifted up to `shift` mm in x and y, its TCP `z0` to 1.5 `z0` mm up.
    fn tilted_down(rng: &mut crate::Rng, shift: f64, z0: f64, tilt: f64) -> Isometry3<f64> {
        let axis = Vector3::new(rng.uniform() - 0.5, rng.uniform() - 0.5, 0.0).normalize();
        Isometry3::from_parts(
            Translation3::new(
                rng.uniform() * shift,
                rng.uniform() * shift,
                z0 + rng.uniform() * z0 / 2.0,
            ),
            UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), tilt * rng.uniform())
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        )
    }

    #[test]
    fn a_point_is_in_a_finger_the_body_or_the_gap() {
        let none = Clearance::default();
        // Fingers 40 mm apart: the right finger spans x in [20, 28], the gap between is free.
        assert!(SHAPE.occupied(&Point::new(24.0, 0.0, 0.0), 40.0, none));
        assert!(SHAPE.occupied(&Point::new(-24.0, 9.9, 9.9), 40.0, none));
        assert!(!SHAPE.occupied(&Point::new(0.0, 0.0, 0.0), 40.0, none));
        assert!(!SHAPE.occupied(&Point::new(24.0, 0.0, 10.1), 40.0, none)); // below the tips
        assert!(!SHAPE.occupied(&Point::new(24.0, 10.1, 0.0), 40.0, none)); // beside the finger
                                                                            // The body: z in [-95, -35), within 45 mm of the axis.
        assert!(SHAPE.occupied(&Point::new(0.0, 0.0, -50.0), 40.0, none));
        assert!(SHAPE.occupied(&Point::new(30.0, 30.0, -90.0), 40.0, none));
        assert!(!SHAPE.occupied(&Point::new(40.0, 40.0, -50.0), 40.0, none));
        assert!(!SHAPE.occupied(&Point::new(0.0, 0.0, -95.5), 40.0, none));
        // A margin keeps a grazing point out; growing takes a near one in (not below the tips).
        let margin = Clearance { margin: 1.0, grow: 0.0 };
        assert!(!SHAPE.occupied(&Point::new(20.5, 0.0, 0.0), 40.0, margin));
        let grown = Clearance { margin: 0.0, grow: 2.0 };
        assert!(SHAPE.occupied(&Point::new(18.5, 0.0, 0.0), 40.0, grown));
        assert!(!SHAPE.occupied(&Point::new(24.0, 0.0, 11.0), 40.0, grown));
    }

    #[test]
    fn a_swept_gripper_meets_what_its_approach_crosses_and_what_lies_under_a_seen_surface() {
        let (none, opening) = (Clearance::default(), 40.0);
        // Straight down (gripper z = base −z, gripper x = base x): a point 120 mm above the TCP
        // over the −x finger is 25 mm past the body's back end (95 mm back): the approach meets
        // it once it comes from more than 25 mm back.
        let down = Isometry3::rotation(Vector3::x() * std::f64::consts::PI);
        let overhead = [Point::new(-24.0, 0.0, 120.0)];
        let local = down.inverse_transform_point(&overhead[0]);
        assert!((local.z + 120.0).abs() < 1e-9 && (local.x + 24.0).abs() < 1e-9);
        let no_sweep = SHAPE.hits_swept(&overhead, &[down], &[opening], none, Sweep::default());
        let short = SHAPE.hits_swept(
            &overhead,
            &[down],
            &[opening],
            none,
            Sweep {
                back: 20.0,
                floor: None,
            },
        );
        let long = SHAPE.hits_swept(
            &overhead,
            &[down],
            &[opening],
            none,
            Sweep {
                back: 30.0,
                floor: None,
            },
        );
        assert_eq!((no_sweep[0], short[0], long[0]), (0, 0, 1));

        // Tilted 30° about y: a point of a neighbour's top 15 mm above the +x finger's middle,
        // off to the side the finger leans under, is not in the finger, but the column under it
        // crosses the finger: counted only when the points stand for what lies below them.
        let tilt = std::f64::consts::FRAC_PI_6;
        let tilted = Isometry3::from_parts(
            Translation3::new(0.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt)
                * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
        );
        let finger_middle = tilted.transform_point(&Point::new(24.0, 0.0, -12.5));
        let above = Point::new(finger_middle.x, finger_middle.y, finger_middle.z + 15.0);
        assert!(!SHAPE.occupied(&tilted.inverse_transform_point(&above), opening, none));
        let floor_far_below = Sweep {
            back: 0.0,
            floor: Some(finger_middle.z - 100.0),
        };
        let floor_above_finger = Sweep {
            back: 0.0,
            floor: Some(finger_middle.z + 10.0),
        };
        let pts = [above];
        assert_eq!(
            SHAPE.hits_swept(&pts, &[tilted], &[opening], none, Sweep::default())[0],
            0
        );
        assert_eq!(
            SHAPE.hits_swept(&pts, &[tilted], &[opening], none, floor_far_below)[0],
            1
        );
        assert_eq!(
            SHAPE.hits_swept(&pts, &[tilted], &[opening], none, floor_above_finger)[0],
            0
        );
        // The column misses a gripper beside it, and a point on the floor stands for itself.
        let aside = Isometry3::translation(200.0, 0.0, 0.0) * tilted;
        assert_eq!(
            SHAPE.hits_swept(&pts, &[aside], &[opening], none, floor_far_below)[0],
            0
        );
        let on_floor = [Point::new(finger_middle.x, finger_middle.y, finger_middle.z)];
        let floor_here = Sweep {
            back: 0.0,
            floor: Some(finger_middle.z),
        };
        assert_eq!(
            SHAPE.hits_swept(&on_floor, &[tilted], &[opening], none, floor_here)[0],
            1
        );
    }

    #[test]
    fn closing_fingers_meet_what_lies_between_their_open_and_closed_faces() {
        let none = Clearance::default();
        let down = Isometry3::rotation(Vector3::x() * std::f64::consts::PI);
        // Gripper-frame points on the +x side, 5 mm short of the tips: inside the closed fingers'
        // inner face (x 10), between the closed and the open inner faces (x 14), in the open
        // finger (x 24), and past its outer face (x 29).
        let at = |x: f64| down.transform_point(&Point::new(x, 0.0, 5.0));
        let grid = PointGrid::new(&[at(5.0), at(14.0), at(24.0), at(29.0)]);
        let count = |closed: &[f64], floor: Option<f64>| {
            let sweep = Sweep { back: 0.0, floor };
            SHAPE.hits_in(&grid, &[down], &[40.0], closed, none, sweep, usize::MAX)[0]
        };
        for floor in [None, Some(-100.0)] {
            assert_eq!(count(&[], floor), 1, "open only: the finger's own box");
            assert_eq!(count(&[40.0], floor), 1, "closing to the opening is not closing");
            assert_eq!(count(&[20.0], floor), 2, "closing to 20 mm sweeps x 10 to 20");
            assert_eq!(count(&[60.0], floor), 1, "a width past the opening is the opening");
        }
        // Random tilted poses, closing widths and points: the count is that of the open fingers'
        // motion or of the fingers at any width between, sampled every 0.25 mm (the clearance
        // grows each finger but for the inner face, which closes onto the part).
        let mut rng = crate::Rng::new(5);
        let points = random_points(&mut rng, 3000, 40.0, 60.0);
        let grid = PointGrid::new(&points);
        for k in 0..8 {
            let pose = tilted_down(&mut rng, 10.0, 20.0, 0.5);
            let (opening, closed) = (40.0, 10.0 + 25.0 * rng.uniform());
            let clearance = Clearance {
                margin: 0.0,
                grow: if k % 2 == 0 { 0.0 } else { 2.0 },
            };
            let capped = |limit| {
                SHAPE.hits_in(
                    &grid,
                    &[pose],
                    &[opening],
                    &[closed],
                    clearance,
                    Sweep::default(),
                    limit,
                )[0]
            };
            let exact = capped(usize::MAX);
            // Each width's finger grown but for its inner face: as if closed 2·grow wider.
            let widths: Vec<f64> = (0..=((opening - closed) / 0.25) as usize)
                .map(|i| (closed + i as f64 * 0.25 + 2.0 * clearance.grow).min(opening))
                .collect();
            let sampled = points
                .iter()
                .filter(|p| {
                    let local = pose.inverse_transform_point(p);
                    widths.iter().any(|&w| SHAPE.occupied(&local, w, clearance))
                        || SHAPE.occupied(&local, opening, clearance)
                })
                .count();
            assert!(
                exact.abs_diff(sampled) <= 2,
                "pose {k}: exact {exact}, sampled {sampled}"
            );
            assert!(
                exact > SHAPE.hits(&points, &[pose], &[opening], clearance)[0],
                "pose {k}: closing meets more"
            );
            // The count stops at the limit, and is exact below it.
            assert_eq!(capped(3), 3.min(exact));
            assert_eq!(capped(exact + 1), exact);
            assert_eq!(capped(exact), exact);
        }
    }

    #[test]
    fn swept_counts_agree_with_dense_sampling_of_the_columns() {
        // Each point's column sampled every 0.05 mm against `occupied`, over random tilted poses:
        // the exact segment test counts the same points (up to points within a sample of an edge).
        let mut rng = crate::Rng::new(11);
        let points = random_points(&mut rng, 400, 80.0, 150.0);
        let floor = 0.0;
        for k in 0..6 {
            let pose = tilted_down(&mut rng, 20.0, 40.0, 0.8);
            let clearance = Clearance {
                margin: 0.0,
                grow: if k % 2 == 0 { 0.0 } else { 3.0 },
            };
            let back = 10.0 * k as f64;
            let exact = SHAPE.hits_swept(
                &points,
                &[pose],
                &[30.0],
                clearance,
                Sweep {
                    back,
                    floor: Some(floor),
                },
            )[0];
            let sampled = points
                .iter()
                .filter(|p| {
                    let steps = ((p.z - floor) / 0.05).ceil() as usize;
                    (0..=steps).any(|i| {
                        let below = Point::new(p.x, p.y, (p.z - i as f64 * 0.05).max(floor));
                        (0..=(back / 0.5) as usize).any(|j| {
                            let local = pose.inverse_transform_point(&below);
                            SHAPE.occupied(&Point::new(local.x, local.y, local.z + j as f64 * 0.5), 30.0, clearance)
                        })
                    })
                })
                .count();
            assert!(
                exact.abs_diff(sampled) <= 2,
                "pose {k}: exact {exact}, sampled {sampled}"
            );
            assert!(exact > 0, "pose {k}: the test should meet some points");
        }
    }

    #[test]
    fn the_widest_point_between_the_fingers_is_measured_in_their_slab_only() {
        // A bar along object x from -15 to 15 at y = z = 0, and a point far off in y; the
        // gripper at the object's origin (identity), and shifted 30 mm along z (the bar below the tips).
        let mut bar: Vec<Point> = (-15..=15).map(|x| Point::new(x as f64, 0.0, 0.0)).collect();
        bar.push(Point::new(22.0, 30.0, 0.0));
        let below = Isometry3::translation(0.0, 0.0, 30.0);
        let widest = SHAPE.widest_between(&bar, &[Isometry3::identity(), below], 50.0, 0.5);
        assert_eq!(widest, vec![15.0, -1.0]);
        // A point beyond the open fingers' outer faces (25 + 8) is not between them.
        let wide: Vec<Point> = vec![Point::new(34.0, 0.0, 0.0), Point::new(-12.0, 0.0, 0.0)];
        assert_eq!(
            SHAPE.widest_between(&wide, &[Isometry3::identity()], 50.0, 0.5),
            vec![12.0]
        );
    }

    #[test]
    fn hits_count_the_points_in_the_gripper_at_each_pose() {
        // A column of points along base z at x = 100; a gripper turned 90° about z with its TCP
        // at (100, -24, 0): its +x finger (gripper x = base y) covers the column where z ∈ [-35, 10].
        let column: Vec<Point> = (-200..=200).map(|z| Point::new(100.0, 0.0, z as f64)).collect();
        let turned = Isometry3::from_parts(
            Translation3::new(100.0, -24.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        let away = Isometry3::translation(500.0, 0.0, 0.0);
        let counts = SHAPE.hits(
            &column,
            &[turned, away, turned],
            &[40.0, 40.0, 60.0],
            Clearance::default(),
        );
        // Fingers 40 apart: the finger at gripper x ∈ [20, 28] holds base y = 0 (x = 24): z ∈ [-35, 10], 46 points.
        // 60 apart: the finger moves to x ∈ [30, 38], off the column; the body (radius 45) still holds z ∈ [-95, -35).
        assert_eq!(counts[1], 0);
        assert_eq!(counts[0], 46 + 60);
        assert_eq!(counts[2], 60);
    }
}
