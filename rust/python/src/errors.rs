//! Mapping core errors and caught panics to the exception classes of `binpick.errors`: one
//! exhaustive `match` over the core's error enum, so a new variant cannot go unmapped.

use binpick_core::{cancel_scope, CancelFlag, Error};
use pyo3::prelude::*;
use std::any::Any;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
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
        Error::Cancelled => pyo3::exceptions::PyKeyboardInterrupt::new_err(message),
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

/// Worker threads of [`run`] still running, interrupted ones included.
static RUNNING: AtomicUsize = AtomicUsize::new(0);

/// How many native calls are still running, those abandoned on Ctrl-C included: the tests use it
/// to see that an interrupted call stops its work rather than running on to its end.
pub fn running_calls() -> usize {
    RUNNING.load(Ordering::SeqCst)
}

/// Counts a worker thread of [`run`] for as long as it lives.
struct Running;

impl Running {
    fn start() -> Self {
        RUNNING.fetch_add(1, Ordering::SeqCst);
        Running
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        RUNNING.fetch_sub(1, Ordering::SeqCst);
    }
}

/// Runs core work on owned data on a worker thread, panics caught as in [`run_borrowed`], while
/// the calling thread waits with the GIL released and checks Python's signals every 50 ms: on
/// Ctrl-C the call raises `KeyboardInterrupt` at once and raises the work's cancel flag, so that
/// the work stops at its next check (between iterations of its long loops) and its result, if
/// any, is dropped; nothing half-built is cached.
pub fn run<T: Send + 'static>(py: Python<'_>, work: impl FnOnce() -> Result<T, Error> + Send + 'static) -> PyResult<T> {
    let (tx, rx) = channel::<Outcome<T>>();
    let flag = CancelFlag::new();
    let worker_flag = flag.clone();
    let running = Running::start();
    std::thread::Builder::new()
        .name("binpick-call".into())
        .stack_size(WORKER_STACK)
        .spawn(move || {
            let _running = running;
            let outcome = cancel_scope(&worker_flag, || catch_unwind(AssertUnwindSafe(work)));
            // The receiver is gone only when the caller was interrupted: nobody wants the result.
            let _ = tx.send(outcome);
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
            Err(RecvTimeoutError::Timeout) => {
                if let Err(interrupt) = py.check_signals() {
                    flag.cancel();
                    return Err(interrupt);
                }
            }
            Err(RecvTimeoutError::Disconnected) => {
                return Err(classes::InternalError::new_err(
                    "binpick's worker thread ended without a result; this is a bug, please report it",
                ))
            }
        }
    }
}
