//! Time functions for boundary conditions: constants, tabulated (periodic linear or periodic
//! cubic spline) and Fourier series.

use crate::error::{Error, Result};
use serde::Deserialize;

/// A linear table's sample is a corner of its forcing (a breakpoint an error-controlled step
/// ends on, [`Waveform::kinks`]) where the slope changes by more than this share of the table's
/// largest |slope|: a sampled smooth curve's slope changes by ~2π/N of it per sample (N
/// samples a period), so tables of more than ~25 samples a period have none but their true
/// corners, and a coarse table is all corners.
pub const KINK_SHARE: f64 = 0.25;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// Periodic piecewise-linear, as svZeroDSolver (`fmod` of the time by the table period).
    #[default]
    Linear,
    /// Periodic C2 cubic spline through the samples (first and last sample must agree).
    PeriodicCubic,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum WaveformSpec {
    Constant {
        value: f64,
    },
    Table {
        time: Vec<f64>,
        value: Vec<f64>,
        #[serde(default)]
        interpolation: Interpolation,
        /// Value used for the steady initial state; default: exact time mean over one period.
        #[serde(default)]
        steady: Option<f64>,
    },
    Fourier {
        period: f64,
        mean: f64,
        #[serde(default)]
        cos: Vec<f64>,
        #[serde(default)]
        sin: Vec<f64>,
    },
}

/// A validated, ready-to-evaluate time function.
#[derive(Debug, Clone)]
pub enum Waveform {
    Constant(f64),
    Table {
        t: Vec<f64>,
        v: Vec<f64>,
        m: Option<Vec<f64>>,
        mean: f64,
    },
    Fourier {
        omega: f64,
        mean: f64,
        cos: Vec<f64>,
        sin: Vec<f64>,
    },
}

impl Waveform {
    pub fn constant(value: f64) -> Self {
        Waveform::Constant(value)
    }

    pub fn from_spec(spec: &WaveformSpec, element: &str) -> Result<Self> {
        let bad = |msg: String| Error::model(element, msg);
        match spec {
            WaveformSpec::Constant { value } => {
                if !value.is_finite() {
                    return Err(bad(format!("value must be finite, got {value}")));
                }
                Ok(Waveform::Constant(*value))
            }
            WaveformSpec::Fourier {
                period,
                mean,
                cos,
                sin,
            } => {
                if !(period.is_finite() && *period > 0.0) {
                    return Err(bad(format!("Fourier period must be > 0, got {period}")));
                }
                if let Some(x) = cos.iter().chain(sin).chain([mean]).find(|x| !x.is_finite()) {
                    return Err(bad(format!("Fourier coefficients must be finite, got {x}")));
                }
                Ok(Waveform::Fourier {
                    omega: 2.0 * std::f64::consts::PI / period,
                    mean: *mean,
                    cos: cos.clone(),
                    sin: sin.clone(),
                })
            }
            WaveformSpec::Table {
                time,
                value,
                interpolation,
                steady,
            } => {
                if time.len() != value.len() {
                    return Err(bad(format!(
                        "time table has {} entries but value table has {}",
                        time.len(),
                        value.len()
                    )));
                }
                if time.is_empty() {
                    return Err(bad("empty time table".into()));
                }
                if let Some((i, x)) = time
                    .iter()
                    .chain(value)
                    .enumerate()
                    .find(|(_, x)| !x.is_finite())
                {
                    return Err(bad(format!("table entry {i} is not finite ({x})")));
                }
                if time.len() == 1 {
                    return Ok(Waveform::Constant(steady.unwrap_or(value[0])));
                }
                if let Some(i) = (1..time.len()).find(|&i| time[i] <= time[i - 1]) {
                    return Err(bad(format!(
                        "time table must be strictly increasing, but t[{}] = {} <= t[{}] = {}",
                        i,
                        time[i],
                        i - 1,
                        time[i - 1]
                    )));
                }
                let m = match interpolation {
                    Interpolation::Linear => None,
                    Interpolation::PeriodicCubic => {
                        let (first, last) = (value[0], value[value.len() - 1]);
                        if (first - last).abs() > 1e-9 * first.abs().max(last.abs()).max(1e-300) {
                            return Err(bad(format!(
                                "periodic-cubic interpolation needs the first and last values equal, got {first} and {last}"
                            )));
                        }
                        Some(periodic_spline_moments(time, value))
                    }
                };
                let mean = table_mean(time, value, m.as_deref());
                Ok(Waveform::Table {
                    t: time.clone(),
                    v: value.clone(),
                    m,
                    mean: steady.unwrap_or(mean),
                })
            }
        }
    }

    /// The waveform with every value negated (−w(t)).
    pub fn negated(self) -> Self {
        match self {
            Waveform::Constant(v) => Waveform::Constant(-v),
            Waveform::Table { t, v, m, mean } => Waveform::Table {
                t,
                v: v.iter().map(|x| -x).collect(),
                m: m.map(|m| m.iter().map(|x| -x).collect()),
                mean: -mean,
            },
            Waveform::Fourier {
                omega,
                mean,
                cos,
                sin,
            } => Waveform::Fourier {
                omega,
                mean: -mean,
                cos: cos.iter().map(|x| -x).collect(),
                sin: sin.iter().map(|x| -x).collect(),
            },
        }
    }

    /// Period of a tabulated waveform (t_last - t_first) or Fourier series.
    pub fn period(&self) -> Option<f64> {
        match self {
            Waveform::Constant(_) => None,
            Waveform::Table { t, .. } => Some(t[t.len() - 1] - t[0]),
            Waveform::Fourier { omega, .. } => Some(2.0 * std::f64::consts::PI / omega),
        }
    }

    /// Value used for the steady initial state.
    pub fn mean(&self) -> f64 {
        match self {
            Waveform::Constant(v) => *v,
            Waveform::Table { mean, .. } => *mean,
            Waveform::Fourier { mean, .. } => *mean,
        }
    }

    /// dw/dt (one-sided within a segment of a linear table: its slope).
    pub fn slope(&self, time: f64) -> f64 {
        match self {
            Waveform::Constant(_) => 0.0,
            Waveform::Fourier {
                omega, cos, sin, ..
            } => {
                let mut s = 0.0;
                for (k, a) in cos.iter().enumerate() {
                    let w = omega * (k + 1) as f64;
                    s -= a * w * (w * time).sin();
                }
                for (k, b) in sin.iter().enumerate() {
                    let w = omega * (k + 1) as f64;
                    s += b * w * (w * time).cos();
                }
                s
            }
            Waveform::Table { t, v, m, .. } => {
                let (k, a, b, h) = table_locate(t, time);
                let linear = (v[k] - v[k - 1]) / h;
                match m {
                    None => linear,
                    Some(m) => {
                        linear
                            + ((3.0 * b * b - 1.0) * m[k] - (3.0 * a * a - 1.0) * m[k - 1]) * h
                                / 6.0
                    }
                }
            }
        }
    }

    /// d²w/dt² (within a segment of a table: zero for a linear one, the spline's own for a
    /// cubic one; one-sided as [`Waveform::slope`]).
    pub fn curvature(&self, time: f64) -> f64 {
        match self {
            Waveform::Constant(_) => 0.0,
            Waveform::Fourier {
                omega, cos, sin, ..
            } => {
                let mut s = 0.0;
                for (k, a) in cos.iter().enumerate() {
                    let w = omega * (k + 1) as f64;
                    s -= a * w * w * (w * time).cos();
                }
                for (k, b) in sin.iter().enumerate() {
                    let w = omega * (k + 1) as f64;
                    s -= b * w * w * (w * time).sin();
                }
                s
            }
            Waveform::Table { t, m, .. } => match m {
                None => 0.0,
                Some(m) => {
                    let (k, a, b, _) = table_locate(t, time);
                    a * m[k - 1] + b * m[k]
                }
            },
        }
    }

    /// The times within one period of a linear table (from its first time, before its last)
    /// where its slope changes by at least [`KINK_SHARE`] of the table's largest |slope|, or
    /// its value jumps (at the wrap, where the last value is not the first): the corners an
    /// error-controlled run ends a step on (docs/physics.md §10, "Breakpoints"). A sampled
    /// smooth curve's corners, each ~ its slope's change over one sample spacing, lie below
    /// the share (a half-sine of 201 samples: 5 % of its largest slope at the most, its two
    /// ends 100 %). None for a constant, a Fourier series or a cubic spline (C²).
    pub fn kinks(&self) -> Vec<f64> {
        let Waveform::Table { t, v, m: None, .. } = self else {
            return Vec::new();
        };
        let n = t.len();
        let slope = |k: usize| (v[k] - v[k - 1]) / (t[k] - t[k - 1]);
        let largest = (1..n).map(|k| slope(k).abs()).fold(0.0f64, f64::max);
        let range = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let share = KINK_SHARE * largest;
        let mut kinks = Vec::new();
        // the wrap: the last segment goes on into the first (or the value jumps there)
        let jump = (v[n - 1] - v[0]).abs() > 1e-12 * range;
        if jump || (slope(1) - slope(n - 1)).abs() > share {
            kinks.push(t[0]);
        }
        let inner = (1..n - 1).filter(|&k| (slope(k + 1) - slope(k)).abs() > share);
        kinks.extend(inner.map(|k| t[k]));
        kinks
    }

    pub fn eval(&self, time: f64) -> f64 {
        match self {
            Waveform::Constant(v) => *v,
            Waveform::Fourier {
                omega,
                mean,
                cos,
                sin,
            } => {
                let mut s = *mean;
                for (k, a) in cos.iter().enumerate() {
                    s += a * (omega * (k + 1) as f64 * time).cos();
                }
                for (k, b) in sin.iter().enumerate() {
                    s += b * (omega * (k + 1) as f64 * time).sin();
                }
                s
            }
            Waveform::Table { t, v, m, .. } => {
                let (k, a, b, h) = table_locate(t, time);
                match m {
                    None => a * v[k - 1] + b * v[k],
                    Some(m) => {
                        a * v[k - 1]
                            + b * v[k]
                            + ((a * a * a - a) * m[k - 1] + (b * b * b - b) * m[k]) * h * h / 6.0
                    }
                }
            }
        }
    }
}

/// Segment k (t[k-1] ≤ τ ≤ t[k]) of the periodic table holding `time`, the interpolation
/// weights a = (t[k] − τ)/h, b = (τ − t[k-1])/h, and h.
pub(crate) fn table_locate(t: &[f64], time: f64) -> (usize, f64, f64, f64) {
    let n = t.len();
    let period = t[n - 1] - t[0];
    let mut rt = (time - t[0]).rem_euclid(period) + t[0];
    if rt < t[0] {
        rt = t[0];
    }
    // first index with t[k] >= rt
    let k = t.partition_point(|&x| x < rt).clamp(1, n - 1);
    let h = t[k] - t[k - 1];
    (k, (t[k] - rt) / h, (rt - t[k - 1]) / h, h)
}

/// Why a time table cannot be read as svZeroDSolver reads it ([`fmod_table`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FmodTableFault {
    /// t[i] ≤ t[i − 1].
    NotIncreasing(usize),
    /// The table starts before 0 (svZeroDSolver's lookup is not defined there).
    StartsBeforeZero,
}

/// svZeroDSolver's value of the table (`t`, `v`) at `r` in [0, P]: linear between the
/// samples around `r` (the first with t ≥ r and the one before), the first segment extended
/// below t₀ and the last above the end.
fn fmod_lookup(t: &[f64], v: &[f64], r: f64) -> f64 {
    let k = t.iter().position(|&x| x >= r).unwrap_or(t.len() - 1);
    let m = if k > 0 { k - 1 } else { 1 };
    v[m] + (v[k] - v[m]) / (t[k] - t[m]) * (r - t[m])
}

/// The table over [0, P] that this module's periodic linear table evaluates as svZeroDSolver
/// evaluates (`t`, `v`) — its value at `fmod(time, P)` with P = t_last − t₀ — at every
/// time: the samples within [0, P) and both ends, each at svZeroDSolver's value. A table
/// starting at 0 is already that table (returned as it is).
pub fn fmod_table(
    t: &[f64],
    v: &[f64],
) -> std::result::Result<(Vec<f64>, Vec<f64>), FmodTableFault> {
    if t.len() < 2 || v.len() != t.len() {
        return Ok((t.to_vec(), v.to_vec())); // nothing to look up: the caller checks lengths
    }
    if let Some(i) = (1..t.len()).find(|&i| t[i] <= t[i - 1]) {
        return Err(FmodTableFault::NotIncreasing(i));
    }
    if t[0] == 0.0 {
        return Ok((t.to_vec(), v.to_vec()));
    }
    if t[0] < 0.0 {
        return Err(FmodTableFault::StartsBeforeZero);
    }
    let period = t[t.len() - 1] - t[0];
    let mut times = vec![0.0];
    times.extend(t.iter().copied().filter(|&x| x < period));
    times.push(period);
    let values = times.iter().map(|&r| fmod_lookup(t, v, r)).collect();
    Ok((times, values))
}

fn table_mean(t: &[f64], v: &[f64], m: Option<&[f64]>) -> f64 {
    let n = t.len();
    let mut s = 0.0;
    for k in 1..n {
        let h = t[k] - t[k - 1];
        s += 0.5 * h * (v[k] + v[k - 1]);
        if let Some(m) = m {
            s -= h * h * h * (m[k] + m[k - 1]) / 24.0;
        }
    }
    s / (t[n - 1] - t[0])
}

/// Second derivatives of the periodic cubic spline (cyclic tridiagonal system, dense solve:
/// tables are short).
fn periodic_spline_moments(t: &[f64], v: &[f64]) -> Vec<f64> {
    let n = t.len() - 1; // unknowns m_0..m_{n-1}, m_n = m_0
    if n < 3 {
        return vec![0.0; t.len()];
    }
    let h = |i: usize| t[i + 1] - t[i];
    let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
    let mut rhs = nalgebra::DVector::<f64>::zeros(n);
    for i in 0..n {
        let (hp, hn) = (if i == 0 { h(n - 1) } else { h(i - 1) }, h(i));
        let vp = if i == 0 { v[n - 1] } else { v[i - 1] };
        let im = (i + n - 1) % n;
        let ip = (i + 1) % n;
        a[(i, im)] += hp / 6.0;
        a[(i, i)] += (hp + hn) / 3.0;
        a[(i, ip)] += hn / 6.0;
        rhs[i] = (v[i + 1] - v[i]) / hn - (v[i] - vp) / hp;
    }
    let sol = a
        .lu()
        .solve(&rhs)
        .unwrap_or_else(|| nalgebra::DVector::zeros(n));
    let mut m: Vec<f64> = sol.iter().copied().collect();
    m.push(m[0]);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The waveform of a table without a steady value, for element `el`.
    fn table(
        time: Vec<f64>,
        value: Vec<f64>,
        interpolation: Interpolation,
        el: &str,
    ) -> Result<Waveform> {
        let spec = WaveformSpec::Table {
            time,
            value,
            interpolation,
            steady: None,
        };
        Waveform::from_spec(&spec, el)
    }

    #[test]
    fn an_svzerod_table_resampled_from_zero_evaluates_as_svzerod_does() {
        // svZeroDSolver: value at fmod(τ, P), P = t_last − t₀, linear, first segment extended
        // below t₀. A table on [0.25, 1.25] (P = 1) rising with slope 2 to a kink at 0.75.
        let t = [0.25, 0.75, 1.25];
        let v = [3.5, 4.5, 3.5];
        let (tt, vv) = fmod_table(&t, &v).unwrap();
        assert_eq!(tt, vec![0.0, 0.25, 0.75, 1.0]);
        // the lookup by hand: below t₀ the first segment (slope 2), above 0.75 the second (−2)
        let svzerod = |r: f64| {
            if r <= 0.75 {
                3.5 + 2.0 * (r - 0.25)
            } else {
                4.5 - 2.0 * (r - 0.75)
            }
        };
        let w = Waveform::from_spec(
            &WaveformSpec::Table {
                time: tt,
                value: vv,
                interpolation: Interpolation::Linear,
                steady: None,
            },
            "x",
        )
        .unwrap();
        for i in 0..=40 {
            let time = 0.025 * f64::from(i) + 3.0; // three periods on
            let r = time % 1.0;
            assert!((w.eval(time) - svzerod(r)).abs() < 1e-12, "{time}");
        }
        // a table from 0 is svZeroDSolver's as it is; the faults name the row
        assert_eq!(
            fmod_table(&[0.0, 1.0], &[1.0, 2.0]),
            Ok((vec![0.0, 1.0], vec![1.0, 2.0]))
        );
        assert_eq!(
            fmod_table(&[0.0, 0.5, 0.5], &[1.0, 2.0, 3.0]),
            Err(FmodTableFault::NotIncreasing(2))
        );
        assert_eq!(
            fmod_table(&[-0.1, 0.5], &[1.0, 2.0]),
            Err(FmodTableFault::StartsBeforeZero)
        );
    }

    #[test]
    fn slope_matches_central_differences_of_every_kind() {
        let specs = [
            r#"{"kind": "fourier", "period": 0.8, "mean": 1.0, "cos": [0.3, -0.1], "sin": [0.5]}"#,
            r#"{"kind": "table", "time": [0, 0.3, 0.5, 1.0], "value": [1, 4, 2, 1]}"#,
            r#"{"kind": "table", "time": [0, 0.2, 0.45, 0.7, 1.0], "value": [1, 3, 2, 5, 1],
                "interpolation": "periodic-cubic"}"#,
        ];
        for spec in specs {
            let w = Waveform::from_spec(&serde_json::from_str(spec).unwrap(), "w").unwrap();
            for &t in &[0.05, 0.37, 0.61, 0.93, 1.41] {
                let h = 1e-6;
                let fd = (w.eval(t + h) - w.eval(t - h)) / (2.0 * h);
                assert!(
                    (w.slope(t) - fd).abs() < 1e-6 * (1.0 + fd.abs()),
                    "{spec} t={t}"
                );
                let fd2 = (w.slope(t + h) - w.slope(t - h)) / (2.0 * h);
                assert!(
                    (w.curvature(t) - fd2).abs() < 1e-5 * (1.0 + fd2.abs()),
                    "{spec} t={t}: curvature {} vs {fd2}",
                    w.curvature(t)
                );
            }
        }
        assert_eq!(Waveform::constant(2.0).slope(0.3), 0.0);
    }

    #[test]
    fn a_tables_corners_are_its_sharp_slope_changes_only() {
        // a half-sine systole over 0.3 s and a zero diastole, 201 samples: the corners are the
        // systole's start (the wrap) and end, not the sampled sine's own small bends
        let time: Vec<f64> = (0..=200).map(|i| f64::from(i) / 200.0).collect();
        let value: Vec<f64> = time
            .iter()
            .map(|&t| {
                if t < 0.3 {
                    (std::f64::consts::PI * t / 0.3).sin()
                } else {
                    0.0
                }
            })
            .collect();
        let w = table(time.clone(), value, Interpolation::Linear, "in").unwrap();
        let kinks = w.kinks();
        assert_eq!(kinks.len(), 2, "{kinks:?}");
        assert_eq!(kinks[0], 0.0);
        assert!((kinks[1] - 0.3).abs() < 1e-12, "{kinks:?}");
        // a coarse table is all corners; a value that jumps at the wrap is one there
        let w = table(
            vec![0.0, 0.3, 0.55, 1.0],
            vec![1.0, 4.0, 1.5, 1.0],
            Interpolation::Linear,
            "in",
        );
        assert_eq!(w.unwrap().kinks(), vec![0.0, 0.3, 0.55]);
        let w = table(
            vec![0.0, 0.5, 1.0],
            vec![0.0, 1.0, 2.0],
            Interpolation::Linear,
            "in",
        );
        assert_eq!(w.unwrap().kinks(), vec![0.0]);
        // a cubic spline (C²), a Fourier series and a constant have none
        let mut v: Vec<f64> = time.iter().map(|&t| (6.0 * t).sin() + 2.0).collect();
        v[200] = v[0];
        let w = table(time, v, Interpolation::PeriodicCubic, "in").unwrap();
        assert!(w.kinks().is_empty());
        assert!(Waveform::constant(1.0).kinks().is_empty());
    }

    #[test]
    fn linear_table_is_periodic_and_mean_is_exact() {
        let w = table(
            vec![0.0, 0.5, 1.0],
            vec![0.0, 2.0, 0.0],
            Interpolation::Linear,
            "inlet",
        )
        .unwrap();
        assert_eq!(w.eval(0.25), 1.0);
        assert_eq!(w.eval(1.25), 1.0);
        assert!((w.mean() - 1.0).abs() < 1e-15);
    }

    #[test]
    fn cubic_spline_reproduces_a_sine_and_its_mean() {
        let n = 64;
        let time: Vec<f64> = (0..=n).map(|i| i as f64 / n as f64).collect();
        let value: Vec<f64> = time
            .iter()
            .map(|t| 3.0 + (2.0 * std::f64::consts::PI * t).sin())
            .collect();
        let w = table(time, value, Interpolation::PeriodicCubic, "inlet").unwrap();
        for t in [0.013, 0.37, 0.81, 1.5] {
            let exact = 3.0 + (2.0 * std::f64::consts::PI * t).sin();
            assert!((w.eval(t) - exact).abs() < 1e-6, "{t}");
        }
        assert!((w.mean() - 3.0).abs() < 1e-12);
    }

    #[test]
    fn non_increasing_time_is_rejected_with_context() {
        let e = table(
            vec![0.0, 0.5, 0.5],
            vec![1.0, 2.0, 3.0],
            Interpolation::Linear,
            "boundary condition 'inlet'",
        )
        .unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("inlet") && msg.contains("t[2] = 0.5"), "{msg}");
    }
}
