//! Activation functions φ(t) ∈ [0, 1] of heart chambers (docs/physics.md §1.8), as
//! svZeroDSolver defines them (time within the cycle by `fmod`).

use super::in_cycle;
use crate::error::{Error, Result};
use std::f64::consts::PI;

#[derive(Debug, Clone, PartialEq)]
pub enum Activation {
    /// 0 before `t_active`, then ½(1 − cos(2π (t − t_active)/t_twitch)) for one twitch.
    HalfCosine { t_active: f64, t_twitch: f64 },
    /// A half-cosine rise of `contract_duration` from `contract_start`, a half-cosine fall of
    /// `relax_duration` from `relax_start`, 0 otherwise.
    PiecewiseCosine {
        contract_start: f64,
        relax_start: f64,
        contract_duration: f64,
        relax_duration: f64,
    },
    /// The two-Hill function g₁/(1 + g₁) · 1/(1 + g₂), g_i = (t_s/τ_i)^{m_i}, t_s the time
    /// since `t_shift`, normalised to a peak of 1 over the cycle.
    TwoHill {
        t_shift: f64,
        tau_1: f64,
        tau_2: f64,
        m1: f64,
        m2: f64,
        /// 1 / (the peak), found as svZeroDSolver does (grid of 1e-5 s over the period).
        norm: f64,
        /// The grid time of that peak (the normalisation's derivative is the shape's there).
        peak_time: f64,
    },
    /// The atrial activation of Sankaran et al. 2012: a cosine of duration T_sa = f·T that
    /// wraps across the cycle's end and ends at the P-wave time T/d.
    WrappingCosine {
        systole_fraction: f64,
        p_wave_divisor: f64,
    },
    /// The 25-mode Fourier series of ventricular elastance used by svZeroDSolver (J. Tran's
    /// tuning framework), scaled to [0, 1] by its extremes over 10,000 samples of the cycle.
    Fourier { min: f64, range: f64 },
}

/// Fourier coefficients (cos, sin) of the ventricular elastance series (svZeroDSolver's
/// `FourierActivation` table, published with the closed-loop heart model).
const FOURIER: [[f64; 2]; 25] = [
    [0.283748803, 0.000000000],
    [0.031830626, -0.374299825],
    [-0.209472400, -0.018127770],
    [0.020520047, 0.073971113],
    [0.008316883, -0.047249597],
    [-0.041677660, 0.003212163],
    [0.000867323, 0.019441411],
    [-0.001675379, -0.005565534],
    [-0.011252277, 0.003401432],
    [-0.000414677, 0.008376795],
    [0.000253749, -0.000071880],
    [-0.002584966, 0.001566861],
    [0.000584752, 0.003143555],
    [0.000028502, -0.000024787],
    [0.000022961, -0.000007476],
    [0.000018735, -0.000001281],
    [0.000015573, 0.000001781],
    [0.000013133, 0.000003494],
    [0.000011199, 0.000004507],
    [0.000009634, 0.000005117],
    [0.000008343, 0.000005481],
    [0.000007265, 0.000005687],
    [0.000006354, 0.000005789],
    [0.000005575, 0.000005821],
    [0.000004903, 0.000005805],
];

pub(crate) fn fourier_raw(tc: f64, period: f64) -> f64 {
    FOURIER.iter().enumerate().fold(0.0, |v, (i, [a, b])| {
        let w = 2.0 * PI * i as f64 * tc / period;
        v + a * w.cos() - b * w.sin()
    })
}

impl Activation {
    /// A two-Hill activation normalised over `period`; a non-positive peak is a model error.
    pub fn two_hill(
        element: &str,
        period: f64,
        [t_shift, tau_1, tau_2, m1, m2]: [f64; 5],
    ) -> Result<Self> {
        let raw = |t: f64| {
            let (g1, g2) = hill_gains(t, [tau_1, tau_2, m1, m2]);
            g1 / (1.0 + g1) / (1.0 + g2)
        };
        // svZeroDSolver's grid: t = 0, 1e-5, ... < period (accumulated as it does)
        let (mut peak, mut peak_time) = (0.0f64, 0.0);
        let mut t = 0.0;
        while t < period {
            let r = raw(t);
            if r > peak {
                (peak, peak_time) = (r, t);
            }
            t += 1e-5;
        }
        if !(peak > 0.0 && peak.is_finite()) {
            return Err(Error::model(
                element,
                format!("two_hill activation has peak {peak}; check tau_1, tau_2 > 0"),
            ));
        }
        Ok(Activation::TwoHill {
            t_shift,
            tau_1,
            tau_2,
            m1,
            m2,
            norm: 1.0 / peak,
            peak_time,
        })
    }

    /// The Fourier activation normalised over `period`.
    pub fn fourier(period: f64) -> Self {
        let n = 10_000;
        let dt = period / n as f64;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..n {
            let v = fourier_raw(k as f64 * dt, period);
            lo = lo.min(v);
            hi = hi.max(v);
        }
        let range = if hi - lo > 0.0 { hi - lo } else { 1.0 };
        Activation::Fourier { min: lo, range }
    }

    /// φ(t) for cardiac period `period`.
    pub fn eval(&self, t: f64, period: f64) -> f64 {
        match *self {
            Activation::HalfCosine { t_active, t_twitch } => {
                let tc = in_cycle(t, period);
                let contract = if tc >= t_active { tc - t_active } else { 0.0 };
                if contract <= t_twitch {
                    -0.5 * (2.0 * PI * contract / t_twitch).cos() + 0.5
                } else {
                    0.0
                }
            }
            Activation::PiecewiseCosine {
                contract_start,
                relax_start,
                contract_duration,
                relax_duration,
            } => match piecewise_phase(
                t,
                period,
                [contract_start, contract_duration],
                [relax_start, relax_duration],
            ) {
                Piece::Contract(c) => 0.5 * (1.0 - (PI * c / contract_duration).cos()),
                Piece::Relax(r) => 0.5 * (1.0 + (PI * r / relax_duration).cos()),
                Piece::Rest => 0.0,
            },
            Activation::TwoHill {
                t_shift,
                tau_1,
                tau_2,
                m1,
                m2,
                norm,
                ..
            } => {
                let ts = since_shift(t, t_shift, period);
                let (g1, g2) = hill_gains(ts, [tau_1, tau_2, m1, m2]);
                norm * g1 / (1.0 + g1) / (1.0 + g2)
            }
            Activation::WrappingCosine {
                systole_fraction,
                p_wave_divisor,
            } => {
                let (tc, tsa, tp, wrap) =
                    wrapping_phase(t, period, systole_fraction, p_wave_divisor);
                match wrap {
                    Some(false) => 0.5 * (1.0 - (2.0 * PI * (tc - tp + tsa) / tsa).cos()),
                    Some(true) => 0.5 * (1.0 - (2.0 * PI * (tc - tp - (period - tsa)) / tsa).cos()),
                    None => 0.0,
                }
            }
            Activation::Fourier { min, range } => {
                (fourier_raw(in_cycle(t, period), period) - min) / range
            }
        }
    }

    /// ∂φ/∂θ at time t for the timing or shape parameter `key` (its model key) of the
    /// activation: every law but the parameter-free Fourier series. Each law is a cosine or
    /// Hill shape of the time within the cycle, differentiated in closed form on the branch
    /// that holds time t (a law's jumps between branches move with the timing, which the
    /// discrete run only sees when a step time crosses them). None for a key the law lacks.
    pub fn derivative(&self, key: &str, t: f64, period: f64) -> Option<f64> {
        match *self {
            Activation::HalfCosine { t_active, t_twitch } => {
                half_cosine_derivative(key, in_cycle(t, period) - t_active, t_twitch)
            }
            Activation::PiecewiseCosine {
                contract_start,
                relax_start,
                contract_duration,
                relax_duration,
            } => {
                if !matches!(
                    key,
                    "contract_start" | "relax_start" | "contract_duration" | "relax_duration"
                ) {
                    return None;
                }
                let phase = piecewise_phase(
                    t,
                    period,
                    [contract_start, contract_duration],
                    [relax_start, relax_duration],
                );
                Some(match phase {
                    Piece::Contract(c) => {
                        // φ = ½(1 − cos(π c/d)): ∂φ/∂c = ½ (π/d) sin(π c/d)
                        let h = 0.5 * PI / contract_duration * (PI * c / contract_duration).sin();
                        match key {
                            "contract_start" => -h,
                            "contract_duration" => -h * c / contract_duration,
                            _ => 0.0,
                        }
                    }
                    Piece::Relax(r) => {
                        // φ = ½(1 + cos(π r/d)): ∂φ/∂r = −½ (π/d) sin(π r/d)
                        let h = -0.5 * PI / relax_duration * (PI * r / relax_duration).sin();
                        match key {
                            "relax_start" => -h,
                            "relax_duration" => -h * r / relax_duration,
                            _ => 0.0,
                        }
                    }
                    Piece::Rest => 0.0,
                })
            }
            Activation::TwoHill { .. } => self.two_hill_derivative(key, t, period),
            Activation::WrappingCosine {
                systole_fraction,
                p_wave_divisor,
            } => {
                // φ = ½(1 − cos θ), θ = 2π (1 + u/T_sa), T_sa = f T, u = t_c − T/d on the
                // branch before the P wave and t_c − T/d − T on the one wrapping from the end
                let (tc, tsa, tp, wrap) =
                    wrapping_phase(t, period, systole_fraction, p_wave_divisor);
                let u = match wrap {
                    Some(false) => tc - tp,
                    Some(true) => tc - tp - period,
                    None => {
                        return matches!(key, "systole_fraction" | "p_wave_divisor").then_some(0.0);
                    }
                };
                let half_sin = 0.5 * (2.0 * PI * (1.0 + u / tsa)).sin();
                match key {
                    "systole_fraction" => Some(-half_sin * 2.0 * PI * u * period / (tsa * tsa)),
                    "p_wave_divisor" => {
                        Some(half_sin * 2.0 * PI * period / (p_wave_divisor * p_wave_divisor * tsa))
                    }
                    _ => None,
                }
            }
            Activation::Fourier { .. } => None,
        }
    }

    /// ∂φ/∂θ of the two-Hill law φ = raw(t_s)/raw(t*), raw = g₁/(1 + g₁) · 1/(1 + g₂),
    /// g_i = (t_s/τ_i)^{m_i}: the normalising peak raw(t*) is a maximum over a fixed grid, so
    /// its derivative is raw's own at the grid point t* that holds it (the shift moves only
    /// t_s, not the peak).
    fn two_hill_derivative(&self, key: &str, t: f64, period: f64) -> Option<f64> {
        let Activation::TwoHill {
            t_shift,
            tau_1,
            tau_2,
            m1,
            m2,
            norm,
            peak_time,
        } = *self
        else {
            return None;
        };
        // (raw, ∂raw/∂t_s, ∂raw/∂τ₁, ∂raw/∂τ₂, ∂raw/∂m₁, ∂raw/∂m₂) at t_s
        let parts = |ts: f64| {
            let (g1, g2) = hill_gains(ts, [tau_1, tau_2, m1, m2]);
            let d1 = 1.0 / ((1.0 + g1) * (1.0 + g1) * (1.0 + g2));
            let d2 = -g1 / ((1.0 + g1) * (1.0 + g2) * (1.0 + g2));
            // g ln(t_s/τ) → 0 as t_s → 0 (g vanishes faster than the logarithm grows)
            let log = |g: f64, tau: f64| if g > 0.0 { g * (ts / tau).ln() } else { 0.0 };
            let dts = if ts > 0.0 {
                d1 * m1 * g1 / ts + d2 * m2 * g2 / ts
            } else {
                0.0
            };
            let raw = g1 / (1.0 + g1) / (1.0 + g2);
            [
                raw,
                dts,
                -d1 * m1 * g1 / tau_1,
                -d2 * m2 * g2 / tau_2,
                d1 * log(g1, tau_1),
                d2 * log(g2, tau_2),
            ]
        };
        let k = match key {
            "t_shift" => 1,
            "tau_1" => 2,
            "tau_2" => 3,
            "m1" => 4,
            "m2" => 5,
            _ => return None,
        };
        let here = parts(since_shift(t, t_shift, period));
        if k == 1 {
            return Some(-norm * here[1]);
        }
        // φ = raw/peak: ∂φ = (∂raw − φ ∂peak)/peak
        let peak = parts(peak_time);
        Some(norm * (here[k] - norm * here[0] * peak[k]))
    }

    /// Phase ends within the cycle (for RK4's stability sampling).
    pub fn breakpoints(&self) -> Vec<f64> {
        match *self {
            Activation::HalfCosine { t_active, t_twitch } => {
                vec![t_active, t_active + 0.5 * t_twitch, t_active + t_twitch]
            }
            Activation::PiecewiseCosine {
                contract_start,
                relax_start,
                contract_duration,
                relax_duration,
            } => vec![
                contract_start,
                contract_start + contract_duration,
                relax_start,
                relax_start + relax_duration,
            ],
            Activation::TwoHill { t_shift, .. } => vec![t_shift],
            Activation::WrappingCosine { .. } | Activation::Fourier { .. } => Vec::new(),
        }
    }
}

/// The two-Hill law's time since `t_shift` within the cycle, in [0, period).
fn since_shift(t: f64, t_shift: f64, period: f64) -> f64 {
    let ts = (in_cycle(t, period) - t_shift) % period;
    if ts < 0.0 { ts + period } else { ts }
}

/// The two-Hill law's g₁ = (t_s/τ₁)^{m₁} and g₂ = (t_s/τ₂)^{m₂}.
fn hill_gains(ts: f64, [tau_1, tau_2, m1, m2]: [f64; 4]) -> (f64, f64) {
    ((ts / tau_1).powf(m1), (ts / tau_2).powf(m2))
}

/// Where time t falls in the piecewise-cosine law (`[start, duration]` of the contraction
/// and of the relaxation, each taken modulo the period as svZeroDSolver does).
enum Piece {
    /// Time `c` into the contraction.
    Contract(f64),
    /// Time `r` into the relaxation.
    Relax(f64),
    /// Neither: φ = 0.
    Rest,
}

fn piecewise_phase(t: f64, period: f64, [cs, cd]: [f64; 2], [rs, rd]: [f64; 2]) -> Piece {
    let c = (t - cs) % period;
    if (0.0..cd).contains(&c) {
        return Piece::Contract(c);
    }
    let r = (t - rs) % period;
    if (0.0..rd).contains(&r) {
        Piece::Relax(r)
    } else {
        Piece::Rest
    }
}

/// The wrapping cosine at time t: the time within the cycle t_c, T_sa = f T, the P-wave time
/// T/d, and its branch: Some(false) up to the P wave, Some(true) on the part that wraps from
/// the cycle's end, None between them (φ = 0).
fn wrapping_phase(
    t: f64,
    period: f64,
    systole_fraction: f64,
    p_wave_divisor: f64,
) -> (f64, f64, f64, Option<bool>) {
    let tsa = period * systole_fraction;
    let tp = period / p_wave_divisor;
    let tc = in_cycle(t, period);
    let wrap = if tc <= tp {
        Some(false)
    } else if tc >= (period - tsa) + tp && tc < period {
        Some(true)
    } else {
        None
    };
    (tc, tsa, tp, wrap)
}

/// ∂φ/∂θ of the half-cosine law for `key` (`t_active`, `t_twitch`) at `contract` = t_c −
/// t_active: φ = ½ (1 − cos θ), θ = 2π contract/t_twitch during the twitch, so the derivative
/// is ½ sin θ ∂θ/∂key there and 0 outside it (continuous at both ends, where sin θ = 0).
fn half_cosine_derivative(key: &str, contract: f64, t_twitch: f64) -> Option<f64> {
    let twitch = contract > 0.0 && contract <= t_twitch;
    let half_sin = if twitch {
        0.5 * (2.0 * PI * contract / t_twitch).sin()
    } else {
        0.0
    };
    match key {
        "t_active" => Some(-half_sin * 2.0 * PI / t_twitch),
        "t_twitch" => Some(-half_sin * 2.0 * PI * contract / (t_twitch * t_twitch)),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn activations_stay_in_unit_range_and_peak_at_one() {
        let period = 0.8;
        let acts = [
            Activation::HalfCosine {
                t_active: 0.2,
                t_twitch: 0.3,
            },
            Activation::PiecewiseCosine {
                contract_start: 0.2,
                relax_start: 0.3,
                contract_duration: 0.1,
                relax_duration: 0.3,
            },
            Activation::two_hill("a", period, [0.2, 0.18, 0.31, 1.32, 27.4]).unwrap(),
        ];
        for a in &acts {
            let v: Vec<f64> = (0..8000).map(|k| a.eval(k as f64 * 1e-4, period)).collect();
            let max = v.iter().copied().fold(f64::MIN, f64::max);
            assert!(
                v.iter().all(|&x| (-1e-12..=1.0 + 1e-12).contains(&x)),
                "{a:?}"
            );
            // the 1e-4 s sampling misses the peak by at most O((1e-4/width)²)
            assert!((max - 1.0).abs() < 1e-3, "{a:?}: {max}");
        }
    }

    /// Each law's ∂φ/∂θ against central differences of φ in θ (relative step 1e-6: the
    /// truncation O(h²) and the rounding ~1e-16/h stay below 1e-7 of the slope scale), at
    /// times inside every branch of the law.
    #[test]
    fn activation_derivatives_match_central_differences() {
        let period = 0.8;
        type Build = fn(&[f64]) -> Activation;
        let cases: [(Build, Vec<f64>, [&str; 5]); 4] = [
            (
                |p| Activation::HalfCosine {
                    t_active: p[0],
                    t_twitch: p[1],
                },
                vec![0.1, 0.35],
                ["t_active", "t_twitch", "", "", ""],
            ),
            (
                |p| Activation::PiecewiseCosine {
                    contract_start: p[0],
                    relax_start: p[1],
                    contract_duration: p[2],
                    relax_duration: p[3],
                },
                vec![0.05, 0.3, 0.2, 0.25],
                [
                    "contract_start",
                    "relax_start",
                    "contract_duration",
                    "relax_duration",
                    "",
                ],
            ),
            (
                |p| Activation::two_hill("a", 0.8, [p[0], p[1], p[2], p[3], p[4]]).unwrap(),
                vec![0.05, 0.18, 0.31, 1.32, 27.4],
                ["t_shift", "tau_1", "tau_2", "m1", "m2"],
            ),
            (
                |p| Activation::WrappingCosine {
                    systole_fraction: p[0],
                    p_wave_divisor: p[1],
                },
                vec![0.17, 9.0],
                ["systole_fraction", "p_wave_divisor", "", "", ""],
            ),
        ];
        for (build, p, keys) in &cases {
            let base = build(p);
            for (k, key) in keys.iter().enumerate().filter(|(_, k)| !k.is_empty()) {
                let h = 1e-6 * p[k];
                let (mut up, mut down) = (p.clone(), p.clone());
                up[k] += h;
                down[k] -= h;
                let (a, b) = (build(&up), build(&down));
                // the two-Hill peak's grid point must not move between the two evaluations
                let times = (0..80).map(|j| 0.0037 + j as f64 * 0.01);
                let mut scale = 0.0f64;
                let mut rows = Vec::new();
                for t in times {
                    let fd = (a.eval(t, period) - b.eval(t, period)) / (2.0 * h);
                    let exact = base.derivative(key, t, period).unwrap();
                    scale = scale.max(exact.abs());
                    rows.push((t, fd, exact));
                }
                assert!(scale > 0.0, "{key}");
                for (t, fd, exact) in rows {
                    assert!(
                        (fd - exact).abs() <= 1e-6 * scale,
                        "{key} at {t}: {fd} vs {exact}"
                    );
                }
            }
        }
        let fourier = Activation::fourier(period);
        assert_eq!(fourier.derivative("t_active", 0.1, period), None);
    }
}
