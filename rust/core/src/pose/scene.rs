//! The scene side of every method: input checks, bin removal, and the one judge every pose
//! passes ([`DetectionScene::judge`], the depth test against the scan's height map).

use super::{PoseConfig, PoseModel};
use crate::error::{Error, Result};
use crate::geometry::{check_finite, BinBox, Plane, Point};
use crate::registration::ppf::PpfModel;
use crate::registration::verify::{depth_evidence, Evidence, HeightMap};
use crate::search::KdIndex;
use crate::segment::{could_hold_support_plane, crop_to_bin, point_spacing, remove_support_planes};
use crate::voxel::voxel_downsample;
use nalgebra::{Isometry3, Vector3};

pub(super) fn check_scene(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vector3<f64>> {
    check_finite("scene", scene)?;
    if scene.len() < 10 {
        return Err(Error::TooFewPoints {
            arg: "scene".into(),
            got: scene.len(),
            needed: 10,
            hint: "; pass the scan's points".into(),
        });
    }
    if !(cfg.up.norm() > 0.0) {
        return Err(Error::invalid("up", "must be a non-zero direction"));
    }
    let (lo, hi) = scene
        .iter()
        .fold((scene[0], scene[0]), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
    let extent = (hi - lo).norm();
    if extent < 0.2 * model.diameter {
        return Err(Error::invalid(
            "scene",
            format!(
                "the scene is {extent:.3} mm across but the model is {:.1} mm: is the scene in metres? Pass millimetres (multiply by 1000) or load the model with the scene's unit",
                model.diameter
            ),
        ));
    }
    Ok(cfg.up.normalize())
}

/// Scene indices inside the bin box (all without one), and — with `planes` and no box — without
/// the support planes wider than the part.
pub(super) fn remove_bin(scene: &[Point], model: &PoseModel, cfg: &PoseConfig, planes: bool) -> Result<Vec<usize>> {
    let kept: Vec<usize> = match &cfg.bin {
        Some(bin) => crop_to_bin(scene, bin, 1.0)?,
        None if planes && could_hold_support_plane(scene, model.diameter) => {
            let idx = KdIndex::new(scene);
            let tol = (2.0 * point_spacing(scene, &idx)).max(0.5);
            remove_support_planes(scene, model.diameter, tol, 1).0
        }
        None => (0..scene.len()).collect(),
    };
    if kept.len() < 10 {
        return Err(Error::NoObjectFound {
            reason: format!(
                "only {} points remain after removing the bin; the bin is empty",
                kept.len()
            ),
        });
    }
    Ok(kept)
}

/// The scene prepared for detection and judging.
pub(crate) struct DetectionScene {
    /// Voxel-grid points (mean of each voxel) and their KD-tree.
    pub fine: Vec<Point>,
    pub fine_index: KdIndex,
    /// The height map of the whole scene.
    pub heights: HeightMap,
    /// Depth-test and inlier tolerance, mm.
    pub tol: f64,
    /// Support surfaces no part can pass through: the bin's floor and walls (from the bin box),
    /// or the floor-like support planes removed without one; normals point to the free side.
    pub supports: Vec<Plane>,
}

/// Tolerance of the depth test and of inliers for a PPF step (mm): 0.12 of the step, not below
/// 1 mm (scan noise and the voxel means' bias on curved surfaces).
pub(super) fn tolerance(step: f64) -> f64 {
    (0.12 * step).max(1.0)
}

impl DetectionScene {
    /// Voxel grid and normals of `points` (the scene without the bin) for `ppf`, and the height
    /// map of the whole scene (the bin's floor is evidence too: surface predicted above a
    /// visible floor is surface where the sensor saw free space). Without a bin box, support
    /// planes wider than the part are removed from the voxel grid.
    pub fn new(
        scene_all: &[Point],
        points: &[Point],
        model: &PoseModel,
        ppf: &PpfModel,
        cfg: &PoseConfig,
    ) -> Result<Self> {
        let step = ppf.step();
        let voxel = (step / 3.0).max(0.5);
        let mut fine = voxel_downsample(points, None, voxel)?.points;
        let up = cfg.up.normalize();
        let mut supports = Vec::new();
        if let Some(bin) = &cfg.bin {
            supports = bin_walls(bin);
        } else if fine.len() >= 50 {
            let (keep, planes) = remove_support_planes(&fine, model.diameter, (0.5 * voxel).max(1.0), 1);
            fine = keep.iter().map(|&i| fine[i]).collect();
            supports = floors_below(&fine, planes, &up, tolerance(step));
        }
        if fine.len() < 10 {
            return Err(Error::NoObjectFound {
                reason: format!(
                    "only {} occupied {voxel:.1} mm voxels remain after removing the bin; the bin is empty",
                    fine.len()
                ),
            });
        }
        let fine_index = KdIndex::new(&fine);
        let heights = HeightMap::fitted(scene_all, &up, (0.5 * voxel).max(1.0));
        Ok(DetectionScene {
            fine,
            fine_index,
            heights,
            tol: tolerance(step),
            supports,
        })
    }

    /// Probe stride over the model's dense points for about `n` probes.
    pub(super) fn probe_step(model: &PoseModel, n: usize) -> usize {
        (model.target().points().len() / n.max(1)).max(1)
    }

    /// Judges a pose with the dense probe (about 2000 model points).
    pub fn judge(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Evidence {
        depth_evidence(
            model.target(),
            &self.heights,
            t_scene_model,
            Self::probe_step(model, 2000),
            self.tol,
            true,
        )
    }

    /// Whether the posed part stays on the free side of every support surface (a pose through
    /// the bin's floor or walls is no pose), within twice the tolerance for 2 % of its surface.
    pub(super) fn physically_possible(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> bool {
        if self.supports.is_empty() {
            return true;
        }
        let pts = model.target().points();
        let step = (pts.len() / 500).max(1);
        let inside = pts
            .iter()
            .step_by(step)
            .filter(|p| {
                let q = t_scene_model * *p;
                self.supports
                    .iter()
                    .any(|s| s.normal.dot(&q.coords) < s.offset - 2.0 * self.tol)
            })
            .count();
        (inside as f64) < 0.02 * pts.len().div_ceil(step) as f64
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
/// without the bin) with the scene above them (a bin's rim is a wide plane too, with parts
/// below), normals toward `up`.
fn floors_below(fine: &[Point], planes: Vec<Plane>, up: &Vector3<f64>, tol: f64) -> Vec<Plane> {
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
        .filter(|p| {
            fine.iter()
                .filter(|q| p.normal.dot(&q.coords) < p.offset - 2.0 * tol)
                .count()
                * 50
                < fine.len()
        })
        .collect()
}

/// Indices of `points` within `tol` of the posed model.
pub(super) fn scene_indices(
    points: &[Point],
    model: &PoseModel,
    t_scene_model: &Isometry3<f64>,
    tol: f64,
) -> Vec<usize> {
    let c = t_scene_model * model.symmetries.center;
    let reach = model.radius + tol;
    let t_model_scene = t_scene_model.inverse();
    points
        .iter()
        .enumerate()
        .filter(|(_, p)| (*p - c).norm_squared() <= reach * reach)
        .filter(|(_, p)| {
            let q = t_model_scene * *p;
            model
                .target()
                .search()
                .nearest_within(&[q.x, q.y, q.z], tol * tol)
                .is_some()
        })
        .map(|(i, _)| i)
        .collect()
}
