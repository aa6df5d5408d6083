//! Exact parameter sensitivities of a model's periodic state: the parameters by their patch
//! paths ([`parameter`]), the derivative of the DAE with respect to each, and the
//! tangent-linear generalized-α run to the periodic state ([`tangent`]), and its adjoint
//! (reverse) sweep for many parameters and few functionals ([`adjoint`]). A closed loop's
//! conserved blood volume closes its periodic problem ([`volume`]). Calibration targets (an
//! output by name, its value and derivatives from the signals' tangents) in [`targets`], the
//! signals each output name reads in [`target_signals`], every target of one tangent or
//! adjoint run (the adjoint's output weights) in [`target_runs`]. Flow and oxygen signals by
//! flow and oxygen parameters together, as the bindings ask for them, in [`outputs`].

pub mod krylov;
pub mod outputs;
pub mod parameter;
pub mod species;
pub mod tangent;
pub mod target_runs;
pub mod target_signals;
pub mod targets;
pub mod volume;

use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::model::NetworkSpec;
use crate::output::VESSEL_VARIABLES;
pub use outputs::{SignalAdjoint, SignalSensitivities, signal_adjoint_with, signal_sensitivities};
pub use parameter::{DaeTangent, Parameter};
pub use species::{
    SpeciesAdjoint, SpeciesSensitivities, species_adjoint_with, species_sensitivities,
};
pub use tangent::{
    PeriodicAdjoint, PeriodicTangent, TangentSettings, periodic_adjoint, periodic_adjoint_in,
    periodic_adjoint_with, periodic_tangent, periodic_tangent_in,
};
pub use volume::ConservedVolume;

/// The result of [`sensitivities`]: the parameters' SI values and the signals over the
/// periodic cycle with their derivatives.
#[derive(Debug, Clone)]
pub struct Sensitivities {
    pub values: Vec<f64>,
    pub cycle: PeriodicTangent,
}

/// d(signal)/d(parameter) over the periodic cycle of `spec`. `signals` are (vessel, variable)
/// pairs, the variable one of [`VESSEL_VARIABLES`]; `paths` the parameters' patch paths.
pub fn sensitivities(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    settings: TangentSettings,
) -> Result<Sensitivities> {
    let (dae, tangents, unknowns, volume) = prepare(spec, paths, signals)?;
    let cycle = periodic_tangent_in(&dae, &tangents, &unknowns, settings, volume.as_ref())?;
    Ok(Sensitivities {
        values: tangents.iter().map(|t| t.value).collect(),
        cycle,
    })
}

/// The gradients of functionals J_f = Σ_k Σ_j w[(f n_steps + k) n_signals + j] · signal j
/// after step k of the periodic cycle, by the adjoint (one backward sweep per functional,
/// whatever the number of parameters): the parameters' SI values and the adjoint's result.
pub fn adjoint(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    weights: &[f64],
    settings: TangentSettings,
) -> Result<(Vec<f64>, PeriodicAdjoint)> {
    adjoint_with(spec, paths, signals, |_, _| Ok(weights.to_vec()), settings)
}

/// [`adjoint`] with the weights chosen from the one primal run's periodic cycle:
/// `weights_of(times, values)` gets the step end times and the signals (n_steps × signals)
/// and returns the weights ([`tangent::periodic_adjoint_with`]).
pub fn adjoint_with<W>(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    weights_of: W,
    settings: TangentSettings,
) -> Result<(Vec<f64>, PeriodicAdjoint)>
where
    W: FnOnce(&[f64], &[f64]) -> Result<Vec<f64>>,
{
    let (dae, tangents, unknowns, volume) = prepare(spec, paths, signals)?;
    let out = periodic_adjoint_in(
        &dae,
        &tangents,
        &unknowns,
        weights_of,
        settings,
        volume.as_ref(),
    )?;
    Ok((tangents.iter().map(|t| t.value).collect(), out))
}

/// d(unknown)/d(parameter) over the periodic cycle of `spec`, the unknowns by their circuit
/// names (`Circuit::unknown_name`, e.g. "flow in vessel 'lv'"): what a caller reading a run's
/// unknowns by name (the closed loop's heart) needs of the same run's tangent. An error names
/// a path that does not resolve or a name that is not one of the model's unknowns.
pub fn unknown_sensitivities(
    spec: &NetworkSpec,
    paths: &[String],
    unknowns: &[String],
    settings: TangentSettings,
) -> Result<Sensitivities> {
    let (assembled, dae, tangents, volume) = differentiated(spec, paths)?;
    let circuit = &assembled.circuit;
    let index: std::collections::HashMap<String, usize> =
        (0..dae.n).map(|i| (circuit.unknown_name(i), i)).collect();
    let columns = unknowns
        .iter()
        .map(|name| {
            index.get(name).copied().ok_or_else(|| {
                Error::model(
                    format!("model '{}'", spec.name),
                    format!("'{name}' is not one of its unknowns"),
                )
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let cycle = periodic_tangent_in(&dae, &tangents, &columns, settings, volume.as_ref())?;
    Ok(Sensitivities {
        values: tangents.iter().map(|t| t.value).collect(),
        cycle,
    })
}

/// The assembled model of `spec` (every vessel recorded), its DAE, the derivative of the DAE
/// by each parameter and a closed loop's conserved volume; an error naming a path that does
/// not resolve.
fn differentiated(spec: &NetworkSpec, paths: &[String]) -> Result<Differentiated> {
    let mut spec = spec.clone();
    for v in &mut spec.vessels {
        v.output = true;
    }
    let params = paths
        .iter()
        .map(|p| Parameter::parse(&spec, p))
        .collect::<Result<Vec<_>>>()?;
    let assembled = spec.assemble()?;
    let circuit = &assembled.circuit;
    let dae = circuit.assemble()?;
    parameter::check_supported(circuit, &dae)?;
    let volume = ConservedVolume::of(circuit, &dae);
    parameter::check_closed_loop(&spec, volume.is_some())?;
    let stamps = parameter::Stamps::new(circuit, &dae);
    let mut tangents = Vec::with_capacity(params.len());
    for (p, path) in params.iter().zip(paths) {
        let mut t = stamps.tangent(&spec, p, path)?;
        // a node whose row a pressure condition took holds no capacitance
        for (node, _) in &circuit.fixed_pressures {
            t.de[*node] = 0.0;
        }
        tangents.push(t);
    }
    Ok((assembled, dae, tangents, volume))
}

/// [`differentiated`]'s result.
type Differentiated = (
    crate::assemble::Assembled,
    Dae,
    Vec<DaeTangent>,
    Option<ConservedVolume>,
);

/// The DAE of `spec`, the derivative of it by each parameter, the unknowns of the signals,
/// and a closed loop's conserved volume; an error naming a path, vessel or variable that does
/// not resolve.
fn prepare(spec: &NetworkSpec, paths: &[String], signals: &[(String, String)]) -> Result<Prepared> {
    let (assembled, dae, tangents, volume) = differentiated(spec, paths)?;
    let probes = &assembled.probes;
    let unknowns = signals
        .iter()
        .map(|(vessel, var)| {
            let k = VESSEL_VARIABLES
                .iter()
                .position(|v| v == var)
                .ok_or_else(|| {
                    Error::model(
                        format!("output '{vessel}:{var}'"),
                        format!("unknown variable '{var}' (one of {VESSEL_VARIABLES:?})"),
                    )
                })?;
            if let Some(vi) = probes.vessels.iter().position(|v| v == vessel) {
                return Ok(probes.vessel_unknowns[4 * vi + k]);
            }
            // a heart block's valve `<vessel>:<valve>`: the pressures behind (in) and in
            // front of it (out) and its flow (the left ventricle is `<vessel>:aortic`'s in)
            let valve = probes.valves.iter().find(|v| v.name == *vessel);
            let valve = valve.ok_or_else(|| {
                Error::model(
                    format!("output '{vessel}:{var}'"),
                    format!("no vessel named '{vessel}' in model '{}'", spec.name),
                )
            })?;
            Ok(valve.unknowns[k.min(2)])
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((dae, tangents, unknowns, volume))
}

/// [`prepare`]'s result.
type Prepared = (Dae, Vec<DaeTangent>, Vec<usize>, Option<ConservedVolume>);

#[cfg(test)]
mod tests;

#[cfg(test)]
#[path = "kinds_tests.rs"]
mod kinds_tests;
