//! The closed-loop heart that drives the O2 loop's flows (docs/oxygen.md "Oxygen around a
//! closed loop"): a closed circulation (heart, systemic arteries or the arterial tree, organ
//! beds, veins) run in the core to its last cycle with every unknown recorded; the loop's
//! branch flows and the tree's boundary tables are read from that cycle by name, so that one
//! call runs the flow and the O2 compartments to the periodic state.
//!
//! A branch's flow is a sum of recorded unknowns times coefficients; an on/off valve's flow
//! counts only while the valve is open (docs/physics.md §1.10: closed when the pressure behind
//! does not exceed the pressure in front and the flow is not positive). Each O2 step's flow is
//! the mean of the recorded intervals it spans (trapezoidal).

use super::closed_loop::TreeSpec;
use crate::error::{Error, Result};
use crate::run::{Method, RunSettings, Start};
use serde::Deserialize;
use serde_json::{Value, json};
use std::collections::HashMap;

/// A flow (or pressure) read from the heart run's recorded unknowns.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Series {
    /// (unknown name, coefficient): the series is Σ coefficient × unknown.
    pub terms: Vec<(String, f64)>,
    /// An on/off valve: zero while the unknown `behind` ≤ the unknown `front` and the series
    /// is not positive.
    #[serde(default)]
    pub valve: Option<(String, String)>,
}

/// The closed-loop heart's run and what the O2 loop reads from it.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeartSpec {
    /// The closed circulation: a canonical SI model (no boundary conditions needed).
    pub model: Value,
    /// Flow step and output interval (s).
    pub dt: f64,
    /// Cycles to run (the least, with `until_periodic`).
    pub cycles: usize,
    /// Run on until the relative cycle-to-cycle change of the state is below this, at most
    /// `max_cycles` cycles (None: exactly `cycles`).
    #[serde(default)]
    pub until_periodic: Option<f64>,
    #[serde(default)]
    pub max_cycles: Option<usize>,
    /// generalized-α's ρ∞ and Newton's absolute tolerance (None: the default control).
    #[serde(default = "default_rho")]
    pub rho_infty: f64,
    #[serde(default)]
    pub newton_atol: Option<f64>,
    /// One series per O2 branch, in the loop's branch order.
    #[serde(default)]
    pub branches: Vec<Series>,
    /// Named series recorded for the caller (the heart's valves, the venous pressure ...).
    #[serde(default)]
    pub record: Vec<(String, Series)>,
    /// With an arterial tree: the series that feeds its root and the venous pressure its
    /// outlets drain to, written into its model's `inlet` flow and outlet pressure tables.
    #[serde(default)]
    pub tree_inflow: Option<Series>,
    #[serde(default)]
    pub tree_venous_pressure: Option<Series>,
    /// The heart of `oxyline.closed_loop` and its loop: `branches`, `record` and the tree's
    /// series are derived from it (`closed_loop_heart_series`).
    #[serde(default)]
    pub series_of: Option<super::closed_loop_heart_series::SeriesOf>,
}

fn default_rho() -> f64 {
    0.5
}

/// What the heart run gives the O2 loop: its flow table (steps × branches, row-major) and
/// the recorded series over the last cycle (time from 0).
pub struct HeartFlows {
    pub table: Vec<f64>,
    pub time: Vec<f64>,
    pub record: Vec<(String, Vec<f64>)>,
    /// The heart run's cycles, its last cycle-to-cycle change and whether that met its
    /// `until_periodic` (true without one).
    pub cycles: usize,
    pub periodic_error: f64,
    pub periodic: bool,
}

/// The last cycle of the heart model (every unknown, by name).
struct Recorded {
    time: Vec<f64>,
    data: Vec<f64>,
    n: usize,
    index: HashMap<String, usize>,
    cycles: usize,
    periodic_error: f64,
}

impl Recorded {
    fn eval(&self, s: &Series) -> Result<Vec<f64>> {
        let col = |name: &str| {
            self.index.get(name).copied().ok_or_else(|| {
                Error::model(
                    "closed-loop heart",
                    format!("'{name}' is not one of its unknowns"),
                )
            })
        };
        let terms = s
            .terms
            .iter()
            .map(|(name, c)| Ok((col(name)?, *c)))
            .collect::<Result<Vec<_>>>()?;
        let valve = s
            .valve
            .as_ref()
            .map(|(b, f)| Ok::<_, Error>((col(b)?, col(f)?)))
            .transpose()?;
        Ok(self
            .data
            .chunks_exact(self.n)
            .map(|row| {
                let q: f64 = terms.iter().map(|&(i, c)| c * row[i]).sum();
                match valve {
                    Some((b, f)) if row[b] <= row[f] && q <= 0.0 => 0.0,
                    _ => q,
                }
            })
            .collect())
    }
}

/// Runs the heart model for `spec.cycles` cycles of `period` (on to its periodic state with
/// `until_periodic`) and records its last cycle.
fn run(spec: &HeartSpec, period: f64) -> Result<Recorded> {
    let model: crate::model::NetworkSpec = serde_json::from_value(spec.model.clone())
        .map_err(|e| Error::model("closed-loop heart", e.to_string()))?;
    let assembled = model.assemble()?;
    let dae = assembled.circuit.assemble()?;
    let mut s = RunSettings::one_cycle(
        Method::GeneralizedAlpha {
            rho_inf: spec.rho_infty,
        },
        Some(spec.dt),
        (0..dae.n).collect(),
    );
    s.period = period;
    s.cycles = spec.cycles;
    s.until_periodic = spec.until_periodic;
    s.max_cycles = spec.max_cycles.unwrap_or(spec.cycles).max(spec.cycles);
    s.output_every = spec.dt;
    s.start = Start::Steady;
    if let Some(atol) = spec.newton_atol {
        s.newton.atol = Some(atol);
    }
    let out = crate::run::simulate(&dae, &s, &mut |_, _| true)?;
    if let Some(e) = out.error {
        return Err(e);
    }
    let index = (0..dae.n)
        .map(|i| (assembled.circuit.unknown_name(i), i))
        .collect();
    Ok(Recorded {
        time: out.times,
        data: out.data,
        n: dae.n,
        index,
        cycles: out.cycles_run,
        periodic_error: out.periodic_error,
    })
}

/// Runs the heart, and returns the O2 loop's flow table at step `dt` and the recorded series;
/// with `tree`, its model's inlet flow and outlet pressure tables are set from the run.
pub fn heart_flows(
    spec: &HeartSpec,
    dt: f64,
    period: f64,
    tree: Option<&mut TreeSpec>,
) -> Result<HeartFlows> {
    let rec = run(spec, period)?;
    let k = (dt / spec.dt).round() as usize;
    let intervals = rec.time.len().saturating_sub(1);
    let whole = k > 0 && ((k as f64) * spec.dt - dt).abs() <= 1e-9 * dt;
    if !whole || intervals == 0 || intervals % k != 0 {
        return Err(Error::model(
            "closed-loop heart",
            format!(
                "the O2 step {dt} s is not a whole number of its flow steps {} s over its \
                 {intervals} recorded intervals",
                spec.dt
            ),
        ));
    }
    let steps = intervals / k;
    let nb = spec.branches.len();
    let mut table = vec![0.0; steps * nb];
    for (b, series) in spec.branches.iter().enumerate() {
        let x = rec.eval(series)?;
        for s in 0..steps {
            let sum: f64 = (s * k..(s + 1) * k).map(|i| 0.5 * (x[i] + x[i + 1])).sum();
            table[s * nb + b] = sum / k as f64;
        }
    }
    let t0 = rec.time[0];
    let time: Vec<f64> = rec.time.iter().map(|t| t - t0).collect();
    if let Some(tree) = tree {
        let inflow = series_or(&rec, spec.tree_inflow.as_ref(), "tree_inflow")?;
        let venous = series_or(
            &rec,
            spec.tree_venous_pressure.as_ref(),
            "tree_venous_pressure",
        )?;
        set_tree_tables(tree, &time, &inflow, &venous)?;
    }
    let record = spec
        .record
        .iter()
        .map(|(name, s)| Ok((name.clone(), rec.eval(s)?)))
        .collect::<Result<Vec<_>>>()?;
    let periodic = spec
        .until_periodic
        .is_none_or(|tol| rec.periodic_error < tol);
    Ok(HeartFlows {
        table,
        time,
        record,
        cycles: rec.cycles,
        periodic_error: rec.periodic_error,
        periodic,
    })
}

fn series_or(rec: &Recorded, s: Option<&Series>, key: &str) -> Result<Vec<f64>> {
    let s = s.ok_or_else(|| {
        Error::model(
            "closed-loop heart",
            format!("an arterial tree needs '{key}'"),
        )
    })?;
    rec.eval(s)
}

/// Writes the heart run's root inflow and venous pressure into the tree model's conditions:
/// the times and values of the inlet's flow table and of every outlet's pressure table (the
/// model carries those tables, read by the schema, with placeholder values).
fn set_tree_tables(
    tree: &mut TreeSpec,
    time: &[f64],
    inflow: &[f64],
    venous: &[f64],
) -> Result<()> {
    let mut model: Value = serde_json::from_str(&tree.model)
        .map_err(|e| Error::model("arterial tree", e.to_string()))?;
    let mut put = |bc: &str, key: &str, values: &[f64]| -> Result<()> {
        let table = model
            .pointer_mut(&format!(
                "/boundary_conditions/{}/{key}",
                bc.replace('~', "~0").replace('/', "~1")
            ))
            .and_then(Value::as_object_mut)
            .filter(|t| t.contains_key("time") && t.contains_key("value"))
            .ok_or_else(|| {
                Error::model(
                    "arterial tree",
                    format!("boundary condition '{bc}' needs a {key} table"),
                )
            })?;
        table.insert("time".into(), json!(time));
        table.insert("value".into(), json!(values));
        Ok(())
    };
    put(&tree.inlet, "flow", inflow)?;
    for o in &tree.outlets {
        put(&o.boundary, "pressure", venous)?;
    }
    tree.model = model.to_string();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three recorded rows of (valve flow, pressure behind, pressure in front).
    fn recorded() -> Recorded {
        let names = ["q", "behind", "front"];
        Recorded {
            time: vec![0.0, 1.0, 2.0],
            data: vec![-1.0, 1.0, 2.0, -1.0, 3.0, 2.0, 2.0, 1.0, 2.0],
            n: 3,
            index: names
                .iter()
                .enumerate()
                .map(|(i, n)| (n.to_string(), i))
                .collect(),
            cycles: 1,
            periodic_error: 0.0,
        }
    }

    #[test]
    fn a_valve_carries_no_flow_only_while_closed() {
        // docs/physics.md §1.10: closed when the pressure behind does not exceed the pressure
        // in front and the flow is not positive; open it passes the flow, backflow included
        let s = Series {
            terms: vec![("q".into(), 0.5)],
            valve: Some(("behind".into(), "front".into())),
        };
        assert_eq!(recorded().eval(&s).unwrap(), vec![0.0, -0.5, 1.0]);
        let plain = Series {
            terms: vec![("q".into(), 1.0), ("front".into(), -1.0)],
            valve: None,
        };
        assert_eq!(recorded().eval(&plain).unwrap(), vec![-3.0, -3.0, 0.0]);
    }

    #[test]
    fn an_unknown_name_is_a_model_error_naming_it() {
        let s = Series {
            terms: vec![("flow in nowhere".into(), 1.0)],
            valve: None,
        };
        let e = recorded().eval(&s).unwrap_err().to_string();
        assert!(
            e.contains("'flow in nowhere' is not one of its unknowns"),
            "{e}"
        );
    }
}
