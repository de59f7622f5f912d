//! [`PoseModel`]: a part prepared for pose estimation, and what the stages derive from the part
//! alone: the probes on and past its branch ends ([`BranchEnd`]) and the turns of its
//! near-symmetries ([`near_turns`]). A leaf: of the pose room it imports only the plain data types.

use super::types::TrustParams;
use crate::error::{Error, Result};
use crate::geometry::{eigen_ascending, Point};
use crate::mesh::{sample_surface, Density, TriMesh};
use crate::registration::ccp::BranchLayout;
use crate::registration::ppf::{PpfConfig, PpfModel};
use crate::registration::IcpTarget;
use crate::search::KdIndex;
use crate::segment::point_spacing;
use crate::symmetry::{detect_all_symmetries, NearSymmetry, Symmetries, SymmetryConfig};
use crate::voxel::subsample;
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::TAU;

/// The coarse checks' nearest field: cells of 1/64 of the part's diameter (coarser cells let
/// wrong readings of Table 3's case 6 win), over its box grown by 0.35 × the diameter (farther
/// than the coarse checks' correspondences reach for a densely sampled model).
const FIELD_CELLS: f64 = 64.0;
const FIELD_MARGIN: f64 = 0.35;
/// The PPF screen's nearest field, for a model without a branch layout (one with a layout keeps
/// the coarse checks' field, and its screen the exact search): cells of 1/256 of the diameter
/// (finer than the 1 mm samples of parts up to 250 mm, within the field's cell budget), over the
/// box grown by the screen's reach. The field's answer lies within about a cell diagonal of the
/// exact nearest sample, so the screen's few ICP steps land about where exact steps would; the
/// polish after it is exact. With cells of 1/64 a confident right pose of a keyed shaft in the
/// near-symmetric bench came back ambiguous.
pub(super) const SCREEN_FIELD_CELLS: f64 = 256.0;
/// The screen's correspondence reach in PPF steps. For a model without a branch layout its ICP
/// steps take their correspondences from the model's approximate nearest field
/// ([`crate::search::field::NearestField`], built out to this reach when the PPF table is
/// installed): a hypothesis a few degrees off needs wide exact searches, which took about a sixth
/// of a view's time (5.5–8.9 ms of the median of 40 single views of the near-symmetric bench;
/// 1.5–2.1 ms on the field). A model with a layout keeps the exact search: its field is the
/// coarse checks' (1/64 of the diameter), which answered a pile of tees differently and was not
/// measured for the screen.
pub(super) const SCREEN_REACH: f64 = 1.5;

/// A model prepared for pose estimation: dense points with normals and their search structure,
/// its symmetries and (once built) its point-pair-feature table.
pub struct PoseModel {
    pub(super) target: IcpTarget,
    /// Largest extent of the part, mm.
    pub diameter: f64,
    /// Surface area, mm².
    pub area: f64,
    /// Branch layout for CCP, if the part has one.
    pub layout: Option<BranchLayout>,
    /// Median spacing of the model's samples, mm.
    pub spacing: f64,
    /// The part's proper symmetries (about its surface centroid).
    pub symmetries: Symmetries,
    /// Rotations that map most of the surface onto itself without being symmetries, with the
    /// features that break them: the poses a scan must tell apart.
    pub near_symmetries: Vec<NearSymmetry>,
    /// Largest distance of a surface point from the symmetry centre, mm.
    pub radius: f64,
    /// Smallest extent of the part along its principal axes, mm.
    pub thickness: f64,
    /// The point-pair-feature table, once built or loaded.
    pub ppf: Option<PpfModel>,
    /// The mesh surface sampled densely, when the samples are much sparser than that: the final
    /// refinement and its verification run against it.
    pub surface: Option<IcpTarget>,
    /// With a branch layout: probes on and past each end of each branch (see [`BranchEnd`]).
    pub(crate) branch_ends: Vec<BranchEnd>,
    /// The motions the part's whole surface hardly constrains and that are no symmetry of it (a
    /// plate without edges slides in its plane and turns about its normal, a tube without ends
    /// slides along its axis): no scan can locate the part along them.
    pub degenerate: Vec<FreeMotion>,
}

/// A rigid motion of a part that its surface hardly constrains (model frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FreeMotion {
    /// A slide along a unit direction.
    Slide(Vector3<f64>),
    /// A turn about a unit axis through a point.
    Turn(Vector3<f64>, Point),
}

/// A motion is free when moving the part by a tenth of its size along it moves its surface off
/// itself by less than a hundredth of that size (root mean square over the surface): the
/// constraint's eigenvalue per sample, against the motion's size, is below this (0.1² · …).
const FREE_SHARE: f64 = 0.01;
/// Samples the degeneracy is judged on, at most.
const FREE_SAMPLES: usize = 4000;
/// A free turn is a symmetry (a surface of revolution) when this share of the samples turned by
/// [`REVOLUTION_TURN`] lies on the surface.
const REVOLUTION_SHARE: f64 = 0.98;
/// The turn (radians) a free turn is tried at.
const REVOLUTION_TURN: f64 = 0.5;

/// A free turn within about 10° of a continuous near-symmetry's axis is that near-symmetry.
const NEAR_AXIS_COS: f64 = 0.985;

/// The free motions of a surface sampled by `points` with `normals` (see [`PoseModel::degenerate`]),
/// `target` the samples' search structure and `spacing` their spacing. A turn about the axis of a
/// continuous near-symmetry (a shaft with a keyway) is not one: its feature decides it, which the
/// trust stage weighs.
fn free_motions(
    points: &[Point],
    normals: &[Vector3<f64>],
    target: &IcpTarget,
    spacing: f64,
    near: &[NearSymmetry],
) -> Vec<FreeMotion> {
    let stride = points.len().div_ceil(FREE_SAMPLES).max(1);
    let q: Vec<(Point, Vector3<f64>)> = points
        .iter()
        .zip(normals)
        .step_by(stride)
        .map(|(p, n)| (*p, *n))
        .collect();
    let n = q.len() as f64;
    if q.len() < 12 {
        return Vec::new();
    }
    let c = Constraints::of(&q);
    let mut free = Vec::new();
    let (values, vectors) = c.slides();
    for (v, d) in values.iter().zip(vectors) {
        if *v < FREE_SHARE * n {
            free.push(FreeMotion::Slide(d));
        }
    }
    let r2 = q
        .iter()
        .map(|(p, _)| (p.coords - c.centroid).norm_squared())
        .sum::<f64>()
        / n;
    let Some((values, vectors)) = c.turns() else {
        return free;
    };
    for (v, axis) in values.iter().zip(vectors) {
        let Some(at) = c.axis_point(&axis) else { continue };
        let near_axis = near
            .iter()
            .any(|s| s.angle.is_none() && s.axis.dot(&axis).abs() > NEAR_AXIS_COS);
        if *v >= FREE_SHARE * n * r2 || near_axis {
            continue;
        }
        let turn = Translation3::from(at.coords)
            * UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), REVOLUTION_TURN)
            * Translation3::from(-at.coords);
        let reach = 2.0 * spacing;
        let on = q
            .iter()
            .filter(|(p, _)| {
                let t = turn * p;
                target
                    .search()
                    .nearest_within(&[t.x, t.y, t.z], reach * reach)
                    .is_some()
            })
            .count();
        if (on as f64) < REVOLUTION_SHARE * n {
            free.push(FreeMotion::Turn(axis, at));
        }
    }
    free
}

impl PoseModel {
    /// Prepares a model from its surface samples (mm) and outward unit normals, and detects its
    /// symmetries.
    pub fn new(
        points: Vec<Point>,
        normals: Vec<Vector3<f64>>,
        diameter: f64,
        area: f64,
        layout: Option<BranchLayout>,
    ) -> Result<Self> {
        if !(diameter.is_finite() && diameter > 0.0) {
            return Err(Error::invalid("model", "the model's diameter must be positive"));
        }
        if let Some(layout) = &layout {
            layout.validate()?;
        }
        let spacing = point_spacing(&points, &KdIndex::new(&points));
        let (symmetries, near_symmetries) = detect_all_symmetries(&points, &normals, &SymmetryConfig::default())?;
        let c = symmetries.center;
        let radius = points.iter().map(|p| (p - c).norm()).fold(0.0, f64::max);
        let (_, cov) = crate::geometry::covariance(&points);
        let (_, axes) = crate::geometry::principal_axes(&cov);
        let thickness = axes
            .iter()
            .map(|a| {
                let (lo, hi) = points.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
                    let v = p.coords.dot(a);
                    (l.min(v), h.max(v))
                });
                hi - lo
            })
            .fold(f64::INFINITY, f64::min);
        // Only CCP's coarse checks use the nearest field: a model without branches does not pay for it.
        let mut target = IcpTarget::new(points, Some(normals))?.with_spacing(spacing);
        if layout.is_some() {
            target = target.with_field(diameter / FIELD_CELLS, FIELD_MARGIN * diameter);
        }
        let branch_ends = match &layout {
            Some(layout) => branch_ends(layout, spacing, &target),
            None => Vec::new(),
        };
        let degenerate = free_motions(
            target.points(),
            target.normals().unwrap_or(&[]),
            &target,
            spacing,
            &near_symmetries,
        );
        Ok(PoseModel {
            degenerate,
            branch_ends,
            target,
            diameter,
            area,
            layout,
            spacing,
            symmetries,
            near_symmetries,
            radius,
            thickness,
            ppf: None,
            surface: None,
        })
    }

    /// The dense model as an ICP target.
    pub fn target(&self) -> &IcpTarget {
        &self.target
    }

    /// What the final refinement registers onto: the dense mesh surface when there is one,
    /// the samples otherwise.
    pub fn fine_target(&self) -> &IcpTarget {
        self.surface.as_ref().unwrap_or(&self.target)
    }

    /// Gives a model whose samples are sparser than 1.5 × 1/100 of the mesh's bounding-box
    /// diagonal (a paper-style 300-point model cloud) a dense sampling of the mesh for the final
    /// refinement, so its accuracy no longer depends on how sparse the samples are. The mesh
    /// must be the samples' surface, in the same frame; one that is not (samples farther than
    /// two sample spacings from it) is ignored.
    pub fn with_surface_of(mut self, mesh: &TriMesh) -> Result<Self> {
        let (lo, hi) = mesh.bounds();
        let spacing = (hi - lo).norm() / 100.0;
        if !(self.spacing > 1.5 * spacing) {
            return Ok(self);
        }
        let s = sample_surface(mesh, Density::Spacing(spacing), 0)?;
        let surface = IcpTarget::new(s.points, Some(s.normals))?;
        let pts = self.target.points();
        let reach = 2.0 * self.spacing;
        let probes: Vec<&Point> = pts.iter().step_by(pts.len().div_ceil(64)).collect();
        let on = probes
            .iter()
            .filter(|p| {
                surface
                    .search()
                    .nearest_within(&[p.x, p.y, p.z], reach * reach)
                    .is_some()
            })
            .count();
        if on * 10 >= 9 * probes.len() {
            self.surface = Some(surface);
            // Past a branch's end is off the part by the surface, not by samples 5 mm apart.
            if let Some(layout) = &self.layout {
                self.branch_ends = branch_ends(layout, self.spacing, self.fine_target());
            }
        }
        Ok(self)
    }

    /// Builds the point-pair-feature table from an even subsample of the dense points.
    pub fn build_ppf(&mut self, config: PpfConfig) -> Result<()> {
        config.validate()?;
        let pts = self.target.points();
        let normals = self.target.normals().unwrap_or(&[]);
        let keep = subsample(pts, config.sampling_ratio * self.diameter);
        let ppf = PpfModel::new(
            keep.iter().map(|&i| pts[i]).collect(),
            keep.iter().map(|&i| normals[i]).collect(),
            self.diameter,
            config,
        )?;
        self.install_ppf(ppf);
        Ok(())
    }

    /// Installs a PPF table and, for a model without a branch layout, the screen's nearest field
    /// reaching as far as the screen's correspondences at the table's step.
    fn install_ppf(&mut self, ppf: PpfModel) {
        if self.screens_on_field() {
            let reach = SCREEN_REACH * ppf.step();
            self.target.set_field(self.diameter / SCREEN_FIELD_CELLS, reach);
        }
        self.ppf = Some(ppf);
    }

    /// Whether the PPF screen reads the model's nearest field (built for it with the table): a
    /// model without a branch layout; one with a layout keeps the exact search (its field is the
    /// coarse checks').
    pub(super) fn screens_on_field(&self) -> bool {
        self.layout.is_none()
    }

    /// Installs a table read from a cache; it must have been built for this model's diameter.
    pub fn set_ppf(&mut self, ppf: PpfModel) -> Result<()> {
        if (ppf.step() / ppf.config().sampling_ratio - self.diameter).abs() > 1e-6 * self.diameter {
            return Err(Error::invalid(
                "ppf_cache",
                "the cached table was built for another model; it will be rebuilt",
            ));
        }
        self.install_ppf(ppf);
        Ok(())
    }
}

/// Probes on and past one end of one branch (model frame): what the judge's extension test
/// reads the scan at.
#[derive(Debug, Clone, Default)]
pub(crate) struct BranchEnd {
    /// Probes on the branch's cylinder carried past the end, with their outward normals and
    /// their distance from the part's surface, mm.
    pub past: Vec<(Point, Vector3<f64>, f64)>,
    /// Probes on the branch's own surface over the same length inside the end.
    pub inside: Vec<(Point, Vector3<f64>)>,
    /// The surface each probe stands for, mm².
    pub probe_area: f64,
}

/// The probes of every branch end of `layout`: the tip (past the end face, one radius long) and
/// the back (through the junction, from one radius behind it to two, inside from one to two
/// radii out), on a grid of about `spacing` mm (at most a tenth of the radius), each past probe
/// with its distance from `surface` (the part's densest surface: its mesh's samples where the
/// model's own are sparse).
fn branch_ends(layout: &BranchLayout, spacing: f64, surface: &IcpTarget) -> Vec<BranchEnd> {
    let distance = |p: &Point| {
        surface
            .search()
            .nearest_within(&[p.x, p.y, p.z], f64::INFINITY)
            .map_or(f64::INFINITY, |(_, d)| d.sqrt())
    };
    let r = layout.radius;
    // About the samples' spacing, within a tenth and a fortieth of the radius: at most about
    // 250 × 40 probes per stretch whatever the samples or the declared radius.
    let step = spacing.clamp(r / 40.0, r / 10.0);
    let around = ((std::f64::consts::TAU * r / step).ceil() as usize).max(8);
    let along = ((r / step).ceil() as usize).max(2);
    let mut ends = Vec::new();
    for (u, &len) in layout.directions.iter().zip(&layout.lengths) {
        let u = u.normalize();
        let a = if u.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
        let e1 = u.cross(&a).normalize();
        let e2 = u.cross(&e1);
        let ring = |t: f64, out: &mut dyn FnMut(Point, Vector3<f64>)| {
            for k in 0..around {
                let phi = std::f64::consts::TAU * k as f64 / around as f64;
                let n = e1 * phi.cos() + e2 * phi.sin();
                out(Point::from(u * t + n * r), n);
            }
        };
        // (inside span, past span) along the axis: the tip and the back.
        for (inside, past) in [((len - r, len), (len, len + r)), ((r, 2.0 * r), (-2.0 * r, -r))] {
            let mut end = BranchEnd {
                probe_area: (std::f64::consts::TAU * r / around as f64) * (r / along as f64),
                ..BranchEnd::default()
            };
            for i in 0..along {
                let f = (i as f64 + 0.5) / along as f64;
                ring(inside.0 + f * (inside.1 - inside.0), &mut |p, n| {
                    end.inside.push((p, n))
                });
                ring(past.0 + f * (past.1 - past.0), &mut |p, n| {
                    end.past.push((p, n, distance(&p)))
                });
            }
            ends.push(end);
        }
    }
    ends
}

/// A near turn (model frame) and whether it is one of a continuous axis's.
pub(super) type Turn = (Isometry3<f64>, bool);

/// The turns (model frame; `true` for a continuous axis's) of one near-symmetry: its half turn,
/// or [`TrustParams::continuous_turns`] even turns about a continuous axis.
pub(super) fn turns_of(n: &NearSymmetry, p: &TrustParams) -> Vec<Turn> {
    match n.angle {
        Some(_) => vec![(n.transform(0.0), false)],
        None => {
            let k = p.continuous_turns.max(2);
            (1..k).map(|i| (n.transform(TAU * i as f64 / k as f64), true)).collect()
        }
    }
}

/// The turns of every near-symmetry of `model` (see [`turns_of`]).
pub(super) fn near_turns(model: &PoseModel, p: &TrustParams) -> Vec<Turn> {
    model.near_symmetries.iter().flat_map(|n| turns_of(n, p)).collect()
}

/// How surface samples with normals hold a rigid motion: the point-to-plane constraints of a small
/// turn ω about their centroid c and slide t, each sample's row J = [(p − c) × n; n]. A motion the
/// samples barely constrain (a small eigenvalue) moves their surface along itself: a cylinder
/// turns about and slides along its axis, a plane slides in itself and turns about its normal.
pub(crate) struct Constraints {
    /// The samples' centroid.
    pub centroid: Vector3<f64>,
    /// Σ (p − c) × n ((p − c) × n)ᵀ: turns alone.
    turn: Matrix3<f64>,
    /// Σ (p − c) × n nᵀ: turns against slides.
    mixed: Matrix3<f64>,
    /// Σ n nᵀ: slides alone.
    slide: Matrix3<f64>,
}

impl Constraints {
    /// The constraints of `q` (points with unit normals).
    pub fn of(q: &[(Point, Vector3<f64>)]) -> Self {
        let n = q.len().max(1) as f64;
        let centroid = q.iter().fold(Vector3::zeros(), |s, (p, _)| s + p.coords) / n;
        let (mut turn, mut mixed, mut slide) = (Matrix3::zeros(), Matrix3::zeros(), Matrix3::zeros());
        for (p, nrm) in q {
            let r = (p.coords - centroid).cross(nrm);
            turn += r * r.transpose();
            mixed += r * nrm.transpose();
            slide += nrm * nrm.transpose();
        }
        Constraints {
            centroid,
            turn,
            mixed,
            slide,
        }
    }

    /// The slides' constraint, weakest first: eigenvalues (per sample, summed) and unit directions.
    pub fn slides(&self) -> ([f64; 3], [Vector3<f64>; 3]) {
        eigen_ascending(self.slide)
    }

    /// The slides' constraint inverted, slightly regularised (a flat patch leaves some slides free).
    fn slide_inverse(&self) -> Option<Matrix3<f64>> {
        let reg = 1e-9 * self.slide.trace().max(1e-12);
        (self.slide + Matrix3::identity() * reg).try_inverse()
    }

    /// The turns' constraint with the slide that best accompanies each turn taken out (the Schur
    /// complement), weakest first: eigenvalues (mm² per sample, summed) and unit axes.
    pub fn turns(&self) -> Option<([f64; 3], [Vector3<f64>; 3])> {
        let cinv = self.slide_inverse()?;
        Some(eigen_ascending(self.turn - self.mixed * cinv * self.mixed.transpose()))
    }

    /// A point on the axis of the turn about `omega` with its best slide: the translation that
    /// accompanies a turn about an axis through the centroid moves the axis to where the turn
    /// keeps the surface on itself.
    pub fn axis_point(&self, omega: &Vector3<f64>) -> Option<Point> {
        let cinv = self.slide_inverse()?;
        let dt = -(cinv * self.mixed.transpose() * omega);
        Some(Point::from(self.centroid + omega.cross(&dt) / omega.norm_squared()))
    }
}
