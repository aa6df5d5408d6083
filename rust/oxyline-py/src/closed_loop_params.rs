//! Binding of the closed loop's parameter set (`oxyline_core::transport::closed_loop_params`):
//! the set as JSON in (its published units), its SI layout as JSON and, when asked for, the
//! prescribed flow table (steps × branches, m³/s) out.

use crate::errors::to_py;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use oxyline_core::transport::closed_loop_params::LoopParams;
use pyo3::prelude::*;

#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (params_json, table))]
pub fn closed_loop_layout<'py>(
    py: Python<'py>,
    params_json: &str,
    table: bool,
) -> PyResult<(String, Option<Bound<'py, PyArray2<f64>>>)> {
    let params = LoopParams::from_json(params_json).map_err(to_py)?;
    let layout = params.layout();
    let flows = if table {
        let (flat, steps) = params.flow_table(&layout).map_err(to_py)?;
        let width = layout.branches.len();
        Some(PyArray1::from_vec(py, flat).reshape([steps, width])?)
    } else {
        None
    };
    let json = serde_json::to_string(&layout).map_err(|e| {
        to_py(oxyline_core::error::Error::model(
            "closed loop",
            e.to_string(),
        ))
    })?;
    Ok((json, flows))
}
