//! The one reader of models from Python objects: a native model dict read in one call
//! (`model`: top level, elements, transport, by the core's schema), its plain vessels and
//! outlets read key by key straight into the network's parts (`native`), the schema's
//! pieces for an ensemble's variants (`schema`), and the canonical element dicts (`extract`)
//! an ensemble hands over.

pub(crate) mod extract;
pub(crate) mod model;
pub(crate) mod native;

pub(crate) use native::NativeParts;
pub(crate) mod node;
pub(crate) mod schema;
