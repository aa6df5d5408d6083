//! Haemoglobin facilitation of the wall boundary layer (docs/physics.md §3.4).
//!
//! With binding equilibrium and oxyhaemoglobin diffusing with D_Hb, the O2 content is
//! C(P) = α P + H S(P) and the total flux −∇Φ with Φ(P) = α D P + D_Hb H S(P). In the Lévêque
//! layer (u = γ y) the PO2 is a similarity profile P = F(ζ), ζ = y (γ/(9 D x))^{1/3}:
//!
//! ```text
//!     d/dζ (Φ'(F) F') = −3 D ζ² C'(F) F',     F(0) = P_w,  F(∞) = P_in,
//! ```
//!
//! and the wall flux is Φ'(F) F'(0) (γ/(9 D x))^{1/3}. For dissolved O2 alone (Φ' = α D,
//! C' = α) this is Lévêque's F' ∝ exp(−ζ³), flux α D (P_in − P_w)/Γ(4/3); the ratio of the two
//! is the facilitation factor E_Hb that multiplies the dissolved-O2 closure.
//!
//! * linearised haemoglobin has C' = α(1 + K̄), Φ' = α D (1 + K̄ D_Hb/D) with the secant K̄:
//!   the ODE is linear and E_Hb = (1 + K̄)^{1/3} (1 + K̄ D_Hb/D)^{2/3} in closed form;
//! * Hill haemoglobin has K(P) = H S'(P)/α varying several-fold across the layer (26 at
//!   60 mmHg, 8 at 85 mmHg): the secant factor then overestimates the uptake by 7–12 % against
//!   the 2-D solution with Hill binding (docs/validation-oxygen.md §7), so E_Hb is the ratio of
//!   the nonlinear similarity solution's wall flux to Lévêque's, found here by shooting.
//!
//! Any consistent units (the Python layer passes mmHg and mol m⁻³ mmHg⁻¹): only ratios enter.

use crate::closure::GAMMA_4_3;
use crate::hemoglobin::{hill, secant_capacity_ratio};

/// Integration range in ζ for the largest diffusivity ratio D*/D = Φ'/(D C') ≤ 1 met: F'
/// decays at least as exp(−ζ³ D/D*max), so the profile is flat to < e^-27 at 3 (D*max/D)^{1/3}.
const ZETA_RANGE: f64 = 3.0;
/// RK4 stability: the decay rate 3 ζ² D/D* times the step stays below this (RK4's real-axis
/// limit is 2.79); at least MIN_STEPS steps (300 change E_Hb by < 1e-7 from 600).
const STEP_RATE: f64 = 1.5;
const MIN_STEPS: usize = 300;
/// Pressures sampled across [P_w, P_in] for the bracket of the wall flux.
const SAMPLES: usize = 64;

/// Haemoglobin's Hill law and the diffusivities of the layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    /// Solubility α (content per pressure).
    pub alpha: f64,
    /// O2 diffusivity D and oxyhaemoglobin diffusivity D_Hb (m²/s).
    pub d: f64,
    pub d_hb: f64,
    /// Binding capacity H (content), Hill P50 (pressure) and exponent n.
    pub capacity: f64,
    pub p50: f64,
    pub n: f64,
}

/// E_Hb of linearised binding with secant K̄ (closed form).
pub fn linear_factor(kbar: f64, d: f64, d_hb: f64) -> f64 {
    (1.0 + kbar).cbrt() * (1.0 + kbar * d_hb / d).powf(2.0 / 3.0)
}

/// E_Hb of the linearised law between the wall and inlet pressures: the Hill secant K̄ over
/// [P_w, P_in] in [`linear_factor`] (K̄ = 0 without a layer, P_in = P_w).
pub fn secant_factor(p_in: f64, p_w: f64, layer: &Layer) -> f64 {
    let kbar = if p_in == p_w {
        0.0
    } else {
        secant_capacity_ratio(layer.alpha, layer.p50, layer.n, layer.capacity, p_w, p_in)
    };
    linear_factor(kbar, layer.d, layer.d_hb)
}

impl Layer {
    /// dS/dP of the Hill law (0 at P ≤ 0).
    fn dsat(&self, p: f64) -> f64 {
        hill(p, self.p50, self.n).1
    }

    /// (F', G') of the ODE as the first-order system F' = G/Φ'(F), G' = −3 D ζ² C'(F) F'.
    fn rates(&self, z: f64, f: f64, g: f64) -> (f64, f64) {
        let ds = self.dsat(f);
        let dphi = self.alpha * self.d + self.d_hb * self.capacity * ds;
        let dc = self.alpha + self.capacity * ds;
        let fp = g / dphi;
        (fp, -3.0 * self.d * z * z * dc * fp)
    }

    /// F(ζ_end) of the ODE started at F(0) = P_w with Φ'F'(0) = g0 (RK4, `steps` steps).
    fn end_value(&self, g0: f64, p_w: f64, zeta_end: f64, steps: usize) -> f64 {
        let h = zeta_end / steps as f64;
        let (mut f, mut g, mut z) = (p_w, g0, 0.0);
        for _ in 0..steps {
            let k1 = self.rates(z, f, g);
            let k2 = self.rates(z + h / 2.0, f + h / 2.0 * k1.0, g + h / 2.0 * k1.1);
            let k3 = self.rates(z + h / 2.0, f + h / 2.0 * k2.0, g + h / 2.0 * k2.1);
            let k4 = self.rates(z + h, f + h * k3.0, g + h * k3.1);
            f += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            g += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
            z += h;
        }
        f
    }
}

/// The shooting solve of the Hill layer: the wall flux Φ'F'(0) that reaches P_in, the
/// dissolved layer's flux, and the integration range and steps it was found with.
struct Shot {
    g0: f64,
    dissolved: f64,
    zeta_end: f64,
    steps: usize,
}

/// E_Hb of Hill binding: the nonlinear Lévêque layer's wall flux over the dissolved one (1
/// when P_in = P_w: no layer). F(ζ_max) increases monotonically and smoothly with the wall
/// flux: Illinois regula falsi on it, to 1e-10 of P_in − P_w.
pub fn hill_factor(p_in: f64, p_w: f64, layer: &Layer) -> f64 {
    if p_in == p_w {
        return 1.0;
    }
    let shot = shoot(p_in, p_w, layer);
    shot.g0 / shot.dissolved
}

fn shoot(p_in: f64, p_w: f64, layer: &Layer) -> Shot {
    let (d, d_hb) = (layer.d, layer.d_hb);
    let dissolved = layer.alpha * d * (p_in - p_w) / GAMMA_4_3;
    // the flux lies between the dissolved value scaled by the smallest and largest linear
    // factors over [P_w, P_in]; widened so that the bracket always holds
    let (mut k_min, mut k_max) = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut ratio_min, mut ratio_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for i in 0..=SAMPLES {
        let p = p_w + (p_in - p_w) * i as f64 / SAMPLES as f64;
        let k = layer.capacity * layer.dsat(p) / layer.alpha;
        let ratio = (1.0 + k * d_hb / d) / (1.0 + k); // D*/D
        (k_min, k_max) = (k_min.min(k), k_max.max(k));
        (ratio_min, ratio_max) = (ratio_min.min(ratio), ratio_max.max(ratio));
    }
    let zeta_end = ZETA_RANGE * ratio_max.cbrt();
    let steps = MIN_STEPS.max((3.0 * zeta_end.powi(3) / ratio_min / STEP_RATE).ceil() as usize);
    let miss = |g0: f64| (layer.end_value(g0, p_w, zeta_end, steps) - p_in) / (p_in - p_w);
    let mut a = 0.5 * dissolved * linear_factor(k_min, d, d_hb);
    let mut b = 2.0 * dissolved * linear_factor(k_max, d, d_hb);
    let (mut fa, mut fb) = (miss(a), miss(b));
    let mut side = 0;
    let mut c = a;
    for _ in 0..100 {
        c = (a * fb - b * fa) / (fb - fa);
        let fc = miss(c);
        if fc.abs() < 1e-10 {
            break;
        }
        if (fc > 0.0) == (fb > 0.0) {
            (b, fb) = (c, fc);
            if side == -1 {
                fa /= 2.0;
            }
            side = -1;
        } else {
            (a, fa) = (c, fc);
            if side == 1 {
                fb /= 2.0;
            }
            side = 1;
        }
    }
    Shot {
        g0: c,
        dissolved,
        zeta_end,
        steps,
    }
}

#[path = "facilitation_derivatives.rs"]
mod derivatives;
pub use derivatives::{FactorDerivatives, hill_factor_derivatives, secant_factor_derivatives};

#[cfg(test)]
mod tests {
    use super::*;

    /// O2 in plasma (mmHg units, as the Python layer passes them): α mol m⁻³ mmHg⁻¹, D, D_Hb.
    const ALPHA: f64 = 1.40e-3;
    const D: f64 = 2.0e-9;
    const D_HB: f64 = 5.5e-12;

    #[test]
    fn linear_limit_is_the_closed_form() {
        // n = 1 and P ≪ P50: S ≈ P/P50, so K(P) = H/(α P50) is constant and the layer is
        // linear; the closed form (1 + K)^{1/3} (1 + K D_Hb/D)^{2/3} written out here
        let p50 = 1.0e6;
        for k in [0.5, 5.0, 50.0] {
            let layer = Layer {
                alpha: ALPHA,
                d: D,
                d_hb: D_HB,
                capacity: k * ALPHA * p50,
                p50,
                n: 1.0,
            };
            let e = hill_factor(85.0, 48.0, &layer);
            let exact = f64::powf(1.0 + k, 1.0 / 3.0) * f64::powf(1.0 + k * D_HB / D, 2.0 / 3.0);
            // S = P/(P + P50) departs from P/P50 by P/P50 ~ 1e-4: K varies by ~1e-4 across
            // the layer, E_Hb by less
            assert!((e / exact - 1.0).abs() < 1e-4, "k {k}: {e} vs {exact}");
            assert!((linear_factor(k, D, D_HB) / exact - 1.0).abs() < 1e-15);
        }
    }

    #[test]
    fn no_haemoglobin_is_no_facilitation() {
        // capacity 0: the dissolved layer itself, whose wall flux is Lévêque's (E = 1); RK4 with
        // 300 steps over ζ ≤ 3 and the 1e-10 stopping rule
        let layer = Layer {
            alpha: ALPHA,
            d: D,
            d_hb: D_HB,
            capacity: 0.0,
            p50: 26.8,
            n: 2.7,
        };
        assert!((hill_factor(85.0, 48.0, &layer) - 1.0).abs() < 1e-8);
        assert_eq!(hill_factor(60.0, 60.0, &layer), 1.0);
    }

    #[test]
    fn hill_factor_lies_between_the_linear_factors_of_its_extreme_slopes() {
        // a monotone bound: K(P) between its extremes over [48, 85] mmHg bounds the flux
        let layer = Layer {
            alpha: ALPHA,
            d: D,
            d_hb: 7.0e-11,
            capacity: 1.34 * 150.0 / 22.414,
            p50: 26.8,
            n: 2.7,
        };
        let e = hill_factor(85.0, 48.0, &layer);
        let k = |p: f64| layer.capacity * layer.dsat(p) / ALPHA;
        let (lo, hi) = (k(85.0), k(48.0));
        assert!(linear_factor(lo, D, 7.0e-11) < e && e < linear_factor(hi, D, 7.0e-11));
        // and below the secant factor over the same range (docs/validation-oxygen.md §7)
        assert!(e < secant_factor(85.0, 48.0, &layer));
    }
}
