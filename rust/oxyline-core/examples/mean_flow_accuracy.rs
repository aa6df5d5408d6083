//! How coarse may the flow-only first pass of a Lévêque/Graetz run be? Runs the model's flow
//! with generalized-α at period/N for several N, and compares each segment's cycle-mean |Q|
//! and forward-flow mean (rectangle rule over the step ends, as the first pass) against the
//! finest N; the closures' k ∝ mean^{1/3}, so the k error is a third of the printed one.
//!
//!     cargo run --release -p oxyline-core --example mean_flow_accuracy -- \
//!         model.json [period] [cycles] [N...]
//!
//! (`RHO=1.0` runs the passes with ρ∞ = 1, `LINEAR=1` integrates |Q| exactly between steps.)

use oxyline_core::genalpha::NewtonControl;
use oxyline_core::model::parse;
use oxyline_core::{Method, RunSettings, Start, Transport, simulate_with_transport};

/// ∫|q| over a step of the linear interpolant between q0 and q1, divided by the step.
fn abs_linear(q0: f64, q1: f64) -> f64 {
    if (q0 >= 0.0) == (q1 >= 0.0) {
        0.5 * (q0 + q1).abs()
    } else {
        0.5 * (q0 * q0 + q1 * q1) / (q0.abs() + q1.abs())
    }
}

/// Per segment: the cycle-mean |Q| and forward-flow mean over the rows (rows 1.. are the step
/// ends of the last cycle, row 0 its start): the rectangle rule on the step ends, as the first
/// pass, or with `LINEAR` set in the environment the exact integral of the linear interpolant
/// between step ends (`abs_linear`).
fn means(data: &[f64], n: usize, rows: usize) -> (Vec<f64>, Vec<f64>) {
    let linear = std::env::var("LINEAR").is_ok();
    let mut abs = vec![0.0; n];
    let mut sgn = vec![0.0; n];
    for r in 1..rows {
        for j in 0..n {
            let (q0, q1) = (data[(r - 1) * n + j], data[r * n + j]);
            let (a, s) = if linear {
                (abs_linear(q0, q1), 0.5 * (q0 + q1))
            } else {
                (q1.abs(), q1)
            };
            abs[j] += a;
            sgn[j] += s;
        }
    }
    let c = (rows - 1) as f64;
    let fwd = abs
        .iter()
        .zip(&sgn)
        .map(|(a, s)| 0.5 * (a + s.abs()) / c)
        .collect();
    (abs.iter().map(|a| a / c).collect(), fwd)
}

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .expect("usage: mean_flow_accuracy MODEL.json [cycles] [N...]");
    let period: f64 = args.next().map_or(1.0, |c| c.parse().expect("period"));
    let cycles: usize = args.next().map_or(1, |c| c.parse().expect("cycles"));
    let mut ns: Vec<usize> = args.map(|n| n.parse().expect("N")).collect();
    if ns.is_empty() {
        ns = vec![2000, 250, 125, 100, 50];
    }
    let json = std::fs::read_to_string(&path).expect("readable model file");
    let spec = parse(&json).expect("valid model");
    let assembled = spec.assemble().expect("valid network");
    let dae = assembled.circuit.assemble().expect("valid circuit");
    let spec_tr = spec.transport.as_ref().expect("a transport section");
    let tr = Transport::build(spec_tr, &assembled.circuit, &dae, &assembled.probes).expect("ok");
    let unknowns = tr.new_run().mean_flow_unknowns();
    assert!(
        !unknowns.is_empty(),
        "a wall closure that needs the cycle-mean flow"
    );
    let n = unknowns.len();
    let mut reference: Option<(Vec<f64>, Vec<f64>)> = None;
    for &steps in &ns {
        let dt = period / steps as f64;
        let s = RunSettings {
            method: Method::GeneralizedAlpha {
                rho_inf: std::env::var("RHO").map_or(0.5, |r| r.parse().expect("rho")),
            },
            dt: Some(dt),
            period,
            cycles,
            until_periodic: None,
            max_cycles: cycles,
            output_every: dt,
            output_all_cycles: false,
            keep_current_cycle: false,
            start: Start::Steady,
            newton: NewtonControl::default(),
            probes: unknowns.clone(),
            species_columns: None,
            tolerances: None,
            svzerod: Default::default(),
            finer_last_cycle: None,
        };
        let out = simulate_with_transport(&dae, None, &s, &mut |_, _| true).expect("flow run");
        let (abs, fwd) = means(&out.data, n, out.times.len());
        match &reference {
            None => {
                let rev = abs.iter().zip(&fwd).filter(|(a, f)| a != f).count();
                println!("N {steps}: reference ({n} segments, {rev} with reversal)");
                reference = Some((abs, fwd));
            }
            Some((ra, rf)) => {
                // max, 99th percentile and median of the relative errors over the segments
                let err = |a: &[f64], r: &[f64]| {
                    let mut e: Vec<f64> =
                        a.iter().zip(r).map(|(x, y)| (x / y - 1.0).abs()).collect();
                    e.sort_by(f64::total_cmp);
                    let q = |f: f64| e[((e.len() - 1) as f64 * f) as usize];
                    format!("{:.2e} / {:.2e} / {:.2e}", q(1.0), q(0.99), q(0.5))
                };
                println!(
                    "N {steps}: rel. error of mean |Q| (max / p99 / median) {}, forward mean {}",
                    err(&abs, ra),
                    err(&fwd, rf)
                );
            }
        }
    }
}
