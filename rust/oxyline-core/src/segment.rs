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

/// The slopes of a segment's R, L and C with respect to its end radii: (∂/∂r0, ∂/∂r1) of
/// [`segment_rlc`] at (`r0`, `r1`), at a fixed wall thickness and modulus (the calibration's
/// tapered radii). R = A (r0⁻¹r1⁻³ + r0⁻²r1⁻² + r0⁻³r1⁻¹), A = 8μ dx/(3π), and L ∝ 1/(r0 r1) in
/// closed form; the thin-wall C term by term of the same Gauss sum, whose r³ it integrates
/// exactly (∂r/∂r0 = 1 − s, ∂r/∂r1 = s at the node s = (ξ + 1)/2); the thick wall's C the
/// same way, each node's Lamé term differentiated in closed form ([`thick_wall_slope`]; the
/// derivative of the quadrature the run sums). The lumen volume is not needed by the flow
/// and is left at 0.
pub fn segment_rlc_radius_slopes(
    dx: f64,
    r0: f64,
    r1: f64,
    blood: Blood,
    wall: Option<Wall>,
    profile: InertanceProfile,
) -> Option<[SegmentRlc; 2]> {
    let pi = std::f64::consts::PI;
    let a = 8.0 * blood.viscosity * dx / (3.0 * pi);
    let inductance = segment_rlc(dx, r0, r1, blood, None, profile).inductance;
    // ∂R/∂r0 = −A (r0⁻²r1⁻³ + 2 r0⁻³r1⁻² + 3 r0⁻⁴r1⁻¹), and r0 ↔ r1
    let dr = |p: f64, q: f64| {
        -a * (1.0 / (p * p * q.powi(3)) + 2.0 / (p.powi(3) * q * q) + 3.0 / (p.powi(4) * q))
    };
    let mut out = [
        SegmentRlc {
            resistance: dr(r0, r1),
            inductance: -inductance / r0,
            compliance: 0.0,
            volume: 0.0,
        },
        SegmentRlc {
            resistance: dr(r1, r0),
            inductance: -inductance / r1,
            compliance: 0.0,
            volume: 0.0,
        },
    ];
    if let Some(w) = wall {
        let k =
            2.0 * pi * (1.0 - w.poisson_ratio * w.poisson_ratio) / (w.youngs_modulus * w.thickness);
        for (xi, wt) in GAUSS5 {
            let s = 0.5 * (xi + 1.0);
            let r = r0 + (r1 - r0) * s;
            let per_length = match w.model {
                WallModel::Thin => k * 3.0 * r * r,
                WallModel::Thick => thick_wall_slope(r, w),
            };
            let dc = 0.5 * wt * dx * per_length;
            out[0].compliance += dc * (1.0 - s);
            out[1].compliance += dc * s;
        }
    }
    Some(out)
}

/// d/da of the thick (Lamé, plane strain) wall's compliance per length at lumen radius a,
/// c(a) = K a² ((1 − 2ν) a² + b²)/(b² − a²), K = 2π (1 + ν)/E, b = a + h at the wall
/// thickness h held: with N = a² ((1 − 2ν) a² + b²) and D = b² − a² = h (2a + h),
/// N′ = 2a ((1 − 2ν) a² + b²) + a² (2 (1 − 2ν) a + 2b), D′ = 2h, c′ = K (N′D − N D′)/D².
fn thick_wall_slope(a: f64, w: Wall) -> f64 {
    let (e, h, nu) = (w.youngs_modulus, w.thickness, w.poisson_ratio);
    let k = 2.0 * std::f64::consts::PI * (1.0 + nu) / e;
    let b = a + h;
    let inner = (1.0 - 2.0 * nu) * a * a + b * b;
    let n = a * a * inner;
    let dn = 2.0 * a * inner + a * a * (2.0 * (1.0 - 2.0 * nu) * a + 2.0 * b);
    let d = h * (2.0 * a + h);
    k * (dn * d - n * 2.0 * h) / (d * d)
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

    /// The end-radius slopes against central differences of [`segment_rlc`] itself (relative
    /// step 1e-6: truncation ~1e-12 and rounding ~1e-10 of each value, so 1e-7 relative tells
    /// a wrong term from a right one).
    #[test]
    fn end_radius_slopes_are_the_segments_derivatives() {
        let blood = Blood {
            density: 1050.0,
            viscosity: 3.5e-3,
        };
        let wall = Some(Wall {
            thickness: 5e-4,
            youngs_modulus: 6e5,
            poisson_ratio: 0.5,
            model: WallModel::Thin,
        });
        let (dx, r0, r1) = (0.03, 0.003, 0.0021);
        let profile = InertanceProfile::Poiseuille;
        let slopes = segment_rlc_radius_slopes(dx, r0, r1, blood, wall, profile).unwrap();
        for end in 0..2 {
            let h = 1e-6 * [r0, r1][end];
            let at = |d: f64| {
                let (a, b) = if end == 0 { (r0 + d, r1) } else { (r0, r1 + d) };
                segment_rlc(dx, a, b, blood, wall, profile)
            };
            let (up, down) = (at(h), at(-h));
            let close = |exact: f64, u: f64, d: f64| {
                let fd = (u - d) / (2.0 * h);
                assert!(
                    (exact - fd).abs() <= 1e-7 * fd.abs(),
                    "end {end}: {exact} vs {fd}"
                );
            };
            close(slopes[end].resistance, up.resistance, down.resistance);
            close(slopes[end].inductance, up.inductance, down.inductance);
            close(slopes[end].compliance, up.compliance, down.compliance);
        }
    }

    /// The thick wall's end-radius slopes against central differences of [`segment_rlc`]
    /// (as above), at ν = 0.5 and 0.45 (the (1 − 2ν) term) and a wall thick against the
    /// lumen (h/r ≈ 0.3–0.5, where the Lamé form departs from the thin wall's r³).
    #[test]
    fn thick_wall_end_radius_slopes_are_the_segments_derivatives() {
        let blood = Blood {
            density: 1050.0,
            viscosity: 3.5e-3,
        };
        for nu in [0.5, 0.45] {
            let wall = Some(Wall {
                thickness: 1e-3,
                youngs_modulus: 6e5,
                poisson_ratio: nu,
                model: WallModel::Thick,
            });
            let (dx, r0, r1) = (0.03, 0.003, 0.0021);
            let profile = InertanceProfile::Flat;
            let slopes = segment_rlc_radius_slopes(dx, r0, r1, blood, wall, profile).unwrap();
            for end in 0..2 {
                let h = 1e-6 * [r0, r1][end];
                let at = |d: f64| {
                    let (a, b) = if end == 0 { (r0 + d, r1) } else { (r0, r1 + d) };
                    segment_rlc(dx, a, b, blood, wall, profile).compliance
                };
                let fd = (at(h) - at(-h)) / (2.0 * h);
                let exact = slopes[end].compliance;
                assert!(
                    (exact - fd).abs() <= 1e-7 * fd.abs(),
                    "ν {nu} end {end}: {exact} vs {fd}"
                );
            }
        }
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
