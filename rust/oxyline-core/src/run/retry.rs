//! An error-controlled step's answer to a Newton failure (docs/physics.md §10.5). A steep
//! valve law (a tanh switch of width 1/k) makes the algebraic rows strongly nonlinear near its
//! switch: plain Newton can cycle there (increments of 1/k for ever) whatever the step, as the
//! algebraic rows do not shrink with it. So the same step is first taken again with Newton's
//! natural-monotonicity line search (`integrate::newton::solve`), which stays on for the next
//! `DAMPED_STEPS` accepted steps (the switch takes a few steps to pass); only a failure with
//! the line search shortens the step, and one at the smallest step is the run's error.

use crate::error::Error;

/// Accepted steps the line search stays on for after a Newton failure.
pub(super) const DAMPED_STEPS: u32 = 16;

/// What to do after a Newton failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum OnFailure {
    /// The same step again, with the line search.
    Damp,
    /// A shorter step (the line search was on already).
    Shrink,
    /// The step was the smallest already: the run fails.
    GiveUp,
}

/// The line search's state over the steps.
#[derive(Debug, Default)]
pub(super) struct Retry {
    damped_left: u32,
}

impl Retry {
    /// A Newton failure of a step of `h` (the controller's smallest step `h_min`).
    pub fn failed(&mut self, h: f64, h_min: f64) -> OnFailure {
        let was_damped = self.damped_left > 0;
        self.damped_left = DAMPED_STEPS;
        if !was_damped {
            OnFailure::Damp
        } else if h > h_min {
            OnFailure::Shrink
        } else {
            OnFailure::GiveUp
        }
    }

    /// The line search is on.
    pub fn damping(&self) -> bool {
        self.damped_left > 0
    }

    /// A step was accepted: true when the line search ends with it.
    pub fn accepted(&mut self) -> bool {
        if self.damped_left == 0 {
            return false;
        }
        self.damped_left -= 1;
        self.damped_left == 0
    }
}

/// The run's error after Newton failed with the line search at the smallest step `h_min`
/// (the failure `e` names the time and the unknown of the largest correction).
pub(super) fn given_up(e: Error, h_min: f64, period: f64) -> Error {
    match e {
        Error::Solver { time, message } => Error::solver(
            time,
            format!(
                "{message}, with the line search at the smallest step {h_min:.2e} s ({:.0e} of the period)",
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
    fn a_failure_damps_first_then_shrinks_then_gives_up_at_the_smallest_step() {
        let mut r = Retry::default();
        assert_eq!(r.failed(1e-3, 1e-9), OnFailure::Damp);
        assert_eq!(r.failed(1e-3, 1e-9), OnFailure::Shrink);
        assert_eq!(r.failed(1e-9, 1e-9), OnFailure::GiveUp);
        // the line search stays on for DAMPED_STEPS accepted steps, then ends
        let ends: Vec<bool> = (0..DAMPED_STEPS).map(|_| r.accepted()).collect();
        assert!(ends[..ends.len() - 1].iter().all(|e| !e) && ends[ends.len() - 1]);
        assert!(!r.accepted());
        assert_eq!(r.failed(1e-3, 1e-9), OnFailure::Damp);
    }

    #[test]
    fn giving_up_names_the_smallest_step() {
        let e = given_up(Error::solver(1.5, "Newton did not converge"), 8e-10, 0.8);
        let text = e.to_string();
        assert!(
            text.contains("8.00e-10 s") && text.contains("1e-9 of the period"),
            "{text}"
        );
    }
}
