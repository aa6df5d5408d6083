//! A whole native model read into its canonical SI description, over any front end's values
//! ([`Node`]: a JSON value the core built itself, e.g. the closed loop's circulation, or the
//! user's Python dicts through the binding): header, vessels, boundary conditions, the period
//! checked against every element's, the simulation keys and the transport section, in that
//! order ([`read_in_order`], the one place that order is written; an ensemble's variant reads
//! through it too, reusing its base's canonical elements). The pieces are public so that the
//! binding's fast reader (plain vessels straight into the network's parts) checks the same
//! things in the same order.

use super::{
    Header, boundary_condition, check_conditions, check_periods, condition_periods,
    element_periods, header, period, simulation, vessel,
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
        let el = condition_element(&node);
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

/// How an error and a period name the condition at `node`.
pub fn condition_element(node: &str) -> String {
    format!("boundary condition '{node}'")
}

/// A native model read in the canonical order, its elements in the caller's form `V`.
pub struct Read<V> {
    /// Name, unit system and the canonical top-level sections.
    pub header: Header,
    pub vessels: Vec<V>,
    /// The conditions by node, in the model's order.
    pub conditions: Vec<(String, V)>,
    /// The model period, checked against every element's (None: no element repeats).
    pub period: Option<f64>,
    /// The transport section (None without `oxygen` or `species`).
    pub transport: Option<species::Transport>,
}

/// The one order a native model is read in: header, vessels, boundary conditions, the period
/// checked against every element's, the simulation keys, the transport section.
/// `vessel_of(i, vessel, units)` and `condition_of(node, condition, units)` give each
/// element's canonical form: read from the model by the schema ([`vessel`],
/// [`boundary_condition`]), or a canonical element the caller already holds and knows to be
/// unchanged (an ensemble's variant reuses its base model's). A condition comes with its
/// waveforms' periods when the caller knows them (None: found here, [`condition_periods`]).
pub fn read_in_order<N, V, FV, FC>(
    data: &N,
    mut vessel_of: FV,
    mut condition_of: FC,
) -> Result<Read<V>>
where
    N: Node + Clone,
    V: Node,
    FV: FnMut(usize, N, Units) -> Result<V>,
    FC: FnMut(&str, N, Units) -> Result<(V, Option<Periods>)>,
{
    let head = header(data)?;
    let units = head.units;
    let items = data
        .get("vessels")
        .and_then(|v| v.items())
        .unwrap_or_default();
    let mut vessels = Vec::with_capacity(items.len());
    for (i, v) in items.into_iter().enumerate() {
        vessels.push(vessel_of(i, v, units)?);
    }
    let mut conditions = Vec::new();
    let mut periods = Vec::new();
    for (node, bc) in condition_entries(data)? {
        let (c, known) = condition_of(&node, bc, units)?;
        match known {
            Some(p) => periods.extend(p),
            None => periods.extend(condition_periods(&c, &condition_element(&node))),
        }
        conditions.push((node, c));
    }
    periods.extend(element_periods(&vessels));
    let period = period_and_simulation(data, &periods)?;
    let ctx = transport_context(data, &head.canonical["blood"], units, period);
    let transport = species::read(data, &ctx)?;
    Ok(Read {
        header: head,
        vessels,
        conditions,
        period,
        transport,
    })
}

/// The canonical SI description of the native model `data` (every vessel and condition as
/// its canonical dict, the transport section when it has species) and the transport
/// section's warnings for the user.
pub fn canonical<N: Node + Clone>(data: &N) -> Result<(Value, Vec<String>)> {
    let read = read_in_order(
        data,
        |i, v, units| vessel(&Fields::new(v), i, units),
        |node, bc, units| {
            let c = boundary_condition(&Fields::new(bc), units, &condition_element(node))?;
            Ok((c, None))
        },
    )?;
    let mut canon = read.header.canonical;
    canon.insert("vessels".into(), Value::Array(read.vessels));
    let bcs: Map<String, Value> = read.conditions.into_iter().collect();
    canon.insert("boundary_conditions".into(), Value::Object(bcs));
    let mut warnings = Vec::new();
    if let Some(tr) = read.transport {
        canon.insert("transport".into(), tr.section);
        warnings = tr.warnings;
    }
    Ok((Value::Object(canon), warnings))
}
