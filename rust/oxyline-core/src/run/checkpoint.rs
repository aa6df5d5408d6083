//! Checkpoints: at the end of a cycle the run hands a [`Snapshot`] of
//! everything it needs to continue — the flow state (y, ẏ), what the integrator and the
//! transport carry between steps, the species amounts, the periodicity references, the
//! cycle-mean |Q| of a two-pass run and the output recorded so far — to a caller's `save`.
//! A run started from a snapshot continues exactly as the uninterrupted run would: same
//! steps, same arithmetic, bit-identical output. Writing the snapshot to a file (atomically,
//! versioned) is the caller's part; the file's metadata schema is [`meta`]'s.

pub mod meta;

use std::time::{Duration, Instant};

/// Layout version of [`Snapshot`]; a file of another version is refused.
pub const CHECKPOINT_VERSION: u32 = 2;

/// The state of a run at the end of cycle `cycles_run`.
#[derive(Debug, Clone, Default)]
pub struct Snapshot {
    pub cycles_run: usize,
    /// Steps taken since t = 0 (the time is `steps · dt`).
    pub steps: usize,
    /// The step of the run that wrote it (a resumed run must plan the same one).
    pub dt: f64,
    pub periodic_error: f64,
    pub y: Vec<f64>,
    pub yd: Vec<f64>,
    /// y at the end of the cycle before (periodicity reference).
    pub prev_cycle_end: Vec<f64>,
    /// See `Integrator::carried`.
    pub integrator: Vec<f64>,
    /// Species amounts and accumulators (empty for flow-only runs).
    pub z: Vec<f64>,
    pub prev_cycle_z: Vec<f64>,
    /// See `Transport::carried`.
    pub transport: Vec<f64>,
    pub initial_stored: Vec<f64>,
    /// The first pass's cycle-mean |Q| (empty when none was needed).
    pub mean_abs_flow: Vec<f64>,
    /// Output recorded so far, in the layout of `Outcome`.
    pub times: Vec<f64>,
    pub data: Vec<f64>,
    pub transport_rows: Vec<f64>,
    /// See `StepEnds::carried` (empty without index-2 unknowns).
    pub step_ends: Vec<f64>,
}

/// When to write a checkpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Every {
    /// At the end of every n-th cycle.
    Cycles(usize),
    /// At the end of the first cycle at least this long (wall time) after the start or the
    /// last checkpoint.
    Wall(Duration),
}

/// Checkpointing of a run: when, where to (`save`; false stops the run as an interruption),
/// and optionally the snapshot to start from.
pub struct Checkpoints<'a> {
    pub every: Every,
    pub save: &'a mut dyn FnMut(&Snapshot) -> bool,
    pub resume: Option<Snapshot>,
    /// Set by the two-pass driver for the snapshots.
    pub(super) mean_abs_flow: Vec<f64>,
    last: Instant,
}

impl<'a> Checkpoints<'a> {
    pub fn new(
        every: Every,
        save: &'a mut dyn FnMut(&Snapshot) -> bool,
        resume: Option<Snapshot>,
    ) -> Self {
        Checkpoints {
            every,
            save,
            resume,
            mean_abs_flow: Vec::new(),
            last: Instant::now(),
        }
    }

    /// Is a checkpoint due at the end of cycle `cycles_run`?
    pub(super) fn due(&self, cycles_run: usize) -> bool {
        match self.every {
            Every::Cycles(n) => n > 0 && cycles_run % n == 0,
            Every::Wall(d) => self.last.elapsed() >= d,
        }
    }

    /// Hand `snap` to `save`; false if it stopped the run.
    pub(super) fn save(&mut self, snap: &Snapshot) -> bool {
        let ok = (self.save)(snap);
        self.last = Instant::now();
        ok
    }
}
