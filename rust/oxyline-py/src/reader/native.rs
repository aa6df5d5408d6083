//! The bulk of a large native model read straight from the user's dicts: plain geometric
//! vessels and plain resistance/RCR outlets, converted to SI here without a canonical dict per
//! element. An element this reader does not take (anything else, or a value out of range)
//! goes through the core's full schema check (`oxyline_core::model::native`, with its precise
//! error): [`NativeParts::read_rest`] for vessels, `read_conditions` for outlets. The same
//! numbers as the canonical route: each value is multiplied by the same unit factor once.

use super::node::PyNode;
use crate::errors::to_py;
use oxyline_core::Error;
use oxyline_core::model::native;
use oxyline_core::model::node::Fields;
use oxyline_core::model::units::{Quantity, Units};
use oxyline_core::model::{Arrangement, BoundarySpec, GeometrySpec, VesselSpec};
use oxyline_core::waveform::WaveformSpec;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat, PyInt, PyList, PyString};

/// A value of exact type float or int (bool, str, None and subclasses take the full check),
/// as f64 (an int too large for a float is left to the full check as well).
fn real(v: &Bound<'_, PyAny>) -> Option<f64> {
    if v.is_exact_instance_of::<PyFloat>() || v.is_exact_instance_of::<PyInt>() {
        v.extract::<f64>().ok()
    } else {
        None
    }
}

/// 0 < x < ∞ (false for NaN).
fn positive(v: &Bound<'_, PyAny>) -> Option<f64> {
    real(v).filter(|x| *x > 0.0 && *x < f64::INFINITY)
}

fn finite(v: &Bound<'_, PyAny>) -> Option<f64> {
    real(v).filter(|x| x.is_finite())
}

fn name(v: &Bound<'_, PyAny>) -> Option<String> {
    if !v.is_exact_instance_of::<PyString>() {
        return None;
    }
    v.cast::<PyString>().ok()?.to_str().ok().map(str::to_owned)
}

fn arrangement(v: &Bound<'_, PyAny>) -> Option<Arrangement> {
    match name(v)?.as_str() {
        "inverted-L" => Some(Arrangement::InvertedL),
        "L" => Some(Arrangement::L),
        "pi" => Some(Arrangement::Pi),
        "RCL" => Some(Arrangement::Rcl),
        _ => None,
    }
}

/// A plain geometric vessel (name, from, to, length, radius or radius_in/radius_out, optional
/// wall, segments, arrangement, output, description) in SI, or None. `length` and `modulus`
/// are the model's unit factors.
fn vessel(item: &Bound<'_, PyAny>, length: f64, modulus: f64) -> Option<VesselSpec> {
    if !item.is_exact_instance_of::<PyDict>() {
        return None;
    }
    let d = item.cast::<PyDict>().ok()?;
    let mut v = VesselSpec::blank();
    let mut g = GeometrySpec {
        length: f64::NAN,
        radius_in: f64::NAN,
        radius_out: f64::NAN,
        wall_thickness: None,
        youngs_modulus: None,
        poisson_ratio: 0.5,
        wall_viscosity: 0.0,
    };
    let (mut has_name, mut has_from, mut has_to) = (false, false, false);
    let (mut radius, mut radius_in, mut radius_out) = (None, None, None);
    for (k, x) in d.iter() {
        if !k.is_exact_instance_of::<PyString>() {
            return None;
        }
        match k.cast::<PyString>().ok()?.to_str().ok()? {
            "name" => (v.name, has_name) = (name(&x)?, true),
            "from" => (v.from, has_from) = (name(&x)?, true),
            "to" => (v.to, has_to) = (name(&x)?, true),
            "length" => g.length = length * positive(&x)?,
            "radius" => radius = Some(positive(&x)?),
            "radius_in" => radius_in = Some(positive(&x)?),
            "radius_out" => radius_out = Some(positive(&x)?),
            "wall_thickness" => g.wall_thickness = Some(length * positive(&x)?),
            "youngs_modulus" => g.youngs_modulus = Some(modulus * positive(&x)?),
            "poisson_ratio" => g.poisson_ratio = finite(&x)?,
            "segments" => {
                if !x.is_exact_instance_of::<PyInt>() {
                    return None;
                }
                v.segments = Some(x.extract::<usize>().ok().filter(|&n| n >= 1)?);
            }
            "arrangement" => v.arrangement = Some(arrangement(&x)?),
            "output" => v.output = x.is_truthy().ok()?,
            "description" => {}
            _ => return None,
        }
    }
    (g.radius_in, g.radius_out) = match (radius, radius_in, radius_out) {
        (Some(r), None, None) => (length * r, length * r),
        (None, Some(a), Some(b)) => (length * a, length * b),
        _ => return None,
    };
    if !(has_name && has_from && has_to) || g.length.is_nan() {
        return None;
    }
    v.geometry = Some(g);
    Some(v)
}

/// A resistance or RCR outlet with plain finite values and a constant (or no) pressure, in
/// SI, or None. `factors`: resistance, capacitance, pressure.
fn outlet(item: &Bound<'_, PyAny>, (r, c, p): (f64, f64, f64)) -> Option<BoundarySpec> {
    if !item.is_exact_instance_of::<PyDict>() {
        return None;
    }
    let d = item.cast::<PyDict>().ok()?;
    let kind = name(&d.get_item("type").ok()??)?;
    let (mut pressure, mut values) = (0.0, [None; 4]);
    for (k, x) in d.iter() {
        if !k.is_exact_instance_of::<PyString>() {
            return None;
        }
        let slot = match (kind.as_str(), k.cast::<PyString>().ok()?.to_str().ok()?) {
            (_, "type") => continue,
            (_, "pressure") => {
                pressure = finite(&x)?;
                continue;
            }
            ("resistance", "resistance") => 0,
            ("rcr", "proximal_resistance") => 1,
            ("rcr", "capacitance") => 2,
            ("rcr", "distal_resistance") => 3,
            _ => return None,
        };
        values[slot] = Some(finite(&x)?);
    }
    let pressure = Some(WaveformSpec::Constant {
        value: p * pressure,
    });
    match (kind.as_str(), values) {
        ("resistance", [Some(x), ..]) => Some(BoundarySpec::Resistance {
            resistance: r * x,
            pressure,
        }),
        ("rcr", [None, Some(rp), Some(cap), Some(rd)]) => Some(BoundarySpec::Rcr {
            proximal_resistance: r * rp,
            capacitance: c * cap,
            distal_resistance: r * rd,
            pressure,
        }),
        _ => None,
    }
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
        let (length, modulus) = (u.factor(Quantity::Length), u.factor(Quantity::Modulus));
        Ok(NativeParts {
            vessels: vessels
                .iter()
                .map(|v| vessel(&v, length, modulus))
                .collect(),
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
        let resistance = u.factor(Quantity::Resistance);
        let capacitance = u.factor(Quantity::Capacitance);
        let pressure = u.factor(Quantity::Pressure);
        let mut slow = Vec::new();
        self.outlets.reserve(bcs.len());
        for (node, bc) in bcs.iter() {
            match (
                name(&node),
                outlet(&bc, (resistance, capacitance, pressure)),
            ) {
                (Some(n), Some(spec)) => self.outlets.push((n, spec)),
                _ => slow.push(node),
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
