//! Python objects as the core's model values ([`Node`]): the core's schema reader reads the
//! user's dicts in place, with Python's own `repr`, `str` and type names in its messages.
//! And the canonical description back as Python objects ([`to_python`]).

use oxyline_core::model::node::{Kind, Node};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping, PyString, PyTuple};
use serde_json::Value;

/// `v` as a number, when its kind (the node's) is one.
fn number(v: &Bound<'_, PyAny>, kind: Kind) -> Option<f64> {
    match kind {
        Kind::Int | Kind::Float => v.extract::<f64>().ok(),
        _ => None,
    }
}

/// `v` as an integer, when its kind (the node's) is one.
fn integer(v: &Bound<'_, PyAny>, kind: Kind) -> Option<i64> {
    (kind == Kind::Int)
        .then(|| v.extract::<i64>().ok())
        .flatten()
}

/// A Python value of a model description.
#[derive(Clone)]
pub(crate) struct PyNode<'py>(pub Bound<'py, PyAny>);

impl Node for PyNode<'_> {
    fn kind(&self) -> Kind {
        let v = &self.0;
        if v.is_none() {
            Kind::Null
        } else if v.is_instance_of::<PyBool>() {
            Kind::Bool
        } else if v.is_instance_of::<PyInt>() {
            Kind::Int
        } else if v.is_instance_of::<PyFloat>() {
            Kind::Float
        } else if v.is_instance_of::<PyString>() {
            Kind::Str
        } else if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
            Kind::List
        } else if v.is_instance_of::<PyDict>() || v.cast::<PyMapping>().is_ok() {
            Kind::Map
        } else {
            Kind::Other
        }
    }
    fn number(&self) -> Option<f64> {
        number(&self.0, self.kind())
    }
    fn integer(&self) -> Option<i64> {
        integer(&self.0, self.kind())
    }
    fn text(&self) -> Option<String> {
        (self.kind() == Kind::Str)
            .then(|| self.0.extract::<String>().ok())
            .flatten()
    }
    fn get(&self, key: &str) -> Option<Self> {
        if let Ok(d) = self.0.cast::<PyDict>() {
            return d.get_item(key).ok().flatten().map(PyNode);
        }
        let m = self.0.cast::<PyMapping>().ok()?;
        if !m.contains(key).ok()? {
            return None;
        }
        m.get_item(key).ok().map(PyNode)
    }
    fn entries(&self) -> Vec<(String, Self)> {
        // a text key as it is (no `str()` call): the common case, once per key of a vessel
        let show = |k: &Bound<'_, PyAny>| match k.cast::<PyString>() {
            Ok(s) => s.to_str().map(str::to_owned).unwrap_or_default(),
            Err(_) => k.str().map(|s| s.to_string()).unwrap_or_default(),
        };
        if let Ok(d) = self.0.cast::<PyDict>() {
            return d.iter().map(|(k, v)| (show(&k), PyNode(v))).collect();
        }
        let Ok(m) = self.0.cast::<PyMapping>() else {
            return Vec::new();
        };
        let Ok(keys) = m.keys() else {
            return Vec::new();
        };
        keys.iter()
            .filter_map(|k| m.get_item(&k).ok().map(|v| (show(&k), PyNode(v))))
            .collect()
    }
    fn items(&self) -> Option<Vec<Self>> {
        let v = &self.0;
        if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
            return v
                .try_iter()
                .ok()
                .map(|it| it.filter_map(|x| x.ok().map(PyNode)).collect());
        }
        // an array: its `tolist()` (as Python's `list(x.tolist())`)
        let list = v.call_method0("tolist").ok()?;
        let it = list.try_iter().ok()?;
        Some(it.filter_map(|x| x.ok().map(PyNode)).collect())
    }
    fn repr(&self) -> String {
        self.0
            .repr()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "<?>".into())
    }
    fn show(&self) -> String {
        self.0
            .str()
            .map(|s| s.to_string())
            .unwrap_or_else(|_| "<?>".into())
    }
    fn type_name(&self) -> String {
        self.0
            .get_type()
            .name()
            .map(|s| s.to_string())
            .unwrap_or_default()
    }
    fn truthy(&self) -> bool {
        self.0.is_truthy().unwrap_or(true)
    }
    fn callable(&self) -> bool {
        self.0.is_callable()
    }
    fn call(&self, t: f64) -> Result<Self, String> {
        self.0.call1((t,)).map(PyNode).map_err(|e| e.to_string())
    }
}

/// A canonical JSON value as Python objects (floats stay floats, integers ints).
pub(crate) fn to_python<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) if !n.is_f64() => i.into_pyobject(py)?.into_any(),
            (_, Some(x)) => PyFloat::new(py, x).into_any(),
            _ => py.None().into_bound(py),
        },
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Array(a) => {
            let items = a
                .iter()
                .map(|x| to_python(py, x))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, to_python(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// A run setting's Python value: as [`PyNode`], and numpy's numbers and bools count as
/// numbers and bools (`numbers.Integral`, `numbers.Real`, `numpy.bool_`), as `simulate`
/// has always taken them.
#[derive(Clone)]
pub(crate) struct PySetting<'py>(pub Bound<'py, PyAny>);

impl<'py> PySetting<'py> {
    fn node(&self) -> PyNode<'py> {
        PyNode(self.0.clone())
    }
    fn is(&self, module: &str, name: &str) -> bool {
        let py = self.0.py();
        py.import(module)
            .and_then(|m| m.getattr(name))
            .and_then(|t| self.0.is_instance(&t))
            .unwrap_or(false)
    }
}

impl<'py> Node for PySetting<'py> {
    fn kind(&self) -> Kind {
        match self.node().kind() {
            Kind::Other if self.is("numpy", "bool_") => Kind::Bool,
            Kind::Other if self.is("numbers", "Integral") => Kind::Int,
            Kind::Other if self.is("numbers", "Real") => Kind::Float,
            k => k,
        }
    }
    fn number(&self) -> Option<f64> {
        number(&self.0, self.kind())
    }
    fn integer(&self) -> Option<i64> {
        integer(&self.0, self.kind())
    }
    fn text(&self) -> Option<String> {
        self.node().text()
    }
    fn get(&self, key: &str) -> Option<Self> {
        self.node().get(key).map(|n| PySetting(n.0))
    }
    fn entries(&self) -> Vec<(String, Self)> {
        let entries = self.node().entries();
        entries
            .into_iter()
            .map(|(k, n)| (k, PySetting(n.0)))
            .collect()
    }
    fn items(&self) -> Option<Vec<Self>> {
        let items = self.node().items()?;
        Some(items.into_iter().map(|n| PySetting(n.0)).collect())
    }
    fn repr(&self) -> String {
        self.node().repr()
    }
    fn show(&self) -> String {
        self.node().show()
    }
    fn type_name(&self) -> String {
        self.node().type_name()
    }
    fn truthy(&self) -> bool {
        self.node().truthy()
    }
    fn callable(&self) -> bool {
        self.0.is_callable()
    }
}
