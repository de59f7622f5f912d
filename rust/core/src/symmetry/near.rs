//! Near-symmetries: rotations that map most of a part's surface onto itself without being
//! symmetries (a shaft whose keyway breaks its round, a plate with one cut corner, a tee whose
//! boss stands proud of the run), and the surface regions that break each one — the feature a
//! scan must show to tell the poses apart.
//!
//! They are the rotations (and a continuous axis) that the proper group lacks, one per class
//! modulo it, of two groups: the one found at the symmetry's agreement before a small feature
//! took some of its turns out of the proper group, and the one found at a lower agreement
//! ([`NEAR_AGREEMENT`]).

use super::matcher::Matcher;
use super::*;

/// A rotation is a near-symmetry when it maps at least this fraction of the surface onto itself
/// and is no symmetry (it maps less than [`SymmetryConfig::min_agreement`], or leaves a feature).
/// A flange's turn by one bolt pitch maps about 84 % of it when one locating hole breaks the
/// pattern: 0.8 keeps it.
pub const NEAR_AGREEMENT: f64 = 0.8;
/// Turns of a continuous near axis whose failures intersect to its feature, degrees.
const FEATURE_TURNS_DEG: [f64; 3] = [61.0, 131.0, 180.0];

/// A rotation about [`Symmetries::center`] that maps most of the surface onto itself, or a
/// continuous family of them about one axis.
#[derive(Debug, Clone, PartialEq)]
pub struct NearSymmetry {
    /// The point the axis passes through, model frame, mm (the centre of the group it came from:
    /// with a feature off-centre it is not the surface centroid).
    pub center: Point,
    /// Unit axis of the rotation, model frame.
    pub axis: Vector3<f64>,
    /// The turn, radians; `None` for a continuous near axis (every turn about it nearly maps).
    pub angle: Option<f64>,
    /// Fraction of the surface samples the rotation maps onto the surface (for a continuous
    /// axis, the least over a few turns).
    pub agreement: f64,
    /// Model-frame surface points that break it: the samples not mapped onto the surface by the
    /// turn or by its inverse (for a continuous axis, those no turn maps: the feature itself).
    pub feature: Vec<Point>,
}

impl NearSymmetry {
    /// The turn as a model-frame transform about [`NearSymmetry::center`]; for a continuous
    /// axis, the turn by `angle_if_continuous`.
    pub fn transform(&self, angle_if_continuous: f64) -> Isometry3<f64> {
        let r = rot(&self.axis, self.angle.unwrap_or(angle_if_continuous));
        Isometry3::from_parts(Translation3::from(self.center.coords - r * self.center.coords), r)
    }
}

/// The near-symmetries of a part from the same samples and normals as [`detect_symmetries`] and
/// its proper group `proper`: at most a few, strongest first. A part whose surface no rotation
/// maps at [`NEAR_AGREEMENT`] has none. (Detecting both at once,
/// [`super::detect_all_symmetries`] shares the search this repeats.)
pub fn detect_near_symmetries(
    points: &[Point],
    normals: &[Vector3<f64>],
    proper: &Symmetries,
    cfg: &SymmetryConfig,
) -> Result<Vec<NearSymmetry>> {
    let unit = super::unit_normals(points, normals, cfg)?;
    let lenient = Matcher::new(points, unit.clone(), cfg)?.detect();
    let groups = Groups {
        proper: proper.clone(),
        lenient: Some(lenient),
    };
    near_symmetries(points, unit, &groups, cfg)
}

/// The near-symmetries given the part's groups: the rotations the lenient group holds beyond the
/// proper one (each maps as much of the surface as a symmetry, but leaves a feature), then those
/// of the group found at [`NEAR_AGREEMENT`].
pub(super) fn near_symmetries(
    points: &[Point],
    unit: Vec<V3>,
    groups: &Groups,
    cfg: &SymmetryConfig,
) -> Result<Vec<NearSymmetry>> {
    let proper = &groups.proper;
    let near_cfg = SymmetryConfig {
        min_agreement: NEAR_AGREEMENT.min(cfg.min_agreement),
        ..*cfg
    };
    let matcher = Matcher::new(points, unit, &near_cfg)?;
    let mut found: Vec<NearSymmetry> = Vec::new();
    // One representative per class modulo the proper group, the identity's class left out.
    let mut classes: Vec<Rot> = proper.rotations.clone();
    let mut near_axis: Option<V3> = None;
    let near = matcher.detect();
    for group in groups.lenient.iter().chain(std::iter::once(&near)) {
        let c = group.center;
        if let (Some(a), None, None) = (group.continuous_axis, proper.continuous_axis, near_axis) {
            if let Some(n) = continuous(points, &matcher, &a, &c, cfg) {
                near_axis = Some(a);
                found.push(n);
            }
        }
        // A turn about a continuous near axis is that axis's, not one of its own.
        let spin = group
            .continuous_axis
            .filter(|_| proper.continuous_axis.is_none())
            .or(near_axis);
        for g in group.rotations.iter() {
            let known = classes
                .iter()
                .any(|k| proper.rotation_distance(k, g) < SAME_ROTATION.max(2f64.to_radians()));
            let along_near_axis = spin.is_some_and(|a| same_line(&g.axis().map_or(a, |u| *u), &a, SAME_AXIS));
            if known || along_near_axis {
                continue;
            }
            classes.push(*g);
            let mut fails = matcher.failures(g, &c);
            for (f, h) in fails.iter_mut().zip(matcher.failures(&g.inverse(), &c)) {
                *f |= h;
            }
            let agreement = 1.0 - fails.iter().filter(|&&f| f).count() as f64 / points.len() as f64;
            // The closure of the near turns holds products that map much less: not near ones. A
            // turn that maps as much as a symmetry is a near one when it leaves a feature (the
            // proper search refused it for that), else a symmetry that search missed: not near.
            let symmetry = agreement >= cfg.min_agreement && matcher.feature_free(g, &c);
            if agreement < NEAR_AGREEMENT || symmetry {
                continue;
            }
            if agreement >= cfg.min_agreement {
                // Near only for its feature, which may lie within the tolerance the agreement
                // counts at (it is sought at a finer one): the feature is what that check saw.
                for (f, p) in fails.iter_mut().zip(points) {
                    *f |= matcher.absent(g, &c, p, false);
                }
            }
            let (axis, angle) = g.axis_angle().map_or((V3::z(), 0.0), |(u, t)| (u.into_inner(), t));
            found.push(NearSymmetry {
                center: c,
                axis,
                angle: Some(angle),
                agreement,
                feature: select(points, &fails),
            });
        }
    }
    found.sort_by(|x, y| y.agreement.total_cmp(&x.agreement));
    Ok(found)
}

/// The continuous near axis `a` through `c`, when its turns map at least [`NEAR_AGREEMENT`] of
/// the surface and it is no symmetry (it maps less than one, or leaves a feature).
fn continuous(points: &[Point], matcher: &Matcher, a: &V3, c: &Point, cfg: &SymmetryConfig) -> Option<NearSymmetry> {
    let turns: Vec<Rot> = FEATURE_TURNS_DEG.iter().map(|d| rot(a, d.to_radians())).collect();
    let mut broken = vec![true; points.len()];
    let mut agreement = 1.0f64;
    for r in &turns {
        let fails = matcher.failures(r, c);
        agreement = agreement.min(1.0 - fails.iter().filter(|&&f| f).count() as f64 / points.len() as f64);
        for (b, f) in broken.iter_mut().zip(fails) {
            *b &= f;
        }
    }
    let near_only = agreement < cfg.min_agreement || !matcher.axis_feature_free(a, c);
    if agreement >= cfg.min_agreement && near_only {
        // As for a discrete turn: the feature is what the finer check saw.
        for (b, p) in broken.iter_mut().zip(points) {
            *b = *b || turns.iter().all(|r| matcher.absent(r, c, p, true));
        }
    }
    (agreement >= NEAR_AGREEMENT && near_only).then(|| NearSymmetry {
        center: *c,
        axis: a.normalize(),
        angle: None,
        agreement,
        feature: select(points, &broken),
    })
}

fn select(points: &[Point], mask: &[bool]) -> Vec<Point> {
    points.iter().zip(mask).filter(|(_, &m)| m).map(|(p, _)| *p).collect()
}
