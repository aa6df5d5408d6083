//! Stamp a `chamber_sphere` element (svZeroDSolver's `ChamberSphere`, docs/physics.md §1.11):
//! the chamber's pressure node between two wires (its inflow and outflow), and its five wall
//! unknowns; the node keeps its ordinary flow balance, which the element completes with the
//! volume the growing sphere takes up (`crate::element::sphere`).

use super::checks::{check_finite, check_positive};
use super::vessel::Chain;
use crate::circuit::{Circuit, CircuitElement, Label, Part};
use crate::element::sphere::SphereParams;
use crate::error::Result;
use crate::model::ChamberSphereSpec;

/// The checked wall parameters of chamber `name`.
pub fn sphere_params(name: &str, s: &ChamberSphereSpec) -> Result<SphereParams> {
    let el = format!("chamber_sphere '{name}'");
    for (key, v) in [
        ("density", s.density),
        ("wall_thickness", s.wall_thickness),
        ("reference_radius", s.reference_radius),
        ("activation_steepness", s.activation_steepness),
        ("period", s.period),
    ] {
        check_positive(&el, key, v)?;
    }
    for (key, v) in [
        ("w1", s.w1),
        ("w2", s.w2),
        ("viscosity", s.viscosity),
        ("max_active_stress", s.max_active_stress),
        ("max_activation_rate", s.max_activation_rate),
        ("min_activation_rate", s.min_activation_rate),
        ("systole_start", s.systole_start),
        ("diastole_start", s.diastole_start),
    ] {
        check_finite(&el, key, v)?;
    }
    Ok(SphereParams {
        density: s.density,
        thickness: s.wall_thickness,
        radius: s.reference_radius,
        w1: s.w1,
        w2: s.w2,
        viscosity: s.viscosity,
        max_active_stress: s.max_active_stress,
        alpha_max: s.max_activation_rate,
        alpha_min: s.min_activation_rate,
        t_systole: s.systole_start,
        t_diastole: s.diastole_start,
        steepness: s.activation_steepness,
        period: s.period,
    })
}

pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    spec: &ChamberSphereSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let params = sphere_params(name, spec)?;
    let vessel = circuit.add_vessel(name) as u32;
    let label = |part| Label::Vessel { vessel, part, k: 0 };
    // P_in = P_out (upstream's pressure equality): one node, wired to both ends so that the
    // element's flow_in and flow_out are the chamber's inflow and outflow
    let node = circuit.add_node(label(Part::Point), 0.0, 0.0);
    let inflow = circuit.add_branch(label(Part::Resistance), from, node, 0.0, 0.0, 0.0);
    let outflow = circuit.add_branch(label(Part::Inductance), node, to, 0.0, 0.0, 0.0);
    // mass-matrix entries: ṙ, ρ d₀ v̇, none for the stress, τ̇, V̇
    let extras = [
        (Part::WallDisplacement, 1.0),
        (Part::WallVelocity, params.density * params.thickness),
        (Part::WallStress, 0.0),
        (Part::ActiveStress, 1.0),
        (Part::Volume, 1.0),
    ]
    .map(|(part, mass)| circuit.add_extra(label(part), mass));
    circuit.elements.push(CircuitElement::Sphere {
        name: format!("chamber_sphere '{name}'"),
        params,
        node,
        extras,
    });
    Ok(Chain {
        points: vec![from, node, to],
        branches: vec![inflow, outflow],
    })
}
