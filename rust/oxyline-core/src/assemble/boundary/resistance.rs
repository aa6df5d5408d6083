//! `resistance`: a resistor from the vessel end to a distal pressure (0 when absent).

use super::Site;
use crate::assemble::checks::check_nonnegative;
use crate::circuit::{Circuit, Part};
use crate::error::Result;
use crate::waveform::WaveformSpec;

pub(super) fn stamp(
    circuit: &mut Circuit,
    site: &Site,
    resistance: f64,
    pressure: &Option<WaveformSpec>,
) -> Result<()> {
    let el = &site.element;
    check_nonnegative(el, "resistance", resistance)?;
    let g = circuit.add_node(site.label(Part::Distal), 0.0, 0.0);
    circuit.nodes[g].boundary = Some(site.tag as u32);
    circuit.fixed_pressures.push((g, site.waveform(pressure)?));
    let (a, b) = if site.inlet {
        (g, site.node)
    } else {
        (site.node, g)
    };
    circuit.add_branch(site.label(Part::Resistance), a, b, resistance, 0.0, 0.0);
    Ok(())
}
