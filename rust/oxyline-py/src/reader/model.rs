//! The one entry of a native model dict into the core: [`read_model`] reads the whole model
//! (top level, vessels, boundary conditions, periods, simulation keys, species transport) with
//! the core's schema (`oxyline_core::model`) in one call; the network is then built from what
//! it read (`Network.from_parts`) without a second crossing. [`canonical_model`] writes the
//! full canonical description (for display and ensembles) with the core's own
//! `model::native::canonical`, whose pieces `read_model` shares.

use super::de;
use super::native::NativeParts;
use super::node::{PyNode, to_python};
use super::schema::{transport, warn_facilitation};
use crate::errors::to_py;
use oxyline_core::Error;
use oxyline_core::NetworkSpec;
use oxyline_core::model::native;
use oxyline_core::model::node::Node;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use serde_json::Value;

/// What `read_model` returns: the parts, name, period, canonical transport section (None
/// without species) and transport facts.
type Read<'py> = (
    Bound<'py, NativeParts>,
    String,
    Option<f64>,
    Bound<'py, PyAny>,
    Bound<'py, PyDict>,
);

/// The conditions of the nodes `only` among the mapping `bcs`, as entries.
fn entries_of<'py>(
    bcs: &Bound<'py, PyAny>,
    only: &[Bound<'py, PyAny>],
) -> PyResult<Vec<(String, PyNode<'py>)>> {
    only.iter()
        .map(|n| Ok((n.str()?.to_string(), PyNode(bcs.get_item(n)?))))
        .collect()
}

/// The model's `boundary_conditions` (an empty mapping when missing).
fn conditions_node<'py>(data: &PyNode<'py>) -> PyNode<'py> {
    data.get("boundary_conditions")
        .unwrap_or_else(|| PyNode(PyDict::new(data.0.py()).into_any()))
}

/// Read a native model dict: (the parts the network is built from, name, period, canonical
/// transport section or None, transport facts for results). The plain vessels and outlets
/// (the bulk of a large tree) are read straight into the parts; every other element goes
/// through the core's full schema check.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn read_model<'py>(py: Python<'py>, data: Bound<'py, PyAny>) -> PyResult<Read<'py>> {
    let node = PyNode(data);
    let header = native::header(&node).map_err(to_py)?;
    let units = header.units;
    let vessels = node.0.get_item("vessels")?;
    let vessels = vessels.cast::<PyList>()?;
    let mut parts = NativeParts::read(vessels, units)?;
    let vessel_periods = parts.read_rest(vessels, units)?;
    let bcs = conditions_node(&node);
    let entries = match bcs.0.cast::<PyDict>() {
        Ok(d) if d.is_exact_instance_of::<PyDict>() => {
            let slow = parts.read_outlets(d, units);
            entries_of(&bcs.0, &slow)?
        }
        _ => native::condition_entries(&node).map_err(to_py)?,
    };
    let (slow, mut periods) = native::conditions(entries, units).map_err(to_py)?;
    periods.extend(vessel_periods);
    let period = native::period_and_simulation(&node, &periods).map_err(to_py)?;
    let mut rest = header.canonical;
    rest.insert("vessels".into(), Value::Array(Vec::new()));
    rest.insert("boundary_conditions".into(), Value::Object(slow));
    let ctx = native::transport_context(&node, &rest["blood"], units, period);
    let (section, info) = transport(py, &node, &ctx)?;
    let section = match section {
        Some(s) => {
            let out = to_python(py, &s)?;
            rest.insert("transport".into(), s);
            out
        }
        None => py.None().into_bound(py),
    };
    parts.rest = Some(rest);
    Ok((Bound::new(py, parts)?, header.name, period, section, info))
}

/// The full canonical SI description of a native model dict (every vessel and condition as
/// its canonical dict), read by the core's `canonical` over the Python objects; a wall that
/// needs it warns (`oxyline.HemoglobinFacilitationWarning`).
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn canonical_model<'py>(
    py: Python<'py>,
    data: Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let (canon, warnings) = native::canonical(&PyNode(data)).map_err(to_py)?;
    warn_facilitation(py, &warnings)?;
    to_python(py, &canon)
}

/// The highest significant frequency (Hz) of a native model dict's forcing and the
/// segmentation tolerance it was found at (`rtol`, else the model's `segmentation: rtol`, else
/// the default): the `segments: auto` rule's (`oxyline_core::assemble::auto_segments`).
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (data, rtol = None))]
pub(crate) fn forcing_frequency(data: Bound<'_, PyAny>, rtol: Option<f64>) -> PyResult<(f64, f64)> {
    use oxyline_core::assemble::auto_segments;
    let node = PyNode(data);
    let header = native::header(&node).map_err(to_py)?;
    let rtol = rtol
        .or_else(|| {
            header
                .canonical
                .get("segmentation_rtol")
                .and_then(Value::as_f64)
        })
        .unwrap_or(auto_segments::DEFAULT_RTOL);
    if !(rtol > 0.0 && rtol < 1.0) {
        return Err(to_py(oxyline_core::Error::model(
            "segmentation",
            format!("rtol must be in (0, 1), got {rtol}"),
        )));
    }
    // the flow and pressure conditions only (a structured tree is grown later)
    let all = conditions_node(&node);
    let forcing: Vec<Bound<'_, PyAny>> = Node::entries(&all)
        .into_iter()
        .filter(|(_, bc)| {
            bc.get("type")
                .and_then(|t| t.text())
                .is_some_and(|t| t == "flow" || t == "pressure")
        })
        .map(|(n, _)| pyo3::types::PyString::new(all.0.py(), &n).into_any())
        .collect();
    native::check_conditions(&all).map_err(to_py)?;
    let (bcs, _) =
        native::conditions(entries_of(&all.0, &forcing)?, header.units).map_err(to_py)?;
    let specs = bcs
        .into_iter()
        .map(|(n, v)| {
            serde_json::from_value::<oxyline_core::model::BoundarySpec>(v).map_err(|e| {
                to_py(oxyline_core::Error::model(
                    format!("boundary condition '{n}'"),
                    e.to_string(),
                ))
            })
        })
        .collect::<PyResult<Vec<_>>>()?;
    Ok((auto_segments::forcing_frequency(&specs, rtol), rtol))
}

/// A canonical SI model given as its dicts (an ensemble's variant, a model rebuilt from its
/// `canonical`), read by the core's serde types in place: each vessel and condition on its
/// own, so that an error names it, then the rest of the top level.
pub(crate) fn canonical_spec(model: &Bound<'_, PyAny>) -> PyResult<NetworkSpec> {
    let py = model.py();
    let whole = || "model".to_owned();
    let Ok(d) = model.cast::<PyDict>() else {
        return de::read(model, whole).map_err(to_py);
    };
    let rest = d.copy()?;
    let vessels = rest
        .get_item("vessels")?
        .filter(|v| v.is_instance_of::<PyList>());
    if vessels.is_some() {
        rest.set_item("vessels", PyList::empty(py))?;
    }
    let bcs = rest.get_item("boundary_conditions")?;
    let bcs = bcs.and_then(|b| b.cast_into::<PyDict>().ok());
    if bcs.is_some() {
        rest.set_item("boundary_conditions", PyDict::new(py))?;
    }
    let mut spec: NetworkSpec = de::read(rest.as_any(), whole).map_err(to_py)?;
    for (i, v) in vessels
        .iter()
        .flat_map(|l| l.try_iter())
        .flatten()
        .enumerate()
    {
        let v = v?;
        spec.vessels
            .push(de::read(&v, || vessel_name(i, &v)).map_err(to_py)?);
    }
    for (node, bc) in bcs.iter().flat_map(|d| d.iter()) {
        let node: String = node.extract().map_err(|_| {
            to_py(Error::model(
                "boundary_conditions",
                format!(
                    "node {} is not a string",
                    node.repr().map(|r| r.to_string()).unwrap_or_default()
                ),
            ))
        })?;
        let spec_bc = de::read(&bc, || format!("boundary condition '{node}'")).map_err(to_py)?;
        spec.boundary_conditions.insert(node, spec_bc);
    }
    Ok(spec)
}

/// `vessel 'name'` of a canonical vessel dict (`vessel #i` when it has no name).
pub(crate) fn vessel_name(i: usize, v: &Bound<'_, PyAny>) -> String {
    let name = v
        .cast::<PyDict>()
        .ok()
        .and_then(|d| d.get_item("name").ok().flatten());
    match name {
        Some(n) => format!("vessel '{n}'"),
        None => format!("vessel #{i}"),
    }
}
