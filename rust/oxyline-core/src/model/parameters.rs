//! Parameter paths of a native model (docs/calibration.md, "Parameters"): the number a path
//! names, in the model's own units ([`base_value`]), and the model with paths set to values
//! ([`set_values`]). The sensitivities resolve the same paths on the read model, in SI
//! (`crate::sensitivity::parameter`); calibration moves the model along them.
//!
//! A path is an ensemble patch path (`vessels.<name>.radius`,
//! `vessels.<name>.lumped.resistance`, `boundary_conditions.<node>.resistance`,
//! `oxygen.wall.k`, `scale.resistance`, …: set through [`super::patch::merge`], with its rules
//! and checks), or one of three that no patch has:
//! * `scale.inflow`: a factor on every flow condition's waveform (its `value` or `flow`
//!   table, or its `fourier` mean and coefficients);
//! * `boundary_conditions.<node>.intramyocardial_pressure.scale`: a factor on a coronary
//!   outlet's intramyocardial pressure waveform (a number, `value` or `pressure` table, or
//!   `fourier`), 1 at the model;
//! * `vessels.<name>.<chamber|valve|chamber_sphere|heart_pulmonary>.<key>…`: a heart
//!   element's value, set where the element holds it.
//!
//! Base values: a scale is 1, the radius of a vessel given by `radius_in`/`radius_out` is its
//! `radius_in` (and either end radius of a vessel given by `radius` that radius), and a lumped vessel without a stenosis coefficient has 0. Every error names
//! the parameter path.

use super::native::py_float;
use super::node::{Kind, Node, py_dict, py_list, py_quote, py_repr};
use super::patch::{Merged, PatchError, Patched, merge, set, set_at};
use super::path::{heart_paths, nearest, parameter_keys};
use crate::error::{Error, Result};

#[cfg(test)]
mod tests;

/// The heart elements whose values are set in place (no patch has them).
const HEART: &[&str] = &["chamber", "valve", "chamber_sphere", "heart_pulmonary"];
/// The factor on a coronary outlet's intramyocardial pressure (after the node).
const PIM_SCALE: [&str; 2] = ["intramyocardial_pressure", "scale"];
/// The keys of a Fourier waveform that a factor multiplies.
const FOURIER_KEYS: [&str; 3] = ["mean", "cos", "sin"];

fn error(path: &str, message: impl Into<String>) -> Error {
    Error::model(format!("parameter '{path}'"), message)
}

/// A number as the front end's `float()` reads it (a bool, YAML 1.1's `5.0e5` text).
fn float_of<N: Node>(n: &N) -> Option<f64> {
    match n.kind() {
        Kind::Int | Kind::Float => n.number(),
        Kind::Bool => Some(if n.truthy() { 1.0 } else { 0.0 }),
        Kind::Str => n.text().and_then(|s| py_float(&s)),
        _ => None,
    }
}

/// The keys of `path` in the native model `source`: a vessel or node name may itself hold
/// dots, the longest name of the model wins (`super::path::parameter_keys`). Only a path of
/// four pieces or more can hold a dotted name before its property: the model's names are
/// read for those alone.
fn keys_of<'p, N: Node>(source: &N, path: &'p str) -> Vec<&'p str> {
    if path.matches('.').count() < 3 {
        return path.split('.').collect();
    }
    let vessels: Vec<String> = source
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default()
        .iter()
        .filter_map(|v| v.get("name").and_then(|n| n.text()))
        .collect();
    let nodes: Vec<String> = source
        .get("boundary_conditions")
        .map(|b| b.entries().into_iter().map(|(node, _)| node).collect())
        .unwrap_or_default();
    parameter_keys(
        path,
        &[("vessels", &vessels), ("boundary_conditions", &nodes)],
    )
}

/// The value under `keys` of nested mappings.
fn walk<N: Node>(node: N, keys: &[&str]) -> Option<N> {
    keys.iter().try_fold(node, |n, key| n.get(key))
}

/// The index and value of the vessel named `name`.
fn vessel<N: Node>(source: &N, name: &str, path: &str) -> Result<(usize, N)> {
    source
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default()
        .into_iter()
        .enumerate()
        .find(|(_, v)| v.get("name").and_then(|n| n.text()).as_deref() == Some(name))
        .ok_or_else(|| error(path, format!("no vessel named {}", py_quote(name))))
}

/// The number `path` names in the native model `source`, in the model's units (1 for a
/// scale; see the module's documentation).
pub fn base_value<N: Node>(source: &N, path: &str) -> Result<f64> {
    let parts = keys_of(source, path);
    let value = match parts.as_slice() {
        ["scale", ..] => return Ok(1.0),
        ["vessels", name, rest @ ..] => {
            let (_, v) = vessel(source, name, path)?;
            match rest {
                ["radius"] if !v.has("radius") => v.get("radius_in").and_then(|r| float_of(&r)),
                // an end radius of a vessel given by one `radius` is that radius
                [end @ ("radius_in" | "radius_out")] if !v.has(end) => {
                    v.get("radius").and_then(|r| float_of(&r))
                }
                ["lumped", "stenosis_coefficient"]
                    if v.get("lumped").is_some_and(|l| l.is_map()) =>
                {
                    // a lumped vessel without a stenosis: S = 0
                    walk(v, rest).map_or(Some(0.0), |s| float_of(&s))
                }
                _ => walk(v, rest).and_then(|x| float_of(&x)),
            }
        }
        ["boundary_conditions", node, rest @ ..] => {
            match source.get("boundary_conditions").and_then(|b| b.get(node)) {
                Some(bc) if rest == PIM_SCALE && bc.has(PIM_SCALE[0]) => Some(1.0),
                Some(bc) => walk(bc, rest).and_then(|x| float_of(&x)),
                None => None,
            }
        }
        ["oxygen", rest @ ..] => source
            .get("oxygen")
            .and_then(|o| walk(o, rest))
            .and_then(|x| float_of(&x)),
        _ => None,
    };
    value.ok_or_else(|| {
        let hint = heart_hint(source, &parts);
        error(path, format!("no such number in the model{hint}"))
    })
}

/// Whether `node` holds the dotted `keys` (`activation.t_active`).
fn holds<N: Node>(node: &N, keys: &str) -> bool {
    let mut parts = keys.split('.');
    let Some(mut at) = parts.next().and_then(|k| node.get(k)) else {
        return false;
    };
    for key in parts {
        match at.get(key) {
            Some(next) => at = next,
            None => return false,
        }
    }
    true
}

/// ` (nearest: <keys>)` for a heart element's key (`vessels.<name>.<kind>.<key>`) that the
/// element does not hold but holds a key a typo away ([`nearest`] of the keys the schema
/// knows for the element, `super::path::heart_paths`); else nothing.
fn heart_hint<N: Node>(source: &N, parts: &[&str]) -> String {
    let ["vessels", name, kind, key @ ..] = parts else {
        return String::new();
    };
    let section = source
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default()
        .into_iter()
        .find(|v| v.get("name").and_then(|n| n.text()).as_deref() == Some(*name))
        .and_then(|v| v.get(kind))
        .filter(Node::is_map);
    let (Some(section), false) = (section, key.is_empty()) else {
        return String::new();
    };
    let candidates = heart_paths(kind);
    let held: Vec<&str> = candidates
        .iter()
        .map(String::as_str)
        .filter(|k| holds(&section, k))
        .collect();
    let near = nearest(&key.join("."), &held);
    if near.is_empty() {
        String::new()
    } else {
        format!(" (nearest: {})", near.join(", "))
    }
}

/// The model `source` with each of `paths` set to its value (the model's units; a scale to
/// its factor), as a patch's replaced vessels, conditions and sections (the front end
/// rebuilds the model dict from them, as for a variant). The patch paths are merged first
/// (a `scale.resistance` then multiplies the values set explicitly, as a patch's `scale`),
/// then the waveforms are scaled and the heart elements' values set. A path given twice
/// takes its last value.
pub fn set_values<N: Node + Clone>(
    source: &N,
    paths: &[String],
    values: &[f64],
) -> Result<Patched<N>> {
    if paths.len() != values.len() {
        return Err(Error::model(
            "parameters",
            format!("{} paths but {} values", paths.len(), values.len()),
        ));
    }
    let mut patch: Vec<(String, f64)> = Vec::new();
    let mut inflow = None;
    let mut squeeze: Vec<(String, (f64, String))> = Vec::new();
    let mut heart: Vec<(String, f64)> = Vec::new();
    for (path, &x) in paths.iter().zip(values) {
        let parts = keys_of(source, path);
        match parts.as_slice() {
            ["scale", "inflow"] => inflow = Some(x),
            ["boundary_conditions", node, rest @ ..] if rest == PIM_SCALE => {
                set_at(&mut squeeze, (*node).to_owned(), (x, path.clone()));
            }
            ["vessels", _, kind, ..] if HEART.contains(kind) => heart.push((path.clone(), x)),
            _ => patch.push((path.clone(), x)),
        }
    }
    let mut model = patched(source, &patch).map_err(|e| patch_error(source, &patch, &e))?;
    if let Some(factor) = inflow {
        scale_inflow(source, &mut model, factor)?;
    }
    for (node, (factor, path)) in &squeeze {
        scale_intramyocardial(source, &mut model, node, *factor, path)?;
    }
    for (path, x) in &heart {
        set_heart(source, &mut model, path, *x)?;
    }
    Ok(model)
}

/// `x` at the nested keys of a patch under construction.
fn put<N>(entries: &mut Vec<(String, Merged<N>)>, keys: &[&str], x: f64) {
    let Some((first, rest)) = keys.split_first() else {
        return;
    };
    if rest.is_empty() {
        set(entries, first, Merged::Number(x));
        return;
    }
    if !entries
        .iter()
        .any(|(k, v)| k == first && matches!(v, Merged::Map(_)))
    {
        set(entries, first, Merged::Map(Vec::new()));
    }
    if let Some((_, Merged::Map(child))) = entries.iter_mut().find(|(k, _)| k == first) {
        put(child, rest, x);
    }
}

/// The patch of the patch paths merged into `source` (nothing replaced without one).
fn patched<N: Node + Clone>(
    source: &N,
    patch: &[(String, f64)],
) -> std::result::Result<Patched<N>, PatchError> {
    if patch.is_empty() {
        return Ok(Patched {
            vessels: Vec::new(),
            conditions: Vec::new(),
            sections: Vec::new(),
            vessel_paths: Vec::new(),
            condition_paths: Vec::new(),
            has_vessels: false,
            has_conditions: false,
        });
    }
    let mut entries = Vec::new();
    for (path, x) in patch {
        put(&mut entries, &keys_of(source, path), *x);
    }
    let p = merge(&Merged::Node(source.clone()), &Merged::Map(entries), 0)?;
    Ok(Patched {
        vessels: flat(p.vessels),
        conditions: flat(p.conditions),
        sections: flat(p.sections),
        vessel_paths: p.vessel_paths,
        condition_paths: p.condition_paths,
        has_vessels: p.has_vessels,
        has_conditions: p.has_conditions,
    })
}

/// Replaced elements of the model patched by values of the model: the model's own values.
fn flat<K, N>(items: Vec<(K, Merged<Merged<N>>)>) -> Vec<(K, Merged<N>)> {
    items.into_iter().map(|(k, v)| (k, flatten(v))).collect()
}

/// A value of the model patched by values of the model: the model's own values.
fn flatten<N>(m: Merged<Merged<N>>) -> Merged<N> {
    match m {
        Merged::Node(inner) => inner,
        Merged::Map(e) => Merged::Map(e.into_iter().map(|(k, v)| (k, flatten(v))).collect()),
        Merged::Number(x) => Merged::Number(x),
        Merged::Numbers(v) => Merged::Numbers(v),
    }
}

/// A refused patch named by the path that the patch refuses on its own (the message of the
/// patch's own path, which may be a prefix of the parameter's, is the parameter's).
fn patch_error<N: Node + Clone>(source: &N, patch: &[(String, f64)], e: &PatchError) -> Error {
    let message = |e: &PatchError| match e.error() {
        Error::Model { message, .. } => message.clone(),
        other => other.to_string(),
    };
    for one in patch {
        if let Err(own) = patched(source, std::slice::from_ref(one)) {
            return error(&one.0, message(&own));
        }
    }
    let names: Vec<String> = patch.iter().map(|(p, _)| format!("'{p}'")).collect();
    Error::model(format!("parameters {}", names.join(", ")), message(e))
}

/// The condition at `node` as the model now holds it.
fn condition_at<N: Node + Clone>(source: &N, p: &Patched<N>, node: &str) -> Option<Merged<N>> {
    match p.conditions.iter().find(|(n, _)| n == node) {
        Some((_, c)) => Some(c.clone()),
        None => source
            .get("boundary_conditions")?
            .get(node)
            .map(Merged::Node),
    }
}

/// `value` (a number, or a table of numbers) times `factor`; None for anything else.
fn scaled<N: Node + Clone>(value: &Merged<N>, factor: f64) -> Option<Merged<N>> {
    match value.kind() {
        Kind::List | Kind::Other => value
            .items()?
            .iter()
            .map(|x| float_of(x).map(|x| x * factor))
            .collect::<Option<Vec<f64>>>()
            .map(Merged::Numbers),
        _ => float_of(value).map(|x| Merged::Number(x * factor)),
    }
}

/// The entry `key` (if there is one) of a waveform times `factor`.
fn scale_entry<N: Node + Clone>(
    entries: &mut Vec<(String, Merged<N>)>,
    key: &str,
    factor: f64,
    path: &str,
    node: &str,
) -> Result<()> {
    let Some(old) = entries
        .iter()
        .find(|(k, _)| k == key)
        .map(|(_, v)| v.clone())
    else {
        return Ok(());
    };
    let new = scaled(&old, factor).ok_or_else(|| {
        error(
            path,
            format!(
                "the condition at {} has '{key}' {}, not a number or a table of numbers",
                py_quote(node),
                old.repr()
            ),
        )
    })?;
    set(entries, key, new);
    Ok(())
}

/// A waveform's mapping with its `keys` and its `fourier` mean and coefficients times
/// `factor`.
fn scale_waveform<N: Node + Clone>(
    mut entries: Vec<(String, Merged<N>)>,
    keys: &[&str],
    factor: f64,
    path: &str,
    node: &str,
) -> Result<Vec<(String, Merged<N>)>> {
    for key in keys {
        scale_entry(&mut entries, key, factor, path, node)?;
    }
    let fourier = entries
        .iter()
        .find(|(k, _)| k == "fourier")
        .map(|(_, f)| f.clone())
        .and_then(Merged::into_entries);
    if let Some(mut f) = fourier {
        for key in FOURIER_KEYS {
            scale_entry(&mut f, key, factor, path, node)?;
        }
        set(&mut entries, "fourier", Merged::Map(f));
    }
    Ok(entries)
}

/// `scale.inflow`: every flow condition's waveform times `factor`.
fn scale_inflow<N: Node + Clone>(source: &N, p: &mut Patched<N>, factor: f64) -> Result<()> {
    const PATH: &str = "scale.inflow";
    let nodes: Vec<String> = source
        .get("boundary_conditions")
        .map(|b| b.entries().into_iter().map(|(n, _)| n).collect())
        .unwrap_or_default();
    for node in nodes {
        let Some(bc) = condition_at(source, p, &node) else {
            continue;
        };
        let flow = bc.get("type").map(|t| t.show().to_lowercase());
        if flow.as_deref() != Some("flow") {
            continue;
        }
        let entries = bc.into_entries().unwrap_or_default();
        let has = |key: &str| {
            entries
                .iter()
                .any(|(k, v)| k == key && (key != "fourier" || v.is_map()))
        };
        if !(has("value") || has("flow") || has("fourier")) {
            return Err(error(
                PATH,
                format!(
                    "the flow condition at {} has no 'value', 'flow' or 'fourier' to scale",
                    py_quote(&node)
                ),
            ));
        }
        let entries = scale_waveform(entries, &["value", "flow"], factor, PATH, &node)?;
        set_at(&mut p.conditions, node, Merged::Map(entries));
        p.has_conditions = true;
    }
    Ok(())
}

/// `boundary_conditions.<node>.intramyocardial_pressure.scale`: the outlet's intramyocardial
/// pressure (a number, or a waveform's `value`/`pressure` table or `fourier`) times `factor`.
fn scale_intramyocardial<N: Node + Clone>(
    source: &N,
    p: &mut Patched<N>,
    node: &str,
    factor: f64,
    path: &str,
) -> Result<()> {
    let bc = condition_at(source, p, node).ok_or_else(|| {
        error(
            path,
            format!("no boundary condition at node {}", py_quote(node)),
        )
    })?;
    let mut entries = bc.into_entries().unwrap_or_default();
    let Some(w) = entries
        .iter()
        .find(|(k, _)| k == PIM_SCALE[0])
        .map(|(_, w)| w.clone())
    else {
        return Err(error(
            path,
            format!(
                "the condition at node {} has no intramyocardial pressure",
                py_quote(node)
            ),
        ));
    };
    let new = match w.clone().into_entries() {
        Some(we) => Merged::Map(scale_waveform(
            we,
            &["value", "pressure"],
            factor,
            path,
            node,
        )?),
        None => float_of(&w)
            .map(|x| Merged::Number(x * factor))
            .ok_or_else(|| {
                error(
                    path,
                    format!(
                        "cannot scale the intramyocardial pressure {}, not a number",
                        w.repr()
                    ),
                )
            })?,
    };
    set(&mut entries, PIM_SCALE[0], new);
    set_at(&mut p.conditions, node.to_owned(), Merged::Map(entries));
    p.has_conditions = true;
    Ok(())
}

/// `value` at the nested `keys` of the mapping `node` (None where a mapping is missing).
fn set_nested<N: Node + Clone>(node: Merged<N>, keys: &[&str], x: f64) -> Option<Merged<N>> {
    let mut entries = node.into_entries()?;
    let (first, rest) = keys.split_first()?;
    let value = if rest.is_empty() {
        Merged::Number(x)
    } else {
        let child = entries.iter().find(|(k, _)| k == first)?.1.clone();
        set_nested(child, rest, x)?
    };
    set(&mut entries, first, value);
    Some(Merged::Map(entries))
}

/// A heart element's value, set where the element holds it.
fn set_heart<N: Node + Clone>(source: &N, p: &mut Patched<N>, path: &str, x: f64) -> Result<()> {
    let parts = keys_of(source, path);
    let (i, v) = vessel(source, parts[1], path)?;
    let current = match p.vessels.iter().find(|(j, _)| *j == i) {
        Some((_, m)) => m.clone(),
        None => Merged::Node(v),
    };
    let new = set_nested(current, &parts[2..], x)
        .ok_or_else(|| error(path, "no such number in the model"))?;
    set_at(&mut p.vessels, i, new);
    p.has_vessels = true;
    Ok(())
}

/// A value of the model being patched read as a model value: what lets a patch be merged
/// into a model that parameters have already changed, and its waveforms be read.
impl<N: Node + Clone> Node for Merged<N> {
    fn kind(&self) -> Kind {
        match self {
            Merged::Node(n) => n.kind(),
            Merged::Map(_) => Kind::Map,
            Merged::Number(_) => Kind::Float,
            Merged::Numbers(_) => Kind::List,
        }
    }
    fn number(&self) -> Option<f64> {
        match self {
            Merged::Node(n) => n.number(),
            Merged::Number(x) => Some(*x),
            _ => None,
        }
    }
    fn integer(&self) -> Option<i64> {
        match self {
            Merged::Node(n) => n.integer(),
            _ => None,
        }
    }
    fn text(&self) -> Option<String> {
        match self {
            Merged::Node(n) => n.text(),
            _ => None,
        }
    }
    fn get(&self, key: &str) -> Option<Self> {
        Merged::get(self, key)
    }
    fn entries(&self) -> Vec<(String, Self)> {
        self.clone().into_entries().unwrap_or_default()
    }
    fn items(&self) -> Option<Vec<Self>> {
        match self {
            Merged::Node(n) => Some(n.items()?.into_iter().map(Merged::Node).collect()),
            Merged::Numbers(v) => Some(v.iter().map(|x| Merged::Number(*x)).collect()),
            _ => None,
        }
    }
    fn repr(&self) -> String {
        match self {
            Merged::Node(n) => n.repr(),
            Merged::Number(x) => py_repr(*x),
            Merged::Numbers(v) => py_list(v.iter().map(|x| py_repr(*x))),
            Merged::Map(e) => py_dict(e.iter().map(|(k, v)| (k, v.repr()))),
        }
    }
    fn show(&self) -> String {
        match self {
            Merged::Node(n) => n.show(),
            _ => self.repr(),
        }
    }
    fn type_name(&self) -> String {
        match self {
            Merged::Node(n) => n.type_name(),
            Merged::Map(_) => "dict".to_owned(),
            Merged::Number(_) => "float".to_owned(),
            Merged::Numbers(_) => "list".to_owned(),
        }
    }
    fn truthy(&self) -> bool {
        match self {
            Merged::Node(n) => n.truthy(),
            Merged::Map(e) => !e.is_empty(),
            Merged::Number(x) => *x != 0.0,
            Merged::Numbers(v) => !v.is_empty(),
        }
    }
    fn callable(&self) -> bool {
        matches!(self, Merged::Node(n) if n.callable())
    }
    fn call(&self, t: f64) -> std::result::Result<Self, String> {
        match self {
            Merged::Node(n) => n.call(t).map(Merged::Node),
            _ => Err(format!("{} is not callable", self.repr())),
        }
    }
}
