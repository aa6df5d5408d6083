//! An ensemble's variant read by the core in its one canonical order
//! (`oxyline_core::model::native::read_in_order`): the vessels and conditions its patch changed
//! are read by the schema, the others are the base model's canonical dicts, shared as they are.

use super::node::{PyNode, to_python};
use super::schema::transport_facts;
use crate::errors::to_py;
use oxyline_core::model::native;
use oxyline_core::model::node::Fields;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use serde_json::Value;
use std::cell::RefCell;
use std::collections::HashSet;

/// What `read_variant` returns: name, canonical description, period, transport facts.
type Variant<'py> = (String, Bound<'py, PyDict>, Option<f64>, Bound<'py, PyDict>);

/// The element a schema error is about: `("vessel", index)` or `("condition", node)`.
type Element<'py> = Bound<'py, PyTuple>;

/// The base model's canonical elements a variant may reuse, and which ones it changed.
struct Base<'py> {
    vessels: Option<Bound<'py, PyList>>,
    conditions: Option<Bound<'py, PyDict>>,
    changed_vessels: HashSet<usize>,
    changed_nodes: HashSet<String>,
}

impl<'py> Base<'py> {
    fn vessel(&self, i: usize) -> Option<PyNode<'py>> {
        if self.changed_vessels.contains(&i) {
            return None;
        }
        let list = self.vessels.as_ref()?;
        list.get_item(i).ok().map(PyNode)
    }
    fn condition(&self, node: &str) -> Option<PyNode<'py>> {
        if self.changed_nodes.contains(node) {
            return None;
        }
        self.conditions
            .as_ref()?
            .get_item(node)
            .ok()
            .flatten()
            .map(PyNode)
    }
}

/// The canonical description of the native model `data` (an ensemble's variant), read by the
/// core in its one order, and its (name, period, transport facts). The canonical vessels and
/// conditions of `base` (a canonical model dict, None: read everything) are reused, except the
/// vessels at the indices `vessels` and the conditions of the nodes `nodes`. A `ModelError`
/// about one element has the attribute `element`: `("vessel", index)` or
/// `("condition", node)`, for the caller to name the patch paths that changed it (None: the
/// other sections).
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (data, base = None, vessels = Vec::new(), nodes = Vec::new()))]
pub(crate) fn read_variant<'py>(
    py: Python<'py>,
    data: Bound<'py, PyAny>,
    base: Option<Bound<'py, PyDict>>,
    vessels: Vec<usize>,
    nodes: Vec<String>,
) -> PyResult<Variant<'py>> {
    let part = |key: &str| base.as_ref().and_then(|b| b.get_item(key).ok().flatten());
    let base = Base {
        vessels: part("vessels").and_then(|v| v.cast_into::<PyList>().ok()),
        conditions: part("boundary_conditions").and_then(|c| c.cast_into::<PyDict>().ok()),
        changed_vessels: vessels.into_iter().collect(),
        changed_nodes: nodes.into_iter().collect(),
    };
    // which element failed, and a failure of Python itself (not the schema's)
    let failed: RefCell<Option<Element<'py>>> = RefCell::new(None);
    let python: RefCell<Option<PyErr>> = RefCell::new(None);
    let to_node = |c: Value| {
        to_python(py, &c).map(PyNode).map_err(|e| {
            python.replace(Some(e));
            oxyline_core::Error::model("model", "not representable in Python")
        })
    };
    let read = native::read_in_order(
        &PyNode(data),
        |i, v, units| {
            if let Some(c) = base.vessel(i) {
                return Ok(c);
            }
            let c = native::vessel(&Fields::new(v), i, units)
                .inspect_err(|_| drop(failed.replace(("vessel", i).into_pyobject(py).ok())))?;
            to_node(c)
        },
        |node, bc, units| {
            if let Some(c) = base.condition(node) {
                return Ok(c);
            }
            let el = native::condition_element(node);
            let c = native::boundary_condition(&Fields::new(bc), units, &el).inspect_err(|_| {
                drop(failed.replace(("condition", node).into_pyobject(py).ok()))
            })?;
            to_node(c)
        },
    );
    let read = match read {
        Ok(read) => read,
        Err(e) => {
            if let Some(e) = python.take() {
                return Err(e);
            }
            let err = to_py(e);
            let element = match failed.take() {
                Some(t) => t.into_any(),
                None => py.None().into_bound(py),
            };
            err.value(py).setattr("element", element)?;
            return Err(err);
        }
    };
    let canon = to_python(py, &Value::Object(read.header.canonical))?;
    let canon = canon.cast_into::<PyDict>()?;
    let vessels = PyList::new(py, read.vessels.into_iter().map(|v| v.0))?;
    canon.set_item("vessels", vessels)?;
    let bcs = PyDict::new(py);
    for (node, c) in read.conditions {
        bcs.set_item(node, c.0)?;
    }
    canon.set_item("boundary_conditions", bcs)?;
    let (section, info) = transport_facts(py, read.transport)?;
    if let Some(s) = section {
        canon.set_item("transport", to_python(py, &s)?)?;
    }
    Ok((read.header.name, canon, read.period, info))
}
