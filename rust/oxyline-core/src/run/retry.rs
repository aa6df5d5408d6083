//! An error-controlled step's answer to a Newton failure (docs/physics.md §10.5). A steep
//! valve law (a tanh switch of width 1/k) makes the algebraic rows strongly nonlinear near its
//! switch: plain Newton can cycle there (increments of 1/k for ever) whatever the step, as the
//! algebraic rows do not shrink with it. So the same step is first taken again with Newton's
//! natural-monotonicity line search (`integrate::newton::solve`), which stays on for the next
//! `DAMPED_STEPS` accepted steps (the switch takes a few steps to pass); only a failure with
//! the line search shortens the step. A failure that persists down to the smallest step does
//! not yield to shorter steps at all: the algebraic state has no solution near the step's
//! start (its valve rows pass a fold, where the branch of solutions it follows ends), so the
//! solution jumps, and the step leaps over it: steps growing `LEAP_GROWTH`× from twice the one
//! that failed first, the first that converges accepted whatever its error estimate (the
//! error control starts again after it, as after a valve event). A leap beyond the largest
//! step is the run's error.

use crate::error::Error;

/// Accepted steps the line search stays on for after a Newton failure.
pub(super) const DAMPED_STEPS: u32 = 16;

/// Growth of the leap's step from one failed try to the next.
pub(super) const LEAP_GROWTH: f64 = 4.0;

/// What to do after a Newton failure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum OnFailure {
    /// The same step again, with the line search.
    Damp,
    /// A shorter step (the line search was on already).
    Shrink,
    /// Shorter steps failed down to the smallest: a step of this length, accepted as it comes.
    Leap(f64),
    /// The leap grew beyond the largest step: the run fails.
    GiveUp,
}

/// The line search's state over the steps.
#[derive(Debug, Default)]
pub(super) struct Retry {
    damped_left: u32,
    /// The step of the first failure of this sequence.
    first: f64,
    /// The leap's current step (None: not leaping).
    leap: Option<f64>,
}

impl Retry {
    /// A Newton failure of a step of `h` (the controller's smallest and largest steps
    /// `h_min`, `h_max`).
    pub fn failed(&mut self, h: f64, (h_min, h_max): (f64, f64)) -> OnFailure {
        let was_damped = self.damped_left > 0;
        self.damped_left = DAMPED_STEPS;
        if !was_damped {
            self.first = h;
            return OnFailure::Damp;
        }
        if h > h_min && self.leap.is_none() {
            return OnFailure::Shrink;
        }
        let next = match self.leap {
            Some(l) => LEAP_GROWTH * l,
            None => (2.0 * self.first).max(LEAP_GROWTH * h_min),
        };
        if next > h_max * (1.0 + 1e-12) {
            self.leap = None;
            return OnFailure::GiveUp;
        }
        self.leap = Some(next);
        OnFailure::Leap(next)
    }

    /// A leap's step is being tried (its error is not judged).
    pub fn leaping(&self) -> bool {
        self.leap.is_some()
    }

    /// The line search is on.
    pub fn damping(&self) -> bool {
        self.damped_left > 0
    }

    /// A step was accepted: true when the line search ends with it.
    pub fn accepted(&mut self) -> bool {
        self.leap = None;
        if self.damped_left == 0 {
            return false;
        }
        self.damped_left -= 1;
        self.damped_left == 0
    }
}

/// The run's error after Newton failed with the line search at every step from the smallest
/// `h_min` to the largest `h_max` (the failure `e` names the time and the unknown of the
/// largest correction).
pub(super) fn given_up(e: Error, (h_min, h_max): (f64, f64), period: f64) -> Error {
    match e {
        Error::Solver { time, message } => Error::solver(
            time,
            format!(
                "{message}, with the line search at every step from the smallest {h_min:.2e} s \
                 ({:.0e} of the period) to the largest {h_max:.2e} s",
                h_min / period
            ),
        ),
        e => e,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failure_damps_then_shrinks_then_leaps_then_gives_up_beyond_the_largest_step() {
        let mut r = Retry::default();
        let range = (1e-9, 1e-2);
        assert_eq!(r.failed(1e-3, range), OnFailure::Damp);
        assert_eq!(r.failed(1e-3, range), OnFailure::Shrink);
        // at the smallest step: twice the first failed step, then 4× per failure
        assert_eq!(r.failed(1e-9, range), OnFailure::Leap(2e-3));
        assert!(r.leaping());
        assert_eq!(r.failed(2e-3, range), OnFailure::Leap(8e-3));
        assert_eq!(r.failed(8e-3, range), OnFailure::GiveUp);
        assert_eq!(r.failed(1e-3, range), OnFailure::Shrink);
        assert_eq!(r.failed(1e-9, range), OnFailure::Leap(2e-3));
        // the leap's step converged: accepted, and the line search stays on for DAMPED_STEPS
        // accepted steps, then ends
        let ends: Vec<bool> = (0..DAMPED_STEPS).map(|_| r.accepted()).collect();
        assert!(!r.leaping());
        assert!(ends[..ends.len() - 1].iter().all(|e| !e) && ends[ends.len() - 1]);
        assert!(!r.accepted());
        assert_eq!(r.failed(1e-3, range), OnFailure::Damp);
    }

    #[test]
    fn giving_up_names_the_steps_tried() {
        let e = given_up(
            Error::solver(1.5, "Newton did not converge"),
            (8e-10, 2.5e-2),
            0.8,
        );
        let text = e.to_string();
        assert!(
            text.contains("8.00e-10 s") && text.contains("1e-9 of the period"),
            "{text}"
        );
        assert!(text.contains("2.50e-2 s"), "{text}");
    }
}
