//! Stamp a `chamber` element: the chamber's volume unknown (which takes the flow balance of the
//! element's inlet node), its pressure law at that node and an inductor to the outlet node
//! (`crate::element::chamber`, docs/physics.md §1.8).

use super::checks::{check_nonnegative, check_positive};
use super::vessel::Chain;
use crate::circuit::{Circuit, CircuitElement, Label, Part};
use crate::element::activation::Activation;
use crate::element::chamber::{Elastance, ElastanceLaw};
use crate::error::Result;
use crate::spec::{ActivationSpec, ChamberLawSpec, ChamberSpec};

fn activation(el: &str, spec: &ActivationSpec, period: f64) -> Result<Activation> {
    Ok(match *spec {
        ActivationSpec::HalfCosine { t_active, t_twitch } => {
            check_nonnegative(el, "t_active", t_active)?;
            check_positive(el, "t_twitch", t_twitch)?;
            Activation::HalfCosine { t_active, t_twitch }
        }
        ActivationSpec::PiecewiseCosine {
            contract_start,
            relax_start,
            contract_duration,
            relax_duration,
        } => {
            check_positive(el, "contract_duration", contract_duration)?;
            check_positive(el, "relax_duration", relax_duration)?;
            Activation::PiecewiseCosine {
                contract_start,
                relax_start,
                contract_duration,
                relax_duration,
            }
        }
        ActivationSpec::TwoHill {
            t_shift,
            tau_1,
            tau_2,
            m1,
            m2,
        } => {
            check_positive(el, "tau_1", tau_1)?;
            check_positive(el, "tau_2", tau_2)?;
            Activation::two_hill(el, period, [t_shift, tau_1, tau_2, m1, m2])?
        }
    })
}

/// The elastance law E(t), V_rest(t) of chamber `name` (checked).
pub fn chamber_elastance(name: &str, spec: &ChamberSpec) -> Result<Elastance> {
    let el = format!("chamber '{name}'");
    check_positive(&el, "period", spec.period)?;
    check_nonnegative(&el, "inductance", spec.inductance)?;
    let law = match spec.law {
        ChamberLawSpec::ElastanceInductor {
            max_elastance,
            min_elastance,
            rest_volume_diastole,
            rest_volume_systole,
        } => {
            check_positive(&el, "min_elastance", min_elastance)?;
            check_positive(&el, "max_elastance", max_elastance)?;
            ElastanceLaw::ElastanceInductor {
                e_max: max_elastance,
                e_min: min_elastance,
                v_rest_diastole: rest_volume_diastole,
                v_rest_systole: rest_volume_systole,
            }
        }
        ChamberLawSpec::Linear {
            max_elastance,
            passive_elastance,
            rest_volume,
        } => {
            check_positive(&el, "passive_elastance", passive_elastance)?;
            check_nonnegative(&el, "max_elastance", max_elastance)?;
            ElastanceLaw::Linear {
                e_max: max_elastance,
                e_pass: passive_elastance,
                v_rest: rest_volume,
            }
        }
    };
    Ok(Elastance {
        law,
        activation: activation(&el, &spec.activation, spec.period)?,
        period: spec.period,
    })
}

pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    spec: &ChamberSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let elastance = chamber_elastance(name, spec)?;
    let el = format!("chamber '{name}'");
    let vessel = circuit.add_vessel(name) as u32;
    let label = |part| Label::Vessel { vessel, part, k: 0 };
    // the chamber's own pressure node behind a wire from the inlet node: the wire carries the
    // inflow Q_in (recorded as the element's flow_in), and the inlet node keeps its ordinary
    // flow balance (other vessels' capacitance or a boundary condition may sit there)
    let node = circuit.add_node(label(Part::Point), 0.0, 0.0);
    let wire = circuit.add_branch(label(Part::Resistance), from, node, 0.0, 0.0, 0.0);
    let volume = circuit.add_extra(label(Part::Volume), 1.0);
    circuit.moved_rows.push((node, volume));
    circuit.initial_extras.push((volume, spec.initial_volume));
    let branch = circuit.add_branch(label(Part::Inductance), node, to, 0.0, spec.inductance, 0.0);
    circuit.elements.push(CircuitElement::Chamber {
        name: el,
        elastance,
        node,
        volume,
    });
    Ok(Chain {
        points: vec![from, node, to],
        branches: vec![wire, branch],
    })
}
