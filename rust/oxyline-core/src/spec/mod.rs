//! Serde input types (the canonical model's sections), kept apart from what is built from them.

pub mod transport;
