//! The binding's exceptions and the mapping of core errors onto them: every `Error::Model`
//! of the core surfaces as `oxyline.errors.ModelError`.

use oxyline_core::Error;
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;

pyo3::create_exception!(
    oxyline,
    ModelError,
    PyValueError,
    "The network model or its settings are invalid."
);
pyo3::create_exception!(
    oxyline,
    UnstableTimeStep,
    ModelError,
    "The requested explicit time step is unstable."
);
pyo3::create_exception!(
    oxyline,
    ResourceError,
    ModelError,
    "The model or the requested output needs more memory than allowed (max_memory) or available."
);
pyo3::create_exception!(
    oxyline,
    SolverError,
    PyRuntimeError,
    "Time integration failed."
);

pub(crate) fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Model { .. } => ModelError::new_err(msg),
        Error::Unstable { .. } => UnstableTimeStep::new_err(msg),
        Error::Solver { .. } => SolverError::new_err(msg),
        Error::Interrupted { .. } => PyKeyboardInterrupt::new_err(msg),
        Error::Resource { .. } => ResourceError::new_err(msg),
    }
}

pub(crate) fn error_kind(e: &Error) -> &'static str {
    match e {
        Error::Model { .. } => "model",
        Error::Unstable { .. } => "unstable",
        Error::Solver { .. } => "solver",
        Error::Interrupted { .. } => "interrupted",
        Error::Resource { .. } => "resource",
    }
}

/// The body of a Python entry, with a Rust panic inside it turned into `SolverError` naming
/// the entry and the panic's message (`#[oxyline_py_guard::guard]` wraps every entry in it):
/// pyo3 would raise its `PanicException`, a `BaseException` no `except Exception` catches.
/// The default panic hook has already printed the panic's location to stderr.
pub(crate) fn guarded<T>(entry: &str, body: impl FnOnce() -> T) -> PyResult<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)).map_err(|payload| {
        let msg = payload
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "(no message)".to_owned());
        SolverError::new_err(format!(
            "{entry}: internal error in the core (a Rust panic: {msg}); please report it with \
             the model that caused it"
        ))
    })
}

/// A hidden entry that panics with `message`: the tests' proof that a panic at an entry
/// reaches Python as `SolverError` (there is no input known to make the core panic).
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn _panic_probe(message: &str) {
    panic!("{message}")
}
