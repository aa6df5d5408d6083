//! The memory estimate's layout figures (`run::memory`) against the heap the core really
//! allocates for a network with oxygen: each figure must cover what its owner holds, or the
//! estimate would fall below the peak it is meant to bound.

mod common;

use oxyline_core::circuit::{Branch, Node};
use oxyline_core::run::memory::{
    CIRCUIT_PER_SEGMENT, PLAN_PER_CELL, TRANSPORT_BYTES_PER_CELL, TRANSPORT_RUN_PER_CELL,
};
use std::mem::size_of;

#[test]
fn the_estimates_layout_covers_the_plan_the_run_state_and_the_circuit() {
    let mut seed = 11;
    let b = common::build(&common::random_tree(300, &mut seed));
    let cells = b.transport.n_cells() as f64;
    let segments = b.assembled.circuit.segments.len() as f64;
    let plan = b.transport.plan().heap_bytes() as f64 / cells;
    assert!(plan <= PLAN_PER_CELL, "plan {plan:.0} B per cell");
    let run = b.transport.new_run();
    let state = run.state_heap_bytes() as f64 / cells;
    assert!(
        state <= TRANSPORT_RUN_PER_CELL,
        "run state {state:.0} B per cell"
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
