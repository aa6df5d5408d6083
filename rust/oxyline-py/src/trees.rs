//! Binding of the core's model-reading physics (`oxyline_core::model`): structured-tree growth
//! (read from the user's condition dict, grown by the core, on load straight into the native
//! parts), its steady resistance, the Poiseuille law, and the haemoglobin facilitation factor.
//! Type errors of the condition's values are written here, with the value's Python repr; range
//! checks and their messages are the core's.

use crate::reader::native::NativeParts;
use oxyline_core::Error;
use oxyline_core::model::facilitation::{self, Layer};
use oxyline_core::model::structured_tree::{
    self as st, Grown, Root, Shape, Stiffness, Tree, TreeInput, Units,
};
use oxyline_core::model::{BoundarySpec, VesselSpec, from_json};
use oxyline_core::segment::WallFriction;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping, PyString};

pub(crate) fn model_error(node: &str, message: String) -> PyErr {
    crate::to_py(Error::model(st::element(node), message))
}

fn repr(x: &Bound<'_, PyAny>) -> String {
    x.repr().map_or_else(|_| "?".into(), |r| r.to_string())
}

/// A number as Python's `float()` reads it (int, float, or a numeric string; not bool).
pub(crate) fn number(node: &str, key: &str, x: &Bound<'_, PyAny>) -> PyResult<f64> {
    let ok = !x.is_instance_of::<PyBool>()
        && (x.is_instance_of::<PyFloat>()
            || x.is_instance_of::<PyInt>()
            || x.is_instance_of::<PyString>());
    let v = if ok {
        x.py().get_type::<PyFloat>().call1((x,)).ok()
    } else {
        None
    };
    match v.and_then(|v| v.extract::<f64>().ok()) {
        Some(v) if v.is_finite() || !x.is_instance_of::<PyString>() => Ok(v),
        _ => Err(model_error(
            node,
            format!("'{key}' must be a finite number, got {}", repr(x)),
        )),
    }
}

pub(crate) fn stiffness(node: &str, s: &Bound<'_, PyAny>) -> PyResult<Option<Stiffness>> {
    if s.is_none() {
        return Ok(None);
    }
    let Ok(map) = s.cast::<PyMapping>() else {
        return Err(model_error(
            node,
            format!("'stiffness' must be a mapping, got {}", repr(s)),
        ));
    };
    let mut keys: Vec<String> = Vec::new();
    for k in map.keys()?.iter() {
        keys.push(k.extract::<String>().unwrap_or_else(|_| repr(&k)));
    }
    keys.sort();
    let get =
        |k: &str| -> PyResult<f64> { number(node, &format!("stiffness.{k}"), &map.get_item(k)?) };
    match keys.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["k1", "k2", "k3"] => Ok(Some(Stiffness::KLaw {
            k1: get("k1")?,
            k2: get("k2")?,
            k3: get("k3")?,
        })),
        ["thickness_ratio", "youngs_modulus"] => Ok(Some(Stiffness::Modulus {
            youngs_modulus: get("youngs_modulus")?,
            thickness_ratio: get("thickness_ratio")?,
        })),
        _ => {
            let listed: Vec<String> = keys.iter().map(|k| format!("'{k}'")).collect();
            Err(model_error(
                node,
                format!(
                    "'stiffness' needs {{k1, k2, k3}} or {{youngs_modulus, thickness_ratio}}, got keys [{}]",
                    listed.join(", ")
                ),
            ))
        }
    }
}

/// The values of a structured-tree condition dict (model units), its keys checked.
fn tree_input(node: &str, bc: &Bound<'_, PyDict>) -> PyResult<TreeInput> {
    let mut unknown: Vec<String> = Vec::new();
    let mut t = TreeInput::default();
    for (k, x) in bc.iter() {
        let key = k.extract::<String>().unwrap_or_else(|_| repr(&k));
        match key.as_str() {
            "type" | "terminal" => {}
            "alpha" => t.alpha = Some(number(node, "alpha", &x)?),
            "beta" => t.beta = Some(number(node, "beta", &x)?),
            "length_ratio" => t.length_ratio = Some(number(node, "length_ratio", &x)?),
            "min_radius" => t.min_radius = Some(number(node, "min_radius", &x)?),
            "root_radius" => t.root_radius = Some(number(node, "root_radius", &x)?),
            "max_length" if x.is_none() => {}
            "max_length" => t.max_length = Some(number(node, "max_length", &x)?),
            "stiffness" => t.stiffness = stiffness(node, &x)?,
            "stopping" => {
                let name = x.extract::<String>().unwrap_or_else(|_| repr(&x));
                t.stopping = Some(st::Stopping::parse(&name).ok_or_else(|| {
                    model_error(
                        node,
                        format!(
                            "'stopping' must be one of {}, got {}",
                            st::STOPPINGS.join(", "),
                            repr(&x)
                        ),
                    )
                })?);
            }
            "wall_friction" => {
                let name = x.extract::<String>().unwrap_or_default();
                t.wall_friction = Some(match name.as_str() {
                    "poiseuille" => WallFriction::Poiseuille,
                    "womersley" => WallFriction::Womersley,
                    _ => {
                        return Err(model_error(
                            node,
                            format!(
                                "'wall_friction' must be one of poiseuille, womersley, got {}",
                                repr(&x)
                            ),
                        ));
                    }
                });
            }
            "segments" if x.is_none() => {}
            "segments" if x.extract::<String>().is_ok_and(|t| t == "auto") => {
                t.segments_auto = true;
            }
            "segments" => {
                let int = x.is_instance_of::<PyInt>() && !x.is_instance_of::<PyBool>();
                t.segments = Some(match x.extract::<i64>() {
                    Ok(n) if int => n,
                    _ => {
                        return Err(model_error(
                            node,
                            format!(
                                "'segments' must be an integer >= 1 or 'auto', got {}",
                                repr(&x)
                            ),
                        ));
                    }
                });
            }
            "max_vessels" => {
                let real = (x.is_instance_of::<PyInt>() || x.is_instance_of::<PyFloat>())
                    && !x.is_instance_of::<PyBool>();
                t.max_vessels = Some(match x.extract::<f64>() {
                    Ok(v) if real => v,
                    _ => {
                        let shown: String = repr(&x).chars().take(40).collect();
                        return Err(model_error(
                            node,
                            format!(
                                "'max_vessels' must be a number from 1 to {}, got {shown}",
                                st::fmt_g(st::HARD_MAX_VESSELS)
                            ),
                        ));
                    }
                });
            }
            _ => unknown.push(key),
        }
    }
    if let Some(first) = unknown.iter().min() {
        return Err(model_error(
            node,
            format!("unknown key '{first}' (allowed: {})", st::KEYS.join(", ")),
        ));
    }
    Ok(t)
}

/// A tree vessel as a native dict in model units (the keys of a native vessel).
fn native_vessel<'py>(py: Python<'py>, v: &VesselSpec, u: Units) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let g = v.geometry.as_ref().expect("a tree vessel has geometry");
    d.set_item("name", &v.name)?;
    d.set_item("from", &v.from)?;
    d.set_item("to", &v.to)?;
    d.set_item("length", g.length / u.length)?;
    d.set_item("radius", g.radius_in / u.length)?;
    d.set_item("wall_thickness", g.wall_thickness.unwrap_or(0.0) / u.length)?;
    d.set_item(
        "youngs_modulus",
        g.youngs_modulus.unwrap_or(0.0) / u.modulus,
    )?;
    if let Some(n) = v.segments {
        d.set_item("segments", n)?;
    } else if v.segments_auto {
        d.set_item("segments", "auto")?;
    }
    if let Some(f) = v.wall_friction {
        let name = match f {
            WallFriction::Poiseuille => "poiseuille",
            WallFriction::Womersley => "womersley",
        };
        d.set_item("wall_friction", name)?;
    }
    Ok(d)
}

/// The tree of `input` checked (count in closed form, then counted; memory estimated against
/// `memory_limit` bytes) and only then grown.
fn checked_growth(
    node: &str,
    input: &TreeInput,
    root: Root,
    u: Units,
    memory_limit: Option<f64>,
) -> Result<Grown, Error> {
    let tree = Tree::new(node, input, root, u)?;
    tree.check_memory(memory_limit)?;
    tree.grow()
}

/// The structured tree of `condition` below `node` as native vessel dicts (model units: unit
/// factors `length`, `modulus`) and its leaf nodes. `root_radius` (model units) stands in for
/// the condition's own; `memory_limit` (bytes; None: none) bounds the tree's estimated memory.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (node, condition, root_radius, length = 1.0, modulus = 1.0, memory_limit = None))]
pub fn grow_structured_tree<'py>(
    py: Python<'py>,
    node: &str,
    condition: &Bound<'py, PyDict>,
    root_radius: &Bound<'py, PyAny>,
    length: f64,
    modulus: f64,
    memory_limit: Option<f64>,
) -> PyResult<(Bound<'py, PyList>, Vec<String>)> {
    let u = Units { length, modulus };
    let input = tree_input(node, condition)?;
    let root = Root::Given(number(node, "root_radius", root_radius)?);
    let Grown { vessels, leaves } = py
        .detach(|| checked_growth(node, &input, root, u, memory_limit))
        .map_err(crate::to_py)?;
    let list = PyList::empty(py);
    for v in &vessels {
        list.append(native_vessel(py, v, u)?)?;
    }
    Ok((list, leaves))
}

/// The structured trees of a model, checked and grown by the core when the model is read
/// (before its other elements, as their conditions come first in the error order), then moved
/// into the parts the core assembles.
#[pyclass(module = "oxyline._core")]
pub struct StructuredTrees {
    /// Every tree's vessels, in tree order, grown straight into the element type of the
    /// parts (one allocation, nothing copied per vessel when they are moved in).
    vessels: Vec<Option<VesselSpec>>,
    /// Each tree's node and leaves.
    leaves: Vec<(String, Vec<String>)>,
}

#[oxyline_py_guard::guard]
#[pymethods]
impl StructuredTrees {
    /// `trees`: (node, condition dict, root radius in model units) per tree; `length`,
    /// `modulus`: the model's unit factors; `memory_limit`: bytes all trees may take (None:
    /// no limit), each tree estimated against what the ones before it left; `own_vessels`:
    /// the model's own vessel count (room is kept for them).
    #[new]
    #[pyo3(signature = (trees, length, modulus, memory_limit = None, own_vessels = 0))]
    fn new(
        py: Python<'_>,
        trees: Vec<(String, Bound<'_, PyDict>, Bound<'_, PyAny>)>,
        length: f64,
        modulus: f64,
        memory_limit: Option<f64>,
        own_vessels: usize,
    ) -> PyResult<Self> {
        let u = Units { length, modulus };
        // every tree checked (counted, its memory estimated) before any is grown
        let mut checked = Vec::with_capacity(trees.len());
        let mut total = 0usize;
        for (node, bc, root) in &trees {
            let input = tree_input(node, bc)?;
            let root = Root::Given(number(node, "root_radius", root)?);
            let left = memory_limit
                .map(|m| m - oxyline_core::run::memory::model_bytes(total, total, 0.0, 0));
            let tree = py
                .detach(|| -> Result<Tree, Error> {
                    let tree = Tree::new(node, &input, root, u)?;
                    tree.check_memory(left)?;
                    Ok(tree)
                })
                .map_err(crate::to_py)?;
            total = total.saturating_add(usize::try_from(tree.count).unwrap_or(usize::MAX));
            checked.push((node.clone(), tree));
        }
        py.detach(|| -> Result<Self, Error> {
            let mut out = StructuredTrees {
                vessels: Vec::with_capacity(total.saturating_add(own_vessels)),
                leaves: Vec::with_capacity(checked.len()),
            };
            for (node, tree) in checked {
                let mut leaves = Vec::new();
                tree.grow_into(|v, leaf| {
                    if leaf {
                        leaves.push(v.name.clone());
                    }
                    out.vessels.push(Some(v));
                })?;
                out.leaves.push((node, leaves));
            }
            Ok(out)
        })
        .map_err(crate::to_py)
    }

    /// The number of tree vessels.
    fn vessel_count(&self) -> usize {
        self.vessels.len()
    }

    /// Move the trees into `parts`: the vessels after the model's own, each leaf with its copy
    /// of its tree's terminal condition (`terminals`: canonical JSON per tree, in order).
    fn move_into(
        &mut self,
        parts: &Bound<'_, NativeParts>,
        terminals: Vec<String>,
    ) -> PyResult<()> {
        let mut parts = parts.borrow_mut();
        let leaves: usize = self.leaves.iter().map(|(_, l)| l.len()).sum();
        parts.outlets.reserve(leaves);
        for ((node, leaves), terminal) in
            std::mem::take(&mut self.leaves).into_iter().zip(terminals)
        {
            let terminal: BoundarySpec =
                from_json(&terminal).map_err(|e| model_error(&node, format!("'terminal': {e}")))?;
            let outlets = leaves.into_iter().map(|leaf| (leaf, terminal.clone()));
            parts.outlets.extend(outlets);
        }
        // the model's own vessels go in front of the trees' (their storage is the larger)
        let mut all = std::mem::take(&mut self.vessels);
        let own = std::mem::take(&mut parts.vessels);
        all.splice(0..0, own);
        parts.vessels = all;
        Ok(())
    }
}

/// (min_radius, terminal resistance) of the structured tree below `node` (root radius
/// `root_radius`, SI) whose steady resistance is `total` (see `Shape::matched`).
#[oxyline_py_guard::guard]
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn match_structured_tree(
    node: &str,
    root_radius: f64,
    total: f64,
    viscosity: f64,
    min_radius: f64,
    tree_fraction: f64,
    alpha: f64,
    beta: f64,
    length_ratio: f64,
) -> PyResult<(f64, f64)> {
    let shape = Shape {
        alpha,
        beta,
        length_ratio,
        root_radius,
        viscosity,
    };
    shape
        .matched(node, total, min_radius, tree_fraction)
        .map_err(crate::to_py)
}

/// (Young's modulus, wall thickness) in SI of a vessel of radius `radius` (SI) under the
/// `stiffness` law of a structured tree (None: Olufsen's).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn structured_tree_wall(
    node: &str,
    stiffness_law: &Bound<'_, PyAny>,
    radius: f64,
) -> PyResult<(f64, f64)> {
    let law = stiffness(node, stiffness_law)?;
    st::wall_at(node, law, radius, Units::SI).map_err(crate::to_py)
}

/// A lower bound of the vessel count of the structured tree (α, β, root radius, min_radius),
/// in closed form (`vessel_count_bound`).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn structured_tree_count_bound(
    alpha: f64,
    beta: f64,
    root_radius: f64,
    min_radius: f64,
) -> f64 {
    st::vessel_count_bound(alpha, beta, root_radius, min_radius)
}

/// The haemoglobin facilitation factor E_Hb of the wall layer between inlet PO2 `p_in` and
/// wall PO2 `p_w`: the nonlinear Lévêque layer of Hill binding, or (`linearized`) the closed
/// form with the Hill secant over [p_w, p_in].
#[oxyline_py_guard::guard]
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn facilitation_factor(
    p_in: f64,
    p_w: f64,
    alpha: f64,
    d: f64,
    d_hb: f64,
    capacity: f64,
    p50: f64,
    n: f64,
    linearized: bool,
) -> f64 {
    let layer = Layer {
        alpha,
        d,
        d_hb,
        capacity,
        p50,
        n,
    };
    if linearized {
        facilitation::secant_factor(p_in, p_w, &layer)
    } else {
        facilitation::hill_factor(p_in, p_w, &layer)
    }
}

/// E_Hb of linearised binding with secant K̄ (closed form).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn linear_facilitation_factor(kbar: f64, d: f64, d_hb: f64) -> f64 {
    facilitation::linear_factor(kbar, d, d_hb)
}
