//! Oxygen sensitivities through the haemoglobin facilitation of boundary-layer walls: a
//! wall's PO2 (or concentration) and P50 move its conductance through E_Hb. Against central
//! differences of whole periodic runs whose walls' E_Hb is recomputed for the perturbed
//! model as the model reader computes it (the shooting solve), relative step 1e-4, judged as
//! the other oxygen sensitivities (per signal against its largest difference quotient over
//! the cycle, or the quotient's rounding floor); and the adjoint against the forward tangents.

use super::tests::{compare, run_with, settings};
use super::*;
use crate::closure::{Facilitation, MeanFlow};
use crate::model::facilitation::{Layer, hill_factor};
use crate::model::parse;

/// The Y network's oxygen (Hill's law; inlet 85 mmHg, α = 1e-5 mol m⁻³ Pa⁻¹) with a
/// facilitated Graetz wall of the forward-flow mean at 40 mmHg on every vessel but d2 and
/// a facilitated cycle-mean Lévêque wall at 45 mmHg on d2, each given an enhancement (×8,
/// ×6) so that the walls take a few per cent of the oxygen delivered. Their E_Hb is
/// written by [`refresh`].
const TRANSPORT: &str = r#""transport": {"species": [{
    "name": "o2", "diffusivity": 1.5e-9,
    "binding": {"kind": "hill", "solubility": 1e-5, "p50": 3573.04, "n": 2.7,
                "capacity": 9.0},
    "inlet": {"kind": "constant", "value": 0.113324},
    "wall": {"model": "graetz", "wall_concentration": 0.0533288, "flow": "forward-mean",
             "enhancement": 8.0, "facilitation": {"factor": 1.0,
             "inlet_concentration": 0.113324, "d_hb": 7e-11}},
    "per_vessel": {"d2": {"model": "leveque", "wall_concentration": 0.06, "enhancement": 6.0,
                          "facilitation": {"factor": 1.0, "inlet_concentration": 0.113324,
                                           "d_hb": 5.5e-12}}}
  }]}
}"#;

fn model() -> NetworkSpec {
    let y = super::tests::MODEL;
    let at = y.find(r#""transport""#).expect("a transport section");
    let mut spec = parse(&format!("{}{TRANSPORT}", &y[..at])).unwrap();
    refresh(&mut spec);
    spec
}

/// Every facilitated wall's E_Hb recomputed at the model's binding and wall concentration
/// (the shooting solve, as the model reader does), the given enhancement kept.
fn refresh(spec: &mut NetworkSpec) {
    let sp = &mut spec.transport.as_mut().unwrap().species[0];
    let BindingSpec::Hill {
        solubility,
        p50,
        n,
        capacity,
    } = sp.binding
    else {
        panic!("Hill's law");
    };
    let d = sp.diffusivity;
    let walls = std::iter::once(&mut sp.wall).chain(sp.per_vessel.values_mut());
    for wall in walls {
        if let WallSpec::Graetz {
            wall_concentration,
            enhancement,
            facilitation: Some(f),
            ..
        }
        | WallSpec::Leveque {
            wall_concentration,
            enhancement,
            facilitation: Some(f),
            ..
        } = wall
        {
            let layer = Layer {
                alpha: solubility,
                d,
                d_hb: f.d_hb,
                capacity,
                p50,
                n,
            };
            let (p_in, p_w) = (
                f.inlet_concentration / solubility,
                *wall_concentration / solubility,
            );
            let e = hill_factor(p_in, p_w, &layer);
            *enhancement *= e / f.factor;
            f.factor = e;
        }
    }
}

fn signals() -> Vec<(String, String)> {
    [
        ("d1", "po2_out"),
        ("d2", "saturation_out"),
        ("parent", "wall_uptake"),
        ("d2", "wall_uptake"),
        ("", "consumption"),
        ("", "outflow"),
    ]
    .iter()
    .map(|(a, b)| (a.to_string(), b.to_string()))
    .collect()
}

/// `s` with `path` multiplied by `f` and E_Hb recomputed.
fn scaled(mut s: NetworkSpec, path: &str, f: f64) -> NetworkSpec {
    let sp = &mut s.transport.as_mut().unwrap().species[0];
    if path == "oxygen.hill.p50" {
        if let BindingSpec::Hill { p50, .. } = &mut sp.binding {
            *p50 *= f;
        }
    } else {
        let wall = match path.split('.').nth(1) {
            Some("per_vessel") => sp.per_vessel.get_mut("d2").unwrap(),
            _ => &mut sp.wall,
        };
        match (path.rsplit('.').next(), wall) {
            (
                Some("concentration" | "po2"),
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
    }
    refresh(&mut s);
    s
}

fn check(spec: &NetworkSpec, path: &str) -> f64 {
    let h = 1e-4;
    let sig = signals();
    let exact = run_with(spec, &[path], &sig);
    let up = run_with(&scaled(spec.clone(), path, 1.0 + h), &[], &sig);
    let down = run_with(&scaled(spec.clone(), path, 1.0 - h), &[], &sig);
    compare(path, h, &exact, &up, &down)
}

const PATHS: [&str; 5] = [
    "oxygen.hill.p50",
    "oxygen.wall.po2",
    "oxygen.wall.enhancement",
    "oxygen.per_vessel.d2.wall.po2",
    "oxygen.per_vessel.d2.wall.concentration",
];

/// The shooting solve stops at 1e-10 of P_in − P_w, so E_Hb carries ~1e-10 of itself from
/// run to run: over h = 1e-4 that is ~1e-6 of d ln E_Hb, of which the signals see a part;
/// judged to 1e-6 as the other oxygen parameters (a missing facilitation term is ≥ 1e-2).
#[test]
fn facilitated_walls_against_central_differences() {
    let spec = model();
    for path in PATHS {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
}

/// The same walls with the section's Graetz wall on the inlet renewal (the default law).
#[test]
fn facilitated_inlet_renewal_wall_against_central_differences() {
    let mut spec = model();
    if let WallSpec::Graetz {
        flow,
        kinematic_viscosity,
        ..
    } = &mut spec.transport.as_mut().unwrap().species[0].wall
    {
        (*flow, *kinematic_viscosity) = (MeanFlow::InletRenewal, 3e-7);
    }
    for path in ["oxygen.hill.p50", "oxygen.wall.po2"] {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
}

/// The facilitation's conductance slopes in the adjoint (dg per cell) against the forward
/// tangents, per functional relative to its largest |dJ/d ln θ| (~1e-11; 1e-8 tells a
/// wrong term).
#[test]
fn facilitated_walls_adjoint_equals_forward() {
    let spec = model();
    let sig = signals();
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &PATHS, &sig);
    eprintln!("facilitated walls: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// [`model`] with a permeability in series behind both facilitated walls (3e-4 m/s: the
/// blood side's share d ln g/d ln G = 1 − g/G_p is 0.35–0.9 over the segments), so E_Hb
/// and the enhancement move g by that share only.
fn leaky() -> NetworkSpec {
    let mut spec = model();
    let sp = &mut spec.transport.as_mut().unwrap().species[0];
    for wall in std::iter::once(&mut sp.wall).chain(sp.per_vessel.values_mut()) {
        if let WallSpec::Graetz { permeability, .. } | WallSpec::Leveque { permeability, .. } = wall
        {
            *permeability = Some(3e-4);
        }
    }
    spec
}

/// Facilitated walls behind a permeability in series: P50, the walls' PO2 and
/// concentration and the enhancement against central differences (judged as above), and
/// the adjoint against the forward tangents. Without the blood side's share the
/// derivatives by the walls' keys are off by g/G_p of the wall's part (tens of per cent).
#[test]
fn facilitated_walls_behind_a_permeability() {
    let spec = leaky();
    for path in PATHS {
        assert!(check(&spec, path) < 1e-6, "{path}");
    }
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &PATHS, &signals());
    eprintln!("facilitated walls behind a permeability: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// The given enhancement is reported (the wall's enhancement over E_Hb), and what stays
/// undifferentiated is refused by name: a wall at the inlet PO2 (no layer: E_Hb jumps to 1
/// there).
#[test]
fn given_enhancement_and_refusals() {
    let spec = model();
    let sig = signals();
    let one = |spec: &NetworkSpec, path: &str| {
        species_sensitivities(spec, &[path.to_string()], &sig, settings())
    };
    let sp = &spec.transport.as_ref().unwrap().species[0];
    let p = oxygen_parameter(sp, "oxygen.per_vessel.d2.wall.enhancement").unwrap();
    assert!((p.unwrap().value / 6.0 - 1.0).abs() < 1e-12);
    let mut flat = spec.clone();
    if let WallSpec::Graetz {
        wall_concentration, ..
    } = &mut flat.transport.as_mut().unwrap().species[0].wall
    {
        *wall_concentration = 0.113324;
    }
    let m = one(&flat, "oxygen.wall.po2").unwrap_err().to_string();
    assert!(m.contains("equals the inlet PO2"), "{m}");
    // a record of the facilitation is checked like the rest of the wall
    let bad = Facilitation {
        factor: -1.0,
        inlet_concentration: 0.1,
        d_hb: 0.0,
    };
    let mut wrong = spec.clone();
    if let WallSpec::Graetz { facilitation, .. } =
        &mut wrong.transport.as_mut().unwrap().species[0].wall
    {
        *facilitation = Some(bad);
    }
    assert!(one(&wrong, "oxygen.wall.po2").is_err());
}

/// [`model`] (Hill's law) with the parent tapered 4 → 3.6 mm (d1 is tapered 3 → 2.5 mm
/// already): its end radii barely move the exchange under these boundary-layer walls (the
/// Graetz law does not read a radius, the Lévêque one only through the flow), so the
/// network's mean outflow moves by ~1e-7 of itself per unit log, while the amounts the
/// transport tangent's periodicity is judged against are mostly bound oxygen. The forward
/// tangent stopped at the tolerance there still stored ~1e-13 of the largest amount per
/// cycle, which the mean outflow read as flux: 6.5e-7 of its derivative off the adjoint's
/// (whose mean outflow balances the consumption, as a periodic state's must). It now goes
/// on while its change still falls (`still_settling`), to the amounts' rounding floor:
/// 9.8e-8 measured (the mean outflow's derivative by the inlet radius, ~1e-16 of the
/// amounts over a cycle; d1's mean PO2 1.4e-9). Judged at 2e-7: that floor with 2× room;
/// the stop at the tolerance fails it by 3×.
#[test]
fn taper_end_radii_with_haemoglobin_adjoint_equals_forward() {
    let mut spec = model();
    let parent = spec
        .vessels
        .iter_mut()
        .find(|v| v.name == "parent")
        .unwrap();
    parent.geometry.as_mut().unwrap().radius_out = 0.0036;
    let paths = ["vessels.parent.radius_in", "vessels.parent.radius_out"];
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
    eprintln!("taper with haemoglobin: adjoint against forward {worst:.2e}");
    assert!(worst < 2e-7, "{worst:e}");
}

/// [`model`] with d2's facilitated Lévêque wall on the relaxed or instantaneous shear: P50
/// and its wall PO2 move the step's conductance through E_Hb (the same relative change of
/// the blood side as at a fixed shear). Against central differences (judged as above) and
/// the adjoint against the forward tangents.
#[test]
fn facilitated_shear_dependent_walls() {
    for law in [
        crate::closure::Shear::Relaxed,
        crate::closure::Shear::Instantaneous,
    ] {
        let mut spec = model();
        let sp = &mut spec.transport.as_mut().unwrap().species[0];
        if let Some(WallSpec::Leveque { shear, .. }) = sp.per_vessel.get_mut("d2") {
            *shear = law;
        }
        let paths = ["oxygen.hill.p50", "oxygen.per_vessel.d2.wall.po2"];
        for path in paths {
            let worst = check(&spec, path);
            eprintln!("{law:?} shear, {path}: {worst:.2e}");
            assert!(worst < 1e-6, "{law:?}: {path}");
        }
        let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
        eprintln!("{law:?} shear, facilitated: adjoint against forward {worst:.2e}");
        assert!(worst < 1e-8, "{law:?}: {worst:e}");
    }
}
