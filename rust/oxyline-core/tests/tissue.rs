//! Wall/tissue compartment (docs/physics.md §3.7) through the whole transport, in both
//! integrations: the steady wall profile against the closed form of zero-order consumption in
//! a cylindrical shell, exact mass balance (lumen and wall), and typed errors.

mod common;

use common::{Built, build_error as error, try_build};
use oxyline_core::rk4::CoupledStages;
use oxyline_core::transport::{
    BALANCE_COLUMNS, SEGMENT_COLUMNS, TISSUE_SEGMENT_COLUMNS, TISSUE_VESSEL_COLUMNS, VESSEL_COLUMNS,
};
use std::f64::consts::PI;

// test wall: r 5 mm, h 0.1 mm, D 1.5e-9 m²/s, 16 radial cells, partition 0.8
const R: f64 = 5e-3;
const H: f64 = 1e-4;
const D: f64 = 1.5e-9;
const N_R: usize = 16;
const PHI: f64 = 0.8;
const C_IN: f64 = 0.112;
const Q: f64 = 1e-5;
const SEGS: usize = 4;

/// The shared tube fixture (`common::tube`) with this file's wall, tissue and extra keys.
fn tube(wall: &str, tissue: &str, extra: &str) -> String {
    let flow = format!(r#"{{"kind": "constant", "value": {Q}}}"#);
    let species = format!(
        r#"{extra} "species": [{{"name": "o2", "inlet": {{"kind": "constant", "value": {C_IN}}},
              "wall": {wall}, "tissue": {tissue}}}]"#
    );
    common::tube(R, 0.05, SEGS, "", &flow, 1e7, &species)
}

fn tissue(consumption: &str, outer: &str) -> String {
    format!(
        r#"{{"thickness": {H}, "diffusivity": {D}, "partition": {PHI}, "radial_cells": {N_R},
            "consumption": {consumption}, "outer": {outer}, "hypoxic_threshold": 0.05}}"#
    )
}

const LUMEN: &str = r#"{"model": "mass-transfer", "k": 1.0, "wall_concentration": 0.0}"#;

/// Rigid tube, the flow Q in every branch, pressures at the reference.
fn flow_state(b: &Built) -> Vec<f64> {
    let mut y = vec![0.0; b.dae.n];
    y[b.dae.n_nodes..].iter_mut().for_each(|v| *v = Q);
    y
}

/// The observed species block and its tissue tail.
fn observe(b: &mut Built, t: f64, y: &[f64], z: &[f64], implicit: bool) -> (Vec<f64>, Vec<f64>) {
    let mut out = Vec::new();
    b.transport
        .observe(t, y, None, z, implicit, &mut out)
        .unwrap();
    let tail = out.split_off(out.len() - b.transport.tissue_columns());
    (out, tail)
}

/// Lumen balance residual (mol) of an observed block: ΔΣN − (in − out − wall − decay).
fn lumen_residual(block: &[f64], stored0: f64) -> f64 {
    let b = &block[block.len() - BALANCE_COLUMNS..];
    (b[0] - stored0) - (b[1] - b[2] - b[3] - b[4])
}

/// Wall balance residual: ΔΣN_wall − (lumen → wall − consumed + outer inflow).
fn wall_residual(tail: &[f64], stored0: f64) -> f64 {
    let b = &tail[tail.len() - 4..];
    (b[0] - stored0) - (b[1] - b[2] + b[3])
}

/// Closed-form steady profile of zero-order consumption `rate` in the shell [R, R + H] with
/// u(R) = ui: u = ui + rate (r² − R²)/(4D) + A ln(r/R), A from u'(R + H) = 0 or u(R + H) = uo.
fn exact(r: f64, ui: f64, rate: f64, uo: Option<f64>) -> f64 {
    let ro = R + H;
    let a = match uo {
        None => -rate * ro * ro / (2.0 * D),
        Some(uo) => (uo - ui - rate * (ro * ro - R * R) / (4.0 * D)) / (ro / R).ln(),
    };
    ui + rate * (r * r - R * R) / (4.0 * D) + a * (r / R).ln()
}

enum Scheme {
    Rk4,
    Implicit,
}

/// Run to the steady state, checking the lumen and wall balances after every step
/// (relative to the throughput Q c_in t); returns the last observation.
fn run(b: &mut Built, scheme: Scheme, dt: f64, steps: usize) -> (Vec<f64>, Vec<f64>, f64) {
    let mut y = flow_state(b);
    let mut z = b.transport.initial_state(&y).unwrap();
    let (block0, tail0) = observe(b, 0.0, &y, &z, false);
    let stored0 = block0[block0.len() - BALANCE_COLUMNS];
    let wall0 = tail0[tail0.len() - 4];
    let mut st = CoupledStages::new(z.len());
    let mut worst = 0.0f64;
    let implicit = matches!(scheme, Scheme::Implicit);
    for k in 0..steps {
        let t = k as f64 * dt;
        match scheme {
            Scheme::Rk4 => {
                let mut flow = |_: f64, y: &mut [f64]| y[b.dae.n_nodes..].fill(Q);
                b.transport
                    .step_prescribed(t, dt, &mut flow, &mut y, &mut z, &mut st)
                    .unwrap();
            }
            Scheme::Implicit => b
                .transport
                .implicit_step(t, dt, 1.0, &y, &y, &mut z)
                .unwrap(),
        }
        if k % 97 == 0 || k + 1 == steps {
            let (block, tail) = observe(b, t + dt, &y, &z, implicit);
            let throughput = Q * C_IN * (t + dt);
            let lumen = lumen_residual(&block, stored0);
            let wall = wall_residual(&tail, wall0);
            // all of the lumen's wall uptake goes into the wall columns
            let coupling = block[block.len() - 2] - tail[tail.len() - 3];
            for r in [lumen, wall, coupling] {
                worst = worst.max(r.abs() / throughput);
            }
        }
    }
    let (block, tail) = observe(b, steps as f64 * dt, &y, &z, implicit);
    (block, tail, worst)
}

/// Steady wall profile of every segment against the closed form (evaluated at the innermost
/// and outermost cell centres, ui = φ × the segment's lumen concentration), relative to the
/// drop across the wall.
fn profile_error(block: &[f64], tail: &[f64], rate: f64, uo: Option<f64>) -> f64 {
    let dr = H / N_R as f64;
    let (r0, r1) = (R + 0.5 * dr, R + H - 0.5 * dr);
    let mut worst = 0.0f64;
    for j in 0..SEGS {
        let c = block[VESSEL_COLUMNS + SEGMENT_COLUMNS * j];
        let ui = PHI * c;
        let drop = ui - exact(R + H, ui, rate, uo);
        assert!(drop > 0.1 * ui, "the test needs a real drop: {drop}");
        let s = &tail[TISSUE_VESSEL_COLUMNS + TISSUE_SEGMENT_COLUMNS * j..];
        let (inner, outer, min) = (s[0], s[1], s[2]);
        for (got, r) in [(inner, r0), (outer, r1), (min, r1)] {
            worst = worst.max((PHI * got - exact(r, ui, rate, uo)).abs() / drop);
        }
    }
    worst
}

#[test]
fn steady_wall_matches_the_closed_form_and_balances_exactly_in_both_schemes() {
    let rate = 0.012; // mol m⁻³ s⁻¹: ≈ 0.04 mol/m³ across 0.1 mm
    for (outer, uo) in [
        (r#"{"kind": "no-flux"}"#.to_string(), None),
        (
            r#"{"kind": "concentration", "value": 0.05}"#.to_string(),
            Some(0.05),
        ),
    ] {
        let consumption = format!(r#"{{"kind": "zero-order", "rate": {rate}}}"#);
        let json = tube(LUMEN, &tissue(&consumption, &outer), "");
        // the wall's diffusion time h²/D ≈ 7 s: 60 s reach the steady state
        for (scheme, dt, steps) in [(Scheme::Rk4, 2e-3, 30_000), (Scheme::Implicit, 0.05, 1200)] {
            let name = match scheme {
                Scheme::Rk4 => "rk4",
                Scheme::Implicit => "implicit",
            };
            let mut b = try_build(&json).unwrap();
            let (block, tail, balance) = run(&mut b, scheme, dt, steps);
            let err = profile_error(&block, &tail, rate, uo);
            eprintln!(
                "{name} outer {uo:?}: profile error {err:e} of the drop, balance {balance:e}"
            );
            // observed 1.0e-3: the FV error at 16 radial cells (~2.5e-4 of the drop, second
            // order, see the kernel test in transport/tissue.rs) and the lumen concentration's
            // change along the segment, which the segment's single value does not resolve
            assert!(err < 2e-3, "{name}: {err:e}");
            // mass balance to round-off of the throughput
            assert!(balance < 1e-9, "{name}: balance {balance:e}");
            // hypoxic fraction (threshold 0.05 mol/m³ of wall): between 0 and 1, 0 where the
            // whole profile is above it
            let hyp = tail[3];
            assert!((0.0..=1.0).contains(&hyp), "{hyp}");
            // the observed wall flux of the vessel is the flux into the wall: at the steady
            // state with a no-flux outer face, the consumption rate × wall volume
            if uo.is_none() {
                let consumed = rate * PI * ((R + H) * (R + H) - R * R) * 0.05;
                let wall = block[4];
                assert!(
                    (wall / consumed - 1.0).abs() < 1e-6,
                    "{name}: {wall:e} vs {consumed:e}"
                );
            }
        }
    }
}

#[test]
fn michaelis_menten_balances_exactly_and_tends_to_zero_order() {
    let outer = r#"{"kind": "no-flux"}"#;
    let mut mins = Vec::new();
    for consumption in [
        r#"{"kind": "zero-order", "rate": 0.012}"#,
        r#"{"kind": "michaelis-menten", "vmax": 0.012, "km": 1e-9}"#,
        r#"{"kind": "michaelis-menten", "vmax": 0.012, "km": 1e-3}"#,
    ] {
        let mut b = try_build(&tube(LUMEN, &tissue(consumption, outer), "")).unwrap();
        let (_, tail, balance) = run(&mut b, Scheme::Implicit, 0.05, 1200);
        assert!(balance < 1e-9, "{consumption}: balance {balance:e}");
        mins.push(tail[2]);
    }
    // km → 0: the zero-order profile (to ~km relative), and a larger km consumes less
    assert!((mins[1] - mins[0]).abs() < 1e-6 * C_IN, "{mins:?}");
    assert!(mins[2] > mins[0] + 1e-4, "{mins:?}");
}

#[test]
fn without_a_tissue_wall_nothing_changes() {
    let json = tube(LUMEN, "null", "");
    let b = try_build(&json).unwrap();
    assert_eq!(b.transport.tissue_columns(), 0);
}

#[test]
fn bad_tissue_settings_are_typed_errors_naming_the_vessel_and_value() {
    let ok = r#"{"kind": "zero-order", "rate": 0.01}"#;
    let bad = |t: &str, extra: &str, wall: &str| error(&tube(wall, t, extra));
    let nf = r#"{"kind": "no-flux"}"#;
    let e = bad(
        &tissue(ok, nf).replace("\"thickness\": 0.0001", "\"thickness\": -1"),
        "",
        LUMEN,
    );
    assert!(
        e.contains("vessel 'tube'") && e.contains("thickness") && e.contains("-1"),
        "{e}"
    );
    let e = bad(
        &tissue(ok, nf).replace("\"radial_cells\": 16", "\"radial_cells\": 2.5"),
        "",
        LUMEN,
    );
    assert!(e.contains("radial_cells") && e.contains("2.5"), "{e}");
    let e = bad(
        &tissue(r#"{"kind": "zero-order", "rate": -3}"#, nf),
        "",
        LUMEN,
    );
    assert!(e.contains("rate") && e.contains("-3"), "{e}");
    let e = bad(
        &tissue(ok, r#"{"kind": "concentration", "value": -0.5}"#),
        "",
        LUMEN,
    );
    assert!(e.contains("outer") && e.contains("-0.5"), "{e}");
    // the luminal closure's wall concentration is the wall's own
    let fixed = r#"{"model": "mass-transfer", "k": 1.0, "wall_concentration": 0.08}"#;
    let e = bad(&tissue(ok, nf), "", fixed);
    assert!(
        e.contains("vessel 'tube'") && e.contains("luminal closure"),
        "{e}"
    );
    let e = bad(
        &tissue(ok, nf),
        r#""formulation": "tl-quasisteady","#,
        LUMEN,
    );
    assert!(e.contains("conservative"), "{e}");
}
