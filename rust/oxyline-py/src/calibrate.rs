//! Exact parameter sensitivities of a model's periodic state (`oxyline_core::sensitivity`):
//! the binding of `oxyline.sensitivities` and `oxyline.calibrate`.

use crate::ensemble::patched_model;
use crate::errors::to_py;
use crate::reader::node::PyNode;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray1};
use oxyline_core::error::Error;
use oxyline_core::model::{NetworkSpec, parameters, parse};
use oxyline_core::sensitivity::{
    TangentSettings, adjoint_with, sensitivities, species_adjoint_with,
    species_sensitivities as species,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The signals (vessel, variable) over the periodic cycle of the canonical model
/// `model_json` and their derivatives with respect to the parameters `paths`: a dict of
/// `values` (SI value of each parameter), `times` (n_steps), `signals` (n_steps × n_signals),
/// `derivatives` (n_params × n_steps × n_signals), `cycles` (the forward run's, the
/// recorded one included), `tangent_cycles` and `periodic_change`.
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
    tangent_cycle(
        py,
        model_json,
        paths,
        signals,
        move |spec, paths, signals| {
            let out = sensitivities(spec, paths, signals, settings)?;
            let c = out.cycle;
            Ok(Cycle {
                values: out.values,
                times: c.times,
                signals: c.values,
                derivs: c.derivs,
                cycles: c.cycles,
                tangent_cycles: c.tangent_cycles,
                periodic_change: c.periodic_change,
            })
        },
    )
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

/// Parse `model_json` and run `solve` on it (without the GIL); its cycle as `cycle_dict`.
fn tangent_cycle<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    solve: impl FnOnce(&NetworkSpec, &[String], &[(String, String)]) -> Result<Cycle, Error> + Send,
) -> PyResult<Bound<'py, PyDict>> {
    let (np, nsig) = (paths.len(), signals.len());
    let cycle = py
        .detach(move || solve(&parse(model_json)?, &paths, &signals))
        .map_err(to_py)?;
    cycle_dict(py, cycle, np, nsig)
}

/// The periodic cycle's signals and their derivatives, as both tangent bindings return them.
struct Cycle {
    values: Vec<f64>,
    times: Vec<f64>,
    signals: Vec<f64>,
    derivs: Vec<f64>,
    cycles: usize,
    tangent_cycles: usize,
    periodic_change: f64,
}

/// `c` as the dict of the tangent bindings (signals n_steps × n_signals, derivatives
/// n_params × n_steps × n_signals).
fn cycle_dict(py: Python<'_>, c: Cycle, np: usize, nsig: usize) -> PyResult<Bound<'_, PyDict>> {
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

/// The oxygen signals (vessel, name) over the periodic cycle of `model_json` and their
/// derivatives by the oxygen parameters `paths` (`oxyline_core::sensitivity::species`): a
/// dict of `values`, `times`, `signals` (n_steps × n_signals), `derivatives` (n_params ×
/// n_steps × n_signals), `cycles` (the flow's), `tangent_cycles` (the transport's, with its
/// tangents) and `periodic_change`.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, period, steps_per_cycle, rho_infty = 0.5,
                    max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn species_sensitivities<'py>(
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
    tangent_cycle(
        py,
        model_json,
        paths,
        signals,
        move |spec, paths, signals| {
            let out = species(spec, paths, signals, settings)?;
            Ok(Cycle {
                values: out.values,
                times: out.times,
                signals: out.signals,
                derivs: out.derivs,
                cycles: out.cycles,
                tangent_cycles: out.transport_cycles,
                periodic_change: out.periodic_change,
            })
        },
    )
}

/// The gradients of functionals J_f = Σ_kj weights[f, k, j] · signal j after step k of the
/// periodic cycle of `model_json` by the adjoint (one backward sweep per functional, whatever
/// the number of parameters). `weights_of(times, signals)` is called once with the step end
/// times (n_steps) and the signals (n_steps × n_signals) of the one primal run and returns
/// the weights, flat n_functionals × n_steps × n_signals (chosen from the cycle: no second
/// forward run). A dict of `values` (SI value of each parameter), `functionals` (J_f),
/// `gradients` (n_functionals × n_params), `cycles`, `adjoint_cycles` (per functional) and
/// `periodic_change`; an exception of `weights_of` is raised as it is.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, weights_of, period, steps_per_cycle,
                    rho_infty = 0.5, max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn adjoint_gradients<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    weights_of: Py<PyAny>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = cycle_settings(period, steps_per_cycle, rho_infty, max_cycles, tol);
    let (np, nsig) = (paths.len(), signals.len());
    let (values, out) = detach_with_weights(py, model_json, &weights_of, nsig, |spec, w| {
        adjoint_with(spec, &paths, &signals, w, settings)
    })?;
    let d = adjoint_dict(py, values, out.values, out.gradients, np)?;
    d.set_item("cycles", out.cycles)?;
    d.set_item("adjoint_cycles", out.adjoint_cycles)?;
    d.set_item("periodic_change", out.periodic_change)?;
    Ok(d)
}

/// [`adjoint_gradients`] of oxygen signals (vessel, name; vessel "" for the network's
/// balance fluxes) by oxygen and flow parameters
/// (`oxyline_core::sensitivity::species_adjoint_with`): one backward sweep of the species
/// transport per functional (a flow parameter's flow tangent forward beside the flow). The same dict, with
/// `tangent_cycles` (the transport's cycles to its periodic state).
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, weights_of, period, steps_per_cycle,
                    rho_infty = 0.5, max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn species_adjoint_gradients<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    weights_of: Py<PyAny>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = cycle_settings(period, steps_per_cycle, rho_infty, max_cycles, tol);
    let (np, nsig) = (paths.len(), signals.len());
    let (values, out) = detach_with_weights(py, model_json, &weights_of, nsig, |spec, w| {
        species_adjoint_with(spec, &paths, &signals, w, settings)
    })?;
    let d = adjoint_dict(py, values, out.functionals, out.gradients, np)?;
    d.set_item("cycles", out.cycles)?;
    d.set_item("tangent_cycles", out.transport_cycles)?;
    d.set_item("adjoint_cycles", out.adjoint_cycles)?;
    d.set_item("periodic_change", out.periodic_change)?;
    Ok(d)
}

/// An adjoint's dict: the parameters' SI `values`, the `functionals` and their `gradients`
/// (n_functionals × `np`); the caller adds its cycle counts.
fn adjoint_dict<'py>(
    py: Python<'py>,
    values: Vec<f64>,
    functionals: Vec<f64>,
    gradients: Vec<f64>,
    np: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let nf = functionals.len();
    let d = PyDict::new(py);
    d.set_item("values", values.into_pyarray(py))?;
    d.set_item("functionals", functionals.into_pyarray(py))?;
    d.set_item("gradients", gradients.into_pyarray(py).reshape([nf, np])?)?;
    Ok(d)
}

/// The weights callback an adjoint sweep calls once with its signals' series.
type Weights<'a> = Box<dyn FnOnce(&[f64], &[f64]) -> oxyline_core::error::Result<Vec<f64>> + 'a>;

/// Parses the model and runs an adjoint (`run`) without the GIL, handing it the Python
/// `weights_of` callback; an exception the callback raised is returned as itself.
fn detach_with_weights<T, R>(
    py: Python<'_>,
    model_json: &str,
    weights_of: &Py<PyAny>,
    nsig: usize,
    run: R,
) -> PyResult<T>
where
    T: Send,
    R: for<'a> FnOnce(&NetworkSpec, Weights<'a>) -> oxyline_core::error::Result<T> + Send,
{
    let mut raised: Option<PyErr> = None;
    let result = py.detach(|| {
        let spec = parse(model_json)?;
        let weights: Weights<'_> = Box::new(|times: &[f64], values: &[f64]| {
            Python::attach(|py| call_weights(py, weights_of, times, values, nsig)).map_err(|e| {
                raised = Some(e);
                Error::model("adjoint", "weights_of raised")
            })
        });
        run(&spec, weights)
    });
    if let Some(e) = raised {
        return Err(e);
    }
    result.map_err(to_py)
}

/// `weights_of(times, signals)`: the weights as a flat float64 vector.
fn call_weights(
    py: Python<'_>,
    weights_of: &Py<PyAny>,
    times: &[f64],
    values: &[f64],
    nsig: usize,
) -> PyResult<Vec<f64>> {
    let times = times.to_vec().into_pyarray(py);
    let sig = values
        .to_vec()
        .into_pyarray(py)
        .reshape([values.len() / nsig.max(1), nsig])?;
    let w = weights_of.call1(py, (times, sig))?;
    let w: PyReadonlyArray1<f64> = w.bind(py).extract()?;
    Ok(w.as_slice()?.to_vec())
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
