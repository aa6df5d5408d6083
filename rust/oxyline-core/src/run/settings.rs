//! What the caller asks of a run, and the checks that make a bad request a typed error.

use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::integrate::adaptive::Tolerances;
use crate::integrate::newton::NewtonControl;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    Rk4,
    GeneralizedAlpha {
        rho_inf: f64,
    },
    /// Implicit when the stable RK4 step is far below the output step, else RK4; under error
    /// control, the explicit pair or generalized-α by predicted cost (`run::explicit`).
    Auto {
        rho_inf: f64,
    },
    /// Dormand–Prince 5(4) under error control (`integrate::explicit_pair`).
    Dopri5,
}

impl Method {
    /// ρ∞ of generalized-α when this method runs implicitly.
    pub(super) fn rho_inf(self) -> f64 {
        match self {
            Method::GeneralizedAlpha { rho_inf } | Method::Auto { rho_inf } => rho_inf,
            Method::Rk4 | Method::Dopri5 => 0.5,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// Exact steady solution of the mean boundary conditions.
    Steady,
    /// The periodic solution at t = 0 of a linear circuit, from the harmonics of its forcing
    /// (`integrate::periodic`); any other circuit starts as `Steady`.
    Periodic,
    /// svZeroDSolver's: 31 generalized-α steps of T/10 with mean BCs and no Windkessel C.
    SvZeroDSteady { rho_inf: f64 },
    /// Zero differential state; algebraic unknowns consistent with the forcing at t = 0.
    Zero,
    /// All-zero y and ẏ, as svZeroDSolver without `steady_initial`.
    SvZeroDZero,
}

#[derive(Debug, Clone)]
pub struct RunSettings {
    pub method: Method,
    /// Time step; None = automatic.
    pub dt: Option<f64>,
    pub period: f64,
    /// Cycles to run (the minimum when `until_periodic` is set).
    pub cycles: usize,
    /// Stop when the cycle-to-cycle change of the state falls below this (relative).
    pub until_periodic: Option<f64>,
    pub max_cycles: usize,
    /// Output interval in seconds (rounded to a whole number of steps).
    pub output_every: f64,
    pub output_all_cycles: bool,
    /// With last-cycle output, also record the cycles before the last (each is dropped when the
    /// next starts), so that a run stopped early returns its current cycle. Off, those cycles
    /// are not recorded at all: a streaming run then never holds a whole cycle of rows.
    pub keep_current_cycle: bool,
    pub start: Start,
    pub newton: NewtonControl,
    pub probes: Vec<usize>,
    /// Recorded columns of each species block of `Transport::observe` (see
    /// `crate::output::Selection::species_columns`); None records every column.
    pub species_columns: Option<Vec<usize>>,
    /// Error control (docs/physics.md §10): generalized-α with a variable step meeting these
    /// tolerances and output by dense output. None: the fixed step of `dt` (or `auto`).
    pub tolerances: Option<Tolerances>,
    /// svZeroDSolver's output and stop conventions (derived columns, rates, its
    /// cycle-to-cycle rule) asked by the drop-in; empty by default.
    pub svzerod: super::svzerod::SvZeroDRules,
    /// An error-controlled run's accumulated-error estimate (docs/solvers.md, "The
    /// accumulated error"): the last cycle is run again from its start at rtol over this
    /// factor and its output rows returned beside the run's (`ErrorControlOutcome::finer`).
    /// None: no second integration (the run is unchanged either way).
    pub finer_last_cycle: Option<f64>,
}

impl RunSettings {
    /// One cycle of period 1 s from the steady state, output every 10 ms of the last cycle
    /// (kept while it runs), every species column, fixed step `dt` (None: automatic): the run
    /// the tests and examples change a field or two of.
    pub fn one_cycle(method: Method, dt: Option<f64>, probes: Vec<usize>) -> Self {
        RunSettings {
            method,
            dt,
            period: 1.0,
            cycles: 1,
            until_periodic: None,
            max_cycles: 1,
            output_every: 1e-2,
            output_all_cycles: false,
            keep_current_cycle: true,
            start: Start::Steady,
            newton: NewtonControl::default(),
            probes,
            species_columns: None,
            tolerances: None,
            svzerod: Default::default(),
            finer_last_cycle: None,
        }
    }

    /// Refuse settings no run can honour, naming the offending value.
    pub(super) fn validate(&self, dae: &Dae) -> Result<()> {
        let bad = |what: String| Err(Error::model("simulation", what));
        if !(self.period.is_finite() && self.period > 0.0) {
            return bad(format!("period must be > 0, got {}", self.period));
        }
        if self.cycles == 0 {
            return bad("cycles must be >= 1".into());
        }
        if !(self.output_every.is_finite() && self.output_every > 0.0) {
            return bad(format!(
                "output every must be > 0, got {}",
                self.output_every
            ));
        }
        if let Some(dt) = self.dt.filter(|dt| !(dt.is_finite() && *dt > 0.0)) {
            return bad(format!("dt must be > 0, got {dt}"));
        }
        if let Some(tol) = &self.tolerances {
            validate_tolerances(tol, self)?;
        }
        if let (Method::Dopri5, Some(dt)) = (self.method, self.dt) {
            return bad(format!(
                "method 'dopri5' chooses its own steps (error control): give rtol, not dt = {dt}"
            ));
        }
        if let Some(p) = self.probes.iter().find(|&&p| p >= dae.n) {
            return bad(format!("output index {p} out of range"));
        }
        if let Some(f) = self
            .finer_last_cycle
            .filter(|f| !(f.is_finite() && *f > 1.0))
        {
            return bad(format!(
                "the time error's tolerance factor must be > 1, got {f}"
            ));
        }
        if !self.svzerod.is_empty() && self.adaptive().is_some() {
            return bad("svZeroDSolver's output conventions need a fixed step (dt)".into());
        }
        self.svzerod.validate(dae.n)
    }

    /// An error-controlled run: tolerances and no fixed step (`dopri5` without tolerances:
    /// rtol 1e-3 and the default atol).
    pub(super) fn adaptive(&self) -> Option<Tolerances> {
        if self.dt.is_some() {
            return None;
        }
        match (self.tolerances, self.method) {
            (None, Method::Dopri5) => Some(Tolerances {
                rtol: 1e-3,
                atol: Default::default(),
            }),
            (tol, _) => tol,
        }
    }

    /// The most cycles the run may take: `cycles`, or up to `max_cycles` while waiting for
    /// periodicity.
    pub(super) fn max_cycles(&self) -> usize {
        if let Some(stop) = &self.svzerod.cycle_mean_stop {
            self.cycles + stop.max_extra
        } else if self.until_periodic.is_some() {
            self.max_cycles.max(self.cycles)
        } else {
            self.cycles
        }
    }
}

/// rtol in (0, 1), every atol finite and > 0; error control runs generalized-α and excludes
/// a fixed `dt`.
fn validate_tolerances(tol: &Tolerances, s: &RunSettings) -> Result<()> {
    let bad = |what: String| Err(Error::model("simulation", what));
    if !(tol.rtol.is_finite() && tol.rtol > 0.0 && tol.rtol < 1.0) {
        return bad(format!("rtol must be > 0 and < 1, got {}", tol.rtol));
    }
    let kinds = crate::integrate::adaptive::KINDS;
    for (kind, a) in kinds.iter().zip(tol.atol.as_array()) {
        if !(a.is_finite() && a > 0.0) {
            return bad(format!("atol {kind} must be a finite number > 0, got {a}"));
        }
    }
    if let Some(dt) = s.dt {
        return bad(format!(
            "rtol (error control) and dt = {dt} (a fixed step) exclude each other: give one"
        ));
    }
    if matches!(s.method, Method::Rk4) {
        return bad(
            "rtol (error control) runs generalized-alpha: method 'rk4' needs a fixed dt".into(),
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::circuit::Circuit;
    use crate::waveform::Waveform;

    #[test]
    fn bad_settings_are_model_errors_naming_the_value() {
        let mut k = Circuit::default();
        let p = k.add_node("p", 1e-9, 0.0);
        let out = k.add_node("out", 0.0, 0.0);
        k.add_branch("drain", p, out, 1e8, 0.0, 0.0);
        k.fixed_pressures.push((out, Waveform::constant(0.0)));
        let dae = k.assemble().unwrap();
        let ok = RunSettings {
            method: Method::Rk4,
            dt: None,
            period: 1.0,
            cycles: 1,
            until_periodic: None,
            max_cycles: 1,
            output_every: 0.01,
            output_all_cycles: false,
            keep_current_cycle: false,
            start: Start::Zero,
            newton: NewtonControl::default(),
            probes: vec![0],
            species_columns: None,
            tolerances: None,
            svzerod: Default::default(),
            finer_last_cycle: None,
        };
        assert!(ok.validate(&dae).is_ok());
        let message = |s: RunSettings| match s.validate(&dae) {
            Err(Error::Model { element, message }) => format!("{element}: {message}"),
            other => panic!("{other:?}"),
        };
        let bad = |f: fn(&mut RunSettings)| {
            let mut s = ok.clone();
            f(&mut s);
            message(s)
        };
        assert_eq!(
            bad(|s| s.period = -1.0),
            "simulation: period must be > 0, got -1"
        );
        assert_eq!(bad(|s| s.cycles = 0), "simulation: cycles must be >= 1");
        assert_eq!(
            bad(|s| s.output_every = f64::NAN),
            "simulation: output every must be > 0, got NaN"
        );
        assert_eq!(
            bad(|s| s.dt = Some(0.0)),
            "simulation: dt must be > 0, got 0"
        );
        assert_eq!(
            bad(|s| {
                s.method = Method::Dopri5;
                s.dt = Some(1e-3);
            }),
            "simulation: method 'dopri5' chooses its own steps (error control): give rtol, not \
             dt = 0.001"
        );
        assert_eq!(
            bad(|s| s.probes = vec![0, 7]),
            "simulation: output index 7 out of range"
        );
        assert_eq!(
            bad(|s| s.finer_last_cycle = Some(1.0)),
            "simulation: the time error's tolerance factor must be > 1, got 1"
        );
    }
}
