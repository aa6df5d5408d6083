//! Binding of a tree's root radius at an outlet and of the structured tree that replaces a
//! Windkessel outlet (`oxyline_core::model::structured_tree::windkessel`), read from the
//! model's dicts.

use crate::trees::{model_error, number};
use oxyline_core::model::structured_tree::{Shape, VesselEnds, end_radius, windkessel_tree};
use pyo3::prelude::*;
use pyo3::types::{PyList, PyMapping};

/// One vessel dict's ends: (name, from, to, radius_in, radius_out); a `radius` stands for
/// both ends, a node that is not a string meets no outlet.
type Ends = (
    String,
    Option<String>,
    Option<String>,
    Option<f64>,
    Option<f64>,
);

fn ends<'py>(node: &str, v: &Bound<'py, PyMapping>) -> PyResult<Ends> {
    let get = |k: &str| -> PyResult<Option<Bound<'py, PyAny>>> {
        Ok(if v.contains(k)? {
            Some(v.get_item(k)?)
        } else {
            None
        })
    };
    let text = |k: &str| -> PyResult<Option<String>> {
        Ok(get(k)?.and_then(|x| x.extract::<String>().ok()))
    };
    let radius = |keys: [&str; 2]| -> PyResult<Option<f64>> {
        for k in keys {
            if let Some(x) = get(k)? {
                return number(node, k, &x).map(Some);
            }
        }
        Ok(None)
    };
    let name = match get("name")? {
        Some(x) => x.str()?.to_string(),
        None => "None".into(),
    };
    Ok((
        name,
        text("from")?,
        text("to")?,
        radius(["radius_in", "radius"])?,
        radius(["radius_out", "radius"])?,
    ))
}

/// The radius (the model's units) of the first vessel end at outlet `node` among `vessels`
/// (the model's vessel dicts; None: none): a structured tree's default root radius there.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn outlet_root_radius(node: &str, vessels: &Bound<'_, PyAny>) -> PyResult<f64> {
    let mut all: Vec<Ends> = Vec::new();
    if let Ok(list) = vessels.cast::<PyList>() {
        for v in list.iter() {
            if let Ok(map) = v.cast::<PyMapping>() {
                all.push(ends(node, map)?);
            }
        }
    }
    let view = all.iter().map(|(name, from, to, r_in, r_out)| VesselEnds {
        name,
        from: from.as_deref(),
        to: to.as_deref(),
        radius_in: *r_in,
        radius_out: *r_out,
    });
    end_radius(node, view).map_err(crate::to_py)
}

/// (min_radius, terminal resistance) of the structured tree at `node` (root radius
/// `root_radius`, SI) that keeps the steady resistance of the RCR condition `rcr` (its
/// `proximal_resistance` + `distal_resistance`).
#[oxyline_py_guard::guard]
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn windkessel_tree_match(
    node: &str,
    rcr: &Bound<'_, PyMapping>,
    root_radius: f64,
    viscosity: f64,
    min_radius: f64,
    tree_fraction: f64,
    alpha: f64,
    beta: f64,
    length_ratio: f64,
) -> PyResult<(f64, f64)> {
    let resistance = |k: &str| -> PyResult<f64> {
        if !rcr.contains(k)? {
            return Err(model_error(node, format!("the RCR condition has no '{k}'")));
        }
        number(node, k, &rcr.get_item(k)?)
    };
    let (proximal, distal) = (
        resistance("proximal_resistance")?,
        resistance("distal_resistance")?,
    );
    let shape = Shape {
        alpha,
        beta,
        length_ratio,
        root_radius,
        viscosity,
    };
    windkessel_tree(node, proximal, distal, &shape, min_radius, tree_fraction).map_err(crate::to_py)
}
