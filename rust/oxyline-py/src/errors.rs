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
