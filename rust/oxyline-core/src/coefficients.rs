//! Time-varying circuit coefficients (docs/physics.md §1.7): a branch resistance that follows a
//! periodic law R(t). The DAE keeps the law's base value R₀ in its constant matrix F (it is also
//! the value of the steady regimes) and adds the time-varying part (R(t) − R₀)·Q as a separate,
//! linear-in-the-state term, so circuits without such laws keep their constant-matrix fast path.

use crate::error::{Error, Result};

/// A periodic law for a branch resistance (Pa·s/m³).
#[derive(Debug, Clone, PartialEq)]
pub enum ResistanceLaw {
    /// The microvascular resistance of a coronary bed under cardiac contraction
    /// (svZeroDSolver's `CORONARY_VAR_RES`): √R(t) = √R_min + (√R_max − √R_min)·e(t) with the
    /// activation e(τ) = ½(1 − cos(πτ/T_c)) for τ ≤ T_c (contraction), ½(1 + cos(π(τ − T_c)/T_r))
    /// for T_c < τ ≤ T_c + T_r (relaxation) and 0 after (rest); τ = t mod the cycle period.
    /// Its base (steady) value is R_min.
    Contraction {
        min: f64,
        max: f64,
        contraction: f64,
        relaxation: f64,
        period: f64,
    },
}

impl ResistanceLaw {
    /// The contraction law, with its values checked (`element` names the condition).
    pub fn contraction(
        element: &str,
        min: f64,
        max: f64,
        contraction: f64,
        relaxation: f64,
        period: f64,
    ) -> Result<Self> {
        let bad = |key: &str, v: f64, what: &str| {
            Err(Error::model(
                element,
                format!("{key} must be {what}, got {v}"),
            ))
        };
        if !(min.is_finite() && min >= 0.0) {
            return bad("microvascular_resistance", min, "a finite number >= 0");
        }
        if !(max.is_finite() && max >= 0.0) {
            return bad("microvascular_resistance_max", max, "a finite number >= 0");
        }
        if !(contraction.is_finite() && contraction > 0.0) {
            return bad("contraction_time", contraction, "a finite number > 0");
        }
        if !(relaxation.is_finite() && relaxation > 0.0) {
            return bad("relaxation_time", relaxation, "a finite number > 0");
        }
        if !(period.is_finite() && period > 0.0) {
            return bad("cycle_period", period, "a finite number > 0");
        }
        Ok(ResistanceLaw::Contraction {
            min,
            max,
            contraction,
            relaxation,
            period,
        })
    }

    /// R(t).
    pub fn value(&self, t: f64) -> f64 {
        let ResistanceLaw::Contraction { min, max, .. } = *self;
        match self.activation(t) {
            Some(e) => {
                let r = min.sqrt() + (max.sqrt() - min.sqrt()) * e;
                r * r
            }
            // at rest exactly R_min (the square of its square root can differ by an ulp):
            // the time-varying term then vanishes
            None => min,
        }
    }

    /// ∂R(t)/∂R_min, or ∂R(t)/∂R_max with `of_max` (the law's values above zero): by
    /// √R = √R_min + (√R_max − √R_min) e, 2√R ∂√R = … gives √R (1 − e)/√R_min and √R e/√R_max.
    pub fn slope(&self, of_max: bool, t: f64) -> f64 {
        let ResistanceLaw::Contraction { min, max, .. } = *self;
        match self.activation(t) {
            Some(e) => {
                let r = min.sqrt() + (max.sqrt() - min.sqrt()) * e;
                if of_max {
                    r * e / max.sqrt()
                } else {
                    r * (1.0 - e) / min.sqrt()
                }
            }
            // at rest R = R_min exactly (`value`)
            None => {
                if of_max {
                    0.0
                } else {
                    1.0
                }
            }
        }
    }

    /// ∂R(t)/∂T_c, or ∂R(t)/∂T_r with `of_relaxation`: ∂R/∂e = 2√R (√R_max − √R_min) times
    /// the activation's slope by the time, −½ sin(πτ/T_c) πτ/T_c² over the contraction and
    /// ½ sin(u) π/T_r (by T_c) or ½ sin(u) π(τ − T_c)/T_r² (by T_r), u = π(τ − T_c)/T_r, over
    /// the relaxation; 0 at rest. Both vanish at the phase ends, so R(t) is differentiable in
    /// the times at every t.
    pub fn timing_slope(&self, of_relaxation: bool, t: f64) -> f64 {
        let ResistanceLaw::Contraction {
            min,
            max,
            contraction,
            relaxation,
            period,
        } = *self;
        let tau = t.rem_euclid(period);
        let pi = std::f64::consts::PI;
        let de = if tau <= contraction {
            if of_relaxation {
                0.0
            } else {
                -0.5 * (pi * tau / contraction).sin() * pi * tau / (contraction * contraction)
            }
        } else if tau <= contraction + relaxation {
            let u = pi * (tau - contraction) / relaxation;
            if of_relaxation {
                0.5 * u.sin() * pi * (tau - contraction) / (relaxation * relaxation)
            } else {
                0.5 * u.sin() * pi / relaxation
            }
        } else {
            return 0.0;
        };
        let e = self.activation(t).unwrap_or(0.0);
        let span = max.sqrt() - min.sqrt();
        2.0 * (min.sqrt() + span * e) * span * de
    }

    /// The contraction's activation e(t) in [0, 1] (a raised cosine up over the contraction,
    /// down over the relaxation); None at rest, where R is R_min exactly.
    fn activation(&self, t: f64) -> Option<f64> {
        let ResistanceLaw::Contraction {
            contraction,
            relaxation,
            period,
            ..
        } = *self;
        let tau = t.rem_euclid(period);
        let pi = std::f64::consts::PI;
        if tau <= contraction {
            Some(0.5 * (1.0 - (pi * tau / contraction).cos()))
        } else if tau <= contraction + relaxation {
            Some(0.5 * (1.0 + (pi * (tau - contraction) / relaxation).cos()))
        } else {
            None
        }
    }

    /// The value kept in the constant matrix and used by the steady regimes.
    pub fn base(&self) -> f64 {
        match *self {
            ResistanceLaw::Contraction { min, .. } => min,
        }
    }

    /// R(t) − R₀: the time-varying part added to the constant matrix.
    #[inline]
    pub fn delta(&self, t: f64) -> f64 {
        self.value(t) - self.base()
    }

    pub fn period(&self) -> f64 {
        match *self {
            ResistanceLaw::Contraction { period, .. } => period,
        }
    }

    /// Times within a period where the law reaches its extremes or changes phase (for
    /// sampling the frozen-coefficient stability limit).
    pub fn breakpoints(&self) -> Vec<f64> {
        match *self {
            ResistanceLaw::Contraction {
                contraction,
                relaxation,
                period,
                ..
            } => [0.0, contraction, contraction + relaxation]
                .into_iter()
                .filter(|&t| t < period)
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contraction_law_reaches_its_extremes_at_the_phase_ends() {
        let law = ResistanceLaw::contraction("c", 50.0, 200.0, 0.3, 0.4, 1.0).unwrap();
        // exact values of the cosine activation: 0 at rest, 1 at the end of contraction,
        // ½ half-way (√R = (√50 + √200)/2 = 1.5 √50, R = 112.5)
        assert!((law.value(0.0) - 50.0).abs() < 1e-12);
        assert!((law.value(0.3) - 200.0).abs() < 1e-12);
        assert!((law.value(0.15) - 112.5).abs() < 1e-12);
        assert!((law.value(0.9) - 50.0).abs() < 1e-12);
        // periodic
        assert!((law.value(3.15) - 112.5).abs() < 1e-9);
        assert_eq!(law.delta(0.8), 0.0);
        assert!(ResistanceLaw::contraction("c", 50.0, 200.0, 0.0, 0.4, 1.0).is_err());
    }

    /// The slope of the law's value at each of `times` by each of its two parameters
    /// (`slope(law, second, t)`) against central differences of the law built at `base`
    /// moved by ±`step[k]` in parameter k (`at(p0, p1)`), within `tol(slope)`.
    fn assert_slopes_are_differences(
        at: impl Fn(f64, f64) -> ResistanceLaw,
        base: [f64; 2],
        step: [f64; 2],
        times: &[f64],
        slope: impl Fn(&ResistanceLaw, bool, f64) -> f64,
        tol: impl Fn(f64) -> f64,
    ) {
        let law = at(base[0], base[1]);
        for &t in times {
            for (k, second) in [(0, false), (1, true)] {
                let moved = |d: f64| {
                    let mut p = base;
                    p[k] += d;
                    at(p[0], p[1]).value(t)
                };
                let h = step[k];
                let diff = (moved(h) - moved(-h)) / (2.0 * h);
                let got = slope(&law, second, t);
                assert!(
                    (got - diff).abs() <= tol(got),
                    "t {t} parameter {k}: {got} vs {diff}"
                );
            }
        }
    }

    /// The slopes by R_min and R_max against central differences of the law's values over
    /// its phases (relative step 1e-6: truncation and rounding near 1e-10 of R).
    #[test]
    fn contraction_law_slopes_are_its_differences() {
        assert_slopes_are_differences(
            |min, max| ResistanceLaw::contraction("c", min, max, 0.3, 0.4, 1.0).unwrap(),
            [50.0, 200.0],
            [50e-6, 200e-6],
            &[0.05, 0.2, 0.3, 0.45, 0.69, 0.9],
            |law, of_max, t| law.slope(of_max, t),
            |_| 1e-7,
        );
    }

    #[test]
    fn contraction_law_timing_slopes_are_its_differences() {
        // T_c 0.3, T_r 0.4 in a 1 s cycle: times in the contraction, the relaxation, at rest
        // and in the next cycle; central differences with a step of 1e-6 of the times
        // (truncation ~1e-12 · the third derivative, rounding ~1e-16 · 200 / 1e-6 ~ 2e-8)
        let at = |tc: f64, tr: f64| ResistanceLaw::contraction("c", 50.0, 200.0, tc, tr, 1.0);
        assert_slopes_are_differences(
            |tc, tr| at(tc, tr).unwrap(),
            [0.3, 0.4],
            [0.3e-6, 0.4e-6],
            &[0.05, 0.2, 0.29, 0.45, 0.69, 0.9, 1.2],
            |law, of_relaxation, t| law.timing_slope(of_relaxation, t),
            |slope| 1e-5 * (1.0 + slope.abs()),
        );
        let law = at(0.3, 0.4).unwrap();
        // inside a phase the slope is not zero (the check can fail)
        assert!(law.timing_slope(false, 0.2).abs() > 1.0);
        assert!(law.timing_slope(true, 0.45).abs() > 1.0);
    }
}
