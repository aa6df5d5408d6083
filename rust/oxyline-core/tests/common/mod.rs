//! The tube fixture shared by the transport and tissue integration tests: one straight vessel
//! from `in` (a flow inlet) to `out` (a resistance outlet) with a transport section, built
//! through the same parse → assemble → `Transport::build` path as a run.

// each test crate uses its own part of the fixture
#![allow(dead_code)]

use oxyline_core::Transport;
use oxyline_core::model::parse;

pub struct Built {
    pub assembled: oxyline_core::Assembled,
    pub dae: oxyline_core::Dae,
    pub transport: Transport,
}

/// Single tube of `n` segments; `geometry_extra` is appended inside its geometry (e.g.
/// `, "wall_thickness": ...`), `flow` is the inlet's flow object, and `transport` the body of
/// the transport section (`"species": [...]`, optionally preceded by other keys).
pub fn tube(
    radius: f64,
    length: f64,
    n: usize,
    geometry_extra: &str,
    flow: &str,
    r_out: f64,
    transport: &str,
) -> String {
    format!(
        r#"{{"vessels": [{{"name": "tube", "from": "in", "to": "out", "segments": {n},
            "geometry": {{"length": {length}, "radius_in": {radius}, "radius_out": {radius} {geometry_extra}}}}}],
          "boundary_conditions": {{"in": {{"type": "flow", "flow": {flow}}},
                                   "out": {{"type": "resistance", "resistance": {r_out}}}}},
          "transport": {{{transport}}}}}"#
    )
}

pub fn build(json: &str) -> Built {
    try_build(json).unwrap()
}

/// `build`, with the transport's model error (the flow model must be valid).
pub fn try_build(json: &str) -> oxyline_core::Result<Built> {
    let spec = parse(json).unwrap();
    let assembled = spec.assemble().unwrap();
    let dae = assembled.circuit.assemble().unwrap();
    let transport = Transport::build(
        spec.transport.as_ref().unwrap(),
        &assembled.circuit,
        &dae,
        &assembled.probes,
    )?;
    Ok(Built {
        assembled,
        dae,
        transport,
    })
}

/// The transport's model error of a model that must be refused.
pub fn build_error(json: &str) -> String {
    match try_build(json) {
        Ok(_) => panic!("the model was accepted"),
        Err(e) => e.to_string(),
    }
}
