//! What a run returns: the recorded table, the final state, how the run went.

use super::cycle::Cycles;
use super::settings::{Method, RunSettings};
use crate::error::Error;
use crate::integrate::stability::StabilityLimit;
use crate::output::{HeartColumns, HeartRows};
use crate::transport::Transport;

#[derive(Debug, Clone)]
pub struct Outcome {
    pub times: Vec<f64>,
    /// Row-major (time, probe).
    pub data: Vec<f64>,
    pub n_probes: usize,
    pub dt: f64,
    pub method: &'static str,
    pub cycles_run: usize,
    pub periodic_error: f64,
    pub stability: Option<StabilityLimit>,
    pub final_state: Vec<f64>,
    /// Set when the run stopped early (error or interruption); the data up to then are kept.
    pub error: Option<Error>,
    /// Species transport records (None for flow-only runs).
    pub transport: Option<TransportOutcome>,
    /// Most output rows the driver held at once: all of them without a sink; with one, at most
    /// the sink's chunk for all-cycles output and one cycle's output for last-cycle output.
    pub max_buffered_rows: usize,
    /// Error control's account (None for a fixed step).
    pub error_control: Option<ErrorControlOutcome>,
}

/// What an error-controlled run reports (docs/physics.md §10).
#[derive(Debug, Clone, PartialEq)]
pub struct ErrorControlOutcome {
    /// Largest estimated error per kind over the run (pressure, flow, volume, species; see
    /// `integrate::adaptive::KINDS`), relative to atol/rtol + |y|: at most rtol where the
    /// controller met its tolerance.
    pub estimate: [f64; 4],
    pub steps: usize,
    pub rejected: usize,
    pub dt_min: f64,
    pub dt_max: f64,
    /// The valves' status changes located during the run, in time order (docs/physics.md
    /// §10.5).
    pub events: Vec<super::events::Event>,
    /// The step-size history of the last cycle run (docs/solvers.md, "Step-size history"):
    /// its start time (run time, s) and its accepted steps in order (s), each step starting
    /// where the ones before it end (a run stopped early: the steps of its last cycle so far).
    pub last_cycle_start: f64,
    pub last_cycle_steps: Vec<f64>,
    /// The last cycle run again at rtol / factor (`RunSettings::finer_last_cycle`; None when
    /// not asked, or not done: the explicit pair, valves, a failed second integration).
    pub finer: Option<FinerCycle>,
}

/// The last cycle of an error-controlled run integrated again from its start state at
/// rtol / `factor` (docs/solvers.md, "The accumulated error"): its output rows at the
/// run's output times after the cycle's first, in the layout of [`Outcome`].
#[derive(Debug, Clone, PartialEq)]
pub struct FinerCycle {
    pub factor: f64,
    pub times: Vec<f64>,
    /// Row-major (time, probe).
    pub data: Vec<f64>,
    /// Row-major (time, species × columns); empty for flow-only runs.
    pub transport: Vec<f64>,
    /// The second integration's accepted and rejected steps.
    pub steps: usize,
    pub rejected: usize,
}

/// Species outputs, recorded at the same times as the flow probes.
#[derive(Debug, Clone)]
pub struct TransportOutcome {
    pub species: Vec<String>,
    /// Columns per species and output time (see `Transport::observe`).
    pub columns_per_species: usize,
    /// Row-major (time, species × columns).
    pub data: Vec<f64>,
    /// Σ N of each species at t = 0 (mass balance reference).
    pub initial_stored: Vec<f64>,
    pub final_state: Vec<f64>,
    /// Cycle-mean |Q| of every segment used by the closures (empty if none needed it).
    pub mean_abs_flow: Vec<f64>,
}

impl Outcome {
    /// Take the heart outputs (recorded as columns `at..at + heart.width()` of every row,
    /// after the selected columns) out of the rows, and out of the last cycle's second
    /// integration's rows (whose own heart outputs are not reported): the rows keep the
    /// selected (and svZeroDSolver's derived) columns, `n_probes` shrinks to them.
    pub fn take_heart(&mut self, heart: &mut HeartColumns, at: usize) -> HeartRows {
        let n = self.n_probes;
        let rows = heart.split(&mut self.data, n, at);
        if let Some(f) = self.error_control.as_mut().and_then(|ec| ec.finer.as_mut()) {
            heart.clone().split(&mut f.data, n, at);
        }
        self.n_probes -= heart.width();
        rows
    }

    /// The outcome of a run stopped (`error`) before its recording pass started: during the
    /// step estimate or a transport run's flow-only mean-flow pass. No row was recorded, so
    /// its tables are empty but of the run's layout (the columns of `s` and, for a transport
    /// run, of `transport`'s recorded species columns): the caller still gets a result,
    /// flagged by `error`, as from a run stopped in any other phase.
    pub(super) fn unstarted(s: &RunSettings, transport: Option<&Transport>, error: Error) -> Self {
        let n_probes = s.probes.len() + s.svzerod.extra_columns(s.probes.len());
        Outcome {
            times: Vec::new(),
            data: Vec::new(),
            n_probes,
            // no step was planned or taken: the requested step if any
            dt: s.dt.unwrap_or(f64::NAN),
            // an automatic choice not made yet stays "auto"
            method: match s.method {
                Method::Rk4 => "rk4",
                Method::GeneralizedAlpha { .. } => "generalized-alpha",
                Method::Dopri5 => crate::integrate::explicit_pair::NAME,
                Method::Auto { .. } => "auto",
            },
            cycles_run: 0,
            periodic_error: f64::NAN,
            stability: None,
            final_state: Vec::new(),
            error: Some(error),
            transport: transport.map(|tr| {
                let species = tr.species_names();
                let columns_per_species = s
                    .species_columns
                    .as_ref()
                    .map_or(tr.columns_per_species(), Vec::len);
                TransportOutcome {
                    // nothing was computed: no stored amount at t = 0 either
                    initial_stored: vec![f64::NAN; species.len()],
                    species,
                    columns_per_species,
                    data: Vec::new(),
                    final_state: Vec::new(),
                    mean_abs_flow: Vec::new(),
                }
            }),
            max_buffered_rows: 0,
            error_control: None,
        }
    }

    /// The outcome of the finished (or stopped) cycle loop.
    pub(super) fn of(
        cycles: Cycles<'_, '_>,
        method: &'static str,
        stability: Option<StabilityLimit>,
        error: Option<Error>,
    ) -> Outcome {
        let (cycles_run, periodic_error) = (cycles.cycles_run, cycles.periodic_error);
        let period = cycles.s_period();
        let (state, rec) = (cycles.state, cycles.rec);
        let (n_probes, columns_per_species) = (rec.n_probes(), rec.columns_per_species());
        let events = cycles.events.map(|ev| ev.log).unwrap_or_default();
        let (last_cycle_start, last_cycle_steps) =
            (cycles.cycle_start, cycles.periodic_steps.taken().to_vec());
        // (the last cycle's second integration of either controller, when asked)
        let mut finer = cycles.finer;
        let explicit = cycles.explicit.map(|ex| ErrorControlOutcome {
            estimate: ex.estimate,
            steps: ex.steps,
            rejected: ex.rejected,
            dt_min: ex.h_smallest,
            dt_max: ex.h_largest,
            events: events.clone(),
            last_cycle_start,
            last_cycle_steps: last_cycle_steps.clone(),
            finer: finer.take(),
        });
        let error_control = cycles
            .adaptive
            .map(|ad| ErrorControlOutcome {
                estimate: ad.estimate,
                steps: ad.steps,
                rejected: ad.rejected,
                dt_min: ad.h_smallest,
                dt_max: ad.h_largest,
                events,
                last_cycle_start,
                last_cycle_steps,
                finer,
            })
            .or(explicit);
        // an error-controlled run reports its mean step
        let dt = match &error_control {
            Some(ec) if ec.steps > 0 => cycles_run as f64 * period / ec.steps as f64,
            _ => state.dt,
        };
        Outcome {
            error_control,
            max_buffered_rows: rec.max_rows,
            times: rec.times,
            data: rec.data,
            n_probes,
            dt,
            method,
            cycles_run,
            periodic_error,
            stability,
            final_state: state.y,
            error,
            transport: state.species.map(|sp| TransportOutcome {
                species: sp.tr.species_names(),
                columns_per_species,
                data: rec.transport,
                initial_stored: rec.initial_stored,
                final_state: sp.z,
                mean_abs_flow: Vec::new(),
            }),
        }
    }
}
