//! The core's schema reader (`oxyline_core::model::native`) called on the user's Python
//! objects: vessels and boundary conditions on their own, the transport sections and the run
//! settings. Each returns the canonical SI description as Python objects.

use super::node::{PyNode, to_python};
use crate::errors::to_py;
use oxyline_core::Error;
use oxyline_core::model::node::{Fields, Node};
use oxyline_core::model::units::Units;
use oxyline_core::model::{native, species};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

/// Periods of the elements that repeat, with the element.
type Periods = Vec<(f64, String)>;

/// The unit system named `units` (checked by `read_header` before).
pub(crate) fn units(units: &str) -> PyResult<Units> {
    Units::parse(units).ok_or_else(|| {
        to_py(Error::model(
            "model",
            format!("units must be 'SI' or 'cgs', got '{units}'"),
        ))
    })
}

/// The canonical dicts of the native `vessels` (a list), in order.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn read_vessels<'py>(
    py: Python<'py>,
    vessels: &Bound<'py, PyList>,
    units: &str,
) -> PyResult<Vec<Bound<'py, PyAny>>> {
    let u = self::units(units)?;
    vessels
        .iter()
        .enumerate()
        .map(|(i, v)| {
            let c = native::vessel(&Fields::new(PyNode(v)), i, u).map_err(to_py)?;
            to_python(py, &c)
        })
        .collect()
}

/// Canonical boundary conditions by node and the periods of their waveforms, with the
/// element they come from.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn read_conditions<'py>(
    py: Python<'py>,
    bcs: Bound<'py, PyAny>,
    units: &str,
) -> PyResult<(Bound<'py, PyDict>, Periods)> {
    let bcs = PyNode(bcs);
    native::check_conditions(&bcs).map_err(to_py)?;
    let u = self::units(units)?;
    let out = PyDict::new(py);
    let mut periods = Vec::new();
    for (node, bc) in Node::entries(&bcs) {
        let el = format!("boundary condition '{node}'");
        let c = native::boundary_condition(&Fields::new(bc), u, &el).map_err(to_py)?;
        periods.extend(native::condition_periods(&c, &el));
        out.set_item(node, to_python(py, &c)?)?;
    }
    Ok((out, periods))
}

/// The transport sections of `data` alone (no blood: a `graetz` wall without its kinematic
/// viscosity), read against a pressure unit factor, a period and a run duration.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn transport_section<'py>(
    py: Python<'py>,
    data: Bound<'py, PyAny>,
    pressure_factor: f64,
    period: Option<f64>,
    duration: Option<f64>,
) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyDict>)> {
    let ctx = species::Context {
        pressure_factor,
        period,
        duration,
        kinematic_viscosity: None,
    };
    let (section, info) = transport(py, &PyNode(data), &ctx)?;
    let section = match section {
        Some(s) => to_python(py, &s)?,
        None => py.None().into_bound(py),
    };
    Ok((section, info))
}

/// (canonical transport section or None, facts for results); a wall that needs it warns
/// (`oxyline.HemoglobinFacilitationWarning`).
pub(crate) fn transport<'py>(
    py: Python<'py>,
    node: &PyNode<'py>,
    ctx: &species::Context,
) -> PyResult<(Option<serde_json::Value>, Bound<'py, PyDict>)> {
    transport_facts(py, species::read(node, ctx).map_err(to_py)?)
}

/// A transport section read by the core as (canonical section or None, facts for results:
/// species names, the oxygen species and its solubility per mmHg); its warnings are emitted
/// (`oxyline.HemoglobinFacilitationWarning`).
pub(crate) fn transport_facts(
    py: Python<'_>,
    tr: Option<species::Transport>,
) -> PyResult<(Option<serde_json::Value>, Bound<'_, PyDict>)> {
    let info = PyDict::new(py);
    let Some(tr) = tr else {
        return Ok((None, info));
    };
    warn_facilitation(py, &tr.warnings)?;
    info.set_item("species", &tr.species)?;
    info.set_item("oxygen", tr.oxygen.as_ref().map(|o| o.0.clone()))?;
    info.set_item("solubility", tr.oxygen.as_ref().map(|o| o.1))?;
    Ok((Some(tr.section), info))
}

/// The transport section's `warnings` as `oxyline.HemoglobinFacilitationWarning`s.
pub(crate) fn warn_facilitation(py: Python<'_>, warnings: &[String]) -> PyResult<()> {
    if warnings.is_empty() {
        return Ok(());
    }
    let category = py
        .import("oxyline.errors")?
        .getattr("HemoglobinFacilitationWarning")?;
    for w in warnings {
        let text = std::ffi::CString::new(w.as_str()).unwrap_or_default();
        PyErr::warn(py, &category, &text, 2)?;
    }
    Ok(())
}

/// The run settings of a model's `simulation` section with `simulate`'s keyword overrides,
/// checked and defaulted by the core (`oxyline_core::model::settings`); `period`: the model's.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn resolve_settings<'py>(
    py: Python<'py>,
    sim: Bound<'py, PyAny>,
    overrides: Bound<'py, PyAny>,
    period: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    use super::node::PySetting;
    let s = oxyline_core::model::settings::resolve(&PySetting(sim), &PySetting(overrides), period)
        .map_err(to_py)?;
    let d = PyDict::new(py);
    d.set_item("period", s.period)?;
    d.set_item("cycles", s.cycles)?;
    d.set_item("dt", s.dt)?;
    d.set_item("method", s.method)?;
    d.set_item("output_every", s.output_every)?;
    d.set_item("output_all_cycles", s.output_all_cycles)?;
    d.set_item("until_periodic", s.until_periodic)?;
    d.set_item("max_cycles", s.max_cycles)?;
    d.set_item("rho_infty", s.rho_infty)?;
    d.set_item("start", s.start)?;
    d.set_item("segments", s.segments)?;
    d.set_item("newton_atol", s.newton_atol)?;
    d.set_item("max_iterations", s.max_iterations)?;
    d.set_item("transport", s.transport)?;
    d.set_item("rtol", s.rtol)?;
    d.set_item("rtol_default", s.rtol_default)?;
    d.set_item("threads", s.threads)?;
    d.set_item("estimate_space_error", s.estimate_space_error)?;
    d.set_item("estimate_time_error", s.estimate_time_error)?;
    d.set_item("meet_rtol", s.meet_rtol)?;
    match s.atol {
        Some(atol) => {
            let a = PyDict::new(py);
            for (kind, v) in atol {
                a.set_item(kind, v)?;
            }
            d.set_item("atol", a)?;
        }
        None => d.set_item("atol", py.None())?,
    }
    Ok(d)
}
