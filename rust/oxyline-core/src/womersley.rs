//! Frequency-dependent (Womersley) friction and inertia of a segment (docs/physics.md §1.12).
//!
//! The longitudinal impedance of oscillatory flow in a rigid tube,
//! Z(ω) = iωρ dx / (π r² (1 − F₁₀(α))), α = r √(ω/ν), goes from the Poiseuille resistance with
//! the 4/3 inertance of a parabolic profile at α → 0 to the flat-profile inertance with a
//! boundary-layer resistance at large α. It is represented in the time domain by a Foster
//! network: the Poiseuille resistance R₀ and the flat-profile inertance L₀ in series with
//! `CELLS` cells, each a resistance R_k in parallel with an inertance L_k:
//!
//!   Z(s) = R₀ + s L₀ + Σ_k R_k s / (s + p_k),   p_k = R_k / L_k.
//!
//! In units of the tube (R₀ = 8μ dx/(π r⁴), L₀ = ρ dx/(π r²), ν/r² = R₀/(8 L₀)) the cells are
//! universal: R_k = ρ_k R₀ and p_k = β_k ν/r². The (ρ_k, β_k) below minimise the largest
//! relative error |Z_cells/Z − 1| over 0 ≤ α ≤ 20 (poles by Nelder–Mead, residues by least
//! squares at each set of poles), with R₀ and L₀ held exact so that the steady resistance and
//! the high-frequency inertance are those of the tube: 0.11 % at most for α ≤ 20, 1.5 % at
//! most for α ≤ 200. Σ 8ρ_k/β_k = 0.3313 (the parabolic profile's extra 1/3 of L₀ at α → 0).
//!
//! A cell whose pole is far above the frequencies a pulse holds acts as its inertance L_k alone
//! (R_k s/(s + p_k) = s L_k (1 + O(s/p_k))): cells with p_k above [`FOLD_ABOVE`] are folded
//! into the series inertance, which keeps small vessels from adding stiff unknowns. At 20 Hz
//! a folded cell changes Z by less than 2 % of its own share.

/// Number of R‖L cells of a Womersley segment.
pub const CELLS: usize = 3;
/// Cell resistances in units of the Poiseuille resistance.
const RHO: [f64; CELLS] = [
    0.688_093_727_523_794_4,
    1.694_197_926_113_648,
    12.288_246_517_083_206,
];
/// Cell poles in units of ν/r².
const BETA: [f64; CELLS] = [
    30.174_925_066_304_48,
    157.174_268_582_964_46,
    1_568.578_897_328_867_5,
];
/// Poles above this (rad/s, 2π × 1 kHz) are folded into the series inertance.
pub const FOLD_ABOVE: f64 = 2.0 * std::f64::consts::PI * 1000.0;

/// The Womersley representation of one segment: series resistance and inertance and the
/// unfolded cells (R_k, L_k).
#[derive(Debug, Clone, PartialEq)]
pub struct FrictionCells {
    pub resistance: f64,
    pub inductance: f64,
    pub cells: Vec<(f64, f64)>,
}

/// The cells of a segment of Poiseuille resistance `resistance` and flat-profile inertance
/// `inductance` (a taper's own integrals: ν/r² is taken as R₀/(8 L₀), exact for a uniform
/// tube).
pub fn cells(resistance: f64, inductance: f64) -> FrictionCells {
    let nu_over_r2 = resistance / (8.0 * inductance);
    let mut out = FrictionCells {
        resistance,
        inductance,
        cells: Vec::with_capacity(CELLS),
    };
    for (rho, beta) in RHO.iter().zip(BETA) {
        let (r, p) = (rho * resistance, beta * nu_over_r2);
        if p > FOLD_ABOVE {
            out.inductance += r / p;
        } else {
            out.cells.push((r, r / p));
        }
    }
    out
}

/// The derivative of [`cells`]' values by the segment's Poiseuille resistance and
/// flat-profile inertance, (dR₀, dL₀), with the first `kept` cells unfolded as [`cells`] kept
/// them. R_k = ρ_k R₀ and L_k = R_k/p_k = 8 ρ_k L₀/β_k, so the cells move as R₀ and L₀ do, and
/// a folded cell's 8 ρ_k L₀/β_k moves with the series inertance. The fold is held: it is a
/// step in ν/r² (a pole crossing [`FOLD_ABOVE`]), and the derivative is that of the discrete
/// circuit between its steps. Cells keep a prefix of the ladder (the poles β_k ν/r² grow
/// with k at one ν/r²).
pub fn cells_derivative(kept: usize, d_resistance: f64, d_inductance: f64) -> FrictionCells {
    let mut out = FrictionCells {
        resistance: d_resistance,
        inductance: d_inductance,
        cells: Vec::with_capacity(kept),
    };
    for (k, (rho, beta)) in RHO.iter().zip(BETA).enumerate() {
        let dl = 8.0 * rho / beta * d_inductance;
        if k < kept {
            out.cells.push((rho * d_resistance, dl));
        } else {
            out.inductance += dl;
        }
    }
    out
}

/// The flat-profile inertance L₀ of a segment whose series inertance, with the cells past the
/// first `kept` folded into it by [`cells`], is `series`.
pub fn flat_inductance(series: f64, kept: usize) -> f64 {
    let folded: f64 = (RHO.iter().zip(BETA).skip(kept))
        .map(|(rho, beta)| 8.0 * rho / beta)
        .sum();
    series / (1.0 + folded)
}

/// Z(iω) of the representation (for checks; the circuit's DAE is what the solvers use).
pub fn impedance(f: &FrictionCells, omega: f64) -> faer::c64 {
    let s = faer::c64::new(0.0, omega);
    let mut z = faer::c64::new(f.resistance, 0.0) + s * f.inductance;
    for &(r, l) in &f.cells {
        z += s * r / (s + r / l);
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Poiseuille segment of radius r (m), length 1 m, blood 1050 kg/m³, 3.5 mPa·s.
    fn tube(r: f64) -> (f64, f64) {
        let pi = std::f64::consts::PI;
        (8.0 * 3.5e-3 / (pi * r.powi(4)), 1050.0 / (pi * r * r))
    }

    #[test]
    fn steady_resistance_and_low_frequency_inertance_are_poiseuille() {
        for r in [5e-5, 5e-4, 3e-3, 1.2e-2] {
            let (r0, l0) = tube(r);
            let f = cells(r0, l0);
            let z0 = impedance(&f, 0.0);
            assert!((z0.re / r0 - 1.0).abs() < 1e-14 && z0.im == 0.0);
            // dZ/d(iω) at ω → 0: the parabolic profile's 4/3 L₀ (the fit gives 1.3313)
            let w = 1e-6;
            let l_low = impedance(&f, w).im / w;
            assert!(
                (l_low / (4.0 / 3.0 * l0) - 1.0).abs() < 2e-3,
                "{r}: {l_low}"
            );
        }
    }

    /// The derivative against central differences of [`cells`] by R₀ and by L₀ separately,
    /// on tubes that keep every cell, fold some, and fold all; and L₀ recovered from the
    /// series inertance. The values are linear in R₀ and L₀ at a held fold, so the quotient
    /// is exact to rounding.
    #[test]
    fn cell_derivatives_are_the_difference_quotients() {
        for r in [1.2e-2, 8e-4, 5e-5] {
            let (r0, l0) = tube(r);
            let f = cells(r0, l0);
            let kept = f.cells.len();
            assert!((flat_inductance(f.inductance, kept) / l0 - 1.0).abs() < 1e-14);
            let h = 1e-6;
            for (dr, dl) in [(1.0, 0.0), (0.0, 1.0)] {
                let up = cells(r0 * (1.0 + h * dr), l0 * (1.0 + h * dl));
                let down = cells(r0 * (1.0 - h * dr), l0 * (1.0 - h * dl));
                assert_eq!((up.cells.len(), down.cells.len()), (kept, kept));
                let d = cells_derivative(kept, dr * r0, dl * l0);
                // per unit log of R₀ or L₀: within 1e-8 of the value itself (a value that
                // does not move quotes rounding of ~1e-16/h of itself)
                let q = |a: f64, b: f64| (a - b) / (2.0 * h);
                let close = |x: f64, y: f64, of: f64| (x - y).abs() <= 1e-8 * of.abs();
                assert!(close(d.resistance, q(up.resistance, down.resistance), r0));
                let (l, ul, dl_) = (f.inductance, up.inductance, down.inductance);
                assert!(close(d.inductance, q(ul, dl_), l), "{r}");
                for k in 0..kept {
                    let (rk, lk) = f.cells[k];
                    assert!(close(d.cells[k].0, q(up.cells[k].0, down.cells[k].0), rk));
                    assert!(close(d.cells[k].1, q(up.cells[k].1, down.cells[k].1), lk));
                }
            }
        }
    }

    #[test]
    fn small_vessels_fold_every_cell_large_ones_keep_them() {
        let (r0, l0) = tube(5e-5);
        assert!(cells(r0, l0).cells.is_empty());
        let (r0, l0) = tube(1.2e-2);
        assert_eq!(cells(r0, l0).cells.len(), CELLS);
    }
}
