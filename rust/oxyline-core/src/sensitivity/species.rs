//! Exact sensitivities of the oxygen outputs by oxygen and flow parameters at the periodic
//! state: the flow and its tangents by the flow parameters run to their periodic state by
//! generalized-α ([`super::tangent::periodic_tangent`]; oxygen parameters do not change the
//! flow), then the species transport and its tangents ([`crate::transport::tangent`]) repeat
//! that cycle's recorded flow (and flow tangents) until both the amounts and every tangent
//! are periodic. A flow parameter (any path of [`Parameter`]) reaches the oxygen through the
//! face flows and transport volumes of every step, and a vessel's radius or length through
//! its reference volumes and wall coefficients too.
//!
//! Parameters (SI values): `oxygen.wall.k` (mass-transfer coefficient, m/s),
//! `oxygen.wall.po2` (its wall PO2, Pa), `oxygen.wall.concentration` (mol/m³),
//! `oxygen.wall.flux` (a constant prescribed wall flux, mol m⁻² s⁻¹: consumption) and
//! `oxygen.hill.p50` (Pa). Signals: per vessel `po2_out`, `saturation_out`,
//! `concentration_out`, `flow_out`, `wall_uptake`; for the whole network (vessel "") the
//! step's `inflow`, `outflow` and `consumption` (mol/s, the balance's own fluxes).

use super::parameter::{self, DaeTangent, Parameter};
use super::tangent::{TangentSettings, periodic_tangent};
use crate::assemble::Assembled;
use crate::circuit::Dae;
use crate::closure::{FluxSpec, WallSpec};
use crate::error::{Error, Result};
use crate::hemoglobin::{BindingSpec, HillAnchor};
use crate::model::NetworkSpec;
use crate::run::flow_harmonics::FlowHarmonics;
use crate::transport::tangent::{
    FlowEffect, FlowGeometry, FlowStep, MeanFlowTangent, SpeciesDerivative, SpeciesParameterKind,
    SpeciesTangent, TaperEnd, VesselSpeciesSignal,
};
use crate::transport::{SpeciesSpec, Transport};
use facilitation::By;

/// Per-vessel species signals by name.
pub const SPECIES_VESSEL_SIGNALS: &[&str] = &[
    "po2_out",
    "saturation_out",
    "concentration_out",
    "flow_out",
    "wall_uptake",
];
/// Network species signals (vessel ""): the step's balance fluxes (mol/s).
pub const SPECIES_NETWORK_SIGNALS: &[&str] = &["inflow", "outflow", "consumption"];

/// Values and derivatives of species signals over the periodic cycle.
#[derive(Debug, Clone)]
pub struct SpeciesSensitivities {
    /// The parameters' SI values.
    pub values: Vec<f64>,
    /// Step end times of the cycle (n_steps).
    pub times: Vec<f64>,
    /// n_steps × n_signals.
    pub signals: Vec<f64>,
    /// n_params × n_steps × n_signals.
    pub derivs: Vec<f64>,
    /// Flow cycles to its periodic state, and transport cycles (with the tangents) to theirs.
    pub cycles: usize,
    pub transport_cycles: usize,
    /// The last transport cycle's relative change (amounts and tangents).
    pub periodic_change: f64,
}

#[derive(Debug, Clone, Copy)]
enum Signal {
    Vessel(usize, VesselSpeciesSignal),
    /// index into the accumulators (inflow, outflow, wall)
    Network(usize),
}

/// The species oxygen's parameters address: the one species, or the one named "o2".
fn oxygen_species(spec: &NetworkSpec) -> Result<SpeciesSpec> {
    let t = spec.transport.as_ref().ok_or_else(|| {
        Error::model(
            "sensitivities",
            format!("model '{}' has no oxygen (no transport section)", spec.name),
        )
    })?;
    match t.species.as_slice() {
        [one] => Ok(one.clone()),
        many => many
            .iter()
            .find(|s| s.name == "o2")
            .cloned()
            .ok_or_else(|| Error::model("sensitivities", "no species named 'o2' among several")),
    }
}

/// An oxygen parameter: what it changes, its SI value, and the vessel whose own wall
/// (`per_vessel`) it belongs to (None: the section's wall, on every vessel without its own,
/// or the binding).
#[derive(Debug, Clone, PartialEq)]
pub struct OxygenParameter {
    pub kind: SpeciesParameterKind,
    pub value: f64,
    pub vessel: Option<String>,
    /// d ln g/dθ of the walls whose conductance the parameter moves through their
    /// haemoglobin facilitation (`species_facilitation`): (None: the section's wall,
    /// Some(vessel): that vessel's own wall; the slope per SI unit of the parameter).
    pub ln_conductance: Vec<(Option<String>, f64)>,
}

/// An oxygen parameter path's kind, SI value and scope; None for a path outside `oxygen.`.
/// `oxygen.per_vessel.<vessel>.wall.<key>` names a vessel's own wall.
pub fn oxygen_parameter(sp: &SpeciesSpec, path: &str) -> Result<Option<OxygenParameter>> {
    let mut parts: Vec<&str> = path.split('.').collect();
    if parts.first() != Some(&"oxygen") {
        return Ok(None);
    }
    let fail = |why: String| Error::model(format!("parameter '{path}'"), why);
    let scoped = match parts.as_slice() {
        ["oxygen", "per_vessel", name, "wall", key] => Some((name.to_string(), *key)),
        _ => None,
    };
    let (wall, vessel) = match scoped {
        Some((name, key)) => {
            let w = sp
                .per_vessel
                .get(&name)
                .ok_or_else(|| fail(format!("no per-vessel wall of a vessel named '{name}'")))?;
            parts = vec!["oxygen", "wall", key];
            (w, Some(name))
        }
        None => (&sp.wall, None),
    };
    let nonzero = |v: f64| {
        if v != 0.0 && v.is_finite() {
            Ok(v)
        } else {
            Err(fail(format!(
                "the value is {v}: its derivative scales a coefficient by 1/value"
            )))
        }
    };
    let mut ln_conductance = Vec::new();
    let (kind, value) = match (parts.as_slice(), wall, &sp.binding) {
        (["oxygen", "wall", "k"], WallSpec::MassTransfer { k, .. }, _) => {
            (SpeciesParameterKind::Conductance, nonzero(*k)?)
        }
        (
            ["oxygen", "wall", key @ ("po2" | "concentration")],
            WallSpec::MassTransfer {
                wall_concentration, ..
            },
            b,
        ) => {
            let cw = nonzero(*wall_concentration)?;
            match (*key, b) {
                ("concentration", _) => (SpeciesParameterKind::WallConcentration, cw),
                (_, BindingSpec::Hill { solubility, .. }) => {
                    (SpeciesParameterKind::WallConcentration, cw / solubility)
                }
                _ => {
                    return Err(fail(
                        "a wall PO2 needs haemoglobin (hemoglobin: hill)".into(),
                    ));
                }
            }
        }
        (
            ["oxygen", "wall", "flux"],
            WallSpec::Flux {
                flux: FluxSpec::Constant(q),
            },
            _,
        ) => (SpeciesParameterKind::Flux, nonzero(*q)?),
        (
            [
                "oxygen",
                "wall",
                key @ ("concentration" | "po2" | "enhancement"),
            ],
            w @ (WallSpec::Leveque { .. } | WallSpec::Graetz { .. }),
            b,
        ) => {
            let (kind, v, slope) = boundary_layer_parameter(sp, key, w, b).map_err(fail)?;
            let scope = vessel.clone();
            ln_conductance.extend(slope.map(|a| (scope, a)));
            (kind, nonzero(v)?)
        }
        (["oxygen", "hill", "p50"], _, BindingSpec::Hill { p50, .. }) => {
            ln_conductance = facilitation::p50_slopes(sp)
                .map_err(|why| fail(format!("P50 through the haemoglobin facilitation: {why}")))?;
            (SpeciesParameterKind::P50, nonzero(*p50)?)
        }
        (["oxygen", "wall", key], w, _) => {
            return Err(fail(format!(
                "the wall ({}) has no differentiable '{key}' (mass-transfer: k, po2, \
                 concentration; flux: a constant flux)",
                wall_name(w)
            )));
        }
        (["oxygen", "hill", "p50"], _, _) => {
            return Err(fail(
                "P50 needs haemoglobin with Hill's law (hemoglobin: hill)".into(),
            ));
        }
        _ => {
            return Err(fail(
                "not an oxygen parameter (oxygen.wall.k, oxygen.wall.po2, \
                 oxygen.wall.concentration, oxygen.wall.flux, oxygen.hill.p50, or \
                 oxygen.per_vessel.<vessel>.wall.<key>)"
                    .into(),
            ));
        }
    };
    Ok(Some(OxygenParameter {
        kind,
        value,
        vessel,
        ln_conductance,
    }))
}

/// A Lévêque or Graetz wall's parameter `key`: its concentration or PO2 (g c_w ∝ it; with
/// haemoglobin facilitation g moves too, by the slope returned) or the enhancement it was
/// given (the blood side's conductance ∝ it): the kind, SI value and d ln G/dθ of the blood
/// side (a permeability in series takes its share, `Transport::add_conductance_slopes`).
fn boundary_layer_parameter(
    sp: &SpeciesSpec,
    key: &str,
    wall: &WallSpec,
    binding: &BindingSpec,
) -> std::result::Result<(SpeciesParameterKind, f64, Option<f64>), String> {
    let (WallSpec::Leveque {
        wall_concentration,
        enhancement,
        ..
    }
    | WallSpec::Graetz {
        wall_concentration,
        enhancement,
        ..
    }) = wall
    else {
        unreachable!("a boundary-layer wall");
    };
    match (key, binding) {
        ("concentration", _) => {
            let slope = facilitation::ln_conductance_slope(sp, wall, By::WallConcentration)?;
            Ok((
                SpeciesParameterKind::WallConcentration,
                *wall_concentration,
                slope,
            ))
        }
        // (behind a permeability in series g moves by its blood side's share of the change:
        // `Transport::species_derivative`)
        ("enhancement", _) => Ok((
            SpeciesParameterKind::Conductance,
            facilitation::given_enhancement(wall, *enhancement),
            None,
        )),
        (_, BindingSpec::Hill { solubility, .. }) => {
            let slope = facilitation::ln_conductance_slope(sp, wall, By::WallPo2)?;
            Ok((
                SpeciesParameterKind::WallConcentration,
                wall_concentration / solubility,
                slope,
            ))
        }
        _ => Err(
            "a wall PO2 needs haemoglobin (hemoglobin: hill); without it the wall's \
                  concentration is the parameter (oxygen.wall.concentration)"
                .into(),
        ),
    }
}

fn wall_name(w: &WallSpec) -> &'static str {
    match w {
        WallSpec::None => "none",
        WallSpec::Flux { .. } => "flux",
        WallSpec::MassTransfer { .. } => "mass-transfer",
        WallSpec::Leveque { .. } => "leveque",
        WallSpec::Graetz { .. } => "graetz",
        WallSpec::Permeability { .. } => "permeability",
    }
}

/// A parameter of the oxygen sensitivities: an oxygen parameter, or a flow parameter with
/// its path.
#[derive(Debug, Clone)]
enum Param {
    Oxygen(OxygenParameter),
    Flow(Parameter, String),
}

/// The parameters of `paths`: oxygen paths, else flow parameter paths (a path that resolves
/// to neither is an error naming it).
fn parameters(spec: &NetworkSpec, sp: &SpeciesSpec, paths: &[String]) -> Result<Vec<Param>> {
    paths
        .iter()
        .map(|path| {
            Ok(match oxygen_parameter(sp, path)? {
                Some(p) => Param::Oxygen(p),
                None => Param::Flow(Parameter::parse(spec, path)?, path.clone()),
            })
        })
        .collect()
}

/// The derivative of the DAE by each flow parameter (the oxygen parameters' entries None),
/// after the circuit is checked against what the flow tangent covers.
fn flow_tangents(
    spec: &NetworkSpec,
    assembled: &Assembled,
    dae: &Dae,
    params: &[Param],
) -> Result<Vec<Option<DaeTangent>>> {
    if params.iter().all(|p| matches!(p, Param::Oxygen(_))) {
        return Ok(vec![None; params.len()]);
    }
    let circuit = &assembled.circuit;
    parameter::check_supported(circuit, dae)?;
    let stamps = parameter::Stamps::new(circuit, dae);
    params
        .iter()
        .map(|p| match p {
            Param::Oxygen(_) => Ok(None),
            Param::Flow(par, path) => {
                let mut t = stamps.tangent(spec, par, path)?;
                // a node whose row a pressure condition took holds no capacitance
                for (node, _) in &circuit.fixed_pressures {
                    t.de[*node] = 0.0;
                }
                Ok(Some(t))
            }
        })
        .collect()
}

/// What flow parameter `p` (DAE derivative `t`) changes in the transport besides the flows:
/// a vessel's wall area and lumen volume (radius: ∝ r, r²; length: ∝ L, L), its compliances
/// (`t.de`), and the flow conditions whose waveform it scales (`t.dforcing` on their rows).
fn flow_effect<'a>(
    spec: &NetworkSpec,
    assembled: &Assembled,
    dae: &Dae,
    p: &Parameter,
    t: &'a DaeTangent,
    sources: &'a mut Vec<(usize, f64)>,
) -> FlowEffect<'a> {
    let circuit = &assembled.circuit;
    let geometry = match p {
        Parameter::Radius(vi) | Parameter::Length(vi) => {
            let name = &spec.vessels[*vi].name;
            let vessel = circuit.vessel_names.iter().position(|n| n == name);
            let k = if matches!(p, Parameter::Radius(_)) {
                2.0
            } else {
                1.0
            };
            let radius = matches!(p, Parameter::Radius(_));
            vessel.map(|vessel| FlowGeometry {
                vessel,
                area: 1.0 / t.value,
                volume: k / t.value,
                radius: if radius { 1.0 / t.value } else { 0.0 },
                length: if radius { 0.0 } else { 1.0 / t.value },
                taper: None,
            })
        }
        Parameter::EndRadius { vessel: vi, outlet } => {
            let v = &spec.vessels[*vi];
            let vessel = circuit.vessel_names.iter().position(|n| *n == v.name);
            let g = v.geometry.as_ref();
            vessel.zip(g).map(|(vessel, g)| FlowGeometry {
                vessel,
                area: 0.0,
                volume: 0.0,
                radius: 0.0,
                length: 0.0,
                taper: Some(TaperEnd {
                    radius_in: g.radius_in,
                    radius_out: g.radius_out,
                    length: g.length,
                    outlet: *outlet,
                }),
            })
        }
        _ => None,
    };
    sources.clear();
    for &(k, factor) in &t.dforcing {
        let row = dae.forcing[k].0;
        if row < circuit.nodes.len() {
            sources.push((row, factor));
        }
    }
    FlowEffect {
        geometry,
        de: &t.de,
        sources,
        mean_flows: None,
    }
}

/// The signals by (vessel, name), resolved against the probes' vessels.
fn resolve(vessels: &[String], signals: &[(String, String)]) -> Result<Vec<Signal>> {
    signals
        .iter()
        .map(|(vessel, var)| {
            let what = format!("output '{vessel}:{var}'");
            if vessel.is_empty() {
                return SPECIES_NETWORK_SIGNALS
                    .iter()
                    .position(|v| v == var)
                    .map(Signal::Network)
                    .ok_or_else(|| {
                        Error::model(
                            what.clone(),
                            format!("unknown network signal '{var}' (one of {SPECIES_NETWORK_SIGNALS:?})"),
                        )
                    });
            }
            let k = vessels.iter().position(|v| v == vessel).ok_or_else(|| {
                Error::model(what.clone(), format!("no vessel named '{vessel}'"))
            })?;
            let kind = match var.as_str() {
                "po2_out" => VesselSpeciesSignal::Po2,
                "saturation_out" => VesselSpeciesSignal::Saturation,
                "concentration_out" => VesselSpeciesSignal::Concentration,
                "flow_out" => VesselSpeciesSignal::Flow,
                "wall_uptake" => VesselSpeciesSignal::WallUptake,
                _ => {
                    return Err(Error::model(
                        what,
                        format!("unknown oxygen signal '{var}' (one of {SPECIES_VESSEL_SIGNALS:?})"),
                    ));
                }
            };
            Ok(Signal::Vessel(k, kind))
        })
        .collect()
}

/// The largest change of `b` against `a` relative to `scale` (or to |b| when larger).
fn change(a: &[f64], b: &[f64], scale: f64) -> f64 {
    let s = b.iter().fold(scale, |m, v| m.max(v.abs()));
    let d = a
        .iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    if s > 0.0 { d / s } else { d }
}

/// The flow's periodic cycle by generalized-α and its tangents by the flow parameters:
/// the flow states at the cycle's step ends (n + 1, the first the cycle's start; only the
/// `unknowns` the transport reads are set), the tangents of those unknowns
/// (n_flow_params × n_steps × unknowns, after each step), and the cycles run.
struct FlowCycle {
    ys: Vec<Vec<f64>>,
    derivs: Vec<f64>,
    nu: usize,
    cycles: usize,
    change: f64,
    /// Per flow parameter, per step (n_steps × shear-dependent pieces): d ln of the flow
    /// magnitude each shear-dependent wall law reads ([`Transport::shear_tangents`]).
    shear: Vec<Vec<f64>>,
}

impl FlowCycle {
    fn run(
        dae: &Dae,
        tangents: &[DaeTangent],
        unknowns: &[usize],
        set: &TangentSettings,
    ) -> Result<FlowCycle> {
        let ns = set.steps_per_cycle;
        let flow = periodic_tangent(dae, tangents, unknowns, *set)?;
        if flow.periodic_change > set.tol {
            return Err(Error::model(
                "sensitivities",
                format!(
                    "the flow (or its tangent) is not periodic after max_cycles = {} (last \
                     change {:.2e})",
                    set.max_cycles, flow.periodic_change
                ),
            ));
        }
        let nu = unknowns.len();
        // the periodic cycle starts where it ends
        let ys = (0..=ns)
            .map(|k| {
                let mut y = vec![0.0; dae.n];
                let at = if k == 0 { ns - 1 } else { k - 1 };
                for (&u, v) in unknowns.iter().zip(&flow.values[at * nu..(at + 1) * nu]) {
                    y[u] = *v;
                }
                y
            })
            .collect();
        Ok(FlowCycle {
            ys,
            derivs: flow.derivs,
            nu,
            cycles: flow.cycles,
            change: flow.periodic_change,
            shear: Vec::new(),
        })
    }

    /// Flow parameter `p`'s d ln of the shear-dependent laws' flows over step `k` (from the
    /// end of step k to that of k + 1, as [`FlowCycle::tangent`] counts; empty without
    /// such laws).
    fn shear(&self, p: usize, k: usize) -> &[f64] {
        let ns = self.ys.len() - 1;
        match self.shear.get(p) {
            Some(t) if !t.is_empty() => {
                let nd = t.len() / ns;
                &t[k * nd..(k + 1) * nd]
            }
            _ => &[],
        }
    }

    /// Flow parameter `p`'s tangents of the recorded unknowns at every step end (n + 1).
    fn tangents(&self, p: usize) -> Vec<&[f64]> {
        (0..self.ys.len()).map(|k| self.tangent(p, k)).collect()
    }

    /// Flow parameter `p`'s tangent of the unknowns at the end of step `k` (k = 0..n_steps;
    /// step 0's end is the cycle's start, the last step's end).
    fn tangent(&self, p: usize, k: usize) -> &[f64] {
        let ns = self.ys.len() - 1;
        let at = if k == 0 { ns - 1 } else { k - 1 };
        let o = (p * ns + at) * self.nu;
        &self.derivs[o..o + self.nu]
    }
}

/// What the oxygen tangent and adjoint share: the model (every vessel an output), its
/// oxygen species, the parameters, the assembled circuit, its DAE, the transport run and
/// the resolved signals.
struct Setup {
    spec: NetworkSpec,
    sp: SpeciesSpec,
    params: Vec<Param>,
    assembled: Assembled,
    dae: Dae,
    tr: Transport,
    s: usize,
    sigs: Vec<Signal>,
}

impl Setup {
    /// The setup of `spec`, refusing what the species tangent does not follow (an error
    /// naming the path, output or wall).
    fn new(
        spec: &NetworkSpec,
        paths: &[String],
        signals: &[(String, String)],
        settings: &TangentSettings,
    ) -> Result<Setup> {
        settings.check()?;
        let mut spec = spec.clone();
        for v in &mut spec.vessels {
            v.output = true;
        }
        let sp = oxygen_species(&spec)?;
        let params = parameters(&spec, &sp, paths)?;
        let tspec = spec.transport.clone().expect("checked by oxygen_species");
        let assembled = spec.assemble()?;
        let dae = assembled.circuit.assemble()?;
        let tr = Transport::build(&tspec, &assembled.circuit, &dae, &assembled.probes)?.new_run();
        let s = tr.species_index(&sp.name).expect("the spec's species");
        tr.check_species_tangent(s, "sensitivities")?;
        let sigs = resolve(&assembled.probes.vessels, signals)?;
        Ok(Setup {
            spec,
            sp,
            params,
            assembled,
            dae,
            tr,
            s,
            sigs,
        })
    }
}

/// d(signal)/d(parameter) over the periodic cycle of `spec` (see the module doc).
pub fn species_sensitivities(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    settings: TangentSettings,
) -> Result<SpeciesSensitivities> {
    let Setup {
        spec,
        sp,
        params,
        assembled,
        dae,
        mut tr,
        s,
        sigs,
    } = Setup::new(spec, paths, signals, &settings)?;
    let (flow, Derivatives { derivs, values, .. }) =
        flow_and_derivatives(&spec, &sp, &params, &assembled, &dae, &mut tr, s, &settings)?;
    let mut run = TransportRun::new(&mut tr, s, (derivs, values), &flow, &settings)?;
    let (transport_cycles, periodic_change, (sig_values, sig_derivs)) =
        run.run_to_periodic(&flow, &settings, signals, &sigs)?;
    let ns = settings.steps_per_cycle;
    let dt = settings.period / ns as f64;
    Ok(SpeciesSensitivities {
        values: run.values,
        times: (1..=ns).map(|k| k as f64 * dt).collect(),
        signals: sig_values,
        derivs: sig_derivs,
        cycles: flow.cycles,
        transport_cycles,
        periodic_change: periodic_change.max(flow.change),
    })
}

/// The parameters' derivatives: of the DAE by each flow parameter (in their order among
/// the parameters), of the species step by every parameter, and the parameters' SI values.
struct Derivatives {
    flow_params: Vec<DaeTangent>,
    derivs: Vec<SpeciesDerivative>,
    values: Vec<f64>,
    /// Per flow parameter: the vessel whose geometry it sets (for the shears' tangents).
    geometry: Vec<Option<FlowGeometry>>,
}

/// The flow's periodic cycle and the parameters' derivatives: the flow and its tangents by
/// the flow parameters run first; the walls whose law reads the cycle-mean flow take it
/// from that cycle (and its derivative by each flow parameter from the tangents), then
/// every parameter's derivative of the species step is taken on those laws.
#[allow(clippy::too_many_arguments)]
fn flow_and_derivatives(
    spec: &NetworkSpec,
    sp: &SpeciesSpec,
    params: &[Param],
    assembled: &Assembled,
    dae: &Dae,
    tr: &mut Transport,
    s: usize,
    settings: &TangentSettings,
) -> Result<(FlowCycle, Derivatives)> {
    let dae_tangents = flow_tangents(spec, assembled, dae, params)?;
    let flow_params: Vec<DaeTangent> = dae_tangents.iter().flatten().cloned().collect();
    let mut unknowns = tr.flow_tangent_unknowns();
    let read = unknowns.len();
    let mean_unknowns = tr.mean_flow_unknowns();
    unknowns.extend(&mean_unknowns);
    let inlets = tr.renewal_inlets();
    let inlets_from = unknowns.len();
    unknowns.extend(inlets.iter().map(|i| i.1));
    // the branch flows the shear-dependent walls read
    unknowns.extend(tr.shear_unknowns());
    let mut flow = FlowCycle::run(dae, &flow_params, &unknowns, settings)?;
    let mut means =
        (!mean_unknowns.is_empty()).then(|| CycleMeans::of(&flow, read, &mean_unknowns));
    let renewal = (!inlets.is_empty()).then(|| InletHarmonics::of(&flow, inlets_from, &inlets));
    if let Some(m) = &mut means {
        match renewal.as_ref().and_then(|r| r.primal.flows()) {
            Some(flows) => {
                m.renewal = tr.renewal_factors(&m.abs, &m.forward, settings.period, flows)?;
                tr.set_mean_flows_with_renewal(&m.abs, &m.forward, &m.renewal)?;
            }
            None => tr.set_mean_flows(&m.abs, &m.forward)?,
        }
        tr.check_species_tangent(s, "sensitivities")?;
    }
    let mut d = Derivatives::new(
        spec,
        sp,
        params,
        (assembled, dae),
        tr,
        s,
        dae_tangents,
        means
            .as_ref()
            .map(|m| (m, renewal.as_ref(), settings.period)),
    )?;
    flow.shear = (d.geometry.iter().enumerate())
        .map(|(p, g)| {
            let mean = means.as_ref().map(|m| m.tangent(p, &[]));
            let steps = (
                settings.period / settings.steps_per_cycle as f64,
                settings.alpha_f(),
            );
            let dys = flow.tangents(p);
            tr.shear_tangents(s, &flow.ys, &dys, &unknowns, steps, mean.as_ref(), *g)
        })
        .collect::<Result<_>>()?;
    d.geometry.clear();
    Ok((flow, d))
}

/// The inlet renewal's inlet flows over the flow's periodic cycle: their harmonics (as a
/// run's first pass takes them from its step ends, `run::flow_harmonics`) and, per flow
/// parameter, the harmonics of their tangents (the same sums of the tangent's samples).
struct InletHarmonics {
    primal: FlowHarmonics,
    tangents: Vec<FlowHarmonics>,
}

impl InletHarmonics {
    /// `inlets` (vessel, flow unknown) recorded in `flow` from index `from`.
    fn of(flow: &FlowCycle, from: usize, inlets: &[(usize, usize)]) -> InletHarmonics {
        let ns = flow.ys.len() - 1;
        let np = flow.derivs.len() / (ns * flow.nu).max(1);
        let mut primal = FlowHarmonics::new(inlets.to_vec());
        primal.start_cycle(ns);
        for y in &flow.ys[1..] {
            primal.accumulate(y);
        }
        primal.end_cycle();
        let in_record: Vec<(usize, usize)> = (inlets.iter().enumerate())
            .map(|(i, &(v, _))| (v, from + i))
            .collect();
        let tangents = (0..np)
            .map(|p| {
                let mut h = FlowHarmonics::new(in_record.clone());
                h.start_cycle(ns);
                for k in 1..=ns {
                    h.accumulate(flow.tangent(p, k));
                }
                h.end_cycle();
                h
            })
            .collect();
        InletHarmonics { primal, tangents }
    }
}

/// The segments' cycle means over the flow's periodic cycle (of its step ends, as a run's
/// first pass takes them: `run::mean_flow`) of |Q| and of the forward flow ⟨max(±Q, 0)⟩ =
/// (⟨|Q|⟩ + |⟨Q⟩|)/2 (⟨|Q|⟩ itself without reversal), and their derivatives by each flow
/// parameter (sign(Q) Q′ averaged; per flow parameter, per segment).
struct CycleMeans {
    abs: Vec<f64>,
    forward: Vec<f64>,
    d_abs: Vec<Vec<f64>>,
    d_forward: Vec<Vec<f64>>,
    /// Per species, per segment: the inlet renewal's factors (empty without renewal).
    renewal: Vec<Vec<f64>>,
}

impl CycleMeans {
    /// `unknowns` the segments' flow unknowns, recorded in `flow` from index `from`.
    fn of(flow: &FlowCycle, from: usize, unknowns: &[usize]) -> CycleMeans {
        let ns = flow.ys.len() - 1;
        let np = flow.derivs.len() / (ns * flow.nu).max(1);
        let n = unknowns.len();
        let (mut abs, mut signed) = (vec![0.0; n], vec![0.0; n]);
        let (mut d_abs, mut d_signed) = (vec![vec![0.0; n]; np], vec![vec![0.0; n]; np]);
        for k in 1..=ns {
            let y = &flow.ys[k];
            for (j, &u) in unknowns.iter().enumerate() {
                let sign = if y[u] < 0.0 { -1.0 } else { 1.0 };
                abs[j] += y[u].abs() / ns as f64;
                signed[j] += y[u] / ns as f64;
                for p in 0..np {
                    let dy = flow.tangent(p, k)[from + j];
                    d_abs[p][j] += sign * dy / ns as f64;
                    d_signed[p][j] += dy / ns as f64;
                }
            }
        }
        let forward = |a: f64, s: f64| if a == s.abs() { a } else { 0.5 * (a + s.abs()) };
        let d_forward = (d_abs.iter().zip(&d_signed))
            .map(|(da, ds)| {
                (0..n)
                    .map(|j| {
                        let (a, s) = (abs[j], signed[j]);
                        if a == s.abs() {
                            da[j]
                        } else {
                            0.5 * (da[j] + s.signum() * ds[j])
                        }
                    })
                    .collect()
            })
            .collect();
        CycleMeans {
            forward: abs
                .iter()
                .zip(&signed)
                .map(|(a, s)| forward(*a, *s))
                .collect(),
            abs,
            d_abs,
            d_forward,
            renewal: Vec::new(),
        }
    }

    /// The means and their derivatives by flow parameter `p` (with the renewal factors,
    /// their tangent `d_ln_renewal`).
    fn tangent<'a>(&'a self, p: usize, d_ln_renewal: &'a [Vec<f64>]) -> MeanFlowTangent<'a> {
        MeanFlowTangent {
            abs: &self.abs,
            forward: &self.forward,
            d_abs: &self.d_abs[p],
            d_forward: &self.d_forward[p],
            renewal: &self.renewal,
            d_ln_renewal,
        }
    }
}

impl Derivatives {
    #[allow(clippy::too_many_arguments)]
    fn new(
        spec: &NetworkSpec,
        sp: &SpeciesSpec,
        params: &[Param],
        (assembled, dae): (&Assembled, &Dae),
        tr: &Transport,
        s: usize,
        dae_tangents: Vec<Option<DaeTangent>>,
        means: Option<(&CycleMeans, Option<&InletHarmonics>, f64)>,
    ) -> Result<Derivatives> {
        let names = &assembled.circuit.vessel_names;
        let mut derivs = Vec::with_capacity(params.len());
        let mut sources = Vec::new();
        let mut geometry = Vec::new();
        let mut next_flow = 0;
        for (p, t) in params.iter().zip(&dae_tangents) {
            derivs.push(match (p, t) {
                (Param::Flow(par, _), Some(t)) => {
                    let mut e = flow_effect(spec, assembled, dae, par, t, &mut sources);
                    let d_ln_renewal = means
                        .map(|m| renewal_tangent(tr, m, next_flow, e.geometry))
                        .unwrap_or_default();
                    e.mean_flows = means.map(|m| m.0.tangent(next_flow, &d_ln_renewal));
                    geometry.push(e.geometry);
                    next_flow += 1;
                    tr.species_flow_derivative(s, &e)
                }
                (Param::Oxygen(o), _) => {
                    let mut d = tr.species_derivative(s, o.kind, o.value, &on(o, sp, names));
                    if !o.ln_conductance.is_empty() {
                        let slopes = facilitation::per_vessel_slopes(&o.ln_conductance, sp, names);
                        tr.add_conductance_slopes(s, &mut d, &slopes);
                    }
                    d
                }
                (Param::Flow(..), None) => unreachable!("every flow parameter has its tangent"),
            });
        }
        let values = (params.iter().zip(&dae_tangents))
            .map(|(p, t)| match (p, t) {
                (Param::Oxygen(o), _) => o.value,
                (_, t) => t.as_ref().map_or(f64::NAN, |t| t.value),
            })
            .collect();
        Ok(Derivatives {
            flow_params: dae_tangents.into_iter().flatten().collect(),
            derivs,
            values,
            geometry,
        })
    }
}

/// Per species, per segment: d ln(inlet renewal factor) by flow parameter `p` (empty
/// without the renewal's harmonics).
fn renewal_tangent(
    tr: &Transport,
    (means, harmonics, period): (&CycleMeans, Option<&InletHarmonics>, f64),
    p: usize,
    geometry: Option<FlowGeometry>,
) -> Vec<Vec<f64>> {
    let Some(h) = harmonics else {
        return Vec::new();
    };
    match (h.primal.flows(), h.tangents[p].flows()) {
        (Some(flows), Some(dflows)) if !means.renewal.is_empty() => {
            tr.renewal_factor_tangents(means.tangent(p, &[]), period, flows, dflows, geometry)
        }
        _ => Vec::new(),
    }
}

/// Per parameter: its index among the flow parameters (None: an oxygen parameter).
fn flow_indices(derivs: &[SpeciesDerivative]) -> Vec<Option<usize>> {
    let mut next = 0;
    (derivs.iter())
        .map(|d| {
            (d.kind == SpeciesParameterKind::Flow).then(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}

/// The vessels (by circuit index) whose wall oxygen parameter `p` is: its own vessel's, or
/// the section's on every vessel without a wall of its own.
fn on(p: &OxygenParameter, sp: &SpeciesSpec, vessel_names: &[String]) -> Vec<bool> {
    vessel_names
        .iter()
        .map(|v| match &p.vessel {
            Some(own) => own == v,
            None => !sp.per_vessel.contains_key(v),
        })
        .collect()
}

/// At most this many cycles past the tolerance while the tangents still settle
/// ([`still_settling`]); their change falls by ~4× a cycle on the test networks.
const SETTLING_CYCLES: usize = 8;

/// Whether the transport's tangents, their change `last` under the tolerance after
/// `before` the cycle before, are still settling (and `settling` cycles past the tolerance
/// leave room for one more): while the change still falls by half a cycle. The tolerance is
/// relative to the largest amount, so a tangent that meets it still changes the stored
/// oxygen by ~tol of that amount per cycle, and the network's fluxes over the cycle (its
/// inflow, outflow and consumption) read that change as flux. With haemoglobin the amount
/// is mostly bound oxygen, ~100× the free, while a parameter that barely moves the exchange
/// (a taper's end radius under a boundary-layer wall) moves the mean outflow by ~1e-7 of
/// itself: stopping at the tolerance left that derivative up to 1.3e-6 off the exactly
/// periodic one (the adjoint's); going on to the rounding floor takes it to ≤ 1e-7.
fn still_settling(before: f64, last: f64, settling: usize) -> bool {
    settling < SETTLING_CYCLES && last < 0.5 * before
}

/// One cycle's signals (n_steps × n_signals) and their derivatives (n_params × n_steps ×
/// n_signals).
type Cycle = (Vec<f64>, Vec<f64>);

/// The transport's run with its tangents over a recorded flow cycle.
struct TransportRun<'t> {
    tr: &'t mut Transport,
    s: usize,
    z: Vec<f64>,
    derivs: Vec<SpeciesDerivative>,
    tangents: Vec<SpeciesTangent>,
    values: Vec<f64>,
    /// Per parameter: its index among the flow parameters (None: an oxygen parameter).
    flow_index: Vec<Option<usize>>,
    anchors: Vec<HillAnchor>,
}

impl<'t> TransportRun<'t> {
    fn new(
        tr: &'t mut Transport,
        s: usize,
        (derivs, values): (Vec<SpeciesDerivative>, Vec<f64>),
        flow: &FlowCycle,
        set: &TangentSettings,
    ) -> Result<Self> {
        let y0 = &flow.ys[0];
        let mut z = tr.initial_state(y0)?;
        let dt = set.period / set.steps_per_cycle as f64;
        tr.set_periodic_relaxed_shears(&flow.ys, dt, set.alpha_f(), &mut z);
        let flow_index = flow_indices(&derivs);
        let tangents = (derivs.iter().zip(&flow_index))
            .map(|(d, f)| match f {
                Some(p) => tr.species_flow_tangent_start(s, d, y0, flow.tangent(*p, 0), &z),
                None => tr.species_tangent_start(),
            })
            .collect();
        Ok(TransportRun {
            tr,
            s,
            z,
            derivs,
            tangents,
            values,
            flow_index,
            anchors: Vec::new(),
        })
    }

    /// Cycles over the recorded flow until the amounts and tangents repeat to the
    /// tolerance; the cycles, the last change and the last cycle's signals (values
    /// n_steps × n_signals, derivatives n_params × n_steps × n_signals).
    fn run_to_periodic(
        &mut self,
        flow: &FlowCycle,
        set: &TangentSettings,
        names: &[(String, String)],
        sigs: &[Signal],
    ) -> Result<(usize, f64, Cycle)> {
        let (nc, s) = (self.tr.n_cells(), self.s);
        let mut last = f64::INFINITY;
        let mut settling = 0;
        for cycle in 1..=set.max_cycles {
            let z0 = self.z[s * nc..(s + 1) * nc].to_vec();
            let dz0: Vec<Vec<f64>> = self.tangents.iter().map(|t| t.dz.clone()).collect();
            let rec = self.cycle(flow, set, names, sigs)?;
            let z1 = &self.z[s * nc..(s + 1) * nc];
            let scale = z1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let before = last;
            last = change(&z0, z1, 0.0);
            for ((t, d0), p) in self.tangents.iter().zip(&dz0).zip(&self.values) {
                let a: Vec<f64> = d0.iter().map(|x| x * p.abs()).collect();
                let b: Vec<f64> = t.dz.iter().map(|x| x * p.abs()).collect();
                last = last.max(change(&a, &b, scale));
            }
            if last <= set.tol {
                if !still_settling(before, last, settling) || cycle == set.max_cycles {
                    return Ok((cycle, last, rec));
                }
                settling += 1;
            }
        }
        Err(Error::model(
            "sensitivities",
            format!(
                "the oxygen field (or its tangent) is not periodic after max_cycles = {} \
                 (last change {last:.2e})",
                set.max_cycles
            ),
        ))
    }

    /// One cycle of the transport and its tangents, recording the signals.
    fn cycle(
        &mut self,
        flow: &FlowCycle,
        set: &TangentSettings,
        names: &[(String, String)],
        sigs: &[Signal],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let ns = set.steps_per_cycle;
        let dt = set.period / ns as f64;
        let af = set.alpha_f();
        let (np, nsig) = (self.tangents.len(), sigs.len());
        let (nc, s) = (self.tr.n_cells(), self.s);
        let nsp = self.tr.species_names().len();
        let acc = nsp * nc + 4 * s;
        let any_flow = self.flow_index.iter().any(Option::is_some);
        let mut values = vec![0.0; ns * nsig];
        let mut derivs = vec![0.0; np * ns * nsig];
        for k in 0..ns {
            let t = k as f64 * dt;
            let z_old = self.z.clone();
            let w_old = self.tr.cell_volumes().to_vec();
            let x_old = if any_flow {
                self.tr.species_node_values(s, &self.z)
            } else {
                Vec::new()
            };
            let dacc_old: Vec<[f64; 4]> = self.tangents.iter().map(|t| t.dacc).collect();
            let (y0, y1) = (&flow.ys[k], &flow.ys[k + 1]);
            self.tr.implicit_step(t, dt, af, y0, y1, &mut self.z)?;
            let steps: Vec<Option<FlowStep<'_>>> = (self.flow_index.iter())
                .map(|f| {
                    f.map(|p| FlowStep {
                        start: flow.tangent(p, k),
                        end: flow.tangent(p, k + 1),
                        alpha_f: af,
                        shear: flow.shear(p, k),
                    })
                })
                .collect();
            if !self.tangents.is_empty() {
                self.tr.species_tangent_step(
                    s,
                    t + af * dt,
                    dt,
                    &z_old,
                    &w_old,
                    &self.z,
                    &self.derivs,
                    &steps,
                    &x_old,
                    &mut self.tangents,
                    &mut self.anchors,
                )?;
            }
            let shears: Vec<&[f64]> = (self.flow_index.iter())
                .map(|f| f.map_or(&[][..], |p| flow.shear(p, k)))
                .collect();
            for (j, sig) in sigs.iter().enumerate() {
                let (v, d) = match *sig {
                    Signal::Network(a) => (
                        (self.z[acc + a] - z_old[acc + a]) / dt,
                        self.tangents
                            .iter()
                            .zip(&dacc_old)
                            .map(|(t, d0)| (t.dacc[a] - d0[a]) / dt)
                            .collect(),
                    ),
                    Signal::Vessel(v, kind) => self.tr.species_vessel_signal(
                        s,
                        v,
                        &names[j].0,
                        kind,
                        &self.z,
                        &self.derivs,
                        (&self.tangents[..], &shears[..]),
                    )?,
                };
                values[k * nsig + j] = v;
                for (p, dp) in d.iter().enumerate() {
                    derivs[(p * ns + k) * nsig + j] = *dp;
                }
            }
        }
        Ok((values, derivs))
    }
}

#[path = "species_facilitation.rs"]
mod facilitation;

#[path = "species_adjoint.rs"]
mod adjoint;
pub use adjoint::{SpeciesAdjoint, species_adjoint_with};

#[cfg(test)]
#[path = "species_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "species_wall_tests.rs"]
mod wall_tests;

#[cfg(test)]
#[path = "species_renewal_tests.rs"]
mod renewal_tests;

#[cfg(test)]
#[path = "species_facilitation_tests.rs"]
mod facilitation_tests;

#[cfg(test)]
#[path = "species_loop_tests.rs"]
mod loop_tests;
