//! ICP bindings: a frozen [`IcpConfig`] in, an [`IcpResult`] out.

use crate::convert::{isometry_to_py, matrix4, points, threads, vectors};
use crate::errors::{run, to_py};
use binpick_core::{icp as core_icp, isometry_from_matrix, IcpMethod, IcpTarget, RobustKernel};
use numpy::{PyArray2, PyReadonlyArray2};
use pyo3::prelude::*;

/// ICP parameters (the core's `IcpConfig`); an argument left out takes the core's default.
#[pyclass(frozen, eq, module = "binpick._core")]
#[derive(PartialEq)]
pub struct IcpConfig {
    inner: binpick_core::IcpConfig,
}

#[pymethods]
impl IcpConfig {
    /// Keyword-only; `kernel_scale` defaults to a third of `max_correspondence_distance`.
    #[new]
    #[pyo3(signature = (*, method=None, max_correspondence_distance=None, max_iterations=None, rotation_tolerance=None, translation_tolerance=None, kernel=None, kernel_scale=None, trim_fraction=None, num_threads=None))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        method: Option<&str>,
        max_correspondence_distance: Option<f64>,
        max_iterations: Option<usize>,
        rotation_tolerance: Option<f64>,
        translation_tolerance: Option<f64>,
        kernel: Option<&str>,
        kernel_scale: Option<f64>,
        trim_fraction: Option<f64>,
        num_threads: Option<usize>,
    ) -> PyResult<Self> {
        let d = binpick_core::IcpConfig::default();
        let max_correspondence_distance = max_correspondence_distance.unwrap_or(d.max_correspondence_distance);
        let kernel = match kernel {
            Some(name) => RobustKernel::from_name(name, kernel_scale, max_correspondence_distance).map_err(to_py)?,
            None => d.kernel,
        };
        Ok(IcpConfig {
            inner: binpick_core::IcpConfig {
                method: method
                    .map(IcpMethod::from_name)
                    .transpose()
                    .map_err(to_py)?
                    .unwrap_or(d.method),
                max_correspondence_distance,
                max_iterations: max_iterations.unwrap_or(d.max_iterations),
                rotation_tolerance: rotation_tolerance.unwrap_or(d.rotation_tolerance),
                translation_tolerance: translation_tolerance.unwrap_or(d.translation_tolerance),
                kernel,
                trim_fraction: trim_fraction.unwrap_or(d.trim_fraction),
                num_threads: num_threads.map(threads).transpose()?.unwrap_or(d.num_threads),
                approximate: d.approximate,
            },
        })
    }

    /// `"point_to_point"` or `"point_to_plane"`.
    #[getter]
    fn method(&self) -> &'static str {
        self.inner.method.name()
    }
    /// Pairs farther apart are not correspondences, mm.
    #[getter]
    fn max_correspondence_distance(&self) -> f64 {
        self.inner.max_correspondence_distance
    }
    /// Upper bound on iterations.
    #[getter]
    fn max_iterations(&self) -> usize {
        self.inner.max_iterations
    }
    /// Stop when an update rotates less than this (rad)…
    #[getter]
    fn rotation_tolerance(&self) -> f64 {
        self.inner.rotation_tolerance
    }
    /// …and translates less than this (mm).
    #[getter]
    fn translation_tolerance(&self) -> f64 {
        self.inner.translation_tolerance
    }
    /// `"none"`, `"huber"`, `"tukey"` or `"cauchy"`.
    #[getter]
    fn kernel(&self) -> &'static str {
        self.inner.kernel.name()
    }
    /// The kernel's scale, mm (None without a kernel).
    #[getter]
    fn kernel_scale(&self) -> Option<f64> {
        self.inner.kernel.scale()
    }
    /// Fraction of the farthest pairs dropped each iteration.
    #[getter]
    fn trim_fraction(&self) -> f64 {
        self.inner.trim_fraction
    }
    /// Worker threads; 0 = all cores.
    #[getter]
    fn num_threads(&self) -> usize {
        self.inner.num_threads
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "IcpConfig(method='{}', max_correspondence_distance={:?}, max_iterations={}, rotation_tolerance={:?}, \
             translation_tolerance={:?}, kernel='{}', kernel_scale={}, trim_fraction={:?}, num_threads={})",
            c.method.name(),
            c.max_correspondence_distance,
            c.max_iterations,
            c.rotation_tolerance,
            c.translation_tolerance,
            c.kernel.name(),
            c.kernel.scale().map_or("None".into(), |k| format!("{k:?}")),
            c.trim_fraction,
            c.num_threads
        )
    }
}

/// The outcome of one ICP run (the core's `IcpResult`).
#[pyclass(frozen, module = "binpick._core")]
pub struct IcpResult {
    inner: binpick_core::IcpResult,
}

#[pymethods]
impl IcpResult {
    /// (4, 4) transform taking source points into the target frame.
    #[getter(T_target_source)]
    fn t_target_source<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        isometry_to_py(py, &self.inner.t_target_source)
    }
    /// The last update fell below both tolerances within `max_iterations`.
    #[getter]
    fn converged(&self) -> bool {
        self.inner.converged
    }
    /// Updates applied.
    #[getter]
    fn iterations(&self) -> usize {
        self.inner.iterations
    }
    /// Fraction of source points with a target point within the correspondence distance.
    #[getter]
    fn fitness(&self) -> f64 {
        self.inner.fitness
    }
    /// RMS distance of those pairs, mm.
    #[getter]
    fn rmse(&self) -> f64 {
        self.inner.rmse
    }
    /// Number of those pairs.
    #[getter]
    fn num_inliers(&self) -> usize {
        self.inner.num_inliers
    }

    fn __repr__(&self) -> String {
        format!(
            "IcpResult(converged={}, iterations={}, fitness={:.4}, rmse={:.4} mm, num_inliers={})",
            if self.inner.converged { "True" } else { "False" },
            self.inner.iterations,
            self.inner.fitness,
            self.inner.rmse,
            self.inner.num_inliers
        )
    }
}

/// Registers `source` onto `target` (normals needed for point-to-plane), starting from `init`.
#[pyfunction]
#[pyo3(signature = (source, target, target_normals, init, config))]
fn icp(
    py: Python<'_>,
    source: PyReadonlyArray2<'_, f64>,
    target: PyReadonlyArray2<'_, f64>,
    target_normals: Option<PyReadonlyArray2<'_, f64>>,
    init: PyReadonlyArray2<'_, f64>,
    config: &IcpConfig,
) -> PyResult<IcpResult> {
    let src = points(&source, "source")?;
    let tgt = points(&target, "target")?;
    let normals = target_normals
        .as_ref()
        .map(|n| vectors(n, "target_normals"))
        .transpose()?;
    let init_m = matrix4(&init, "init")?;
    let config = config.inner.clone();
    let res = run(py, move || {
        let init_t = isometry_from_matrix("init", &init_m)?;
        let target = IcpTarget::new(tgt, normals)?;
        core_icp(&src, &target, &init_t, &config)
    })?;
    Ok(IcpResult { inner: res })
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<IcpConfig>()?;
    m.add_class::<IcpResult>()?;
    m.add_function(wrap_pyfunction!(icp, m)?)?;
    Ok(())
}
