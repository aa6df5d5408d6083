//! The memory estimate's layout figures (`run::memory`) against the heap the core really
//! allocates for a network with oxygen: each figure must cover what its owner holds, or the
//! estimate would fall below the peak it is meant to bound.

mod common;

use oxyline_core::circuit::{Branch, Node};
use oxyline_core::run::memory::{
    CIRCUIT_PER_SEGMENT, PLAN_PER_CELL, TRANSPORT_BYTES_PER_CELL, TRANSPORT_RUN_PER_CELL,
};
use std::mem::size_of;

/// A binary tree of `2^depth - 1` vessels of 4 segments each (the layout the figures were
/// counted on), a constant flow in, a resistance per leaf, oxygen with a constant-k wall.
fn binary_tree(depth: u32) -> String {
    let n = (1usize << depth) - 1;
    let vessels: Vec<String> = (0..n)
        .map(|i| {
            let from = if i == 0 {
                "in".to_owned()
            } else {
                format!("n{}", (i - 1) / 2)
            };
            let r = 2e-3 * 0.8f64.powi((i + 1).ilog2() as i32);
            format!(
                r#"{{"name": "v{i}", "from": "{from}", "to": "n{i}", "segments": 4,
                "geometry": {{"length": 0.02, "radius_in": {r}, "radius_out": {r},
                "wall_thickness": 3e-4, "youngs_modulus": 4e5}}}}"#
            )
        })
        .collect();
    let mut bcs =
        vec![r#""in": {"type": "flow", "flow": {"kind": "constant", "value": 2e-6}}"#.to_owned()];
    for i in n / 2..n {
        bcs.push(format!(
            r#""n{i}": {{"type": "resistance", "resistance": 1e9}}"#
        ));
    }
    format!(
        r#"{{"vessels": [{}], "boundary_conditions": {{{}}},
            "transport": {{"species": [{{"name": "o2",
                "inlet": {{"kind": "constant", "value": 0.127}}, "initial": 0.1,
                "wall": {{"model": "mass-transfer", "k": 1e-5,
                          "wall_concentration": 0.04}}}}]}}}}"#,
        vessels.join(","),
        bcs.join(",")
    )
}

#[test]
fn the_estimates_layout_covers_the_plan_the_run_state_and_the_circuit() {
    let b = common::build(&binary_tree(9));
    let cells = b.transport.n_cells() as f64;
    let segments = b.assembled.summary.segments as f64;
    assert_eq!(segments, 4.0 * 511.0);
    let plan = b.transport.plan().heap_bytes() as f64 / cells;
    let run = b.transport.new_run();
    let state = run.state_heap_bytes() as f64 / cells;
    assert!(
        plan + state <= PLAN_PER_CELL + TRANSPORT_RUN_PER_CELL,
        "plan {plan:.0} + run state {state:.0} B per cell"
    );
    // nodes and branches (one of each per segment, the junctions and boundaries beside) and
    // their labels
    let c = &b.assembled.circuit;
    let circuit = (c.nodes.capacity() * size_of::<Node>()
        + c.branches.capacity() * size_of::<Branch>()
        + c.names.heap_bytes()) as f64
        / segments;
    assert!(
        circuit <= CIRCUIT_PER_SEGMENT,
        "circuit {circuit:.0} B per segment"
    );
    // the measured peak per cell is a share of the plan and the state, not a figure apart
    // from them: between half and all of their counted bytes
    let layout = PLAN_PER_CELL + TRANSPORT_RUN_PER_CELL;
    assert!((0.5 * layout..=layout).contains(&TRANSPORT_BYTES_PER_CELL));
}
