//! The one reader of models from Python objects: the native model's vessels and outlets
//! (`native`), read key by key from the Python dicts, and the canonical element dicts
//! (`extract`) an ensemble or a released model hands over.

pub(crate) mod extract;
pub(crate) mod native;

pub(crate) use native::NativeParts;
pub(crate) mod node;
pub(crate) mod schema;
