//! Binding of a transported species (physics spec §4, §5): the transported state is the *total*
//! amount (free + bound, both carried by the blood), while wall exchange acts on the free
//! (dissolved) concentration. Every binding law is a strictly increasing map c ↦ C_t(c), so the
//! free concentration is recovered from the total by a safeguarded Newton solve.
//!
//! Units are SI throughout: c in mol/m³, partial pressure P = c/α in Pa, α in mol m⁻³ Pa⁻¹.

use crate::error::{Error, Result};
use serde::Deserialize;

#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BindingSpec {
    /// Passive scalar: C_t = c.
    #[default]
    None,
    /// Linear partition C_t = (1 + K) c.
    Linear { partition: f64 },
    /// Hill saturation (oxyhaemoglobin; or a saturable binder with α = 1, p50 = K_d):
    /// C_t = c + H S(c/α), S(P) = Pⁿ/(Pⁿ + P50ⁿ).
    Hill {
        solubility: f64,
        p50: f64,
        n: f64,
        capacity: f64,
    },
    /// The paper's "approximately linear relationship" (physics §4.4):
    /// C_t = C_t,Hill(P_ref) + α (1 + K̄)(P − P_ref), K̄ the Hill secant between `p_low` and `p_high`.
    Linearized {
        solubility: f64,
        p50: f64,
        n: f64,
        capacity: f64,
        p_low: f64,
        p_high: f64,
    },
}

/// A validated binding law.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Binding {
    None,
    /// C_t = slope · c + offset (linear partition and the linearised Hill curve).
    Affine {
        slope: f64,
        offset: f64,
    },
    Hill {
        alpha: f64,
        p50: f64,
        n: f64,
        capacity: f64,
    },
}

/// Hill saturation S(P) and dS/dP, written in the ratio x = P/P50 so that it is exact at P = 0.
#[inline]
fn hill(p: f64, p50: f64, n: f64) -> (f64, f64) {
    if p <= 0.0 {
        return (0.0, 0.0);
    }
    let xn = (p / p50).powf(n);
    let s = xn / (1.0 + xn);
    (s, n * s * (1.0 - s) / p)
}

impl Binding {
    pub fn from_spec(spec: &BindingSpec, element: &str) -> Result<Self> {
        let pos = |k: &str, v: f64| -> Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::model(
                    element,
                    format!("binding {k} must be a finite number > 0, got {v}"),
                ))
            }
        };
        Ok(match *spec {
            BindingSpec::None => Binding::None,
            BindingSpec::Linear { partition } => {
                if !(partition.is_finite() && partition >= 0.0) {
                    return Err(Error::model(
                        element,
                        format!("binding partition must be a finite number >= 0, got {partition}"),
                    ));
                }
                Binding::Affine {
                    slope: 1.0 + partition,
                    offset: 0.0,
                }
            }
            BindingSpec::Hill {
                solubility,
                p50,
                n,
                capacity,
            } => {
                pos("solubility", solubility)?;
                pos("p50", p50)?;
                pos("n", n)?;
                pos("capacity", capacity)?;
                Binding::Hill {
                    alpha: solubility,
                    p50,
                    n,
                    capacity,
                }
            }
            BindingSpec::Linearized {
                solubility,
                p50,
                n,
                capacity,
                p_low,
                p_high,
            } => {
                pos("solubility", solubility)?;
                pos("p50", p50)?;
                pos("n", n)?;
                pos("capacity", capacity)?;
                pos("p_low", p_low)?;
                pos("p_high", p_high)?;
                if p_low == p_high {
                    return Err(Error::model(
                        element,
                        "linearized binding needs p_low != p_high",
                    ));
                }
                let kbar = secant_capacity_ratio(solubility, p50, n, capacity, p_low, p_high);
                let slope = 1.0 + kbar;
                // C_t(c) = C_t,Hill(p_high) + slope (c − α p_high): passes through the Hill curve
                // at the inlet (high) pressure and has the secant slope.
                let (s_hi, _) = hill(p_high, p50, n);
                let ct_hi = solubility * p_high + capacity * s_hi;
                Binding::Affine {
                    slope,
                    offset: ct_hi - slope * solubility * p_high,
                }
            }
        })
    }

    pub fn is_identity(&self) -> bool {
        matches!(self, Binding::None)
    }

    /// Total concentration C_t from the free concentration c.
    #[inline]
    pub fn total(&self, c: f64) -> f64 {
        match *self {
            Binding::None => c,
            Binding::Affine { slope, offset } => slope * c + offset,
            Binding::Hill {
                alpha,
                p50,
                n,
                capacity,
            } => c + capacity * hill(c / alpha, p50, n).0,
        }
    }

    /// dC_t/dc.
    #[inline]
    pub fn capacity_slope(&self, c: f64) -> f64 {
        match *self {
            Binding::None => 1.0,
            Binding::Affine { slope, .. } => slope,
            Binding::Hill {
                alpha,
                p50,
                n,
                capacity,
            } => 1.0 + capacity * hill(c / alpha, p50, n).1 / alpha,
        }
    }

    /// Free concentration c from the total C_t; `guess` is a warm start (previous value).
    /// Hill: Newton on f(P) = αP + H S(P) − C_t (strictly increasing), kept inside a bisection
    /// bracket [lo, hi] ⊂ [0, C_t/α]; stops when |ΔP| < 1e-10 mmHg.
    #[inline]
    pub fn free(&self, ct: f64, guess: f64) -> f64 {
        match *self {
            Binding::None => ct,
            Binding::Affine { slope, offset } => (ct - offset) / slope,
            Binding::Hill {
                alpha,
                p50,
                n,
                capacity,
            } => {
                if ct <= 0.0 {
                    // negative totals (round-off below zero) map linearly, keeping the law monotone
                    return ct;
                }
                let (mut lo, mut hi) = (0.0, ct / alpha);
                let mut p = (guess / alpha).clamp(lo, hi);
                // |ΔP| below 1e-12 mmHg (margin under the 1e-10 mmHg contract), or a few ulps of P
                // (quadratic convergence stalls there)
                let tol_abs: f64 = 1e-12 * 133.322_368;
                for _ in 0..100 {
                    let (s, ds) = hill(p, p50, n);
                    let f = alpha * p + capacity * s - ct;
                    let dp = -f / (alpha + capacity * ds);
                    // converged: accept the Newton step without the bracket test (near the root
                    // it can land exactly on a bracket end, which would trigger a bisection)
                    if dp.abs() < tol_abs.max(1e-14 * p) {
                        p += dp;
                        break;
                    }
                    if f > 0.0 {
                        hi = p;
                    } else {
                        lo = p;
                    }
                    let next = p + dp;
                    // Newton's error after this step is ≈ |f''/2f'| dp² ≤ (n/P) dp² for the Hill
                    // curve: when that is far below the tolerance the step is final, which saves
                    // the confirming evaluation in the common warm-started case
                    if next > lo && next < hi && 10.0 * n * dp * dp < tol_abs * p {
                        p = next;
                        break;
                    }
                    p = if next > lo && next < hi {
                        next
                    } else {
                        0.5 * (lo + hi)
                    };
                    if hi - lo < tol_abs {
                        break;
                    }
                }
                alpha * p
            }
        }
    }
}

/// Secant bound/dissolved capacity ratio K̄ = H (S(p_high) − S(p_low)) / (α (p_high − p_low)).
pub fn secant_capacity_ratio(
    alpha: f64,
    p50: f64,
    n: f64,
    capacity: f64,
    p_low: f64,
    p_high: f64,
) -> f64 {
    let (sh, _) = hill(p_high, p50, n);
    let (sl, _) = hill(p_low, p50, n);
    capacity * (sh - sl) / (alpha * (p_high - p_low))
}

#[cfg(test)]
mod tests {
    use super::*;
    const MMHG: f64 = 133.322_368;

    fn standard() -> Binding {
        // physics §4.1: α = 1.40e-3 mol m⁻³ mmHg⁻¹, P50 26.8 mmHg, n 2.7, H = 1.34 mL/g × 150 g/L
        let h = 1.34 * 150.0 * 1e-3 / 22.414e-3; // mL O2/L → mol/m³ (1 mL/L = 1e-3 L/L; 22.414 L/mol)
        Binding::Hill {
            alpha: 1.40e-3 / MMHG,
            p50: 26.8 * MMHG,
            n: 2.7,
            capacity: h,
        }
    }

    #[test]
    fn hill_inversion_round_trip_1_to_600_mmhg() {
        let b = standard();
        let mut worst = 0.0f64;
        let alpha = 1.40e-3 / MMHG;
        for i in 0..=2000 {
            let p = 1.0 + 599.0 * i as f64 / 2000.0; // mmHg
            let ct = b.total(alpha * p * MMHG);
            // cold starts, and warm starts near the root (the early-exit path)
            let c = alpha * p * MMHG;
            for guess in [
                0.0,
                alpha * 40.0 * MMHG,
                alpha * 900.0 * MMHG,
                c * (1.0 + 1e-2),
                c * (1.0 - 1e-4),
                c * (1.0 + 1e-7),
            ] {
                let back = b.free(ct, guess) / alpha / MMHG;
                worst = worst.max((back - p).abs());
            }
        }
        assert!(worst < 1e-10, "worst round-trip error {worst:e} mmHg");
    }

    #[test]
    fn total_content_table_of_physics_4_2() {
        let b = standard();
        let alpha = 1.40e-3 / MMHG;
        // (PO2 mmHg, S, C_t mol/m³, K)
        let table = [
            (100.0, 0.97222, 8.8585, 4.67),
            (85.3, 0.95795, 8.7100, 8.17),
            (85.0, 0.95757, 8.7061, 8.27),
            (60.0, 0.89808, 8.1376, 26.4),
            (55.5, 0.87713, 7.9435, 33.6),
            (48.0, 0.82829, 7.4950, 51.2),
        ];
        for (p, s, ct, k) in table {
            let c = alpha * p * MMHG;
            let (sat, _) = hill(p * MMHG, 26.8 * MMHG, 2.7);
            assert!((sat - s).abs() < 0.5e-5, "S({p}) = {sat}");
            assert!(
                (b.total(c) - ct).abs() < 0.5e-4,
                "C_t({p}) = {}",
                b.total(c)
            );
            let kk = b.capacity_slope(c) - 1.0;
            assert!((kk - k).abs() / k < 6e-3, "K({p}) = {kk}");
        }
    }

    #[test]
    fn linearized_secant_matches_physics_3_4() {
        // K̄ = 15.2 (85→60 mmHg), 22.4 (85→48), 17.4 (85.3→55.5)
        let h = 1.34 * 150.0 / 22.414;
        for (lo, hi, k) in [(60.0, 85.0, 15.2), (48.0, 85.0, 22.4), (55.5, 85.3, 17.4)] {
            let kb = secant_capacity_ratio(1.40e-3, 26.8, 2.7, h, lo, hi);
            assert!((kb - k).abs() < 0.05, "{lo}-{hi}: {kb}");
        }
        let spec = BindingSpec::Linearized {
            solubility: 1.40e-3,
            p50: 26.8,
            n: 2.7,
            capacity: h,
            p_low: 60.0,
            p_high: 85.0,
        };
        let b = Binding::from_spec(&spec, "t").unwrap();
        let full = standard();
        // passes through the Hill curve at both secant ends (units: mmHg here, scale-free)
        for p in [60.0, 85.0] {
            let exact = full.total(1.40e-3 / MMHG * p * MMHG);
            assert!((b.total(1.40e-3 * p) - exact).abs() < 1e-9 * exact, "{p}");
            assert!((b.free(b.total(1.40e-3 * p), 0.0) - 1.40e-3 * p).abs() < 1e-15);
        }
    }
}
