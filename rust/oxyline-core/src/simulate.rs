//! The run driver: initial state, time stepping cycle by cycle with either integrator,
//! periodicity check, decimated output of selected unknowns, progress and cancellation.
//! A failed or interrupted run still returns everything recorded so far.

use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::integrate::genalpha::GenAlpha;
use crate::integrate::newton::{NewtonControl, scaled_increment};
use crate::integrate::rk4::{CoupledStages, Rk4};
use crate::integrate::stability::{StabilityLimit, rk4_limit};
use crate::integrate::steady::SteadyCache;
// moved to `integrate::steady`, kept here for the callers of `crate::simulate::steady_state`
pub use crate::integrate::steady::steady_state;
use crate::transport::{Formulation, Transport};

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    Rk4,
    GeneralizedAlpha {
        rho_inf: f64,
    },
    /// Implicit when the stable RK4 step is far below the output step, else RK4.
    Auto {
        rho_inf: f64,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// Exact steady solution of the mean boundary conditions.
    Steady,
    /// svZeroDSolver's: 31 generalized-α steps of T/10 with mean BCs and no Windkessel C.
    SvZeroDSteady { rho_inf: f64 },
    /// Zero differential state; algebraic unknowns consistent with the forcing at t = 0.
    Zero,
    /// All-zero y and ẏ, as svZeroDSolver without `steady_initial`.
    SvZeroDZero,
}

#[derive(Debug, Clone)]
pub struct RunSettings {
    pub method: Method,
    /// Time step; None = automatic.
    pub dt: Option<f64>,
    pub period: f64,
    /// Cycles to run (the minimum when `until_periodic` is set).
    pub cycles: usize,
    /// Stop when the cycle-to-cycle change of the state falls below this (relative).
    pub until_periodic: Option<f64>,
    pub max_cycles: usize,
    /// Output interval in seconds (rounded to a whole number of steps).
    pub output_every: f64,
    pub output_all_cycles: bool,
    /// With last-cycle output, also record the cycles before the last (each is dropped when the
    /// next starts), so that a run stopped early returns its current cycle. Off, those cycles
    /// are not recorded at all: a streaming run then never holds a whole cycle of rows.
    pub keep_current_cycle: bool,
    pub start: Start,
    pub newton: NewtonControl,
    pub probes: Vec<usize>,
    /// Recorded columns of each species block of `Transport::observe` (see
    /// `crate::output::Selection::species_columns`); None records every column.
    pub species_columns: Option<Vec<usize>>,
}

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
}

/// Output rows handed to an [`OutputSink`]: `times.len()` rows of the recorded unknowns
/// (row-major, time × probe) and, for transport runs, of the species outputs (row-major,
/// time × species columns as in [`TransportOutcome::data`]; NaN rows where the run stopped
/// before they were computed).
pub struct Chunk<'a> {
    pub times: &'a [f64],
    pub data: &'a [f64],
    /// Empty for flow-only runs.
    pub transport: &'a [f64],
    /// Σ N of each species at t = 0 (the mass-balance reference; empty for flow-only runs).
    pub initial_stored: &'a [f64],
}

/// Streams the output instead of collecting it: the driver hands every `rows` output rows to
/// `write` as soon as they are certain to be part of the output and then forgets them, so a
/// long all-cycles run holds at most one chunk. Last-cycle output holds at most one cycle, as
/// without a sink: the rows of a cycle that may be superseded (with `until_periodic`, or an
/// interrupted run's partial cycle) are handed over once they are known to be the output.
/// When the run stops early (error or interruption) the rows recorded so far are handed over
/// in a last, shorter chunk. `write` returning false stops the run as an interruption and is
/// not called again.
pub struct OutputSink<'a> {
    pub rows: usize,
    pub write: &'a mut dyn FnMut(Chunk<'_>) -> bool,
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

/// Running mean of |y_i| over the current cycle (for cycle-mean wall shear).
struct MeanAbs {
    unknowns: Vec<usize>,
    sum: Vec<f64>,
    last: Vec<f64>,
    prev: Vec<f64>,
    count: usize,
}

/// The flow-only first pass stops once the cycle-mean |Q| of every segment changes by less
/// than this (relative to the largest) between two cycles: the closures need the mean shear,
/// not a fully settled pressure level.
const MEAN_FLOW_TOL: f64 = 1e-6;

enum Stepper<'a> {
    Rk4(Rk4<'a>),
    GenAlpha(GenAlpha<'a>),
}

/// The output table under construction: flow probes and species outputs of the same rows,
/// optionally streamed to a sink.
struct Recorder<'p, 's, 'f> {
    probes: &'p [usize],
    times: Vec<f64>,
    data: Vec<f64>,
    /// Species columns, one row per `observe` call (0 for flow-only runs).
    transport_cols: usize,
    transport: Vec<f64>,
    /// Selected columns of every species block of `block` columns (None: all).
    species_select: Option<&'p [usize]>,
    block: usize,
    sink: Option<&'s mut OutputSink<'f>>,
    max_rows: usize,
}

impl Recorder<'_, '_, '_> {
    fn record(&mut self, t: f64, y: &[f64]) {
        self.times.push(t);
        self.data.extend(self.probes.iter().map(|&i| y[i]));
        self.max_rows = self.max_rows.max(self.times.len());
    }
    /// Keep the selected columns of one `observe` row (all species blocks).
    fn push_species(&mut self, row: &[f64]) {
        match self.species_select {
            None => self.transport.extend_from_slice(row),
            Some(sel) => {
                for b in row.chunks(self.block.max(1)) {
                    self.transport.extend(sel.iter().map(|&c| b[c]));
                }
            }
        }
    }
    fn clear(&mut self) {
        self.times.clear();
        self.data.clear();
        self.transport.clear();
    }
    /// One species row per flow row: rows the run stopped before computing (an error in
    /// `observe`, or an interruption in a cycle whose species outputs were being skipped)
    /// become NaN, so the two tables always describe the same times.
    fn align(&mut self) {
        if self.transport_cols > 0 {
            self.transport
                .resize(self.times.len() * self.transport_cols, f64::NAN);
        }
    }
    /// Hand the buffered rows to the sink in chunks of `rows`: only whole chunks unless `all`.
    /// Returns false if the sink stopped the run (it is then dropped, the rows kept).
    fn flush(&mut self, all: bool, initial_stored: &[f64]) -> bool {
        if self.sink.is_none() {
            return true;
        }
        self.align();
        let Some(sink) = self.sink.as_deref_mut() else {
            return true;
        };
        let rows = sink.rows.max(1);
        let n = self.times.len();
        if !all && n < rows {
            return true;
        }
        let end = if all { n } else { n - n % rows };
        let (np, nc) = (self.probes.len(), self.transport_cols);
        let mut done = 0;
        while done < end {
            let upto = (done + rows).min(end);
            let ok = (sink.write)(Chunk {
                times: &self.times[done..upto],
                data: &self.data[done * np..upto * np],
                transport: &self.transport[done * nc..upto * nc],
                initial_stored,
            });
            if !ok {
                self.sink = None;
                break;
            }
            done = upto;
        }
        self.times.drain(..done);
        self.data.drain(..done * np);
        self.transport.drain(..done * nc);
        self.sink.is_some()
    }
}

/// Run the circuit. `progress(t, t_end)` is called every few hundred steps; returning false
/// interrupts the run.
pub fn simulate(
    dae: &Dae,
    s: &RunSettings,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    run(dae, s, None, None, None, progress)
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

fn run_two_pass(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    let Some(tr) = transport else {
        return run(dae, s, None, None, sink, progress);
    };
    let unknowns = tr.mean_flow_unknowns();
    let mut mean_abs_flow = Vec::new();
    if !unknowns.is_empty() {
        let n = unknowns.len();
        let mut mean = MeanAbs {
            unknowns,
            sum: vec![0.0; n],
            last: vec![0.0; n],
            prev: vec![f64::INFINITY; n],
            count: 0,
        };
        // the first pass records nothing: no sink
        let first = run(
            dae,
            &mean_flow_pass(s),
            None,
            Some(&mut mean),
            None,
            progress,
        )?;
        if let Some(e) = first.error {
            return Err(e);
        }
        tr.set_mean_flow(&mean.last)?;
        mean_abs_flow = mean.last;
    }
    let mut out = run(dae, s, Some(tr), None, sink, progress)?;
    if let Some(t) = out.transport.as_mut() {
        t.mean_abs_flow = mean_abs_flow;
    }
    Ok(out)
}

/// Steps per cycle of the flow-only first pass when the main run is explicit.
const MEAN_FLOW_STEPS_PER_CYCLE: f64 = 2000.0;
/// An implicit run at the usual step (>= period/1000) measures the mean |Q| at
/// period/`MEAN_FLOW_COARSE_STEPS`: the pass then costs a quarter of the coupled run's flow
/// instead of all of it. The rectangle rule of the mean over 250 steps is accurate to ~2e-5 of
/// <|Q|> for a reversing sinusoid, so k ∝ <|Q|>^{1/3} to ~7e-6 — far inside the closures' own
/// uncertainty (physics §3.1). Finer implicit runs keep their own step (an exact mean).
const MEAN_FLOW_COARSE_STEPS: f64 = 250.0;
const MEAN_FLOW_FINE_STEPS: f64 = 1000.0;

/// Settings of the flow-only pass that measures the cycle-mean |Q|. The closures need a mean
/// (k ∝ γ̄^{1/3}), not the explicit scheme's stability-limited resolution: an RK4 run gets an
/// implicit pass at period/2000 (second order: the mean |Q| differs by ~1e-5 relative, k by a
/// third of that), which costs a few percent of the RK4 pass it replaces. Implicit runs
/// at the usual step coarsen it (see `MEAN_FLOW_COARSE_STEPS`).
fn mean_flow_pass(s: &RunSettings) -> RunSettings {
    let mut first = RunSettings {
        probes: Vec::new(),
        ..s.clone()
    };
    match s.method {
        Method::Rk4 => {
            first.method = Method::GeneralizedAlpha { rho_inf: 0.5 };
            let coarse = s.period / MEAN_FLOW_STEPS_PER_CYCLE;
            first.dt = Some(s.dt.map_or(coarse, |dt| dt.max(coarse)));
        }
        Method::GeneralizedAlpha { .. } => {
            let dt = s.dt.unwrap_or(s.output_every);
            if dt * MEAN_FLOW_FINE_STEPS >= s.period * (1.0 - 1e-9) {
                first.dt = Some(dt.max(s.period / MEAN_FLOW_COARSE_STEPS));
            }
        }
        Method::Auto { .. } => {}
    }
    first
}

fn run(
    dae: &Dae,
    s: &RunSettings,
    mut transport: Option<&mut Transport>,
    mut mean: Option<&mut MeanAbs>,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    if !(s.period.is_finite() && s.period > 0.0) {
        return Err(Error::model(
            "simulation",
            format!("period must be > 0, got {}", s.period),
        ));
    }
    if s.cycles == 0 {
        return Err(Error::model("simulation", "cycles must be >= 1"));
    }
    if !(s.output_every.is_finite() && s.output_every > 0.0) {
        return Err(Error::model(
            "simulation",
            format!("output every must be > 0, got {}", s.output_every),
        ));
    }
    if let Some(dt) = s.dt {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(Error::model(
                "simulation",
                format!("dt must be > 0, got {dt}"),
            ));
        }
    }
    for &p in &s.probes {
        if p >= dae.n {
            return Err(Error::model(
                "simulation",
                format!("output index {p} out of range"),
            ));
        }
    }
    // explicit stability limit, needed by rk4 and by auto
    let rho_of = |m: Method| match m {
        Method::GeneralizedAlpha { rho_inf } | Method::Auto { rho_inf } => rho_inf,
        Method::Rk4 => 0.5,
    };
    // Explicit upwind transport is stable for Courant numbers up to 1.3926 (physics §1.5), a
    // limit the flow eigenvalues do not see. The automatic step keeps the Courant number of the
    // mean flow below 0.5 × 1.39 / 3 (pulsatile peaks of up to 3× the mean); the run itself
    // monitors the actual value.
    // the steady state is solved at most once per run, by whichever part needs it first
    let steady = SteadyCache::new(dae);
    let transport_dt = match transport.as_deref_mut() {
        Some(tr) if tr.formulation() == Formulation::Conservative => {
            // (no steady state, or a non-positive volume there: left to the run to report)
            let rate = steady.get().map_or(0.0, |y| tr.max_outflow_rate(y, 0.0));
            if rate > 0.0 && rate.is_finite() {
                0.5 * 1.392_647 / (3.0 * rate)
            } else {
                f64::INFINITY
            }
        }
        _ => f64::INFINITY,
    };
    let mut stability = None;
    let mut use_rk4 = matches!(s.method, Method::Rk4);
    // the RK4 integrator built for the stability probe is reused for the run (its step is set
    // below; the linearisation only affects the probe)
    let mut rk4_built: Option<Rk4> = None;
    if matches!(s.method, Method::Rk4 | Method::Auto { .. }) {
        let mut probe = Rk4::new(dae, Regime::Transient, 1.0);
        match (&mut probe, s.method) {
            (Ok(rk), _) => {
                if !dae.is_linear() {
                    // stenoses stiffen their branches in proportion to the flow: linearise at
                    // the steady state of the mean boundary conditions
                    if let Ok(ys) = steady.get() {
                        rk.set_linearization(ys)?;
                    }
                }
                let lim = rk4_limit(rk, &dae.names)?;
                if let Method::Auto { .. } = s.method {
                    use_rk4 = (0.5 * lim.dt_max).min(transport_dt) >= s.output_every / 20.0;
                }
                stability = Some(lim);
            }
            (Err(e), Method::Rk4) => return Err(e.clone()),
            (Err(_), _) => use_rk4 = false,
        }
        rk4_built = probe.ok();
    }
    let out_per_cycle = (s.period / s.output_every).round().max(1.0) as usize;
    let (dt, method_name) = if use_rk4 {
        let lim = stability.as_ref().unwrap();
        let dt = match s.dt {
            Some(dt) => {
                if dt > lim.dt_max * (1.0 + 1e-9) {
                    return Err(Error::Unstable {
                        dt,
                        limit: lim.dt_max,
                        element: lim.element.clone(),
                    });
                }
                dt
            }
            None => (0.5 * lim.dt_max).min(s.output_every).min(transport_dt),
        };
        (dt, "rk4")
    } else {
        (s.dt.unwrap_or(s.output_every), "generalized-alpha")
    };
    // whole number of steps per cycle and per output interval
    let substeps = ((s.period / out_per_cycle as f64) / dt * (1.0 - 1e-12))
        .ceil()
        .max(1.0) as usize;
    let (steps_per_cycle, stride) = if s.dt.is_some() {
        let spc = (s.period / dt).round().max(1.0) as usize;
        let stride = (s.output_every / (s.period / spc as f64)).round().max(1.0) as usize;
        (spc, stride)
    } else {
        (out_per_cycle * substeps, substeps)
    };
    let dt = s.period / steps_per_cycle as f64;
    if use_rk4 {
        if let Some(lim) = &stability {
            if dt > lim.dt_max * (1.0 + 1e-9) {
                return Err(Error::Unstable {
                    dt,
                    limit: lim.dt_max,
                    element: lim.element.clone(),
                });
            }
        }
    }

    // initial state
    let n = dae.n;
    let (mut y, mut yd) = match s.start {
        Start::Zero | Start::SvZeroDZero => (vec![0.0; n], vec![0.0; n]),
        Start::Steady => {
            let y = steady.get()?.to_vec();
            let mut f = vec![0.0; n];
            dae.forcing_into(0.0, Regime::Transient, &mut f);
            let mut r = vec![0.0; n];
            dae.static_residual(&y, &f, &mut r);
            let yd = (0..n)
                .map(|i| if dae.e[i] > 0.0 { r[i] / dae.e[i] } else { 0.0 })
                .collect();
            (y, yd)
        }
        Start::SvZeroDSteady { rho_inf } => {
            let h = s.period / 10.0;
            let mut ga = GenAlpha::new(dae, Regime::SteadyNoWindkessel, h, rho_inf, s.newton)?;
            let (mut y, mut yd) = (vec![0.0; n], vec![0.0; n]);
            for i in 0..31 {
                ga.step(h * i as f64, &mut y, &mut yd)?;
            }
            (y, yd)
        }
    };
    if matches!(s.start, Start::Zero | Start::Steady) && !use_rk4 {
        // the algebraic unknowns (e.g. the pressure before a resistance fed by the inflow) follow
        // the forcing at t = 0, and ẏ of the differential ones is the circuit's own; an index-2
        // circuit (RK4 refuses it) keeps the start as given
        if rk4_built.is_none() {
            rk4_built = Rk4::new(dae, Regime::Transient, dt).ok();
        }
        if let Some(rk) = rk4_built.as_mut() {
            let mut yc = y.clone();
            if let Ok(d) = rk
                .make_consistent(0.0, &mut yc)
                .and_then(|_| rk.derivative(0.0, &mut yc))
            {
                y = yc;
                yd = d;
            }
        }
    }
    let mut stepper = if use_rk4 {
        let mut rk = match rk4_built.take() {
            Some(rk) => rk,
            None => Rk4::new(dae, Regime::Transient, dt)?,
        };
        rk.dt = dt;
        rk.make_consistent(0.0, &mut y)?;
        Stepper::Rk4(rk)
    } else {
        Stepper::GenAlpha(GenAlpha::new(
            dae,
            Regime::Transient,
            dt,
            rho_of(s.method),
            s.newton,
        )?)
    };

    // species state, started uniform in the initial volumes
    let alpha_f = match &stepper {
        Stepper::GenAlpha(ga) => ga.alpha_f(),
        Stepper::Rk4(_) => 1.0,
    };
    let mut z = match transport.as_deref_mut() {
        Some(tr) => tr.initial_state(&y)?,
        None => Vec::new(),
    };
    let initial_stored: Vec<f64> = match transport.as_deref() {
        Some(tr) => (0..tr.species_names().len())
            .map(|k| z[k * tr.n_cells()..(k + 1) * tr.n_cells()].iter().sum())
            .collect(),
        None => Vec::new(),
    };
    let quasi = transport
        .as_deref()
        .is_some_and(|t| t.formulation() == Formulation::TlQuasisteady);
    if quasi {
        // the quasi-steady field is algebraic in the flow: make the initial one consistent
        if let Some(tr) = transport.as_deref_mut() {
            let y0 = y.clone();
            tr.implicit_step(0.0, dt, 1.0, &y0, &y0, &mut z)?;
            // reset the accumulators (not the relaxed shears that follow them)
            let nsp = tr.species_names().len();
            for a in z.iter_mut().skip(tr.n_cells() * nsp).take(4 * nsp) {
                *a = 0.0;
            }
        }
    }
    let explicit_transport = matches!(stepper, Stepper::Rk4(_)) && !quasi;
    let mut zk = CoupledStages::new(z.len());
    let mut y_prev = vec![0.0; n];
    let mut prev_cycle_z = z.clone();
    let observe = |tr: &mut Transport,
                   stepper: &mut Stepper,
                   t: f64,
                   y: &[f64],
                   yd: &[f64],
                   z: &[f64],
                   out: &mut Vec<f64>|
     -> Result<()> {
        match stepper {
            Stepper::Rk4(rk) => {
                let mut yc = y.to_vec();
                let ydot = rk.derivative(t, &mut yc)?;
                tr.observe(t, &yc, Some(&ydot), z, !explicit_transport, out)
            }
            Stepper::GenAlpha(_) => tr.observe(t, y, Some(yd), z, true, out),
        }
    };

    let block = transport.as_deref().map_or(0, |t| t.columns_per_species());
    // the flow-only first pass of a transport run has no species to select
    let species_select = s.species_columns.as_deref().filter(|_| transport.is_some());
    if let Some(&c) = species_select.and_then(|sel| sel.iter().find(|&&c| c >= block)) {
        return Err(Error::model(
            "simulation output",
            format!("species column {c} out of range (0..{block})"),
        ));
    }
    let kept = species_select.map_or(block, <[usize]>::len);
    let mut rec = Recorder {
        probes: &s.probes,
        times: Vec::new(),
        data: Vec::new(),
        transport_cols: transport
            .as_deref()
            .map_or(0, |t| t.species_names().len() * kept),
        transport: Vec::new(),
        species_select,
        block,
        sink,
        max_rows: 0,
    };
    let mut obs_row = Vec::new();
    let max_cycles = if s.until_periodic.is_some() {
        s.max_cycles.max(s.cycles)
    } else {
        s.cycles
    };
    let t_end = max_cycles as f64 * s.period;
    let mut prev_cycle_end = y.clone();
    let mut periodic_error = f64::NAN;
    let mut error = None;
    let mut cycles_run = 0;
    let mut step_global: usize = 0;
    'cycles: for cycle in 0..max_cycles {
        let t0 = cycle as f64 * s.period;
        if !s.output_all_cycles {
            rec.clear();
        }
        // rows certain to be output can go to the sink as they come; a cycle that may still be
        // superseded by the next (last-cycle output with `until_periodic`) waits for its end
        let committed = s.output_all_cycles || cycle + 1 == max_cycles;
        let recorded = committed || s.until_periodic.is_some() || s.keep_current_cycle;
        if let Some(m) = mean.as_deref_mut() {
            m.sum.iter_mut().for_each(|v| *v = 0.0);
            m.count = 0;
        }
        if recorded && (!s.output_all_cycles || cycle == 0) {
            rec.record(if s.output_all_cycles { t0 } else { 0.0 }, &y);
            if let Some(tr) = transport.as_deref_mut() {
                obs_row.clear();
                if let Err(e) = observe(tr, &mut stepper, t0, &y, &yd, &z, &mut obs_row) {
                    error = Some(e);
                    break 'cycles;
                }
                rec.push_species(&obs_row);
            }
            if committed && !rec.flush(false, &initial_stored) {
                error = Some(Error::Interrupted { time: t0 });
                break 'cycles;
            }
        }
        for k in 1..=steps_per_cycle {
            let t = (step_global as f64) * dt;
            let r = match (&mut stepper, transport.as_deref_mut()) {
                (Stepper::Rk4(rk), Some(tr)) if explicit_transport => {
                    rk.step_coupled(t, &mut y, &mut z, &mut zk, tr)
                }
                (Stepper::Rk4(rk), tr) => rk.step(t, &mut y).and_then(|()| match tr {
                    Some(tr) => tr.implicit_step(t, dt, 1.0, &y, &y, &mut z),
                    None => Ok(()),
                }),
                (Stepper::GenAlpha(ga), tr) => {
                    if tr.is_some() {
                        y_prev.copy_from_slice(&y);
                    }
                    ga.step(t, &mut y, &mut yd).and_then(|()| match tr {
                        Some(tr) => tr.implicit_step(
                            t,
                            dt,
                            if quasi { 1.0 } else { alpha_f },
                            &y_prev,
                            &y,
                            &mut z,
                        ),
                        None => Ok(()),
                    })
                }
            };
            step_global += 1;
            let t_new = step_global as f64 * dt;
            if let Err(e) = r {
                error = Some(e);
                break 'cycles;
            }
            if let Some(m) = mean.as_deref_mut() {
                for (acc, &i) in m.sum.iter_mut().zip(&m.unknowns) {
                    *acc += y[i].abs();
                }
                m.count += 1;
            }
            if k % 64 == 0 || k == steps_per_cycle {
                if let Some(tr) = transport.as_deref_mut().filter(|_| explicit_transport) {
                    // explicit upwind transport is stable for Courant numbers up to 1.3926
                    // (physics §1.5); the flow eigenvalues alone do not bound it
                    let courant = dt * tr.max_outflow_rate(&y, t_new);
                    if courant > 0.95 * 1.392_647 {
                        error = Some(Error::solver(
                            t_new,
                            format!(
                                "transport Courant number {courant:.3} exceeds the RK4 limit 1.39 (dt {dt:.3e} s): reduce dt to {:.3e} s or use method 'generalized-alpha'",
                                dt * 0.7 / courant
                            ),
                        ));
                        break 'cycles;
                    }
                }
                if let Some(i) = y.iter().position(|v| !v.is_finite()) {
                    error = Some(Error::solver(
                        t_new,
                        format!("non-finite value of {}", dae.names[i]),
                    ));
                    break 'cycles;
                }
            }
            // last-cycle output counts from the cycle start (svZeroDSolver's convention), so
            // the output times do not depend on how many cycles ran
            let due = if s.output_all_cycles {
                step_global % stride == 0
            } else {
                k % stride == 0
            };
            if due && recorded {
                let tr = if s.output_all_cycles {
                    t_new
                } else {
                    t_new - t0
                };
                rec.record(tr, &y);
                // species outputs of cycles that will be discarded are not computed
                let keep =
                    s.output_all_cycles || s.until_periodic.is_some() || cycle + 1 == max_cycles;
                if let Some(tp) = transport.as_deref_mut().filter(|_| keep) {
                    obs_row.clear();
                    if let Err(e) = observe(tp, &mut stepper, t_new, &y, &yd, &z, &mut obs_row) {
                        error = Some(e);
                        break 'cycles;
                    }
                    rec.push_species(&obs_row);
                }
                if committed && !rec.flush(false, &initial_stored) {
                    error = Some(Error::Interrupted { time: t_new });
                    break 'cycles;
                }
            }
            if step_global % 256 == 0 && !progress(t_new, t_end) {
                error = Some(Error::Interrupted { time: t_new });
                break 'cycles;
            }
        }
        cycles_run = cycle + 1;
        periodic_error = scaled_increment(
            dae,
            &y.iter()
                .zip(&prev_cycle_end)
                .map(|(a, b)| a - b)
                .collect::<Vec<_>>(),
            &y,
        );
        prev_cycle_end.copy_from_slice(&y);
        if let Some(m) = mean.as_deref_mut() {
            let c = m.count.max(1) as f64;
            for (l, v) in m.last.iter_mut().zip(&m.sum) {
                *l = v / c;
            }
            let scale = m
                .last
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()))
                .max(1e-300);
            let change = m
                .last
                .iter()
                .zip(&m.prev)
                .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
            m.prev.copy_from_slice(&m.last);
            if change <= MEAN_FLOW_TOL * scale {
                break;
            }
        }
        if let Some(tr) = transport.as_deref() {
            // species need several transit times: include them in the periodicity test
            periodic_error = periodic_error.max(tr.relative_change(&z, &prev_cycle_z));
            prev_cycle_z.copy_from_slice(&z);
        }
        if let Some(tol) = s.until_periodic {
            if cycles_run >= s.cycles && periodic_error < tol {
                break;
            }
        }
    }
    // the rest of the output (the partial chunk, or all rows of an interrupted run) goes to the
    // sink too: a long run keeps everything it computed
    rec.align();
    if !rec.flush(true, &initial_stored) && error.is_none() {
        error = Some(Error::Interrupted {
            time: step_global as f64 * dt,
        });
    }
    progress(cycles_run as f64 * s.period, t_end);
    Ok(Outcome {
        max_buffered_rows: rec.max_rows,
        times: rec.times,
        data: rec.data,
        n_probes: s.probes.len(),
        dt,
        method: method_name,
        cycles_run,
        periodic_error,
        stability,
        final_state: y,
        error,
        transport: transport.map(|tr| TransportOutcome {
            species: tr.species_names(),
            columns_per_species: kept,
            data: rec.transport,
            initial_stored,
            final_state: z,
            mean_abs_flow: Vec::new(),
        }),
    })
}
