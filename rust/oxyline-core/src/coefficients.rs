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

    /// The slopes by R_min and R_max against central differences of the law's values over
    /// its phases (relative step 1e-6: truncation and rounding near 1e-10 of R).
    #[test]
    fn contraction_law_slopes_are_its_differences() {
        let at = |min: f64, max: f64| ResistanceLaw::contraction("c", min, max, 0.3, 0.4, 1.0);
        let law = at(50.0, 200.0).unwrap();
        for t in [0.05, 0.2, 0.3, 0.45, 0.69, 0.9] {
            for (of_max, h) in [(false, 50e-6), (true, 200e-6)] {
                let moved = |d: f64| {
                    let (min, max) = if of_max {
                        (50.0, 200.0 + d)
                    } else {
                        (50.0 + d, 200.0)
                    };
                    at(min, max).unwrap().value(t)
                };
                let diff = (moved(h) - moved(-h)) / (2.0 * h);
                let slope = law.slope(of_max, t);
                assert!(
                    (slope - diff).abs() <= 1e-7,
                    "t {t} max {of_max}: {slope} vs {diff}"
                );
            }
        }
    }
}
