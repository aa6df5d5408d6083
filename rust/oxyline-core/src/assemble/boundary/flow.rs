//! `flow`: a prescribed inflow Q(t), positive along the vessel.

use super::Site;
use crate::circuit::Circuit;
use crate::error::Result;
use crate::waveform::{Waveform, WaveformSpec};

pub(super) fn stamp(circuit: &mut Circuit, site: &Site, flow: &WaveformSpec) -> Result<()> {
    let w = Waveform::from_spec(flow, &site.element)?;
    // positive flow runs along the vessel: into the network at an inlet end
    let w = if site.inlet { w } else { negate(w) };
    circuit.sources.push((site.node, w));
    circuit.source_boundary.push(site.tag);
    Ok(())
}

fn negate(w: Waveform) -> Waveform {
    match w {
        Waveform::Constant(v) => Waveform::Constant(-v),
        Waveform::Table { t, v, m, mean } => Waveform::Table {
            t,
            v: v.iter().map(|x| -x).collect(),
            m: m.map(|m| m.iter().map(|x| -x).collect()),
            mean: -mean,
        },
        Waveform::Fourier {
            omega,
            mean,
            cos,
            sin,
        } => Waveform::Fourier {
            omega,
            mean: -mean,
            cos: cos.iter().map(|x| -x).collect(),
            sin: sin.iter().map(|x| -x).collect(),
        },
    }
}
