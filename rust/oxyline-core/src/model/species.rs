//! The `oxygen:`, `species:` and `transport:` sections of a native model read into the
//! canonical `transport` description ([`super::transport::TransportSpec`]): every key, unit
//! (PO2 in mmHg at the file boundary, SI inside), default and range check, the haemoglobin
//! facilitation factor of boundary-layer walls, and the sampling of a prescribed wall flux
//! given as a front-end callable (docs/physics.md §2-5). A message names the section, the
//! vessel or inlet, the user's key and value as the front end prints them.
//!
//! Oxygen (docs/physics.md §2-4)::
//!
//! ```text
//! oxygen:
//!   inlet: {po2: 85.0}             # mmHg; or {time: [..], po2: [..]}, or {fourier: {..}}
//!   inlets: {inlet_bc: {po2: 90}}  # per-inlet overrides
//!   hemoglobin: none               # none | hill | linearized
//!   hill: {p50: 26.8, n: 2.7, hb: 150, huefner: 1.34}   # mmHg, -, g/L, mL O2/g
//!   linearized: {p_low: 60, p_high: 85}                  # secant end points (mmHg)
//!   solubility: 1.40e-3            # mol m^-3 mmHg^-1
//!   diffusivity: 1.2e-9            # m^2/s
//!   wall: {model: leveque, po2: 60.0, shear: cycle-mean}   # or tissue (§3.7)
//!   per_vessel: {ICA: {wall: {...}, cells_per_segment: 4}}
//!   cells_per_segment: 1
//!   outlet_backflow: zero-gradient # or {outlet_bc: {po2: ..}}
//!   formulation: conservative      # or tl-quasisteady
//!   reference_pressure: 0          # mmHg
//!   initial: {po2: 85}
//! ```
//!
//! Other species are all SI (concentrations in mol/m³), with `binding: none | linear
//! {partition} | saturable {b_max, k_d, n}`, `decay` (1/s) and an inlet that may also be a
//! gamma-variate bolus. `transport: {cells_per_segment, cells_per_vessel, formulation,
//! reference_pressure, velocity_threshold}` is shared by all species (oxygen's keys win).

use super::facilitation::{self, Layer};
use super::native::err;
use super::node::{Kind, Node, py_quote, py_repr};
use super::units::MMHG;
use crate::error::Result;
use serde_json::{Map, Value, json};

pub const OXYGEN_KEYS: &[&str] = &[
    "inlet",
    "inlets",
    "hemoglobin",
    "hill",
    "linearized",
    "solubility",
    "diffusivity",
    "wall",
    "per_vessel",
    "outlet_backflow",
    "formulation",
    "reference_pressure",
    "initial",
    "name",
    "cells_per_segment",
];
/// The keys of each wall closure, in the order the messages list the closures.
pub const WALL_KEYS: &[(&str, &[&str])] = &[
    ("none", &["model"]),
    ("flux", &["model", "flux"]),
    (
        "mass-transfer",
        &["model", "k", "po2", "concentration", "permeability"],
    ),
    (
        "leveque",
        &[
            "model",
            "po2",
            "concentration",
            "shear",
            "enhancement",
            "permeability",
            "hb_facilitation",
        ],
    ),
    (
        "graetz",
        &[
            "model",
            "po2",
            "concentration",
            "enhancement",
            "permeability",
            "hb_facilitation",
            "flow",
        ],
    ),
    (
        "permeability",
        &["model", "permeability", "po2", "concentration"],
    ),
];
pub const SPECIES_KEYS: &[&str] = &[
    "name",
    "diffusivity",
    "decay",
    "binding",
    "wall",
    "inlet",
    "inlets",
    "backflow",
    "initial",
    "per_vessel",
    "units",
];
pub const TRANSPORT_KEYS: &[&str] = &[
    "reference_pressure",
    "formulation",
    "velocity_threshold",
    "cells_per_segment",
    "cells_per_vessel",
];
const TISSUE_KEYS: &[&str] = &[
    "model",
    "thickness",
    "diffusivity",
    "solubility",
    "consumption",
    "outer",
    "radial_cells",
    "hypoxic_po2",
    "boundary_layer",
];
/// Luminal closures a tissue wall accepts (a conductance against its innermost PO2).
const TISSUE_BOUNDARY_LAYERS: &[&str] = &["leveque", "graetz", "mass-transfer", "permeability"];
pub const MAX_CELLS_PER_SEGMENT: f64 = 10_000.0;
/// Hypoxia threshold (mmHg): hypoxia markers form below ~10 mmHg (docs/physics.md §3.7).
const HYPOXIC_PO2: f64 = 10.0;
const TISSUE_RADIAL_CELLS: i64 = 4;
const FORMULATIONS: &[&str] = &["conservative", "tl-quasisteady"];
/// A `graetz` wall's flow: inlet renewal (docs/physics.md §3.6) or a cycle-mean closure.
const MEAN_FLOWS: &[&str] = &["inlet-renewal", "forward-mean", "cycle-mean"];
/// Samples per period of a wall flux given as a callable (linear in between).
const FLUX_SAMPLES_PER_PERIOD: f64 = 200.0;
/// Facilitated diffusivity of HbO2 (m²/s, docs/physics.md §3.4).
const D_HB_DEFAULT: f64 = 5.5e-12;
/// mL O2 (STPD) per mmol.
const MOLAR_VOLUME_ML: f64 = 22.414;
const SOLUBILITY: f64 = 1.40e-3;
const DIFFUSIVITY: f64 = 1.2e-9;

/// The canonical transport section and what results need to know of it.
pub struct Transport {
    pub section: Value,
    /// Species names, in order.
    pub species: Vec<String>,
    /// The oxygen species' name and its solubility (mol m⁻³ mmHg⁻¹), if there is oxygen.
    pub oxygen: Option<(String, f64)>,
    /// Warnings for the user (a boundary-layer wall without haemoglobin facilitation).
    pub warnings: Vec<String>,
}

/// What the sections are read against: the pressure unit factor of the model (for
/// `transport: reference_pressure`), its period and run duration (a callable flux and a bolus
/// are sampled over the run), and the blood's kinematic viscosity (a `graetz` wall's).
pub struct Context {
    pub pressure_factor: f64,
    pub period: Option<f64>,
    pub duration: Option<f64>,
    /// None: the graetz walls are written without it (a section read on its own).
    pub kinematic_viscosity: Option<f64>,
}

/// How `num` bounds a value.
#[derive(Clone, Copy, PartialEq)]
enum Bound {
    Any,
    NonNegative,
    Positive,
}

/// A finite number (text read as a number), bounded: the section's message for anything else.
fn num<N: Node>(v: Option<&N>, el: &str, key: &str, bound: Bound) -> Result<f64> {
    let x = match v {
        Some(v) => match v.kind() {
            Kind::Int | Kind::Float => v.number(),
            Kind::Str => v.text().and_then(|s| super::native::py_float(&s)),
            _ => None,
        },
        None => None,
    };
    let Some(x) = x.filter(|x| x.is_finite()) else {
        let shown = match (x, v) {
            (Some(x), _) => py_repr(x),
            (None, Some(v)) => v.repr(),
            (None, None) => "None".to_owned(),
        };
        return Err(err(
            el,
            format!("'{key}' must be a finite number, got {shown}"),
        ));
    };
    if bound == Bound::Positive && x <= 0.0 {
        return Err(err(el, format!("'{key}' must be > 0, got {}", py_repr(x))));
    }
    if bound == Bound::NonNegative && x < 0.0 {
        return Err(err(
            el,
            format!("'{key}' must be >= 0.0, got {}", py_repr(x)),
        ));
    }
    Ok(x)
}

/// A default that is a value read before (the inlet PO2), checked as `num` checks a value > 0.
fn bounded(x: f64, el: &str, key: &str) -> Result<f64> {
    num(Some(&json!(x)), el, key, Bound::Positive)
}

/// `num` of `key` in `d`, or `default` when it is missing.
fn num_or<N: Node>(d: &N, key: &str, default: f64, el: &str, name: &str, b: Bound) -> Result<f64> {
    match d.get(key) {
        Some(v) => num(Some(&v), el, name, b),
        None => Ok(default),
    }
}

/// `d` is a mapping whose keys are all in `allowed`.
fn check<N: Node>(d: &N, allowed: &[&str], el: &str) -> Result<()> {
    if !d.is_map() {
        return Err(err(el, format!("expected a mapping, got {}", d.repr())));
    }
    for (k, _) in d.entries() {
        if !allowed.contains(&k.as_str()) {
            let mut sorted = allowed.to_vec();
            sorted.sort_unstable();
            return Err(err(
                el,
                format!("unknown key '{k}' (allowed: {})", sorted.join(", ")),
            ));
        }
    }
    Ok(())
}

/// A mapping given as `d`'s value under `key`, or an empty one when it is missing or falsy
/// (the sections' `hill`, `linearized` and `transport`).
fn section<N: Node>(d: &N, key: &str) -> Option<N> {
    d.get(key).filter(Node::truthy)
}

/// The items of a list-like value, or the section's message.
fn items<N: Node>(v: &N, el: &str, key: &str) -> Result<Vec<N>> {
    v.items().ok_or_else(|| {
        err(
            el,
            format!("'{key}' must be a list of numbers, got {}", v.repr()),
        )
    })
}

/// A front-end value as JSON (a synthetic mapping, an interpolation name).
fn to_value<N: Node>(n: &N) -> Value {
    match n.kind() {
        Kind::Null => Value::Null,
        Kind::Bool => Value::Bool(n.truthy()),
        Kind::Int => n.integer().map_or_else(|| json!(n.number()), |i| json!(i)),
        Kind::Float => json!(n.number()),
        Kind::Str => Value::String(n.text().unwrap_or_default()),
        Kind::List => Value::Array(n.items().unwrap_or_default().iter().map(to_value).collect()),
        Kind::Map => Value::Object(
            n.entries()
                .iter()
                .map(|(k, v)| (k.clone(), to_value(v)))
                .collect(),
        ),
        Kind::Other => Value::String(n.repr()),
    }
}

fn strictly_increasing(t: &[f64]) -> bool {
    t.windows(2).all(|w| w[1] > w[0])
}

/// Canonical waveform of a concentration-like quantity (`key`, scaled by `scale`): a number,
/// `{key: x}`, `{time, key}` tables, `{fourier: ..}` or a gamma-variate bolus.
fn wave<N: Node>(spec: &N, key: &str, scale: f64, el: &str, ctx: &Context) -> Result<Value> {
    if !spec.is_map() {
        let x = num(Some(spec), el, key, Bound::NonNegative)?;
        return Ok(json!({"kind": "constant", "value": scale * x}));
    }
    if let Some(b) = spec.get("bolus") {
        return bolus(&b, scale, el, ctx.duration);
    }
    if let Some(fo) = spec.get("fourier") {
        check(
            &fo,
            &["period", "mean", "cos", "sin"],
            &format!("{el} fourier"),
        )?;
        let period = num_or(
            &fo,
            "period",
            ctx.period.unwrap_or(1.0),
            el,
            "period",
            Bound::Positive,
        )?;
        let mean = scale * num_or(&fo, "mean", 0.0, el, "mean", Bound::Any)?;
        let series = |name: &str| -> Result<Vec<f64>> {
            let Some(s) = fo.get(name) else {
                return Ok(Vec::new());
            };
            items(&s, el, name)?
                .iter()
                .map(|x| Ok(scale * num(Some(x), el, name, Bound::Any)?))
                .collect()
        };
        let (cos, sin) = (series("cos")?, series("sin")?);
        return Ok(
            json!({"kind": "fourier", "period": period, "mean": mean, "cos": cos, "sin": sin}),
        );
    }
    if let Some(time) = spec.get("time") {
        let t = items(&time, el, "time")?
            .iter()
            .map(|x| num(Some(x), el, "time", Bound::Any))
            .collect::<Result<Vec<_>>>()?;
        let Some(values) = spec.get(key) else {
            return Err(err(el, format!("has 'time' but no '{key}' table")));
        };
        let v = items(&values, el, key)?
            .iter()
            .map(|x| Ok(scale * num(Some(x), el, key, Bound::NonNegative)?))
            .collect::<Result<Vec<_>>>()?;
        if t.len() != v.len() || t.len() < 2 {
            return Err(err(
                el,
                format!("'time' and '{key}' need the same length >= 2"),
            ));
        }
        if !strictly_increasing(&t) {
            return Err(err(el, "'time' must be strictly increasing"));
        }
        let interp = spec
            .get("interpolation")
            .map_or_else(|| json!("linear"), |i| to_value(&i));
        return Ok(json!({"kind": "table", "time": t, "value": v, "interpolation": interp}));
    }
    if let Some(x) = spec.get(key) {
        let x = num(Some(&x), el, key, Bound::NonNegative)?;
        return Ok(json!({"kind": "constant", "value": scale * x}));
    }
    Err(err(
        el,
        format!("needs '{key}' (a number, 'time' + '{key}' tables, or 'fourier')"),
    ))
}

/// Gamma-variate bolus c(t) = K (t − t0)^a exp(−(t − t0)/b) for t > t0, sampled as a table
/// spanning the whole run (a table repeats with its own length).
fn bolus<N: Node>(spec: &N, scale: f64, element: &str, duration: Option<f64>) -> Result<Value> {
    let el = format!("{element} bolus");
    check(spec, &["gamma_variate"], &el)?;
    let g = spec.get("gamma_variate");
    let gel = format!("{el} gamma_variate");
    match &g {
        Some(g) => check(g, &["k", "t0", "a", "b"], &gel)?,
        None => return Err(err(&gel, "expected a mapping, got None")),
    }
    let g = g.expect("checked above");
    let k = num(g.get("k").as_ref(), &el, "k", Bound::NonNegative)?;
    let t0 = num_or(&g, "t0", 0.0, &el, "t0", Bound::NonNegative)?;
    let a = num(g.get("a").as_ref(), &el, "a", Bound::NonNegative)?;
    let b = num(g.get("b").as_ref(), &el, "b", Bound::Positive)?;
    let end = duration
        .filter(|d| *d != 0.0)
        .unwrap_or(0.0)
        .max(t0 + 40.0 * b * (1.0 + a))
        + 1.0;
    let n = 4000;
    let times: Vec<f64> = (0..n).map(|i| end * i as f64 / (n - 1) as f64).collect();
    let vals: Vec<f64> = times
        .iter()
        .map(|&t| {
            let c = if t > t0 {
                k * (t - t0).powf(a) * (-(t - t0) / b).exp()
            } else {
                0.0
            };
            scale * c
        })
        .collect();
    Ok(json!({"kind": "table", "time": times, "value": vals, "interpolation": "linear"}))
}

/// Time mean of a linear table (the facilitation secant of a tabulated inlet PO2), summed
/// left to right.
fn table_mean(w: &Value) -> f64 {
    let col = |k: &str| -> Vec<f64> {
        w[k].as_array()
            .map(|a| a.iter().filter_map(Value::as_f64).collect())
            .unwrap_or_default()
    };
    let (t, v) = (col("time"), col("value"));
    let mut area = 0.0;
    for i in 1..t.len() {
        area += 0.5 * (t[i] - t[i - 1]) * (v[i - 1] + v[i]);
    }
    area / (t[t.len() - 1] - t[0])
}

/// Haemoglobin's Hill law as the wall closures see it (PO2 in mmHg, capacity mol/m³).
#[derive(Clone, Copy)]
struct Hill {
    p50: f64,
    n: f64,
    capacity: f64,
    /// Solubility per mmHg.
    alpha: f64,
    linearized: bool,
}

fn hill<N: Node>(ox: &N, alpha: f64) -> Result<Hill> {
    let el = "oxygen hill";
    let h = section(ox, "hill");
    if let Some(h) = &h {
        check(h, &["p50", "n", "hb", "huefner"], el)?;
    }
    let get = |key: &str, default: f64| match &h {
        Some(h) => num_or(h, key, default, el, key, Bound::Positive),
        None => Ok(default),
    };
    let p50 = get("p50", 26.8)?;
    let n = get("n", 2.7)?;
    let hb = get("hb", 150.0)?;
    let huefner = get("huefner", 1.34)?;
    // g/L × mL/g = mL O2 per L blood; / 22.414 mL/mmol = mmol/L = mol/m³
    let capacity = hb * huefner / MOLAR_VOLUME_ML;
    Ok(Hill {
        p50,
        n,
        capacity,
        alpha,
        linearized: false,
    })
}

mod wall;
use wall::{WallContext, WallValue, wall, wall_of};

/// `('a', 'b')`: a tuple of names as the front end prints it.
fn py_tuple(names: &[&str]) -> String {
    let quoted: Vec<String> = names.iter().map(|s| py_quote(s)).collect();
    format!("({})", quoted.join(", "))
}

fn is_tissue<N: Node>(spec: Option<&N>) -> bool {
    spec.is_some_and(|s| {
        s.text().as_deref() == Some("tissue")
            || (s.is_map() && s.get("model").and_then(|m| m.text()).as_deref() == Some("tissue"))
    })
}

mod tissue;

/// The canonical description of the oxygen section.
fn oxygen<N: Node>(ox: &N, ctx: &Context, warnings: &mut Vec<String>) -> Result<Value> {
    check(ox, OXYGEN_KEYS, "oxygen")?;
    let el = "oxygen";
    let alpha = num_or(
        ox,
        "solubility",
        SOLUBILITY,
        el,
        "solubility",
        Bound::Positive,
    )?;
    let d = num_or(
        ox,
        "diffusivity",
        DIFFUSIVITY,
        el,
        "diffusivity",
        Bound::Positive,
    )?;
    let Some(inlet_spec) = ox.get("inlet") else {
        return Err(err(el, "needs 'inlet' (e.g. {po2: 85})"));
    };
    let inlet = wave(&inlet_spec, "po2", alpha, "oxygen inlet", ctx)?;
    let p_in = match inlet["kind"].as_str() {
        Some("constant") => inlet["value"].as_f64().map(|v| v / alpha),
        Some("fourier") => inlet["mean"].as_f64().map(|v| v / alpha),
        _ => None,
    };
    // the facilitation secant's inlet PO2: a tabulated inlet's time mean
    let p_fac = p_in.unwrap_or_else(|| table_mean(&inlet) / alpha);
    let (h, binding) = hemoglobin(ox, alpha, p_in)?;
    let name = ox.get("name").map_or_else(|| "o2".to_owned(), |n| n.show());
    let mut sp = Map::new();
    sp.insert("name".into(), json!(name));
    sp.insert("diffusivity".into(), json!(d));
    sp.insert("binding".into(), binding);
    sp.insert("inlet".into(), inlet);
    let value = WallValue::Oxygen { alpha, el };
    let w = WallContext {
        value,
        hill: h,
        diffusivity: d,
        p_in: Some(p_fac),
    };
    let tissue_ctx = tissue::Oxygen {
        alpha,
        hill: h,
        d,
        p_in,
    };
    let wall_spec = ox.get("wall");
    if is_tissue(wall_spec.as_ref()) {
        let (lumen, t) = tissue::read(
            wall_spec.as_ref().expect("a tissue wall"),
            el,
            &tissue_ctx,
            ctx,
            warnings,
        )?;
        sp.insert("wall".into(), lumen);
        sp.insert("tissue".into(), t);
    } else {
        sp.insert(
            "wall".into(),
            wall(wall_spec.as_ref(), el, &w, ctx, warnings)?,
        );
    }
    ends(ox, alpha, ctx, &mut sp)?;
    if let Some(pv) = ox.get("per_vessel") {
        per_vessel(&pv, &w, &tissue_ctx, ctx, &mut sp, warnings)?;
    }
    Ok(Value::Object(sp))
}

/// Oxygen's per-inlet values, outlet backflow and initial PO2 into the species `sp`.
fn ends<N: Node>(ox: &N, alpha: f64, ctx: &Context, sp: &mut Map<String, Value>) -> Result<()> {
    let el = "oxygen";
    if let Some(inlets) = ox.get("inlets") {
        sp.insert(
            "inlets".into(),
            waves(&inlets, "po2", alpha, el, "inlet", ctx, el)?,
        );
    }
    if let Some(back) = ox.get("outlet_backflow") {
        if back.text().as_deref() != Some("zero-gradient") {
            if !back.is_map() {
                return Err(err(
                    el,
                    "outlet_backflow must be 'zero-gradient' or {outlet: {po2: ..}}",
                ));
            }
            sp.insert(
                "backflow".into(),
                waves(&back, "po2", alpha, el, "backflow", ctx, el)?,
            );
        }
    }
    if let Some(ini) = ox.get("initial") {
        let v = if ini.is_map() {
            ini.get("po2")
        } else {
            Some(ini)
        };
        sp.insert(
            "initial".into(),
            json!(alpha * num(v.as_ref(), el, "initial po2", Bound::NonNegative)?),
        );
    }
    Ok(())
}

/// Oxygen's `hemoglobin` mode: its Hill law (None: no haemoglobin) and canonical binding.
fn hemoglobin<N: Node>(ox: &N, alpha: f64, p_in: Option<f64>) -> Result<(Option<Hill>, Value)> {
    let el = "oxygen";
    let mode = ox
        .get("hemoglobin")
        .map_or_else(|| "none".to_owned(), |m| m.show());
    match mode.as_str() {
        "none" => Ok((None, json!({"kind": "none"}))),
        "hill" | "linearized" => {
            let mut h = hill(ox, alpha)?;
            let mut binding = json!({"kind": "hill", "solubility": alpha / MMHG,
                "p50": h.p50 * MMHG, "n": h.n, "capacity": h.capacity});
            if mode == "linearized" {
                h.linearized = true;
                let lin = section(ox, "linearized");
                if let Some(lin) = &lin {
                    check(lin, &["p_low", "p_high"], "oxygen linearized")?;
                }
                let wall = ox.get("wall").filter(Node::is_map);
                let p_low = match lin.as_ref().and_then(|l| l.get("p_low")) {
                    Some(v) => num(Some(&v), el, "p_low", Bound::Positive)?,
                    None => match wall.as_ref().and_then(|w| w.get("po2")) {
                        Some(v) => num(Some(&v), el, "p_low", Bound::Positive)?,
                        None => 60.0,
                    },
                };
                let p_high = match lin.as_ref().and_then(|l| l.get("p_high")) {
                    Some(v) => num(Some(&v), el, "p_high", Bound::Positive)?,
                    None => bounded(p_in.unwrap_or(85.0), el, "p_high")?,
                };
                binding["kind"] = json!("linearized");
                binding["p_low"] = json!(p_low * MMHG);
                binding["p_high"] = json!(p_high * MMHG);
            }
            Ok((Some(h), binding))
        }
        _ => Err(err(
            el,
            format!(
                "hemoglobin must be none, hill or linearized, got {}",
                py_quote(&mode)
            ),
        )),
    }
}

/// Per-inlet (or per-outlet) waveforms `{node: wave}`, named `{el} {what} 'node'`.
fn waves<N: Node>(
    d: &N,
    key: &str,
    scale: f64,
    el: &str,
    what: &str,
    ctx: &Context,
    map_el: &str,
) -> Result<Value> {
    if !d.is_map() {
        return Err(err(map_el, format!("expected a mapping, got {}", d.repr())));
    }
    let mut out = Map::new();
    for (k, v) in d.entries() {
        let w = wave(&v, key, scale, &format!("{el} {what} '{k}'"), ctx)?;
        out.insert(k, w);
    }
    Ok(Value::Object(out))
}

/// Oxygen's `per_vessel` walls (and tissue layers) into the species `sp`.
fn per_vessel<N: Node>(
    pv: &N,
    w: &WallContext,
    t: &tissue::Oxygen,
    ctx: &Context,
    sp: &mut Map<String, Value>,
    warnings: &mut Vec<String>,
) -> Result<()> {
    if !pv.is_map() {
        return Err(err(
            "oxygen",
            format!("'per_vessel' must be a mapping, got {}", pv.repr()),
        ));
    }
    let (mut walls, mut tissues) = (Map::new(), Map::new());
    for (name, over) in pv.entries() {
        let vel = format!("oxygen per_vessel '{name}'");
        check(&over, &["wall", "cells_per_segment"], &vel)?;
        // an override with only cells_per_segment keeps the section's wall
        if over.has("wall") || !over.has("cells_per_segment") {
            let spec = over.get("wall");
            if is_tissue(spec.as_ref()) {
                let (lumen, layer) = tissue::read(
                    spec.as_ref().expect("a tissue wall"),
                    &vel,
                    t,
                    ctx,
                    warnings,
                )?;
                walls.insert(name.clone(), lumen);
                tissues.insert(name, layer);
            } else {
                walls.insert(name.clone(), wall(spec.as_ref(), &vel, w, ctx, warnings)?);
                tissues.insert(name, Value::Null); // no tissue wall on this vessel
            }
        }
    }
    let any_tissue = tissues.values().any(|v| !v.is_null()) || sp.contains_key("tissue");
    if !walls.is_empty() {
        sp.insert("per_vessel".into(), Value::Object(walls));
    }
    if any_tissue {
        sp.insert("per_vessel_tissue".into(), Value::Object(tissues));
    }
    Ok(())
}

/// `cells_per_segment`: an integer m between 1 and [`MAX_CELLS_PER_SEGMENT`].
fn cells<N: Node>(v: &N, el: &str) -> Result<i64> {
    let x = match v.kind() {
        Kind::Int => v.number(),
        Kind::Float => v.number().filter(|x| x.fract() == 0.0),
        _ => None,
    };
    match x {
        Some(x) if (1.0..=MAX_CELLS_PER_SEGMENT).contains(&x) => Ok(x as i64),
        _ => Err(err(
            el,
            format!(
                "'cells_per_segment' must be an integer between 1 and 10000, got {}",
                v.repr()
            ),
        )),
    }
}

/// (cells_per_segment, per-vessel overrides) of the oxygen (`per_vessel: {name:
/// {cells_per_segment: m}}`) or transport (`cells_per_vessel: {name: m}`) section.
fn refinement<N: Node>(
    s: Option<&N>,
    el: &str,
    key: &str,
) -> Result<(Option<i64>, Map<String, Value>)> {
    let mut over = Map::new();
    let Some(s) = s else {
        return Ok((None, over));
    };
    let m = s
        .get("cells_per_segment")
        .map(|v| cells(&v, el))
        .transpose()?;
    let Some(pv) = s.get(key).filter(Node::truthy) else {
        return Ok((m, over));
    };
    if !pv.is_map() {
        return Err(err(
            el,
            format!("'{key}' must be a mapping, got {}", pv.repr()),
        ));
    }
    for (name, v) in pv.entries() {
        let v = if key == "per_vessel" {
            match v.get("cells_per_segment").filter(|_| v.is_map()) {
                Some(c) => c,
                None => continue,
            }
        } else {
            v
        };
        over.insert(
            name.clone(),
            json!(cells(&v, &format!("{el} vessel '{name}'"))?),
        );
    }
    Ok((m, over))
}

mod other;

/// The canonical transport section of a native model (None without `oxygen` or `species`).
pub fn read<N: Node>(data: &N, ctx: &Context) -> Result<Option<Transport>> {
    let ox = data.get("oxygen").filter(|o| o.kind() != Kind::Null);
    let sps = data.get("species").filter(Node::truthy);
    if ox.is_none() && sps.is_none() {
        return Ok(None);
    }
    let tr = section(data, "transport");
    if let Some(tr) = &tr {
        check(tr, TRANSPORT_KEYS, "transport")?;
    }
    let mut formulation = tr.as_ref().and_then(|t| t.get("formulation"));
    let p_ref = match tr.as_ref().and_then(|t| t.get("reference_pressure")) {
        Some(p) => {
            ctx.pressure_factor * num(Some(&p), "transport", "reference_pressure", Bound::Any)?
        }
        None => ctx.pressure_factor * 0.0,
    };
    let mut p_ref = p_ref;
    let (mut species, mut warnings, mut oxygen_info) = (Vec::new(), Vec::new(), None);
    if let Some(ox) = &ox {
        if !ox.is_map() {
            return Err(err(
                "oxygen",
                format!("expected a mapping, got {}", ox.repr()),
            ));
        }
        let o2 = oxygen(ox, ctx, &mut warnings)?;
        let solubility = num_or(
            ox,
            "solubility",
            SOLUBILITY,
            "oxygen",
            "solubility",
            Bound::Any,
        )?;
        oxygen_info = Some((o2["name"].as_str().unwrap_or("o2").to_owned(), solubility));
        species.push(o2);
        if let Some(f) = ox.get("formulation") {
            formulation = Some(f);
        }
        if let Some(p) = ox.get("reference_pressure") {
            p_ref = MMHG * num(Some(&p), "oxygen", "reference_pressure", Bound::Any)?;
        }
    }
    if let Some(sps) = &sps {
        if sps.type_name() != "list" {
            return Err(err("species", "must be a list"));
        }
        for (i, sp) in sps.items().unwrap_or_default().iter().enumerate() {
            species.push(other::species(sp, i, ctx, &mut warnings)?);
        }
    }
    let formulation = match &formulation {
        None => "conservative".to_owned(),
        Some(f) => match f.text() {
            Some(t) if FORMULATIONS.contains(&t.as_str()) => t,
            _ => {
                return Err(err(
                    "oxygen",
                    format!(
                        "formulation must be one of {}, got {}",
                        py_tuple(FORMULATIONS),
                        f.repr()
                    ),
                ));
            }
        },
    };
    let names: Vec<String> = species
        .iter()
        .map(|s| s["name"].as_str().unwrap_or("").to_owned())
        .collect();
    let mut unique = names.clone();
    unique.sort();
    unique.dedup();
    if unique.len() != names.len() {
        let quoted: Vec<String> = names.iter().map(|n| py_quote(n)).collect();
        return Err(err(
            "species",
            format!("names must be unique, got [{}]", quoted.join(", ")),
        ));
    }
    let mut out = Map::new();
    out.insert("reference_pressure".into(), json!(p_ref));
    out.insert("formulation".into(), json!(formulation));
    out.insert("species".into(), Value::Array(species));
    grid(tr.as_ref(), ox.as_ref(), &mut out)?;
    Ok(Some(Transport {
        section: Value::Object(out),
        species: names,
        oxygen: oxygen_info,
        warnings,
    }))
}

/// The transport cells per flow segment, one grid for all species (oxygen's keys win), and
/// the velocity threshold, into the section `out`.
fn grid<N: Node>(tr: Option<&N>, ox: Option<&N>, out: &mut Map<String, Value>) -> Result<()> {
    // transport cells per flow segment: one grid for all species (oxygen's keys win)
    let (mut m, mut cells_pv) = refinement(tr, "transport", "cells_per_vessel")?;
    if let Some(ox) = ox {
        let (m_ox, pv_ox) = refinement(Some(ox), "oxygen", "per_vessel")?;
        m = m_ox.or(m);
        cells_pv.extend(pv_ox);
    }
    if let Some(m) = m {
        out.insert("cells_per_segment".into(), json!(m));
    }
    if !cells_pv.is_empty() {
        out.insert("cells_per_vessel".into(), Value::Object(cells_pv));
    }
    if let Some(v) = tr.and_then(|t| t.get("velocity_threshold")) {
        let x = num(
            Some(&v),
            "transport",
            "velocity_threshold",
            Bound::NonNegative,
        )?;
        out.insert("velocity_threshold".into(), json!(x));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ctx() -> Context {
        Context {
            pressure_factor: 1.0,
            period: Some(1.0),
            duration: Some(10.0),
            kinematic_viscosity: Some(3.5e-3 / 1050.0),
        }
    }

    fn read_json(v: Value) -> Result<Option<Transport>> {
        read(&v, &ctx())
    }

    /// PO2 in mmHg becomes a concentration α P (mol/m³); the Hill P50 becomes Pa; the Hill
    /// capacity is Hb × Hüfner / 22.414 mL/mmol (hand-computed, not the reader's constants).
    #[test]
    fn oxygen_converts_mmhg_and_hemoglobin_to_si() {
        let tr = read_json(json!({"oxygen": {
            "inlet": {"po2": 85.0}, "hemoglobin": "hill",
            "wall": {"model": "mass-transfer", "k": 1e-5, "po2": 60.0}}}))
        .unwrap()
        .unwrap();
        let sp = &tr.section["species"][0];
        assert_eq!(sp["inlet"]["value"].as_f64(), Some(1.40e-3 * 85.0));
        assert_eq!(
            sp["wall"]["wall_concentration"].as_f64(),
            Some(1.40e-3 * 60.0)
        );
        assert_eq!(sp["binding"]["p50"].as_f64(), Some(26.8 * 133.322368));
        let cap = sp["binding"]["capacity"].as_f64().unwrap();
        assert!((cap - 150.0 * 1.34 / 22.414).abs() < 1e-12 * cap);
        assert_eq!(tr.species, ["o2"]);
        assert_eq!(tr.oxygen, Some(("o2".to_owned(), 1.40e-3)));
    }

    /// A Lévêque wall with haemoglobin is facilitated by default (E_Hb > 1, docs/physics.md
    /// §3.4); switched off it keeps the given enhancement and warns.
    #[test]
    fn hemoglobin_facilitates_a_leveque_wall_unless_switched_off() {
        let on = read_json(
            json!({"oxygen": {"inlet": {"po2": 85.0}, "hemoglobin": "hill",
            "wall": {"model": "leveque", "po2": 60.0}}}),
        )
        .unwrap()
        .unwrap();
        let e = on.section["species"][0]["wall"]["enhancement"]
            .as_f64()
            .unwrap();
        assert!(e > 1.5 && e < 5.0, "E_Hb = {e}");
        assert!(on.warnings.is_empty());
        // the factor is recorded with what it was taken at (α P_in, the default D_Hb)
        let record = &on.section["species"][0]["wall"]["facilitation"];
        assert_eq!(record["factor"].as_f64(), Some(e));
        let c_in = record["inlet_concentration"].as_f64().unwrap();
        assert!((c_in / (1.40e-3 * 85.0) - 1.0).abs() < 1e-14, "{c_in}");
        assert_eq!(record["d_hb"].as_f64(), Some(D_HB_DEFAULT));
        let off = read_json(
            json!({"oxygen": {"inlet": {"po2": 85.0}, "hemoglobin": "hill",
            "wall": {"model": "leveque", "po2": 60.0, "hb_facilitation": false}}}),
        )
        .unwrap()
        .unwrap();
        assert_eq!(
            off.section["species"][0]["wall"]["enhancement"].as_f64(),
            Some(1.0)
        );
        assert!(off.warnings[0].contains("dissolved O2 only"));
        assert!(
            off.section["species"][0]["wall"]
                .get("facilitation")
                .is_none()
        );
    }

    /// Messages name the section, the key and the value as the user wrote them.
    #[test]
    fn errors_name_the_section_key_and_value() {
        let msg = |v: Value| read_json(v).err().unwrap().to_string();
        let m = msg(json!({"oxygen": {"inlet": {"po2": 85.0}, "colour": 1}}));
        assert!(
            m.contains("oxygen") && m.contains("unknown key 'colour'"),
            "{m}"
        );
        let m = msg(json!({"oxygen": {"inlet": {"po2": -1.0}}}));
        assert!(
            m.contains("oxygen inlet") && m.contains("'po2' must be >= 0.0, got -1.0"),
            "{m}"
        );
        let m = msg(json!({"species": [{"name": "s", "inlet": 1.0, "decay": "fast"}]}));
        assert!(
            m.contains("species 's'") && m.contains("'decay'") && m.contains("'fast'"),
            "{m}"
        );
        let m = msg(json!({"oxygen": {"inlet": {"po2": 85}, "per_vessel": {
            "ICA": {"wall": {"model": "graetz", "po2": 50, "flow": "mean"}}}}}));
        assert!(
            m.contains("per_vessel 'ICA'") && m.contains("'mean'"),
            "{m}"
        );
    }
}
