//! The forcing's corners as breakpoints of the error-controlled step (docs/physics.md §10,
//! "Breakpoints"): a linear table's sample where the slope changes sharply (a half-sine
//! inflow's start and stop) is a known discontinuity of the forcing's derivative. A step
//! across it errs to first order in the step (the forcing's slope jump times h²), which the
//! estimate meets by rejecting and shrinking the step until the corner is passed, and the
//! extrapolation through the last three states then straddles the corner for two more steps.
//! As usual for a piecewise forcing, a step ends on each corner instead, and the error history
//! starts again there (as after a valve event).

use crate::circuit::Dae;

/// Corners closer than this share of the period to one already kept are the same corner.
const SAME_CORNER: f64 = 1e-9;

/// A waveform with more corners than this per cycle has its corners left to the error
/// control (a breakpoint each would bound the step by the corners' spacing).
const MAX_CORNERS: usize = 64;

/// The forcing's corners: (the first time of each, the period of its waveform).
#[derive(Debug, Default)]
pub(super) struct Breakpoints {
    corners: Vec<(f64, f64)>,
    /// The corners of the cycle being run, in order, and the next one not yet reached.
    cycle: Vec<f64>,
    next: usize,
}

impl Breakpoints {
    /// The corners of every periodic forcing of `dae` (`Waveform::kinks`), a run of cycles of
    /// `period`.
    pub fn of(dae: &Dae, period: f64) -> Self {
        let mut corners = Vec::new();
        for (_, w) in &dae.forcing {
            let (kinks, Some(p)) = (w.kinks(), w.period()) else {
                continue;
            };
            if p > 0.0 && (kinks.len() as f64) * (period / p).max(1.0) <= MAX_CORNERS as f64 {
                corners.extend(kinks.into_iter().map(|k| (k, p)));
            }
        }
        Breakpoints {
            corners,
            ..Default::default()
        }
    }

    /// A cycle from `t0` to `t1` starts: its corners in (t0, t1] (a corner on t0 ended the
    /// cycle before), in order.
    pub fn start_cycle(&mut self, t0: f64, t1: f64) {
        let tol = SAME_CORNER * (t1 - t0);
        self.cycle.clear();
        self.next = 0;
        for &(first, p) in &self.corners {
            // the corner's first time after t0 (within the tolerance: none on t0 itself)
            let mut c = first + ((t0 + tol - first) / p).floor() * p;
            while c <= t0 + tol {
                c += p;
            }
            while c <= t1 + tol {
                self.cycle.push(c.min(t1));
                c += p;
            }
        }
        self.cycle.sort_by(f64::total_cmp);
        self.cycle.dedup_by(|b, a| *b - *a <= tol);
    }

    /// The next corner after `t` (None: none left in this cycle).
    pub fn next_after(&mut self, t: f64) -> Option<f64> {
        while self.cycle.get(self.next).is_some_and(|&c| c <= t) {
            self.next += 1;
        }
        self.cycle.get(self.next).copied()
    }
}

/// The step toward a corner `to_corner` ahead of the step's start: the step `h` chosen
/// without it, ended on the corner when it nearly reaches it and halved when under two steps
/// are left (no sliver of a step before the corner: `cycle::toward_end`); a replayed step
/// (`exact`: the step sequence of the cycle before) only ends on the corner it reaches.
pub(super) fn toward_corner(h: f64, to_corner: f64, exact: bool) -> f64 {
    if exact {
        if h >= to_corner * (1.0 - 1e-9) {
            to_corner
        } else {
            h
        }
    } else {
        super::cycle::toward_end(h, to_corner)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn of(corners: &[(f64, f64)]) -> Breakpoints {
        Breakpoints {
            corners: corners.to_vec(),
            ..Default::default()
        }
    }

    #[test]
    fn a_cycles_corners_are_those_after_its_start_up_to_its_end() {
        // a corner at 0 (the table's wrap) and at 0.3 of a waveform of period 1; another of
        // period 0.5 at 0.3 (0.3 and 0.8): cycle 2 (from 2 to 3)
        let mut b = of(&[(0.0, 1.0), (0.3, 1.0), (0.3, 0.5)]);
        b.start_cycle(2.0, 3.0);
        // 2.0 is the cycle's start (the corner ended the cycle before); 2.3 once; 3.0 its end
        assert_eq!(b.cycle.len(), 3, "{:?}", b.cycle);
        assert!((b.cycle[0] - 2.3).abs() < 1e-12 && (b.cycle[1] - 2.8).abs() < 1e-12);
        assert_eq!(b.cycle[2], 3.0);
        assert_eq!(b.next_after(2.0), Some(b.cycle[0]));
        assert_eq!(b.next_after(2.5), Some(b.cycle[1]));
        assert_eq!(b.next_after(3.0), None);
    }

    #[test]
    fn a_step_ends_on_the_corner_it_nearly_reaches_and_leaves_no_sliver() {
        assert_eq!(toward_corner(0.1, 0.5, false), 0.1);
        assert_eq!(toward_corner(0.3, 0.5, false), 0.25);
        assert_eq!(toward_corner(0.6, 0.5, false), 0.5);
        // a replayed step keeps its length unless it reaches the corner
        assert_eq!(toward_corner(0.3, 0.5, true), 0.3);
        assert_eq!(toward_corner(0.5 * (1.0 + 1e-12), 0.5, true), 0.5);
    }
}
