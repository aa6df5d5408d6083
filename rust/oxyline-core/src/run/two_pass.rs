//! The paper's two-pass procedure (physics §3.1): closures that need the cycle-mean |Q| get
//! it from a first, flow-only pass over the same cycles; the coupled run then starts again
//! from the same initial state. Both passes share one steady state.

use super::settings::{Method, RunSettings};
use super::{Outcome, OutputSink, run};
use crate::circuit::Dae;
use crate::error::Result;
use crate::integrate::steady::SteadyCache;
use crate::transport::Transport;

/// Running mean of |y_i| over the current cycle (for cycle-mean wall shear).
pub(super) struct MeanAbs {
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

impl MeanAbs {
    fn new(unknowns: Vec<usize>) -> Self {
        let n = unknowns.len();
        MeanAbs {
            unknowns,
            sum: vec![0.0; n],
            last: vec![0.0; n],
            prev: vec![f64::INFINITY; n],
            count: 0,
        }
    }

    pub fn start_cycle(&mut self) {
        self.sum.iter_mut().for_each(|v| *v = 0.0);
        self.count = 0;
    }

    pub fn accumulate(&mut self, y: &[f64]) {
        for (acc, &i) in self.sum.iter_mut().zip(&self.unknowns) {
            *acc += y[i].abs();
        }
        self.count += 1;
    }

    /// Close the cycle's mean; true once it has settled (see [`MEAN_FLOW_TOL`]).
    pub fn end_cycle(&mut self) -> bool {
        let c = self.count.max(1) as f64;
        for (l, v) in self.last.iter_mut().zip(&self.sum) {
            *l = v / c;
        }
        let scale = self
            .last
            .iter()
            .fold(0.0f64, |a, v| a.max(v.abs()))
            .max(1e-300);
        let change = self
            .last
            .iter()
            .zip(&self.prev)
            .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()));
        self.prev.copy_from_slice(&self.last);
        change <= MEAN_FLOW_TOL * scale
    }
}

pub(super) fn run_two_pass(
    dae: &Dae,
    transport: Option<&mut Transport>,
    s: &RunSettings,
    sink: Option<&mut OutputSink<'_>>,
    progress: &mut dyn FnMut(f64, f64) -> bool,
) -> Result<Outcome> {
    // the steady state is solved at most once per call, by whichever part of either pass
    // needs it first
    let steady = SteadyCache::new(dae);
    let Some(tr) = transport else {
        return run(dae, &steady, s, None, None, sink, progress);
    };
    let unknowns = tr.mean_flow_unknowns();
    let mut mean_abs_flow = Vec::new();
    if !unknowns.is_empty() {
        let mut mean = MeanAbs::new(unknowns);
        // the first pass records nothing: no sink
        let first = run(
            dae,
            &steady,
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
    let mut out = run(dae, &steady, s, Some(tr), None, sink, progress)?;
    if let Some(t) = out.transport.as_mut() {
        t.mean_abs_flow = mean_abs_flow;
    }
    Ok(out)
}

/// Steps per cycle of the flow-only first pass when the main run is explicit.
const MEAN_FLOW_STEPS_PER_CYCLE: f64 = 2000.0;

/// Settings of the flow-only pass that measures the cycle-mean |Q|. The closures need a mean
/// (k ∝ γ̄^{1/3}), not the explicit scheme's stability-limited resolution: an RK4 run gets an
/// implicit pass at period/2000 (second order: the mean |Q| differs by ~1e-5 relative, k by a
/// third of that), which costs a few percent of the RK4 pass it replaces. Implicit runs keep
/// their own step.
fn mean_flow_pass(s: &RunSettings) -> RunSettings {
    let mut first = RunSettings {
        probes: Vec::new(),
        ..s.clone()
    };
    if matches!(s.method, Method::Rk4) {
        first.method = Method::GeneralizedAlpha { rho_inf: 0.5 };
        let coarse = s.period / MEAN_FLOW_STEPS_PER_CYCLE;
        first.dt = Some(s.dt.map_or(coarse, |dt| dt.max(coarse)));
    }
    first
}
