//! Pose-estimation bindings: a prepared model (built once per Model), the frozen [`PpfParams`]
//! and [`PoseConfig`] in, [`PoseEstimate`]s out.

use crate::convert::{
    bin_box, bin_box_to_py, branch_layout, indices_to_py, isometry, isometry_to_py, matrix4, mesh_from_py,
};
use crate::convert::{points, points_to_py, real_number, rotations_to_rows, threads, vector3, vectors, whole_number};
use crate::errors::{run, to_py};
use binpick_core::{
    estimate_poses as core_estimate, estimate_poses_excluding, isometry_from_matrix, CcpConfig, CoarseMethod,
    DetectConfig, FreeMotion, SensorModel,
};
use binpick_core::{stage_totals, FeatureEvidence, FitQuality, PoseModel, PpfConfig, PpfModel};
use nalgebra::{Point3, Vector3};
use numpy::{PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArrayDyn};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::sync::Arc;

/// Largest bin count of a PPF feature accepted by [`PpfParams`] (the core checks its own range
/// when the table is built; this only keeps the conversion from overflowing).
const MAX_PPF_BINS: u32 = 1 << 16;

/// Parameters of a model's point-pair-feature table (the core's `PpfConfig`); an argument left
/// out takes the core's default.
#[pyclass(frozen, eq, module = "binpick._core")]
#[derive(PartialEq)]
pub struct PpfParams {
    inner: PpfConfig,
}

#[pymethods]
impl PpfParams {
    /// Keyword-only: `sampling_ratio` (model and scene sampling distance, and the distance step,
    /// as a fraction of the model's diameter), `angle_bins` (over [0, π]), `rotation_bins` (over
    /// a turn about the reference normal).
    #[new]
    #[pyo3(signature = (*, sampling_ratio=None, angle_bins=None, rotation_bins=None))]
    fn new(
        sampling_ratio: Option<&Bound<'_, PyAny>>,
        angle_bins: Option<&Bound<'_, PyAny>>,
        rotation_bins: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let d = PpfConfig::default();
        let bins = |v, arg, default: u32| -> PyResult<u32> {
            Ok(whole_number(v, arg, u64::from(MAX_PPF_BINS))?.map_or(default, |b| b as u32))
        };
        let inner = PpfConfig {
            sampling_ratio: real_number(sampling_ratio, "sampling_ratio")?.unwrap_or(d.sampling_ratio),
            angle_bins: bins(angle_bins, "angle_bins", d.angle_bins)?,
            rotation_bins: bins(rotation_bins, "rotation_bins", d.rotation_bins)?,
        };
        // Refused when built, not later when a model is prepared with them.
        inner.validate().map_err(to_py)?;
        Ok(PpfParams { inner })
    }
    /// Sampling distance as a fraction of the model's diameter.
    #[getter]
    fn sampling_ratio(&self) -> f64 {
        self.inner.sampling_ratio
    }
    /// Bins of each angle feature over [0, π].
    #[getter]
    fn angle_bins(&self) -> u32 {
        self.inner.angle_bins
    }
    /// Bins of the rotation about the reference normal over a turn.
    #[getter]
    fn rotation_bins(&self) -> u32 {
        self.inner.rotation_bins
    }
    fn __hash__(&self) -> u64 {
        let c = &self.inner;
        c.sampling_ratio.to_bits() ^ (u64::from(c.angle_bins) << 32) ^ u64::from(c.rotation_bins)
    }
    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "PpfParams(sampling_ratio={:?}, angle_bins={}, rotation_bins={})",
            c.sampling_ratio, c.angle_bins, c.rotation_bins
        )
    }
}

/// A model prepared for pose estimation (its search structures built once).
#[pyclass(frozen, module = "binpick._core")]
pub struct PreparedModel {
    inner: Arc<PoseModel>,
    /// Whether the PPF table came from the cache bytes passed in.
    ppf_from_cache: bool,
}

#[pymethods]
impl PreparedModel {
    /// Prepares points (N,3), normals (N,3), diameter and area; `branches` rows are
    /// [dx, dy, dz, length, radius]; `special` the special feature's direction or None.
    /// `ppf` builds the point-pair-feature table, or loads it from `ppf_cache` (bytes of
    /// `ppf_bytes()`) when those are valid for it. `mesh` = (vertices, faces) is the samples'
    /// surface: a model whose samples are sparse refines against a dense sampling of it.
    #[new]
    #[pyo3(signature = (points_in, normals, diameter, area, branches, special, ppf=None, ppf_cache=None, mesh=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        points_in: PyReadonlyArray2<'_, f64>,
        normals: PyReadonlyArray2<'_, f64>,
        diameter: f64,
        area: f64,
        branches: Option<PyReadonlyArray2<'_, f64>>,
        special: Option<PyReadonlyArray1<'_, f64>>,
        ppf: Option<&PpfParams>,
        ppf_cache: Option<Vec<u8>>,
        mesh: Option<(PyReadonlyArray2<'_, f64>, PyReadonlyArray2<'_, i64>)>,
    ) -> PyResult<Self> {
        let pts = points(&points_in, "model.points")?;
        let mesh = mesh.map(|(v, f)| mesh_from_py(&v, &f)).transpose()?;
        let ns = vectors(&normals, "model.normals")?;
        let layout = branch_layout(branches, special)?;
        let ppf = ppf.map(|p| p.inner);
        let (inner, from_cache) = run(py, move || {
            let mut m = PoseModel::new(pts, ns, diameter, area, layout)?;
            if let Some(mesh) = &mesh {
                m = m.with_surface_of(mesh)?;
            }
            let mut from_cache = false;
            if let Some(config) = ppf {
                let cached = ppf_cache
                    .and_then(|b| PpfModel::from_bytes(&b).ok())
                    .filter(|t| t.config() == &config);
                match cached.map(|t| m.set_ppf(t)) {
                    Some(Ok(())) => from_cache = true,
                    _ => m.build_ppf(config)?,
                }
            }
            Ok((m, from_cache))
        })?;
        Ok(PreparedModel {
            inner: Arc::new(inner),
            ppf_from_cache: from_cache,
        })
    }

    /// The PPF table as bytes (for the cache on disk), or None when it was not built.
    fn ppf_bytes<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyBytes>> {
        self.inner.ppf.as_ref().map(|t| PyBytes::new(py, &t.to_bytes()))
    }

    /// Whether the PPF table was loaded from the cache bytes given to the constructor.
    fn ppf_from_cache(&self) -> bool {
        self.ppf_from_cache
    }

    /// Number of model pairs in the PPF table (0 without one).
    fn ppf_pairs(&self) -> usize {
        self.inner.ppf.as_ref().map_or(0, |t| t.pair_count())
    }

    /// The detected symmetries: dict with `center` (3,), `continuous_axis` (3,) or None, and
    /// `rotations` (K, 3, 3), identity first.
    fn symmetries<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = &self.inner.symmetries;
        let d = PyDict::new(py);
        d.set_item("center", s.center.coords.as_slice().to_vec())?;
        d.set_item("continuous_axis", s.continuous_axis.map(|a| a.as_slice().to_vec()))?;
        d.set_item("rotations", rotations_to_rows(&s.rotations))?;
        Ok(d)
    }

    /// The motions the part's surface hardly constrains and that are no symmetry of it: dicts with
    /// `kind` ("slide" or "turn"), `axis` (3,) and, for a turn, `point` (3,) on its axis.
    fn degenerate<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .degenerate
            .iter()
            .map(|m| {
                let d = PyDict::new(py);
                match m {
                    FreeMotion::Slide(a) => {
                        d.set_item("kind", "slide")?;
                        d.set_item("axis", a.as_slice().to_vec())?;
                        d.set_item("point", py.None())?;
                    }
                    FreeMotion::Turn(a, p) => {
                        d.set_item("kind", "turn")?;
                        d.set_item("axis", a.as_slice().to_vec())?;
                        d.set_item("point", p.coords.as_slice().to_vec())?;
                    }
                }
                Ok(d)
            })
            .collect()
    }

    /// The near-symmetries: dicts with `center` (3,), `axis` (3,), `angle` (radians, None for a
    /// continuous near axis), `agreement` and `feature` (M, 3), the model points that break it.
    fn near_symmetries<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .near_symmetries
            .iter()
            .map(|n| {
                let d = PyDict::new(py);
                d.set_item("center", n.center.coords.as_slice().to_vec())?;
                d.set_item("axis", n.axis.as_slice().to_vec())?;
                d.set_item("angle", n.angle)?;
                d.set_item("agreement", n.agreement)?;
                d.set_item("feature", points_to_py(py, &n.feature))?;
                Ok(d)
            })
            .collect()
    }

    /// The canonical form of a pose (4,4) under the symmetries.
    fn canonical<'py>(
        &self,
        py: Python<'py>,
        t_scene_model: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = matrix4(&t_scene_model, "T_scene_model")?;
        let t = isometry_from_matrix("T_scene_model", &m).map_err(to_py)?;
        Ok(isometry_to_py(py, &self.inner.symmetries.canonical(&t)))
    }
}

/// Parameters of pose estimation (the core's `PoseConfig`, with the CCP and PPF tunings the
/// Python API exposes); an argument left out, or None, takes the core's default. Values are
/// checked by the core when the estimate runs.
#[pyclass(frozen, module = "binpick._core")]
pub struct PoseConfig {
    inner: binpick_core::PoseConfig,
}

#[pymethods]
impl PoseConfig {
    /// Keyword-only; see `binpick.estimate_poses` for each argument.
    #[new]
    #[pyo3(signature = (*, bin=None, up=None, method=None, viewpoint=None, along_rays=None, light=None, noise_mm=None, noise_per_m2=None, d_star=None, min_points=None, max_normal_angle=None, inlier_distance=None, min_fitness=None, min_coverage=None, ccp_closer_radius=None, ccp_tau=None, reference_fraction=None, max_hypotheses=None, max_instances=None, search_instances=None, num_threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        bin: Option<PyReadonlyArrayDyn<'_, f64>>,
        up: Option<PyReadonlyArray1<'_, f64>>,
        method: Option<&str>,
        viewpoint: Option<PyReadonlyArray1<'_, f64>>,
        along_rays: Option<bool>,
        light: Option<PyReadonlyArray1<'_, f64>>,
        noise_mm: Option<f64>,
        noise_per_m2: Option<f64>,
        d_star: Option<f64>,
        min_points: Option<usize>,
        max_normal_angle: Option<f64>,
        inlier_distance: Option<f64>,
        min_fitness: Option<f64>,
        min_coverage: Option<f64>,
        ccp_closer_radius: Option<f64>,
        ccp_tau: Option<f64>,
        reference_fraction: Option<f64>,
        max_hypotheses: Option<usize>,
        max_instances: Option<usize>,
        search_instances: Option<usize>,
        num_threads: Option<usize>,
    ) -> PyResult<Self> {
        let d = binpick_core::PoseConfig::default();
        let detect = DetectConfig {
            reference_fraction: reference_fraction.unwrap_or(d.detect.reference_fraction),
            max_hypotheses: max_hypotheses.unwrap_or(d.detect.max_hypotheses),
            ..d.detect
        };
        let inner = binpick_core::PoseConfig {
            bin: bin.map(|b| bin_box(&b, "bin")).transpose()?.or(d.bin),
            up: up.map(|u| vector3(&u, "up")).transpose()?.or(d.up),
            method: method
                .map(CoarseMethod::from_name)
                .transpose()
                .map_err(to_py)?
                .unwrap_or(d.method),
            d_star: d_star.or(d.d_star),
            min_points: min_points.or(d.min_points),
            max_normal_angle: max_normal_angle.unwrap_or(d.max_normal_angle),
            inlier_distance: inlier_distance.or(d.inlier_distance),
            min_fitness: min_fitness.unwrap_or(d.min_fitness),
            min_coverage: min_coverage.unwrap_or(d.min_coverage),
            ccp: CcpConfig {
                closer_radius: ccp_closer_radius.or(d.ccp.closer_radius),
                tau: ccp_tau.or(d.ccp.tau),
            },
            ccp_path: d.ccp_path,
            detect,
            trust: d.trust,
            viewpoint: match viewpoint {
                Some(v) => Some(Point3::from(vector3(&v, "viewpoint")?)),
                None => d.viewpoint,
            },
            along_rays: along_rays.unwrap_or(d.along_rays),
            light: match light {
                Some(v) => Some(Point3::from(vector3(&v, "light")?)),
                None => d.light,
            },
            sensor: SensorModel {
                noise_mm: noise_mm.or(d.sensor.noise_mm),
                noise_per_m2: noise_per_m2.unwrap_or(d.sensor.noise_per_m2),
            },
            max_instances: max_instances.unwrap_or(d.max_instances),
            search_instances: search_instances.unwrap_or(d.search_instances),
            num_threads: num_threads.map(threads).transpose()?.unwrap_or(d.num_threads),
        };
        Ok(PoseConfig { inner })
    }

    /// The bin box ((xmin, ymin, zmin), (xmax, ymax, zmax)), mm, or None.
    #[getter]
    fn bin<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner.bin.as_ref().map(|b| bin_box_to_py(py, b))
    }
    /// What is up in the bin (toward the sensor), or None: +z, or toward a viewpoint more than 80° off +z.
    #[getter]
    fn up(&self) -> Option<(f64, f64, f64)> {
        self.inner.up.map(|u| triple(&u))
    }
    /// With a viewpoint: whether the depth test looks along the sensor's rays (else along up).
    #[getter]
    fn along_rays(&self) -> bool {
        self.inner.along_rays
    }
    /// The sensor's depth noise σ, mm, or None: read from the scan.
    #[getter]
    fn noise_mm(&self) -> Option<f64> {
        self.inner.sensor.noise_mm
    }
    /// Growth of the noise with range, mm per m² (σ(r) = noise_mm + noise_per_m2 · r²).
    #[getter]
    fn noise_per_m2(&self) -> f64 {
        self.inner.sensor.noise_per_m2
    }
    /// `"auto"`, `"ppf"`, `"ccp"` or `"centroid"`.
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method.name()
    }
    /// The sensor's position in the scene frame, mm, or None.
    #[getter]
    fn viewpoint(&self) -> Option<(f64, f64, f64)> {
        self.inner.viewpoint.map(|p| triple(&p.coords))
    }
    /// Where the scan's light came from in the scene frame, mm, or None.
    #[getter]
    fn light(&self) -> Option<(f64, f64, f64)> {
        self.inner.light.map(|p| triple(&p.coords))
    }
    /// d* of segmentation, mm (None: derived from the scan).
    #[getter]
    fn d_star(&self) -> Option<f64> {
        self.inner.d_star
    }
    /// Smallest object region, points (None: derived from the scan and the model).
    #[getter]
    fn min_points(&self) -> Option<usize> {
        self.inner.min_points
    }
    /// Largest angle between neighbouring normals inside one object, rad.
    #[getter]
    fn max_normal_angle(&self) -> f64 {
        self.inner.max_normal_angle
    }
    /// Inlier distance of verification, mm (None: derived from the samplings).
    #[getter]
    fn inlier_distance(&self) -> Option<f64> {
        self.inner.inlier_distance
    }
    /// CCP and centroid: smallest fraction of the object's points on the posed model.
    #[getter]
    fn min_fitness(&self) -> f64 {
        self.inner.min_fitness
    }
    /// PPF: smallest confirmed fraction of the posed model's judged sensor-facing surface.
    #[getter]
    fn min_coverage(&self) -> f64 {
        self.inner.min_coverage
    }
    /// CCP's s of Eq. 21, mm (None: from the branch radius).
    #[getter]
    fn ccp_closer_radius(&self) -> Option<f64> {
        self.inner.ccp.closer_radius
    }
    /// CCP's τ of Eq. 25, mm (None: from the shortest branch).
    #[getter]
    fn ccp_tau(&self) -> Option<f64> {
        self.inner.ccp.tau
    }
    /// PPF: fraction of the scene samples that vote.
    #[getter]
    fn reference_fraction(&self) -> f64 {
        self.inner.detect.reference_fraction
    }
    /// PPF: pose clusters refined.
    #[getter]
    fn max_hypotheses(&self) -> usize {
        self.inner.detect.max_hypotheses
    }
    /// Instances returned.
    #[getter]
    fn max_instances(&self) -> usize {
        self.inner.max_instances
    }
    /// PPF: instances the search is sized for, at least.
    #[getter]
    fn search_instances(&self) -> usize {
        self.inner.search_instances
    }
    /// Worker threads; 0 = all cores.
    #[getter]
    fn num_threads(&self) -> usize {
        self.inner.num_threads
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        let bin = c
            .bin
            .map(|b| format!("({:?}, {:?})", triple(&b.min.coords), triple(&b.max.coords)));
        format!(
            "PoseConfig(bin={}, up={}, method='{}', viewpoint={}, noise_mm={}, noise_per_m2={:?}, d_star={}, min_points={}, max_normal_angle={:?}, \
             inlier_distance={}, min_fitness={:?}, min_coverage={:?}, ccp_closer_radius={}, ccp_tau={}, \
             reference_fraction={:?}, max_hypotheses={}, max_instances={}, search_instances={}, num_threads={}, along_rays={})",
            bin.unwrap_or_else(|| "None".into()),
            c.up.map_or("None".into(), |u| format!("{:?}", triple(&u))),
            c.method.name(),
            c.viewpoint
                .map_or("None".into(), |p| format!("{:?}", triple(&p.coords))),
            or_none(c.sensor.noise_mm),
            c.sensor.noise_per_m2,
            or_none(c.d_star),
            or_none(c.min_points),
            c.max_normal_angle,
            or_none(c.inlier_distance),
            c.min_fitness,
            c.min_coverage,
            or_none(c.ccp.closer_radius),
            or_none(c.ccp.tau),
            c.detect.reference_fraction,
            c.detect.max_hypotheses,
            c.max_instances,
            c.search_instances,
            c.num_threads,
            if c.along_rays { "True" } else { "False" }
        )
    }
}

fn triple(v: &Vector3<f64>) -> (f64, f64, f64) {
    (v.x, v.y, v.z)
}

fn fit_to_py<'py>(py: Python<'py>, f: &FitQuality) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("residual_sigma_mm", f.residual_sigma)?;
    d.set_item("noise_floor_mm", f.noise_floor)?;
    d.set_item("ratio", f.ratio)?;
    d.set_item("factor", f.factor)?;
    Ok(d)
}

fn evidence_to_py<'py>(py: Python<'py>, e: &FeatureEvidence) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("fits", e.fits)?;
    d.set_item("misfits", e.misfits)?;
    d.set_item("seen_through", e.seen_through)?;
    d.set_item("tolerance", e.tolerance)?;
    d.set_item("score", e.score)?;
    Ok(d)
}

fn or_none<T: std::fmt::Debug>(v: Option<T>) -> String {
    v.map_or("None".into(), |v| format!("{v:?}"))
}

/// A verified pose (the core's `PoseEstimate`).
#[pyclass(frozen, module = "binpick._core")]
pub struct PoseEstimate {
    inner: binpick_core::PoseEstimate,
}

#[pymethods]
impl PoseEstimate {
    /// (4, 4) model (mesh) frame → scene frame.
    #[getter(T_scene_model)]
    fn t_scene_model<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        isometry_to_py(py, &self.inner.t_scene_model)
    }
    /// The coarse pose before ICP.
    #[getter(T_scene_model_coarse)]
    fn t_scene_model_coarse<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        isometry_to_py(py, &self.inner.t_scene_model_coarse)
    }
    /// Quality in [0, 1].
    #[getter]
    fn score(&self) -> f64 {
        self.inner.score
    }
    /// RMS distance of the inliers, mm.
    #[getter]
    fn rmse(&self) -> f64 {
        self.inner.rmse
    }
    /// Scene indices of the points on the posed model.
    #[getter]
    fn indices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        indices_to_py(py, &self.inner.indices)
    }
    /// Milliseconds per stage, in the order the stages first ran; a stage that ran more than
    /// once (CCP's, once per region it tried) reports its total.
    #[getter]
    fn timings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let t = PyDict::new(py);
        for (k, v) in stage_totals(&self.inner.timings) {
            t.set_item(k, v)?;
        }
        Ok(t)
    }
    /// ICP iterations of the refinement.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// The coarse method that found it.
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method.name()
    }
    /// Share of the sensor-facing surface the scan confirms, or None where not judged.
    #[getter]
    fn visible_fraction(&self) -> Option<f64> {
        self.inner.visible_fraction
    }
    /// Share of the sensor-facing surface under other objects, or None where not judged.
    #[getter]
    fn occluded_fraction(&self) -> Option<f64> {
        self.inner.occluded_fraction
    }
    /// Rank score among the instances found, or None when not ranked.
    #[getter]
    fn pickability(&self) -> Option<f64> {
        self.inner.pickability
    }
    /// In [0, 1]: how likely the pose is pick-grade.
    #[getter]
    fn confidence(&self) -> f64 {
        self.inner.confidence
    }
    /// In [0, 1]: how likely the pose or one of its alternatives is pick-grade.
    #[getter]
    fn confidence_any(&self) -> f64 {
        self.inner.confidence_any
    }
    /// Whether the scan cannot rule out a distinct alternative.
    #[getter]
    fn ambiguous(&self) -> bool {
        self.inner.ambiguous
    }
    /// The alternatives the scan cannot rule out: dicts with `T_scene_model` (4, 4) and
    /// `evidence` (a dict as `feature_evidence`).
    #[getter]
    fn alternatives<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.inner
            .alternatives
            .iter()
            .map(|a| {
                let d = PyDict::new(py);
                d.set_item("T_scene_model", isometry_to_py(py, &a.t_scene_model))?;
                d.set_item("evidence", evidence_to_py(py, &a.evidence)?)?;
                Ok(d)
            })
            .collect()
    }
    /// Unit axis (scene frame) of a continuous near-symmetry the scan cannot fix, or None.
    #[getter]
    fn free_axis(&self) -> Option<Vec<f64>> {
        self.inner.free_axis.map(|a| a.as_slice().to_vec())
    }
    /// The evidence in the feature regions of the pose kept, or None without near-symmetries.
    #[getter]
    fn feature_evidence<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner
            .feature_evidence
            .as_ref()
            .map(|e| evidence_to_py(py, e))
            .transpose()
    }

    /// How well the pose's points lie on the posed model against the scan's own noise: a dict
    /// (`residual_sigma_mm`, `noise_floor_mm`, `ratio`, `factor` — the factor in `confidence`),
    /// or None where too few points judge it.
    #[getter]
    fn fit<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        self.inner.fit.as_ref().map(|f| fit_to_py(py, f)).transpose()
    }

    fn __repr__(&self) -> String {
        let e = &self.inner;
        let t = e.t_scene_model.translation.vector;
        format!(
            "PoseEstimate(method='{}', score={:.3}, rmse={:.3} mm, points={}, t=[{:.2}, {:.2}, {:.2}] mm, pickability={}, confidence={:.2}, ambiguous={})",
            e.method.name(),
            e.score,
            e.rmse,
            e.indices.len(),
            t.x,
            t.y,
            t.z,
            or_none(e.pickability),
            e.confidence,
            if e.ambiguous { "True" } else { "False" }
        )
    }
}

/// Estimates up to `config.max_instances` instances, most pickable first; the search leaves out
/// the points `exclude` flags (one bool per point), which the judge still reads.
#[pyfunction]
#[pyo3(signature = (scene, model, config, exclude=None))]
fn estimate_poses(
    py: Python<'_>,
    scene: PyReadonlyArray2<'_, f64>,
    model: &PreparedModel,
    config: &PoseConfig,
    exclude: Option<PyReadonlyArray1<'_, bool>>,
) -> PyResult<Vec<PoseEstimate>> {
    let pts = points(&scene, "scene")?;
    let exclude: Option<Vec<bool>> = exclude.map(|e| e.as_array().iter().copied().collect());
    let cfg = config.inner.clone();
    let model = model.inner.clone();
    let found = run(py, move || match &exclude {
        Some(x) => estimate_poses_excluding(&pts, &model, &cfg, x),
        None => core_estimate(&pts, &model, &cfg),
    })?;
    Ok(found.into_iter().map(|inner| PoseEstimate { inner }).collect())
}

/// The verdict on a given pose `T_scene_model` (4×4), judged as found ones are.
#[pyfunction]
#[pyo3(name = "verify_pose")]
fn verify_pose_py(
    py: Python<'_>,
    scene: PyReadonlyArray2<'_, f64>,
    model: &PreparedModel,
    config: &PoseConfig,
    t_scene_model: PyReadonlyArray2<'_, f64>,
) -> PyResult<PoseEstimate> {
    let pts = points(&scene, "scene")?;
    let t = isometry(&t_scene_model, "T_scene_model")?;
    let cfg = config.inner.clone();
    let model = model.inner.clone();
    let inner = run(py, move || binpick_core::verify_pose(&pts, &model, &cfg, &t))?;
    Ok(PoseEstimate { inner })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PpfParams>()?;
    m.add_class::<PreparedModel>()?;
    m.add_class::<PoseConfig>()?;
    m.add_class::<PoseEstimate>()?;
    m.add_function(wrap_pyfunction!(estimate_poses, m)?)?;
    m.add_function(wrap_pyfunction!(verify_pose_py, m)?)?;
    m.add("MAX_NOISE_MM", binpick_core::MAX_NOISE_MM)?;
    Ok(())
}
