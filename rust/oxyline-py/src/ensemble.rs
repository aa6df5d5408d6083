//! `oxyline._core.Ensemble`: variants of one network run on rayon threads with the GIL
//! released (see `oxyline_core::ensemble`). Each finished variant is handed to a Python
//! callback on the calling thread, in completion order, while the others keep running.

use crate::errors::{error_kind, to_py};
use crate::reader::de;
use crate::reader::model::vessel_name;
use crate::reader::node::PyNode;
use crate::results::{layout_dict, outcome_dict, put_heart, recorded_columns};
use crate::settings::Shared;
use numpy::IntoPyArray;
use oxyline_core::ensemble::{
    ColumnStats, Member, SpecPatch, StatsFold, column_stats, run_fed, worker_count,
};
use oxyline_core::model::patch::{self, Merged, PatchError, Patched};
use oxyline_core::model::path;
use oxyline_core::model::{BoundarySpec, NetworkSpec, VesselSpec, parse};
use oxyline_core::output::{HeartColumns, HeartRows};
use oxyline_core::{Chunk, Error, Outcome, OutputSink, RunSettings, Selection, Transport};
use pyo3::exceptions::PyKeyboardInterrupt;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyFloat, PyList, PyMapping};
use std::cell::RefCell;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// What a worker hands back: the assembled variant and its selection (None if it could not
/// be assembled) and the run's outcome.
struct Finished {
    member: Option<(Member, Selection)>,
    outcome: Result<Outcome, Error>,
    /// The per-column statistics of the output rows (summary output only).
    stats: Option<ColumnStats>,
    /// The chamber volumes and valve statuses of the rows (see `Output::heart`).
    heart: Option<(HeartColumns, HeartRows)>,
}

/// What the calling thread hands a worker: a variant's patch and its own settings.
struct Input {
    patch: Option<String>,
    /// The patch's elements handed over as Python objects, read on the calling thread.
    handed: Result<Handed, Error>,
    period: f64,
    output_every: f64,
}

/// Vessels (by index) and conditions of a patch read from their canonical dicts (by the
/// core's serde types, `reader::de`) instead of its JSON text.
#[derive(Default)]
struct Handed {
    vessels: Vec<(usize, VesselSpec)>,
    outlets: Vec<(String, BoundarySpec)>,
}

fn handed_over(
    vessels: Option<Bound<'_, PyDict>>,
    outlets: Option<Bound<'_, PyDict>>,
) -> Result<Handed, Error> {
    let mut h = Handed::default();
    for (k, v) in vessels.iter().flat_map(|d| d.iter()) {
        let i: usize = k.extract().map_err(|_| {
            Error::model(
                "variant patch",
                format!("vessel index {k} is not an integer"),
            )
        })?;
        h.vessels.push((i, de::read(&v, || vessel_name(i, &v))?));
    }
    for (k, v) in outlets.iter().flat_map(|d| d.iter()) {
        let node: String = k
            .extract()
            .map_err(|_| Error::model("variant patch", format!("node {k} is not a string")))?;
        let bc = de::read(&v, || format!("boundary condition '{node}'"))?;
        h.outlets.push((node, bc));
    }
    Ok(h)
}

/// The base model with a variant's patch (JSON text and handed-over elements; none of them:
/// the base itself), assembled.
fn member_of(base: &NetworkSpec, patch: Option<&str>, handed: Handed) -> Result<Member, Error> {
    if handed.vessels.is_empty() && handed.outlets.is_empty() {
        return Member::of_patch(base, patch);
    }
    let mut p = match patch {
        Some(json) => SpecPatch::parse(json)?,
        None => SpecPatch::default(),
    };
    p.vessels.extend(handed.vessels);
    p.boundary_conditions.extend(handed.outlets);
    Member::build(&p.apply(base)?)
}

/// The output selection of a run (the names `Network.simulate` takes).
struct Output {
    variables: Option<Vec<String>>,
    vessels: Option<Vec<String>>,
    segments: bool,
    transport: bool,
    /// Summary output: compute [`ColumnStats`] here, on the worker thread.
    summary: bool,
    /// Return the heart outputs (`chamber_volume`, `valve_status`: their unknowns recorded
    /// after the selected columns and taken out of the rows after the run); the rows are
    /// then kept (no streamed summary).
    heart: bool,
    /// Wall time a variant may run: it is stopped at its next progress check after that and
    /// fails with a solver error naming `variant_timeout` (the others run on).
    timeout: Option<Duration>,
}

/// A variant stopped because it ran past `timeout` (not by a cancelled ensemble) fails with
/// an error that says so instead of "interrupted".
fn name_timeout(
    mut outcome: oxyline_core::Result<Outcome>,
    timeout: Option<Duration>,
    started: Instant,
    cancelled: &AtomicBool,
) -> oxyline_core::Result<Outcome> {
    let Some(limit) = timeout else {
        return outcome;
    };
    if started.elapsed() < limit || cancelled.load(Ordering::Relaxed) {
        return outcome;
    }
    let late = |e: &Error| match e {
        Error::Interrupted { time } => Some(Error::solver(
            *time,
            format!(
                "variant_timeout: stopped after {:.3} s of wall time (the limit)",
                limit.as_secs_f64()
            ),
        )),
        _ => None,
    };
    match &mut outcome {
        Ok(out) => {
            if let Some(e) = out.error.as_ref().and_then(late) {
                out.error = Some(e);
            }
        }
        Err(e) => {
            if let Some(n) = late(e) {
                *e = n;
            }
        }
    }
    outcome
}

/// One variant: patch, assemble, select, run; `template` holds the shared settings.
fn run_variant(
    base: &NetworkSpec,
    input: Input,
    template: &RunSettings,
    output: &Output,
    cancelled: &AtomicBool,
) -> Finished {
    let Input { patch, handed, .. } = input;
    let built = handed.and_then(|h| member_of(base, patch.as_deref(), h));
    let member = match built {
        Ok(m) => m,
        Err(e) => {
            return Finished {
                member: None,
                outcome: Err(e),
                stats: None,
                heart: None,
            };
        }
    };
    let sel = Selection::resolve(
        &member.assembled.probes,
        output.variables.as_deref(),
        output.vessels.as_deref(),
        output.segments,
        member.transport.is_some(),
    );
    let sel = match sel {
        Ok(s) => s,
        Err(e) => {
            return Finished {
                member: None,
                outcome: Err(e),
                stats: None,
                heart: None,
            };
        }
    };
    let selected = output.variables.is_some() || output.vessels.is_some();
    let (mut probes, species_columns) = recorded_columns(
        &member.assembled.probes,
        member.transport.as_ref(),
        &sel,
        selected,
        output.segments,
    );
    let mut heart = if output.heart {
        HeartColumns::of(&member.assembled.probes)
    } else {
        HeartColumns::default()
    };
    let heart_at = probes.len();
    probes.extend_from_slice(heart.unknowns());
    let settings = RunSettings {
        probes,
        species_columns,
        ..template.clone()
    };
    // a cancelled ensemble stops its running variants at their next progress check, as
    // does a variant past its variant_timeout
    let started = Instant::now();
    let mut keep_going = |_: f64, _: f64| {
        !cancelled.load(Ordering::Relaxed) && output.timeout.is_none_or(|l| started.elapsed() < l)
    };
    // a summary that the collecting thread reads from the column statistics alone (no
    // species, two or more vessels: see `stats_summary` in ensemble/collect.py) folds them
    // as the rows stream by: no output table per variant
    let species_recorded = output.transport && member.transport.is_some();
    let streamed = output.summary && !species_recorded && !output.heart && sel.vessels.len() >= 2;
    if streamed {
        let mut fold = StatsFold::new(settings.probes.len());
        let mut write = |c: Chunk<'_>| {
            fold.push(c.times, c.data);
            true
        };
        let mut sink = OutputSink {
            rows: STREAM_BYTES / (8 * settings.probes.len().max(1)),
            write: &mut write,
        };
        let outcome = oxyline_core::simulate_to_sink(
            &member.dae,
            None,
            &settings,
            &mut sink,
            &mut keep_going,
        );
        let outcome = name_timeout(outcome, output.timeout, started, cancelled);
        let finished = matches!(&outcome, Ok(out) if out.error.is_none());
        let stats = if finished { fold.finish() } else { None };
        // a finished run without two distinct output times (no time average) needs its rows:
        // it runs again below, as every other output does
        if !finished || stats.is_some() {
            return Finished {
                member: Some((member, sel)),
                outcome,
                stats,
                heart: None,
            };
        }
    }
    let mut species = if species_recorded {
        member.transport.as_ref().map(Transport::new_run)
    } else {
        None
    };
    let outcome = oxyline_core::simulate_with_transport(
        &member.dae,
        species.as_mut(),
        &settings,
        &mut keep_going,
    );
    let mut outcome = name_timeout(outcome, output.timeout, started, cancelled);
    let hearts = match &mut outcome {
        Ok(out) if !heart.is_empty() => Some(out.take_heart(&mut heart, heart_at)),
        _ => None,
    };
    let stats = match &outcome {
        Ok(out) if output.summary && out.error.is_none() => {
            column_stats(&out.times, &out.data, out.n_probes)
        }
        _ => None,
    };
    Finished {
        member: Some((member, sel)),
        outcome,
        stats,
        heart: hearts.map(|rows| (heart, rows)),
    }
}

/// The output rows a streamed summary holds at once (see `run_variant`): whole chunks of the
/// rows a worker has just written, far below the allocator's mmap threshold (128 kB).
const STREAM_BYTES: usize = 32 * 1024;

/// Hand a finished variant to `on_done(index, raw, layout, error_kind, error)`: `raw` is the
/// dict of `Network.simulate` (None if the variant never ran), `layout` its `output_layout`.
fn deliver(py: Python<'_>, on_done: &Py<PyAny>, i: usize, f: Finished) -> PyResult<()> {
    let layout = match &f.member {
        Some((m, sel)) => Some(layout_dict(
            py,
            &m.assembled.probes,
            m.transport.as_ref(),
            sel,
        )?),
        None => None,
    };
    let (raw, error) = match f.outcome {
        Ok(mut out) => {
            let error = out.error.take();
            let raw = outcome_dict(py, out)?;
            if let Some(s) = f.stats {
                let arrays = (
                    s.mean.into_pyarray(py),
                    s.min.into_pyarray(py),
                    s.max.into_pyarray(py),
                );
                raw.set_item("column_stats", arrays)?;
            }
            if let Some((heart, rows)) = f.heart {
                put_heart(&raw, &heart, Some(rows))?;
            }
            (Some(raw), error)
        }
        Err(e) => (None, Some(e)),
    };
    let (kind, message) = match &error {
        Some(e) => (Some(error_kind(e)), Some(e.to_string())),
        None => (None, None),
    };
    on_done.call1(py, (i, raw, layout, kind, message))?;
    Ok(())
}

/// What `feed()` returns for a variant (see `Ensemble.run`).
type Fed<'py> = (
    usize,
    Option<String>,
    f64,
    f64,
    Option<Bound<'py, PyDict>>,
    Option<Bound<'py, PyDict>>,
);

/// A parsed base model whose variants run in parallel.
#[pyclass(frozen, module = "oxyline._core")]
pub struct Ensemble {
    base: Arc<NetworkSpec>,
}

#[oxyline_py_guard::guard]
#[pymethods]
impl Ensemble {
    /// Parse the canonical SI JSON of the base model (once for every variant).
    #[new]
    fn new(py: Python<'_>, model_json: &str) -> PyResult<Self> {
        let json = model_json.to_owned();
        let spec = py.detach(move || parse(&json)).map_err(to_py)?;
        Ok(Ensemble {
            base: Arc::new(spec),
        })
    }

    /// Run variants as `feed()` hands them over: it returns `(i, patch, period,
    /// output_every, vessels, outlets)` for the next variant (`patch` its canonical JSON,
    /// None for the base model; `vessels` {index: canonical vessel dict} and `outlets`
    /// {node: canonical condition dict}: elements of the patch handed over as objects, or
    /// None) or None when there are no more, and is called on this thread while the workers
    /// run (so preparing a variant overlaps the runs). `settings`: the run settings shared
    /// with `Network.simulate` (`settings::KEYS`), the same for every variant. `on_done(i, raw, layout, error_kind, error)` is called
    /// on this thread as each variant finishes; a failed variant has `error_kind` set
    /// ("model", "unstable", "solver", "interrupted") and never stops the others. Returns
    /// False if Ctrl-C stopped the ensemble (the variants finished until then were handed
    /// over, running ones as "interrupted"; the rest were never fed). `summary`: each
    /// finished variant's `raw` also has `column_stats`, the (mean, min, max) arrays of
    /// `oxyline_core::ensemble::column_stats` over its output columns. `heart`: each finished
    /// variant's `raw` also has `chamber_volume` and `valve_status` (see `Output::heart`).
    /// `poll()` (if given) is called on this thread a few times a second: an exception it
    /// raises stops the ensemble as Ctrl-C does (a `cancel` event). `variant_timeout`: the
    /// wall time (s) each variant may run (see `Output::timeout`). `max_memory` (bytes; None:
    /// no limit): each variant's model is checked against it as it is assembled
    /// (`run::memory::check_model`); one above it fails with error_kind "resource".
    #[pyo3(signature = (feed, *, on_done, workers = None, summary = false, heart = false,
        poll = None, variant_timeout = None, max_memory = None, **settings))]
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        py: Python<'_>,
        feed: Py<PyAny>,
        on_done: Py<PyAny>,
        workers: Option<usize>,
        summary: bool,
        heart: bool,
        poll: Option<Py<PyAny>>,
        variant_timeout: Option<f64>,
        max_memory: Option<f64>,
        settings: Option<Bound<'_, PyDict>>,
    ) -> PyResult<bool> {
        let timeout =
            variant_timeout
                .map(|s| {
                    Duration::try_from_secs_f64(s).ok().filter(|d| !d.is_zero()).ok_or_else(|| {
                    crate::errors::ModelError::new_err(format!(
                        "simulate_ensemble: variant_timeout must be a number of seconds > 0, \
                         got {s}"
                    ))
                })
                })
                .transpose()?;
        let shared = Shared::from_kwargs(settings.as_ref())?;
        let workers = worker_count(workers).map_err(to_py)?;
        // the cycles before the last are not recorded: a variant stopped early is reported
        // as failed, without its rows (the recorder's copies were ~5 % of a variant of a
        // small tree); period and output_every are each variant's own
        let template = shared.run_settings(1.0, 1.0, false)?;
        let output = Output {
            variables: shared.variables,
            vessels: shared.vessels,
            segments: shared.segments,
            transport: shared.transport,
            summary,
            heart,
            timeout,
        };
        let base = match max_memory {
            Some(limit) => Arc::new(NetworkSpec {
                max_memory: Some(limit),
                ..(*self.base).clone()
            }),
            None => self.base.clone(),
        };
        let job = |_: usize, input: Input, cancelled: &AtomicBool| {
            let s = RunSettings {
                period: input.period,
                output_every: input.output_every,
                ..template.clone()
            };
            run_variant(&base, input, &s, &output, cancelled)
        };
        py.detach(|| {
            // the first Python error (Ctrl-C, or one raised by `feed` or `on_done`) cancels
            // the ensemble: nothing more is fed and the running variants stop
            let first_error: RefCell<Option<PyErr>> = RefCell::new(None);
            let keep = |r: PyResult<()>| {
                if let Err(e) = r {
                    first_error.borrow_mut().get_or_insert(e);
                }
            };
            let mut next = || -> Option<(usize, Input)> {
                if first_error.borrow().is_some() {
                    return None;
                }
                Python::attach(|py| {
                    let item = feed
                        .call0(py)
                        .and_then(|v| v.extract::<Option<Fed<'_>>>(py));
                    match item {
                        Ok(item) => {
                            item.map(|(i, patch, period, output_every, vessels, outlets)| {
                                let input = Input {
                                    patch,
                                    handed: handed_over(vessels, outlets),
                                    period,
                                    output_every,
                                };
                                (i, input)
                            })
                        }
                        Err(e) => {
                            keep(Err(e));
                            None
                        }
                    }
                })
            };
            let mut done = |item: Option<(usize, Finished)>| -> bool {
                Python::attach(|py| {
                    keep(py.check_signals());
                    if let Some(p) = &poll {
                        keep(p.call0(py).map(drop));
                    }
                    if let Some((i, f)) = item {
                        keep(deliver(py, &on_done, i, f));
                    }
                    first_error.borrow().is_none()
                })
            };
            run_fed(workers, &job, &mut next, &mut done).map_err(to_py)?;
            match first_error.into_inner() {
                None => Ok(true),
                Some(e) if Python::attach(|py| e.is_instance_of::<PyKeyboardInterrupt>(py)) => {
                    Ok(false)
                }
                Some(e) => Err(e),
            }
        })
    }
}

/// A patched value as Python objects: the base model's and the patch's objects themselves
/// (the front end hands over a copy of the patch), rebuilt dicts, scaled floats.
fn merged_to_python<'py>(py: Python<'py>, m: &Merged<PyNode<'py>>) -> PyResult<Bound<'py, PyAny>> {
    Ok(match m {
        Merged::Node(n) => n.0.clone(),
        Merged::Number(x) => PyFloat::new(py, *x).into_any(),
        Merged::Numbers(v) => PyList::new(py, v)?.into_any(),
        Merged::Map(entries) => {
            let d = PyDict::new(py);
            for (k, v) in entries {
                d.set_item(k, merged_to_python(py, v)?)?;
            }
            d.into_any()
        }
    })
}

/// The model dict of a patched model (`oxyline_core::model::patch::Patched`): `source`'s
/// entries, its vessel list and condition dict rebuilt where the patch replaced any, sharing
/// every element it leaves alone.
pub(crate) fn patched_model<'py>(
    py: Python<'py>,
    source: &Bound<'py, PyDict>,
    patched: &Patched<PyNode<'py>>,
) -> PyResult<Bound<'py, PyDict>> {
    let data = source.copy()?;
    if patched.has_vessels {
        let list = PyList::new(
            py,
            source.get_item("vessels")?.map_or(Ok(Vec::new()), |v| {
                v.try_iter()?.collect::<PyResult<Vec<_>>>()
            })?,
        )?;
        for (i, v) in &patched.vessels {
            list.set_item(*i, merged_to_python(py, v)?)?;
        }
        data.set_item("vessels", list)?;
    }
    if patched.has_conditions {
        let bcs = PyDict::new(py);
        if let Some(old) = source.get_item("boundary_conditions")? {
            bcs.update(old.cast::<PyMapping>()?)?;
        }
        for (node, bc) in &patched.conditions {
            bcs.set_item(node, merged_to_python(py, bc)?)?;
        }
        data.set_item("boundary_conditions", bcs)?;
    }
    for (key, value) in &patched.sections {
        data.set_item(key, merged_to_python(py, value)?)?;
    }
    Ok(data)
}

/// What `merge_patch` returns (see there).
type MergeOut<'py> = (
    Option<Bound<'py, PyDict>>,
    Vec<usize>,
    Vec<String>,
    Bound<'py, PyDict>,
    Option<String>,
);

/// `merge_patch(source, patch, variant)`: the variant's native model, `patch` applied to
/// the native model dict `source` by the core (`oxyline_core::model::patch::merge`).
/// Returns `(data, vessels, nodes, paths, refused)`: the patched model dict (sharing every
/// element the patch leaves alone), the indices of the changed vessels, the nodes of the
/// changed conditions, the patch paths (`path = value`) that changed each of them (keys
/// `("vessel", i)` and `("condition", node)`), and None; or, for a value the patch cannot
/// apply (the variant fails), `(None, [], [], {}, message)`. A path that names nothing of
/// the model raises `ModelError` naming the variant and the path.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn merge_patch<'py>(
    py: Python<'py>,
    source: Bound<'py, PyDict>,
    patch: Bound<'py, PyAny>,
    variant: usize,
) -> PyResult<MergeOut<'py>> {
    let base = PyNode(source.clone().into_any());
    let patched = match patch::merge(&base, &PyNode(patch), variant) {
        Ok(p) => p,
        Err(PatchError::Name(e)) => return Err(to_py(e)),
        Err(PatchError::Value(e)) => {
            return Ok((
                None,
                Vec::new(),
                Vec::new(),
                PyDict::new(py),
                Some(e.to_string()),
            ));
        }
    };
    let data = patched_model(py, &source, &patched)?;
    let paths = PyDict::new(py);
    for (i, p) in &patched.vessel_paths {
        paths.set_item(("vessel", *i), p)?;
    }
    for (node, p) in &patched.condition_paths {
        paths.set_item(("condition", node), p)?;
    }
    let vessels = patched.vessels.iter().map(|(i, _)| *i).collect();
    let nodes = patched.conditions.iter().map(|(n, _)| n.clone()).collect();
    Ok((Some(data), vessels, nodes, paths, None))
}

/// `column_keys(parts, dotted, vessels, nodes, variant)`: the keys of a patch table's column
/// (`oxyline_core::model::path::column_keys`, the model's path resolver): `parts` its dot-separated pieces (`dotted`)
/// or the levels of a multi-level column, resolved against the model's vessel names and
/// condition nodes. Raises `ModelError` naming the variant and the column.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn column_keys(
    parts: Vec<String>,
    dotted: bool,
    vessels: Vec<String>,
    nodes: Vec<String>,
    variant: usize,
) -> PyResult<Vec<String>> {
    let names: [(&str, &[String]); 2] = [("vessels", &vessels), ("boundary_conditions", &nodes)];
    path::column_keys(&parts, dotted, &names, variant).map_err(to_py)
}
