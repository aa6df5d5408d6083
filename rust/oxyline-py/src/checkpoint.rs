//! Checkpoint snapshots (`oxyline_core::run::checkpoint`) as Python dicts of numbers and
//! float64 arrays: the Python side writes them to a versioned file and reads them back; the
//! file's metadata and `checkpoint_every` read by the core's schema.

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use oxyline_core::run::checkpoint::meta::{self, Interval};
use oxyline_core::run::checkpoint::{CHECKPOINT_VERSION, Snapshot};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors::{ModelError, to_py};
use crate::reader::node::{PyNode, PySetting};

/// The snapshot's arrays and their dict keys, in one place for both directions:
/// `arrays!(s, &)` borrows them for writing, `arrays!(s, &mut)` for reading into.
macro_rules! arrays {
    ($s:ident, $($borrow:tt)+) => {
        [
            ("y", $($borrow)+ $s.y),
            ("yd", $($borrow)+ $s.yd),
            ("prev_cycle_end", $($borrow)+ $s.prev_cycle_end),
            ("integrator", $($borrow)+ $s.integrator),
            ("z", $($borrow)+ $s.z),
            ("prev_cycle_z", $($borrow)+ $s.prev_cycle_z),
            ("transport", $($borrow)+ $s.transport),
            ("initial_stored", $($borrow)+ $s.initial_stored),
            ("mean_abs_flow", $($borrow)+ $s.mean_abs_flow),
            ("times", $($borrow)+ $s.times),
            ("data", $($borrow)+ $s.data),
            ("transport_rows", $($borrow)+ $s.transport_rows),
            ("step_ends", $($borrow)+ $s.step_ends),
        ]
    };
}

/// The snapshot as a dict (arrays copied: the run goes on).
pub fn to_dict<'py>(py: Python<'py>, s: &Snapshot) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("version", CHECKPOINT_VERSION)?;
    d.set_item("cycles_run", s.cycles_run)?;
    d.set_item("steps", s.steps)?;
    d.set_item("dt", s.dt)?;
    d.set_item("periodic_error", s.periodic_error)?;
    for (key, v) in arrays!(s, &) {
        d.set_item(key, PyArray1::from_slice(py, v))?;
    }
    Ok(d)
}

fn array(d: &Bound<'_, PyDict>, key: &str) -> PyResult<Vec<f64>> {
    let item = item(d, key)?;
    match item.extract::<PyReadonlyArray1<'_, f64>>() {
        Ok(a) => Ok(a
            .as_slice()
            .map_or_else(|_| a.to_vec().unwrap_or_default(), <[f64]>::to_vec)),
        Err(_) => item.extract::<Vec<f64>>().map_err(|_| {
            ModelError::new_err(format!("checkpoint: '{key}' must be a float64 array"))
        }),
    }
}

fn item<'py>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<Bound<'py, PyAny>> {
    d.get_item(key)?
        .ok_or_else(|| ModelError::new_err(format!("checkpoint: '{key}' is missing")))
}

fn wrong(key: &str) -> PyErr {
    ModelError::new_err(format!("checkpoint: '{key}' has the wrong type"))
}

/// The snapshot of a dict written by [`to_dict`] (its version checked).
pub fn from_dict(d: &Bound<'_, PyDict>) -> PyResult<Snapshot> {
    let version: u32 = item(d, "version")?
        .extract()
        .map_err(|_| wrong("version"))?;
    if version != CHECKPOINT_VERSION {
        return Err(ModelError::new_err(format!(
            "checkpoint: state layout version {version}, this oxyline reads version {CHECKPOINT_VERSION}"
        )));
    }
    let count = |key: &str| -> PyResult<usize> { item(d, key)?.extract().map_err(|_| wrong(key)) };
    let real = |key: &str| -> PyResult<f64> { item(d, key)?.extract().map_err(|_| wrong(key)) };
    let mut s = Snapshot {
        cycles_run: count("cycles_run")?,
        steps: count("steps")?,
        dt: real("dt")?,
        periodic_error: real("periodic_error")?,
        ..Snapshot::default()
    };
    for (key, v) in arrays!(s, &mut) {
        *v = array(d, key)?;
    }
    Ok(s)
}

/// `checkpoint_every` as the run's keywords (`oxyline_core::run::checkpoint::meta`):
/// `checkpoint_every_cycles` or `checkpoint_every_seconds`, none when not given; a
/// `ModelError` naming the setting and the value otherwise, or when no `checkpoint` file is
/// given (`file` false).
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (value, file = true))]
pub(crate) fn checkpoint_interval<'py>(
    py: Python<'py>,
    value: Bound<'py, PyAny>,
    file: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    match meta::parse_every(&PySetting(value), file).map_err(to_py)? {
        None => {}
        Some(Interval::Cycles(n)) => d.set_item("checkpoint_every_cycles", n)?,
        Some(Interval::Seconds(x)) => d.set_item("checkpoint_every_seconds", x)?,
    }
    Ok(d)
}

/// A checkpoint file's metadata (its JSON record as Python values) and its arrays (name →
/// numpy array) checked by the core's schema before any field is used:
/// `oxyline.CheckpointError` naming `file` and the field.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn check_checkpoint_meta<'py>(
    py: Python<'py>,
    file: &str,
    meta: Bound<'py, PyAny>,
    arrays: Bound<'py, PyDict>,
) -> PyResult<()> {
    let shapes = arrays
        .iter()
        .map(|(name, a)| {
            let ndim: usize = a.getattr("ndim")?.extract()?;
            Ok((
                name.extract()?,
                ndim,
                a.getattr("dtype")?.str()?.to_string(),
            ))
        })
        .collect::<PyResult<Vec<_>>>()?;
    if let Err(e) = meta::check(&PyNode(meta), file, &shapes) {
        let class = py.import("oxyline.errors")?.getattr("CheckpointError")?;
        return Err(PyErr::from_value(class.call1((e.to_string(),))?));
    }
    Ok(())
}

/// The settings given to a resumed run (`keys`): only the run control
/// (`_core.RUN_CONTROL`) may change; a `ModelError` names the others.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn check_resumed(keys: Vec<String>) -> PyResult<()> {
    meta::check_resumed(&keys).map_err(to_py)
}
