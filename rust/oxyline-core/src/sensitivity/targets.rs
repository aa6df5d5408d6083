//! Calibration targets: an output of the periodic cycle by name, its value and its
//! derivatives by the parameters from the signals' tangents.
//!
//! An output reads one or more signals over the cycle (the signals and their derivatives of
//! [`super::sensitivities`] or [`super::species_sensitivities`]) and reduces them: a
//! statistic (`min`, `max`, `mean`, `pulse` = max − min) or a `series` of one signal, a flow
//! split (mean flow into a vessel over that into its parent), a cycle-mean total (cardiac
//! output, VO2), a flow-weighted outflow saturation (SvO2 = Σ Q S / Σ Q) or a pulse-wave
//! velocity (path length over the foot-to-foot transit time), a pulse-pressure
//! amplification (the pulse at a peripheral site over that at a central one) or an
//! augmentation index ((P_sys − P_i)/PP, P_i at the inflection of the systolic upstroke, or
//! (P_i − P_sys)/PP with P_i at the shoulder after the peak of a type C wave). A
//! mean's derivative is the
//! mean of the derivatives; a maximum's the derivative at the step of the maximum (the
//! derivative of the discrete maximum, exact wherever the maximum is unique); a foot's is
//! that of the foot's smooth formula in the samples it used (the steepest upstroke and the
//! diastolic minimum), which stay the same samples under a small change; an inflection's
//! likewise through the samples of the second differences whose sign change it
//! interpolates.

use crate::error::{Error, Result};
use crate::model::NetworkSpec;
use std::collections::HashMap;

/// What an output computes from its signals over the cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reduction {
    Min,
    Max,
    Mean,
    /// max − min
    Pulse,
    /// the signal at given times, linearly interpolated in the periodic cycle
    Series,
    /// mean flow into a vessel (signal 0) over that into its parent (signal 1)
    FlowSplit,
    /// the cycle mean of the signals' sum (cardiac output, VO2)
    MeanTotal,
    /// outflow saturation (signal 0) weighted by outflow (signal 1): Σ Q S / Σ Q
    FlowWeighted,
    /// path length over the foot-to-foot transit time of the proximal (signal 0) and distal
    /// (signal 1) pressures
    PulseWaveVelocity,
    /// pulse (max − min) of the peripheral (signal 1) over that of the central (signal 0)
    /// pressure
    Amplification,
    /// (P_sys − P_i)/(P_sys − P_dia) of signal 0, P_i the pressure at the inflection of the
    /// systolic upstroke, or (P_i − P_sys)/(P_sys − P_dia) with P_i at the shoulder after
    /// the peak of a type C wave ([`inflection`])
    AugmentationIndex,
}

impl Reduction {
    /// The reduction an output's name asks for: `pwv.<proximal>.<distal>`,
    /// `amplification.<central>.<peripheral>`, `augmentation_index.<vessel>`,
    /// `flow_split.<vessel>.<parent>`, `cardiac_output`, `VO2[.<vessel>...]`,
    /// `SvO2.<vessel>` or `<signal>.<statistic>`.
    pub fn of(output: &str) -> Result<Reduction> {
        let first = output.split('.').next().unwrap_or("");
        Ok(match first {
            "pwv" => Reduction::PulseWaveVelocity,
            "amplification" => Reduction::Amplification,
            "augmentation_index" => Reduction::AugmentationIndex,
            _ if output == "cardiac_output" || first == "VO2" => Reduction::MeanTotal,
            "SvO2" => Reduction::FlowWeighted,
            "flow_split" => Reduction::FlowSplit,
            _ => match output.rsplit('.').next().unwrap_or("") {
                "min" => Reduction::Min,
                "max" => Reduction::Max,
                "mean" => Reduction::Mean,
                "pulse" => Reduction::Pulse,
                "series" => Reduction::Series,
                stat => {
                    return Err(Error::model(
                        format!("output '{output}'"),
                        format!(
                            "unknown statistic {stat:?} (one of min, max, mean, pulse, series)"
                        ),
                    ));
                }
            },
        })
    }

    /// How many signals the reduction reads (None: one or more).
    fn signals(self) -> Option<usize> {
        match self {
            Reduction::FlowSplit
            | Reduction::FlowWeighted
            | Reduction::PulseWaveVelocity
            | Reduction::Amplification => Some(2),
            Reduction::MeanTotal => None,
            _ => Some(1),
        }
    }
}

/// One periodic cycle's signals and their derivatives, row-major as the tangent runs give
/// them.
#[derive(Debug, Clone, Copy)]
pub struct CycleSignals<'a> {
    /// the step end times Δt … T (s)
    pub times: &'a [f64],
    /// n_steps × n_signals
    pub values: &'a [f64],
    /// n_params × n_steps × n_signals
    pub derivs: &'a [f64],
    pub n_signals: usize,
}

impl CycleSignals<'_> {
    fn n_steps(&self) -> usize {
        self.times.len()
    }

    fn n_params(&self) -> usize {
        self.derivs.len() / (self.n_steps() * self.n_signals).max(1)
    }

    /// Signal `j` over the cycle.
    fn signal(&self, j: usize) -> Vec<f64> {
        self.values
            .iter()
            .skip(j)
            .step_by(self.n_signals)
            .copied()
            .collect()
    }

    /// d signal `j` / d parameter `p` over the cycle.
    fn deriv(&self, p: usize, j: usize) -> Vec<f64> {
        let ns = self.n_steps();
        let row = &self.derivs[p * ns * self.n_signals..(p + 1) * ns * self.n_signals];
        row.iter()
            .skip(j)
            .step_by(self.n_signals)
            .copied()
            .collect()
    }

    /// The derivatives of signal `j` by every parameter, reduced step-wise by `f`.
    fn deriv_rows(&self, j: usize, f: impl Fn(&[f64]) -> f64) -> Vec<f64> {
        (0..self.n_params()).map(|p| f(&self.deriv(p, j))).collect()
    }

    fn check(&self, output: &str, reduction: Reduction) -> Result<()> {
        let fail = |why: String| Err(Error::model(format!("output '{output}'"), why));
        let (ns, nsig) = (self.n_steps(), self.n_signals);
        if ns == 0 {
            return fail("no steps over the cycle".into());
        }
        if nsig == 0 || reduction.signals().is_some_and(|n| n != nsig) {
            let reads = reduction
                .signals()
                .map_or("one or more".into(), |n| n.to_string());
            return fail(format!("{nsig} signals given, it reads {reads}"));
        }
        if self.values.len() != ns * nsig || self.derivs.len() % (ns * nsig) != 0 {
            return fail(format!(
                "{} signal values and {} derivatives for {ns} steps of {nsig} signals",
                self.values.len(),
                self.derivs.len()
            ));
        }
        Ok(())
    }
}

/// An output's value(s) (one, or one per datum of a series) and its Jacobian (n_values ×
/// n_params, row-major).
#[derive(Debug, Clone, PartialEq)]
pub struct TargetValue {
    pub values: Vec<f64>,
    pub jacobian: Vec<f64>,
}

impl TargetValue {
    fn one(value: f64, row: Vec<f64>) -> TargetValue {
        TargetValue {
            values: vec![value],
            jacobian: row,
        }
    }
}

/// A pulse-wave velocity's path length (m) and its derivative by each parameter.
#[derive(Debug, Clone, Copy)]
pub struct PathLength<'a> {
    pub length: f64,
    pub dlength: &'a [f64],
}

/// The value and derivatives of `output` (its name, [`Reduction::of`]) from its signals
/// over the cycle; `at`, a series' times (s from the cycle's start); `path`, a pulse-wave
/// velocity's path length.
pub fn evaluate(
    output: &str,
    cycle: &CycleSignals,
    at: Option<&[f64]>,
    path: Option<PathLength>,
) -> Result<TargetValue> {
    let reduction = Reduction::of(output)?;
    cycle.check(output, reduction)?;
    let fail = |why: &str| Error::model(format!("output '{output}'"), why);
    Ok(match reduction {
        Reduction::PulseWaveVelocity => {
            let path = path.ok_or_else(|| fail("a pulse-wave velocity needs its path length"))?;
            if path.dlength.len() != cycle.n_params() {
                return Err(fail("one path length derivative per parameter needed"));
            }
            pulse_wave_velocity(cycle, path)?
        }
        Reduction::Amplification => amplification(cycle).map_err(|why| fail(&why))?,
        Reduction::AugmentationIndex => augmentation_index(cycle).map_err(|why| fail(&why))?,
        Reduction::MeanTotal => mean_total(cycle),
        Reduction::FlowWeighted => flow_weighted(cycle),
        Reduction::FlowSplit => flow_split(cycle),
        Reduction::Series => {
            let at = at.ok_or_else(|| fail("a series needs the times to read it at"))?;
            series(cycle, at)
        }
        stat => statistic(cycle, stat),
    })
}

fn mean(x: &[f64]) -> f64 {
    x.iter().sum::<f64>() / x.len() as f64
}

/// The first index of the largest (`sign` 1) or smallest (`sign` −1) sample.
fn extreme(x: &[f64], sign: f64) -> usize {
    let mut best = 0;
    for (k, &v) in x.iter().enumerate() {
        if sign * v > sign * x[best] {
            best = k;
        }
    }
    best
}

/// min, max, mean or pulse of signal 0.
fn statistic(cycle: &CycleSignals, stat: Reduction) -> TargetValue {
    let x = cycle.signal(0);
    if stat == Reduction::Mean {
        return TargetValue::one(mean(&x), cycle.deriv_rows(0, mean));
    }
    let (hi, lo) = (extreme(&x, 1.0), extreme(&x, -1.0));
    match stat {
        Reduction::Max => TargetValue::one(x[hi], cycle.deriv_rows(0, |d| d[hi])),
        Reduction::Min => TargetValue::one(x[lo], cycle.deriv_rows(0, |d| d[lo])),
        _ => TargetValue::one(x[hi] - x[lo], cycle.deriv_rows(0, |d| d[hi] - d[lo])),
    }
}

/// The pulse (max − min) of signal `j` and its derivative by each parameter.
fn pulse_of(cycle: &CycleSignals, j: usize) -> (f64, Vec<f64>) {
    let x = cycle.signal(j);
    let (hi, lo) = (extreme(&x, 1.0), extreme(&x, -1.0));
    (x[hi] - x[lo], cycle.deriv_rows(j, |d| d[hi] - d[lo]))
}

/// The pulse of the peripheral pressure (signal 1) over that of the central one (signal 0);
/// the reason if the central pressure has no pulse.
fn amplification(cycle: &CycleSignals) -> std::result::Result<TargetValue, String> {
    let (central, dcentral) = pulse_of(cycle, 0);
    let (peripheral, dperipheral) = pulse_of(cycle, 1);
    if !central.is_finite() || central <= 0.0 {
        return Err(format!(
            "the central pulse pressure is {central} Pa (a flat pressure has no amplification)"
        ));
    }
    let value = peripheral / central;
    let rows = dcentral
        .iter()
        .zip(&dperipheral)
        .map(|(dc, dp)| (dp - value * dc) / central)
        .collect();
    Ok(TargetValue::one(value, rows))
}

/// The inflection of a periodic wave's systolic upstroke (a type A or B wave) or its shoulder
/// after the peak (type C), between samples `step` and `step + 1` (indices modulo the
/// cycle's length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inflection {
    /// the sample before the inflection
    pub step: usize,
    /// where between `step` (0) and `step + 1` (1) the second difference changes sign
    pub fraction: f64,
    /// the systolic peak's sample
    pub peak: usize,
    /// the diastolic minimum's sample
    pub minimum: usize,
    /// a type C wave: the inflection is the shoulder after the peak (the reflection arrives
    /// after it), the augmentation index negative
    pub after_peak: bool,
}

/// The second difference x[i+1] − 2 x[i] + x[i−1] of the periodic samples `x` at `i` (any
/// index, taken modulo the length).
fn curvature(x: &[f64], i: usize) -> f64 {
    let n = x.len();
    x[(i + 1) % n] - 2.0 * x[i % n] + x[(i + n - 1) % n]
}

/// The first step j in `from..to` (unwrapped indices) where the second difference of `x`
/// changes sign from `sign` (strictly) to the opposite or zero, and where between j and
/// j + 1 the linear interpolation puts its zero.
fn sign_change(x: &[f64], from: usize, to: usize, sign: f64) -> Option<(usize, f64)> {
    (from..to).find_map(|j| {
        let (c0, c1) = (curvature(x, j), curvature(x, j + 1));
        (sign * c0 > 0.0 && sign * c1 <= 0.0).then(|| (j % x.len(), c0 / (c0 - c1)))
    })
}

/// The inflection point of one cycle of periodic uniform samples `x` that an augmentation
/// index reads. A type A or B wave (its reflection arrives before the peak): the shoulder of
/// its systolic upstroke, the first local minimum of the slope after the diastolic minimum
/// (the lowest sample), where the second difference changes sign from negative to
/// non-negative, before the systolic peak (the highest sample). Failing that, a type C wave
/// (the reflection arrives after the peak): the shoulder on its fall, the first local
/// maximum of the slope after the peak, where the second difference changes sign from
/// positive to non-positive, while the pressure is above its diastolic minimum by a quarter
/// of the pulse. The zero crossing is
/// interpolated linearly between its two samples (the pressure's own curvature is zero
/// there, so a chord reads the pressure to second order). None if the slope has neither
/// (a sinusoid: its slope falls from the steepest rise straight to the steepest fall).
pub fn inflection(x: &[f64]) -> Option<Inflection> {
    let n = x.len();
    if n < 4 {
        return None;
    }
    let (peak, minimum) = (extreme(x, 1.0), extreme(x, -1.0));
    // the peak's index unwrapped to follow the minimum, and the minimum's to follow the peak
    let top = if peak > minimum { peak } else { peak + n };
    // a type C shoulder is looked for while the pressure stays above a quarter of the pulse
    // (AIx > −3/4; in vivo it is −0.3 … 0): below, the diastolic decay's ripples and a
    // valve's notch are not a reflection's shoulder
    let floor = x[minimum] + 0.25 * (x[peak] - x[minimum]);
    let fall = (peak + 1..peak + n)
        .find(|&k| x[k % n] <= floor)
        .unwrap_or(peak + n);
    let found = |(step, fraction), after_peak| Inflection {
        step,
        fraction,
        peak,
        minimum,
        after_peak,
    };
    if let Some(at) = sign_change(x, minimum + 1, top.saturating_sub(1), -1.0) {
        return Some(found(at, false));
    }
    sign_change(x, peak + 1, fall.saturating_sub(1), 1.0).map(|at| found(at, true))
}

/// The augmentation index of signal 0 and its derivatives through the samples of the peak,
/// the minimum and the inflection's crossing; the reason if there is no pulse or no
/// inflection. P_i the pressure at the inflection ([`inflection`]): (P_sys − P_i)/(P_sys −
/// P_dia) ≥ 0 for a shoulder before the peak (type A or B), (P_i − P_sys)/(P_sys − P_dia) < 0
/// for one after it (type C: the late shoulder is the augmentation, below the peak).
fn augmentation_index(cycle: &CycleSignals) -> std::result::Result<TargetValue, String> {
    let x = cycle.signal(0);
    let n = x.len();
    let pulse = x[extreme(&x, 1.0)] - x[extreme(&x, -1.0)];
    if !pulse.is_finite() || pulse <= 0.0 {
        return Err(format!(
            "the pulse pressure is {pulse} Pa (a flat pressure has no augmentation index)"
        ));
    }
    let Some(at) = inflection(&x) else {
        return Err(
            "no inflection on the systolic upstroke nor after the peak (the slope has no \
             local minimum between the diastolic minimum and the systolic peak and no local \
             maximum after the peak while the pressure is above a quarter of the pulse)"
                .into(),
        );
    };
    let (j, w, hi, lo) = (at.step, at.fraction, at.peak, at.minimum);
    let sign = if at.after_peak { -1.0 } else { 1.0 };
    let (c0, c1) = (curvature(&x, j), curvature(&x, j + 1));
    let (p0, p1) = (x[j], x[(j + 1) % n]);
    let shoulder = p0 + w * (p1 - p0);
    let value = sign * (x[hi] - shoulder) / pulse;
    let rows = (0..cycle.n_params())
        .map(|p| {
            let d = cycle.deriv(p, 0);
            let (dc0, dc1) = (curvature(&d, j), curvature(&d, j + 1));
            let dw = (c0 * dc1 - c1 * dc0) / ((c0 - c1) * (c0 - c1));
            let dshoulder = d[j] + w * (d[(j + 1) % n] - d[j]) + dw * (p1 - p0);
            (sign * (d[hi] - dshoulder) - value * (d[hi] - d[lo])) / pulse
        })
        .collect();
    Ok(TargetValue::one(value, rows))
}

/// The cycle mean of the signals' sum (per step, then over the cycle).
fn mean_total(cycle: &CycleSignals) -> TargetValue {
    let nsig = cycle.n_signals;
    let total = |v: &[f64]| mean(&v.chunks(nsig).map(|s| s.iter().sum()).collect::<Vec<f64>>());
    let ns = cycle.n_steps();
    let rows = cycle.derivs.chunks(ns * nsig).map(total).collect();
    TargetValue::one(total(cycle.values), rows)
}

/// Σ Q S / Σ Q of the saturation (signal 0) and the flow (signal 1).
fn flow_weighted(cycle: &CycleSignals) -> TargetValue {
    let (sat, q) = (cycle.signal(0), cycle.signal(1));
    let total: f64 = q.iter().sum();
    let value = q.iter().zip(&sat).map(|(q, s)| q * s).sum::<f64>() / total;
    let rows = (0..cycle.n_params())
        .map(|p| {
            let (dsat, dq) = (cycle.deriv(p, 0), cycle.deriv(p, 1));
            let weighted: f64 = (0..q.len()).map(|k| dsat[k] * q[k] + dq[k] * sat[k]).sum();
            (weighted - value * dq.iter().sum::<f64>()) / total
        })
        .collect();
    TargetValue::one(value, rows)
}

/// Mean of signal 0 over mean of signal 1.
fn flow_split(cycle: &CycleSignals) -> TargetValue {
    let (q, p) = (mean(&cycle.signal(0)), mean(&cycle.signal(1)));
    let rows = (0..cycle.n_params())
        .map(|k| {
            let (dq, dp) = (mean(&cycle.deriv(k, 0)), mean(&cycle.deriv(k, 1)));
            (dq * p - q * dp) / (p * p)
        })
        .collect();
    TargetValue::one(q / p, rows)
}

/// The cycle closed at its start: times 0, Δt … T and the signal at T also at 0.
fn closed(times: &[f64], x: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let t = std::iter::once(0.0).chain(times.iter().copied()).collect();
    let v = std::iter::once(x[x.len() - 1])
        .chain(x.iter().copied())
        .collect();
    (t, v)
}

/// Signal 0 at the times `at` (taken modulo the period), linearly interpolated, and its
/// derivatives likewise.
fn series(cycle: &CycleSignals, at: &[f64]) -> TargetValue {
    let period = cycle.times[cycle.n_steps() - 1];
    let at: Vec<f64> = at.iter().map(|t| t.rem_euclid(period)).collect();
    let (tt, xx) = closed(cycle.times, &cycle.signal(0));
    let values = at.iter().map(|&t| interpolate(t, &tt, &xx)).collect();
    let np = cycle.n_params();
    let mut jacobian = vec![0.0; at.len() * np];
    for p in 0..np {
        let (_, dd) = closed(cycle.times, &cycle.deriv(p, 0));
        for (i, &t) in at.iter().enumerate() {
            jacobian[i * np + p] = interpolate(t, &tt, &dd);
        }
    }
    TargetValue { values, jacobian }
}

/// Piecewise-linear interpolation of (`xp`, `fp`) at `x` (`xp` increasing), the end values
/// outside; a sample's own value at a sample.
pub fn interpolate(x: f64, xp: &[f64], fp: &[f64]) -> f64 {
    let last = xp.len() - 1;
    if x >= xp[last] {
        return fp[last];
    }
    if x <= xp[0] {
        return fp[0];
    }
    // the interval [xp[j], xp[j + 1]) holding x
    let j = xp.partition_point(|&t| t <= x) - 1;
    if xp[j] == x {
        return fp[j];
    }
    let slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j]);
    let y = slope * (x - xp[j]) + fp[j];
    // (an infinite sample: from the other end)
    if y.is_nan() {
        slope * (x - xp[j + 1]) + fp[j + 1]
    } else {
        y
    }
}

/// The foot of a periodic wave and the samples it was drawn from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Foot {
    /// the foot time (s), in [t₀, t₀ + T)
    pub time: f64,
    /// the upstroke: the tangent runs through samples `upstroke` and `upstroke + 1`
    pub upstroke: usize,
    /// the diastolic minimum's sample
    pub minimum: usize,
}

/// The foot of a periodic wave by the intersecting-tangent method: the intersection of the
/// tangent at the steepest upstroke (the largest forward difference, taken at the midpoint
/// of its two samples) with the horizontal through the diastolic minimum (the lowest sample
/// in the half period before the upstroke). `time`/`pressure`: one cycle of uniform samples
/// with both ends (t₀ and t₀ + T); the last sample only closes the last difference (no
/// artificial jump at the wrap when the cycle is not yet periodic).
pub fn foot_time(time: &[f64], pressure: &[f64]) -> Result<Foot> {
    let n = time.len().saturating_sub(1);
    if n < 2 || pressure.len() != time.len() {
        return Err(Error::model(
            "foot time",
            format!(
                "{} times and {} pressures (one cycle with both ends, at least 3 samples)",
                time.len(),
                pressure.len()
            ),
        ));
    }
    let dt = time[1] - time[0];
    let period = n as f64 * dt;
    let slope: Vec<f64> = pressure.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
    let k = extreme(&slope, 1.0);
    let mut m = k;
    for back in 1..n / 2 {
        let s = (k + n - back) % n;
        if pressure[s] < pressure[m] {
            m = s;
        }
    }
    let t_mid = time[k] + dt / 2.0;
    let p_mid = (pressure[k] + pressure[k + 1]) / 2.0;
    let foot = (t_mid - (p_mid - pressure[m]) / slope[k] - time[0]).rem_euclid(period) + time[0];
    Ok(Foot {
        time: foot,
        upstroke: k,
        minimum: m,
    })
}

/// Foot-to-foot transit time (s) from `proximal` to `distal` (one cycle each with both ends,
/// [`foot_time`]), in [0, T).
pub fn transit_time(time: &[f64], proximal: &[f64], distal: &[f64]) -> Result<f64> {
    let (distal, proximal) = (foot_time(time, distal)?, foot_time(time, proximal)?);
    let period = time[time.len() - 1] - time[0];
    Ok((distal.time - proximal.time).rem_euclid(period))
}

/// The foot of signal `j` over the closed cycle and its derivative by each parameter: the
/// foot t_mid − (p_mid − p_min)/slope is a smooth function of the samples of the upstroke
/// and the minimum.
fn foot_of(cycle: &CycleSignals, j: usize) -> Result<(f64, Vec<f64>)> {
    let (t_all, p_all) = closed(cycle.times, &cycle.signal(j));
    let foot = foot_time(&t_all, &p_all)?;
    let (k, m, dt) = (foot.upstroke, foot.minimum, cycle.times[0]);
    let slope = (p_all[k + 1] - p_all[k]) / dt;
    let rise = (p_all[k] + p_all[k + 1]) / 2.0 - p_all[m];
    let rows = (0..cycle.n_params())
        .map(|p| {
            let (_, d) = closed(cycle.times, &cycle.deriv(p, j));
            let dslope = (d[k + 1] - d[k]) / dt;
            let drise = (d[k] + d[k + 1]) / 2.0 - d[m];
            -drise / slope + rise * dslope / (slope * slope)
        })
        .collect();
    Ok((foot.time, rows))
}

/// Path length over the foot-to-foot transit time of the proximal (signal 0) and distal
/// (signal 1) pressures.
fn pulse_wave_velocity(cycle: &CycleSignals, path: PathLength) -> Result<TargetValue> {
    let period = cycle.times[cycle.n_steps() - 1];
    let (f0, d0) = foot_of(cycle, 0)?;
    let (f1, d1) = foot_of(cycle, 1)?;
    let transit = (f1 - f0).rem_euclid(period);
    if transit <= 0.0 {
        return Err(Error::model(
            "pulse-wave velocity",
            "both feet fall on the same sample (the path is shorter than one step of the wave)",
        ));
    }
    let length = path.length;
    let rows = (0..d0.len())
        .map(|p| path.dlength[p] / transit - length * (d1[p] - d0[p]) / (transit * transit))
        .collect();
    Ok(TargetValue::one(length / transit, rows))
}

/// The path of `pwv.<proximal>.<distal>`: the vessels from the inlet of `proximal` to the
/// outlet of `distal` with their lengths (m), found walking upstream from `distal` (one
/// vessel into each node on the way); an error naming the output if a vessel is missing,
/// has no length (lumped) or `distal` is not downstream of `proximal` along one path.
pub fn pulse_wave_path(spec: &NetworkSpec, output: &str) -> Result<Vec<(String, f64)>> {
    let fail = |why: String| Error::model(format!("output '{output}'"), why);
    let parts: Vec<&str> = output.split('.').collect();
    let [_, proximal, distal] = parts[..] else {
        return Err(fail(
            "expected pwv.<proximal vessel>.<distal vessel>".into(),
        ));
    };
    let vessels: HashMap<&str, _> = spec.vessels.iter().map(|v| (v.name.as_str(), v)).collect();
    for name in [proximal, distal] {
        if !vessels.contains_key(name) {
            return Err(fail(format!(
                "no vessel named '{name}' in model '{}'",
                spec.name
            )));
        }
    }
    let mut into: HashMap<&str, Vec<&str>> = HashMap::new();
    for v in &spec.vessels {
        into.entry(v.to.as_str()).or_default().push(v.name.as_str());
    }
    let (mut path, mut at) = (Vec::new(), distal);
    loop {
        let Some(geometry) = vessels[at].geometry.as_ref() else {
            return Err(fail(format!(
                "vessel '{at}' on the path has no length (lumped)"
            )));
        };
        path.push((at.to_string(), geometry.length));
        if at == proximal {
            path.reverse();
            return Ok(path);
        }
        match into.get(vessels[at].from.as_str()).map(Vec::as_slice) {
            Some([up]) if path.len() <= spec.vessels.len() => at = up,
            _ => {
                return Err(fail(format!(
                    "vessel '{distal}' is not downstream of '{proximal}' along one path"
                )));
            }
        }
    }
}

#[cfg(test)]
#[path = "targets_tests.rs"]
mod tests;

#[cfg(test)]
#[path = "targets_shape_tests.rs"]
mod shape_tests;
