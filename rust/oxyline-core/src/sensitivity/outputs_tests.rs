//! The merged entry points against independent truths: the merged tangent of flow and
//! oxygen signals by flow and oxygen parameters against central differences of whole
//! periodic runs (relative step 1e-4: truncation and rounding below 1e-7 of a derivative's
//! scale, so 1e-6 tells a wrong splice from a right one), an oxygen parameter's rows of
//! the flow signals exactly 0 (it does not enter the flow), and the merged adjoint of a
//! functional of flow and oxygen signals against the merged tangent contracted with the
//! same weights (the adjoint transposes each step: an independent linearisation; both at a
//! periodic change of 1e-13, so 1e-8 of a gradient's scale).

use super::*;
use crate::closure::WallSpec;
use crate::model::parse;

/// A pulsatile inflow into an elastic parent that splits into an RCR and a resistance
/// outlet, with Hill's law and a mass-transfer wall (as the species tests' network).
const MODEL: &str = r#"{
  "name": "y",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 3,
     "geometry": {"length": 0.1, "radius_in": 0.004, "radius_out": 0.004,
                  "wall_thickness": 0.0006, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "o1", "segments": 4,
     "geometry": {"length": 0.08, "radius_in": 0.003, "radius_out": 0.0025,
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
  },
  "transport": {"species": [{
    "name": "o2", "diffusivity": 1.5e-9,
    "binding": {"kind": "hill", "solubility": 1e-5, "p50": 3573.04, "n": 2.7,
                "capacity": 9.0},
    "inlet": {"kind": "constant", "value": 0.113324},
    "wall": {"model": "mass-transfer", "k": 5e-3, "wall_concentration": 0.0533288}
  }]}
}"#;

fn strings(pairs: &[(&str, &str)]) -> Vec<(String, String)> {
    pairs
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect()
}

/// A flow signal of each kind, and oxygen signals of a vessel and of the network.
fn mixed_signals() -> Vec<(String, String)> {
    strings(&[
        ("parent", "pressure_in"),
        ("d1", "saturation_out"),
        ("d1", "flow_out"),
        ("", "consumption"),
        ("d1", "po2_out"),
    ])
}

const PATHS: [&str; 2] = ["oxygen.wall.k", "boundary_conditions.o1.distal_resistance"];

fn settings() -> TangentSettings {
    TangentSettings {
        period: 0.8,
        steps_per_cycle: 160,
        rho_infty: 0.5,
        max_cycles: 2000,
        tol: 1e-13,
    }
}

/// `s` with the parameter `path` (of [`PATHS`]) multiplied by `f`.
fn scaled(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    if path != "oxygen.wall.k" {
        return super::super::tests::scaled_from(s, path, f);
    }
    match &mut s.transport.as_mut().unwrap().species[0].wall {
        WallSpec::MassTransfer { k, .. } => *k *= f,
        _ => panic!("the test model's wall is a mass-transfer wall"),
    }
    s
}

fn owned(paths: &[&str]) -> Vec<String> {
    paths.iter().map(|p| p.to_string()).collect()
}

/// The cycle mean of each signal (n_steps × n_signals).
fn means(values: &[f64], nsig: usize) -> Vec<f64> {
    let ns = values.len() / nsig;
    (0..nsig)
        .map(|j| (0..ns).map(|k| values[k * nsig + j]).sum::<f64>() / ns as f64)
        .collect()
}

#[test]
fn merged_tangent_is_the_central_difference_of_every_signal() {
    let spec = parse(MODEL).unwrap();
    let sig = mixed_signals();
    let nsig = sig.len();
    let exact = signal_sensitivities(&spec, &owned(&PATHS), &sig, settings()).unwrap();
    let nt = exact.times.len();
    let h = 1e-4;
    for (p, path) in PATHS.iter().enumerate() {
        let at = |f: f64| {
            let s = scaled(spec.clone(), path, f);
            let out = signal_sensitivities(&s, &[], &sig, settings()).unwrap();
            means(&out.signals, nsig)
        };
        let (up, down) = (at(1.0 + h), at(1.0 - h));
        for j in 0..nsig {
            let d: f64 = (0..nt)
                .map(|k| exact.derivs[(p * nt + k) * nsig + j])
                .sum::<f64>()
                / nt as f64;
            let fd = (up[j] - down[j]) / (2.0 * h * exact.values[p]);
            let scale = fd.abs().max(1e-12 * up[j].abs() / (h * exact.values[p]));
            assert!(
                (d - fd).abs() <= 1e-6 * scale,
                "{path} by {:?}: tangent {d:e}, central difference {fd:e}",
                sig[j]
            );
        }
    }
    // the oxygen parameter does not enter the flow: its rows of the flow signals are 0
    for k in 0..nt {
        for j in [0, 2] {
            assert_eq!(exact.derivs[k * nsig + j], 0.0);
        }
    }
}

#[test]
fn merged_adjoint_is_the_merged_tangent() {
    let spec = parse(MODEL).unwrap();
    let sig = mixed_signals();
    let nsig = sig.len();
    let paths = owned(&PATHS);
    let fwd = signal_sensitivities(&spec, &paths, &sig, settings()).unwrap();
    let ns = fwd.times.len();
    let mut used = Vec::new();
    // an SvO2-like Σ Q S / Σ Q (linearised at the cycle) plus the mean pressure and flow:
    // weights on oxygen and flow signals alike, chosen from every signal of the cycle
    let adj = signal_adjoint_with(
        &spec,
        &paths,
        &sig,
        |_, v| {
            let total: f64 = (0..ns).map(|k| v[k * nsig + 2]).sum();
            let mut w = vec![0.0; ns * nsig];
            for k in 0..ns {
                w[k * nsig + 1] = v[k * nsig + 2] / total;
                w[k * nsig + 2] = v[k * nsig + 1] / total;
                w[k * nsig] = 1e-4 / ns as f64;
            }
            used = w.clone();
            Ok(w)
        },
        settings(),
    )
    .unwrap();
    let j: f64 = used.iter().zip(&fwd.signals).map(|(a, b)| a * b).sum();
    assert!((adj.functionals[0] - j).abs() <= 1e-9 * j.abs());
    let block = ns * nsig;
    let grads: Vec<f64> = (0..paths.len())
        .map(|p| {
            let d = &fwd.derivs[p * block..(p + 1) * block];
            used.iter().zip(d).map(|(a, b)| a * b).sum()
        })
        .collect();
    let scale = grads
        .iter()
        .zip(&fwd.values)
        .fold(0.0f64, |m, (g, v)| m.max((g * v).abs()));
    assert!(scale > 0.0);
    for p in 0..paths.len() {
        let err = (adj.gradients[p] - grads[p]).abs() * fwd.values[p];
        assert!(
            err <= 1e-8 * scale,
            "{}: adjoint {:e}, tangent {:e}",
            paths[p],
            adj.gradients[p],
            grads[p]
        );
    }
    assert_eq!(adj.values, fwd.values);
}

#[test]
fn an_oxygen_parameter_of_flow_outputs_alone_is_refused_by_the_adjoint() {
    let spec = parse(MODEL).unwrap();
    let sig = strings(&[("parent", "pressure_in")]);
    let err = signal_adjoint_with(
        &spec,
        &owned(&PATHS[..1]),
        &sig,
        |_, _| Ok(vec![]),
        settings(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("parent.pressure_in"), "{err}");
}
