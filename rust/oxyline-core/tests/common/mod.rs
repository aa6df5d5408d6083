//! The fixtures shared by the transport and tissue integration tests and the core's own unit
//! tests (the crate includes this file as `test_common`): a tube, one straight vessel from
//! `in` (a flow inlet) to `out` (a resistance outlet) with a transport section, and a random
//! tree, built through the same parse → assemble → `Transport::build` path as a run.

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

/// The next number in [0, 1) of a linear congruential sequence (Knuth's MMIX constants):
/// reproducible models and states without a random-number crate.
pub fn lcg(seed: &mut u64) -> f64 {
    *seed = seed
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    ((*seed >> 33) as f64) / (1u64 << 31) as f64
}

/// A random tree of `vessels` vessels (1–4 segments each, up to three children per
/// junction: mixing points), a pulsatile-free flow inlet and a resistance per leaf, with
/// oxygen bound to haemoglobin (Hill) and a constant-k wall.
pub fn random_tree(vessels: usize, seed: &mut u64) -> String {
    let mut rnd = || lcg(seed);
    let mut children = vec![0usize; vessels];
    let mut list = Vec::new();
    for i in 0..vessels {
        let from = if i == 0 {
            "in".to_owned()
        } else {
            // a parent with fewer than three children
            let mut p = (rnd() * i as f64) as usize;
            while children[p] >= 3 {
                p = (p + 1) % i;
            }
            children[p] += 1;
            format!("n{p}")
        };
        let r = 2e-3 * (0.5 + rnd());
        list.push(format!(
            r#"{{"name": "v{i}", "from": "{from}", "to": "n{i}", "segments": {},
                "geometry": {{"length": 0.02, "radius_in": {r}, "radius_out": {r},
                "wall_thickness": 3e-4, "youngs_modulus": 4e5}}}}"#,
            1 + (rnd() * 4.0) as usize
        ));
    }
    let mut bcs =
        vec![r#""in": {"type": "flow", "flow": {"kind": "constant", "value": 2e-6}}"#.to_owned()];
    for (i, _) in children.iter().enumerate().filter(|(_, c)| **c == 0) {
        bcs.push(format!(
            r#""n{i}": {{"type": "resistance", "resistance": 1e9}}"#
        ));
    }
    format!(
        r#"{{"vessels": [{}], "boundary_conditions": {{{}}},
            "transport": {{"species": [{{"name": "o2",
                "inlet": {{"kind": "constant", "value": 0.127}}, "initial": 0.1,
                "binding": {{"kind": "hill", "solubility": 1e-5, "p50": 3573.0, "n": 2.7,
                             "capacity": 8.9}},
                "wall": {{"model": "mass-transfer", "k": 1e-5,
                          "wall_concentration": 0.04}}}}]}}}}"#,
        list.join(","),
        bcs.join(",")
    )
}

/// A ring a → b → c → d → a fed at a by a parent of four segments, drained at b and d
/// and through a pendant vessel of three segments at c, dissolved oxygen with a
/// constant-k wall: a core (the ring) with pendant trees (the parent, the outlets).
pub const RING: &str = r#"{
  "vessels": [
    {"name": "p", "from": "in", "to": "a", "segments": 4,
     "geometry": {"length": 0.05, "radius_in": 0.003, "radius_out": 0.003}},
    {"name": "ab", "from": "a", "to": "b", "segments": 2,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "bc", "from": "b", "to": "c", "segments": 1,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "cd", "from": "c", "to": "d", "segments": 2,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "da", "from": "d", "to": "a", "segments": 1,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "bo", "from": "b", "to": "o1", "segments": 1,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "co", "from": "c", "to": "o2", "segments": 3,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}},
    {"name": "do", "from": "d", "to": "o3", "segments": 1,
     "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "constant", "value": 3e-6}},
    "o1": {"type": "resistance", "resistance": 1e9},
    "o2": {"type": "resistance", "resistance": 1e9},
    "o3": {"type": "resistance", "resistance": 1e9}
  },
  "transport": {"species": [{
    "name": "o2", "diffusivity": 1.5e-9,
    "inlet": {"kind": "constant", "value": 0.119},
    "wall": {"model": "mass-transfer", "k": 1e-4, "wall_concentration": 0.05}
  }]}
}"#;
