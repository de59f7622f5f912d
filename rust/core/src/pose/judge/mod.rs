//! The one judge every method's pose passes, whatever found it (CCP, the centroid baseline,
//! PPF): the depth test against the scan's height map, a minimum of evidence relative to the
//! part's visible surface, and no pose through the bin's floor or walls or the removed support
//! planes. Its checks are its children, each importing only [`depth`]:
//!
//! - [`depth`]: the depth test itself — what the scan confirms of a posed surface, the patches of
//!   it the sensor saw through, the share of it through a support — through which the other
//!   checks read the scan;
//! - [`mod@outline`], [`mod@continuation`], [`extension`]: a pose that fits a piece of a larger shape is
//!   refused where the scan's surface goes on past the edges of its sensor-facing faces, runs on
//!   in the tangent planes of its confirmed surface, or carries a declared branch's cylinder on
//!   past its end.
//!
//! The judge owns what it decides by: built once per call ([`Judge::new`]) from the context, it
//! takes no configuration afterwards.

pub(crate) mod continuation;
pub(crate) mod depth;
pub(crate) mod extension;
#[cfg(test)]
mod extension_tests;
pub(crate) mod outline;
#[cfg(test)]
mod outline_tests;

use crate::error::{Error, Result};
use crate::geometry::{Plane, Point};
use crate::pose::model::{near_turns, PoseModel};
use crate::pose::scene::Context;
use crate::registration::verify::Evidence;
use continuation::continuation;
use depth::{share, DepthTest, MAX_PATCH_PROBES};
use extension::{read_ends, MAX_CARRIED};
use nalgebra::Isometry3;
use outline::outline;

pub(crate) use depth::{probe_step, voxel_size};

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
/// past the part in the tangent planes of its confirmed surface (see [`continuation()`]). A plate
/// read on a tee's tilted run runs on over 0.35–2.5 times as many cells as confirm it; parts in
/// the near-symmetric bench's views and piles, at most 0.25 (they meet their neighbours at an
/// angle or a step). An elbow read on a tee's run and stem reaches 0.25 too: this test does not
/// tell it from a part; the extension test ([`extension`]) does where the scan shows the
/// run going on past the elbow's corner.
const MAX_BEYOND: f64 = 0.5;
/// The largest share of a pose's surface that may lie beyond the bin's floor or walls or the
/// removed support planes (more than twice the tolerance): a part rests on them, it does not
/// pass through them.
const MAX_THROUGH: f64 = 0.02;
/// The fewest confirmed outline cells for the outline test to decide.
const MIN_OUTLINE: usize = 4;

/// The one judge every method's pose passes: the depth test of the scan and the thresholds it
/// decides by, fixed when it is built.
pub(crate) struct Judge {
    /// The scan as the depth test reads it (height map, tolerance, supports).
    pub depth: DepthTest,
    /// The least share of the posed model's sensor-facing surface, where the scan can judge it,
    /// that the scan must confirm ([`crate::PoseConfig::min_coverage`]).
    pub min_coverage: f64,
    /// The near-symmetric turns (model frame) tried for a pose refused only for a patch of its
    /// surface the sensor saw through (see [`Judge::accept`]).
    near_turns: Vec<Isometry3<f64>>,
}

impl Judge {
    /// The judge of the context's whole scene for its model: `removed` are the support planes bin
    /// removal took out (unused with a bin box), `remaining` the points it kept. The thresholds
    /// come from the context's configuration, the turns from its model.
    pub fn new(ctx: &Context<'_>, remaining: &[Point], removed: Vec<Plane>) -> Self {
        Judge {
            depth: DepthTest::new(ctx, remaining, removed),
            min_coverage: ctx.cfg.min_coverage,
            near_turns: near_turns(ctx.model, &ctx.cfg.trust)
                .into_iter()
                .map(|(turn, _)| turn)
                .collect(),
        }
    }

    /// The verdict on a pose: the pose [`Judge::accept`] keeps (it or a near-symmetric turn of
    /// it) and its evidence, otherwise `NoObjectFound` saying which test failed.
    pub fn verdict(&self, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Result<(Isometry3<f64>, Evidence)> {
        self.accept(self.depth.evidence(model, t_scene_model), model, t_scene_model)
    }

    /// Whether a pose with depth evidence `e` is an instance: the scan confirms it wherever it
    /// can judge, it shows enough of its surface, not much of it hangs over cells without data
    /// and it passes through no support. The error says which test failed.
    pub fn check(&self, e: &Evidence, model: &PoseModel, t_scene_model: &Isometry3<f64>) -> Result<()> {
        let fail = |what: String| Err(Error::NoObjectFound { reason: what });
        let through = self.depth.through_supports(model, t_scene_model);
        if through >= MAX_THROUGH {
            return fail(format!(
                "the best pose puts {:.0} % of the part through the bin's floor or walls or a support surface the scan shows in front of it",
                100.0 * through
            ));
        }
        if e.coverage() < self.min_coverage {
            return fail(format!(
                "the scan confirms only {:.0} % of the best pose's surface where it can judge it (need {:.0} %); the rest is where the sensor saw free space",
                100.0 * e.coverage(),
                100.0 * self.min_coverage
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
        let o = outline(&self.depth, model, t_scene_model);
        if o.counted >= MIN_OUTLINE && o.continued_fraction() > MAX_CONTINUED {
            return fail(format!(
                "past {:.0} % of the best pose's outline the scan's surface goes on (at most {:.0} %): it fits a piece of a larger shape, not the part",
                100.0 * o.continued_fraction(),
                100.0 * MAX_CONTINUED
            ));
        }
        let c = continuation(&self.depth, model, t_scene_model);
        if c.beyond_fraction() > MAX_BEYOND {
            return fail(format!(
                "the scan's surface runs on past the best pose in the tangent planes of its own surface, over {:.0} % as many cells as confirm the pose (at most {:.0} %): it fits a piece of a larger shape, not the part",
                100.0 * c.beyond_fraction(),
                100.0 * MAX_BEYOND
            ));
        }
        if let Some(end) = read_ends(&self.depth, model, t_scene_model)
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
        let patch = self.depth.seen_through_patch(model, t_scene_model, e.violated);
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
    ) -> Result<(Isometry3<f64>, Evidence)> {
        let Err(refused) = self.check(&e, model, t_scene_model) else {
            return Ok((*t_scene_model, e));
        };
        // The pose puts material where the sensor saw free space, or into a support the part
        // rests on: with its feature turned the other way it may fit. Any other test failed: a
        // turn of the feature does not mend it.
        let misplaced = self.depth.through_supports(model, t_scene_model) >= MAX_THROUGH
            || self.check_patch(&e, model, t_scene_model).is_err();
        if !misplaced {
            return Err(refused);
        }
        self.near_turns
            .iter()
            .map(|turn| t_scene_model * turn)
            .find_map(|t| {
                let e = self.depth.evidence(model, &t);
                self.check(&e, model, &t).is_ok().then_some((t, e))
            })
            .ok_or(refused)
    }
}
