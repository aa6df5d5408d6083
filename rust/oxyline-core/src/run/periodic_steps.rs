//! Error control and `until_periodic` (docs/physics.md §10, "Periodic state"). The controller
//! chooses each cycle's steps from the state it meets, so a nearly periodic state meets a
//! slightly different step sequence every cycle: the cycle-to-cycle change of the state then
//! stalls at the integration error (measured: 6e-4 at rtol 1e-3 on an RCR bifurcation after
//! 400 cycles) instead of falling to round-off as with a fixed step, and a run
//! `until_periodic` below it never stops. Once the change is within [`NEAR_PERIODIC`] × rtol,
//! each cycle replays the accepted steps of the one before (still judged by the estimate; a
//! replayed step the estimate refuses hands the rest of the cycle back to the controller), so
//! the cycles become one fixed map, whose periodic state the run approaches as a fixed step's.

/// The cycle-to-cycle change, in units of rtol, from which the steps are replayed.
pub(super) const NEAR_PERIODIC: f64 = 10.0;

/// A replayed step is kept while its scaled error is at most this (the controller's own
/// bound is 1: a state close to the previous cycle's meets close errors).
pub(super) const REPLAY_SLACK: f64 = 2.0;

/// The accepted steps of the cycle being run, and those of the cycle before being replayed.
#[derive(Debug, Default)]
pub(super) struct PeriodicSteps {
    taken: Vec<f64>,
    replay: Vec<f64>,
    next: usize,
    /// Replaying in this cycle (off again after a refused step).
    active: bool,
}

impl PeriodicSteps {
    /// At a cycle's start: replay the last cycle's steps when `near` (the run waits for
    /// periodicity and its last change was within [`NEAR_PERIODIC`] × rtol).
    pub fn start_cycle(&mut self, near: bool) {
        self.active = near && !self.taken.is_empty();
        if self.active {
            std::mem::swap(&mut self.replay, &mut self.taken);
        }
        self.taken.clear();
        self.next = 0;
    }

    /// The replayed step (its last one: the cycle's remainder `rem`), or None.
    pub fn step(&self, rem: f64) -> Option<f64> {
        if !self.active || self.next >= self.replay.len() {
            return None;
        }
        Some(if self.next + 1 == self.replay.len() {
            rem
        } else {
            self.replay[self.next].min(rem)
        })
    }

    /// Whether a replayed step of scaled error `err` is kept; a refused one ends the replay.
    pub fn keeps(&mut self, err: f64) -> bool {
        if self.active && err > REPLAY_SLACK {
            self.active = false;
        }
        self.active
    }

    /// Ends this cycle's replay (a valve event cut a step).
    pub fn stop(&mut self) {
        self.active = false;
    }

    pub fn replaying(&self) -> bool {
        self.active
    }

    /// The accepted steps of the cycle being run (of the last cycle, once the run ended), in
    /// order: the step-size history an error-controlled run reports.
    pub fn taken(&self) -> &[f64] {
        &self.taken
    }

    /// A step of `h` was accepted.
    pub fn accepted(&mut self, h: f64) {
        self.taken.push(h);
        if self.active {
            self.next += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_near_periodic_cycle_replays_the_steps_of_the_one_before() {
        let mut p = PeriodicSteps::default();
        p.start_cycle(true); // nothing taken yet: the controller chooses
        assert_eq!(p.step(1.0), None);
        for h in [0.25, 0.5, 0.25] {
            p.accepted(h);
        }
        p.start_cycle(false); // not near: the controller again
        assert_eq!(p.step(1.0), None);
        for h in [0.5, 0.3, 0.2] {
            p.accepted(h);
        }
        // the cycle's accepted steps, in order: the step-size history a run reports
        assert_eq!(p.taken(), &[0.5, 0.3, 0.2]);
        p.start_cycle(true);
        assert_eq!(p.step(1.0), Some(0.5));
        assert!(p.keeps(1.5));
        p.accepted(0.5);
        assert_eq!(p.step(0.5), Some(0.3));
        p.accepted(0.3);
        // the last step is the cycle's remainder, whatever the rounding of the sum
        assert_eq!(p.step(0.2 + 1e-16), Some(0.2 + 1e-16));
        p.accepted(0.2 + 1e-16);
        // a refused step hands the cycle back to the controller
        p.start_cycle(true);
        assert!(!p.keeps(REPLAY_SLACK * 1.01));
        assert_eq!(p.step(1.0), None);
    }
}
