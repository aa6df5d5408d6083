//! Former home of the network model; kept as re-exports so that existing paths
//! (`oxyline_core::network::parse`, `network::Probes`) keep working. New code uses
//! `crate::model` (input types), `crate::assemble` (graph → circuit) and `crate::output`
//! (probes, column schema).

pub use crate::assemble::{Assembled, SegmentRow, Summary};
pub use crate::model::{
    Arrangement, BloodSpec, BoundarySpec, GeometrySpec, LumpedSpec, NetworkSpec, VesselSpec, parse,
};
pub use crate::output::Probes;
