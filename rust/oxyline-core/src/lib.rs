//! oxyline-core: arterial networks as lumped R–L–C circuits, assembled in linear time and
//! integrated with RK4 or generalized-α. Pure Rust; the Python binding lives in `oxyline-py`.

pub mod assemble;
pub mod calibration;
pub mod circuit;
pub mod closure;
pub mod coefficients;
pub mod element;
pub mod ensemble;
pub mod error;
pub mod frequency;
mod graetz;
pub mod hemoglobin;
pub mod impedance;
pub mod integrate;
pub mod model;
pub mod monitor;
pub mod output;
pub mod run;
pub mod segment;
pub mod sensitivity;
pub mod simulate;
pub mod sparse;
pub mod threads;
pub mod transport;
pub mod waveform;
pub mod womersley;

// The integration tests' fixtures (tests/common), shared with the unit tests: the file names
// this crate by its package name, as the integration tests see it.
#[cfg(test)]
extern crate self as oxyline_core;
#[cfg(test)]
#[path = "../tests/common/mod.rs"]
mod test_common;

pub use assemble::{Assembled, SegmentRow, Summary};
pub use circuit::{Circuit, Dae, Regime};
pub use error::{Error, Result};
// the integrators' old module paths (`crate::rk4::Rk4`, `crate::genalpha::GenAlpha`, ...)
pub use integrate::{genalpha, rk4, stability};
pub use model::NetworkSpec;
pub use output::{Probes, Selection};
pub use run::{
    Chunk, Method, Outcome, OutputSink, RunSettings, Start, TransportOutcome, simulate,
    simulate_to_sink, simulate_with_transport,
};
pub use transport::{Transport, TransportSpec};
