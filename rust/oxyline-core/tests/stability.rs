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
