//! Memory estimates made before anything large is allocated: a model with
//! 10⁹ segments, or an output of every cycle of a long run, is refused with a typed
//! [`Error::Resource`] giving the estimate and the setting to change, instead of taking all
//! RAM and aborting the process.
//!
//! The per-segment figures are peak resident bytes measured for whole runs (load, assembly,
//! solver factors, run state; `benches/bench_memory.py`: ~1.6 kB per flow segment, ~0.5 kB
//! more per O2 cell), rounded up: an estimate is meant to be within a small factor of the
//! real peak, never far below it.

use crate::error::{Error, Result};

/// Peak bytes per flow segment: circuit, DAE, sparse LU, integrator state, names, the
/// binding's copy of the model.
pub const FLOW_BYTES_PER_SEGMENT: f64 = 2500.0;
/// Peak bytes per transport cell and species: plan, laws, per-run state.
pub const TRANSPORT_BYTES_PER_CELL: f64 = 1000.0;
/// Bytes per vessel and per boundary condition beyond their segments (names, the model's
/// dicts on the Python side).
pub const BYTES_PER_ELEMENT: f64 = 2000.0;

/// Estimated peak bytes of a model with `segments` flow segments, `elements` vessels and
/// boundary conditions, `cells` transport cells per segment (0 without transport) and
/// `species` species.
pub fn model_bytes(segments: usize, elements: usize, cells: f64, species: usize) -> f64 {
    let s = segments as f64;
    s * FLOW_BYTES_PER_SEGMENT
        + s * cells * species as f64 * TRANSPORT_BYTES_PER_CELL
        + elements as f64 * BYTES_PER_ELEMENT
}

/// What the user can change when a model is too large.
pub const MODEL_ADVICE: &str = "use fewer segments (segmentation max_length, a vessel's \
segments) or raise the limit (simulation: max_memory in the model, the environment variable \
OXYLINE_MAX_MEMORY)";

/// Refuse a model of `segments` segments whose estimate exceeds `limit` (bytes; None: no
/// limit).
pub fn check_model(
    name: &str,
    segments: usize,
    elements: usize,
    transport: Option<(f64, usize)>,
    limit: Option<f64>,
) -> Result<()> {
    let Some(limit) = limit else {
        return Ok(());
    };
    let (cells, species) = transport.unwrap_or((0.0, 0));
    let need = model_bytes(segments, elements, cells, species);
    if need > limit {
        return Err(Error::over_limit(
            format!("model '{name}' ({segments} segments)"),
            need,
            limit,
            MODEL_ADVICE,
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_billion_segments_is_refused_with_the_estimate_and_the_setting() {
        let e = check_model("big", 1_000_000_000, 3, None, Some(8e9)).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Resource { bytes, .. } if bytes == 2_500_000_006_000));
        assert!(msg.starts_with("model 'big' (1000000000 segments): needs about 2.500 TB"));
        assert!(msg.contains("max_memory = 8.000 GB") && msg.contains("max_length"));
        assert!(check_model("small", 1000, 3, Some((1.0, 1)), Some(8e9)).is_ok());
        assert!(check_model("any", usize::MAX / 2, 3, None, None).is_ok());
    }
}
