//! The closed loop's O2 sensitivities in one call (docs/calibration.md "A closed loop's
//! oxygen"): the parameter set (its published units), its flows and run controls, the
//! parameters by their keys in the set and the outputs by name in; the run to the periodic
//! state (`closed_loop_run::simulate`), then the exact tangent of that state
//! (`closed_loop::tangent`). Values and derivatives are in SI.
//!
//! Parameters: `organs.<organ>.vo2` (the organ's Michaelis–Menten vmax, mol/s), `km` (every
//! organ's, Pa), `lungs.diffusing_capacity` (mol s⁻¹ Pa⁻¹), `lungs.alveolar_po2` (Pa),
//! `blood.p50` (Pa),
//! `blood.hemoglobin` (kg/m³ = g/L), and with the prescribed flow table `cardiac_output`
//! (m³/s: the table is proportional to it); with the heart run's flows (`flows: heart`) the
//! heart model's parameters `vessels.<name>.<element>.<key>` and
//! `boundary_conditions.<node>.<key>` (their SI values, read from `heart_model_of`, the set's
//! `heart_values` written over its built ones), through the heart run's flow tangent
//! (`closed_loop_heart_tangent`). Outputs: `SaO2`, `SvO2` (flow-weighted
//! saturations of the left and right hearts' ejections), `PaO2`, `PvO2` (Pa), `VO2` (the
//! loop's cycle-mean consumption, mol/s), `VO2.<organ>`, `cardiac_output` (m³/s).

use super::closed_loop::tangent::{Cycle, LoopOutput, LoopParameter};
use super::closed_loop::{ClosedLoop, ClosedLoopSpec};
use super::closed_loop_circulation::heart_model;
use super::closed_loop_heart_tangent::heart_tangent;
use super::closed_loop_heart_values::number_at;
use super::closed_loop_params::{LoopParams, ML_O2};
use super::closed_loop_run::{Flows, RunSettings, heart_spec, simulate};
use crate::error::{Error, Result};
use crate::model::units::MMHG;
use serde_json::{Value, json};

/// The loop's outputs at its periodic state and their derivatives (row-major outputs ×
/// parameters), with the parameters' SI values and the run's convergence.
#[derive(Debug, Clone)]
pub struct LoopSensitivities {
    pub parameter_values: Vec<f64>,
    pub values: Vec<f64>,
    pub jacobian: Vec<f64>,
    pub cycles: usize,
    pub periodic_error: f64,
    /// With the heart run's flows: its cycles and whether it met its periodicity.
    pub heart_cycles: usize,
    pub heart_periodic: bool,
}

const WHAT: &str = "closed-loop sensitivities";

/// The parameter keys the tangent covers (for the error that names an unknown one).
const KEYS: &str = "organs.<organ>.vo2, km, lungs.diffusing_capacity, lungs.alveolar_po2, \
                    blood.p50, blood.hemoglobin, cardiac_output (with the prescribed flow \
                    table), vessels.<name>.<element>.<key> and \
                    boundary_conditions.<node>.<key> of the heart model (with flows='heart')";

/// Whether `path` names a parameter of the heart model (its patch paths).
fn is_heart(path: &str) -> bool {
    path.starts_with("vessels.") || path.starts_with("boundary_conditions.")
}

/// A parameter key of the set: the core's parameter, its SI value, and the factor from the
/// core's derivative to the derivative by that value.
fn parameter(p: &LoopParams, path: &str, prescribed: bool) -> Result<(LoopParameter, f64, f64)> {
    let organ = path
        .strip_prefix("organs.")
        .and_then(|r| r.strip_suffix(".vo2"));
    if let Some(name) = organ {
        // the compartments start with the left heart and (without a tree) the arteries
        let k = p
            .organs
            .iter()
            .position(|(k, _)| k == name)
            .ok_or_else(|| {
                let names: Vec<&str> = p.organs.iter().map(|(k, _)| k.as_str()).collect();
                Error::model(
                    WHAT,
                    format!("parameter '{path}': no organ '{name}' (organs: {names:?})"),
                )
            })?;
        return Ok((
            LoopParameter::Vmax(2 + k),
            p.organs[k].1.vo2 / 60.0 * ML_O2,
            1.0,
        ));
    }
    let b = &p.blood;
    Ok(match path {
        "km" => (LoopParameter::Km, p.km * MMHG, 1.0),
        "lungs.diffusing_capacity" => (
            LoopParameter::DiffusingCapacity,
            p.lungs.diffusing_capacity / 60.0 * ML_O2 / MMHG,
            1.0,
        ),
        "lungs.alveolar_po2" => (LoopParameter::AlveolarPo2, p.lungs.alveolar_po2 * MMHG, 1.0),
        "blood.p50" => (LoopParameter::P50, b.p50 * MMHG, 1.0),
        "blood.hemoglobin" => (
            LoopParameter::Capacity,
            b.hemoglobin,
            b.hufner * 1e3 * ML_O2,
        ),
        "cardiac_output" if prescribed => {
            let q = p.cardiac_output * 1e-3 / 60.0;
            (LoopParameter::FlowScale, q, 1.0 / q)
        }
        "cardiac_output" => {
            return Err(Error::model(
                WHAT,
                "parameter 'cardiac_output': covered with the prescribed flow table only \
                 (flows='table'); a heart run's output follows from its heart model's \
                 parameters (vessels.<name>.<element>.<key>)",
            ));
        }
        _ => {
            return Err(Error::model(
                WHAT,
                format!("parameter '{path}' is not one the tangent covers ({KEYS})"),
            ));
        }
    })
}

/// An output name, resolved against the loop's compartments.
fn output(lp: &ClosedLoop, name: &str) -> Result<LoopOutput> {
    Ok(match name {
        "SaO2" => LoopOutput::SaO2,
        "SvO2" => LoopOutput::SvO2,
        "PaO2" => LoopOutput::PaO2,
        "PvO2" => LoopOutput::PvO2,
        "VO2" => LoopOutput::Vo2,
        "cardiac_output" => LoopOutput::CardiacOutput,
        _ => match name.strip_prefix("VO2.") {
            Some(organ) => match lp.names.iter().position(|n| n == organ) {
                Some(n) => LoopOutput::OrganVo2(n),
                None => {
                    return Err(Error::model(
                        WHAT,
                        format!("output '{name}': the loop has no compartment '{organ}'"),
                    ));
                }
            },
            None => {
                return Err(Error::model(
                    WHAT,
                    format!(
                        "output '{name}' is not one of SaO2, SvO2, PaO2, PvO2, VO2, \
                         VO2.<organ>, cardiac_output"
                    ),
                ));
            }
        },
    })
}

/// Whether the run's flows are the prescribed table (proportional to the cardiac output).
fn prescribed(p: &Value, flows: &Flows) -> bool {
    match flows {
        Flows::Named(s) => s == "table",
        Flows::Default => p.get("flows").is_none_or(|f| f == "table"),
        Flows::Table { .. } => false,
    }
}

/// Whether the run's flows are those of the heart run.
fn from_heart(p: &Value, flows: &Flows) -> bool {
    match flows {
        Flows::Named(s) => s == "heart",
        Flows::Default => p.get("flows").is_some_and(|f| f == "heart"),
        Flows::Table { .. } => false,
    }
}

/// The heart parameters among `paths` (their positions), checked against the heart model
/// before any run: they need the heart run's flows, and resolve in its model (a path naming
/// nothing is named with the nearest key, `sensitivity::Parameter`).
fn heart_paths(
    params_json: &str,
    params: &LoopParams,
    heart: bool,
    paths: &[String],
) -> Result<Vec<usize>> {
    let chosen: Vec<usize> = (0..paths.len()).filter(|&i| is_heart(&paths[i])).collect();
    let Some(&first) = chosen.first() else {
        return Ok(chosen);
    };
    if !heart {
        return Err(Error::model(
            WHAT,
            format!(
                "parameter '{}': a heart model's parameter needs the heart run's flows \
                 (flows='heart')",
                paths[first]
            ),
        ));
    }
    let p: Value =
        serde_json::from_str(params_json).map_err(|e| Error::model(WHAT, e.to_string()))?;
    let mut native = heart_model(&p, params, &params.layout())?;
    let spec = heart_spec(&p, params, &params.layout())?;
    let model: crate::model::NetworkSpec = serde_json::from_value(spec.model)
        .map_err(|e| Error::model("closed-loop heart", e.to_string()))?;
    for &i in &chosen {
        let path = &paths[i];
        // a number of the heart model as built (named with the nearest key when it is not
        // one), then one the tangent covers
        number_at(&mut native, path)?;
        crate::sensitivity::Parameter::parse(&model, path)?;
        // the block's lungs' flow is read through R_pd itself (closed_loop_heart_series)
        if path.ends_with(".pulmonary_resistance") && path.contains(".heart_pulmonary.") {
            return Err(Error::model(
                WHAT,
                format!(
                    "parameter '{path}': the lungs' flow is read through it; not covered \
                     (the block's other values are)"
                ),
            ));
        }
    }
    Ok(chosen)
}

/// The outputs `outputs` of the loop of `params_json` at its periodic state and their exact
/// derivatives by the parameters `paths`; an error naming an unknown parameter or output
/// (both checked before the run), or a loop with an arterial tree.
pub fn sensitivities(
    params_json: &str,
    flows: Flows,
    settings: &RunSettings,
    paths: &[String],
    outputs: &[String],
) -> Result<LoopSensitivities> {
    let p: Value =
        serde_json::from_str(params_json).map_err(|e| Error::model(WHAT, e.to_string()))?;
    let params = LoopParams::from_json(params_json)?;
    if params.has_tree() {
        return Err(Error::model(
            WHAT,
            "do not cover a loop with an arterial tree (arteries: 'tree')",
        ));
    }
    let table = prescribed(&p, &flows);
    let hearts = heart_paths(params_json, &params, from_heart(&p, &flows), paths)?;
    let heart_list: Vec<String> = hearts.iter().map(|&i| paths[i].clone()).collect();
    let mut chosen = paths
        .iter()
        .map(
            |path| match hearts.iter().position(|&i| paths[i] == *path) {
                // its value is the heart model's, known after the heart's tangent run
                Some(j) => Ok((LoopParameter::Flow(j), f64::NAN, 1.0)),
                None => parameter(&params, path, table),
            },
        )
        .collect::<Result<Vec<_>>>()?;
    let layout = params.layout();
    let spec: ClosedLoopSpec = serde_json::from_value(json!({
        "compartments": &layout.compartments, "branches": &layout.branches,
        "binding": &layout.binding}))
    .map_err(|e| Error::model(WHAT, e.to_string()))?;
    let lp = ClosedLoop::new(&spec)?;
    let wanted = outputs
        .iter()
        .map(|o| output(&lp, o))
        .collect::<Result<Vec<_>>>()?;
    let run = simulate(params_json, flows, settings)?.run;
    let mut flow_tangents = Vec::new();
    if !heart_list.is_empty() {
        let spec = heart_spec(&p, &params, &layout)?;
        let ht = heart_tangent(&spec, &heart_list, params.dt, params.period)?;
        for (j, &i) in hearts.iter().enumerate() {
            chosen[i].1 = ht.values[j];
        }
        flow_tangents = ht.tables;
        for t in &mut flow_tangents {
            lp.balance_direction(t)?;
        }
    }
    let cycle = Cycle {
        dt: params.dt,
        flow: &run.flow,
        volume: &run.volume,
        total: &run.total,
        start_volume: &lp.volume,
        flow_tangents: &flow_tangents,
    };
    let kinds: Vec<LoopParameter> = chosen.iter().map(|c| c.0).collect();
    let tangent = lp.cycle_tangent(&cycle, &kinds)?;
    let mut values = Vec::with_capacity(wanted.len());
    let mut jacobian = Vec::with_capacity(wanted.len() * kinds.len());
    for &o in &wanted {
        let (v, d) = lp.output(&cycle, &tangent, &kinds, o)?;
        values.push(v);
        jacobian.extend(d.iter().zip(&chosen).map(|(d, c)| d * c.2));
    }
    Ok(LoopSensitivities {
        parameter_values: chosen.iter().map(|c| c.1).collect(),
        values,
        jacobian,
        cycles: run.cycles,
        periodic_error: run.periodic_error,
        heart_cycles: run.heart_cycles,
        heart_periodic: run.heart_periodic,
    })
}
