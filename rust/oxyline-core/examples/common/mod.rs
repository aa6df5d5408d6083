//! The model-loading prologue and the CPU clock shared by the per-step cost examples
//! (`leveque_cost`, `o2_step_ratio`, `o2_pass_ratio`, `transport_memory`), included by each with `mod common;`.
// (each example uses a part of this module)
#![allow(dead_code)]

use oxyline_core::transport::{BALANCE_COLUMNS, VESSEL_COLUMNS};
use oxyline_core::{Assembled, model::parse};
use oxyline_core::{Dae, Transport};

/// CPU seconds of this process (user + system, from /proc: robust on a shared machine).
pub fn cpu() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("/proc/self/stat");
    // the fields after the parenthesised command name; utime and stime are fields 14, 15
    let rest = &stat[stat.rfind(')').expect("stat format") + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks: f64 = f[11].parse::<f64>().expect("utime") + f[12].parse::<f64>().expect("stime");
    ticks / 100.0
}

/// A model file's network, circuit and transport prototype.
pub struct Model {
    pub assembled: Assembled,
    pub dae: Dae,
    pub transport: Transport,
}

/// Load, assemble and build the transport of the model file at `path` (canonical SI JSON
/// with a transport section).
pub fn load(path: &str) -> Model {
    let json = std::fs::read_to_string(path).expect("readable model file");
    let spec = parse(&json).expect("valid model");
    let assembled = spec.assemble().expect("valid network");
    let dae = assembled.circuit.assemble().expect("valid circuit");
    let spec_tr = spec.transport.as_ref().expect("a transport section");
    let transport =
        Transport::build(spec_tr, &assembled.circuit, &dae, &assembled.probes).expect("valid");
    Model {
        assembled,
        dae,
        transport,
    }
}

impl Model {
    /// The vessel-level species columns and the mass-balance columns (what the bench trees
    /// record: vessel output, no segments).
    pub fn vessel_columns(&self) -> Vec<usize> {
        let nv = self.assembled.probes.vessels.len();
        let mut columns: Vec<usize> = (0..VESSEL_COLUMNS * nv).collect();
        let balance = self.transport.columns_per_species() - BALANCE_COLUMNS;
        columns.extend(balance..balance + BALANCE_COLUMNS);
        columns
    }
}
