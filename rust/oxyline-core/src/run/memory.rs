//! Memory estimates made before anything large is allocated: a model with
//! 10⁹ segments, or an output of every cycle of a long run, is refused with a typed
//! [`Error::Resource`] giving the estimate and the setting to change, instead of taking all
//! RAM and aborting the process.
//!
//! The estimate is the core's own layout: the bytes each owner allocates per flow segment, per
//! transport cell and species and per vessel or boundary condition (heap capacities counted
//! with a counting allocator, `examples/mem_stages.rs` and `examples/transport_memory.rs`;
//! `tests/memory_layout.rs` checks the plan's, the transport state's and the circuit's against
//! the heap they hold), plus what stays resident beyond it at a whole run's peak, measured
//! with `benches/profile_memory.py`. It is meant to be at or somewhat above the real peak
//! (`tests/test_resources.py` states the factor), never far below it.

use crate::error::{Error, Result};

/// Circuit per flow segment: its node (40 bytes), its branch (~50) and their labels (~60),
/// kept beside the DAE for the impedance and `circuit()` reads.
pub const CIRCUIT_PER_SEGMENT: f64 = 150.0;
/// The same above [`RELEASED_CIRCUIT_SEGMENTS`] segments, whose node and branch tables are
/// dropped once the DAE and the transport plan are built: the labels (shared with the DAE).
pub const RELEASED_CIRCUIT_PER_SEGMENT: f64 = 60.0;
/// DAE per flow segment: the mass diagonal (~23 bytes) and the flow matrix F in CSR (~87,
/// with 32-bit row starts).
pub const DAE_PER_SEGMENT: f64 = 110.0;
/// Output probes (the segments' unknowns) and the other tables per segment: DAE elements,
/// forcing, boundary rows (~37 + ~90 bytes).
pub const TABLES_PER_SEGMENT: f64 = 127.0;
/// The run's state per flow segment (two unknowns each): the tree LU's arrays, y, ẏ and the
/// cycle-end copy, the generalized-α residual and the recorder's row in flight.
pub const RUN_PER_SEGMENT: f64 = 290.0;
/// The transport plan per cell and species: its segment with wall and volume (72 bytes), the
/// wall law (68), faces and their incidence (~25), wall pieces (28), output layout (22), the
/// 32-bit cell and node maps, volumes and sources (~102; a tree keeps no domain list).
pub const PLAN_PER_CELL: f64 = 318.0;
/// The transport run's state per cell and species: the sweep's node arrays, the amounts and
/// concentrations and the species' output row.
pub const TRANSPORT_RUN_PER_CELL: f64 = 108.0;
/// The core's bytes per vessel and per boundary condition beyond their segments: the segment
/// recipe, names, the boundary's law and rows.
pub const CORE_PER_ELEMENT: f64 = 150.0;
/// The user's own description per vessel and per boundary condition (their dicts), alive
/// while the model loads: a flow-only run of a large model peaks then.
pub const LOAD_PER_ELEMENT: f64 = 400.0;
/// The Python model's copy of the description per vessel and per boundary condition, held
/// while it runs; a model above [`PACKED_DESCRIPTION_SEGMENTS`] segments keeps it packed (a
/// few bytes per segment).
pub const DESCRIPTION_PER_ELEMENT: f64 = 1500.0;
/// Models above this many segments keep their description packed (`oxyline.model`).
pub const PACKED_DESCRIPTION_SEGMENTS: usize = 500_000;
/// Networks above this many segments drop their circuit's node and branch tables once the
/// DAE and the transport plan are built (`Circuit::release_tables`): a run reads neither, and
/// the circuit's diagnostics and the impedance assemble the model anew.
pub const RELEASED_CIRCUIT_SEGMENTS: usize = 500_000;
/// Resident bytes per segment beyond the layout at a whole run's peak: the load's freed pages
/// (the parsed model, the assembly's rows, the JSON text) stay resident under the run's state,
/// and the run's setup (steady start, factors, first steps) peaks on top of it. Measured:
/// ~10 000-segment models and `benches/profile_memory.py` (1.05 M segments) against the
/// layout's sum.
pub const RESIDENT_PER_SEGMENT: f64 = 165.0;

/// Peak bytes per flow segment: circuit, DAE, tables, run state, and what stays resident.
pub const FLOW_BYTES_PER_SEGMENT: f64 = CIRCUIT_PER_SEGMENT
    + DAE_PER_SEGMENT
    + TABLES_PER_SEGMENT
    + RUN_PER_SEGMENT
    + RESIDENT_PER_SEGMENT;
/// Peak bytes per transport cell and species, measured (the peak's increment over a
/// flow-only run of the same network: ~280 B at 10 000 segments and at 1.05 M): below the
/// plan's and the transport state's heap ([`PLAN_PER_CELL`] + [`TRANSPORT_RUN_PER_CELL`]),
/// because a flow-only run peaks while it loads and the plan and the state fill part of the
/// room the load leaves behind.
pub const TRANSPORT_BYTES_PER_CELL: f64 = 300.0;
/// Peak bytes per vessel and per boundary condition beyond their segments, of a model whose
/// description is not packed.
pub const BYTES_PER_ELEMENT: f64 = CORE_PER_ELEMENT + LOAD_PER_ELEMENT + DESCRIPTION_PER_ELEMENT;

/// Estimated peak bytes of a model with `segments` flow segments, `elements` vessels and
/// boundary conditions, `cells` transport cells per segment (0 without transport) and
/// `species` species.
pub fn model_bytes(segments: usize, elements: usize, cells: f64, species: usize) -> f64 {
    let s = segments as f64;
    let per_element = if segments > PACKED_DESCRIPTION_SEGMENTS {
        CORE_PER_ELEMENT + LOAD_PER_ELEMENT
    } else {
        BYTES_PER_ELEMENT
    };
    let released = if segments > RELEASED_CIRCUIT_SEGMENTS {
        CIRCUIT_PER_SEGMENT - RELEASED_CIRCUIT_PER_SEGMENT
    } else {
        0.0
    };
    s * (FLOW_BYTES_PER_SEGMENT - released)
        + s * cells * species as f64 * TRANSPORT_BYTES_PER_CELL
        + elements as f64 * per_element
}

/// The error-controlled integrators' state per circuit unknown (bytes), beyond the fixed-step
/// state [`FLOW_BYTES_PER_SEGMENT`] measured: counted from their vectors.
///
/// * generalized-α (`run::adaptive::Adaptive`): the start state and rate, the two accepted
///   states before it (the error estimate's extrapolation), the local error, the peaks of
///   |y|, |ẏ|, |ÿ|, the accumulation frequency, atol, scale and error weight: 12 f64; the
///   algebraic flag, flow group and algebraic index: 9 bytes.
/// * the explicit pair (`integrate::explicit_pair::Stages`, `run::explicit::Explicit`): seven
///   stage rates (the dense output's coefficients are formed from them), the stage, the start
///   and the error estimate, the peaks of |y|, |ẏ|, |ÿ|, the accumulation frequency, atol and
///   scale: 16 f64; the differential flag and flow group: 5 bytes.
pub const CONTROLLED_BYTES_PER_UNKNOWN: [f64; 2] = [12.0 * 8.0 + 9.0, 16.0 * 8.0 + 5.0];
/// The same per transport cell and species (each one amount unknown).
///
/// * generalized-α: the amounts at the step's start, the concentrations at the start, before
///   and at the end, their peaks, the cells' volumes at the start; the interpolated amounts and
///   volumes of species output rows: 8 f64.
/// * the explicit pair: the species' seven stage rates, stage, start and error, atol and
///   peak: 12 f64.
pub const CONTROLLED_BYTES_PER_CELL: [f64; 2] = [8.0 * 8.0, 12.0 * 8.0];

/// The integrator of an error-controlled run, for [`controlled_bytes`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Controlled {
    GeneralizedAlpha,
    ExplicitPair,
}

/// Bytes of the error control's state of a run with `unknowns` circuit unknowns and
/// `species_cells` transport cells × species (0 without transport), for `integrator`.
pub fn controlled_bytes(unknowns: usize, species_cells: f64, integrator: Controlled) -> f64 {
    let k = match integrator {
        Controlled::GeneralizedAlpha => 0,
        Controlled::ExplicitPair => 1,
    };
    unknowns as f64 * CONTROLLED_BYTES_PER_UNKNOWN[k] + species_cells * CONTROLLED_BYTES_PER_CELL[k]
}

/// Estimated peak bytes of a run of an assembled network: its model ([`model_bytes`], from
/// the sizes the core allocated: `segments`, `elements` vessels and boundary conditions,
/// `species_cells` transport cells × species, 0 without transport) and the error control's
/// state ([`controlled_bytes`] of its `unknowns`; None: a fixed step).
pub fn run_bytes(
    segments: usize,
    elements: usize,
    species_cells: f64,
    unknowns: usize,
    controlled: Option<Controlled>,
) -> f64 {
    let per_segment = if segments > 0 {
        species_cells / segments as f64
    } else {
        0.0
    };
    model_bytes(segments, elements, per_segment, 1)
        + controlled.map_or(0.0, |c| controlled_bytes(unknowns, species_cells, c))
}

/// What the user can change when a model is too large.
pub const MODEL_ADVICE: &str = "use fewer segments (segmentation max_length, a vessel's \
segments) or raise the limit (simulation: max_memory in the model, the environment variable \
OXYLINE_MAX_MEMORY)";

/// Refuse a model of `segments` segments whose estimate exceeds `limit` (bytes; None: no
/// limit).
pub fn check_model(
    name: &str,
    segments: usize,
    elements: usize,
    transport: Option<(f64, usize)>,
    limit: Option<f64>,
) -> Result<()> {
    let Some(limit) = limit else {
        return Ok(());
    };
    let (cells, species) = transport.unwrap_or((0.0, 0));
    let need = model_bytes(segments, elements, cells, species);
    if need > limit {
        return Err(Error::over_limit(
            format!("model '{name}' ({segments} segments)"),
            need,
            limit,
            MODEL_ADVICE,
        ));
    }
    Ok(())
}

/// Matrix products of at most this order in every dimension (m·n·k ≤ 16³) go through faer's
/// allocation-free small kernels (`nano-gemm`), never the packing buffers.
pub const SMALL_PRODUCT_ORDER: usize = 16;

/// Bytes of the dense linear algebra's scratch: the matrix products (faer's gemm, used by the
/// eigenvalue estimate of RK4's step and by supernodal sparse factorisations) take packing
/// buffers of twice the L3 cache the first time a thread multiplies matrices larger than
/// [`SMALL_PRODUCT_ORDER`], and that allocation aborts the process when it fails. Twice the
/// L3 size the kernel reports (at most 128 MiB); the library's own default cache (2 MiB)
/// when it reports none. A run whose plan has no such product (a tree or simplicial sparse
/// factorisation, no RK4 step estimate of more than that many unknowns) takes none.
pub fn scratch_bytes() -> f64 {
    static BYTES: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *BYTES.get_or_init(|| {
        let l3 = std::fs::read_to_string("/sys/devices/system/cpu/cpu0/cache/index3/size")
            .ok()
            .and_then(|t| cache_size(t.trim()))
            .unwrap_or(2.0 * 1024.0 * 1024.0);
        (2.0 * l3).min(128.0 * 1024.0 * 1024.0)
    })
}

/// A sysfs cache size ("32768K", "2M", "1G", "512") in bytes.
fn cache_size(text: &str) -> Option<f64> {
    let (digits, scale) = match text.chars().last()? {
        'K' => (&text[..text.len() - 1], 1024.0),
        'M' => (&text[..text.len() - 1], 1024.0 * 1024.0),
        'G' => (&text[..text.len() - 1], 1024.0 * 1024.0 * 1024.0),
        _ => (text, 1.0),
    };
    digits.parse::<f64>().ok().map(|v| v * scale)
}

thread_local! {
    /// Whether this thread has shown it can hold the linear algebra's scratch (the library
    /// keeps it per thread once allocated).
    static SCRATCH_PROVED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Before the first dense matrix product of a thread (RK4's step estimate, a supernodal
/// factorisation): reserve (and release at once) the linear algebra's scratch
/// ([`scratch_bytes`]) with a fallible allocation, so that a process near its address-space
/// limit (`ulimit -v`) or out of memory gets a typed [`Error::Resource`] instead of the
/// allocator's abort. Once per thread.
pub fn check_scratch() -> Result<()> {
    if SCRATCH_PROVED.with(|p| p.get()) {
        return Ok(());
    }
    let bytes = scratch_bytes();
    let mut probe: Vec<u8> = Vec::new();
    probe
        .try_reserve_exact(bytes as usize)
        .map_err(|_| Error::Resource {
            what: "run".into(),
            bytes: bytes as u64,
            message: format!(
                "cannot reserve the {} the linear algebra's matrix products take per thread \
                 (out of memory, or above the address-space limit `ulimit -v`); free memory \
                 or raise the limit",
                crate::error::human_bytes(bytes)
            ),
        })?;
    drop(probe);
    SCRATCH_PROVED.with(|p| p.set(true));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_billion_segments_is_refused_with_the_estimate_and_the_setting() {
        let e = check_model("big", 1_000_000_000, 3, None, Some(8e9)).unwrap_err();
        let msg = e.to_string();
        // a packed description and a released circuit above 500 000 segments: the core's bytes
        // per element only, the circuit's labels only
        let flow = FLOW_BYTES_PER_SEGMENT - CIRCUIT_PER_SEGMENT + RELEASED_CIRCUIT_PER_SEGMENT;
        let need = 1e9 * flow + 3.0 * (CORE_PER_ELEMENT + LOAD_PER_ELEMENT);
        assert!(matches!(e, Error::Resource { bytes, .. } if bytes == need as u64));
        let told = format!("needs about {}", crate::error::human_bytes(need));
        assert!(msg.starts_with(&format!("model 'big' (1000000000 segments): {told}")));
        assert!(msg.contains("max_memory = 8.000 GB") && msg.contains("max_length"));
        assert!(check_model("small", 1000, 3, Some((1.0, 1)), Some(8e9)).is_ok());
        assert!(check_model("any", usize::MAX / 2, 3, None, None).is_ok());
    }

    #[test]
    fn the_controlled_state_counts_the_pair_above_generalized_alpha() {
        let ga = controlled_bytes(1000, 10.0, Controlled::GeneralizedAlpha);
        let dp = controlled_bytes(1000, 10.0, Controlled::ExplicitPair);
        assert_eq!(ga, 1000.0 * 105.0 + 10.0 * 64.0);
        assert_eq!(dp, 1000.0 * 133.0 + 10.0 * 96.0);
        assert_eq!(controlled_bytes(0, 0.0, Controlled::ExplicitPair), 0.0);
    }

    #[test]
    fn sysfs_cache_sizes_are_read_in_bytes() {
        assert_eq!(cache_size("32768K"), Some(32.0 * 1024.0 * 1024.0));
        assert_eq!(cache_size("2M"), Some(2.0 * 1024.0 * 1024.0));
        assert_eq!(cache_size("512"), Some(512.0));
        assert_eq!(cache_size("x"), None);
        let s = scratch_bytes();
        assert!((4096.0..=128.0 * 1024.0 * 1024.0).contains(&s));
        assert!(check_scratch().is_ok() && check_scratch().is_ok());
    }
}
