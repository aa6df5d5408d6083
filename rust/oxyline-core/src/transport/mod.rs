//! Species transport on the flow circuit (docs/physics.md §2.5): the conservative finite-volume
//! form of the paper's oxygen transmission line.
//!
//! * Cells are the circuit nodes that hold lumen volume; V_n = V0_n + C_n (P_n − P_ref) is taken
//!   from the flow state, so dV_n/dt equals the net inflow exactly and a uniform field stays
//!   uniform (free-stream preservation).
//! * Faces are the branches (and flow sources); each carries F = Q · C_t,upwind, upwind on the
//!   sign of Q. The state is the amount N (mol) per cell and species, so every face flux leaves
//!   one cell and enters another: Σ N + I_out + I_wall + I_decay − I_in is an exact linear
//!   invariant, which any Runge–Kutta method preserves to round-off.
//! * Capacitance- and volume-free nodes inside the network (lumped vessels, the inlet node of an
//!   L arrangement) are pass-through mixing points; nodes of boundary conditions (Windkessel,
//!   distal and prescribed-pressure nodes) are outside the domain: flow into them is outflow,
//!   flow out of them carries the inlet or backflow concentration.
//! * The advected quantity is the total concentration C_t (free + bound); wall exchange acts
//!   on the free concentration c = binding⁻¹(C_t) (docs/physics.md §4.3).
//!
//! Two integrations share this description: the explicit right-hand side (`rhs`), integrated
//! monolithically with the flow by RK4, and a backward-Euler step (`implicit_step`) used after
//! each generalized-α flow step, solved by one sweep in flow order (an M-matrix that is
//! triangular whenever the directed flow graph is acyclic, e.g. on every tree).

use crate::circuit::{Circuit, Dae};
use crate::closure::{self, SegmentLaw, SegmentWall, WallSpec};
use crate::error::{Error, Result};
use crate::hemoglobin::{Binding, HillAnchor};
pub use crate::model::transport::{Formulation, SpeciesSpec, TransportSpec};
use crate::output::Probes;
use crate::waveform::Waveform;
use std::sync::Arc;

mod boundary_chunks; // the boundary faces' passes on the run's threads
mod build;
pub mod closed_loop; // closed circulation: compartments, lungs
pub mod closed_loop_balance; // its flow table's periodic volumes
pub mod closed_loop_circulation; // its circulation, built from the parameter set
pub mod closed_loop_heart; // the heart run that drives its flows
pub mod closed_loop_heart_series; // what the loop reads from that run, by name
pub mod closed_loop_heart_tangent; // that run's flow table's derivative by heart parameters
pub mod closed_loop_heart_values; // the set's own values of its heart model
pub mod closed_loop_params; // its parameter set in published units, to SI
pub mod closed_loop_run; // the whole run in one call: settings, heart, O2
pub mod closed_loop_sensitivity; // its periodic O2 state's exact derivatives
pub mod closed_loop_summary; // its cycle's summary: SaO2, SvO2, VO2, Fick
pub mod closed_loop_tree; // its segment-resolved arterial tree
pub mod compartment;
mod core; // the implicit solve of a domain with loops
mod fused;
mod implicit;
mod laws;
pub mod lung;
mod memory;
mod observe;
mod parallel; // the fused tree step on the run's threads
mod plan;
pub mod renewal; // inlet renewal's per-vessel flows and factors
mod rhs;
mod state;
mod stiffness;
pub mod tangent; // the species step's tangent by oxygen parameters
mod tissue; // wall/tissue compartment
mod wall_flux;
pub use stiffness::ReactionRate;
pub use tissue::{TISSUE_BALANCE_COLUMNS, TISSUE_SEGMENT_COLUMNS, TISSUE_VESSEL_COLUMNS};

pub use plan::Plan;
#[allow(unused_imports)]
use plan::*;
#[allow(unused_imports)]
use {build::*, core::*, implicit::*, laws::*, observe::*, rhs::*, state::*};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum End {
    Node(usize),
    Boundary(usize),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Cell,
    Mixing,
    Exterior,
}

/// A face between two ends, oriented `from` → `to`: 12 bytes (a million-segment tree's plan
/// holds ~1.3 M of them; with `usize` fields it was 40). The flow unknown, and each end as a
/// node's index or a boundary's with [`Face::BOUNDARY`] set: the plan refuses a network of
/// 2^31 nodes or more when built (`Transport::build`).
#[derive(Debug, Clone, Copy)]
struct Face {
    unknown: u32,
    from: u32,
    to: u32,
}

impl Face {
    const BOUNDARY: u32 = 1 << 31;
    /// The unknown of an interior face of a refined cell, whose flow `Chain::flows` derives
    /// from the unknowns.
    const NO_UNKNOWN: u32 = u32::MAX;

    /// The face from `from` to `to` carrying flow unknown `unknown` (`usize::MAX`: none).
    fn new(unknown: usize, from: End, to: End) -> Face {
        Face {
            unknown: if unknown == usize::MAX {
                Self::NO_UNKNOWN
            } else {
                unknown as u32
            },
            from: Self::pack(from),
            to: Self::pack(to),
        }
    }

    fn pack(e: End) -> u32 {
        match e {
            End::Node(n) => {
                debug_assert!(n < Self::BOUNDARY as usize);
                n as u32
            }
            End::Boundary(b) => {
                debug_assert!(b < Self::BOUNDARY as usize);
                b as u32 | Self::BOUNDARY
            }
        }
    }

    #[inline]
    fn unpack(x: u32) -> End {
        if x & Self::BOUNDARY == 0 {
            End::Node(x as usize)
        } else {
            End::Boundary((x & !Self::BOUNDARY) as usize)
        }
    }

    /// Flow unknown (index into y); `usize::MAX` for the interior faces of a refined cell.
    #[inline]
    fn unknown(&self) -> usize {
        if self.unknown == Self::NO_UNKNOWN {
            usize::MAX
        } else {
            self.unknown as usize
        }
    }

    /// The end the face leaves (positive flow runs from it).
    #[inline]
    fn tail(&self) -> End {
        Self::unpack(self.from)
    }

    /// The end the face enters.
    #[inline]
    fn head(&self) -> End {
        Self::unpack(self.to)
    }

    fn set_tail(&mut self, e: End) {
        self.from = Self::pack(e);
    }

    fn set_head(&mut self, e: End) {
        self.to = Self::pack(e);
    }
}

/// A volume node refined into m sub-cells in series (sub-cell 0 = the node itself takes the
/// faces entering it and its flow sources, sub-cell m−1 the faces leaving it). Sub-cell k holds
/// V_n/m, so with Q_A = inflow, Q_B = outflow of the node the interior face k (between
/// sub-cells k−1 and k) carries Q_k = Q_A − (k/m)(Q_A − Q_B): each sub-cell receives
/// dV_n/dt / m, and a uniform field stays uniform.
#[derive(Debug, Clone)]
struct Chain {
    in_faces: Vec<usize>,
    out_faces: Vec<usize>,
    sources: Vec<usize>,
    /// Index of interior face 1; faces 1..m−1 follow.
    first_face: usize,
    m: usize,
}

/// Part of a flow segment's wall seen by one cell: the cell's uptake is share × law(wall).
/// The wall is the segment's own (`sub == Piece::OWN_WALL`), or for a refined node's
/// sub-cell the sub-interval `Plan::sub_walls[sub]`: 24 bytes a piece instead of 48 with a
/// copy of the segment's wall in every piece (`plan::piece_wall`).
#[derive(Debug, Clone)]
struct Piece {
    seg: u32,
    node: u32,
    cell: u32,
    sub: u32,
    share: f64,
}

impl Piece {
    /// `sub` of a piece on its segment's own wall.
    const OWN_WALL: u32 = u32::MAX;
}

#[derive(Debug, Clone)]
enum BoundaryValue {
    Wave(Waveform),
    ZeroGradient,
}

/// Immutable settings of one species (part of the [`Plan`]).
#[derive(Debug, Clone)]
struct SpeciesPlan {
    name: String,
    binding: Binding,
    decay: f64,
    diffusivity: f64,
    boundary: Vec<BoundaryValue>,
    /// The boundaries with a prescribed value (`BoundaryValue::Wave`).
    waves: Vec<usize>,
    walls: Vec<WallSpec>,
    initial_free: f64,
}

/// The wall laws of one species for one cycle-mean flow. The plan holds those of the build
/// (final unless a closure needs the mean flow); a run that sets its mean flow gets its own.
/// Runs share them through an `Arc`.
#[derive(Debug, Clone, Default)]
struct Laws {
    /// Law of every wall piece.
    laws: Vec<SegmentLaw>,
    /// Per cell: Σ share·g, Σ share·g·c_w, Σ share·q of its segments' fixed laws, and
    /// Σ share·q − Σ share·g·c_w (the constant part of the implicit step's wall uptake).
    cell_g: Vec<f64>,
    cell_gcw: Vec<f64>,
    cell_q: Vec<f64>,
    cell_wc: Vec<f64>,
    /// Wall pieces whose conductance follows a time-dependent shear.
    dynamic: Vec<usize>,
    /// Segments with a relaxed Lévêque shear: (segment, τ_BL, cycle-mean |Q|); their
    /// equivalent flows Q̃ = π r³ γ̃/4 are state entries `relax_offset + k`, starting at the
    /// cycle mean.
    relax: Vec<(usize, f64, f64)>,
    /// Per segment: its index in `relax` (`u32::MAX`: none); empty without dynamic pieces.
    relax_of_seg: Vec<u32>,
    relax_offset: usize,
    /// Segments with dynamic pieces (their shear is loaded by `load_shear`).
    dynamic_segs: Vec<usize>,
    /// Prescribed wall fluxes given as time tables: `cell_q`/`cell_wc` of their cells are
    /// set to the current time by `update_wall_flux` (None: no table).
    flux_tables: Option<Arc<wall_flux::FluxTables>>,
    has_wall: bool,
}

/// Per-run state of one species.
#[derive(Debug, Clone)]
struct Species {
    laws: Arc<Laws>,
    /// Per segment with dynamic pieces: the cube root of the flow magnitude its dynamic laws
    /// see (|Q| or Q̃), see `load_shear`; empty without dynamic pieces.
    shear_cbrt: Vec<f64>,
    /// Free concentration per node: warm start of the binding inversion, and reporting
    /// (empty until the run starts, and without binding).
    free: Vec<f64>,
    /// Per node: Taylor anchor of the Hill inversion (cells change little between stages);
    /// empty unless the binding is Hill's.
    anchors: Vec<HillAnchor>,
    /// Total concentration of the mixing points: their lagged value (used when a point has
    /// no outflow, and for zero-gradient backflow into it) is per species.
    mixing_conc: Vec<f64>,
}

#[derive(Debug, Clone)]
struct Segment {
    /// Flow unknown of the segment's branch, and its face (`u32::MAX`: none).
    branch_unknown: u32,
    face: u32,
    /// The segment's circuit nodes and the share of its volume each holds.
    nodes: [u32; 2],
    shares: [f64; 2],
    wall: SegmentWall,
    volume: f64,
    compliance: f64,
}

impl Segment {
    #[inline]
    fn dx(&self) -> f64 {
        self.wall.x1 - self.wall.x0
    }
    /// (node, share) of both ends.
    #[inline]
    fn node_shares(&self) -> [(usize, f64); 2] {
        [
            (self.nodes[0] as usize, self.shares[0]),
            (self.nodes[1] as usize, self.shares[1]),
        ]
    }
}

/// Outputs of one vessel: its first and last face (`usize::MAX`: none), its segment range,
/// and the cells holding a share of its first and last segment at the vessel's ends
/// (`u32::MAX`: none, the end face then is the vessel's end). The inlet of an inverted-L or π
/// vessel lies upstream of its first cell, the outlet of an L or π vessel downstream of its last.
#[derive(Debug, Clone)]
struct OutVessel {
    first: usize,
    last: usize,
    segs: std::ops::Range<usize>,
    inlet_cell: u32,
    outlet_cell: u32,
}

pub const VESSEL_COLUMNS: usize = 5;
pub const SEGMENT_COLUMNS: usize = 5;
pub const BALANCE_COLUMNS: usize = 5;

/// Per-run transport: the shared immutable [`Plan`] and this run's state (amounts live in
/// the integrator's vector; here: per-species laws (shared until a run sets its own mean
/// flow) and free concentrations, scratch). The scratch is allocated when the run starts
/// (`initial_state`), so an unrun prototype holds little beyond the plan.
#[derive(Debug, Clone)]
pub struct Transport {
    /// Immutable topology and species settings, shared between runs (and threads).
    plan: Arc<Plan>,
    species: Vec<Species>,
    /// Compute the per-segment columns in `observe` (off: they are NaN, see
    /// `set_recorded_columns`).
    segment_output: bool,
    // scratch, sized by `ensure_scratch` when the run starts
    vol: Vec<f64>,
    conc: Vec<f64>,
    qf: Vec<f64>,
    qs: Vec<f64>,
    bval: Vec<Option<f64>>,
    /// The species whose values `bval` holds (`usize::MAX`: none).
    bval_species: usize,
    sweep: Sweep,
    /// Transport volumes of the implicit path (evolved with the face flows).
    wvol: Vec<f64>,
    /// Tissue hook: scratch of the implicit wall elimination (empty without tissue).
    tissue: tissue::TissueScratch,
    /// Closed-loop hook: (boundary, total concentration) carried in by that boundary instead
    /// of its prescribed value, set step by step by a closed circulation (`closed_loop_tree`).
    inflow_override: Option<(usize, f64)>,
}

fn bad(element: &str, msg: String) -> Error {
    Error::model(element, msg)
}

impl Transport {
    /// The immutable plan this run shares with every other run of the model.
    pub fn plan(&self) -> &Arc<Plan> {
        &self.plan
    }

    /// A run of `plan` with a fresh state: the build's wall laws (shared), no scratch yet.
    fn from_plan(plan: Arc<Plan>) -> Transport {
        let species = plan
            .base_laws
            .iter()
            .map(|laws| Species {
                laws: Arc::clone(laws),
                shear_cbrt: Vec::new(),
                free: Vec::new(),
                anchors: Vec::new(),
                mixing_conc: Vec::new(),
            })
            .collect();
        Transport {
            plan,
            species,
            segment_output: true,
            vol: Vec::new(),
            conc: Vec::new(),
            qf: Vec::new(),
            qs: Vec::new(),
            bval: Vec::new(),
            bval_species: usize::MAX,
            sweep: Sweep::default(),
            wvol: Vec::new(),
            tissue: tissue::TissueScratch::default(),
            inflow_override: None,
        }
    }

    /// A new run of the model: shares the plan and the build's wall laws (no copy of either)
    /// with a fresh state. Callers keep an unrun prototype and start every run here.
    pub fn new_run(&self) -> Transport {
        Transport::from_plan(Arc::clone(&self.plan))
    }

    /// Size the per-run scratch and per-species state (once per run; cheap afterwards).
    #[inline]
    fn ensure_scratch(&mut self) {
        if self.conc.len() != self.plan.kind.len() {
            self.allocate_scratch();
        }
    }

    #[cold]
    fn allocate_scratch(&mut self) {
        let p = &self.plan;
        let (nn, nc) = (p.kind.len(), p.cells.len());
        self.vol = vec![0.0; nc];
        self.conc = vec![0.0; nn];
        self.qf = vec![0.0; p.faces.len()];
        self.qs = vec![0.0; p.sources.len()];
        self.bval = vec![None; p.boundary_inlet.len()];
        self.bval_species = usize::MAX;
        self.sweep = Sweep::new(nn);
        for (sp, set) in self.species.iter_mut().zip(&p.species) {
            let binding = !set.binding.is_identity();
            sp.free = if binding {
                vec![set.initial_free; nn]
            } else {
                Vec::new()
            };
            sp.anchors = if matches!(set.binding, Binding::Hill { .. }) {
                vec![HillAnchor::default(); nn]
            } else {
                Vec::new()
            };
            if !sp.laws.dynamic_segs.is_empty() {
                sp.shear_cbrt = vec![0.0; p.segments.len()];
            }
        }
    }

    pub fn species_names(&self) -> Vec<String> {
        self.plan.species.iter().map(|s| s.name.clone()).collect()
    }
    pub fn n_cells(&self) -> usize {
        self.plan.cells.len()
    }
    /// Each cell's transport volume after the last step (m³; before the first, its volume
    /// at the start): the amounts of a cell over it are the concentrations the step
    /// transported, which an error-controlled run judges and interpolates.
    pub fn cell_transport_volumes(&self) -> &[f64] {
        if self.wvol.is_empty() {
            &self.vol
        } else {
            &self.wvol
        }
    }
    /// Replace the cells' transport volumes (the dense output of an error-controlled run
    /// observes amounts interpolated within a step over volumes interpolated alike; it
    /// restores the carried state afterwards).
    pub fn set_cell_transport_volumes(&mut self, volumes: &[f64]) {
        if self.wvol.is_empty() {
            self.vol.copy_from_slice(volumes);
        } else {
            self.wvol.copy_from_slice(volumes);
        }
    }
    /// Length of the coupled state: amounts per cell and species, then 4 accumulators per
    /// species (I_in, I_out, I_wall, I_decay), then the relaxed shears of every species.
    pub fn state_len(&self) -> usize {
        self.species.len() * (self.plan.cells.len() + 4)
            + self
                .species
                .iter()
                .map(|s| s.laws.relax.len())
                .sum::<usize>()
            + self.tissue_len() // tissue hook: wall cells and their accumulators
    }
    pub fn formulation(&self) -> Formulation {
        self.plan.formulation
    }
    /// Columns of every species block of `observe` at every output time.
    pub fn columns_per_species(&self) -> usize {
        VESSEL_COLUMNS * self.plan.out_vessels.len()
            + SEGMENT_COLUMNS * self.plan.out_segments.len()
            + BALANCE_COLUMNS
            + self.tissue_columns() // tissue hook (0 without tissue)
    }
    /// The columns of each species block a run records (None: all). When none of them is a
    /// per-segment column, `observe` neither computes nor writes those (`unwritten_columns`),
    /// which keeps the observation of large trees cheap.
    pub fn set_recorded_columns(&mut self, columns: Option<&[usize]>) {
        let seg = VESSEL_COLUMNS * self.plan.out_vessels.len();
        let seg_end = seg + SEGMENT_COLUMNS * self.plan.out_segments.len();
        self.segment_output = columns.is_none_or(|c| c.iter().any(|&k| k >= seg && k < seg_end));
    }
    /// The per-segment columns of each species block that `observe` leaves out of its rows,
    /// as (first column, count): every per-segment column when no run records one
    /// (`set_recorded_columns`), else none (count 0). Rows stay one `f64` per recorded column
    /// instead of carrying ~40 B per segment of NaN (a million-segment tree's output row).
    pub fn unwritten_columns(&self) -> (usize, usize) {
        if self.segment_output {
            (0, 0)
        } else {
            (
                VESSEL_COLUMNS * self.plan.out_vessels.len(),
                SEGMENT_COLUMNS * self.plan.out_segments.len(),
            )
        }
    }
    /// Recorded segments of every output vessel.
    pub fn out_segment_counts(&self) -> Vec<usize> {
        self.plan.out_vessels.iter().map(|v| v.segs.len()).collect()
    }

    /// The branch-flow unknowns of the segments whose wall law reads the step's shear
    /// (instantaneous or relaxed Lévêque walls), species by species.
    pub fn shear_unknowns(&self) -> Vec<usize> {
        let segs = self
            .species
            .iter()
            .flat_map(|sp| sp.laws.dynamic_segs.iter());
        segs.map(|&j| self.plan.segments[j].branch_unknown as usize)
            .collect()
    }

    /// Flow unknowns whose cycle-mean |Q| the closures need (empty: single pass).
    pub fn mean_flow_unknowns(&self) -> Vec<usize> {
        if self
            .plan
            .species
            .iter()
            .any(|s| s.walls.iter().any(|w| w.needs_mean_flow()))
        {
            self.plan
                .segments
                .iter()
                .map(|s| s.branch_unknown as usize)
                .collect()
        } else {
            Vec::new()
        }
    }

    /// Evaluate the segment laws of this run; `mean_abs[j]` is segment j's cycle-mean |Q|
    /// (taken as its forward-flow mean too: a flow without reversal).
    pub fn set_mean_flow(&mut self, mean_abs: &[f64]) -> Result<()> {
        self.set_mean_flows(mean_abs, mean_abs)
    }

    /// Evaluate the segment laws of this run from segment j's cycle-mean |Q| `mean_abs[j]` and
    /// its forward-flow mean `mean_forward[j]` = ⟨max(±Q, 0)⟩ in the direction of the net flow
    /// (docs/physics.md §3.6).
    /// Walls with `flow: inlet-renewal` read the forward mean here (no flow harmonics: the
    /// closed-loop tree); a two-pass run calls `set_mean_flows_renewed`.
    pub fn set_mean_flows(&mut self, mean_abs: &[f64], mean_forward: &[f64]) -> Result<()> {
        self.set_laws(MeanFlows {
            abs: mean_abs,
            forward: mean_forward,
            renewal: &[],
        })
    }

    fn set_laws(&mut self, mean: MeanFlows<'_>) -> Result<()> {
        let laws = Laws::evaluate_all(&self.plan, mean, true)?;
        let nsegs = self.plan.segments.len();
        for (sp, l) in self.species.iter_mut().zip(laws) {
            if !l.dynamic_segs.is_empty() && sp.shear_cbrt.len() != nsegs {
                sp.shear_cbrt = vec![0.0; nsegs];
            }
            sp.laws = Arc::new(l);
        }
        Ok(())
    }

    /// max over cells of (total outflow rate)/V (1/s): dt × this is the upwind Courant number.
    pub fn max_outflow_rate(&mut self, y: &[f64], time: f64) -> f64 {
        self.ensure_scratch();
        if self.volumes(y, time).is_err() {
            return f64::INFINITY;
        }
        self.load_flows(time, y);
        let mut out = vec![0.0; self.plan.cells.len()];
        for (f, &q) in self.plan.faces.iter().zip(&self.qf) {
            let up = if q >= 0.0 { f.tail() } else { f.head() };
            if let End::Node(n) = up {
                if self.plan.node_cell[n] != u32::MAX {
                    out[self.plan.node_cell[n] as usize] += q.abs();
                }
            }
        }
        for ((n, _, _), &q) in self.plan.sources.iter().zip(&self.qs) {
            if q < 0.0 && self.plan.node_cell[*n] != u32::MAX {
                out[self.plan.node_cell[*n] as usize] -= q;
            }
        }
        out.iter()
            .zip(&self.vol)
            .fold(0.0f64, |m, (o, v)| m.max(o / v))
    }

    /// Cell holding most of segment `j`'s volume (its last sub-cell when refined), as an index
    /// into the species block of the state.
    pub fn segment_cell(&self, j: usize) -> Option<usize> {
        self.segment_cells(j).map(|cells| cells.end - 1)
    }

    /// Cells (sub-cells in flow order, contiguous in the state) of the node holding most of
    /// segment `j`'s volume.
    pub fn segment_cells(&self, j: usize) -> Option<std::ops::Range<usize>> {
        let seg = self.plan.segments.get(j)?;
        let (n, _) = seg
            .node_shares()
            .into_iter()
            .fold((usize::MAX, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        let (a, b) = (
            self.plan.node_cell[n],
            self.plan.node_cell[self.plan.last_sub(n)],
        );
        (a != u32::MAX).then_some(a as usize..b as usize + 1)
    }

    /// One classical RK4 step of the species state alone, the flow state being prescribed:
    /// `flow(t, y)` writes the flow unknowns at time t. This is the "prescribed flow" path used
    /// for rigid tubes, whose flow-driven circuits are index-2 DAEs that RK4 cannot integrate;
    /// the transport kernel is the same `rhs` as in the monolithic step.
    pub fn step_prescribed(
        &mut self,
        time: f64,
        dt: f64,
        flow: &mut dyn FnMut(f64, &mut [f64]),
        y: &mut [f64],
        z: &mut [f64],
        stages: &mut crate::rk4::CoupledStages,
    ) -> Result<()> {
        crate::rk4::rk4_ode(time, dt, z, stages, &mut |t, zs, dzs| {
            flow(t, y);
            self.rhs(t, y, zs, dzs)
        })
    }

    /// Largest relative change of the amounts between two states (periodicity check).
    pub fn relative_change(&self, a: &[f64], b: &[f64]) -> f64 {
        let n = self.species.len() * self.plan.cells.len();
        let scale = a[..n]
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()))
            .max(1e-300);
        let lumen = a[..n]
            .iter()
            .zip(&b[..n])
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / scale;
        if self.plan.tissue.is_empty() {
            lumen
        } else {
            lumen.max(self.tissue_relative_change(a, b)) // tissue hook: the wall's own change
        }
    }
}

/// Concentration carried into the domain by a boundary: its prescribed value, or (zero-gradient
/// backflow) the lagged value of the node it enters.
#[inline]
fn inflow_value(prescribed: Option<f64>, lagged: f64) -> f64 {
    prescribed.unwrap_or(lagged)
}

#[inline]
fn account(inlet: bool, flux_into_domain: f64, i_in: &mut f64, i_out: &mut f64) {
    if inlet {
        *i_in += flux_into_domain;
    } else {
        *i_out -= flux_into_domain;
    }
}

/// Flow of face `fi` and its ends ordered along the flow (upstream, downstream). A free function so
/// that callers holding a mutable borrow of other transport fields can use it.
#[inline]
fn oriented(faces: &[Face], qf: &[f64], fi: usize) -> (f64, End, End) {
    let f = &faces[fi];
    let q = qf[fi];
    if q >= 0.0 {
        (q, f.tail(), f.head())
    } else {
        (q, f.head(), f.tail())
    }
}
