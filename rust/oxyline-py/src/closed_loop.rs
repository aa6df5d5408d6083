//! Binding of the closed loop (`oxyline_core::transport::closed_loop_run`): the parameter set
//! (a dict in its published units), the caller's flows and run controls in; the core checks
//! them, builds the circulation, runs the closed-loop heart when it gives the flows and the O2
//! loop to its periodic state in one call. Out: the recorded last cycle as flat arrays (Python
//! reshapes them) with the names of the compartments and branches, and the table used.

use crate::errors::to_py;
use crate::reader::node::{PyNode, to_python};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use oxyline_core::transport::closed_loop::ClosedLoopRun;
use oxyline_core::transport::closed_loop_run::{
    Flows, LoopRun, RunSettings, check_times, heart_model_of, heart_newton_atol_of, simulate,
};
use oxyline_core::transport::closed_loop_sensitivity::sensitivities;
use oxyline_core::transport::closed_loop_summary::{LoopSummary, WEIGHTED};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

/// The caller's flows: None (the set's own choice), a name, or a table (any array-like).
fn flows_of<'py>(py: Python<'py>, flows: &Bound<'py, PyAny>) -> PyResult<Flows> {
    if flows.is_none() {
        return Ok(Flows::Default);
    }
    if let Ok(name) = flows.cast::<PyString>() {
        return Ok(Flows::Named(name.to_str()?.to_owned()));
    }
    let table = py
        .import("numpy")?
        .call_method1("asarray", (flows, "float64"))?;
    let table: PyReadonlyArrayDyn<'py, f64> = table.extract()?;
    Ok(Flows::Table {
        shape: table.shape().to_vec(),
        values: table.as_array().iter().copied().collect(),
    })
}

/// The parameter set as JSON, the caller's flows and the run controls, each checked by the
/// core; the set's values are checked as the caller wrote them (a NaN period is named, not
/// lost to JSON).
fn inputs<'py>(
    py: Python<'py>,
    params: &Bound<'py, PyAny>,
    flows: &Bound<'py, PyAny>,
    max_cycles: Bound<'py, PyAny>,
    tol: Bound<'py, PyAny>,
    shooting: Bound<'py, PyAny>,
) -> PyResult<(String, Flows, RunSettings)> {
    check_times(&PyNode(params.clone())).map_err(to_py)?;
    let settings =
        RunSettings::read(&PyNode(max_cycles), &PyNode(tol), &PyNode(shooting)).map_err(to_py)?;
    let flows = flows_of(py, flows)?;
    let json: String = py
        .import("json")?
        .call_method1("dumps", (params,))?
        .extract()?;
    Ok((json, flows, settings))
}

#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (params, flows, max_cycles, tol, shooting))]
pub fn closed_loop_run<'py>(
    py: Python<'py>,
    params: Bound<'py, PyAny>,
    flows: Bound<'py, PyAny>,
    max_cycles: Bound<'py, PyAny>,
    tol: Bound<'py, PyAny>,
    shooting: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyDict>> {
    let (json, flows, settings) = inputs(py, &params, &flows, max_cycles, tol, shooting)?;
    let out = py
        .detach(move || simulate(&json, flows, &settings))
        .map_err(to_py)?;
    if !out.warnings.is_empty() {
        let category = py
            .import("oxyline.errors")?
            .getattr("HemoglobinFacilitationWarning")?;
        for w in &out.warnings {
            let text = std::ffi::CString::new(w.as_str()).unwrap_or_default();
            PyErr::warn(py, &category, &text, 2)?;
        }
    }
    if !out.run.heart_periodic {
        let category = py.import("oxyline.errors")?.getattr("PeriodicityWarning")?;
        let text = format!(
            "the closed-loop heart run stopped at its most cycles ({}) with a cycle-to-cycle \
             change of {:.3e}, above its periodicity tolerance: its flows are not periodic",
            out.run.heart_cycles, out.run.heart_periodic_error
        );
        let text = std::ffi::CString::new(text).unwrap_or_default();
        PyErr::warn(py, &category, &text, 2)?;
    }
    let d = record(py, &out.run)?;
    d.set_item("compartments", &out.compartments)?;
    d.set_item("branches", &out.branches)?;
    d.set_item("summary", summary(py, &out)?)?;
    let shape = [out.branches.len(), out.compartments.len()];
    let weighted = PyDict::new(py);
    for (name, table) in WEIGHTED.iter().zip(&out.summary.weighted) {
        weighted.set_item(*name, PyArray1::from_slice(py, table).reshape(shape)?)?;
    }
    d.set_item("weighted", weighted)?;
    let along = PyDict::new(py);
    for (vessel, means) in &out.summary.po2_along {
        along.set_item(vessel, PyArray1::from_slice(py, means))?;
    }
    d.set_item("tree_po2_along", along)?;
    Ok(d)
}

/// The summary as `ClosedLoopO2Result.summary()` returns it (its keys, in its order).
fn summary<'py>(py: Python<'py>, out: &LoopRun) -> PyResult<Bound<'py, PyDict>> {
    let s: &LoopSummary = &out.summary;
    let d = PyDict::new(py);
    let by_name = |pairs: &[(String, f64)]| -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        for (k, v) in pairs {
            d.set_item(k.as_str(), *v)?;
        }
        Ok(d)
    };
    for (k, v) in [
        ("SaO2", s.sao2),
        ("SvO2", s.svo2),
        ("PaO2", s.pao2),
        ("PvO2", s.pvo2),
        ("CaO2", s.cao2),
        ("CvO2", s.cvo2),
        ("VO2", s.vo2),
    ] {
        d.set_item(k, v)?;
    }
    d.set_item("VO2_organs", by_name(&s.vo2_organs)?)?;
    for (k, v) in [
        ("VO2_tree_wall", s.vo2_tree_wall),
        ("lung_uptake", s.lung_uptake),
        ("cardiac_output", s.cardiac_output),
        ("fick_residual", s.fick_residual),
        ("mass_balance_residual", s.mass_balance_residual),
    ] {
        d.set_item(k, v)?;
    }
    d.set_item("cycles", out.run.cycles)?;
    d.set_item("periodic_error", out.run.periodic_error)?;
    if !s.do2_organs.is_empty() {
        d.set_item("DO2_organs", by_name(&s.do2_organs)?)?;
    }
    Ok(d)
}

/// The loop's outputs at its periodic state and their exact derivatives by the parameters
/// (keys of the set; `oxyline_core::transport::closed_loop_sensitivity`), SI: a dict of
/// `parameter_values`, `values`, `jacobian` (outputs × parameters), `cycles`,
/// `periodic_error`.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (params, flows, max_cycles, tol, shooting, parameters, outputs))]
#[allow(clippy::too_many_arguments)]
pub fn closed_loop_sensitivities<'py>(
    py: Python<'py>,
    params: Bound<'py, PyAny>,
    flows: Bound<'py, PyAny>,
    max_cycles: Bound<'py, PyAny>,
    tol: Bound<'py, PyAny>,
    shooting: Bound<'py, PyAny>,
    parameters: Vec<String>,
    outputs: Vec<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let (json, flows, settings) = inputs(py, &params, &flows, max_cycles, tol, shooting)?;
    let out = py
        .detach(move || sensitivities(&json, flows, &settings, &parameters, &outputs))
        .map_err(to_py)?;
    let d = PyDict::new(py);
    let rows = out.values.len();
    let jac =
        PyArray1::from_slice(py, &out.jacobian).reshape([rows, out.parameter_values.len()])?;
    d.set_item(
        "parameter_values",
        PyArray1::from_slice(py, &out.parameter_values),
    )?;
    d.set_item("values", PyArray1::from_slice(py, &out.values))?;
    d.set_item("jacobian", jac)?;
    d.set_item("cycles", out.cycles)?;
    d.set_item("periodic_error", out.periodic_error)?;
    d.set_item("heart_cycles", out.heart_cycles)?;
    d.set_item("heart_periodic", out.heart_periodic)?;
    Ok(d)
}

/// The native model dict of the parameter set's closed-loop heart (SI; the heart block's
/// values in mmHg and mL).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn closed_loop_heart_model<'py>(
    py: Python<'py>,
    params_json: &str,
) -> PyResult<Bound<'py, PyAny>> {
    let model = heart_model_of(params_json).map_err(to_py)?;
    to_python(py, &model)
}

/// The number at `path` (`vessels.<name>.<key>...`) of the set's closed-loop heart model, in
/// the model's own units (the set's `heart_values` written over the built values); a path
/// naming nothing is a ModelError naming it and the nearest key.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn closed_loop_heart_value(params_json: &str, path: &str) -> PyResult<f64> {
    let mut model = heart_model_of(params_json).map_err(to_py)?;
    let x = oxyline_core::transport::closed_loop_heart_values::number_at(&mut model, path)
        .map_err(to_py)?;
    Ok(x.as_f64().unwrap_or(f64::NAN))
}

/// The run options of the set's closed-loop heart as the core's loop runs it
/// (`newton_atol` for svZeroDSolver's block; none for the native heart).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn closed_loop_heart_run_options<'py>(
    py: Python<'py>,
    params_json: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    if let Some(atol) = heart_newton_atol_of(params_json).map_err(to_py)? {
        d.set_item("newton_atol", atol)?;
    }
    Ok(d)
}

/// A run's record as a dict of flat arrays.
fn record<'py>(py: Python<'py>, run: &ClosedLoopRun) -> PyResult<Bound<'py, PyDict>> {
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
    d.set_item("heart_cycles", run.heart_cycles)?;
    d.set_item("heart_periodic_error", run.heart_periodic_error)?;
    d.set_item("heart_periodic", run.heart_periodic)?;
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
