//! An ensemble's variant read by the core in its one canonical order
//! (`oxyline_core::model::native::read_in_order`): the vessels and conditions its patch changed
//! are read by the schema, the others are the base model's canonical dicts, shared as they are,
//! with the periods of the base's conditions found once.
//!
//! [`VariantReader::prepare`] is a variant's whole preparation in one call: its patch merged
//! into the base model by the core (`oxyline_core::model::patch`, its keys checked by the
//! model's path resolver `oxyline_core::model::path`), the elements it changed read, and
//! what the ensemble's workers need (the changed elements and sections), an error traced to
//! the patch paths that caused it.

use super::node::{PyNode, to_python};
use super::schema::transport_facts;
use crate::ensemble::patched_model;
use crate::errors::{ModelError, to_py};
use oxyline_core::model::native::{self, Periods};
use oxyline_core::model::node::{Fields, Kind, Node};
use oxyline_core::model::patch::{self, PatchError, Patched};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyTuple};
use serde_json::{Map, Value};
use std::cell::RefCell;
use std::collections::{HashMap, HashSet};

/// What `VariantReader.read` returns: name, canonical description, period, transport facts.
type Variant<'py> = (String, Bound<'py, PyDict>, Option<f64>, Bound<'py, PyDict>);

/// What `VariantReader.prepare` returns (see there).
type Prepared<'py> = (
    String,
    Option<Bound<'py, PyDict>>,
    Option<Bound<'py, PyDict>>,
    Variant<'py>,
    Bound<'py, PyDict>,
);

/// The sections besides the elements that a variant hands its worker when they differ from
/// the base model's (canonical form).
const WORKER_SECTIONS: [&str; 2] = ["blood", "transport"];

/// The reader of an ensemble's variants: the base model's canonical vessels and conditions
/// (None: none to reuse, every element is read), the periods of the base's conditions, and
/// its canonical `blood` and `transport` sections (a variant hands its worker those that
/// differ).
#[pyclass(module = "oxyline._core", frozen)]
pub(crate) struct VariantReader {
    vessels: Option<Py<PyList>>,
    conditions: Option<Py<PyDict>>,
    periods: HashMap<String, Periods>,
    sections: Vec<(&'static str, Option<Py<PyAny>>)>,
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
        let sections = WORKER_SECTIONS
            .iter()
            .map(|&key| (key, part(key).map(Bound::unbind)))
            .collect();
        Ok(Self {
            vessels: vessels.map(Bound::unbind),
            conditions: conditions.map(Bound::unbind),
            periods,
            sections,
        })
    }

    /// Raise `ModelError` for the first patch of `patches` (variant `numbers[i]`) with a
    /// path that names nothing of the native model `source` (an unknown vessel, node,
    /// section or property): the ensemble's definition is wrong, before anything runs. A
    /// value a patch cannot apply is not raised: it fails only its variant, when prepared.
    fn check(
        &self,
        source: Bound<'_, PyDict>,
        patches: Vec<Bound<'_, PyAny>>,
        numbers: Vec<usize>,
    ) -> PyResult<()> {
        let base = PyNode(source.into_any());
        for (i, p) in patches.into_iter().enumerate() {
            if !p.is_truthy()? {
                continue;
            }
            let k = numbers.get(i).copied().unwrap_or(i);
            if let Err(PatchError::Name(e)) = patch::merge(&base, &PyNode(p), k) {
                return Err(to_py(e));
            }
        }
        Ok(())
    }

    /// Variant `k` of the native model `source` (the base model): `patch` merged into it by
    /// the core and the elements it changed read. Returns `(sections, vessels, outlets,
    /// (name, canonical, period, transport facts), data)`: the canonical `blood` and
    /// `transport` sections that differ from the base's as JSON text, the changed vessels by
    /// index and conditions by node as canonical dicts (None: none), the variant's model as
    /// `read` gives it and its native model dict (sharing every element the patch leaves
    /// alone). Raises `ModelError` naming the variant and the patch path for a path that
    /// names nothing and a value the patch cannot apply, and for a value the schema refuses
    /// the variant and the patch paths that changed the element (`variant 1:
    /// vessels.aorta.radius = -1.0: vessel 'aorta': ...`).
    fn prepare<'py>(
        &self,
        py: Python<'py>,
        source: Bound<'py, PyDict>,
        patch: Bound<'py, PyAny>,
        k: usize,
    ) -> PyResult<Prepared<'py>> {
        let base = PyNode(source.clone().into_any());
        let patched =
            patch::merge(&base, &PyNode(patch.clone()), k).map_err(|e| to_py(e.error().clone()))?;
        let data = patched_model(py, &source, &patched)?;
        let vessels: Vec<usize> = patched.vessels.iter().map(|(i, _)| *i).collect();
        let nodes: Vec<String> = patched.conditions.iter().map(|(n, _)| n.clone()).collect();
        let (variant, values) = self
            .read_in(py, data.clone().into_any(), vessels.clone(), nodes.clone())
            .map_err(|e| traced(py, e, k, &patched, &patch))?;
        let sections = self.changed_sections(&variant.1, values)?;
        let canon = &variant.1;
        let handed = PyDict::new(py);
        let all = canon.get_item("vessels")?;
        let mut order = vessels.clone();
        order.sort_unstable();
        for i in order {
            if let Some(list) = &all {
                handed.set_item(i, list.get_item(i)?)?;
            }
        }
        let outlets = PyDict::new(py);
        if let Some(bcs) = canon.get_item("boundary_conditions")? {
            for node in &nodes {
                outlets.set_item(node, bcs.get_item(node)?)?;
            }
        }
        let some = |d: Bound<'py, PyDict>| (!d.is_empty()).then_some(d);
        Ok((sections, some(handed), some(outlets), variant, data))
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
        Ok(self.read_in(py, data, vessels, nodes)?.0)
    }
}

impl VariantReader {
    /// The canonical `blood` and `transport` sections of a variant (`values`, as read) that
    /// differ from the base's, as compact JSON text for the worker.
    fn changed_sections(
        &self,
        canon: &Bound<'_, PyDict>,
        mut values: Map<String, Value>,
    ) -> PyResult<String> {
        let mut out = Map::new();
        for (key, old) in &self.sections {
            let new = canon.get_item(*key)?;
            let same = match (&new, old) {
                (None, None) => true,
                (Some(a), Some(b)) => a.eq(b.bind(canon.py()))?,
                _ => false,
            };
            if !same {
                out.insert((*key).into(), values.remove(*key).unwrap_or(Value::Null));
            }
        }
        Ok(Value::Object(out).to_string())
    }

    /// The variant read in the core's order, and its canonical `blood` and `transport`
    /// sections as JSON values.
    fn read_in<'py>(
        &self,
        py: Python<'py>,
        data: Bound<'py, PyAny>,
        vessels: Vec<usize>,
        nodes: Vec<String>,
    ) -> PyResult<(Variant<'py>, Map<String, Value>)> {
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
        let mut values = Map::new();
        if let Some(b) = read.header.canonical.get("blood") {
            values.insert("blood".into(), b.clone());
        }
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
            values.insert("transport".into(), s);
        }
        Ok(((read.header.name, canon, read.period, info), values))
    }
}

/// A schema error of a patched variant, prefixed by the variant and the patch paths that
/// changed the element it is about (its `element` attribute; None: the other sections, whose
/// paths are the patch's scalar leaves outside `vessels`, `boundary_conditions`, `scale`).
fn traced(
    py: Python<'_>,
    e: PyErr,
    k: usize,
    patched: &Patched<PyNode<'_>>,
    patch: &Bound<'_, PyAny>,
) -> PyErr {
    if !e.is_instance_of::<ModelError>(py) {
        return e;
    }
    let value = e.value(py);
    let text = value.str().map(|s| s.to_string()).unwrap_or_default();
    let prefix = format!("variant {k}: ");
    if text.starts_with(&prefix) {
        return e;
    }
    let element = value.getattr("element").ok().filter(|x| !x.is_none());
    let paths = match element.map(|x| x.extract::<(String, Bound<'_, PyAny>)>()) {
        Some(Ok((kind, at))) if kind == "vessel" => at
            .extract::<usize>()
            .ok()
            .and_then(|i| patched.vessel_paths.iter().find(|(j, _)| *j == i))
            .map(|(_, p)| p.clone())
            .unwrap_or_default(),
        Some(Ok((_, at))) => at
            .extract::<String>()
            .ok()
            .and_then(|n| patched.condition_paths.iter().find(|(m, _)| *m == n))
            .map(|(_, p)| p.clone())
            .unwrap_or_default(),
        Some(Err(_)) => Vec::new(),
        None => section_paths(patch),
    };
    let message = if paths.is_empty() {
        format!("{prefix}{text}")
    } else {
        format!("{prefix}{}: {text}", paths.join("; "))
    };
    ModelError::new_err(message)
}

/// The scalar leaves (`path = value`) of a patch's sections other than its elements' and
/// `scale`: what a schema error of the blood, oxygen, transport or period is traced to.
fn section_paths(patch: &Bound<'_, PyAny>) -> Vec<String> {
    let mut out = Vec::new();
    for (key, value) in PyNode(patch.clone()).entries() {
        if !["vessels", "boundary_conditions", "scale"].contains(&key.as_str()) {
            scalar_leaves(&value, &key, &mut out);
        }
    }
    out
}

fn scalar_leaves(value: &PyNode<'_>, path: &str, out: &mut Vec<String>) {
    if value.is_map() {
        for (key, v) in value.entries() {
            scalar_leaves(&v, &format!("{path}.{key}"), out);
        }
    } else if matches!(
        value.kind(),
        Kind::Bool | Kind::Int | Kind::Float | Kind::Str
    ) {
        out.push(format!("{path} = {}", value.repr()));
    }
}
