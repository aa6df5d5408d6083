//! Ensembles: many variants of one network run in parallel on rayon threads.
//!
//! The base model is parsed once ([`NetworkSpec`]); a variant is a [`SpecPatch`] that replaces
//! whole elements of it (vessels by index, boundary conditions by node, the blood or the
//! transport section), written by the front end in the canonical SI form of the elements it
//! changed. Each variant then assembles its own circuit (its R, L, C and closure values are its
//! own), gets its own state and runs exactly as a plain run of the patched model would: the
//! results of a variant do not depend on the thread that runs it or on the other variants.
//!
//! [`run_parallel`] is the driver: jobs run on a pool of `workers` threads while the calling
//! thread receives each finished job in completion order (to convert, store or report it) and
//! may cancel the rest.

use crate::assemble::Assembled;
use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::spec::transport::TransportSpec;
use crate::spec::{BloodSpec, BoundarySpec, NetworkSpec, VesselSpec};
use crate::transport::Transport;
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
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
    pub fn build(spec: &NetworkSpec) -> Result<Member> {
        let assembled = spec.assemble()?;
        let dae = assembled.circuit.assemble()?;
        let transport = match &spec.transport {
            Some(t) => Some(Transport::build(
                t,
                &assembled.circuit,
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

/// Run `job(i, cancelled)` for every `i` in `0..n` on a pool of `workers` threads. The calling
/// thread calls `done(Some((i, out)))` as each job finishes (completion order) and `done(None)`
/// whenever it has waited [`POLL`] without one; `done` returning false cancels the ensemble:
/// jobs not started are skipped (they return nothing) and running ones see `cancelled` set.
/// Returns once every started job has finished and been handed to `done`.
pub fn run_parallel<T: Send>(
    n: usize,
    workers: usize,
    job: &(dyn Fn(usize, &AtomicBool) -> T + Sync),
    done: &mut dyn FnMut(Option<(usize, T)>) -> bool,
) -> Result<()> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(workers)
        .thread_name(|i| format!("oxyline-ensemble-{i}"))
        .build()
        .map_err(|e| Error::model("ensemble", format!("cannot start worker threads: {e}")))?;
    let cancelled = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel::<(usize, T)>();
    std::thread::scope(|s| {
        let cancelled = &cancelled;
        s.spawn(move || {
            pool.install(|| {
                // one variant per task: variants differ in cost, idle threads steal the rest
                (0..n)
                    .into_par_iter()
                    .with_max_len(1)
                    .for_each_with(tx, |tx, i| {
                        if !cancelled.load(Ordering::Relaxed) {
                            // the receiver only goes away once every sender is dropped
                            let _ = tx.send((i, job(i, cancelled)));
                        }
                    });
            });
        });
        loop {
            let next = match rx.recv_timeout(POLL) {
                Ok(item) => Some(item),
                Err(mpsc::RecvTimeoutError::Timeout) => None,
                Err(mpsc::RecvTimeoutError::Disconnected) => break,
            };
            if !done(next) {
                cancelled.store(true, Ordering::Relaxed);
            }
        }
    });
    Ok(())
}

#[cfg(test)]
mod tests;
