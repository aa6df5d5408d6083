//! PyO3 binding of oxyline-core (module `oxyline._core`). Only glue lives here: argument
//! conversion, error mapping, GIL release with periodic Ctrl-C checks, zero-copy results.

use numpy::IntoPyArray;
use oxyline_core::output::{
    BALANCE_VARIABLES, SEGMENT_VARIABLES, SPECIES_SEGMENT_VARIABLES, SPECIES_VESSEL_VARIABLES,
    TISSUE_BALANCE_VARIABLES, TISSUE_SEGMENT_VARIABLES, TISSUE_VESSEL_VARIABLES, VESSEL_VARIABLES,
};
use pyo3::prelude::*;

mod arterial_laws;
mod calibrate;
mod calibration;
mod checkpoint;
mod closed_loop;
mod closed_loop_params;
mod ensemble;
mod errors;
mod monitor;
mod network;
mod reader;
mod results;
mod settings;
mod svzerod;
mod svzerod_rows;
mod targets;
mod trees;
mod windkessel_trees;

use errors::to_py;
use results::ArrayPair;

// the core's multi-MB vectors on their own mappings, handed back when freed (see
// `oxyline_core::run::large_blocks`): a large run's setup leaves no freed pages resident under its later blocks
#[global_allocator]
static ALLOCATOR: oxyline_core::run::large_blocks::LargeBlocksMapped =
    oxyline_core::run::large_blocks::LargeBlocksMapped;

// the schema names the columns `Transport::observe` writes, one name per column
const _: () = assert!(oxyline_core::transport::VESSEL_COLUMNS == SPECIES_VESSEL_VARIABLES.len());
const _: () = assert!(oxyline_core::transport::SEGMENT_COLUMNS == SPECIES_SEGMENT_VARIABLES.len());
const _: () = assert!(oxyline_core::transport::BALANCE_COLUMNS == BALANCE_VARIABLES.len());
const _: () = assert!(
    oxyline_core::transport::TISSUE_VESSEL_COLUMNS == TISSUE_VESSEL_VARIABLES.len()
        && oxyline_core::transport::TISSUE_SEGMENT_COLUMNS == TISSUE_SEGMENT_VARIABLES.len()
        && oxyline_core::transport::TISSUE_BALANCE_COLUMNS == TISSUE_BALANCE_VARIABLES.len()
);

/// (E(t), V_rest(t)) of a canonical chamber spec (JSON text) at `times`: the drop-in rebuilds
/// a chamber's volume V = V_rest + P/E from its recorded pressure (docs/svzerod.md).
#[oxyline_py_guard::guard]
#[pyfunction]
fn chamber_elastance<'py>(
    py: Python<'py>,
    name: &str,
    chamber_json: &str,
    times: Vec<f64>,
) -> PyResult<ArrayPair<'py>> {
    let spec: oxyline_core::model::ChamberSpec = oxyline_core::model::from_json(chamber_json)
        .map_err(|e| to_py(oxyline_core::Error::model(format!("chamber '{name}'"), e)))?;
    let law = oxyline_core::assemble::chamber_elastance(name, &spec).map_err(to_py)?;
    let (e, v): (Vec<f64>, Vec<f64>) = times.iter().map(|&t| law.at(t)).unzip();
    Ok((e.into_pyarray(py), v.into_pyarray(py)))
}

/// A canonical waveform spec (JSON text) of `element` evaluated by the core at `times`: the
/// svZeroDSolver writer samples a waveform with it (no second evaluator in Python).
#[oxyline_py_guard::guard]
#[pyfunction]
fn waveform_values<'py>(
    py: Python<'py>,
    element: &str,
    spec_json: &str,
    times: Vec<f64>,
) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
    let spec: oxyline_core::waveform::WaveformSpec = oxyline_core::model::from_json(spec_json)
        .map_err(|e| to_py(oxyline_core::Error::model(element, e)))?;
    let w = oxyline_core::waveform::Waveform::from_spec(&spec, element).map_err(to_py)?;
    let v: Vec<f64> = times.iter().map(|&t| w.eval(t)).collect();
    Ok(v.into_pyarray(py))
}

/// Estimated peak bytes of a model (`oxyline_core::run::memory::model_bytes`): `segments`
/// flow segments, `elements` vessels and boundary conditions, `cells` transport cells per
/// segment and `species` species.
#[oxyline_py_guard::guard]
#[pyfunction]
fn model_bytes(segments: usize, elements: usize, cells: f64, species: usize) -> f64 {
    oxyline_core::run::memory::model_bytes(segments, elements, cells, species)
}

/// Bytes of the error control's state (`oxyline_core::run::memory::controlled_bytes`):
/// `unknowns` circuit unknowns, `species_cells` transport cells × species, and whether the
/// integrator is the explicit pair (`dopri5`) rather than generalized-α.
#[oxyline_py_guard::guard]
#[pyfunction]
fn controlled_bytes(unknowns: usize, species_cells: f64, explicit: bool) -> f64 {
    use oxyline_core::run::memory::{Controlled, controlled_bytes};
    let integrator = if explicit {
        Controlled::ExplicitPair
    } else {
        Controlled::GeneralizedAlpha
    };
    controlled_bytes(unknowns, species_cells, integrator)
}

#[pymodule]
mod _core {
    #[pymodule_export]
    use super::arterial_laws::{
        circulatory_autogen_inflow, circulatory_autogen_youngs_modulus, cycle_mean, murray_radius,
        openbf_characteristic_impedance, openbf_friction_viscosity, openbf_linearised,
        openbf_taper_distal_radius, openbf_wall_thickness, openbf_wall_viscosity,
        pwdb_aortic_inflow, pwdb_check_terminals, pwdb_diameter_segments, pwdb_fit_k3,
        pwdb_outlets, pwdb_subject_geometry, pwdb_wall_properties, structured_tree_root,
        terminal_compartment, thin_wall_compliance, wall_thickness_law,
    };
    #[pymodule_export]
    use super::calibrate::{
        parameter_value, set_parameters, tangent_sensitivities, target_gradients, target_tangents,
    };
    #[pymodule_export]
    use super::calibration::CalibrationProblem;
    #[pymodule_export]
    use super::closed_loop::{
        closed_loop_heart_model, closed_loop_heart_run_options, closed_loop_heart_value,
        closed_loop_run, closed_loop_sensitivities,
    };
    #[pymodule_export]
    use super::closed_loop_params::closed_loop_layout;
    #[pymodule_export]
    use super::svzerod_rows::{svzerod_output_rows, svzerod_rcr_cycles};
    #[pymodule_export]
    use super::targets::{foot_time, pulse_wave_path, target_signals, transit_time};
    #[pymodule_export]
    use super::trees::{
        StructuredTrees, facilitation_factor, grow_structured_tree, linear_facilitation_factor,
        match_structured_tree, structured_tree_count_bound, structured_tree_wall,
    };
    #[pymodule_export]
    use super::windkessel_trees::{outlet_root_radius, windkessel_tree_match};
    #[pymodule_export]
    use super::{
        chamber_elastance,
        checkpoint::{check_checkpoint_meta, check_resumed, checkpoint_interval},
        controlled_bytes,
        ensemble::{Ensemble, column_keys, merge_patch},
        errors::{_panic_probe, ModelError, ResourceError, SolverError, UnstableTimeStep},
        model_bytes,
        monitor::{BoundsMonitor, species_bounds},
        network::Network,
        reader::NativeParts,
        reader::formats::{openbf_mean_pressures, svzerod_periodic_table},
        reader::model::{canonical_model, forcing_frequency, read_model},
        reader::schema::{read_conditions, read_vessels, resolve_settings, transport_section},
        reader::variant::VariantReader,
        results::ColumnStatsFold,
        settings::{run_facts, segmentation_facts},
        waveform_values,
    };

    use pyo3::types::{PyDictMethods, PyModuleMethods};

    #[pymodule_init]
    fn init(m: &pyo3::Bound<'_, pyo3::types::PyModule>) -> pyo3::PyResult<()> {
        m.add("__version__", env!("CARGO_PKG_VERSION"))?;
        // mol per mL O2 (STPD): the closed loop reports its O2 flows in mL/min
        m.add("ML_O2", oxyline_core::transport::closed_loop_params::ML_O2)?;
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
        // PWDB's constants (`oxyline_core::model::pwdb`): the front end names no value itself
        {
            use oxyline_core::model::pwdb;
            m.add("PWDB_MMHG", pwdb::MMHG)?;
            m.add("PWDB_DENSITY", pwdb::DENSITY)?;
            m.add("PWDB_VISCOSITY", pwdb::VISCOSITY)?;
            m.add("PWDB_OUTFLOW_PRESSURE", pwdb::OUTFLOW_PRESSURE)?;
            m.add("PWDB_POISSON_RATIO", pwdb::POISSON_RATIO)?;
            m.add(
                "PWDB_PROXIMAL_AORTA",
                pwdb::geometry::PROXIMAL_AORTA.to_vec(),
            )?;
            use oxyline_core::model::openbf;
            m.add("OPENBF_POISSON_RATIO", openbf::POISSON_RATIO)?;
            m.add("OPENBF_VISCO_B0", openbf::VISCO_B0)?;
            m.add("OPENBF_VISCO_B1", openbf::VISCO_B1)?;
        }
        // the run settings' names and the transport sections' key sets (`oxyline_core::model`)
        {
            m.add("STARTS", oxyline_core::model::settings::STARTS.to_vec())?;
            m.add("OPTIONS", oxyline_core::model::settings::OPTIONS.to_vec())?;
            use oxyline_core::model::species;
            m.add("OXYGEN_KEYS", species::OXYGEN_KEYS.to_vec())?;
            m.add("TRANSPORT_KEYS", species::TRANSPORT_KEYS.to_vec())?;
            m.add("SPECIES_KEYS", species::SPECIES_KEYS.to_vec())?;
            let walls = pyo3::types::PyDict::new(m.py());
            for (model, keys) in species::WALL_KEYS {
                walls.set_item(*model, keys.to_vec())?;
            }
            m.add("WALL_KEYS", walls)?;
        }
        // the run settings `Network.simulate` and `Ensemble.run` take as `**settings`
        m.add("RUN_SETTINGS", super::settings::KEYS.to_vec())?;
        // checkpoints and memory estimates (`oxyline_core::run::{checkpoint, memory}`)
        m.add(
            "CHECKPOINT_VERSION",
            oxyline_core::run::checkpoint::CHECKPOINT_VERSION,
        )?;
        {
            use oxyline_core::run::checkpoint::meta;
            m.add("CHECKPOINT_FORMAT", meta::FORMAT)?;
            m.add("CHECKPOINT_FILE_VERSION", meta::FILE_VERSION)?;
            m.add("CHECKPOINT_STATE_SCALARS", meta::STATE_SCALARS.to_vec())?;
            m.add("CHECKPOINT_MAX_EVERY_SECONDS", meta::MAX_EVERY_SECONDS)?;
            // the settings a resumed run may change (a checkpoint stores the others)
            m.add("RUN_CONTROL", meta::RUN_CONTROL.to_vec())?;
        }
        {
            use oxyline_core::run::memory as mem;
            m.add("FLOW_BYTES_PER_SEGMENT", mem::FLOW_BYTES_PER_SEGMENT)?;
            m.add("TRANSPORT_BYTES_PER_CELL", mem::TRANSPORT_BYTES_PER_CELL)?;
            m.add("BYTES_PER_ELEMENT", mem::BYTES_PER_ELEMENT)?;
            m.add(
                "PACKED_DESCRIPTION_SEGMENTS",
                mem::PACKED_DESCRIPTION_SEGMENTS,
            )?;
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
