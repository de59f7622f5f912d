//! Pose-estimation bindings: a prepared model (built once per Model) and estimate_pose.

use crate::convert::{indices_to_py, isometry_to_py, points, vectors};
use crate::errors::{invalid, run};
use binpick_core::pose::{estimate_pose as core_estimate, CoarseMethod, PoseConfig, PoseModel};
use binpick_core::registration::ccp::{BranchLayout, CcpConfig};
use binpick_core::segment::BinBox;
use nalgebra::Vector3;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::sync::Arc;

/// A model prepared for pose estimation (its search structure built once).
#[pyclass(frozen, module = "binpick._core")]
pub struct PreparedModel {
    inner: Arc<PoseModel>,
}

#[pymethods]
impl PreparedModel {
    /// Prepares points (N,3), normals (N,3), diameter and area; `branches` rows are
    /// [dx, dy, dz, length, radius]; `special` the special feature's direction or None.
    #[new]
    #[pyo3(signature = (points_in, normals, diameter, area, branches, special))]
    fn new(
        py: Python<'_>,
        points_in: PyReadonlyArray2<'_, f64>,
        normals: PyReadonlyArray2<'_, f64>,
        diameter: f64,
        area: f64,
        branches: Option<PyReadonlyArray2<'_, f64>>,
        special: Option<PyReadonlyArray1<'_, f64>>,
    ) -> PyResult<Self> {
        let pts = points(&points_in, "model.points")?;
        let ns = vectors(&normals, "model.normals")?;
        let layout = match branches {
            Some(b) => {
                let a = b.as_array();
                if a.ncols() != 5 {
                    return Err(invalid("branches", "rows must be [dx, dy, dz, length, radius]"));
                }
                if a.nrows() == 0 {
                    None
                } else {
                    let special = match special {
                        Some(s) => {
                            let s = s.as_slice()?;
                            if s.len() != 3 {
                                return Err(invalid("special", "must be a 3-vector"));
                            }
                            Some(Vector3::new(s[0], s[1], s[2]).normalize())
                        }
                        None => None,
                    };
                    Some(BranchLayout {
                        directions: a.rows().into_iter().map(|r| Vector3::new(r[0], r[1], r[2]).normalize()).collect(),
                        lengths: a.rows().into_iter().map(|r| r[3]).collect(),
                        radius: a.rows().into_iter().map(|r| r[4]).fold(0.0, f64::max),
                        special,
                    })
                }
            }
            None => None,
        };
        let inner = run(py, move || PoseModel::new(pts, ns, diameter, area, layout))?;
        Ok(PreparedModel { inner: Arc::new(inner) })
    }
}

/// Estimates the top object's pose; returns a dict of the PoseResult fields.
#[pyfunction]
#[pyo3(signature = (scene, model, bin_box, up, method, d_star, min_points, max_normal_angle, inlier_distance, min_fitness, closer_radius, tau, num_threads))]
#[allow(clippy::too_many_arguments)]
fn estimate_pose<'py>(
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
) -> PyResult<Bound<'py, PyDict>> {
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
    let u = up.as_slice()?;
    if u.len() != 3 {
        return Err(invalid("up", "must be a 3-vector"));
    }
    let method = match method {
        "ccp" => CoarseMethod::Ccp,
        "centroid" => CoarseMethod::Centroid,
        other => return Err(invalid("method", &format!("unknown coarse method {other:?}; use \"ccp\" or \"centroid\""))),
    };
    let cfg = PoseConfig {
        bin,
        up: Vector3::new(u[0], u[1], u[2]),
        method,
        d_star,
        min_points,
        max_normal_angle,
        inlier_distance,
        min_fitness,
        ccp: CcpConfig { closer_radius, tau },
        num_threads,
    };
    let model = model.inner.clone();
    let est = run(py, move || core_estimate(&pts, &model, &cfg))?;
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
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PreparedModel>()?;
    m.add_function(wrap_pyfunction!(estimate_pose, m)?)?;
    Ok(())
}
