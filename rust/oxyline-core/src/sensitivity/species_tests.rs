//! Oxygen sensitivities against central differences of the same periodic run, one test per
//! parameter kind, and the balance they must keep. With a relative step h = 1e-4 the
//! difference quotient's truncation (O(h²)) and the rounding of the binding's inversion
//! (1e-10 mmHg on ~50 mmHg, over h) are both below 1e-7 of the derivative's scale, so
//! agreement to 1e-6 relative tells a wrong tangent from a right one.

use super::*;
use crate::hemoglobin::BindingSpec;
use crate::model::parse;

/// A pulsatile inflow (no backflow) into an elastic parent that splits into elastic
/// daughters ending in an RCR and a resistance; oxygen with Hill's
/// law and a mass-transfer wall (SI: α = 1e-5 mol m⁻³ Pa⁻¹, P50 = 26.8 mmHg, an inlet PO2 of
/// 85 mmHg, a wall PO2 of 40 mmHg). k (and the consumption flux below) are far above an
/// artery's, so that the wall takes a few per cent of the oxygen delivered and the signals
/// move well above the difference quotients' rounding.
pub(super) const MODEL: &str = r#"{
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

pub(super) fn signals() -> Vec<(String, String)> {
    [
        ("d1", "po2_out"),
        ("d1", "saturation_out"),
        ("parent", "wall_uptake"),
        ("d1", "wall_uptake"),
        ("", "consumption"),
        ("", "inflow"),
        ("", "outflow"),
        ("d1", "flow_out"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

pub(super) fn settings() -> TangentSettings {
    TangentSettings {
        period: 0.8,
        steps_per_cycle: 160,
        rho_infty: 0.5,
        max_cycles: 2000,
        tol: 1e-13,
    }
}

pub(super) fn run(spec: &NetworkSpec, paths: &[&str]) -> SpeciesSensitivities {
    run_with(spec, paths, &signals())
}

/// [`run`] of the signals `sig`.
pub(super) fn run_with(
    spec: &NetworkSpec,
    paths: &[&str],
    sig: &[(String, String)],
) -> SpeciesSensitivities {
    let paths: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    species_sensitivities(spec, &paths, sig, settings()).unwrap()
}

pub(super) fn oxygen(s: &mut NetworkSpec) -> &mut SpeciesSpec {
    &mut s.transport.as_mut().unwrap().species[0]
}

/// `s` with the oxygen parameter `path` multiplied by `f`, written into the spec directly.
pub(super) fn scaled(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    if !path.starts_with("oxygen.") {
        return crate::sensitivity::tests::scaled_from(s, path, f);
    }
    let sp = oxygen(&mut s);
    match (path, &mut sp.wall, &mut sp.binding) {
        ("oxygen.wall.k", WallSpec::MassTransfer { k, .. }, _) => *k *= f,
        (
            "oxygen.wall.po2",
            WallSpec::MassTransfer {
                wall_concentration, ..
            },
            _,
        ) => *wall_concentration *= f,
        (
            "oxygen.wall.flux",
            WallSpec::Flux {
                flux: FluxSpec::Constant(q),
            },
            _,
        ) => *q *= f,
        ("oxygen.hill.p50", _, BindingSpec::Hill { p50, .. }) => *p50 *= f,
        _ => panic!("no such parameter in the test model: {path}"),
    }
    s
}

/// The tangent of `path` against the central difference of the periodic signals, per
/// signal relative to the largest difference quotient of that signal over the cycle.
fn check(spec: &NetworkSpec, path: &str) -> f64 {
    let h = 1e-4;
    let exact = run(spec, &[path]);
    let up = run(&scaled(spec.clone(), path, 1.0 + h), &[]);
    let down = run(&scaled(spec.clone(), path, 1.0 - h), &[]);
    compare(path, h, &exact, &up, &down)
}

/// The largest difference of the tangent from the central difference of `up` and `down`
/// (relative step `h`), per signal relative to the largest difference quotient of that
/// signal over the cycle, or to the quotient's rounding floor when that is larger: the
/// signals carry ~1e-12 of their magnitude in rounding (the periodic tolerance 1e-13; the
/// network fluxes are differences of accumulators summed over every cycle), so a quotient
/// below 1e6 × 1e-12 |value| / (h |θ|) cannot be judged to 1e-6 (a far vessel's wall by a
/// length, say); at least two signals must move above that floor.
pub(super) fn compare(
    path: &str,
    h: f64,
    exact: &SpeciesSensitivities,
    up: &SpeciesSensitivities,
    down: &SpeciesSensitivities,
) -> f64 {
    let p = exact.values[0];
    let nt = exact.times.len();
    let nsig = exact.signals.len() / nt;
    let (mut worst, mut moved) = (0.0f64, 0);
    for j in 0..nsig {
        let fd: Vec<f64> = (0..nt)
            .map(|k| (up.signals[k * nsig + j] - down.signals[k * nsig + j]) / (2.0 * h * p))
            .collect();
        let scale = fd.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let vmax = (0..nt).fold(0.0f64, |m, k| m.max(exact.signals[k * nsig + j].abs()));
        let floor = 1e-6 * vmax / (h * p.abs());
        if scale == 0.0 {
            // (the inflow of a prescribed inlet by a wall parameter): exactly no derivative
            assert!(
                (0..nt).all(|k| exact.derivs[k * nsig + j] == 0.0),
                "{path}: {j}"
            );
            continue;
        }
        moved += usize::from(scale > floor);
        for (k, d) in fd.iter().enumerate() {
            let e = (exact.derivs[k * nsig + j] - d).abs() / scale.max(floor);
            worst = worst.max(e);
        }
    }
    // (a stiffness moves the oxygen only through the flow's pulsatility and the volumes)
    assert!(moved >= 2, "{path}: only {moved} signals move");
    eprintln!("{path}: worst relative difference {worst:.2e} (h = {h:e})");
    worst
}

#[test]
fn wall_conductance_against_central_differences() {
    assert!(check(&parse(MODEL).unwrap(), "oxygen.wall.k") < 1e-6);
}

/// A mass-transfer wall behind a permeability in series equal to k (the blood side's
/// share of d ln g is 1/2): k, the wall PO2 and a radius (the wall's area moves both
/// conductances) against central differences, and the adjoint against the tangents.
#[test]
fn wall_conductance_behind_a_permeability() {
    let mut spec = parse(MODEL).unwrap();
    if let WallSpec::MassTransfer { permeability, .. } = &mut oxygen(&mut spec).wall {
        *permeability = Some(5e-3);
    }
    for path in ["oxygen.wall.k", "oxygen.wall.po2", "vessels.d1.radius_out"] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    let paths = ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"];
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
    eprintln!("mass transfer behind a permeability: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

#[test]
fn wall_po2_against_central_differences() {
    assert!(check(&parse(MODEL).unwrap(), "oxygen.wall.po2") < 1e-6);
}

#[test]
fn p50_against_central_differences() {
    assert!(check(&parse(MODEL).unwrap(), "oxygen.hill.p50") < 1e-6);
}

/// A prescribed consumption flux (mol m⁻² s⁻¹) instead of the mass-transfer wall.
pub(super) fn consuming() -> NetworkSpec {
    let mut s = parse(MODEL).unwrap();
    oxygen(&mut s).wall = WallSpec::Flux {
        flux: FluxSpec::Constant(1.5e-4),
    };
    s
}

#[test]
fn wall_flux_against_central_differences() {
    assert!(check(&consuming(), "oxygen.wall.flux") < 1e-6);
    assert!(check(&consuming(), "oxygen.hill.p50") < 1e-6);
}

/// At the periodic state the stored oxygen repeats, so over a cycle the consumption equals
/// inflow − outflow, and so do their derivatives (the tangent keeps the same balance).
#[test]
fn consumption_balances_inflow_minus_outflow() {
    let s = run(
        &parse(MODEL).unwrap(),
        &["oxygen.wall.k", "oxygen.hill.p50", "oxygen.wall.po2"],
    );
    let (nt, nsig) = (s.times.len(), signals().len());
    let mean = |p: usize, j: usize| -> f64 {
        (0..nt)
            .map(|k| s.derivs[(p * nt + k) * nsig + j])
            .sum::<f64>()
            / nt as f64
    };
    for p in 0..3 {
        let (wall, inflow, outflow) = (mean(p, 4), mean(p, 5), mean(p, 6));
        let scale = wall.abs().max(inflow.abs()).max(outflow.abs());
        let err = (wall - (inflow - outflow)).abs() / scale;
        eprintln!(
            "parameter {p}: d consumption {wall:.6e}, d(in - out) {:.6e}, {err:.1e}",
            inflow - outflow
        );
        assert!(err < 1e-8, "parameter {p}: {err:e}");
    }
}

#[test]
fn bad_paths_are_model_errors_naming_them() {
    let spec = parse(MODEL).unwrap();
    let sig = signals();
    let msg = |path: &str| {
        species_sensitivities(&spec, &[path.to_string()], &sig, settings())
            .unwrap_err()
            .to_string()
    };
    for path in [
        "oxygen.wall.kk",
        "oxygen.wall.flux",
        "oxygen.colour",
        "vessels.nope.length",
    ] {
        let m = msg(path);
        assert!(m.contains(path) || m.contains("nope"), "{path}: {m}");
    }
    // d1 is tapered: its radius is not one number
    let m = msg("vessels.d1.radius");
    assert!(
        m.contains("vessels.d1.radius") && m.contains("tapered"),
        "{m}"
    );
    let bad = [("nope".to_string(), "po2_out".to_string())];
    let m = species_sensitivities(&spec, &["oxygen.wall.k".into()], &bad, settings())
        .unwrap_err()
        .to_string();
    assert!(m.contains("nope"), "{m}");
}

/// The oxygen outputs by flow parameters: through the face flows and transport volumes of
/// every step (all of them), the reference volumes (radius, length) and the wall area
/// (radius, length). Relative step 1e-4 as for the oxygen parameters.
#[test]
fn flow_parameters_against_central_differences() {
    let spec = parse(MODEL).unwrap();
    for path in [
        "vessels.parent.radius",
        "vessels.d2.length",
        "vessels.d1.youngs_modulus",
        "boundary_conditions.o1.distal_resistance",
        "boundary_conditions.o1.capacitance",
        "scale.inflow",
    ] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    // a prescribed consumption flux: the wall takes flux × area, the area moves with r and L
    for path in ["vessels.d2.radius", "vessels.parent.length"] {
        assert!(check(&consuming(), path) < 1e-6, "{path}");
    }
}

/// The central difference's error against the tangent falls as h² (the tangent is the
/// limit it converges to): halving h divides it by about 4 while truncation dominates.
#[test]
fn flow_parameter_difference_quotients_converge_as_h_squared() {
    let spec = parse(MODEL).unwrap();
    let path = "vessels.parent.radius";
    let exact = run(&spec, &[path]);
    let errors: Vec<f64> = [4e-2, 2e-2, 1e-2]
        .iter()
        .map(|&h| {
            let up = run(&scaled(spec.clone(), path, 1.0 + h), &[]);
            let down = run(&scaled(spec.clone(), path, 1.0 - h), &[]);
            compare(path, h, &exact, &up, &down)
        })
        .collect();
    eprintln!("{path}: errors at h = 4e-2, 2e-2, 1e-2: {errors:?}");
    for w in errors.windows(2) {
        let ratio = w[0] / w[1];
        assert!((3.0..5.0).contains(&ratio), "ratio {ratio}: {errors:?}");
    }
}

/// The oxygen outputs by the geometry of viscoelastic vessels (Kelvin–Voigt walls of
/// relaxation times 0.5 ms on the parent, in the π arrangement, and 5 ms on d1, mixed at
/// their junction with the elastic d2's share): a
/// capacitance behind a wall sits at its elastic pressure, whose unknown sets the cell's
/// transport volume, and the wall's conductance moves with it. Against central differences
/// (relative step 1e-4, as above), and the adjoint against the forward tangents (1e-8).
#[test]
fn viscoelastic_geometry_against_central_differences() {
    let mut spec = parse(MODEL).unwrap();
    spec.vessels[0].geometry.as_mut().unwrap().wall_viscosity = 2e2;
    spec.vessels[0].arrangement = Some(crate::model::Arrangement::Pi);
    spec.vessels[1].geometry.as_mut().unwrap().wall_viscosity = 3e3;
    let paths = [
        "vessels.parent.radius",
        "vessels.d1.youngs_modulus",
        "vessels.d1.length",
        "vessels.d2.radius",
    ];
    for path in paths {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
    eprintln!("viscoelastic geometry: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:.2e}");
}

/// The oxygen outputs by the geometry of vessels with Womersley friction cells (the model's
/// `wall_friction: womersley`: cells on every segment, kept at these radii): the cells
/// follow each segment's R₀ and L₀, and the flows they shape carry the oxygen. Against
/// central differences (relative step 1e-4, as above), and the adjoint against the forward
/// tangents (1e-8).
#[test]
fn womersley_geometry_against_central_differences() {
    let mut spec = parse(MODEL).unwrap();
    spec.wall_friction = crate::segment::WallFriction::Womersley;
    let paths = [
        "vessels.parent.radius",
        "vessels.parent.length",
        "vessels.d1.youngs_modulus",
        "vessels.d1.length",
        "vessels.d2.radius",
    ];
    for path in paths {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
    eprintln!("Womersley geometry: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:.2e}");
}

/// A taper's end radii (d1: 3 → 2.5 mm in four segments): each segment's lumen volume and
/// wall area move by its own share of the end radius (`FlowGeometry::at`), under the
/// mass-transfer wall (g ∝ area) and a prescribed consumption flux (q ∝ area). Against
/// central differences (relative step 1e-4, as above), and the adjoint against the forward
/// tangents (1e-8).
#[test]
fn taper_end_radii_against_central_differences() {
    let paths = ["vessels.d1.radius_in", "vessels.d1.radius_out"];
    for spec in [parse(MODEL).unwrap(), consuming()] {
        for path in paths {
            assert!(check(&spec, path) < 1e-6, "{path}");
        }
    }
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(
        &consuming(),
        &[
            "vessels.d1.radius_in",
            "vessels.d1.radius_out",
            "vessels.parent.radius",
        ],
        &signals(),
    );
    eprintln!("taper end radii: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:.2e}");
}
