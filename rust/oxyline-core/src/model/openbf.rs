//! openBF's vessel laws (INSIGNEO openBF v2), as its importer maps them onto the linear
//! model: the tube law P = Pext + β′ (√(A/A₀) − 1) with β′ = E h₀ / ((1 − ν²) R₀), the
//! characteristic impedance ρ c₀ / A₀, the Kelvin–Voigt wall viscosity of its visco-elastic
//! wall and the friction of its velocity profile (docs/networks.md, the importer's notes).
//! The importer reads the file; the formulas are here, and the fixed point of the steady
//! network and the tube law that gives the linearisation pressures (`steady`).

pub mod steady;

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
    crate::segment::wall_thickness_law(r, ADAN_THICKNESS)
}

/// The ADAN thickness law's [a, b, c, d] of [`crate::segment::wall_thickness_law`] (b, d
/// per metre).
pub const ADAN_THICKNESS: [f64; 4] = [0.2802, -505.3, 0.1324, -11.14];

/// The model viscosity [Pa s] that gives openBF's friction 2 (γ + 2) π μ Q / A² per unit
/// length with the linear model's Poiseuille resistance 8 μ dx / (π r⁴): μ (γ + 2) / 4.
pub fn friction_viscosity(viscosity: f64, gamma_profile: f64) -> f64 {
    viscosity * (gamma_profile + 2.0) / 4.0
}

/// openBF v2's number of cells along a vessel: max(M, 5, ⌈L [mm]⌉), `m` the file's `M`.
pub fn cells(m: f64, length: f64) -> f64 {
    m.max(5.0).max((length * 1e3).ceil())
}

/// The distal radius [m] that openBF v2 actually uses along a tapered vessel: its R₀ at cell
/// i is Rp + (Rd − Rp) xᵢ/(M − 1) with xᵢ in metres, so at x = L it reaches
/// Rp + (Rd − Rp) L/(M − 1), not Rd (the importer's `taper="openbf"`; `m` the file's `M`).
pub fn taper_quirk_distal_radius(rp: f64, rd: f64, length: f64, m: f64) -> f64 {
    rp + (rd - rp) / (cells(m, length) - 1.0) * length
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

    /// r/R₀ = √(A/A₀) = 1 + (p − Pext)/β′ at `x` and pressure `p` (the tube law).
    pub fn stretch(&self, x: f64, p: f64, external_pressure: f64) -> f64 {
        1.0 + (p - external_pressure) / self.beta(x)
    }

    /// The linear model's vessel at end pressures `p_in` → `p_out` (linear along x): the
    /// radii r = R₀ s at the ends and the wall thickness h for which the thin-wall compliance
    /// of the linear taper (ν = [`POISSON_RATIO`]) equals openBF's tangent compliance
    /// dA/dP = 2π R₀³ (1 − ν²)/(E h₀) s integrated over the vessel (8-point rule). Err: the
    /// tube law collapses the vessel (s ≤ 0.05), with the lowest pressure of the points
    /// checked (the ends, else the rule's nodes).
    pub fn linearised(
        &self,
        p_in: f64,
        p_out: f64,
        external_pressure: f64,
    ) -> std::result::Result<(f64, f64, f64), f64> {
        let l = self.length;
        let collapsed = |ps: &[f64]| ps.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        let ends = [(0.0, p_in), (l, p_out)];
        let s_end = ends.map(|(x, p)| self.stretch(x, p, external_pressure));
        if s_end.iter().any(|&s| s <= 0.05) {
            return Err(collapsed(&[p_in, p_out]));
        }
        let r_in = self.r0(0.0) * s_end[0];
        let r_out = self.r0(l) * s_end[1];
        let nu2 = 1.0 - POISSON_RATIO.powi(2);
        let mut target = [0.0; 8];
        let mut linear = [0.0; 8];
        for k in 0..8 {
            let x = 0.5 * l * (GL_X[k] + 1.0);
            let w = 0.5 * l * GL_W[k];
            let p = p_in + (p_out - p_in) * x / l;
            let s = self.stretch(x, p, external_pressure);
            if s <= 0.05 {
                return Err(collapsed(&pressures_at(p_in, p_out, l)));
            }
            target[k] =
                w * 2.0 * PI * self.r0(x).powf(3.0) * nu2 * s / (self.youngs_modulus * self.h0(x));
            let r_lin = r_in + (r_out - r_in) * x / l;
            linear[k] = w * 2.0 * PI * r_lin.powf(3.0) * nu2 / self.youngs_modulus;
        }
        let h = sum::pairwise(&linear) / sum::pairwise(&target);
        Ok((r_in, r_out, h))
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

/// The pressures at the 8-point rule's nodes of a vessel of length `l` at end pressures
/// `p_in` → `p_out`.
fn pressures_at(p_in: f64, p_out: f64, l: f64) -> [f64; 8] {
    GL_X.map(|g| p_in + (p_out - p_in) * (0.5 * l * (g + 1.0)) / l)
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
    fn a_uniform_wall_linearised_keeps_its_compliance() {
        // uniform R₀, h₀ and pressure: s constant, r = R₀ s, and C' = 2π r³ (1 − ν²)/(E h)
        // must equal openBF's 2π R₀³ (1 − ν²) s/(E h₀): h = h₀ s²
        let w = Wall {
            radius: (3e-3, 3e-3),
            ..wall(Some(3e-4))
        };
        let beta = 4e5 * 3e-4 / (0.75 * 3e-3);
        let s = 1.0 + (1.2e4 - 2e3) / beta;
        let (r_in, r_out, h) = w.linearised(1.2e4, 1.2e4, 2e3).unwrap();
        assert!((r_in / (3e-3 * s) - 1.0).abs() < 1e-15);
        assert!((r_out / r_in - 1.0).abs() < 1e-15);
        assert!((h / (3e-4 * s * s) - 1.0).abs() < 1e-14, "{h}");
        // a pressure far below Pext collapses the tube: the lower end pressure is named
        assert_eq!(w.linearised(-1e6, -2e6, 0.0), Err(-2e6));
    }

    #[test]
    fn the_taper_quirk_slope_is_per_cell_times_metres() {
        // 10 cells (M = 10 > 5 and > ⌈L mm⌉ = 5): R₀(L) = Rp + (Rd − Rp) L / 9, ~Rp
        let (rp, rd, l) = (4e-3, 2e-3, 5e-3);
        assert_eq!(cells(10.0, l), 10.0);
        assert_eq!(cells(2.0, l), 5.0);
        assert_eq!(cells(2.0, 0.0123), 13.0);
        // within an ulp of the closed form (the same operations in another order)
        let r = taper_quirk_distal_radius(rp, rd, l, 10.0);
        assert!((r - (4e-3 - 2e-3 * 5e-3 / 9.0)).abs() < 1e-17, "{r}");
        // a 12.3 mm vessel without M: ⌈12.3⌉ = 13 cells, slope (Rd − Rp)/12 per metre
        let r = taper_quirk_distal_radius(rp, rd, 0.0123, 5.0);
        assert!((r - (4e-3 - 2e-3 * 0.0123 / 12.0)).abs() < 1e-17, "{r}");
        assert!((r - rp).abs() < 1e-2 * (rd - rp).abs());
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
