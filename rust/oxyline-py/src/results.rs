//! Run results and output layouts as Python dicts and numpy arrays (zero-copy where the core
//! hands over its vectors).

use crate::errors::{error_kind, to_py};
use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use oxyline_core::output::{
    HeartColumns, HeartRows, SEGMENT_VARIABLES, SPECIES_SEGMENT_VARIABLES,
    SPECIES_VESSEL_VARIABLES, VESSEL_VARIABLES,
};
use oxyline_core::{Error, Outcome, Selection, Transport};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// (state, derivative) as numpy arrays.
pub(crate) type ArrayPair<'py> = (
    Bound<'py, numpy::PyArray1<f64>>,
    Bound<'py, numpy::PyArray1<f64>>,
);

/// Species rows for [`put_rows`]: names, rows (flat, row-major) and Σ N at t = 0.
pub(crate) type SpeciesRows<'a, 'py> = (&'a [String], Bound<'py, PyArray1<f64>>, &'a [f64]);

/// Output rows in the layout of `simulate`'s result: `times` (n,) and `data` (n, n_probes) in
/// `d`, and for transport runs a `transport` dict with the species names, their rows
/// `data` (n, species × columns) and `initial_stored`, which is returned for further entries.
pub(crate) fn put_rows<'py>(
    d: &Bound<'py, PyDict>,
    times: Bound<'py, PyArray1<f64>>,
    data: Bound<'py, PyArray1<f64>>,
    n_probes: usize,
    species: Option<SpeciesRows<'_, 'py>>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let nt = PyUntypedArrayMethods::len(&times);
    d.set_item("data", data.reshape([nt, n_probes])?)?;
    d.set_item("times", times)?;
    let Some((names, rows, initial_stored)) = species else {
        return Ok(None);
    };
    let td = PyDict::new(d.py());
    let cols = PyUntypedArrayMethods::len(&rows)
        .checked_div(nt)
        .unwrap_or(0);
    td.set_item("species", names.to_vec())?;
    td.set_item("data", rows.reshape([nt, cols])?)?;
    td.set_item("initial_stored", initial_stored.to_vec())?;
    d.set_item("transport", &td)?;
    Ok(Some(td))
}

/// The recorded flow columns and species columns of an output selection. The default
/// selection (`selected` false, segments on) records every probe and every species column:
/// that path is kept as it was (bit-identical rows).
pub(crate) fn recorded_columns(
    probes: &oxyline_core::Probes,
    transport: Option<&Transport>,
    sel: &Selection,
    selected: bool,
    segments: bool,
) -> (Vec<usize>, Option<Vec<usize>>) {
    if !selected && segments {
        return (probes.all(), None);
    }
    let counts = transport
        .map(|t| t.out_segment_counts())
        .unwrap_or_default();
    (
        sel.flow_columns(probes),
        transport.map(|t| with_tissue_tail(t, sel.species_columns(&counts))),
    )
}

/// A species-column selection plus the tissue columns, which are always recorded whole (the
/// last `tissue_columns` of every block; none without a tissue wall).
pub(crate) fn with_tissue_tail(t: &Transport, mut columns: Vec<usize>) -> Vec<usize> {
    let tail = t.tissue_columns();
    let base = t.columns_per_species() - tail;
    columns.extend(base..base + tail);
    columns
}

/// Layout of the output selection `sel` of a network (see `oxyline_core::output`): selected
/// vessels, their segment counts and positions, the selected variable names, column counts.
pub(crate) fn layout_dict<'py>(
    py: Python<'py>,
    p: &oxyline_core::Probes,
    transport: Option<&Transport>,
    sel: &Selection,
) -> PyResult<Bound<'py, PyDict>> {
    let names = |list: &[&str], idx: &[usize]| -> Vec<String> {
        idx.iter().map(|&i| list[i].to_owned()).collect()
    };
    let d = PyDict::new(py);
    d.set_item(
        "vessels",
        sel.vessels
            .iter()
            .map(|&v| p.vessels[v].clone())
            .collect::<Vec<_>>(),
    )?;
    d.set_item("segment_count", sel.segment_count(&p.segment_count, false))?;
    d.set_item("segment_position", sel.segment_position(p).into_pyarray(py))?;
    d.set_item(
        "vessel_variables",
        names(&VESSEL_VARIABLES, &sel.vessel_variables),
    )?;
    d.set_item(
        "segment_variables",
        names(&SEGMENT_VARIABLES, &sel.segment_variables),
    )?;
    d.set_item("n_columns", sel.flow_columns(p).len())?;
    // the heart outputs (`Result.chamber_volume`, `Result.valve_status`): every chamber and
    // valve, whatever the selection
    let heart = HeartColumns::of(p);
    d.set_item("chambers", heart.chambers)?;
    d.set_item("valves", heart.valves)?;
    if let Some(t) = transport {
        let counts = t.out_segment_counts();
        let td = PyDict::new(py);
        td.set_item("species", t.species_names())?;
        td.set_item(
            "vessel_variables",
            names(&SPECIES_VESSEL_VARIABLES, &sel.species_vessel_variables),
        )?;
        td.set_item(
            "segment_variables",
            names(&SPECIES_SEGMENT_VARIABLES, &sel.species_segment_variables),
        )?;
        td.set_item("segment_count", sel.segment_count(&counts, true))?;
        td.set_item(
            "columns_per_species",
            sel.species_columns(&counts).len() + t.tissue_columns(),
        )?;
        // tissue wall columns: every output vessel and segment of the network (see
        // `with_tissue_tail`)
        td.set_item("tissue_columns", t.tissue_columns())?;
        td.set_item("tissue_vessels", p.vessels.clone())?;
        td.set_item("tissue_segment_count", counts.clone())?;
        d.set_item("transport", td)?;
    }
    Ok(d)
}

/// A run's outcome as the dict `Network.simulate` returns, without its error: `times`, `data`
/// (and `transport`) without a copy, and the run facts.
pub(crate) fn outcome_dict(py: Python<'_>, out: Outcome) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    // the species rows go to numpy without a copy; the other transport facts follow
    let (species_rows, species_state) = match out.transport {
        Some(t) => (
            Some((t.species, t.data.into_pyarray(py), t.initial_stored)),
            Some((t.final_state, t.mean_abs_flow)),
        ),
        None => (None, None),
    };
    let td = put_rows(
        &d,
        out.times.into_pyarray(py),
        out.data.into_pyarray(py),
        out.n_probes,
        species_rows
            .as_ref()
            .map(|(names, rows, init)| (names.as_slice(), rows.clone(), init.as_slice())),
    )?;
    d.set_item("dt", out.dt)?;
    d.set_item("method", out.method)?;
    d.set_item("cycles_run", out.cycles_run)?;
    d.set_item("periodic_error", out.periodic_error)?;
    d.set_item("max_buffered_rows", out.max_buffered_rows)?;
    if let Some(ec) = &out.error_control {
        let est = PyDict::new(py);
        for (kind, v) in oxyline_core::integrate::adaptive::KINDS
            .iter()
            .zip(ec.estimate)
        {
            est.set_item(*kind, v)?;
        }
        d.set_item("error_estimate", est)?;
        d.set_item("steps", ec.steps)?;
        d.set_item("rejected_steps", ec.rejected)?;
        d.set_item("dt_min", ec.dt_min)?;
        d.set_item("dt_max", ec.dt_max)?;
        let events: Vec<(f64, &str, bool)> = ec
            .events
            .iter()
            .map(|e| (e.time, e.valve.as_str(), e.opened))
            .collect();
        d.set_item("valve_events", events)?;
        d.set_item("last_cycle_start", ec.last_cycle_start)?;
        d.set_item(
            "last_cycle_steps",
            ec.last_cycle_steps.clone().into_pyarray(py),
        )?;
        if let Some(f) = &ec.finer {
            d.set_item("finer_last_cycle", finer_dict(py, f, out.n_probes)?)?;
        }
    }
    if let Some(lim) = &out.stability {
        d.set_item("rk4_dt_max", lim.dt_max)?;
        d.set_item("rk4_limiting_element", lim.element.clone())?;
    }
    d.set_item("final_state", out.final_state.into_pyarray(py))?;
    if let (Some(td), Some((final_state, mean_abs_flow))) = (td, species_state) {
        td.set_item("final_state", final_state.into_pyarray(py))?;
        td.set_item("mean_abs_flow", mean_abs_flow.into_pyarray(py))?;
    }
    Ok(d)
}

/// The last cycle at the tighter tolerance (`FinerCycle`): `factor`, `steps`,
/// `rejected_steps`, `times`, `data` (n, n_probes) and, with species, `transport` (n, columns).
fn finer_dict<'py>(
    py: Python<'py>,
    f: &oxyline_core::run::FinerCycle,
    n_probes: usize,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let nt = f.times.len();
    d.set_item("factor", f.factor)?;
    d.set_item("steps", f.steps)?;
    d.set_item("rejected_steps", f.rejected)?;
    d.set_item("times", f.times.clone().into_pyarray(py))?;
    d.set_item(
        "data",
        f.data.clone().into_pyarray(py).reshape([nt, n_probes])?,
    )?;
    if !f.transport.is_empty() {
        let cols = f.transport.len() / nt.max(1);
        let rows = f.transport.clone().into_pyarray(py).reshape([nt, cols])?;
        d.set_item("transport", rows)?;
    }
    Ok(d)
}

/// The run's result dict; a run stopped by a callback's Python error (progress, Ctrl-C, a
/// sink) or by the core keeps its rows and says why in `error`/`error_kind`.
pub(crate) fn finished_run(
    py: Python<'_>,
    outcome: std::result::Result<Outcome, Error>,
    pending: Option<PyErr>,
) -> PyResult<Bound<'_, PyDict>> {
    let mut out = match outcome {
        Ok(out) => out,
        // a callback's Python error (Ctrl-C, a cancel event) that stopped the run before its
        // first step (e.g. during the step estimate) is raised itself, not the core's error
        Err(e) => return Err(pending.unwrap_or_else(|| to_py(e))),
    };
    let error = out.error.take();
    let d = outcome_dict(py, out)?;
    match (pending, error) {
        (Some(e), _) => {
            d.set_item("error_kind", "interrupted")?;
            d.set_item("error", e.value(py).clone())?;
        }
        (None, Some(e)) => {
            d.set_item("error_kind", error_kind(&e))?;
            d.set_item("error", to_py(e).value(py).clone())?;
        }
        (None, None) => {}
    }
    Ok(d)
}

/// Put a run's heart outputs into its rows' dict `d`: `chamber_volume` {chamber: volumes
/// (m³)} and `valve_status` {valve: statuses (int8, 1 open, 0 closed)}, one value per row
/// (see `oxyline_core::output::HeartColumns`). Nothing when `rows` is None.
pub(crate) fn put_heart(
    d: &Bound<'_, PyDict>,
    heart: &HeartColumns,
    rows: Option<HeartRows>,
) -> PyResult<()> {
    let Some(rows) = rows else {
        return Ok(());
    };
    let py = d.py();
    let volume = PyDict::new(py);
    for (name, v) in heart.chambers.iter().zip(rows.volume) {
        volume.set_item(name, v.into_pyarray(py))?;
    }
    let status = PyDict::new(py);
    for (name, s) in heart.valves.iter().zip(rows.status) {
        status.set_item(name, s.into_pyarray(py))?;
    }
    d.set_item("chamber_volume", volume)?;
    d.set_item("valve_status", status)
}

/// `oxyline_core::ensemble::StatsFold` for Python: each column's time mean (trapezoidal rule,
/// numpy's arithmetic), minimum and maximum, folded over output rows as a run hands them over
/// in chunks, without holding them (a large model's summarized run, `oxyline.large_output`).
#[pyclass(module = "oxyline._core")]
pub struct ColumnStatsFold {
    fold: oxyline_core::ensemble::StatsFold,
    n_cols: usize,
}

#[oxyline_py_guard::guard]
#[pymethods]
impl ColumnStatsFold {
    #[new]
    fn new(n_cols: usize) -> Self {
        ColumnStatsFold {
            fold: oxyline_core::ensemble::StatsFold::new(n_cols),
            n_cols,
        }
    }

    /// Add the rows of C-contiguous (time, column) `data` at `times` (after those added).
    fn push(
        &mut self,
        times: numpy::PyReadonlyArray1<'_, f64>,
        data: numpy::PyReadonlyArray2<'_, f64>,
    ) -> PyResult<()> {
        let shape = data.shape();
        if shape[1] != self.n_cols || shape[0] != times.len() {
            return Err(pyo3::exceptions::PyValueError::new_err(format!(
                "ColumnStatsFold.push: data of shape {shape:?}, expected ({}, {})",
                times.len(),
                self.n_cols
            )));
        }
        self.fold.push(times.as_slice()?, data.as_slice()?);
        Ok(())
    }

    /// (mean, min, max) of every column over the rows added; None without two rows over a
    /// positive time span.
    fn finish<'py>(&self, py: Python<'py>) -> Option<ArrayTriple<'py>> {
        self.fold.clone().finish().map(|s| {
            (
                s.mean.into_pyarray(py),
                s.min.into_pyarray(py),
                s.max.into_pyarray(py),
            )
        })
    }
}

/// Three numpy arrays (a column statistic each).
type ArrayTriple<'py> = (
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<f64>>,
);
