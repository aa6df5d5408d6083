//! `segments: auto` (docs/solvers.md, "Space"): each vessel gets the fewest segments whose
//! lumped ladder stands for its transmission line within the model's segmentation `rtol` at
//! the highest significant harmonic of the forcing.
//!
//! The rule, in two steps:
//! 1. **Significant harmonics.** Every time-varying flow or pressure condition is cut
//!    into its harmonics (the Fourier coefficients of a series; a DFT of 4096 samples of a
//!    table). The significant ones are the lowest K that together carry all but a fraction
//!    `rtol` of its pulsatile power (Σ_{k>K} |a_k|² ≤ rtol Σ_{k≥1} |a_k|²). The highest
//!    frequency kept, K/period, over all the waveforms, is the model's. A model forced by no
//!    periodic waveform (a heart, a constant inflow) is given 10 Hz (the tenth harmonic at
//!    60 beats per minute).
//! 2. **Segment count.** A vessel of total series impedance Z = R + iωL and shunt admittance
//!    Y = iωC is the two-port of a line [cosh θ, Z_c sinh θ; sinh θ / Z_c, cosh θ], θ = √(ZY),
//!    Z_c = √(Z/Y). Its n-segment ladder (the arrangement's section — inverted-L, L or π —
//!    repeated n times) is compared with it at that frequency, entry by entry with B and C
//!    scaled by Z_c (a dimensionless matrix, so that any load sees the same relative error):
//!    n is the smallest count whose largest entry error is within `rtol / LOAD_MARGIN` times
//!    the largest entry, found by doubling then bisection. The margin covers the load: the
//!    input impedance Z_in = (A Z_T + B)/(C Z_T + D) of a line closed by Z_T can move more
//!    than its two-port, near a reflection's minimum; over random arterial lines (radius
//!    0.1–20 mm, length 3–300 radii, E 0.1–3 MPa, 1–30 Hz, 1–64 segments) closed by loads
//!    from Z_c/10 to 10 Z_c the ratio is 1.5 at the median, 2.3 at 90 % and 5.4 at 99 %.
//!    This is the sections' known error (θ²/2n per vessel for the first-order L
//!    arrangements, θ³/24n² for π) evaluated exactly rather than from its leading term, so it
//!    holds for lossy (resistance-dominated) vessels too.
//!
//! The rule bounds each vessel's error; vessels in series add theirs (a ladder's wave speed
//! is off the same way in each), so a network's inlet impedance can be a few times rtol off
//! (ADAN56: ~3× at 1e-2; benches/bench_space.py, docs/solvers.md).
//!
//! A rigid vessel (no compliance) is exactly one series impedance: one segment. An RCL
//! vessel is always one segment (svZeroDSolver's block). A vessel cut by the rule with no
//! arrangement stated (its own or the model's) is a π ladder (`segments::arrangement`): the
//! first-order ladders need about the square of its count (ADAN56 at 1e-3: 267,013 segments
//! inverted-L, 5,184 π).

use crate::model::{Arrangement, BoundarySpec, NetworkSpec};
use crate::waveform::Waveform;
use faer::c64;

/// The segmentation tolerance when the model gives none.
pub const DEFAULT_RTOL: f64 = 1e-3;
/// The highest frequency (Hz) of a model forced by no periodic waveform.
pub const UNFORCED_FREQUENCY: f64 = 10.0;
/// Samples per period of a tabulated waveform's DFT.
const SAMPLES: usize = 4096;
/// The two-port's error is held within rtol / LOAD_MARGIN (module text).
pub const LOAD_MARGIN: f64 = 4.0;
/// The largest count `auto` gives a vessel (a line of ~10⁴ wavelengths at the tolerance).
pub const MAX_AUTO_SEGMENTS: usize = 1 << 16;

/// What `auto` resolves against: the angular frequency (rad/s) and tolerance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AutoRule {
    pub omega: f64,
    pub rtol: f64,
}

impl AutoRule {
    /// The rule of `spec`, or None when no vessel asks for `auto`.
    pub fn of(spec: &NetworkSpec) -> Option<AutoRule> {
        let any = spec
            .vessels
            .iter()
            .any(|v| super::segments::is_auto(spec, v));
        if !any {
            return None;
        }
        let rtol = spec.segmentation_rtol.unwrap_or(DEFAULT_RTOL);
        let f = forcing_frequency(spec.boundary_conditions.values(), rtol);
        Some(AutoRule {
            omega: 2.0 * std::f64::consts::PI * f,
            rtol,
        })
    }

    /// The segment count of a vessel of total resistance `r`, inductance `l`, compliance `c`
    /// in `arrangement`.
    pub fn count(&self, r: f64, l: f64, c: f64, arrangement: Arrangement) -> usize {
        let (z, y) = (c64::new(r, self.omega * l), c64::new(0.0, self.omega * c));
        if arrangement == Arrangement::Rcl || y.norm() == 0.0 || z.norm() == 0.0 {
            return 1;
        }
        let within = |n: usize| ladder_error(z, y, n, arrangement) <= self.rtol / LOAD_MARGIN;
        let mut hi = 1;
        while !within(hi) {
            if hi >= MAX_AUTO_SEGMENTS {
                return MAX_AUTO_SEGMENTS;
            }
            hi *= 2;
        }
        // the smallest count within the tolerance in (hi/2, hi]
        let mut lo = hi / 2;
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if within(mid) { hi = mid } else { lo = mid }
        }
        hi
    }
}

/// The highest significant frequency (Hz) of the forcing by the boundary conditions `bcs`
/// (rule in the module text).
pub fn forcing_frequency<'a>(bcs: impl IntoIterator<Item = &'a BoundarySpec>, rtol: f64) -> f64 {
    let mut best: Option<f64> = None;
    for bc in bcs {
        // the driving conditions (an outlet's reference pressure is not the forcing)
        let w = match bc {
            BoundarySpec::Flow { flow } => Some(flow),
            BoundarySpec::Pressure { pressure } => Some(pressure),
            _ => None,
        };
        let Some(w) = w.and_then(|s| Waveform::from_spec(s, "").ok()) else {
            continue;
        };
        if let Some(f) = waveform_frequency(&w, rtol) {
            best = Some(best.map_or(f, |b: f64| b.max(f)));
        }
    }
    best.unwrap_or(UNFORCED_FREQUENCY)
}

/// The highest significant frequency (Hz) of one periodic waveform (None: not periodic, or
/// no pulsatile power).
pub fn waveform_frequency(w: &Waveform, rtol: f64) -> Option<f64> {
    let period = w.period().filter(|p| *p > 0.0)?;
    let k = significant_harmonics(&harmonic_powers(w, period), rtol);
    (k > 0).then(|| k as f64 / period)
}

/// |a_k|² of harmonics k = 1, 2, … of `w` over `period`.
fn harmonic_powers(w: &Waveform, period: f64) -> Vec<f64> {
    if let Waveform::Fourier { cos, sin, .. } = w {
        let n = cos.len().max(sin.len());
        return (0..n)
            .map(|k| {
                let a = cos.get(k).copied().unwrap_or(0.0);
                let b = sin.get(k).copied().unwrap_or(0.0);
                a * a + b * b
            })
            .collect();
    }
    let t0 = match w {
        Waveform::Table { t, .. } => t[0],
        _ => 0.0,
    };
    let x: Vec<f64> = (0..SAMPLES)
        .map(|i| w.eval(t0 + period * i as f64 / SAMPLES as f64))
        .collect();
    // the SAMPLES phases' cosines and sines, once: a harmonic's phase (k i) mod SAMPLES (which
    // keeps the angle exact for large k) is one of them, the same value as computed in place
    let (cos, sin): (Vec<f64>, Vec<f64>) = (0..SAMPLES)
        .map(|m| {
            let phase = 2.0 * std::f64::consts::PI * m as f64 / SAMPLES as f64;
            (phase.cos(), phase.sin())
        })
        .unzip();
    (1..SAMPLES / 2)
        .map(|k| {
            let (mut re, mut im) = (0.0, 0.0);
            for (i, xi) in x.iter().enumerate() {
                let m = (k * i) % SAMPLES;
                re += xi * cos[m];
                im -= xi * sin[m];
            }
            re * re + im * im
        })
        .collect()
}

/// The lowest K whose harmonics 1..=K carry all but `rtol` of the pulsatile power (0: none).
pub fn significant_harmonics(power: &[f64], rtol: f64) -> usize {
    let total: f64 = power.iter().sum();
    if total.is_nan() || total <= 0.0 {
        return 0;
    }
    let mut tail = total;
    for (k, p) in power.iter().enumerate() {
        if tail <= rtol * total {
            return k;
        }
        tail -= p;
    }
    power.len()
}

type Two = [[c64; 2]; 2];

fn mul(a: &Two, b: &Two) -> Two {
    let e = |i: usize, j: usize| a[i][0] * b[0][j] + a[i][1] * b[1][j];
    [[e(0, 0), e(0, 1)], [e(1, 0), e(1, 1)]]
}

fn power(m: &Two, mut n: usize) -> Two {
    let one = c64::new(1.0, 0.0);
    let zero = c64::new(0.0, 0.0);
    let (mut out, mut base) = ([[one, zero], [zero, one]], *m);
    while n > 0 {
        if n & 1 == 1 {
            out = mul(&out, &base);
        }
        base = mul(&base, &base);
        n >>= 1;
    }
    out
}

/// Relative error of the n-section ladder's two-port against the line's (module text), for
/// total series impedance `z` and shunt admittance `y`.
pub fn ladder_error(z: c64, y: c64, n: usize, arrangement: Arrangement) -> f64 {
    let (zs, ys) = (z / n as f64, y / n as f64);
    let one = c64::new(1.0, 0.0);
    let zero = c64::new(0.0, 0.0);
    let series = [[one, zs], [zero, one]];
    let shunt = |y: c64| [[one, zero], [y, one]];
    let section = match arrangement {
        Arrangement::L => mul(&series, &shunt(ys)),
        Arrangement::Pi => mul(&mul(&shunt(ys * 0.5), &series), &shunt(ys * 0.5)),
        _ => mul(&shunt(ys), &series),
    };
    let m = power(&section, n);
    let theta = (z * y).sqrt();
    let zc = (z / y).sqrt();
    let (ch, sh) = (theta.cosh(), theta.sinh());
    let exact = [[ch, sh], [sh, ch]];
    let lumped = [[m[0][0], m[0][1] / zc], [m[1][0] * zc, m[1][1]]];
    let mut worst: f64 = 0.0;
    let mut size: f64 = 0.0;
    for i in 0..2 {
        for j in 0..2 {
            worst = worst.max((lumped[i][j] - exact[i][j]).norm());
            size = size.max(exact[i][j].norm());
        }
    }
    worst / size
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A uniform tube's line (c ≈ 5 m/s, 0.2 m, 10 Hz: θ ≈ 2.5 rad): the first-order
    /// arrangements' error falls as 1/n, π's as 1/n² (their known orders), and the count
    /// found is the smallest within the tolerance.
    #[test]
    fn ladder_error_has_the_sections_order_and_the_count_is_minimal() {
        let (r, l, c) = (2.0e7, 1.4e7, 3.0e-10);
        let w = 2.0 * std::f64::consts::PI * 10.0;
        let (z, y) = (c64::new(r, w * l), c64::new(0.0, w * c));
        for (arr, order) in [
            (Arrangement::Pi, 2.0),
            (Arrangement::L, 1.0),
            (Arrangement::InvertedL, 1.0),
        ] {
            let (e1, e2) = (ladder_error(z, y, 64, arr), ladder_error(z, y, 128, arr));
            let got = (e1 / e2).log2();
            assert!((got - order).abs() < 0.1, "{arr:?}: order {got}");
            for rtol in [1e-2, 1e-3] {
                let n = AutoRule { omega: w, rtol }.count(r, l, c, arr);
                let tol = rtol / LOAD_MARGIN;
                assert!(ladder_error(z, y, n, arr) <= tol);
                assert!(ladder_error(z, y, n - 1, arr) > tol, "{arr:?} {rtol}: {n}");
            }
        }
        // rigid: one segment is exact
        assert_eq!(
            AutoRule {
                omega: w,
                rtol: 1e-3
            }
            .count(r, l, 0.0, Arrangement::Pi),
            1
        );
    }

    /// A Fourier series with harmonics 1..=3 of powers 1, 0.1, 0.001: at rtol 1e-2 the third
    /// (0.09 % of the power) is dropped, at 1e-4 it is kept.
    #[test]
    fn significant_harmonics_keep_all_but_rtol_of_the_power() {
        let p = [1.0, 0.1, 0.001];
        assert_eq!(significant_harmonics(&p, 1e-2), 2);
        assert_eq!(significant_harmonics(&p, 1e-4), 3);
        assert_eq!(significant_harmonics(&[0.0, 0.0], 1e-3), 0);
    }
}
