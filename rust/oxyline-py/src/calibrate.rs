//! Exact parameter sensitivities of a model's periodic state (`oxyline_core::sensitivity`):
//! the binding of `oxyline.sensitivities` and `oxyline.calibrate`.

use crate::ensemble::patched_model;
use crate::errors::to_py;
use crate::reader::node::PyNode;
use numpy::{IntoPyArray, PyArrayMethods};
use oxyline_core::error::Error;
use oxyline_core::model::{parameters, parse};
use oxyline_core::sensitivity::target_runs::{TargetRead, target_adjoint, target_values};
use oxyline_core::sensitivity::targets::CycleSignals;
use oxyline_core::sensitivity::{TangentSettings, signal_sensitivities};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// A target as the bindings take it: its output's name, the columns of the run's signals it
/// reads, and a series' times (None: the cycle's steps).
type Target = (String, Vec<usize>, Option<Vec<f64>>);

fn reads(targets: Vec<Target>) -> Vec<TargetRead> {
    targets
        .into_iter()
        .map(|(output, columns, at)| TargetRead {
            output,
            columns,
            at,
        })
        .collect()
}

/// Every target's value(s) and Jacobian by the parameters `paths` at the periodic state of
/// the canonical model `model_json`, by the tangents (`oxyline_core::sensitivity::
/// target_runs::target_values`: one tangent run of the `signals`, each target reduced from
/// its columns, a pulse-wave velocity with its path length from the model). `targets`:
/// (output, signal columns, a series' times or None for the cycle's steps). A dict of
/// `values` (SI value of each parameter), `outputs` (per target: (values (m), jacobian (m ×
/// n_params))), `cycles`, `tangent_cycles` and `periodic_change`.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, targets, period, steps_per_cycle,
                    rho_infty = 0.5, max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn target_tangents<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    targets: Vec<Target>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = cycle_settings(period, steps_per_cycle, rho_infty, max_cycles, tol);
    let (np, nsig, targets) = (paths.len(), signals.len(), reads(targets));
    let (c, outs) = py
        .detach(move || {
            let spec = parse(model_json)?;
            let c = signal_sensitivities(&spec, &paths, &signals, settings)?;
            let cycle = CycleSignals {
                times: &c.times,
                values: &c.signals,
                derivs: &c.derivs,
                n_signals: nsig,
            };
            let outs = target_values(&spec, &paths, &targets, &cycle)?;
            Ok::<_, Error>((c, outs))
        })
        .map_err(to_py)?;
    let list = PyList::empty(py);
    for o in outs {
        let m = o.values.len();
        let j = o.jacobian.into_pyarray(py).reshape([m, np])?;
        list.append((o.values.into_pyarray(py), j))?;
    }
    let d = PyDict::new(py);
    d.set_item("values", c.values.into_pyarray(py))?;
    d.set_item("outputs", list)?;
    d.set_item("cycles", c.cycles)?;
    d.set_item("periodic_change", c.periodic_change)?;
    d.set_item("tangent_cycles", c.tangent_cycles)?;
    Ok(d)
}

/// Every target's value(s) and gradients by the parameters `paths` at the periodic state of
/// `model_json` by the adjoint, in one primal run (`oxyline_core::sensitivity::
/// target_runs::target_adjoint`: the targets' output weights chosen by the core from the
/// cycle, one backward sweep per target value, a pulse-wave velocity's path-length term
/// added). `targets` as [`target_tangents`]'. A dict of `values` (SI value of each
/// parameter), `outputs` (per target: its values (m)), `gradients` (n_rows × n_params, the
/// targets' rows in order), `cycles`, `tangent_cycles` (the species transport's),
/// `adjoint_cycles` (per row) and `periodic_change`.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, targets, period, steps_per_cycle,
                    rho_infty = 0.5, max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn target_gradients<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    targets: Vec<Target>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = cycle_settings(period, steps_per_cycle, rho_infty, max_cycles, tol);
    let (np, targets) = (paths.len(), reads(targets));
    let out = py
        .detach(move || target_adjoint(&parse(model_json)?, &paths, &signals, &targets, settings))
        .map_err(to_py)?;
    let rows: usize = out.values.iter().map(Vec::len).sum();
    let list = PyList::empty(py);
    for v in out.values {
        list.append(v.into_pyarray(py))?;
    }
    let d = PyDict::new(py);
    d.set_item("values", out.run.values.into_pyarray(py))?;
    d.set_item("outputs", list)?;
    d.set_item(
        "gradients",
        out.gradients.into_pyarray(py).reshape([rows, np])?,
    )?;
    d.set_item("cycles", out.run.cycles)?;
    d.set_item("tangent_cycles", out.run.transport_cycles)?;
    d.set_item("adjoint_cycles", out.run.adjoint_cycles)?;
    d.set_item("periodic_change", out.run.periodic_change)?;
    Ok(d)
}

/// The signals over the periodic cycle of the canonical model `model_json` and their
/// derivatives with respect to the parameters `paths`, flow and oxygen alike
/// (`oxyline_core::sensitivity::signal_sensitivities`: a flow signal by the flow tangent, an
/// oxygen signal by the species tangent; an oxygen parameter's rows of a flow signal are 0):
/// a dict of `values` (SI value of each parameter), `times` (n_steps), `signals` (n_steps ×
/// n_signals), `derivatives` (n_params × n_steps × n_signals), `cycles` (the forward run's,
/// the recorded one included), `tangent_cycles` and `periodic_change`.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, period, steps_per_cycle, rho_infty = 0.5,
                    max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn tangent_sensitivities<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = cycle_settings(period, steps_per_cycle, rho_infty, max_cycles, tol);
    let (np, nsig) = (paths.len(), signals.len());
    let c = py
        .detach(move || signal_sensitivities(&parse(model_json)?, &paths, &signals, settings))
        .map_err(to_py)?;
    let nt = c.times.len();
    let d = PyDict::new(py);
    d.set_item("values", c.values.into_pyarray(py))?;
    d.set_item("times", c.times.into_pyarray(py))?;
    d.set_item("signals", c.signals.into_pyarray(py).reshape([nt, nsig])?)?;
    d.set_item(
        "derivatives",
        c.derivs.into_pyarray(py).reshape([np, nt, nsig])?,
    )?;
    d.set_item("cycles", c.cycles)?;
    d.set_item("periodic_change", c.periodic_change)?;
    d.set_item("tangent_cycles", c.tangent_cycles)?;
    Ok(d)
}

/// The bindings' keyword arguments of the periodic cycle, as the core's settings.
fn cycle_settings(
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> TangentSettings {
    TangentSettings {
        period,
        steps_per_cycle,
        rho_infty,
        max_cycles,
        tol,
    }
}

/// `parameter_value(source, path)`: the number the parameter path names in the native model
/// dict `source`, in the model's units (1 for a scale; `oxyline_core::model::parameters`).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn parameter_value(source: Bound<'_, PyAny>, path: &str) -> PyResult<f64> {
    parameters::base_value(&PyNode(source), path).map_err(to_py)
}

/// `set_parameters(source, paths, values)`: the native model dict `source` with each
/// parameter path set to its value (the model's units; a scale to its factor), sharing every
/// element the values leave alone (`oxyline_core::model::parameters::set_values`).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn set_parameters<'py>(
    py: Python<'py>,
    source: Bound<'py, PyDict>,
    paths: Vec<String>,
    values: Vec<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    let base = PyNode(source.clone().into_any());
    let patched = parameters::set_values(&base, &paths, &values).map_err(to_py)?;
    patched_model(py, &source, &patched)
}
