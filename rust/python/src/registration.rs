//! ICP bindings.

use crate::convert::{isometry_to_py, matrix4, points, vectors};
use crate::errors::{invalid, run};
use binpick_core::{icp as core_icp, isometry_from_matrix, IcpConfig, IcpMethod, IcpTarget, RobustKernel};
use numpy::PyReadonlyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// Registers `source` onto `target`; returns a dict of the IcpResult fields.
#[pyfunction]
#[pyo3(signature = (source, target, target_normals, init, method, max_correspondence_distance, max_iterations, rotation_tolerance, translation_tolerance, kernel, kernel_scale, trim_fraction, num_threads))]
#[allow(clippy::too_many_arguments)]
fn icp<'py>(
    py: Python<'py>,
    source: PyReadonlyArray2<'py, f64>,
    target: PyReadonlyArray2<'py, f64>,
    target_normals: Option<PyReadonlyArray2<'py, f64>>,
    init: PyReadonlyArray2<'py, f64>,
    method: &str,
    max_correspondence_distance: f64,
    max_iterations: usize,
    rotation_tolerance: f64,
    translation_tolerance: f64,
    kernel: &str,
    kernel_scale: f64,
    trim_fraction: f64,
    num_threads: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let src = points(&source, "source")?;
    let tgt = points(&target, "target")?;
    let normals = target_normals
        .as_ref()
        .map(|n| vectors(n, "target_normals"))
        .transpose()?;
    let init_m = matrix4(&init, "init")?;
    let method = match method {
        "point_to_point" => IcpMethod::PointToPoint,
        "point_to_plane" => IcpMethod::PointToPlane,
        other => {
            return Err(invalid(
                "method",
                &format!("unknown method {other:?}; use \"point_to_point\" or \"point_to_plane\""),
            ))
        }
    };
    let kernel = match kernel {
        "none" => RobustKernel::None,
        "huber" => RobustKernel::Huber(kernel_scale),
        "tukey" => RobustKernel::Tukey(kernel_scale),
        "cauchy" => RobustKernel::Cauchy(kernel_scale),
        other => {
            return Err(invalid(
                "kernel",
                &format!("unknown kernel {other:?}; use \"none\", \"huber\", \"tukey\" or \"cauchy\""),
            ))
        }
    };
    let config = IcpConfig {
        method,
        max_correspondence_distance,
        max_iterations,
        rotation_tolerance,
        translation_tolerance,
        kernel,
        trim_fraction,
        num_threads,
        approximate: false,
    };
    let res = run(py, move || {
        let init_t = isometry_from_matrix("init", &init_m)?;
        let target = IcpTarget::new(tgt, normals)?;
        core_icp(&src, &target, &init_t, &config)
    })?;
    let d = PyDict::new(py);
    d.set_item("T_target_source", isometry_to_py(py, &res.t_target_source))?;
    d.set_item("converged", res.converged)?;
    d.set_item("iterations", res.iterations)?;
    d.set_item("fitness", res.fitness)?;
    d.set_item("rmse", res.rmse)?;
    d.set_item("num_inliers", res.num_inliers)?;
    Ok(d)
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(icp, m)?)?;
    Ok(())
}
