//! The paper's two-pass procedure (docs/physics.md §3.1): closures that need the cycle-mean |Q|
//! (or the forward-flow mean, §3.6) get it from a first, flow-only pass over the same cycles;
//! the coupled run then starts again from the same initial state. Both passes share one
//! steady state.

use super::adaptive::{Adaptive, Scouted};
use super::checkpoint::Checkpoints;
use super::flow_harmonics::FlowHarmonics;
use super::mean_flow::{self, MeanAbs};
use super::outcome::Outcome;
use super::pass::run;
use super::recorder::OutputSink;
use super::settings::{Method, RunSettings};
use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::integrate::steady::SteadyCache;
use crate::transport::Transport;

pub(super) fn run_two_pass(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
    mut checkpoints: Option<&mut Checkpoints<'_>>,
) -> Result<Outcome> {
    // the steady state is solved at most once per call, by whichever part of either pass
    // needs it first
    let mut steady = SteadyCache::new(dae);
    let Some(tr) = transport else {
        let out = run(
            dae,
            &mut steady,
            s,
            None,
            None,
            None,
            sink,
            progress,
            checkpoints,
        );
        return keep_interrupted(out, s, None);
    };
    let unknowns = tr.mean_flow_unknowns();
    let mut mean_abs_flow = Vec::new();
    let mut scouted = None;
    // A resumed run repeats the first pass (it starts from the initial state, not from the
    // snapshot, so it is the same pass): the laws also need the forward-flow means and the
    // inlet-renewal harmonics, which the checkpoint's mean |Q| alone does not give, and the
    // pass costs ~0.15 of a flow run. The resumed run is then bit-identical to the
    // uninterrupted one for every closure.
    if !unknowns.is_empty() {
        let mut mean = MeanAbs::new(unknowns);
        mean.harmonics = FlowHarmonics::for_transport(tr);
        // an error-controlled run's scout pass from the same first cycle's steps (a run with
        // valves takes none: see `Adaptive::scout`)
        let valves = dae.elements.iter().any(|el| !el.switches().is_empty());
        mean.scout = s.adaptive().filter(|_| !valves).map(|tol| {
            let rho_inf = s.method.rho_inf();
            Scouted::new(Adaptive::new(dae, tol, rho_inf, s.period, s.output_every))
        });
        // the first pass records nothing: no sink
        let first = run(
            dae,
            &mut steady,
            &mean_flow_pass(s),
            None,
            Some(&mut mean),
            None,
            None,
            progress,
            None,
        );
        // stopped in this pass (cancel, signal, solver failure): a result with no rows yet,
        // of the coupled run's layout, says so (as a stop in any later phase does)
        match first {
            Ok(Outcome { error: Some(e), .. }) => return Ok(Outcome::unstarted(s, Some(&*tr), e)),
            Err(e @ Error::Interrupted { .. }) => {
                return Ok(Outcome::unstarted(s, Some(&*tr), e));
            }
            Err(e) => return Err(e),
            Ok(_) => {}
        }
        mean_flow::set_mean_flows(tr, &mean, s.period)?;
        scouted = mean.scout.take();
        mean_abs_flow = mean.last;
    }
    if let Some(c) = checkpoints.as_deref_mut() {
        c.mean_abs_flow.clone_from(&mean_abs_flow);
    }
    let out = run(
        dae,
        &mut steady,
        s,
        Some(&mut *tr),
        None,
        scouted,
        sink,
        progress,
        checkpoints,
    );
    let mut out = keep_interrupted(out, s, Some(&*tr))?;
    if let Some(t) = out.transport.as_mut() {
        t.mean_abs_flow = mean_abs_flow;
    }
    Ok(out)
}

/// A pass interrupted before its cycle loop (during the step estimate) returns, like one
/// interrupted later, a result flagged by the interruption: here with no rows.
fn keep_interrupted(
    out: Result<Outcome>,
    s: &RunSettings,
    tr: Option<&Transport>,
) -> Result<Outcome> {
    match out {
        Err(e @ Error::Interrupted { .. }) => Ok(Outcome::unstarted(s, tr, e)),
        out => out,
    }
}

/// Steps per cycle of the flow-only first pass when the main run is explicit.
const MEAN_FLOW_STEPS_PER_CYCLE: f64 = 2000.0;
/// An implicit run at the usual step (>= period/1000) measures the mean |Q| at
/// period/`MEAN_FLOW_COARSE_STEPS`: the pass then costs an eighth of the coupled run's flow
/// instead of all of it. The mean over 125 steps is accurate to 2.6e-4 of <|Q|> for a reversing
/// sinusoid (tests/test_oxygen.py checks 1e-3 against the closed form), so k ∝ <|Q|>^{1/3} to
/// ~1e-4 — far inside the closures' own uncertainty (docs/physics.md
/// §3.1). With a sharper inflow the step's resolution of the flow dominates (not the
/// quadrature: the exact integral between steps gives the same): on the half-sine bench trees
/// (`benches/bench_scale.py`, 16 k and 65 k segments) the 125-step mean differs from a
/// period/2000 pass by ≤ 1.2e-2 (p99 ≤ 8.9e-3, median 2.5e-3; 250 steps: ≤ 1.1e-2, p99 9.7e-3;
/// 200 and 160 steps 1.3e-2, 100 steps 1.9e-2), so k by ≤ 4e-3, still inside that uncertainty;
/// 50 steps would give 5.7e-2 (`examples/mean_flow_accuracy.rs`, benches/results.md).
/// Finer implicit runs keep their own step (an exact mean).
const MEAN_FLOW_COARSE_STEPS: f64 = 125.0;
const MEAN_FLOW_FINE_STEPS: f64 = 1000.0;

/// Settings of the flow-only pass that measures the cycle-mean |Q|. The closures need a mean
/// (k ∝ γ̄^{1/3}), not the explicit scheme's stability-limited resolution: an RK4 run gets an
/// implicit pass at period/2000 (second order: the mean |Q| differs by ~1e-5 relative, k by a
/// third of that), which costs a few percent of the RK4 pass it replaces. Implicit runs
/// at the usual step coarsen it (see `MEAN_FLOW_COARSE_STEPS`).
fn mean_flow_pass(s: &RunSettings) -> RunSettings {
    let mut first = RunSettings {
        probes: Vec::new(),
        svzerod: Default::default(),
        finer_last_cycle: None,
        ..s.clone()
    };
    if s.adaptive().is_some() {
        // an error-controlled run measures the mean on the fixed coarse implicit step: the
        // closures then depend neither on its tolerances' steps nor on its output interval
        first.tolerances = None;
        first.method = Method::GeneralizedAlpha {
            rho_inf: s.method.rho_inf(),
        };
        first.dt = Some(s.period / MEAN_FLOW_COARSE_STEPS);
        return first;
    }
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
        Method::Auto { .. } | Method::Dopri5 => {}
    }
    first
}
