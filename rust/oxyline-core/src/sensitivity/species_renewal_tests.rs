//! Oxygen sensitivities with the Graetz wall's inlet renewal (its default law): the renewal
//! factor of each segment reads the inlet flow's harmonics (through the backward wall strain
//! of their Womersley wall shear), the net mean flows and the vessel's radius and length, so
//! every flow parameter moves it. Against central differences of whole periodic runs
//! (relative step 1e-4, judged as the other oxygen sensitivities: 1e-6 of the quotient's
//! largest value over the cycle, or its rounding floor), and the adjoint against the forward
//! tangents (1e-8 tells a wrong term).

use super::adjoint::tests::{mean_and_series_weights, worst_against_forward};
use super::tests::{run_with, settings};
use super::wall_tests::{check, model, signals};
use super::*;
use crate::model::parse;

/// The walls' Y network (`wall_tests::model`: a Graetz wall on parent and d1, a cycle-mean
/// Lévêque wall on d2) with the Graetz walls' default inlet renewal, an inflow whose first
/// harmonic is 70 % of its mean and the walls' Womersley numbers those of a kinematic
/// viscosity of 3e-7 m²/s (α ≈ 20 in the parent): the flow keeps its sign, but the wall
/// shear runs backward for part of the beat, so the renewal adds a conductance of its own
/// (checked below).
fn renewal_model() -> NetworkSpec {
    let text = model()
        .replace(
            r#""flow": "forward-mean""#,
            r#""kinematic_viscosity": 3e-7"#,
        )
        .replace(
            r#""cos": [1e-6, -0.4e-6], "sin": [1.2e-6, 0.3e-6]"#,
            r#""cos": [1.5e-6, -0.4e-6], "sin": [1.5e-6, 0.3e-6]"#,
        );
    let spec = parse(&text).unwrap();
    let sp = &spec.transport.as_ref().unwrap().species[0];
    assert!(matches!(
        sp.wall,
        WallSpec::Graetz {
            flow: crate::closure::MeanFlow::InletRenewal,
            ..
        }
    ));
    spec
}

/// The same network with the Graetz walls on the forward-flow mean (no renewal).
fn forward_mean_model() -> NetworkSpec {
    let mut spec = renewal_model();
    if let WallSpec::Graetz { flow, .. } = &mut spec.transport.as_mut().unwrap().species[0].wall {
        *flow = crate::closure::MeanFlow::ForwardMean;
    }
    spec
}

/// The renewal is at work in this network: the parent's and d1's wall uptake exceed the
/// forward-mean law's by more than a per cent (so the tests below exercise its derivative).
#[test]
fn the_test_network_renews_its_graetz_walls() {
    let sig = signals();
    let renewed = run_with(&renewal_model(), &[], &sig);
    let plain = run_with(&forward_mean_model(), &[], &sig);
    let nsig = sig.len();
    let mean = |s: &SpeciesSensitivities, j: usize| {
        let n = s.times.len();
        (0..n).map(|k| s.signals[k * nsig + j]).sum::<f64>() / n as f64
    };
    // signals 2 and 3: the parent's and d1's wall uptake
    for j in [2, 3] {
        let ratio = mean(&renewed, j) / mean(&plain, j);
        eprintln!("{:?}: renewed/forward-mean uptake {ratio:.4}", sig[j]);
        assert!(ratio > 1.01, "{:?}: {ratio}", sig[j]);
    }
}

/// Every kind of flow parameter: the parent's radius (the renewal conductance ∝ R^{5/2} and
/// its Womersley numbers; d1 is tapered, so its radius is no parameter) and the Graetz
/// vessels' lengths (the layer's development, the net-mean law's total), the Lévêque
/// vessel's radius (the flow split), a Windkessel's resistance and the inflow's scale (the
/// harmonics and the means).
#[test]
fn inlet_renewal_by_flow_parameters_against_central_differences() {
    let spec = renewal_model();
    for path in [
        "vessels.parent.radius",
        "vessels.parent.length",
        "vessels.d1.length",
        "vessels.d2.radius",
        "boundary_conditions.o1.distal_resistance",
        "scale.inflow",
    ] {
        let worst = check(&spec, path);
        eprintln!("{path}: {worst:.2e}");
        assert!(worst < 1e-6, "{path}: {worst:e}");
    }
}

/// A taper's end radii under renewing Graetz walls: each segment's radius moves by its own
/// share, the inlet segment's carrying the renewal conductance's Womersley numbers and
/// R^{5/2} (`closure::renewal::tangent`), each segment's its cap. The parent tapered 4 →
/// 3.6 mm (three segments; its renewal moves the network's uptake well above the
/// quotients' rounding): both end radii against central differences; d1 (3 → 2.5 mm, whose
/// renewal moves only its own wall above that rounding) and the parent's, the adjoint
/// against the forward tangents.
#[test]
fn inlet_renewal_by_taper_end_radii() {
    let mut spec = renewal_model();
    let parent = spec
        .vessels
        .iter_mut()
        .find(|v| v.name == "parent")
        .unwrap();
    parent.geometry.as_mut().unwrap().radius_out = 0.0036;
    for path in ["vessels.parent.radius_in", "vessels.parent.radius_out"] {
        let worst = check(&spec, path);
        eprintln!("{path}: {worst:.2e}");
        assert!(worst < 1e-6, "{path}: {worst:e}");
    }
    let paths = [
        "vessels.parent.radius_in",
        "vessels.parent.radius_out",
        "vessels.d1.radius_in",
        "vessels.d1.radius_out",
    ];
    let worst = super::adjoint::tests::mean_and_series_adjoint_worst(&spec, &paths, &signals());
    eprintln!("tapers under the inlet renewal: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}

/// The wall's own parameters on renewed laws (the factor does not read them).
#[test]
fn inlet_renewal_by_oxygen_parameters_against_central_differences() {
    let spec = renewal_model();
    for path in ["oxygen.wall.concentration", "oxygen.wall.enhancement"] {
        let worst = check(&spec, path);
        eprintln!("{path}: {worst:.2e}");
        assert!(worst < 1e-6, "{path}: {worst:e}");
    }
}

/// The renewal factors' derivatives in the adjoint against the forward tangents: the cycle
/// mean of every signal and a weighted series of each, per functional relative to its
/// largest |dJ/d ln θ|.
#[test]
fn inlet_renewal_adjoint_equals_forward() {
    let spec = renewal_model();
    let paths = [
        "vessels.parent.radius",
        "vessels.d1.length",
        "scale.inflow",
        "boundary_conditions.o1.distal_resistance",
        "oxygen.wall.enhancement",
    ];
    let sig = signals();
    let owned: Vec<String> = paths.iter().map(|p| p.to_string()).collect();
    let ns = settings().steps_per_cycle;
    let nsig = sig.len();
    let weights = mean_and_series_weights(ns, nsig);
    let (values, adj) =
        species_adjoint_with(&spec, &owned, &sig, |_, _| Ok(weights.clone()), settings()).unwrap();
    let fwd = run_with(&spec, &paths, &sig);
    let worst = worst_against_forward(
        &weights,
        ns * nsig,
        paths.len(),
        &values,
        &adj.gradients,
        &fwd.derivs,
    );
    eprintln!("inlet renewal: adjoint against forward {worst:.2e}");
    assert!(worst < 1e-8, "{worst:e}");
}
