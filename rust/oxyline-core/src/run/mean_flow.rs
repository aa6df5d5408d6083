//! The cycle-mean |Q| and signed Q of the segments, accumulated during the flow-only first
//! pass of a transport run (see `two_pass`).

use super::adaptive::Scouted;
use super::flow_harmonics::FlowHarmonics;
use crate::error::Result;
use crate::transport::Transport;

/// Running means of |y_i| and y_i over the current cycle (for cycle-mean wall shear).
pub(super) struct MeanAbs {
    unknowns: Vec<usize>,
    sum: Vec<f64>,
    sum_signed: Vec<f64>,
    /// The mean |y_i| of the last cycle completed.
    pub last: Vec<f64>,
    /// The mean y_i of the last cycle completed.
    pub last_signed: Vec<f64>,
    prev: Vec<f64>,
    count: usize,
    /// The inlet renewal's flow harmonics, fed with the same steps (None: not needed).
    pub harmonics: Option<FlowHarmonics>,
    /// An error-controlled run's scout pass, fed with the first cycle's steps (None: the run
    /// has a fixed step).
    pub scout: Option<Scouted>,
}

/// The flow-only first pass stops once the cycle-mean |Q| of every segment changes by less
/// than this (relative to the largest) between two cycles: the closures need the mean shear,
/// not a fully settled pressure level.
const MEAN_FLOW_TOL: f64 = 1e-6;

impl MeanAbs {
    pub fn new(unknowns: Vec<usize>) -> Self {
        let n = unknowns.len();
        MeanAbs {
            unknowns,
            sum: vec![0.0; n],
            sum_signed: vec![0.0; n],
            last: vec![0.0; n],
            last_signed: vec![0.0; n],
            prev: vec![f64::INFINITY; n],
            count: 0,
            harmonics: None,
            scout: None,
        }
    }

    /// A new cycle of `steps` steps (the harmonics' phases need the count up front).
    pub fn start_cycle(&mut self, steps: usize) {
        self.sum.iter_mut().for_each(|v| *v = 0.0);
        self.sum_signed.iter_mut().for_each(|v| *v = 0.0);
        self.count = 0;
        if let Some(h) = self.harmonics.as_mut() {
            h.start_cycle(steps);
        }
    }

    pub fn accumulate(&mut self, y: &[f64]) {
        for ((acc, sgn), &i) in self
            .sum
            .iter_mut()
            .zip(&mut self.sum_signed)
            .zip(&self.unknowns)
        {
            *acc += y[i].abs();
            *sgn += y[i];
        }
        self.count += 1;
        if let Some(h) = self.harmonics.as_mut() {
            h.accumulate(y);
        }
        if let Some(s) = self.scout.as_mut() {
            s.step(y);
        }
    }

    /// The forward-flow mean of the last cycle, ⟨max(±y_i, 0)⟩ in the direction of the net
    /// flow = (⟨|y_i|⟩ + |⟨y_i⟩|)/2 (equal to ⟨|y_i|⟩ bit for bit when y_i keeps one sign).
    pub fn forward(&self) -> Vec<f64> {
        self.last
            .iter()
            .zip(&self.last_signed)
            .map(|(a, s)| {
                if a == &s.abs() {
                    *a
                } else {
                    0.5 * (a + s.abs())
                }
            })
            .collect()
    }

    /// Close the cycle's mean; true once it has settled (see [`MEAN_FLOW_TOL`]).
    pub fn end_cycle(&mut self) -> bool {
        if let Some(h) = self.harmonics.as_mut() {
            h.end_cycle();
        }
        let c = self.count.max(1) as f64;
        for (l, v) in self.last.iter_mut().zip(&self.sum) {
            *l = v / c;
        }
        for (l, v) in self.last_signed.iter_mut().zip(&self.sum_signed) {
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

/// Set `tr`'s segment laws from the first pass: the cycle means, and the inlet renewal of
/// every vessel whose harmonics were recorded (the one call of `two_pass`).
pub(super) fn set_mean_flows(tr: &mut Transport, mean: &MeanAbs, period: f64) -> Result<()> {
    match mean.harmonics.as_ref().and_then(FlowHarmonics::flows) {
        Some(flows) => tr.set_mean_flows_renewed(&mean.last, &mean.forward(), period, flows),
        None => tr.set_mean_flows(&mean.last, &mean.forward()),
    }
}
