//! Exact sensitivities of the oxygen outputs by the oxygen parameters at the periodic state:
//! the flow runs to its periodic state by generalized-α (oxygen parameters do not change
//! it), then the species transport and its tangents ([`crate::transport::tangent`]) repeat
//! that cycle's recorded flow until both the amounts and every tangent are periodic.
//!
//! Parameters (SI values): `oxygen.wall.k` (mass-transfer coefficient, m/s),
//! `oxygen.wall.po2` (its wall PO2, Pa), `oxygen.wall.concentration` (mol/m³),
//! `oxygen.wall.flux` (a constant prescribed wall flux, mol m⁻² s⁻¹: consumption) and
//! `oxygen.hill.p50` (Pa). Signals: per vessel `po2_out`, `saturation_out`,
//! `concentration_out`, `flow_out`, `wall_uptake`; for the whole network (vessel "") the
//! step's `inflow`, `outflow` and `consumption` (mol/s, the balance's own fluxes).

use super::parameter::Parameter;
use super::tangent::TangentSettings;
use crate::circuit::{Dae, Regime};
use crate::closure::{FluxSpec, WallSpec};
use crate::error::{Error, Result};
use crate::hemoglobin::{BindingSpec, HillAnchor};
use crate::integrate::{GenAlpha, NewtonControl};
use crate::model::NetworkSpec;
use crate::transport::tangent::{
    SpeciesDerivative, SpeciesParameterKind, SpeciesTangent, VesselSpeciesSignal,
};
use crate::transport::{SpeciesSpec, Transport};

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
    let (kind, value) = match (parts.as_slice(), wall, &sp.binding) {
        (
            ["oxygen", "wall", "k"],
            WallSpec::MassTransfer {
                k,
                permeability: None,
                ..
            },
            _,
        ) => (SpeciesParameterKind::Conductance, nonzero(*k)?),
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
        (["oxygen", "hill", "p50"], w, BindingSpec::Hill { p50, .. }) => {
            let facilitated = matches!(w, WallSpec::Leveque { .. } | WallSpec::Graetz { .. });
            if facilitated
                || sp
                    .per_vessel
                    .values()
                    .any(|w| matches!(w, WallSpec::Leveque { .. } | WallSpec::Graetz { .. }))
            {
                return Err(fail(
                    "P50 with a Lévêque or Graetz wall (its haemoglobin facilitation reads \
                     the Hill law) is not differentiated yet"
                        .into(),
                ));
            }
            (SpeciesParameterKind::P50, nonzero(*p50)?)
        }
        (["oxygen", "wall", key], w, _) => {
            return Err(fail(format!(
                "the wall ({}) has no differentiable '{key}' (mass-transfer: k, po2, \
                 concentration without permeability; flux: a constant flux)",
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
    }))
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

/// The oxygen parameters of `paths`; a flow parameter is refused by name (the oxygen
/// outputs' derivative by the flow is not chained yet), a path that resolves to nothing too.
fn parameters(
    spec: &NetworkSpec,
    sp: &SpeciesSpec,
    paths: &[String],
) -> Result<Vec<OxygenParameter>> {
    let mut out = Vec::with_capacity(paths.len());
    for path in paths {
        match oxygen_parameter(sp, path)? {
            Some(p) => out.push(p),
            None => {
                Parameter::parse(spec, path)?;
                return Err(Error::model(
                    format!("parameter '{path}'"),
                    "a flow parameter: the derivative of oxygen outputs by flow parameters \
                     (through the velocities) is not available yet; ask for flow outputs or \
                     oxygen parameters",
                ));
            }
        }
    }
    Ok(out)
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

/// The flow's periodic cycle by generalized-α: the states at the cycle's step ends (n + 1,
/// the first the cycle's start), the cycles run and the method's α_f.
fn periodic_flow(dae: &Dae, set: &TangentSettings) -> Result<(Vec<Vec<f64>>, usize, f64)> {
    let ns = set.steps_per_cycle;
    let dt = set.period / ns as f64;
    let control = NewtonControl::default();
    let mut ig = GenAlpha::new(dae, Regime::Transient, dt, set.rho_infty, control)?;
    let mut y = dae.initial_state();
    let mut yd = vec![0.0; dae.n];
    let k = dae.n_nodes.min(dae.n);
    for cycle in 1..=set.max_cycles {
        let mut rec = Vec::with_capacity(ns + 1);
        rec.push(y.clone());
        for step in 0..ns {
            ig.step(step as f64 * dt, &mut y, &mut yd)?;
            rec.push(y.clone());
        }
        let c = change(&rec[0][..k], &y[..k], 0.0).max(change(&rec[0][k..], &y[k..], 0.0));
        if c <= set.tol {
            return Ok((rec, cycle, ig.alpha_f()));
        }
    }
    Err(Error::model(
        "sensitivities",
        format!(
            "the flow is not periodic after max_cycles = {}",
            set.max_cycles
        ),
    ))
}

/// d(signal)/d(oxygen parameter) over the periodic cycle of `spec` (see the module doc).
pub fn species_sensitivities(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    settings: TangentSettings,
) -> Result<SpeciesSensitivities> {
    settings.check()?;
    let mut spec = spec.clone();
    for v in &mut spec.vessels {
        v.output = true;
    }
    let sp = oxygen_species(&spec)?;
    let params = parameters(&spec, &sp, paths)?;
    let tspec = spec.transport.clone().expect("checked by oxygen_species");
    if std::iter::once(&sp.wall)
        .chain(sp.per_vessel.values())
        .any(WallSpec::needs_mean_flow)
    {
        return Err(Error::model(
            "sensitivities",
            "oxygen sensitivities with a wall that reads the cycle-mean flow (Graetz) are not \
             available yet",
        ));
    }
    let assembled = spec.assemble()?;
    let dae = assembled.circuit.assemble()?;
    let mut tr = Transport::build(&tspec, &assembled.circuit, &dae, &assembled.probes)?.new_run();
    let s = tr.species_index(&sp.name).expect("the spec's species");
    tr.check_species_tangent(s, "sensitivities")?;
    let sigs = resolve(&assembled.probes.vessels, signals)?;
    let (ys, cycles, af) = periodic_flow(&dae, &settings)?;
    let names = &assembled.circuit.vessel_names;
    let mut run = TransportRun::new(&mut tr, s, &params, &sp, names, &ys[0])?;
    let (transport_cycles, periodic_change, (sig_values, sig_derivs)) =
        run.run_to_periodic(&ys, af, &settings, signals, &sigs)?;
    let ns = settings.steps_per_cycle;
    let dt = settings.period / ns as f64;
    Ok(SpeciesSensitivities {
        values: params.iter().map(|p| p.value).collect(),
        times: (1..=ns).map(|k| k as f64 * dt).collect(),
        signals: sig_values,
        derivs: sig_derivs,
        cycles,
        transport_cycles,
        periodic_change,
    })
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
    anchors: Vec<HillAnchor>,
}

impl<'t> TransportRun<'t> {
    fn new(
        tr: &'t mut Transport,
        s: usize,
        params: &[OxygenParameter],
        sp: &SpeciesSpec,
        vessel_names: &[String],
        y0: &[f64],
    ) -> Result<Self> {
        let z = tr.initial_state(y0)?;
        // the vessels each parameter's wall is on
        let on = |p: &OxygenParameter| -> Vec<bool> {
            vessel_names
                .iter()
                .map(|v| match &p.vessel {
                    Some(own) => own == v,
                    None => !sp.per_vessel.contains_key(v),
                })
                .collect()
        };
        let derivs = params
            .iter()
            .map(|p| tr.species_derivative(s, p.kind, p.value, &on(p)))
            .collect();
        let tangents = vec![tr.species_tangent_start(); params.len()];
        Ok(TransportRun {
            tr,
            s,
            z,
            derivs,
            tangents,
            values: params.iter().map(|p| p.value).collect(),
            anchors: Vec::new(),
        })
    }

    /// Cycles over the recorded flow `ys` until the amounts and tangents repeat to the
    /// tolerance; the cycles, the last change and the last cycle's signals (values
    /// n_steps × n_signals, derivatives n_params × n_steps × n_signals).
    fn run_to_periodic(
        &mut self,
        ys: &[Vec<f64>],
        af: f64,
        set: &TangentSettings,
        names: &[(String, String)],
        sigs: &[Signal],
    ) -> Result<(usize, f64, Cycle)> {
        let (nc, s) = (self.tr.n_cells(), self.s);
        let mut last = f64::INFINITY;
        for cycle in 1..=set.max_cycles {
            let z0 = self.z[s * nc..(s + 1) * nc].to_vec();
            let dz0: Vec<Vec<f64>> = self.tangents.iter().map(|t| t.dz.clone()).collect();
            let rec = self.cycle(ys, af, set, names, sigs)?;
            let z1 = &self.z[s * nc..(s + 1) * nc];
            let scale = z1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            last = change(&z0, z1, 0.0);
            for ((t, d0), p) in self.tangents.iter().zip(&dz0).zip(&self.values) {
                let a: Vec<f64> = d0.iter().map(|x| x * p.abs()).collect();
                let b: Vec<f64> = t.dz.iter().map(|x| x * p.abs()).collect();
                last = last.max(change(&a, &b, scale));
            }
            if last <= set.tol {
                return Ok((cycle, last, rec));
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
        ys: &[Vec<f64>],
        af: f64,
        set: &TangentSettings,
        names: &[(String, String)],
        sigs: &[Signal],
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let ns = set.steps_per_cycle;
        let dt = set.period / ns as f64;
        let (np, nsig) = (self.tangents.len(), sigs.len());
        let (nc, s) = (self.tr.n_cells(), self.s);
        let nsp = self.tr.species_names().len();
        let acc = nsp * nc + 4 * s;
        let mut values = vec![0.0; ns * nsig];
        let mut derivs = vec![0.0; np * ns * nsig];
        for k in 0..ns {
            let t = k as f64 * dt;
            let z_old = self.z.clone();
            let w_old = self.tr.cell_volumes().to_vec();
            let dacc_old: Vec<[f64; 4]> = self.tangents.iter().map(|t| t.dacc).collect();
            self.tr
                .implicit_step(t, dt, af, &ys[k], &ys[k + 1], &mut self.z)?;
            if !self.tangents.is_empty() {
                self.tr.species_tangent_step(
                    s,
                    t + af * dt,
                    dt,
                    &z_old,
                    &w_old,
                    &self.z,
                    &self.derivs,
                    &mut self.tangents,
                    &mut self.anchors,
                )?;
            }
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
                        &self.tangents,
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

#[cfg(test)]
#[path = "species_tests.rs"]
mod tests;
