//! An ensemble's variant read by the core in its one canonical order
//! (`oxyline_core::model::native::read_in_order`): the vessels and conditions its patch changed
//! are read by the schema, the others are the base model's canonical dicts, shared as they are,
//! with the periods of the base's conditions found once.

use super::node::{PyNode, to_python};
use super::schema::transport_facts;
use crate::errors::to_py;
use oxyline_core::model::native::{self, Periods};
use oxyline_core::model::node::Fields;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use serde_json::Value;
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};

/// What `VariantReader.read` returns: name, canonical description, period, transport facts.
type Variant<'py> = (String, Bound<'py, PyDict>, Option<f64>, Bound<'py, PyDict>);

/// The reader of an ensemble's variants: the base model's canonical vessels and conditions
/// (None: none to reuse, every element is read) and the periods of the base's conditions.
#[pyclass(module = "oxyline._core", frozen)]
pub(crate) struct VariantReader {
    vessels: Option<Py<PyList>>,
    conditions: Option<Py<PyDict>>,
    periods: HashMap<String, Periods>,
}

#[oxyline_py_guard::guard]
#[pymethods]
impl VariantReader {
    /// `base`: a canonical model dict (`Model.canonical`) whose elements variants may share.
    #[new]
    #[pyo3(signature = (base = None))]
    fn new(base: Option<Bound<'_, PyDict>>) -> PyResult<Self> {
        let part = |key: &str| base.as_ref().and_then(|b| b.get_item(key).ok().flatten());
        let vessels = part("vessels").and_then(|v| v.cast_into::<PyList>().ok());
        let conditions = part("boundary_conditions").and_then(|c| c.cast_into::<PyDict>().ok());
        let mut periods = HashMap::new();
        for (node, c) in conditions.iter().flat_map(|d| d.iter()) {
            let node: String = node.extract()?;
            let el = native::condition_element(&node);
            periods.insert(node, native::condition_periods(&PyNode(c), &el));
        }
        Ok(Self {
            vessels: vessels.map(Bound::unbind),
            conditions: conditions.map(Bound::unbind),
            periods,
        })
    }

    /// The canonical description of the native model `data` (a variant of the base), read by
    /// the core in its one order, and its (name, period, transport facts). The base's
    /// canonical vessels and conditions are reused, except the vessels at the indices
    /// `vessels` and the conditions of the nodes `nodes`. A `ModelError` about one element
    /// has the attribute `element`: `("vessel", index)` or `("condition", node)`, for the
    /// caller to name the patch paths that changed it (None: the other sections).
    #[pyo3(signature = (data, vessels = Vec::new(), nodes = Vec::new()))]
    fn read<'py>(
        &self,
        py: Python<'py>,
        data: Bound<'py, PyAny>,
        vessels: Vec<usize>,
        nodes: Vec<String>,
    ) -> PyResult<Variant<'py>> {
        self.read_in(py, data, vessels, nodes)
    }
}

impl VariantReader {
    fn read_in<'py>(
        &self,
        py: Python<'py>,
        data: Bound<'py, PyAny>,
        vessels: Vec<usize>,
        nodes: Vec<String>,
    ) -> PyResult<Variant<'py>> {
        let changed_vessels: HashSet<usize> = vessels.into_iter().collect();
        let changed_nodes: HashSet<String> = nodes.into_iter().collect();
        let base_vessels = self.vessels.as_ref().map(|v| v.bind(py));
        let base_conditions = self.conditions.as_ref().map(|c| c.bind(py));
        // which element failed, and a failure of Python itself (not the schema's)
        let failed: RefCell<Option<Bound<'py, PyTuple>>> = RefCell::new(None);
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
                if !changed_vessels.contains(&i)
                    && let Some(c) = base_vessels.and_then(|b| b.get_item(i).ok())
                {
                    return Ok(PyNode(c));
                }
                let c = native::vessel(&Fields::new(v), i, units).inspect_err(|_| {
                    drop(failed.replace(("vessel", i).into_pyobject(py).ok()));
                })?;
                to_node(c)
            },
            |node, bc, units| {
                if !changed_nodes.contains(node)
                    && let Some(c) = base_conditions.and_then(|b| b.get_item(node).ok().flatten())
                {
                    return Ok((PyNode(c), self.periods.get(node).cloned()));
                }
                let el = native::condition_element(node);
                let c =
                    native::boundary_condition(&Fields::new(bc), units, &el).inspect_err(|_| {
                        drop(failed.replace(("condition", node).into_pyobject(py).ok()));
                    })?;
                Ok((to_node(c)?, None))
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
}
