//! Physics piles: instances of one part dropped into a bin from random poses and left to settle
//! (rapier3d), every instance's pose read back; a part can be removed and the pile settles again.
//!
//! Each instance collides through a compound of convex hulls enclosing its mesh (`hulls`).

use super::convert;
use super::hulls::{decomposition_shape, hulls_of, Hull};
use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::TriMesh;
use crate::rng::Rng;
use nalgebra::{Isometry3, Translation3, Vector3};
use parry3d::math::Vector;
use parry3d::query::PointQuery;
use parry3d::shape::{SharedShape, TriMeshFlags};
use rapier3d::prelude::{ColliderBuilder, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle};

/// An open box standing on the floor of the robot's base frame (+z up). Its inner floor is the
/// plane z = `floor_z`; the inner volume spans `center ± inner_size / 2` in x and y.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BinSpec {
    /// Centre of the inner floor in x and y, mm.
    pub center: (f64, f64),
    /// Inner length (x), width (y) and wall height (z), mm.
    pub inner_size: Vector3<f64>,
    /// Height of the inner floor, mm.
    pub floor_z: f64,
    /// Thickness of the floor and the walls, mm.
    pub wall_thickness: f64,
}

impl Default for BinSpec {
    /// The default cell's bin: 300 × 200 mm inside, 80 mm deep, centred at (400, 0), floor at z = 0.
    fn default() -> Self {
        BinSpec {
            center: (400.0, 0.0),
            inner_size: Vector3::new(300.0, 200.0, 80.0),
            floor_z: 0.0,
            wall_thickness: 8.0,
        }
    }
}

impl BinSpec {
    /// Checks that every size is positive and finite.
    pub fn validate(&self) -> Result<()> {
        let s = self.inner_size;
        if !(s.iter().all(|v| v.is_finite() && *v > 0.0)) {
            return Err(Error::invalid(
                "bin",
                format!("inner size must be three positive lengths in mm, got {s:?}"),
            ));
        }
        if !(self.wall_thickness.is_finite() && self.wall_thickness > 0.0) {
            return Err(Error::invalid(
                "wall_thickness",
                format!("must be a positive length in mm, got {}", self.wall_thickness),
            ));
        }
        if !(self.center.0.is_finite() && self.center.1.is_finite() && self.floor_z.is_finite()) {
            return Err(Error::invalid("bin", "the centre and floor height must be finite"));
        }
        Ok(())
    }

    /// The inner volume as (min, max) corners, mm.
    pub fn inner_bounds(&self) -> (Point, Point) {
        let h = self.inner_size / 2.0;
        (
            Point::new(self.center.0 - h.x, self.center.1 - h.y, self.floor_z),
            Point::new(
                self.center.0 + h.x,
                self.center.1 + h.y,
                self.floor_z + self.inner_size.z,
            ),
        )
    }

    /// The floor and the four walls as boxes (centre, half extents), walls `wall_height` tall.
    fn boxes(&self, wall_height: f64) -> Vec<(Point, Vector3<f64>)> {
        let (lo, hi) = self.inner_bounds();
        let t = self.wall_thickness;
        let c = Point::new(self.center.0, self.center.1, 0.0);
        let h = self.inner_size / 2.0;
        let zc = self.floor_z + wall_height / 2.0;
        vec![
            (
                Point::new(c.x, c.y, self.floor_z - t / 2.0),
                Vector3::new(h.x + t, h.y + t, t / 2.0),
            ),
            (
                Point::new(lo.x - t / 2.0, c.y, zc),
                Vector3::new(t / 2.0, h.y + t, wall_height / 2.0),
            ),
            (
                Point::new(hi.x + t / 2.0, c.y, zc),
                Vector3::new(t / 2.0, h.y + t, wall_height / 2.0),
            ),
            (
                Point::new(c.x, lo.y - t / 2.0, zc),
                Vector3::new(h.x, t / 2.0, wall_height / 2.0),
            ),
            (
                Point::new(c.x, hi.y + t / 2.0, zc),
                Vector3::new(h.x, t / 2.0, wall_height / 2.0),
            ),
        ]
    }

    /// The bin as a closed triangle mesh (five boxes) in the base frame, for rendering.
    pub fn mesh(&self) -> TriMesh {
        let mut vertices = Vec::new();
        let mut faces = Vec::new();
        for (c, h) in self.boxes(self.inner_size.z) {
            let base = vertices.len() as u32;
            for i in 0..8 {
                let s = |bit: usize| if i & bit != 0 { 1.0 } else { -1.0 };
                vertices.push(Point::new(c.x + s(1) * h.x, c.y + s(2) * h.y, c.z + s(4) * h.z));
            }
            // Outward-wound quads of the box, corner index bits (x = 1, y = 2, z = 4).
            for q in [
                [0, 2, 3, 1],
                [4, 5, 7, 6],
                [0, 1, 5, 4],
                [2, 6, 7, 3],
                [0, 4, 6, 2],
                [1, 3, 7, 5],
            ] {
                faces.push([base + q[0], base + q[1], base + q[2]]);
                faces.push([base + q[0], base + q[2], base + q[3]]);
            }
        }
        TriMesh { vertices, faces }
    }
}

/// How a pile is dropped and settled. Lengths mm, times s.
#[derive(Debug, Clone, PartialEq)]
pub struct PileParams {
    /// Seed of every random choice: the same seed gives the same pile.
    pub seed: u64,
    /// Coulomb friction coefficient between parts and with the bin.
    pub friction: f64,
    /// Restitution (bounciness) in [0, 1].
    pub restitution: f64,
    /// Gap between the bounding spheres of parts at their drop positions, mm.
    pub drop_gap: f64,
    /// Simulation time step, s.
    pub time_step: f64,
    /// Give up settling after this much simulated time, s.
    pub max_settle_time: f64,
    /// The pile counts as settled when no part moves faster than this, mm/s ...
    pub rest_linear_speed: f64,
    /// ... nor turns faster than this, rad/s.
    pub rest_angular_speed: f64,
    /// Edge of the vertex-clustering grid used to simplify the mesh before decomposition, mm
    /// (0 = use the mesh as is).
    pub simplify_cell: f64,
    /// V-HACD voxel resolution along the mesh's longest side.
    pub decomposition_resolution: u32,
    /// Upper bound on convex pieces per part.
    pub max_convex_hulls: u32,
    /// Rounding added around every convex piece, mm: contacts form this far from the mesh, so
    /// the solver's small resting penetration does not reach the real surfaces.
    pub skin: f64,
}

impl Default for PileParams {
    fn default() -> Self {
        PileParams {
            seed: 0,
            friction: 0.5,
            restitution: 0.05,
            drop_gap: 5.0,
            time_step: 1.0 / 120.0,
            max_settle_time: 6.0,
            rest_linear_speed: 2.0,
            rest_angular_speed: 0.02,
            simplify_cell: 1.5,
            decomposition_resolution: 48,
            max_convex_hulls: 24,
            skin: 0.3,
        }
    }
}

impl PileParams {
    pub(super) fn validate(&self) -> Result<()> {
        let checks: [(&str, f64, bool); 9] = [
            ("friction", self.friction, self.friction >= 0.0),
            ("restitution", self.restitution, (0.0..=1.0).contains(&self.restitution)),
            ("drop_gap", self.drop_gap, self.drop_gap >= 0.0),
            (
                "time_step",
                self.time_step,
                self.time_step > 0.0 && self.time_step <= 0.05,
            ),
            ("max_settle_time", self.max_settle_time, self.max_settle_time > 0.0),
            (
                "rest_linear_speed",
                self.rest_linear_speed,
                self.rest_linear_speed > 0.0,
            ),
            (
                "rest_angular_speed",
                self.rest_angular_speed,
                self.rest_angular_speed > 0.0,
            ),
            ("simplify_cell", self.simplify_cell, self.simplify_cell >= 0.0),
            ("skin", self.skin, (0.0..=5.0).contains(&self.skin)),
        ];
        for (name, v, ok) in checks {
            if !v.is_finite() || !ok {
                return Err(Error::invalid(
                    name,
                    format!("{v} is out of range; see PileParams for the allowed values"),
                ));
            }
        }
        if self.decomposition_resolution < 8 || self.decomposition_resolution > 256 {
            return Err(Error::invalid(
                "decomposition_resolution",
                format!("must be in 8..=256, got {}", self.decomposition_resolution),
            ));
        }
        if self.max_convex_hulls == 0 {
            return Err(Error::invalid("max_convex_hulls", "must be at least 1"));
        }
        Ok(())
    }
}

/// What a call to settle did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SettleReport {
    /// Simulation steps taken.
    pub steps: usize,
    /// Simulated time, s.
    pub simulated_time: f64,
    /// True when every part came to rest before `max_settle_time`.
    pub settled: bool,
    /// Largest part speed at the end, mm/s.
    pub max_speed: f64,
}

/// Most parts one pile holds.
pub const MAX_PARTS: usize = 500;

/// A settled pile of parts in a bin, simulated by rapier. Instance ids are 0..count in drop order
/// and stay valid after other parts are removed.
pub struct Pile {
    pub(super) world: PhysicsWorld,
    pub(super) bodies: Vec<Option<RigidBodyHandle>>,
    pub(super) params: PileParams,
    bin: BinSpec,
    hull_shape: SharedShape,
    last: SettleReport,
}

impl std::fmt::Debug for Pile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pile")
            .field("remaining", &self.remaining())
            .field("bin", &self.bin)
            .field("last", &self.last)
            .finish()
    }
}

impl Pile {
    /// Drops `count` instances of `mesh` (mm, model frame) into `bin` from random poses above it
    /// and lets them settle. Deterministic for `params.seed`.
    pub fn drop(mesh: &TriMesh, count: usize, bin: &BinSpec, params: &PileParams) -> Result<Pile> {
        bin.validate()?;
        params.validate()?;
        if count == 0 {
            return Err(Error::invalid("count", "must be at least 1"));
        }
        if count > MAX_PARTS {
            return Err(Error::invalid(
                "count",
                format!("{count} parts is more than the simulator supports ({MAX_PARTS})"),
            ));
        }
        let hull_shape = decomposition_shape(mesh, params)?;
        // The bounding sphere about the mesh's centroid-of-bounds keeps drop positions apart.
        let (lo, hi) = mesh.bounds();
        let centre = nalgebra::center(&lo, &hi);
        let radius = mesh.vertices.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
        let (blo, bhi) = bin.inner_bounds();
        let mut rng = Rng::new(params.seed);
        let mut drops: Vec<Point> = Vec::with_capacity(count);
        let mut poses = Vec::with_capacity(count);
        for _ in 0..count {
            let span = |a: f64, b: f64, rng: &mut Rng| {
                let (a, b) = (a + radius, b - radius);
                if a < b {
                    rng.range(a, b)
                } else {
                    0.5 * (a + b)
                }
            };
            let x = span(blo.x, bhi.x, &mut rng);
            let y = span(blo.y, bhi.y, &mut rng);
            let mut z = bhi.z + radius + params.drop_gap;
            for d in &drops {
                let dxy = ((d.x - x).powi(2) + (d.y - y).powi(2)).sqrt();
                let need = 2.0 * radius + params.drop_gap;
                if dxy < need {
                    z = z.max(d.z + (need * need - dxy * dxy).sqrt());
                }
            }
            let c = Point::new(x, y, z);
            drops.push(c);
            let rot = rng.rotation();
            // Place the rotated mesh so that its bounds centre lands on the drop point.
            let t = Isometry3::from_parts(Translation3::from(c.coords - rot * centre.coords), rot);
            poses.push(t);
        }
        let top = drops.iter().map(|d| d.z + radius).fold(bhi.z, f64::max);
        let mut pile = Pile::build(hull_shape, &poses, bin, params, top);
        pile.settle();
        Ok(pile)
    }

    /// Instances of `mesh` placed at `poses` (`T_base_object`, mm) in `bin` and left to settle:
    /// a scene as a scan located it, for predicting what a motion through it does. Parts placed
    /// overlapping each other or the bin are pushed apart by the physics as it settles.
    pub fn place(mesh: &TriMesh, poses: &[Isometry3<f64>], bin: &BinSpec, params: &PileParams) -> Result<Pile> {
        bin.validate()?;
        params.validate()?;
        if poses.is_empty() || poses.len() > MAX_PARTS {
            return Err(Error::invalid(
                "poses",
                format!("{} poses; place 1 to {MAX_PARTS} parts", poses.len()),
            ));
        }
        let (_, bhi) = bin.inner_bounds();
        let (lo, hi) = mesh.bounds();
        let radius = 0.5 * (hi - lo).norm();
        let mut top = bhi.z;
        for (i, t) in poses.iter().enumerate() {
            let finite = t
                .translation
                .vector
                .iter()
                .chain(t.rotation.coords.iter())
                .all(|v| v.is_finite());
            if !finite {
                return Err(Error::invalid("poses", format!("pose {i} is not finite")));
            }
            top = top.max(t.translation.vector.z + radius);
        }
        let hull_shape = decomposition_shape(mesh, params)?;
        let mut pile = Pile::build(hull_shape, poses, bin, params, top);
        pile.settle();
        Ok(pile)
    }

    /// The physics world: the bin's walls reaching above `top` and a body per pose.
    fn build(hull_shape: SharedShape, poses: &[Isometry3<f64>], bin: &BinSpec, params: &PileParams, top: f64) -> Pile {
        let count = poses.len();

        let mut world = PhysicsWorld::new();
        world.gravity = Vector::new(0.0, 0.0, -9810.0);
        let ip = &mut world.integration_parameters;
        ip.dt = params.time_step as f32;
        ip.length_unit = 1000.0;
        ip.normalized_allowed_linear_error = 0.0001;
        ip.normalized_prediction_distance = 0.002;
        ip.num_solver_iterations = 8;
        // Clustered contact manifolds dropped the one corner a tilted part rests on, letting it sink.
        ip.contact_clustering = false;
        // Recycled manifolds went stale in resting piles and held parts millimetres deep in each other.
        ip.contact_recycling = false;
        // Stiffer contacts than rapier's game-tuned defaults: resting parts sink a fraction of a
        // millimetre instead of several.
        ip.contact_softness.natural_frequency *= 4.0;
        ip.static_contact_softness.natural_frequency *= 4.0;
        // Hopper walls: the physical walls reach above the highest drop so nothing falls out; the
        // rendered bin keeps its real height.
        let fixed = world.insert_body(RigidBodyBuilder::fixed().build());
        for (c, h) in bin.boxes(top - bin.floor_z + 50.0) {
            let collider = ColliderBuilder::cuboid(h.x as f32, h.y as f32, h.z as f32)
                .translation(convert::point_vec(&c))
                .friction(params.friction as f32)
                .restitution(params.restitution as f32)
                .build();
            world.insert_collider(collider, Some(fixed));
        }
        let mut bodies = Vec::with_capacity(count);
        for t in poses {
            let body = RigidBodyBuilder::dynamic()
                .pose(convert::pose(t))
                .ccd_enabled(true)
                .can_sleep(false)
                .linear_damping(0.2)
                .angular_damping(0.5)
                .build();
            let collider = ColliderBuilder::new(hull_shape.clone())
                .density(1e-3)
                .friction(params.friction as f32)
                .restitution(params.restitution as f32)
                .build();
            let (h, _) = world.insert(body, collider);
            bodies.push(Some(h));
        }
        Pile {
            world,
            bodies,
            params: params.clone(),
            bin: *bin,
            hull_shape,
            last: SettleReport {
                steps: 0,
                simulated_time: 0.0,
                settled: false,
                max_speed: 0.0,
            },
        }
    }

    /// Steps the simulation until every part is at rest (or `max_settle_time` passes).
    pub fn settle(&mut self) -> SettleReport {
        let dt = self.params.time_step;
        let max_steps = (self.params.max_settle_time / dt).ceil() as usize;
        // Rest must hold for a tenth of a second, so a part at the top of a bounce is not taken for settled.
        let need_quiet = ((0.1 / dt).ceil() as usize).max(1);
        let mut quiet = 0;
        let mut steps = 0;
        let mut max_speed = 0.0;
        while steps < max_steps {
            self.world.step();
            steps += 1;
            let (mut lin, mut ang) = (0.0f64, 0.0f64);
            for h in self.bodies.iter().flatten() {
                let b = &self.world.bodies[*h];
                lin = lin.max(b.linvel().length() as f64);
                ang = ang.max(b.angvel().length() as f64);
            }
            max_speed = lin;
            if lin < self.params.rest_linear_speed && ang < self.params.rest_angular_speed {
                quiet += 1;
                if quiet >= need_quiet {
                    break;
                }
            } else {
                quiet = 0;
            }
        }
        self.last = SettleReport {
            steps,
            simulated_time: steps as f64 * dt,
            settled: quiet >= need_quiet,
            max_speed,
        };
        self.last
    }

    /// The bin the pile lies in.
    pub fn bin(&self) -> &BinSpec {
        &self.bin
    }

    /// The report of the last settling.
    pub fn last_settle(&self) -> SettleReport {
        self.last
    }

    /// How many parts remain.
    pub fn remaining(&self) -> usize {
        self.bodies.iter().flatten().count()
    }

    /// `(id, T_base_object)` of every remaining part, by id.
    pub fn poses(&self) -> Vec<(usize, Isometry3<f64>)> {
        self.bodies
            .iter()
            .enumerate()
            .filter_map(|(i, h)| h.map(|h| (i, convert::isometry(self.world.bodies[h].position()))))
            .collect()
    }

    /// Removes part `id` (as a pick would) and lets the rest settle again.
    pub fn remove(&mut self, id: usize) -> Result<SettleReport> {
        let handle = match self.bodies.get(id) {
            Some(Some(h)) => *h,
            Some(None) => return Err(Error::invalid("id", format!("part {id} was already removed"))),
            None => {
                return Err(Error::invalid(
                    "id",
                    format!(
                        "no part {id}; ids run from 0 to {}",
                        self.bodies.len().saturating_sub(1)
                    ),
                ))
            }
        };
        self.world.remove_body(handle);
        self.bodies[id] = None;
        self.world.wake_up_all(true);
        Ok(self.settle())
    }

    /// Moves the remaining parts (in id order) to `poses`, at rest, and lets them settle: the
    /// same scene tried again without rebuilding its collision shapes.
    pub fn set_poses(&mut self, poses: &[Isometry3<f64>]) -> Result<SettleReport> {
        let handles: Vec<RigidBodyHandle> = self.bodies.iter().flatten().copied().collect();
        if poses.len() != handles.len() {
            return Err(Error::invalid(
                "poses",
                format!(
                    "{} poses for {} parts; pass one per remaining part",
                    poses.len(),
                    handles.len()
                ),
            ));
        }
        for (h, t) in handles.iter().zip(poses) {
            if !t
                .translation
                .vector
                .iter()
                .chain(t.rotation.coords.iter())
                .all(|v| v.is_finite())
            {
                return Err(Error::invalid("poses", "a pose is not finite"));
            }
            let body = &mut self.world.bodies[*h];
            body.set_position(convert::pose(t), true);
            body.set_linvel(Vector::ZERO, true);
            body.set_angvel(Vector::ZERO, true);
        }
        Ok(self.settle())
    }

    /// The deepest penetration between any two colliders (parts and bin) in the physics
    /// state, mm: how far the convex pieces overlap, before the skin is taken off. 0 when none do.
    pub fn max_contact_penetration(&self) -> f64 {
        let mut worst = 0.0f64;
        for pair in self.world.contact_pairs() {
            if let Some((_, c)) = pair.find_deepest_contact() {
                worst = worst.max(-(c.dist as f64));
            }
        }
        worst
    }

    /// The convex pieces every part collides with, in the model frame.
    pub fn collision_hulls(&self) -> Vec<Hull> {
        hulls_of(&self.hull_shape)
    }
}

/// The deepest interpenetration between instances of a closed mesh, mm: for every pair of
/// instances whose bounds overlap, how far the `samples` (points on the surface, model frame) of
/// one lie inside the other's mesh, and the other way round. 0 when no sample is inside.
pub fn max_interpenetration(mesh: &TriMesh, poses: &[Isometry3<f64>], samples: &[Point]) -> Result<f64> {
    if mesh.faces.is_empty() {
        return Err(Error::invalid("mesh", "has no faces"));
    }
    let verts: Vec<Vector> = mesh.vertices.iter().map(convert::point_vec).collect();
    let shape = parry3d::shape::TriMesh::with_flags(
        verts,
        mesh.faces.clone(),
        TriMeshFlags::ORIENTED | TriMeshFlags::MERGE_DUPLICATE_VERTICES,
    )
    .map_err(|e| {
        Error::invalid(
            "mesh",
            format!("cannot be used for inside tests ({e}); pass a closed, consistently wound mesh"),
        )
    })?;
    let aabb = shape.local_aabb();
    let (lo, hi) = mesh.bounds();
    let centre = nalgebra::center(&lo, &hi);
    let radius = mesh.vertices.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
    use rayon::prelude::*;
    let pairs: Vec<(usize, usize)> = (0..poses.len())
        .flat_map(|i| (0..poses.len()).filter(move |&j| j != i).map(move |j| (i, j)))
        .filter(|&(i, j)| ((poses[i] * centre) - (poses[j] * centre)).norm() < 2.0 * radius)
        .collect();
    let depth = pairs
        .par_iter()
        .map(|&(i, j)| {
            let t = poses[j].inverse() * poses[i];
            let mut worst = 0.0f64;
            for s in samples {
                let q = convert::point_vec(&(t * s));
                if q.cmplt(aabb.mins).any() || q.cmpgt(aabb.maxs).any() {
                    continue;
                }
                let proj = shape.project_local_point(q, false);
                if proj.is_inside {
                    worst = worst.max((proj.point - q).length() as f64);
                }
            }
            worst
        })
        .reduce(|| 0.0, f64::max);
    Ok(depth)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::mesh::parts::{tee, TeeParams};
    use crate::sim::hulls::convex_decomposition;

    pub(in crate::sim) fn small_tee() -> TriMesh {
        tee(&TeeParams {
            resolution: 2.0,
            ..Default::default()
        })
        .unwrap()
        .mesh
    }

    #[test]
    fn bin_mesh_is_closed_boxes() {
        let m = BinSpec::default().mesh();
        assert_eq!(m.faces.len(), 60);
        assert!(m.volume() > 0.0, "outward winding gives positive volume");
    }

    #[test]
    fn decomposition_encloses_the_mesh() {
        let m = small_tee();
        let hulls = convex_decomposition(&m, &PileParams::default()).unwrap();
        assert!(hulls.len() >= 2, "a tee is not convex: {} pieces", hulls.len());
        let hull_volume: f64 = hulls
            .iter()
            .map(|(v, f)| {
                TriMesh {
                    vertices: v.clone(),
                    faces: f.clone(),
                }
                .volume()
            })
            .sum();
        assert!(hull_volume > 0.95 * m.volume(), "{hull_volume} vs {}", m.volume());
    }

    #[test]
    fn pile_settles_inside_the_bin_and_repeats_for_a_seed() {
        let m = small_tee();
        let bin = BinSpec::default();
        let params = PileParams {
            seed: 7,
            ..Default::default()
        };
        let a = Pile::drop(&m, 4, &bin, &params).unwrap();
        let b = Pile::drop(&m, 4, &bin, &params).unwrap();
        assert_eq!(a.poses(), b.poses());
        assert!(a.last_settle().settled, "{:?}", a.last_settle());
        assert_inside_bin(&a, &m, 0.5);
    }

    /// Every part's mesh vertices (every 5th) lie inside the bin's inner volume, within `tol` mm.
    pub(in crate::sim) fn assert_inside_bin(pile: &Pile, mesh: &TriMesh, tol: f64) {
        let (lo, hi) = pile.bin().inner_bounds();
        for (id, t) in pile.poses() {
            for v in mesh.vertices.iter().step_by(5) {
                let p = t * v;
                assert!(
                    p.x > lo.x - tol && p.x < hi.x + tol && p.y > lo.y - tol && p.y < hi.y + tol && p.z > lo.z - tol,
                    "part {id} pokes out of the bin at {p}"
                );
            }
        }
    }

    #[test]
    fn a_settled_scene_placed_again_stays_and_can_be_set_back() {
        let m = small_tee();
        let bin = BinSpec::default();
        let params = PileParams::default();
        let dropped: Vec<Isometry3<f64>> = Pile::drop(&m, 3, &bin, &params)
            .unwrap()
            .poses()
            .into_iter()
            .map(|(_, t)| t)
            .collect();
        let mut placed = Pile::place(&m, &dropped, &bin, &params).unwrap();
        let close = |a: &[(usize, Isometry3<f64>)]| {
            a.iter().zip(&dropped).all(|((_, t), u)| {
                (t.translation.vector - u.translation.vector).norm() < 1.0 && t.rotation.angle_to(&u.rotation) < 0.02
            })
        };
        assert!(close(&placed.poses()), "{:?}", placed.poses());
        // Moved away and set back: the same scene, the same place.
        let mut shifted = dropped.clone();
        shifted[0].translation.vector.x += 20.0;
        placed.set_poses(&shifted).unwrap();
        placed.set_poses(&dropped).unwrap();
        assert!(close(&placed.poses()));
        assert!(placed.set_poses(&dropped[..2]).is_err());
        let mut bad = dropped.clone();
        bad[1].translation.vector.y = f64::NAN;
        assert!(placed.set_poses(&bad).is_err());
        assert!(Pile::place(&m, &bad, &bin, &params).is_err());
        assert!(Pile::place(&m, &[], &bin, &params).is_err());
    }

    #[test]
    fn removing_a_part_resettles() {
        let m = small_tee();
        let mut pile = Pile::drop(&m, 3, &BinSpec::default(), &PileParams::default()).unwrap();
        pile.remove(1).unwrap();
        assert_eq!(pile.remaining(), 2);
        assert_eq!(pile.poses().iter().map(|p| p.0).collect::<Vec<_>>(), vec![0, 2]);
        assert!(pile.remove(1).is_err());
        assert!(pile.remove(9).is_err());
    }
}
