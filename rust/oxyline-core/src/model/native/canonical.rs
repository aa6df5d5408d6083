//! A whole native model read into its canonical SI description inside the core (a model the
//! core builds itself, e.g. the closed loop's circulation): the same readers, in the same
//! order, as the binding's `canonical_model` applies to a Python dict.

use super::{
    boundary_condition, check_conditions, check_periods, condition_periods, element_periods,
    header, period, simulation, vessel,
};
use crate::error::Result;
use crate::model::node::{Fields, Kind, Node};
use crate::model::species;
use crate::model::units::Quantity;
use serde_json::{Map, Value};

/// The run's duration (s) a callable wall flux and a bolus are sampled over: the model period
/// (1 s when none) times the file's `cycles` (`max_cycles` when `until_periodic`); None when
/// the count is no number.
pub fn duration<N: Node>(data: &N, period: Option<f64>) -> Option<f64> {
    let sim = data.get("simulation").filter(Node::truthy);
    let get = |k: &str| sim.as_ref().and_then(|s| s.get(k));
    let periodic = get("until_periodic").is_some_and(|u| u.truthy());
    let (key, default) = if periodic {
        ("max_cycles", 100.0)
    } else {
        ("cycles", 10.0)
    };
    let cycles = match get(key) {
        None => Some(default),
        Some(c) => match c.kind() {
            Kind::Bool => Some(if c.truthy() { 1.0 } else { 0.0 }),
            Kind::Int | Kind::Float => c.number(),
            _ => None,
        },
    };
    cycles.map(|c| period.unwrap_or(1.0) * c)
}

/// The canonical SI description of the native model `data` (every vessel and condition as
/// its canonical dict, the transport section when it has species) and the transport
/// section's warnings for the user.
pub fn canonical(data: &Value) -> Result<(Value, Vec<String>)> {
    let head = header(data)?;
    let units = head.units;
    let mut canon = head.canonical;
    let vessels = data
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default();
    let mut list = Vec::with_capacity(vessels.len());
    for (i, v) in vessels.into_iter().enumerate() {
        list.push(vessel(&Fields::new(v), i, units)?);
    }
    let bcs = data
        .get("boundary_conditions")
        .cloned()
        .unwrap_or_else(|| Value::Object(Map::new()));
    check_conditions(&bcs)?;
    let mut conditions = Map::new();
    let mut periods = Vec::new();
    for (node, bc) in bcs.entries() {
        let el = format!("boundary condition '{node}'");
        let c = boundary_condition(&Fields::new(bc), units, &el)?;
        periods.extend(condition_periods(&c, &el));
        conditions.insert(node, c);
    }
    periods.extend(element_periods(&list));
    let period = check_periods(period(data)?, &periods)?;
    if let Some(sim) = data.get("simulation").filter(|s| s.truthy()) {
        simulation(sim)?;
    }
    canon.insert("vessels".into(), Value::Array(list));
    canon.insert("boundary_conditions".into(), Value::Object(conditions));
    let blood = &canon["blood"];
    let (mu, rho) = (blood["viscosity"].as_f64(), blood["density"].as_f64());
    let ctx = species::Context {
        pressure_factor: units.factor(Quantity::Pressure),
        period,
        duration: duration(data, period),
        kinematic_viscosity: mu.zip(rho).map(|(mu, rho)| mu / rho),
    };
    let mut warnings = Vec::new();
    if let Some(tr) = species::read(data, &ctx)? {
        canon.insert("transport".into(), tr.section);
        warnings = tr.warnings;
    }
    Ok((Value::Object(canon), warnings))
}
