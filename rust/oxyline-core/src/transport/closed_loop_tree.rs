//! A segment-resolved systemic arterial tree inside the closed O2 loop (docs/oxygen.md "Oxygen
//! around a closed loop", "arterial tree"). The tree is an ordinary open network (vessels cut
//! into segments, an inflow condition at its root, resistances to the venous pressure at its
//! outlets) whose flow is driven by the closed-loop heart; its oxygen runs through the
//! product's own transport (`Transport`: the conservative transmission-line cells, upwind faces,
//! Hill binding, wall closures; docs/physics.md §2.5, §3) with the backward-Euler step that
//! follows every generalized-α flow step. The closed loop couples to it at its boundaries only:
//!
//! * the root carries in the total concentration of the compartment that ejects into it (the
//!   left heart), set step by step (`inflow_override`), at the transport's own boundary flow;
//! * each outlet's O2 flux (flow × upwind concentration of the solved field, the same flux the
//!   transport removed) enters its organ compartment;
//! * the wall uptake of the tree is a sink of the loop beside the organs.
//!
//! So the loop's amount changes by exactly dt (lung uptake − Σ organ VO2 − tree wall uptake)
//! per step: the tree's Σ N changes by dt (root inflow − outlet outflow − wall uptake) exactly
//! (the transport's linear invariant), and the compartments lose and gain those same fluxes.

use super::plan::upwind_flux_in;
use super::{End, Transport};
use crate::circuit::Regime;
use crate::error::{Error, Result};
use crate::hemoglobin::Binding;
use crate::integrate::NewtonControl;
use crate::integrate::genalpha::GenAlpha;

/// The tree's flow over one periodic cycle and its O2 state.
pub struct ArterialTree {
    tr: Transport,
    /// Flow state at the step ends of the last flow cycle (steps + 1 rows, row 0 its start).
    ys: Vec<Vec<f64>>,
    alpha_f: f64,
    dt: f64,
    inlet: usize,
    outlets: Vec<usize>,
    binding: Binding,
    /// Species amounts per cell, then the transport's accumulators (reset every step).
    z: Vec<f64>,
    /// Per step: the flow into the root and out of every outlet (m³/s), at the transport's
    /// α_f level (the flows that carry the species).
    pub inflow: Vec<f64>,
    pub outflow: Vec<Vec<f64>>,
    /// Last step: O2 flux into the root, out of every outlet, and into the wall (mol/s).
    pub in_flux: f64,
    pub out_flux: Vec<f64>,
    pub wall: f64,
    /// max |y(end) − y(start)| of the last flow cycle relative to max |y|.
    pub flow_periodic_error: f64,
    /// "vessel:k" of every flow segment, in model order.
    pub segment_names: Vec<String>,
}

/// Index of the boundary condition called `name` in the tree's circuit.
fn boundary_index(circuit: &crate::circuit::Circuit, name: &str) -> Result<usize> {
    circuit
        .boundaries
        .iter()
        .position(|b| b.name == name)
        .ok_or_else(|| {
            Error::model(
                "arterial tree",
                format!("'{name}' is not one of its boundary conditions"),
            )
        })
}

/// `vessel:k` for every segment, k counted from the vessel's inlet.
fn segment_names(circuit: &crate::circuit::Circuit) -> Vec<String> {
    let mut seg_count = vec![0usize; circuit.vessel_names.len()];
    circuit
        .segments
        .iter()
        .map(|s| {
            seg_count[s.vessel] += 1;
            format!(
                "{}:{}",
                circuit.vessel_names[s.vessel],
                seg_count[s.vessel] - 1
            )
        })
        .collect()
}

impl ArterialTree {
    /// Assemble the tree model (canonical SI JSON with an `oxygen` section), run its flow by
    /// generalized-α at step dt for `cycles` cycles of `steps` steps and keep the last one; the
    /// root is boundary `inlet`, the outlets are `outlets` (boundary names).
    pub fn new(
        model_json: &str,
        inlet: &str,
        outlets: &[String],
        dt: f64,
        steps: usize,
        cycles: usize,
    ) -> Result<Self> {
        let spec = crate::model::parse(model_json)?;
        let assembled = spec.assemble()?;
        let circuit = &assembled.circuit;
        let dae = circuit.assemble()?;
        let tspec = spec.transport.as_ref().ok_or_else(|| {
            Error::model(
                "arterial tree",
                "needs an oxygen section (its wall and binding)",
            )
        })?;
        let mut tr = Transport::build(tspec, circuit, &dae, &assembled.probes)?;
        if tr.plan.species.len() != 1 {
            return Err(Error::model(
                "arterial tree",
                "carries oxygen only (one species)",
            ));
        }
        let inlet = boundary_index(circuit, inlet)?;
        let outlets = outlets
            .iter()
            .map(|o| boundary_index(circuit, o))
            .collect::<Result<Vec<_>>>()?;
        if steps == 0 || cycles == 0 || !(dt.is_finite() && dt > 0.0) {
            return Err(Error::model(
                "arterial tree",
                format!(
                    "needs dt > 0, steps and cycles ≥ 1 (dt {dt}, {steps} steps, {cycles} cycles)"
                ),
            ));
        }
        let (ys, alpha_f, flow_periodic_error) = periodic_flow(&dae, dt, steps, cycles)?;
        let segment_names = segment_names(circuit);
        set_closure_flows(&mut tr, &ys, alpha_f)?;
        let z = tr.initial_state(&ys[0])?;
        let binding = tr.plan.species[0].binding;
        let mut tree = ArterialTree {
            tr,
            ys,
            alpha_f,
            dt,
            inlet,
            outlets,
            binding,
            z,
            inflow: Vec::with_capacity(steps),
            outflow: Vec::with_capacity(steps),
            in_flux: 0.0,
            out_flux: Vec::new(),
            wall: 0.0,
            flow_periodic_error,
            segment_names,
        };
        tree.record_boundary_flows(steps);
        Ok(tree)
    }

    /// The inlet's inflow and every outlet's outflow at each step of the stored cycle.
    fn record_boundary_flows(&mut self, steps: usize) {
        for s in 0..steps {
            let t_af = self.dt * (s as f64 + self.alpha_f);
            let (y0, y1) = (&self.ys[s], &self.ys[s + 1]);
            self.tr.load_flows_between(t_af, y0, y1, self.alpha_f);
            let q = self.tr.boundary_flows();
            self.inflow.push(q[self.inlet]);
            self.outflow
                .push(self.outlets.iter().map(|&b| -q[b]).collect());
        }
        self.out_flux = vec![0.0; self.outlets.len()];
    }

    /// Steps per cycle of the tree's flow.
    pub fn steps(&self) -> usize {
        self.inflow.len()
    }

    /// O2 in the tree (mol).
    pub fn amount(&self) -> f64 {
        self.z[..self.tr.n_cells()].iter().sum()
    }

    /// The O2 amount of every cell (mol).
    pub fn cells(&self) -> &[f64] {
        &self.z[..self.tr.n_cells()]
    }

    pub fn set_cells(&mut self, cells: &[f64]) {
        let nc = self.tr.n_cells();
        self.z[..nc].copy_from_slice(cells);
    }

    /// The O2 state (amounts and the transport's carried state) to restart a step or a cycle.
    pub fn snapshot(&self) -> (Vec<f64>, Vec<f64>) {
        (self.z.clone(), self.tr.carried())
    }

    pub fn restore(&mut self, snap: &(Vec<f64>, Vec<f64>)) -> Result<()> {
        self.z.copy_from_slice(&snap.0);
        self.tr.restore_carried(&snap.1)
    }

    /// Largest relative change of the cell amounts between two snapshots.
    pub fn relative_change(&self, a: &(Vec<f64>, Vec<f64>), b: &(Vec<f64>, Vec<f64>)) -> f64 {
        self.tr.relative_change(&a.0, &b.0)
    }

    /// Step `s` of the cycle with the root carrying total concentration `c_in` (mol/m³) in.
    pub fn step(&mut self, s: usize, c_in: f64) -> Result<()> {
        let nc = self.tr.n_cells();
        self.tr.inflow_override = Some((self.inlet, c_in));
        // the accumulators restart at zero so that this step's integrals are read exactly
        self.z[nc..nc + 4].fill(0.0);
        let time = self.dt * s as f64;
        let (y0, y1) = (&self.ys[s], &self.ys[s + 1]);
        self.tr
            .implicit_step(time, self.dt, self.alpha_f, y0, y1, &mut self.z)?;
        self.wall = self.z[nc + 2] / self.dt;
        let j = self.tr.boundary_fluxes();
        self.in_flux = j[self.inlet];
        for (o, &b) in self.out_flux.iter_mut().zip(&self.outlets) {
            *o = -j[b];
        }
        Ok(())
    }

    /// Free concentration (mol/m³) in the cell holding most of every segment's volume.
    pub fn segment_free(&self) -> Vec<f64> {
        let wvol = &self.tr.wvol;
        (0..self.segment_names.len())
            .map(|j| match self.tr.segment_cell(j) {
                Some(i) => {
                    let ct = self.z[i] / wvol[i];
                    self.binding
                        .free(ct, self.tr.species[0].free.get(i).copied().unwrap_or(0.0))
                }
                None => f64::NAN,
            })
            .collect()
    }
}

/// The flow state at every step end of the last of `cycles` generalized-α cycles from the zero
/// state (the tree forgets its start with its RC time), α_f, and the last cycle's periodicity.
fn periodic_flow(
    dae: &crate::circuit::Dae,
    dt: f64,
    steps: usize,
    cycles: usize,
) -> Result<(Vec<Vec<f64>>, f64, f64)> {
    let mut ga = GenAlpha::new(dae, Regime::Transient, dt, 0.5, NewtonControl::default())?;
    let alpha_f = ga.alpha_f();
    let mut y = dae.initial_state();
    let mut yd = vec![0.0; dae.n];
    let mut ys = Vec::with_capacity(steps + 1);
    for c in 0..cycles {
        let last = c + 1 == cycles;
        if last {
            ys.push(y.clone());
        }
        for s in 0..steps {
            ga.step(dt * (c * steps + s) as f64, &mut y, &mut yd)?;
            if last {
                ys.push(y.clone());
            }
        }
    }
    let scale = ys[0]
        .iter()
        .fold(0.0_f64, |m, v| m.max(v.abs()))
        .max(1e-300);
    let err = ys[0]
        .iter()
        .zip(&ys[steps])
        .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
        / scale;
    Ok((ys, alpha_f, err))
}

/// The wall closures that need the cycle-mean flow (Graetz, Lévêque) get it from the recorded
/// cycle at the transport's α_f level: ⟨|Q|⟩ and the forward mean ⟨max(±Q, 0)⟩ in the
/// direction of the net flow (docs/physics.md §3.6).
fn set_closure_flows(tr: &mut Transport, ys: &[Vec<f64>], alpha_f: f64) -> Result<()> {
    let unknowns = tr.mean_flow_unknowns();
    if unknowns.is_empty() {
        return Ok(());
    }
    let steps = (ys.len() - 1) as f64;
    let (mut abs, mut fwd) = (Vec::new(), Vec::new());
    for &u in &unknowns {
        let q: Vec<f64> = ys
            .windows(2)
            .map(|w| w[0][u] + alpha_f * (w[1][u] - w[0][u]))
            .collect();
        let sign = if q.iter().sum::<f64>() >= 0.0 {
            1.0
        } else {
            -1.0
        };
        abs.push(q.iter().map(|x| x.abs()).sum::<f64>() / steps);
        fwd.push(q.iter().map(|x| (sign * x).max(0.0)).sum::<f64>() / steps);
    }
    tr.set_mean_flows(&abs, &fwd)
}

impl Transport {
    /// Flow into the domain through every boundary (m³/s) with the loaded face flows.
    fn boundary_flows(&self) -> Vec<f64> {
        let mut q_in = vec![0.0; self.plan.boundary_inlet.len()];
        for b in &self.plan.boundary_links {
            let q = self.qf[b.face as usize];
            q_in[b.boundary as usize] += b.inflow(q);
        }
        for ((_, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
            q_in[*bb] += q;
        }
        q_in
    }

    /// Species flux into the domain through every boundary (mol/s) of the solved implicit
    /// field: per boundary, the terms `implicit_boundary_fluxes` sums (the fluxes of the solve).
    fn boundary_fluxes(&self) -> Vec<f64> {
        let mut j_in = vec![0.0; self.plan.boundary_inlet.len()];
        for b in &self.plan.boundary_links {
            let (n, bb, q) = (
                b.node as usize,
                b.boundary as usize,
                self.qf[b.face as usize],
            );
            j_in[bb] += b.flux_in(q, self.conc[n], || self.lagged_boundary(bb, End::Node(n)));
        }
        for ((n, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
            j_in[*bb] += upwind_flux_in(q, true, self.conc[*n], || {
                self.lagged_boundary(*bb, End::Node(*n))
            });
        }
        j_in
    }
}
