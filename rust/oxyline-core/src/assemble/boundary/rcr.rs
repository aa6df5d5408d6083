//! `rcr`: three-element Windkessel, proximal resistance – capacitor – distal resistance to a
//! distal pressure (0 when absent).

use super::Site;
use crate::assemble::checks::{check_nonnegative, check_positive};
use crate::circuit::{Circuit, Part};
use crate::error::Result;
use crate::waveform::WaveformSpec;

pub(super) struct Rcr {
    pub proximal: f64,
    pub capacitance: f64,
    pub distal: f64,
}

/// Returns the Windkessel capacitance (for the summary's total compliance).
pub(super) fn stamp(
    circuit: &mut Circuit,
    site: &Site,
    rcr: Rcr,
    pressure: &Option<WaveformSpec>,
) -> Result<f64> {
    let el = &site.element;
    check_nonnegative(el, "proximal_resistance", rcr.proximal)?;
    check_nonnegative(el, "capacitance", rcr.capacitance)?;
    check_positive(el, "distal_resistance", rcr.distal)?;
    let wk = circuit.add_node(site.label(Part::Capacitor), rcr.capacitance, 0.0);
    circuit.nodes[wk].windkessel = true;
    circuit.nodes[wk].boundary = Some(site.tag as u32);
    let g = circuit.add_node(site.label(Part::Distal), 0.0, 0.0);
    circuit.nodes[g].boundary = Some(site.tag as u32);
    circuit.fixed_pressures.push((g, site.waveform(pressure)?));
    let (proximal, distal) = (
        site.label(Part::ProximalResistance),
        site.label(Part::DistalResistance),
    );
    // branches keep the order and direction of the flow path from the network outwards
    if site.inlet {
        circuit.add_branch(distal, g, wk, rcr.distal, 0.0, 0.0);
        circuit.add_branch(proximal, wk, site.node, rcr.proximal, 0.0, 0.0);
    } else {
        circuit.add_branch(proximal, site.node, wk, rcr.proximal, 0.0, 0.0);
        circuit.add_branch(distal, wk, g, rcr.distal, 0.0, 0.0);
    }
    Ok(rcr.capacitance)
}
