//! `pressure`: the vessel end's pressure P(t) is prescribed.

use super::Site;
use crate::circuit::Circuit;
use crate::error::Result;
use crate::waveform::{Waveform, WaveformSpec};

pub(super) fn stamp(circuit: &mut Circuit, site: &Site, pressure: &WaveformSpec) -> Result<()> {
    circuit
        .fixed_pressures
        .push((site.node, Waveform::from_spec(pressure, &site.element)?));
    circuit.nodes[site.node].boundary = Some(site.tag as u32);
    Ok(())
}
