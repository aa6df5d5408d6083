//! The importers' calls into the core: what reading a file format needs beyond its keys
//! (openBF's linearisation pressures, svZeroDSolver's time-table lookup), each one call.

use crate::errors::{ModelError, to_py};
use oxyline_core::model::node::py_repr;
use oxyline_core::model::openbf::Wall;
use oxyline_core::model::openbf::steady::{SteadyVessel, Terminal, mean_pressures};
use oxyline_core::waveform::{FmodTableFault, fmod_table};
use pyo3::prelude::*;

/// One openBF vessel as the importer reads it: from and to node, length, proximal and distal
/// reference radius, Young's modulus, wall thickness (None: the ADAN law), external
/// pressure, the element as messages name it and the file's label.
type OpenbfVessel = (
    String,
    String,
    f64,
    f64,
    f64,
    f64,
    Option<f64>,
    f64,
    String,
    String,
);

/// openBF's `linearize="mean"` pressures: (inlet end, outlet end) of every vessel on the
/// steady network of the mean inflow `flow` at node `inlet` into the `terminals` (node, total
/// resistance, outflow pressure), with blood of `viscosity`, the radii on the tube law at
/// those pressures (`oxyline_core::model::openbf::steady`).
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn openbf_mean_pressures(
    py: Python<'_>,
    vessels: Vec<OpenbfVessel>,
    inlet: String,
    flow: f64,
    terminals: Vec<(String, f64, f64)>,
    viscosity: f64,
) -> PyResult<Vec<(f64, f64)>> {
    let vessels: Vec<SteadyVessel> = vessels
        .into_iter()
        .map(
            |(from, to, length, rp, rd, e, h, pext, element, label)| SteadyVessel {
                wall: Wall {
                    length,
                    radius: (rp, rd),
                    youngs_modulus: e,
                    wall_thickness: h,
                },
                external_pressure: pext,
                from,
                to,
                element,
                label,
            },
        )
        .collect();
    let terminals: Vec<Terminal> = terminals
        .into_iter()
        .map(|(node, resistance, pressure)| Terminal {
            node,
            resistance,
            pressure,
        })
        .collect();
    py.detach(|| mean_pressures(&vessels, &inlet, flow, &terminals, viscosity))
        .map_err(to_py)
}

/// An svZeroDSolver time table (`t`, `v`) of `element` as the table over [0, P] that the
/// core's periodic table evaluates as svZeroDSolver does (`oxyline_core::waveform::fmod_table`):
/// `ModelError` when `t` does not increase, `UnsupportedElement` when it starts before 0.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn svzerod_periodic_table(
    py: Python<'_>,
    t: Vec<f64>,
    v: Vec<f64>,
    element: &str,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    if t.len() != v.len() {
        return Err(ModelError::new_err(format!(
            "{element}: 't' has {} entries but the values have {}",
            t.len(),
            v.len()
        )));
    }
    match fmod_table(&t, &v) {
        Ok(table) => Ok(table),
        Err(FmodTableFault::NotIncreasing(i)) => Err(ModelError::new_err(format!(
            "{element}: 't' must be strictly increasing: t[{i}] = {} <= t[{}] = {}",
            py_repr(t[i]),
            i - 1,
            py_repr(t[i - 1])
        ))),
        Err(FmodTableFault::StartsBeforeZero) => {
            let unsupported = py.import("oxyline.errors")?.getattr("UnsupportedElement")?;
            Err(PyErr::from_value(unsupported.call1((format!(
                "{element}: a time table starting before 0 (t[0] = {}) is not supported",
                py_repr(t[0])
            ),))?))
        }
    }
}
