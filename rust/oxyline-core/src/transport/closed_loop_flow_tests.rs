//! The O2 loop's derivatives along directions of its flow table ([`LoopParameter::Flow`]),
//! against central differences of whole periodic runs on the perturbed tables, the outputs
//! read from the runs' own records (saturations, flows, consumptions).

use super::super::{ClosedLoop, ClosedLoopSpec, run_periodic};
use super::*;
use std::f64::consts::PI;

const MMHG: f64 = 133.322368;
const STEPS: usize = 100;
const DT: f64 = 0.008;
/// the mean flow (m³/s, 5 L/min)
const Q0: f64 = 8.3e-5;

/// right heart → (lungs) → left heart → tissue (Michaelis–Menten) → veins → right heart.
fn spec() -> ClosedLoopSpec {
    ClosedLoopSpec::from_json(&format!(
        r#"{{"compartments": [
             {{"name": "right_heart", "volume": 1e-4, "initial_po2": 5000}},
             {{"name": "left_heart", "volume": 1e-4, "initial_po2": 13000}},
             {{"name": "tissue", "volume": 1e-3, "initial_po2": 6000,
               "consumption": {{"kind": "michaelis-menten", "vmax": 1.9e-4, "km": 133.0}}}},
             {{"name": "veins", "volume": 3e-3, "initial_po2": 5000}}],
           "branches": [
             {{"name": "ejection_right", "from": 0, "to": 1,
               "lungs": {{"alveolar_po2": {pa}, "diffusing_capacity": 1.5e-7}}}},
             {{"name": "ejection_left", "from": 1, "to": 2}},
             {{"name": "capillaries", "from": 2, "to": 3}},
             {{"name": "return", "from": 3, "to": 0}}],
           "binding": {{"kind": "hill", "solubility": {a}, "p50": {p50}, "n": 2.7,
                       "capacity": 8.97}}}}"#,
        pa = 100.0 * MMHG,
        a = 1.34e-3 / MMHG,
        p50 = 26.8 * MMHG,
    ))
    .unwrap()
}

/// Per step (steps × 4 branches): `f(phase, branch)`, phase ωt at the step's middle.
fn table(f: impl Fn(f64, usize) -> f64) -> Vec<f64> {
    (0..STEPS)
        .flat_map(|s| {
            let phase = 2.0 * PI * (s as f64 + 0.5) / STEPS as f64;
            (0..4).map(move |b| (phase, b))
        })
        .map(|(phase, b)| f(phase, b))
        .collect()
}

/// Pulsatile ejections, the same mean through every branch (every volume periodic).
fn flows() -> Vec<f64> {
    table(|w, b| match b {
        0 => Q0 * (1.0 + 0.8 * (w - 0.3).sin()),
        1 => Q0 * (1.0 + 0.8 * w.sin()),
        2 => Q0 * (1.0 + 0.2 * w.cos()),
        _ => Q0,
    })
}

/// Two directions: a pulsatile flow added around the whole ring (no compartment's volume
/// moves), and a zero-mean change of the left ejection alone (the left heart's and the
/// tissue's volumes move within the cycle).
fn directions() -> Vec<Vec<f64>> {
    vec![
        table(|w, _| Q0 * (0.5 + 0.3 * (w + 1.0).sin())),
        table(|w, b| if b == 1 { 0.3 * Q0 * w.cos() } else { 0.0 }),
    ]
}

/// SaO2, SvO2 (the ejections' flow-weighted saturations), VO2 (the cycle mean) and the
/// cardiac output of a whole periodic run on `flows`, from its record.
fn run_outputs(flows: &[f64]) -> Vec<f64> {
    let run = run_periodic(&spec(), flows, DT, 400, 1e-14).unwrap();
    let (nc, nb) = (4, 4);
    let weighted = |b: usize, n: usize| {
        let q: f64 = (0..STEPS).map(|s| run.flow[s * nb + b]).sum();
        let qs: f64 = (0..STEPS)
            .map(|s| run.flow[s * nb + b] * run.saturation[s * nc + n])
            .sum();
        qs / q
    };
    let vo2 = run.vo2.iter().sum::<f64>() / STEPS as f64;
    let co = (0..STEPS).map(|s| run.flow[s * nb + 1]).sum::<f64>() / STEPS as f64;
    vec![weighted(1, 1), weighted(0, 0), vo2, co]
}

#[test]
fn flow_directions_match_central_differences_of_periodic_runs() {
    let base = flows();
    let dirs = directions();
    let run = run_periodic(&spec(), &base, DT, 400, 1e-14).unwrap();
    let lp = ClosedLoop::new(&spec()).unwrap();
    let cycle = Cycle {
        dt: DT,
        flow: &run.flow,
        volume: &run.volume,
        total: &run.total,
        start_volume: &lp.volume,
        flow_tangents: &dirs,
    };
    let params = [LoopParameter::Flow(0), LoopParameter::Flow(1)];
    let tangent = lp.cycle_tangent(&cycle, &params).unwrap();
    let outs = [
        LoopOutput::SaO2,
        LoopOutput::SvO2,
        LoopOutput::Vo2,
        LoopOutput::CardiacOutput,
    ];
    // five-point differences at h = 1e-3 of each direction: truncation O(h⁴) ~ 1e-12, the
    // runs' periodic error 1e-14/h ~ 1e-11; each output is compared on the scale of its
    // largest derivative (the zero-mean change hardly moves the cycle means)
    let h = 1e-3;
    let run_at = |dir: &[f64], k: f64| {
        let t: Vec<f64> = base.iter().zip(dir).map(|(q, d)| q + k * h * d).collect();
        run_outputs(&t)
    };
    let fd: Vec<Vec<f64>> = dirs
        .iter()
        .map(|dir| {
            let at: Vec<Vec<f64>> = [-2.0, -1.0, 1.0, 2.0]
                .iter()
                .map(|&k| run_at(dir, k))
                .collect();
            (0..outs.len())
                .map(|i| (at[0][i] - 8.0 * at[1][i] + 8.0 * at[2][i] - at[3][i]) / (12.0 * h))
                .collect()
        })
        .collect();
    for (i, &o) in outs.iter().enumerate() {
        let (value, d) = lp.output(&cycle, &tangent, &params, o).unwrap();
        // or the differences' rounding floor: the runs' periodic error 1e-14 of the value
        // over h is 1e-11 of it (SaO2 near 1 hardly moves with the flow: ~3e-7)
        let largest = fd.iter().map(|f| f[i].abs()).fold(0.0, f64::max);
        let scale = largest.max(1e-5 * value.abs());
        for j in 0..dirs.len() {
            let rel = (d[j] - fd[j][i]).abs() / scale;
            eprintln!("{o:?} by direction {j}: {} vs {} ({rel:e})", d[j], fd[j][i]);
            assert!(
                rel <= 1e-6,
                "output {o:?} by direction {j}: {} vs {}",
                d[j],
                fd[j][i]
            );
        }
    }
}
