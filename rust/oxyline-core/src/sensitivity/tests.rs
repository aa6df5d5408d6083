//! Tangent sensitivities against central differences of the same periodic run, one test per
//! parameter kind. The difference quotient's error is O(h²) truncation plus rounding of
//! ~1e-16 × |signal| / (h p): with h = 1e-4 relative both are below 1e-8 of the derivative's
//! scale, so agreement to 1e-6 relative tells a wrong tangent from a right one.

use super::*;
use crate::model::{BoundarySpec, parse};
use crate::waveform::WaveformSpec;

/// An inflow (two harmonics) into a uniform elastic parent that splits into an elastic
/// daughter ending in an RCR and a lumped daughter ending in a resistance.
const MODEL: &str = r#"{
  "name": "y",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 3,
     "geometry": {"length": 0.1, "radius_in": 0.004, "radius_out": 0.004,
                  "wall_thickness": 0.0006, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "o1", "segments": 2,
     "geometry": {"length": 0.08, "radius_in": 0.003, "radius_out": 0.0025,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}},
    {"name": "d2", "from": "j", "to": "o2", "segments": 2,
     "lumped": {"resistance": 3e7, "inductance": 1e5, "capacitance": 2e-10}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 5e-6,
                                    "cos": [3e-6, -1e-6], "sin": [4e-6, 1e-6]}},
    "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-9,
           "distal_resistance": 1.2e9},
    "o2": {"type": "resistance", "resistance": 1.6e9}
  }
}"#;

pub(super) const SIGNALS: [(&str, &str); 4] = [
    ("parent", "pressure_in"),
    ("d1", "flow_out"),
    ("d2", "flow_in"),
    ("d1", "pressure_out"),
];

pub(super) fn settings() -> TangentSettings {
    TangentSettings {
        period: 0.8,
        steps_per_cycle: 200,
        rho_infty: 0.5,
        max_cycles: 400,
        tol: 1e-13,
    }
}

pub(super) fn run(spec: &NetworkSpec, paths: &[&str]) -> Sensitivities {
    let paths: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let signals: Vec<(String, String)> = SIGNALS
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    sensitivities(spec, &paths, &signals, settings()).unwrap()
}

/// [`MODEL`] with a stenosis in the lumped daughter: S Q² at its peak flow (~4e-6 m³/s) is
/// ~1.6× its linear drop R Q, so the nonlinear term matters as much as the linear one.
fn stenosed() -> NetworkSpec {
    let mut s = parse(MODEL).unwrap();
    let d2 = s.vessels.iter_mut().find(|v| v.name == "d2").unwrap();
    d2.lumped.as_mut().unwrap().stenosis_coefficient = 1.2e13;
    s
}

/// `s` with parameter `path` multiplied by `f`, written into the spec directly.
pub(super) fn scaled_from(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    let vi = |s: &NetworkSpec, n: &str| s.vessels.iter().position(|v| v.name == n).unwrap();
    let parts: Vec<&str> = path.split('.').collect();
    match parts.as_slice() {
        ["vessels", n, "length"] => {
            let i = vi(&s, n);
            s.vessels[i].geometry.as_mut().unwrap().length *= f;
        }
        ["vessels", n, "radius"] => {
            let i = vi(&s, n);
            let g = s.vessels[i].geometry.as_mut().unwrap();
            g.radius_in *= f;
            g.radius_out *= f;
        }
        ["vessels", n, "radius_in"] => {
            let i = vi(&s, n);
            s.vessels[i].geometry.as_mut().unwrap().radius_in *= f;
        }
        ["vessels", n, "radius_out"] => {
            let i = vi(&s, n);
            s.vessels[i].geometry.as_mut().unwrap().radius_out *= f;
        }
        ["vessels", n, "youngs_modulus"] => {
            let i = vi(&s, n);
            *s.vessels[i]
                .geometry
                .as_mut()
                .unwrap()
                .youngs_modulus
                .as_mut()
                .unwrap() *= f;
        }
        ["vessels", n, "lumped", "capacitance"] => {
            let i = vi(&s, n);
            s.vessels[i].lumped.as_mut().unwrap().capacitance *= f;
        }
        ["vessels", n, "lumped", "inductance"] => {
            let i = vi(&s, n);
            s.vessels[i].lumped.as_mut().unwrap().inductance *= f;
        }
        ["vessels", n, "lumped", "resistance"] => {
            let i = vi(&s, n);
            s.vessels[i].lumped.as_mut().unwrap().resistance *= f;
        }
        ["vessels", n, "lumped", "stenosis_coefficient"] => {
            let i = vi(&s, n);
            s.vessels[i].lumped.as_mut().unwrap().stenosis_coefficient *= f;
        }
        ["boundary_conditions", node, key] => match s.boundary_conditions.get_mut(*node) {
            Some(BoundarySpec::Resistance { resistance, .. }) => *resistance *= f,
            Some(BoundarySpec::Rcr {
                proximal_resistance,
                capacitance,
                distal_resistance,
                ..
            }) => match *key {
                "proximal_resistance" => *proximal_resistance *= f,
                "capacitance" => *capacitance *= f,
                _ => *distal_resistance *= f,
            },
            _ => unreachable!(),
        },
        ["scale", "resistance"] => {
            for bc in s.boundary_conditions.values_mut() {
                match bc {
                    BoundarySpec::Resistance { resistance, .. } => *resistance *= f,
                    BoundarySpec::Rcr {
                        proximal_resistance,
                        distal_resistance,
                        ..
                    } => {
                        *proximal_resistance *= f;
                        *distal_resistance *= f;
                    }
                    _ => {}
                }
            }
            for v in &mut s.vessels {
                if let Some(l) = v.lumped.as_mut() {
                    l.resistance *= f;
                }
            }
        }
        ["scale", "compliance"] => {
            for bc in s.boundary_conditions.values_mut() {
                if let BoundarySpec::Rcr { capacitance, .. } = bc {
                    *capacitance *= f;
                }
            }
            for v in &mut s.vessels {
                if let Some(l) = v.lumped.as_mut() {
                    l.capacitance *= f;
                }
                if let Some(g) = v.geometry.as_mut() {
                    *g.youngs_modulus.as_mut().unwrap() /= f;
                }
            }
        }
        ["scale", "inflow"] => {
            if let Some(BoundarySpec::Flow {
                flow: WaveformSpec::Fourier { mean, cos, sin, .. },
            }) = s.boundary_conditions.get_mut("in")
            {
                *mean *= f;
                cos.iter_mut().chain(sin.iter_mut()).for_each(|c| *c *= f);
            }
        }
        _ => unreachable!("{path}"),
    }
    s
}

/// Largest |tangent − central difference| over the cycle and signals, relative to the
/// derivative's scale per signal.
fn check(path: &str) {
    check_on(&parse(MODEL).unwrap(), path);
}

pub(super) fn check_on(base: &NetworkSpec, path: &str) {
    let exact = run(base, &[path]);
    let h = 1e-4;
    let up = run(&scaled_from(base.clone(), path, 1.0 + h), &[]);
    let down = run(&scaled_from(base.clone(), path, 1.0 - h), &[]);
    let p = exact.values[0];
    let c = &exact.cycle;
    // the cycle before the last one changed by at most `tol`; the last by about as much
    assert!(
        c.periodic_change <= 1e-11,
        "{path}: not periodic {}",
        c.periodic_change
    );
    let nsig = SIGNALS.len();
    for (j, signal) in SIGNALS.iter().enumerate() {
        let col = |v: &[f64]| -> Vec<f64> { v.iter().skip(j).step_by(nsig).copied().collect() };
        let (d, u, w) = (
            col(&c.derivs),
            col(&up.cycle.values),
            col(&down.cycle.values),
        );
        let scale = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{path}: zero derivative of {signal:?}");
        let worst = d
            .iter()
            .zip(u.iter().zip(&w))
            .map(|(dk, (uk, wk))| (dk - (uk - wk) / (2.0 * h * p)).abs())
            .fold(0.0f64, f64::max);
        eprintln!("{path} {signal:?}: {:.2e} of the scale", worst / scale);
        assert!(
            worst <= 1e-6 * scale,
            "{path} {signal:?}: {worst:e} vs scale {scale:e}"
        );
    }
}

#[test]
fn windkessel_and_resistance_conditions() {
    check("boundary_conditions.o1.proximal_resistance");
    check("boundary_conditions.o1.distal_resistance");
    check("boundary_conditions.o1.capacitance");
    check("boundary_conditions.o2.resistance");
}

#[test]
fn vessel_geometry_and_wall() {
    check("vessels.parent.length");
    check("vessels.d1.length");
    check("vessels.parent.radius");
    check("vessels.parent.youngs_modulus");
}

#[test]
fn lumped_values_and_scales() {
    check("vessels.d2.lumped.resistance");
    check("vessels.d2.lumped.capacitance");
    check("scale.resistance");
    check("scale.compliance");
    check("scale.inflow");
}

/// A stenosis: its own coefficient, and other kinds whose tangents now pass through the
/// per-step Newton matrices (the slope 2 S |Q| enters every tangent's homogeneous part).
#[test]
fn stenosis_coefficient_and_kinds_through_a_stenosis() {
    let base = stenosed();
    check_on(&base, "vessels.d2.lumped.stenosis_coefficient");
    check_on(&base, "vessels.d2.lumped.resistance");
    check_on(&base, "boundary_conditions.o2.resistance");
    check_on(&base, "vessels.parent.radius");
    check_on(&base, "scale.inflow");
}

/// A flow through a lone stenosis into a resistance is the quadratic
/// P = (R_out + R) Q + S Q² at every instant (no capacitance, inductance only in the
/// parent, which a constant inflow does not excite): d P/d S = Q² exactly.
#[test]
fn stenosis_derivative_of_a_steady_flow_is_q_squared() {
    let json = r#"{
      "name": "s",
      "vessels": [
        {"name": "st", "from": "in", "to": "out",
         "lumped": {"resistance": 1e7, "stenosis_coefficient": 5e12}}
      ],
      "boundary_conditions": {
        "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 4e-6,
                                        "cos": [], "sin": []}},
        "out": {"type": "resistance", "resistance": 1e8}
      }
    }"#;
    let spec = parse(json).unwrap();
    let out = sensitivities(
        &spec,
        &["vessels.st.lumped.stenosis_coefficient".to_owned()],
        &[("st".into(), "pressure_in".into())],
        settings(),
    )
    .unwrap();
    let q: f64 = 4e-6;
    let p = (1e8 + 1e7) * q + 5e12 * q * q;
    let c = &out.cycle;
    for (v, d) in c.values.iter().zip(&c.derivs) {
        assert!((v - p).abs() <= 1e-9 * p, "{v} vs {p}");
        assert!((d - q * q).abs() <= 1e-9 * q * q, "{d} vs {}", q * q);
    }
}

#[test]
fn several_parameters_share_one_run() {
    let base = parse(MODEL).unwrap();
    let one = run(&base, &["vessels.parent.radius"]);
    let two = run(
        &base,
        &["boundary_conditions.o2.resistance", "vessels.parent.radius"],
    );
    let n = one.cycle.derivs.len();
    // the same arithmetic for the same parameter; the runs may stop after different cycle
    // counts (the periodic test takes every tangent), within the periodic tolerance
    let scale = one.cycle.derivs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (a, b) in one.cycle.derivs.iter().zip(&two.cycle.derivs[n..]) {
        assert!((a - b).abs() <= 1e-9 * scale, "{a} {b}");
    }
}

#[test]
fn bad_paths_name_themselves() {
    let base = parse(MODEL).unwrap();
    let err = |p: &str| {
        sensitivities(&base, &[p.to_owned()], &[], settings())
            .err()
            .unwrap()
            .to_string()
    };
    assert!(err("vessels.nope.radius").contains("no vessel named 'nope'"));
    assert!(err("vessels.d1.radius").contains("tapered"));
    assert!(err("boundary_conditions.o2.capacitance").contains("'capacitance'"));
    assert!(err("boundary_conditions.zz.resistance").contains("node 'zz'"));
    assert!(err("blood.viscosity").contains("parameter 'blood.viscosity'"));
    assert!(err("vessels.parent.lumped.stenosis_coefficient").contains("no differentiable"));
    // the shape and keys through the model's path resolver: the scope's keys, the nearest
    let e = err("scale.inflw");
    assert!(
        e.ends_with(
            "parameter 'scale.inflw': unknown scale key (allowed: compliance, inflow, \
             resistance; nearest: inflow)"
        ),
        "{e}"
    );
    let e = err("vesels.parent.length");
    assert!(
        e.ends_with(
            "parameter 'vesels.parent.length': unknown parameter section (allowed: \
             boundary_conditions, scale, vessels; nearest: vessels)"
        ),
        "{e}"
    );
    let e = err("vessels.parent.lenght");
    assert!(e.contains("unknown vessel property (allowed: "), "{e}");
    assert!(e.ends_with("; nearest: length)"), "{e}");
    assert!(err("vessels.parent").ends_with("expected vessels.NAME.PROPERTY"));
    // a key the schema has that the condition lacks: its differentiable values named
    let e = err("boundary_conditions.o2.resistanse");
    assert!(
        e.ends_with(
            "the condition at node 'o2' has no differentiable value 'resistanse' \
             (differentiable: resistance; nearest: resistance)"
        ),
        "{e}"
    );
    let signal = sensitivities(&base, &[], &[("parent".into(), "speed".into())], settings())
        .err()
        .unwrap()
        .to_string();
    assert!(signal.contains("unknown variable 'speed'"), "{signal}");
}

/// The adjoint's gradient of a functional against the same functional of the forward
/// tangents (validated against central differences above): a mean of one signal, a weighted
/// sample of another and a spread of weights over a third. The two differ by the fixed
/// points' tolerances (1e-13 of the scale) and rounding, so 1e-8 relative tells a wrong
/// transpose, source or periodic coupling.
fn check_adjoint(base: &NetworkSpec, paths: &[&str]) {
    check_adjoint_of(base, paths, &SIGNALS);
}

pub(super) fn check_adjoint_of(base: &NetworkSpec, paths: &[&str], signals: &[(&str, &str)]) {
    let ns = settings().steps_per_cycle;
    let nsig = signals.len();
    let mut w = vec![0.0; 2 * ns * nsig];
    for k in 0..ns {
        w[k * nsig] = 1.0 / ns as f64; // mean inlet pressure
        w[k * nsig + 2] = ((k * 7) % 11) as f64 * 1e6; // a spread over d2's inflow
    }
    w[ns * nsig + 37 * nsig + 1] = 1.0; // d1's outflow at step 37
    w[ns * nsig + 120 * nsig + 3] = -0.5; // minus half d1's outlet pressure at step 120
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let sig: Vec<(String, String)> = signals
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    let (_, adj) = adjoint(base, &owned, &sig, &w, settings()).unwrap();
    let fwd = sensitivities(base, &owned, &sig, settings()).unwrap();
    let np = paths.len();
    for f in 0..2 {
        let wf = &w[f * ns * nsig..(f + 1) * ns * nsig];
        let value: f64 = wf.iter().zip(&fwd.cycle.values).map(|(a, b)| a * b).sum();
        assert!((adj.values[f] - value).abs() <= 1e-9 * value.abs(), "J_{f}");
        let scale = (0..np)
            .map(|p| {
                let d = &fwd.cycle.derivs[p * ns * nsig..(p + 1) * ns * nsig];
                (wf.iter().zip(d).map(|(a, b)| a * b).sum::<f64>() * fwd.values[p]).abs()
            })
            .fold(0.0f64, f64::max);
        for (p, path) in paths.iter().enumerate() {
            let d = &fwd.cycle.derivs[p * ns * nsig..(p + 1) * ns * nsig];
            let tangent: f64 = wf.iter().zip(d).map(|(a, b)| a * b).sum();
            let got = adj.gradients[f * np + p];
            assert!(
                (got - tangent).abs() * fwd.values[p].abs() <= 1e-8 * scale,
                "{path} J_{f}: adjoint {got:e} vs tangent {tangent:e}"
            );
        }
    }
    assert!(
        adj.adjoint_cycles
            .iter()
            .all(|&c| c < settings().max_cycles)
    );
}

#[test]
fn adjoint_gradients_are_the_tangents() {
    let all = [
        "boundary_conditions.o1.proximal_resistance",
        "boundary_conditions.o1.capacitance",
        "boundary_conditions.o2.resistance",
        "vessels.parent.radius",
        "vessels.d1.youngs_modulus",
        "vessels.d2.lumped.inductance",
        "scale.compliance",
        "scale.inflow",
    ];
    check_adjoint(&parse(MODEL).unwrap(), &all);
    let mut stenosed_paths = all.to_vec();
    stenosed_paths.push("vessels.d2.lumped.stenosis_coefficient");
    check_adjoint(&stenosed(), &stenosed_paths);
}

/// A left heart between a venous pressure and a Windkessel: a tanh mitral valve, an
/// elastance-inductor chamber with a half-cosine activation, a tanh aortic valve and a
/// lumped aorta. The valves switch over ~1/k = 200 Pa (smooth on the step grid), so central
/// differences with h = 1e-4 resolve their derivatives like any other kind's.
const HEART: &str = r#"{
  "name": "left-heart",
  "vessels": [
    {"name": "mitral", "from": "ven", "to": "mv_out",
     "valve": {"law": "tanh", "min_resistance": 2e6, "max_resistance": 1e10, "steepness": 5e-3}},
    {"name": "lv", "from": "mv_out", "to": "lv_out",
     "chamber": {"law": "elastance-inductor", "max_elastance": 3.0e8, "min_elastance": 1.3e7,
                 "rest_volume_diastole": 2e-5, "rest_volume_systole": 1e-5,
                 "activation": {"kind": "half-cosine", "t_active": 0.1, "t_twitch": 0.35},
                 "period": 0.8, "inductance": 1e5, "initial_volume": 1.2e-4}},
    {"name": "aortic", "from": "lv_out", "to": "ao",
     "valve": {"law": "tanh", "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}},
    {"name": "aorta", "from": "ao", "to": "out",
     "lumped": {"resistance": 5e6, "inductance": 1e5, "capacitance": 3e-9}}
  ],
  "boundary_conditions": {
    "ven": {"type": "pressure", "pressure": {"kind": "fourier", "period": 0.8, "mean": 1200.0,
                                             "cos": [], "sin": []}},
    "out": {"type": "rcr", "proximal_resistance": 1e7, "capacitance": 1.2e-8,
            "distal_resistance": 1.3e8}
  }
}"#;

const HEART_SIGNALS: [(&str, &str); 4] = [
    ("lv", "pressure_in"),
    ("aortic", "flow_in"),
    ("aorta", "pressure_out"),
    ("mitral", "flow_in"),
];

/// `spec` with the heart parameter `path` multiplied by `f`.
fn heart_scaled(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    use crate::model::{ActivationSpec, ChamberLawSpec, ValveSpec};
    let parts: Vec<&str> = path.split('.').collect();
    let v = s.vessels.iter_mut().find(|v| v.name == parts[1]).unwrap();
    match (parts[2], v.chamber.as_deref_mut(), v.valve.as_deref_mut()) {
        (
            "valve",
            _,
            Some(ValveSpec::Tanh {
                min_resistance,
                max_resistance,
                steepness,
            }),
        ) => match parts[3] {
            "min_resistance" => *min_resistance *= f,
            "max_resistance" => *max_resistance *= f,
            _ => *steepness *= f,
        },
        ("chamber", Some(c), _) => match (&mut c.law, &mut c.activation, parts[3]) {
            (_, ActivationSpec::HalfCosine { t_active, t_twitch }, "activation") => {
                match parts[4] {
                    "t_active" => *t_active *= f,
                    _ => *t_twitch *= f,
                }
            }
            (
                ChamberLawSpec::ElastanceInductor {
                    max_elastance,
                    min_elastance,
                    rest_volume_diastole,
                    rest_volume_systole,
                },
                _,
                key,
            ) => match key {
                "max_elastance" => *max_elastance *= f,
                "min_elastance" => *min_elastance *= f,
                "rest_volume_diastole" => *rest_volume_diastole *= f,
                _ => *rest_volume_systole *= f,
            },
            _ => unreachable!("{path}"),
        },
        _ => unreachable!("{path}"),
    }
    s
}

fn heart_run(spec: &NetworkSpec, paths: &[&str]) -> Sensitivities {
    let paths: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let signals: Vec<(String, String)> = HEART_SIGNALS
        .iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    sensitivities(spec, &paths, &signals, settings()).unwrap()
}

/// Tangent vs central differences (as [`check_on`]) on the heart model, per kind.
fn check_heart(path: &str) {
    let base = parse(HEART).unwrap();
    let exact = heart_run(&base, &[path]);
    // φ is C¹ but not C² in the activation's timing (its square-law ends move across the
    // step grid): the difference quotient's error is O(h), not O(h²), so a smaller step
    let h = if path.contains(".activation.") {
        1e-5
    } else {
        1e-4
    };
    let up = heart_run(&heart_scaled(base.clone(), path, 1.0 + h), &[]);
    let down = heart_run(&heart_scaled(base.clone(), path, 1.0 - h), &[]);
    let p = exact.values[0];
    let c = &exact.cycle;
    assert!(c.periodic_change <= 1e-11, "{path}: {}", c.periodic_change);
    let nsig = HEART_SIGNALS.len();
    for (j, signal) in HEART_SIGNALS.iter().enumerate() {
        let col = |v: &[f64]| -> Vec<f64> { v.iter().skip(j).step_by(nsig).copied().collect() };
        let (d, u, w) = (
            col(&c.derivs),
            col(&up.cycle.values),
            col(&down.cycle.values),
        );
        let scale = d.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(scale > 0.0, "{path}: zero derivative of {signal:?}");
        let worst = d
            .iter()
            .zip(u.iter().zip(&w))
            .map(|(dk, (uk, wk))| (dk - (uk - wk) / (2.0 * h * p)).abs())
            .fold(0.0f64, f64::max);
        eprintln!("{path} {signal:?}: {:.2e}", worst / scale);
        assert!(
            worst <= 1e-6 * scale,
            "{path} {signal:?}: {worst:e} vs scale {scale:e}"
        );
    }
}

#[test]
fn heart_chamber_parameters() {
    check_heart("vessels.lv.chamber.max_elastance");
    check_heart("vessels.lv.chamber.min_elastance");
    check_heart("vessels.lv.chamber.rest_volume_diastole");
    check_heart("vessels.lv.chamber.rest_volume_systole");
    check_heart("vessels.lv.chamber.activation.t_active");
    check_heart("vessels.lv.chamber.activation.t_twitch");
}

#[test]
fn heart_valve_coefficients() {
    check_heart("vessels.aortic.valve.min_resistance");
    check_heart("vessels.aortic.valve.max_resistance");
    check_heart("vessels.aortic.valve.steepness");
    check_heart("vessels.mitral.valve.min_resistance");
}

#[test]
fn heart_adjoint_gradients_are_the_tangents() {
    let paths = [
        "vessels.lv.chamber.max_elastance",
        "vessels.lv.chamber.min_elastance",
        "vessels.lv.chamber.activation.t_twitch",
        "vessels.aortic.valve.min_resistance",
        "vessels.mitral.valve.steepness",
        "boundary_conditions.out.distal_resistance",
        "vessels.aorta.lumped.capacitance",
    ];
    check_adjoint_of(&parse(HEART).unwrap(), &paths, &HEART_SIGNALS);
}

#[test]
fn bad_heart_paths_name_themselves() {
    let base = parse(HEART).unwrap();
    let err = |p: &str| {
        sensitivities(&base, &[p.to_owned()], &[], settings())
            .err()
            .unwrap()
            .to_string()
    };
    let e = err("vessels.lv.chamber.passive_elastance");
    assert!(
        e.contains("'vessels.lv.chamber.passive_elastance'") && e.contains("no differentiable"),
        "{e}"
    );
    let e = err("vessels.aorta.valve.min_resistance");
    assert!(e.contains("is not a valve"), "{e}");
    let e = err("vessels.lv.chamber.activation.t_shift");
    assert!(e.contains("'activation.t_shift'"), "{e}");
    let e = err("vessels.mitral.valve.width");
    assert!(e.contains("'vessels.mitral.valve.width'"), "{e}");
}

/// The chamber value `key` of `e` (None: its law has no such value), for a test to change.
fn chamber_value_mut<'e>(
    e: &'e mut crate::element::chamber::Elastance,
    key: &str,
) -> Option<&'e mut f64> {
    use crate::element::activation::Activation;
    use crate::element::chamber::ElastanceLaw as L;
    let Activation::HalfCosine { t_active, t_twitch } = &mut e.activation else {
        return None;
    };
    match (&mut e.law, key) {
        (_, "activation.t_active") => Some(t_active),
        (_, "activation.t_twitch") => Some(t_twitch),
        (L::ElastanceInductor { e_max, .. }, "max_elastance")
        | (L::Linear { e_max, .. }, "max_elastance")
        | (L::Exponential { e_max, .. }, "max_elastance") => Some(e_max),
        (L::ElastanceInductor { e_min, .. }, "min_elastance") => Some(e_min),
        (
            L::ElastanceInductor {
                v_rest_diastole, ..
            },
            "rest_volume_diastole",
        ) => Some(v_rest_diastole),
        (L::ElastanceInductor { v_rest_systole, .. }, "rest_volume_systole") => {
            Some(v_rest_systole)
        }
        (L::Linear { e_pass, .. }, "passive_elastance") => Some(e_pass),
        (L::Linear { v_rest, .. }, "rest_volume")
        | (L::Exponential { v_aso: v_rest, .. }, "rest_volume") => Some(v_rest),
        (L::Exponential { k_pressure, .. }, "passive_pressure") => Some(k_pressure),
        (L::Exponential { k_volume, .. }, "passive_volume_coefficient") => Some(k_volume),
        _ => None,
    }
}

/// Every chamber law's ∂P/∂θ (the tangent's element source) against central differences of
/// P(V, t) in θ (relative step 1e-6: truncation O(h²) and rounding ~1e-16/h, both far below
/// 1e-7 of the derivative), at times before, during and after the twitch.
#[test]
fn chamber_pressure_derivatives_of_every_law() {
    use crate::element::activation::Activation;
    use crate::element::chamber::{Elastance, ElastanceLaw};
    let laws = [
        ElastanceLaw::ElastanceInductor {
            e_max: 3e8,
            e_min: 1.3e7,
            v_rest_diastole: 2e-5,
            v_rest_systole: 1e-5,
        },
        ElastanceLaw::Linear {
            e_max: 3e8,
            e_pass: 1.2e7,
            v_rest: 1.5e-5,
        },
        ElastanceLaw::Exponential {
            e_max: 2e7,
            k_pressure: 50.0,
            k_volume: 3e4,
            v_aso: 1e-5,
        },
    ];
    let keys = [
        "max_elastance",
        "min_elastance",
        "rest_volume_diastole",
        "rest_volume_systole",
        "passive_elastance",
        "rest_volume",
        "passive_pressure",
        "passive_volume_coefficient",
        "activation.t_active",
        "activation.t_twitch",
    ];
    let mut checked = 0;
    for law in laws {
        let mut base = Elastance {
            law,
            activation: Activation::HalfCosine {
                t_active: 0.1,
                t_twitch: 0.35,
            },
            period: 0.8,
        };
        for key in keys {
            for (t, v) in [(0.05, 1.1e-4), (0.2, 9e-5), (0.37, 6e-5), (0.7, 1.2e-4)] {
                let exact = base.pressure_derivative(key, t, v);
                let Some(x0) = chamber_value_mut(&mut base, key).map(|x| *x) else {
                    assert!(exact.is_none(), "{key}: a law without it");
                    continue;
                };
                let h = 1e-6 * x0.abs();
                let at = |x: f64| {
                    let mut e = base.clone();
                    *chamber_value_mut(&mut e, key).unwrap() = x;
                    e.pressure(t, v).0
                };
                let fd = (at(x0 + h) - at(x0 - h)) / (2.0 * h);
                let d = exact.unwrap_or_else(|| panic!("{key} at {t}"));
                // the response to a 100 % change, floored by the pressure's own size
                let scale = (x0 * d).abs().max(1e-6 * base.pressure(t, v).0.abs());
                assert!(
                    ((d - fd) * x0).abs() <= 1e-7 * scale,
                    "{key} at t {t}: {d:e} vs {fd:e}"
                );
                checked += 1;
            }
        }
    }
    assert_eq!(checked, 4 * (6 + 5 + 6));
}

/// A closed loop without boundary conditions: a left ventricle between tanh valves, an aorta
/// and a systemic bed back to the mitral valve; the blood is the ventricle's start volume.
const CLOSED_LOOP: &str = r#"{
  "name": "loop",
  "vessels": [
    {"name": "mitral", "from": "ven", "to": "mv_out", "valve": {"law": "tanh",
     "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}},
    {"name": "lv", "from": "mv_out", "to": "lv_out", "chamber": {
      "law": "elastance-inductor", "max_elastance": 3.0e8, "min_elastance": 1.3e7,
      "rest_volume_diastole": 2e-5, "rest_volume_systole": 1e-5, "period": 0.8,
      "inductance": 1e4, "initial_volume": 1.0e-4,
      "activation": {"kind": "half-cosine", "t_active": 0.1, "t_twitch": 0.35}}},
    {"name": "aortic", "from": "lv_out", "to": "ao", "valve": {"law": "tanh",
     "min_resistance": 3e6, "max_resistance": 1e10, "steepness": 5e-3}},
    {"name": "aorta", "from": "ao", "to": "art",
     "lumped": {"resistance": 5e6, "inductance": 1e5, "capacitance": 1.2e-8}},
    {"name": "systemic", "from": "art", "to": "ven",
     "lumped": {"resistance": 1.4e8, "capacitance": 5e-8}}
  ],
  "boundary_conditions": {}
}"#;

/// The blood volume Σ C P + Σ V_chamber of state `y` (the circuit's node capacitances and
/// its chambers' volume unknowns): the conservation law, apart from the DAE's rows.
fn blood_volume(circuit: &crate::circuit::Circuit, caps: &[f64], y: &[f64]) -> f64 {
    let (nn, nb) = (circuit.nodes.len(), circuit.branches.len());
    let nodes: f64 = caps.iter().zip(y).map(|(c, p)| c * p).sum();
    let chambers: f64 = (circuit.moved_rows.iter())
        .map(|&(_, x)| y[nn + nb + x])
        .sum();
    nodes + chambers
}

/// The tangent of the blood volume after every step of the periodic cycle is the volume
/// change of the start values (dC · P₀: the runs from the same start values hold their
/// volume), for a capacitance (which changes it) and an elastance (which does not); the
/// primal's volume is the start values' to Newton's tolerance.
#[test]
fn closed_loop_tangent_holds_the_blood_volume() {
    let spec = parse(CLOSED_LOOP).unwrap();
    let assembled = spec.assemble().unwrap();
    let circuit = &assembled.circuit;
    let dae = circuit.assemble().unwrap();
    let volume = ConservedVolume::of(circuit, &dae).expect("a closed loop's volume");
    let caps_of = |s: &NetworkSpec| -> Vec<f64> {
        let a = s.assemble().unwrap();
        a.circuit.nodes.iter().map(|n| n.capacitance).collect()
    };
    let caps = caps_of(&spec);
    let stamps = parameter::Stamps::new(circuit, &dae);
    let paths = [
        "vessels.systemic.lumped.capacitance",
        "vessels.lv.chamber.max_elastance",
    ];
    let tangents: Vec<DaeTangent> = (paths.iter())
        .map(|p| {
            let parsed = Parameter::parse(&spec, p).unwrap();
            stamps.tangent(&spec, &parsed, p).unwrap()
        })
        .collect();
    let signals: Vec<usize> = (0..dae.n).collect();
    let set = settings();
    let run = periodic_tangent_in(&dae, &tangents, &signals, set, Some(&volume)).unwrap();
    assert!(run.periodic_change <= 1e-11, "{}", run.periodic_change);
    let y0 = dae.initial_state();
    let v0 = blood_volume(circuit, &caps, &y0);
    let (ns, n) = (set.steps_per_cycle, dae.n);
    for k in 0..ns {
        let v = blood_volume(circuit, &caps, &run.values[k * n..(k + 1) * n]);
        assert!((v / v0 - 1.0).abs() <= 1e-9, "step {k}: {v} vs {v0}");
    }
    for (p, path) in paths.iter().enumerate() {
        // dC/dp of every node, by the circuit's capacitances at p (1 ± h) (linear in p)
        let h = 1e-3;
        let value = tangents[p].value;
        let (up, down) = (
            caps_of(&scaled_or_heart(&spec, path, 1.0 + h)),
            caps_of(&scaled_or_heart(&spec, path, 1.0 - h)),
        );
        let dcaps: Vec<f64> = (up.iter().zip(&down))
            .map(|(a, b)| (a - b) / (2.0 * h * value))
            .collect();
        let expected: f64 = dcaps.iter().zip(&y0).map(|(d, p)| d * p).sum();
        for k in 0..ns {
            let y = &run.values[k * n..(k + 1) * n];
            let s = &run.derivs[(p * ns + k) * n..(p * ns + k + 1) * n];
            let dv = blood_volume(circuit, &caps, s)
                + dcaps.iter().zip(y).map(|(d, q)| d * q).sum::<f64>();
            // judged on the volume's response to a 100 % change of p against the volume
            assert!(
                (value * (dv - expected)).abs() <= 1e-9 * v0,
                "{path} step {k}: {dv} vs {expected}"
            );
        }
    }
}

fn scaled_or_heart(spec: &NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    if path.contains(".lumped.") {
        scaled_from(spec.clone(), path, f)
    } else {
        heart_scaled(spec.clone(), path, f)
    }
}

/// An open model (an inflow, pressure-fixed outlets) has no conserved volume: its tangent is
/// the plain fixed point.
#[test]
fn an_open_model_conserves_no_volume() {
    for spec in [parse(MODEL).unwrap(), parse(HEART).unwrap()] {
        let assembled = spec.assemble().unwrap();
        let dae = assembled.circuit.assemble().unwrap();
        assert!(ConservedVolume::of(&assembled.circuit, &dae).is_none());
    }
}

/// A vessel or node whose name holds dots is addressed by it (the longest name of the model
/// wins), and a name of no vessel or node is named with the model's nearest: the indices and
/// names are those of the model as written.
#[test]
fn dotted_names_resolve_to_their_vessel_and_a_near_miss_names_the_nearest() {
    let mut spec = parse(MODEL).unwrap();
    spec.vessels[0].name = "p.a".into();
    spec.vessels[2].name = "p".into();
    let o2 = spec.boundary_conditions.remove("o2").unwrap();
    spec.boundary_conditions.insert("o.2".into(), o2);
    assert_eq!(
        Parameter::parse(&spec, "vessels.p.a.radius").unwrap(),
        Parameter::Radius(0)
    );
    assert_eq!(
        Parameter::parse(&spec, "vessels.p.lumped.resistance").unwrap(),
        Parameter::Lumped(2, "resistance".into())
    );
    assert_eq!(
        Parameter::parse(&spec, "boundary_conditions.o.2.resistance").unwrap(),
        Parameter::Condition {
            node: "o.2".into(),
            key: "resistance".into()
        }
    );
    let err = |p: &str| Parameter::parse(&spec, p).unwrap_err().to_string();
    assert_eq!(
        err("vessels.q.a.radius"),
        "parameter 'vessels.q.a.radius': no vessel named 'q' in model 'y' (nearest: p.a)"
    );
    assert_eq!(
        err("boundary_conditions.o.3.resistance"),
        "parameter 'boundary_conditions.o.3.resistance': no boundary condition at node 'o' \
         in model 'y' (nearest: o.2)"
    );
}

/// A heart element's key it has no value for names the keys it has (its law's, written out
/// from the schema's tables) and the nearest of them.
#[test]
fn a_heart_key_typo_names_the_elements_keys_and_the_nearest() {
    let base = parse(HEART).unwrap();
    let err = |p: &str| Parameter::parse(&base, p).unwrap_err().to_string();
    assert_eq!(
        err("vessels.lv.chamber.max_elastanse"),
        "parameter 'vessels.lv.chamber.max_elastanse': the chamber 'lv' has no \
         differentiable value 'max_elastanse' (differentiable: max_elastance, min_elastance, \
         rest_volume_diastole, rest_volume_systole, activation.t_active, activation.t_twitch; \
         nearest: max_elastance)"
    );
    assert_eq!(
        err("vessels.mitral.valve.steepnes"),
        "parameter 'vessels.mitral.valve.steepnes': the valve 'mitral' has no differentiable \
         value 'steepnes' (differentiable: min_resistance, max_resistance, steepness; \
         nearest: steepness)"
    );
    assert!(
        err("vessels.lv.chamber.activation.t_twich").ends_with("; nearest: activation.t_twitch)")
    );
}
