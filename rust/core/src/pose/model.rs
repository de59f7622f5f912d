//! [`PoseModel`]: a part prepared for pose estimation.

use crate::error::{Error, Result};
use crate::geometry::Point;
use crate::mesh::{sample_surface, Density, TriMesh};
use crate::registration::ccp::BranchLayout;
use crate::registration::ppf::{PpfConfig, PpfModel};
use crate::registration::IcpTarget;
use crate::search::KdIndex;
use crate::segment::point_spacing;
use crate::symmetry::{detect_all_symmetries, NearSymmetry, Symmetries, SymmetryConfig};
use crate::voxel::subsample;
use nalgebra::Vector3;

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
    /// With a branch layout: probes on and past each end of each branch (see [`super::extension`]).
    pub(crate) branch_ends: Vec<super::extension::BranchEnd>,
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
        let mut target = IcpTarget::new(points, Some(normals))?;
        if layout.is_some() {
            target = target.with_field(diameter / FIELD_CELLS, FIELD_MARGIN * diameter);
        }
        let branch_ends = match &layout {
            Some(layout) => super::extension::branch_ends(layout, spacing, &target),
            None => Vec::new(),
        };
        Ok(PoseModel {
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
                self.branch_ends = super::extension::branch_ends(layout, self.spacing, self.fine_target());
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
            let reach = super::ppf_path::SCREEN_REACH * ppf.step();
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
