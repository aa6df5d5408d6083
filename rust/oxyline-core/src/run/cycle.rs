//! The cycle loop: steps cycle by cycle, records the output rows that are due, checks the
//! state, reports progress, and stops when the run is periodic (or the mean flow of a first
//! pass has settled), interrupted, or failed.

use super::adaptive::Adaptive;
use super::breakpoints::{Breakpoints, toward_corner};
use super::checkpoint::{Checkpoints, Snapshot};
use super::coupling::State;
use super::events::{Cut, Next, decide};
use super::mean_flow::MeanAbs;
use super::periodic_steps::{NEAR_PERIODIC, PeriodicSteps};
use super::recorder::Recorder;
use super::retry::{OnFailure, Retry, given_up};
use super::settings::RunSettings;
use super::svzerod::{CycleMeans, DerivedState};
use crate::error::{Error, Result};
use crate::integrate::index2::StepEnds;
use crate::integrate::newton::scaled_increment;
use crate::integrate::stability::growth;

mod finer; // the accumulated-error estimate: the last cycle again at a tighter tolerance

/// Observation rows of at least this many values are freed between output rows (see
/// `Cycles::push_observed`): 2 MB, a row of ~60 000 output vessels with oxygen.
const OBSERVATION_KEPT_MAX: usize = 1 << 18;

/// The running loop. A failed or interrupted run keeps everything recorded so far.
pub(super) struct Cycles<'r, 'f> {
    pub(super) s: &'r RunSettings,
    pub state: State<'r, 'r>,
    pub rec: Recorder<'r, 'r, 'f>,
    /// The first pass's running mean of |Q|.
    mean: Option<&'r mut MeanAbs>,
    steps_per_cycle: usize,
    /// Steps per output row.
    stride: usize,
    max_cycles: usize,
    /// Steps taken.
    pub(super) steps: usize,
    pub cycles_run: usize,
    /// Cycle-to-cycle change of the state at the end of the last cycle run (relative).
    pub periodic_error: f64,
    prev_cycle_end: Vec<f64>,
    /// The species observation of the row being recorded (every species column of every
    /// output vessel, before the recorder's selection), and its length the last time.
    obs_row: Vec<f64>,
    obs_len: usize,
    /// The allocator's free pages were handed back after the pass's first output row.
    released: bool,
    /// Error control (None: the fixed step).
    pub adaptive: Option<Adaptive>,
    /// Error control's accepted steps of the cycle being run (near-periodic cycles waiting for
    /// periodicity replay them; the last cycle's are the reported step-size history).
    pub(super) periodic_steps: PeriodicSteps,
    /// The start time of the cycle being run (of the last cycle, once the run ended).
    pub(super) cycle_start: f64,
    /// Error control with the explicit pair.
    pub explicit: Option<super::explicit::Explicit>,
    /// The valve events of an error-controlled run (None: no switching element).
    pub events: Option<super::events::Events>,
    /// svZeroDSolver's derived columns and cycle means (`RunSettings::svzerod`).
    derived: Option<DerivedState>,
    cycle_means: Option<CycleMeans>,
    /// (y, ẏ) of an RK4 output row's rates (`record_rates`).
    rate_scratch: (Vec<f64>, Vec<f64>),
    /// The start of the cycle being run, kept when `RunSettings::finer_last_cycle` asks
    /// for the last cycle again (`finer`).
    last_start: Option<finer::CycleStart>,
    /// The last cycle's rows at the tighter tolerance, once run.
    pub finer: Option<super::outcome::FinerCycle>,
    /// The index-2 unknowns' values consistent with the constraint at the step ends, which a
    /// row recorded from the state reports (None: the circuit has none, or the integrator
    /// meets its algebraic rows at the step's end).
    step_ends: Option<StepEnds>,
    /// The forcing's corners, each of which an error-controlled step ends on.
    breakpoints: Breakpoints,
}

/// What the rows of one cycle are for.
pub(super) struct CycleRows {
    pub t0: f64,
    /// Certain to be part of the output: they may go to the sink as they come.
    pub committed: bool,
    /// Recorded at all.
    pub recorded: bool,
    /// With their species outputs (those of cycles that will be discarded are not computed).
    pub species: bool,
}

impl CycleRows {
    /// A row's output time: the run's time, or the time into the recorded cycle.
    pub(super) fn output_time(&self, time: f64, all_cycles: bool) -> f64 {
        if all_cycles { time } else { time - self.t0 }
    }

    /// The output times of an error-controlled cycle of `n_out` rows that a step ending at
    /// `t_new` has reached, from row `*next` on (1-based; advanced past each time given).
    pub(super) fn due<'a>(
        &self,
        period: f64,
        n_out: usize,
        next: &'a mut usize,
        t_new: f64,
    ) -> impl Iterator<Item = f64> + 'a {
        let t0 = self.t0;
        std::iter::from_fn(move || {
            let tau = t0 + period * *next as f64 / n_out as f64;
            (*next <= n_out && tau <= t_new + 1e-12 * period).then(|| {
                *next += 1;
                tau
            })
        })
    }
}

/// The step of an error-controlled cycle at `rem` before its end, the controller proposing
/// `h`: the whole remainder when `h` nearly reaches it, half of it when under two steps
/// are left (no sliver of a last step), else `h`.
pub(super) fn toward_end(h: f64, rem: f64) -> f64 {
    if h >= rem * (1.0 - 1e-9) {
        rem
    } else if h > 0.5 * rem {
        0.5 * rem
    } else {
        h
    }
}

impl<'r, 'f> Cycles<'r, 'f> {
    pub fn new(
        s: &'r RunSettings,
        mut state: State<'r, 'r>,
        rec: Recorder<'r, 'r, 'f>,
        mean: Option<&'r mut MeanAbs>,
        steps_per_cycle: usize,
        stride: usize,
    ) -> Self {
        // (not in svZeroDSolver's drop-in, whose rows keep its arithmetic)
        let step_ends = (!s.svzerod.drop_in)
            .then(|| StepEnds::new(state.dae, state.flow.integrator().alpha_f()))
            .flatten();
        let breakpoints = Breakpoints::of(state.dae, s.period);
        Cycles {
            step_ends,
            breakpoints,
            s,
            prev_cycle_end: state.y.clone(),
            state,
            rec,
            mean,
            steps_per_cycle,
            stride,
            max_cycles: s.max_cycles(),
            steps: 0,
            cycles_run: 0,
            periodic_error: f64::NAN,
            obs_row: Vec::new(),
            obs_len: 0,
            released: false,
            adaptive: None,
            periodic_steps: PeriodicSteps::default(),
            cycle_start: 0.0,
            explicit: None,
            events: None,
            derived: None,
            cycle_means: None,
            rate_scratch: Default::default(),
            last_start: None,
            finer: None,
        }
    }

    /// Start svZeroDSolver's derived columns and cycle means at the initial state (`implicit`:
    /// the run steps generalized-α, whose α_f stage the valve status follows).
    pub fn start_svzerod(&mut self, implicit: bool) {
        let rules = &self.s.svzerod;
        let y = &self.state.y;
        if !rules.derived.is_empty() {
            let alpha_f = implicit.then(|| 1.0 / (1.0 + self.s.method.rho_inf()));
            let steady = matches!(self.s.start, super::settings::Start::SvZeroDSteady { .. });
            self.derived = Some(DerivedState::new(&rules.derived, y, alpha_f, steady));
        }
        if let Some(stop) = &rules.cycle_mean_stop {
            let mut m = CycleMeans::new(stop);
            m.add(y);
            self.cycle_means = Some(m);
        }
    }

    pub fn s_period(&self) -> f64 {
        self.s.period
    }

    fn t_end(&self) -> f64 {
        self.max_cycles as f64 * self.s.period
    }

    /// Run the cycles; the error that stopped the run early, if any. The rest of the output
    /// (the partial chunk, or all rows of an interrupted run) goes to the sink too: a long run
    /// keeps everything it computed.
    ///
    /// With `checkpoints`, a snapshot is saved at the end of every cycle it asks for (not
    /// after the last); a run restored from one (see [`Cycles::restore`]) starts at its cycle.
    pub fn run(
        &mut self,
        progress: &mut dyn FnMut(f64, f64) -> bool,
        mut checkpoints: Option<&mut Checkpoints<'_>>,
    ) -> Option<Error> {
        let mut error = None;
        for cycle in self.cycles_run..self.max_cycles {
            let saved = match (self.cycle(cycle, progress), checkpoints.as_deref_mut()) {
                (Ok(true), Some(ck)) => self.checkpoint(ck).map(|()| true),
                (done, _) => done,
            };
            match saved {
                Ok(true) => {}
                Ok(false) => break,
                Err(e) => {
                    error = Some(e);
                    break;
                }
            }
        }
        if error.is_none() {
            error = self.finer_last_cycle(progress).err();
        }
        self.rec.align();
        if !self.rec.flush(true) && error.is_none() {
            error = Some(Error::Interrupted {
                time: self.steps as f64 * self.state.dt,
            });
        }
        progress(self.cycles_run as f64 * self.s.period, self.t_end());
        error
    }

    /// Save a snapshot if one is due after the cycle just run (and the run goes on); a `save`
    /// that fails stops the run as an interruption (the caller reports its own error).
    fn checkpoint(&mut self, ck: &mut Checkpoints<'_>) -> Result<()> {
        if self.cycles_run >= self.max_cycles || !ck.due(self.cycles_run) {
            return Ok(());
        }
        let snap = self.snapshot(ck.mean_abs_flow.clone());
        if ck.save(&snap) {
            Ok(())
        } else {
            Err(Error::Interrupted {
                time: self.steps as f64 * self.state.dt,
            })
        }
    }

    /// Everything needed to continue from the end of the current cycle.
    fn snapshot(&mut self, mean_abs_flow: Vec<f64>) -> Snapshot {
        let (z, prev_cycle_z, transport) = self
            .state
            .species
            .as_ref()
            .map(|sp| sp.carried())
            .unwrap_or_default();
        Snapshot {
            cycles_run: self.cycles_run,
            steps: self.steps,
            dt: self.state.dt,
            periodic_error: self.periodic_error,
            y: self.state.y.clone(),
            yd: self.state.yd.clone(),
            prev_cycle_end: self.prev_cycle_end.clone(),
            integrator: self.state.flow.integrator().carried(),
            z,
            prev_cycle_z,
            transport,
            initial_stored: self.rec.initial_stored.clone(),
            mean_abs_flow,
            times: self.rec.times.clone(),
            data: self.rec.data.clone(),
            transport_rows: self.rec.transport.clone(),
            step_ends: self
                .step_ends
                .as_ref()
                .map(StepEnds::carried)
                .unwrap_or_default(),
        }
    }

    /// Continue from `snap` (the state (y, ẏ) was started from it): the integrator's and the
    /// species' carried state, the cycle count, the periodicity references and the rows.
    pub fn restore(&mut self, snap: &Snapshot) -> Result<()> {
        let bad = |what: String| Err(Error::model("checkpoint", what));
        if snap.prev_cycle_end.len() != self.prev_cycle_end.len() {
            return bad(format!(
                "the flow state has {} unknowns, this model's has {}: the checkpoint is of another model",
                snap.prev_cycle_end.len(),
                self.prev_cycle_end.len()
            ));
        }
        if snap.cycles_run >= self.max_cycles {
            return bad(format!(
                "it was written after cycle {}, but the run has at most {} cycles",
                snap.cycles_run, self.max_cycles
            ));
        }
        self.state
            .flow
            .integrator()
            .restore_carried(&snap.integrator)?;
        match self.state.species.as_mut() {
            Some(sp) => sp.restore(snap)?,
            None if !snap.z.is_empty() => {
                return bad("it has species, this run has none".into());
            }
            None => {}
        }
        // (the rows' consistent values of index-2 unknowns go on from the same points)
        let step_ends = match self.step_ends.as_mut() {
            Some(se) => se.restore_carried(&snap.step_ends),
            None => snap.step_ends.is_empty(),
        };
        if !step_ends {
            return bad(
                "its index-2 unknowns are not this model's: the checkpoint is of another model"
                    .into(),
            );
        }
        self.steps = snap.steps;
        self.cycles_run = snap.cycles_run;
        self.periodic_error = snap.periodic_error;
        self.prev_cycle_end.copy_from_slice(&snap.prev_cycle_end);
        self.rec.restore(snap)
    }

    /// One cycle; Ok(false) when the run is complete. A solver failure names its cause where
    /// the state shows one (a negative incremental resistance: `stability::growth`).
    fn cycle(&mut self, cycle: usize, progress: &mut dyn FnMut(f64, f64) -> bool) -> Result<bool> {
        self.cycle_steps(cycle, progress).map_err(|e| match e {
            Error::Solver { time, message } => {
                let cause = growth::cause_at(self.state.dae, &self.state.y);
                Error::Solver {
                    time,
                    message: message + &cause,
                }
            }
            e => e,
        })
    }

    fn cycle_steps(
        &mut self,
        cycle: usize,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<bool> {
        let s = self.s;
        let last = cycle + 1 == self.max_cycles;
        // rows certain to be output can go to the sink as they come; a cycle that may still be
        // superseded by the next (last-cycle output with `until_periodic`) waits for its end
        let committed = s.output_all_cycles || last;
        let open_ended = s.until_periodic.is_some() || s.svzerod.cycle_mean_stop.is_some();
        let rows = CycleRows {
            t0: cycle as f64 * s.period,
            committed,
            recorded: committed || open_ended || s.keep_current_cycle,
            species: s.output_all_cycles || open_ended || last,
        };
        if !s.output_all_cycles {
            self.rec.clear();
        }
        if let Some(m) = self.mean.as_deref_mut() {
            m.start_cycle(self.steps_per_cycle);
            if let Some(scout) = m.scout.as_mut().filter(|_| cycle == 0) {
                let st = &self.state;
                scout.start(&st.y, &st.yd, st.dt, self.steps_per_cycle);
            }
        }
        if let Some(se) = self.step_ends.as_mut().filter(|se| !se.started()) {
            se.start(rows.t0, &self.state.y);
        }
        if rows.recorded && (!s.output_all_cycles || cycle == 0) {
            let t = rows.output_time(rows.t0, s.output_all_cycles);
            self.output_row(t, rows.t0, true, committed)?;
        }
        if self.keeps_cycle_start() {
            self.last_start = Some(self.cycle_start_state(rows.t0));
        }
        if let Some(mut ex) = self.explicit.take() {
            let done = self.explicit_cycle(&mut ex, &rows, progress);
            self.explicit = Some(ex);
            done?;
        } else if self.adaptive.is_some() {
            let mut ad = self.adaptive.take().expect("error control");
            let done = self.adaptive_cycle(&mut ad, &rows, progress);
            self.adaptive = Some(ad);
            done?;
        } else {
            for k in 1..=self.steps_per_cycle {
                self.step(k, &rows, progress)?;
            }
        }
        self.cycles_run = cycle + 1;
        self.end_cycle()
    }

    /// Step `k` of the cycle, and its output row when due.
    fn step(
        &mut self,
        k: usize,
        rows: &CycleRows,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<()> {
        let dt = self.state.dt;
        // the flow and species passes of the step in one entry of the run's pool
        let t = self.steps as f64 * dt;
        let work = self.state.work();
        let done = crate::threads::in_pool_for(work, || self.state.advance(t));
        self.steps += 1;
        let t_new = self.steps as f64 * dt;
        done?;
        if let Some(se) = self.step_ends.as_mut() {
            se.stepped(t, dt, &self.state.y);
        }
        if let Some(m) = self.mean.as_deref_mut() {
            m.accumulate(&self.state.y);
        }
        if let Some(d) = self.derived.as_mut() {
            d.after_step(&self.state.y, dt);
        }
        if let Some(m) = self.cycle_means.as_mut() {
            m.add(&self.state.y);
        }
        if k % 64 == 0 || k == self.steps_per_cycle {
            self.state.check(t_new)?;
        }
        // last-cycle output counts from the cycle start (svZeroDSolver's convention), so the
        // output times do not depend on how many cycles ran
        let all = self.s.output_all_cycles;
        let due = if all { self.steps } else { k } % self.stride == 0;
        if due && rows.recorded {
            let t = rows.output_time(t_new, all);
            self.output_row(t, t_new, rows.species, rows.committed)?;
            if !self.released {
                // the setup's (and a first pass's) freed memory, and the first steps' and
                // observations' scratch, would stay resident under the output table the
                // loop grows from here: hand it back once (see `heap`)
                self.released = true;
                super::heap::release_free_pages(self.state.dae.n);
            }
        }
        if self.steps % 256 == 0 && !progress(t_new, self.t_end()) {
            return Err(Error::Interrupted { time: t_new });
        }
        Ok(())
    }

    /// One cycle of an error-controlled run (docs/physics.md §10): steps chosen by the local
    /// error estimate, the last one ending on the cycle's end, output rows from the dense
    /// output at the cycle's output times.
    fn adaptive_cycle(
        &mut self,
        ad: &mut Adaptive,
        rows: &CycleRows,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<()> {
        let period = self.s.period;
        let (t0, t_end) = (rows.t0, rows.t0 + period);
        let n_out = ad.out_per_cycle;
        let mut next_out = 1;
        let mut t = t0;
        let near = self.s.until_periodic.is_some()
            && self
                .s
                .adaptive()
                .is_some_and(|tol| self.periodic_error < NEAR_PERIODIC * tol.rtol);
        self.periodic_steps.start_cycle(near);
        self.cycle_start = t0;
        if self.events.is_none() {
            ad.scout(&mut self.state, t0, period);
        }
        // the error control's scales: the previous cycle's and this one's largest values
        ad.start_cycle(&self.state.y);
        self.breakpoints.start_cycle(t0, t_end);
        // (a small circuit's step stays on this thread: `threads::in_pool_for`)
        let work = self.state.work();
        // a step taken again to end on a valve event
        let mut cut: Option<Cut> = None;
        let mut retry = Retry::default();
        while t < t_end {
            let rem = t_end - t;
            // the last step ends on the cycle's end, and a step on each corner of the forcing;
            // a remainder under two steps is halved
            let corner = self.breakpoints.next_after(t);
            let to_corner = corner.map_or(rem, |c| c - t);
            let h = if let Some(c) = cut {
                c.h
            } else if let Some(h) = self.periodic_steps.step(rem) {
                toward_corner(h, to_corner, true)
            } else {
                toward_corner(ad.h, to_corner, false)
            };
            let replayed = self.periodic_steps.replaying();
            // the flow step and its estimate in one entry of the run's pool
            let stepped = crate::threads::in_pool_for(work, || {
                ad.save_start(&mut self.state);
                let stepped = self.state.advance_flow(t, h, ad.start());
                stepped.map(|()| ad.judge_flow(&mut self.state, h))
            });
            let (err, kinds) = match stepped {
                Ok(judged) => judged,
                Err(e) => match retry.failed(h, (ad.h_min(), ad.h_max())) {
                    OnFailure::Damp => {
                        // the same step again, Newton with its line search
                        ad.restore(&mut self.state);
                        self.state.flow.integrator().set_damped_newton(true);
                        ad.rejected += 1;
                        ad.h = h;
                        continue;
                    }
                    OnFailure::Leap(h_leap) => {
                        ad.restore(&mut self.state);
                        ad.rejected += 1;
                        ad.h = h_leap;
                        cut = None;
                        continue;
                    }
                    OnFailure::Shrink => (f64::INFINITY, [0.0; 3]),
                    OnFailure::GiveUp => {
                        return Err(given_up(e, (ad.h_min(), ad.h_max()), period));
                    }
                },
            };
            let kept = replayed && self.periodic_steps.keeps(err);
            let leap = retry.leaping();
            if err > 1.0 && h > ad.h_min() && !kept && !leap {
                ad.restore(&mut self.state);
                ad.reject(h, err);
                cut = None;
                continue;
            }
            let next = match self.events.as_ref() {
                Some(ev) => {
                    let (y, yd) = (&self.state.y, &self.state.yd);
                    let at = |th: f64| {
                        let d = ad.dense(th, h, y, yd);
                        move |i: usize| d.value(i)
                    };
                    let found = ev.locate(&|i| y[i], at, ad.rtol());
                    match found {
                        // a leap's step is not cut (a shorter one did not converge): its
                        // valve switches at its end
                        Some(loc) if leap => Next::Switch(loc.switch, ad.h),
                        _ => decide(found, (h, ad.h_min(), ad.rtol()), ad.h, cut.take()),
                    }
                }
                None => Next::Go,
            };
            if let Next::Redo(c) = next {
                ad.restore(&mut self.state);
                // an event moves the cycle's steps: the controller takes over from here
                self.periodic_steps.stop();
                cut = Some(c);
                continue;
            }
            if retry.accepted() {
                self.state.flow.integrator().set_damped_newton(false);
            }
            if let Some(ev) = self.events.as_ref() {
                let st = &mut self.state;
                ev.hold_closed(&mut st.y, &mut st.yd);
                ad.state_changed();
            }
            self.periodic_steps.accepted(h);
            let t_new = if h == rem { t_end } else { t + h };
            // (a step that ends on a corner ends on it exactly)
            let at_corner = corner.filter(|_| h == to_corner);
            let t_new = at_corner.unwrap_or(t_new);
            let mut peek = next_out;
            if rows.recorded
                && rows.species
                && rows.due(period, n_out, &mut peek, t_new).count() > 0
            {
                ad.keep_species_start(&self.state);
            }
            crate::threads::in_pool_for(work, || {
                self.state.advance_species(t, h)?;
                ad.after_species(&self.state, h);
                Ok::<(), Error>(())
            })?;
            for tau in rows.due(period, n_out, &mut next_out, t_new) {
                self.dense_row(ad, rows, (tau - t) / h, h, tau)?;
            }
            // the estimates and the next step's size in one entry of the run's pool
            crate::threads::in_pool_for(work, || ad.accept(&self.state, h, err, kinds));
            let restarted = leap || matches!(next, Next::Switch(..)) || at_corner.is_some();
            if leap {
                // the solution jumped within the leap: the estimates start again after it
                ad.restart(ad.h.min(h));
            }
            if at_corner.is_some() {
                // the extrapolation through the last states would straddle the corner: the
                // estimates start again from it, at the step the controller proposed
                ad.restart(ad.h);
            }
            match next {
                Next::Switch(k, proposed) => {
                    self.switch_valves(k, t_new);
                    // the error history straddles the kink: the controller starts again,
                    // from the step it proposed before the event
                    ad.restart(proposed);
                }
                Next::Approach(h_next) => {
                    ad.h = ad.h.min(h_next);
                    self.settle_events();
                }
                _ => self.settle_events(),
            }
            if let Some(se) = self.step_ends.as_mut() {
                se.stepped(t, h, &self.state.y);
                if restarted {
                    se.start(t_new, &self.state.y);
                }
            }
            self.steps += 1;
            t = t_new;
            if ad.steps % 64 == 0 || t == t_end {
                self.state.check(t)?;
            }
            if self.steps % 256 == 0 && !progress(t, self.t_end()) {
                return Err(Error::Interrupted { time: t });
            }
        }
        if retry.damping() {
            self.state.flow.integrator().set_damped_newton(false);
        }
        Ok(())
    }

    /// A step without an event was accepted.
    pub(super) fn settle_events(&mut self) {
        if let Some(ev) = self.events.as_mut() {
            ev.settle(&self.state.y);
        }
    }

    /// Switch valve `k` at `time` (the step just taken ends on its event), and every other
    /// valve the state there finds switched too.
    pub(super) fn switch_valves(&mut self, k: usize, time: f64) {
        let Some(ev) = self.events.as_mut() else {
            return;
        };
        let st = &mut self.state;
        ev.settle(&st.y);
        ev.switch(k, time, &mut st.y, &mut st.yd);
        let y = &st.y;
        for other in ev.due_at(&|i| y[i]) {
            if other != k {
                ev.switch(other, time, &mut st.y, &mut st.yd);
            }
        }
    }

    /// The output row at `time`, θ into the step of `h` just taken: the probes from the
    /// dense output, the species outputs of the interpolated state.
    fn dense_row(
        &mut self,
        ad: &mut Adaptive,
        rows: &CycleRows,
        theta: f64,
        h: f64,
        time: f64,
    ) -> Result<()> {
        if !rows.recorded {
            return Ok(());
        }
        let t = rows.output_time(time, self.s.output_all_cycles);
        let theta = theta.clamp(0.0, 1.0);
        let (y, yd) = (&self.state.y[..], &self.state.yd[..]);
        (self.rec).record_row(t, |probes, out| {
            ad.dense_row((theta, h), (y, yd), probes, out);
        })?;
        if rows.species && self.state.species.is_some() {
            // the interpolation and the observation in one entry of the run's pool
            self.obs_row.reserve_exact(self.obs_len);
            let (state, row) = (&mut self.state, &mut self.obs_row);
            crate::threads::in_pool(|| {
                let (yi, ydi, zi, vi) = ad.interpolate_all(theta, h, state);
                state.observe_at(time, yi, ydi, zi, vi, row)
            })?;
            self.push_observed();
        }
        if rows.committed && !self.rec.flush(false) {
            return Err(Error::Interrupted { time });
        }
        Ok(())
    }

    /// Record the state at `time` as the row at output time `t`, with its species outputs when
    /// `species`; a `committed` row goes on to the sink once a chunk is full.
    fn output_row(&mut self, t: f64, time: f64, species: bool, committed: bool) -> Result<()> {
        // (the index-2 unknowns' consistent values in the row, the run's own back after it)
        if let Some(se) = self.step_ends.as_mut() {
            se.substitute(time, &mut self.state.y);
        }
        let recorded = self.rec.record(t, &self.state.y);
        if let Some(se) = self.step_ends.as_ref() {
            se.restore(&mut self.state.y);
        }
        recorded?;
        if let Some(d) = &self.derived {
            self.rec.record_extra(d.value.iter().copied());
        }
        if self.s.svzerod.rates {
            self.record_rates(time)?;
        }
        if species && self.state.species.is_some() {
            // the row's observation passes in one entry of the run's pool
            self.obs_row.reserve_exact(self.obs_len);
            let (state, row) = (&mut self.state, &mut self.obs_row);
            crate::threads::in_pool(|| state.observe(time, row))?;
            self.push_observed();
        }
        if committed && !self.rec.flush(false) {
            return Err(Error::Interrupted { time });
        }
        Ok(())
    }

    /// The recorder's species columns of the observation just made. A large observation row
    /// is then freed, not kept between rows: it holds every species column of every output
    /// vessel (and segment, when recorded), ~12 bytes per segment of a 1e6-segment tree's
    /// large-model output, beside the recorder's own selection, through every step of the
    /// run; the next row allocates its remembered length at once (no growth by doubling).
    /// A small one keeps its length only (the first row grew it by doubling).
    fn push_observed(&mut self) {
        self.rec.push_species(&self.obs_row);
        self.obs_len = self.obs_row.len();
        if self.obs_len >= OBSERVATION_KEPT_MAX {
            self.obs_row = Vec::new();
        } else {
            self.obs_row.shrink_to_fit();
        }
    }

    /// The rates of the probes and derived columns (svZeroDSolver's `output_derivative`):
    /// generalized-α's carried ẏ, or the rate RK4 evaluates at the state (its algebraic
    /// unknowns included), on a copy so that the run is not touched.
    fn record_rates(&mut self, time: f64) -> Result<()> {
        let ig = self.state.flow.integrator();
        let yd = if ig.rate_is_carried() {
            &self.state.yd
        } else {
            let (y, yd) = &mut self.rate_scratch;
            y.clone_from(&self.state.y);
            yd.resize(y.len(), 0.0);
            ig.full_rate(time, y, yd)?;
            if let Some(d) = self.derived.as_mut() {
                d.exact_rates(y, yd);
            }
            &self.rate_scratch.1
        };
        let derived = self.derived.as_ref().map_or(&[][..], |d| &d.rate[..]);
        let rates = self.s.probes.iter().map(|&i| yd[i]);
        self.rec.record_extra(rates.chain(derived.iter().copied()));
        Ok(())
    }

    /// Close a cycle: the periodicity error and the first pass's mean flow. False when the run
    /// is complete (mean flow settled, or periodic after the minimum cycles).
    fn end_cycle(&mut self) -> Result<bool> {
        let y = &self.state.y;
        // the change y − y_prev in place of y_prev (no state-sized copy at the end of the run,
        // when the whole output table is held), then y_prev = y
        for (p, a) in self.prev_cycle_end.iter_mut().zip(y) {
            *p = a - *p;
        }
        self.periodic_error = scaled_increment(self.state.dae, &self.prev_cycle_end, y);
        self.prev_cycle_end.copy_from_slice(y);
        if self.mean.as_deref_mut().is_some_and(MeanAbs::end_cycle) {
            return Ok(false);
        }
        if let Some(m) = self.cycle_means.as_mut() {
            let stop = m.end_cycle(y, self.cycles_run, self.s.cycles)?;
            return Ok(!stop);
        }
        if let Some(sp) = self.state.species.as_mut() {
            // species need several transit times: include them in the periodicity test
            self.periodic_error = self.periodic_error.max(sp.cycle_change());
        }
        Ok(match self.s.until_periodic {
            Some(tol) => !(self.cycles_run >= self.s.cycles && self.periodic_error < tol),
            None => true,
        })
    }
}
