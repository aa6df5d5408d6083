//! The one reader of models from Python objects: a native model dict read in one call by the
//! core's schema (`model`: top level, elements, transport), its plain vessels and outlets read
//! straight into the network's parts (`native`), an ensemble's variant read in the same order
//! reusing its base's canonical elements (`variant`), the schema's pieces (`schema`), canonical
//! dicts read by the core's serde types in place (`de`), and
//! the importers' calls into the core (`formats`).

pub(crate) mod de;
pub(crate) mod formats;
pub(crate) mod model;
pub(crate) mod native;

pub(crate) use native::NativeParts;
pub(crate) mod node;
pub(crate) mod schema;
pub(crate) mod variant;
