//! The physical-bounds monitor (`oxyline_core::monitor`) over a result's numpy arrays: the
//! arrays are read in place, the core finds and words what is outside its bounds.

use crate::errors::to_py;
use numpy::ndarray::{ArrayView2, ArrayView3};
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3};
use oxyline_core::model::transport::{SpeciesSpec, TransportSpec};
use oxyline_core::monitor::{self, Chunk, SpeciesRows, Table};
use pyo3::prelude::*;

/// One variable of a (time, column, variable) array.
struct Plane<'a> {
    data: ArrayView3<'a, f64>,
    var: usize,
}

impl Table for Plane<'_> {
    fn rows(&self) -> usize {
        self.data.shape()[0]
    }
    fn columns(&self) -> usize {
        self.data.shape()[1]
    }
    fn at(&self, t: usize, k: usize) -> f64 {
        self.data[[t, k, self.var]]
    }
}

/// A (time, column) array.
struct Grid<'a>(ArrayView2<'a, f64>);

impl Table for Grid<'_> {
    fn rows(&self) -> usize {
        self.0.shape()[0]
    }
    fn columns(&self) -> usize {
        self.0.shape()[1]
    }
    fn at(&self, t: usize, k: usize) -> f64 {
        self.0[[t, k]]
    }
}

/// A species' arrays as a result holds them: (name, vessel data, its variables, segment
/// data, its variables, balance data, initial amount, mmHg per mol/m³ or None).
type SpeciesArrays<'py> = (
    String,
    PyReadonlyArray3<'py, f64>,
    Vec<String>,
    PyReadonlyArray3<'py, f64>,
    Vec<String>,
    PyReadonlyArray2<'py, f64>,
    f64,
    Option<f64>,
);

/// The planes of one species' recorded arrays the monitor reads.
struct SpeciesPlanes<'a> {
    name: &'a str,
    ends: Vec<Plane<'a>>,
    segments: Option<Plane<'a>>,
    tl_resistance: Option<Plane<'a>>,
    balance: Grid<'a>,
    initial_stored: f64,
    po2_per_concentration: Option<f64>,
}

impl<'a> SpeciesPlanes<'a> {
    fn new(s: &'a SpeciesArrays<'_>) -> Self {
        let (vessel, segment) = (s.1.as_array(), s.3.as_array());
        let plane = |data: ArrayView3<'a, f64>, vars: &[String], key: &str| {
            let var = vars.iter().position(|v| v == key)?;
            Some(Plane { data, var })
        };
        let ends = ["concentration_in", "concentration_out"];
        let recorded = segment.shape()[1] > 0;
        SpeciesPlanes {
            name: &s.0,
            ends: ends.iter().filter_map(|k| plane(vessel, &s.2, k)).collect(),
            segments: plane(segment, &s.4, "concentration").filter(|_| recorded),
            tl_resistance: plane(segment, &s.4, "tl_resistance").filter(|_| recorded),
            balance: Grid(s.5.as_array()),
            initial_stored: s.6,
            po2_per_concentration: s.7,
        }
    }

    fn rows(&self) -> SpeciesRows<'_> {
        SpeciesRows {
            name: self.name,
            ends: self.ends.iter().map(|p| p as &dyn Table).collect(),
            segments: self.segments.as_ref().map(|p| p as &dyn Table),
            tl_resistance: self.tl_resistance.as_ref().map(|p| p as &dyn Table),
            balance: &self.balance,
            initial_stored: self.initial_stored,
            po2_per_concentration: self.po2_per_concentration,
        }
    }
}

/// The monitor of one run (docs/physics.md §2.8): built from the model's canonical
/// transport section (None: no species), fed the recorded rows chunk by chunk.
#[pyclass(module = "oxyline._core")]
pub struct BoundsMonitor(monitor::Monitor);

/// The model's transport section read as the core reads it (None: no species).
fn transport_spec(transport: &Bound<'_, PyAny>) -> PyResult<Option<TransportSpec>> {
    if transport.is_none() {
        return Ok(None);
    }
    crate::reader::de::read(transport, || "transport".into()).map_err(to_py)
}

#[oxyline_py_guard::guard]
#[pymethods]
impl BoundsMonitor {
    #[new]
    fn new(transport: &Bound<'_, PyAny>) -> PyResult<Self> {
        let spec = transport_spec(transport)?;
        Ok(BoundsMonitor(
            monitor::Monitor::new(spec.as_ref()).map_err(to_py)?,
        ))
    }

    /// Take the next recorded rows: times, vessel names, recorded segments per vessel, each
    /// species' arrays, (flow_in, flow_out) when both are recorded, the oxygen species.
    #[pyo3(signature = (time, vessels, segment_count, species, flows, oxygen))]
    fn update(
        &mut self,
        time: PyReadonlyArray1<'_, f64>,
        vessels: Vec<String>,
        segment_count: Vec<usize>,
        species: Vec<SpeciesArrays<'_>>,
        flows: Option<(PyReadonlyArray2<'_, f64>, PyReadonlyArray2<'_, f64>)>,
        oxygen: Option<String>,
    ) -> PyResult<()> {
        let time = time.as_array().to_vec();
        let planes: Vec<SpeciesPlanes<'_>> = species.iter().map(SpeciesPlanes::new).collect();
        let flows = flows
            .as_ref()
            .map(|(a, b)| (Grid(a.as_array()), Grid(b.as_array())));
        self.0.update(&Chunk {
            time: &time,
            vessels: &vessels,
            segment_count: &segment_count,
            species: planes.iter().map(SpeciesPlanes::rows).collect(),
            flows: flows
                .as_ref()
                .map(|(a, b)| (a as &dyn Table, b as &dyn Table)),
            oxygen: oxygen.as_deref(),
        });
        Ok(())
    }

    /// Every finding so far (species by species: bounds, then balance; then the
    /// tl-quasisteady validity), as the warnings word them.
    fn messages(&self) -> Vec<String> {
        self.0.messages()
    }
}

/// [min, max] of a species' inlet, backflow, initial and wall values (its maximum-principle
/// range, mol/m³), or None for a species with a prescribed source (a `flux` wall).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn species_bounds(species: &Bound<'_, PyAny>) -> PyResult<Option<(f64, f64)>> {
    let sp: SpeciesSpec =
        crate::reader::de::read(species, || "transport species".into()).map_err(to_py)?;
    monitor::species_bounds(&sp).map_err(to_py)
}
