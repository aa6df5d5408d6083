//! The state a run advances: the flow (y, ẏ) with its integrator, and the species amounts
//! with their transport model. One step, the health checks between steps and the observation
//! of the species outputs live here, so the cycle loop sees neither integrator nor coupling.

use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::integrate::Integrator;
use crate::integrate::explicit_pair::Dopri5;
use crate::integrate::rk4::{CoupledStages, Rk4};
use crate::transport::{Formulation, Transport};

/// Explicit upwind transport is stable for Courant numbers up to this (docs/physics.md §1.5).
pub(super) const RK4_UPWIND_COURANT: f64 = 1.392_647;

/// How the flow advances, and with it the species.
pub(super) enum Flow<'d> {
    /// Any integrator; species (if any) follow each flow step with a backward-Euler transport
    /// step (generalized-α, and the quasi-steady formulation with RK4).
    Split(Box<dyn Integrator + 'd>),
    /// RK4 advancing flow and species as one ODE in the same stages (docs/physics.md §2.5,
    /// "monolithic"). It stays a special case: the coupled step evaluates the species
    /// derivative at every RK4 stage's consistent flow state, which [`Integrator`] (one whole
    /// step at a time) does not expose.
    Monolithic(Box<Rk4<'d>>),
    /// The explicit pair of an error-controlled run, species (if any) in its stages
    /// (`run::explicit`).
    Explicit(Box<Dopri5<'d>>),
}

impl<'d> Flow<'d> {
    pub fn integrator(&mut self) -> &mut (dyn Integrator + 'd) {
        match self {
            Flow::Split(ig) => ig.as_mut(),
            Flow::Monolithic(rk) => rk.as_mut(),
            Flow::Explicit(dp) => dp.as_mut(),
        }
    }
}

/// The species side of a run.
pub(super) struct Species<'t> {
    pub tr: &'t mut Transport,
    /// Amounts per cell and species, then the transport model's accumulators.
    pub z: Vec<f64>,
    /// The level within a step of the face flows of a split transport step (α_f, or 1 for the
    /// quasi-steady field, which is algebraic in the flow).
    level: f64,
    /// The flow state at the start of the step, when a split transport step interpolates its
    /// face flows between the step's start and end (generalized-α); None when it takes the
    /// end-of-step flows (RK4, whose end state is consistent). Kept only while the transport
    /// reads the whole state (`Transport::needs_step_state`); otherwise the transport carries
    /// the face flows from one step's end to the next step's start (no copy of y per step).
    step_start: Option<Vec<f64>>,
    /// The transport holds the face flows of the current flow state (`set_step_start`, then
    /// carried by every `implicit_step_carried`); false after anything else sets y.
    start_carried: bool,
    /// Stages of the monolithic RK4 step, allocated by its first step: a split step (every
    /// generalized-α run) needs none of the five z-sized vectors (~35 B per segment at 1e6).
    zk: Option<CoupledStages>,
    /// z at the end of the previous cycle (periodicity).
    prev_cycle_z: Vec<f64>,
    /// Scratch of `observe`: the flow state and its rate as the integrator reports them.
    /// Sized by the first observation that needs them: an integrator whose carried ẏ is the
    /// rate (generalized-α) never does, and two state-sized vectors (~40 B per segment) would
    /// stay resident under the whole output table.
    y_obs: Vec<f64>,
    yd_obs: Vec<f64>,
}

impl<'t> Species<'t> {
    /// The species state started uniform in the initial volumes of the flow state `y`, and
    /// Σ N of each species then. `level` is the integrator's α_f; `interpolate` whether its
    /// step's flows lie between the step's start and end (see `step_start`).
    pub fn start(
        tr: &'t mut Transport,
        y: &[f64],
        dt: f64,
        level: f64,
        interpolate: bool,
    ) -> Result<(Self, Vec<f64>)> {
        let mut z = tr.initial_state(y)?;
        let cells = tr.n_cells();
        let nsp = tr.species_names().len();
        let initial_stored: Vec<f64> = (0..nsp)
            .map(|k| z[k * cells..(k + 1) * cells].iter().sum())
            .collect();
        let quasi = tr.formulation() == Formulation::TlQuasisteady;
        if quasi {
            // the quasi-steady field is algebraic in the flow: make the initial one consistent
            tr.implicit_step(0.0, dt, 1.0, y, y, &mut z)?;
            // reset the accumulators (not the relaxed shears that follow them)
            for a in z.iter_mut().skip(cells * nsp).take(4 * nsp) {
                *a = 0.0;
            }
        }
        let species = Species {
            tr,
            zk: None,
            prev_cycle_z: z.clone(),
            z,
            level: if quasi { 1.0 } else { level },
            step_start: interpolate.then(Vec::new),
            start_carried: false,
            y_obs: Vec::new(),
            yd_obs: Vec::new(),
        };
        Ok((species, initial_stored))
    }

    /// The backward-Euler transport step over [t, t + dt] after the flow step that ended in `y`.
    fn implicit_step(&mut self, t: f64, dt: f64, y: &[f64]) -> Result<()> {
        if self.start_carried {
            return self
                .tr
                .implicit_step_carried(t, dt, self.level, y, &mut self.z);
        }
        let y0 = self.step_start.as_deref().unwrap_or(y);
        self.tr.implicit_step(t, dt, self.level, y0, y, &mut self.z)
    }

    /// Before a flow step from `y`: keep what the transport step interpolates from (the
    /// face flows, or the whole state; see `step_start`).
    fn before_flow_step(&mut self, y: &[f64]) {
        let Some(start) = self.step_start.as_mut() else {
            return;
        };
        if self.tr.needs_step_state() {
            start.clear();
            start.extend_from_slice(y);
            self.start_carried = false;
        } else if !self.start_carried {
            self.tr.set_step_start(y);
            self.start_carried = true;
        }
    }

    /// (z, z at the end of the cycle before, the transport's carried state) for a checkpoint.
    pub fn carried(&self) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        (self.z.clone(), self.prev_cycle_z.clone(), self.tr.carried())
    }

    /// Continue from a checkpoint's species state (see [`Species::carried`]).
    pub fn restore(&mut self, snap: &super::checkpoint::Snapshot) -> Result<()> {
        if snap.z.len() != self.z.len() || snap.prev_cycle_z.len() != self.z.len() {
            return Err(Error::model(
                "checkpoint",
                format!(
                    "the species state has {} values, this run's has {}: the checkpoint is of \
                     another model",
                    snap.z.len(),
                    self.z.len()
                ),
            ));
        }
        self.z.copy_from_slice(&snap.z);
        self.prev_cycle_z.copy_from_slice(&snap.prev_cycle_z);
        // the flow state is restored too: take the next step's start flows from it
        self.start_carried = false;
        self.tr.restore_carried(&snap.transport)
    }

    /// The relative change of the species state over the cycle just ended (species need
    /// several transit times, so the periodicity test includes them).
    pub fn cycle_change(&mut self) -> f64 {
        let change = self.tr.relative_change(&self.z, &self.prev_cycle_z);
        self.prev_cycle_z.copy_from_slice(&self.z);
        change
    }
}

/// The state a run advances.
pub(super) struct State<'d, 't> {
    pub dae: &'d Dae,
    pub flow: Flow<'d>,
    pub species: Option<Species<'t>>,
    pub y: Vec<f64>,
    /// ẏ: generalized-α's carried rate; RK4 leaves it at the start's.
    pub yd: Vec<f64>,
    pub dt: f64,
}

impl State<'_, '_> {
    /// The elements a step's passes go over: the unknowns, or the species' cell amounts if
    /// more (see `threads::in_pool_for`).
    pub fn work(&self) -> usize {
        let cells = self.species.as_ref().map_or(0, |sp| sp.z.len());
        self.y.len().max(cells)
    }

    /// One step from `t` to `t + dt`, flow and species.
    pub fn advance(&mut self, t: f64) -> Result<()> {
        let (y, yd) = (&mut self.y, &mut self.yd);
        match (&mut self.flow, self.species.as_mut()) {
            (Flow::Monolithic(rk), Some(sp)) => {
                let n = sp.z.len();
                let zk = sp.zk.get_or_insert_with(|| CoupledStages::coupled(n));
                rk.step_coupled(t, y, &mut sp.z, zk, &mut *sp.tr)
            }
            (Flow::Explicit(dp), Some(sp)) => {
                // one step of dt accepted whatever its estimate (error-controlled runs step
                // through `run::explicit`)
                dp.step(t, self.dt, y, &mut sp.z, &mut *sp.tr)?;
                dp.accept();
                Ok(())
            }
            (flow, mut species) => {
                if let Some(sp) = species.as_mut() {
                    sp.before_flow_step(y);
                }
                flow.integrator().step(t, y, yd)?;
                match species {
                    Some(sp) => sp.implicit_step(t, self.dt, y),
                    None => Ok(()),
                }
            }
        }
    }

    /// The flow part of one split step of `h` from `t` (error-controlled runs, which judge the
    /// flow step before the species follow it): the transport's start flows are set first.
    /// The step starts from (y, ẏ) = `start` (the state the run keeps to go back to on a
    /// rejection), and its end is written into the state's vectors, whatever they held.
    pub fn advance_flow(&mut self, t: f64, h: f64, start: (&[f64], &[f64])) -> Result<()> {
        if let Some(sp) = self.species.as_mut() {
            sp.before_flow_step(start.0);
        }
        self.dt = h;
        let ig = self.flow.integrator();
        ig.set_dt(h);
        ig.step_from(t, start, &mut self.y, &mut self.yd)
    }

    /// The species part of the split step of `h` from `t` that [`State::advance_flow`] began.
    pub fn advance_species(&mut self, t: f64, h: f64) -> Result<()> {
        match self.species.as_mut() {
            Some(sp) => sp.implicit_step(t, h, &self.y),
            None => Ok(()),
        }
    }

    /// The species outputs at `t` of an interpolated flow state (y, ẏ) and amounts `z`
    /// (dense output between steps), over the cells' transport `volumes` interpolated alike.
    /// What the transport carries between steps (volumes, warm starts) is put back
    /// afterwards, so output times never change the solution.
    pub fn observe_at(
        &mut self,
        t: f64,
        y: &[f64],
        yd: &[f64],
        z: &[f64],
        volumes: &[f64],
        out: &mut Vec<f64>,
    ) -> Result<()> {
        out.clear();
        let Some(sp) = self.species.as_mut() else {
            return Ok(());
        };
        let names = &self.dae.names;
        sp.tr
            .check_finite(z, t, &|v| names.vessel(v).map(str::to_owned))?;
        let carried = sp.tr.carried();
        sp.tr.set_cell_transport_volumes(volumes);
        let seen = sp.tr.observe(t, y, Some(yd), z, true, out);
        sp.tr.restore_carried(&carried)?;
        seen
    }

    /// The checks run every few steps: the explicit transport's Courant number and a finite
    /// flow state.
    pub fn check(&mut self, t: f64) -> Result<()> {
        if let (Flow::Monolithic(_), Some(sp)) = (&self.flow, self.species.as_mut()) {
            // explicit upwind transport is stable for Courant numbers up to 1.3926
            // (docs/physics.md §1.5); the flow eigenvalues alone do not bound it
            let dt = self.dt;
            let courant = dt * sp.tr.max_outflow_rate(&self.y, t);
            if courant > 0.95 * RK4_UPWIND_COURANT {
                return Err(Error::solver(
                    t,
                    format!(
                        "transport Courant number {courant:.3} exceeds the RK4 limit 1.39 (dt {dt:.3e} s): reduce dt to {:.3e} s or use method 'generalized-alpha'",
                        dt * 0.7 / courant
                    ),
                ));
            }
        }
        if let Some(i) = self.y.iter().position(|v| !v.is_finite()) {
            return Err(Error::solver(
                t,
                format!("non-finite value of {}", self.dae.names.unknown(i)),
            ));
        }
        Ok(())
    }

    /// The species outputs at `t` into `out` (cleared first; nothing for a flow-only run).
    /// They see the flow state with the rate the integrator reports for it (RK4 derives ẏ
    /// with its algebraic unknowns made consistent).
    pub fn observe(&mut self, t: f64, out: &mut Vec<f64>) -> Result<()> {
        out.clear();
        let Some(sp) = self.species.as_mut() else {
            return Ok(());
        };
        let monolithic = matches!(self.flow, Flow::Monolithic(_) | Flow::Explicit(_));
        let names = &self.dae.names;
        sp.tr
            .check_finite(&sp.z, t, &|v| names.vessel(v).map(str::to_owned))?;
        let ig = self.flow.integrator();
        if ig.rate_is_carried() {
            // (y, ẏ) are what `rate` would report: no copies of the flow state per row
            return sp
                .tr
                .observe(t, &self.y, Some(&self.yd), &sp.z, !monolithic, out);
        }
        sp.y_obs.clone_from(&self.y);
        sp.yd_obs.clone_from(&self.yd);
        ig.rate(t, &mut sp.y_obs, &mut sp.yd_obs)?;
        sp.tr
            .observe(t, &sp.y_obs, Some(&sp.yd_obs), &sp.z, !monolithic, out)
    }
}
