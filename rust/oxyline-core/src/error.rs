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
    /// The model or the requested output needs more memory than allowed (the `max_memory`
    /// setting) or than the system gives (a failed fallible allocation). `bytes` is the
    /// estimate or the request; the message names what needs it and the setting to change.
    #[error("{what}: {message}")]
    Resource {
        what: String,
        bytes: u64,
        message: String,
    },
}

impl Error {
    pub fn model(element: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Model {
            element: element.into(),
            message: message.into(),
        }
    }
    /// `what` needs an estimated `bytes`, above the limit `limit` (bytes).
    pub fn over_limit(what: impl Into<String>, bytes: f64, limit: f64, advice: &str) -> Self {
        Error::Resource {
            what: what.into(),
            bytes: bytes as u64,
            message: format!(
                "needs about {} of memory (estimate), above max_memory = {}; {advice}",
                human_bytes(bytes),
                human_bytes(limit)
            ),
        }
    }

    /// A fallible allocation of `bytes` for `what` failed: the system has not that much.
    pub fn allocation(what: impl Into<String>, bytes: f64) -> Self {
        Error::Resource {
            what: what.into(),
            bytes: bytes as u64,
            message: format!(
                "cannot allocate {} (out of memory); reduce the model or the output, or free memory",
                human_bytes(bytes)
            ),
        }
    }

    pub fn solver(time: f64, message: impl Into<String>) -> Self {
        Error::Solver {
            time,
            message: message.into(),
        }
    }
}

/// `bytes` as "1.23 GB" (decimal units, as `max_memory` accepts them).
pub fn human_bytes(bytes: f64) -> String {
    const UNITS: [&str; 5] = ["B", "kB", "MB", "GB", "TB"];
    let mut x = bytes;
    let mut u = 0;
    while x >= 1000.0 && u + 1 < UNITS.len() {
        x /= 1000.0;
        u += 1;
    }
    if u == 0 {
        format!("{x:.0} B")
    } else {
        format!("{x:.3} {}", UNITS[u])
    }
}

/// Reserve room for `extra` more elements of `v`, or a typed [`Error::Resource`] naming `what`
/// (instead of the allocator's abort).
pub fn try_reserve<T>(v: &mut Vec<T>, extra: usize, what: &str) -> Result<()> {
    v.try_reserve_exact(extra)
        .map_err(|_| Error::allocation(what, extra as f64 * std::mem::size_of::<T>() as f64))
}

pub type Result<T> = std::result::Result<T, Error>;
