//! The run driver's former path: the driver lives in [`crate::run`]; these re-exports keep
//! `crate::simulate::...` paths (the binding, the tests) compiling.

pub use crate::integrate::steady::steady_state;
pub use crate::run::{
    Chunk, Method, Outcome, OutputSink, RunSettings, Start, TransportOutcome, simulate,
    simulate_to_sink, simulate_with_transport,
};
