//! oxyline-core: arterial networks as lumped R–L–C circuits, assembled in linear time and
//! integrated with RK4 or generalized-α. Pure Rust; the Python binding lives in `oxyline-py`.

pub mod circuit;
pub mod closure;
pub mod error;
pub mod frequency;
pub mod genalpha;
mod graetz;
pub mod hemoglobin;
pub mod network;
pub mod rk4;
pub mod segment;
pub mod simulate;
pub mod sparse;
pub mod spec;
pub mod stability;
pub mod transport;
pub mod waveform;

pub use circuit::{Circuit, Dae, Regime};
pub use error::{Error, Result};
pub use network::{Assembled, NetworkSpec, Probes, Summary};
pub use simulate::{
    Chunk, Method, Outcome, OutputSink, RunSettings, Start, TransportOutcome, simulate,
    simulate_to_sink, simulate_with_transport,
};
pub use transport::{Transport, TransportSpec};
