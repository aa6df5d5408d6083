//! Heap bytes per flow segment of the transport plan and of one run's state, for a model
//! given as the canonical SI JSON (`json.dumps(oxyline.load_model(...).canonical)`):
//!
//!     cargo run --release -p oxyline-core --example transport_memory -- model.json

mod common;

fn main() {
    let path = std::env::args()
        .nth(1)
        .expect("usage: transport_memory MODEL.json");
    let common::Model {
        assembled,
        dae,
        transport: prototype,
        ..
    } = common::load(&path);
    let segments = assembled.circuit.segments.len() as f64;
    let mut run = prototype.new_run();
    let unknowns = run.mean_flow_unknowns();
    if !unknowns.is_empty() {
        run.set_mean_flow(&vec![1e-6; unknowns.len()])
            .expect("laws");
    }
    // the steady state is not needed for the sizes: a uniform pressure, no flow
    let mut y = vec![0.0; dae.n];
    y[..dae.n_nodes].iter_mut().for_each(|p| *p = 1.3e4);
    let z = run.initial_state(&y).expect("initial state");
    let mut zz = z.clone();
    run.implicit_step(0.0, 1e-3, 0.5, &y, &y, &mut zz)
        .expect("step");
    let mut row = Vec::new();
    run.observe(0.0, &y, None, &zz, true, &mut row)
        .expect("observe");
    let plan = prototype.plan().heap_bytes() as f64;
    if std::env::args().any(|a| a == "--fields") {
        for (name, bytes) in prototype.plan().heap_report() {
            println!(
                "  plan {name:>16}: {:6.1} B/segment",
                bytes as f64 / segments
            );
        }
    }
    println!(
        "segments {segments}: plan {:.0} B/segment, prototype state {:.0} B/segment, run state {:.0} B/segment (amounts {:.0} B/segment)",
        plan / segments,
        prototype.state_heap_bytes() as f64 / segments,
        run.state_heap_bytes() as f64 / segments,
        (8 * z.len()) as f64 / segments,
    );
}
