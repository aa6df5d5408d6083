//! Inlet renewal of the concentration boundary layer by the near-wall backward excursion of the
//! Womersley profile (docs/physics.md §3.6, docs/validation-oxygen.md §12). Near the wall the
//! fluid moves backward by B y every period (B the backward wall strain); where it leaves the
//! vessel inlet fresh fluid renews the layer over x_c ∝ B^{3/2} sqrt(D/γ̄), which adds the wall
//! conductance
//!
//! ```text
//! G_r = A · 2πR D · B^{3/2} / sqrt(γ̄ T),   γ̄ = 4 |⟨Q⟩| / (πR³),
//! ```
//!
//! to the Graetz law of the net mean flow (ΔU = G_r (c − c_w)). The exponent is penetration
//! theory's; A is fitted to the 27 rows of docs/validation-oxygen.md §2 and checked on 20
//! held-out vessels there (within 0.95 % of the 2-D reference whose layer continues through
//! the outlet; within 2 % of the outlet-independent reference in all 47 rows, §13). The
//! default of the Graetz closure since the inlet-renewal fit (`MeanFlow::InletRenewal`): a run gets each
//! vessel's flow harmonics from its flow-only first pass (`run::flow_harmonics`).

use super::{SegmentWall, finite_number, graetz_conductance};
use crate::error::{Error, Result};
use nalgebra::Complex;
use std::f64::consts::PI;

pub mod tangent; // the law's derivative (oxygen sensitivities)

/// The inlet-renewal constant A (docs/validation-oxygen.md §12; `INLET_RENEWAL_A` of
/// `oxyline.reference.validation`).
pub const INLET_RENEWAL_A: f64 = 0.329;

/// A vessel's periodic flow Q(t) = mean + Re Σ_k Q̂_k e^{ikωt} (m³/s), ω = 2π/period;
/// `harmonics[k − 1]` = Q̂_k (a cos + b sin is Q̂ = a − i b).
#[derive(Debug, Clone, Copy)]
pub struct PeriodicFlow<'a> {
    pub period: f64,
    pub mean: f64,
    pub harmonics: &'a [Complex<f64>],
}

/// −d(shape)/dρ at the wall of one Womersley harmonic, shape = u(ρ)/(Q̂/πR²)
/// = (1 − J0(zρ)/J0(z))/(1 − 2J1(z)/(z J0(z))), z = α i^{3/2}: the wall shear rate of the
/// harmonic is Q̂/(πR³) times this. 4 for α → 0 (Poiseuille).
///
/// With J0 + J2 = (2/z) J1 the denominator is −J2/J0, so the slope is z J1(z)/J2(z): no
/// cancellation at small α. Up to [`SLOPE_SERIES_MAX_ALPHA`] it is summed as a power series
/// (`slope_power_series`), beyond by Miller's backward recurrence (`slope_closed`).
pub fn womersley_wall_slope(alpha: f64) -> Complex<f64> {
    if alpha <= SLOPE_SERIES_MAX_ALPHA {
        slope_power_series(alpha)
    } else {
        slope_closed(alpha)
    }
}

/// Below this α [`womersley_wall_slope`] sums the power series (≤ 30 real terms: ~20× cheaper
/// than the recurrence, which needs |z| + 60 complex steps); see `slope_power_series` for its
/// error bound.
pub const SLOPE_SERIES_MAX_ALPHA: f64 = 12.0;

/// z J1(z)/J2(z) = 2 S1/S2 with S_ν = Σ_m (i x)^m/(m! (m+ν)!), x = α²/4 (the Bessel power
/// series J_ν(z) = (z/2)^ν Σ_m (−z²/4)^m/(m!(m+ν)!) with −z²/4 = i α²/4). The powers of i
/// split each sum into real and imaginary parts of real terms, summed until a term is below
/// 1e-17 of its sum. Round-off: the terms' magnitudes sum to I_ν(α)/(α/2)^ν against
/// |J_ν(z)|/(α/2)^ν for the sum, a ratio ≈ e^{(1 − 1/√2) α} ≤ 34 at α = 12, so the relative
/// error is at most ~2 × 30 terms × 34 × 1.1e-16 ≈ 2e-13 (measured against scipy's complex
/// Bessel functions: ≤ 5e-16 for α ≤ 12; the tests check 1e-11 and the join with the
/// recurrence).
fn slope_power_series(alpha: f64) -> Complex<f64> {
    let x = 0.25 * alpha * alpha;
    // (real, imaginary) parts of S1 and S2; the m = 0 terms are 1/1! and 1/2!
    let (mut t1, mut t2) = (1.0, 0.5);
    let (mut s1, mut s2) = ([1.0, 0.0], [0.5, 0.0]);
    for m in 1..200 {
        let mf = m as f64;
        t1 *= x / (mf * (mf + 1.0));
        t2 *= x / (mf * (mf + 2.0));
        // i^m: 1, i, −1, −i
        let (part, sign) = (m % 2, if m % 4 >= 2 { -1.0 } else { 1.0 });
        s1[part] += sign * t1;
        s2[part] += sign * t2;
        let small = |t: f64, s: [f64; 2]| t <= 1e-17 * s[0].abs().max(s[1].abs());
        if small(t1, s1) && small(t2, s2) {
            break;
        }
    }
    Complex::new(s1[0], s1[1]) * 2.0 / Complex::new(s2[0], s2[1])
}

fn slope_closed(alpha: f64) -> Complex<f64> {
    let z = Complex::from_polar(alpha, 0.75 * PI);
    let r1 = bessel_ratio_j1_j0(z);
    -(z * r1) / (Complex::new(1.0, 0.0) - r1 * 2.0 / z)
}

/// J1(z)/J0(z) by the backward recurrence r_n = J_n/J_{n−1} = 1/(2n/z − r_{n+1}) from r_N = 0
/// (Miller; converges for every z ≠ 0, with N well above |z|).
fn bessel_ratio_j1_j0(z: Complex<f64>) -> Complex<f64> {
    let n_start = z.norm() as usize + 60;
    let mut r = Complex::new(0.0, 0.0);
    for n in (1..=n_start).rev() {
        r = Complex::new(1.0, 0.0) / (Complex::new(2.0 * n as f64, 0.0) / z - r);
    }
    r
}

/// Wall shear rate γ_w(t) (1/s, positive along the net flow's direction sign of `mean`) of the
/// fully developed Womersley profile of `flow` in a rigid tube.
pub fn wall_shear_rate(
    flow: &PeriodicFlow,
    radius: f64,
    density: f64,
    viscosity: f64,
    t: f64,
) -> f64 {
    let scale = 1.0 / (PI * radius.powi(3));
    let omega = 2.0 * PI / flow.period;
    let mut g = 4.0 * flow.mean * scale;
    for (i, qk) in flow.harmonics.iter().enumerate() {
        let k = (i + 1) as f64;
        let alpha = radius * (k * omega * density / viscosity).sqrt();
        let phase = Complex::from_polar(1.0, k * omega * t);
        g += (qk * scale * womersley_wall_slope(alpha) * phase).re;
    }
    g
}

/// B = ∫ max(−γ_w, 0) dt over one period (dimensionless), γ_w taken positive along the net
/// flow. Exact for the trigonometric polynomial γ_w (docs/physics.md §3.6): the sign changes
/// of γ_w are bracketed on at least [`CROSSING_SAMPLES_PER_HARMONIC`] samples per harmonic
/// (a power of two: all samples at once by one inverse FFT), refined by regula falsi, and the
/// backward arcs integrated with γ_w's antiderivative. A backward excursion narrower than one
/// sample spacing (≤ T/(16H)) between two forward samples would be missed; its strain is below
/// that width times its depth, far under the law's accuracy. Cost per vessel: O(m log m) for
/// the m samples plus a few H-term evaluations per crossing (the 20,000-sample rectangle rule
/// it replaces cost ~12 ms per vessel: 50 min for a 1e6-segment tree's first pass; the direct
/// sum over the samples after it, O(16 H²), ~50 µs).
pub fn backward_wall_strain(flow: &PeriodicFlow, radius: f64, density: f64, viscosity: f64) -> f64 {
    let mut b = 0.0;
    backward_arcs(flow, radius, density, viscosity, |shear, start, end| {
        b += shear.primitive(end) - shear.primitive(start);
    });
    b
}

/// The backward arcs [start, end] of one period (an arc through t = 0 in two pieces) of the
/// backward wall shear of [`backward_wall_strain`], each given to `arc` with that shear.
fn backward_arcs(
    flow: &PeriodicFlow,
    radius: f64,
    density: f64,
    viscosity: f64,
    mut arc: impl FnMut(&BackwardShear<'_>, f64, f64),
) {
    let sign = if flow.mean < 0.0 { -1.0 } else { 1.0 };
    // f(t) = −sign γ_w(t) = f0 + Re Σ_k c_k e^{ikωt}: the backward shear
    let scale = 1.0 / (PI * radius.powi(3));
    let omega = 2.0 * PI / flow.period;
    let f0 = -sign * 4.0 * flow.mean * scale;
    SCRATCH.with(|cell| {
        let mut scratch = cell.borrow_mut();
        let Scratch { c, values, fft } = &mut *scratch;
        c.clear();
        c.extend(flow.harmonics.iter().enumerate().map(|(i, qk)| {
            let alpha = radius * (((i + 1) as f64) * omega * density / viscosity).sqrt();
            -sign * qk * scale * womersley_wall_slope(alpha)
        }));
        let shear = BackwardShear { f0, c, omega };
        let m = (CROSSING_SAMPLES_PER_HARMONIC * c.len())
            .max(64)
            .next_power_of_two();
        fft.sample(f0, c, m, values);
        let dt = flow.period / m as f64;
        let mut arc_start = (values[0] > 0.0).then_some(0.0);
        for j in 0..m {
            let (fa, fb) = (values[j], values[(j + 1) % m]);
            if (fa > 0.0) == (fb > 0.0) {
                continue;
            }
            let root = shear.crossing(j as f64 * dt, (j + 1) as f64 * dt, fa, fb);
            match arc_start.take() {
                Some(s) => arc(&shear, s, root),
                None => arc_start = Some(root),
            }
        }
        if let Some(s) = arc_start {
            arc(&shear, s, flow.period);
        }
    })
}

/// The per-thread buffers of [`backward_wall_strain`], reused from vessel to vessel.
#[derive(Default)]
struct Scratch {
    c: Vec<Complex<f64>>,
    values: Vec<f64>,
    fft: Fft,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Samples per harmonic (at least) on which [`backward_wall_strain`] brackets the sign changes:
/// 16 per period of the highest harmonic.
const CROSSING_SAMPLES_PER_HARMONIC: usize = 16;

/// A radix-2 inverse FFT of one size at a time, with its table of roots of unity (kept while
/// the size stays: every vessel with as many harmonics on this thread shares it).
#[derive(Default)]
struct Fft {
    /// e^{2πip/m}, p < m/2, each from its own `from_polar` (no accumulated rotation).
    roots: Vec<Complex<f64>>,
    work: Vec<Complex<f64>>,
}

impl Fft {
    /// values[j] = f0 + Re Σ_{k=1}^{H} c_k e^{2πijk/m}, j < m (m a power of two > 2H): the
    /// inverse DFT of (0, c_1, …, c_H, 0, …), in m/2 log2 m butterflies instead of m H terms.
    /// Round-off: O(ε log2 m Σ|c_k|), that of the direct sum (whose phases came from the same
    /// table) within a small factor.
    fn sample(&mut self, f0: f64, c: &[Complex<f64>], m: usize, values: &mut Vec<f64>) {
        debug_assert!(m.is_power_of_two() && 2 * c.len() < m);
        if self.roots.len() != m / 2 {
            self.roots = (0..m / 2)
                .map(|p| Complex::from_polar(1.0, 2.0 * PI * p as f64 / m as f64))
                .collect();
        }
        let a = &mut self.work;
        a.clear();
        a.resize(m, Complex::new(0.0, 0.0));
        // bit-reversed order of the input, then in-place butterflies (decimation in time)
        let bits = m.trailing_zeros();
        for (k, ck) in c.iter().enumerate() {
            a[((k + 1).reverse_bits() >> (usize::BITS - bits)) % m] = *ck;
        }
        let mut half = 1;
        while half < m {
            let stride = m / (2 * half);
            for block in a.chunks_exact_mut(2 * half) {
                let (lo, hi) = block.split_at_mut(half);
                for (p, (u, v)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
                    let t = *v * self.roots[p * stride];
                    *v = *u - t;
                    *u += t;
                }
            }
            half *= 2;
        }
        values.clear();
        values.extend(a.iter().map(|z| f0 + z.re));
    }
}

/// The backward wall shear f(t) = f0 + Re Σ_k c_k e^{ikωt} of [`backward_wall_strain`].
struct BackwardShear<'a> {
    f0: f64,
    c: &'a [Complex<f64>],
    omega: f64,
}

impl BackwardShear<'_> {
    /// start + Σ_k term(k, c_k, e^{ikωt}), the phases by powers of one `from_polar` (H complex
    /// products instead of H sine-cosine pairs; the k-th power's rounding is ~k ulp, far below
    /// the crossing's tolerance).
    fn harmonic_sum(
        &self,
        t: f64,
        start: f64,
        term: impl Fn(f64, Complex<f64>, Complex<f64>) -> f64,
    ) -> f64 {
        let w = Complex::from_polar(1.0, self.omega * t);
        let mut phase = w;
        let mut f = start;
        for (i, ck) in self.c.iter().enumerate() {
            f += term((i + 1) as f64, *ck, phase);
            phase *= w;
        }
        f
    }

    fn value(&self, t: f64) -> f64 {
        self.harmonic_sum(t, self.f0, |_, ck, phase| (ck * phase).re)
    }

    /// ∫_0^t f: f0 t + Re Σ_k c_k (e^{ikωt} − 1)/(ikω).
    fn primitive(&self, t: f64) -> f64 {
        self.harmonic_sum(t, self.f0 * t, |k, ck, phase| {
            (ck * (phase - 1.0) / Complex::new(0.0, k * self.omega)).re
        })
    }

    /// The sign change of f in [a, b] (f(a) = fa, f(b) = fb of opposite signs), by the
    /// Illinois variant of regula falsi. The arcs' integrals depend on a crossing to second
    /// order only (f vanishes there), so 1e-10 of the bracket is ample.
    fn crossing(&self, mut a: f64, mut b: f64, mut fa: f64, mut fb: f64) -> f64 {
        let tol = 1e-10 * (b - a);
        let mut side = 0;
        for _ in 0..100 {
            let t = (a * fb - b * fa) / (fb - fa);
            let ft = self.value(t);
            if ft == 0.0 || (b - a) <= tol {
                return t;
            }
            if (ft > 0.0) == (fb > 0.0) {
                b = t;
                fb = ft;
                if side == -1 {
                    fa *= 0.5;
                }
                side = -1;
            } else {
                a = t;
                fa = ft;
                if side == 1 {
                    fb *= 0.5;
                }
                side = 1;
            }
            if (b - a).abs() <= tol {
                return 0.5 * (a + b);
            }
        }
        0.5 * (a + b)
    }
}

/// The inlet-renewal conductance G_r (m³/s) of a vessel (module doc): the extra wall uptake
/// is G_r (c − c_w) on top of the Graetz law of the net mean flow. Errors name the vessel:
/// non-finite or non-positive geometry/properties/period, or no net flow (the law diverges as
/// ⟨Q⟩ → 0, docs/validation-oxygen.md §12).
pub fn inlet_renewal_conductance(
    vessel: &str,
    flow: &PeriodicFlow,
    radius: f64,
    density: f64,
    viscosity: f64,
    diffusivity: f64,
) -> Result<f64> {
    renewal_conductance(
        &|| vessel.to_owned(),
        flow,
        radius,
        density,
        viscosity,
        diffusivity,
    )
}

/// [`inlet_renewal_conductance`] with the vessel's name made only for an error (a tree's
/// setup calls it once per vessel).
fn renewal_conductance(
    vessel: &dyn Fn() -> String,
    flow: &PeriodicFlow,
    radius: f64,
    density: f64,
    viscosity: f64,
    diffusivity: f64,
) -> Result<f64> {
    for (what, v) in [
        ("radius", radius),
        ("blood density", density),
        ("blood viscosity", viscosity),
        ("O2 diffusivity", diffusivity),
        ("flow period", flow.period),
    ] {
        finite_number("", what, v, false).map_err(|e| match e {
            Error::Model { message, .. } => Error::model(vessel(), message),
            e => e,
        })?;
    }
    if !(flow.mean.is_finite() && flow.mean != 0.0)
        || flow
            .harmonics
            .iter()
            .any(|q| !(q.re.is_finite() && q.im.is_finite()))
    {
        return Err(Error::model(
            vessel(),
            format!(
                "inlet renewal needs a finite, nonzero net mean flow and finite harmonics, got mean {} m³/s",
                flow.mean
            ),
        ));
    }
    let b = backward_wall_strain(flow, radius, density, viscosity);
    let gamma_t = 4.0 * flow.mean.abs() * flow.period / (PI * radius.powi(3));
    Ok(INLET_RENEWAL_A * 2.0 * PI * radius * diffusivity * b.powf(1.5) / gamma_t.sqrt())
}

/// |⟨Q⟩| of a segment from its cycle-mean |Q| and its forward-flow mean ⟨max(±Q, 0)⟩ =
/// (⟨|Q|⟩ + |⟨Q⟩|)/2 (`run::mean_flow`): exactly ⟨|Q|⟩ when the flow keeps one sign.
pub fn net_mean(mean_abs: f64, mean_forward: f64) -> f64 {
    if mean_forward == mean_abs {
        mean_abs
    } else {
        (2.0 * mean_forward - mean_abs).max(0.0)
    }
}

/// The inlet-renewal law of one vessel as per-segment factors on the Graetz law of each
/// segment's net mean flow `net[j]` (docs/physics.md §3.6): the vessel's net-mean law G_net =
/// Σ_j G(net_j) plus the renewal conductance G_r of its inlet (the first segment, or the last
/// when the net flow runs backward), spread in proportion to G(net_j), and capped per segment
/// by complete renewal every period, penetration theory's 2 sqrt(D/(πT)) over the segment's
/// wall (never reached in the validated rows, where it is 5–100× the law; it bounds G_r's
/// divergence as ⟨Q⟩ → 0). A cap by the law of ⟨|Q|⟩ would be wrong: near-wall reversal
/// renews the layer even when Q(t) keeps its sign (⟨|Q|⟩ = ⟨Q⟩). `abs[j]` (⟨|Q|⟩) is kept for
/// a segment without net flow, whose net law is the fully developed one. `flow`: the inlet
/// segment's periodic flow; `nu` the kinematic viscosity μ/ρ (m²/s), `d` the diffusivity.
pub fn segment_factors(
    vessel: &str,
    segs: &[SegmentWall],
    net: &[f64],
    abs: &[f64],
    flow: &PeriodicFlow,
    nu: f64,
    d: f64,
) -> Result<Vec<f64>> {
    let mut out = Vec::with_capacity(segs.len());
    segment_factors_into(&|| vessel.to_owned(), segs, net, abs, flow, nu, d, &mut out)?;
    Ok(out)
}

/// [`segment_factors`] into `out` (cleared first; reused from vessel to vessel by a tree's
/// setup), the vessel's name made only for an error.
#[allow(clippy::too_many_arguments)]
pub fn segment_factors_into(
    vessel: &dyn Fn() -> String,
    segs: &[SegmentWall],
    net: &[f64],
    abs: &[f64],
    flow: &PeriodicFlow,
    nu: f64,
    d: f64,
    out: &mut Vec<f64>,
) -> Result<()> {
    // G(net_j) first, in `out`; then each replaced by its factor
    out.clear();
    out.extend(
        segs.iter()
            .zip(net)
            .map(|(s, &q)| graetz_conductance(s, d, q)),
    );
    let total: f64 = out.iter().sum();
    let inlet = if flow.mean < 0.0 {
        segs.last()
    } else {
        segs.first()
    };
    let ratio = match inlet {
        Some(s) if flow.mean != 0.0 && total > 0.0 => {
            renewal_conductance(vessel, flow, s.radius, 1.0, nu, d)? / total
        }
        _ => f64::INFINITY,
    };
    let k_renewed = 2.0 * (d / (PI * flow.period)).sqrt();
    for ((s, &qa), f) in segs.iter().zip(abs).zip(out.iter_mut()) {
        let g = *f;
        *f = if g > 0.0 {
            let renewed = g * (1.0 + ratio);
            // the cap max(complete renewal, G(⟨|Q|⟩), g) only binds above the larger of the
            // other two: the law of ⟨|Q|⟩ (two Graetz series) is evaluated only then
            let cap = (k_renewed * s.area()).max(g);
            let cap = if renewed > cap {
                cap.max(graetz_conductance(s, d, qa))
            } else {
                cap
            };
            renewed.min(cap) / g
        } else {
            1.0
        };
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// −d(shape)/dρ at the wall from scipy's complex Bessel functions (an independent
    /// implementation), α = 0.5, 2, 5, 11, 30, 60.
    const SCIPY_SLOPES: [(f64, f64, f64); 6] = [
        (0.5, 4.000216997407073, 0.041664858371753107),
        (2.0, 4.054499164773957, 0.659417317143574),
        (5.0, 5.289423811659766, 3.1745214602309932),
        (11.0, 9.39826556965691, 7.641547127614052),
        (30.0, 22.75737193299561, 21.16689806529684),
        (60.0, 43.948500620519894, 42.4037854912172),
    ];

    #[test]
    fn womersley_wall_slope_matches_scipy_bessel_functions() {
        // 1e-11 relative: both are double-precision evaluations of the same closed form
        for (alpha, re, im) in SCIPY_SLOPES {
            let s = womersley_wall_slope(alpha);
            let want = Complex::new(re, im);
            assert!(
                (s - want).norm() < 1e-11 * want.norm(),
                "α {alpha}: {s} vs {want}"
            );
        }
        // the power series joins the recurrence at the switch and agrees with it below
        // (1e-13: both round-off; the closed form loses digits to 1 − 2J1/(zJ0) ≈ α²/8 at
        // small α, hence from α = 0.5 on)
        for alpha in [0.5, 1.0, 3.0, 7.0, SLOPE_SERIES_MAX_ALPHA] {
            let (a, b) = (slope_power_series(alpha), slope_closed(alpha));
            assert!((a - b).norm() < 1e-13 * b.norm(), "α {alpha}: {a} vs {b}");
        }
        // Poiseuille in the limit, and its first Womersley terms 4 + iα²/6 + α⁴/288 + O(α⁶)
        assert_eq!(womersley_wall_slope(0.0), Complex::new(4.0, 0.0));
        let a: f64 = 0.01;
        let taylor = Complex::new(4.0 + a.powi(4) / 288.0, a * a / 6.0);
        assert!((womersley_wall_slope(a) - taylor).norm() < 1e-15);
    }

    fn paper_straight() -> [Complex<f64>; 2] {
        // paper-straight.yaml: cos (0, −8e-6), sin (3e-5, 8e-6) → Q̂ = a − i b
        [Complex::new(0.0, -3e-5), Complex::new(-8e-6, -8e-6)]
    }

    #[test]
    fn backward_wall_strain_of_a_slow_sinusoid_is_the_closed_form() {
        // α → 0 (radius 0.1 mm): γ_w = γ̄ (1 + a sin ωt); B/(γ̄T) = (2 sqrt(a² − 1) − π + 2 asin(1/a))/(2π)
        let (r, mean, a, period) = (1e-4, 1e-9, 2.5, 1.0);
        let h = [Complex::new(0.0, -a * mean)];
        let flow = PeriodicFlow {
            period,
            mean,
            harmonics: &h,
        };
        let b = backward_wall_strain(&flow, r, 1050.0, 3.5e-3);
        let gbar_t = 4.0 * mean * period / (PI * r.powi(3));
        let want =
            gbar_t * (2.0 * (a * a - 1.0f64).sqrt() - PI + 2.0 * (1.0 / a).asin()) / (2.0 * PI);
        // α = 0.055 here: the Womersley correction to the shear is O(α²/6) ≈ 5e-4
        assert!((b / want - 1.0).abs() < 2e-3, "{b} vs {want}");
    }

    #[test]
    fn backward_wall_strain_of_one_womersley_harmonic_is_the_closed_form() {
        // one harmonic, α ≈ 12 (an aorta), strong reversal: the backward shear is
        // f0 + |c| cos(ωt + φ), positive on an arc of half-width θ* = acos(−f0/|c|), so
        // B = (2 f0 θ* + 2|c| sin θ*)/ω, with c from the Womersley wall slope (checked
        // against scipy's Bessel functions above)
        let (r, rho, mu, period) = (0.008, 1050.0, 3.5e-3, 0.9);
        for (mean, q1) in [
            (2e-5, Complex::new(0.0, -6e-5)),
            (2e-5, Complex::new(4e-5, 3e-5)),
            (-1e-5, Complex::new(-2e-5, 5e-5)),
        ] {
            let h = [q1];
            let flow = PeriodicFlow {
                period,
                mean,
                harmonics: &h,
            };
            let b = backward_wall_strain(&flow, r, rho, mu);
            let omega = 2.0 * PI / period;
            let scale = 1.0 / (PI * r.powi(3));
            let sign = mean.signum();
            let f0 = -sign * 4.0 * mean * scale;
            let alpha = r * (omega * rho / mu).sqrt();
            let c = (q1 * scale * womersley_wall_slope(alpha)).norm();
            let theta = (-f0 / c).acos();
            let want = (2.0 * f0 * theta + 2.0 * c * theta.sin()) / omega;
            assert!(want > 0.0);
            assert!((b / want - 1.0).abs() < 1e-12, "{b} vs {want}");
        }
    }

    #[test]
    fn backward_wall_strain_of_many_harmonics_is_the_integral_of_the_backward_shear() {
        // 24 harmonics (a sharp waveform with reversal; 512 samples in the inverse FFT)
        // against a midpoint rule of max(−γ_w, 0) with γ_w summed term by term (as
        // `wall_shear_rate`, one sine-cosine per term: independent of the FFT, the powers and
        // the crossings). The midpoint rule's error at the few kinks is O(h²) of the shear's
        // slope there: 1e-8 relative with 200,000 points.
        let h: Vec<Complex<f64>> = (1..=24)
            .map(|k| {
                let k = k as f64;
                Complex::from_polar(3e-5 / k, 0.7 * k + 0.3 * k * k)
            })
            .collect();
        for (r, mean) in [(0.008, 2e-5), (1.5e-3, -6e-6), (3e-4, 2.5e-6)] {
            let flow = PeriodicFlow {
                period: 0.8,
                mean,
                harmonics: &h,
            };
            let (rho, mu) = (1050.0, 3.5e-3);
            let b = backward_wall_strain(&flow, r, rho, mu);
            let n = 200_000;
            let dt = flow.period / n as f64;
            // γ_w as `wall_shear_rate` sums it, its Womersley factors computed once
            let scale = 1.0 / (PI * r.powi(3));
            let omega = 2.0 * PI / flow.period;
            let c: Vec<Complex<f64>> = (1..=h.len())
                .map(|k| {
                    let alpha = r * (k as f64 * omega * rho / mu).sqrt();
                    h[k - 1] * scale * womersley_wall_slope(alpha)
                })
                .collect();
            let want: f64 = (0..n)
                .map(|i| {
                    let t = (i as f64 + 0.5) * dt;
                    let g = c.iter().enumerate().fold(4.0 * mean * scale, |g, (k, ck)| {
                        g + (ck * Complex::from_polar(1.0, (k + 1) as f64 * omega * t)).re
                    });
                    (-mean.signum() * g).max(0.0) * dt
                })
                .sum();
            assert!(want > 0.0);
            assert!((b / want - 1.0).abs() < 1e-8, "r {r}: {b} vs {want}");
        }
    }

    #[test]
    fn the_paper_aorta_matches_the_python_reference_formula() {
        // oxyline.reference.validation: backward_wall_strain = 49.63287234028849 and
        // inlet_renewal_excess/(α ΔP) = 9.839341556188514e-10 m³/s (both with 20,000 samples)
        let h = paper_straight();
        let flow = PeriodicFlow {
            period: 1.0,
            mean: 2e-5,
            harmonics: &h,
        };
        let b = backward_wall_strain(&flow, 0.008, 1050.0, 3.5e-3);
        assert!((b / 49.63287234028849 - 1.0).abs() < 1e-9, "{b}");
        let g = inlet_renewal_conductance("aorta", &flow, 0.008, 1050.0, 3.5e-3, 1.2e-9).unwrap();
        assert!((g / 9.839341556188514e-10 - 1.0).abs() < 1e-9, "{g}");
        // a reversed vessel (net flow backward) renews at its other end: the same conductance
        let neg: Vec<_> = h.iter().map(|q| -q).collect();
        let back = PeriodicFlow {
            period: 1.0,
            mean: -2e-5,
            harmonics: &neg,
        };
        let g_back =
            inlet_renewal_conductance("aorta", &back, 0.008, 1050.0, 3.5e-3, 1.2e-9).unwrap();
        assert!((g_back / g - 1.0).abs() < 1e-12);
    }

    fn ten_segments(length: f64) -> Vec<SegmentWall> {
        (0..10)
            .map(|i| SegmentWall {
                radius: 0.008,
                x0: length * i as f64 / 10.0,
                x1: length * (i + 1) as f64 / 10.0,
            })
            .collect()
    }

    #[test]
    fn segment_factors_add_the_renewal_conductance_to_the_net_mean_law() {
        // the paper aorta in ten segments: Σ_j G(net) f_j = G_net + G_r (the law of the module
        // doc), G_net the Graetz law of the whole vessel at the net flow (one segment [0, L]:
        // the segment laws telescope, 1e-12), G_r the pure function above
        let h = paper_straight();
        let flow = PeriodicFlow {
            period: 1.0,
            mean: 2e-5,
            harmonics: &h,
        };
        let (d, nu) = (1.2e-9, 3.5e-3 / 1050.0);
        let segs = ten_segments(0.2);
        let net = vec![2e-5; 10];
        let abs = vec![3.1e-5; 10];
        let f = segment_factors("aorta", &segs, &net, &abs, &flow, nu, d).unwrap();
        let whole = SegmentWall {
            radius: 0.008,
            x0: 0.0,
            x1: 0.2,
        };
        let g_net = graetz_conductance(&whole, d, 2e-5);
        let g_r = inlet_renewal_conductance("aorta", &flow, 0.008, 1050.0, 3.5e-3, d).unwrap();
        let got: f64 = segs
            .iter()
            .zip(&f)
            .map(|(s, k)| graetz_conductance(s, d, 2e-5) * k)
            .sum();
        assert!(
            (got / (g_net + g_r) - 1.0).abs() < 1e-12,
            "{got} vs {}",
            g_net + g_r
        );
        // without backward wall strain (no harmonics) the law is the net-mean Graetz law
        let steady = PeriodicFlow {
            period: 1.0,
            mean: 2e-5,
            harmonics: &[],
        };
        let f = segment_factors("aorta", &segs, &net, &net, &steady, nu, d).unwrap();
        assert!(f.iter().all(|&k| k == 1.0));
    }

    #[test]
    fn segment_factors_are_capped_by_complete_renewal() {
        // a purely oscillating inlet flow (⟨Q⟩ = 0: G_r → ∞): penetration
        // theory's complete renewal every period, 2 sqrt(D/(πT)) × wall area, segment by
        // segment (above the law of ⟨|Q|⟩ here)
        let h = paper_straight();
        let (d, nu) = (1.2e-9, 3.5e-3 / 1050.0);
        let segs = ten_segments(0.2);
        let net = vec![1e-9; 10];
        let abs = vec![2.5e-5; 10];
        let flow = PeriodicFlow {
            period: 1.0,
            mean: 0.0,
            harmonics: &h,
        };
        let f = segment_factors("aorta", &segs, &net, &abs, &flow, nu, d).unwrap();
        for (s, k) in segs.iter().zip(&f) {
            let renewed = 2.0 * (d / PI).sqrt() * s.area();
            assert!(renewed > graetz_conductance(s, d, 2.5e-5));
            let want = renewed / graetz_conductance(s, d, net[0]);
            assert!((k / want - 1.0).abs() < 1e-12, "{k} vs {want}");
        }
    }

    #[test]
    fn bad_input_is_a_typed_error_naming_the_vessel() {
        let h = paper_straight();
        let none = PeriodicFlow {
            period: 1.0,
            mean: 0.0,
            harmonics: &h,
        };
        let e =
            inlet_renewal_conductance("aorta", &none, 0.008, 1050.0, 3.5e-3, 1.2e-9).unwrap_err();
        assert!(e.to_string().contains("aorta") && e.to_string().contains("net mean flow"));
        let flow = PeriodicFlow {
            period: 1.0,
            mean: 2e-5,
            harmonics: &h,
        };
        let e =
            inlet_renewal_conductance("aorta", &flow, -1.0, 1050.0, 3.5e-3, 1.2e-9).unwrap_err();
        assert!(e.to_string().contains("aorta") && e.to_string().contains("radius"));
    }
}
