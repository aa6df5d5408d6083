//! Heart chambers with a time-varying elastance (docs/physics.md §1.8). The chamber's volume V
//! is an unknown of its own; the chamber pressure P (its inlet node) follows
//!
//!   P = E(t) (V − V_rest(t)),   dV/dt = Q_in − Q_out,
//!
//! and an optional inductor L between the chamber and its outlet node. The volume row carries
//! the inlet node's flow balance (so the mass matrix stays diagonal); the node's own row is
//! P − E(t) V + E(t) V_rest(t) = 0, linear in the state, its coefficient time-varying.
//!
//! * `elastance-inductor` (svZeroDSolver's `ChamberElastanceInductor`): E = E_min +
//!   (E_max − E_min) φ, V_rest = (1 − φ)(V_rd − V_rs) + V_rs, φ the half-cosine activation;
//! * `linear` (svZeroDSolver's `LinearElastanceChamber`): E = E_pass + E_max φ, V_rest fixed.

use super::Element;
use super::activation::Activation;

#[derive(Debug, Clone, PartialEq)]
pub enum ElastanceLaw {
    ElastanceInductor {
        e_max: f64,
        e_min: f64,
        v_rest_diastole: f64,
        v_rest_systole: f64,
    },
    Linear {
        e_max: f64,
        e_pass: f64,
        v_rest: f64,
    },
    /// svZeroDSolver's `ChamberElastanceInductorExponential` (the atria of the closed-loop
    /// heart): P = φ E_max (V − V_aso) + (1 − φ) K_p (e^{K_v (V − V_aso)} − 1), an active
    /// linear part and a passive exponential one.
    Exponential {
        e_max: f64,
        k_pressure: f64,
        k_volume: f64,
        v_aso: f64,
    },
}

/// E(t) and V_rest(t) of a chamber.
#[derive(Debug, Clone, PartialEq)]
pub struct Elastance {
    pub law: ElastanceLaw,
    pub activation: Activation,
    pub period: f64,
}

impl Elastance {
    /// (E, V_rest) at time t.
    pub fn at(&self, t: f64) -> (f64, f64) {
        self.at_activation(self.activation.eval(t, self.period))
    }

    /// (E, V_rest) at activation φ (the exponential law's active part: E = φ E_max about
    /// V_aso).
    fn at_activation(&self, phi: f64) -> (f64, f64) {
        match self.law {
            ElastanceLaw::ElastanceInductor {
                e_max,
                e_min,
                v_rest_diastole,
                v_rest_systole,
            } => (
                (e_max - e_min) * phi + e_min,
                (1.0 - phi) * (v_rest_diastole - v_rest_systole) + v_rest_systole,
            ),
            ElastanceLaw::Linear {
                e_max,
                e_pass,
                v_rest,
            } => (e_pass + e_max * phi, v_rest),
            ElastanceLaw::Exponential { e_max, v_aso, .. } => (phi * e_max, v_aso),
        }
    }

    /// The chamber pressure P(V, t) and ∂P/∂V.
    pub fn pressure(&self, t: f64, v: f64) -> (f64, f64) {
        if let ElastanceLaw::Exponential {
            e_max,
            k_pressure,
            k_volume,
            v_aso,
        } = self.law
        {
            let phi = self.activation.eval(t, self.period);
            let ex = (k_volume * (v - v_aso)).exp();
            // svZeroDSolver's split: −φE_max V in F, φE_max V_aso + ψ(φ − 1) in C
            let p = phi * e_max * v - (phi * e_max * v_aso + k_pressure * (ex - 1.0) * (phi - 1.0));
            let dp = phi * e_max - k_pressure * k_volume * ex * (phi - 1.0);
            return (p, dp);
        }
        let (e, v_rest) = self.at(t);
        (e * v - e * v_rest, e)
    }
}

impl Elastance {
    /// ∂P/∂θ at (t, V) for the chamber's parameter `key` (its model key: `max_elastance`,
    /// `min_elastance`, `passive_elastance`, the rest volumes, the exponential law's passive
    /// coefficients, or `activation.<timing>` of a differentiable activation, through ∂P/∂φ);
    /// None for a key the chamber's law does not have.
    pub fn pressure_derivative(&self, key: &str, t: f64, v: f64) -> Option<f64> {
        let phi = self.activation.eval(t, self.period);
        if let Some(timing) = key.strip_prefix("activation.") {
            let dphi = self.activation.derivative(timing, t, self.period)?;
            return Some(self.pressure_by_activation(phi, v) * dphi);
        }
        // P = E (V − V_rest) + the exponential law's passive part: ∂P/∂E_max = φ (V − V_rest)
        // in every law
        let (e, vr) = self.at_activation(phi);
        if key == "max_elastance" {
            return Some(phi * (v - vr));
        }
        match self.law {
            ElastanceLaw::ElastanceInductor { .. } => match key {
                "min_elastance" => Some((1.0 - phi) * (v - vr)),
                "rest_volume_diastole" => Some(-e * (1.0 - phi)),
                "rest_volume_systole" => Some(-e * phi),
                _ => None,
            },
            ElastanceLaw::Linear { .. } => match key {
                "passive_elastance" => Some(v - vr),
                "rest_volume" => Some(-e),
                _ => None,
            },
            ElastanceLaw::Exponential {
                k_pressure,
                k_volume,
                ..
            } => {
                let ex = (k_volume * (v - vr)).exp();
                match key {
                    "passive_pressure" => Some(-(ex - 1.0) * (phi - 1.0)),
                    "passive_volume_coefficient" => Some(-k_pressure * (v - vr) * ex * (phi - 1.0)),
                    "rest_volume" => Some(-e + k_pressure * k_volume * ex * (phi - 1.0)),
                    _ => None,
                }
            }
        }
    }

    /// ∂P/∂φ at activation φ and volume V.
    fn pressure_by_activation(&self, phi: f64, v: f64) -> f64 {
        let (e, vr) = self.at_activation(phi);
        match self.law {
            ElastanceLaw::ElastanceInductor {
                e_max,
                e_min,
                v_rest_diastole,
                v_rest_systole,
            } => (e_max - e_min) * (v - vr) + e * (v_rest_diastole - v_rest_systole),
            ElastanceLaw::Linear { e_max, .. } => e_max * (v - vr),
            ElastanceLaw::Exponential {
                e_max,
                k_pressure,
                k_volume,
                ..
            } => e_max * (v - vr) - k_pressure * ((k_volume * (v - vr)).exp() - 1.0),
        }
    }
}

/// The chamber's pressure row: unknowns `pressure` (the chamber node) and `volume`.
#[derive(Debug, Clone)]
pub struct Chamber {
    pub name: String,
    pub elastance: Elastance,
    rows: [usize; 1],
    pattern: [(usize, usize); 1],
}

impl Chamber {
    pub fn new(name: String, elastance: Elastance, pressure: usize, volume: usize) -> Self {
        Chamber {
            name,
            elastance,
            rows: [pressure],
            pattern: [(pressure, volume)],
        }
    }
}

impl Element for Chamber {
    element_fields!();
    fn residual(&self, t: f64, y: &[f64], c: &mut [f64]) {
        c[0] = -self.elastance.pressure(t, y[self.pattern[0].1]).0;
    }
    fn jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        j[0] = -self.elastance.pressure(t, y[self.pattern[0].1]).1;
    }
    fn parameter_derivative(&self, key: &str, t: f64, y: &[f64], dc: &mut [f64]) -> bool {
        let v = y[self.pattern[0].1];
        match self.elastance.pressure_derivative(key, t, v) {
            Some(dp) => {
                dc[0] = -dp;
                true
            }
            None => false,
        }
    }
    fn is_nonlinear(&self) -> bool {
        matches!(self.elastance.law, ElastanceLaw::Exponential { .. })
    }
    fn period(&self) -> Option<f64> {
        Some(self.elastance.period)
    }
    fn breakpoints(&self) -> Vec<f64> {
        self.elastance.activation.breakpoints()
    }
}
