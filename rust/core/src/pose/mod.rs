//! The pose pipeline: bin removal → top-object segmentation → coarse pose (CCP or the paper's
//! centroid baseline) → ICP of the scene points onto the dense model → verification.
//!
//! Frames: ICP registers the object's scene points onto the model (as the paper does, Eq. 6),
//! giving `T_model_scene`; the result reports its inverse `T_scene_model` (model → scene). A
//! result is returned only when enough of the object's points lie on the posed model;
//! otherwise the pipeline answers `NoObjectFound` rather than a guess.

mod ccp_path;
mod model;
mod ppf_path;
mod scene;
#[cfg(test)]
mod tests;
mod types;

pub use ccp_path::{CcpPathParams, CheckIcpParams, FineIcpParams};
pub use model::PoseModel;
pub use types::{CoarseMethod, PoseConfig, PoseEstimate};

use crate::error::{Error, Result};
use crate::geometry::Point;
use ccp_path::run;
use ppf_path::detect;
use scene::{check_scene, remove_bin};
use std::time::Instant;

/// Estimates the pose of the top pickable object of `scene` (N×3, mm) against `model`.
pub fn estimate_pose(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<PoseEstimate> {
    let one = PoseConfig {
        max_instances: 1,
        ..cfg.clone()
    };
    let mut all = estimate_poses(scene, model, &one)?;
    Ok(all.swap_remove(0))
}

/// Estimates up to `cfg.max_instances` instances, most pickable first. CCP and the centroid
/// baseline find the top object only; PPF finds every instance it can confirm.
pub fn estimate_poses(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vec<PoseEstimate>> {
    crate::parallel::with_threads(cfg.num_threads, || dispatch(scene, model, cfg))
}

fn dispatch(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vec<PoseEstimate>> {
    check_scene(scene, model, cfg)?;
    let method = match (cfg.method, &model.layout, &model.ppf) {
        (CoarseMethod::Auto, None, _) => CoarseMethod::Ppf,
        (CoarseMethod::Auto, Some(_), None) => CoarseMethod::Ccp,
        (m, _, _) => m,
    };
    // Bin removal: PPF removes support planes itself, on its voxel grid.
    let clock = Instant::now();
    let kept = remove_bin(
        scene,
        model,
        cfg,
        matches!(method, CoarseMethod::Ccp | CoarseMethod::Centroid),
    )?;
    let bin_ms = clock.elapsed().as_secs_f64() * 1e3;
    let pts: Vec<Point> = kept.iter().map(|&i| scene[i]).collect();
    // Indices of the points a method saw (`kept` of the scene) become scene indices.
    let reindex = |mut e: PoseEstimate, kept: &[usize]| {
        e.indices = e.indices.iter().map(|&i| kept[i]).collect();
        e
    };
    let with_timings = |found: Vec<PoseEstimate>, timings: &[(&'static str, f64)]| -> Vec<PoseEstimate> {
        let mut all = vec![("bin_removal", bin_ms)];
        all.extend_from_slice(timings);
        found
            .into_iter()
            .map(|e| PoseEstimate {
                timings: all.clone(),
                ..e
            })
            .collect()
    };
    match method {
        CoarseMethod::Ccp | CoarseMethod::Centroid => {
            let mut timings = Vec::new();
            let e = run(scene, &pts, model, cfg, method, &mut timings)?;
            Ok(with_timings(vec![reindex(e, &kept)], &timings))
        }
        CoarseMethod::Ppf | CoarseMethod::Auto => {
            let ppf = model.ppf.as_ref().ok_or_else(|| {
                Error::invalid(
                    "model",
                    "PPF needs the model's feature table; prepare the model with PPF (binpick builds it on first use)",
                )
            })?;
            let mut timings = Vec::new();
            let detected = detect(scene, &pts, model, ppf, cfg, &mut timings).map(|(found, prepared)| {
                (
                    found.into_iter().map(|e| reindex(e, &kept)).collect::<Vec<_>>(),
                    prepared,
                )
            });
            if method == CoarseMethod::Ppf {
                return Ok(with_timings(detected?.0, &timings));
            }
            // Auto with a branch layout: CCP on the top object too; the verified winner leads.
            let clock = Instant::now();
            let ccp_kept = if cfg.bin.is_some() {
                kept.clone()
            } else {
                remove_bin(scene, model, cfg, true)?
            };
            timings.push(("ccp_bin_removal", clock.elapsed().as_secs_f64() * 1e3));
            let ccp_pts: Vec<Point> = ccp_kept.iter().map(|&i| scene[i]).collect();
            let mut ccp_timings = Vec::new();
            let by_ccp =
                run(scene, &ccp_pts, model, cfg, CoarseMethod::Ccp, &mut ccp_timings).map(|e| reindex(e, &ccp_kept));
            for (name, ms) in ccp_timings {
                timings.push((
                    match name {
                        "icp" => "ccp_icp",
                        "coarse" => "ccp_coarse",
                        "normals" => "ccp_normals",
                        "segmentation" => "ccp_segmentation",
                        "verification" => "ccp_verification",
                        other => other,
                    },
                    ms,
                ));
            }
            match (detected, by_ccp) {
                (Ok((mut found, prepared)), Ok(mut c)) => {
                    let e = prepared.judge(model, &c.t_scene_model);
                    let first = prepared.judge(model, &found[0].t_scene_model);
                    c.visible_fraction = Some(e.visible_fraction());
                    c.occluded_fraction = Some(e.occluded_fraction());
                    if e.quality() > first.quality() {
                        let gap = 0.5 * model.thickness;
                        let cc = c.t_scene_model * model.symmetries.center;
                        found.retain(|f| (f.t_scene_model * model.symmetries.center - cc).norm() > gap);
                        c.pickability = found.first().and_then(|f| f.pickability);
                        found.insert(0, c);
                        found.truncate(cfg.max_instances.max(1));
                    }
                    Ok(with_timings(found, &timings))
                }
                (Ok((found, _)), Err(_)) => Ok(with_timings(found, &timings)),
                (Err(_), Ok(c)) => Ok(with_timings(vec![c], &timings)),
                (Err(e), Err(_)) => Err(e),
            }
        }
    }
}
