//! The one judge every method's pose passes, whatever found it (CCP, the centroid baseline,
//! PPF): the depth test against the scan's height map, a minimum of evidence relative to the
//! part's visible surface, and no pose through the bin's floor or walls or the removed support
//! planes.

use super::continuation::continuation;
use super::extension::{read_ends, MAX_CARRIED};
use super::model::{near_turns, PoseModel};
use super::outline::outline;
use super::scene::Context;
use super::types::PoseConfig;
use crate::error::{Error, Result};
use crate::geometry::{BinBox, Plane, Point};
use crate::registration::ppf::PpfConfig;
use crate::registration::verify::{depth_evidence, depth_evidence_with, Evidence, HeightMap};
use nalgebra::{Isometry3, Vector3};

/// Of the surface nothing else covers, the least share the scan must confirm: a pose that hangs
/// over cells without data (a part matched onto the faces of another shape) fails here.
const MIN_SUPPORTED: f64 = 0.5;
/// The least share of the surface the sensor should see that the scan must confirm.
const MIN_VISIBLE: f64 = 0.08;
/// The fewest confirmed probe points (of about 2000 over the whole part).
const MIN_SEEN: usize = 12;
/// Of the confirmed outline of a pose's sensor-facing faces, the most past which the scan's
/// surface may go on in the face's plane: more is a piece of a larger shape. A rod laid along a
/// longer cylinder continues past one of its two ends at least (half its facing outline); a
/// plate touching a neighbour edge to edge at one height, past one side of four (a quarter).
const MAX_CONTINUED: f64 = 0.4;
/// Of the cells confirming a pose, the most (as a share) that the scan's surface may run on
/// past the part in the tangent planes of its confirmed surface (see [`continuation`]). A plate
/// read on a tee's tilted run runs on over 0.35–2.5 times as many cells as confirm it; parts in
/// the near-symmetric bench's views and piles, at most 0.25 (they meet their neighbours at an
/// angle or a step). An elbow read on a tee's run and stem reaches 0.25 too: this test does not
/// tell it from a part; the extension test ([`super::extension`]) does where the scan shows the
/// run going on past the elbow's corner.
const MAX_BEYOND: f64 = 0.5;
/// The largest share of a pose's surface that may lie beyond the bin's floor or walls or the
/// removed support planes (more than twice the tolerance): a part rests on them, it does not
/// pass through them.
const MAX_THROUGH: f64 = 0.02;
/// The fewest confirmed outline cells for the outline test to decide.
const MIN_OUTLINE: usize = 4;
/// Probe points of the judge over the model's dense surface.
pub(super) const JUDGE_PROBES: usize = 2000;
/// Seen-through probes with at least this many seen-through neighbours within two probe
/// spacings lie inside a patch of them (on an even sampling a disc of that radius holds about
/// twelve probes; a strip along a silhouette, where cells straddle the edge, about four).
const PATCH_NEIGHBOURS: usize = 6;
/// The most probes inside seen-through patches a pose may have: a patch of the surface where
/// the sensor saw free space — a branch standing where the scan looks past it — is material
/// that is not there, whatever else the pose explains.
const MAX_PATCH_PROBES: usize = 8;

/// `part` over `whole`, 0 when `whole` is 0: the shares the outline and continuation tests decide on.
pub(super) fn share(part: usize, whole: usize) -> f64 {
    if whole == 0 {
        0.0
    } else {
        part as f64 / whole as f64
    }
}

/// The scene as the judge sees it.
pub(crate) struct Judge {
    /// The height map of the whole scene (the bin's floor is evidence too: surface predicted
    /// above a visible floor is surface where the sensor saw free space).
    pub heights: HeightMap,
    /// Depth-test and inlier tolerance, mm.
    pub tol: f64,
    /// Support surfaces no part can pass through: the bin's floor and walls (from the bin box),
    /// or the floor-like support planes removed without one; normals point to the free side.
    pub supports: Vec<Plane>,
}

/// The PPF step of `model` (its table's, or the default table's when it has none): the scale of
/// the judge's tolerance and height-map cells.
pub(super) fn judge_step(model: &PoseModel) -> f64 {
    model
        .ppf
        .as_ref()
        .map(|p| p.step())
        .unwrap_or(PpfConfig::default().sampling_ratio * model.diameter)
}

/// Tolerance of the depth test and of inliers for a PPF step (mm): 0.12 of the step, not below
/// 1 mm (scan noise and the voxel means' bias on curved surfaces).
pub(super) fn tolerance(step: f64) -> f64 {
    (0.12 * step).max(1.0)
}

/// Voxel size of the detection grid for a PPF step, mm.
pub(super) fn voxel_size(step: f64) -> f64 {
    (step / 3.0).max(0.5)
}

impl Judge {
    /// The judge of the context's whole scene for its model: `removed` are the support planes bin
    /// removal took out (unused with a bin box), `remaining` the points it kept.
    pub fn new(ctx: &Context<'_>, remaining: &[Point], removed: Vec<Plane>) -> Self {
        let step = judge_step(ctx.model);
        let tol = tolerance(step);
        let up = ctx.up;
        let supports = match &ctx.cfg.bin {
            Some(bin) => bin_walls(bin),
            None => floors_below(remaining, removed, &up, tol),
        };
        Judge {
            heights: HeightMap::fitted(ctx.scene, &up, (0.5 * voxel_size(step)).max(1.0)),
            tol,
            supports,
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

    /// Probe stride over the model's dense points for about `n` probes.
    pub(super) fn probe_step(model: &PoseModel, n: usize) -> usize {
        (model.target().points().len() / n.max(1)).max(1)
    }

    /// The depth test of a pose with the dense probe.
    pub fn evidence(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Evidence {
        depth_evidence(
            model.target(),
            &self.heights,
            t_scene_model,
            Self::probe_step(model, JUDGE_PROBES),
            self.tol,
            true,
        )
    }

    /// Seen-through probes of the posed model that lie inside a patch of them (see
    /// [`PATCH_NEIGHBOURS`]), counted only when there are enough to make one.
    fn seen_through_patch(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>, violated: usize) -> usize {
        if violated <= MAX_PATCH_PROBES {
            return 0;
        }
        let step = Self::probe_step(model, JUDGE_PROBES);
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
    pub(super) fn through_supports(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> f64 {
        if self.supports.is_empty() {
            return 0.0;
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
        inside as f64 / pts.len().div_ceil(step) as f64
    }

    /// The verdict on a pose: the pose [`Judge::accept`] keeps (it or a near-symmetric turn of
    /// it) and its evidence, otherwise `NoObjectFound` saying which test failed.
    pub fn verdict(
        &self,
        model: &PoseModel,
        t_scene_model: &Isometry3<f64>,
        cfg: &PoseConfig,
    ) -> Result<(Isometry3<f64>, Evidence)> {
        self.accept(self.evidence(model, t_scene_model), model, t_scene_model, cfg)
    }

    /// Whether a pose with depth evidence `e` is an instance: the scan confirms it wherever it
    /// can judge, it shows enough of its surface, not much of it hangs over cells without data
    /// and it passes through no support. The error says which test failed.
    pub fn check(
        &self,
        e: &Evidence,
        model: &PoseModel,
        t_scene_model: &Isometry3<f64>,
        cfg: &PoseConfig,
    ) -> Result<()> {
        let fail = |what: String| Err(Error::NoObjectFound { reason: what });
        let through = self.through_supports(model, t_scene_model);
        if through >= MAX_THROUGH {
            return fail(format!(
                "the best pose puts {:.0} % of the part through the bin's floor or walls",
                100.0 * through
            ));
        }
        if e.coverage() < cfg.min_coverage {
            return fail(format!(
                "the scan confirms only {:.0} % of the best pose's surface where it can judge it (need {:.0} %); the rest is where the sensor saw free space",
                100.0 * e.coverage(),
                100.0 * cfg.min_coverage
            ));
        }
        if e.seen < MIN_SEEN || e.visible_fraction() < MIN_VISIBLE {
            return fail(format!(
                "the scan shows only {:.0} % of the surface the best pose should show (need {:.0} %)",
                100.0 * e.visible_fraction(),
                100.0 * MIN_VISIBLE
            ));
        }
        if e.supported_fraction() < MIN_SUPPORTED {
            return fail(format!(
                "{:.0} % of the best pose's uncovered surface lies over cells the scan holds nothing in (need at most {:.0} %)",
                100.0 * (1.0 - e.supported_fraction()),
                100.0 * (1.0 - MIN_SUPPORTED)
            ));
        }
        let o = outline(self, model, t_scene_model);
        if o.counted >= MIN_OUTLINE && o.continued_fraction() > MAX_CONTINUED {
            return fail(format!(
                "past {:.0} % of the best pose's outline the scan's surface goes on (at most {:.0} %): it fits a piece of a larger shape, not the part",
                100.0 * o.continued_fraction(),
                100.0 * MAX_CONTINUED
            ));
        }
        let c = continuation(self, model, t_scene_model);
        if c.beyond_fraction() > MAX_BEYOND {
            return fail(format!(
                "the scan's surface runs on past the best pose in the tangent planes of its own surface, over {:.0} % as many cells as confirm the pose (at most {:.0} %): it fits a piece of a larger shape, not the part",
                100.0 * c.beyond_fraction(),
                100.0 * MAX_BEYOND
            ));
        }
        if let Some(end) = read_ends(self, model, t_scene_model)
            .into_iter()
            .find(|r| r.carried_on())
        {
            return fail(format!(
                "the scan carries a branch's cylinder on past its end, over {:.0} % as much surface as just inside the end (at most {:.0} %): it fits a piece of a larger fitting, not the part",
                100.0 * share(end.past, end.inside),
                100.0 * MAX_CARRIED
            ));
        }
        self.check_patch(e, model, t_scene_model)
    }

    /// The last test of [`Judge::check`]: no patch of the predicted surface where the sensor saw
    /// free space.
    fn check_patch(&self, e: &Evidence, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Result<()> {
        let patch = self.seen_through_patch(model, t_scene_model, e.violated);
        if patch > MAX_PATCH_PROBES {
            return Err(Error::NoObjectFound {
                reason: format!(
                    "the sensor saw through a patch of the surface the best pose predicts ({patch} probes inside it, at most {MAX_PATCH_PROBES}): material the pose puts where there is none"
                ),
            });
        }
        Ok(())
    }

    /// [`Judge::check`] of a pose with evidence `e`, and when only its last test fails (a patch of
    /// the predicted surface seen through), of its near-symmetric turns: a hypothesis that puts
    /// the part's feature where the scan shows free space (the boss of a block whose boss faces
    /// the floor, on top) is the right pose turned, which the trust stage then weighs. Returns
    /// the pose that passes, with its evidence.
    pub fn accept(
        &self,
        e: Evidence,
        model: &PoseModel,
        t_scene_model: &Isometry3<f64>,
        cfg: &PoseConfig,
    ) -> Result<(Isometry3<f64>, Evidence)> {
        let Err(refused) = self.check(&e, model, t_scene_model, cfg) else {
            return Ok((*t_scene_model, e));
        };
        if self.check_patch(&e, model, t_scene_model).is_ok() {
            return Err(refused); // an earlier test failed: a turn of the feature does not mend it
        }
        near_turns(model, &cfg.trust)
            .into_iter()
            .map(|(turn, _)| t_scene_model * turn)
            .find_map(|t| {
                let e = self.evidence(model, &t);
                self.check(&e, model, &t, cfg).is_ok().then_some((t, e))
            })
            .ok_or(refused)
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
fn floors_below(remaining: &[Point], planes: Vec<Plane>, up: &Vector3<f64>, tol: f64) -> Vec<Plane> {
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
            remaining
                .iter()
                .filter(|q| p.normal.dot(&q.coords) < p.offset - 2.0 * tol)
                .count()
                * 50
                < remaining.len()
        })
        .collect()
}
