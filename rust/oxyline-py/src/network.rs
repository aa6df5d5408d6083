//! `_core.Network`: an assembled network, built once from the model and run many times.

use crate::errors::{ModelError, to_py};
use crate::results::{ArrayPair, finished_run, layout_dict, put_heart, put_rows, recorded_columns};
use crate::{checkpoint, reader, settings};
use numpy::{IntoPyArray, PyArray1};
use oxyline_core::model::parse;
use oxyline_core::model::plausibility::{self, Warning};
use oxyline_core::output::{HeartColumns, HeartRows, VESSEL_VARIABLES};
use oxyline_core::run::checkpoint::{Checkpoints, Every, Snapshot};
use oxyline_core::run::memory::RELEASED_CIRCUIT_SEGMENTS;
use oxyline_core::{Assembled, Chunk, Dae, Error, OutputSink, Selection, Transport};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};
use reader::model::canonical_spec;
use std::cell::Cell;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What `Network::new` builds: the circuit and its DAE, the transport plan and the
/// plausibility warnings of the model.
type Built = ((Assembled, Dae), Option<Transport>, Vec<Warning>);

/// `spec` with the outlets' conditions added (each node once), assembled as every ensemble
/// member is (spec → circuit → DAE → transport), with its plausibility findings. Above
/// `RELEASED_CIRCUIT_SEGMENTS` segments the circuit's node and branch tables are dropped once
/// the DAE and the transport plan are built (a run reads those only); `keep_circuit` decides
/// it instead when given.
fn assemble(
    mut spec: oxyline_core::NetworkSpec,
    outlets: Vec<(String, oxyline_core::model::BoundarySpec)>,
    keep_circuit: Option<bool>,
) -> Result<Built, Error> {
    use std::collections::btree_map::Entry;
    for (node, bc) in outlets {
        match spec.boundary_conditions.entry(node) {
            Entry::Occupied(e) => {
                return Err(Error::model(
                    format!("boundary condition '{}'", e.key()),
                    "given twice",
                ));
            }
            Entry::Vacant(e) => {
                e.insert(bc);
            }
        }
    }
    let warnings = plausibility::check(&spec);
    // the spec dropped once the circuit is assembled (a large tree's load peak)
    let mut member = oxyline_core::ensemble::Member::build_owned(spec)?;
    let large = member.assembled.summary.segments > RELEASED_CIRCUIT_SEGMENTS;
    if !keep_circuit.unwrap_or(!large) {
        member.assembled.circuit.release_tables();
    }
    Ok(((member.assembled, member.dae), member.transport, warnings))
}

/// An assembled network: built once from the canonical SI JSON model, run many times.
#[pyclass(frozen, module = "oxyline._core")]
pub(crate) struct Network {
    inner: Arc<(Assembled, Dae)>,
    /// Validated species transport, never run: each run takes `new_run` (the shared plan and a
    /// fresh state); None for flow-only models.
    transport: Option<Arc<Transport>>,
    /// The model's values outside their physiological ranges (`model::plausibility`).
    plausibility: Vec<Warning>,
}

impl Network {
    fn from_built((built, transport, plausibility): Built) -> Self {
        Network {
            inner: Arc::new(built),
            transport: transport.map(Arc::new),
            plausibility,
        }
    }

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

#[oxyline_py_guard::guard]
#[pymethods]
impl Network {
    /// The network of a canonical SI model: its JSON text, or its dicts read in place by the
    /// core's serde types (`reader::de`; an error names the vessel or condition and the key).
    /// `max_memory`: the memory limit in bytes (None: the model's own, if any).
    /// `keep_circuit`: keep the circuit's tables (`circuit()`, the impedance) or drop them
    /// once the run's matrices are built (None: drop them for a large model; see `assemble`).
    #[new]
    #[pyo3(signature = (model, max_memory = None, keep_circuit = None))]
    fn new(
        py: Python<'_>,
        model: Bound<'_, PyAny>,
        max_memory: Option<f64>,
        keep_circuit: Option<bool>,
    ) -> PyResult<Self> {
        let spec = match model.cast::<PyString>() {
            // the text is parsed where Python holds it (no copy)
            Ok(text) => {
                let text = text.to_str()?;
                py.detach(|| parse(text)).map_err(to_py)?
            }
            Err(_) => canonical_spec(&model)?,
        };
        // the spec is dropped once the circuit and the transport plan are built from it
        let built = py.detach(move || {
            let mut spec = spec;
            spec.max_memory = max_memory.or(spec.max_memory);
            assemble(spec, Vec::new(), keep_circuit)
        });
        Ok(Network::from_built(built.map_err(to_py)?))
    }

    /// The network of a model read by `read_model` (its parts, structured trees grown into
    /// them, moved into the spec): the model crosses from Python once. `max_memory`: the
    /// memory limit in bytes (None: none).
    #[staticmethod]
    #[pyo3(signature = (parts, max_memory = None))]
    fn from_parts(
        py: Python<'_>,
        parts: Bound<'_, reader::NativeParts>,
        max_memory: Option<f64>,
    ) -> PyResult<Self> {
        let (vessels, outlets, rest) = {
            let mut p = parts.borrow_mut();
            let rest = p.rest.take().ok_or_else(|| {
                to_py(Error::model(
                    "model",
                    "was not read (no parts to build from)",
                ))
            })?;
            let (v, o) = p.take().map_err(to_py)?;
            (v, o, rest)
        };
        let built = py.detach(move || -> Result<Built, Error> {
            let mut spec: oxyline_core::NetworkSpec =
                serde_json::from_value(serde_json::Value::Object(rest))
                    .map_err(|e| Error::model("model", e.to_string()))?;
            spec.vessels = vessels;
            spec.max_memory = max_memory;
            assemble(spec, outlets, None)
        });
        Ok(Network::from_built(built.map_err(to_py)?))
    }

    /// How many passes a run makes over its cycles: 2 for a transport model whose wall
    /// closures need the cycle-mean flow (a flow-only pass first, docs/physics.md §3.1), else
    /// 1. The progress bar counts the cycles of the last pass only.
    fn passes(&self) -> usize {
        match &self.transport {
            Some(t) if !t.mean_flow_unknowns().is_empty() => 2,
            _ => 1,
        }
    }

    /// The model's values outside their physiological ranges, one dict each (element, key,
    /// value, unit, low, high, likely_cause, more, message) for `oxyline.PlausibilityWarning`.
    fn plausibility<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.plausibility
            .iter()
            .map(|w| {
                let d = PyDict::new(py);
                d.set_item("element", &w.element)?;
                d.set_item("key", &w.key)?;
                d.set_item("value", w.value)?;
                d.set_item("unit", w.unit)?;
                d.set_item("low", w.low)?;
                d.set_item("high", w.high)?;
                d.set_item("likely_cause", w.likely_cause.as_deref())?;
                d.set_item("more", w.more)?;
                d.set_item("message", w.message())?;
                Ok(d)
            })
            .collect()
    }

    /// Counts and totals for `oxyline validate`.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let (a, dae) = &*self.inner;
        let s = &a.summary;
        let d = PyDict::new(py);
        d.set_item("vessels", s.vessels)?;
        d.set_item("segments", s.segments)?;
        d.set_item("auto_segments", s.auto_segments)?;
        d.set_item("auto_vessels", s.auto_vessels)?;
        d.set_item("auto_rtol", s.auto_rtol)?;
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

    /// Estimated peak bytes of a run (`oxyline_core::run::memory::run_bytes`), from the sizes
    /// this network allocated: its segments, vessels and boundary conditions, transport cells
    /// × species (when `transport`), and the error control's state of its unknowns
    /// (`controlled`: None for a fixed step, else whether the explicit pair may run).
    #[pyo3(signature = (*, transport = true, controlled = None))]
    fn memory_estimate(&self, transport: bool, controlled: Option<bool>) -> f64 {
        use oxyline_core::run::memory::{Controlled, run_bytes};
        let (a, dae) = &*self.inner;
        let s = &a.summary;
        let species_cells = match (&self.transport, transport) {
            (Some(t), true) => (t.n_cells() * t.species_names().len()) as f64,
            _ => 0.0,
        };
        let controlled = controlled.map(|explicit| {
            if explicit {
                Controlled::ExplicitPair
            } else {
                Controlled::GeneralizedAlpha
            }
        });
        run_bytes(
            s.segments,
            s.vessels + s.boundary_conditions,
            species_cells,
            dae.n,
            controlled,
        )
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
        // the table keeps each vessel's recipe: its rows are written here, once per call
        let t: Vec<oxyline_core::SegmentRow> = a.segments.rows().collect();
        let col = |f: fn(&oxyline_core::SegmentRow) -> f64| {
            t.iter().map(f).collect::<Vec<_>>().into_pyarray(py)
        };
        let d = PyDict::new(py);
        d.set_item("vessel_names", a.circuit.vessel_names.clone())?;
        // per vessel: the arrangement its segments were stamped in (stated or resolved)
        let arrangement = |x: &oxyline_core::model::Arrangement| match x {
            oxyline_core::model::Arrangement::InvertedL => "inverted-L",
            oxyline_core::model::Arrangement::L => "L",
            oxyline_core::model::Arrangement::Pi => "pi",
            oxyline_core::model::Arrangement::Rcl => "RCL",
        };
        d.set_item(
            "vessel_arrangements",
            a.arrangements.iter().map(arrangement).collect::<Vec<_>>(),
        )?;
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

    /// Whether the circuit's node and branch tables are kept (`circuit()`, the impedance):
    /// a large network drops them once built (see `assemble`).
    fn circuit_kept(&self) -> bool {
        !self.inner.0.circuit.is_released()
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
        if c.is_released() {
            return Err(ModelError::new_err(format!(
                "circuit: {}",
                oxyline_core::circuit::RELEASED
            )));
        }
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

    /// An upper bound of the largest stable RK4 step from a few power iterations (no
    /// eigen-iteration over the whole circuit): what `method: auto` weighs before it probes
    /// the spectrum of a large circuit. For checking against the dense eigenvalues.
    fn rk4_step_ceiling(&self, py: Python<'_>) -> PyResult<f64> {
        let inner = self.inner.clone();
        py.detach(move || {
            let dae = &inner.1;
            let mut rk = oxyline_core::rk4::Rk4::new(dae, oxyline_core::Regime::Transient, 1.0)?;
            oxyline_core::stability::rk4_step_ceiling(&mut rk, &mut || true)
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
        let idx = (0..dae.n_nodes)
            .position(|i| a.circuit.names.node(i) == node)
            .ok_or_else(|| ModelError::new_err(format!("node '{node}': not in the network")))?;
        let z = oxyline_core::frequency::input_impedance(dae, idx, omega).map_err(to_py)?;
        Ok((z.re, z.im))
    }

    /// Input impedances (Pa·s/m³) seen from graph node `node` at each frequency of
    /// `frequencies` (Hz; the core checks them) into the network `direction` of it
    /// ("downstream", "upstream", "both"): (real parts, imaginary parts). O(n) per frequency
    /// by the time stepping's elimination, with the GIL released.
    #[pyo3(signature = (node, frequencies, direction = "downstream"))]
    fn input_impedances<'py>(
        &self,
        py: Python<'py>,
        node: &str,
        frequencies: Vec<f64>,
        direction: &str,
    ) -> PyResult<ArrayPair<'py>> {
        use oxyline_core::impedance::{Direction, input_impedances_at_hz};
        let direction = Direction::parse(direction).map_err(to_py)?;
        let circuit = &self.inner.0.circuit;
        if circuit.is_released() {
            return Err(ModelError::new_err(format!(
                "impedance: {}",
                oxyline_core::circuit::RELEASED
            )));
        }
        let idx = (0..circuit.nodes.len())
            .position(|i| circuit.names.node(i) == node)
            .ok_or_else(|| ModelError::new_err(format!("node '{node}': not in the network")))?;
        let inner = self.inner.clone();
        let z = py
            .detach(move || {
                input_impedances_at_hz(&inner.0.circuit, &inner.1, idx, direction, &frequencies)
            })
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
    /// `heart`: the dict (and every streamed chunk) also has `chamber_volume` {chamber:
    /// volume (m³) per row} and `valve_status` {valve: status (int8, 1 open, 0 closed) per
    /// row; a chunk's valves go on from the last chunk's}: the heart outputs of the model's
    /// chambers and valves (`oxyline_core::output::HeartColumns`), none when it has neither.
    ///
    /// `svzerod`: svZeroDSolver's output and stop conventions for the drop-in (derived
    /// columns, rates, the cycle-to-cycle rule; see `svzerod.rs`), recorded after the columns.
    ///
    /// `settings`: the run settings shared with `Ensemble.run` (`settings::KEYS`: cycles,
    /// method, dt, ..., the output selection). The step control defaults as in
    /// `oxyline.simulate` ([`settings::Shared::default_step_control`]): error control at rtol
    /// 1e-3 without `rtol`, `dt` or checkpoints; `rtol = None` keeps the fixed step.
    #[pyo3(signature = (*, period, output_every, all_unknowns = false, heart = false,
        progress = None,
        chunk_sink = None, chunk_rows = 1024, keep_current_cycle = true, checkpoint_sink = None,
        checkpoint_every_cycles = None, checkpoint_every_seconds = None, resume = None,
        svzerod = None, finer_last_cycle = None, **settings))]
    #[allow(clippy::too_many_arguments)]
    fn simulate<'py>(
        &self,
        py: Python<'py>,
        period: f64,
        output_every: f64,
        all_unknowns: bool,
        heart: bool,
        progress: Option<Py<PyAny>>,
        chunk_sink: Option<Py<PyAny>>,
        chunk_rows: usize,
        keep_current_cycle: bool,
        checkpoint_sink: Option<Py<PyAny>>,
        checkpoint_every_cycles: Option<usize>,
        checkpoint_every_seconds: Option<f64>,
        resume: Option<Bound<'py, PyDict>>,
        svzerod: Option<Bound<'py, PyDict>>,
        finer_last_cycle: Option<f64>,
        settings: Option<Bound<'py, PyDict>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut shared = settings::Shared::from_kwargs(settings.as_ref())?;
        if chunk_rows == 0 {
            return Err(ModelError::new_err("simulation: chunk_rows must be >= 1"));
        }
        let every = checkpoint_every(checkpoint_every_cycles, checkpoint_every_seconds)?;
        let resume = resume.map(|d| checkpoint::from_dict(&d)).transpose()?;
        let checkpointing = checkpoint_sink.is_some() || resume.is_some();
        shared.default_step_control(checkpointing);
        let transport_on = shared.transport;
        let mut settings = shared.run_settings(period, output_every, keep_current_cycle)?;
        let threads = shared.threads;
        let (mut probes, species_columns) = self.columns(shared, all_unknowns)?;
        // the heart outputs' unknowns, recorded after the selected columns (taken out again
        // as chamber volumes and valve statuses when the rows are handed over)
        let mut heart = if heart {
            HeartColumns::of(&self.inner.0.probes)
        } else {
            HeartColumns::default()
        };
        let heart_at = probes.len();
        probes.extend_from_slice(heart.unknowns());
        settings.probes = probes;
        settings.species_columns = species_columns;
        if let Some(d) = &svzerod {
            settings.svzerod = crate::svzerod::rules(d, &self.inner.0.probes)?;
        }
        // the accumulated-error estimate: the last cycle again at rtol / this factor
        settings.finer_last_cycle = finer_last_cycle;
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
        let n_probes =
            settings.probes.len() + settings.svzerod.extra_columns(settings.probes.len());
        let mut streamed_heart = heart.clone();
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
                    let (data, hearts) =
                        chunk_heart(py, &mut streamed_heart, c.data, n_probes, heart_at);
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
                        data.unwrap_or_else(|| PyArray1::from_slice(py, c.data)),
                        n_probes - streamed_heart.width(),
                        species,
                    )
                    .and_then(|_| put_heart(&d, &streamed_heart, hearts))
                    .and_then(|()| f.call1(py, (d,)).map(drop));
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
            // the run stays on this thread; its large loops use the pool of `threads`
            let run = || {
                if checkpointing {
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
                }
            };
            let out = oxyline_core::threads::with_threads(threads, run).and_then(|o| o);
            (out, pending.into_inner())
        });
        // the run's state (its transport state here, the integrators in the core) is freed
        // before Python builds the result, and the allocator's free pages are handed back:
        // else the result's arrays and tables stack on the run's freed, still resident
        // memory (the peak of a million-segment run)
        drop(species);
        drop(settings);
        oxyline_core::run::release_free_pages(inner.1.n);
        let mut hearts = None;
        let outcome = outcome.map(|mut out| {
            if !heart.is_empty() {
                hearts = Some(out.take_heart(&mut heart, heart_at));
            }
            out
        });
        let d = finished_run(py, outcome, pending)?;
        if let Some(rows) = hearts {
            put_heart(&d, &heart, Some(rows))?;
        }
        Ok(d)
    }
}

impl Network {
    /// The unknowns a run records: the selected output columns (or every unknown), and the
    /// species columns of the selection.
    fn columns(
        &self,
        shared: settings::Shared,
        all_unknowns: bool,
    ) -> PyResult<(Vec<usize>, Option<Vec<usize>>)> {
        let segments = shared.segments;
        let selected = shared.variables.is_some() || shared.vessels.is_some();
        let sel = self.selection(shared.variables, shared.vessels, segments)?;
        let (cols, species_columns) = if all_unknowns {
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
        Ok((cols, species_columns))
    }
}

/// A streamed chunk's rows (`n_cols` wide) without the heart columns at `at`, and its
/// chamber volumes and valve statuses, each valve going on from the last chunk's status
/// (None, None without heart outputs: the rows go over as they are).
fn chunk_heart<'py>(
    py: Python<'py>,
    heart: &mut HeartColumns,
    data: &[f64],
    n_cols: usize,
    at: usize,
) -> (Option<Bound<'py, PyArray1<f64>>>, Option<HeartRows>) {
    if heart.is_empty() {
        return (None, None);
    }
    let mut kept = data.to_vec();
    let rows = heart.split(&mut kept, n_cols, at);
    (Some(kept.into_pyarray(py)), Some(rows))
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
        // a wall time a Duration cannot hold (e.g. 1e20 s) is refused, never a panic
        (None, Some(s)) => match Duration::try_from_secs_f64(s) {
            Ok(d) => Ok(Every::Wall(d)),
            Err(_) => Err(ModelError::new_err(format!(
                "simulation: checkpoint_every must be a number of seconds >= 0 and below \
                 {:e}, got {s}",
                Duration::MAX.as_secs_f64()
            ))),
        },
        (None, None) => Ok(Every::Wall(Duration::from_secs(300))),
    }
}
