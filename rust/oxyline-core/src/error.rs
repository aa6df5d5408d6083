//! The core's single error type. Every variant names the element (vessel, node, branch,
//! boundary condition) and the offending value so that users can fix their model.

use thiserror::Error;

#[derive(Debug, Clone, Error, PartialEq)]
pub enum Error {
    /// The model description is invalid (geometry, topology, boundary conditions, tables).
    #[error("{element}: {message}")]
    Model { element: String, message: String },
    /// The requested explicit time step is outside the stability region.
    #[error(
        "time step {dt:.3e} s is unstable for rk4: the largest stable step is {limit:.3e} s, set by {element}; use dt <= {limit:.3e} or method 'generalized-alpha'"
    )]
    Unstable {
        dt: f64,
        limit: f64,
        element: String,
    },
    /// The integration failed (singular system, Newton failure, non-finite state).
    #[error("solver failed at t = {time:.6e} s: {message}")]
    Solver { time: f64, message: String },
    /// The run was cancelled by the caller (e.g. Ctrl-C).
    #[error("run interrupted at t = {time:.6e} s")]
    Interrupted { time: f64 },
}

impl Error {
    pub fn model(element: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Model {
            element: element.into(),
            message: message.into(),
        }
    }
    pub fn solver(time: f64, message: impl Into<String>) -> Self {
        Error::Solver {
            time,
            message: message.into(),
        }
    }
}

pub type Result<T> = std::result::Result<T, Error>;
