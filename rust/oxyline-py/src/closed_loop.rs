//! Binding of the closed-loop O2 run (`oxyline_core::transport::closed_loop`): JSON spec and a
//! flat flow table in, the recorded last cycle out (flat arrays; Python reshapes them).

use crate::to_py;
use numpy::{PyArray1, PyReadonlyArray1};
use oxyline_core::transport::closed_loop::{ClosedLoopSpec, run_periodic};
use pyo3::prelude::*;
use pyo3::types::PyDict;

#[pyfunction]
#[pyo3(signature = (spec_json, flows, dt, max_cycles, tol))]
pub fn closed_loop_o2<'py>(
    py: Python<'py>,
    spec_json: &str,
    flows: PyReadonlyArray1<'py, f64>,
    dt: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let spec = ClosedLoopSpec::from_json(spec_json).map_err(to_py)?;
    let flows = flows.as_slice()?.to_vec();
    let run = py
        .detach(move || run_periodic(&spec, &flows, dt, max_cycles, tol))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("cycles", run.cycles)?;
    d.set_item("periodic_error", run.periodic_error)?;
    d.set_item("amount_start", run.amount_start)?;
    for (k, v) in [
        ("time", &run.time),
        ("volume", &run.volume),
        ("total", &run.total),
        ("po2", &run.po2),
        ("saturation", &run.saturation),
        ("vo2", &run.vo2),
        ("flux", &run.flux),
        ("uptake", &run.uptake),
        ("amount", &run.amount),
    ] {
        d.set_item(k, PyArray1::from_slice(py, v))?;
    }
    Ok(d)
}
