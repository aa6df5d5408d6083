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
//! (m³/s: the table is proportional to it). Outputs: `SaO2`, `SvO2` (flow-weighted
//! saturations of the left and right hearts' ejections), `PaO2`, `PvO2` (Pa), `VO2` (the
//! loop's cycle-mean consumption, mol/s), `VO2.<organ>`, `cardiac_output` (m³/s).

use super::closed_loop::tangent::{Cycle, LoopOutput, LoopParameter};
use super::closed_loop::{ClosedLoop, ClosedLoopSpec};
use super::closed_loop_params::{LoopParams, ML_O2};
use super::closed_loop_run::{Flows, RunSettings, simulate};
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
}

const WHAT: &str = "closed-loop sensitivities";

/// The parameter keys the tangent covers (for the error that names an unknown one).
const KEYS: &str = "organs.<organ>.vo2, km, lungs.diffusing_capacity, lungs.alveolar_po2, \
                    blood.p50, blood.hemoglobin, cardiac_output (with the prescribed flow \
                    table)";

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
                 (flows='table'); a heart run's flows are not differentiated",
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
    let chosen = paths
        .iter()
        .map(|path| parameter(&params, path, table))
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
    let cycle = Cycle {
        dt: params.dt,
        flow: &run.flow,
        volume: &run.volume,
        total: &run.total,
        start_volume: &lp.volume,
        flow_tangents: &[],
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
    })
}
