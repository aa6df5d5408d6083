//! Variant patches (docs/ensembles.md): what one member of an ensemble changes in its base
//! model, a nested mapping of the native model's paths to new values:
//!
//! ```text
//! vessels.<name>.<property>, vessels.<name>.lumped.<property>,
//! boundary_conditions.<node>.<property>, blood.<property>, oxygen.<...>, transport.<...>,
//! period, scale.{resistance, compliance, vessels}
//! ```
//!
//! [`merge`] applies a patch to the native model as the user wrote it (in its units; the
//! changed elements are then read by the schema reader like any model's): a waveform property
//! replaces the condition's whole waveform, `radius` replaces `radius_in`/`radius_out` and the
//! other way round, a new condition `type` replaces the whole condition, a new
//! `oxygen.wall.model` the whole wall; `scale` multiplies after the explicit values (the
//! resistances of the selected lumped vessels and of the resistance/RCR conditions at their
//! ends, their capacitances, and divides the Young's modulus of geometric vessels: C ∝ 1/E).
//!
//! Two kinds of mistakes: a path that names nothing of the model ([`PatchError::Name`]: an
//! unknown vessel, node, section or property, a topology change, a mapping where a number
//! belongs) is a mistake in the ensemble's definition; a value that cannot be applied
//! ([`PatchError::Value`]: a scale factor that is not a finite number, a number to scale that
//! is not one, a scaled value that is not finite, such as a Young's modulus divided by a
//! compliance factor 0) fails only its variant. Every message names the variant, the patch
//! path and the value.

use super::native::py_float;
use super::native::vessel::LUMPED_KEYS;
use super::node::{Kind, Node, py_repr};
use super::path::{BLOOD_KEYS, HEART_SECTIONS, Scope, at};
use crate::error::Error;
use std::collections::BTreeSet;

/// Vessel properties that hold one number: a mapping there is a dotted path gone too deep.
const VESSEL_SCALARS: &[&str] = &[
    "length",
    "radius",
    "radius_in",
    "radius_out",
    "wall_thickness",
    "youngs_modulus",
    "poisson_ratio",
    "segments",
];
const CONDITION_SCALARS: &[&str] = &[
    "resistance",
    "proximal_resistance",
    "distal_resistance",
    "capacitance",
];
/// The keys of a flow or pressure condition's waveform; patching one of the first five
/// replaces the whole waveform.
const WAVEFORM_KEYS: &[&str] = &[
    "time",
    "flow",
    "pressure",
    "value",
    "fourier",
    "interpolation",
    "steady",
];

/// Why a patch cannot be applied (see the module's documentation).
#[derive(Debug, Clone, PartialEq)]
pub enum PatchError {
    /// The path names nothing of the model: the ensemble's definition is wrong.
    Name(Error),
    /// The value cannot be applied: only this variant fails.
    Value(Error),
}

impl PatchError {
    pub fn error(&self) -> &Error {
        match self {
            PatchError::Name(e) | PatchError::Value(e) => e,
        }
    }
}

type Res<T> = std::result::Result<T, PatchError>;

/// A value of the patched model: a value of the base model or of the patch as it is, a
/// mapping rebuilt from both, a number computed by `scale`, or a table of numbers computed
/// by a parameter (a scaled waveform, `super::parameters`).
#[derive(Clone)]
pub enum Merged<N> {
    Node(N),
    Map(Vec<(String, Merged<N>)>),
    Number(f64),
    Numbers(Vec<f64>),
}

impl<N: Node + Clone> Merged<N> {
    /// The entries of a mapping (a node's read once), or None for anything else.
    pub(super) fn into_entries(self) -> Option<Vec<(String, Merged<N>)>> {
        match self {
            Merged::Map(e) => Some(e),
            Merged::Node(n) if n.is_map() => Some(
                n.entries()
                    .into_iter()
                    .map(|(k, v)| (k, Merged::Node(v)))
                    .collect(),
            ),
            _ => None,
        }
    }

    pub(super) fn get(&self, key: &str) -> Option<Merged<N>> {
        match self {
            Merged::Map(e) => e.iter().find(|(k, _)| k == key).map(|(_, v)| v.clone()),
            Merged::Node(n) => n.get(key).map(Merged::Node),
            Merged::Number(_) | Merged::Numbers(_) => None,
        }
    }
}

pub(super) fn set<N>(entries: &mut Vec<(String, Merged<N>)>, key: &str, value: Merged<N>) {
    match entries.iter_mut().find(|(k, _)| k == key) {
        Some(slot) => slot.1 = value,
        None => entries.push((key.to_owned(), value)),
    }
}

fn remove<N>(entries: &mut Vec<(String, Merged<N>)>, key: &str) -> Option<Merged<N>> {
    let i = entries.iter().position(|(k, _)| k == key)?;
    Some(entries.remove(i).1)
}

/// `patch` deep-merged into `base`: mappings merge key by key, anything else replaces.
fn deep_merge<N: Node + Clone>(base: Option<Merged<N>>, patch: &N) -> Merged<N> {
    let Some(mut entries) = base
        .filter(|_| patch.is_map())
        .and_then(Merged::into_entries)
    else {
        return Merged::Node(patch.clone());
    };
    for (key, value) in patch.entries() {
        let merged = if value.is_map() {
            let old = entries
                .iter()
                .find(|(k, _)| *k == key)
                .map(|(_, v)| v.clone());
            deep_merge(old, &value)
        } else {
            Merged::Node(value)
        };
        set(&mut entries, &key, merged);
    }
    Merged::Map(entries)
}

/// The patched parts of a model: every replaced vessel (by index) and condition (by node),
/// the replaced top-level sections (`blood`, `oxygen`, `transport`, `period`), and for each
/// changed element the patch paths that changed it, with their values (`path = value`), so
/// that a value the schema reader then refuses can be traced to the patch.
pub struct Patched<N> {
    pub vessels: Vec<(usize, Merged<N>)>,
    pub conditions: Vec<(String, Merged<N>)>,
    pub sections: Vec<(String, Merged<N>)>,
    pub vessel_paths: Vec<(usize, Vec<String>)>,
    pub condition_paths: Vec<(String, Vec<String>)>,
    /// Whether the patch has a `vessels` / `boundary_conditions` / `scale` section (the
    /// front end then rebuilds those containers).
    pub has_vessels: bool,
    pub has_conditions: bool,
}

fn name_error(k: usize, path: &str, message: impl Into<String>) -> PatchError {
    PatchError::Name(Error::model(at(k, path), message))
}

/// `key` (at `path`) checked against `scope` by the path resolver (`super::path`).
fn known(k: usize, path: &str, scope: Scope<'_>, key: &str) -> Res<()> {
    scope
        .check(key)
        .map_err(|message| name_error(k, path, message))
}

fn mapping<N: Node>(value: &N, k: usize, path: &str) -> Res<()> {
    if value.is_map() {
        return Ok(());
    }
    Err(name_error(
        k,
        path,
        format!("expected a mapping, got {}", value.repr()),
    ))
}

/// A mapping where `keys` hold one number is a dotted path one level too deep.
fn scalars<N: Node>(props: &N, keys: &[&str], k: usize, path: &str) -> Res<()> {
    for (key, value) in props.entries() {
        if keys.contains(&key.as_str()) && value.is_map() {
            return Err(name_error(
                k,
                &format!("{path}.{key}"),
                format!(
                    "expected a number, got the mapping {} (a dotted path ends at the property)",
                    value.repr()
                ),
            ));
        }
    }
    Ok(())
}

/// The scalar leaves of a patch value as `path = value` (a table is named, not listed).
fn leaves<N: Node>(value: &N, path: &str, out: &mut Vec<String>) {
    if value.is_map() {
        for (key, v) in value.entries() {
            leaves(&v, &format!("{path}.{key}"), out);
        }
    } else if matches!(value.kind(), Kind::List | Kind::Other) {
        out.push(format!("{path} (a table)"));
    } else {
        out.push(format!("{path} = {}", value.repr()));
    }
}

fn patch_vessel<N: Node + Clone>(
    vessel: Merged<N>,
    props: &N,
    k: usize,
    path: &str,
) -> Res<Merged<N>> {
    mapping(props, k, path)?;
    for (key, _) in props.entries() {
        if ["name", "from", "to"].contains(&key.as_str()) {
            return Err(name_error(
                k,
                &format!("{path}.{key}"),
                "a variant cannot change the network's topology",
            ));
        }
        known(k, &format!("{path}.{key}"), Scope::Vessel, &key)?;
    }
    scalars(props, VESSEL_SCALARS, k, path)?;
    if let Some(lumped) = props.get("lumped") {
        let lpath = format!("{path}.lumped");
        mapping(&lumped, k, &lpath)?;
        for (key, _) in lumped.entries() {
            known(k, &format!("{lpath}.{key}"), Scope::Lumped, &key)?;
        }
        scalars(&lumped, LUMPED_KEYS, k, &lpath)?;
    }
    check_heart(&vessel, props, k, path)?;
    let mut base = vessel.into_entries().unwrap_or_default();
    if props.has("radius") {
        remove(&mut base, "radius_in");
        remove(&mut base, "radius_out");
    } else if props.has("radius_in") || props.has("radius_out") {
        if let Some(r) = remove(&mut base, "radius") {
            set(&mut base, "radius_in", r.clone());
            set(&mut base, "radius_out", r);
        }
    }
    Ok(deep_merge(Some(Merged::Map(base)), props))
}

/// The text at `key` of a patch's section, else of the base model's (empty: neither has it).
fn given<N: Node + Clone>(patch: &N, base: Option<&Merged<N>>, key: &str) -> String {
    match patch.get(key) {
        Some(x) => x.show(),
        None => base
            .and_then(|b| b.get(key))
            .map(|x| text_of(&x))
            .unwrap_or_default(),
    }
}

/// Unknown keys of a patch's heart element sections (`chamber`, `valve`, …: the element's
/// law, the patch's else the base vessel's) and of a chamber's `activation` (its kind),
/// checked by the path resolver: a typo raises before anything runs, with the nearest key.
fn check_heart<N: Node + Clone>(vessel: &Merged<N>, props: &N, k: usize, path: &str) -> Res<()> {
    for kind in HEART_SECTIONS {
        let Some(section) = props.get(kind).filter(Node::is_map) else {
            continue;
        };
        let base = vessel.get(kind);
        let law = given(&section, base.as_ref(), "law");
        let spath = format!("{path}.{kind}");
        for (key, _) in section.entries() {
            known(k, &format!("{spath}.{key}"), Scope::Heart(kind, &law), &key)?;
        }
        let Some(act) = section.get("activation").filter(Node::is_map) else {
            continue;
        };
        let base_act = base.as_ref().and_then(|b| b.get("activation"));
        let act_kind = given(&act, base_act.as_ref(), "kind");
        for (key, _) in act.entries() {
            let apath = format!("{spath}.activation.{key}");
            known(k, &apath, Scope::Activation(&act_kind), &key)?;
        }
    }
    Ok(())
}

fn text_of<N: Node>(m: &Merged<N>) -> String {
    match m {
        Merged::Node(n) => n.show(),
        Merged::Number(x) => py_repr(*x),
        Merged::Map(_) | Merged::Numbers(_) => String::new(),
    }
}

fn patch_condition<N: Node + Clone>(
    bc: Merged<N>,
    props: &N,
    k: usize,
    path: &str,
) -> Res<Merged<N>> {
    mapping(props, k, path)?;
    let old_type = bc.get("type").map(|t| text_of(&t)).unwrap_or_default();
    let kind = props
        .get("type")
        .map_or_else(|| old_type.clone(), |t| t.show())
        .to_lowercase();
    for (key, _) in props.entries() {
        known(k, &format!("{path}.{key}"), Scope::Condition(&kind), &key)?;
    }
    scalars(props, CONDITION_SCALARS, k, path)?;
    if props.has("type") && kind != old_type.to_lowercase() {
        return Ok(Merged::Node(props.clone())); // another kind: nothing of the old one holds
    }
    let mut base = bc.into_entries().unwrap_or_default();
    let waveform = WAVEFORM_KEYS[..5].iter().any(|key| props.has(key));
    if (kind == "flow" || kind == "pressure") && waveform {
        base.retain(|(key, _)| !WAVEFORM_KEYS.contains(&key.as_str()));
    }
    if props.has("pressure") {
        // a resistance/RCR outlet pressure: a number or a waveform, replaced as a whole
        remove(&mut base, "pressure");
    }
    Ok(deep_merge(Some(Merged::Map(base)), props))
}

/// The closure of an `oxygen.wall` entry (a mapping with `model`, or its name).
fn wall_model<N: Node>(wall: Option<N>) -> String {
    match wall {
        Some(w) if w.is_map() => w.get("model").map(|m| m.show()).unwrap_or_default(),
        Some(w) => w.show(),
        None => "None".to_owned(),
    }
}

/// Unknown keys of an `oxygen` or `transport` patch and of its `oxygen.wall`.
fn check_transport<N: Node>(source: &N, section: &str, patch: &N, k: usize) -> Res<()> {
    let scope = if section == "oxygen" {
        Scope::Oxygen
    } else {
        Scope::Transport
    };
    for (key, _) in patch.entries() {
        known(k, &format!("{section}.{key}"), scope, &key)?;
    }
    let Some(wall) = patch
        .get("wall")
        .filter(|w| section == "oxygen" && w.is_map())
    else {
        return Ok(());
    };
    let model = wall.get("model").map_or_else(
        || wall_model(source.get(section).and_then(|s| s.get("wall"))),
        |m| m.show(),
    );
    for (key, _) in wall.entries() {
        known(k, &format!("oxygen.wall.{key}"), Scope::Wall(&model), &key)?;
    }
    Ok(())
}

/// The vessels a `scale` section selects (None: all) and its factors, checked.
struct Scale {
    selected: Option<BTreeSet<usize>>,
    factors: Vec<(&'static str, f64)>,
}

fn scale_terms<N: Node>(scale: &N, names: &[String], k: usize) -> Res<Scale> {
    mapping(scale, k, "scale")?;
    for (key, _) in scale.entries() {
        known(k, &format!("scale.{key}"), Scope::Scale, &key)?;
    }
    let mut selected = None;
    if let Some(chosen) = scale
        .get("vessels")
        .filter(|c| c.text().as_deref() != Some("all"))
    {
        let items = (chosen.kind() == Kind::List)
            .then(|| chosen.items())
            .flatten();
        let Some(items) = items else {
            let message = format!(
                "expected 'all' or a list of vessel names, got {}",
                chosen.repr()
            );
            return Err(name_error(k, "scale.vessels", message));
        };
        let mut set = BTreeSet::new();
        for item in items {
            let name = item.show();
            let Some(i) = names.iter().position(|n| *n == name) else {
                let message = format!("no vessel named {} in the model", item.repr());
                return Err(name_error(k, &format!("scale.vessels.{name}"), message));
            };
            set.insert(i);
        }
        selected = Some(set);
    }
    let mut factors = Vec::new();
    for key in ["resistance", "compliance"] {
        let Some(f) = scale.get(key) else { continue };
        let x = matches!(f.kind(), Kind::Int | Kind::Float)
            .then(|| f.number())
            .flatten()
            .filter(|x| x.is_finite());
        let Some(x) = x else {
            let shown: String = f.repr().chars().take(40).collect();
            let e = Error::model(
                at(k, &format!("scale.{key}")),
                format!("expected a number, got {shown}"),
            );
            return Err(PatchError::Value(e));
        };
        factors.push((key, x));
    }
    Ok(Scale { selected, factors })
}

/// A number of the model to scale (YAML 1.1 reads 5.0e5 as text, read as Python's `float`).
fn scale_base<N: Node>(x: Option<&Merged<N>>, k: usize, path: &str) -> Res<f64> {
    let value = match x {
        Some(Merged::Number(v)) => Some(*v),
        Some(Merged::Node(n)) => match n.kind() {
            Kind::Int | Kind::Float => n.number(),
            Kind::Bool => Some(if n.truthy() { 1.0 } else { 0.0 }),
            Kind::Str => n.text().and_then(|s| py_float(&s)),
            _ => None,
        },
        _ => None,
    };
    value.ok_or_else(|| {
        let shown = match x {
            Some(Merged::Node(n)) => n.repr(),
            Some(Merged::Map(_)) => "a mapping".to_owned(),
            Some(Merged::Numbers(_)) => "a table".to_owned(),
            _ => "None".to_owned(),
        };
        PatchError::Value(Error::model(
            at(k, path),
            format!("cannot scale {shown}, not a number"),
        ))
    })
}

/// One scaled number: `base * factor` (`base / factor` for a Young's modulus), which must be
/// finite: a compliance factor 0 would make a wall infinitely stiff.
struct Scaling<'a> {
    k: usize,
    key: &'static str,
    factor: f64,
    element: &'a str,
}

impl Scaling<'_> {
    fn apply<N: Node>(
        &self,
        entries: &mut Vec<(String, Merged<N>)>,
        prop: &str,
        path: &str,
        divide: bool,
    ) -> Res<()> {
        let old = entries.iter().find(|(key, _)| key == prop).map(|(_, v)| v);
        let base = scale_base(old, self.k, path)?;
        let (value, op) = if divide {
            (base / self.factor, "/")
        } else {
            (base * self.factor, "*")
        };
        if !value.is_finite() {
            let message = format!(
                "factor {} makes {prop} of {} {} {op} {} = {}, not a finite number ({})",
                py_repr(self.factor),
                self.element,
                py_repr(base),
                py_repr(self.factor),
                py_repr(value),
                if divide {
                    "a compliance factor must not be 0"
                } else {
                    "the factor is too large for this value"
                },
            );
            let e = Error::model(at(self.k, &format!("scale.{}", self.key)), message);
            return Err(PatchError::Value(e));
        }
        set(entries, prop, Merged::Number(value));
        Ok(())
    }
}

/// The model being patched: the base model's vessels and conditions, the replaced ones.
struct Work<'a, N> {
    source: &'a N,
    k: usize,
    names: Vec<String>,
    base_vessels: Vec<N>,
    vessels: Vec<(usize, Merged<N>)>,
    conditions: Vec<(String, Merged<N>)>,
    vessel_paths: Vec<(usize, Vec<String>)>,
    condition_paths: Vec<(String, Vec<String>)>,
}

fn note<K: PartialEq + Clone>(paths: &mut Vec<(K, Vec<String>)>, key: &K, new: Vec<String>) {
    match paths.iter_mut().find(|(k, _)| k == key) {
        Some((_, p)) => p.extend(new),
        None => paths.push((key.clone(), new)),
    }
}

impl<N: Node + Clone> Work<'_, N> {
    fn vessel(&self, i: usize) -> Merged<N> {
        match self.vessels.iter().find(|(j, _)| *j == i) {
            Some((_, v)) => v.clone(),
            None => Merged::Node(self.base_vessels[i].clone()),
        }
    }

    fn condition(&self, node: &str) -> Option<Merged<N>> {
        match self.conditions.iter().find(|(n, _)| n == node) {
            Some((_, c)) => Some(c.clone()),
            None => self
                .source
                .get("boundary_conditions")?
                .get(node)
                .map(Merged::Node),
        }
    }

    fn model_name(&self) -> String {
        self.source
            .get("name")
            .map_or_else(|| "network".to_owned(), |n| n.show())
    }

    fn patch_vessels(&mut self, patch: &N) -> Res<()> {
        mapping(patch, self.k, "vessels")?;
        for (name, props) in patch.entries() {
            let path = format!("vessels.{name}");
            let Some(i) = self.names.iter().position(|n| *n == name) else {
                let message = format!("no vessel named '{name}' in model '{}'", self.model_name());
                return Err(name_error(self.k, &path, message));
            };
            let merged = patch_vessel(self.vessel(i), &props, self.k, &path)?;
            set_at(&mut self.vessels, i, merged);
            let mut paths = Vec::new();
            leaves(&props, &path, &mut paths);
            note(&mut self.vessel_paths, &i, paths);
        }
        Ok(())
    }

    fn patch_conditions(&mut self, patch: &N) -> Res<()> {
        mapping(patch, self.k, "boundary_conditions")?;
        for (node, props) in patch.entries() {
            let path = format!("boundary_conditions.{node}");
            let Some(bc) = self.condition(&node) else {
                let message = format!(
                    "no boundary condition at node '{node}' in model '{}'",
                    self.model_name()
                );
                return Err(name_error(self.k, &path, message));
            };
            let merged = patch_condition(bc, &props, self.k, &path)?;
            set_at(&mut self.conditions, node.clone(), merged);
            let mut paths = Vec::new();
            leaves(&props, &path, &mut paths);
            note(&mut self.condition_paths, &node, paths);
        }
        Ok(())
    }
}

pub(super) fn set_at<K: PartialEq, V>(items: &mut Vec<(K, V)>, key: K, value: V) {
    match items.iter_mut().find(|(k, _)| *k == key) {
        Some(slot) => slot.1 = value,
        None => items.push((key, value)),
    }
}

impl<N: Node + Clone> Work<'_, N> {
    /// Apply `scale` to the merged vessels and to the conditions at their ends.
    fn scale(&mut self, scale: &N) -> Res<()> {
        let terms = scale_terms(scale, &self.names, self.k)?;
        let factor = |key: &str| terms.factors.iter().find(|(n, _)| *n == key).map(|p| p.1);
        let mut ends: BTreeSet<String> = BTreeSet::new();
        let all: Vec<usize> = (0..self.names.len()).collect();
        let chosen: Vec<usize> = terms
            .selected
            .as_ref()
            .map_or(all, |s| s.iter().copied().collect());
        for i in chosen {
            let v = self.vessel(i);
            for end in ["from", "to"] {
                ends.insert(
                    v.get(end)
                        .map_or_else(|| "None".to_owned(), |n| text_of(&n)),
                );
            }
            let name = &self.names[i];
            let element = format!("vessel '{name}'");
            let mut entries = v.into_entries().unwrap_or_default();
            let mut paths = Vec::new();
            if let Some(lumped) = entries
                .iter()
                .find(|(k, _)| k == "lumped")
                .map(|p| p.1.clone())
            {
                let mut lp = lumped.into_entries().unwrap_or_default();
                for (key, prop) in [("resistance", "resistance"), ("compliance", "capacitance")] {
                    let Some(f) = factor(key) else { continue };
                    if lp.iter().any(|(k, _)| k == prop) {
                        let s = Scaling {
                            k: self.k,
                            key: if key == "resistance" {
                                "resistance"
                            } else {
                                "compliance"
                            },
                            factor: f,
                            element: &element,
                        };
                        s.apply(
                            &mut lp,
                            prop,
                            &format!("vessels.{name}.lumped.{prop}"),
                            false,
                        )?;
                        paths.push(format!("scale.{key} = {}", py_repr(f)));
                    }
                }
                set(&mut entries, "lumped", Merged::Map(lp));
            } else if let Some(f) =
                factor("compliance").filter(|_| entries.iter().any(|(k, _)| k == "youngs_modulus"))
            {
                let s = Scaling {
                    k: self.k,
                    key: "compliance",
                    factor: f,
                    element: &element,
                };
                s.apply(
                    &mut entries,
                    "youngs_modulus",
                    &format!("vessels.{name}.youngs_modulus"),
                    true,
                )?;
                paths.push(format!("scale.compliance = {}", py_repr(f)));
            } else {
                continue;
            }
            set_at(&mut self.vessels, i, Merged::Map(entries));
            note(&mut self.vessel_paths, &i, paths);
        }
        self.scale_conditions(&ends, factor("resistance"), factor("compliance"))
    }

    /// The resistance and RCR conditions at the ends of the scaled vessels.
    fn scale_conditions(
        &mut self,
        ends: &BTreeSet<String>,
        resistance: Option<f64>,
        compliance: Option<f64>,
    ) -> Res<()> {
        let nodes: Vec<String> = self
            .source
            .get("boundary_conditions")
            .map(|b| b.entries().into_iter().map(|(n, _)| n).collect())
            .unwrap_or_default();
        for node in nodes.into_iter().filter(|n| ends.contains(n)) {
            let Some(bc) = self.condition(&node) else {
                continue;
            };
            let kind = bc
                .get("type")
                .map(|t| text_of(&t))
                .unwrap_or_default()
                .to_lowercase();
            let mut props: Vec<(&'static str, &str, f64)> = Vec::new();
            if let Some(f) = resistance {
                match kind.as_str() {
                    "resistance" => props.push(("resistance", "resistance", f)),
                    "rcr" => {
                        props.push(("resistance", "proximal_resistance", f));
                        props.push(("resistance", "distal_resistance", f));
                    }
                    _ => {}
                }
            }
            if let Some(f) = compliance.filter(|_| kind == "rcr") {
                props.push(("compliance", "capacitance", f));
            }
            if props.is_empty() {
                continue; // an inflow stays as it is
            }
            let element = format!("boundary condition '{node}'");
            let mut entries = bc.into_entries().unwrap_or_default();
            let mut paths = Vec::new();
            for (key, prop, f) in props {
                let s = Scaling {
                    k: self.k,
                    key,
                    factor: f,
                    element: &element,
                };
                s.apply(
                    &mut entries,
                    prop,
                    &format!("boundary_conditions.{node}.{prop}"),
                    false,
                )?;
                paths.push(format!("scale.{key} = {}", py_repr(f)));
            }
            paths.dedup();
            set_at(&mut self.conditions, node.clone(), Merged::Map(entries));
            note(&mut self.condition_paths, &node, paths);
        }
        Ok(())
    }
}

/// `patch` (variant `k`) applied to the native model `source`: the replaced elements and
/// sections (see [`Patched`]), or why it cannot be (see [`PatchError`]).
pub fn merge<N: Node + Clone>(source: &N, patch: &N, k: usize) -> Res<Patched<N>> {
    mapping(patch, k, "patch")?;
    for (key, _) in patch.entries() {
        known(k, &key, Scope::PatchSection, &key)?;
    }
    let base_vessels = source
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default();
    let names = base_vessels
        .iter()
        .map(|v| v.get("name").map(|n| n.show()).unwrap_or_default())
        .collect();
    let mut work = Work {
        source,
        k,
        names,
        base_vessels,
        vessels: Vec::new(),
        conditions: Vec::new(),
        vessel_paths: Vec::new(),
        condition_paths: Vec::new(),
    };
    if let Some(v) = patch.get("vessels") {
        work.patch_vessels(&v)?;
    }
    if let Some(b) = patch.get("boundary_conditions") {
        work.patch_conditions(&b)?;
    }
    let sections = sections(source, patch, k)?;
    if let Some(s) = patch.get("scale") {
        work.scale(&s)?;
    }
    Ok(Patched {
        vessels: work.vessels,
        conditions: work.conditions,
        sections,
        vessel_paths: work.vessel_paths,
        condition_paths: work.condition_paths,
        has_vessels: patch.has("vessels") || patch.has("scale"),
        has_conditions: patch.has("boundary_conditions") || patch.has("scale"),
    })
}

/// The replaced `blood`, `oxygen`, `transport` and `period` sections.
fn sections<N: Node + Clone>(source: &N, patch: &N, k: usize) -> Res<Vec<(String, Merged<N>)>> {
    let mut out = Vec::new();
    if let Some(blood) = patch.get("blood") {
        mapping(&blood, k, "blood")?;
        for (key, _) in blood.entries() {
            known(k, &format!("blood.{key}"), Scope::Blood, &key)?;
        }
        scalars(&blood, BLOOD_KEYS, k, "blood")?;
        let base = source
            .get("blood")
            .filter(Node::truthy)
            .map_or(Merged::Map(Vec::new()), Merged::Node);
        out.push(("blood".to_owned(), deep_merge(Some(base), &blood)));
    }
    for section in ["oxygen", "transport"] {
        let Some(p) = patch.get(section) else {
            continue;
        };
        let Some(base) = source.get(section) else {
            let message = format!("the model has no '{section}' section to patch");
            return Err(name_error(k, section, message));
        };
        mapping(&p, k, section)?;
        check_transport(source, section, &p, k)?;
        let mut merged = deep_merge(Some(Merged::Node(base.clone())), &p);
        let wall = p.get("wall").filter(|w| section == "oxygen" && w.is_map());
        if let Some(wall) = wall.filter(|w| w.has("model")) {
            let model = wall.get("model").map(|m| m.show()).unwrap_or_default();
            if model != wall_model(base.get("wall")) {
                // another wall closure: none of the old one's keys hold
                let mut entries = merged.into_entries().unwrap_or_default();
                set(&mut entries, "wall", Merged::Node(wall));
                merged = Merged::Map(entries);
            }
        }
        out.push((section.to_owned(), merged));
    }
    if let Some(p) = patch.get("period") {
        out.push(("period".to_owned(), Merged::Node(p)));
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
