//! Mapping core errors and caught panics to the exception classes of `binpick.errors`: one
//! exhaustive `match` over the core's error enum, so a new variant cannot go unmapped.

use binpick_core::Error;
use pyo3::prelude::*;
use std::any::Any;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::mpsc::{channel, RecvTimeoutError};
use std::time::Duration;

mod classes {
    pyo3::import_exception!(binpick.errors, InvalidInputError);
    pyo3::import_exception!(binpick.errors, InvalidTypeError);
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

/// An `InvalidTypeError` (a `TypeError` too) naming the argument and the type expected.
pub fn wrong_type(arg: &str, expected: &str, got: &Bound<'_, PyAny>) -> PyErr {
    let got = got.get_type().name().map_or_else(|_| "?".into(), |n| n.to_string());
    classes::InvalidTypeError::new_err(format!("{arg}: must be {expected}, got a {got}"))
}

type Outcome<T> = Result<Result<T, Error>, Box<dyn Any + Send>>;

fn outcome_to_py<T>(outcome: Outcome<T>) -> PyResult<T> {
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

/// Runs core work that borrows its data with the GIL released and any panic caught, so that no
/// Rust panic ever reaches Python: a panic becomes `binpick.errors.InternalError`. For the
/// short calls of the simulator; long calls on owned data use [`run`], which Ctrl-C stops.
pub fn run_borrowed<T: Send>(py: Python<'_>, work: impl FnOnce() -> Result<T, Error> + Send) -> PyResult<T> {
    outcome_to_py(py.detach(|| catch_unwind(AssertUnwindSafe(work))))
}

/// How often a waiting call looks for Ctrl-C.
const SIGNAL_POLL: Duration = Duration::from_millis(50);

/// Stack of the worker thread: as large as a main thread's, for the core's recursive builds.
const WORKER_STACK: usize = 8 << 20;

/// Runs core work on owned data on a worker thread, panics caught as in [`run_borrowed`], while
/// the calling thread waits with the GIL released and checks Python's signals every 50 ms: on
/// Ctrl-C the call raises `KeyboardInterrupt` at once. The core has no cancellation hook, so the
/// abandoned work runs on in the background to its end (or the process's) and its result is dropped.
pub fn run<T: Send + 'static>(py: Python<'_>, work: impl FnOnce() -> Result<T, Error> + Send + 'static) -> PyResult<T> {
    let (tx, rx) = channel::<Outcome<T>>();
    std::thread::Builder::new()
        .name("binpick-call".into())
        .stack_size(WORKER_STACK)
        .spawn(move || {
            // The receiver is gone only when the caller was interrupted: nobody wants the result.
            let _ = tx.send(catch_unwind(AssertUnwindSafe(work)));
        })
        .map_err(|e| classes::InternalError::new_err(format!("binpick cannot start a worker thread ({e})")))?;
    let mut rx = rx;
    loop {
        // The receiver travels into the GIL-free closure and back: it is Send but not Sync.
        let (back, received) = py.detach(move || {
            let r = rx.recv_timeout(SIGNAL_POLL);
            (rx, r)
        });
        rx = back;
        match received {
            Ok(outcome) => return outcome_to_py(outcome),
            Err(RecvTimeoutError::Timeout) => py.check_signals()?,
            Err(RecvTimeoutError::Disconnected) => {
                return Err(classes::InternalError::new_err(
                    "binpick's worker thread ended without a result; this is a bug, please report it",
                ))
            }
        }
    }
}
