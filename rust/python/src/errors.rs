//! Mapping core errors and caught panics to the exception classes of `binpick.errors`: one
//! exhaustive `match` over the core's error enum, so a new variant cannot go unmapped.

use binpick_core::Error;
use pyo3::prelude::*;
use std::panic::{catch_unwind, AssertUnwindSafe};

mod classes {
    pyo3::import_exception!(binpick.errors, InvalidInputError);
    pyo3::import_exception!(binpick.errors, NonFiniteError);
    pyo3::import_exception!(binpick.errors, TooFewPointsError);
    pyo3::import_exception!(binpick.errors, DegenerateCloudError);
    pyo3::import_exception!(binpick.errors, UnknownUnitError);
    pyo3::import_exception!(binpick.errors, MeshFileNotFoundError);
    pyo3::import_exception!(binpick.errors, MeshFileError);
    pyo3::import_exception!(binpick.errors, FileWriteError);
    pyo3::import_exception!(binpick.errors, NoObjectFound);
    pyo3::import_exception!(binpick.errors, InternalError);
}

/// The Python exception for a core error: its class of `binpick.errors`, its message.
pub fn to_py(err: Error) -> PyErr {
    let message = err.to_string();
    match err {
        Error::InvalidInput { .. } => classes::InvalidInputError::new_err(message),
        Error::NonFinite { .. } => classes::NonFiniteError::new_err(message),
        Error::TooFewPoints { .. } => classes::TooFewPointsError::new_err(message),
        Error::Degenerate { .. } => classes::DegenerateCloudError::new_err(message),
        Error::UnknownUnit { .. } => classes::UnknownUnitError::new_err(message),
        Error::FileNotFound { .. } => classes::MeshFileNotFoundError::new_err(message),
        Error::BadFile { .. } => classes::MeshFileError::new_err(message),
        Error::WriteFailed { .. } => classes::FileWriteError::new_err(message),
        Error::NoObjectFound { .. } => classes::NoObjectFound::new_err(message),
    }
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
            Err(classes::InternalError::new_err(format!(
                "binpick's native core failed ({what}); this is a bug, please report it with the input that caused it"
            )))
        }
    }
}
