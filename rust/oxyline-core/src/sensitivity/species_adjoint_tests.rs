//! The oxygen adjoint against the forward tangents (an independent linearisation: the
//! tangent steps forwards, the adjoint transposes each step) on the same periodic cycle, for
//! every oxygen parameter kind × several functionals, and against central differences of
//! whole periodic runs for a few. Both runs iterate to a relative periodic change of 1e-13,
//! so they agree to ~1e-11 of a gradient's scale; 1e-8 tells a wrong transpose (an O(1)
//! error in some term) from a right one.

use super::super::tests::{MODEL, consuming, oxygen, run, scaled, settings, signals};
use super::*;
use crate::model::parse;

/// Functionals of the signals (n_steps × n_signals): the cycle mean of each signal, a
/// weighted series of each (weights varying over the cycle, so a step's own derivative
/// counts), and an SvO2-like flow-weighted saturation Σ Q S / Σ Q of d1 (weights chosen
/// from the cycle's values, as a target's are).
fn weights(ns: usize, values: &[f64], sig: &[(String, String)]) -> Vec<f64> {
    let nsig = sig.len();
    let mut w = mean_and_series_weights(ns, nsig);
    let at = |name: &str| {
        sig.iter()
            .position(|(v, s)| v == "d1" && s == name)
            .unwrap()
    };
    let (q, s) = (at("flow_out"), at("saturation_out"));
    let total: f64 = (0..ns).map(|k| values[k * nsig + q]).sum();
    let mut f = vec![0.0; ns * nsig];
    for k in 0..ns {
        // d(Σ Q S/Σ Q) = Σ Q S′/Σ Q when the flow does not change
        f[k * nsig + s] = values[k * nsig + q] / total;
    }
    w.extend(f);
    w
}

/// Two functionals per signal, one block of `ns * nsig` weights each: its cycle mean, and a
/// series weighted by 0.3 + sin(0.37 k) over the cycle (so that a step's own derivative
/// counts).
pub(crate) fn mean_and_series_weights(ns: usize, nsig: usize) -> Vec<f64> {
    let mut w = Vec::new();
    for j in 0..nsig {
        for series in [false, true] {
            let mut f = vec![0.0; ns * nsig];
            for k in 0..ns {
                let weight = if series {
                    0.3 + (k as f64 * 0.37).sin()
                } else {
                    1.0
                };
                f[k * nsig + j] = weight / ns as f64;
            }
            w.extend(f);
        }
    }
    w
}

/// The adjoint gradients and the forward tangents' gradients of the same functionals; the
/// largest difference relative to each functional's largest |dJ/d ln θ|.
fn adjoint_against_forward(spec: &NetworkSpec, paths: &[&str]) -> f64 {
    let sig = signals();
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let set = settings();
    let ns = set.steps_per_cycle;
    let mut w_used = Vec::new();
    let (values, adj) = species_adjoint_with(
        spec,
        &owned,
        &sig,
        |_, v| {
            w_used = weights(ns, v, &sig);
            Ok(w_used.clone())
        },
        set,
    )
    .unwrap();
    let fwd = run(spec, paths);
    let (np, nsig) = (paths.len(), sig.len());
    for (f, w) in w_used.chunks(ns * nsig).enumerate() {
        let j: f64 = w.iter().zip(&fwd.signals).map(|(a, b)| a * b).sum();
        assert!((adj.functionals[f] - j).abs() <= 1e-9 * j.abs().max(1e-300));
    }
    worst_against_forward(&w_used, ns * nsig, np, &values, &adj.gradients, &fwd.derivs)
}

/// The adjoint's gradients of the mean-and-series functionals of `sig` against the forward
/// tangents of the same signals: the worst difference, in units of each functional's largest
/// |dJ/d ln θ| ([`worst_against_forward`]).
pub(crate) fn mean_and_series_adjoint_worst(
    spec: &NetworkSpec,
    paths: &[&str],
    sig: &[(String, String)],
) -> f64 {
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let ns = settings().steps_per_cycle;
    let weights = mean_and_series_weights(ns, sig.len());
    let (values, adj) =
        species_adjoint_with(spec, &owned, sig, |_, _| Ok(weights.clone()), settings()).unwrap();
    let fwd = super::super::tests::run_with(spec, paths, sig);
    worst_against_forward(
        &weights,
        ns * sig.len(),
        paths.len(),
        &values,
        &adj.gradients,
        &fwd.derivs,
    )
}

/// The largest difference of the adjoint's gradients (`gradients[f * np + p]`) from the
/// forward tangents (`derivs[p * block ..]`) contracted with each functional's weights (one
/// `block` of `weights` per functional), each in units of its functional's largest
/// |dJ/d ln θ| (the parameter `values` turn derivatives into logarithmic ones).
pub(crate) fn worst_against_forward(
    weights: &[f64],
    block: usize,
    np: usize,
    values: &[f64],
    gradients: &[f64],
    derivs: &[f64],
) -> f64 {
    let mut worst = 0.0f64;
    for (f, w) in weights.chunks(block).enumerate() {
        let g: Vec<f64> = (0..np)
            .map(|p| {
                let d = &derivs[p * block..(p + 1) * block];
                w.iter().zip(d).map(|(a, b)| a * b).sum()
            })
            .collect();
        let scale = (g.iter().zip(values)).fold(0.0f64, |m, (d, v)| m.max((d * v).abs()));
        for p in 0..np {
            let e = (gradients[f * np + p] - g[p]).abs() * values[p].abs();
            if scale > 0.0 {
                worst = worst.max(e / scale);
            }
        }
    }
    worst
}

#[test]
fn adjoint_equals_forward_on_every_oxygen_parameter_kind() {
    let mt = parse(MODEL).unwrap();
    let e = adjoint_against_forward(
        &mt,
        &["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"],
    );
    eprintln!("adjoint vs forward, mass-transfer wall: {e:.2e}");
    assert!(e < 1e-8, "mass-transfer wall: {e:.2e}");
    let e = adjoint_against_forward(&consuming(), &["oxygen.wall.flux", "oxygen.hill.p50"]);
    eprintln!("adjoint vs forward, consumption flux: {e:.2e}");
    assert!(e < 1e-8, "consumption flux: {e:.2e}");
    // a daughter's own wall beside the section's
    let mut own = parse(MODEL).unwrap();
    oxygen(&mut own).per_vessel.insert(
        "d1".into(),
        WallSpec::MassTransfer {
            k: 2e-3,
            wall_concentration: 0.04,
            permeability: None,
        },
    );
    let e = adjoint_against_forward(
        &own,
        &[
            "oxygen.per_vessel.d1.wall.k",
            "oxygen.per_vessel.d1.wall.concentration",
            "oxygen.wall.k",
            "oxygen.hill.p50",
        ],
    );
    eprintln!("adjoint vs forward, own wall: {e:.2e}");
    assert!(e < 1e-8, "a vessel's own wall: {e:.2e}");
}

/// The adjoint of the cycle-mean outlet PO2 and the flow-weighted saturation of d1 against
/// central differences of whole periodic runs (relative step 1e-4: truncation and rounding
/// below 1e-7 of the derivative, as the forward tests find).
#[test]
fn adjoint_against_central_differences() {
    let spec = parse(MODEL).unwrap();
    let sig = signals();
    let (ns, nsig) = (settings().steps_per_cycle, sig.len());
    let at = |name: &str| {
        sig.iter()
            .position(|(v, s)| v == "d1" && s == name)
            .unwrap()
    };
    let (po2, sat, q) = (at("po2_out"), at("saturation_out"), at("flow_out"));
    let functionals = |v: &[f64]| {
        let mean = (0..ns).map(|k| v[k * nsig + po2]).sum::<f64>() / ns as f64;
        let qs: f64 = (0..ns).map(|k| v[k * nsig + q] * v[k * nsig + sat]).sum();
        let qt: f64 = (0..ns).map(|k| v[k * nsig + q]).sum();
        [mean, qs / qt]
    };
    let paths = ["oxygen.wall.k", "oxygen.hill.p50"];
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let (values, adj) = species_adjoint_with(
        &spec,
        &owned,
        &sig,
        |_, v| {
            let w = weights(ns, v, &sig);
            // the PO2 mean (its first functional) and the SvO2-like one (the last)
            let per = ns * nsig;
            let mut out = w[2 * po2 * per..(2 * po2 + 1) * per].to_vec();
            out.extend_from_slice(&w[w.len() - per..]);
            Ok(out)
        },
        settings(),
    )
    .unwrap();
    let h = 1e-4;
    for (p, path) in paths.iter().enumerate() {
        let up = functionals(&run(&scaled(spec.clone(), path, 1.0 + h), &[]).signals);
        let down = functionals(&run(&scaled(spec.clone(), path, 1.0 - h), &[]).signals);
        for f in 0..2 {
            let cd = (up[f] - down[f]) / (2.0 * h * values[p]);
            let a = adj.gradients[f * paths.len() + p];
            eprintln!("{path}, functional {f}: {:.2e}", (a - cd).abs() / cd.abs());
            assert!(
                (a - cd).abs() <= 1e-6 * cd.abs(),
                "{path}, functional {f}: adjoint {a:e}, central difference {cd:e}"
            );
        }
    }
}

/// Flow parameters (a vessel's radius, length and stiffness, a Windkessel's R and C, the
/// inflow scale) beside oxygen ones: the adjoint contracts each step's forcing by the flow's
/// tangent with the species adjoint, the forward tangent solves the species step for it;
/// both read the same flow tangent, so they agree to the periodic tolerance as the oxygen
/// parameters do (1e-8: see the module doc).
#[test]
fn adjoint_equals_forward_on_flow_parameters() {
    let paths = [
        "vessels.parent.radius",
        "vessels.d2.length",
        "vessels.d1.youngs_modulus",
        "boundary_conditions.o1.distal_resistance",
        "boundary_conditions.o1.capacitance",
        "boundary_conditions.o2.resistance",
        "scale.inflow",
        "oxygen.wall.k",
    ];
    let e = adjoint_against_forward(&parse(MODEL).unwrap(), &paths);
    eprintln!("adjoint vs forward, flow parameters: {e:.2e}");
    assert!(e < 1e-8, "flow parameters: {e:.2e}");
    // a prescribed consumption: the wall's uptake moves with the wall area (r, L)
    let paths = [
        "vessels.d2.radius",
        "vessels.parent.length",
        "oxygen.wall.flux",
    ];
    let e = adjoint_against_forward(&consuming(), &paths);
    eprintln!("adjoint vs forward, flow parameters with consumption: {e:.2e}");
    assert!(e < 1e-8, "flow parameters with consumption: {e:.2e}");
}

/// The adjoint of the cycle-mean outlet PO2 of d1 and the network's mean consumption by
/// flow parameters against central differences of whole periodic runs (relative step 1e-4,
/// as for the oxygen parameters: truncation and rounding below 1e-7 of the derivative). The
/// consumption carries ~1e-12 of its value in rounding (a difference of accumulators over
/// every cycle), so a quotient is judged to 1e-6 of itself or to that rounding over the
/// step, 1e-12 |J| / (h θ), whichever is larger (the compliance barely moves it).
#[test]
fn flow_parameters_adjoint_against_central_differences() {
    let spec = parse(MODEL).unwrap();
    let sig = signals();
    let (ns, nsig) = (settings().steps_per_cycle, sig.len());
    let at = |v: &str, name: &str| sig.iter().position(|(a, b)| a == v && b == name).unwrap();
    let cols = [at("d1", "po2_out"), at("", "consumption")];
    let mean = |v: &[f64], j: usize| (0..ns).map(|k| v[k * nsig + j]).sum::<f64>() / ns as f64;
    let paths = [
        "vessels.parent.radius",
        "boundary_conditions.o1.capacitance",
        "scale.inflow",
    ];
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let (values, adj) = species_adjoint_with(
        &spec,
        &owned,
        &sig,
        |_, _| {
            let mut w = vec![0.0; 2 * ns * nsig];
            for (f, &j) in cols.iter().enumerate() {
                for k in 0..ns {
                    w[(f * ns + k) * nsig + j] = 1.0 / ns as f64;
                }
            }
            Ok(w)
        },
        settings(),
    )
    .unwrap();
    let h = 1e-4;
    for (p, path) in paths.iter().enumerate() {
        let up = run(&scaled(spec.clone(), path, 1.0 + h), &[]).signals;
        let down = run(&scaled(spec.clone(), path, 1.0 - h), &[]).signals;
        for (f, &j) in cols.iter().enumerate() {
            let cd = (mean(&up, j) - mean(&down, j)) / (2.0 * h * values[p]);
            let a = adj.gradients[f * paths.len() + p];
            let floor = 1e-12 * adj.functionals[f].abs() / (h * values[p].abs());
            eprintln!("{path}, functional {f}: {:.2e}", (a - cd).abs() / cd.abs());
            assert!(
                (a - cd).abs() <= (1e-6 * cd.abs()).max(floor),
                "{path}, functional {f}: adjoint {a:e}, central difference {cd:e}"
            );
        }
    }
}

/// A flow parameter path that does not resolve is an error naming it.
#[test]
fn unknown_flow_paths_are_refused_by_name() {
    let paths = vec![
        "oxygen.wall.k".to_string(),
        "vessels.nope.radius".to_string(),
    ];
    let e = species_adjoint_with(
        &parse(MODEL).unwrap(),
        &paths,
        &signals(),
        |_, _| Ok(vec![]),
        settings(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("nope"), "{e}");
}
