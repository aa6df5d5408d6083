//! The model as the core reads it: structured-tree growth and the haemoglobin facilitation
//! factor, computed when a model is read (docs/structured-tree.md, docs/physics.md §3.4).

pub mod facilitation;
pub mod structured_tree;
