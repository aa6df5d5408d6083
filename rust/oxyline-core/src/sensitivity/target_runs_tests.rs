//! The targets of one run against independent truths: the output weights of a mean, a
//! flow split, a total reading a signal twice and a series against their closed forms
//! (d mean/d x_k = 1/n; d (q̄/p̄) = (dq̄ p̄ − q̄ dp̄)/p̄²; a series read at a sample is that
//! sample), the basis taken in chunks giving the same numbers; a pulse-wave path's length
//! against the model's vessel lengths; and the targets' adjoint gradients (a pulse-wave
//! velocity with its path-length term among them) against the tangent's Jacobian (an
//! independent linearisation: each step transposed; both at a periodic change of 1e-13, so
//! 1e-8 of a gradient's scale).

use super::*;
use crate::model::parse;
use crate::sensitivity::signal_sensitivities;

fn read(output: &str, columns: &[usize], at: Option<Vec<f64>>) -> TargetRead {
    TargetRead {
        output: output.into(),
        columns: columns.to_vec(),
        at,
    }
}

/// Four steps of three signals: 0 a flow into a vessel, 1 into its parent, 2 a pressure.
fn cycle() -> (Vec<f64>, Vec<f64>) {
    let times = vec![0.25, 0.5, 0.75, 1.0];
    #[rustfmt::skip]
    let signals = vec![
        1.0, 4.0, 10.0,
        2.0, 4.0, 13.0,
        3.0, 6.0, 11.0,
        2.0, 6.0, 9.0,
    ];
    (times, signals)
}

#[test]
fn output_weights_are_the_closed_forms() {
    let (times, sig) = cycle();
    let targets = [
        read("p.pressure_in.mean", &[2], None),
        read("flow_split.d.p", &[0, 1], None),
        read("VO2", &[0, 0], None),
        read("p.pressure_in.series", &[2], Some(vec![0.5, 1.0])),
    ];
    let (values, w) = output_weights(&targets, &[None; 4], &times, &sig, 3).unwrap();
    assert_eq!(values[0], vec![10.75]);
    let (q, p) = (2.0, 5.0);
    assert_eq!(values[1], vec![q / p]);
    assert_eq!(values[2], vec![4.0]);
    assert_eq!(values[3], vec![13.0, 9.0]);
    let block = 4 * 3;
    assert_eq!(w.len(), 5 * block);
    for k in 0..4 {
        let at = |row: usize, j: usize| w[row * block + k * 3 + j];
        assert_eq!([at(0, 0), at(0, 1), at(0, 2)], [0.0, 0.0, 0.25]);
        assert!((at(1, 0) - 0.25 / p).abs() < 1e-15);
        assert!((at(1, 1) + 0.25 * q / (p * p)).abs() < 1e-15);
        // a signal read twice: both reads add up
        assert_eq!([at(2, 0), at(2, 1), at(2, 2)], [0.5, 0.0, 0.0]);
        let sample = |step: usize| if k == step { 1.0 } else { 0.0 };
        // 0.5 s is step 1's end; 1.0 s is the cycle's start, the last step's sample
        assert_eq!([at(3, 2), at(4, 2)], [sample(1), sample(3)]);
    }
}

#[test]
fn output_weights_in_chunks_are_the_whole_basis() {
    let (times, sig) = cycle();
    for (output, cols) in [
        ("flow_split.d.p", &[0, 1][..]),
        ("p.pressure_in.pulse", &[2]),
    ] {
        let t = read(output, cols, None);
        let whole = weights_of_target(&t, &times, &sig, 3, None, BASIS_ENTRIES).unwrap();
        for most in [1, 3, 5] {
            let part = weights_of_target(&t, &times, &sig, 3, None, most).unwrap();
            assert_eq!(part, whole, "{output} in chunks of {most}");
        }
    }
}

#[test]
fn a_column_outside_the_run_is_named() {
    let (times, sig) = cycle();
    let t = read("p.pressure_in.mean", &[3], None);
    let err = output_weights(&[t], &[None], &times, &sig, 3).unwrap_err();
    assert!(err.to_string().contains("p.pressure_in.mean"), "{err}");
}

/// A pulsatile inflow into an elastic parent that splits into an RCR and a resistance
/// outlet.
const MODEL: &str = r#"{
  "name": "y",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 6,
     "geometry": {"length": 0.2, "radius_in": 0.004, "radius_out": 0.004,
                  "wall_thickness": 0.0006, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "o1", "segments": 6,
     "geometry": {"length": 0.15, "radius_in": 0.003, "radius_out": 0.0025,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}},
    {"name": "d2", "from": "j", "to": "o2", "segments": 2,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002,
                  "wall_thickness": 0.0004, "youngs_modulus": 6e5}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 3e-6,
                                    "cos": [1e-6, -0.4e-6], "sin": [1.2e-6, 0.3e-6]}},
    "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-10,
           "distal_resistance": 1.2e9},
    "o2": {"type": "resistance", "resistance": 1.6e9}
  }
}"#;

fn owned(x: &[&str]) -> Vec<String> {
    x.iter().map(|p| p.to_string()).collect()
}

#[test]
fn a_pulse_wave_path_length_is_its_vessels() {
    let spec = parse(MODEL).unwrap();
    let paths = owned(&[
        "vessels.d1.length",
        "vessels.d2.length",
        "vessels.parent.length",
    ]);
    let (l, dl) = path_length(&spec, "pwv.parent.d1", &paths)
        .unwrap()
        .unwrap();
    assert!((l - 0.35).abs() < 1e-15);
    assert_eq!(dl, vec![1.0, 0.0, 1.0]);
    assert_eq!(
        path_length(&spec, "parent.pressure_in.mean", &paths).unwrap(),
        None
    );
    let err = path_length(&spec, "pwv.d2.d1", &paths).unwrap_err();
    assert!(err.to_string().contains("pwv.d2.d1"), "{err}");
}

#[test]
fn target_adjoint_is_the_tangent() {
    let spec = parse(MODEL).unwrap();
    let settings = TangentSettings {
        period: 0.8,
        steps_per_cycle: 160,
        rho_infty: 0.5,
        max_cycles: 2000,
        tol: 1e-13,
    };
    let paths = owned(&[
        "vessels.parent.length",
        "boundary_conditions.o1.distal_resistance",
    ]);
    let signals: Vec<(String, String)> = [
        ("d1", "flow_in"),
        ("d1", "pressure_out"),
        ("parent", "flow_in"),
        ("parent", "pressure_in"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect();
    let targets = [
        read("pwv.parent.d1", &[3, 1], None),
        read("parent.pressure_in.max", &[3], None),
        read("flow_split.d1.parent", &[0, 2], None),
        read("d1.pressure_out.series", &[1], Some(vec![0.1, 0.45])),
    ];
    let fwd = signal_sensitivities(&spec, &paths, &signals, settings).unwrap();
    let cycle = CycleSignals {
        times: &fwd.times,
        values: &fwd.signals,
        derivs: &fwd.derivs,
        n_signals: signals.len(),
    };
    let tangent = target_values(&spec, &paths, &targets, &cycle).unwrap();
    let adj = target_adjoint(&spec, &paths, &signals, &targets, settings).unwrap();
    assert_eq!(adj.run.values, fwd.values);
    let mut row = 0;
    for (t, (tv, v)) in targets.iter().zip(tangent.iter().zip(&adj.values)) {
        assert_eq!(&tv.values, v, "{}", t.output);
        for i in 0..v.len() {
            let g = &adj.gradients[(row + i) * 2..(row + i + 1) * 2];
            // by the SI parameter: compare d value / d log parameter
            let scale = (0..2).fold(0.0f64, |m, p| {
                m.max((tv.jacobian[i * 2 + p] * fwd.values[p]).abs())
            });
            assert!(scale > 0.0, "{}", t.output);
            for p in 0..2 {
                let err = (g[p] - tv.jacobian[i * 2 + p]).abs() * fwd.values[p];
                assert!(
                    err <= 1e-8 * scale,
                    "{} row {i} by {}: adjoint {:e}, tangent {:e}",
                    t.output,
                    paths[p],
                    g[p],
                    tv.jacobian[i * 2 + p]
                );
            }
        }
        row += v.len();
    }
    // the pulse-wave velocity's own path-length term: 1/transit by the parent's length
    let pwv = adj.values[0][0];
    let without = adj.run.gradients[0];
    assert!((adj.gradients[0] - without - pwv / 0.35).abs() <= 1e-12 * pwv / 0.35);
}
