//! Boundary conditions: one stamp function per condition type, each in its own file, so that
//! a new condition type touches one file (plus its `BoundarySpec` variant in `crate::model`).

mod coronary;
mod flow;
mod pressure;
mod rcr;
mod resistance;
mod svzerod_inlet;

use crate::circuit::{BoundaryTag, Circuit, Label, Part};
use crate::error::Result;
use crate::model::BoundarySpec;
use crate::waveform::{Waveform, WaveformSpec};

/// Where a condition sits: the free vessel end's circuit node, which end it is, and the tag
/// that marks the condition's own nodes (outside the transport domain).
pub(crate) struct Site {
    pub node: usize,
    /// At a vessel's inlet end (else its outlet end).
    pub inlet: bool,
    pub tag: usize,
    /// `boundary condition '<node>'`, for error messages.
    pub element: String,
}

impl Site {
    /// The name of the condition's element `part`.
    pub fn label(&self, part: Part) -> Label {
        Label::Boundary {
            tag: self.tag as u32,
            part,
        }
    }

    /// An optional distal pressure waveform (0 when absent).
    fn waveform(&self, spec: &Option<WaveformSpec>) -> Result<Waveform> {
        match spec {
            Some(s) => Waveform::from_spec(s, &self.element),
            None => Ok(Waveform::constant(0.0)),
        }
    }
}

/// Stamp the condition `bc` at graph node `node`; returns the compliance it adds.
pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    node: usize,
    inlet: bool,
    bc: &BoundarySpec,
) -> Result<f64> {
    let tag = circuit.boundaries.len();
    std::sync::Arc::make_mut(&mut circuit.names).add_boundary(name);
    circuit.boundaries.push(BoundaryTag {
        name: name.to_owned(),
        inlet,
    });
    let site = Site {
        node,
        inlet,
        tag,
        element: format!("boundary condition '{name}'"),
    };
    match bc {
        BoundarySpec::Flow { flow } => flow::stamp(circuit, &site, flow).map(|()| 0.0),
        BoundarySpec::Pressure { pressure } => {
            pressure::stamp(circuit, &site, pressure).map(|()| 0.0)
        }
        BoundarySpec::Resistance {
            resistance,
            pressure,
        } => resistance::stamp(circuit, &site, *resistance, pressure).map(|()| 0.0),
        BoundarySpec::Rcr {
            proximal_resistance,
            capacitance,
            distal_resistance,
            pressure,
        } => rcr::stamp(
            circuit,
            &site,
            rcr::Rcr {
                proximal: *proximal_resistance,
                capacitance: *capacitance,
                distal: *distal_resistance,
            },
            pressure,
        ),
        BoundarySpec::Coronary(c) => coronary::stamp(circuit, &site, c),
        BoundarySpec::SvzerodInlet(s) => svzerod_inlet::stamp(circuit, &site, s).map(|()| 0.0),
    }
}
