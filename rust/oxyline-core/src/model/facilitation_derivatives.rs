//! Derivatives of the facilitation factor E_Hb by the wall PO2 P_w and by Hill's P50 (the
//! oxygen sensitivities carry them into the wall conductance, docs/calibration.md).
//!
//! Hill binding: E_Hb = g₀/g_d with g₀ the wall flux Φ'F'(0) that the shooting solve finds
//! (F(ζ_end; g₀, P_w, P50) = P_in) and g_d = α D (P_in − P_w)/Γ(4/3) the dissolved layer's.
//! By the implicit-function theorem on the shooting condition, dg₀/dθ = −(∂F_end/∂θ) /
//! (∂F_end/∂g₀), the partial derivatives from the forward sensitivities (u, v) = ∂(F, G)/∂θ
//! integrated beside the profile by the same RK4 (so they are the exact derivatives of the
//! discrete map the solve inverts):
//!
//! ```text
//!     u' = (v − F' δΦ')/Φ',   v' = −3 D ζ² (δC' F' + C' u'),
//!     δΦ' = D_Hb H δS',   δC' = H δS',   δS' = S''(F) u + ∂S'/∂P50 [θ = P50],
//! ```
//!
//! from u(0) = [θ = P_w], v(0) = [θ = g₀]. With S' = n S (1 − S)/P: S'' = S' (n (1 − 2S) −
//! 1)/P and ∂S'/∂P50 = −(P S'' + S')/P50. The range ζ_end is held: the profile is flat there
//! to e^-27, so moving it moves F_end by nothing the solve resolves.
//!
//! Linearised binding: E_Hb = (1 + K̄)^{1/3} (1 + K̄ D_Hb/D)^{2/3} with the secant
//! K̄ = H (S(P_in) − S(P_w))/(α (P_in − P_w)), differentiated in closed form.

use super::{Layer, Shot, linear_factor, shoot};
use crate::hemoglobin::{hill, secant_capacity_ratio};

/// E_Hb and its derivatives by the wall PO2 and by P50 (in the layer's pressure units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FactorDerivatives {
    pub factor: f64,
    pub d_wall_po2: f64,
    pub d_p50: f64,
}

/// Profile (F, G) and the sensitivities (u, v) by g₀, P_w and P50, in that order.
type Augmented = [f64; 8];

impl Layer {
    /// S'(P), S''(P) and ∂S'/∂P50 of the Hill law (0 at P ≤ 0).
    fn slopes(&self, p: f64) -> (f64, f64, f64) {
        if p <= 0.0 {
            return (0.0, 0.0, 0.0);
        }
        let (s, s1) = hill(p, self.p50, self.n);
        let s2 = s1 * (self.n * (1.0 - 2.0 * s) - 1.0) / p;
        (s1, s2, -(p * s2 + s1) / self.p50)
    }

    /// The rates of the profile and its three sensitivities (see the module doc).
    fn augmented_rates(&self, z: f64, y: &Augmented) -> Augmented {
        let (s1, s2, s1_p50) = self.slopes(y[0]);
        let dphi = self.alpha * self.d + self.d_hb * self.capacity * s1;
        let dc = self.alpha + self.capacity * s1;
        let fp = y[1] / dphi;
        let decay = -3.0 * self.d * z * z;
        let mut r = [0.0; 8];
        r[0] = fp;
        r[1] = decay * dc * fp;
        for k in 0..3 {
            let (u, v) = (y[2 + 2 * k], y[3 + 2 * k]);
            let ds1 = s2 * u + if k == 2 { s1_p50 } else { 0.0 };
            let up = (v - fp * self.d_hb * self.capacity * ds1) / dphi;
            r[2 + 2 * k] = up;
            r[3 + 2 * k] = decay * (self.capacity * ds1 * fp + dc * up);
        }
        r
    }

    /// ∂F(ζ_end)/∂(g₀, P_w, P50) from F(0) = P_w, Φ'F'(0) = g₀ (RK4, the shot's steps).
    fn end_sensitivities(&self, p_w: f64, shot: &Shot) -> [f64; 3] {
        let h = shot.zeta_end / shot.steps as f64;
        let mut y: Augmented = [p_w, shot.g0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0];
        let axpy = |y: &Augmented, a: f64, k: &Augmented| -> Augmented {
            std::array::from_fn(|i| y[i] + a * k[i])
        };
        let mut z = 0.0;
        for _ in 0..shot.steps {
            let k1 = self.augmented_rates(z, &y);
            let k2 = self.augmented_rates(z + h / 2.0, &axpy(&y, h / 2.0, &k1));
            let k3 = self.augmented_rates(z + h / 2.0, &axpy(&y, h / 2.0, &k2));
            let k4 = self.augmented_rates(z + h, &axpy(&y, h, &k3));
            y = std::array::from_fn(|i| {
                y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
            z += h;
        }
        [y[2], y[4], y[6]]
    }
}

/// E_Hb of Hill binding ([`super::hill_factor`]) and its derivatives by P_w and P50 (None
/// when P_in = P_w: without a layer the factor jumps to 1 and has no derivative).
pub fn hill_factor_derivatives(p_in: f64, p_w: f64, layer: &Layer) -> Option<FactorDerivatives> {
    if p_in == p_w {
        return None;
    }
    let shot = shoot(p_in, p_w, layer);
    let [by_flux, by_wall, by_p50] = layer.end_sensitivities(p_w, &shot);
    let factor = shot.g0 / shot.dissolved;
    // g₀ = E g_d with g_d ∝ (P_in − P_w): d g_d/dP_w = −g_d/(P_in − P_w)
    Some(FactorDerivatives {
        factor,
        d_wall_po2: -by_wall / by_flux / shot.dissolved + factor / (p_in - p_w),
        d_p50: -by_p50 / by_flux / shot.dissolved,
    })
}

/// E_Hb of linearised binding ([`super::secant_factor`]) and its derivatives by P_w and P50
/// (None when P_in = P_w).
pub fn secant_factor_derivatives(p_in: f64, p_w: f64, layer: &Layer) -> Option<FactorDerivatives> {
    if p_in == p_w {
        return None;
    }
    let (alpha, h) = (layer.alpha, layer.capacity);
    let kbar = secant_capacity_ratio(alpha, layer.p50, layer.n, h, p_w, p_in);
    let r = layer.d_hb / layer.d;
    let factor = linear_factor(kbar, layer.d, layer.d_hb);
    let de_dk = factor * (1.0 / (3.0 * (1.0 + kbar)) + 2.0 * r / (3.0 * (1.0 + kbar * r)));
    let (_, s1_w) = hill(p_w, layer.p50, layer.n);
    let (_, s1_in) = hill(p_in, layer.p50, layer.n);
    // ∂S/∂P50 = −(P/P50) S'
    let ds_p50 = |p: f64, s1: f64| -p / layer.p50 * s1;
    let dk_wall = (kbar - h * s1_w / alpha) / (p_in - p_w);
    let dk_p50 = h * (ds_p50(p_in, s1_in) - ds_p50(p_w, s1_w)) / (alpha * (p_in - p_w));
    Some(FactorDerivatives {
        factor,
        d_wall_po2: de_dk * dk_wall,
        d_p50: de_dk * dk_p50,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{hill_factor, secant_factor};
    use super::*;

    /// Plasma O2 in mmHg units and the standard oxyhaemoglobin law (docs/physics.md §4.1).
    fn standard(d_hb: f64) -> Layer {
        Layer {
            alpha: 1.40e-3,
            d: 2.0e-9,
            d_hb,
            capacity: 1.34 * 150.0 / 22.414,
            p50: 26.8,
            n: 2.7,
        }
    }

    /// Central differences of `e` at relative step `h` by P_w and by P50.
    fn central(e: impl Fn(f64, f64) -> f64, p_w: f64, p50: f64, h: f64) -> (f64, f64) {
        let (dw, dp) = (h * p_w, h * p50);
        (
            (e(p_w + dw, p50) - e(p_w - dw, p50)) / (2.0 * dw),
            (e(p_w, p50 + dp) - e(p_w, p50 - dp)) / (2.0 * dp),
        )
    }

    #[test]
    fn hill_derivatives_against_central_differences_of_the_factor() {
        // relative step 1e-4: the difference quotient's truncation ~1e-8 of the slope, and
        // the shooting solve's 1e-10 stopping rule moves E_Hb by ~1e-10, ~1e-6 of the
        // quotient; judged to 1e-5 of the factor per unit of ln P (a wrong term is ≥ 1e-2)
        let mut worst = 0.0f64;
        for d_hb in [5.5e-12, 7.0e-11] {
            for (p_in, p_w) in [(85.0, 48.0), (95.0, 60.0), (60.0, 20.0), (40.0, 55.0)] {
                let base = standard(d_hb);
                let e = |p_w: f64, p50: f64| hill_factor(p_in, p_w, &Layer { p50, ..base });
                let got = hill_factor_derivatives(p_in, p_w, &base).unwrap();
                assert_eq!(got.factor, hill_factor(p_in, p_w, &base));
                let (fd_w, fd_p) = central(e, p_w, base.p50, 1e-4);
                let tol = 1e-5 * got.factor;
                let err = (got.d_wall_po2 - fd_w).abs() * p_w;
                worst = worst.max(err.max((got.d_p50 - fd_p).abs() * base.p50) / got.factor);
                assert!(
                    (got.d_wall_po2 - fd_w).abs() * p_w < tol,
                    "P_w {p_w} P_in {p_in}: {} vs {fd_w}",
                    got.d_wall_po2
                );
                assert!(
                    (got.d_p50 - fd_p).abs() * base.p50 < tol,
                    "P_w {p_w} P_in {p_in}: {} vs {fd_p}",
                    got.d_p50
                );
                // and they matter: E_Hb moves by per cent per unit of ln P
                assert!(got.d_p50.abs() * base.p50 > 1e-2 * got.factor);
            }
        }
        eprintln!("E_Hb derivatives against central differences: {worst:.2e} of E_Hb");
    }

    #[test]
    fn linear_limit_derivatives_are_the_closed_form() {
        // n = 1 and P ≪ P50: K = H/(α P50) constant, E = (1 + K)^{1/3} (1 + K r)^{2/3}, so
        // dE/dP50 = −(K/P50) E (1/(3(1 + K)) + 2r/(3(1 + K r))) and dE/dP_w = 0, written out;
        // K moves by ~P/P50 = 1e-4 across the layer, so both to 1e-3 of dE/d ln P50
        let (alpha, d, d_hb, p50) = (1.40e-3, 2.0e-9, 7.0e-11, 1.0e6);
        let r = d_hb / d;
        for k in [0.5, 5.0, 50.0] {
            let layer = Layer {
                alpha,
                d,
                d_hb,
                capacity: k * alpha * p50,
                p50,
                n: 1.0,
            };
            let got = hill_factor_derivatives(85.0, 48.0, &layer).unwrap();
            let e = linear_factor(k, d, d_hb);
            let exact = -k / p50 * e * (1.0 / (3.0 * (1.0 + k)) + 2.0 * r / (3.0 * (1.0 + k * r)));
            let scale = exact.abs() * p50;
            assert!((got.d_p50 - exact).abs() * p50 < 1e-3 * scale, "k {k}");
            assert!(got.d_wall_po2.abs() * 85.0 < 1e-3 * scale, "k {k}");
        }
    }

    #[test]
    fn secant_derivatives_against_central_differences() {
        // closed form against the quotient (relative step 1e-5: truncation ~1e-10, rounding
        // ~1e-11 of the factor), to 1e-7 of the factor per unit of ln P
        let base = standard(7.0e-11);
        for (p_in, p_w) in [(85.0, 48.0), (60.0, 20.0)] {
            let e = |p_w: f64, p50: f64| secant_factor(p_in, p_w, &Layer { p50, ..base });
            let got = secant_factor_derivatives(p_in, p_w, &base).unwrap();
            let (fd_w, fd_p) = central(e, p_w, base.p50, 1e-5);
            assert!((got.d_wall_po2 - fd_w).abs() * p_w < 1e-7 * got.factor);
            assert!((got.d_p50 - fd_p).abs() * base.p50 < 1e-7 * got.factor);
        }
        assert!(secant_factor_derivatives(60.0, 60.0, &base).is_none());
        assert!(hill_factor_derivatives(60.0, 60.0, &base).is_none());
    }
}
