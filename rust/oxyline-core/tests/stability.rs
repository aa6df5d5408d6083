//! RK4 stability bound: the Krylov estimate against the dense spectrum of the same operator
//! (faer's dense eigensolver, a code path independent of the Arnoldi iteration).

use oxyline_core::network::parse;
use oxyline_core::stability::{SpectrumMethod, rk4_limit_by};
use oxyline_core::{Regime, rk4::Rk4};

/// A chain of `n` vessels (radii tapering 1.2 → 0.3 cm with a deterministic wiggle, so the
/// segments differ and the spectrum has no symmetry) from a flow inlet to a resistance outlet.
fn chain(n: usize, segments: usize) -> String {
    let vessels: Vec<String> = (0..n)
        .map(|i| {
            let f = i as f64 / n.max(2) as f64;
            let r = 0.012 - 0.009 * f + 0.001 * ((i * 37 % 11) as f64 / 11.0);
            let l = 0.02 + 0.01 * ((i * 13 % 7) as f64 / 7.0);
            format!(
                r#"{{"name": "v{i}", "from": "n{i}", "to": "n{}", "segments": {segments},
                    "geometry": {{"length": {l}, "radius_in": {r}, "radius_out": {r},
                    "wall_thickness": 1e-3, "youngs_modulus": 4e5}}}}"#,
                i + 1
            )
        })
        .collect();
    format!(
        r#"{{"vessels": [{}],
          "boundary_conditions": {{"n0": {{"type": "flow", "flow": {{"kind": "constant", "value": 1e-6}}}},
                                   "n{n}": {{"type": "resistance", "resistance": 1e8}}}}}}"#,
        vessels.join(",")
    )
}

/// (dense, krylov) limits and the number of differential unknowns.
fn limits(json: &str) -> (f64, f64, usize) {
    let spec = parse(json).unwrap();
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let mut rk = Rk4::new(&dae, Regime::Transient, 1.0).unwrap();
    let dense = rk4_limit_by(&mut rk, &dae.names, SpectrumMethod::Dense).unwrap();
    let krylov = rk4_limit_by(&mut rk, &dae.names, SpectrumMethod::Krylov).unwrap();
    assert!(dense.exact && !krylov.exact, "{} unknowns", rk.diff.len());
    (dense.dt_max, krylov.dt_max, rk.diff.len())
}

#[test]
fn krylov_limit_matches_the_dense_spectrum() {
    for (n, segments) in [(50, 1), (140, 2), (150, 2), (200, 2)] {
        let (dense, krylov, nd) = limits(&chain(n, segments));
        // conservative (never above the exact limit, up to the dense solver's rounding, 1e-9),
        // and tight: the residual push is stopped at 0.1 %, 2 % leaves room for a clustered top
        let ratio = krylov / dense;
        assert!(
            ratio <= 1.0 + 1e-9 && ratio > 0.98,
            "{n} vessels ({nd} unknowns): krylov {krylov:e} dense {dense:e}"
        );
    }
}

/// the scale targets: a stiff wall exchange (k = 30 m/s, rate 2k/r = 2e4 /s in a 3 mm tube) made
/// RK4's automatic step unstable for the species (NaN in the O2 columns, exit 0). The step now
/// keeps the species rate at half RK4's real-axis limit, and the run stays finite and bounded
/// by the inlet and wall concentrations.
#[test]
fn stiff_wall_exchange_limits_the_automatic_rk4_step() {
    use oxyline_core::genalpha::NewtonControl;
    use oxyline_core::{Method, RunSettings, Start, Transport, simulate_with_transport};
    let (r, k, c_in, c_w) = (3e-3, 30.0, 1.0, 0.2);
    let json = format!(
        r#"{{"vessels": [{{"name": "tube", "from": "in", "to": "out", "segments": 10,
            "geometry": {{"length": 0.1, "radius_in": {r}, "radius_out": {r},
                          "wall_thickness": 1e-3, "youngs_modulus": 4e5}}}}],
          "boundary_conditions": {{"in": {{"type": "flow", "flow": {{"kind": "constant", "value": 5e-6}}}},
                                   "out": {{"type": "resistance", "resistance": 1e8}}}},
          "transport": {{"species": [{{"name": "o2", "inlet": {{"kind": "constant", "value": {c_in}}},
              "wall": {{"model": "mass-transfer", "k": {k}, "wall_concentration": {c_w}}}}}]}}}}"#
    );
    let spec = parse(&json).unwrap();
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let mut transport = Transport::build(
        spec.transport.as_ref().unwrap(),
        &assembled.circuit,
        &dae,
        &assembled.probes,
    )
    .unwrap();
    let s = RunSettings {
        method: Method::Rk4,
        dt: None,
        period: 1.0,
        cycles: 1,
        until_periodic: None,
        max_cycles: 1,
        output_every: 1e-2,
        output_all_cycles: true,
        keep_current_cycle: true,
        start: Start::Steady,
        newton: NewtonControl::default(),
        probes: vec![],
        species_columns: None,
        tolerances: None,
        svzerod: Default::default(),
    };
    let out = simulate_with_transport(&dae, Some(&mut transport), &s, &mut |_, _| true).unwrap();
    assert!(out.error.is_none(), "{:?}", out.error);
    // the exchange rate 2k/r at half RK4's real-axis limit 2.785 (1 % for the volume change)
    assert!(
        out.dt <= 0.5 * 2.785 / (2.0 * k / r) * 1.01,
        "dt {:e}",
        out.dt
    );
    // amounts finite, non-negative, and at most the inlet concentration times the tube's
    // volume (maximum principle; 5 % for the compliant volume change)
    let z = &out.transport.as_ref().unwrap().final_state;
    let cells = &z[..transport.n_cells()];
    let total = std::f64::consts::PI * r * r * 0.1;
    assert!(
        cells.iter().all(|a| a.is_finite() && *a >= 0.0),
        "{cells:?}"
    );
    assert!(
        cells.iter().sum::<f64>() <= 1.05 * c_in * total,
        "{cells:?}"
    );
    assert!(cells.iter().sum::<f64>() >= 0.95 * c_w * total, "{cells:?}");
}

/// the scale targets: a generalized-α run computes no RK4 stability limit (its first pass with the
/// default closure included), an RK4 run reports the limit its step obeys.
#[test]
fn only_rk4_runs_probe_the_rk4_limit() {
    use oxyline_core::genalpha::NewtonControl;
    use oxyline_core::{Method, RunSettings, Start, Transport, simulate_with_transport};
    let json = r#"{"vessels": [{"name": "tube", "from": "in", "to": "out", "segments": 4,
            "geometry": {"length": 0.1, "radius_in": 3e-3, "radius_out": 3e-3,
                         "wall_thickness": 1e-3, "youngs_modulus": 4e5}}],
          "boundary_conditions": {"in": {"type": "flow", "flow": {"kind": "fourier", "period": 1.0,
                                          "mean": 5e-6, "sin": [8e-6]}},
                                  "out": {"type": "resistance", "resistance": 1e8}},
          "transport": {"species": [{"name": "o2", "diffusivity": 1.2e-9, "inlet": {"kind": "constant", "value": 1.0},
              "wall": {"model": "graetz", "wall_concentration": 0.2}}]}}"#;
    let spec = parse(json).unwrap();
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let prototype = Transport::build(
        spec.transport.as_ref().unwrap(),
        &assembled.circuit,
        &dae,
        &assembled.probes,
    )
    .unwrap();
    for (method, dt) in [
        (Method::GeneralizedAlpha { rho_inf: 0.5 }, Some(1e-3)),
        (Method::Rk4, None),
    ] {
        let s = RunSettings {
            method,
            dt,
            period: 1.0,
            cycles: 1,
            until_periodic: None,
            max_cycles: 1,
            output_every: 1e-2,
            output_all_cycles: true,
            keep_current_cycle: true,
            start: Start::Steady,
            newton: NewtonControl::default(),
            probes: vec![],
            species_columns: None,
            tolerances: None,
            svzerod: Default::default(),
        };
        let mut tr = prototype.new_run();
        let out = simulate_with_transport(&dae, Some(&mut tr), &s, &mut |_, _| true).unwrap();
        assert!(out.error.is_none(), "{:?}", out.error);
        let rk4 = matches!(method, Method::Rk4);
        assert_eq!(out.stability.is_some(), rk4, "{method:?}");
        if let Some(lim) = &out.stability {
            assert!(out.dt <= lim.dt_max, "dt {} above {}", out.dt, lim.dt_max);
        }
    }
}
