//! The Fourier harmonics of a few segment flows over the first pass's cycles: what the
//! inlet-renewal closure needs of each vessel (its backward wall strain B from every
//! harmonic's Womersley wall shear, docs/physics.md §3.6). Fed by `MeanAbs` step by step;
//! only vessels with a `flow: inlet-renewal` wall are tracked, so other runs pay nothing.

use super::mean_flow::MeanAbs;
use crate::error::Result;
use crate::transport::Transport;
use crate::transport::renewal::VesselFlow;
use nalgebra::Complex;
use std::f64::consts::PI;

/// At most this many harmonics (the rest of a first pass's steps per cycle resolves the
/// waveform's sharp features; the wall shear's backward part comes from the first few).
const MAX_HARMONICS: usize = 32;

/// The samples of the tracked flows over the current cycle (steps are equally spaced in a
/// cycle), and the harmonics of the last completed one.
pub(super) struct FlowHarmonics {
    vessels: Vec<usize>,
    unknowns: Vec<usize>,
    /// Samples of the current cycle, step after step (`unknowns.len()` per step). Memory:
    /// 8 B × tracked vessels × steps per cycle, for the first pass only.
    samples: Vec<f64>,
    /// Per tracked vessel: its flow over the last completed cycle.
    pub last: Vec<VesselFlow>,
}

impl FlowHarmonics {
    /// The accumulator for `tr`'s renewal vessels; None when no wall needs it.
    pub fn for_transport(tr: &Transport) -> Option<Self> {
        let inlets = tr.renewal_inlets();
        (!inlets.is_empty()).then(|| FlowHarmonics {
            vessels: inlets.iter().map(|p| p.0).collect(),
            unknowns: inlets.iter().map(|p| p.1).collect(),
            samples: Vec::new(),
            last: Vec::new(),
        })
    }

    pub fn start_cycle(&mut self) {
        self.samples.clear();
    }

    pub fn accumulate(&mut self, y: &[f64]) {
        self.samples.extend(self.unknowns.iter().map(|&i| y[i]));
    }

    /// The discrete Fourier series of the cycle's samples y_n (n = 1..N, at t_n = n T/N from
    /// the cycle start): mean = Σ y_n/N, Q̂_k = (2/N) Σ y_n e^{−2πikn/N}, k < N/2. A constant
    /// time shift of the samples only shifts the waveform, which leaves B unchanged.
    pub fn end_cycle(&mut self) {
        let m = self.unknowns.len();
        let n = self.samples.len() / m.max(1);
        if n < 4 {
            return;
        }
        let h = MAX_HARMONICS.min((n - 1) / 2);
        self.last = self
            .vessels
            .iter()
            .enumerate()
            .map(|(u, &vessel)| {
                let y = |s: usize| self.samples[s * m + u];
                let mean = (0..n).map(y).sum::<f64>() / n as f64;
                let harmonics = (1..=h)
                    .map(|k| {
                        let step = Complex::from_polar(1.0, -2.0 * PI * k as f64 / n as f64);
                        let mut phase = step; // sample s is at t_{s+1}
                        let mut acc = Complex::new(0.0, 0.0);
                        for s in 0..n {
                            acc += phase * y(s);
                            phase *= step;
                        }
                        acc * (2.0 / n as f64)
                    })
                    .collect();
                VesselFlow {
                    vessel,
                    mean,
                    harmonics,
                }
            })
            .collect();
    }
}

/// Set `tr`'s segment laws from the first pass: the cycle means, and the inlet renewal of
/// every vessel whose harmonics were recorded (the one call of `two_pass`).
pub(super) fn set_mean_flows(tr: &mut Transport, mean: &MeanAbs, period: f64) -> Result<()> {
    match mean.harmonics.as_ref() {
        Some(h) if !h.last.is_empty() => {
            tr.set_mean_flows_renewed(&mean.last, &mean.forward(), period, &h.last)
        }
        _ => tr.set_mean_flows(&mean.last, &mean.forward()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cycle_samples_give_the_waveform_harmonics() {
        // y(t) = m + a cos ωt + b sin 2ωt + c cos 5ωt at t_n = n T/N (n = 1..N): the exact
        // discrete series (no aliasing below N/2), so round-off only (1e-13 of the amplitude)
        let (m, a, b, c, n) = (2e-5, 3e-5, -8e-6, 1e-6, 400usize);
        let mut h = FlowHarmonics {
            vessels: vec![7],
            unknowns: vec![1],
            samples: Vec::new(),
            last: Vec::new(),
        };
        h.start_cycle();
        for s in 1..=n {
            let th = 2.0 * PI * s as f64 / n as f64;
            let y = m + a * th.cos() + b * (2.0 * th).sin() + c * (5.0 * th).cos();
            h.accumulate(&[0.0, y]);
        }
        h.end_cycle();
        let f = &h.last[0];
        assert_eq!(f.vessel, 7);
        assert_eq!(f.harmonics.len(), MAX_HARMONICS);
        let tol = 1e-13 * a;
        assert!((f.mean - m).abs() < tol);
        // Q = mean + Re Σ Q̂_k e^{ikωt}: a cos → Q̂ = a, b sin → Q̂ = −i b
        let want = |k: usize| match k {
            1 => Complex::new(a, 0.0),
            2 => Complex::new(0.0, -b),
            5 => Complex::new(c, 0.0),
            _ => Complex::new(0.0, 0.0),
        };
        for (k, q) in f.harmonics.iter().enumerate() {
            assert!((q - want(k + 1)).norm() < tol, "harmonic {}: {q}", k + 1);
        }
    }
}
