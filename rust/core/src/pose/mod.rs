//! The pose pipeline: bin removal → top-object segmentation → coarse pose (CCP or the paper's
//! centroid baseline) → ICP of the scene points onto the dense model → verification.
//!
//! Frames: ICP registers the object's scene points onto the model (as the paper does, Eq. 6),
//! giving `T_model_scene`; the result reports its inverse `T_scene_model` (model → scene). A
//! result is returned only when enough of the object's points lie on the posed model;
//! otherwise the pipeline answers `NoObjectFound` rather than a guess.
//!
//! # The room
//!
//! Floors, each importing only those below it (`layout_tests` checks that no module imports one
//! that imports it, and each floor only the floors below):
//!
//! | floor | module | what it holds |
//! |---|---|---|
//! | 5 | this file | [`estimate_poses`]: input checks, bin removal, the method run (`dispatch`), CCP beside PPF and the arbitration between them (`auto`) |
//! | 4 | [`ccp_path`] | the paper's path: top-object segmentation, CCP or the centroid baseline, coarse checks, ICP |
//! | 4 | [`ppf_path`] | point-pair-feature detection of every instance, its prepared scene ([`DetectionScene`]), ranking by pickability |
//! | 4 | [`trust`] | how sure each pose is ([`trust::trusted`]): near-symmetric alternatives weighed (`assess`), the fit against the scan's own noise (`fit`), the turns and slides the view leaves open (`unseen_turns`) |
//! | 3 | [`judge`] | the one [`Judge`] every method's pose passes, owning its thresholds; its checks as children: `depth`, `outline`, `continuation`, `extension` |
//! | 2 | [`scene`] | input checks, bin removal, the [`Context`] of one call every stage reads |
//! | 2 | [`surface`] | point-to-plane residuals against the dense model, robust σ, thinning |
//! | 1 | [`model`] | [`PoseModel`], the probes past its branch ends, its near-symmetric turns |
//! | 0 | [`types`] | plain data: [`PoseConfig`], [`PoseEstimate`], every params struct and result type |

mod ccp_path;
mod judge;
#[cfg(test)]
mod layout_tests;
mod model;
mod ppf_path;
mod scene;
mod surface;
#[cfg(test)]
mod tests;
mod trust;
mod types;

pub use model::{FreeMotion, PoseModel};
pub use types::{
    stage_totals, Alternative, CcpPathParams, CheckIcpParams, CoarseMethod, FeatureEvidence, FineIcpParams, FitQuality,
    PoseConfig, PoseEstimate, SensorModel, Timings, TrustParams, MAX_NOISE_MM,
};

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::registration::verify::inlier_stats;
use ccp_path::run;
use judge::Judge;
use nalgebra::Isometry3;
use ppf_path::{detect, DetectionScene};
use scene::{check_scene, remove_bin, scene_noise, Context};
use std::time::Instant;
use trust::trusted;

/// Estimates the pose of the top pickable object of `scene` (N×3, mm) against `model`: exactly
/// the first of [`estimate_poses`] for the same configuration (the search does not depend on
/// how many instances are asked for, up to [`SEARCH_INSTANCES`](types::SEARCH_INSTANCES)).
pub fn estimate_pose(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<PoseEstimate> {
    let mut all = estimate_poses(scene, model, cfg)?;
    Ok(all.swap_remove(0))
}

/// Estimates up to `cfg.max_instances` instances, most pickable first. CCP and the centroid
/// baseline find the top object only; PPF finds every instance it can confirm.
pub fn estimate_poses(scene: &[Point], model: &PoseModel, cfg: &PoseConfig) -> Result<Vec<PoseEstimate>> {
    cfg.validate()?;
    crate::parallel::with_threads(cfg.num_threads, || dispatch(scene, model, cfg, None, None))
}

/// [`estimate_poses`] searching only the points of `scene` where `exclude` is false (the parts a
/// cell has tried already), while the judge reads the whole scan: a point set aside is still a
/// surface the sensor saw, where no pose may put free space and under which a pose's surface is
/// hidden. Setting the points aside instead of removing them keeps a pose from placing what the
/// scan showed there (a part's hidden branch) where those points were.
pub fn estimate_poses_excluding(
    scene: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    exclude: &[bool],
) -> Result<Vec<PoseEstimate>> {
    cfg.validate()?;
    if exclude.len() != scene.len() {
        return Err(Error::invalid(
            "exclude",
            format!(
                "has {} entries but the scene has {} points: pass one flag per scene point",
                exclude.len(),
                scene.len()
            ),
        ));
    }
    crate::parallel::with_threads(cfg.num_threads, || dispatch(scene, model, cfg, None, Some(exclude)))
}

/// Judges a given pose `t_scene_model` of `model` in `scene` exactly as [`estimate_poses`] judges
/// the poses it finds (the one judge, then the trust stage: confidence, alternatives, fit), without
/// refining it; `NoObjectFound` says which test it fails. For a pose from elsewhere (another
/// system, a known placement), or to see what the judge makes of a ground truth.
pub fn verify_pose(
    scene: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    t_scene_model: &Isometry3<f64>,
) -> Result<PoseEstimate> {
    cfg.validate()?;
    if !(t_scene_model.translation.vector.iter().all(|v| v.is_finite())
        && t_scene_model.rotation.coords.iter().all(|v| v.is_finite()))
    {
        return Err(Error::invalid("T_scene_model", "must be a finite rigid transform"));
    }
    crate::parallel::with_threads(cfg.num_threads, || {
        dispatch(scene, model, cfg, Some(t_scene_model), None)
    })
    .map(|mut found| found.swap_remove(0))
}

/// The judge's tolerance (three standard deviations of the scan's depth noise) may be at most this
/// share of the part's diameter: beyond it the noise blurs the part's shape into its neighbours'
/// (a 5 mm noise on a 200 mm part is 0.075; uniform clutter reads as noise of tens of mm).
pub const MAX_TOLERANCE_SHARE: f64 = 0.15;

/// The method a model can run: `Auto` is PPF without a branch layout, CCP without a table.
fn resolve_method(method: CoarseMethod, model: &PoseModel) -> CoarseMethod {
    match (method, &model.layout, &model.ppf) {
        (CoarseMethod::Auto, None, _) => CoarseMethod::Ppf,
        (CoarseMethod::Auto, Some(_), None) => CoarseMethod::Ccp,
        (m, _, _) => m,
    }
}

/// The pipeline of one call: a search with the configured method, or (`given`) the verdict on a
/// pose; the search leaves out the points `exclude` flags (see [`estimate_poses_excluding`]).
fn dispatch(
    scene: &[Point],
    model: &PoseModel,
    cfg: &PoseConfig,
    given: Option<&Isometry3<f64>>,
    exclude: Option<&[bool]>,
) -> Result<Vec<PoseEstimate>> {
    let up = check_scene(scene, model, cfg)?;
    let method = match given {
        Some(_) => CoarseMethod::Given,
        None => resolve_method(cfg.method, model),
    };
    let clock = Instant::now();
    let view = Context::view_of(cfg, up);
    let facing = Context::facing_of(cfg, up);
    let noise = scene_noise(scene, cfg, view);
    let tol = types::NOISE_SIGMAS * noise;
    if tol > MAX_TOLERANCE_SHARE * model.diameter {
        return Err(Error::NoObjectFound {
            reason: format!(
                "the scan's depth noise (σ {noise:.2} mm{}) blurs it by ±{tol:.1} mm, more than {:.0} % of the part's {:.0} mm: no pose of it can be told from its neighbours; scan it closer or with a finer sensor",
                if cfg.sensor.noise_mm.is_some() { ", as declared" } else { ", read from the scan" },
                100.0 * MAX_TOLERANCE_SHARE,
                model.diameter
            ),
        });
    }
    let mut timings = vec![("noise", clock.elapsed().as_secs_f64() * 1e3)];
    // Bin removal: PPF removes support planes itself, on its voxel grid.
    let clock = Instant::now();
    let (kept, removed) = remove_bin(
        scene,
        model,
        cfg,
        matches!(method, CoarseMethod::Ccp | CoarseMethod::Centroid | CoarseMethod::Given),
        noise,
    )
    .and_then(|(kept, removed)| Ok((searched(kept, exclude)?, removed)))?;
    timings.push(("bin_removal", clock.elapsed().as_secs_f64() * 1e3));
    crate::cancel::check()?;
    let pts: Vec<Point> = kept.iter().map(|&i| scene[i]).collect();
    let ctx = Context {
        scene,
        kept: &kept,
        pts: &pts,
        model,
        cfg,
        up,
        view,
        facing,
        noise,
    };
    let (found, judge) = match method {
        CoarseMethod::Ccp | CoarseMethod::Centroid => {
            let judge = Judge::new(&ctx, &pts, removed);
            let e = run(&ctx, method, &judge, &mut timings)?;
            (vec![reindex(e, &kept)], judge)
        }
        CoarseMethod::Ppf => {
            let (found, prepared) = detect_instances(&ctx, &mut timings)?;
            (found, prepared.judge)
        }
        CoarseMethod::Auto => auto(&ctx, exclude, &mut timings)?,
        CoarseMethod::Given => {
            let judge = Judge::new(&ctx, &pts, removed);
            let t = given.ok_or_else(|| Error::invalid("method", "\"given\" is verify_pose's: pass the pose to it"))?;
            (vec![judged_as_given(&ctx, &judge, t)?], judge)
        }
    };
    let clock = Instant::now();
    crate::cancel::check()?;
    let found = trusted(found, &ctx, &judge)?;
    timings.push(("trust", clock.elapsed().as_secs_f64() * 1e3));
    crate::cancel::check()?;
    Ok(found
        .into_iter()
        .map(|e| PoseEstimate {
            timings: timings.clone(),
            ..e
        })
        .collect())
}

/// The points bin removal `kept` that the search may use: all of them, or those `exclude` does
/// not flag (`NoObjectFound` when fewer than ten are left).
fn searched(kept: Vec<usize>, exclude: Option<&[bool]>) -> Result<Vec<usize>> {
    let Some(exclude) = exclude else { return Ok(kept) };
    let left: Vec<usize> = kept.into_iter().filter(|&i| !exclude[i]).collect();
    if left.len() < 10 {
        return Err(Error::NoObjectFound {
            reason: format!(
                "only {} points of the bin are left to search once the excluded ones are set aside",
                left.len()
            ),
        });
    }
    Ok(left)
}

/// A given pose as the judge sees it, unrefined: `NoObjectFound` where it fails a test.
fn judged_as_given(ctx: &Context<'_>, judge: &Judge, t: &Isometry3<f64>) -> Result<PoseEstimate> {
    let (t, e) = judge.verdict(ctx.model, t)?;
    let t = ctx.model.symmetries.canonical(&t);
    let tol = judge.depth.tol;
    let indices = scene::scene_indices(ctx.pts, ctx.model, &t, tol);
    let claimed: Vec<Point> = indices.iter().map(|&i| ctx.pts[i]).collect();
    let (_, rmse) = inlier_stats(&claimed, ctx.model.target(), &t.inverse(), tol);
    let e = PoseEstimate::verified(CoarseMethod::Given, t, t, &e, (e.coverage(), rmse), 0, indices);
    Ok(reindex(e, ctx.kept))
}

/// Indices of the points a method saw (`kept` of the scene) become scene indices.
fn reindex(mut e: PoseEstimate, kept: &[usize]) -> PoseEstimate {
    e.indices = e.indices.iter().map(|&i| kept[i]).collect();
    e
}

/// PPF's instances with scene indices, and its prepared scene.
fn detect_instances(ctx: &Context<'_>, timings: &mut Timings) -> Result<(Vec<PoseEstimate>, DetectionScene)> {
    let ppf = ctx.model.ppf.as_ref().ok_or_else(|| {
        Error::invalid(
            "model",
            "PPF needs the model's feature table; prepare the model with PPF (binpick builds it on first use)",
        )
    })?;
    let (found, prepared) = detect(ctx, ppf, timings)?;
    Ok((found.into_iter().map(|e| reindex(e, ctx.kept)).collect(), prepared))
}

/// Regions CCP tries when it runs beside PPF's instances (auto with a branch layout): the top
/// object, the paper's reading. The regions below it lie among the instances PPF searched the
/// whole pile for; on the cell's piles trying up to eight cost 40–60 ms each, a third of the
/// pose stage, for a pose PPF had mostly found already.
pub const AUTO_CCP_REGIONS: usize = 1;

/// Auto with a branch layout: PPF over the pile and CCP on the top object (the next objects
/// down too when PPF finds nothing); the verified winner leads.
fn auto(ctx: &Context<'_>, exclude: Option<&[bool]>, timings: &mut Timings) -> Result<(Vec<PoseEstimate>, Judge)> {
    let detected = detect_instances(ctx, timings);
    let clock = Instant::now();
    let (ccp_kept, removed) = if ctx.cfg.bin.is_some() {
        (ctx.kept.to_vec(), Vec::new())
    } else {
        let (kept, removed) = remove_bin(ctx.scene, ctx.model, ctx.cfg, true, ctx.noise)?;
        (searched(kept, exclude)?, removed)
    };
    let ccp_pts: Vec<Point> = ccp_kept.iter().map(|&i| ctx.scene[i]).collect();
    // One judge for both paths: PPF's, when it prepared the scene; CCP's own only without it.
    let mut own: Option<Judge> = None;
    timings.push(("ccp_bin_removal", clock.elapsed().as_secs_f64() * 1e3));
    let mut ccp_timings = Vec::new();
    let by_ccp = {
        let judge = match &detected {
            Ok((_, prepared)) => &prepared.judge,
            Err(_) => own.get_or_insert_with(|| Judge::new(ctx, &ccp_pts, removed)),
        };
        // Beside PPF's instances CCP reads the top object only; alone it goes on down the pile.
        let mut ccp_cfg = ctx.cfg.clone();
        if detected.is_ok() {
            ccp_cfg.ccp_path.max_regions = ccp_cfg.ccp_path.max_regions.min(AUTO_CCP_REGIONS);
        }
        let ccp_ctx = Context {
            kept: &ccp_kept,
            pts: &ccp_pts,
            cfg: &ccp_cfg,
            ..*ctx
        };
        run(&ccp_ctx, CoarseMethod::Ccp, judge, &mut ccp_timings).map(|e| reindex(e, &ccp_kept))
    };
    timings.extend(ccp_timings.into_iter().map(|(name, ms)| (ccp_stage(name), ms)));
    match (detected, by_ccp) {
        (Ok((found, prepared)), Ok(c)) => {
            let found = arbitrate(found, c, &prepared, ctx.model, ctx.cfg.max_instances);
            Ok((found, prepared.judge))
        }
        (Ok((found, prepared)), Err(_)) => Ok((found, prepared.judge)),
        (Err(e), Ok(c)) => own.map(|judge| (vec![c], judge)).ok_or(e),
        (Err(e), Err(_)) => Err(e),
    }
}

/// The name of a CCP stage when it runs beside PPF.
fn ccp_stage(name: &'static str) -> &'static str {
    match name {
        "icp" => "ccp_icp",
        "coarse" => "ccp_coarse",
        "normals" => "ccp_normals",
        "segmentation" => "ccp_segmentation",
        "verification" => "ccp_verification",
        other => other,
    }
}

/// CCP's pose `c` leads when the one judge rates it above PPF's best; PPF's instances at its
/// place are then dropped, and it takes the pickability of the best that remains.
fn arbitrate(
    mut found: Vec<PoseEstimate>,
    mut c: PoseEstimate,
    prepared: &DetectionScene,
    model: &PoseModel,
    max_instances: usize,
) -> Vec<PoseEstimate> {
    let e = prepared.judge.depth.evidence(model, &c.t_scene_model);
    let first = prepared.judge.depth.evidence(model, &found[0].t_scene_model);
    if e.quality() > first.quality() {
        c.visible_fraction = Some(e.visible_fraction());
        c.occluded_fraction = Some(e.occluded_fraction());
        let gap = 0.5 * model.thickness;
        let cc = c.t_scene_model * model.symmetries.center;
        found.retain(|f| (f.t_scene_model * model.symmetries.center - cc).norm() > gap);
        c.pickability = found.first().and_then(|f| f.pickability);
        found.insert(0, c);
        found.truncate(max_instances.max(1));
    }
    found
}
