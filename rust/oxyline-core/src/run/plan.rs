//! Everything decided before the first step: the integrator (probing RK4's stability limit
//! for `rk4` and `auto`), the step, the steps per cycle and output stride, the initial state,
//! and the integrator itself. The steady state comes from the caller's [`SteadyCache`], so the
//! two passes of a transport run solve it once.

use super::coupling::{Flow, RK4_UPWIND_COURANT};
use super::settings::{Method, RunSettings, Start};
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::integrate::explicit_pair::Dopri5;
use crate::integrate::genalpha::GenAlpha;
use crate::integrate::periodic;
use crate::integrate::rk4::Rk4;
use crate::integrate::stability::{SpectrumMethod, StabilityLimit, rk4_limit_probed};
use crate::integrate::steady::SteadyCache;
use crate::transport::{Formulation, Transport};

pub(super) struct Plan<'d> {
    dae: &'d Dae,
    pub use_rk4: bool,
    /// An error-controlled run with the explicit pair: its step ceiling.
    pub explicit: Option<f64>,
    /// RK4's stability limit, when it was probed (`rk4` and `auto`).
    pub stability: Option<StabilityLimit>,
    /// The step: a whole fraction of the period.
    pub dt: f64,
    pub steps_per_cycle: usize,
    /// Steps per output row.
    pub stride: usize,
    /// The RK4 integrator built for the stability probe, reused for the run and for the
    /// consistent start (the probe's linearisation only affects the probe).
    rk4: Option<Rk4<'d>>,
}

impl<'d> Plan<'d> {
    /// Choose the integrator and the step. A transport run limits RK4's automatic step by the
    /// upwind Courant number of the mean flow (see [`transport_step_limit`]).
    /// `progress(t, t_end)` is asked during RK4's stability estimate (false: interrupted).
    pub fn new(
        dae: &'d Dae,
        steady: &SteadyCache<'_>,
        s: &RunSettings,
        transport: Option<&mut Transport>,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<Self> {
        let quasi = transport
            .as_deref()
            .is_some_and(|t| t.formulation() == Formulation::TlQuasisteady);
        let (transport_dt, reaction) = transport_step_limit(dae, steady, transport);
        if s.adaptive().is_some() {
            // error control: generalized-α or the explicit pair, its steps chosen during the
            // run; the plan's step is only the quasi-steady transport's start (docs/physics.md
            // §10)
            let t_end = s.max_cycles() as f64 * s.period;
            let mut go = || progress(0.0, t_end);
            let explicit = super::explicit::choose(dae, steady, s, (transport_dt, quasi), &mut go)?;
            let out_per_cycle = (s.period / s.output_every).round().max(1.0) as usize;
            return Ok(Plan {
                dae,
                use_rk4: false,
                explicit: explicit.as_ref().map(|e| e.ceiling),
                stability: explicit.map(|e| e.stability),
                dt: s.period / 1000.0,
                steps_per_cycle: out_per_cycle,
                stride: 1,
                rk4: None,
            });
        }
        let t_end = s.max_cycles() as f64 * s.period;
        let mut go = || progress(0.0, t_end);
        let (use_rk4, stability, rk4) = choose_method(dae, steady, s, transport_dt, &mut go)?;
        let rk4_limit = stability.as_ref().filter(|_| use_rk4);
        let (dt, steps_per_cycle, stride) = schedule(s, rk4_limit, transport_dt)?;
        if let Some(lim) = reaction.filter(|_| use_rk4 && s.dt.is_some()) {
            // a user's step must also keep the species' own stiffness stable, as the flow's
            // (its own limit); the automatic step keeps half of it
            check_stable(dt, &lim)?;
        }
        Ok(Plan {
            dae,
            use_rk4,
            explicit: None,
            stability,
            dt,
            steps_per_cycle,
            stride,
            rk4,
        })
    }

    /// The method's name as reported in the outcome.
    pub fn method_name(&self) -> &'static str {
        if self.explicit.is_some() {
            crate::integrate::explicit_pair::NAME
        } else if self.use_rk4 {
            "rk4"
        } else {
            "generalized-alpha"
        }
    }

    /// The initial (y, ẏ) of `s.start`.
    pub fn initial_state(
        &mut self,
        steady: &SteadyCache<'_>,
        s: &RunSettings,
    ) -> Result<(Vec<f64>, Vec<f64>)> {
        let (dae, n) = (self.dae, self.dae.n);
        let (mut y, mut yd) = match s.start {
            Start::Zero => (dae.initial_state(), vec![0.0; n]),
            Start::SvZeroDZero => (dae.initial_state(), dae.initial_rate_state()),
            // a circuit with chambers (a heart, a closed loop) has no steady state of its mean
            // boundary conditions: its `steady` start is the zero state with the chambers'
            // initial volumes, made consistent below (docs/physics.md §1.8)
            Start::Steady | Start::Periodic if dae.has_chambers() => {
                (dae.initial_state(), vec![0.0; n])
            }
            Start::Steady => steady_start(dae, steady.get()?),
            Start::Periodic if !periodic::applies(dae) => steady_start(dae, steady.get()?),
            Start::Periodic => steady_start(
                dae,
                &periodic::periodic_state(dae, steady.get()?, s.period)?,
            ),
            Start::SvZeroDSteady { rho_inf } => svzerod_steady_start(dae, s, rho_inf)?,
        };
        if matches!(s.start, Start::Zero | Start::Steady | Start::Periodic) && !self.use_rk4 {
            self.make_consistent(&mut y, &mut yd);
        }
        Ok((y, yd))
    }

    /// The algebraic unknowns (e.g. the pressure before a resistance fed by the inflow) follow
    /// the forcing at t = 0, and ẏ of the differential ones is the circuit's own; an index-2
    /// circuit (RK4 refuses it) keeps the start as given. (An RK4 run makes its start
    /// consistent when its integrator is built.)
    fn make_consistent(&mut self, y: &mut Vec<f64>, yd: &mut Vec<f64>) {
        if self.rk4.is_none() {
            self.rk4 = Rk4::new(self.dae, Regime::Transient, self.dt).ok();
        }
        if let Some(rk) = self.rk4.as_mut() {
            let mut yc = y.clone();
            if let Ok(d) = rk
                .make_consistent(0.0, &mut yc)
                .and_then(|_| rk.derivative(0.0, &mut yc))
            {
                *y = yc;
                *yd = d;
            }
        }
    }

    /// The run's flow integrator; an RK4 start `y` is made consistent with the forcing at 0.
    /// With `monolithic`, RK4 carries the species in its own stages (see [`Flow`]).
    pub fn flow(&mut self, s: &RunSettings, y: &mut [f64], monolithic: bool) -> Result<Flow<'d>> {
        if self.explicit.is_some() {
            let mut rk = match self.rk4.take() {
                Some(rk) => rk,
                None => Rk4::new(self.dae, Regime::Transient, self.dt)?,
            };
            rk.make_consistent(0.0, y)?;
            return Ok(Flow::Explicit(Box::new(Dopri5::new(rk))));
        }
        if !self.use_rk4 {
            // the RK4 integrator of the consistent start (or of the stability probe) is not
            // needed again: drop it before the run's own integrator is built
            self.rk4 = None;
            let ga = GenAlpha::new(
                self.dae,
                Regime::Transient,
                self.dt,
                s.method.rho_inf(),
                s.newton,
            )?;
            return Ok(Flow::Split(Box::new(ga)));
        }
        let mut rk = match self.rk4.take() {
            Some(rk) => rk,
            None => Rk4::new(self.dae, Regime::Transient, self.dt)?,
        };
        rk.dt = self.dt;
        rk.make_consistent(0.0, y)?;
        Ok(if monolithic {
            Flow::Monolithic(Box::new(rk))
        } else {
            Flow::Split(Box::new(rk))
        })
    }
}

/// Explicit upwind transport is stable for Courant numbers up to 1.3926 (docs/physics.md §1.5), a
/// limit the flow eigenvalues do not see. The automatic step keeps the Courant number of the
/// mean flow below 0.5 × 1.39 / 3 (pulsatile peaks of up to 3× the mean); the run itself
/// monitors the actual value. The species' own stiffness (wall exchange, decay: real negative
/// rates, RK4's real-axis limit 2.785) is kept at half its limit too (see
/// `Transport::max_reaction_rate`). Infinite without transport, without a steady state, or with
/// a non-positive volume there (left to the run to report).
///
/// Also returns the species' stability limit itself (RK4 on the stiffest cell: dt ≤ 2.785 /
/// rate), naming the species and the vessel, which a user-given RK4 step must respect: only
/// for explicit transport (the quasi-steady formulation's species step is implicit).
fn transport_step_limit(
    dae: &Dae,
    steady: &SteadyCache<'_>,
    transport: Option<&mut Transport>,
) -> (f64, Option<StabilityLimit>) {
    let (Some(tr), Ok(y)) = (transport, steady.get()) else {
        return (f64::INFINITY, None);
    };
    let mut limit = f64::INFINITY;
    if tr.formulation() == Formulation::Conservative {
        let rate = tr.max_outflow_rate(y, 0.0);
        if rate > 0.0 && rate.is_finite() {
            limit = 0.5 * RK4_UPWIND_COURANT / (3.0 * rate);
        }
    }
    let mut species_limit = None;
    if let Some(r) = tr.max_reaction_rate(y, 0.0).filter(|r| r.rate.is_finite()) {
        limit = limit.min(0.5 * RK4_REAL_AXIS / r.rate);
        let vessel = tr
            .cell_vessel(r.cell)
            .and_then(|v| dae.names.vessel(v))
            .map_or_else(|| "a junction cell".to_owned(), |v| format!("vessel '{v}'"));
        species_limit = (tr.formulation() != Formulation::TlQuasisteady).then(|| StabilityLimit {
            dt_max: RK4_REAL_AXIS / r.rate,
            eigenvalue: (-r.rate, 0.0),
            element: format!(
                "species '{}' in {vessel} (wall exchange and decay rate {:.4e} 1/s)",
                r.species, r.rate
            ),
            exact: true,
        });
    }
    (limit, species_limit)
}

/// RK4's stability limit on the negative real axis: |R(−2.785)| = 1.
const RK4_REAL_AXIS: f64 = 2.785;

/// RK4 or generalized-α, RK4's stability limit (probed for `rk4` and `auto`) and the RK4
/// integrator built for the probe. `auto` takes RK4 when its stable step is at least 1/20 of
/// the output step.
fn choose_method<'d>(
    dae: &'d Dae,
    steady: &SteadyCache<'_>,
    s: &RunSettings,
    transport_dt: f64,
    go: &mut dyn FnMut() -> bool,
) -> Result<(bool, Option<StabilityLimit>, Option<Rk4<'d>>)> {
    let mut use_rk4 = matches!(s.method, Method::Rk4);
    if !matches!(s.method, Method::Rk4 | Method::Auto { .. }) {
        return Ok((use_rk4, None, None));
    }
    let mut stability = None;
    let mut probe = Rk4::new(dae, Regime::Transient, 1.0);
    match (&mut probe, s.method) {
        (Ok(rk), _) => {
            if !dae.is_linear() {
                // stenoses stiffen their branches in proportion to the flow: linearise at the
                // steady state of the mean boundary conditions
                if let Ok(ys) = steady.get() {
                    rk.set_linearization(ys)?;
                }
            }
            let lim = rk4_limit_probed(rk, &dae.names, SpectrumMethod::Auto, go)?;
            if let Method::Auto { .. } = s.method {
                use_rk4 = (0.5 * lim.dt_max).min(transport_dt) >= s.output_every / 20.0;
            }
            stability = Some(lim);
        }
        (Err(e), Method::Rk4) => return Err(e.clone()),
        (Err(_), _) => use_rk4 = false,
    }
    Ok((use_rk4, stability, probe.ok()))
}

/// (dt, steps per cycle, output stride): a whole number of steps per cycle and per output
/// interval. `rk4_limit` is set when the run is RK4 (its step must stay below the limit).
fn schedule(
    s: &RunSettings,
    rk4_limit: Option<&StabilityLimit>,
    transport_dt: f64,
) -> Result<(f64, usize, usize)> {
    let out_per_cycle = (s.period / s.output_every).round().max(1.0) as usize;
    let dt = match (rk4_limit, s.dt) {
        (Some(lim), Some(dt)) => {
            check_stable(dt, lim)?;
            dt
        }
        (Some(lim), None) => (0.5 * lim.dt_max).min(s.output_every).min(transport_dt),
        (None, dt) => dt.unwrap_or(s.output_every),
    };
    check_step_count(s, dt, rk4_limit)?;
    let substeps = ((s.period / out_per_cycle as f64) / dt * (1.0 - 1e-12))
        .ceil()
        .max(1.0) as usize;
    let (steps_per_cycle, stride) = if s.dt.is_some() {
        let spc = (s.period / dt).round().max(1.0) as usize;
        let stride = (s.output_every / (s.period / spc as f64)).round().max(1.0) as usize;
        (spc, stride)
    } else {
        (out_per_cycle * substeps, substeps)
    };
    let dt = s.period / steps_per_cycle as f64;
    if let Some(lim) = rk4_limit {
        check_stable(dt, lim)?;
    }
    Ok((dt, steps_per_cycle, stride))
}

/// The most steps a run may plan per cycle. A step this small comes from a degenerate
/// stability limit (e.g. a negative stenosis coefficient, an element with a vanishing
/// capacitance) or a mistyped `dt`; such a run would not end, so it is refused before the
/// first step, naming what set the step.
pub const MAX_STEPS_PER_CYCLE: f64 = 1e9;

fn check_step_count(s: &RunSettings, dt: f64, rk4_limit: Option<&StabilityLimit>) -> Result<()> {
    let planned = s.period / dt;
    if planned <= MAX_STEPS_PER_CYCLE {
        return Ok(());
    }
    let by = match (s.dt, rk4_limit) {
        (Some(_), _) => "the requested dt".to_owned(),
        (None, Some(lim)) => format!("RK4's stability limit, set by {}", lim.element),
        (None, None) => "the output interval".to_owned(),
    };
    Err(Error::Resource {
        what: format!("time step {dt:.3e} s ({by})"),
        bytes: 0,
        message: format!(
            "{planned:.3e} steps per cycle of {} s, more than the {MAX_STEPS_PER_CYCLE:.0e} a \
             run may plan; check that element's parameters, or use a larger dt or method \
             'generalized-alpha'",
            s.period
        ),
    })
}

fn check_stable(dt: f64, lim: &StabilityLimit) -> Result<()> {
    if dt > lim.dt_max * (1.0 + 1e-9) {
        return Err(Error::Unstable {
            dt,
            limit: lim.dt_max,
            element: lim.element.clone(),
        });
    }
    Ok(())
}

/// The state `ys` (steady or periodic), with the ẏ that the transient forcing at t = 0 gives it.
fn steady_start(dae: &Dae, ys: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = dae.n;
    let y = ys.to_vec();
    let mut f = vec![0.0; n];
    dae.forcing_into(0.0, Regime::Transient, &mut f);
    let mut r = vec![0.0; n];
    dae.static_residual(&y, &f, &mut r);
    dae.element_residual(0.0, &y, &mut r);
    let yd = (0..n)
        .map(|i| {
            if dae.e[i] != 0.0 {
                r[i] / dae.e[i]
            } else {
                0.0
            }
        })
        .collect();
    (y, yd)
}

/// svZeroDSolver's steady start: 31 generalized-α steps of T/10 from zero with the mean
/// boundary conditions and no Windkessel capacitance.
fn svzerod_steady_start(dae: &Dae, s: &RunSettings, rho_inf: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let h = s.period / 10.0;
    let mut ga = GenAlpha::new(dae, Regime::SteadyNoWindkessel, h, rho_inf, s.newton)?;
    // svZeroDSolver starts its steady iterations from the user's initial condition
    let (mut y, mut yd) = (dae.initial_state(), dae.initial_rate_state());
    for i in 0..31 {
        ga.step(h * i as f64, &mut y, &mut yd)?;
    }
    Ok((y, yd))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::newton::NewtonControl;

    fn settings(dt: Option<f64>, output_every: f64) -> RunSettings {
        RunSettings {
            method: Method::GeneralizedAlpha { rho_inf: 0.5 },
            dt,
            period: 1.0,
            cycles: 1,
            until_periodic: None,
            max_cycles: 1,
            output_every,
            output_all_cycles: false,
            keep_current_cycle: false,
            start: Start::Zero,
            newton: NewtonControl::default(),
            probes: Vec::new(),
            species_columns: None,
            tolerances: None,
            svzerod: Default::default(),
            finer_last_cycle: None,
        }
    }

    fn limit(dt_max: f64) -> StabilityLimit {
        StabilityLimit {
            dt_max,
            eigenvalue: (-1.0, 0.0),
            element: "branch a".into(),
            exact: true,
        }
    }

    #[test]
    fn steps_divide_the_period_and_the_output_interval() {
        // implicit, automatic step: the output step, 100 per cycle, every step output
        assert_eq!(
            schedule(&settings(None, 0.01), None, f64::INFINITY).unwrap(),
            (0.01, 100, 1)
        );
        // a given 3 ms becomes 1/333 s (333 steps per cycle), output every 3 steps (≈ 10 ms)
        let (dt, spc, stride) = schedule(&settings(Some(3e-3), 0.01), None, f64::INFINITY).unwrap();
        assert_eq!((spc, stride), (333, 3));
        assert_eq!(dt, 1.0 / 333.0); // the period over the steps: the same one division

        // RK4, automatic: at most half the stability limit (4 ms), so ceil(10 / 4) = 3 steps
        // per 10 ms output interval, 1/300 s
        let (dt, spc, stride) =
            schedule(&settings(None, 0.01), Some(&limit(8e-3)), f64::INFINITY).unwrap();
        assert_eq!((spc, stride), (300, 3));
        assert_eq!(dt, 1.0 / 300.0);
        // the transport Courant limit (1 ms) wins over the flow's
        let (_, spc, stride) = schedule(&settings(None, 0.01), Some(&limit(8e-3)), 1e-3).unwrap();
        assert_eq!((spc, stride), (1000, 10));
    }

    #[test]
    fn an_rk4_step_above_the_limit_is_refused_naming_the_element() {
        let e = schedule(
            &settings(Some(2e-3), 0.01),
            Some(&limit(1e-3)),
            f64::INFINITY,
        );
        assert_eq!(
            e.unwrap_err(),
            Error::Unstable {
                dt: 2e-3,
                limit: 1e-3,
                element: "branch a".into()
            }
        );
    }

    #[test]
    fn a_step_count_no_run_can_take_is_refused_naming_what_set_it() {
        // RK4's automatic step from a degenerate limit (1.6e-18 s): 3e17 steps per cycle
        let e = schedule(&settings(None, 0.01), Some(&limit(3.2e-18)), f64::INFINITY);
        match e.unwrap_err() {
            Error::Resource { what, message, .. } => {
                assert!(what.contains("branch a"), "{what}");
                assert!(message.contains("steps per cycle"), "{message}");
            }
            other => panic!("expected a resource error, got {other:?}"),
        }
        // a mistyped dt
        let e = schedule(&settings(Some(1e-15), 0.01), None, f64::INFINITY).unwrap_err();
        assert!(matches!(&e, Error::Resource { what, .. } if what.contains("requested dt")));
        // the largest count a run may plan still runs
        let ok = schedule(
            &settings(Some(1.0 / MAX_STEPS_PER_CYCLE), 0.01),
            None,
            f64::INFINITY,
        );
        assert_eq!(ok.unwrap().1 as f64, MAX_STEPS_PER_CYCLE);
    }
}
