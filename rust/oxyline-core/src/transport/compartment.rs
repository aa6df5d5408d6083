//! Well-mixed capillary compartments of a closed circulation (docs/oxygen.md "Oxygen around a
//! closed loop"): an organ bed (or a mixing pool: a compartment without consumption) holds a
//! blood volume V(t) of uniform total O2 concentration C_t (dissolved + haemoglobin-bound,
//! mol/m³) and consumes O2 at a rate VO2 (mol/s) that depends on its free PO2:
//!
//! ```text
//! d(V C_t)/dt = Σ_in F_in − q_out C_t − VO2(P(C_t)),   dV/dt = Σ_in q_in − q_out.
//! ```
//!
//! Since the compartment is well mixed, its PO2 is the organ's venous PO2. One step is backward
//! Euler in C_t, so the amount changes by exactly dt (inflow − outflow − consumption) with the
//! values reported: the loop's mass balance closes to round-off whatever the step.

use crate::error::{Error, Result};
use crate::hemoglobin::Binding;

/// O2 consumption of an organ (SI: mol/s, Pa).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Consumption {
    /// No consumption (a mixing pool: arteries, veins, heart chambers).
    None,
    /// A fixed VO2 (mol/s), independent of PO2: valid while the organ's PO2 stays well above 0.
    Fixed { rate: f64 },
    /// Michaelis–Menten in the free PO2: VO2 = vmax P/(km + P) (vmax mol/s, km Pa).
    MichaelisMenten { vmax: f64, km: f64 },
}

impl Consumption {
    /// Checks the numbers, naming the compartment.
    pub fn validate(&self, element: &str) -> Result<()> {
        let bad = |k: &str, v: f64| {
            Error::model(
                element,
                format!("consumption {k} must be a finite number >= 0, got {v}"),
            )
        };
        match *self {
            Consumption::None => Ok(()),
            Consumption::Fixed { rate } if !(rate.is_finite() && rate >= 0.0) => {
                Err(bad("rate", rate))
            }
            Consumption::MichaelisMenten { vmax, .. } if !(vmax.is_finite() && vmax >= 0.0) => {
                Err(bad("vmax", vmax))
            }
            Consumption::MichaelisMenten { km, .. } if !(km.is_finite() && km > 0.0) => {
                Err(Error::model(
                    element,
                    format!("consumption km must be a finite number > 0, got {km}"),
                ))
            }
            _ => Ok(()),
        }
    }

    /// VO2 (mol/s) and dVO2/dP (mol s⁻¹ Pa⁻¹) at the free PO2 `p` (Pa).
    #[inline]
    pub fn rate(&self, p: f64) -> (f64, f64) {
        match *self {
            Consumption::None => (0.0, 0.0),
            Consumption::Fixed { rate } => (rate, 0.0),
            Consumption::MichaelisMenten { vmax, km } => {
                let p = p.max(0.0);
                (vmax * p / (km + p), vmax * km / ((km + p) * (km + p)))
            }
        }
    }
}

/// One backward-Euler step of a compartment. Solves
/// (V₁ + dt q_out) C₁ + dt VO2(P(C₁)) = V₀ C₀ + dt `inflow` for C₁ (total concentration) and
/// returns (C₁, VO2(C₁)). `inflow` is Σ q_in C_t,in (mol/s); `guess` a free-concentration warm
/// start. The left side increases strictly with C₁ (VO2 increases with P, P with C₁), so a
/// Newton iteration kept inside the bracket [0, rhs/(V₁ + dt q_out)] converges.
#[allow(clippy::too_many_arguments)]
pub fn step(
    binding: &Binding,
    consumption: &Consumption,
    alpha: f64,
    (v0, c0): (f64, f64),
    v1: f64,
    dt: f64,
    q_out: f64,
    inflow: f64,
    guess: f64,
) -> (f64, f64) {
    let a = v1 + dt * q_out;
    let rhs = v0 * c0 + dt * inflow;
    match *consumption {
        Consumption::None => (rhs / a, 0.0),
        // zero order: linear, exact (may go below zero if the supply cannot meet the demand;
        // the caller reports that)
        Consumption::Fixed { rate } => ((rhs - dt * rate) / a, rate),
        Consumption::MichaelisMenten { .. } => {
            let (mut lo, mut hi) = (0.0_f64, (rhs / a).max(0.0));
            let mut ct = hi;
            let mut c = guess;
            for _ in 0..100 {
                c = binding.free(ct, c);
                let (vo2, dvo2) = consumption.rate(c / alpha);
                let f = a * ct + dt * vo2 - rhs;
                if f > 0.0 {
                    hi = ct;
                } else {
                    lo = ct;
                }
                // dVO2/dC_t = dVO2/dP · dP/dc · dc/dC_t = dVO2/dP / (α · dC_t/dc)
                let df = a + dt * dvo2 / (alpha * binding.capacity_slope(c));
                let next = ct - f / df;
                // converged: accept the Newton step as it is (at the root it may land on a
                // bracket end, which must not trigger a bisection)
                if (next - ct).abs() <= 1e-15 * ct.abs().max(1e-300) {
                    ct = next;
                    break;
                }
                ct = if next > lo && next < hi {
                    next
                } else {
                    0.5 * (lo + hi)
                };
                if hi - lo <= 1e-15 * hi {
                    break;
                }
            }
            let c = binding.free(ct, c);
            (ct, consumption.rate(c / alpha).0)
        }
    }
}
