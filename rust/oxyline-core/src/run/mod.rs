//! The run driver: settings → plan → cycle loop → outcome.
//!
//! * `settings` — what the caller asks ([`RunSettings`], [`Method`], [`Start`]) and its checks;
//! * `plan` — the integrator, the step, the output stride and the initial state, decided before
//!   the first step (the steady state is solved at most once per call, shared by both passes of
//!   a transport run);
//! * `coupling` — the state a run advances (flow and species) and one step of it;
//! * `cycle` — the cycle loop: output rows, checks, progress, periodicity;
//! * `recorder` — the output table, optionally streamed to an [`OutputSink`];
//! * `pass` — one pass: settings → plan → initial state → cycle loop → outcome;
//! * `two_pass` — the flow-only first pass that measures the cycle-mean |Q| for the closures
//!   (accumulated by `mean_flow`), then the coupled pass;
//! * `outcome` — what the run returns ([`Outcome`]); `facts` — what a result records of it;
//! * `resolve` — RK4's step for circuits with valves and chambers, by step doubling.
//!
//! A failed or interrupted run still returns everything recorded so far.

mod adaptive; // error control: variable step, dense output (docs/physics.md §10)
mod breakpoints; // the forcing's corners, each of which a controlled step ends on
pub mod checkpoint;
mod coupling;
mod cycle;
mod events; // valve events of the error-controlled runs (docs/physics.md §10.5)
mod explicit; // error control with the explicit pair (docs/physics.md §10.4)
pub mod facts; // the settings and facts a run records with its result
pub(crate) mod flow_harmonics; // inlet renewal: the first pass's flow harmonics (and their tangents)
mod heap; // freed pages back to the OS before a large pass's cycle loop
pub mod large_blocks; // the Python extension's allocator: blocks ≥ 1 MiB mapped on their own
mod mean_flow;
pub mod memory;
mod outcome;
mod pass;
mod periodic_steps; // error control and until_periodic: near-periodic cycles replay their steps
mod plan;
mod recorder;
mod resolve; // RK4's step for valves and chambers by step doubling
mod retry; // the error-controlled step after a Newton failure
mod settings;
mod svzerod; // svZeroDSolver's output and stop conventions (the drop-in)
mod svzerod_rows; // its output rows of a run extended by the cycle-to-cycle rule
mod two_pass;

pub use checkpoint::{CHECKPOINT_VERSION, Checkpoints, Every, Snapshot};
pub use events::Event;
pub use heap::release_free_pages;
pub use outcome::{ErrorControlOutcome, FinerCycle, Outcome, TransportOutcome};
pub use recorder::{Chunk, OutputSink};
pub use resolve::{Refinement, rk4_step_refinement};
pub use settings::{Method, RunSettings, Start};
pub use svzerod::{CycleMeanStop, Derived, SvZeroDRules, rcr_cycles as svzerod_rcr_cycles};
pub use svzerod_rows::svzerod_output_rows;

use crate::circuit::Dae;
use crate::error::Result;
use crate::integrate::steady::SteadyCache;
use crate::transport::Transport;
use two_pass::run_two_pass;

/// Run the circuit. `progress(t, t_end)` is called every few hundred steps; returning false
/// interrupts the run.
pub fn simulate(
    dae: &Dae,
    s: &RunSettings,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    pass::run(
        dae,
        &mut SteadyCache::new(dae),
        s,
        None,
        None,
        None,
        None,
        progress,
        None,
    )
}

/// Run the circuit with species transport. Closures that need the cycle-mean |Q| get it from
/// a first, flow-only pass over the same cycles (the paper's two-pass procedure, docs/physics.md §3.1);
/// the coupled run then starts again from the same initial state.
pub fn simulate_with_transport(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run_two_pass(dae, transport, s, None, progress, None)
}

/// [`simulate_with_transport`], streaming the output rows to `sink` during the run instead of
/// returning them (the outcome's `times`/`data` then hold only rows the sink refused).
pub fn simulate_to_sink(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    sink: &mut OutputSink<'_>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run_two_pass(dae, transport, s, Some(sink), progress, None)
}

/// [`simulate_with_transport`] (or [`simulate_to_sink`] with `sink`) with checkpoints: a
/// [`Snapshot`] is handed to `checkpoints.save` at the cycle ends it asks for, and a run with
/// `checkpoints.resume` continues from that snapshot, bit-identical to the run that wrote it
/// had it gone on.
pub fn simulate_checkpointed(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    sink: Option<&mut OutputSink<'_>>,
    checkpoints: &mut Checkpoints<'_>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run_two_pass(dae, transport, s, sink, progress, Some(checkpoints))
}
