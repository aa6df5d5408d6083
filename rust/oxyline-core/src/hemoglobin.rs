//! Binding of a transported species (docs/physics.md §4, §5): the transported state is the *total*
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
    /// The paper's "approximately linear relationship" (docs/physics.md §4.4):
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
pub fn hill(p: f64, p50: f64, n: f64) -> (f64, f64) {
    if p <= 0.0 {
        return (0.0, 0.0);
    }
    let xn = (p / p50).powf(n);
    let s = xn / (1.0 + xn);
    (s, n * s * (1.0 - s) / p)
}

/// Local inverse of the Hill law about an anchor pressure P₁, used to invert C_t without a
/// `powf` or a division while the solution stays near the anchor (between Runge–Kutta stages
/// and steps the free concentration of a cell moves by a tiny fraction of itself).
///
/// With the cubic Taylor model C_t − C_t(P₁) = b d + c d² + e d³ (d = P − P₁) and u = (C_t −
/// C_t(P₁))/b, series reversion gives d = u − k₂u² + k₃u³ + k₄u⁴ + …, k₂ = c/b,
/// k₃ = 2k₂² − e/b, k₄ = 5k₂e/b − 5k₂³. The result is accepted when the first neglected terms
/// — k₄u⁴ and the model's remainder H|S⁗|d⁴/(24b), each doubled — are below the tolerance:
/// bound·u⁴ < P_TOL, i.e. |u| below (P_TOL/bound)^¼, folded with the trusted span into one
/// limit `u_max` when the anchor is made.
///
/// 40 bytes per node (was 48): the implicit step reads every cell's anchor once per step, so
/// its size is memory traffic. k₃ and `u_max` are single precision: `u_max` is
/// rounded down (a slightly stricter acceptance), and k₃'s rounding (2⁻²⁴ relative) moves the
/// series' P by |k₃|u³·2⁻²⁴, which `u_max` also keeps below 1e-3 P_TOL (for the standard
/// oxyhaemoglobin law ~1e-14 Pa, four orders under P_TOL and below one ulp of P). k₂'s term is
/// ~1e3 times larger: it stays double.
#[derive(Debug, Clone, Copy)]
pub struct HillAnchor {
    /// Anchor pressure P₁ (Pa).
    p: f64,
    /// C_t(P₁).
    total: f64,
    /// 1/b = 1/(dC_t/dP) at P₁.
    inv_slope: f64,
    k2: f64,
    k3: f32,
    /// |u| above this leaves the model's trusted span or its error bound (negative: no
    /// anchor yet).
    u_max: f32,
}

/// `x` as f32 rounded toward zero (|result| ≤ |x|: a limit stored this way never widens).
fn f32_toward_zero(x: f64) -> f32 {
    let r = x as f32;
    if (r as f64).abs() > x.abs() && r != 0.0 {
        f32::from_bits(r.to_bits() - 1)
    } else {
        r
    }
}

impl HillAnchor {
    /// Values per anchor in a checkpoint.
    pub const CARRIED: usize = 6;

    /// The anchor as plain numbers (a checkpoint carries it: the inversion is warm-started).
    pub fn to_array(&self) -> [f64; Self::CARRIED] {
        [
            self.p,
            self.total,
            self.inv_slope,
            self.k2,
            f64::from(self.k3),
            f64::from(self.u_max),
        ]
    }

    /// The anchor of [`HillAnchor::to_array`].
    pub fn from_array(a: &[f64]) -> Self {
        HillAnchor {
            p: a[0],
            total: a[1],
            inv_slope: a[2],
            k2: a[3],
            // (exact for a checkpoint of this layout)
            k3: a[4] as f32,
            u_max: f32_toward_zero(a[5]),
        }
    }
}

impl Default for HillAnchor {
    fn default() -> Self {
        HillAnchor {
            p: 0.0,
            total: 0.0,
            inv_slope: 0.0,
            k2: 0.0,
            k3: 0.0,
            u_max: -1.0,
        }
    }
}

/// The anchor's model is trusted within this fraction of P₁: S⁗ changes by at most ~n·2 % over
/// the interval, well inside the factor 2 applied to the remainder estimate.
const ANCHOR_SPAN: f64 = 0.02;

/// P^k dᵏS/dPᵏ for k = 1..4 of the Hill law, and S. With D = P d/dP, P^k dᵏ/dPᵏ =
/// D(D−1)…(D−k+1), and Dᵏ of the logistic σ(n ln(P/P50)) are polynomials in σ: exact
/// derivatives from one powf.
fn hill_derivatives(p: f64, p50: f64, n: f64) -> (f64, [f64; 4]) {
    let xn = (p / p50).powf(n);
    let s = xn / (1.0 + xn);
    let q = s * (1.0 - s);
    let d1 = n * q;
    let d2 = n * d1 * (1.0 - 2.0 * s);
    let d3 = n * n * d1 * (1.0 - 6.0 * s + 6.0 * s * s);
    let d4 = n * n * n * d1 * (1.0 - 2.0 * s) * (1.0 - 12.0 * s + 12.0 * s * s);
    (
        s,
        [
            d1,
            d2 - d1,
            d3 - 3.0 * d2 + 2.0 * d1,
            d4 - 6.0 * d3 + 11.0 * d2 - 6.0 * d1,
        ],
    )
}

impl HillAnchor {
    fn new(p: f64, alpha: f64, p50: f64, n: f64, capacity: f64) -> Self {
        let (s, pk) = hill_derivatives(p, p50, n);
        let ip = 1.0 / p;
        let s1 = pk[0] * ip;
        let c = capacity * 0.5 * pk[1] * ip * ip;
        let e = capacity * pk[2] * ip * ip * ip / 6.0;
        let remainder = capacity * pk[3].abs() * ip * ip * ip * ip / 24.0;
        let inv_slope = 1.0 / (alpha + capacity * s1);
        let k2 = c * inv_slope;
        let e_b = e * inv_slope;
        let k4 = 5.0 * k2 * e_b - 5.0 * k2 * k2 * k2;
        let bound = 2.0 * (k4.abs() + remainder * inv_slope);
        // bound·u⁴ < P_TOL ⇔ |u| < (P_TOL/bound)^¼ (a zero bound leaves only the span)
        let u_err = (P_TOL / bound).sqrt().sqrt();
        let k3 = 2.0 * k2 * k2 - e_b;
        // k₃ stored in f32: its rounding error |k₃|u³·2⁻²⁴ (with k₃'s own rounding) below
        // 1e-3 P_TOL ⇔ |u| < (1e-3 P_TOL / (|k₃| 2⁻²³))^⅓
        let u_k3 = (1e-3 * P_TOL / (k3.abs() * f64::from(f32::EPSILON))).cbrt();
        HillAnchor {
            p,
            total: alpha * p + capacity * s,
            inv_slope,
            k2,
            k3: k3 as f32,
            u_max: f32_toward_zero(u_err.min(u_k3).min(ANCHOR_SPAN * p)),
        }
    }

    /// P from C_t by the series, u, and whether it is within tolerance (branch-free).
    #[inline(always)]
    fn invert(&self, ct: f64) -> (f64, f64, bool) {
        let u = (ct - self.total) * self.inv_slope;
        let p = self.p + u * (1.0 + u * (f64::from(self.k3) * u - self.k2));
        (p, u, ct > 0.0 && u.abs() < f64::from(self.u_max))
    }

    /// The warm start of the exact inversion after the series was not accepted for `ct`:
    /// the series' own P (its error grows like u⁴, so just outside `u_max` it is far inside
    /// Newton's final-step test, and within the trusted span it beats the last stored free
    /// value by orders), else `guess` (no anchor yet, a non-positive total, or a wild
    /// extrapolation). α·P, in units of c.
    #[inline(always)]
    fn warm_start(&self, p_series: f64, alpha: f64, ct: f64, guess: f64) -> f64 {
        if self.u_max > 0.0 && p_series > 0.0 && alpha * p_series < ct {
            alpha * p_series
        } else {
            guess
        }
    }
}

/// |ΔP| below 1e-12 mmHg (margin under the 1e-10 mmHg contract of the inversion).
const P_TOL: f64 = 1e-12 * 133.322_368;

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

    /// `free` for repeated inversions near a previous solution (one node): the local series
    /// inverse about `anchor` when it is within tolerance, so most calls need no `powf`;
    /// otherwise the exact Newton solve, re-anchored at its root.
    #[inline(always)]
    pub fn free_anchored(&self, ct: f64, guess: f64, anchor: &mut HillAnchor) -> f64 {
        if let Binding::Hill { alpha, .. } = *self {
            let (p, _, ok) = anchor.invert(ct);
            if ok {
                return alpha * p;
            }
            let guess = anchor.warm_start(p, alpha, ct, guess);
            return self.free_reanchored(ct, guess, anchor);
        }
        self.free_reanchored(ct, guess, anchor)
    }

    /// `free_anchored` and the inverse capacity slope dc/dC_t there (for linearising the wall
    /// uptake of an implicit step, which multiplies by it): with an accepted anchor it comes
    /// from the same series, dP/dC_t = (1 − 2k₂u + 3k₃u²)/b, so neither needs a `powf`, and
    /// it is used as it comes (no division to the slope and back: the implicit step's chain
    /// of divisions per cell was its cost).
    /// (The accepted series is inlined into the implicit step's cell loop; the re-anchoring
    /// is a cold call.)
    #[inline(always)]
    pub fn free_and_inv_slope_anchored(
        &self,
        ct: f64,
        guess: f64,
        anchor: &mut HillAnchor,
    ) -> (f64, f64) {
        if let Binding::Hill { alpha, .. } = *self {
            let (p, u, ok) = anchor.invert(ct);
            if ok {
                let k3 = f64::from(anchor.k3);
                let dp_dct = anchor.inv_slope * (1.0 + u * (3.0 * k3 * u - 2.0 * anchor.k2));
                return (alpha * p, alpha * dp_dct);
            }
            let guess = anchor.warm_start(p, alpha, ct, guess);
            return self.free_and_inv_slope_reanchored(ct, guess, anchor);
        }
        self.free_and_inv_slope_reanchored(ct, guess, anchor)
    }

    /// The exact inversion and its inverse slope, re-anchored at the root (the cold path of
    /// `free_and_inv_slope_anchored`).
    #[cold]
    #[inline(never)]
    fn free_and_inv_slope_reanchored(
        &self,
        ct: f64,
        guess: f64,
        anchor: &mut HillAnchor,
    ) -> (f64, f64) {
        let c = self.free_reanchored(ct, guess, anchor);
        (c, 1.0 / self.capacity_slope(c))
    }

    /// Exact inversion, and a new anchor at its root.
    #[inline(never)]
    fn free_reanchored(&self, ct: f64, guess: f64, anchor: &mut HillAnchor) -> f64 {
        let c = self.free(ct, guess);
        if let Binding::Hill {
            alpha,
            p50,
            n,
            capacity,
        } = *self
        {
            if c > 0.0 {
                *anchor = HillAnchor::new(c / alpha, alpha, p50, n, capacity);
            }
        }
        c
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
                // |ΔP| below P_TOL, or a few ulps of P (quadratic convergence stalls there)
                let tol_abs = P_TOL;
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
        // docs/physics.md §4.1: α = 1.40e-3 mol m⁻³ mmHg⁻¹, P50 26.8 mmHg, n 2.7, H = 1.34 mL/g × 150 g/L
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
    fn hill_derivatives_match_finite_differences() {
        // independent check of the D-operator formulas: central differences of S(P)
        let (p50, n) = (26.8 * MMHG, 2.7);
        let s = |p: f64| hill(p, p50, n).0;
        for p_mmhg in [5.0, 26.8, 60.0, 150.0, 500.0] {
            let p = p_mmhg * MMHG;
            let (s0, pk) = hill_derivatives(p, p50, n);
            let h = 1e-2 * p;
            let fd1 = (s(p + h) - s(p - h)) / (2.0 * h);
            let fd2 = (s(p + h) - 2.0 * s(p) + s(p - h)) / (h * h);
            let fd3 = (s(p + 2.0 * h) - 2.0 * s(p + h) + 2.0 * s(p - h) - s(p - 2.0 * h))
                / (2.0 * h * h * h);
            let fd4 = (s(p + 2.0 * h) - 4.0 * s(p + h) + 6.0 * s(p) - 4.0 * s(p - h)
                + s(p - 2.0 * h))
                / (h * h * h * h);
            // O(h²) differences: relative 1e-3 of each derivative, or of its natural scale S'/Pᵏ⁻¹
            let check = |what: &str, exact: f64, fd: f64, scale: f64| {
                assert!(
                    (exact - fd).abs() < 2e-3 * fd.abs().max(scale),
                    "{what} at {p_mmhg} mmHg: {exact:e} vs {fd:e}"
                );
            };
            assert_eq!(s0, s(p));
            check("S1", pk[0] / p, fd1, 0.0);
            check("S2", pk[1] / (p * p), fd2, fd1 / p);
            check("S3", pk[2] / (p * p * p), fd3, fd1 / (p * p));
            check("S4", pk[3] / (p * p * p * p), fd4, fd1 / (p * p * p));
        }
    }

    #[test]
    fn anchored_inversion_matches_the_exact_one_and_skips_powf_near_the_anchor() {
        let b = standard();
        let alpha = 1.40e-3 / MMHG;
        let (mut worst, mut fast, mut near) = (0.0f64, 0usize, 0usize);
        let mut worst_vs_exact = 0.0f64;
        for i in 0..=300 {
            let p1 = 1.0 + 599.0 * i as f64 / 300.0; // mmHg
            for rel in [
                -0.05, -1e-2, -1e-3, -1e-5, -1e-8, 0.0, 1e-7, 1e-4, 3e-3, 0.03,
            ] {
                let mut anchor = HillAnchor::default();
                // establish the anchor at p1 (exact solve), then invert a nearby total
                let c1 = alpha * p1 * MMHG;
                let c1 = b.free_anchored(b.total(c1), c1, &mut anchor);
                let p = p1 * (1.0 + rel);
                let before = anchor.p;
                let ct = b.total(alpha * p * MMHG);
                let back = b.free_anchored(ct, c1, &mut anchor) / alpha / MMHG;
                worst = worst.max((back - p).abs());
                let exact = b.free(ct, c1) / alpha / MMHG;
                worst_vs_exact = worst_vs_exact.max((back - exact).abs());
                if rel.abs() <= 1e-4 {
                    near += 1;
                    fast += usize::from(anchor.p == before);
                }
            }
        }
        assert!(worst < 1e-10, "worst anchored error {worst:e} mmHg");
        assert!(
            worst_vs_exact < 3e-12,
            "anchored vs exact {worst_vs_exact:e} mmHg"
        );
        // a step's change (|ΔP|/P ≲ 1e-4) must take the series path
        assert_eq!(fast, near, "series path taken {fast} of {near} times");
    }

    #[test]
    fn anchor_is_40_bytes_and_a_checkpoint_restores_it_exactly() {
        // the implicit step streams one anchor per cell: its size is memory traffic
        assert_eq!(std::mem::size_of::<HillAnchor>(), 40);
        let b = standard();
        let alpha = 1.40e-3 / MMHG;
        for p in [3.0, 27.0, 60.0, 95.0, 400.0] {
            let mut a = HillAnchor::default();
            let c = b.free_anchored(b.total(alpha * p * MMHG), 0.0, &mut a);
            let mut back = HillAnchor::from_array(&a.to_array());
            assert_eq!(back.to_array(), a.to_array(), "{p} mmHg");
            // the restored anchor takes the same path to the same bits
            let ct = b.total(c * (1.0 + 1e-5));
            let (x, y) = (
                b.free_anchored(ct, c, &mut a),
                b.free_anchored(ct, c, &mut back),
            );
            assert_eq!(x.to_bits(), y.to_bits(), "{p} mmHg");
        }
    }

    #[test]
    fn anchored_inversion_through_anchor_refreshes() {
        // nodes whose totals drift by growing relative steps (1e-9 … 3e-2 per call, both
        // signs), as cells do between stages; includes a zero and a negative total
        let b = standard();
        let alpha = 1.40e-3 / MMHG;
        let n_nodes = 64;
        let nodes: Vec<usize> = (0..n_nodes).collect();
        let mut p: Vec<f64> = (0..n_nodes).map(|i| 2.0 + 9.0 * i as f64).collect(); // mmHg
        let mut free = vec![0.0; n_nodes];
        let mut anchors = vec![HillAnchor::default(); n_nodes];
        let mut worst = 0.0f64;
        for call in 0..200 {
            let rel = 1e-9 * 10f64.powf((call % 8) as f64);
            let sign = if call % 3 == 0 { -1.0 } else { 1.0 };
            let mut total: Vec<f64> = p.iter().map(|&x| b.total(alpha * x * MMHG)).collect();
            total[5] = 0.0;
            total[6] = -1e-12;
            for &n in &nodes {
                free[n] = b.free_anchored(total[n], free[n], &mut anchors[n]);
            }
            for i in 0..n_nodes {
                let exact = b.free(total[i], 0.0);
                worst = worst.max((free[i] - exact).abs() / alpha / MMHG);
            }
            for x in p.iter_mut() {
                *x = (*x * (1.0 + sign * rel.min(3e-2))).clamp(0.5, 650.0);
            }
        }
        // both solves are within P_TOL (1e-12 mmHg) of the root
        assert!(worst < 3e-12, "worst batch error {worst:e} mmHg");
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
