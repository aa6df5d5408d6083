//! The run driver: settings → plan → cycle loop → outcome.
//!
//! * `settings` — what the caller asks ([`RunSettings`], [`Method`], [`Start`]) and its checks;
//! * `plan` — the integrator, the step, the output stride and the initial state, decided before
//!   the first step (the steady state is solved at most once per call, shared by both passes of
//!   a transport run);
//! * `coupling` — the state a run advances (flow and species) and one step of it;
//! * `cycle` — the cycle loop: output rows, checks, progress, periodicity;
//! * `recorder` — the output table, optionally streamed to an [`OutputSink`];
//! * `two_pass` — the flow-only first pass that measures the cycle-mean |Q| for the closures;
//! * `outcome` — what the run returns ([`Outcome`]).
//!
//! A failed or interrupted run still returns everything recorded so far.

mod coupling;
mod cycle;
mod outcome;
mod plan;
mod recorder;
mod settings;
mod two_pass;

pub use outcome::{Outcome, TransportOutcome};
pub use recorder::{Chunk, OutputSink};
pub use settings::{Method, RunSettings, Start};

use crate::circuit::Dae;
use crate::error::Result;
use crate::integrate::steady::SteadyCache;
use crate::transport::{Formulation, Transport};
use coupling::{Species, State};
use cycle::Cycles;
use plan::Plan;
use recorder::Recorder;
use two_pass::{MeanAbs, run_two_pass};

/// Run the circuit. `progress(t, t_end)` is called every few hundred steps; returning false
/// interrupts the run.
pub fn simulate(
    dae: &Dae,
    s: &RunSettings,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run(dae, &SteadyCache::new(dae), s, None, None, None, progress)
}

/// Run the circuit with species transport. Closures that need the cycle-mean |Q| get it from
/// a first, flow-only pass over the same cycles (the paper's two-pass procedure, physics §3.1);
/// the coupled run then starts again from the same initial state.
pub fn simulate_with_transport(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run_two_pass(dae, transport, s, None, progress)
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
    run_two_pass(dae, transport, s, Some(sink), progress)
}

/// One pass: settings → plan → initial state → cycle loop → outcome. `mean` collects the
/// cycle-mean |Q| of a flow-only first pass.
fn run(
    dae: &Dae,
    steady: &SteadyCache<'_>,
    s: &RunSettings,
    mut transport: Option<&mut Transport>,
    mean: Option<&mut MeanAbs>,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    s.validate(dae)?;
    let mut plan = Plan::new(dae, steady, s, transport.as_deref_mut())?;
    let (mut y, yd) = plan.initial_state(steady, s)?;
    let quasi = transport
        .as_deref()
        .is_some_and(|t| t.formulation() == Formulation::TlQuasisteady);
    // explicit (RK4) transport in the flow's own stages; implicit transport after each step
    let mut flow = plan.flow(s, &mut y, transport.is_some() && !quasi)?;
    let (species, initial_stored) = match transport {
        Some(tr) => {
            let level = flow.integrator().alpha_f();
            let (sp, stored) = Species::start(tr, &y, plan.dt, level, !plan.use_rk4)?;
            (Some(sp), stored)
        }
        None => (None, Vec::new()),
    };
    let layout = species
        .as_ref()
        .map(|sp| (sp.tr.species_names().len(), sp.tr.columns_per_species()));
    let columns = s.species_columns.as_deref();
    let rec = Recorder::new(&s.probes, layout, columns, initial_stored, sink)?;
    let state = State {
        dae,
        flow,
        species,
        y,
        yd,
        dt: plan.dt,
    };
    let method = plan.method_name();
    let mut cycles = Cycles::new(s, state, rec, mean, plan.steps_per_cycle, plan.stride);
    let error = cycles.run(progress);
    Ok(Outcome::of(cycles, method, plan.stability, error))
}
