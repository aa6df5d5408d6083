//! Calibration targets (`oxyline_core::sensitivity::targets`): the foot of a pressure wave,
//! a pulse-wave velocity's path, and the signals an output reads (`oxyline_core::sensitivity::target_signals`).

use crate::errors::to_py;
use crate::reader::model::canonical_spec;
use numpy::PyReadonlyArray1;
use oxyline_core::model::parse;
use oxyline_core::sensitivity::target_signals::signals_of;
use oxyline_core::sensitivity::targets;
use pyo3::prelude::*;

/// The foot time (s) of one cycle of a periodic pressure wave by intersecting tangents
/// (`time`/`pressure`: uniform samples with both ends, t₀ and t₀ + T); in [t₀, t₀ + T).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn foot_time(
    time: PyReadonlyArray1<'_, f64>,
    pressure: PyReadonlyArray1<'_, f64>,
) -> PyResult<f64> {
    let (t, p) = (time.as_array().to_vec(), pressure.as_array().to_vec());
    Ok(targets::foot_time(&t, &p).map_err(to_py)?.time)
}

/// The foot-to-foot transit time (s) from `proximal` to `distal` (one cycle each, with both
/// ends, at `time`), in [0, T).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn transit_time(
    time: PyReadonlyArray1<'_, f64>,
    proximal: PyReadonlyArray1<'_, f64>,
    distal: PyReadonlyArray1<'_, f64>,
) -> PyResult<f64> {
    let [t, p, d] = [time, proximal, distal].map(|a| a.as_array().to_vec());
    targets::transit_time(&t, &p, &d).map_err(to_py)
}

/// The vessels on the path of the pulse-wave velocity `output` (`pwv.<proximal>.<distal>`)
/// in the canonical model `model_json`, from the proximal one's inlet to the distal one's
/// outlet, with their lengths (m).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pulse_wave_path(model_json: &str, output: &str) -> PyResult<Vec<(String, f64)>> {
    let spec = parse(model_json).map_err(to_py)?;
    targets::pulse_wave_path(&spec, output).map_err(to_py)
}

/// Each output's answer of [`target_signals`]: its (vessel, variable) signals, or the
/// message of the error naming it.
type Found = (Vec<(String, String)>, Option<String>);

/// The (vessel, variable) signals each of `outputs` reads in the canonical model `model`
/// (its dicts, read in place), found by the core (`sensitivity::target_signals`) in one read
/// of the model; an output that does not fit gets the message of the `ModelError` naming it
/// instead, for the caller to raise in its own error type where it reads that output.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn target_signals(model: Bound<'_, PyAny>, outputs: Vec<String>) -> PyResult<Vec<Found>> {
    let spec = canonical_spec(&model)?;
    Ok(outputs
        .iter()
        .map(|output| match signals_of(&spec, output) {
            Ok(signals) => (signals, None),
            Err(e) => (Vec::new(), Some(e.to_string())),
        })
        .collect())
}
