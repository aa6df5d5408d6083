//! The inlet-renewal law's derivative by the flow's harmonics and by the vessel's geometry
//! (the oxygen sensitivities' forward tangent and adjoint read it, docs/calibration.md). Each
//! piece of the law is differentiated where it is computed:
//!
//! * the Womersley wall slope W(α) of a harmonic: α dW/dα = z dW/dz = 4W − z² − W² with
//!   z = α e^{3πi/4} (from W = z J1(z)/J2(z), J2′ = J1 − 2J2/z and J0 = 2J1/z − J2; no division
//!   by z, so exact at α = 0);
//! * the backward wall strain B = Σ ∫_arc f dt: the integral of the backward shear's tangent
//!   f′ over the same backward arcs (the arcs' ends move, but f vanishes there);
//! * G_r ∝ R B^{3/2}/sqrt(|⟨Q⟩| / R³): dG_r/G_r = 2.5 dR/R + 1.5 dB/B − 0.5 d⟨Q⟩/⟨Q⟩;
//! * the per-segment factors of [`super::segment_factors_into`]: the ratio G_r/ΣG(net_j), and
//!   where it binds the cap (complete renewal ∝ the wall area, or the law of ⟨|Q|⟩).
//!
//! A vessel's radius and length move every segment's radius and distances from the inlet in
//! proportion (d ln r, d ln x); a taper's end radius moves each segment's (mean) radius by
//! its own share, so d ln r is given per segment (the inlet segment's for G_r, each
//! segment's for its cap).

use super::{
    BackwardShear, INLET_RENEWAL_A, PeriodicFlow, backward_arcs, net_mean, womersley_wall_slope,
};
use crate::closure::{SegmentWall, graetz_conductance, graetz_conductance_slopes};
use nalgebra::Complex;
use std::f64::consts::PI;

/// The tangent of a [`PeriodicFlow`] by one parameter (the period held): d(mean) and the
/// harmonics' derivatives, in the same order.
#[derive(Debug, Clone, Copy)]
pub struct PeriodicFlowTangent<'a> {
    pub mean: f64,
    pub harmonics: &'a [Complex<f64>],
}

/// The derivatives by one parameter of a vessel's geometry: d ln r of each segment's radius
/// (empty: 0) and d ln x of the distances from the inlet, which every segment shares (0 for
/// a parameter that does not set the vessel).
#[derive(Debug, Clone, Copy, Default)]
pub struct GeometryTangent<'a> {
    pub ln_radius: &'a [f64],
    pub ln_length: f64,
}

impl GeometryTangent<'_> {
    /// d ln r of segment `k`.
    fn ln_radius_of(&self, k: usize) -> f64 {
        self.ln_radius.get(k).copied().unwrap_or(0.0)
    }
}

/// α dW/dα of [`womersley_wall_slope`] W at α (see the module doc).
pub fn womersley_wall_log_slope(alpha: f64) -> Complex<f64> {
    let w = womersley_wall_slope(alpha);
    // z² = α² e^{3πi/2} = −i α²
    w * 4.0 + Complex::new(0.0, alpha * alpha) - w * w
}

/// The backward wall strain B of [`super::backward_wall_strain`] and its derivative, for
/// the flow's tangent `dflow` and the radius's d ln R `d_ln_radius`. With f(t) = −sign γ_w =
/// f0 + Re Σ c_k e^{ikωt}, c_k = −sign Q̂_k W(α_k)/(πR³) and α_k ∝ R: dc_k = −sign (dQ̂_k W_k
/// + Q̂_k α dW/dα d ln R)/(πR³) − 3 c_k d ln R, df0 likewise from d⟨Q⟩.
pub fn backward_wall_strain_tangent(
    flow: &PeriodicFlow,
    dflow: &PeriodicFlowTangent,
    radius: f64,
    d_ln_radius: f64,
    density: f64,
    viscosity: f64,
) -> (f64, f64) {
    let sign = if flow.mean < 0.0 { -1.0 } else { 1.0 };
    let scale = 1.0 / (PI * radius.powi(3));
    let omega = 2.0 * PI / flow.period;
    let f0 = -sign * 4.0 * flow.mean * scale;
    let dc: Vec<Complex<f64>> = (flow.harmonics.iter().zip(dflow.harmonics))
        .enumerate()
        .map(|(i, (qk, dqk))| {
            let alpha = radius * (((i + 1) as f64) * omega * density / viscosity).sqrt();
            let w = womersley_wall_slope(alpha);
            let dw = womersley_wall_log_slope(alpha) * d_ln_radius;
            let ck = -sign * qk * scale * w;
            -sign * scale * (dqk * w + qk * dw) - ck * (3.0 * d_ln_radius)
        })
        .collect();
    let dshear = BackwardShear {
        f0: -sign * 4.0 * dflow.mean * scale - 3.0 * d_ln_radius * f0,
        c: &dc,
        omega,
    };
    let (mut b, mut db) = (0.0, 0.0);
    backward_arcs(flow, radius, density, viscosity, |shear, start, end| {
        b += shear.primitive(end) - shear.primitive(start);
        db += dshear.primitive(end) - dshear.primitive(start);
    });
    (b, db)
}

/// The renewal conductance G_r of [`super::inlet_renewal_conductance`] (valid inputs, as
/// [`super::segment_factors_into`] has checked them) and its derivative.
fn renewal_conductance_tangent(
    flow: &PeriodicFlow,
    dflow: &PeriodicFlowTangent,
    radius: f64,
    d_ln_radius: f64,
    nu: f64,
    d: f64,
) -> (f64, f64) {
    let (b, db) = backward_wall_strain_tangent(flow, dflow, radius, d_ln_radius, 1.0, nu);
    let gamma_t = 4.0 * flow.mean.abs() * flow.period / (PI * radius.powi(3));
    let g = INLET_RENEWAL_A * 2.0 * PI * radius * d * b.powf(1.5) / gamma_t.sqrt();
    // B^{3/2} has a zero slope at B = 0 (no backward shear: no renewal)
    let by_strain = if b > 0.0 { 1.5 * db / b } else { 0.0 };
    let dg = g * (2.5 * d_ln_radius - 0.5 * dflow.mean / flow.mean + by_strain);
    (g, dg)
}

/// The derivative of [`net_mean`] (|⟨Q⟩|) from those of ⟨|Q|⟩ and of the forward mean.
pub fn net_mean_tangent(mean_abs: f64, mean_forward: f64, d_abs: f64, d_forward: f64) -> f64 {
    if mean_forward == mean_abs {
        d_abs
    } else if net_mean(mean_abs, mean_forward) > 0.0 {
        2.0 * d_forward - d_abs
    } else {
        0.0
    }
}

/// The per-segment means of a vessel's segments and their derivatives by one parameter:
/// net[j] = |⟨Q⟩| and abs[j] = ⟨|Q|⟩ as [`super::segment_factors_into`] reads them.
#[derive(Debug, Clone, Copy)]
pub struct SegmentMeans<'a> {
    pub net: &'a [f64],
    pub abs: &'a [f64],
    pub d_net: &'a [f64],
    pub d_abs: &'a [f64],
}

/// d ln f_j of the factors f_j of [`super::segment_factors_into`] (same arguments, with
/// the means' and the inlet flow's tangents and the vessel's geometry tangent), into `out`.
/// Uncapped f_j = 1 + G_r/ΣG(net_j); capped f_j = cap_j/G(net_j).
#[allow(clippy::too_many_arguments)]
pub fn segment_factor_tangents_into(
    segs: &[SegmentWall],
    means: SegmentMeans<'_>,
    flow: &PeriodicFlow,
    dflow: &PeriodicFlowTangent,
    geometry: GeometryTangent<'_>,
    nu: f64,
    d: f64,
    out: &mut Vec<f64>,
) {
    let dl = geometry.ln_length;
    // G(net_j) and its derivative
    let law = |s: &SegmentWall, q: f64, dq: f64| {
        let (by_q, by_ln_x) = graetz_conductance_slopes(s, d, q);
        (graetz_conductance(s, d, q), by_q * dq + by_ln_x * dl)
    };
    let g: Vec<(f64, f64)> = (segs.iter().zip(means.net).zip(means.d_net))
        .map(|((s, &q), &dq)| law(s, q, dq))
        .collect();
    let (total, d_total) = g.iter().fold((0.0, 0.0), |(t, dt), (a, b)| (t + a, dt + b));
    let at = if flow.mean < 0.0 {
        segs.len().saturating_sub(1)
    } else {
        0
    };
    let (ratio, d_ratio) = match segs.get(at) {
        Some(s) if flow.mean != 0.0 && total > 0.0 => {
            let d_ln_r = geometry.ln_radius_of(at);
            let (gr, dgr) = renewal_conductance_tangent(flow, dflow, s.radius, d_ln_r, nu, d);
            let ratio = gr / total;
            (ratio, (dgr - ratio * d_total) / total)
        }
        _ => (f64::INFINITY, 0.0),
    };
    let k_renewed = 2.0 * (d / (PI * flow.period)).sqrt();
    out.clear();
    for (k, (s, &(gj, dgj))) in segs.iter().zip(&g).enumerate() {
        if gj <= 0.0 {
            out.push(0.0);
            continue;
        }
        let renewed = gj * (1.0 + ratio);
        // the cap of `segment_factors_into` and its derivative: complete renewal ∝ the
        // wall area 2π r Δx, the net-mean law itself, or the law of ⟨|Q|⟩
        let area = k_renewed * s.area();
        let (mut cap, mut d_cap) = if area >= gj {
            (area, area * (geometry.ln_radius_of(k) + dl))
        } else {
            (gj, dgj)
        };
        if renewed > cap {
            let (ga, dga) = law(s, means.abs[k], means.d_abs[k]);
            if ga > cap {
                (cap, d_cap) = (ga, dga);
            }
        }
        out.push(if renewed < cap {
            d_ratio / (1.0 + ratio)
        } else {
            d_cap / cap - dgj / gj
        });
    }
}

#[cfg(test)]
mod tests {
    use super::super::{backward_wall_strain, segment_factors};
    use super::*;

    /// Relative step of the central differences: their truncation is O(h²) ~ 1e-10 of
    /// the second derivatives' scale, their rounding ~ ε/h ~ 1e-11 of the value.
    const H: f64 = 1e-5;

    /// A sharp waveform with reversal: 24 harmonics (as the strain's own test).
    fn waveform(amplitude: f64) -> Vec<Complex<f64>> {
        (1..=24)
            .map(|k| {
                let k = k as f64;
                Complex::from_polar(amplitude / k, 0.7 * k + 0.3 * k * k)
            })
            .collect()
    }

    /// A direction of the flow's tangent: every harmonic moved in its own way.
    fn direction(h: &[Complex<f64>]) -> Vec<Complex<f64>> {
        (h.iter().enumerate())
            .map(|(k, q)| q * Complex::from_polar(0.3 + 0.1 * k as f64, 0.5 * k as f64))
            .collect()
    }

    fn moved(h: &[Complex<f64>], dh: &[Complex<f64>], e: f64) -> Vec<Complex<f64>> {
        h.iter().zip(dh).map(|(q, d)| q + d * e).collect()
    }

    #[test]
    fn womersley_log_slope_against_central_differences() {
        // both sides of the switch from the power series to the recurrence, and α → 0
        for alpha in [1e-3, 0.3, 2.0, 5.0, 11.9, 12.1, 30.0] {
            let a = womersley_wall_log_slope(alpha);
            let fd = (womersley_wall_slope(alpha * (1.0 + H))
                - womersley_wall_slope(alpha * (1.0 - H)))
                / (2.0 * H);
            // 1e-8 of |W| ≥ 4: the quotient's truncation and rounding (see H)
            let w = womersley_wall_slope(alpha).norm();
            assert!((a - fd).norm() < 1e-8 * w, "α {alpha}: {a} vs {fd}");
        }
        assert_eq!(womersley_wall_log_slope(0.0), Complex::new(0.0, 0.0));
    }

    #[test]
    fn backward_strain_tangent_against_central_differences() {
        let (rho, mu, period) = (1050.0, 3.5e-3, 0.8);
        let h = waveform(3e-5);
        let dh = direction(&h);
        for (r, mean, dmean, dlr) in [
            (0.008, 2e-5, 7e-6, 0.0),
            (0.008, 2e-5, -3e-6, 0.8),
            (1.5e-3, -6e-6, 2e-6, -0.5),
            (3e-4, 2.5e-6, 1e-6, 1.3),
        ] {
            let flow = PeriodicFlow {
                period,
                mean,
                harmonics: &h,
            };
            let dflow = PeriodicFlowTangent {
                mean: dmean,
                harmonics: &dh,
            };
            let (b, db) = backward_wall_strain_tangent(&flow, &dflow, r, dlr, rho, mu);
            assert_eq!(b, backward_wall_strain(&flow, r, rho, mu));
            let at = |e: f64| {
                let hh = moved(&h, &dh, e);
                let f = PeriodicFlow {
                    period,
                    mean: mean + dmean * e,
                    harmonics: &hh,
                };
                backward_wall_strain(&f, r * (dlr * e).exp(), rho, mu)
            };
            let fd = (at(H) - at(-H)) / (2.0 * H);
            // 1e-7 of B: the quotient's (see H) and the crossings' 1e-10 of their bracket
            assert!(b > 0.0 && (db - fd).abs() < 1e-7 * b, "r {r}: {db} vs {fd}");
        }
    }

    /// The paper aorta's inflow in ten segments of a vessel `length` long, at net mean
    /// `mean` (the inlet's flow the same), along a direction of every input.
    fn factors_check(mean: f64, abs: f64, harmonics: &[Complex<f64>]) -> (f64, f64, usize) {
        let (d, nu, period, r, length) = (1.2e-9, 3.5e-3 / 1050.0, 1.0, 0.008, 0.2);
        let dh = direction(harmonics);
        let n = 10;
        let net: Vec<f64> = (0..n).map(|j| mean * (1.0 - 0.01 * j as f64)).collect();
        let d_net: Vec<f64> = (0..n)
            .map(|j| 0.3 * net[j] * (1.0 + 0.1 * j as f64))
            .collect();
        let abs: Vec<f64> = (0..n).map(|j| abs * (1.0 + 0.02 * j as f64)).collect();
        let d_abs: Vec<f64> = (0..n)
            .map(|j| -0.2 * abs[j] * (1.0 + 0.05 * j as f64))
            .collect();
        // a taper: each segment's radius its own, moved by its own share
        let ln_radius: [f64; 10] = std::array::from_fn(|j| 0.7 - 0.05 * j as f64);
        let (dmean, geometry) = (
            0.4 * mean,
            GeometryTangent {
                ln_radius: &ln_radius,
                ln_length: -0.6,
            },
        );
        let segs_at = |e: f64| -> Vec<SegmentWall> {
            let ll = length * (geometry.ln_length * e).exp();
            let rr = |i: usize| r * (1.0 - 0.02 * i as f64) * (geometry.ln_radius[i] * e).exp();
            (0..n)
                .map(|i| SegmentWall {
                    radius: rr(i),
                    x0: ll * i as f64 / n as f64,
                    x1: ll * (i + 1) as f64 / n as f64,
                })
                .collect()
        };
        let factors = |e: f64| {
            let hh = moved(harmonics, &dh, e);
            let f = PeriodicFlow {
                period,
                mean: mean + dmean * e,
                harmonics: &hh,
            };
            let q = |v: &[f64], dv: &[f64]| -> Vec<f64> {
                v.iter().zip(dv).map(|(a, b)| a + b * e).collect()
            };
            let segs = segs_at(e);
            segment_factors("v", &segs, &q(&net, &d_net), &q(&abs, &d_abs), &f, nu, d).unwrap()
        };
        let flow = PeriodicFlow {
            period,
            mean,
            harmonics,
        };
        let dflow = PeriodicFlowTangent {
            mean: dmean,
            harmonics: &dh,
        };
        let means = SegmentMeans {
            net: &net,
            abs: &abs,
            d_net: &d_net,
            d_abs: &d_abs,
        };
        let mut got = Vec::new();
        segment_factor_tangents_into(
            &segs_at(0.0),
            means,
            &flow,
            &dflow,
            geometry,
            nu,
            d,
            &mut got,
        );
        let (f0, up, down) = (factors(0.0), factors(H), factors(-H));
        let worst = (0..n).fold(0.0f64, |w, j| {
            let fd = (up[j].ln() - down[j].ln()) / (2.0 * H);
            w.max((got[j] - fd).abs())
        });
        // the largest factor, and how many segments complete renewal caps
        let k_renewed = 2.0 * (d / (PI * period)).sqrt();
        let segs = segs_at(0.0);
        let capped = (segs.iter().zip(&net).zip(&f0))
            .filter(|((s, q), f)| {
                let cap = k_renewed * s.area();
                (**f * graetz_conductance(s, d, **q) / cap - 1.0).abs() < 1e-12
            })
            .count();
        (worst, f0.iter().cloned().fold(0.0, f64::max), capped)
    }

    #[test]
    fn segment_factor_tangents_against_central_differences() {
        // 1e-7 absolute on d ln f (f of order 1 to 10): the quotients' error (see H)
        // the paper aorta (uncapped: f ≈ 1.02), then a sharper waveform
        let paper = [Complex::new(0.0, -3e-5), Complex::new(-8e-6, -8e-6)];
        let (worst, fmax, capped) = factors_check(2e-5, 3.1e-5, &paper);
        assert!(
            fmax > 1.01 && capped == 0 && worst < 1e-7,
            "paper aorta: {worst:e} (f {fmax})"
        );
        let (worst, _, capped) = factors_check(2e-5, 3.1e-5, &waveform(3e-5));
        assert!(capped == 0 && worst < 1e-7, "sharp waveform: {worst:e}");
        // a tiny net flow under a strong oscillation: G_r above complete renewal, the cap
        // binds (f = cap/G(net)) on some segments
        let (worst, fmax, capped) = factors_check(1e-10, 2.5e-5, &paper);
        assert!(
            capped > 0 && worst < 1e-7,
            "capped: {worst:e} (f {fmax}, {capped} capped)"
        );
    }
}
