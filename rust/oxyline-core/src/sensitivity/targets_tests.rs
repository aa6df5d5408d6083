//! Targets against closed forms: a sinusoid's statistics, a ramp's foot, a pure delay's
//! pulse-wave velocity, and their derivatives by the waves' own parameters.

use super::*;
use std::f64::consts::PI;

const PERIOD: f64 = 0.8;
const STEPS: usize = 400;

fn times() -> Vec<f64> {
    (1..=STEPS)
        .map(|k| k as f64 * PERIOD / STEPS as f64)
        .collect()
}

/// Signals (columns) and their derivatives by parameters (one closure per parameter and
/// signal), sampled at the step end times, in the tangent runs' row-major layout.
fn sample(
    signals: &[&dyn Fn(f64) -> f64],
    derivs: &[&[&dyn Fn(f64) -> f64]],
) -> (Vec<f64>, Vec<f64>) {
    let t = times();
    let values = t
        .iter()
        .flat_map(|&t| signals.iter().map(move |f| f(t)))
        .collect();
    let d = derivs
        .iter()
        .flat_map(|row| t.iter().flat_map(move |&t| row.iter().map(move |f| f(t))))
        .collect();
    (values, d)
}

fn eval(
    output: &str,
    nsig: usize,
    (values, derivs): &(Vec<f64>, Vec<f64>),
    at: Option<&[f64]>,
    path: Option<PathLength>,
) -> TargetValue {
    let t = times();
    let cycle = CycleSignals {
        times: &t,
        values,
        derivs,
        n_signals: nsig,
    };
    evaluate(output, &cycle, at, path).unwrap()
}

fn close(a: f64, b: f64, tol: f64) {
    assert!((a - b).abs() <= tol, "{a} != {b} (tol {tol})");
}

fn close_all(a: &[f64], b: &[f64], tol: f64) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        close(*x, *y, tol);
    }
}

// a + b sin(2πt/T): parameters a (derivative 1) and b (derivative sin)
const A: f64 = 1.3e4;
const B: f64 = 2.1e3;

fn sinusoid() -> (Vec<f64>, Vec<f64>) {
    let w = 2.0 * PI / PERIOD;
    sample(
        &[&|t| A + B * (w * t).sin()],
        &[&[&|_| 1.0], &[&|t| (w * t).sin()]],
    )
}

#[test]
fn a_sinusoids_statistics_and_their_derivatives_are_its_closed_forms() {
    let s = sinusoid();
    // the extremes fall on samples (T/4 and 3T/4 are steps 100 and 300): exact to rounding
    let tol = 1e-9 * A;
    let max = eval("v.pressure_in.max", 1, &s, None, None);
    close(max.values[0], A + B, tol);
    close_all(&max.jacobian, &[1.0, 1.0], 1e-12);
    let min = eval("v.pressure_in.min", 1, &s, None, None);
    close(min.values[0], A - B, tol);
    close_all(&min.jacobian, &[1.0, -1.0], 1e-12);
    // a full period of sin sums to 0
    let mean = eval("v.pressure_in.mean", 1, &s, None, None);
    close(mean.values[0], A, tol);
    close_all(&mean.jacobian, &[1.0, 0.0], 1e-12);
    let pulse = eval("v.pressure_in.pulse", 1, &s, None, None);
    close(pulse.values[0], 2.0 * B, tol);
    close_all(&pulse.jacobian, &[0.0, 2.0], 1e-12);
}

#[test]
fn a_series_is_read_between_samples_linearly_and_periodically() {
    let s = sinusoid();
    let dt = PERIOD / STEPS as f64;
    let w = 2.0 * PI / PERIOD;
    // at a sample, half-way between two (the chord), at 0 (the sample at T) and a cycle on
    let at = [PERIOD / 4.0, 10.5 * dt, 0.0, PERIOD + 10.5 * dt];
    let mid = ((w * 10.0 * dt).sin() + (w * 11.0 * dt).sin()) / 2.0;
    let out = eval("v.flow_out.series", 1, &s, Some(&at), None);
    close_all(&out.values, &[A + B, A + B * mid, A, A + B * mid], 1e-9 * A);
    close_all(
        &out.jacobian,
        &[1.0, 1.0, 1.0, mid, 1.0, 0.0, 1.0, mid],
        1e-12,
    );
}

#[test]
fn a_flow_split_a_total_and_a_flow_weighted_saturation_are_their_closed_forms() {
    let w = 2.0 * PI / PERIOD;
    let (q0, p0) = (2.0e-6, 5.0e-6);
    // split of q0 + B sin over p0 + B cos: q0/p0, by q0 1/p0 and by p0 −q0/p0²
    let s = sample(
        &[&|t| q0 + 1e-6 * (w * t).sin(), &|t| {
            p0 + 1e-6 * (w * t).cos()
        }],
        &[&[&|_| 1.0, &|_| 0.0], &[&|_| 0.0, &|_| 1.0]],
    );
    let split = eval("flow_split.a.b", 2, &s, None, None);
    close(split.values[0], q0 / p0, 1e-12);
    close_all(&split.jacobian, &[1.0 / p0, -q0 / (p0 * p0)], 1e-6);
    let total = eval("cardiac_output", 2, &s, None, None);
    close(total.values[0], q0 + p0, 1e-18);
    close_all(&total.jacobian, &[1.0, 1.0], 1e-12);
    // S = s0 + c sin, Q = q0 + b sin: Σ Q S / Σ Q = s0 + b c / (2 q0); by c: b / (2 q0)
    let (s0, c, b) = (0.7, 0.05, 1e-6);
    let s = sample(
        &[&|t| s0 + c * (w * t).sin(), &|t| q0 + b * (w * t).sin()],
        &[&[&|t| (w * t).sin(), &|_| 0.0]],
    );
    let svo2 = eval("SvO2.a", 2, &s, None, None);
    close(svo2.values[0], s0 + b * c / (2.0 * q0), 1e-12);
    close_all(&svo2.jacobian, &[b / (2.0 * q0)], 1e-12);
}

/// A wave flat at P0 that rises with slope S from `start` for 0.1 s and falls back to P0 by
/// 0.6 s after it: its foot is `start`.
const P0: f64 = 1.0e4;
const S: f64 = 8.0e4;

fn ramp(t: f64, start: f64) -> f64 {
    let top = S * 0.1;
    match t - start {
        x if (0.0..0.1).contains(&x) => P0 + S * x,
        x if (0.1..0.6).contains(&x) => P0 + top * (0.6 - x) / 0.5,
        _ => P0,
    }
}

/// d ramp / d start: −S on the rise, the fall's slope back, 0 on the flat.
fn dramp(t: f64, start: f64) -> f64 {
    match t - start {
        x if (0.0..0.1).contains(&x) => -S,
        x if (0.1..0.6).contains(&x) => S * 0.1 / 0.5,
        _ => 0.0,
    }
}

#[test]
fn the_foot_of_a_ramp_is_its_start_and_moves_with_it() {
    let start = 0.1237; // between samples
    let mut t = vec![0.0];
    t.extend(times());
    let p: Vec<f64> = t.iter().map(|&t| ramp(t, start)).collect();
    let foot = foot_time(&t, &p).unwrap();
    close(foot.time, start, 1e-12);
    close(p[foot.minimum], P0, 0.0);
    // shifted by half a period (the wave wraps): its foot wraps too
    let q: Vec<f64> = t.iter().map(|&t| ramp((t + 0.4) % PERIOD, start)).collect();
    close(foot_time(&t, &q).unwrap().time, start + 0.4, 1e-12);
    // a cycle not starting at 0: the foot in [t₀, t₀ + T)
    let shifted: Vec<f64> = t.iter().map(|t| t + 3.2).collect();
    close(foot_time(&shifted, &p).unwrap().time, start + 3.2, 1e-12);
    assert!(foot_time(&t[..2], &p[..2]).is_err());
}

#[test]
fn a_pure_delays_pulse_wave_velocity_is_length_over_delay_with_its_derivatives() {
    let (start, delay, length) = (0.1237, 0.0311, 0.45);
    let s = sample(
        &[&|t| ramp(t, start), &|t| ramp(t, start + delay)],
        // parameters: the path length (waves unchanged) and the delay (the distal wave moves)
        &[
            &[&|_| 0.0, &|_| 0.0],
            &[&|_| 0.0, &|t| dramp(t, start + delay)],
        ],
    );
    let path = PathLength {
        length,
        dlength: &[1.0, 0.0],
    };
    let pwv = eval("pwv.a.b", 2, &s, None, Some(path));
    close(pwv.values[0], length / delay, 1e-9);
    close_all(
        &pwv.jacobian,
        &[1.0 / delay, -length / (delay * delay)],
        1e-8,
    );
    let t = times();
    let transit = transit_time(
        &[vec![0.0], t.clone()].concat(),
        &[
            vec![ramp(0.0, start)],
            t.iter().map(|&t| ramp(t, start)).collect(),
        ]
        .concat(),
        &[
            vec![ramp(0.0, start + delay)],
            t.iter().map(|&t| ramp(t, start + delay)).collect(),
        ]
        .concat(),
    )
    .unwrap();
    close(transit, delay, 1e-12);
}

#[test]
fn a_name_it_cannot_read_or_signals_that_do_not_fit_are_errors_naming_the_output() {
    let s = sinusoid();
    let t = times();
    let cycle = CycleSignals {
        times: &t,
        values: &s.0,
        derivs: &s.1,
        n_signals: 1,
    };
    let e = evaluate("v.pressure_in.median", &cycle, None, None).unwrap_err();
    assert!(e.to_string().contains("v.pressure_in.median"), "{e}");
    let e = evaluate("flow_split.a.b", &cycle, None, None).unwrap_err();
    assert!(e.to_string().contains("reads 2"), "{e}");
    assert!(evaluate("v.flow_in.series", &cycle, None, None).is_err());
    // two feet on one sample: no transit time
    let two = CycleSignals {
        values: &s.0.iter().flat_map(|&v| [v, v]).collect::<Vec<_>>(),
        derivs: &s.1.iter().flat_map(|&v| [v, v]).collect::<Vec<_>>(),
        n_signals: 2,
        ..cycle
    };
    let path = PathLength {
        length: 1.0,
        dlength: &[0.0, 0.0],
    };
    let e = evaluate("pwv.a.b", &two, None, Some(path)).unwrap_err();
    assert!(e.to_string().contains("same sample"), "{e}");
}

/// parent → d1 (a tube), parent → d2 (lumped), d1 → g (a tube) at a second junction.
const TREE: &str = r#"{
  "name": "y",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 3,
     "geometry": {"length": 0.1, "radius_in": 0.004, "radius_out": 0.004,
                  "wall_thickness": 0.0006, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "k", "segments": 2,
     "geometry": {"length": 0.08, "radius_in": 0.003, "radius_out": 0.0025,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}},
    {"name": "d2", "from": "j", "to": "o2", "segments": 2,
     "lumped": {"resistance": 3e7, "inductance": 1e5, "capacitance": 2e-10}},
    {"name": "g", "from": "k", "to": "o1", "segments": 2,
     "geometry": {"length": 0.05, "radius_in": 0.0025, "radius_out": 0.0025,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 5e-6,
                                    "cos": [3e-6], "sin": [4e-6]}},
    "o1": {"type": "resistance", "resistance": 1.6e9},
    "o2": {"type": "resistance", "resistance": 1.6e9}
  }
}"#;

#[test]
fn a_pulse_wave_path_runs_downstream_through_the_named_vessels_with_their_lengths() {
    let spec = crate::model::parse(TREE).unwrap();
    let path = pulse_wave_path(&spec, "pwv.parent.g").unwrap();
    let names: Vec<&str> = path.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["parent", "d1", "g"]);
    close_all(
        &path.iter().map(|(_, l)| *l).collect::<Vec<_>>(),
        &[0.1, 0.08, 0.05],
        0.0,
    );
    assert_eq!(pulse_wave_path(&spec, "pwv.d1.d1").unwrap().len(), 1);
    for (output, why) in [
        ("pwv.d1.parent", "not downstream"),
        ("pwv.parent.zz", "no vessel named 'zz' in model 'y'"),
        ("pwv.parent.d2", "'d2' on the path has no length"),
        ("pwv.parent", "expected pwv."),
    ] {
        let e = pulse_wave_path(&spec, output).unwrap_err().to_string();
        assert!(e.contains(why) && e.contains(output), "{output}: {e}");
    }
}
