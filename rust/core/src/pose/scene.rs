//! The scene side of every method: input checks, bin removal, the [`Context`] of one call that
//! every stage reads, and the scan points a pose explains. A leaf: of the pose room it imports
//! only the model and the plain data types.

use super::model::PoseModel;
use super::types::PoseConfig;
use crate::error::{Error, Result};
use crate::geometry::{check_finite, Plane, Point};
use crate::search::KdIndex;
use crate::segment::{could_hold_support_plane, crop_to_bin, point_spacing, remove_support_planes};
use nalgebra::{Isometry3, Vector3};

/// One call's inputs as every stage reads them: the scan, the points bin removal kept, the
/// model, the configuration and the direction toward the sensor that [`check_scene`] checked.
#[derive(Clone, Copy)]
pub(super) struct Context<'a> {
    /// The whole scan (N×3, mm): the judge's height map is built on all of it.
    pub scene: &'a [Point],
    /// Scene indices of the points the methods search (those bin removal kept) ...
    pub kept: &'a [usize],
    /// ... and those points.
    pub pts: &'a [Point],
    /// The part.
    pub model: &'a PoseModel,
    /// The configuration.
    pub cfg: &'a PoseConfig,
    /// Unit direction toward the sensor: `cfg.up` as [`check_scene`] checked and normalised it.
    pub up: Vector3<f64>,
}

/// Checks the scene against the model and the configuration's `up`; returns `up` normalised,
/// the direction every stage reads.
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
/// the support planes wider than the part, which are returned too.
pub(super) fn remove_bin(
    scene: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    planes: bool,
) -> Result<(Vec<usize>, Vec<Plane>)> {
    let (kept, removed): (Vec<usize>, Vec<Plane>) = match &cfg.bin {
        Some(bin) => (crop_to_bin(scene, bin, 1.0)?, Vec::new()),
        None if planes && could_hold_support_plane(scene, model.diameter) => {
            let idx = KdIndex::new(scene);
            let tol = (2.0 * point_spacing(scene, &idx)).max(0.5);
            remove_support_planes(scene, model.diameter, tol, 1)
        }
        None => ((0..scene.len()).collect(), Vec::new()),
    };
    if kept.len() < 10 {
        return Err(Error::NoObjectFound {
            reason: format!(
                "only {} points remain after removing the bin; the bin is empty",
                kept.len()
            ),
        });
    }
    Ok((kept, removed))
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
