//! PyO3 binding of oxyline-core (module `oxyline._core`). Only glue lives here: argument
//! conversion, error mapping, GIL release with periodic Ctrl-C checks, zero-copy results.

use numpy::{IntoPyArray, PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use oxyline_core::output::{
    BALANCE_VARIABLES, SEGMENT_VARIABLES, SPECIES_SEGMENT_VARIABLES, SPECIES_VESSEL_VARIABLES,
    TISSUE_BALANCE_VARIABLES, TISSUE_SEGMENT_VARIABLES, TISSUE_VESSEL_VARIABLES, VESSEL_VARIABLES,
};
use oxyline_core::run::checkpoint::{Checkpoints, Every, Snapshot};
use oxyline_core::spec::parse;
use oxyline_core::{
    Assembled, Chunk, Dae, Error, Method, Outcome, OutputSink, Selection, Start, Transport,
};
use pyo3::exceptions::{PyKeyboardInterrupt, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

mod extract;
mod native;
use std::cell::Cell;
use std::sync::Arc;
use std::time::{Duration, Instant};

mod checkpoint;
mod closed_loop;
mod ensemble;
mod settings;

// the schema names the columns `Transport::observe` writes, one name per column
const _: () = assert!(oxyline_core::transport::VESSEL_COLUMNS == SPECIES_VESSEL_VARIABLES.len());
const _: () = assert!(oxyline_core::transport::SEGMENT_COLUMNS == SPECIES_SEGMENT_VARIABLES.len());
const _: () = assert!(oxyline_core::transport::BALANCE_COLUMNS == BALANCE_VARIABLES.len());
const _: () = assert!(
    oxyline_core::transport::TISSUE_VESSEL_COLUMNS == TISSUE_VESSEL_VARIABLES.len()
        && oxyline_core::transport::TISSUE_SEGMENT_COLUMNS == TISSUE_SEGMENT_VARIABLES.len()
        && oxyline_core::transport::TISSUE_BALANCE_COLUMNS == TISSUE_BALANCE_VARIABLES.len()
);

pyo3::create_exception!(
    oxyline,
    ModelError,
    PyValueError,
    "The network model or its settings are invalid."
);
pyo3::create_exception!(
    oxyline,
    UnstableTimeStep,
    ModelError,
    "The requested explicit time step is unstable."
);
pyo3::create_exception!(
    oxyline,
    ResourceError,
    ModelError,
    "The model or the requested output needs more memory than allowed (max_memory) or available."
);
pyo3::create_exception!(
    oxyline,
    SolverError,
    PyRuntimeError,
    "Time integration failed."
);

fn to_py(e: Error) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Model { .. } => ModelError::new_err(msg),
        Error::Unstable { .. } => UnstableTimeStep::new_err(msg),
        Error::Solver { .. } => SolverError::new_err(msg),
        Error::Interrupted { .. } => PyKeyboardInterrupt::new_err(msg),
        Error::Resource { .. } => ResourceError::new_err(msg),
    }
}

fn error_kind(e: &Error) -> &'static str {
    match e {
        Error::Model { .. } => "model",
        Error::Unstable { .. } => "unstable",
        Error::Solver { .. } => "solver",
        Error::Interrupted { .. } => "interrupted",
        Error::Resource { .. } => "resource",
    }
}

/// (state, derivative) as numpy arrays.
type ArrayPair<'py> = (
    Bound<'py, numpy::PyArray1<f64>>,
    Bound<'py, numpy::PyArray1<f64>>,
);

/// Species rows for [`put_rows`]: names, rows (flat, row-major) and Σ N at t = 0.
type SpeciesRows<'a, 'py> = (&'a [String], Bound<'py, PyArray1<f64>>, &'a [f64]);

/// Output rows in the layout of `simulate`'s result: `times` (n,) and `data` (n, n_probes) in
/// `d`, and for transport runs a `transport` dict with the species names, their rows
/// `data` (n, species × columns) and `initial_stored`, which is returned for further entries.
fn put_rows<'py>(
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

fn parse_method(method: &str, rho_infty: f64) -> PyResult<Method> {
    Ok(match method {
        "rk4" => Method::Rk4,
        "generalized-alpha" => Method::GeneralizedAlpha { rho_inf: rho_infty },
        "auto" => Method::Auto { rho_inf: rho_infty },
        other => {
            return Err(ModelError::new_err(format!(
                "simulation: unknown method '{other}' (expected rk4, generalized-alpha or auto)"
            )));
        }
    })
}

fn parse_start(start: &str, rho_infty: f64) -> PyResult<Start> {
    Ok(match start {
        "steady" => Start::Steady,
        "periodic" => Start::Periodic,
        "svzerod-steady" => Start::SvZeroDSteady { rho_inf: rho_infty },
        "zero" => Start::Zero,
        "svzerod-zero" => Start::SvZeroDZero,
        other => {
            return Err(ModelError::new_err(format!(
                "simulation: unknown start '{other}' (expected steady, periodic, zero, svzerod-steady or svzerod-zero)"
            )));
        }
    })
}

/// The recorded flow columns and species columns of an output selection. The default
/// selection (`selected` false, segments on) records every probe and every species column:
/// that path is kept as it was (bit-identical rows).
fn recorded_columns(
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
fn with_tissue_tail(t: &Transport, mut columns: Vec<usize>) -> Vec<usize> {
    let tail = t.tissue_columns();
    let base = t.columns_per_species() - tail;
    columns.extend(base..base + tail);
    columns
}

/// Layout of the output selection `sel` of a network (see `oxyline_core::output`): selected
/// vessels, their segment counts and positions, the selected variable names, column counts.
fn layout_dict<'py>(
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
fn outcome_dict(py: Python<'_>, out: Outcome) -> PyResult<Bound<'_, PyDict>> {
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

/// An assembled network: built once from the canonical SI JSON model, run many times.
#[pyclass(frozen, module = "oxyline._core")]
struct Network {
    inner: Arc<(Assembled, Dae)>,
    /// Validated species transport, never run: each run takes `new_run` (the shared plan and a
    /// fresh state); None for flow-only models.
    transport: Option<Arc<Transport>>,
}

impl Network {
    fn selection(
        &self,
        variables: Option<Vec<String>>,
        vessels: Option<Vec<String>>,
        segments: bool,
    ) -> PyResult<Selection> {
        Selection::resolve(
            &self.inner.0.probes,
            variables.as_deref(),
            vessels.as_deref(),
            segments,
            self.transport.is_some(),
        )
        .map_err(to_py)
    }
}

#[pymethods]
impl Network {
    /// `vessels` (the canonical vessel dicts) and `outlets` (node -> canonical resistance or
    /// RCR condition with a constant pressure) may be handed over as Python objects instead of
    /// inside `model_json` (see `extract`): a large tree then needs no text for its bulk.
    /// `parts`: the vessels and outlets read from a native model (`native::NativeParts`),
    /// moved into the spec in their order (before `vessels`, `outlets`).
    #[new]
    #[pyo3(signature = (model_json, vessels = None, outlets = None, parts = None))]
    fn new(
        py: Python<'_>,
        model_json: &str,
        vessels: Option<Bound<'_, PyList>>,
        outlets: Option<Bound<'_, PyDict>>,
        parts: Option<Bound<'_, native::NativeParts>>,
    ) -> PyResult<Self> {
        let (mut native_vessels, mut bcs) = match parts {
            Some(p) => p.borrow_mut().take().map_err(to_py)?,
            None => (Vec::new(), Vec::new()),
        };
        let vessels = vessels
            .map(|v| extract::vessels(&v))
            .transpose()
            .map_err(to_py)?;
        if let Some(v) = vessels {
            native_vessels.extend(v);
        }
        let vessels = Some(native_vessels).filter(|v| !v.is_empty());
        for (node, bc) in outlets.iter().flat_map(|d| d.iter()) {
            let node: String = node.extract()?;
            let spec = extract::outlet(&node, &bc).map_err(to_py)?;
            bcs.push((node, spec));
        }
        // the text is parsed where Python holds it (no copy); the spec is dropped once the
        // circuit and the transport plan are built from it
        let built = py.detach(
            move || -> Result<((Assembled, Dae), Option<Transport>), Error> {
                let mut spec = parse(model_json)?;
                match vessels {
                    // moved, not copied: ~700 B per vessel
                    Some(v) if spec.vessels.is_empty() => spec.vessels = v,
                    Some(v) => spec.vessels.extend(v),
                    None => {}
                }
                for (node, bc) in bcs {
                    if spec.boundary_conditions.insert(node.clone(), bc).is_some() {
                        return Err(Error::model(
                            format!("boundary condition '{node}'"),
                            "given twice",
                        ));
                    }
                }
                // the same assembly as every ensemble member: spec → circuit → DAE → transport
                let m = oxyline_core::ensemble::Member::build(&spec)?;
                Ok(((m.assembled, m.dae), m.transport))
            },
        );
        let (built, transport) = built.map_err(to_py)?;
        Ok(Network {
            inner: Arc::new(built),
            transport: transport.map(Arc::new),
        })
    }

    /// Counts and totals for `oxyline validate`.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (a, dae) = &*self.inner;
        let s = &a.summary;
        let d = PyDict::new(py);
        d.set_item("vessels", s.vessels)?;
        d.set_item("segments", s.segments)?;
        d.set_item("nodes", s.nodes)?;
        d.set_item("junctions", s.junctions)?;
        d.set_item("inlets", s.inlets)?;
        d.set_item("outlets", s.outlets)?;
        d.set_item("total_compliance", s.total_compliance)?;
        d.set_item("total_volume", s.total_volume)?;
        d.set_item("period", s.period)?;
        d.set_item("unknowns", dae.n)?;
        d.set_item(
            "differential_unknowns",
            dae.e.iter().filter(|e| **e > 0.0).count(),
        )?;
        Ok(d)
    }

    /// Output layout: vessel names, segment counts and positions.
    fn layout<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = &self.inner.0.probes;
        let d = PyDict::new(py);
        d.set_item("vessels", p.vessels.clone())?;
        d.set_item("segment_count", p.segment_count.clone())?;
        d.set_item(
            "segment_position",
            p.segment_position.clone().into_pyarray(py),
        )?;
        d.set_item("n_vessel_columns", p.vessel_unknowns.len())?;
        d.set_item("n_segment_columns", p.segment_unknowns.len())?;
        Ok(d)
    }

    /// Where values live in the unknown vector (the columns of an `all_unknowns` run): each
    /// output vessel's [pressure_in, pressure_out, flow_in, flow_out], each chamber's blood
    /// volume as (name, index), other element unknowns (a spherical chamber's wall) as
    /// (svZeroDSolver variable name, index) and each valve's status inputs as (name,
    /// [pressure behind, pressure in front, flow], on_off rule) (docs/physics.md §1.10).
    fn unknown_layout<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let p = &self.inner.0.probes;
        let d = PyDict::new(py);
        d.set_item("vessel_unknowns", p.vessel_unknowns.clone())?;
        d.set_item("chamber_volumes", p.chamber_volumes.clone())?;
        d.set_item("element_unknowns", p.element_unknowns.clone())?;
        let valves: Vec<(String, [usize; 3], bool)> = (p.valves.iter())
            .map(|v| (v.name.clone(), v.unknowns, v.on_off))
            .collect();
        d.set_item("valves", valves)?;
        Ok(d)
    }

    /// svZeroDSolver's `valve_status` of the `valve` element of vessel `name` at the pressure
    /// differences `dp` = P_front − P_behind (its law's switch, 0 open, 1 closed;
    /// docs/physics.md §1.8). `ValueError` for a name that is no valve element.
    fn valve_closure<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        dp: Vec<f64>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let probes = &self.inner.0.probes;
        let law = (probes.valves.iter())
            .find(|v| v.name == name)
            .and_then(|v| v.law)
            .ok_or_else(|| {
                PyValueError::new_err(format!("valve_closure: '{name}' is not a valve element"))
            })?;
        let out: Vec<f64> = dp.iter().map(|&d| law.closure(d)).collect();
        Ok(out.into_pyarray(py))
    }

    /// Layout of the output selection (see `oxyline_core::output`): selected vessels, their
    /// segment counts and positions, the selected variable names and the column counts.
    #[pyo3(signature = (*, variables = None, vessels = None, segments = true))]
    fn output_layout<'py>(
        &self,
        py: Python<'py>,
        variables: Option<Vec<String>>,
        vessels: Option<Vec<String>>,
        segments: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let sel = self.selection(variables, vessels, segments)?;
        layout_dict(py, &self.inner.0.probes, self.transport.as_deref(), &sel)
    }

    /// The segment table: one entry per flow segment of every vessel, in model order, with
    /// the R, L, C, stenosis coefficient and volume the core assembled (SI; docs/physics.md §1.1).
    fn segment_table<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let a = &self.inner.0;
        let t = &a.segments;
        let col = |f: fn(&oxyline_core::SegmentRow) -> f64| {
            t.iter().map(f).collect::<Vec<_>>().into_pyarray(py)
        };
        let d = PyDict::new(py);
        d.set_item("vessel_names", a.circuit.vessel_names.clone())?;
        d.set_item(
            "vessel",
            t.iter()
                .map(|s| s.vessel as usize)
                .collect::<Vec<_>>()
                .into_pyarray(py),
        )?;
        d.set_item(
            "index",
            t.iter()
                .map(|s| s.index as usize)
                .collect::<Vec<_>>()
                .into_pyarray(py),
        )?;
        d.set_item("resistance", col(|s| s.resistance))?;
        d.set_item("inductance", col(|s| s.inductance))?;
        d.set_item("compliance", col(|s| s.compliance))?;
        d.set_item("stenosis", col(|s| s.stenosis))?;
        d.set_item("volume", col(|s| s.volume))?;
        d.set_item("length", col(|s| s.length))?;
        d.set_item("radius_in", col(|s| s.radius_in))?;
        d.set_item("radius_out", col(|s| s.radius_out))?;
        d.set_item("x0", col(|s| s.x0))?;
        d.set_item("x1", col(|s| s.x1))?;
        d.set_item("position", col(|s| s.position))?;
        Ok(d)
    }

    /// The exact steady state of the mean boundary conditions (the `start="steady"` state):
    /// the full unknown vector, the pressure of every graph node by name, and the end
    /// pressures and flows of every output vessel.
    fn steady_state<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let inner = self.inner.clone();
        let y = py
            .detach(move || oxyline_core::simulate::steady_state(&inner.1))
            .map_err(to_py)?;
        let (a, _) = &*self.inner;
        let p = &a.probes;
        let d = PyDict::new(py);
        let graph_nodes = a.summary.nodes;
        d.set_item(
            "nodes",
            (0..graph_nodes)
                .map(|i| a.circuit.names.node(i))
                .collect::<Vec<_>>(),
        )?;
        d.set_item("node_pressure", y[..graph_nodes].to_vec().into_pyarray(py))?;
        d.set_item("vessels", p.vessels.clone())?;
        for (j, name) in VESSEL_VARIABLES.iter().enumerate() {
            let v: Vec<f64> = p.vessel_unknowns.chunks(4).map(|u| y[u[j]]).collect();
            d.set_item(*name, v.into_pyarray(py))?;
        }
        d.set_item("state", y.into_pyarray(py))?;
        Ok(d)
    }

    /// Species transport layout: species names, cells, recorded columns, segments per vessel.
    fn transport_layout<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(t) = &self.transport else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("species", t.species_names())?;
        d.set_item("cells", t.n_cells())?;
        d.set_item("columns_per_species", t.columns_per_species())?;
        d.set_item("segment_count", t.out_segment_counts())?;
        d.set_item("vessel_columns", oxyline_core::transport::VESSEL_COLUMNS)?;
        d.set_item("segment_columns", oxyline_core::transport::SEGMENT_COLUMNS)?;
        d.set_item("balance_columns", oxyline_core::transport::BALANCE_COLUMNS)?;
        Ok(Some(d))
    }

    /// Names of all circuit unknowns (for diagnostics).
    fn unknown_names(&self) -> Vec<String> {
        self.inner.1.names.unknowns()
    }

    /// The assembled circuit as arrays: unknown names, mass diagonal E (capacitance for node
    /// unknowns, inductance for branch unknowns), node count, fixed-pressure nodes, branch ends.
    fn circuit<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (a, dae) = &*self.inner;
        let c = &a.circuit;
        let d = PyDict::new(py);
        d.set_item("names", dae.names.unknowns())?;
        d.set_item("mass", dae.e.clone().into_pyarray(py))?;
        d.set_item("n_nodes", dae.n_nodes)?;
        d.set_item(
            "fixed_nodes",
            c.fixed_pressures
                .iter()
                .map(|(n, _)| *n)
                .collect::<Vec<_>>(),
        )?;
        d.set_item(
            "source_nodes",
            c.sources.iter().map(|(n, _)| *n).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "branch_from",
            c.branches.iter().map(|b| b.from).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "branch_to",
            c.branches.iter().map(|b| b.to).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "node_volume",
            c.nodes.iter().map(|n| n.volume).collect::<Vec<_>>(),
        )?;
        d.set_item(
            "node_wall_area",
            c.nodes.iter().map(|n| n.wall_area).collect::<Vec<_>>(),
        )?;
        Ok(d)
    }

    /// Source inflows (m³/s) at time t, one per source node (in `circuit()["source_nodes"]` order).
    fn source_flows(&self, t: f64) -> Vec<f64> {
        self.inner
            .0
            .circuit
            .sources
            .iter()
            .map(|(_, w)| w.eval(t))
            .collect()
    }

    /// (consistent state, dy/dt) of the transient circuit at (t, state).
    fn derivative<'py>(
        &self,
        py: Python<'py>,
        t: f64,
        state: Vec<f64>,
    ) -> PyResult<ArrayPair<'py>> {
        let dae = &self.inner.1;
        if state.len() != dae.n {
            return Err(ModelError::new_err(format!(
                "state has {} entries, expected {}",
                state.len(),
                dae.n
            )));
        }
        let mut y = state;
        let mut rk = oxyline_core::rk4::Rk4::new(dae, oxyline_core::Regime::Transient, 1.0)
            .map_err(to_py)?;
        let yd = rk.derivative(t, &mut y).map_err(to_py)?;
        Ok((y.into_pyarray(py), yd.into_pyarray(py)))
    }

    /// Largest stable RK4 step: (dt_max, element, exact). `method`: "auto" (dense spectrum up
    /// to 600 differential unknowns, Krylov beyond), "dense" or "krylov".
    #[pyo3(signature = (method = "auto"))]
    fn rk4_stability_limit(&self, py: Python<'_>, method: &str) -> PyResult<(f64, String, bool)> {
        use oxyline_core::stability::SpectrumMethod;
        let method = match method {
            "auto" => SpectrumMethod::Auto,
            "dense" => SpectrumMethod::Dense,
            "krylov" => SpectrumMethod::Krylov,
            other => {
                return Err(PyValueError::new_err(format!(
                    "method '{other}': expected 'auto', 'dense' or 'krylov'"
                )));
            }
        };
        let inner = self.inner.clone();
        py.detach(move || {
            let dae = &inner.1;
            let mut rk = oxyline_core::rk4::Rk4::new(dae, oxyline_core::Regime::Transient, 1.0)?;
            let lim = oxyline_core::stability::rk4_limit_by(&mut rk, &dae.names, method)?;
            Ok::<_, Error>((lim.dt_max, lim.element, lim.exact))
        })
        .map_err(to_py)
    }

    /// The factor by which to divide the RK4 step of a run with these settings so that its
    /// first cycle is within `tol` of the converged solution (step doubling; 1 without valves
    /// or chambers): (factor, estimated error, converged). See `run::rk4_step_refinement`.
    #[pyo3(signature = (*, period, output_every, tol, max_factor, **settings))]
    fn rk4_step_refinement(
        &self,
        py: Python<'_>,
        period: f64,
        output_every: f64,
        tol: f64,
        max_factor: usize,
        settings: Option<Bound<'_, PyDict>>,
    ) -> PyResult<(usize, f64, bool)> {
        let shared = settings::Shared::from_kwargs(settings.as_ref())?;
        let s = shared.run_settings(period, output_every, false)?;
        let inner = self.inner.clone();
        py.detach(move || {
            let r = oxyline_core::run::rk4_step_refinement(&inner.1, &s, tol, max_factor)?;
            Ok::<_, Error>((r.factor, r.estimate, r.converged))
        })
        .map_err(to_py)
    }

    /// The RK4 iteration operator of the differential unknowns (algebraic unknowns eliminated)
    /// in energy-scaled coordinates, dense, row-major, with its size: for checking the stability
    /// bound against an independent eigensolver.
    fn rk4_operator<'py>(&self, py: Python<'py>) -> PyResult<(Bound<'py, PyArray1<f64>>, usize)> {
        let inner = self.inner.clone();
        let (flat, n) = py
            .detach(move || {
                let dae = &inner.1;
                let mut rk =
                    oxyline_core::rk4::Rk4::new(dae, oxyline_core::Regime::Transient, 1.0)?;
                let a = oxyline_core::stability::scaled_operator(&mut rk)?;
                let n = a.nrows();
                let flat: Vec<f64> = (0..n * n).map(|k| a[(k / n, k % n)]).collect();
                Ok::<_, Error>((flat, n))
            })
            .map_err(to_py)?;
        Ok((flat.into_pyarray(py), n))
    }

    /// Input impedance (Pa·s/m³) seen from the graph node `node` at angular frequency `omega`.
    fn input_impedance(&self, node: &str, omega: f64) -> PyResult<(f64, f64)> {
        let (a, dae) = &*self.inner;
        let idx = a
            .circuit
            .nodes
            .iter()
            .enumerate()
            .position(|(i, _)| a.circuit.names.node(i) == node)
            .ok_or_else(|| ModelError::new_err(format!("node '{node}': not in the network")))?;
        let z = oxyline_core::frequency::input_impedance(dae, idx, omega).map_err(to_py)?;
        Ok((z.re, z.im))
    }

    /// Input impedances (Pa·s/m³) seen from graph node `node` at each angular frequency of
    /// `omegas` (rad/s): (real parts, imaginary parts). O(n) per frequency by the time
    /// stepping's elimination, with the GIL released.
    fn input_impedances<'py>(
        &self,
        py: Python<'py>,
        node: &str,
        omegas: Vec<f64>,
    ) -> PyResult<ArrayPair<'py>> {
        let circuit = &self.inner.0.circuit;
        let idx = (0..circuit.nodes.len())
            .position(|i| circuit.names.node(i) == node)
            .ok_or_else(|| ModelError::new_err(format!("node '{node}': not in the network")))?;
        let inner = self.inner.clone();
        let z = py
            .detach(move || oxyline_core::impedance::input_impedances(&inner.1, idx, &omegas))
            .map_err(to_py)?;
        let re: Vec<f64> = z.iter().map(|z| z.re).collect();
        let im: Vec<f64> = z.iter().map(|z| z.im).collect();
        Ok((re.into_pyarray(py), im.into_pyarray(py)))
    }

    /// Run the network. Returns a dict with `times` (n_t,), `data` (n_t, n_columns) and run
    /// facts; if the run stopped early, `error`/`error_kind` are set and the data so far kept.
    ///
    /// With `chunk_sink`, the output is streamed instead: `chunk_sink(rows)` is called with
    /// dicts of at most `chunk_rows` rows in the same layout (`times`, `data`, `transport`) as
    /// soon as they are final, including the rows of a run that stops early; the returned
    /// `times`/`data` are then empty. An exception raised by `chunk_sink` stops the run and is
    /// returned as its `error`. `max_buffered_rows` tells the most rows the core held at once.
    /// With last-cycle output, `keep_current_cycle = false` records nothing before the last
    /// cycle (a streaming run then holds at most one chunk; a run stopped earlier returns no
    /// rows).
    ///
    /// With `checkpoint_sink`, `checkpoint_sink(state)` is called at the end of every
    /// `checkpoint_every_cycles`-th cycle, or of the first cycle `checkpoint_every_seconds`
    /// (wall time) after the last, with the run's state as a dict of numbers and arrays
    /// (see `checkpoint.rs`); an exception it raises stops the run and is its `error`. With
    /// `resume` (such a dict), the run continues from that state, bit-identical to the run
    /// that saved it.
    ///
    /// `settings`: the run settings shared with `Ensemble.run` (`settings::KEYS`: cycles,
    /// method, dt, ..., the output selection).
    #[pyo3(signature = (*, period, output_every, all_unknowns = false, extra_columns = None,
        progress = None,
        chunk_sink = None, chunk_rows = 1024, keep_current_cycle = true, checkpoint_sink = None,
        checkpoint_every_cycles = None, checkpoint_every_seconds = None, resume = None,
        **settings))]
    #[allow(clippy::too_many_arguments)]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        period: f64,
        output_every: f64,
        all_unknowns: bool,
        extra_columns: Option<Vec<usize>>,
        progress: Option<Py<PyAny>>,
        chunk_sink: Option<Py<PyAny>>,
        chunk_rows: usize,
        keep_current_cycle: bool,
        checkpoint_sink: Option<Py<PyAny>>,
        checkpoint_every_cycles: Option<usize>,
        checkpoint_every_seconds: Option<f64>,
        resume: Option<Bound<'py, PyDict>>,
        settings: Option<Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let shared = settings::Shared::from_kwargs(settings.as_ref())?;
        if chunk_rows == 0 {
            return Err(ModelError::new_err("simulation: chunk_rows must be >= 1"));
        }
        let every = checkpoint_every(checkpoint_every_cycles, checkpoint_every_seconds)?;
        let resume = resume.map(|d| checkpoint::from_dict(&d)).transpose()?;
        let checkpointing = checkpoint_sink.is_some() || resume.is_some();
        let transport_on = shared.transport;
        let mut settings = shared.run_settings(period, output_every, keep_current_cycle)?;
        let (probes, species_columns) = self.columns(shared, all_unknowns, extra_columns)?;
        settings.probes = probes;
        settings.species_columns = species_columns;
        let inner = self.inner.clone();
        let mut species = if transport_on {
            self.transport.as_deref().map(Transport::new_run)
        } else {
            None
        };
        let species_names = species
            .as_ref()
            .map(|t| t.species_names())
            .unwrap_or_default();
        let n_probes = settings.probes.len();
        let (outcome, pending) = py.detach(|| {
            // the first Python error of a callback (progress, Ctrl-C or the sink) stops the run
            // and is reported instead of the core's Interrupted
            let pending: Cell<Option<PyErr>> = Cell::new(None);
            let mut gate = ProgressGate::new(period);
            let mut cb = |t: f64, t_end: f64| -> bool {
                if !gate.open(t, t_end) {
                    return true;
                }
                Python::attach(|py| {
                    let r = py.check_signals().and_then(|()| match &progress {
                        Some(f) => f.call1(py, (t, t_end)).map(drop),
                        None => Ok(()),
                    });
                    r.map_err(|e| pending.set(Some(e))).is_ok()
                })
            };
            let mut write = |c: Chunk<'_>| -> bool {
                let Some(f) = &chunk_sink else {
                    return true;
                };
                Python::attach(|py| {
                    let d = PyDict::new(py);
                    let species = (!species_names.is_empty()).then(|| {
                        (
                            species_names.as_slice(),
                            PyArray1::from_slice(py, c.transport),
                            c.initial_stored,
                        )
                    });
                    let r = put_rows(
                        &d,
                        PyArray1::from_slice(py, c.times),
                        PyArray1::from_slice(py, c.data),
                        n_probes,
                        species,
                    )
                    .and_then(|_| f.call1(py, (d,)).map(drop));
                    r.map_err(|e| pending.set(Some(e))).is_ok()
                })
            };
            let mut sink = OutputSink {
                rows: chunk_rows,
                write: &mut write,
            };
            let mut save = |snap: &Snapshot| -> bool {
                let Some(f) = &checkpoint_sink else {
                    return true;
                };
                Python::attach(|py| {
                    let r = checkpoint::to_dict(py, snap).and_then(|d| f.call1(py, (d,)).map(drop));
                    r.map_err(|e| pending.set(Some(e))).is_ok()
                })
            };
            let out = if checkpointing {
                let mut ck = Checkpoints::new(every, &mut save, resume);
                oxyline_core::run::simulate_checkpointed(
                    &inner.1,
                    species.as_mut(),
                    &settings,
                    chunk_sink.is_some().then_some(&mut sink),
                    &mut ck,
                    &mut cb,
                )
            } else if chunk_sink.is_some() {
                oxyline_core::simulate_to_sink(
                    &inner.1,
                    species.as_mut(),
                    &settings,
                    &mut sink,
                    &mut cb,
                )
            } else {
                oxyline_core::simulate_with_transport(
                    &inner.1,
                    species.as_mut(),
                    &settings,
                    &mut cb,
                )
            };
            (out, pending.into_inner())
        });
        finished_run(py, outcome, pending)
    }
}

impl Network {
    /// The unknowns a run records: the selected output columns (or every unknown), then the
    /// `extra_columns` (chamber volumes, valve pressures and flows: `unknown_layout`),
    /// bounds-checked here; and the species columns of the selection.
    fn columns(
        &self,
        shared: settings::Shared,
        all_unknowns: bool,
        extra_columns: Option<Vec<usize>>,
    ) -> PyResult<(Vec<usize>, Option<Vec<usize>>)> {
        let segments = shared.segments;
        let selected = shared.variables.is_some() || shared.vessels.is_some();
        let sel = self.selection(shared.variables, shared.vessels, segments)?;
        let (mut cols, species_columns) = if all_unknowns {
            ((0..self.inner.1.n).collect(), None)
        } else {
            recorded_columns(
                &self.inner.0.probes,
                self.transport.as_deref(),
                &sel,
                selected,
                segments,
            )
        };
        if let Some(extra) = extra_columns {
            if let Some(&bad) = extra.iter().find(|&&c| c >= self.inner.1.n) {
                return Err(ModelError::new_err(format!(
                    "simulation: extra column {bad} is not an unknown (the circuit has {})",
                    self.inner.1.n
                )));
            }
            cols.extend(extra);
        }
        Ok((cols, species_columns))
    }
}

/// When the run's progress callback reaches Python: at most once per 100 ms, plus the first
/// call of every new cycle (a callback that reacts to a cycle-end event, a checkpoint written
/// or a cancel, then acts within 256 steps however fast the run is), and at the end.
struct ProgressGate {
    period: f64,
    last: Instant,
    last_cycle: i64,
}

impl ProgressGate {
    fn new(period: f64) -> Self {
        ProgressGate {
            period,
            last: Instant::now(),
            last_cycle: 0,
        }
    }
    fn open(&mut self, t: f64, t_end: f64) -> bool {
        let cycle = (t / self.period).floor() as i64;
        if self.last.elapsed() < Duration::from_millis(100) && t < t_end && cycle == self.last_cycle
        {
            return false;
        }
        self.last = Instant::now();
        self.last_cycle = cycle;
        true
    }
}

/// The run's result dict; a run stopped by a callback's Python error (progress, Ctrl-C, a
/// sink) or by the core keeps its rows and says why in `error`/`error_kind`.
fn finished_run(
    py: Python<'_>,
    outcome: std::result::Result<Outcome, Error>,
    pending: Option<PyErr>,
) -> PyResult<Bound<'_, PyDict>> {
    let mut out = outcome.map_err(to_py)?;
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

/// When to checkpoint: every n cycles, or after a wall time in seconds (never both).
fn checkpoint_every(cycles: Option<usize>, seconds: Option<f64>) -> PyResult<Every> {
    match (cycles, seconds) {
        (Some(_), Some(_)) => Err(ModelError::new_err(
            "simulation: checkpoint_every: give cycles or seconds, not both",
        )),
        (Some(0), _) => Err(ModelError::new_err(
            "simulation: checkpoint_every must be >= 1 cycle",
        )),
        (Some(n), None) => Ok(Every::Cycles(n)),
        (None, Some(s)) if s.is_finite() && s >= 0.0 => Ok(Every::Wall(Duration::from_secs_f64(s))),
        (None, Some(s)) => Err(ModelError::new_err(format!(
            "simulation: checkpoint_every must be a number of seconds >= 0, got {s}"
        ))),
        (None, None) => Ok(Every::Wall(Duration::from_secs(300))),
    }
}

/// (E(t), V_rest(t)) of a canonical chamber spec (JSON text) at `times`: the drop-in rebuilds
/// a chamber's volume V = V_rest + P/E from its recorded pressure (docs/svzerod.md).
#[pyfunction]
fn chamber_elastance<'py>(
    py: Python<'py>,
    name: &str,
    chamber_json: &str,
    times: Vec<f64>,
) -> PyResult<ArrayPair<'py>> {
    let spec: oxyline_core::spec::ChamberSpec = oxyline_core::spec::from_json(chamber_json)
        .map_err(|e| to_py(oxyline_core::Error::model(format!("chamber '{name}'"), e)))?;
    let law = oxyline_core::assemble::chamber_elastance(name, &spec).map_err(to_py)?;
    let (e, v): (Vec<f64>, Vec<f64>) = times.iter().map(|&t| law.at(t)).unzip();
    Ok((e.into_pyarray(py), v.into_pyarray(py)))
}

#[pymodule]
mod _core {
    #[pymodule_export]
    use super::closed_loop::{closed_loop_o2, closed_loop_tree_flows};
    #[pymodule_export]
    use super::{
        ModelError, Network, ResourceError, SolverError, UnstableTimeStep, chamber_elastance,
        ensemble::Ensemble, native::NativeParts,
    };

    use pyo3::types::PyModuleMethods;

    #[pymodule_init]
    fn init(m: &pyo3::Bound<'_, pyo3::types::PyModule>) -> pyo3::PyResult<()> {
        m.add("__version__", env!("CARGO_PKG_VERSION"))?;
        // the column schema (`oxyline_core::output`): Python names no column itself
        m.add("VESSEL_VARIABLES", super::VESSEL_VARIABLES.to_vec())?;
        m.add("SEGMENT_VARIABLES", super::SEGMENT_VARIABLES.to_vec())?;
        m.add(
            "SPECIES_VESSEL_VARIABLES",
            super::SPECIES_VESSEL_VARIABLES.to_vec(),
        )?;
        m.add(
            "SPECIES_SEGMENT_VARIABLES",
            super::SPECIES_SEGMENT_VARIABLES.to_vec(),
        )?;
        m.add("BALANCE_VARIABLES", super::BALANCE_VARIABLES.to_vec())?;
        // the run settings `Network.simulate` and `Ensemble.run` take as `**settings`
        m.add("RUN_SETTINGS", super::settings::KEYS.to_vec())?;
        // checkpoints and memory estimates (`oxyline_core::run::{checkpoint, memory}`)
        m.add(
            "CHECKPOINT_VERSION",
            oxyline_core::run::checkpoint::CHECKPOINT_VERSION,
        )?;
        {
            use oxyline_core::run::memory as mem;
            m.add("FLOW_BYTES_PER_SEGMENT", mem::FLOW_BYTES_PER_SEGMENT)?;
            m.add("TRANSPORT_BYTES_PER_CELL", mem::TRANSPORT_BYTES_PER_CELL)?;
            m.add("BYTES_PER_ELEMENT", mem::BYTES_PER_ELEMENT)?;
        }
        m.add(
            "TISSUE_VESSEL_VARIABLES",
            super::TISSUE_VESSEL_VARIABLES.to_vec(),
        )?;
        m.add(
            "TISSUE_SEGMENT_VARIABLES",
            super::TISSUE_SEGMENT_VARIABLES.to_vec(),
        )?;
        m.add(
            "TISSUE_BALANCE_VARIABLES",
            super::TISSUE_BALANCE_VARIABLES.to_vec(),
        )?;
        m.add(
            "build_profile",
            if cfg!(debug_assertions) {
                "debug"
            } else {
                "release"
            },
        )
    }
}
