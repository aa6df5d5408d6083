//! Exact parameter sensitivities of a model's periodic state (`oxyline_core::sensitivity`):
//! the binding of `oxyline.sensitivities` and `oxyline.calibrate`.

use crate::errors::to_py;
use numpy::{IntoPyArray, PyArrayMethods, PyReadonlyArray1};
use oxyline_core::model::parse;
use oxyline_core::sensitivity::{TangentSettings, adjoint, sensitivities};
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
    let settings = TangentSettings {
        period,
        steps_per_cycle,
        rho_infty,
        max_cycles,
        tol,
    };
    let (np, nsig) = (paths.len(), signals.len());
    let out = py
        .detach(move || {
            let spec = parse(model_json)?;
            sensitivities(&spec, &paths, &signals, settings)
        })
        .map_err(to_py)?;
    let c = out.cycle;
    let nt = c.times.len();
    let d = PyDict::new(py);
    d.set_item("values", out.values.into_pyarray(py))?;
    d.set_item("times", c.times.into_pyarray(py))?;
    d.set_item("signals", c.values.into_pyarray(py).reshape([nt, nsig])?)?;
    d.set_item(
        "derivatives",
        c.derivs.into_pyarray(py).reshape([np, nt, nsig])?,
    )?;
    d.set_item("cycles", c.cycles)?;
    d.set_item("periodic_change", c.periodic_change)?;
    d.set_item("tangent_cycles", c.tangent_cycles)?;
    Ok(d)
}

/// The gradients of functionals J_f = Σ_kj weights[f, k, j] · signal j after step k of the
/// periodic cycle of `model_json` by the adjoint (one backward sweep per functional, whatever
/// the number of parameters): a dict of `values` (SI value of each parameter), `functionals`
/// (J_f), `gradients` (n_functionals × n_params), `cycles`, `adjoint_cycles` (per
/// functional) and `periodic_change`. `weights` is flat, n_functionals × n_steps × n_signals.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (model_json, paths, signals, weights, period, steps_per_cycle,
                    rho_infty = 0.5, max_cycles = 2000, tol = 1e-12))]
#[allow(clippy::too_many_arguments)]
pub fn adjoint_gradients<'py>(
    py: Python<'py>,
    model_json: &str,
    paths: Vec<String>,
    signals: Vec<(String, String)>,
    weights: PyReadonlyArray1<'py, f64>,
    period: f64,
    steps_per_cycle: usize,
    rho_infty: f64,
    max_cycles: usize,
    tol: f64,
) -> PyResult<Bound<'py, PyDict>> {
    let settings = TangentSettings {
        period,
        steps_per_cycle,
        rho_infty,
        max_cycles,
        tol,
    };
    let weights = weights.as_slice()?.to_vec();
    let np = paths.len();
    let (values, out) = py
        .detach(move || {
            let spec = parse(model_json)?;
            adjoint(&spec, &paths, &signals, &weights, settings)
        })
        .map_err(to_py)?;
    let nf = out.values.len();
    let d = PyDict::new(py);
    d.set_item("values", values.into_pyarray(py))?;
    d.set_item("functionals", out.values.into_pyarray(py))?;
    d.set_item(
        "gradients",
        out.gradients.into_pyarray(py).reshape([nf, np])?,
    )?;
    d.set_item("cycles", out.cycles)?;
    d.set_item("adjoint_cycles", out.adjoint_cycles)?;
    d.set_item("periodic_change", out.periodic_change)?;
    Ok(d)
}
