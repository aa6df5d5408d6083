//! Per-segment resistance, inertance, compliance and volume from vessel geometry
//! (docs/physics.md §1.1), integrated exactly over a linear taper by Gauss–Legendre quadrature.

use serde::Deserialize;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WallModel {
    /// 2π r³ (1 − ν²) dx / (E h)
    #[default]
    Thin,
    /// Lamé thick-walled tube in plane strain.
    Thick,
}

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum InertanceProfile {
    /// ρ dx / (π r²): flat profile, high Womersley number.
    #[default]
    Flat,
    /// 4 ρ dx / (3 π r²): Poiseuille profile, low Womersley number.
    Poiseuille,
}

/// Friction and inertia of a segment's flow.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum WallFriction {
    /// Poiseuille resistance and the `inertance_profile` inertance at every frequency.
    #[default]
    Poiseuille,
    /// Womersley's oscillatory-flow impedance as a Foster network (`crate::womersley`).
    Womersley,
}

#[derive(Debug, Clone, Copy)]
pub struct Blood {
    pub density: f64,
    pub viscosity: f64,
}

#[derive(Debug, Clone, Copy)]
pub struct Wall {
    pub thickness: f64,
    pub youngs_modulus: f64,
    pub poisson_ratio: f64,
    pub model: WallModel,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentRlc {
    pub resistance: f64,
    pub inductance: f64,
    pub compliance: f64,
    pub volume: f64,
}

const GAUSS5: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_1),
    (0.906_179_845_938_664, 0.236_926_885_056_189_1),
];

/// Wall thickness h = r (a e^(b r) + c e^(d r)) [m] at lumen radius `radius` [m] of the
/// exponential thickness law `[a, b, c, d]` (b, d per metre): the ADAN/openBF law and
/// circulatory_autogen's, each with its constants.
pub fn wall_thickness_law(radius: f64, [a, b, c, d]: [f64; 4]) -> f64 {
    radius * (a * (b * radius).exp() + c * (d * radius).exp())
}

/// Thin-wall compliance C = 2π r³ (1 − ν²) L / (E h) [m³/Pa] of a uniform tube of radius
/// `radius` and length `length` (the per-length law of [`segment_rlc`] for a whole vessel;
/// r³ as `powf`, the bits an importer that re-expresses a vessel's compliance as a lumped
/// capacitor wrote before).
pub fn thin_wall_compliance(
    radius: f64,
    length: f64,
    youngs_modulus: f64,
    wall_thickness: f64,
    poisson_ratio: f64,
) -> f64 {
    2.0 * std::f64::consts::PI * radius.powf(3.0) * (1.0 - poisson_ratio * poisson_ratio) * length
        / (youngs_modulus * wall_thickness)
}

/// Segment of length `dx` whose radius goes linearly from `r0` to `r1`.
pub fn segment_rlc(
    dx: f64,
    r0: f64,
    r1: f64,
    blood: Blood,
    wall: Option<Wall>,
    profile: InertanceProfile,
) -> SegmentRlc {
    let pi = std::f64::consts::PI;
    let l_factor = match profile {
        InertanceProfile::Flat => 1.0,
        InertanceProfile::Poiseuille => 4.0 / 3.0,
    };
    // closed forms of ∫dx/r⁴, ∫dx/r², ∫r²dx for a linear taper (stable as r1 → r0)
    let mut out = SegmentRlc {
        resistance: 8.0 * blood.viscosity / pi * dx * (r0 * r0 + r0 * r1 + r1 * r1)
            / (3.0 * r0.powi(3) * r1.powi(3)),
        inductance: l_factor * blood.density / pi * dx / (r0 * r1),
        compliance: 0.0,
        volume: pi * dx * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0,
    };
    // compliance: polynomial (thin) or smooth rational (thick) in r, Gauss is exact or near it
    for (xi, w) in GAUSS5 {
        let r = r0 + (r1 - r0) * 0.5 * (xi + 1.0);
        let wdx = 0.5 * w * dx;
        if let Some(wall) = wall {
            let (e, h, nu) = (wall.youngs_modulus, wall.thickness, wall.poisson_ratio);
            out.compliance += wdx
                * match wall.model {
                    WallModel::Thin => 2.0 * pi * r.powi(3) * (1.0 - nu * nu) / (e * h),
                    WallModel::Thick => {
                        let (a, b) = (r, r + h);
                        2.0 * pi * a * a * (1.0 + nu) * ((1.0 - 2.0 * nu) * a * a + b * b)
                            / (e * (b * b - a * a))
                    }
                };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physics_table_values_for_the_abdominal_segment() {
        // docs/physics.md §1.5 table: r = 8 mm, dx = 20 mm, E 5.11 MPa, h 2 mm, ν = 0.5
        let s = segment_rlc(
            0.02,
            0.008,
            0.008,
            Blood {
                density: 1050.0,
                viscosity: 3.5e-3,
            },
            Some(Wall {
                thickness: 0.002,
                youngs_modulus: 5.11e6,
                poisson_ratio: 0.5,
                model: WallModel::Thin,
            }),
            InertanceProfile::Flat,
        );
        assert!((s.resistance / 4.352e4 - 1.0).abs() < 1e-3);
        assert!((s.inductance / 1.0445e5 - 1.0).abs() < 1e-4);
        assert!((s.compliance / 4.722e-12 - 1.0).abs() < 1e-3);
    }

    #[test]
    fn taper_resistance_matches_the_closed_form() {
        let (dx, a, b, mu) = (0.05, 0.004, 0.002, 3.5e-3);
        let s = segment_rlc(
            dx,
            a,
            b,
            Blood {
                density: 1050.0,
                viscosity: mu,
            },
            None,
            InertanceProfile::Flat,
        );
        // ∫ 8μ/(π r⁴) dx with r linear: 8μ dx/(3π (a − b)) (1/b³ − 1/a³)
        let exact = 8.0 * mu * dx / (3.0 * std::f64::consts::PI * (a - b))
            * (1.0 / b.powi(3) - 1.0 / a.powi(3));
        assert!(
            (s.resistance / exact - 1.0).abs() < 1e-13,
            "{}",
            s.resistance / exact
        );
    }
}
