//! Ensembles: many variants of one network run in parallel on rayon threads.
//!
//! The base model is parsed once ([`NetworkSpec`]); a variant is a [`SpecPatch`] that replaces
//! whole elements of it (vessels by index, boundary conditions by node, the blood or the
//! transport section), written by the front end in the canonical SI form of the elements it
//! changed. Each variant then assembles its own circuit (its R, L, C and closure values are its
//! own), gets its own state and runs exactly as a plain run of the patched model would: the
//! results of a variant do not depend on the thread that runs it or on the other variants.
//!
//! [`run_fed`] is the driver: jobs run on a pool of `workers` rayon threads while the calling
//! thread prepares the next inputs, receives each finished job in completion order (to
//! convert, store or report it) and may cancel the rest.

use crate::assemble::Assembled;
use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::model::transport::TransportSpec;
use crate::model::{BloodSpec, BoundarySpec, NetworkSpec, VesselSpec};
use crate::transport::Transport;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Mutex, PoisonError};
use std::time::Duration;

/// The elements a variant replaces in the base model (canonical SI form).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecPatch {
    /// Replacement vessels by their index in the base model's vessel list.
    #[serde(default)]
    pub vessels: BTreeMap<usize, VesselSpec>,
    /// Replacement boundary conditions by node name.
    #[serde(default)]
    pub boundary_conditions: BTreeMap<String, BoundarySpec>,
    #[serde(default)]
    pub blood: Option<BloodSpec>,
    #[serde(default)]
    pub transport: Option<TransportSpec>,
}

impl SpecPatch {
    /// Read a patch from its canonical JSON.
    pub fn parse(json: &str) -> Result<SpecPatch> {
        serde_json::from_str(json).map_err(|e| Error::model("variant patch", e.to_string()))
    }

    /// The base model with this patch's elements in place. A patch replaces values only: a
    /// vessel keeps its name and its end nodes, and every condition must already exist.
    pub fn apply(&self, base: &NetworkSpec) -> Result<NetworkSpec> {
        let mut spec = base.clone();
        for (&i, v) in &self.vessels {
            let n = spec.vessels.len();
            let slot = spec.vessels.get_mut(i).ok_or_else(|| {
                Error::model(
                    format!("vessel #{i}"),
                    format!("not in the network ({n} vessels)"),
                )
            })?;
            if (&slot.name, &slot.from, &slot.to) != (&v.name, &v.from, &v.to) {
                return Err(Error::model(
                    format!("vessel '{}'", slot.name),
                    format!(
                        "a variant cannot change a vessel's name or end nodes (got '{}' from '{}' to '{}')",
                        v.name, v.from, v.to
                    ),
                ));
            }
            *slot = v.clone();
        }
        for (node, bc) in &self.boundary_conditions {
            let slot = spec.boundary_conditions.get_mut(node).ok_or_else(|| {
                Error::model(
                    format!("boundary condition '{node}'"),
                    "no condition at this node in the base model",
                )
            })?;
            *slot = bc.clone();
        }
        if let Some(b) = &self.blood {
            spec.blood = b.clone();
        }
        if let Some(t) = &self.transport {
            spec.transport = Some(t.clone());
        }
        Ok(spec)
    }
}

/// One assembled variant: its circuit, DAE and (validated, never run) species transport.
pub struct Member {
    pub assembled: Assembled,
    pub dae: Dae,
    pub transport: Option<Transport>,
}

impl Member {
    /// Assemble a model exactly as a single run does (`spec → circuit → DAE → transport`).
    /// The circuit's per-segment geometry (`Circuit::segments`) is read only by the transport
    /// plan's build, which keeps its own compact copy: it is released here (88 B per segment;
    /// the scale targets), the segment table (`Assembled::segments`) stays.
    pub fn build(spec: &NetworkSpec) -> Result<Member> {
        Self::from_assembled(spec.assemble()?, spec.transport.as_ref())
    }

    /// As [`Member::build`], with the spec's vessels and conditions dropped once the circuit
    /// is assembled: the DAE and the transport plan are built from the circuit alone, and the
    /// spec (~100 B per segment of a large tree: names, geometry, one outlet condition per
    /// leaf) would otherwise sit under a large model's load peak.
    pub fn build_owned(mut spec: NetworkSpec) -> Result<Member> {
        let assembled = spec.assemble()?;
        let transport = spec.transport.take();
        drop(spec);
        Self::from_assembled(assembled, transport.as_ref())
    }

    fn from_assembled(
        mut assembled: Assembled,
        transport: Option<&TransportSpec>,
    ) -> Result<Member> {
        // the segments' geometry is read by the transport plan alone, which takes it over
        // (a flow-only network drops it before its matrices are built)
        if transport.is_none() {
            assembled.circuit.segments = Vec::new();
        }
        let dae = assembled.circuit.assemble()?;
        let transport = match transport {
            Some(t) => Some(Transport::build_taking_segments(
                t,
                &mut assembled.circuit,
                &dae,
                &assembled.probes,
            )?),
            None => None,
        };
        Ok(Member {
            assembled,
            dae,
            transport,
        })
    }

    /// The base model with `patch` (canonical JSON; None: the base itself) applied, assembled.
    pub fn of_patch(base: &NetworkSpec, patch: Option<&str>) -> Result<Member> {
        match patch {
            Some(json) => Member::build(&SpecPatch::parse(json)?.apply(base)?),
            None => Member::build(base),
        }
    }
}

/// Per-column statistics over the output rows of a run: what `oxyline.Result.summary()`
/// computes per vessel (docs/ensembles.md), here on the worker thread so that the thread
/// collecting the variants does no per-variant array work.
#[derive(Debug, Clone, PartialEq)]
pub struct ColumnStats {
    /// Time average by the trapezoidal rule over [t_first, t_last].
    pub mean: Vec<f64>,
    pub min: Vec<f64>,
    pub max: Vec<f64>,
}

/// [`ColumnStats`] of row-major (time, column) `data` sampled at `times`, with numpy's
/// arithmetic: `np.trapezoid(a, t, axis=0) / (t[-1] - t[0])` on a (time, k ≥ 2 columns) array
/// adds the terms `(t[i+1] - t[i]) * (a[i+1] + a[i]) / 2.0` of a column one after the other in
/// time order (numpy reduces a non-innermost axis element by element, starting from the first
/// term), and min/max propagate NaN. A single column is summed pairwise by numpy instead, so
/// the caller uses these values only for arrays of two or more columns. None without two
/// distinct times (the summary then takes plain means).
pub fn column_stats(times: &[f64], data: &[f64], n_cols: usize) -> Option<ColumnStats> {
    if data.len() != times.len() * n_cols {
        return None;
    }
    let mut fold = StatsFold::new(n_cols);
    fold.push(times, data);
    fold.finish()
}

/// [`column_stats`] folded over the output rows as a run streams them (an
/// [`crate::OutputSink`]'s chunks, in time order): the same terms added in the same order, so
/// the same bits whatever the chunk size, without holding the rows. An ensemble's summary thus
/// needs no output table per variant (the table of a 31-vessel tree's last cycle is ~1 MB: one
/// large allocation and its page faults per variant, which a Dask worker's
/// `MALLOC_TRIM_THRESHOLD_` turns into fresh pages every time).
#[derive(Debug, Clone)]
pub struct StatsFold {
    rows: usize,
    t_first: f64,
    t_prev: f64,
    prev: Vec<f64>,
    sum: Vec<f64>,
    min: Vec<f64>,
    max: Vec<f64>,
}

impl StatsFold {
    pub fn new(n_cols: usize) -> StatsFold {
        StatsFold {
            rows: 0,
            t_first: f64::NAN,
            t_prev: f64::NAN,
            prev: vec![0.0; n_cols],
            sum: vec![0.0; n_cols],
            min: vec![0.0; n_cols],
            max: vec![0.0; n_cols],
        }
    }

    /// Add the rows of row-major (time, column) `data` at `times` (the rows after those
    /// already added); rows beyond `times` are ignored.
    pub fn push(&mut self, times: &[f64], data: &[f64]) {
        let n = self.prev.len();
        for (&t, row) in times.iter().zip(data.chunks_exact(n.max(1))) {
            self.push_row(t, &row[..n]);
        }
    }

    fn push_row(&mut self, t: f64, b: &[f64]) {
        if self.rows == 0 {
            self.t_first = t;
            self.min.copy_from_slice(b);
            self.max.copy_from_slice(b);
        } else {
            // the inner loops are branch-free over the columns (selects, so they vectorise:
            // ~5 % of a worker's time was this with a branch per element), each column's
            // arithmetic that of numpy
            let (d, a) = (t - self.t_prev, &self.prev);
            if self.rows == 1 {
                // the first term, as numpy starts the reduction from it (not from 0.0 + term)
                for ((s, &x), &y) in self.sum.iter_mut().zip(b).zip(a) {
                    *s = d * (x + y) / 2.0;
                }
            } else {
                for ((s, &x), &y) in self.sum.iter_mut().zip(b).zip(a) {
                    *s += d * (x + y) / 2.0;
                }
            }
            for ((lo, hi), &x) in self.min.iter_mut().zip(self.max.iter_mut()).zip(b) {
                // NaN propagates: a NaN bound stays, a NaN value replaces the bound
                *lo = if !lo.is_nan() && (x.is_nan() || x < *lo) {
                    x
                } else {
                    *lo
                };
                *hi = if !hi.is_nan() && (x.is_nan() || x > *hi) {
                    x
                } else {
                    *hi
                };
            }
        }
        self.prev.copy_from_slice(b);
        self.t_prev = t;
        self.rows += 1;
    }

    /// The statistics of the rows added, or None without two rows and a positive time span.
    pub fn finish(self) -> Option<ColumnStats> {
        let span = self.t_prev - self.t_first;
        if self.rows < 2 || span.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        Some(ColumnStats {
            mean: self.sum.into_iter().map(|s| s / span).collect(),
            min: self.min,
            max: self.max,
        })
    }
}

/// The number of threads of an ensemble: `workers` if given, else the environment variable
/// `OXYLINE_NUM_THREADS`, else every core.
pub fn worker_count(workers: Option<usize>) -> Result<usize> {
    let n = match workers {
        Some(n) => n,
        None => match std::env::var("OXYLINE_NUM_THREADS") {
            Ok(s) => s.trim().parse().map_err(|_| {
                Error::model(
                    "OXYLINE_NUM_THREADS",
                    format!("must be an integer >= 1, got '{s}'"),
                )
            })?,
            Err(_) => std::thread::available_parallelism().map_or(1, |n| n.get()),
        },
    };
    if n == 0 {
        return Err(Error::model("ensemble", "workers must be >= 1, got 0"));
    }
    Ok(n)
}

/// How often the calling thread wakes up without a finished job (to check for Ctrl-C).
const POLL: Duration = Duration::from_millis(100);

/// Inputs queued ahead of each worker: enough that no worker waits for the calling thread,
/// few enough that a cancellation skips the rest at once.
const AHEAD_PER_WORKER: usize = 2;

/// Run jobs on a pool of `workers` threads, fed by the calling thread. The calling thread
/// takes inputs from `feed` (None: no more) as the workers need them, so that preparing an
/// input overlaps the jobs that run; it calls `done(Some((i, out)))` as each job finishes
/// (completion order) and `done(None)` whenever it has waited [`POLL`] without one. `done`
/// returning false cancels: nothing more is fed, queued jobs are skipped (they return
/// nothing) and running ones see `cancelled` set. With one worker the jobs run in the order
/// fed. Returns once every started job has finished and been handed to `done`.
pub fn run_fed<I: Send, T: Send>(
    workers: usize,
    job: &(dyn Fn(usize, I, &AtomicBool) -> T + Sync),
    feed: &mut dyn FnMut() -> Option<(usize, I)>,
    done: &mut dyn FnMut(Option<(usize, T)>) -> bool,
) -> Result<()> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .thread_name(|i| format!("oxyline-ensemble-{i}"))
        .build()
        .map_err(|e| Error::model("ensemble", format!("cannot start worker threads: {e}")))?;
    let cancelled = AtomicBool::new(false);
    let (input_tx, input_rx) = mpsc::channel::<(usize, I)>();
    let input_rx = Mutex::new(input_rx);
    let (output_tx, output_rx) = mpsc::channel::<(usize, T)>();
    std::thread::scope(|s| {
        let (cancelled, input_rx) = (&cancelled, &input_rx);
        s.spawn(move || {
            pool.scope(|scope| {
                for _ in 0..workers {
                    let tx = output_tx.clone();
                    scope.spawn(move |_| work(job, input_rx, &tx, cancelled));
                }
            });
            drop(output_tx); // the last sender: the calling thread's loop ends with the workers
        });
        let mut input_tx = Some(input_tx);
        let mut in_flight = 0usize;
        loop {
            while in_flight < AHEAD_PER_WORKER * workers {
                let Some(tx) = &input_tx else { break };
                match feed() {
                    // the workers only stop receiving once the sender is dropped
                    Some(item) => {
                        let _ = tx.send(item);
                        in_flight += 1;
                    }
                    None => input_tx = None, // no more: the workers end once the queue is empty
                }
            }
            let next = match output_rx.recv_timeout(POLL) {
                Ok(item) => {
                    in_flight -= 1;
                    Some(item)
                }
                Err(mpsc::RecvTimeoutError::Timeout) => None,
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            };
            if !done(next) {
                cancelled.store(true, Ordering::Relaxed);
                input_tx = None;
            }
        }
    });
    Ok(())
}

/// One worker: run the queued inputs until the queue is closed and empty (skipping them once
/// the ensemble is cancelled).
fn work<I, T>(
    job: &(dyn Fn(usize, I, &AtomicBool) -> T + Sync),
    inputs: &Mutex<mpsc::Receiver<(usize, I)>>,
    outputs: &mpsc::Sender<(usize, T)>,
    cancelled: &AtomicBool,
) {
    loop {
        // a worker that panicked while holding the lock left the queue itself intact
        let next = inputs.lock().unwrap_or_else(PoisonError::into_inner).recv();
        let Ok((i, input)) = next else { return };
        if !cancelled.load(Ordering::Relaxed) {
            // the receiver lives until every sender is gone
            let _ = outputs.send((i, job(i, input, cancelled)));
        }
    }
}

#[cfg(test)]
mod tests;
