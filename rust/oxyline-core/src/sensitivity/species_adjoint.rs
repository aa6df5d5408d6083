//! The adjoint of the oxygen signals at the periodic state: one backward sweep per
//! functional J = Σ_k Σ_j w_kj · signal_j(step k) gives its derivative by every parameter
//! at once (`transport/adjoint.rs` transposes each step). The flow and its tangents by the
//! flow parameters run to their periodic state (one more solve per flow parameter and step
//! on the flow's own factorisation), the transport to its own over that cycle; one more
//! cycle is recorded (each step's flows, volumes and binding), then the adjoint runs that
//! cycle backwards until its state at the cycle's start repeats (the periodic fixed point
//! of the transposed cycle), and the gradient is that last backward cycle's. An oxygen
//! parameter's terms are summed on the way; a flow parameter's (its face flows, transport
//! volumes and walls, driven by the flow's tangent) are its step forcing contracted with
//! the adjoint of each step, in one more backward cycle at the fixed point: the flow's
//! tangents forward, the species' adjoint backward.

use super::*;
use crate::transport::tangent::{
    AdjointSums, SignalRow, SpeciesAdjointState, SpeciesDerivative, SpeciesStepRecord, StepDuals,
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

/// The flow's periodic cycle with its tangents, and per parameter its index among the flow
/// parameters (None: an oxygen parameter).
struct FlowPart<'a> {
    flow: &'a FlowCycle,
    index: Vec<Option<usize>>,
    alpha_f: f64,
}

/// The gradients of functionals of the oxygen signals by the parameters `paths` (oxygen
/// and flow parameters): `weights_of(times, values)` gets the step end times and the
/// signals (n_steps × n_signals) of the recorded periodic cycle and returns the weights,
/// flat n_functionals × n_steps × n_signals. The parameters' SI values and the result; an
/// error naming what the species adjoint does not follow.
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
        spec,
        sp,
        params,
        assembled,
        dae,
        mut tr,
        s,
        sigs,
    } = Setup::new(spec, paths, signals, &settings)?;
    let (
        flow,
        Derivatives {
            flow_params,
            derivs,
            values,
            ..
        },
    ) = flow_and_derivatives(&spec, &sp, &params, &assembled, &dae, &mut tr, s, &settings)?;
    tr.check_species_adjoint(s, "sensitivities")?;
    let part = FlowPart {
        flow: &flow,
        index: flow_indices(&derivs),
        alpha_f: settings.alpha_f(),
    };
    let (transport_cycles, change_z, mut z) = primal_to_periodic(&mut tr, s, &flow, &settings)?;
    let nodes = !flow_params.is_empty();
    let rec = record(
        &mut tr, s, &flow, &settings, signals, &sigs, &derivs, &mut z, nodes,
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
    let back = Backward {
        s,
        dt,
        rec: &rec,
        sigs: &sigs,
        derivs: &derivs,
        set: &settings,
        flow: &part,
    };
    for w in weights.chunks(per) {
        let j: f64 = w.iter().zip(&rec.values).map(|(a, b)| a * b).sum();
        let (cycles, grad) = back.run(&mut tr, w)?;
        out.functionals.push(j);
        out.gradients.extend(grad);
        out.adjoint_cycles.push(cycles);
    }
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
    tr.set_periodic_relaxed_shears(&flow.ys, dt, set.alpha_f(), &mut z);
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
    nodes: bool,
) -> Result<Recorded> {
    let (ns, nsig, nc) = (set.steps_per_cycle, sigs.len(), tr.n_cells());
    let dt = set.period / ns as f64;
    let af = set.alpha_f();
    let acc = tr.species_names().len() * nc + 4 * s;
    let index = flow_indices(derivs);
    let mut rec = Recorded {
        steps: Vec::with_capacity(ns),
        rows: Vec::with_capacity(ns * nsig),
        values: vec![0.0; ns * nsig],
    };
    for k in 0..ns {
        let t = k as f64 * dt;
        let z_old = z.to_vec();
        let w_old = tr.cell_volumes().to_vec();
        let x_old = if nodes {
            tr.species_node_values(s, z)
        } else {
            Vec::new()
        };
        tr.implicit_step(t, dt, af, &flow.ys[k], &flow.ys[k + 1], z)?;
        rec.steps
            .push(tr.species_step_record(s, t + af * dt, &z_old, &w_old, z, x_old));
        let shears: Vec<&[f64]> = (index.iter())
            .map(|f| f.map_or(&[][..], |p| flow.shear(p, k)))
            .collect();
        for (j, sig) in sigs.iter().enumerate() {
            let row = match *sig {
                Signal::Network(a) => {
                    rec.values[k * nsig + j] = (z[acc + a] - z_old[acc + a]) / dt;
                    None
                }
                Signal::Vessel(v, kind) => {
                    let r =
                        tr.species_signal_row(s, v, &names[j].0, kind, z, (derivs, &shears[..]))?;
                    rec.values[k * nsig + j] = r.value;
                    Some(r)
                }
            };
            rec.rows.push(row);
        }
    }
    Ok(rec)
}

/// The backward sweeps of the recorded cycle (one functional's weights at a time).
struct Backward<'a> {
    s: usize,
    dt: f64,
    rec: &'a Recorded,
    sigs: &'a [Signal],
    derivs: &'a [SpeciesDerivative],
    set: &'a TangentSettings,
    flow: &'a FlowPart<'a>,
}

/// One backward cycle's parameter terms: the oxygen parameters' sums, the signals' direct
/// terms and the flow parameters' contracted forcing (per parameter).
struct CycleTerms {
    sums: AdjointSums,
    direct: Vec<f64>,
    flow: Vec<f64>,
}

impl Backward<'_> {
    /// The backward cycles of one functional (weights `w`, n_steps × n_signals) until the
    /// adjoint's state at the cycle's start repeats, and one more at that fixed point for
    /// the flow parameters: the cycles and the gradient.
    fn run(&self, tr: &mut Transport, w: &[f64]) -> Result<(usize, Vec<f64>)> {
        let nc = tr.n_cells();
        let mut lam: SpeciesAdjointState = tr.species_adjoint_start();
        let mut last = f64::INFINITY;
        for cycle in 1..=self.set.max_cycles {
            let (dz0, xt0) = (lam.dz.clone(), lam.xt.clone());
            let mut terms = self.cycle(tr, w, &mut lam, false, nc);
            last = change(&dz0, &lam.dz, 0.0).max(change(&xt0, &lam.xt, 0.0));
            if last <= self.set.tol {
                let mut cycles = cycle;
                if self.flow.index.iter().any(Option::is_some) {
                    terms = self.cycle(tr, w, &mut lam, true, nc);
                    cycles += 1;
                }
                let grad = (self.derivs.iter().enumerate())
                    .map(|(p, d)| terms.sums.gradient(d) + terms.direct[p] + terms.flow[p])
                    .collect();
                return Ok((cycles, grad));
            }
        }
        Err(Error::model(
            "sensitivities",
            format!(
                "the oxygen adjoint is not periodic after max_cycles = {} (last change \
                 {last:.2e})",
                self.set.max_cycles
            ),
        ))
    }

    /// One backward cycle from the adjoint state `lam` after the cycle (to the one before
    /// it); `with_flow`: the flow parameters' forcing contracted on the way.
    fn cycle(
        &self,
        tr: &mut Transport,
        w: &[f64],
        lam: &mut SpeciesAdjointState,
        with_flow: bool,
        nc: usize,
    ) -> CycleTerms {
        let (ns, nsig, np) = (self.set.steps_per_cycle, self.sigs.len(), self.derivs.len());
        let mut terms = CycleTerms {
            sums: AdjointSums::new(nc),
            direct: vec![0.0; np],
            flow: vec![0.0; np],
        };
        let mut seed = vec![0.0; lam.xt.len()];
        let mut duals = StepDuals::default();
        let fl = self.flow;
        // the flow parameters' transport volumes' tangent after the cycle (its start's)
        let mut dw: Vec<Vec<f64>> = if with_flow {
            (self.derivs.iter().zip(&fl.index))
                .map(|(d, i)| match i {
                    Some(i) => {
                        let start = fl.flow.tangent(*i, 0);
                        (tr.flow_volumes_start(d, &fl.flow.ys[0], start)).unwrap_or_default()
                    }
                    None => Vec::new(),
                })
                .collect()
        } else {
            Vec::new()
        };
        for k in (0..ns).rev() {
            seed.iter_mut().for_each(|x| *x = 0.0);
            let mut net = [0.0; 3];
            let mut faces = Vec::new();
            for (j, sig) in self.sigs.iter().enumerate() {
                let wk = w[k * nsig + j];
                if wk == 0.0 {
                    continue;
                }
                match (sig, &self.rec.rows[k * nsig + j]) {
                    (Signal::Network(a), _) => net[*a] += wk,
                    (_, Some(row)) => {
                        for &(n, c) in &row.nodes {
                            seed[n] += wk * c;
                        }
                        for (d, r) in terms.direct.iter_mut().zip(&row.direct) {
                            *d += wk * r;
                        }
                        faces.extend(row.face.map(|f| (f, wk)));
                    }
                    (_, None) => unreachable!("a vessel signal has its row"),
                }
            }
            let step = &self.rec.steps[k];
            let du = with_flow.then_some(&mut duals);
            tr.species_adjoint_step(self.s, self.dt, step, &seed, net, lam, &mut terms.sums, du);
            if !with_flow {
                continue;
            }
            for (p, i) in fl.index.iter().enumerate() {
                let Some(i) = *i else { continue };
                let fs = FlowStep {
                    start: fl.flow.tangent(i, k),
                    end: fl.flow.tangent(i, k + 1),
                    alpha_f: fl.alpha_f,
                    shear: fl.flow.shear(i, k),
                };
                let d = &self.derivs[p];
                terms.flow[p] += tr.species_flow_adjoint_step(
                    self.s, self.dt, step, d, &fs, &mut dw[p], &duals, &faces,
                );
            }
        }
        terms
    }
}

#[cfg(test)]
#[path = "species_adjoint_tests.rs"]
pub(super) mod tests;
