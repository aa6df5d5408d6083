//! The accumulated-error estimate of an error-controlled run (docs/solvers.md, "The
//! accumulated error"): the step control holds every step's *local* error within rtol, but
//! those errors accumulate through the network (the compliances carry them into the pressures,
//! and a small vessel's flow follows its small pressure drop), so the output can be many rtol
//! off. Once the run has ended, its last cycle is integrated again from the same start state
//! at rtol / factor with a fresh controller; the two output tables' difference is what the
//! Python reading turns into the estimate (the achieved error of a controlled run is nearly
//! proportional to rtol, so the difference is (1 − 1/factor) of the run's error accumulated
//! over that cycle). The explicit pair's second integration runs the whole run again from
//! its first cycle's start and also lowers its step ceiling (`Explicit::tighter`): a run whose
//! steps the stability bound sets would otherwise take the same steps again and measure
//! nothing, and its error within a periodic cycle is so small that the error carried from the
//! first cycle's transient is most of it. The run's own state, counters, step history and rows are put back as they
//! were: its output does not change.

use super::super::adaptive::Adaptive;
use super::super::checkpoint::Snapshot;
use super::super::coupling::Flow;
use super::super::explicit::Explicit;
use super::super::outcome::FinerCycle;
use super::{CycleRows, Cycles};
use crate::error::{Error, Result};

/// The controller of the second integration: the run's method at the tighter tolerance.
enum Fine {
    Implicit(Box<Adaptive>),
    Explicit(Box<Explicit>),
}

/// The state a cycle starts from (what `Cycles::snapshot` keeps of the flow and species,
/// without the rows and counters).
pub(in crate::run) struct CycleStart {
    t0: f64,
    y: Vec<f64>,
    yd: Vec<f64>,
    dt: f64,
    integrator: Vec<f64>,
    species: Option<(Vec<f64>, Vec<f64>, Vec<f64>)>,
}

impl Cycles<'_, '_> {
    /// Whether the cycle about to run keeps its start for [`Cycles::finer_last_cycle`]: an
    /// error-controlled run (generalized-α or the explicit pair) that asks for it, without
    /// valves (whose statuses a second integration would have to replay), in its last
    /// (recording) pass. The explicit pair keeps its first cycle's start only: its second
    /// integration runs every cycle again (`Explicit::tighter`).
    pub(super) fn keeps_cycle_start(&self) -> bool {
        self.s.finer_last_cycle.is_some()
            && (self.adaptive.is_some() || (self.explicit.is_some() && self.last_start.is_none()))
            && self.events.is_none()
            && self.mean.is_none()
    }

    /// The state at `t0`, the start of the cycle about to run.
    pub(super) fn cycle_start_state(&mut self, t0: f64) -> CycleStart {
        let st = &mut self.state;
        CycleStart {
            t0,
            y: st.y.clone(),
            yd: st.yd.clone(),
            dt: st.dt,
            integrator: st.flow.integrator().carried(),
            species: st.species.as_ref().map(|sp| sp.carried()),
        }
    }

    /// Put the run's state back to `p`.
    fn put_state(&mut self, p: &CycleStart) -> Result<()> {
        let st = &mut self.state;
        st.y.copy_from_slice(&p.y);
        st.yd.copy_from_slice(&p.yd);
        st.dt = p.dt;
        st.flow.integrator().restore_carried(&p.integrator)?;
        if let Flow::Explicit(dp) = &mut st.flow {
            dp.reset(); // its first stage is of the state it ended in: evaluated again
        }
        if let (Some(sp), Some((z, prev_cycle_z, transport))) = (st.species.as_mut(), &p.species) {
            sp.restore(&Snapshot {
                z: z.clone(),
                prev_cycle_z: prev_cycle_z.clone(),
                transport: transport.clone(),
                ..Default::default()
            })?;
        }
        Ok(())
    }

    /// After the run: its last cycle (the explicit pair: every cycle, from the first) again
    /// from its kept start at rtol / factor, the last cycle's rows
    /// (the output times after the cycle's first) in `self.finer`. Everything the run reports
    /// is put back; an interruption is the run's error, a failure of the second integration
    /// only leaves the estimate out.
    pub(super) fn finer_last_cycle(
        &mut self,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<()> {
        let (Some(start), Some(factor), Some(tol)) = (
            self.last_start.take(),
            self.s.finer_last_cycle,
            self.s.adaptive(),
        ) else {
            return Ok(());
        };
        let s = self.s;
        let tol = crate::integrate::adaptive::Tolerances {
            rtol: tol.rtol / factor,
            ..tol
        };
        let tighter = self
            .explicit
            .as_ref()
            .map(|ex| ex.tighter(self.state.dae, s, factor));
        let mut fine = match tighter {
            Some(ex) => Fine::Explicit(Box::new(ex)),
            None => Fine::Implicit(Box::new(Adaptive::new(
                self.state.dae,
                tol,
                s.method.rho_inf(),
                s.period,
                s.output_every,
            ))),
        };
        let end = self.cycle_start_state(self.cycle_start + s.period);
        // the cycles from the kept start to the run's end (one for generalized-α)
        let cycles = ((self.cycle_start + s.period - start.t0) / s.period).round() as usize;
        let kept = (self.steps, self.cycle_start);
        let taken = std::mem::take(&mut self.periodic_steps);
        self.rec.align();
        let (n, nd, nt) = (
            self.rec.times.len(),
            self.rec.data.len(),
            self.rec.transport.len(),
        );
        self.put_state(&start)?;
        let mut done = Ok(());
        for k in 0..cycles.max(1) {
            let last = k + 1 >= cycles;
            let rows = CycleRows {
                t0: start.t0 + k as f64 * s.period,
                committed: false,
                recorded: last, // (the last cycle's rows only)
                species: last,
            };
            done = match &mut fine {
                Fine::Implicit(ad) => self.adaptive_cycle(ad, &rows, progress),
                Fine::Explicit(ex) => self.explicit_cycle(ex, &rows, progress),
            };
            if done.is_err() {
                break;
            }
        }
        let (steps, rejected) = match &fine {
            Fine::Implicit(ad) => (ad.steps, ad.rejected),
            Fine::Explicit(ex) => (ex.steps, ex.rejected),
        };
        self.rec.align();
        let finer = FinerCycle {
            factor,
            times: self.rec.times.split_off(n),
            data: self.rec.data.split_off(nd),
            transport: self.rec.transport.split_off(nt),
            steps,
            rejected,
        };
        self.put_state(&end)?;
        (self.steps, self.cycle_start) = kept;
        self.periodic_steps = taken;
        match done {
            Ok(()) => self.finer = Some(finer),
            Err(e @ Error::Interrupted { .. }) => return Err(e),
            Err(_) => {}
        }
        Ok(())
    }
}
