//! Stamp the closed-loop heart block (`heart_pulmonary`) and closed-loop coronary beds
//! (`coronary_bed`): their circuit parts plus the elements of `crate::element::heart` and
//! `crate::element::coronary` (docs/physics.md §1.10).

use super::checks::{check_finite, check_nonnegative, check_positive};
use super::vessel::Chain;
use crate::circuit::{Circuit, CircuitElement};
use crate::element::activation::Activation;
use crate::element::heart::{Atrium, HeartParams};
use crate::error::{Error, Result};
use crate::model::{CoronaryBedSpec, HeartPulmonarySpec, Ventricle};

/// The block's parameters, checked (every resistance, inductance, capacitance, elastance and
/// time positive or zero as the law needs).
fn params(el: &str, s: &HeartPulmonarySpec) -> Result<HeartParams> {
    for (k, v) in [
        ("period", s.period),
        ("atrial_systole_fraction", s.atrial_systole_fraction),
        ("p_wave_divisor", s.p_wave_divisor),
        ("pulmonary_resistance", s.pulmonary_resistance),
        ("pulmonary_capacitance", s.pulmonary_capacitance),
        ("aortic_capacitance", s.aortic_capacitance),
    ] {
        check_positive(el, k, v)?;
    }
    for (k, v) in [
        ("right_ventricle_elastance", s.right_ventricle_elastance),
        ("left_ventricle_elastance", s.left_ventricle_elastance),
        ("right_atrium_elastance", s.right_atrium_elastance),
        ("left_atrium_elastance", s.left_atrium_elastance),
        (
            "right_atrium_passive_pressure",
            s.right_atrium_passive_pressure,
        ),
        (
            "left_atrium_passive_pressure",
            s.left_atrium_passive_pressure,
        ),
        ("tricuspid_resistance", s.tricuspid_resistance),
        ("pulmonary_valve_resistance", s.pulmonary_valve_resistance),
        ("mitral_resistance", s.mitral_resistance),
        ("aortic_valve_resistance", s.aortic_valve_resistance),
    ] {
        check_nonnegative(el, k, v)?;
    }
    for (k, v) in [
        (
            "right_atrium_passive_volume_coefficient",
            s.right_atrium_passive_volume_coefficient,
        ),
        (
            "left_atrium_passive_volume_coefficient",
            s.left_atrium_passive_volume_coefficient,
        ),
        ("right_ventricle_rest_volume", s.right_ventricle_rest_volume),
        ("left_ventricle_rest_volume", s.left_ventricle_rest_volume),
        ("right_atrium_rest_volume", s.right_atrium_rest_volume),
        ("left_atrium_rest_volume", s.left_atrium_rest_volume),
    ] {
        check_finite(el, k, v)?;
    }
    Ok(HeartParams {
        period: s.period,
        atrial_activation: Activation::WrappingCosine {
            systole_fraction: s.atrial_systole_fraction,
            p_wave_divisor: s.p_wave_divisor,
        },
        right_atrium: Atrium {
            max_elastance: s.right_atrium_elastance,
            passive_pressure: s.right_atrium_passive_pressure,
            passive_volume_coefficient: s.right_atrium_passive_volume_coefficient,
            rest_volume: s.right_atrium_rest_volume,
        },
        left_atrium: Atrium {
            max_elastance: s.left_atrium_elastance,
            passive_pressure: s.left_atrium_passive_pressure,
            passive_volume_coefficient: s.left_atrium_passive_volume_coefficient,
            rest_volume: s.left_atrium_rest_volume,
        },
        ventricle_elastance: [s.right_ventricle_elastance, s.left_ventricle_elastance],
        ventricle_rest_volume: [s.right_ventricle_rest_volume, s.left_ventricle_rest_volume],
        valve_resistance: [
            s.tricuspid_resistance,
            s.pulmonary_valve_resistance,
            s.mitral_resistance,
            s.aortic_valve_resistance,
        ],
        pulmonary_resistance: s.pulmonary_resistance,
    })
}

/// Stamp a heart block between `from` (venous return) and `to` (aorta). Returns the chain
/// (inlet wire … outlet wire) and the ventricles' pressure nodes [right, left].
pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    spec: &HeartPulmonarySpec,
    (from, to): (usize, usize),
) -> Result<(Chain, [usize; 2])> {
    let el = format!("heart_pulmonary '{name}'");
    let params = params(&el, spec)?;
    for (k, v) in [
        ("tricuspid_inductance", spec.tricuspid_inductance),
        (
            "pulmonary_valve_inductance",
            spec.pulmonary_valve_inductance,
        ),
        ("mitral_inductance", spec.mitral_inductance),
        ("aortic_valve_inductance", spec.aortic_valve_inductance),
    ] {
        check_nonnegative(&el, k, v)?;
    }
    circuit.add_vessel(name);
    let node =
        |c: &mut Circuit, part: &str, cap: f64| c.add_node(format!("{name}: {part}"), cap, 0.0);
    let ra = node(circuit, "right atrium", 0.0);
    let rv = node(circuit, "right ventricle", 0.0);
    let la = node(circuit, "left atrium", 0.0);
    let lv = node(circuit, "left ventricle", 0.0);
    let ao = node(circuit, "aorta", spec.aortic_capacitance);
    let mut branch = |part: &str, a: usize, b: usize, l: f64| {
        circuit.add_branch(format!("{name}: {part}"), a, b, 0.0, l, 0.0)
    };
    let w_in = branch("venous return", from, ra, 0.0);
    // the pulmonary valve's branch ends at the left atrium (see `crate::element::heart`)
    let valves = [
        branch("tricuspid valve", ra, rv, spec.tricuspid_inductance),
        branch("pulmonary valve", rv, la, spec.pulmonary_valve_inductance),
        branch("mitral valve", la, lv, spec.mitral_inductance),
        branch("aortic valve", lv, ao, spec.aortic_valve_inductance),
    ];
    let w_out = branch("aortic outflow", ao, to, 0.0);
    let mut volumes = [0; 4];
    let starts = [
        spec.initial_right_atrium_volume,
        spec.initial_right_ventricle_volume,
        spec.initial_left_atrium_volume,
        spec.initial_left_ventricle_volume,
    ];
    for (k, (chamber, part)) in [ra, rv, la, lv]
        .into_iter()
        .zip([
            "right atrium",
            "right ventricle",
            "left atrium",
            "left ventricle",
        ])
        .enumerate()
    {
        volumes[k] = circuit.add_extra(format!("{name}: {part}"), 1.0);
        circuit.moved_rows.push((chamber, volumes[k]));
        circuit.initial_extras.push((volumes[k], starts[k]));
    }
    let pulmonary = circuit.add_extra(format!("{name}: pulmonary"), spec.pulmonary_capacitance);
    circuit
        .initial_extras
        .push((pulmonary, spec.initial_pulmonary_pressure));
    circuit.elements.push(CircuitElement::Heart {
        name: el,
        params: Box::new(params),
        nodes: [ra, rv, la, lv, ao],
        branches: valves,
        volumes,
        pulmonary,
    });
    let chain = Chain {
        points: vec![from, ra, rv, la, lv, ao, to],
        branches: vec![w_in, valves[0], valves[1], valves[2], valves[3], w_out],
    };
    Ok((chain, [rv, lv]))
}

/// Stamp a closed-loop coronary bed; its ventricle is resolved later (see [`resolve`]), when
/// every heart block is stamped: the element holds `usize::MAX` until then.
pub(crate) fn stamp_coronary(
    circuit: &mut Circuit,
    name: &str,
    spec: &CoronaryBedSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let el = format!("coronary_bed '{name}'");
    for (k, v) in [
        ("arterial_resistance", spec.arterial_resistance),
        ("arterial_capacitance", spec.arterial_capacitance),
        ("microvascular_resistance", spec.microvascular_resistance),
        ("venous_resistance", spec.venous_resistance),
    ] {
        check_nonnegative(&el, k, v)?;
    }
    check_positive(
        &el,
        "intramyocardial_capacitance",
        spec.intramyocardial_capacitance,
    )?;
    check_finite(&el, "intramyocardial_factor", spec.intramyocardial_factor)?;
    circuit.add_vessel(name);
    let a = circuit.add_node(format!("{name}: arterial"), spec.arterial_capacitance, 0.0);
    let m = circuit.add_node(format!("{name}: intramyocardial"), 0.0, 0.0);
    let mut branch = |part: &str, p: usize, q: usize, r: f64| {
        circuit.add_branch(format!("{name}: {part}"), p, q, r, 0.0, 0.0)
    };
    let ra = branch("arterial resistance", from, a, spec.arterial_resistance);
    let ram = branch(
        "microvascular resistance",
        a,
        m,
        spec.microvascular_resistance,
    );
    let rv = branch("venous resistance", m, to, spec.venous_resistance);
    let volume = circuit.add_extra(format!("{name}: intramyocardial"), 1.0);
    circuit.moved_rows.push((m, volume));
    circuit.elements.push(CircuitElement::Coronary {
        name: el,
        capacitance: spec.intramyocardial_capacitance,
        factor: spec.intramyocardial_factor,
        node: m,
        volume,
        ventricle: usize::MAX,
    });
    Ok(Chain {
        points: vec![from, a, m, to],
        branches: vec![ra, ram, rv],
    })
}

/// Point every coronary bed at its heart block's ventricle node. `hearts`: (heart name,
/// [right, left] ventricle nodes); `beds`: (element index, bed name, spec) in stamp order.
pub(crate) fn resolve(
    circuit: &mut Circuit,
    hearts: &[(String, [usize; 2])],
    beds: &[(usize, String, CoronaryBedSpec)],
) -> Result<()> {
    for (index, name, spec) in beds {
        let Some((_, nodes)) = hearts.iter().find(|(h, _)| *h == spec.heart) else {
            return Err(Error::model(
                format!("coronary_bed '{name}'"),
                format!("heart '{}' is not a heart_pulmonary element", spec.heart),
            ));
        };
        let node = match spec.ventricle {
            Ventricle::Right => nodes[0],
            Ventricle::Left => nodes[1],
        };
        if let CircuitElement::Coronary { ventricle, .. } = &mut circuit.elements[*index] {
            *ventricle = node;
        }
    }
    Ok(())
}
