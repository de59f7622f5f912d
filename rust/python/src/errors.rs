//! Mapping core errors and caught panics to the exception classes of `binpick.errors`.

use binpick_core::Error;
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::types::PyType;
use std::panic::{catch_unwind, AssertUnwindSafe};

fn exception(py: Python<'_>, class: &str, message: String) -> PyErr {
    let found = py
        .import("binpick.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
    match found {
        Ok(ty) => PyErr::from_type(ty, message),
        Err(_) => PyRuntimeError::new_err(format!("{class}: {message}")),
    }
}

/// The Python exception for a core error: the class named by its kind, its message.
pub fn to_py(err: Error) -> PyErr {
    Python::attach(|py| exception(py, err.kind(), err.to_string()))
}

/// An `InvalidInputError` naming the argument.
pub fn invalid(arg: &str, problem: &str) -> PyErr {
    to_py(Error::invalid(arg, problem))
}

/// Runs core work with the GIL released and any panic caught, so that no Rust panic ever
/// reaches Python: a panic becomes `binpick.errors.InternalError`.
pub fn run<T: Send>(py: Python<'_>, work: impl FnOnce() -> Result<T, Error> + Send) -> PyResult<T> {
    let outcome = py.detach(|| catch_unwind(AssertUnwindSafe(work)));
    match outcome {
        Ok(Ok(v)) => Ok(v),
        Ok(Err(e)) => Err(to_py(e)),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".into());
            Err(exception(py, "InternalError", format!("binpick's native core failed ({what}); this is a bug, please report it with the input that caused it")))
        }
    }
}
