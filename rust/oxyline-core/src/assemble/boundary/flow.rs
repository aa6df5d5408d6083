//! `flow`: a prescribed inflow Q(t), positive along the vessel.

use super::Site;
use crate::circuit::Circuit;
use crate::error::Result;
use crate::waveform::{Waveform, WaveformSpec};

pub(super) fn stamp(circuit: &mut Circuit, site: &Site, flow: &WaveformSpec) -> Result<()> {
    let w = Waveform::from_spec(flow, &site.element)?;
    // positive flow runs along the vessel: into the network at an inlet end
    let w = if site.inlet { w } else { w.negated() };
    circuit.sources.push((site.node, w));
    circuit.source_boundary.push(site.tag);
    Ok(())
}
