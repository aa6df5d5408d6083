//! A whole native model read into its canonical SI description, over any front end's values
//! ([`Node`]: a JSON value the core built itself, e.g. the closed loop's circulation, or the
//! user's Python dicts through the binding): header, vessels, boundary conditions, the period
//! checked against every element's, the simulation keys and the transport section, in that
//! order. The pieces are public so that the binding's fast reader (plain vessels straight into
//! the network's parts) checks the same things in the same order.

use super::{
    boundary_condition, check_conditions, check_periods, condition_periods, element_periods,
    header, period, simulation, vessel,
};
use crate::error::Result;
use crate::model::node::{Fields, Kind, Node};
use crate::model::species;
use crate::model::units::{Quantity, Units};
use serde_json::{Map, Value};

/// Periods of the elements that repeat (s), each with the element it comes from.
pub type Periods = Vec<(f64, String)>;

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

/// The model's `boundary_conditions` as (node, condition) entries, checked to be a mapping
/// (none when the key is missing).
pub fn condition_entries<N: Node>(data: &N) -> Result<Vec<(String, N)>> {
    match data.get("boundary_conditions") {
        None => Ok(Vec::new()),
        Some(bcs) => {
            check_conditions(&bcs)?;
            Ok(bcs.entries())
        }
    }
}

/// The canonical conditions of `entries` (node, condition) by node, and their waveforms'
/// periods with the element.
pub fn conditions<N: Node + Clone>(
    entries: Vec<(String, N)>,
    units: Units,
) -> Result<(Map<String, Value>, Periods)> {
    let mut out = Map::new();
    let mut periods = Vec::new();
    for (node, bc) in entries {
        let el = format!("boundary condition '{node}'");
        let c = boundary_condition(&Fields::new(bc), units, &el)?;
        periods.extend(condition_periods(&c, &el));
        out.insert(node, c);
    }
    Ok((out, periods))
}

/// The model period checked against every element's `periods`, then the simulation
/// section's keys.
pub fn period_and_simulation<N: Node>(data: &N, periods: &[(f64, String)]) -> Result<Option<f64>> {
    let period = check_periods(period(data)?, periods)?;
    if let Some(sim) = data.get("simulation").filter(Node::truthy) {
        simulation(&sim)?;
    }
    Ok(period)
}

/// What the transport sections of a model are read against: its pressure unit, period, run
/// duration and blood (canonical, SI).
pub fn transport_context<N: Node>(
    data: &N,
    blood: &Value,
    units: Units,
    period: Option<f64>,
) -> species::Context {
    let (mu, rho) = (blood["viscosity"].as_f64(), blood["density"].as_f64());
    species::Context {
        pressure_factor: units.factor(Quantity::Pressure),
        period,
        duration: duration(data, period),
        kinematic_viscosity: mu.zip(rho).map(|(mu, rho)| mu / rho),
    }
}

/// The canonical SI description of the native model `data` (every vessel and condition as
/// its canonical dict, the transport section when it has species) and the transport
/// section's warnings for the user.
pub fn canonical<N: Node + Clone>(data: &N) -> Result<(Value, Vec<String>)> {
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
    let (bcs, mut periods) = conditions(condition_entries(data)?, units)?;
    periods.extend(element_periods(&list));
    let period = period_and_simulation(data, &periods)?;
    canon.insert("vessels".into(), Value::Array(list));
    canon.insert("boundary_conditions".into(), Value::Object(bcs));
    let ctx = transport_context(data, &canon["blood"], units, period);
    let mut warnings = Vec::new();
    if let Some(tr) = species::read(data, &ctx)? {
        canon.insert("transport".into(), tr.section);
        warnings = tr.warnings;
    }
    Ok((Value::Object(canon), warnings))
}
