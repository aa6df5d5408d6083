//! Oxygen sensitivities on a network whose flow graph has a loop (its transport step is
//! solved by the flow-order sweep, not the tree elimination): a ring of four vessels fed by
//! a parent, drained at two of its junctions and by a pendant vessel at the third. Against
//! central differences of whole periodic runs (relative step 1e-4, judged as the other
//! oxygen sensitivities: 1e-6 of the quotient's largest value over the cycle, or its
//! rounding floor), and the adjoint (the sweep's system transposed) against the forward
//! tangents (~1e-11 of a gradient's scale; 1e-8 tells a wrong transpose from a right one).

use super::adjoint::tests::mean_and_series_adjoint_worst;
use super::tests::{compare, oxygen, run_with, scaled};
use super::*;
use crate::model::parse;

/// The ring a → b → c → d → a (the vessels' own directions; the flow picks its own),
/// fed at a by the parent, drained at b by an RCR, at d by a resistance and at c by the
/// pendant vessel. The ring is asymmetric (radii and lengths), so its bridge b → c carries a
/// small net flow whose direction the pulse may turn. Oxygen with Hill's law and a
/// mass-transfer wall, a cycle-mean Lévêque wall on the pendant (`lev` off: the
/// mass-transfer wall there too); the same strong wall as the Y network's tests, so the
/// signals move well above the quotients' rounding.
fn model(lev: bool) -> String {
    let pendant_wall = if lev {
        r#", "per_vessel": {"pendant": {"model": "leveque", "wall_concentration": 0.0533288,
                                          "enhancement": 300.0}}"#
    } else {
        ""
    };
    let vessel = |name: &str, from: &str, to: &str, n: u32, l: f64, r: f64, e: f64| {
        format!(
            r#"{{"name": "{name}", "from": "{from}", "to": "{to}", "segments": {n},
               "geometry": {{"length": {l}, "radius_in": {r}, "radius_out": {r},
                            "wall_thickness": {h}, "youngs_modulus": {e}}}}}"#,
            h = 0.15 * r
        )
    };
    let vessels = [
        vessel("parent", "in", "a", 3, 0.1, 0.004, 4e5),
        vessel("ab", "a", "b", 3, 0.06, 0.003, 6e5),
        vessel("bc", "b", "c", 2, 0.04, 0.0015, 6e5),
        vessel("cd", "c", "d", 2, 0.05, 0.002, 6e5),
        vessel("da", "d", "a", 3, 0.07, 0.0025, 6e5),
        vessel("pendant", "c", "o3", 2, 0.04, 0.0015, 6e5),
        vessel("b_out", "b", "o1", 2, 0.05, 0.0025, 6e5),
        vessel("d_out", "d", "o2", 2, 0.05, 0.002, 6e5),
    ]
    .join(",\n");
    format!(
        r#"{{
  "name": "ring",
  "vessels": [{vessels}],
  "boundary_conditions": {{
    "in": {{"type": "flow", "flow": {{"kind": "fourier", "period": 0.8, "mean": 3e-6,
                                    "cos": [1e-6, -0.4e-6], "sin": [1.2e-6, 0.3e-6]}}}},
    "o1": {{"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-10,
           "distal_resistance": 1.2e9}},
    "o2": {{"type": "resistance", "resistance": 1.6e9}},
    "o3": {{"type": "rcr", "proximal_resistance": 3e8, "capacitance": 3e-10,
           "distal_resistance": 2.4e9}}
  }},
  "transport": {{"species": [{{
    "name": "o2", "diffusivity": 1.5e-9,
    "binding": {{"kind": "hill", "solubility": 1e-5, "p50": 3573.04, "n": 2.7,
                "capacity": 9.0}},
    "inlet": {{"kind": "constant", "value": 0.113324}},
    "wall": {{"model": "mass-transfer", "k": 5e-3, "wall_concentration": 0.0533288}}{pendant_wall}
  }}]}}
}}"#
    )
}

fn ring(lev: bool) -> NetworkSpec {
    parse(&model(lev)).unwrap()
}

/// Outlet PO2 and saturation past the loop (b_out, d_out, the pendant), the bridge's and
/// the pendant's wall uptake, the network's fluxes and an outflow.
fn signals() -> Vec<(String, String)> {
    [
        ("b_out", "po2_out"),
        ("d_out", "saturation_out"),
        ("pendant", "po2_out"),
        ("bc", "wall_uptake"),
        ("pendant", "wall_uptake"),
        ("", "consumption"),
        ("", "inflow"),
        ("", "outflow"),
        ("d_out", "flow_out"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

/// `s` with `path` multiplied by `f`: the Lévêque wall's enhancement here, the rest as the
/// Y network's tests scale them.
fn scaled_ring(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    if path == "oxygen.per_vessel.pendant.wall.enhancement" {
        match oxygen(&mut s).per_vessel.get_mut("pendant") {
            Some(WallSpec::Leveque { enhancement, .. }) => *enhancement *= f,
            _ => panic!("the pendant has no Lévêque wall"),
        }
        return s;
    }
    scaled(s, path, f)
}

fn check(spec: &NetworkSpec, path: &str) -> f64 {
    let h = 1e-4;
    let sig = signals();
    let exact = run_with(spec, &[path], &sig);
    let up = run_with(&scaled_ring(spec.clone(), path, 1.0 + h), &[], &sig);
    let down = run_with(&scaled_ring(spec.clone(), path, 1.0 - h), &[], &sig);
    compare(path, h, &exact, &up, &down)
}

#[test]
fn ring_oxygen_parameters_against_central_differences() {
    let spec = ring(false);
    for path in ["oxygen.wall.k", "oxygen.wall.po2", "oxygen.hill.p50"] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    let lev = ring(true);
    assert!(check(&lev, "oxygen.per_vessel.pendant.wall.enhancement") < 1e-6);
}

/// Every flow parameter kind; the wall stiffness through `scale.compliance` (every vessel's
/// Young's modulus and the Windkessels' C): one vessel's stiffness moves the oxygen by ~1e-5
/// of itself per unit log here, below what the quotients' rounding lets 1e-6 judge (it is
/// in the adjoint-against-forward test below).
#[test]
fn ring_flow_parameters_against_central_differences() {
    let spec = ring(true);
    for path in [
        "scale.inflow",
        "scale.resistance",
        "scale.compliance",
        "vessels.bc.radius",
        "vessels.da.length",
        "vessels.pendant.length",
        "boundary_conditions.o1.distal_resistance",
    ] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
}

/// The adjoint through the transposed sweep against the forward tangents: the cycle mean
/// of every signal and a weighted series of each, per functional relative to its largest
/// |dJ/d ln θ|.
#[test]
fn ring_adjoint_equals_forward() {
    let paths = [
        "oxygen.wall.k",
        "oxygen.hill.p50",
        "oxygen.wall.po2",
        "oxygen.per_vessel.pendant.wall.enhancement",
        "scale.inflow",
        "scale.compliance",
        "vessels.bc.radius",
        "vessels.da.length",
        "vessels.ab.youngs_modulus",
        "boundary_conditions.o3.distal_resistance",
    ];
    let worst = mean_and_series_adjoint_worst(&ring(true), &paths, &signals());
    eprintln!("ring: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}
