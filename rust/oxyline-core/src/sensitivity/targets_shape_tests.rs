//! The waveform-shape targets against closed forms: the pulse-pressure amplification of two
//! sinusoids, and the inflection and augmentation index of a two-harmonic pressure (type A:
//! the shoulder on the upstroke) and of that pressure in a warped phase (type C: the shoulder
//! after the peak), with their derivatives by the waves' own parameters.

use super::*;
use std::f64::consts::PI;

/// `steps` uniform step end times T/steps … T of a cycle of `period`.
fn times(steps: usize, period: f64) -> Vec<f64> {
    (1..=steps)
        .map(|k| k as f64 * period / steps as f64)
        .collect()
}

/// Row-major signals (n_steps × signals) and derivatives (parameter × n_steps × signals)
/// of `wave(t) -> (values, derivatives[parameter][signal])` at `t`.
fn sample(t: &[f64], wave: impl Fn(f64) -> (Vec<f64>, Vec<Vec<f64>>)) -> (Vec<f64>, Vec<f64>) {
    let at: Vec<_> = t.iter().map(|&t| wave(t)).collect();
    let values = at.iter().flat_map(|(v, _)| v.clone()).collect();
    let np = at[0].1.len();
    let derivs = (0..np)
        .flat_map(|p| at.iter().flat_map(move |(_, d)| d[p].clone()))
        .collect();
    (values, derivs)
}

fn eval(
    output: &str,
    t: &[f64],
    nsig: usize,
    (values, derivs): &(Vec<f64>, Vec<f64>),
) -> Result<TargetValue> {
    let cycle = CycleSignals {
        times: t,
        values,
        derivs,
        n_signals: nsig,
    };
    evaluate(output, &cycle, None, None)
}

const PERIOD: f64 = 0.8;

#[test]
fn the_amplification_of_two_sinusoids_is_the_ratio_of_their_amplitudes() {
    // central p0 + a sin ωt, peripheral p1 + b sin(ωt − φ); parameters a and b. 400 steps
    // and a lag of 20 steps: every extreme falls on a sample, so PP = 2a and 2b exactly
    let (a, b) = (1.6e3, 2.3e3);
    let w = 2.0 * PI / PERIOD;
    let lag = 2.0 * PI * 20.0 / 400.0;
    let t = times(400, PERIOD);
    let s = sample(&t, |t| {
        let (c, p) = ((w * t).sin(), (w * t - lag).sin());
        (
            vec![1.1e4 + a * c, 1.0e4 + b * p],
            vec![vec![c, 0.0], vec![0.0, p]],
        )
    });
    let out = eval("amplification.aorta.radial", &t, 2, &s).unwrap();
    let tol = 1e-12;
    assert!((out.values[0] - b / a).abs() <= tol, "{:?}", out.values);
    // d(b/a)/da = −b/a², d(b/a)/db = 1/a
    assert!((out.jacobian[0] + b / (a * a)).abs() <= tol / a);
    assert!((out.jacobian[1] - 1.0 / a).abs() <= tol / a);
}

// P = p0 + s (f(θ) + ε cos 2θ), f = −cos θ + β cos 3θ, θ = ωt + θ₀; parameters s and ε (at 0).
// For −1/3 < β < −1/27, f rises monotonically from its minimum at θ = 0 to its peak at π
// (f' = sin θ (1 − 3β(3 − 4 sin²θ)) > 0) and its slope has one local minimum between them,
// at θ = π/2 (f'' = cos θ − 9β cos 3θ = 0, f''' = −1 − 27β > 0), where f = 0: the
// inflection of the upstroke is at π/2 and AIx = (f(π) − 0)/(f(π) − f(0)) = 1/2 for every β.
const BETA: f64 = -0.1;
const P0: f64 = 1.0e4;
const SCALE: f64 = 2.0e3;

/// The two-harmonic pressure over `steps` steps, its samples off the peak, minimum and
/// inflection by θ₀ (0.37 step); `eps` its cos 2θ part.
fn two_harmonic(steps: usize, eps: f64) -> (Vec<f64>, (Vec<f64>, Vec<f64>)) {
    warped_two_harmonic(steps, eps, BETA, 0.0)
}

/// P = p0 + s (f(φ) + ε cos 2φ), f = −cos φ + β cos 3φ, in the warped phase
/// φ = θ + α (1 + sin θ)² (α = 0: the two-harmonic pressure above), θ = ωt + θ₀.
fn warped_two_harmonic(
    steps: usize,
    eps: f64,
    beta: f64,
    alpha: f64,
) -> (Vec<f64>, (Vec<f64>, Vec<f64>)) {
    let w = 2.0 * PI / PERIOD;
    let theta0 = 0.37 * 2.0 * PI / steps as f64;
    let t = times(steps, PERIOD);
    let s = sample(&t, |t| {
        let th = w * t + theta0;
        let phi = th + alpha * (1.0 + th.sin()).powi(2);
        let f = -phi.cos() + beta * (3.0 * phi).cos();
        let e = (2.0 * phi).cos();
        (
            vec![P0 + SCALE * (f + eps * e)],
            vec![vec![f + eps * e], vec![SCALE * e]],
        )
    });
    (t, s)
}

#[test]
fn a_two_harmonic_pressures_inflection_and_augmentation_index_are_the_closed_forms() {
    let steps = 4000;
    let (t, s) = two_harmonic(steps, 0.0);
    // the inflection at θ = π/2: the step whose interval holds it
    let at = inflection(&s.0).unwrap();
    let w = 2.0 * PI / PERIOD;
    let theta0 = 0.37 * 2.0 * PI / steps as f64;
    let dt = PERIOD / steps as f64;
    let theta_i = w * (t[at.step] + at.fraction * dt) + theta0;
    // the sign change of second differences interpolated linearly: O(Δθ²) from π/2
    let dtheta = 2.0 * PI / steps as f64;
    assert!((theta_i - PI / 2.0).abs() <= dtheta * dtheta, "{theta_i}");
    let out = eval("augmentation_index.aorta", &t, 1, &s).unwrap();
    // the samples' peak and minimum are off the extremes by under a step: PP and P_sys low
    // by O(f'' Δθ²) ~ 1e-6 of the pulse, the shoulder's chord by O(f''' Δθ³)
    assert!((out.values[0] - 0.5).abs() <= 1e-5, "{:?}", out.values);
    // d AIx / d s = 0: a scaled wave has the same index (the same samples, in ratio)
    assert!(out.jacobian[0].abs() <= 1e-12, "{:?}", out.jacobian);
    // d AIx / d ε, e = cos 2θ: the peak and minimum move by e(π) and e(0) (envelope), the
    // inflection by dθ = −e''/f''' at π/2, the shoulder by f' dθ + e, all over PP = f(π) − f(0):
    // (e(π) − e(π/2) + f'(π/2) e''(π/2)/f'''(π/2) − AIx (e(π) − e(0))) / PP
    let (fp, fppp) = (1.0 + 3.0 * BETA, -1.0 - 27.0 * BETA);
    let pp = 2.0 * (1.0 - BETA);
    let exact = (1.0 - (-1.0) + fp * 4.0 / fppp - 0.5 * 0.0) / pp;
    // the discrete crossing's derivative converges at O(Δθ): 1e-3 relative at 4000 steps
    let rel = (out.jacobian[1] - exact).abs() / exact;
    assert!(rel <= 1e-3, "{} vs {exact} ({rel})", out.jacobian[1]);
}

#[test]
fn the_augmentation_indexs_derivative_is_that_of_its_samples() {
    // against central differences of the index of the perturbed samples themselves (h
    // 1e-6 of ε: truncation O(h²) and rounding ~1e-16/h of the index ~1e-10, so 1e-7
    // relative tells a wrong derivative); the samples of the crossing stay the same
    let steps = 400;
    let (t, s) = two_harmonic(steps, 0.0);
    let out = eval("augmentation_index.aorta", &t, 1, &s).unwrap();
    let h = 1e-6;
    let at = |eps: f64| {
        let (t, s) = two_harmonic(steps, eps);
        eval("augmentation_index.aorta", &t, 1, &s).unwrap().values[0]
    };
    let fd = (at(h) - at(-h)) / (2.0 * h);
    let rel = (out.jacobian[1] - fd).abs() / fd.abs();
    assert!(rel <= 1e-7, "{} vs {fd} ({rel})", out.jacobian[1]);
}

#[test]
fn a_wave_without_an_inflection_or_a_pulse_is_an_error_naming_the_output() {
    let w = 2.0 * PI / PERIOD;
    let t = times(400, PERIOD);
    // a sinusoid: its slope falls from the steepest rise straight to the peak
    let sine = sample(&t, |t| (vec![1e4 + 2e3 * (w * t).sin()], vec![]));
    let e = eval("augmentation_index.aorta", &t, 1, &sine).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("augmentation_index.aorta") && msg.contains("no inflection"),
        "{msg}"
    );
    let flat = sample(&t, |_| (vec![1e4], vec![]));
    let e = eval("augmentation_index.aorta", &t, 1, &flat).unwrap_err();
    assert!(e.to_string().contains("pulse pressure is 0"), "{e}");
    // a flat central pressure: no amplification
    let two = sample(&t, |t| (vec![1e4, 1e4 + 2e3 * (w * t).sin()], vec![]));
    let e = eval("amplification.aorta.radial", &t, 2, &two).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("amplification.aorta.radial") && msg.contains("central pulse pressure is 0"),
        "{msg}"
    );
    // one signal for two
    let e = eval("amplification.aorta.radial", &t, 1, &sine).unwrap_err();
    assert!(e.to_string().contains("reads 2"), "{e}");
}

// A type C wave: the two-harmonic pressure f(φ) (β = −0.05) in the warped phase
// φ = θ + α (1 + sin θ)², α = 0.2. The warp is monotone (φ' ≥ 1 − 2α·1.3 > 0) and keeps f's
// range, so P_sys = f(π) and P_dia = f(0) are as before; it steepens the upstroke so that its
// slope has no local minimum (f's inflection at φ = π/2 is gone), and at θ = 3π/2 it is the
// identity to fourth order ((1 + sin θ)² ~ (θ − 3π/2)⁴/4): there P'' = f''(3π/2) = 0 and
// P''' = f'''(3π/2) = 1 + 27β < 0, the slope's local maximum after the peak, where f = 0.
// AIx = (f(3π/2) − f(π))/(f(π) − f(0)) = −1/2 for every β and such α.
const BETA_C: f64 = -0.05;
const ALPHA_C: f64 = 0.2;

#[test]
fn a_type_c_waves_shoulder_after_the_peak_and_negative_index_are_the_closed_forms() {
    let steps = 4000;
    let (t, s) = warped_two_harmonic(steps, 0.0, BETA_C, ALPHA_C);
    let at = inflection(&s.0).unwrap();
    assert!(at.after_peak, "{at:?}");
    let w = 2.0 * PI / PERIOD;
    let theta0 = 0.37 * 2.0 * PI / steps as f64;
    let dt = PERIOD / steps as f64;
    let theta_i = w * (t[at.step] + at.fraction * dt) + theta0;
    let dtheta = 2.0 * PI / steps as f64;
    assert!(
        (theta_i - 1.5 * PI).abs() <= dtheta * dtheta,
        "{theta_i} vs {}",
        1.5 * PI
    );
    let out = eval("augmentation_index.aorta", &t, 1, &s).unwrap();
    // as for the type A wave: the samples' extremes and the chord are O(Δθ²) off
    assert!((out.values[0] + 0.5).abs() <= 1e-5, "{:?}", out.values);
    assert!(out.jacobian[0].abs() <= 1e-12, "{:?}", out.jacobian);
    // d AIx / d ε, e = cos 2φ: at θ = 3π/2 (φ' = 1, φ'' = φ''' = 0) the shoulder moves by
    // dθ = −e''/f''' and P_i by f' dθ + e; P_sys and P_dia by e(π) = e(0) = 1 (envelope):
    // (e(3π/2) − f'(3π/2) e''(3π/2)/f'''(3π/2) − e(π)) / PP
    let b = BETA_C;
    let (fp, fppp) = (-1.0 - 3.0 * b, 1.0 + 27.0 * b);
    let pp = 2.0 * (1.0 - b);
    let exact = (-1.0 - fp * 4.0 / fppp - 1.0) / pp;
    let rel = (out.jacobian[1] - exact).abs() / exact.abs();
    assert!(rel <= 1e-3, "{} vs {exact} ({rel})", out.jacobian[1]);
}

#[test]
fn a_type_c_indexs_derivative_is_that_of_its_samples() {
    // five-point differences of the index of the perturbed samples at h = 1e-5 of ε: the
    // shoulder's f''' is 5× smaller than the type A wave's, so the crossing moves 5× faster,
    // and the index's rounding (~2e-12, from second differences of samples ~1e4) over h is
    // ~3e-7 of the derivative (5.6) at h = 1e-6; at 1e-5 that floor is ~5e-8 and the
    // truncation O(h⁴). 1e-6 relative tells a wrong derivative (a dropped term is O(1))
    let steps = 400;
    let (t, s) = warped_two_harmonic(steps, 0.0, BETA_C, ALPHA_C);
    let out = eval("augmentation_index.aorta", &t, 1, &s).unwrap();
    let h = 1e-5;
    let at = |eps: f64| {
        let (t, s) = warped_two_harmonic(steps, eps, BETA_C, ALPHA_C);
        eval("augmentation_index.aorta", &t, 1, &s).unwrap().values[0]
    };
    let fd = (at(-2.0 * h) - 8.0 * at(-h) + 8.0 * at(h) - at(2.0 * h)) / (12.0 * h);
    let rel = (out.jacobian[1] - fd).abs() / fd.abs();
    eprintln!(
        "type C AIx derivative {} vs {fd} ({rel:e})",
        out.jacobian[1]
    );
    assert!(out.values[0] < 0.0, "{:?}", out.values);
    assert!(rel <= 1e-6, "{} vs {fd} ({rel})", out.jacobian[1]);
}
