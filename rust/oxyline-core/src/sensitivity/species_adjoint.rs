//! The adjoint of the oxygen signals by oxygen parameters at the periodic state: one
//! backward sweep per functional J = Σ_k Σ_j w_kj · signal_j(step k) gives its derivative
//! by every oxygen parameter at once (`transport/adjoint.rs` transposes each step). The
//! flow runs to its periodic state, the transport to its own over that cycle; one more
//! cycle is recorded (each step's flows, volumes and binding), then the adjoint runs that
//! cycle backwards until its state at the cycle's start repeats (the periodic fixed point
//! of the transposed cycle), and the gradient is that last backward cycle's.

use super::*;
use crate::transport::tangent::{
    AdjointSums, SignalRow, SpeciesAdjointState, SpeciesDerivative, SpeciesStepRecord,
};

/// The result of [`species_adjoint_with`].
#[derive(Debug, Clone)]
pub struct SpeciesAdjoint {
    /// J_f over the periodic cycle.
    pub functionals: Vec<f64>,
    /// dJ_f/dθ_p, n_functionals × n_params.
    pub gradients: Vec<f64>,
    /// The flow's cycles to its periodic state, the transport's (and the recorded one).
    pub cycles: usize,
    pub transport_cycles: usize,
    /// Backward cycles per functional.
    pub adjoint_cycles: Vec<usize>,
    /// The transport's last relative change (the flow's if larger).
    pub periodic_change: f64,
}

/// The recorded periodic cycle: every step's primal, the linearised vessel signals (None
/// for a network signal) and the signals' values (n_steps × n_signals).
struct Recorded {
    steps: Vec<SpeciesStepRecord>,
    rows: Vec<Option<SignalRow>>,
    values: Vec<f64>,
}

/// The gradients of functionals of the oxygen signals by the oxygen parameters `paths`:
/// `weights_of(times, values)` gets the step end times and the signals (n_steps ×
/// n_signals) of the recorded periodic cycle and returns the weights, flat n_functionals ×
/// n_steps × n_signals. The parameters' SI values and the result; an error naming a flow
/// parameter (forward tangents only), or what the species adjoint does not follow.
pub fn species_adjoint_with<W>(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    weights_of: W,
    settings: TangentSettings,
) -> Result<(Vec<f64>, SpeciesAdjoint)>
where
    W: FnOnce(&[f64], &[f64]) -> Result<Vec<f64>>,
{
    let Setup {
        sp,
        params,
        assembled,
        dae,
        mut tr,
        s,
        sigs,
        ..
    } = Setup::new(spec, paths, signals, &settings)?;
    let names = &assembled.circuit.vessel_names;
    let mut derivs = Vec::with_capacity(params.len());
    for p in &params {
        match p {
            Param::Oxygen(o) => {
                derivs.push(tr.species_derivative(s, o.kind, o.value, &on(o, &sp, names)))
            }
            Param::Flow(_, path) => {
                return Err(Error::model(
                    format!("parameter '{path}'"),
                    "the oxygen adjoint does not follow flow parameters yet (their oxygen \
                     derivatives have forward tangents: mode='forward')",
                ));
            }
        }
    }
    tr.check_species_adjoint(s, "sensitivities")?;
    let flow = FlowCycle::run(&dae, &[], &tr.flow_tangent_unknowns(), &settings)?;
    let (transport_cycles, change_z, mut z) = primal_to_periodic(&mut tr, s, &flow, &settings)?;
    let rec = record(
        &mut tr, s, &flow, &settings, signals, &sigs, &derivs, &mut z,
    )?;
    let ns = settings.steps_per_cycle;
    let dt = settings.period / ns as f64;
    let times: Vec<f64> = (1..=ns).map(|k| k as f64 * dt).collect();
    let weights = weights_of(&times, &rec.values)?;
    let per = ns * sigs.len();
    if per == 0 || weights.len() % per != 0 {
        return Err(Error::model(
            "adjoint",
            format!(
                "{} weights for {ns} steps × {} signals: expected a multiple of {per}",
                weights.len(),
                sigs.len()
            ),
        ));
    }
    let nf = weights.len() / per;
    let mut out = SpeciesAdjoint {
        functionals: Vec::with_capacity(nf),
        gradients: Vec::with_capacity(nf * derivs.len()),
        cycles: flow.cycles,
        transport_cycles: transport_cycles + 1,
        adjoint_cycles: Vec::with_capacity(nf),
        periodic_change: change_z.max(flow.change),
    };
    for w in weights.chunks(per) {
        let j: f64 = w.iter().zip(&rec.values).map(|(a, b)| a * b).sum();
        let (cycles, grad) = backward(&mut tr, s, dt, &rec, &sigs, &derivs, w, &settings)?;
        out.functionals.push(j);
        out.gradients.extend(grad);
        out.adjoint_cycles.push(cycles);
    }
    let values = derivs
        .iter()
        .zip(&params)
        .map(|(_, p)| match p {
            Param::Oxygen(o) => o.value,
            Param::Flow(..) => f64::NAN,
        })
        .collect();
    Ok((values, out))
}

/// The transport over the flow's periodic cycle until its amounts repeat to the tolerance:
/// the cycles, the last change and the state.
fn primal_to_periodic(
    tr: &mut Transport,
    s: usize,
    flow: &FlowCycle,
    set: &TangentSettings,
) -> Result<(usize, f64, Vec<f64>)> {
    let (ns, nc) = (set.steps_per_cycle, tr.n_cells());
    let dt = set.period / ns as f64;
    let mut z = tr.initial_state(&flow.ys[0])?;
    let mut last = f64::INFINITY;
    for cycle in 1..=set.max_cycles {
        let z0 = z[s * nc..(s + 1) * nc].to_vec();
        for k in 0..ns {
            let (y0, y1) = (&flow.ys[k], &flow.ys[k + 1]);
            tr.implicit_step(k as f64 * dt, dt, set.alpha_f(), y0, y1, &mut z)?;
        }
        last = change(&z0, &z[s * nc..(s + 1) * nc], 0.0);
        if last <= set.tol {
            return Ok((cycle, last, z));
        }
    }
    Err(Error::model(
        "sensitivities",
        format!(
            "the oxygen field is not periodic after max_cycles = {} (last change {last:.2e})",
            set.max_cycles
        ),
    ))
}

/// One more periodic cycle, recorded for the adjoint.
#[allow(clippy::too_many_arguments)]
fn record(
    tr: &mut Transport,
    s: usize,
    flow: &FlowCycle,
    set: &TangentSettings,
    names: &[(String, String)],
    sigs: &[Signal],
    derivs: &[SpeciesDerivative],
    z: &mut [f64],
) -> Result<Recorded> {
    let (ns, nsig, nc) = (set.steps_per_cycle, sigs.len(), tr.n_cells());
    let dt = set.period / ns as f64;
    let af = set.alpha_f();
    let acc = tr.species_names().len() * nc + 4 * s;
    let mut rec = Recorded {
        steps: Vec::with_capacity(ns),
        rows: Vec::with_capacity(ns * nsig),
        values: vec![0.0; ns * nsig],
    };
    for k in 0..ns {
        let t = k as f64 * dt;
        let z_old = z.to_vec();
        let w_old = tr.cell_volumes().to_vec();
        tr.implicit_step(t, dt, af, &flow.ys[k], &flow.ys[k + 1], z)?;
        rec.steps
            .push(tr.species_step_record(s, t + af * dt, &z_old, &w_old, z));
        for (j, sig) in sigs.iter().enumerate() {
            let row = match *sig {
                Signal::Network(a) => {
                    rec.values[k * nsig + j] = (z[acc + a] - z_old[acc + a]) / dt;
                    None
                }
                Signal::Vessel(v, kind) => {
                    let r = tr.species_signal_row(s, v, &names[j].0, kind, z, derivs)?;
                    rec.values[k * nsig + j] = r.value;
                    Some(r)
                }
            };
            rec.rows.push(row);
        }
    }
    Ok(rec)
}

/// The backward cycles of one functional (weights `w`, n_steps × n_signals) until the
/// adjoint's state at the cycle's start repeats: the cycles and the gradient.
#[allow(clippy::too_many_arguments)]
fn backward(
    tr: &mut Transport,
    s: usize,
    dt: f64,
    rec: &Recorded,
    sigs: &[Signal],
    derivs: &[SpeciesDerivative],
    w: &[f64],
    set: &TangentSettings,
) -> Result<(usize, Vec<f64>)> {
    let (ns, nsig, nc) = (set.steps_per_cycle, sigs.len(), tr.n_cells());
    let mut lam: SpeciesAdjointState = tr.species_adjoint_start();
    let nn = lam.xt.len();
    let mut seed = vec![0.0; nn];
    let mut last = f64::INFINITY;
    for cycle in 1..=set.max_cycles {
        let (dz0, xt0) = (lam.dz.clone(), lam.xt.clone());
        let mut sums = AdjointSums::new(nc);
        // the signals' direct terms (a P50 in PO2 and saturation, a wall's own uptake)
        let mut direct = vec![0.0; derivs.len()];
        for k in (0..ns).rev() {
            seed.iter_mut().for_each(|x| *x = 0.0);
            let mut net = [0.0; 3];
            for (j, sig) in sigs.iter().enumerate() {
                let wk = w[k * nsig + j];
                if wk == 0.0 {
                    continue;
                }
                match (sig, &rec.rows[k * nsig + j]) {
                    (Signal::Network(a), _) => net[*a] += wk,
                    (_, Some(row)) => {
                        for &(n, c) in &row.nodes {
                            seed[n] += wk * c;
                        }
                        for (d, r) in direct.iter_mut().zip(&row.direct) {
                            *d += wk * r;
                        }
                    }
                    (_, None) => unreachable!("a vessel signal has its row"),
                }
            }
            tr.species_adjoint_step(s, dt, &rec.steps[k], &seed, net, &mut lam, &mut sums);
        }
        last = change(&dz0, &lam.dz, 0.0).max(change(&xt0, &lam.xt, 0.0));
        if last <= set.tol {
            let grad = derivs
                .iter()
                .zip(&direct)
                .map(|(d, r)| sums.gradient(d) + r)
                .collect();
            return Ok((cycle, grad));
        }
    }
    Err(Error::model(
        "sensitivities",
        format!(
            "the oxygen adjoint is not periodic after max_cycles = {} (last change {last:.2e})",
            set.max_cycles
        ),
    ))
}

#[cfg(test)]
#[path = "species_adjoint_tests.rs"]
mod tests;
