//! Pose-estimation bindings: a prepared model (built once per Model) and estimate_poses.

use crate::convert::{indices_to_py, isometry_to_py, points, vectors};
use crate::errors::{invalid, run};
use crate::geometry::mesh_from_py;
use binpick_core::{estimate_poses as core_estimate, CoarseMethod, PoseConfig, PoseEstimate, PoseModel};
use binpick_core::{BinBox, BranchLayout, CcpConfig, CcpPathParams, DetectConfig, PpfConfig, PpfModel};
use nalgebra::{Point3, Vector3};
use numpy::{PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList};
use std::sync::Arc;

/// A model prepared for pose estimation (its search structures built once).
#[pyclass(frozen, module = "binpick._core")]
pub struct PreparedModel {
    inner: Arc<PoseModel>,
    /// Whether the PPF table came from the cache bytes passed in.
    ppf_from_cache: bool,
}

fn vector3(s: &[f64], arg: &str) -> PyResult<Vector3<f64>> {
    if s.len() != 3 {
        return Err(invalid(arg, "must be a 3-vector"));
    }
    Ok(Vector3::new(s[0], s[1], s[2]))
}

fn layout_from(
    branches: Option<PyReadonlyArray2<'_, f64>>,
    special: Option<PyReadonlyArray1<'_, f64>>,
) -> PyResult<Option<BranchLayout>> {
    let Some(b) = branches else { return Ok(None) };
    let a = b.as_array();
    if a.ncols() != 5 {
        return Err(invalid("branches", "rows must be [dx, dy, dz, length, radius]"));
    }
    if a.nrows() == 0 {
        return Ok(None);
    }
    let special = match special {
        Some(s) => Some(vector3(s.as_slice()?, "special")?.normalize()),
        None => None,
    };
    Ok(Some(BranchLayout {
        directions: a
            .rows()
            .into_iter()
            .map(|r| Vector3::new(r[0], r[1], r[2]).normalize())
            .collect(),
        lengths: a.rows().into_iter().map(|r| r[3]).collect(),
        radius: a.rows().into_iter().map(|r| r[4]).fold(0.0, f64::max),
        special,
    }))
}

#[pymethods]
impl PreparedModel {
    /// Prepares points (N,3), normals (N,3), diameter and area; `branches` rows are
    /// [dx, dy, dz, length, radius]; `special` the special feature's direction or None.
    /// `ppf` = (sampling_ratio, angle_bins, rotation_bins) builds the point-pair-feature table,
    /// or loads it from `ppf_cache` (bytes of `ppf_bytes()`) when those are valid for it.
    /// `mesh` = (vertices, faces) is the samples' surface: a model whose samples are sparse
    /// refines against a dense sampling of it.
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
        ppf: Option<(f64, u32, u32)>,
        ppf_cache: Option<Vec<u8>>,
        mesh: Option<(PyReadonlyArray2<'_, f64>, PyReadonlyArray2<'_, i64>)>,
    ) -> PyResult<Self> {
        let pts = points(&points_in, "model.points")?;
        let mesh = mesh.map(|(v, f)| mesh_from_py(&v, &f)).transpose()?;
        let ns = vectors(&normals, "model.normals")?;
        let layout = layout_from(branches, special)?;
        let (inner, from_cache) = run(py, move || {
            let mut m = PoseModel::new(pts, ns, diameter, area, layout)?;
            if let Some(mesh) = &mesh {
                m = m.with_surface_of(mesh)?;
            }
            let mut from_cache = false;
            if let Some((sampling_ratio, angle_bins, rotation_bins)) = ppf {
                let config = PpfConfig {
                    sampling_ratio,
                    angle_bins,
                    rotation_bins,
                };
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
        let rows: Vec<Vec<Vec<f64>>> = s
            .rotations
            .iter()
            .map(|q| {
                let m = q.to_rotation_matrix();
                (0..3).map(|r| (0..3).map(|c| m[(r, c)]).collect()).collect()
            })
            .collect();
        d.set_item("rotations", rows)?;
        Ok(d)
    }

    /// The canonical form of a pose (4,4) under the symmetries.
    fn canonical<'py>(
        &self,
        py: Python<'py>,
        t_scene_model: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = crate::convert::matrix4(&t_scene_model, "T_scene_model")?;
        let t = binpick_core::isometry_from_matrix("T_scene_model", &m).map_err(crate::errors::to_py)?;
        Ok(isometry_to_py(py, &self.inner.symmetries.canonical(&t)))
    }

    /// (rotation error rad, translation error mm) of `estimate` against `truth`, minimised over
    /// the symmetries.
    fn pose_error(
        &self,
        estimate: PyReadonlyArray2<'_, f64>,
        truth: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<(f64, f64)> {
        let a = binpick_core::isometry_from_matrix("estimate", &crate::convert::matrix4(&estimate, "estimate")?)
            .map_err(crate::errors::to_py)?;
        let b = binpick_core::isometry_from_matrix("truth", &crate::convert::matrix4(&truth, "truth")?)
            .map_err(crate::errors::to_py)?;
        Ok(self.inner.symmetries.pose_error(&a, &b))
    }
}

fn estimate_to_py<'py>(py: Python<'py>, est: &PoseEstimate) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("T_scene_model", isometry_to_py(py, &est.t_scene_model))?;
    d.set_item("T_scene_model_coarse", isometry_to_py(py, &est.t_scene_model_coarse))?;
    d.set_item("score", est.score)?;
    d.set_item("rmse", est.rmse)?;
    d.set_item("indices", indices_to_py(py, &est.indices))?;
    let t = PyDict::new(py);
    for (k, v) in &est.timings {
        t.set_item(*k, *v)?;
    }
    d.set_item("timings", t)?;
    d.set_item("iterations", est.iterations)?;
    d.set_item("method", est.method.name())?;
    // Python reads NaN where a fraction was not judged and 1.0 for an unranked pose.
    d.set_item("visible_fraction", est.visible_fraction.unwrap_or(f64::NAN))?;
    d.set_item("occluded_fraction", est.occluded_fraction.unwrap_or(f64::NAN))?;
    d.set_item("pickability", est.pickability.unwrap_or(1.0))?;
    Ok(d)
}

/// Estimates up to `max_instances` instances, most pickable first; returns a list of dicts of
/// the PoseResult fields.
#[pyfunction]
#[pyo3(signature = (scene, model, bin_box, up, method, d_star, min_points, max_normal_angle, inlier_distance, min_fitness, closer_radius, tau, num_threads, max_instances=1, viewpoint=None, reference_fraction=None, max_hypotheses=None, min_coverage=0.8))]
#[allow(clippy::too_many_arguments)]
fn estimate_poses<'py>(
    py: Python<'py>,
    scene: PyReadonlyArray2<'py, f64>,
    model: &PreparedModel,
    bin_box: Option<PyReadonlyArray2<'py, f64>>,
    up: PyReadonlyArray1<'py, f64>,
    method: &str,
    d_star: Option<f64>,
    min_points: Option<usize>,
    max_normal_angle: f64,
    inlier_distance: Option<f64>,
    min_fitness: f64,
    closer_radius: Option<f64>,
    tau: Option<f64>,
    num_threads: usize,
    max_instances: usize,
    viewpoint: Option<PyReadonlyArray1<'py, f64>>,
    reference_fraction: Option<f64>,
    max_hypotheses: Option<usize>,
    min_coverage: f64,
) -> PyResult<Bound<'py, PyList>> {
    let pts = points(&scene, "scene")?;
    let bin = match bin_box {
        Some(b) => {
            let c = points(&b, "bin")?;
            if c.len() != 2 {
                return Err(invalid("bin", "must be ((xmin, ymin, zmin), (xmax, ymax, zmax))"));
            }
            Some(BinBox { min: c[0], max: c[1] })
        }
        None => None,
    };
    let up = vector3(up.as_slice()?, "up")?;
    let viewpoint = match viewpoint {
        Some(v) => Some(Point3::from(vector3(v.as_slice()?, "viewpoint")?)),
        None => None,
    };
    let method = match method {
        "ccp" => CoarseMethod::Ccp,
        "centroid" => CoarseMethod::Centroid,
        "ppf" => CoarseMethod::Ppf,
        "auto" => CoarseMethod::Auto,
        other => {
            return Err(invalid(
                "method",
                &format!("unknown coarse method {other:?}; use \"auto\", \"ppf\", \"ccp\" or \"centroid\""),
            ))
        }
    };
    let defaults = DetectConfig::default();
    let detect = DetectConfig {
        reference_fraction: reference_fraction.unwrap_or(defaults.reference_fraction),
        max_hypotheses: max_hypotheses.unwrap_or(defaults.max_hypotheses),
        ..defaults
    };
    if !(detect.reference_fraction > 0.0 && detect.reference_fraction <= 1.0) {
        return Err(invalid("reference_fraction", "must be in (0, 1]"));
    }
    let cfg = PoseConfig {
        bin,
        up,
        method,
        d_star,
        min_points,
        max_normal_angle,
        inlier_distance,
        min_fitness,
        min_coverage,
        ccp: CcpConfig { closer_radius, tau },
        ccp_path: CcpPathParams::default(),
        detect,
        viewpoint,
        max_instances: max_instances.max(1),
        num_threads,
    };
    let model = model.inner.clone();
    let found = run(py, move || core_estimate(&pts, &model, &cfg))?;
    let out = PyList::empty(py);
    for est in &found {
        out.append(estimate_to_py(py, est)?)?;
    }
    Ok(out)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PreparedModel>()?;
    m.add_function(wrap_pyfunction!(estimate_poses, m)?)?;
    Ok(())
}
