//! Calibration targets (`oxyline_core::sensitivity::targets`): an output's value and its
//! derivatives from its signals over the periodic cycle, the foot of a pressure wave, and
//! the signals an output reads (`oxyline_core::sensitivity::target_signals`).

use crate::errors::to_py;
use crate::reader::model::canonical_spec;
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1};
use numpy::{PyReadonlyArray2, PyReadonlyArray3, PyUntypedArrayMethods};
use oxyline_core::error::Error;
use oxyline_core::model::parse;
use oxyline_core::sensitivity::target_signals::signals_of;
use oxyline_core::sensitivity::targets::{self, CycleSignals, PathLength};
use pyo3::prelude::*;

/// An output's values (m) and Jacobian (m × n_params).
type ValuesAndJacobian<'py> = (Bound<'py, PyArray1<f64>>, Bound<'py, PyArray2<f64>>);

/// The value(s) and Jacobian of the output named `output` from its signals over the periodic
/// cycle: `times` (the step end times Δt … T), `signals` (n_steps × n_signals),
/// `derivatives` (n_params × n_steps × n_signals); `at`, a series' times (s from the cycle's
/// start); `path`, a pulse-wave velocity's path length (m) and its derivative by each
/// parameter. Returns (values (m), jacobian (m × n_params)).
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (output, times, signals, derivatives, at = None, path = None))]
pub fn target_value<'py>(
    py: Python<'py>,
    output: &str,
    times: PyReadonlyArray1<'py, f64>,
    signals: PyReadonlyArray2<'py, f64>,
    derivatives: PyReadonlyArray3<'py, f64>,
    at: Option<PyReadonlyArray1<'py, f64>>,
    path: Option<(f64, PyReadonlyArray1<'py, f64>)>,
) -> PyResult<ValuesAndJacobian<'py>> {
    let (ns, nsig) = (signals.shape()[0], signals.shape()[1]);
    let [np, dns, dnsig] = [0, 1, 2].map(|k| derivatives.shape()[k]);
    if times.len() != ns || dns != ns || dnsig != nsig {
        return Err(to_py(Error::model(
            format!("output '{output}'"),
            format!(
                "{} times, signals of {ns} × {nsig} and derivatives of {np} × {dns} × {dnsig} \
                 do not fit",
                times.len()
            ),
        )));
    }
    let times = times.as_array().to_vec();
    let values: Vec<f64> = signals.as_array().iter().copied().collect();
    let derivs: Vec<f64> = derivatives.as_array().iter().copied().collect();
    let at = at.map(|a| a.as_array().to_vec());
    let dlength = path.as_ref().map(|(_, d)| d.as_array().to_vec());
    let cycle = CycleSignals {
        times: &times,
        values: &values,
        derivs: &derivs,
        n_signals: nsig,
    };
    let path = path
        .as_ref()
        .zip(dlength.as_deref())
        .map(|((length, _), dlength)| PathLength {
            length: *length,
            dlength,
        });
    let out = targets::evaluate(output, &cycle, at.as_deref(), path).map_err(to_py)?;
    let m = out.values.len();
    Ok((
        out.values.into_pyarray(py),
        out.jacobian.into_pyarray(py).reshape([m, np])?,
    ))
}

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
