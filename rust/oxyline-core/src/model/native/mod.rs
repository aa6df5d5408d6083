//! The native model schema (the README's YAML/dict form) read from a front end's values
//! ([`Node`]) into the canonical SI description: every key, unit, default and range check of
//! the top level, the vessels and heart elements (`vessel`), and the boundary conditions and
//! their waveforms (`boundary`). A message names the element, the user's key and value as the
//! user wrote them. The canonical description is JSON (`serde_json::Value`), the input of
//! [`crate::model::NetworkSpec`]; the bulk of a large tree skips it (`plain`: plain vessels
//! and outlets read by serde straight into the spec types, with the same factors).

use super::node::{Kind, Node, py_g, py_repr};
use super::units::{Quantity, Units};
use crate::error::{Error, Result};
use serde_json::{Map, Value, json};

pub mod boundary;
pub mod canonical;
pub mod plain;
pub mod vessel;

pub use boundary::{boundary_condition, condition_periods};
pub use canonical::{
    Periods, Read, canonical, condition_element, condition_entries, conditions, duration,
    period_and_simulation, read_in_order, transport_context,
};
pub use vessel::{element_periods, vessel};

pub const TOP_KEYS: &[&str] = &[
    "name",
    "units",
    "blood",
    "arrangement",
    "segmentation",
    "period",
    "vessels",
    "boundary_conditions",
    "simulation",
    "wall_model",
    "inertance_profile",
    "wall_friction",
    "description",
    "oxygen",
    "species",
    "transport",
];
pub const SIM_KEYS: &[&str] = &[
    "cycles",
    "dt",
    "method",
    "output",
    "until_periodic",
    "max_cycles",
    "rho_infty",
    "start",
    "max_memory",
    "rtol",
    "atol",
    "threads",
    "estimate_time_error",
    "meet_rtol",
];
pub const OUTPUT_KEYS: &[&str] = &["cycles", "every", "segments", "variables", "vessels"];
/// Run methods a model's `simulation: method` may name.
pub const METHODS: &[&str] = &["auto", "rk4", "generalized-alpha", "dopri5"];

pub(crate) fn err(element: &str, message: impl Into<String>) -> Error {
    Error::model(element, message)
}

/// `allowed`, sorted as the messages list them.
fn sorted(allowed: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = allowed.iter().map(|s| (*s).to_owned()).collect();
    v.sort();
    v
}

/// `['a', 'b']`: a sorted name list as Python prints it.
pub(crate) fn py_list(names: &[&str]) -> String {
    let quoted: Vec<String> = sorted(names).iter().map(|s| format!("'{s}'")).collect();
    format!("[{}]", quoted.join(", "))
}

/// `d` is a mapping whose keys are all in `allowed`.
pub fn check_keys<N: Node>(d: &N, allowed: &[&str], element: &str) -> Result<()> {
    if !d.is_map() {
        return Err(err(
            element,
            format!("expected a mapping, got {}", d.type_name()),
        ));
    }
    for (k, _) in d.entries() {
        if !allowed.contains(&k.as_str()) {
            return Err(err(
                element,
                format!(
                    "unknown key '{k}' (allowed: {})",
                    sorted(allowed).join(", ")
                ),
            ));
        }
    }
    Ok(())
}

fn repr_of<N: Node>(value: Option<&N>) -> String {
    value.map_or_else(|| "None".to_owned(), Node::repr)
}

/// A finite number (YAML 1.1 reads `5.0e5` as text: such text is read as a number).
pub fn number<N: Node>(value: Option<&N>, element: &str, key: &str) -> Result<f64> {
    let x = match value {
        Some(v) => match v.kind() {
            Kind::Int | Kind::Float => v.number(),
            Kind::Str => v.text().and_then(|s| py_float(&s)),
            _ => None,
        },
        None => None,
    };
    let Some(x) = x else {
        return Err(err(
            element,
            format!("'{key}' must be a number, got {}", repr_of(value)),
        ));
    };
    if !x.is_finite() {
        return Err(err(
            element,
            format!("'{key}' must be finite, got {}", py_repr(x)),
        ));
    }
    Ok(x)
}

/// Text read as Python's `float()` reads it (surrounding blanks, `_` between digits, `inf`).
pub(crate) fn py_float(s: &str) -> Option<f64> {
    let t = s.trim();
    let lower = t.to_lowercase();
    let bare = lower.trim_start_matches(['+', '-']);
    if ["inf", "infinity", "nan"].contains(&bare) {
        return t.parse::<f64>().ok().or_else(|| {
            let neg = t.starts_with('-');
            let x = if bare == "nan" {
                f64::NAN
            } else {
                f64::INFINITY
            };
            Some(if neg { -x } else { x })
        });
    }
    if t.contains("__") || t.starts_with('_') || t.ends_with('_') {
        return None;
    }
    t.replace('_', "").parse::<f64>().ok()
}

/// A finite number > 0 (>= 0 with `allow_zero`), named by the user's key.
pub fn positive<N: Node>(
    value: Option<&N>,
    element: &str,
    key: &str,
    allow_zero: bool,
) -> Result<f64> {
    let v = number(value, element, key)?;
    if v < 0.0 || (v == 0.0 && !allow_zero) {
        let op = if allow_zero { ">=" } else { ">" };
        return Err(err(
            element,
            format!("{key} must be a finite number {op} 0, got {}", py_g(v)),
        ));
    }
    Ok(v)
}

/// A list of finite numbers (a list, tuple or array).
pub fn numbers<N: Node>(value: Option<&N>, element: &str, key: &str) -> Result<Vec<f64>> {
    let Some(items) = value.and_then(Node::items) else {
        return Err(err(
            element,
            format!("'{key}' must be a list of numbers, got {}", repr_of(value)),
        ));
    };
    items
        .iter()
        .enumerate()
        .map(|(i, x)| number(Some(x), element, &format!("{key}[{i}]")))
        .collect()
}

/// A name: text or an integer (never a bool or null), as text.
pub(crate) fn name_of<N: Node>(v: &N) -> Option<String> {
    matches!(v.kind(), Kind::Str | Kind::Int).then(|| v.show())
}

fn f(x: f64) -> Value {
    json!(x)
}

/// The top level of a model: its name, unit system and the canonical sections that are not
/// elements (blood, arrangement, wall model, inertance profile, segmentation).
pub struct Header {
    pub name: String,
    pub units: Units,
    pub canonical: Map<String, Value>,
}

/// Read and check the top-level keys of a native model (the elements, the period and the
/// transport sections are read by their own readers).
pub fn header<N: Node>(data: &N) -> Result<Header> {
    check_keys(data, TOP_KEYS, "model")?;
    let name = match data.get("name") {
        None => "network".to_owned(),
        Some(n) => name_of(&n)
            .ok_or_else(|| err("model", format!("'name' must be a name, got {}", n.repr())))?,
    };
    let units_text = data
        .get("units")
        .map_or_else(|| "SI".to_owned(), |u| u.show());
    let units = Units::parse(&units_text).ok_or_else(|| {
        err(
            "model",
            format!(
                "units must be 'SI' or 'cgs', got {}",
                super::node::py_quote(&units_text)
            ),
        )
    })?;
    let mut canon = Map::new();
    canon.insert("name".into(), json!(name));
    canon.insert("blood".into(), blood(data.get("blood"), units)?);
    // written only when stated: an unstated arrangement lets `auto` cut in π sections
    if let Some(a) = data.get("arrangement") {
        canon.insert("arrangement".into(), json!(arrangement(a)?));
    }
    let seg = data.get("segmentation").filter(Node::truthy);
    if let Some(seg) = &seg {
        check_keys(seg, &["max_length", "segments", "rtol"], "segmentation")?;
    }
    let wall = choice(
        data.get("wall_model"),
        "thin",
        &["thin", "thick"],
        "wall_model",
    )?;
    let profile = choice(
        data.get("inertance_profile"),
        "flat",
        &["flat", "poiseuille"],
        "inertance_profile",
    )?;
    let friction = choice(
        data.get("wall_friction"),
        "poiseuille",
        vessel::WALL_FRICTIONS,
        "wall_friction",
    )?;
    canon.insert("wall_friction".into(), json!(friction));
    canon.insert("wall_model".into(), json!(wall));
    canon.insert("inertance_profile".into(), json!(profile));
    let vessels = data.get("vessels");
    // a list (as Python's `list`, not a tuple: the readers index it)
    if !vessels.is_some_and(|v| v.type_name() == "list" && v.truthy()) {
        return Err(err("model", "'vessels' must be a non-empty list"));
    }
    if let Some(m) = seg.as_ref().and_then(|s| s.get("max_length")) {
        let x = number(Some(&m), "segmentation", "max_length")?;
        canon.insert(
            "max_segment_length".into(),
            f(units.factor(Quantity::Length) * x),
        );
    }
    if let Some(seg) = &seg {
        segmentation_auto(seg, &mut canon)?;
    }
    Ok(Header {
        name,
        units,
        canonical: canon,
    })
}

/// The model's `segmentation: {segments: auto, rtol}` (docs/solvers.md, "Space").
fn segmentation_auto<N: Node>(seg: &N, canon: &mut Map<String, Value>) -> Result<()> {
    if let Some(n) = seg.get("segments") {
        if n.text().as_deref() != Some("auto") {
            return Err(err(
                "segmentation",
                format!("'segments' must be 'auto', got {}", n.repr()),
            ));
        }
        if seg.has("max_length") {
            return Err(err(
                "segmentation",
                "give 'segments: auto' or 'max_length', not both",
            ));
        }
        canon.insert("segments_auto".into(), json!(true));
    }
    if let Some(r) = seg.get("rtol") {
        let x = number(Some(&r), "segmentation", "rtol")?;
        if !(x > 0.0 && x < 1.0) {
            return Err(err(
                "segmentation",
                format!("'rtol' must be in (0, 1), got {}", py_g(x)),
            ));
        }
        canon.insert("segmentation_rtol".into(), f(x));
    }
    Ok(())
}

fn blood<N: Node>(value: Option<N>, units: Units) -> Result<Value> {
    let (rho, mu) = (
        units.factor(Quantity::Density),
        units.factor(Quantity::Viscosity),
    );
    let b = value.filter(Node::truthy);
    if let Some(b) = &b {
        check_keys(b, &["density", "viscosity"], "blood")?;
    }
    let get = |key: &str| b.as_ref().and_then(|b| b.get(key));
    let density = match get("density") {
        Some(v) => number(Some(&v), "blood", "density")?,
        None => 1050.0 / rho,
    };
    let viscosity = match get("viscosity") {
        Some(v) => number(Some(&v), "blood", "viscosity")?,
        None => 3.5e-3 / mu,
    };
    Ok(json!({"density": rho * density, "viscosity": mu * viscosity}))
}

fn arrangement<N: Node>(v: N) -> Result<String> {
    match v.text() {
        Some(t) if ["inverted-L", "L", "pi"].contains(&t.as_str()) => Ok(t),
        _ => Err(err(
            "model",
            format!("arrangement must be inverted-L, L or pi, got {}", v.repr()),
        )),
    }
}

/// One of two model-wide options (`wall_model`, `inertance_profile`, `wall_friction`).
fn choice<N: Node>(value: Option<N>, default: &str, options: &[&str], key: &str) -> Result<String> {
    let Some(v) = value else {
        return Ok(default.to_owned());
    };
    match v.text() {
        Some(t) if options.contains(&t.as_str()) => Ok(t),
        _ => Err(err(
            "model",
            format!(
                "{key} must be '{}' or '{}', got {}",
                options[0],
                options[1],
                v.repr()
            ),
        )),
    }
}

/// The model's `boundary_conditions` section is a mapping (checked after the vessels, as
/// the sections are read in that order).
pub fn check_conditions<N: Node>(bcs: &N) -> Result<()> {
    if !bcs.is_map() {
        return Err(err(
            "model",
            "'boundary_conditions' must be a mapping from node name to condition",
        ));
    }
    Ok(())
}

/// The model's `period` (None when not given), > 0.
pub fn period<N: Node>(data: &N) -> Result<Option<f64>> {
    match data.get("period") {
        None => Ok(None),
        Some(p) if p.kind() == Kind::Null => Ok(None),
        Some(p) => {
            let x = number(Some(&p), "model", "period")?;
            if x <= 0.0 {
                return Err(err(
                    "model",
                    format!("period must be > 0, got {}", py_repr(x)),
                ));
            }
            Ok(Some(x))
        }
    }
}

/// The model period: the given one, else the first element's; every element that repeats
/// (a waveform, a heart element's activation) must repeat with it.
pub fn check_periods(period: Option<f64>, periods: &[(f64, String)]) -> Result<Option<f64>> {
    let mut period = period;
    let mut source = "the model period is".to_owned();
    for (p, el) in periods {
        match period {
            None => {
                period = Some(*p);
                source = format!("{el} repeats every");
            }
            Some(t) if (p - t).abs() > 1e-9 * t => {
                return Err(err(
                    el,
                    format!(
                        "period mismatch: it repeats every {} s but {source} {} s",
                        py_g(*p),
                        py_g(t)
                    ),
                ));
            }
            Some(_) => {}
        }
    }
    Ok(period)
}

/// The keys of the model's `simulation` section and its `method`.
pub fn simulation<N: Node>(sim: &N) -> Result<()> {
    check_keys(sim, SIM_KEYS, "simulation")?;
    if let Some(out) = sim.get("output") {
        check_keys(&out, OUTPUT_KEYS, "simulation output")?;
    }
    if let Some(m) = sim.get("method") {
        if !m.text().is_some_and(|t| METHODS.contains(&t.as_str())) {
            return Err(err(
                "simulation",
                format!(
                    "method must be one of {}, got {}",
                    py_list(METHODS),
                    m.repr()
                ),
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
