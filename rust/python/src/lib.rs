//! `binpick._core`: the native module. Thin wrappers over binpick-core; every function copies
//! its numpy input into owned Rust data, releases the GIL for the work and catches panics.

mod convert;
mod errors;
mod geometry;
mod pose;
mod registration;
mod sim;
mod triangulate;

use pyo3::prelude::*;

/// Panics inside the guarded region; the tests use it to prove no panic reaches Python.
#[pyfunction]
fn _panic_for_test(py: Python<'_>) -> PyResult<()> {
    errors::run(py, || -> Result<(), binpick_core::Error> {
        panic!("deliberate test panic")
    })
}

/// How many native calls are still running, interrupted ones included (for the tests).
#[pyfunction]
fn _running_calls() -> usize {
    errors::running_calls()
}

#[pymodule]
fn _core(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(_panic_for_test, m)?)?;
    m.add_function(wrap_pyfunction!(_running_calls, m)?)?;
    geometry::register(m)?;
    registration::register(m)?;
    pose::register(m)?;
    triangulate::register(m)?;
    sim::register(m)?;
    Ok(())
}
