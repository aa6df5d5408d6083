//! Oxygen sensitivities with boundary-layer walls whose law reads the cycle-mean flow (a
//! Graetz wall of the forward-flow mean, a cycle-mean Lévêque wall): their conductance moves
//! with every flow parameter (through the segments' mean flow) and with a vessel's length
//! (the layer's development along it), not in proportion to the wall area. Against central
//! differences of whole periodic runs (relative step 1e-4, judged as the other oxygen
//! sensitivities: 1e-6 of the quotient's largest value over the cycle, or its rounding
//! floor), and the adjoint against the forward tangents (~1e-11; 1e-8 tells a wrong term).

use super::tests::{compare, run_with};
use super::*;
use crate::model::parse;

/// The Y network of the other oxygen tests with dissolved oxygen only (no haemoglobin, so
/// no facilitation factor rides on the walls' enhancement), a Graetz wall of the
/// forward-flow mean on every vessel but d2, and a cycle-mean Lévêque wall on d2. The
/// enhancement (×6) makes the walls take a few per cent of the oxygen delivered, so the
/// signals move well above the difference quotients' rounding. The walls' transport section,
/// put in place of the Y network's (`model`).
const TRANSPORT: &str = r#""transport": {"species": [{
    "name": "o2", "diffusivity": 1.5e-9,
    "inlet": {"kind": "constant", "value": 0.119},
    "wall": {"model": "graetz", "wall_concentration": 0.0777, "flow": "forward-mean",
             "enhancement": 6.0},
    "per_vessel": {"d2": {"model": "leveque", "wall_concentration": 0.06,
                          "enhancement": 6.0}}
  }]}
}"#;

/// The Y network (`super::tests::MODEL`) with [`TRANSPORT`] as its transport section.
pub(super) fn model() -> String {
    let y = super::tests::MODEL;
    let at = y
        .find(r#""transport""#)
        .expect("the Y network has a transport section");
    format!("{}{TRANSPORT}", &y[..at])
}

pub(super) fn signals() -> Vec<(String, String)> {
    [
        ("d1", "concentration_out"),
        ("d2", "concentration_out"),
        ("parent", "wall_uptake"),
        ("d1", "wall_uptake"),
        ("d2", "wall_uptake"),
        ("", "consumption"),
        ("", "inflow"),
        ("", "outflow"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

/// `s` with parameter `path` multiplied by `f` (oxygen keys of the walls here, flow paths
/// as the other tests scale them).
fn scaled(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    if !path.starts_with("oxygen.") {
        return crate::sensitivity::tests::scaled_from(s, path, f);
    }
    let sp = &mut s.transport.as_mut().unwrap().species[0];
    let wall = match path.split('.').nth(1) {
        Some("per_vessel") => sp.per_vessel.get_mut("d2").unwrap(),
        _ => &mut sp.wall,
    };
    match (path.rsplit('.').next(), wall) {
        (
            Some("concentration"),
            WallSpec::Graetz {
                wall_concentration, ..
            }
            | WallSpec::Leveque {
                wall_concentration, ..
            },
        ) => *wall_concentration *= f,
        (
            Some("enhancement"),
            WallSpec::Graetz { enhancement, .. } | WallSpec::Leveque { enhancement, .. },
        ) => *enhancement *= f,
        _ => panic!("no such parameter in the test model: {path}"),
    }
    s
}

pub(super) fn check(spec: &NetworkSpec, path: &str) -> f64 {
    let h = 1e-4;
    let sig = signals();
    let exact = run_with(spec, &[path], &sig);
    let up = run_with(&scaled(spec.clone(), path, 1.0 + h), &[], &sig);
    let down = run_with(&scaled(spec.clone(), path, 1.0 - h), &[], &sig);
    compare(path, h, &exact, &up, &down)
}

#[test]
fn cycle_mean_walls_by_oxygen_parameters_against_central_differences() {
    let spec = parse(&model()).unwrap();
    for path in [
        "oxygen.wall.concentration",
        "oxygen.wall.enhancement",
        "oxygen.per_vessel.d2.wall.concentration",
        "oxygen.per_vessel.d2.wall.enhancement",
    ] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
}

/// A length of each Graetz vessel, the radius and length of the Lévêque one, a Windkessel's
/// resistance and the inflow's scale: each moves the walls' mean flows (and a length their
/// layers' development). (The parent's radius moves the signals by less than the
/// quotients' rounding: the Graetz law does not read a radius, and the inflow is given.)
#[test]
fn cycle_mean_walls_by_flow_parameters_against_central_differences() {
    let spec = parse(&model()).unwrap();
    for path in [
        "vessels.parent.length",
        "vessels.d1.length",
        "vessels.d2.radius",
        "vessels.d2.length",
        "boundary_conditions.o1.distal_resistance",
        "scale.inflow",
    ] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
}

/// The cycle-mean walls' derivatives in the adjoint (their dg per cell, the flow
/// parameters' through the mean flows) against the forward tangents: the cycle mean of
/// every signal and a weighted series of each, per functional relative to its largest
/// |dJ/d ln θ|.
#[test]
fn cycle_mean_walls_adjoint_equals_forward() {
    let spec = parse(&model()).unwrap();
    let paths = [
        "vessels.d2.radius",
        "vessels.d2.length",
        "scale.inflow",
        "oxygen.wall.enhancement",
        "oxygen.per_vessel.d2.wall.concentration",
    ];
    let sig = signals();
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &sig);
    eprintln!("cycle-mean walls: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// [`model`] with d2's Lévêque wall on the shear `law` (relaxed or instantaneous).
pub(super) fn sheared(law: crate::closure::Shear) -> NetworkSpec {
    let mut spec = parse(&model()).unwrap();
    let sp = &mut spec.transport.as_mut().unwrap().species[0];
    if let Some(WallSpec::Leveque { shear, .. }) = sp.per_vessel.get_mut("d2") {
        *shear = law;
    }
    spec
}

const SHEARS: [crate::closure::Shear; 2] = [
    crate::closure::Shear::Relaxed,
    crate::closure::Shear::Instantaneous,
];

/// A Lévêque wall of the relaxed or instantaneous shear on d2: its conductance follows the
/// shear step by step, and the oxygen parameters scale that step's g (the enhancement) or
/// g c_w (the wall concentration). Against central differences of whole periodic runs,
/// judged as above.
#[test]
fn shear_dependent_walls_by_oxygen_parameters_against_central_differences() {
    for law in SHEARS {
        let spec = sheared(law);
        for path in [
            "oxygen.per_vessel.d2.wall.concentration",
            "oxygen.per_vessel.d2.wall.enhancement",
            "oxygen.wall.enhancement",
        ] {
            let worst = check(&spec, path);
            eprintln!("{law:?} shear, {path}: {worst:.2e}");
            assert!(worst < 1e-6, "{law:?}: {path}");
        }
    }
}

/// The same walls' step-by-step terms in the adjoint (two sums per shear-dependent piece)
/// against the forward tangents.
#[test]
fn shear_dependent_walls_adjoint_equals_forward() {
    let paths = [
        "oxygen.per_vessel.d2.wall.concentration",
        "oxygen.per_vessel.d2.wall.enhancement",
        "oxygen.wall.enhancement",
    ];
    for law in SHEARS {
        let worst =
            super::adjoint::tests::mean_and_series_adjoint_worst(&sheared(law), &paths, &signals());
        eprintln!("{law:?} shear: adjoint against forward {worst:.2e}");
        assert!(worst < 1e-8, "{law:?}: {worst:e}");
    }
}

/// Flow parameters on the same walls: a flow parameter moves the shear each step's law
/// reads (the branch flow's tangent; the relaxed shear through its own state's tangent,
/// Q̃′ ← (1 − e) sgn(Q) Q′ + e Q̃′ + (Q̃ − |Q|) e′, with the relaxation time's change by the
/// mean flow and the geometry) and d2's radius and length its law's coefficients. Against
/// central differences of whole periodic runs (the relaxed shear starting at its periodic
/// state in both), judged as above.
#[test]
fn shear_dependent_walls_by_flow_parameters_against_central_differences() {
    for law in SHEARS {
        let spec = sheared(law);
        for path in [
            "vessels.d2.radius",
            "vessels.d2.length",
            "vessels.parent.length",
            "boundary_conditions.o1.distal_resistance",
            "scale.inflow",
        ] {
            let worst = check(&spec, path);
            eprintln!("{law:?} shear, {path}: {worst:.2e}");
            assert!(worst < 1e-6, "{law:?}: {path}");
        }
    }
}

/// The flow parameters' step-by-step terms of the shear-dependent pieces in the adjoint
/// (contracted with each step's weights of dg and d(g c_w)) against the forward tangents,
/// beside an oxygen parameter (a wall stiffness too, which moves these signals by less
/// than the difference quotients' rounding); and a taper's end radii under a relaxed wall
/// on d1.
#[test]
fn shear_dependent_walls_by_flow_parameters_adjoint_equals_forward() {
    let paths = [
        "vessels.d2.radius",
        "vessels.d2.length",
        "vessels.d2.youngs_modulus",
        "boundary_conditions.o1.distal_resistance",
        "scale.inflow",
        "oxygen.per_vessel.d2.wall.enhancement",
    ];
    for law in SHEARS {
        let worst =
            super::adjoint::tests::mean_and_series_adjoint_worst(&sheared(law), &paths, &signals());
        eprintln!("{law:?} shear, flow parameters: adjoint against forward {worst:.2e}");
        assert!(worst < 1e-8, "{law:?}: {worst:e}");
    }
    let mut taper = sheared(crate::closure::Shear::Relaxed);
    let sp = &mut taper.transport.as_mut().unwrap().species[0];
    let d2 = sp.per_vessel["d2"].clone();
    sp.per_vessel.insert("d1".into(), d2);
    let paths = [
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
        "vessels.d1.length",
    ];
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&taper, &paths, &signals());
    eprintln!("taper under a relaxed wall: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// A taper's end radii under the cycle-mean walls, with a cycle-mean Lévêque wall on d1
/// (3 → 2.5 mm) in place of its Graetz one: each segment's mean flow and wall move by its
/// own share (`FlowGeometry::at`). Neither law reads the radius beyond the flow (Graetz not
/// at all, Lévêque's r (Q/r³)^{1/3} not), so an end radius moves these signals by less than
/// the quotients' rounding (as the parent's radius above): the adjoint is checked against
/// the forward tangents here, and the end radii against central differences under the
/// mass-transfer wall and a consumption flux (`super::tests`), and under the inlet
/// renewal's Graetz law in `species_renewal_tests`.
#[test]
fn taper_end_radii_under_cycle_mean_walls() {
    let spec = parse(&model()).unwrap();
    let mut leveque = spec.clone();
    let sp = &mut leveque.transport.as_mut().unwrap().species[0];
    let d2 = sp.per_vessel["d2"].clone();
    sp.per_vessel.insert("d1".into(), d2);
    let paths = [
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
        "scale.inflow",
    ];
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&leveque, &paths, &signals());
    eprintln!("taper under a cycle-mean Lévêque wall: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}
