//! svZeroDSolver's output and stop conventions, as run settings ([`SvZeroDRules`]): the
//! rates ẏ its output reports, the `valve_status` of its tanh valves, a variable measured
//! from the run's start, and its cycle-to-cycle stop rule (`use_cycle_to_cycle_error`
//! without RCR). The drop-in (`oxyline.svzerod`) reads a file, asks for these and formats the
//! rows; every step's arithmetic is here (docs/svzerod.md).

use crate::element::valve::ValveLaw;
use crate::error::{Error, Result};

/// A column computed along the run from the unknowns, recorded after the probes.
#[derive(Debug, Clone, PartialEq)]
pub enum Derived {
    /// svZeroDSolver's `valve_status` s of a valve law between the unknowns `behind` and
    /// `front` (Δp = y[front] − y[behind]). In svZeroDSolver s is an algebraic unknown whose
    /// equation s = f(Δp) holds at generalized-α's α_f stage, so from step to step
    /// s_{n+1} = s_n + (f(Δp_{n+α_f}) − s_n)/α_f (it oscillates around f(Δp) after a switch,
    /// shrinking by ρ∞ each step, as svZeroDSolver's does). Start: f(Δp₀) after a steady start,
    /// 0 from svZeroDSolver's zero state. RK4 runs record f(Δp) itself.
    ValveStatus {
        behind: usize,
        front: usize,
        law: ValveLaw,
    },
    /// Unknown `unknown` minus its value at the run's start (e.g. an intramyocardial volume
    /// that svZeroDSolver measures from the start), times `scale`.
    FromStart { unknown: usize, scale: f64 },
}

/// svZeroDSolver's number of cycles to periodicity with RCR outlets (`use_cycle_to_cycle_error`;
/// Pfaller et al. 2021, eq. 21, as its `Solver.cpp`): −τ/T ln(ε/100) with τ the largest RCR
/// time constant R_d C of `outlets` (capacitance, distal resistance), T the period and ε the
/// percent error. Returns (cycles before rounding up, τ).
pub fn rcr_cycles(outlets: &[(f64, f64)], period: f64, percent: f64) -> (f64, f64) {
    let tau = outlets
        .iter()
        .map(|&(c, rd)| c * rd)
        .fold(f64::NEG_INFINITY, f64::max);
    (-tau / period * (percent / 100.0).ln(), tau)
}

/// svZeroDSolver's cycle-to-cycle rule without RCR (`Solver::run_integration`): after the
/// requested cycles, further cycles run until at every cap the mean over the last cycle of
/// each unknown in `caps` (its points, both ends included) differs from the mean over the
/// cycle before by at most `tolerance` (relative to the earlier mean; 0/0 counts as met). A
/// run of fewer than two cycles never fills the two-cycle window: it stops at once.
#[derive(Debug, Clone, PartialEq)]
pub struct CycleMeanStop {
    pub caps: Vec<usize>,
    pub tolerance: f64,
    /// The most cycles beyond the requested ones before the run fails (svZeroDSolver has no
    /// cap and would run forever).
    pub max_extra: usize,
}

/// What a drop-in run asks beyond the ordinary output (all empty by default).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SvZeroDRules {
    /// Derived columns, recorded after the probes.
    pub derived: Vec<Derived>,
    /// Also record the rate of every probe and derived column (after them): generalized-α's
    /// ẏ_{n+1}, the rate svZeroDSolver's state carries and reports. The derived columns' rates
    /// follow its update ẏ_{n+1} = (1 + ρ∞)(y_{n+1} − y_n)/Δt − ρ∞ ẏ_n. RK4 records the exact
    /// rate of the state at the output time (`Rk4::full_rate`, algebraic unknowns included)
    /// and the derived columns' from it.
    pub rates: bool,
    pub cycle_mean_stop: Option<CycleMeanStop>,
    /// The run is svZeroDSolver's drop-in: its rows keep svZeroDSolver's arithmetic (an
    /// index-2 unknown's step-end value as the method leaves it, not the consistent one of
    /// `integrate::index2`).
    pub drop_in: bool,
}

impl SvZeroDRules {
    pub fn is_empty(&self) -> bool {
        self.derived.is_empty() && !self.rates && self.cycle_mean_stop.is_none()
    }

    /// Columns recorded after the probes.
    pub fn extra_columns(&self, n_probes: usize) -> usize {
        let d = self.derived.len();
        if self.rates { d + n_probes + d } else { d }
    }

    pub(super) fn validate(&self, n: usize) -> Result<()> {
        let bad = |what: String| Err(Error::model("simulation", what));
        for d in &self.derived {
            let idx = match *d {
                Derived::ValveStatus { behind, front, .. } => behind.max(front),
                Derived::FromStart { unknown, .. } => unknown,
            };
            if idx >= n {
                return bad(format!("derived column of unknown {idx}: out of range"));
            }
        }
        if let Some(stop) = &self.cycle_mean_stop {
            if let Some(&c) = stop.caps.iter().find(|&&c| c >= n) {
                return bad(format!("cycle-to-cycle cap unknown {c}: out of range"));
            }
            if !(stop.tolerance.is_finite() && stop.tolerance >= 0.0) {
                return bad(format!(
                    "cycle-to-cycle error must be >= 0, got {}",
                    stop.tolerance
                ));
            }
        }
        Ok(())
    }
}

/// The derived columns' values and rates along a run.
pub(super) struct DerivedState {
    columns: Vec<Derived>,
    /// α_f of generalized-α (None: RK4, whose valve status is f(Δp) itself).
    alpha_f: Option<f64>,
    rho: f64,
    /// Δp (valve status) or the start value (from start) per column.
    reference: Vec<f64>,
    pub value: Vec<f64>,
    pub rate: Vec<f64>,
}

impl DerivedState {
    pub fn new(columns: &[Derived], y: &[f64], alpha_f: Option<f64>, steady: bool) -> Self {
        let reference: Vec<f64> = columns
            .iter()
            .map(|d| match *d {
                Derived::ValveStatus { behind, front, .. } => y[front] - y[behind],
                Derived::FromStart { unknown, .. } => y[unknown],
            })
            .collect();
        let value = columns
            .iter()
            .zip(&reference)
            .map(|(d, &r)| match d {
                Derived::ValveStatus { law, .. } if steady || alpha_f.is_none() => law.closure(r),
                _ => 0.0,
            })
            .collect();
        DerivedState {
            columns: columns.to_vec(),
            alpha_f,
            rho: alpha_f.map_or(0.0, |af| 1.0 / af - 1.0),
            reference,
            value,
            rate: vec![0.0; columns.len()],
        }
    }

    /// After a step of `dt` that ended at state `y`.
    pub fn after_step(&mut self, y: &[f64], dt: f64) {
        for (k, d) in self.columns.iter().enumerate() {
            let old = self.value[k];
            self.value[k] = match *d {
                Derived::ValveStatus { behind, front, law } => {
                    let dp = y[front] - y[behind];
                    let prev = std::mem::replace(&mut self.reference[k], dp);
                    match self.alpha_f {
                        Some(af) => old + (law.closure(prev + af * (dp - prev)) - old) / af,
                        None => law.closure(dp),
                    }
                }
                Derived::FromStart { unknown, scale } => scale * (y[unknown] - self.reference[k]),
            };
            if self.alpha_f.is_some() {
                self.rate[k] =
                    (1.0 + self.rho) * (self.value[k] - old) / dt - self.rho * self.rate[k];
            }
        }
    }

    /// RK4's rates from the state's rate ẏ (see `Rk4::full_rate`), its value being f(Δp)
    /// itself: f′(Δp) (ẏ_front − ẏ_behind) of a valve status, `scale` ẏ of a from-start
    /// unknown.
    pub fn exact_rates(&mut self, y: &[f64], yd: &[f64]) {
        for (k, d) in self.columns.iter().enumerate() {
            self.rate[k] = match *d {
                Derived::ValveStatus { behind, front, law } => {
                    closure_slope(law, y[front] - y[behind]) * (yd[front] - yd[behind])
                }
                Derived::FromStart { unknown, scale } => scale * yd[unknown],
            };
        }
    }
}

/// d(valve status)/dΔp of [`ValveLaw::closure`]: 0.5 k (1 − tanh²(k Δp)) of a tanh law, 0 of
/// a piecewise one (its status is a step).
fn closure_slope(law: ValveLaw, dp: f64) -> f64 {
    match law {
        ValveLaw::Tanh { steepness, .. } => {
            let th = (steepness * dp).tanh();
            0.5 * steepness * (1.0 - th * th)
        }
        ValveLaw::Piecewise { .. } => 0.0,
    }
}

/// svZeroDSolver's cycle means at the caps: the sum over the current cycle's points.
pub(super) struct CycleMeans {
    stop: CycleMeanStop,
    sum: Vec<f64>,
    previous: Option<Vec<f64>>,
    points: usize,
}

impl CycleMeans {
    pub fn new(stop: &CycleMeanStop) -> Self {
        CycleMeans {
            sum: vec![0.0; stop.caps.len()],
            stop: stop.clone(),
            previous: None,
            points: 0,
        }
    }

    /// A point of the current cycle (its start, then every step's end).
    pub fn add(&mut self, y: &[f64]) {
        for (s, &c) in self.sum.iter_mut().zip(&self.stop.caps) {
            *s += y[c];
        }
        self.points += 1;
    }

    /// Close the cycle (`cycles_run` cycles done of the `requested`): whether the run may
    /// stop, an error past the cap. The next cycle starts at this cycle's end point `y`.
    pub fn end_cycle(&mut self, y: &[f64], cycles_run: usize, requested: usize) -> Result<bool> {
        let n = self.points.max(1) as f64;
        let now: Vec<f64> = self.sum.iter().map(|s| s / n).collect();
        let met = self.previous.as_ref().is_some_and(|prev| {
            // as svZeroDSolver's `err > eps` test: a NaN (0/0) counts as met
            !prev
                .iter()
                .zip(&now)
                .any(|(&p, &q)| ((q - p) / p).abs() > self.stop.tolerance)
        });
        self.previous = Some(now);
        self.sum.iter_mut().for_each(|s| *s = 0.0);
        self.points = 0;
        self.add(y);
        if cycles_run < requested {
            return Ok(false);
        }
        if requested < 2 || met {
            return Ok(true);
        }
        if cycles_run >= requested + self.stop.max_extra {
            return Err(Error::model(
                "simulation_parameters",
                format!(
                    "use_cycle_to_cycle_error: the vessel caps' cycle means still change by \
                     more than {}% after {cycles_run} cycles",
                    100.0 * self.stop.tolerance
                ),
            ));
        }
        Ok(false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rcr_cycles_is_the_decay_of_the_slowest_outlet() {
        // e^(−n T/τ) = ε/100: with τ = 2 s (the larger R_d C), T = 1 s, ε = 1 %:
        // n = 2 ln 100 = 9.21 cycles
        let (n, tau) = rcr_cycles(&[(1e-3, 1000.0), (2e-3, 1000.0)], 1.0, 1.0);
        assert_eq!(tau, 2.0);
        assert!((n - 2.0 * 100f64.ln()).abs() < 1e-14, "{n}");
    }

    #[test]
    fn valve_status_follows_the_alpha_f_stage() {
        // a constant Δp after a jump: s approaches f(Δp) with error shrinking by −ρ∞ per step
        let law = ValveLaw::Tanh {
            r_min: 1.0,
            r_max: 2.0,
            steepness: 1.0,
        };
        let col = Derived::ValveStatus {
            behind: 0,
            front: 1,
            law,
        };
        let rho = 0.5;
        let mut d = DerivedState::new(&[col], &[0.0, 0.0], Some(1.0 / (1.0 + rho)), false);
        assert_eq!(d.value[0], 0.0);
        let y = [0.0, 3.0];
        let target = law.closure(3.0);
        let mut errors = Vec::new();
        d.after_step(&y, 0.1);
        for _ in 0..6 {
            d.after_step(&y, 0.1);
            errors.push(d.value[0] - target);
        }
        for w in errors.windows(2) {
            assert!((w[1] / w[0] + rho).abs() < 1e-9, "{errors:?}");
        }
    }

    /// The cycles a run of `requested` cycles takes (None: past `max_extra`) for one cap
    /// whose value is the step index r (2 steps per cycle).
    fn cycles_run(requested: usize, tolerance: f64) -> Option<usize> {
        let stop = CycleMeanStop {
            caps: vec![0],
            tolerance,
            max_extra: 2,
        };
        let mut m = CycleMeans::new(&stop);
        m.add(&[0.0]);
        for cycle in 1..=requested + 2 {
            m.add(&[(2 * cycle - 1) as f64]);
            let end = [(2 * cycle) as f64];
            m.add(&end);
            match m.end_cycle(&end, cycle, requested) {
                Ok(true) => return Some(cycle),
                Ok(false) => {}
                Err(_) => return None,
            }
        }
        unreachable!("the cap stops the run")
    }

    #[test]
    fn cycle_means_stop_when_the_caps_settle() {
        // cycle c's mean over its 3 points (both ends) is 2c − 1: its change from cycle c − 1
        // is 2/(2c − 3), i.e. 2, 0.67, 0.4 for c = 2, 3, 4
        assert_eq!(cycles_run(2, 0.7), Some(3));
        assert_eq!(cycles_run(2, 0.5), Some(4));
        assert_eq!(cycles_run(2, 0.1), None);
        // one cycle never fills svZeroDSolver's two-cycle window: nothing is checked
        assert_eq!(cycles_run(1, 0.1), Some(1));
    }
}
