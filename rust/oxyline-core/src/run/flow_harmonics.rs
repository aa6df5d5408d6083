//! The Fourier harmonics of a few segment flows over the first pass's cycles: what the
//! inlet-renewal closure needs of each vessel (its backward wall strain B from every
//! harmonic's Womersley wall shear, docs/physics.md §3.6). Fed by `MeanAbs` step by step;
//! only vessels with a `flow: inlet-renewal` wall are tracked, so other runs pay nothing.
//!
//! The harmonics are running sums, folded in every [`BLOCK`] steps: the pass holds H complex
//! sums per vessel (H ≤ 32: 512 B) and a block of samples (8 B per step and vessel), not the
//! cycle's samples (8 B × steps per cycle per vessel, plus the growth of their vector).

use crate::transport::Transport;
use crate::transport::renewal::VesselFlows;
use nalgebra::Complex;
use std::f64::consts::PI;

/// At most this many harmonics (the rest of a first pass's steps per cycle resolves the
/// waveform's sharp features; the wall shear's backward part comes from the first few).
const MAX_HARMONICS: usize = 32;

/// The most steps per cycle whose roots of unity are tabulated (256 KiB); a finer cycle's
/// phases are computed per sample and harmonic (the same values).
const MAX_ROOTS: usize = 1 << 14;

/// e^{−2πim/N}, the phase of the residue `m` of a cycle of `n` steps (the one expression of
/// every phase: the same bits tabulated or not).
fn phase(m: usize, n: usize) -> Complex<f64> {
    Complex::from_polar(1.0, -2.0 * PI * m as f64 / n as f64)
}

/// Steps of samples held before they are folded into the sums: each fold reads and writes
/// every vessel's sums once, so the sums' memory traffic is 1/`BLOCK` of a fold per step.
const BLOCK: usize = 16;

/// The running Fourier sums of the tracked flows over the current cycle (steps equally
/// spaced in a cycle), and after [`FlowHarmonics::end_cycle`] the harmonics of that cycle.
pub(crate) struct FlowHarmonics {
    vessels: Vec<usize>,
    unknowns: Vec<usize>,
    /// Steps of the current cycle, and how many were accumulated.
    steps: usize,
    count: usize,
    /// Harmonics kept per vessel: min(`MAX_HARMONICS`, (steps − 1)/2).
    per_vessel: usize,
    /// Per tracked vessel, `per_vessel` sums Σ_s y_s e^{−2πiks/N}; the harmonics once the cycle
    /// is complete.
    sums: Vec<Complex<f64>>,
    /// Per tracked vessel Σ_s y_s; the mean once the cycle is complete.
    means: Vec<f64>,
    /// Samples not yet folded in, step after step (`unknowns.len()` per step).
    block: Vec<f64>,
    /// The phases of the block's steps, e^{−2πiks/N}, `per_vessel` per step.
    phases: Vec<Complex<f64>>,
    /// The cycle's N roots e^{−2πim/N} (m = 0..N; empty for N above `MAX_ROOTS`): the phase
    /// of sample s and harmonic k is the root m = ks mod N, one `from_polar` per root and
    /// cycle instead of one per sample and harmonic (those were a quarter of an O2 run's
    /// instructions on paper-bifurcated).
    roots: Vec<Complex<f64>>,
    /// Whether `sums` and `means` hold the harmonics of a completed cycle.
    complete: bool,
}

impl FlowHarmonics {
    /// The accumulator for `tr`'s renewal vessels; None when no wall needs it.
    pub fn for_transport(tr: &Transport) -> Option<Self> {
        let inlets = tr.renewal_inlets();
        (!inlets.is_empty()).then(|| Self::new(inlets))
    }

    /// The accumulator of the flows `y[unknown]` of `inlets` (vessel, unknown): the samples
    /// may be any vector linear in the flow (a tangent's harmonics are the same sums of the
    /// tangent's samples).
    pub(crate) fn new(inlets: Vec<(usize, usize)>) -> Self {
        FlowHarmonics {
            vessels: inlets.iter().map(|p| p.0).collect(),
            unknowns: inlets.iter().map(|p| p.1).collect(),
            steps: 0,
            count: 0,
            per_vessel: 0,
            sums: Vec::new(),
            means: Vec::new(),
            block: Vec::new(),
            phases: Vec::new(),
            roots: Vec::new(),
            complete: false,
        }
    }

    /// A new cycle of `steps` equally spaced steps (the samples come at t_s = s T/N, s = 1..N).
    pub fn start_cycle(&mut self, steps: usize) {
        let m = self.unknowns.len();
        self.steps = steps;
        self.count = 0;
        self.complete = false;
        self.per_vessel = if steps < 4 {
            0
        } else {
            MAX_HARMONICS.min((steps - 1) / 2)
        };
        self.sums.clear();
        self.sums
            .resize(m * self.per_vessel, Complex::new(0.0, 0.0));
        self.means.clear();
        self.means.resize(m, 0.0);
        self.block.clear();
        self.block.reserve_exact(m * BLOCK);
        self.roots.clear();
        if self.per_vessel > 0 && steps <= MAX_ROOTS {
            self.roots.extend((0..steps).map(|m| phase(m, steps)));
        }
    }

    pub fn accumulate(&mut self, y: &[f64]) {
        self.block.extend(self.unknowns.iter().map(|&i| y[i]));
        self.count += 1;
        if self.block.len() >= BLOCK * self.unknowns.len() {
            self.fold();
        }
    }

    /// Fold the block's samples into the sums (in step order: the same sums as one step at a
    /// time). The phase of sample s and harmonic k is e^{−2πi((ks) mod N)/N}, each from its
    /// own `from_polar` of an angle below 2π.
    fn fold(&mut self) {
        let (m, h) = (self.unknowns.len(), self.per_vessel);
        let rows = self.block.len() / m.max(1);
        let first = self.count - rows + 1; // the block's first sample index s
        let n = self.steps.max(1);
        self.phases.clear();
        let roots = &self.roots;
        for s in first..first + rows {
            self.phases
                .extend((1..=h).map(|k| match roots.get((k * s) % n) {
                    Some(&root) => root,
                    None => phase((k * s) % n, n),
                }));
        }
        for (u, (mean, sums)) in self
            .means
            .iter_mut()
            .zip(self.sums.chunks_exact_mut(h.max(1)))
            .enumerate()
        {
            for r in 0..rows {
                let y = self.block[r * m + u];
                *mean += y;
                for (acc, w) in sums.iter_mut().zip(&self.phases[r * h..(r + 1) * h]) {
                    *acc += w * y;
                }
            }
        }
        self.block.clear();
    }

    /// Close the cycle: the discrete Fourier series of its samples y_s (s = 1..N, at t_s =
    /// s T/N from the cycle start): mean = Σ y_s/N, Q̂_k = (2/N) Σ y_s e^{−2πiks/N}, k < N/2.
    /// A constant time shift of the samples only shifts the waveform, which leaves B
    /// unchanged. A cycle of fewer than 4 steps, or cut short, gives no harmonics.
    pub fn end_cycle(&mut self) {
        self.fold();
        if self.per_vessel == 0 || self.count != self.steps {
            return;
        }
        let n = self.count as f64;
        self.sums.iter_mut().for_each(|q| *q *= 2.0 / n);
        self.means.iter_mut().for_each(|y| *y /= n);
        self.complete = true;
        // the block is not needed again this pass
        self.block = Vec::new();
        self.phases = Vec::new();
        self.roots = Vec::new();
    }

    /// The harmonics of the last completed cycle (None before one completes).
    pub fn flows(&self) -> Option<VesselFlows<'_>> {
        self.complete.then_some(VesselFlows {
            vessels: &self.vessels,
            means: &self.means,
            harmonics: &self.sums,
            per_vessel: self.per_vessel,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cycle_samples_give_the_waveform_harmonics() {
        // y(t) = m + a cos ωt + b sin 2ωt + c cos 5ωt at t_n = n T/N (n = 1..N): the exact
        // discrete series (no aliasing below N/2), so round-off only (1e-13 of the amplitude).
        // N = 400 is not a multiple of the block: the last fold is partial.
        let (m, a, b, c, n) = (2e-5, 3e-5, -8e-6, 1e-6, 400usize);
        // two vessels, the second with the negated flow (its harmonics negated)
        let mut h = FlowHarmonics::new(vec![(7, 1), (9, 2)]);
        h.start_cycle(n);
        assert!(h.flows().is_none());
        for s in 1..=n {
            let th = 2.0 * PI * s as f64 / n as f64;
            let y = m + a * th.cos() + b * (2.0 * th).sin() + c * (5.0 * th).cos();
            h.accumulate(&[0.0, y, -y]);
        }
        h.end_cycle();
        let f = h.flows().expect("a completed cycle");
        assert_eq!(f.vessels, &[7, 9]);
        assert_eq!(f.per_vessel, MAX_HARMONICS);
        let tol = 1e-13 * a;
        // Q = mean + Re Σ Q̂_k e^{ikωt}: a cos → Q̂ = a, b sin → Q̂ = −i b
        let want = |k: usize| match k {
            1 => Complex::new(a, 0.0),
            2 => Complex::new(0.0, -b),
            5 => Complex::new(c, 0.0),
            _ => Complex::new(0.0, 0.0),
        };
        for (i, sign) in [(0, 1.0), (1, -1.0)] {
            let flow = f.flow(i, 1.0);
            assert!((flow.mean - sign * m).abs() < tol);
            for (k, q) in flow.harmonics.iter().enumerate() {
                let w = want(k + 1) * sign;
                assert!((q - w).norm() < tol, "vessel {i} harmonic {}: {q}", k + 1);
            }
        }
        // a cycle cut short gives none
        h.start_cycle(n);
        h.accumulate(&[0.0, 1.0, 1.0]);
        h.end_cycle();
        assert!(h.flows().is_none());
    }
}
