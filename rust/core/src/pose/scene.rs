//! The scene side of every method: input checks, bin removal, the [`Context`] of one call that
//! every stage reads, and the scan points a pose explains. A leaf: of the pose room it imports
//! only the model and the plain data types.

use super::model::PoseModel;
use super::types::{PoseConfig, NOISE_SIGMAS};
use crate::error::{Error, Result};
use crate::geometry::{check_finite, Plane, Point};
use crate::normals::Orientation;
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
    /// Unit direction out of the bin, toward the sensor: `cfg.up` as [`check_scene`] checked and
    /// resolved it.
    pub up: Vector3<f64>,
    /// How the depth test looks at the scene: along the sensor's rays from its viewpoint when
    /// known (and `cfg.along_rays`), else along `up`.
    pub view: Orientation,
    /// Where the scan's normals face: the viewpoint when known, else `up`.
    pub facing: Orientation,
    /// The standard deviation of the scan's depth noise, mm: declared ([`crate::pose::types::SensorModel`],
    /// at the scan's median range) or read from the scan ([`crate::scan_noise`]); 0 where neither says.
    pub noise: f64,
}

impl Context<'_> {
    /// The depth test's view of a scene whose up is `up` (see [`Context::view`]).
    pub fn view_of(cfg: &PoseConfig, up: Vector3<f64>) -> Orientation {
        match cfg.viewpoint {
            Some(v) if cfg.along_rays => Orientation::TowardPoint(v),
            _ => Orientation::TowardDirection(up),
        }
    }

    /// Where the normals of a scene whose up is `up` face (see [`Context::facing`]).
    pub fn facing_of(cfg: &PoseConfig, up: Vector3<f64>) -> Orientation {
        match cfg.viewpoint {
            Some(v) => Orientation::TowardPoint(v),
            None => Orientation::TowardDirection(up),
        }
    }
}

/// The standard deviation of `scene`'s depth noise, mm, as `cfg.sensor` declares it or, without
/// a declaration, as the scan shows it (see [`Context::noise`]).
pub(super) fn scene_noise(scene: &[Point], cfg: &PoseConfig, view: Orientation) -> f64 {
    let range = cfg
        .viewpoint
        .and_then(|v| crate::geometry::median_range(scene, &v))
        .unwrap_or(0.0);
    cfg.sensor
        .sigma_at(range)
        .or_else(|| crate::scan_noise(scene, view))
        .unwrap_or(0.0)
}

/// Checks the scene against the model and the configuration's `up`; returns `up` normalised (or,
/// without one, resolved: see [`PoseConfig::up`]), the direction every stage reads.
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
    if let Some(up) = cfg.up {
        if !(up.norm() > 0.0 && up.iter().all(|v| v.is_finite())) {
            return Err(Error::invalid("up", "must be a finite non-zero direction"));
        }
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
    let centroid = crate::geometry::centroid(scene);
    if cfg.up.is_none() && cfg.viewpoint.is_none() && in_a_camera_frame(scene, &centroid) {
        return Err(Error::invalid(
            "viewpoint",
            "the scene lies in front of the origin along +z, as in a depth camera's own frame (+z away from the camera), where +z is not up: say where the sensor is, viewpoint=(0, 0, 0) for the camera's frame (binpick estimate --camera-frame), or that +z is up after all with up=(0, 0, 1)",
        ));
    }
    let toward_sensor = cfg.viewpoint.map(|v| v - centroid);
    let up = match (cfg.up, toward_sensor) {
        (Some(up), Some(v)) if up.dot(&v) <= 0.0 => Err(Error::invalid(
            "up",
            format!(
                "points away from the sensor at the viewpoint ({:.0}, {:.0}, {:.0}) mm: the bin's up must face the sensor that sees into it; in the camera's own frame (+z away from the camera) leave up out",
                v.x + centroid.x,
                v.y + centroid.y,
                v.z + centroid.z
            ),
        )),
        (Some(up), _) => Ok(up.normalize()),
        // A sensor looks into the bin from above: a viewpoint more than about 80° off +z says the
        // scene is in the sensor's own frame, where "up" is toward the sensor.
        (None, Some(v)) if !(v.z > UP_FROM_VIEW_COS * v.norm()) => Ok(v.try_normalize(1e-9).unwrap_or(Vector3::z())),
        (None, _) => Ok(Vector3::z()),
    }?;
    // The bin box is axis-aligned with its floor at its lowest z: it means nothing in a frame
    // whose up is not +z (a scene in a camera's frame).
    if cfg.bin.is_some() && up.z < BIN_UP_COS {
        return Err(Error::invalid(
            "bin",
            format!(
                "the bin box has its floor at its lowest z, but the scene's up is ({:.2}, {:.2}, {:.2}) (a scene in a camera's frame?): transform the scene into a frame whose +z is up (the robot's base) for a bin box, or leave bin out",
                up.x, up.y, up.z
            ),
        ));
    }
    Ok(up)
}

/// A bin box needs the scene's up within 10° of +z (its floor's normal).
const BIN_UP_COS: f64 = 0.985;

/// Whether `scene` (with centroid `centroid`) looks like a cloud in a camera's own frame: every
/// point in front of the origin along +z within a field of view up to about 100° across, and the
/// scene centred on the optical axis (within about 17°). A cell's base frame has its floor near
/// z = 0, or its bin away from the base's axis.
fn in_a_camera_frame(scene: &[Point], centroid: &Point) -> bool {
    centroid.z > 0.0
        && centroid.x.hypot(centroid.y) <= CAMERA_AXIS_SHARE * centroid.z
        && scene
            .iter()
            .all(|p| p.z > 0.0 && p.x.abs().max(p.y.abs()) <= CAMERA_FIELD_SHARE * p.z)
}

/// See [`in_a_camera_frame`]: the largest tangent of the field of view's half angle, and of the
/// scene centroid's angle off the optical axis.
const CAMERA_FIELD_SHARE: f64 = 1.2;
const CAMERA_AXIS_SHARE: f64 = 0.3;

/// Without an `up`, scene +z is up when the direction from the scene to the viewpoint lies within
/// about 80° of it (a camera tilted up to 80° from vertical); otherwise the direction to the
/// viewpoint is.
const UP_FROM_VIEW_COS: f64 = 0.17;

/// Scene indices inside the bin box (all without one), and — with `planes` and no box — without
/// the support planes wider than the part, which are returned too. `noise` is the scan's depth
/// noise (mm): what lies within [`NOISE_SIGMAS`] of it from the bin's floor and walls, or a
/// support plane, is theirs.
pub(super) fn remove_bin(
    scene: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    planes: bool,
    noise: f64,
) -> Result<(Vec<usize>, Vec<Plane>)> {
    let band = NOISE_SIGMAS * noise;
    let (kept, removed): (Vec<usize>, Vec<Plane>) = match &cfg.bin {
        Some(bin) => (crop_to_bin(scene, bin, band.max(1.0))?, Vec::new()),
        None if planes && could_hold_support_plane(scene, model.diameter) => {
            let idx = KdIndex::new(scene);
            let tol = (2.0 * point_spacing(scene, &idx)).max(0.5).max(band);
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
