//! Binding of the closed-loop O2 run (`oxyline_core::transport::closed_loop`): JSON spec and a
//! flat flow table in (balanced by the core with `balance`), the recorded last cycle and the
//! table used out (flat arrays; Python reshapes them). With a `heart` in the spec the core runs
//! the closed-loop heart first and reads the flows from it (the table passed is then empty).

use crate::errors::to_py;
use numpy::{PyArray1, PyReadonlyArray1};
use oxyline_core::transport::closed_loop::{ClosedLoopSpec, run_periodic};
use pyo3::prelude::*;
use pyo3::types::PyDict;

#[oxyline_py_guard::guard]
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
    d.set_item("tree_segments", &run.tree_segments)?;
    d.set_item("tree_flow_periodic_error", run.tree_flow_periodic_error)?;
    let heart = PyDict::new(py);
    for (name, v) in &run.heart_series {
        heart.set_item(name, PyArray1::from_slice(py, v))?;
    }
    d.set_item("heart_series", heart)?;
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
        ("tree_wall", &run.tree_wall),
        ("tree_amount", &run.tree_amount),
        ("tree_in_flux", &run.tree_in_flux),
        ("tree_out_flux", &run.tree_out_flux),
        ("tree_po2", &run.tree_po2),
        ("tree_inflow", &run.tree_inflow),
        ("tree_outflow", &run.tree_outflow),
        ("flow", &run.flow),
        ("heart_time", &run.heart_time),
    ] {
        d.set_item(k, PyArray1::from_slice(py, v))?;
    }
    Ok(d)
}
