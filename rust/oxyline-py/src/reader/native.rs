//! The bulk of a large native model read straight from the user's dicts by the core's serde
//! types (`oxyline_core::model::native::plain`, over Python objects: `de`): plain geometric
//! vessels and plain resistance/RCR outlets, in SI without a canonical dict per element. An
//! element that is not plain goes through the core's full schema check
//! (`oxyline_core::model::native`, with its precise error): [`NativeParts::read_rest`] for
//! vessels, `read_conditions` for outlets.

use super::de::PyDe;
use super::node::PyNode;
use crate::errors::to_py;
use oxyline_core::Error;
use oxyline_core::model::native;
use oxyline_core::model::native::plain::{PlainOutlet, PlainVessel};
use oxyline_core::model::node::Fields;
use oxyline_core::model::units::Units;
use oxyline_core::model::{BoundarySpec, VesselSpec};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};
use serde::Deserialize;

/// A plain vessel in SI, or None (left to the full check).
fn vessel(item: &Bound<'_, PyAny>, units: Units) -> Option<VesselSpec> {
    PlainVessel::deserialize(PyDe(item)).ok()?.spec(units)
}

/// A plain outlet in SI by its node, or None (left to the full check).
fn outlet(
    node: &Bound<'_, PyAny>,
    item: &Bound<'_, PyAny>,
    units: Units,
) -> Option<(String, BoundarySpec)> {
    let node = node.cast::<PyString>().ok()?.to_str().ok()?.to_owned();
    Some((
        node,
        PlainOutlet::deserialize(PyDe(item)).ok()?.spec(units)?,
    ))
}

/// Outlet conditions by node name, in the order read.
pub(crate) type Outlets = Vec<(String, BoundarySpec)>;

/// The vessels and outlets of a native model (read here, or by the core's full check where
/// this module leaves them), and the rest of the canonical model (`reader::model::read_model`):
/// what the network is built from, with structured trees grown into it (`trees`).
#[pyclass(module = "oxyline._core")]
pub struct NativeParts {
    pub(crate) vessels: Vec<Option<VesselSpec>>,
    pub(crate) outlets: Outlets,
    /// The rest of the canonical model (top level, the conditions not in `outlets`, the
    /// transport section) when the whole model was read here (`read_model`).
    pub(crate) rest: Option<serde_json::Map<String, serde_json::Value>>,
}

#[oxyline_py_guard::guard]
#[pymethods]
impl NativeParts {
    /// Read the plain vessels of the native `vessels` list (in the unit system `units`): the
    /// fast reader alone, as `read_model` uses it.
    #[new]
    fn new(vessels: &Bound<'_, PyList>, units: &str) -> PyResult<Self> {
        Self::read(vessels, super::schema::units(units)?)
    }

    /// Indices of the vessels the fast reader did not take, in order.
    fn slow_vessels(&self) -> Vec<usize> {
        self.slow()
    }

    /// Read the plain outlets of the native `boundary_conditions` mapping (in the unit system
    /// `units`); returns the node keys of the conditions left to the full check, in order.
    #[pyo3(name = "read_outlets")]
    fn py_read_outlets<'py>(
        &mut self,
        bcs: &Bound<'py, PyDict>,
        units: &str,
    ) -> PyResult<Vec<Bound<'py, PyAny>>> {
        Ok(self.read_outlets(bcs, super::schema::units(units)?))
    }

    /// The vessel names in model order (every vessel read or put).
    fn names(&self) -> Vec<&str> {
        self.vessels
            .iter()
            .map(|v| v.as_ref().map_or("", |v| v.name.as_str()))
            .collect()
    }
}

impl NativeParts {
    /// Read the plain vessels of the native `vessels` list (in the unit system `u`).
    pub(crate) fn read(vessels: &Bound<'_, PyList>, u: Units) -> PyResult<Self> {
        Ok(NativeParts {
            vessels: vessels.iter().map(|v| vessel(&v, u)).collect(),
            outlets: Vec::new(),
            rest: None,
        })
    }

    /// Indices of the vessels the fast reader did not take, in order.
    fn slow(&self) -> Vec<usize> {
        (0..self.vessels.len())
            .filter(|&i| self.vessels[i].is_none())
            .collect()
    }

    /// Read the vessels the fast reader did not take with the core's full check (and its
    /// precise error); returns the periods of their heart elements, with the element.
    pub(crate) fn read_rest(
        &mut self,
        vessels: &Bound<'_, PyList>,
        u: Units,
    ) -> PyResult<Vec<(f64, String)>> {
        let mut canonical = Vec::new();
        for i in self.slow() {
            let item = vessels.get_item(i)?;
            let c = native::vessel(&Fields::new(PyNode(item)), i, u).map_err(to_py)?;
            let v: VesselSpec = serde_json::from_value(c.clone())
                .map_err(|e| to_py(Error::model(format!("vessel #{i}"), e.to_string())))?;
            self.vessels[i] = Some(v);
            canonical.push(c);
        }
        Ok(native::element_periods(&canonical))
    }

    /// Read the plain outlets of the native `boundary_conditions` mapping (in the unit system
    /// `u`); returns the node keys of the conditions left to the full check, in order.
    pub(crate) fn read_outlets<'py>(
        &mut self,
        bcs: &Bound<'py, PyDict>,
        u: Units,
    ) -> Vec<Bound<'py, PyAny>> {
        let mut slow = Vec::new();
        self.outlets.reserve(bcs.len());
        for (node, bc) in bcs.iter() {
            match outlet(&node, &bc, u) {
                Some(read) => self.outlets.push(read),
                None => slow.push(node),
            }
        }
        slow
    }

    /// The vessels and outlets, moved out (a second call gets none).
    pub(crate) fn take(&mut self) -> Result<(Vec<VesselSpec>, Outlets), Error> {
        let vessels = std::mem::take(&mut self.vessels);
        let outlets = std::mem::take(&mut self.outlets);
        let vessels = vessels
            .into_iter()
            .enumerate()
            .map(|(i, v)| v.ok_or_else(|| Error::model(format!("vessel #{i}"), "was not read")))
            .collect::<Result<Vec<_>, _>>()?;
        Ok((vessels, outlets))
    }
}
