//! openBF's vessel laws (INSIGNEO openBF v2), as its importer maps them onto the linear
//! model: the tube law P = Pext + β′ (√(A/A₀) − 1) with β′ = E h₀ / ((1 − ν²) R₀), the
//! characteristic impedance ρ c₀ / A₀, the Kelvin–Voigt wall viscosity of its visco-elastic
//! wall and the friction of its velocity profile (docs/networks.md, the importer's notes).
//! The importer reads the file; the formulas are here.

use crate::model::sum;
use std::f64::consts::PI;

/// openBF's Poisson ratio σ.
pub const POISSON_RATIO: f64 = 0.5;
/// openBF v2's wall viscosity law Γ = b₀ + b₁/(2 R₀) [kg/s] (Mynard & Smolich 2015): b₀.
pub const VISCO_B0: f64 = 0.6;
/// b₁ [kg m/s] of the wall viscosity law.
pub const VISCO_B1: f64 = 1.5e-3;

/// The 8-point Gauss–Legendre rule on [−1, 1] (the values numpy's `leggauss(8)` gives).
const GL_X: [f64; 8] = [
    -0.9602898564975362,
    -0.7966664774136267,
    -0.525532409916329,
    -0.18343464249564978,
    0.18343464249564978,
    0.525532409916329,
    0.7966664774136267,
    0.9602898564975362,
];
const GL_W: [f64; 8] = [
    0.10122853629037706,
    0.22238103445337443,
    0.3137066458778869,
    0.36268378337836166,
    0.36268378337836166,
    0.3137066458778869,
    0.22238103445337443,
    0.10122853629037706,
];

/// Wall thickness [m] of the ADAN/openBF law h = R (0.2802 e^(−5.053 R[cm]) + 0.1324
/// e^(−0.1114 R[cm])) at lumen radius `r` [m].
pub fn adan_wall_thickness(r: f64) -> f64 {
    r * (0.2802 * (-505.3 * r).exp() + 0.1324 * (-11.14 * r).exp())
}

/// The model viscosity [Pa s] that gives openBF's friction 2 (γ + 2) π μ Q / A² per unit
/// length with the linear model's Poiseuille resistance 8 μ dx / (π r⁴): μ (γ + 2) / 4.
pub fn friction_viscosity(viscosity: f64, gamma_profile: f64) -> f64 {
    viscosity * (gamma_profile + 2.0) / 4.0
}

/// One openBF vessel's wall along x ∈ [0, L]: reference radius R₀ linear from `radius.0`
/// to `radius.1`, Young's modulus, wall thickness h₀ (None: [`adan_wall_thickness`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    pub length: f64,
    pub radius: (f64, f64),
    pub youngs_modulus: f64,
    pub wall_thickness: Option<f64>,
}

impl Wall {
    /// R₀ at `x`.
    pub fn r0(&self, x: f64) -> f64 {
        self.radius.0 + (self.radius.1 - self.radius.0) * x / self.length
    }

    /// h₀ at `x`.
    pub fn h0(&self, x: f64) -> f64 {
        self.wall_thickness
            .unwrap_or_else(|| adan_wall_thickness(self.r0(x)))
    }

    /// openBF's β′ [Pa] at `x`: P = Pext + β′ (√(A/A₀) − 1).
    pub fn beta(&self, x: f64) -> f64 {
        self.youngs_modulus * self.h0(x) / ((1.0 - POISSON_RATIO.powi(2)) * self.r0(x))
    }

    /// Characteristic impedance ρ c₀ / A₀ [Pa s/m³] of the last cell (openBF's two-element
    /// Windkessel correction and its inlet impedance matching), c₀ = √(β′/(2ρ)).
    pub fn characteristic_impedance(&self, density: f64) -> f64 {
        let x = self.length;
        let c0 = (self.beta(x) / (2.0 * density)).sqrt();
        density * c0 / (PI * self.r0(x).powi(2))
    }

    /// The Kelvin–Voigt viscosity η [Pa s] of openBF's visco-elastic wall: E times the
    /// compliance-weighted mean of τ = 2 Γ/(β′ √A₀) along the vessel (weights dA/dP ∝ R₀²/β′,
    /// the rule of a junction where shares of different τ meet), by the 8-point rule.
    pub fn kelvin_voigt_viscosity(&self) -> f64 {
        let mut weighted = [0.0; 8];
        let mut weights = [0.0; 8];
        for k in 0..8 {
            let x = 0.5 * self.length * (GL_X[k] + 1.0);
            let r0 = self.r0(x);
            let gamma = VISCO_B0 + VISCO_B1 / (2.0 * r0);
            let beta = self.beta(x);
            let tau = 2.0 * gamma / (beta * PI.sqrt() * r0);
            weights[k] = GL_W[k] * r0.powi(2) / beta;
            weighted[k] = weights[k] * tau;
        }
        self.youngs_modulus * sum::pairwise(&weighted) / sum::pairwise(&weights)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall(h: Option<f64>) -> Wall {
        Wall {
            length: 0.1,
            radius: (4e-3, 3e-3),
            youngs_modulus: 4e5,
            wall_thickness: h,
        }
    }

    #[test]
    fn the_impedance_is_rho_c_over_area_with_the_moens_korteweg_speed() {
        // uniform wall: c₀² = β′/(2ρ) = E h/(2 ρ r (1 − ν²)), the thin-wall wave speed
        let w = Wall {
            radius: (3e-3, 3e-3),
            ..wall(Some(3e-4))
        };
        let (rho, e, h, r): (f64, f64, f64, f64) = (1060.0, 4e5, 3e-4, 3e-3);
        let c = (e * h / (2.0 * rho * r * 0.75)).sqrt();
        let z = rho * c / (PI * r * r);
        assert!((w.characteristic_impedance(rho) / z - 1.0).abs() < 1e-14);
    }

    #[test]
    fn a_uniform_wall_has_the_viscosity_of_its_tau() {
        // R₀ and h constant: τ constant, so η = E τ with τ = 2 Γ/(β′ √π R₀)
        let w = Wall {
            radius: (3e-3, 3e-3),
            ..wall(Some(3e-4))
        };
        let beta = 4e5 * 3e-4 / (0.75 * 3e-3);
        let gamma = 0.6 + 1.5e-3 / 6e-3;
        let eta = 4e5 * 2.0 * gamma / (beta * PI.sqrt() * 3e-3);
        assert!((w.kelvin_voigt_viscosity() / eta - 1.0).abs() < 1e-14);
    }

    #[test]
    fn the_gauss_rule_integrates_polynomials_to_degree_15() {
        // ∫_{-1}^{1} x^14 dx = 2/15; the weights sum to 2
        let i: f64 = GL_X.iter().zip(GL_W).map(|(x, w)| w * x.powi(14)).sum();
        assert!((i - 2.0 / 15.0).abs() < 1e-15);
        assert!((GL_W.iter().sum::<f64>() - 2.0).abs() < 1e-15);
    }

    #[test]
    fn the_adan_law_at_one_centimetre() {
        // docs/networks.md: 1 cm radius -> 1.2023 mm
        let h = adan_wall_thickness(0.01);
        assert!((h * 1e3 - 1.2023).abs() < 5e-5, "{h}");
        assert_eq!(wall(None).h0(0.0), adan_wall_thickness(4e-3));
        assert_eq!(friction_viscosity(4e-3, 2.0), 4e-3);
        assert_eq!(friction_viscosity(4e-3, 9.0), 4e-3 * 11.0 / 4.0);
    }
}
