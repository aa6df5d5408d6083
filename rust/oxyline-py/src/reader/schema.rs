//! The core's schema reader (`oxyline_core::model::native`) called on the user's Python
//! objects: the model's top level, its vessels and boundary conditions, the period check and
//! the simulation section. Each returns the canonical SI description as Python objects.

use super::node::{PyNode, to_python};
use crate::errors::to_py;
use oxyline_core::Error;
use oxyline_core::model::native;
use oxyline_core::model::node::{Fields, Node};
use oxyline_core::model::units::Units;
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

/// (name, canonical top-level sections) of a native model dict.
#[pyfunction]
pub(crate) fn read_header<'py>(
    py: Python<'py>,
    data: Bound<'py, PyAny>,
) -> PyResult<(String, Bound<'py, PyAny>)> {
    let header = native::header(&PyNode(data)).map_err(to_py)?;
    let canon = to_python(py, &serde_json::Value::Object(header.canonical))?;
    Ok((header.name, canon))
}

/// The canonical dicts of the native `vessels` (a list), in order.
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

/// The model period: the model's `period` (None: not given) checked against every
/// element's.
#[pyfunction]
pub(crate) fn check_periods(data: Bound<'_, PyAny>, periods: Periods) -> PyResult<Option<f64>> {
    let period = native::period(&PyNode(data)).map_err(to_py)?;
    native::check_periods(period, &periods).map_err(to_py)
}

/// The keys of a model's `simulation` section and its method.
#[pyfunction]
pub(crate) fn check_simulation(sim: Bound<'_, PyAny>) -> PyResult<()> {
    native::simulation(&PyNode(sim)).map_err(to_py)
}

/// The run settings of a model's `simulation` section with `simulate`'s keyword overrides,
/// checked and defaulted by the core (`oxyline_core::model::settings`); `period`: the model's.
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
