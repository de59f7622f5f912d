//! The depth test: a posed model's surface against the scan's height map (what the scan
//! confirms, sees through, leaves over empty cells or under other parts), the patches of the
//! predicted surface the sensor saw through, and how much of a pose passes through the bin's floor
//! or walls or the removed support planes. The bottom of the judge: its other checks read the scan
//! through the [`DepthTest`].

use crate::geometry::{BinBox, Plane, Point};
use crate::pose::model::PoseModel;
use crate::pose::scene::Context;
use crate::pose::types::NOISE_SIGMAS;
use crate::registration::ppf::PpfConfig;
use crate::registration::verify::{depth_evidence, depth_evidence_with, Evidence, HeightMap};
use nalgebra::{Isometry3, Vector3};

/// Probe points of the judge over the model's dense surface.
pub(crate) const JUDGE_PROBES: usize = 2000;
/// Seen-through probes with at least this many seen-through neighbours within two probe
/// spacings lie inside a patch of them (on an even sampling a disc of that radius holds about
/// twelve probes; a strip along a silhouette, where cells straddle the edge, about four).
const PATCH_NEIGHBOURS: usize = 6;
/// The most probes inside seen-through patches a pose may have: a patch of the surface where
/// the sensor saw free space — a branch standing where the scan looks past it — is material
/// that is not there, whatever else the pose explains.
pub(super) const MAX_PATCH_PROBES: usize = 8;

/// `part` over `whole`, 0 when `whole` is 0: the shares the outline and continuation tests decide on.
pub(super) fn share(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// The scan as the depth test reads it: the height map a posed surface is compared with, the
/// tolerance, and the supports no part passes through.
pub(crate) struct DepthTest {
    /// The height map of the whole scene (the bin's floor is evidence too: surface predicted
    /// above a visible floor is surface where the sensor saw free space).
    pub heights: HeightMap,
    /// Depth-test and inlier tolerance, mm.
    pub tol: f64,
    /// Support surfaces no part can pass through: the bin's floor and walls (from the bin box),
    /// or the floor-like support planes removed without one that nothing of the scan lies under;
    /// normals point to the free side.
    pub supports: Vec<Plane>,
    /// Every floor-like support plane removed without a bin box, normal toward `up`: solid where
    /// the sensor sees it. A table with the room's floor or the robot's base under its edge is no
    /// support everywhere (see `supports`), but where the scan shows its surface in front of a
    /// pose's surface, that surface is inside the table.
    pub seen_planes: Vec<Plane>,
}

/// The PPF step of `model` (its table's, or the default table's when it has none): the scale of
/// the judge's tolerance and height-map cells.
pub(crate) fn judge_step(model: &PoseModel) -> f64 {
    model
        .ppf
        .as_ref()
        .map(|p| p.step())
        .unwrap_or(PpfConfig::default().sampling_ratio * model.diameter)
}

/// Tolerance of the depth test and of inliers for a PPF step and the scan's depth noise (σ, mm):
/// 0.12 of the step, not below 1 mm (the voxel means' bias on curved surfaces, and the noise of
/// the laser scanners the 1 mm was set for), and not below [`NOISE_SIGMAS`] σ.
pub(crate) fn tolerance(step: f64, noise: f64) -> f64 {
    (0.12 * step).max(1.0).max(NOISE_SIGMAS * noise)
}

/// Voxel size of the detection grid for a PPF step, mm.
pub(crate) fn voxel_size(step: f64) -> f64 {
    (step / 3.0).max(0.5)
}

/// Probe stride over the model's dense points for about `n` probes.
pub(crate) fn probe_step(model: &PoseModel, n: usize) -> usize {
    (model.target().points().len() / n.max(1)).max(1)
}

impl DepthTest {
    /// The depth test of the context's whole scene for its model: `removed` are the support planes
    /// bin removal took out (unused with a bin box), `remaining` the points it kept. Its
    /// tolerance and cells derive from the model's PPF step ([`judge_step`]).
    pub fn new(ctx: &Context<'_>, remaining: &[Point], removed: Vec<Plane>) -> Self {
        let step = judge_step(ctx.model);
        let tol = tolerance(step, ctx.noise);
        let up = ctx.up;
        let seen_planes = floors(removed, &up);
        let supports = match &ctx.cfg.bin {
            Some(bin) => bin_walls(bin),
            None => with_nothing_below(remaining, &seen_planes, tol),
        };
        DepthTest {
            heights: HeightMap::fitted(ctx.scene, ctx.view, (0.5 * voxel_size(step)).max(1.0))
                .seen_from(ctx.cfg.viewpoint)
                .lit_from(ctx.cfg.light),
            tol,
            supports,
            seen_planes,
        }
    }

    /// Whether `p` lies clear of every support (more than twice the tolerance on its free
    /// side): points on the floor or a wall lie in the plane of the faces that rest on it and
    /// would confirm material wherever a pose puts it.
    pub fn off_supports(&self, p: &Point) -> bool {
        self.supports
            .iter()
            .all(|s| s.normal.dot(&p.coords) - s.offset > 2.0 * self.tol)
    }

    /// The depth test of a pose with the dense probe.
    pub fn evidence(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Evidence {
        depth_evidence(
            model.target(),
            &self.heights,
            t_scene_model,
            probe_step(model, JUDGE_PROBES),
            self.tol,
            true,
        )
    }

    /// Seen-through probes of the posed model that lie inside a patch of them (see
    /// [`PATCH_NEIGHBOURS`]), counted only when there are enough to make one.
    pub(super) fn seen_through_patch(
        &self,
        model: &PoseModel,
        t_scene_model: &Isometry3<f64>,
        violated: usize,
    ) -> usize {
        if violated <= MAX_PATCH_PROBES {
            return 0;
        }
        let step = probe_step(model, JUDGE_PROBES);
        let mut probes = Vec::with_capacity(violated);
        depth_evidence_with(
            model.target(),
            &self.heights,
            t_scene_model,
            step,
            self.tol,
            false,
            |q| probes.push(q),
        );
        // Two probe spacings: the probes share the part's area evenly.
        let probes_total = model.target().points().len().div_ceil(step).max(1);
        let r = 2.0 * (model.area / probes_total as f64).sqrt();
        probes
            .iter()
            .filter(|p| probes.iter().filter(|q| (*q - *p).norm_squared() <= r * r).count() > PATCH_NEIGHBOURS)
            .count()
    }

    /// Fraction of the posed part's surface more than twice the tolerance beyond a support.
    pub fn through_supports(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> f64 {
        if self.supports.is_empty() && self.seen_planes.is_empty() {
            return 0.0;
        }
        let pts = model.target().points();
        let step = (pts.len() / 500).max(1);
        let margin = 2.0 * self.tol;
        let inside = pts
            .iter()
            .step_by(step)
            .filter(|p| {
                let q = t_scene_model * *p;
                self.supports
                    .iter()
                    .any(|s| s.normal.dot(&q.coords) < s.offset - margin)
                    || self.seen_planes.iter().any(|s| {
                        s.normal.dot(&q.coords) < s.offset - margin
                            && self
                                .heights
                                .top_at(&q)
                                .is_some_and(|(_, top)| (s.normal.dot(&top.coords) - s.offset).abs() <= margin)
                    })
            })
            .count();
        inside as f64 / pts.len().div_ceil(step) as f64
    }
}

/// The bin's floor and four walls, normals toward the inside.
fn bin_walls(bin: &BinBox) -> Vec<Plane> {
    let (lo, hi) = (bin.min.coords, bin.max.coords);
    let mut walls = vec![Plane {
        normal: Vector3::z(),
        offset: lo.z,
    }];
    for k in 0..2 {
        let e = Vector3::ith(k, 1.0);
        walls.push(Plane {
            normal: e,
            offset: lo[k],
        });
        walls.push(Plane {
            normal: -e,
            offset: -hi[k],
        });
    }
    walls
}

/// Of the removed support planes, the floors (which side of a wall is free is not known
/// without the bin), normals toward `up`.
fn floors(planes: Vec<Plane>, up: &Vector3<f64>) -> Vec<Plane> {
    planes
        .into_iter()
        .filter(|p| p.normal.dot(up).abs() > 0.8)
        .map(|p| {
            if p.normal.dot(up) > 0.0 {
                p
            } else {
                Plane {
                    normal: -p.normal,
                    offset: -p.offset,
                }
            }
        })
        .collect()
}

/// Of `floors`, those with the scene above them (a bin's rim is a wide plane too, with parts
/// below): supports everywhere.
fn with_nothing_below(remaining: &[Point], floors: &[Plane], tol: f64) -> Vec<Plane> {
    floors
        .iter()
        .filter(|p| {
            remaining
                .iter()
                .filter(|q| p.normal.dot(&q.coords) < p.offset - 2.0 * tol)
                .count()
                * 50
                < remaining.len()
        })
        .copied()
        .collect()
}
