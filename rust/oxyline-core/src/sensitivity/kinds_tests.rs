//! Tangent sensitivities of a tapered vessel's end radii and of a lumped RCL vessel's values
//! (svZeroDSolver's BloodVessel, with a stenosis) against central differences of whole
//! periodic runs, and the adjoint against the tangents. The difference quotient's error is
//! O(h²) truncation plus rounding of ~1e-16 × |signal| / (h p): with h = 1e-4 relative both
//! are below 1e-8 of the derivative's scale, so agreement to 1e-6 relative tells a wrong
//! tangent from a right one (as `super::tests`).

use super::tests::{SIGNALS, check_on, run, settings};
use super::*;
use crate::model::{Arrangement, parse};

/// An inflow into a uniform parent that splits into a tapered daughter (π arrangement, so
/// each segment's C is shared by both its ends) ending in an RCR, and an RCL daughter with a
/// stenosis (S Q² at its peak flow ~1.5× its linear drop) ending in a resistance. Its
/// inertance (ωL ≈ R at the first harmonic) moves the pressures by far more than the
/// difference quotient's rounding (with L = 1e5 the inductance's derivative was within 4×
/// of that floor).
const MODEL: &str = r#"{
  "name": "kinds",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 3,
     "geometry": {"length": 0.1, "radius_in": 0.004, "radius_out": 0.004,
                  "wall_thickness": 0.0006, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "o1", "segments": 3, "arrangement": "pi",
     "geometry": {"length": 0.08, "radius_in": 0.003, "radius_out": 0.0022,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}},
    {"name": "d2", "from": "j", "to": "o2", "arrangement": "RCL",
     "lumped": {"resistance": 3e7, "inductance": 5e6, "capacitance": 2e-10,
                "stenosis_coefficient": 1.2e13}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 5e-6,
                                    "cos": [3e-6, -1e-6], "sin": [4e-6, 1e-6]}},
    "o1": {"type": "rcr", "proximal_resistance": 1.5e8, "capacitance": 6e-9,
           "distal_resistance": 1.2e9},
    "o2": {"type": "resistance", "resistance": 1.6e9}
  }
}"#;

/// Largest |tangent − central difference| over the cycle and signals, relative to the
/// derivative's scale per signal, must be within 1e-6 (see the module's documentation).
fn check(path: &str) {
    check_on(&parse(MODEL).unwrap(), path);
}

#[test]
fn tapered_end_radii() {
    check("vessels.d1.radius_in");
    check("vessels.d1.radius_out");
}

#[test]
fn rcl_vessel_values_through_its_stenosis() {
    check("vessels.d2.lumped.resistance");
    check("vessels.d2.lumped.inductance");
    check("vessels.d2.lumped.capacitance");
    check("vessels.d2.lumped.stenosis_coefficient");
}

/// A uniform vessel's two end radii move it as its radius does: d/dr = ∂/∂r_in + ∂/∂r_out,
/// the taper's slopes summed against the uniform radius's power law (r⁻⁴, r⁻², r³). Both are
/// exact derivatives of the same run, so they agree to the tangents' fixed-point tolerance.
#[test]
fn end_radii_of_a_uniform_vessel_sum_to_its_radius() {
    let base = parse(MODEL).unwrap();
    let s = run(
        &base,
        &[
            "vessels.parent.radius",
            "vessels.parent.radius_in",
            "vessels.parent.radius_out",
        ],
    );
    let n = s.cycle.derivs.len() / 3;
    let (whole, ends) = s.cycle.derivs.split_at(n);
    let scale = whole.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for k in 0..n {
        let sum = ends[k] + ends[n + k];
        assert!(
            (whole[k] - sum).abs() <= 1e-9 * scale,
            "{} vs {sum}",
            whole[k]
        );
    }
}

#[test]
fn adjoint_gradients_are_the_tangents_of_the_new_kinds() {
    super::tests::check_adjoint_of(
        &parse(MODEL).unwrap(),
        &[
            "vessels.d1.radius_in",
            "vessels.d1.radius_out",
            "vessels.d2.lumped.resistance",
            "vessels.d2.lumped.inductance",
            "vessels.d2.lumped.capacitance",
            "vessels.d2.lumped.stenosis_coefficient",
        ],
        &SIGNALS,
    );
}

/// [`MODEL`] with Womersley friction cells (`crate::womersley`) on the parent (4 mm: all
/// three cells kept, the first one's pole at 6 rad/s, between the inflow's two harmonics)
/// and on the tapered daughter narrowed to 1.1 → 0.7 mm (a thinner wall, 0.2 mm), whose
/// first segment keeps its three cells and whose other two fold the top cell into their
/// series inertance (its pole β₃ ν/r² at 4.9e3, 6.5e3 and 9.3e3 rad/s against the fold at
/// 6.28e3: 4 % or more from it, far beyond the difference quotient's 1e-4). The RCL daughter
/// carries no cells.
fn womersley() -> crate::model::NetworkSpec {
    let mut s = parse(MODEL).unwrap();
    s.vessels[0].wall_friction = Some(crate::segment::WallFriction::Womersley);
    s.vessels[1].wall_friction = Some(crate::segment::WallFriction::Womersley);
    let g = s.vessels[1].geometry.as_mut().unwrap();
    (g.radius_in, g.radius_out, g.wall_thickness) = (1.1e-3, 0.7e-3, Some(2e-4));
    s
}

/// The cells the Womersley model holds: 3 on each of the parent's segments, 3 + 2 + 2 on
/// the daughter's (so the tests below cover kept and folded cells alike).
#[test]
fn the_womersley_model_keeps_and_folds_cells() {
    let a = womersley().assemble().unwrap();
    let per_branch = |b: usize| {
        (a.circuit.friction_cells.iter())
            .filter(|c| c.branch == b)
            .count()
    };
    let counts: Vec<usize> = (a.circuit.segments.iter())
        .filter(|s| s.vessel == 1)
        .map(|s| per_branch(s.branch))
        .collect();
    assert_eq!(counts, [3, 2, 2]);
    assert_eq!(a.circuit.friction_cells.len(), 16);
}

/// The geometry of vessels with Womersley friction cells: the cells' R_k and L_k follow
/// each segment's R₀ and L₀ (a uniform radius by r⁻⁴ and r⁻², a taper's end radii by the
/// segments' own slopes with the flat profile, the length linearly; the modulus leaves
/// them), against central differences of whole periodic runs. (The narrow daughter's
/// modulus moves its outlet pressure by ~1e-6 of the other parameters' response, where the
/// quotient's rounding is 1e-6 of it: it is checked against the tangents by the adjoint.)
#[test]
fn geometry_of_womersley_vessels() {
    let base = womersley();
    for path in [
        "vessels.parent.radius",
        "vessels.parent.length",
        "vessels.parent.youngs_modulus",
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
        "vessels.d1.length",
    ] {
        check_on(&base, path);
    }
}

#[test]
fn adjoint_gradients_of_womersley_geometry_are_the_tangents() {
    super::tests::check_adjoint_of(
        &womersley(),
        &[
            "vessels.parent.radius",
            "vessels.parent.length",
            "vessels.d1.radius_in",
            "vessels.d1.radius_out",
            "vessels.d1.length",
            "vessels.d1.youngs_modulus",
        ],
        &SIGNALS,
    );
}

/// The thick (Lamé) wall: its C is no power law of the radius, so a radius and the end
/// radii take each segment's Gauss sum's own slopes (`segment_rlc_radius_slopes`), on the
/// plain Y and on the Womersley one (cells on every vessel), against central differences
/// of whole periodic runs (1e-6 of each signal's largest derivative), and the adjoint
/// against the tangents. h/r is 0.15–0.23 here: the thick wall's C differs from the thin
/// wall's by ~20 %, so a thin-wall slope would be off by far more than 1e-6.
#[test]
fn thick_wall_radii_against_central_differences() {
    let mut plain = parse(MODEL).unwrap();
    plain.wall_model = crate::segment::WallModel::Thick;
    let mut cells = womersley();
    cells.wall_model = crate::segment::WallModel::Thick;
    let paths = [
        "vessels.parent.radius",
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
    ];
    for base in [&plain, &cells] {
        for path in paths {
            check_on(base, path);
        }
    }
    check_on(&cells, "vessels.parent.length");
    super::tests::check_adjoint_of(&plain, &paths, &SIGNALS);
}

/// [`MODEL`] with Kelvin–Voigt walls of different relaxation times η/E on the parent
/// (0.5 ms) and the tapered daughter (5 ms), both in the π arrangement (half of each end
/// segment's C at the junction): their junction's wall mixes both (R_v = τ̄/C, τ̄ the
/// capacitance-weighted mean), so a vessel's parameter moves the wall's capacitance, its own
/// share and, by the modulus, the relaxation time. ωτ at the first harmonic is
/// 0.004–0.04, so the walls move the pressures by far more than the difference quotient's
/// rounding.
fn viscoelastic() -> crate::model::NetworkSpec {
    let mut s = parse(MODEL).unwrap();
    s.vessels[0].geometry.as_mut().unwrap().wall_viscosity = 2e2;
    s.vessels[0].arrangement = Some(Arrangement::Pi);
    s.vessels[1].geometry.as_mut().unwrap().wall_viscosity = 3e3;
    s
}

#[test]
fn geometry_of_viscoelastic_vessels() {
    let base = viscoelastic();
    for path in [
        "vessels.parent.radius",
        "vessels.parent.length",
        "vessels.parent.youngs_modulus",
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
        "vessels.d1.length",
        "vessels.d1.youngs_modulus",
    ] {
        check_on(&base, path);
    }
}

/// An elastic vessel's geometry and a lumped vessel's capacitance at a viscoelastic
/// neighbour's junction: their capacitance shares join the wall's C (behind the neighbour's
/// R_v = τ/C, which moves with it). The parent keeps its π arrangement (half its last
/// segment's C at the junction); the lumped daughter is given two segments of the default
/// (inverted-L) arrangement (its first segment's C at the junction) in place of its RCL form.
#[test]
fn elastic_values_at_a_viscoelastic_junction() {
    let mut base = viscoelastic();
    base.vessels[0].geometry.as_mut().unwrap().wall_viscosity = 0.0;
    let d2 = &mut base.vessels[2];
    (d2.arrangement, d2.segments) = (None, Some(2));
    for path in [
        "vessels.parent.radius",
        "vessels.parent.youngs_modulus",
        "vessels.parent.length",
        "vessels.d2.lumped.capacitance",
    ] {
        check_on(&base, path);
    }
}

#[test]
fn adjoint_gradients_of_viscoelastic_geometry_are_the_tangents() {
    super::tests::check_adjoint_of(
        &viscoelastic(),
        &[
            "vessels.parent.radius",
            "vessels.parent.length",
            "vessels.parent.youngs_modulus",
            "vessels.d1.radius_in",
            "vessels.d1.radius_out",
            "vessels.d1.youngs_modulus",
            "scale.compliance",
        ],
        &SIGNALS,
    );
}

/// [`MODEL`] with the RCL daughter's stenosis in svZeroDSolver's form: its capacitor row is
/// written by the chain rule on the inlet pressure (`super::tangent::chain_rule`).
fn svzerod_form() -> crate::model::NetworkSpec {
    let mut s = parse(MODEL).unwrap();
    let d2 = s.vessels.iter_mut().find(|v| v.name == "d2").unwrap();
    d2.lumped.as_mut().unwrap().stenosis_form = crate::model::StenosisForm::SvZeroD;
    s
}

#[test]
fn svzerod_form_stenosis_and_its_vessel_values() {
    let base = svzerod_form();
    for key in [
        "stenosis_coefficient",
        "resistance",
        "capacitance",
        "inductance",
    ] {
        check_on(&base, &format!("vessels.d2.lumped.{key}"));
    }
    // the other values reach the capacitor row through its pressures and flows alone
    check_on(&base, "boundary_conditions.o2.resistance");
    check_on(&base, "vessels.d1.radius_out");
    check_on(&base, "scale.compliance");
    check_on(&base, "scale.resistance");
}

#[test]
fn svzerod_form_adjoint_gradients_are_the_tangents() {
    super::tests::check_adjoint_of(
        &svzerod_form(),
        &[
            "vessels.d2.lumped.stenosis_coefficient",
            "vessels.d2.lumped.resistance",
            "vessels.d2.lumped.capacitance",
            "vessels.d2.lumped.inductance",
            "boundary_conditions.o2.resistance",
            "scale.compliance",
            "scale.resistance",
        ],
        &SIGNALS,
    );
}

/// Where the svZeroDSolver form's capacitor row switches form (a zero stenosis coefficient
/// or capacitance), its derivative is refused naming the parameter.
#[test]
fn svzerod_form_at_its_switch_is_refused() {
    let mut base = svzerod_form();
    let refused = |s: &crate::model::NetworkSpec, path: &str| {
        let err = sensitivities(s, &[path.into()], &[], settings())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains(&format!("'{path}'")) && err.contains("svzerod"),
            "{err}"
        );
    };
    let l = base.vessels[2].lumped.as_mut().unwrap();
    l.stenosis_coefficient = 0.0;
    refused(&base, "vessels.d2.lumped.stenosis_coefficient");
    let l = base.vessels[2].lumped.as_mut().unwrap();
    (l.stenosis_coefficient, l.capacitance) = (1.2e13, 0.0);
    refused(&base, "vessels.d2.lumped.capacitance");
}

/// `scale.compliance` on a viscoelastic wall moves its capacitance (now at the wall's elastic
/// pressure) and leaves R_v = τ/C (the patch's E/s scales τ = η/E as C); neither scale touches
/// the friction cells of a vessel given by its geometry (their law reads its R and L, which
/// `scale.compliance` leaves and `scale.resistance` does not scale).
#[test]
fn scales_on_viscoelastic_walls_and_womersley_vessels() {
    let mut base = parse(MODEL).unwrap();
    base.vessels[1].geometry.as_mut().unwrap().wall_viscosity = 3e3;
    base.vessels[0].geometry.as_mut().unwrap().wall_viscosity = 1e3;
    check_on(&base, "scale.compliance");
    check_on(&base, "scale.resistance");
    let mut base = parse(MODEL).unwrap();
    base.vessels[0].wall_friction = Some(crate::segment::WallFriction::Womersley);
    base.vessels[1].wall_friction = Some(crate::segment::WallFriction::Womersley);
    check_on(&base, "scale.compliance");
    check_on(&base, "scale.resistance");
}

/// [`MODEL`] with its daughter d2 lumped in two inverted-L segments with Womersley friction
/// cells (as a model-wide `wall_friction: womersley` gives a lumped vessel): each
/// segment's R₀ = R/2 and L₀ = L/2 set its cells (poles 23, 118 and 1.2e3 rad/s), so the
/// vessel's R and L move them, and `scale.resistance` with R.
fn lumped_womersley() -> crate::model::NetworkSpec {
    let mut base = parse(MODEL).unwrap();
    let lumped = crate::model::LumpedSpec {
        resistance: 3e7,
        inductance: 5e6,
        capacitance: 2e-10,
        stenosis_coefficient: 0.0,
        stenosis_form: Default::default(),
    };
    let d2 = &mut base.vessels[2];
    (d2.arrangement, d2.segments) = (None, Some(2));
    d2.lumped = Some(lumped);
    d2.wall_friction = Some(crate::segment::WallFriction::Womersley);
    base
}

#[test]
fn lumped_womersley_values_and_the_resistance_scale() {
    let base = lumped_womersley();
    assert_eq!(base.assemble().unwrap().circuit.friction_cells.len(), 6);
    for path in [
        "vessels.d2.lumped.resistance",
        "vessels.d2.lumped.inductance",
        "vessels.d2.lumped.capacitance",
        "scale.resistance",
    ] {
        check_on(&base, path);
    }
    super::tests::check_adjoint_of(
        &base,
        &[
            "vessels.d2.lumped.resistance",
            "vessels.d2.lumped.inductance",
            "scale.resistance",
        ],
        &SIGNALS,
    );
}
