//! Species transport verification (docs/physics.md §6 (a)–(e), (h)): every expected value is a
//! closed form, a number of the spec, or a conservation law.

mod common;

use common::{Built, build, build_error};
use oxyline_core::rk4::CoupledStages;
use oxyline_core::transport::{BALANCE_COLUMNS, SEGMENT_COLUMNS, VESSEL_COLUMNS};
use oxyline_core::{Method, RunSettings, simulate_with_transport};
use std::f64::consts::PI;

const MMHG: f64 = 133.322_368;

/// Single tube from `in` to `out`, flow inlet, resistance outlet, with a transport section
/// of one species (the shared fixture, `common::tube`).
fn tube(
    radius: f64,
    length: f64,
    n: usize,
    wall: &str,
    flow: &str,
    r_out: f64,
    species: &str,
) -> String {
    common::tube(
        radius,
        length,
        n,
        wall,
        flow,
        r_out,
        &format!(r#""species": [{species}]"#),
    )
}

/// Drive a rigid tube with a prescribed flow q(t) in every branch (prescribed-flow path).
fn run_prescribed(
    b: &mut Built,
    q: &dyn Fn(f64) -> f64,
    dt: f64,
    steps: usize,
) -> (Vec<f64>, Vec<f64>) {
    let nn = b.dae.n_nodes;
    let n = b.dae.n;
    let mut y = vec![0.0; n];
    y[nn..].iter_mut().for_each(|v| *v = q(0.0));
    let mut z = b.transport.initial_state(&y).unwrap();
    let z0 = z.clone();
    let mut st = CoupledStages::new(z.len());
    let mut flow = |t: f64, y: &mut [f64]| {
        for v in &mut y[nn..] {
            *v = q(t);
        }
    };
    for k in 0..steps {
        b.transport
            .step_prescribed(k as f64 * dt, dt, &mut flow, &mut y, &mut z, &mut st)
            .unwrap();
    }
    (z0, z)
}

fn cell_conc(b: &Built, z: &[f64]) -> Vec<f64> {
    // concentrations of the tube's segments in order (rigid: V = V0)
    let nseg = b.assembled.circuit.segments.len();
    (0..nseg)
        .map(|j| {
            let c = b.transport.segment_cell(j).unwrap();
            z[c] / b.assembled.circuit.segments[j].volume
        })
        .collect()
}

#[test]
fn a_constant_wall_flux_steady_profile_is_exact() {
    let (r, dx, n, q, qw) = (8e-3, 0.02, 10, 2e-5, 1.7e-7);
    let c_in = 85.0 * 1.34e-3;
    let sp = format!(
        r#"{{"name": "o2", "inlet": {{"kind": "constant", "value": {c_in}}}, "wall": {{"model": "flux", "flux": {qw}}}}}"#
    );
    let mut b = build(&tube(
        r,
        dx * n as f64,
        n,
        "",
        r#"{"kind": "constant", "value": 2e-5}"#,
        1e7,
        &sp,
    ));
    let (_, z) = run_prescribed(&mut b, &|_| q, 1e-3, 20_000);
    let c = cell_conc(&b, &z);
    let mut worst = 0.0f64;
    for (k, ck) in c.iter().enumerate() {
        let exact = c_in - (k + 1) as f64 * 2.0 * PI * r * dx * qw / q;
        worst = worst.max((ck / exact - 1.0).abs());
    }
    assert!(worst < 1e-12, "max relative error {worst:e}");
    assert!((c[n - 1] - 0.113814548679822).abs() < 1e-12 * 0.1138);
    let dj = q * c_in - q * c[n - 1];
    assert!(
        (dj / 1.709026403553e-9 - 1.0).abs() < 1e-9,
        "J_in − J_out = {dj:e}"
    );
}

fn constant_k_theta(n: usize) -> f64 {
    let (r, l, q) = (1.5e-3, 9.0 * 3.84e-3, 1.6e-6);
    let alpha = 1.4e-3;
    let k = 0.5 * q / (2.0 * PI * r * l);
    let (cw, cin) = (48.0 * alpha, 85.0 * alpha);
    let sp = format!(
        r#"{{"name": "o2", "inlet": {{"kind": "constant", "value": {cin}}},
            "wall": {{"model": "mass-transfer", "k": {k}, "wall_concentration": {cw}}}}}"#
    );
    let mut b = build(&tube(
        r,
        l,
        n,
        "",
        r#"{"kind": "constant", "value": 1.6e-6}"#,
        1e7,
        &sp,
    ));
    // V/Q per cell = transit / n; 60 transit times reach the steady state to round-off
    let transit = PI * r * r * l / q;
    let dt = (transit / n as f64) * 0.2;
    let steps = (60.0 * transit / dt) as usize;
    let (_, z) = run_prescribed(&mut b, &|_| q, dt, steps);
    let c = cell_conc(&b, &z);
    (c[n - 1] - cw) / (cin - cw)
}

#[test]
fn b_constant_k_discrete_formula_and_first_order_convergence() {
    let t9 = constant_k_theta(9);
    assert!((t9 - 0.6147098006316).abs() < 1e-10, "θ_N = {t9}");
    let exact = (-0.5f64).exp();
    let errs: Vec<f64> = [9, 18, 36, 72]
        .iter()
        .map(|&n| constant_k_theta(n) - exact)
        .collect();
    for (n, e) in [9i32, 18, 36, 72].iter().zip(&errs) {
        let discrete = (1.0 + 0.5 / *n as f64).powi(-*n) - exact;
        assert!((e - discrete).abs() < 1e-10, "N={n}");
    }
    assert!((errs[0] - 8.179e-3).abs() < 1e-6);
    for w in errs.windows(2) {
        let ratio = w[0] / w[1];
        assert!((ratio - 2.0).abs() < 0.05, "convergence ratio {ratio}");
    }
}

/// Regularised lower incomplete gamma P(k, x) for integer k: 1 − e^{−x} Σ_{j<k} x^j/j!.
fn gammainc_int(k: usize, x: f64) -> f64 {
    let (mut term, mut sum) = (1.0, 1.0);
    for j in 1..k {
        term *= x / j as f64;
        sum += term;
    }
    1.0 - (-x).exp() * sum
}

#[test]
fn d_step_response_is_the_tanks_in_series_law() {
    let (r, dx, n, v) = (8e-3, 0.02, 10, 0.1);
    let q = v * PI * r * r;
    let sp = r#"{"name": "dye", "inlet": {"kind": "constant", "value": 1.0}, "initial": 0.0}"#;
    let mut b = build(&tube(
        r,
        dx * n as f64,
        n,
        "",
        &format!(r#"{{"kind": "constant", "value": {q}}}"#),
        1e7,
        sp,
    ));
    let dt = 5e-4;
    let mut worst = 0.0f64;
    let nn = b.dae.n_nodes;
    let mut y = vec![0.0; b.dae.n];
    y[nn..].iter_mut().for_each(|x| *x = q);
    let mut z = b.transport.initial_state(&y).unwrap();
    let mut st = CoupledStages::new(z.len());
    let mut flow = |_: f64, _: &mut [f64]| {};
    let expected = [
        (2000, 0.0318280573),
        (4000, 0.5420702855),
        (6000, 0.9301463393),
    ];
    for step in 1..=6000 {
        b.transport
            .step_prescribed(
                (step - 1) as f64 * dt,
                dt,
                &mut flow,
                &mut y,
                &mut z,
                &mut st,
            )
            .unwrap();
        if step % 100 == 0 {
            let t = step as f64 * dt;
            let c = cell_conc(&b, &z);
            for (k, ck) in c.iter().enumerate() {
                worst = worst.max((ck - gammainc_int(k + 1, v * t / dx)).abs());
            }
            if let Some(&(_, e)) = expected.iter().find(|(s, _)| *s == step) {
                assert!((c[n - 1] - e).abs() < 1e-10, "t={t}: c10 = {}", c[n - 1]);
            }
        }
    }
    assert!(worst < 1e-12, "max |c − P(k, vt/dx)| = {worst:e}");
}

#[test]
fn e1_rigid_pulsatile_flow_with_reversal_conserves_mass() {
    let alpha = 1.34e-3;
    let (r, dx, n) = (8e-3, 0.02, 10);
    let sp = format!(
        r#"{{"name": "o2", "inlet": {{"kind": "fourier", "period": 1.0, "mean": {m}, "sin": [{a}]}},
            "wall": {{"model": "mass-transfer", "k": 5e-6, "wall_concentration": {cw}}}}}"#,
        m = 85.0 * alpha,
        a = 5.0 * alpha,
        cw = 60.0 * alpha
    );
    let flow = r#"{"kind": "fourier", "period": 1.0, "mean": 2e-5, "sin": [3e-5]}"#;
    let mut b = build(&tube(r, dx * n as f64, n, "", flow, 1e7, &sp));
    let q = |t: f64| 2e-5 * (1.0 + 1.5 * (2.0 * PI * t).sin());
    let (z0, z) = run_prescribed(&mut b, &q, 1e-4, 30_000);
    let nc = b.transport.n_cells();
    let stored: f64 = z[..nc].iter().sum::<f64>() - z0[..nc].iter().sum::<f64>();
    let (i_in, i_out, i_wall) = (z[nc], z[nc + 1], z[nc + 2]);
    assert!(i_out != 0.0);
    let residual = stored - (i_in - i_out - i_wall);
    assert!(
        residual.abs() <= 1e-12 * i_in,
        "relative residual {:e}",
        residual / i_in
    );
    // reversal happened and the field stayed within the inlet/wall bounds
    let c = cell_conc(&b, &z);
    assert!(
        c.iter().all(|&x| x > 59.0 * alpha && x < 91.0 * alpha),
        "{c:?}"
    );
}

fn settings(method: Method, dt: f64, cycles: usize, probes: Vec<usize>) -> RunSettings {
    RunSettings {
        cycles,
        max_cycles: cycles,
        output_all_cycles: true,
        ..RunSettings::one_cycle(method, Some(dt), probes)
    }
}

/// O2 solubility (mol m⁻³ mmHg⁻¹): the tests' concentrations are PO2s in mmHg times it.
const ALPHA: f64 = 1.4e-3;

/// A mass-transfer wall (k = 5e-6 m/s) at a wall PO2 of 60 mmHg.
fn wall_60() -> String {
    format!(
        r#"{{"model": "mass-transfer", "k": 5e-6, "wall_concentration": {}}}"#,
        60.0 * ALPHA
    )
}

/// An inlet PO2 of 85 ± 5 mmHg over a 1 s cycle.
fn pulsatile_inlet() -> String {
    format!(
        r#"{{"kind": "fourier", "period": 1.0, "mean": {}, "sin": [{}]}}"#,
        85.0 * ALPHA,
        5.0 * ALPHA
    )
}

/// Run `b` to the end (flow and transport) without checking the run's own error.
fn outcome(b: &mut Built, s: &RunSettings) -> oxyline_core::Outcome {
    simulate_with_transport(&b.dae, Some(&mut b.transport), s, &mut |_, _| true).unwrap()
}

/// The largest |c/c0 − 1| over the segment concentrations `segments` of every recorded row
/// (`vessels` vessel column groups first).
fn free_stream_error(
    t: &oxyline_core::TransportOutcome,
    vessels: usize,
    segments: usize,
    c0: f64,
) -> f64 {
    let mut worst = 0.0f64;
    for row in t.data.chunks(t.columns_per_species) {
        for j in 0..segments {
            let c = row[VESSEL_COLUMNS * vessels + SEGMENT_COLUMNS * j];
            worst = worst.max((c / c0 - 1.0).abs());
        }
    }
    worst
}

/// (e2)/(e3): compliant abdominal tube, R_out in series with the last branch, reversing flow.
fn abdominal(wall: &str, cin: &str) -> Built {
    let sp = format!(
        r#"{{"name": "o2", "inlet": {cin}, "initial": {c0}, "wall": {wall}}}"#,
        c0 = 85.0 * 1.4e-3
    );
    let flow = r#"{"kind": "fourier", "period": 1.0, "mean": 2e-5, "sin": [3e-5]}"#;
    build(&tube(
        8e-3,
        0.2,
        10,
        r#", "wall_thickness": 2e-3, "youngs_modulus": 5.11e6"#,
        flow,
        0.0865 * MMHG * 1e6,
        &sp,
    ))
}

/// Run `b` to the end (flow and transport), which must succeed.
fn run(b: &mut Built, s: &RunSettings) -> oxyline_core::Outcome {
    let out = outcome(b, s);
    assert!(out.error.is_none(), "{:?}", out.error);
    out
}

fn balance_residual(out: &oxyline_core::Outcome) -> (f64, f64) {
    let t = out.transport.as_ref().unwrap();
    let cols = t.columns_per_species;
    let last = &t.data[t.data.len() - cols..];
    let bal = &last[cols - BALANCE_COLUMNS..];
    let (stored, i_in, i_out, i_wall, i_decay) = (bal[0], bal[1], bal[2], bal[3], bal[4]);
    let residual = stored - t.initial_stored[0] - (i_in - i_out - i_wall - i_decay);
    (residual, i_in)
}

#[test]
fn e2_e3_compliant_monolithic_rk4_balance_and_free_stream() {
    let alpha = 1.4e-3;
    for method in [Method::Rk4, Method::GeneralizedAlpha { rho_inf: 0.5 }] {
        let mut b = abdominal(&wall_60(), &pulsatile_inlet());
        let out = run(&mut b, &settings(method, 1e-4, 2, vec![]));
        let (res, i_in) = balance_residual(&out);
        assert!(
            res.abs() <= 1e-12 * i_in,
            "{method:?}: relative residual {:e}",
            res / i_in
        );

        // (e3) free stream: c_in = c0, no wall
        let mut b = abdominal(
            r#"{"model": "none"}"#,
            &format!(r#"{{"kind": "constant", "value": {}}}"#, 85.0 * alpha),
        );
        let out = outcome(&mut b, &settings(method, 1e-4, 2, vec![]));
        let worst = free_stream_error(out.transport.as_ref().unwrap(), 1, 10, 85.0 * alpha);
        assert!(worst <= 1e-12, "{method:?}: free-stream error {worst:e}");
    }
}

#[test]
fn e4_coronary_free_stream_with_compliant_volumes() {
    let alpha = 1.4e-3;
    let sp = format!(
        r#"{{"name": "o2", "inlet": {{"kind": "constant", "value": {c}}}}}"#,
        c = 85.0 * alpha
    );
    let flow = r#"{"kind": "fourier", "period": 1.0, "mean": 1.6e-6, "sin": [0.8e-6]}"#;
    let mut b = build(&tube(
        1.5e-3,
        9.0 * 3.84e-3,
        9,
        r#", "wall_thickness": 1.8e-4, "youngs_modulus": 7e5, "poisson_ratio": 0.49"#,
        flow,
        55.6 * MMHG * 1e6,
        &sp,
    ));
    let out = outcome(&mut b, &settings(Method::Rk4, 1e-4, 2, vec![]));
    let worst = free_stream_error(out.transport.as_ref().unwrap(), 1, 9, 85.0 * alpha);
    assert!(worst <= 1e-12, "free-stream error {worst:e}");
}

#[test]
fn h1_inductor_flux_linkage_equals_minus_the_amount() {
    let mut b = abdominal(&wall_60(), &pulsatile_inlet());
    let out = outcome(&mut b, &settings(Method::Rk4, 1e-4, 1, vec![]));
    let t = out.transport.as_ref().unwrap();
    let cols = t.columns_per_species;
    let row = &t.data[t.data.len() - cols..];
    let z = &t.final_state;
    let mut checked = 0;
    // interior segments (cells holding one segment each); the inlet cell is shared with nothing
    // here either, so all 10 qualify
    for j in 0..10 {
        let base = VESSEL_COLUMNS + SEGMENT_COLUMNS * j;
        let (flux, l_tl) = (row[base + 1], row[base + 4]);
        if l_tl.is_nan() || flux <= 0.0 {
            continue;
        }
        let n = z[b.transport.segment_cell(j).unwrap()];
        assert!(
            (l_tl * flux / -n - 1.0).abs() < 1e-13,
            "segment {j}: L J = {:e}, −N = {:e}",
            l_tl * flux,
            -n
        );
        checked += 1;
    }
    assert!(checked >= 5);
}

#[test]
fn h3_quasi_steady_equals_conservative_at_steady_state() {
    let alpha = 1.4e-3;
    let mk = |form: &str| {
        let sp = format!(
            r#"{{"name": "o2", "inlet": {{"kind": "constant", "value": {cin}}},
                "wall": {{"model": "mass-transfer", "k": 2e-5, "wall_concentration": {cw}}}}}"#,
            cin = 85.0 * alpha,
            cw = 48.0 * alpha
        );
        let json = tube(
            1.5e-3,
            0.0346,
            9,
            r#", "wall_thickness": 1.8e-4, "youngs_modulus": 7e5"#,
            r#"{"kind": "constant", "value": 1.6e-6}"#,
            55.6 * MMHG * 1e6,
            &sp,
        )
        .replace(
            r#""transport": {"#,
            &format!(r#""transport": {{"formulation": "{form}", "#),
        );
        build(&json)
    };
    let mut results = Vec::new();
    for form in ["conservative", "tl-quasisteady"] {
        let mut b = mk(form);
        let out = outcome(&mut b, &settings(Method::Rk4, 1e-4, 3, vec![]));
        let t = out.transport.as_ref().unwrap();
        let cols = t.columns_per_species;
        let row = t.data[t.data.len() - cols..].to_vec();
        results.push(
            (0..9)
                .map(|j| row[VESSEL_COLUMNS + SEGMENT_COLUMNS * j])
                .collect::<Vec<_>>(),
        );
    }
    for (a, q) in results[0].iter().zip(&results[1]) {
        assert!((a / q - 1.0).abs() < 1e-10, "{a} vs {q}");
    }
}

/// Backward-Euler sweep on a loop with circulating flow (a directed cycle: the Gauss–Seidel
/// fallback): every step conserves mass to round-off, amounts stay positive, and the steady
/// field solves the explicit balance dN/dt = 0.
#[test]
fn implicit_sweep_on_a_circulating_loop() {
    let json = r#"{"vessels": [
        {"name": "v0", "from": "in", "to": "A", "segments": 2, "geometry": {"length": 0.02, "radius_in": 2e-3, "radius_out": 2e-3}},
        {"name": "v1", "from": "A", "to": "B", "segments": 2, "geometry": {"length": 0.02, "radius_in": 2e-3, "radius_out": 2e-3}},
        {"name": "v2", "from": "B", "to": "C", "segments": 2, "geometry": {"length": 0.02, "radius_in": 2e-3, "radius_out": 2e-3}},
        {"name": "v3", "from": "C", "to": "A", "segments": 2, "geometry": {"length": 0.02, "radius_in": 2e-3, "radius_out": 2e-3}},
        {"name": "v4", "from": "C", "to": "out", "segments": 2, "geometry": {"length": 0.02, "radius_in": 2e-3, "radius_out": 2e-3}}],
      "boundary_conditions": {"in": {"type": "flow", "flow": {"kind": "constant", "value": 1e-6}},
                              "out": {"type": "resistance", "resistance": 1e8}},
      "transport": {"species": [{"name": "s", "inlet": {"kind": "constant", "value": 2.0}, "initial": 1.0,
                                 "wall": {"model": "mass-transfer", "k": 1e-5, "wall_concentration": 0.5}}]}}"#;
    let mut b = build(json);
    let (q, r) = (1e-6, 3e-6);
    let nn = b.dae.n_nodes;
    let mut y = vec![0.0; b.dae.n];
    for bi in 0..b.assembled.circuit.branches.len() {
        let name = b.assembled.circuit.names.branch(bi);
        let v = name.split('\'').nth(1).unwrap_or("");
        y[nn + bi] = match v {
            "v0" | "v4" => q,
            "v1" | "v2" => q + r,
            "v3" => r,
            _ => q, // the outlet resistance
        };
    }
    let mut z = b.transport.initial_state(&y).unwrap();
    let nc = b.transport.n_cells();
    let dt = 0.05;
    let mut worst: f64 = 0.0;
    for k in 0..400 {
        let before: f64 = z[..nc].iter().sum();
        let acc0: Vec<f64> = z[nc..nc + 4].to_vec();
        b.transport
            .implicit_step(k as f64 * dt, dt, 1.0, &y, &y, &mut z)
            .unwrap();
        let after: f64 = z[..nc].iter().sum();
        let d: Vec<f64> = (0..4).map(|i| z[nc + i] - acc0[i]).collect();
        let res = (after - before) - (d[0] - d[1] - d[2] - d[3]);
        worst = worst.max(res.abs() / before);
        assert!(z[..nc].iter().all(|&n| n > 0.0));
    }
    assert!(worst < 1e-13, "per-step relative mass residual {worst:e}");
    // steady state: the implicit field solves the explicit balance (dN/dt = 0)
    let mut dz = vec![0.0; z.len()];
    b.transport.rhs(0.0, &y, &z, &mut dz).unwrap();
    // flux scale: Q × concentration (≈ 1e-6 × 2 mol/s)
    let scale = (q + r) * 2.0;
    assert!(
        dz[..nc].iter().all(|d| d.abs() < 1e-9 * scale),
        "{:?}",
        &dz[..nc]
    );
}

// ---------------------------------------------------------------------------------------------
// Refinement: m transport cells per flow segment (docs/physics.md §5)

/// `json` with `"cells_per_segment": m` in its transport section.
fn refined(json: &str, m: usize) -> String {
    json.replace(
        r#""transport": {"#,
        &format!(r#""transport": {{"cells_per_segment": {m}, "#),
    )
}

/// Concentrations of every transport cell of a rigid tube in flow order (sub-cells of segment
/// 0 first), with V = V0/m.
fn chain_conc(b: &Built, z: &[f64]) -> Vec<f64> {
    let nseg = b.assembled.circuit.segments.len();
    let mut c = Vec::new();
    for j in 0..nseg {
        let cells = b.transport.segment_cells(j).unwrap();
        let v = b.assembled.circuit.segments[j].volume / cells.len() as f64;
        c.extend(cells.map(|i| z[i] / v));
    }
    c
}

/// (d) with N segments × m cells: a chain of N·m tanks, c_i(t) = P(i, v t m/dx); the
/// spatial spread of the front is σ_x = sqrt(x dx/m).
#[test]
fn d_refined_step_response_is_the_tanks_in_series_law_of_n_times_m_tanks() {
    // 30 segments: the Poisson tail of the front beyond the tube end is < 1e-13 at t = 1 s
    let (r, dx, n, v) = (8e-3, 0.02, 30, 0.1);
    let q = v * PI * r * r;
    let sp = r#"{"name": "dye", "inlet": {"kind": "constant", "value": 1.0}, "initial": 0.0}"#;
    let t_end = 1.0;
    let mut sigmas = Vec::new();
    for m in [1usize, 2, 4] {
        let mut b = build(&refined(
            &tube(
                r,
                dx * n as f64,
                n,
                "",
                &format!(r#"{{"kind": "constant", "value": {q}}}"#),
                1e7,
                sp,
            ),
            m,
        ));
        assert_eq!(b.transport.n_cells(), n * m);
        let rate = v * m as f64 / dx;
        let dt = 2e-3 / rate; // Courant 2e-3
        let steps = (t_end / dt).round() as usize;
        let (_, z) = run_prescribed(&mut b, &|_| q, dt, steps);
        let t = steps as f64 * dt;
        let c = chain_conc(&b, &z);
        let worst = c
            .iter()
            .enumerate()
            .map(|(i, ci)| (ci - gammainc_int(i + 1, rate * t)).abs())
            .fold(0.0f64, f64::max);
        eprintln!("(d) m={m}: max |c − P(i, vtm/dx)| = {worst:e}");
        assert!(worst < 1e-12, "m={m}: max |c − P(i, vtm/dx)| = {worst:e}");
        // front: cell i holds the mass c_{i−1} − c_i of dc/dx (c_0 = 1 at the inlet)
        let h = dx / m as f64;
        let (mut s0, mut s1, mut s2) = (0.0, 0.0, 0.0);
        let mut prev = 1.0;
        for (i, &ci) in c.iter().enumerate() {
            let (w, x) = (prev - ci, i as f64 * h);
            (s0, s1, s2) = (s0 + w, s1 + w * x, s2 + w * x * x);
            prev = ci;
        }
        let mean = s1 / s0;
        let sigma = (s2 / s0 - mean * mean).sqrt();
        assert!(
            (mean / (v * t) - 1.0).abs() < 1e-6,
            "m={m}: front at {mean}"
        );
        assert!(
            (sigma / (v * t * dx / m as f64).sqrt() - 1.0).abs() < 1e-6,
            "m={m}: σ_x = {sigma}"
        );
        eprintln!("(d) m={m}: front {mean}, σ_x = {sigma}");
        sigmas.push(sigma);
    }
    for w in sigmas.windows(2) {
        assert!((w[0] / w[1] - 2f64.sqrt()).abs() < 1e-9, "{sigmas:?}");
    }
}

fn constant_k_theta_refined(n: usize, m: usize) -> f64 {
    let (r, l, q) = (1.5e-3, 9.0 * 3.84e-3, 1.6e-6);
    let alpha = 1.4e-3;
    let k = 0.5 * q / (2.0 * PI * r * l);
    let (cw, cin) = (48.0 * alpha, 85.0 * alpha);
    let sp = format!(
        r#"{{"name": "o2", "inlet": {{"kind": "constant", "value": {cin}}},
            "wall": {{"model": "mass-transfer", "k": {k}, "wall_concentration": {cw}}}}}"#
    );
    let flow = r#"{"kind": "constant", "value": 1.6e-6}"#;
    let mut b = build(&refined(&tube(r, l, n, "", flow, 1e7, &sp), m));
    let transit = PI * r * r * l / q;
    let dt = (transit / (n * m) as f64) * 0.2;
    let steps = (60.0 * transit / dt) as usize;
    let (_, z) = run_prescribed(&mut b, &|_| q, dt, steps);
    let c = chain_conc(&b, &z);
    (c[n * m - 1] - cw) / (cin - cw)
}

/// (b) with refinement: the discrete law (1 + St/(N m))^{−N m}, first order in m.
#[test]
fn b_refined_constant_k_discrete_formula_and_first_order_in_m() {
    let exact = (-0.5f64).exp();
    let mut errs = Vec::new();
    for m in [1usize, 2, 4, 8] {
        let th = constant_k_theta_refined(9, m);
        let nm = (9 * m) as i32;
        let discrete = (1.0 + 0.5 / nm as f64).powi(-nm);
        assert!(
            (th - discrete).abs() < 1e-10,
            "m={m}: θ = {th} vs {discrete}"
        );
        eprintln!(
            "(b) m={m}: θ = {th}, |θ − discrete| = {:e}",
            (th - discrete).abs()
        );
        errs.push(th - exact);
    }
    for w in errs.windows(2) {
        let ratio = w[0] / w[1];
        eprintln!("(b) error ratio per doubling of m: {ratio}");
        assert!((ratio - 2.0).abs() < 0.05, "convergence ratio in m {ratio}");
    }
}

/// Compliant Y network with a reversing inflow; `cells_per_segment` 3 with a per-vessel 2.
fn refined_y(wall: &str, cin: &str, m: usize) -> Built {
    let c0 = 85.0 * 1.4e-3;
    let geo = r#""wall_thickness": 5e-4, "youngs_modulus": 1e6"#;
    let json = format!(
        r#"{{"vessels": [
        {{"name": "p", "from": "in", "to": "J", "segments": 4, "geometry": {{"length": 0.08, "radius_in": 4e-3, "radius_out": 4e-3, {geo}}}}},
        {{"name": "d1", "from": "J", "to": "o1", "segments": 3, "geometry": {{"length": 0.05, "radius_in": 3e-3, "radius_out": 3e-3, {geo}}}}},
        {{"name": "d2", "from": "J", "to": "o2", "segments": 3, "geometry": {{"length": 0.06, "radius_in": 2.5e-3, "radius_out": 2.5e-3, {geo}}}}}],
      "boundary_conditions": {{"in": {{"type": "flow", "flow": {{"kind": "fourier", "period": 1.0, "mean": 5e-6, "sin": [8e-6]}}}},
                              "o1": {{"type": "rcr", "proximal_resistance": 1e7, "capacitance": 1e-9, "distal_resistance": 1e8}},
                              "o2": {{"type": "resistance", "resistance": 2e8}}}},
      "transport": {{"cells_per_segment": {m}, "cells_per_vessel": {{"d2": 2}},
        "species": [{{"name": "o2", "diffusivity": 1.2e-9, "inlet": {cin}, "initial": {c0}, "wall": {wall}}}]}}}}"#
    );
    build(&json)
}

#[test]
fn refined_network_balance_is_exact_and_free_stream_is_preserved() {
    let alpha = 1.4e-3;
    let walls = [
        wall_60(),
        // the boundary-layer shear as extra state (enhanced so that the uptake matters)
        format!(
            r#"{{"model": "leveque", "shear": "relaxed", "enhancement": 50, "wall_concentration": {}}}"#,
            60.0 * alpha
        ),
    ];
    let methods = [Method::Rk4, Method::GeneralizedAlpha { rho_inf: 0.5 }];
    // RK4 keeps both to ~5e-15; the implicit path rounds each of its 2e4 steps (measured
    // 6e-13 after 2 s on this network, the same with m = 1)
    const TOL: f64 = 1e-11;
    for (method, wall) in methods
        .iter()
        .flat_map(|m| walls.iter().map(move |w| (*m, w)))
    {
        let mut b = refined_y(wall, &pulsatile_inlet(), 3);
        // inverted-L: p 4 nodes × 3, the junction node (holding d1's and d2's first segments)
        // takes the finer m = 3, then d1 2 × 3 and d2 2 × 2
        assert_eq!(b.transport.n_cells(), 12 + 3 + 6 + 4);
        let out = run(&mut b, &settings(method, 1e-4, 2, vec![]));
        let (res, i_in) = balance_residual(&out);
        assert!(
            res.abs() <= TOL * i_in,
            "{method:?}: relative residual {:e}",
            res / i_in
        );
        eprintln!(
            "refined Y {method:?} {}: relative residual {:e}",
            &wall[..30],
            res / i_in
        );
        // the inflow reverses: the inlet flux column changes sign
        let t = out.transport.as_ref().unwrap();
        let cols = t.columns_per_species;
        assert!(t.data.chunks(cols).any(|row| row[2] < 0.0));

        // free stream: uniform c stays uniform in every (sub-)cell
        let c0 = 85.0 * alpha;
        let mut b = refined_y(
            r#"{"model": "none"}"#,
            &format!(r#"{{"kind": "constant", "value": {c0}}}"#),
            3,
        );
        let out = outcome(&mut b, &settings(method, 1e-4, 2, vec![]));
        let t = out.transport.as_ref().unwrap();
        let cols = t.columns_per_species;
        let nseg = b.assembled.circuit.segments.len();
        let mut worst = 0.0f64;
        for row in t.data.chunks(cols) {
            // reported vessel values, then the segments
            let nv = (cols - BALANCE_COLUMNS - SEGMENT_COLUMNS * nseg) / VESSEL_COLUMNS;
            for k in 0..nv {
                for c in [row[VESSEL_COLUMNS * k], row[VESSEL_COLUMNS * k + 1]] {
                    worst = worst.max((c / c0 - 1.0).abs());
                }
            }
            for j in 0..nseg {
                let c = row[VESSEL_COLUMNS * nv + SEGMENT_COLUMNS * j];
                worst = worst.max((c / c0 - 1.0).abs());
            }
        }
        // sub-cells of one node hold equal volumes, so equal amounts
        let z = &t.final_state;
        for j in 0..nseg {
            let cells = b.transport.segment_cells(j).unwrap();
            let first = z[cells.start];
            for i in cells {
                worst = worst.max((z[i] / first - 1.0).abs());
            }
        }
        eprintln!("refined Y {method:?}: free-stream error {worst:e}");
        assert!(worst <= TOL, "{method:?}: free-stream error {worst:e}");
    }
}

/// The Lévêque law integrated over the sub-intervals sums to the segment's law exactly
/// ((3/2) a (x_b^{2/3} − x_a^{2/3}) telescopes): with a uniform field the reported wall flux
/// of every segment is the same for m = 1 and m = 4.
#[test]
fn refined_leveque_pieces_sum_to_the_segment_law() {
    let alpha = 1.4e-3;
    let sp = format!(
        r#"{{"name": "o2", "diffusivity": 1.2e-9, "inlet": {{"kind": "constant", "value": {}}},
            "wall": {{"model": "leveque", "wall_concentration": {}}}}}"#,
        85.0 * alpha,
        60.0 * alpha
    );
    let flow = r#"{"kind": "constant", "value": 2e-5}"#;
    let walls: Vec<Vec<f64>> = [1usize, 4]
        .iter()
        .map(|&m| {
            let mut b = build(&refined(&tube(8e-3, 0.2, 10, "", flow, 1e7, &sp), m));
            let mut s = settings(Method::GeneralizedAlpha { rho_inf: 0.5 }, 1e-3, 1, vec![]);
            s.output_every = 0.5;
            let out = outcome(&mut b, &s);
            let t = out.transport.as_ref().unwrap();
            (0..10)
                .map(|j| t.data[VESSEL_COLUMNS + SEGMENT_COLUMNS * j + 2])
                .collect()
        })
        .collect();
    for (a, b) in walls[0].iter().zip(&walls[1]) {
        assert!(*a > 0.0 && (a / b - 1.0).abs() < 1e-13, "{a} vs {b}");
    }
}

#[test]
fn bad_cells_per_segment_is_a_model_error_naming_key_and_value() {
    let sp = r#"{"name": "dye", "inlet": {"kind": "constant", "value": 1.0}}"#;
    let flow = r#"{"kind": "constant", "value": 1e-6}"#;
    let base = tube(1e-3, 0.01, 2, "", flow, 1e7, sp);
    for bad in ["0", "-1", "2.5", "1e9"] {
        let json = base.replace(
            r#""transport": {"#,
            &format!(r#""transport": {{"cells_per_segment": {bad}, "#),
        );
        let err = build_error(&json);
        let shown = bad.parse::<f64>().unwrap().to_string();
        assert!(
            err.contains("cells_per_segment") && err.contains(&shown),
            "{bad}: {err}"
        );
    }
    let json = base.replace(
        r#""transport": {"#,
        r#""transport": {"cells_per_vessel": {"nope": 2}, "#,
    );
    let err = build_error(&json);
    assert!(
        err.contains("cells_per_vessel") && err.contains("nope"),
        "{err}"
    );
}

// ---------------------------------------------------------------------------------------------
// Lévêque with `shear: relaxed` (docs/physics.md §3.1 "Pulsatility")

/// Rigid coronary tube with the relaxed Lévêque wall; Q(t) = Q0 (1 + a sin ωt), no reversal.
/// The relaxed equivalent flow solves Q̃' = (Q − Q̃)/τ from Q̃(0) = Q0 (the cycle mean):
///   Q̃ = Q0 + a Q0 [sin ωt − ωτ cos ωt + ωτ e^{−t/τ}]/(1 + ω²τ²),
/// τ = δ²/D, δ = Γ(4/3)(9 D x_mid/γ̄)^{1/3}, γ̄ = 4 Q0/(π r³). The reported wall flux is
/// coef Q̃^{1/3} (c − c_w) with the segment-integrated Lévêque coefficient.
#[test]
fn relaxed_shear_follows_the_linear_relaxation_law() {
    let (r, n, dx, q0, a, d) = (1.5e-3, 9, 3.84e-3, 1.6e-6, 0.5, 1.2e-9);
    let alpha = 1.4e-3;
    let (cin, cw) = (85.0 * alpha, 48.0 * alpha);
    let sp = format!(
        r#"{{"name": "o2", "diffusivity": {d}, "inlet": {{"kind": "constant", "value": {cin}}},
            "wall": {{"model": "leveque", "shear": "relaxed", "wall_concentration": {cw}}}}}"#
    );
    let flow = format!(r#"{{"kind": "constant", "value": {q0}}}"#);
    let mut b = build(&tube(r, dx * n as f64, n, "", &flow, 1e7, &sp));
    b.transport.set_mean_flow(&vec![q0; n]).unwrap();
    let omega = 2.0 * PI;
    let q = |t: f64| q0 * (1.0 + a * (omega * t).sin());
    let gamma43 = 0.892_979_511_569_249_2;
    let tau: Vec<f64> = (0..n)
        .map(|j| {
            let x = (j as f64 + 0.5) * dx;
            let delta = gamma43 * (9.0 * d * x / (4.0 * q0 / (PI * r.powi(3)))).cbrt();
            delta * delta / d
        })
        .collect();
    let exact = |j: usize, t: f64| {
        let wt = omega * tau[j];
        q0 + a * q0 * ((omega * t).sin() - wt * (omega * t).cos() + wt * (-t / tau[j]).exp())
            / (1.0 + wt * wt)
    };
    let coef = |j: usize| {
        let (x0, x1) = (j as f64 * dx, (j + 1) as f64 * dx);
        2.0 * PI * r * 1.5 * (4.0 / (PI * r.powi(3)) * d * d / 9.0).cbrt() / gamma43
            * (x1.powf(2.0 / 3.0) - x0.powf(2.0 / 3.0))
    };
    let nn = b.dae.n_nodes;
    let mut y = vec![0.0; b.dae.n];
    y[nn..].iter_mut().for_each(|v| *v = q(0.0));
    let mut z = b.transport.initial_state(&y).unwrap();
    let nc = b.transport.n_cells();
    assert_eq!(z.len(), nc + 4 + n);
    let mut st = CoupledStages::new(z.len());
    let mut set_flow = |t: f64, y: &mut [f64]| {
        for v in &mut y[nn..] {
            *v = q(t);
        }
    };
    let dt = 1e-3;
    let (mut worst_state, mut worst_law) = (0.0f64, 0.0f64);
    let mut spread = 0.0f64;
    for k in 0..3000 {
        b.transport
            .step_prescribed(k as f64 * dt, dt, &mut set_flow, &mut y, &mut z, &mut st)
            .unwrap();
        if (k + 1) % 50 != 0 {
            continue;
        }
        let t = (k + 1) as f64 * dt;
        set_flow(t, &mut y);
        let mut out = Vec::new();
        b.transport
            .observe(t, &y, None, &z, false, &mut out)
            .unwrap();
        for j in 0..n {
            let qe = exact(j, t);
            worst_state = worst_state.max((z[nc + 4 + j] / qe - 1.0).abs());
            let base = VESSEL_COLUMNS + SEGMENT_COLUMNS * j;
            let (c, wall) = (out[base], out[base + 2]);
            let g = coef(j) * qe.cbrt();
            worst_law = worst_law.max((wall / (g * (c - cw)) - 1.0).abs());
            spread = spread.max((qe / q(t) - 1.0).abs());
        }
    }
    eprintln!("relaxed shear: state error {worst_state:e}, law error {worst_law:e}");
    assert!(worst_state < 1e-10, "Q̃ vs closed form: {worst_state:e}");
    assert!(worst_law < 1e-10, "wall law vs closed form: {worst_law:e}");
    // the test discriminates: Q̃ is far from the instantaneous flow
    assert!(spread > 0.2, "{spread}");
}

/// Constant flow: relaxed, cycle-mean and instantaneous shear give the same results, with
/// both integrations.
#[test]
fn relaxed_cycle_mean_and_instantaneous_shear_agree_in_constant_flow() {
    let alpha = 1.4e-3;
    for method in [Method::Rk4, Method::GeneralizedAlpha { rho_inf: 0.5 }] {
        let mut rows = Vec::new();
        for shear in ["cycle-mean", "instantaneous", "relaxed"] {
            let sp = format!(
                r#"{{"name": "o2", "diffusivity": 1.2e-9, "inlet": {{"kind": "constant", "value": {cin}}},
                    "wall": {{"model": "leveque", "shear": "{shear}", "wall_concentration": {cw}}}}}"#,
                cin = 85.0 * alpha,
                cw = 48.0 * alpha
            );
            let mut b = build(&tube(
                1.5e-3,
                0.0346,
                9,
                r#", "wall_thickness": 1.8e-4, "youngs_modulus": 7e5"#,
                r#"{"kind": "constant", "value": 1.6e-6}"#,
                55.6 * MMHG * 1e6,
                &sp,
            ));
            let out = outcome(&mut b, &settings(method, 1e-4, 1, vec![]));
            rows.push(out.transport.unwrap().data);
        }
        for other in &rows[1..] {
            for (a, b) in rows[0].iter().zip(other) {
                assert!(
                    (a - b).abs() <= 1e-11 * a.abs().max(1e-300) || (a.is_nan() && b.is_nan()),
                    "{method:?}: {a} vs {b}"
                );
            }
        }
    }
}
