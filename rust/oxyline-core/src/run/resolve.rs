//! RK4's step for circuits with valves and chambers from an accuracy criterion (docs/physics.md
//! §1.8, "RK4's step for valves and chambers"). A tanh valve switches over a pressure width
//! 1/k (svZeroDSolver's steepness k = 1e4: microseconds), far below any affordable step, so an
//! explicit step places each opening and closing to within one step: a first-order timing
//! error that the stability bound does not see. The step is therefore refined by step doubling
//! over the run's first cycles until two successive runs agree to the tolerance.

use super::plan::Plan;
use super::settings::{Method, RunSettings};
use crate::circuit::{Dae, Regime};
use crate::error::Result;
use crate::integrate::rk4::Rk4;
use crate::integrate::steady::SteadyCache;

/// The outcome of [`rk4_step_refinement`].
#[derive(Debug, Clone, PartialEq)]
pub struct Refinement {
    /// Divide the planned RK4 step by this (a power of two, 1 without valves or chambers).
    pub factor: usize,
    /// Estimated error of the refined run over the trial cycles: max over the unknowns of
    /// max|y − y_exact| / range(y) at the output times of the last trial cycle (0 without valves or chambers).
    pub estimate: f64,
    /// The estimate met the tolerance (false when `max_factor` stopped the doubling).
    pub converged: bool,
}

/// Steps at the planned step that the trial runs span at least (all of a shorter run): a run
/// that approaches its periodic state over many cycles accumulates the valves' timing error
/// (chamber_elastance_inductor: 1.2e-1 of its last cycle's `Vc` range after its 30).
const TRIAL_STEPS: usize = 20_000;

/// The factor by which to divide the RK4 step that `s` plans (its `dt`, or the automatic one)
/// so that the output of its first cycles is within `tol` (scaled by each unknown's range) of
/// the converged solution. Circuits without valves or chambers return 1 without a trial.
///
/// The trial spans the run's cycles, or as many as hold [`TRIAL_STEPS`] planned steps (at
/// least one). Its runs at factors 1, 2, 4, ... give the differences d_k between factors
/// 2^k and 2^(k+1). Where the differences shrink (d_k ≤ 0.75 d_(k−1): the runs are in the
/// range where the error falls with the step; a valve switching within the same step of two
/// runs can make d small by chance, which the next difference then exposes), the error of
/// factor 2^k is about 2 d_k for a first-order error (the valve timing's) and d_k is the error
/// of factor 2^(k+1). The coarser of the two that meets `tol` is returned; at `max_factor`
/// the doubling stops unconverged.
pub fn rk4_step_refinement(
    dae: &Dae,
    s: &RunSettings,
    tol: f64,
    max_factor: usize,
) -> Result<Refinement> {
    if dae.elements.is_empty() {
        return Ok(Refinement {
            factor: 1,
            estimate: 0.0,
            converged: true,
        });
    }
    let mut s = s.clone();
    s.method = Method::Rk4;
    let steady = SteadyCache::new(dae);
    let mut plan = Plan::new(dae, &steady, &s, None, &mut |_, _| true)?;
    let (y0, _) = plan.initial_state(&steady, &s)?;
    let cycles = s
        .max_cycles()
        .min(TRIAL_STEPS.div_ceil(plan.steps_per_cycle.max(1)))
        .max(1);
    let trial = |factor: usize| first_cycles(dae, &y0, &plan, cycles, factor);
    let mut coarse = trial(1)?;
    let mut fine = trial(2)?;
    let mut last = difference(&coarse, &fine);
    let mut factor = 2;
    while factor < max_factor {
        coarse = fine;
        fine = trial(2 * factor)?;
        let d = difference(&coarse, &fine);
        // both at round-off: the run does not depend on the step
        let settled = last <= 1e-9 && d <= 1e-9;
        if settled || (last <= 0.5 * tol && d <= 0.75 * last) {
            return Ok(done(factor / 2, 2.0 * last, true));
        }
        if d <= tol && d <= 0.75 * last {
            return Ok(done(2 * factor, d, true));
        }
        last = d;
        factor *= 2;
    }
    Ok(done(factor, last, last <= tol))
}

fn done(factor: usize, estimate: f64, converged: bool) -> Refinement {
    Refinement {
        factor,
        estimate,
        converged,
    }
}

/// The unknowns at the output times of the last of the first `cycles` (its start included),
/// RK4 with the planned step / `factor`, from the run's start `y0` (made consistent with the
/// forcing at 0, as the run's). The last cycle is what a last-cycle output shows, and its own
/// range the scale of its error: a zero start's transient would make the range of the whole
/// trial, and so the scaled differences, far larger (chamber_elastance_inductor's `Vc`).
fn first_cycles(
    dae: &Dae,
    y0: &[f64],
    plan: &Plan<'_>,
    cycles: usize,
    factor: usize,
) -> Result<Vec<Vec<f64>>> {
    let dt = plan.dt / factor as f64;
    let mut rk = Rk4::new(dae, Regime::Transient, dt)?;
    let mut y = y0.to_vec();
    rk.make_consistent(0.0, &mut y)?;
    let (stride, per_cycle) = (plan.stride * factor, plan.steps_per_cycle * factor);
    let last = per_cycle * (cycles - 1);
    let mut rows = Vec::new();
    if last == 0 {
        rows.push(y.clone());
    }
    for i in 0..per_cycle * cycles {
        rk.step(i as f64 * dt, &mut y)?;
        if i + 1 >= last && (i + 1) % stride == 0 {
            rows.push(y.clone());
        }
    }
    Ok(rows)
}

/// max over unknowns and rows of |a − b| / scale, the scale being the unknown's range over
/// `b`'s rows, at least 1e-6 of its largest magnitude (an unknown that varies by less is
/// compared relative to that; one that is zero throughout is left out). Not more: a chamber's
/// volume that drifts by 2e-5 of its value over the cycle is compared on that range, as
/// svZeroDSolver's comparisons do (chamber_elastance_inductor's `Vc`).
fn difference(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    let n = b.first().map_or(0, Vec::len);
    let mut worst = 0.0_f64;
    for i in 0..n {
        let (lo, hi, big) = b
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY, 0.0_f64), |acc, r| {
                (acc.0.min(r[i]), acc.1.max(r[i]), acc.2.max(r[i].abs()))
            });
        let scale = (hi - lo).max(1e-6 * big);
        if scale == 0.0 {
            continue;
        }
        let d = a
            .iter()
            .zip(b)
            .fold(0.0_f64, |m, (ra, rb)| m.max((ra[i] - rb[i]).abs()));
        // a NaN (a failed trial) counts as unconverged
        worst = if d.is_nan() {
            f64::INFINITY
        } else {
            worst.max(d / scale)
        };
    }
    worst
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn difference_is_scaled_by_each_unknowns_range() {
        let b = vec![vec![0.0, 100.0, 0.0], vec![2.0, 100.0, 0.0]];
        let a = vec![vec![0.1, 100.00005, 0.0], vec![2.0, 100.0, 0.0]];
        // unknown 0: 0.1 / range 2; unknown 1: 5e-5 / (1e-6 · 100); unknown 2 left out
        // (100.00005 − 100 carries the rounding of 100.00005: ~1e-14 absolute, 1e-10 scaled)
        assert!((difference(&a, &b) - 0.5).abs() < 1e-9);
        let a = vec![vec![0.1, 100.0, 0.0], vec![2.0, 100.0, 0.0]];
        assert!((difference(&a, &b) - 0.05).abs() < 1e-12);
    }
}
