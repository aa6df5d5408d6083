//! A vessel of the native schema and the elements that stand in its place (lumped R–L–C,
//! valve, chamber, flow-through RC, spherical chamber, closed-loop heart block and coronary
//! bed; docs/physics.md §1.8–1.11), checked and converted to the canonical SI form.

use super::{check_keys, err, name_of, number, positive, py_list};
use crate::error::Result;
use crate::model::node::{Node, py_repr};
use crate::model::units::{Quantity, Quantity::*, Units};
use serde_json::{Map, Value, json};

pub const VESSEL_KEYS: &[&str] = &[
    "name",
    "from",
    "to",
    "length",
    "radius",
    "radius_in",
    "radius_out",
    "wall_thickness",
    "youngs_modulus",
    "poisson_ratio",
    "wall_viscosity",
    "segments",
    "lumped",
    "arrangement",
    "wall_friction",
    "output",
    "description",
    "valve",
    "chamber",
    "through_rc",
    "heart_pulmonary",
    "coronary_bed",
    "initial",
    "initial_rate",
    "chamber_sphere",
];
pub const ARRANGEMENTS: &[&str] = &["inverted-L", "L", "pi", "RCL"];
/// A segment's friction and inertia: Poiseuille, or Womersley's (docs/physics.md §1.12).
pub const WALL_FRICTIONS: &[&str] = &["poiseuille", "womersley"];
pub const LUMPED_KEYS: &[&str] = &[
    "resistance",
    "inductance",
    "capacitance",
    "stenosis_coefficient",
    "stenosis_form",
];
/// How generalized-α discretises an RCL vessel's stenosis (docs/svzerod.md, "C + stenosis").
pub const STENOSIS_FORMS: &[&str] = &["branch", "svzerod"];
/// A vessel's start values (docs/physics.md §1.9): end pressures and flows.
const START_KEYS: &[(&str, Quantity)] = &[
    ("pressure_in", Pressure),
    ("pressure_out", Pressure),
    ("flow_in", Flow),
    ("flow_out", Flow),
];
const VALVE_LAWS: &[(&str, &[(&str, Quantity)])] = &[
    (
        "tanh",
        &[
            ("min_resistance", Resistance),
            ("max_resistance", Resistance),
            ("steepness", PerPressure),
        ],
    ),
    (
        "piecewise",
        &[
            ("min_resistance", Resistance),
            ("max_resistance", Resistance),
        ],
    ),
];
const CHAMBER_LAWS: &[(&str, &[(&str, Quantity)])] = &[
    (
        "elastance-inductor",
        &[
            ("max_elastance", Elastance),
            ("min_elastance", Elastance),
            ("rest_volume_diastole", Volume),
            ("rest_volume_systole", Volume),
        ],
    ),
    (
        "linear",
        &[
            ("max_elastance", Elastance),
            ("passive_elastance", Elastance),
            ("rest_volume", Volume),
        ],
    ),
    (
        "exponential",
        &[
            ("max_elastance", Elastance),
            ("passive_pressure", Pressure),
            ("passive_volume_coefficient", PerVolume),
            ("rest_volume", Volume),
        ],
    ),
];
const CHAMBER_COMMON: &[(&str, Quantity)] = &[
    ("period", Time),
    ("inductance", Inductance),
    ("initial_volume", Volume),
];
const ACTIVATIONS: &[(&str, &[&str])] = &[
    ("half-cosine", &["t_active", "t_twitch"]),
    (
        "piecewise-cosine",
        &[
            "contract_start",
            "relax_start",
            "contract_duration",
            "relax_duration",
        ],
    ),
    ("two-hill", &["t_shift", "tau_1", "tau_2", "m1", "m2"]),
    ("wrapping-cosine", &["systole_fraction", "p_wave_divisor"]),
    ("fourier", &[]),
];
const THROUGH_RC_KEYS: &[(&str, Quantity)] =
    &[("resistance", Resistance), ("capacitance", Capacitance)];
const CHAMBER_SPHERE_KEYS: &[(&str, Quantity)] = &[
    ("density", Density),
    ("wall_thickness", Length),
    ("reference_radius", Length),
    ("w1", Pressure),
    ("w2", Pressure),
    ("viscosity", Viscosity),
    ("max_active_stress", Pressure),
    ("max_activation_rate", PerTime),
    ("min_activation_rate", PerTime),
    ("systole_start", Time),
    ("diastole_start", Time),
    ("activation_steepness", Time),
    ("period", Time),
];
/// The closed-loop heart block (docs/physics.md §1.10).
const HEART_PULMONARY_KEYS: &[(&str, Quantity)] = &[
    ("period", Time),
    ("atrial_systole_fraction", Number),
    ("p_wave_divisor", Number),
    ("right_ventricle_elastance", Elastance),
    ("right_ventricle_rest_volume", Volume),
    ("left_ventricle_elastance", Elastance),
    ("left_ventricle_rest_volume", Volume),
    ("right_atrium_elastance", Elastance),
    ("right_atrium_passive_pressure", Pressure),
    ("right_atrium_passive_volume_coefficient", PerVolume),
    ("right_atrium_rest_volume", Volume),
    ("left_atrium_elastance", Elastance),
    ("left_atrium_passive_pressure", Pressure),
    ("left_atrium_passive_volume_coefficient", PerVolume),
    ("left_atrium_rest_volume", Volume),
    ("tricuspid_resistance", Resistance),
    ("tricuspid_inductance", Inductance),
    ("pulmonary_valve_resistance", Resistance),
    ("pulmonary_valve_inductance", Inductance),
    ("mitral_resistance", Resistance),
    ("mitral_inductance", Inductance),
    ("aortic_valve_resistance", Resistance),
    ("aortic_valve_inductance", Inductance),
    ("pulmonary_resistance", Resistance),
    ("pulmonary_capacitance", Capacitance),
    ("aortic_capacitance", Capacitance),
];
const HEART_PULMONARY_START: &[(&str, Quantity)] = &[
    ("initial_right_atrium_volume", Volume),
    ("initial_right_ventricle_volume", Volume),
    ("initial_left_atrium_volume", Volume),
    ("initial_left_ventricle_volume", Volume),
    ("initial_pulmonary_pressure", Pressure),
];
const CORONARY_BED_KEYS: &[(&str, Quantity)] = &[
    ("arterial_resistance", Resistance),
    ("arterial_capacitance", Capacitance),
    ("microvascular_resistance", Resistance),
    ("intramyocardial_capacitance", Capacitance),
    ("venous_resistance", Resistance),
    ("intramyocardial_factor", Number),
];

/// Keys and their quantities.
type Table = &'static [(&'static str, Quantity)];

fn names<'a>(table: &[(&'a str, Quantity)]) -> Vec<&'a str> {
    table.iter().map(|(k, _)| *k).collect()
}

/// The keys a heart element's section may hold, as [`vessel`] checks them: a `chamber` or
/// `valve` of law `law` (None for a law the schema does not know: its reader names the law),
/// a `chamber_sphere`, a `heart_pulmonary` block, a `coronary_bed`, a `through_rc`.
pub fn heart_keys(kind: &str, law: &str) -> Option<Vec<&'static str>> {
    let keys = match kind {
        "chamber" | "valve" => {
            let chamber = kind == "chamber";
            let laws = if chamber { CHAMBER_LAWS } else { VALVE_LAWS };
            let (_, table) = laws.iter().find(|(name, _)| *name == law)?;
            let mut keys = names(table);
            keys.push("law");
            if chamber {
                keys.extend(names(CHAMBER_COMMON));
                keys.push("activation");
            }
            keys
        }
        "chamber_sphere" => names(CHAMBER_SPHERE_KEYS),
        "heart_pulmonary" => {
            let mut keys = names(HEART_PULMONARY_KEYS);
            keys.extend(names(HEART_PULMONARY_START));
            keys.push("units");
            keys
        }
        "coronary_bed" => {
            let mut keys = names(CORONARY_BED_KEYS);
            keys.extend(["units", "heart", "ventricle"]);
            keys
        }
        "through_rc" => names(THROUGH_RC_KEYS),
        _ => return None,
    };
    Some(keys)
}

/// Every key a heart element's section of `kind` holds under any of its laws, a chamber's
/// activation keys (of every kind) as `activation.<key>`: the keys a parameter path may name
/// after the element, each law's own picked by its reader.
pub fn heart_key_paths(kind: &str) -> Vec<String> {
    let laws: &[(&str, Table)] = match kind {
        "chamber" => CHAMBER_LAWS,
        "valve" => VALVE_LAWS,
        _ => &[],
    };
    let mut keys: Vec<String> = laws
        .iter()
        .flat_map(|(law, _)| heart_keys(kind, law).unwrap_or_default())
        .chain(heart_keys(kind, "").unwrap_or_default())
        .map(str::to_owned)
        .collect();
    if kind == "chamber" {
        let timing = ACTIVATIONS.iter().flat_map(|(_, keys)| keys.iter());
        keys.extend(timing.map(|k| format!("activation.{k}")));
    }
    let mut seen = std::collections::HashSet::new();
    keys.retain(|k| seen.insert(k.clone()));
    keys
}

/// The keys of a chamber's `activation` of kind `kind` (None for a kind the schema does not
/// know), as [`vessel`] checks them.
pub fn activation_keys(kind: &str) -> Option<Vec<&'static str>> {
    let (_, keys) = ACTIVATIONS.iter().find(|(name, _)| *name == kind)?;
    let mut keys = keys.to_vec();
    keys.push("kind");
    Some(keys)
}

/// The canonical form of vessel `i` (0-based), checking every key and value.
pub fn vessel<N: Node>(v: &N, i: usize, units: Units) -> Result<Value> {
    let el = match v
        .get("name")
        .filter(|n| n.kind() != crate::model::node::Kind::Null)
    {
        Some(n) if v.is_map() => format!("vessel '{}'", n.show()),
        _ => format!("vessel #{i}"),
    };
    check_keys(v, VESSEL_KEYS, &el)?;
    let mut cv = Map::new();
    for k in ["name", "from", "to"] {
        let x = v.get(k).ok_or_else(|| err(&el, format!("missing '{k}'")))?;
        let n = name_of(&x)
            .ok_or_else(|| err(&el, format!("'{k}' must be a name, got {}", x.repr())))?;
        cv.insert(k.into(), json!(n));
    }
    if let Some(n) = v.get("segments") {
        match n.integer().filter(|&n| n >= 1) {
            Some(x) if n.kind() == crate::model::node::Kind::Int => {
                cv.insert("segments".into(), json!(x));
            }
            _ if n.text().as_deref() == Some("auto") => {
                cv.insert("segments_auto".into(), json!(true));
            }
            _ => {
                return Err(err(
                    &el,
                    format!(
                        "'segments' must be an integer >= 1 or 'auto', got {}",
                        n.repr()
                    ),
                ));
            }
        }
    }
    if let Some(a) = v.get("arrangement") {
        match a.text() {
            Some(t) if ARRANGEMENTS.contains(&t.as_str()) => {
                cv.insert("arrangement".into(), json!(t));
            }
            _ => {
                return Err(err(
                    &el,
                    format!(
                        "arrangement must be one of {}, got {}",
                        py_list(ARRANGEMENTS),
                        a.repr()
                    ),
                ));
            }
        }
    }
    if let Some(o) = v.get("output") {
        cv.insert("output".into(), json!(o.truthy()));
    }
    for key in ["initial", "initial_rate"] {
        if let Some(d) = v.get(key) {
            cv.insert(key.into(), start_values(&d, &el, key, units)?);
        }
    }
    if (v.has("wall_friction") || v.has("wall_viscosity"))
        && [
            "heart_pulmonary",
            "coronary_bed",
            "chamber_sphere",
            "valve",
            "chamber",
            "through_rc",
        ]
        .iter()
        .any(|k| v.has(k))
    {
        return Err(err(
            &el,
            "wall_friction and wall_viscosity apply to a vessel with length and radius, not to a heart, valve or lumped element",
        ));
    }
    if v.has("heart_pulmonary") || v.has("coronary_bed") {
        return closed_loop_element(v, cv, &el, units);
    }
    if v.has("chamber_sphere") {
        return sphere_element(v, cv, &el, units);
    }
    if v.has("valve") || v.has("chamber") || v.has("through_rc") {
        return heart_element(v, cv, &el, units);
    }
    let friction = wall_friction(v, &el)?;
    if let Some(lp) = v.get("lumped") {
        if friction.as_deref() == Some("womersley") {
            return Err(err(
                &el,
                "wall_friction 'womersley' needs the vessel's length and radius, not lumped values",
            ));
        }
        if v.has("wall_viscosity") {
            // (before: accepted and ignored)
            return Err(err(
                &el,
                "wall_viscosity needs a wall (wall_thickness and youngs_modulus), not lumped values",
            ));
        }
        cv.insert("lumped".into(), lumped(&lp, &el, units)?);
    } else {
        cv.insert("geometry".into(), geometry(v, &el, units)?);
        if let Some(f) = friction {
            cv.insert("wall_friction".into(), json!(f));
        }
    }
    Ok(Value::Object(cv))
}

/// The vessel's `wall_friction` (None: the model's), checked against [`WALL_FRICTIONS`].
fn wall_friction<N: Node>(v: &N, el: &str) -> Result<Option<String>> {
    let Some(x) = v.get("wall_friction") else {
        return Ok(None);
    };
    match x.text() {
        Some(t) if WALL_FRICTIONS.contains(&t.as_str()) => Ok(Some(t)),
        _ => Err(err(
            el,
            format!(
                "wall_friction must be one of {}, got {}",
                py_list(WALL_FRICTIONS),
                x.repr()
            ),
        )),
    }
}

fn lumped<N: Node>(lp: &N, el: &str, units: Units) -> Result<Value> {
    check_keys(lp, LUMPED_KEYS, &format!("{el} lumped"))?;
    if !lp.has("resistance") {
        return Err(err(el, "lumped needs 'resistance'"));
    }
    let mut out = Map::new();
    for (k, x) in lp.entries() {
        // calibrated svZeroDSolver models carry negative stenosis coefficients: the core
        // accepts any finite one, so only R, L and C must be >= 0
        let (q, value) = match k.as_str() {
            "stenosis_form" => continue,
            "stenosis_coefficient" => (Stenosis, number(Some(&x), el, &k)?),
            "resistance" => (Resistance, positive(Some(&x), el, &k, true)?),
            "inductance" => (Inductance, positive(Some(&x), el, &k, true)?),
            _ => (Capacitance, positive(Some(&x), el, &k, true)?),
        };
        out.insert(k, json!(units.factor(q) * value));
    }
    if let Some(form) = lp.get("stenosis_form") {
        match form.text() {
            Some(t) if STENOSIS_FORMS.contains(&t.as_str()) => {
                out.insert("stenosis_form".into(), json!(t));
            }
            _ => {
                return Err(err(
                    el,
                    format!(
                        "lumped stenosis_form must be one of ['branch', 'svzerod'], got {}",
                        form.repr()
                    ),
                ));
            }
        }
    }
    Ok(Value::Object(out))
}

fn geometry<N: Node>(v: &N, el: &str, units: Units) -> Result<Value> {
    let l = units.factor(Length);
    if !v.has("length") {
        return Err(err(el, "missing 'length' (or give 'lumped' values)"));
    }
    if v.has("radius") && (v.has("radius_in") || v.has("radius_out")) {
        return Err(err(
            el,
            "give 'radius' or 'radius_in'/'radius_out', not both",
        ));
    }
    let (r_in, r_out) = if v.has("radius") {
        let r = positive(v.get("radius").as_ref(), el, "radius", false)?;
        (r, r)
    } else if v.has("radius_in") && v.has("radius_out") {
        (
            positive(v.get("radius_in").as_ref(), el, "radius_in", false)?,
            positive(v.get("radius_out").as_ref(), el, "radius_out", false)?,
        )
    } else {
        return Err(err(
            el,
            "missing 'radius' (or 'radius_in' and 'radius_out')",
        ));
    };
    let length = positive(v.get("length").as_ref(), el, "length", false)?;
    let mut g = Map::new();
    g.insert("length".into(), json!(l * length));
    g.insert("radius_in".into(), json!(l * r_in));
    g.insert("radius_out".into(), json!(l * r_out));
    if let Some(h) = v.get("wall_thickness") {
        let h = positive(Some(&h), el, "wall_thickness", false)?;
        g.insert("wall_thickness".into(), json!(l * h));
    }
    if let Some(e) = v.get("youngs_modulus") {
        let e = positive(Some(&e), el, "youngs_modulus", false)?;
        g.insert("youngs_modulus".into(), json!(units.factor(Modulus) * e));
    }
    if let Some(eta) = v.get("wall_viscosity") {
        let eta = positive(Some(&eta), el, "wall_viscosity", true)?;
        if !(v.has("wall_thickness") && v.has("youngs_modulus")) {
            return Err(err(
                el,
                "wall_viscosity needs a wall (wall_thickness and youngs_modulus)",
            ));
        }
        g.insert(
            "wall_viscosity".into(),
            json!(units.factor(Viscosity) * eta),
        );
    }
    if let Some(nu) = v.get("poisson_ratio") {
        g.insert(
            "poisson_ratio".into(),
            json!(number(Some(&nu), el, "poisson_ratio")?),
        );
    }
    Ok(Value::Object(g))
}

/// A vessel's `initial` (or `initial_rate`: the same quantities per second) in SI.
fn start_values<N: Node>(d: &N, el: &str, key: &str, units: Units) -> Result<Value> {
    if !d.is_map() {
        return Err(err(
            el,
            format!(
                "'{key}' must be a mapping of ['flow_in', 'flow_out', 'pressure_in', 'pressure_out']"
            ),
        ));
    }
    let allowed: Vec<&str> = START_KEYS.iter().map(|(k, _)| *k).collect();
    check_keys(d, &allowed, &format!("{el} {key}"))?;
    let mut out = Map::new();
    for (k, x) in d.entries() {
        let q = START_KEYS
            .iter()
            .find(|(name, _)| *name == k)
            .map_or(Pressure, |(_, q)| *q);
        let value = number(Some(&x), el, &format!("{key} {k}"))?;
        out.insert(k, json!(units.factor(q) * value));
    }
    Ok(Value::Object(out))
}

/// The element's one kind among `kinds` (the first given), or the "give one of" error.
fn one_kind<N: Node>(v: &N, kinds: &[&str], el: &str, message: &str) -> Result<String> {
    let given: Vec<&str> = kinds.iter().copied().filter(|k| v.has(k)).collect();
    if given.len() > 1 {
        return Err(err(el, format!("{message}{}", given.join(" and "))));
    }
    Ok(given[0].to_owned())
}

/// The element's section `kind`, a mapping.
fn section<N: Node>(v: &N, kind: &str, el: &str) -> Result<N> {
    match v.get(kind) {
        Some(s) if s.is_map() => Ok(s),
        _ => Err(err(el, format!("'{kind}' must be a mapping"))),
    }
}

/// Every key of `table` from `spec` (all required), scaled to SI.
fn required<N: Node>(
    spec: &N,
    table: &[(&str, Quantity)],
    kind: &str,
    el: &str,
    units: Units,
) -> Result<Map<String, Value>> {
    let mut out = Map::new();
    for (k, _) in table {
        if !spec.has(k) {
            return Err(err(el, format!("{kind} needs '{k}'")));
        }
    }
    for (k, q) in table {
        let x = number(spec.get(k).as_ref(), el, k)?;
        out.insert((*k).into(), json!(units.factor(*q) * x));
    }
    Ok(out)
}

/// A `heart_pulmonary` or `coronary_bed` element (docs/physics.md §1.10).
fn closed_loop_element<N: Node>(
    v: &N,
    mut cv: Map<String, Value>,
    el: &str,
    units: Units,
) -> Result<Value> {
    let kinds = [
        "heart_pulmonary",
        "coronary_bed",
        "valve",
        "chamber",
        "through_rc",
        "lumped",
        "length",
    ];
    let kind = one_kind(
        v,
        &kinds,
        el,
        "give one of heart_pulmonary, coronary_bed, valve, chamber, through_rc, lumped or \
         geometry, not ",
    )?;
    let spec = section(v, &kind, el)?;
    let heart = kind == "heart_pulmonary";
    let (keys, optional): (Table, Table) = if heart {
        (HEART_PULMONARY_KEYS, HEART_PULMONARY_START)
    } else {
        (CORONARY_BED_KEYS, &[])
    };
    let mut allowed = names(keys);
    allowed.extend(names(optional));
    allowed.push("units");
    if !heart {
        allowed.extend(["heart", "ventricle"]);
    }
    check_keys(&spec, &allowed, &format!("{el} {kind}"))?;
    let units = element_units(&spec, units, &format!("{kind} units"), el)?;
    let mut out = Map::new();
    for (k, q) in keys.iter().chain(optional) {
        if let Some(x) = spec.get(k) {
            let x = number(Some(&x), el, k)?;
            out.insert((*k).into(), json!(units.factor(*q) * x));
        } else if keys.iter().any(|(name, _)| name == k) {
            return Err(err(el, format!("{kind} needs '{k}'")));
        }
    }
    if !heart {
        let Some(h) = spec.get("heart").and_then(|h| h.text()) else {
            return Err(err(
                el,
                "coronary_bed needs 'heart', the name of a heart_pulmonary element",
            ));
        };
        let side = spec.get("ventricle");
        let side_text = side.as_ref().and_then(Node::text);
        if !matches!(side_text.as_deref(), Some("left" | "right")) {
            let shown = side.map_or_else(|| "None".to_owned(), |s| s.repr());
            return Err(err(
                el,
                format!("coronary_bed ventricle must be 'left' or 'right', got {shown}"),
            ));
        }
        out.insert("heart".into(), json!(h));
        out.insert("ventricle".into(), json!(side_text));
    }
    cv.insert(kind, Value::Object(out));
    Ok(Value::Object(cv))
}

/// The units of an element's section: its own `units` key (`SI`, `cgs` or `mmHg-mL`, the
/// published lumped heart parameters' units), else the model's.
fn element_units<N: Node>(spec: &N, model: Units, key: &str, el: &str) -> Result<Units> {
    let Some(u) = spec.get("units") else {
        return Ok(model);
    };
    u.text()
        .and_then(|t| Units::parse_element(&t))
        .ok_or_else(|| {
            err(
                el,
                format!("{key} must be 'SI', 'cgs' or 'mmHg-mL', got {}", u.repr()),
            )
        })
}

/// A `chamber_sphere` element (docs/physics.md §1.11).
fn sphere_element<N: Node>(
    v: &N,
    mut cv: Map<String, Value>,
    el: &str,
    units: Units,
) -> Result<Value> {
    let others: Vec<&str> = ["valve", "chamber", "through_rc", "lumped", "length"]
        .into_iter()
        .filter(|k| v.has(k))
        .collect();
    if !others.is_empty() {
        return Err(err(
            el,
            format!(
                "give one of chamber_sphere, {}, not both",
                others.join(", ")
            ),
        ));
    }
    let spec = section(v, "chamber_sphere", el)?;
    check_keys(
        &spec,
        &names(CHAMBER_SPHERE_KEYS),
        &format!("{el} chamber_sphere"),
    )?;
    let out = required(&spec, CHAMBER_SPHERE_KEYS, "chamber_sphere", el, units)?;
    cv.insert("chamber_sphere".into(), Value::Object(out));
    Ok(Value::Object(cv))
}

/// A `valve`, `chamber` or `through_rc` element (docs/physics.md §1.8).
fn heart_element<N: Node>(
    v: &N,
    mut cv: Map<String, Value>,
    el: &str,
    units: Units,
) -> Result<Value> {
    let kinds = ["valve", "chamber", "through_rc", "lumped", "length"];
    let kind = one_kind(
        v,
        &kinds,
        el,
        "give one of valve, chamber, through_rc, lumped or geometry, not ",
    )?;
    let spec = section(v, &kind, el)?;
    if kind == "through_rc" {
        check_keys(&spec, &names(THROUGH_RC_KEYS), &format!("{el} through_rc"))?;
        let out = required(&spec, THROUGH_RC_KEYS, "through_rc", el, units)?;
        cv.insert(kind, Value::Object(out));
        return Ok(Value::Object(cv));
    }
    let chamber = kind == "chamber";
    let laws = if chamber { CHAMBER_LAWS } else { VALVE_LAWS };
    let law_node = spec.get("law");
    let law_name = law_node.as_ref().and_then(Node::text);
    let Some((law, table)) = laws
        .iter()
        .find(|(name, _)| Some(*name) == law_name.as_deref())
    else {
        let names: Vec<&str> = laws.iter().map(|(n, _)| *n).collect();
        let shown = law_node.map_or_else(|| "None".to_owned(), |l| l.repr());
        return Err(err(
            el,
            format!("{kind} law must be one of {}, got {shown}", py_list(&names)),
        ));
    };
    let mut keys: Vec<(&str, Quantity)> = table.to_vec();
    if chamber {
        keys.extend_from_slice(CHAMBER_COMMON);
    }
    let mut allowed: Vec<&str> = keys.iter().map(|(k, _)| *k).collect();
    allowed.push("law");
    if chamber {
        allowed.push("activation");
    }
    check_keys(&spec, &allowed, &format!("{el} {kind}"))?;
    let mut out = Map::new();
    out.insert("law".into(), json!(law));
    for (k, q) in &keys {
        if let Some(x) = spec.get(k) {
            let x = number(Some(&x), el, k)?;
            out.insert((*k).into(), json!(units.factor(*q) * x));
        } else if !matches!(*k, "inductance" | "initial_volume") {
            return Err(err(el, format!("{kind} needs '{k}'")));
        }
    }
    if chamber {
        chamber_extras(&spec, &mut out, el)?;
    }
    cv.insert(kind, Value::Object(out));
    Ok(Value::Object(cv))
}

/// A chamber's start volume check and its `activation`.
fn chamber_extras<N: Node>(spec: &N, out: &mut Map<String, Value>, el: &str) -> Result<()> {
    let v0 = out
        .get("initial_volume")
        .and_then(Value::as_f64)
        .unwrap_or(0.0);
    if v0 < 0.0 {
        // a blood volume (the core checks the rest)
        let given = spec
            .get("initial_volume")
            .map_or_else(|| py_repr(v0), |x| x.repr());
        return Err(err(
            el,
            format!("chamber initial_volume must be >= 0, got {given}"),
        ));
    }
    let act = spec.get("activation").filter(Node::is_map);
    let kind = act
        .as_ref()
        .and_then(|a| a.get("kind"))
        .and_then(|k| k.text());
    let found = ACTIVATIONS
        .iter()
        .find(|(name, _)| Some(*name) == kind.as_deref());
    let (Some(act), Some((kind, keys))) = (act, found) else {
        let names: Vec<&str> = ACTIVATIONS.iter().map(|(n, _)| *n).collect();
        return Err(err(
            el,
            format!(
                "chamber needs an 'activation' with kind one of {}",
                py_list(&names)
            ),
        ));
    };
    let mut allowed: Vec<&str> = keys.to_vec();
    allowed.push("kind");
    check_keys(&act, &allowed, &format!("{el} activation"))?;
    for k in *keys {
        if !act.has(k) {
            return Err(err(el, format!("activation needs '{k}'")));
        }
    }
    let mut a = Map::new();
    for (k, x) in act.entries() {
        if k == "kind" {
            a.insert(k, json!(kind));
        } else {
            let value = number(Some(&x), el, &k)?;
            a.insert(k, json!(value));
        }
    }
    out.insert("activation".into(), Value::Object(a));
    Ok(())
}

/// The cardiac periods of the heart elements (a `chamber`'s activation, a `heart_pulmonary`
/// block) among canonical vessels, with the element: like a waveform's, each must equal the
/// model period, or the chamber would beat out of step with the cycles that are run, output
/// and tested for periodicity (docs/physics.md §1.8).
pub fn element_periods<N: Node>(vessels: &[N]) -> Vec<(f64, String)> {
    let mut out = Vec::new();
    for v in vessels {
        for kind in ["chamber", "heart_pulmonary"] {
            if let Some(p) = v
                .get(kind)
                .and_then(|s| s.get("period"))
                .and_then(|p| p.number())
            {
                let name = v.get("name").and_then(|n| n.text()).unwrap_or_default();
                out.push((p, format!("vessel '{name}' {kind} (its activation)")));
            }
        }
    }
    out
}
