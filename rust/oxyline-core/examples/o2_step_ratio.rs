//! Same-process timing of a flow-only and a flow + species run of one model (canonical SI
//! JSON, see `transport_memory`): one cycle of generalized-α at dt = 1 ms, vessel-level output
//! every 10 ms (no per-segment columns), alternating the two `reps` times; prints the best CPU
//! time (Linux /proc, 10 ms ticks) of each and their ratio (a quieter measure of the O2 step's cost than separate
//! processes on a shared machine).
//!
//!     cargo run --release -p oxyline-core --example o2_step_ratio -- model.json [reps]
//!     cargo run --release -p oxyline-core --example o2_step_ratio -- model.json 1 rk4 0.01
//!
//! With a stop time (RK4 on big trees), each run is interrupted at the first progress check
//! (every 256 steps) past it, and the CPU time between the first and the last check is compared
//! (per step: the steady start and RK4's step-size search left out).

mod common;

use common::{cpu, load};
use oxyline_core::genalpha::NewtonControl;
use oxyline_core::{Method, RunSettings, Start, Transport, simulate_with_transport};

fn main() {
    let mut args = std::env::args().skip(1);
    let path = args.next().expect("usage: o2_step_ratio MODEL.json [reps]");
    let reps: usize = args.next().map_or(3, |r| r.parse().expect("reps"));
    let method = match args.next().as_deref() {
        Some("rk4") => Method::Rk4,
        _ => Method::GeneralizedAlpha { rho_inf: 0.5 },
    };
    let stop: Option<f64> = args.next().map(|t| t.parse().expect("stop time"));
    let model = load(&path);
    let (assembled, dae, prototype) = (&model.assembled, &model.dae, &model.transport);
    let columns = model.vessel_columns();
    let s = RunSettings {
        method,
        dt: matches!(method, Method::GeneralizedAlpha { .. }).then_some(1e-3),
        period: 1.0, // the bench trees (`benches/bench_scale.py`) beat once a second
        cycles: 1,
        until_periodic: None,
        max_cycles: 1,
        output_every: 1e-2,
        output_all_cycles: false,
        keep_current_cycle: true,
        start: Start::Steady,
        newton: NewtonControl::default(),
        probes: assembled.probes.vessel_unknowns.clone(),
        species_columns: Some(columns),
        tolerances: None,
        svzerod: Default::default(),
    };
    let (mut best_flow, mut best_o2) = (f64::INFINITY, f64::INFINITY);
    // CPU s of a run: whole, or between the first progress check and the one past `stop`
    let timed = |run: Option<&mut Transport>| {
        let (t0, mut marks) = (cpu(), Vec::new());
        let mut progress = |t: f64, _: f64| {
            marks.push(cpu());
            stop.is_none_or(|stop| t < stop || marks.len() < 2)
        };
        match simulate_with_transport(dae, run, &s, &mut progress) {
            Ok(_) => cpu() - t0,
            Err(oxyline_core::Error::Interrupted { .. }) => marks[marks.len() - 1] - marks[0],
            Err(e) => panic!("run failed: {e}"),
        }
    };
    for _ in 0..reps {
        best_flow = best_flow.min(timed(None));
        let mut run = prototype.new_run();
        best_o2 = best_o2.min(timed(Some(&mut run)));
    }
    println!(
        "segments {}: flow {best_flow:.3} s, with species {best_o2:.3} s, ratio {:.3}",
        assembled.circuit.segments.len(),
        best_o2 / best_flow
    );
}
