//! Boundary conditions of the native schema and their waveforms (a number, `time` + value
//! tables, `fourier` coefficients), checked and converted to the canonical SI form.

use super::{check_keys, err, number, numbers};
use crate::error::Result;
use crate::model::node::{Kind, Node, py_repr};
use crate::model::units::{Quantity, Quantity::*, Units};
use serde_json::{Map, Value, json};

/// The condition types and their keys.
pub const BC_KEYS: &[(&str, &[&str])] = &[
    (
        "flow",
        &[
            "type",
            "time",
            "flow",
            "value",
            "fourier",
            "interpolation",
            "steady",
        ],
    ),
    (
        "pressure",
        &[
            "type",
            "time",
            "pressure",
            "value",
            "fourier",
            "interpolation",
            "steady",
        ],
    ),
    ("resistance", &["type", "resistance", "pressure"]),
    (
        "rcr",
        &[
            "type",
            "proximal_resistance",
            "capacitance",
            "distal_resistance",
            "pressure",
        ],
    ),
    // svZeroDSolver's RESISTANCE / RCR at a vessel inlet, its own equations (docs/svzerod.md)
    (
        "svzerod-inlet",
        &[
            "type",
            "resistance",
            "proximal_resistance",
            "capacitance",
            "distal_resistance",
            "pressure",
        ],
    ),
    (
        "coronary",
        &[
            "type",
            "arterial_resistance",
            "arterial_capacitance",
            "microvascular_resistance",
            "intramyocardial_capacitance",
            "venous_resistance",
            "intramyocardial_pressure",
            "pressure",
            "microvascular_resistance_max",
            "contraction_time",
            "relaxation_time",
            "cycle_period",
        ],
    ),
];
/// A coronary outlet's numbers and their quantities (docs/physics.md §1.7).
const CORONARY_QUANTITIES: &[(&str, Quantity)] = &[
    ("arterial_resistance", Resistance),
    ("arterial_capacitance", Capacitance),
    ("microvascular_resistance", Resistance),
    ("intramyocardial_capacitance", Capacitance),
    ("venous_resistance", Resistance),
    ("microvascular_resistance_max", Resistance),
    ("contraction_time", Time),
    ("relaxation_time", Time),
    ("cycle_period", Time),
];
const CORONARY_REQUIRED: &[&str] = &[
    "arterial_resistance",
    "arterial_capacitance",
    "microvascular_resistance",
    "intramyocardial_capacitance",
    "venous_resistance",
    "intramyocardial_pressure",
];
const EXPECTED: &str = "flow, pressure, resistance, rcr or coronary";

/// The canonical form of one boundary condition (`el` names it), checking every key and value.
pub fn boundary_condition<N: Node>(bc: &N, units: Units, el: &str) -> Result<Value> {
    let Some(ty) = bc.get("type").filter(|_| bc.is_map()) else {
        return Err(err(el, format!("needs a 'type' ({EXPECTED})")));
    };
    let kind = ty.show().to_lowercase();
    let Some((_, keys)) = BC_KEYS.iter().find(|(k, _)| *k == kind) else {
        return Err(err(
            el,
            format!("unknown type '{}' (expected {EXPECTED})", ty.show()),
        ));
    };
    check_keys(bc, keys, el)?;
    let mut cb = Map::new();
    cb.insert("type".into(), json!(kind));
    match kind.as_str() {
        "flow" | "pressure" => {
            let q = if kind == "flow" { Flow } else { Pressure };
            let w = waveform(bc, &kind, q, units, el, true)?;
            cb.insert(kind.clone(), w);
        }
        "coronary" => return coronary(bc, units, el),
        "svzerod-inlet" => {
            for (k, q) in [
                ("resistance", Resistance),
                ("proximal_resistance", Resistance),
                ("capacitance", Capacitance),
                ("distal_resistance", Resistance),
            ] {
                if let Some(x) = bc.get(k) {
                    let x = number(Some(&x), el, k)?;
                    cb.insert(k.into(), json!(units.factor(q) * x));
                }
            }
            cb.insert("pressure".into(), pressure(bc.get("pressure"), units, el)?);
        }
        "resistance" => {
            let r = number(bc.get("resistance").as_ref(), el, "resistance")?;
            cb.insert("resistance".into(), json!(units.factor(Resistance) * r));
            cb.insert("pressure".into(), pressure(bc.get("pressure"), units, el)?);
        }
        _ => {
            for (k, q) in [
                ("proximal_resistance", Resistance),
                ("capacitance", Capacitance),
                ("distal_resistance", Resistance),
            ] {
                let Some(x) = bc.get(k) else {
                    return Err(err(el, format!("rcr needs '{k}'")));
                };
                let x = number(Some(&x), el, k)?;
                cb.insert(k.into(), json!(units.factor(q) * x));
            }
            cb.insert("pressure".into(), pressure(bc.get("pressure"), units, el)?);
        }
    }
    Ok(Value::Object(cb))
}

/// A pressure given as a number (default 0) or as a waveform mapping.
fn pressure<N: Node>(p: Option<N>, units: Units, el: &str) -> Result<Value> {
    match p {
        Some(p) if p.is_map() => waveform(&p, "pressure", Pressure, units, el, true),
        Some(p) => scalar(&p, "pressure", Pressure, units, el),
        None => Ok(json!({"kind": "constant", "value": units.factor(Pressure) * 0.0})),
    }
}

/// A waveform given by a bare value under `key` (null: none given).
fn scalar<N: Node>(x: &N, key: &str, q: Quantity, units: Units, el: &str) -> Result<Value> {
    match x.kind() {
        Kind::Null => Err(err(el, needs(key))),
        Kind::List => Err(err(
            el,
            format!("'{key}' is a list but no 'time' table is given"),
        )),
        _ => {
            let v = number(Some(x), el, key)?;
            Ok(json!({"kind": "constant", "value": units.factor(q) * v}))
        }
    }
}

fn needs(key: &str) -> String {
    format!("needs '{key}' (a number, or 'time' + '{key}' tables, or 'fourier')")
}

/// Canonical waveform from `value:`, `time:` + `key:` tables, `fourier:` or a scalar `key:`.
pub fn waveform<N: Node>(
    bc: &N,
    key: &str,
    q: Quantity,
    units: Units,
    el: &str,
    required: bool,
) -> Result<Value> {
    let f = units.factor(q);
    if let Some(fo) = bc.get("fourier") {
        check_keys(
            &fo,
            &["period", "mean", "cos", "sin"],
            &format!("{el} fourier"),
        )?;
        let period = number(fo.get("period").as_ref(), el, "fourier.period")?;
        let mean = match fo.get("mean") {
            Some(m) => number(Some(&m), el, "fourier.mean")?,
            None => 0.0,
        };
        let series = |name: &str| -> Result<Vec<f64>> {
            match fo.get(name) {
                Some(x) => Ok(numbers(Some(&x), el, &format!("fourier.{name}"))?
                    .into_iter()
                    .map(|x| f * x)
                    .collect()),
                None => Ok(Vec::new()),
            }
        };
        let (cos, sin) = (series("cos")?, series("sin")?);
        return Ok(
            json!({"kind": "fourier", "period": period, "mean": f * mean,
                         "cos": cos, "sin": sin}),
        );
    }
    if let Some(time) = bc.get("time") {
        return table(bc, &time, key, f, el);
    }
    for k in ["value", key] {
        if let Some(x) = bc.get(k).filter(|x| x.kind() != Kind::Null) {
            return scalar(&x, k, q, units, el);
        }
    }
    if required {
        return Err(err(el, needs(key)));
    }
    Ok(Value::Null)
}

/// A `time` + `key` table (scaled by `f`), its interpolation and steady value.
fn table<N: Node>(bc: &N, time: &N, key: &str, f: f64, el: &str) -> Result<Value> {
    let Some(values) = bc.get(key) else {
        return Err(err(el, format!("has 'time' but no '{key}' table")));
    };
    let t = numbers(Some(time), el, "time")?;
    let v: Vec<f64> = numbers(Some(&values), el, key)?
        .into_iter()
        .map(|x| f * x)
        .collect();
    if t.len() != v.len() {
        return Err(err(
            el,
            format!("'time' has {} entries but '{key}' has {}", t.len(), v.len()),
        ));
    }
    for i in 1..t.len() {
        if t[i] <= t[i - 1] {
            return Err(err(
                el,
                format!(
                    "'time' must be strictly increasing: t[{i}] = {} <= t[{}] = {}",
                    py_repr(t[i]),
                    i - 1,
                    py_repr(t[i - 1])
                ),
            ));
        }
    }
    let interpolation = bc.get("interpolation");
    let interp = match &interpolation {
        None => "linear".to_owned(),
        Some(x) => match x.text() {
            Some(s) if s == "linear" || s == "periodic-cubic" => s,
            _ => {
                return Err(err(
                    el,
                    format!(
                        "interpolation must be 'linear' or 'periodic-cubic', got {}",
                        x.repr()
                    ),
                ));
            }
        },
    };
    let mut out = json!({"kind": "table", "time": t, "value": v, "interpolation": interp});
    if let Some(s) = bc.get("steady") {
        out["steady"] = json!(f * number(Some(&s), el, "steady")?);
    }
    Ok(out)
}

/// The canonical form of a `coronary` outlet (numbers in SI; pressures as waveforms).
fn coronary<N: Node>(bc: &N, units: Units, el: &str) -> Result<Value> {
    for k in CORONARY_REQUIRED {
        if !bc.has(k) {
            return Err(err(el, format!("coronary needs '{k}'")));
        }
    }
    let mut cb = Map::new();
    cb.insert("type".into(), json!("coronary"));
    for (k, q) in CORONARY_QUANTITIES {
        if let Some(x) = bc.get(k).filter(|x| x.kind() != Kind::Null) {
            let x = number(Some(&x), el, k)?;
            cb.insert((*k).into(), json!(units.factor(*q) * x));
        }
    }
    for k in ["intramyocardial_pressure", "pressure"] {
        let w = pressure(bc.get(k), units, &format!("{el} {k}"))?;
        cb.insert(k.into(), w);
    }
    Ok(Value::Object(cb))
}

/// The periods of a canonical condition's waveforms (a table's span, a Fourier period) and of
/// a coronary's varying resistance, with the element they come from; `cb` in any front end's
/// values (a canonical condition already read, such as an ensemble base's Python dict).
pub fn condition_periods<N: Node>(cb: &N, el: &str) -> Vec<(f64, String)> {
    let mut out = Vec::new();
    for key in ["flow", "pressure", "intramyocardial_pressure"] {
        let Some(w) = cb.get(key) else { continue };
        match w.get("kind").and_then(|k| k.text()).as_deref() {
            Some("table") => {
                let t = w.get("time").and_then(|t| t.items());
                if let Some(t) = t.filter(|t| t.len() > 1) {
                    let (a, b) = (t[0].number(), t[t.len() - 1].number());
                    out.push((b.unwrap_or(0.0) - a.unwrap_or(0.0), el.to_owned()));
                }
            }
            Some("fourier") => {
                if let Some(p) = w.get("period").and_then(|p| p.number()) {
                    out.push((p, el.to_owned()));
                }
            }
            _ => {}
        }
    }
    if let Some(p) = cb.get("cycle_period").and_then(|p| p.number()) {
        out.push((p, format!("{el} cycle_period")));
    }
    out
}
