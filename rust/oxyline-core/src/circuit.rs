//! The assembled lumped circuit: capacitive nodes (pressure unknowns) and series
//! R–L(–stenosis) branches (flow unknowns), written as one DAE
//!
//!   E ẏ + F y + c(y) + D(t) y = f(t)
//!
//! with E diagonal (node capacitance or branch inertance; zero rows are algebraic),
//! F the constant incidence/resistance matrix, c the stenosis term S|Q|Q and D(t) the diagonal
//! time-varying part of branch resistances that follow a law (`crate::coefficients`; empty for
//! most circuits, which then keep their constant-matrix fast path). f holds the boundary
//! waveforms: inflows and pressures on node rows, series pressure sources on branch rows.
//! Unknown i < n_nodes is the pressure of node i, unknown n_nodes + b the flow of branch b.

use crate::coefficients::ResistanceLaw;
use crate::element::Element;
use crate::element::chamber::{Chamber, Elastance};
use crate::element::coronary::ClosedLoopCoronary;
use crate::element::heart::{HeartParams, HeartPulmonary, HeartUnknowns};
use crate::element::sphere::{ChamberSphere, SphereParams, SphereUnknowns};
use crate::element::valve::{Valve, ValveLaw};
use crate::error::{Error, Result};
use crate::waveform::Waveform;
use std::sync::Arc;

/// A part of a vessel or boundary condition that a circuit element stands for (its name).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// Interior point k of a vessel.
    Point,
    /// Segment k of a vessel of several segments.
    Segment,
    /// The one branch of a single-segment vessel.
    Whole,
    Resistance,
    Inductance,
    Capacitor,
    Distal,
    ProximalResistance,
    DistalResistance,
    /// A coronary bed's microvascular resistance.
    MicrovascularResistance,
    /// A coronary bed's intramyocardial compartment.
    Intramyocardial,
    /// A chamber's blood volume.
    Volume,
    /// A spherical chamber's wall unknowns (docs/physics.md §1.11).
    WallDisplacement,
    WallVelocity,
    WallStress,
    ActiveStress,
    /// A friction cell of a Womersley segment (`k`: the segment), `crate::womersley`.
    FrictionCell,
}

impl Part {
    fn suffix(self) -> &'static str {
        match self {
            Part::Point => "point",
            Part::Segment => "segment",
            Part::Whole => "",
            Part::Resistance => "resistance",
            Part::Inductance => "inductance",
            Part::Capacitor => "capacitor",
            Part::Distal => "distal",
            Part::ProximalResistance => "proximal resistance",
            Part::DistalResistance => "distal resistance",
            Part::MicrovascularResistance => "microvascular resistance",
            Part::Intramyocardial => "intramyocardial compartment",
            Part::Volume => "chamber",
            Part::WallDisplacement => "wall displacement",
            Part::WallVelocity => "wall velocity",
            Part::WallStress => "wall stress",
            Part::ActiveStress => "active stress",
            Part::FrictionCell => "friction cell",
        }
    }
}

/// What a node or branch is, from which its name is written on demand: a million-segment
/// circuit would otherwise hold two million strings that only an error message or a
/// diagnostic ever reads (12 bytes each instead of ~70).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Label {
    /// Free text (index into the name table's texts).
    Text(u32),
    /// A part of vessel `vessel` (index into `Names::vessels`); `k` numbers points and
    /// segments from 1.
    Vessel { vessel: u32, part: Part, k: u32 },
    /// A part of boundary condition `tag` (index into `Names::boundaries`).
    Boundary { tag: u32, part: Part },
    /// The viscoelastic wall of circuit node `node` (its elastic pressure).
    Wall(u32),
}

/// The names of a circuit's nodes and branches, shared by the circuit and its DAE.
#[derive(Debug, Clone, Default)]
pub struct Names {
    nodes: Vec<Label>,
    branches: Vec<Label>,
    texts: Vec<String>,
    /// Vessel names, as `Circuit::vessel_names`.
    vessels: Vec<String>,
    /// Boundary condition names (graph node names).
    boundaries: Vec<String>,
    /// Element unknowns after the flows (a chamber's volume).
    extras: Vec<Label>,
}

fn index32(i: usize) -> u32 {
    u32::try_from(i).expect("more than 2^32 circuit elements")
}

impl Names {
    /// Heap bytes held (capacities; profiling, `examples/mem_stages`).
    pub fn heap_bytes(&self) -> usize {
        let strings = |v: &Vec<String>| {
            v.capacity() * std::mem::size_of::<String>()
                + v.iter().map(String::capacity).sum::<usize>()
        };
        (self.nodes.capacity() + self.branches.capacity() + self.extras.capacity())
            * std::mem::size_of::<Label>()
            + strings(&self.texts)
            + strings(&self.vessels)
            + strings(&self.boundaries)
    }
    /// A free-text label.
    pub fn text(&mut self, s: impl Into<String>) -> Label {
        self.texts.push(s.into());
        Label::Text(index32(self.texts.len() - 1))
    }
    /// Register vessel `name`; returns its index.
    pub fn add_vessel(&mut self, name: &str) -> u32 {
        self.vessels.push(name.to_owned());
        index32(self.vessels.len() - 1)
    }
    /// Register boundary condition `name` (its graph node); returns its tag.
    pub fn add_boundary(&mut self, name: &str) -> u32 {
        self.boundaries.push(name.to_owned());
        index32(self.boundaries.len() - 1)
    }
    fn write(&self, l: Label) -> String {
        match l {
            Label::Text(i) => self.texts[i as usize].clone(),
            Label::Vessel { vessel, part, k } => {
                let v = &self.vessels[vessel as usize];
                match part {
                    Part::Whole => format!("vessel '{v}'"),
                    Part::Point | Part::Segment => format!("vessel '{v}' {} {k}", part.suffix()),
                    Part::FrictionCell => format!("vessel '{v}' segment {k} friction cell"),
                    _ => format!("vessel '{v}' {}", part.suffix()),
                }
            }
            Label::Wall(node) => format!("the wall at {}", self.write(self.nodes[node as usize])),
            Label::Boundary { tag, part } => format!(
                "boundary condition '{}' {}",
                self.boundaries[tag as usize],
                part.suffix()
            ),
        }
    }
    /// Name of vessel `v` (as given in the model).
    pub fn vessel(&self, v: usize) -> Option<&str> {
        self.vessels.get(v).map(String::as_str)
    }
    /// Number of named nodes.
    pub fn n_nodes(&self) -> usize {
        self.nodes.len()
    }
    /// Number of branches (their flows follow the node pressures among the unknowns).
    pub fn n_branches(&self) -> usize {
        self.branches.len()
    }
    /// The vessel (index into the vessel names) that branch `b` is part of, if any.
    pub fn branch_vessel(&self, b: usize) -> Option<usize> {
        match self.branches[b] {
            Label::Vessel { vessel, .. } => Some(vessel as usize),
            _ => None,
        }
    }
    /// Name of node `i`.
    pub fn node(&self, i: usize) -> String {
        self.write(self.nodes[i])
    }
    /// Name of branch `b`.
    pub fn branch(&self, b: usize) -> String {
        self.write(self.branches[b])
    }
    /// Name of unknown `i` of the DAE (node pressures first, then branch flows).
    pub fn unknown(&self, i: usize) -> String {
        let (nn, nb) = (self.nodes.len(), self.branches.len());
        if i < nn {
            format!("pressure at {}", self.node(i))
        } else if i < nn + nb {
            format!("flow in {}", self.branch(i - nn))
        } else {
            let label = self.extras[i - nn - nb];
            let what = match label {
                Label::Vessel {
                    part: Part::FrictionCell,
                    ..
                } => "flow in",
                Label::Wall(_) => "elastic pressure of",
                _ => "volume of",
            };
            format!("{what} {}", self.write(label))
        }
    }
    /// Names of all unknowns.
    pub fn unknowns(&self) -> Vec<String> {
        (0..self.nodes.len() + self.branches.len() + self.extras.len())
            .map(|i| self.unknown(i))
            .collect()
    }
}

/// A node's or branch's name: free text or a [`Label`].
pub enum NameOf {
    Text(String),
    Label(Label),
}
impl From<&str> for NameOf {
    fn from(s: &str) -> Self {
        NameOf::Text(s.to_owned())
    }
}
impl From<String> for NameOf {
    fn from(s: String) -> Self {
        NameOf::Text(s)
    }
}
impl From<Label> for NameOf {
    fn from(l: Label) -> Self {
        NameOf::Label(l)
    }
}

#[derive(Debug, Clone)]
pub struct Node {
    pub capacitance: f64,
    /// Lumen volume lumped into this node at the reference pressure (m³); 0 for BC-internal nodes.
    pub volume: f64,
    /// svZeroDSolver's steady initialisation removes Windkessel capacitances.
    pub windkessel: bool,
    /// Lumen (wall) area lumped into this node (m²), with the same shares as `volume`.
    pub wall_area: f64,
    /// Set for nodes that belong to a boundary condition (index into `Circuit::boundaries`):
    /// they are outside the transport domain. (u32, as the names' indices: 40 bytes a node,
    /// not 48.)
    pub boundary: Option<u32>,
}

/// The capacitor of an svZeroDSolver-form RCL vessel with a stenosis
/// (`StenosisForm::SvZeroD`, docs/svzerod.md): generalized-α replaces the row C dP_c/dt of
/// `node` by C (dP_in/dt − (R + 2S|Q|) dQ/dt), with P_in the vessel's inlet pressure and Q the
/// flow through its R branch. `inlet` and `node` are node indices (= pressure unknowns);
/// `flow` is the R branch's index in the circuit and its flow unknown in the DAE.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainRuleCapacitor {
    pub node: usize,
    pub inlet: usize,
    pub flow: usize,
    pub capacitance: f64,
    pub resistance: f64,
    pub stenosis: f64,
}

/// A flow-through R–C branch (svZeroDSolver's `BloodVesselRC`): the row of `node` (its
/// `from` end) reads C dP/dt + (P − P_to)/R − Q = 0 and the branch's row holds the node's flow
/// balance.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwappedRow {
    pub node: usize,
    pub branch: usize,
    pub capacitance: f64,
    pub resistance: f64,
}

/// An element of `crate::element` as stamped, with circuit indices (resolved to DAE unknowns by
/// [`Circuit::assemble`]).
#[derive(Debug, Clone)]
pub enum CircuitElement {
    /// A valve on branch `branch` from node `from` to node `to`.
    Valve {
        name: String,
        law: ValveLaw,
        branch: usize,
        from: usize,
        to: usize,
    },
    /// A chamber: its pressure node and its volume (index into `Circuit::extras`).
    Chamber {
        name: String,
        elastance: Elastance,
        node: usize,
        volume: usize,
    },
    /// The closed-loop heart block: its pressure nodes (right atrium, right ventricle, left
    /// atrium, left ventricle, aorta), valve branches (tricuspid, pulmonary, mitral, aortic),
    /// chamber volumes and pulmonary pressure (indices into `Circuit::extras`).
    Heart {
        name: String,
        params: Box<HeartParams>,
        nodes: [usize; 5],
        branches: [usize; 4],
        volumes: [usize; 4],
        pulmonary: usize,
    },
    /// A closed-loop coronary bed's intramyocardial node, its volume (extra) and the node of
    /// the ventricle whose pressure squeezes it.
    Coronary {
        name: String,
        capacitance: f64,
        factor: f64,
        node: usize,
        volume: usize,
        ventricle: usize,
    },
    /// A spherical chamber (docs/physics.md §1.11): its pressure node and its wall
    /// displacement, velocity, stress, active stress and volume (indices into
    /// `Circuit::extras`).
    Sphere {
        name: String,
        params: SphereParams,
        node: usize,
        extras: [usize; 5],
    },
}

/// A boundary condition as seen by species transport.
#[derive(Debug, Clone)]
pub struct BoundaryTag {
    pub name: String,
    /// At a vessel's inlet end (inflow carries the inlet concentration) or outlet end.
    pub inlet: bool,
}

/// Geometry of one flow segment, kept for species transport (wall closures, reporting).
#[derive(Debug, Clone)]
pub struct SegmentGeom {
    /// Index into `Circuit::vessel_names`.
    pub vessel: usize,
    /// The branch carrying the segment's flow (its downstream face for inverted-L).
    pub branch: usize,
    /// Nodes holding the segment's volume, compliance and wall area, with their shares.
    pub nodes: [(usize, f64); 2],
    /// Mean radius (m); 0 for lumped segments (no wall exchange).
    pub radius: f64,
    /// Distance of the segment ends from the vessel inlet (m).
    pub x0: f64,
    pub x1: f64,
    pub volume: f64,
    pub compliance: f64,
}

/// A cell R_k ‖ L_k in series with branch `branch` (a Womersley segment, `crate::womersley`):
/// its unknown is the flow i_k through L_k (element unknown `extra`), with the row
/// L_k di_k/dt + R_k i_k − R_k Q = 0, and the branch's row gains R_k (Q − i_k), the cell's
/// pressure drop. The cell hangs off the branch's flow alone, so a tree stays a tree.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrictionCell {
    pub branch: usize,
    pub extra: usize,
    pub resistance: f64,
}

/// A Kelvin–Voigt wall at node `node` (docs/physics.md §1.13): the node's capacitance C sits
/// behind a resistance R_v = τ/C, τ the capacitance-weighted mean of the wall relaxation times
/// η/E of the viscoelastic segments sharing the node. Element unknown `extra` is the wall's elastic pressure P_e, with
/// the row C dP_e/dt + (P_e − P)/R_v = 0; the node's own row becomes its flow balance with the
/// wall's flow (P − P_e)/R_v in place of C dP/dt. The wall hangs off its node alone.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ViscousWall {
    pub node: usize,
    pub extra: usize,
    /// Σ C_i τ_i over the viscoelastic segment shares at the node (s·m³/Pa).
    pub capacitance_time: f64,
    /// Σ C_i over the same shares (m³/Pa).
    pub capacitance: f64,
}

#[derive(Debug, Clone)]
pub struct Branch {
    pub from: usize,
    pub to: usize,
    pub resistance: f64,
    pub inductance: f64,
    pub stenosis: f64,
}

/// Compressed sparse rows. Column indices and row starts are u32 (a circuit of more than
/// 2^32 unknowns or matrix entries is refused at assembly): the per-step residual pass reads
/// every entry, so 4-byte indices cut its memory traffic and the matrix's size by a sixth,
/// and 4-byte row starts save 4 bytes per unknown.
#[derive(Debug, Clone, Default)]
pub struct Csr {
    pub ptr: Vec<u32>,
    pub col: Vec<u32>,
    pub val: Vec<f64>,
}

impl Csr {
    /// The entries of row `i` (indices into `col` and `val`).
    #[inline]
    pub fn row(&self, i: usize) -> std::ops::Range<usize> {
        self.ptr[i] as usize..self.ptr[i + 1] as usize
    }
    /// Close the current row: its end is the number of entries pushed so far (below 2^32:
    /// the matrix's upper bound is checked before it is built).
    #[inline]
    pub fn end_row(&mut self) {
        self.ptr.push(self.col.len() as u32);
    }
    #[inline]
    pub fn row_dot(&self, i: usize, y: &[f64]) -> f64 {
        let mut s = 0.0;
        for k in self.row(i) {
            s += self.val[k] * y[self.col[k] as usize];
        }
        s
    }
    pub fn nrows(&self) -> usize {
        self.ptr.len() - 1
    }
}

/// The flow matrix's row starts are u32: a circuit whose matrix may hold 2^32 entries or more
/// (`nnz`, its upper bound) is refused, never wrapped.
fn flow_matrix_fits(nnz: usize) -> Result<()> {
    if u32::try_from(nnz).is_err() {
        return Err(Error::model(
            "circuit",
            format!("has up to {nnz} flow-matrix entries, more than 2^32"),
        ));
    }
    Ok(())
}

/// A node pressure or a branch flow of the circuit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unknown {
    Node(usize),
    Branch(usize),
}

/// The start value of an unknown (`rate`: of its time derivative).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StartValue {
    pub unknown: Unknown,
    pub value: f64,
    pub rate: bool,
}

#[derive(Debug, Clone, Default)]
pub struct Circuit {
    pub nodes: Vec<Node>,
    pub branches: Vec<Branch>,
    /// Prescribed inflow into a node (m³/s), e.g. an inlet flow boundary condition.
    pub sources: Vec<(usize, Waveform)>,
    /// Prescribed node pressures (Pa): pressure BCs and the distal pressure of outlets.
    pub fixed_pressures: Vec<(usize, Waveform)>,
    /// Pressure sources in series with a branch (Pa): the pressure rises by e(t) along the
    /// branch, P_from + e(t) − R Q − L Q̇ = P_to (e.g. the intramyocardial pressure of a
    /// coronary bed).
    pub branch_sources: Vec<(usize, Waveform)>,
    /// Branch resistances that follow a law R(t); the branch's `resistance` is the law's base.
    pub resistance_laws: Vec<(usize, ResistanceLaw)>,
    /// Boundary conditions (transport); `source_boundary[k]` tags `sources[k]`.
    pub boundaries: Vec<BoundaryTag>,
    pub source_boundary: Vec<usize>,
    pub segments: Vec<SegmentGeom>,
    /// The capacitance each vessel end puts on its end node, with the branch of that end
    /// segment: (node, branch, capacitance). Two per segmented vessel, kept when `segments`
    /// is released, so that a node's capacitance can be told apart by the side it belongs to
    /// (`impedance::Direction`).
    pub end_capacitors: Vec<(usize, usize, f64)>,
    /// Capacitor rows in svZeroDSolver's form (empty unless a vessel asks for it).
    pub chain_rule: Vec<ChainRuleCapacitor>,
    /// Element unknowns after the branch flows (a chamber's volume): their E_ii.
    pub extras: Vec<f64>,
    /// (node, extra): the node's flow balance (and any inflow into it) is the row of element
    /// unknown `extra` (E_ii ẏ_extra + Σ Q_out − Σ Q_in = inflow), and the node's own row holds
    /// its pressure, P = …, completed by an element (a chamber: P − E(t)(V − V_rest) = 0).
    pub moved_rows: Vec<(usize, usize)>,
    /// Nonlinear and time-varying elements (`crate::element`).
    pub elements: Vec<CircuitElement>,
    /// (extra, value): element unknowns' values at a zero start (a chamber's initial volume).
    pub initial_extras: Vec<(usize, f64)>,
    /// Node pressures and branch flows (or their rates) at a zero start, from the vessels'
    /// `initial` and `initial_rate` (docs/physics.md §1.9).
    pub start_values: Vec<StartValue>,
    /// Flow-through R–C branches, whose equation takes their `from` node's row.
    pub swapped_rows: Vec<SwappedRow>,
    /// Friction cells of Womersley segments, in the order of their branches.
    pub friction_cells: Vec<FrictionCell>,
    /// Cells whose unknown is not placed yet (`place_friction_cells`): their names and
    /// inertances.
    pending_cells: Vec<(Label, f64)>,
    /// Viscoelastic walls, one per node that has one.
    pub viscous_walls: Vec<ViscousWall>,
    /// Node → index into `viscous_walls`.
    viscous_wall_of: std::collections::HashMap<usize, usize>,
    pub vessel_names: Vec<String>,
    /// Node and branch names (shared with the assembled DAE).
    pub names: Arc<Names>,
    /// The per-node and per-branch tables were dropped once the DAE and the transport plan
    /// were built from them (`release_tables`): what a run reads is in those.
    released: bool,
}

/// Why a released circuit (`Circuit::release_tables`) cannot serve a read of its tables.
pub const RELEASED: &str = "its node and branch tables are not kept for a model this large \
(they were dropped once the run's matrices were built): load the model anew with the circuit \
kept to read them";

/// Which forcing and capacitances to use: the real ones, or the steady (mean) ones.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    Transient,
    /// Mean boundary values; Windkessel capacitances removed (svZeroDSolver's `to_steady`).
    SteadyNoWindkessel,
    /// Mean boundary values, all capacitances kept.
    Steady,
}

impl Circuit {
    /// An empty circuit with room for `nodes` nodes, `branches` branches and `segments`
    /// segments (large circuits are then allocated once, not grown by doubling).
    pub fn with_capacity(nodes: usize, branches: usize, segments: usize) -> Self {
        let names = Names {
            nodes: Vec::with_capacity(nodes),
            branches: Vec::with_capacity(branches),
            ..Default::default()
        };
        Circuit {
            nodes: Vec::with_capacity(nodes),
            branches: Vec::with_capacity(branches),
            segments: Vec::with_capacity(segments),
            names: Arc::new(names),
            ..Default::default()
        }
    }
    /// [`Circuit::with_capacity`] with fallible allocation: a circuit too large for the
    /// memory left is a typed [`Error::Resource`], not an abort.
    pub fn try_with_capacity(nodes: usize, branches: usize, segments: usize) -> Result<Self> {
        use crate::error::try_reserve;
        let mut names = Names::default();
        try_reserve(&mut names.nodes, nodes, "circuit node names")?;
        try_reserve(&mut names.branches, branches, "circuit branch names")?;
        let mut c = Circuit::default();
        try_reserve(&mut c.nodes, nodes, "circuit nodes")?;
        try_reserve(&mut c.branches, branches, "circuit branches")?;
        try_reserve(&mut c.segments, segments, "circuit segments")?;
        c.names = Arc::new(names);
        Ok(c)
    }
    /// Release the spare capacity of the per-node, per-branch and per-segment tables once
    /// the circuit is complete (~15 B per segment at 1e6 segments).
    pub fn shrink_to_fit(&mut self) {
        self.nodes.shrink_to_fit();
        self.branches.shrink_to_fit();
        self.segments.shrink_to_fit();
        let names = Arc::make_mut(&mut self.names);
        names.nodes.shrink_to_fit();
        names.branches.shrink_to_fit();
    }
    /// Drop the per-node, per-branch and per-segment tables (and the elements and boundary
    /// rows), keeping the names, the vessel names and the inflow sources. A run reads the DAE
    /// and the transport plan only, which hold their own copies of what they need; the
    /// tables are read again only by the circuit's diagnostics and the impedance, which then
    /// need the model assembled anew. A million-segment tree's tables are ~150 B per segment
    /// of its running peak.
    pub fn release_tables(&mut self) {
        let Circuit {
            nodes,
            branches,
            fixed_pressures,
            branch_sources,
            resistance_laws,
            boundaries,
            source_boundary,
            segments,
            end_capacitors,
            chain_rule,
            extras,
            moved_rows,
            elements,
            initial_extras,
            start_values,
            swapped_rows,
            friction_cells,
            pending_cells,
            viscous_walls,
            viscous_wall_of,
            released,
            // kept: what the output, the segment table and `source_flows` read
            sources: _,
            vessel_names: _,
            names: _,
        } = self;
        *nodes = Vec::new();
        *branches = Vec::new();
        *fixed_pressures = Vec::new();
        *branch_sources = Vec::new();
        *resistance_laws = Vec::new();
        *boundaries = Vec::new();
        *source_boundary = Vec::new();
        *segments = Vec::new();
        *end_capacitors = Vec::new();
        *chain_rule = Vec::new();
        *extras = Vec::new();
        *moved_rows = Vec::new();
        *elements = Vec::new();
        *initial_extras = Vec::new();
        *start_values = Vec::new();
        *swapped_rows = Vec::new();
        *friction_cells = Vec::new();
        *pending_cells = Vec::new();
        *viscous_walls = Vec::new();
        *viscous_wall_of = Default::default();
        *released = true;
    }
    /// Whether the per-node and per-branch tables were dropped (`release_tables`).
    pub fn is_released(&self) -> bool {
        self.released
    }
    fn label(&mut self, name: NameOf) -> Label {
        match name {
            NameOf::Label(l) => l,
            NameOf::Text(s) => Arc::make_mut(&mut self.names).text(s),
        }
    }
    pub fn add_node(&mut self, name: impl Into<NameOf>, capacitance: f64, volume: f64) -> usize {
        let label = self.label(name.into());
        Arc::make_mut(&mut self.names).nodes.push(label);
        self.nodes.push(Node {
            capacitance,
            volume,
            windkessel: false,
            wall_area: 0.0,
            boundary: None,
        });
        self.nodes.len() - 1
    }
    pub fn add_branch(
        &mut self,
        name: impl Into<NameOf>,
        from: usize,
        to: usize,
        resistance: f64,
        inductance: f64,
        stenosis: f64,
    ) -> usize {
        let label = self.label(name.into());
        Arc::make_mut(&mut self.names).branches.push(label);
        self.branches.push(Branch {
            from,
            to,
            resistance,
            inductance,
            stenosis,
        });
        self.branches.len() - 1
    }
    pub fn n_unknowns(&self) -> usize {
        self.nodes.len() + self.branches.len() + self.extras.len()
    }
    /// Add an element unknown (after the flows) with mass-matrix entry `mass`; returns its
    /// index into `extras`.
    pub fn add_extra(&mut self, name: impl Into<NameOf>, mass: f64) -> usize {
        let label = self.label(name.into());
        Arc::make_mut(&mut self.names).extras.push(label);
        self.extras.push(mass);
        self.extras.len() - 1
    }
    /// Put a cell R ‖ L in series with branch `branch` (`crate::womersley`). Its unknown is
    /// placed by [`Circuit::place_friction_cells`], after every other element unknown.
    pub fn add_friction_cell(
        &mut self,
        name: impl Into<NameOf>,
        branch: usize,
        resistance: f64,
        inductance: f64,
    ) {
        let label = self.label(name.into());
        self.pending_cells.push((label, inductance));
        self.friction_cells.push(FrictionCell {
            branch,
            extra: usize::MAX,
            resistance,
        });
    }
    /// Give the friction cells added since the last call their unknowns, after every other
    /// unknown: the cells are then the DAE's trailing leaves, which a linear
    /// generalized-α step condenses into their branches (`integrate::leaves`).
    pub fn place_friction_cells(&mut self) {
        let pending = std::mem::take(&mut self.pending_cells);
        let first = self.friction_cells.len() - pending.len();
        for (k, (label, inductance)) in pending.into_iter().enumerate() {
            self.friction_cells[first + k].extra = self.add_extra(label, inductance);
        }
    }
    /// Give node `node` a share `capacitance` of wall with relaxation time `relaxation`
    /// (η/E, s) behind a viscous resistance (a Kelvin–Voigt wall, [`ViscousWall`]).
    pub fn add_wall_viscosity(&mut self, node: usize, capacitance: f64, relaxation: f64) {
        if !(capacitance > 0.0 && relaxation > 0.0) {
            return;
        }
        let k = match self.viscous_wall_of.get(&node) {
            Some(&k) => k,
            None => {
                let extra = self.add_extra(Label::Wall(node as u32), 0.0);
                self.viscous_walls.push(ViscousWall {
                    node,
                    extra,
                    capacitance_time: 0.0,
                    capacitance: 0.0,
                });
                self.viscous_wall_of
                    .insert(node, self.viscous_walls.len() - 1);
                self.viscous_walls.len() - 1
            }
        };
        self.viscous_walls[k].capacitance_time += capacitance * relaxation;
        self.viscous_walls[k].capacitance += capacitance;
    }
    /// The viscoelastic walls in force, as (wall, capacitance C, viscous resistance R_v): the
    /// nodes' capacitance as it is now (an impedance view may have split it) behind τ/C, τ
    /// the mean relaxation time of the viscoelastic shares. Walls at prescribed pressures, or whose node's row moved to an
    /// element, are left elastic.
    fn active_walls(&self, rows: &RowOwners) -> Vec<(ViscousWall, f64, f64)> {
        self.viscous_walls
            .iter()
            .filter(|w| {
                rows.fixed[w.node].is_none()
                    && rows.moved[w.node].is_none()
                    && self.nodes[w.node].capacitance > 0.0
            })
            .map(|w| {
                let c = self.nodes[w.node].capacitance;
                (*w, c, w.capacitance_time / w.capacitance / c)
            })
            .collect()
    }
    pub fn unknown_name(&self, i: usize) -> String {
        self.names.unknown(i)
    }
    /// Room for `texts` more free-text labels and `vessels` more vessel names (the tables
    /// grow once, not by doubling).
    pub fn reserve_names(&mut self, texts: usize, vessels: usize) {
        self.vessel_names.reserve(vessels);
        let names = Arc::make_mut(&mut self.names);
        names.texts.reserve(texts);
        names.vessels.reserve(vessels);
    }
    /// Register vessel `name` (in `vessel_names` and the name table); returns its index.
    pub fn add_vessel(&mut self, name: &str) -> usize {
        self.vessel_names.push(name.to_owned());
        Arc::make_mut(&mut self.names).add_vessel(name) as usize
    }

    /// Assemble the DAE (linear in the network size): which row holds each node's equation,
    /// the node–branch incidences, then the flow matrix F, the mass diagonal E and the forcing.
    pub fn assemble(&self) -> Result<Dae> {
        if self.released {
            return Err(Error::model("circuit", RELEASED));
        }
        let n = self.n_unknowns();
        if u32::try_from(n).is_err() {
            return Err(Error::model(
                "circuit",
                format!("has {n} unknowns, more than 2^32"),
            ));
        }
        let rows = self.row_owners()?;
        let incidence = Incidence::of(self);
        let walls = self.active_walls(&rows);
        let f = self.flow_matrix(&rows, &incidence, &walls)?;
        let (e, windkessel) = self.mass_diagonal(&rows, &walls);
        let (nn, nb) = (self.nodes.len(), self.branches.len());
        let wall_unknowns = walls
            .iter()
            .map(|(w, _, _)| (w.node, nn + nb + w.extra))
            .collect();
        let forcing = self.forcing(&rows);
        let stenosis: Vec<(usize, f64)> = self
            .branches
            .iter()
            .enumerate()
            .filter(|(_, b)| b.stenosis != 0.0)
            .map(|(bi, b)| (nn + bi, b.stenosis))
            .collect();
        let chain_rule = self
            .chain_rule
            .iter()
            .map(|c| ChainRuleCapacitor {
                flow: nn + c.flow,
                ..*c
            })
            .collect();
        let varying = self
            .resistance_laws
            .iter()
            .map(|(b, law)| (nn + b, law.clone()))
            .collect();
        let elements = self.elements.iter().map(|el| resolve(el, nn, nb)).collect();
        let (initial, initial_rate) = self.start(nn, nb);
        Ok(Dae {
            n,
            n_nodes: nn,
            elements,
            initial,
            initial_rate,
            e,
            windkessel,
            f,
            stenosis,
            chain_rule,
            varying,
            forcing,
            walls: wall_unknowns,
            names: self.names.clone(),
        })
    }

    /// Which row holds each node's equation: a pressure condition, a flow-through R–C element
    /// (the node's balance moves to the element's branch row), a chamber (the balance moves to
    /// its volume's row). A node may have at most one of them (checked here, by name).
    fn row_owners(&self) -> Result<RowOwners> {
        let (nn, nb) = (self.nodes.len(), self.branches.len());
        let mut rows = RowOwners {
            fixed: vec![None; nn],
            swapped: vec![None; nn],
            moved: vec![None; nn],
            balance_of_branch: vec![usize::MAX; nb],
        };
        for (k, (node, _)) in self.fixed_pressures.iter().enumerate() {
            if rows.fixed[*node].is_some() {
                return Err(Error::model(
                    self.names.node(*node),
                    "has two pressure conditions",
                ));
            }
            rows.fixed[*node] = Some(k);
        }
        for sw in &self.swapped_rows {
            let node = sw.node;
            if rows.fixed[node].is_some()
                || rows.swapped[node].is_some()
                || self.nodes[node].capacitance != 0.0
            {
                return Err(Error::model(
                    self.names.node(node),
                    "a through_rc element's inlet node cannot also have a pressure condition, a capacitance or a second such element",
                ));
            }
            rows.swapped[node] = Some(*sw);
            rows.moved[node] = Some(nn + sw.branch);
            rows.balance_of_branch[sw.branch] = node;
        }
        for &(node, x) in &self.moved_rows {
            if self.nodes[node].capacitance != 0.0 {
                return Err(Error::model(
                    self.names.node(node),
                    "a chamber's pressure node cannot also hold a vessel's capacitance (put a valve or a resistance between them)",
                ));
            }
            if rows.fixed[node].is_some() || rows.moved[node].is_some() {
                return Err(Error::model(
                    self.names.node(node),
                    "a chamber's pressure node cannot also have a pressure condition or a second chamber",
                ));
            }
            rows.moved[node] = Some(nn + nb + x);
        }
        Ok(rows)
    }

    /// The flow matrix F: a node row holds its incidences (the flow balance) unless its
    /// balance moved, a branch row −P_from + P_to + R Q (or the balance of the node it took
    /// over), an element unknown's row the balance of the chamber node it owns.
    fn flow_matrix(
        &self,
        rows: &RowOwners,
        incidence: &Incidence,
        walls: &[(ViscousWall, f64, f64)],
    ) -> Result<Csr> {
        let (nn, nb) = (self.nodes.len(), self.branches.len());
        let n = self.n_unknowns();
        // a node row holds its incidences (or 1–3 entries), a branch row 3 (or a node's
        // incidences): allocated once at an upper bound instead of grown by doubling (whose
        // copies touch the pattern's bytes twice at 1e6 segments)
        let nnz = 2 * incidence.inc.len()
            + 3 * (nn + nb)
            + self.extras.len()
            + 3 * self.friction_cells.len()
            + 4 * walls.len();
        flow_matrix_fits(nnz)?;
        // per node: its viscoelastic wall's unknown and 1/R_v (none for most circuits)
        let mut wall_at: Vec<Option<(u32, f64)>> = Vec::new();
        if !walls.is_empty() {
            wall_at = vec![None; nn];
            for (w, _, rv) in walls {
                wall_at[w.node] = Some(((nn + nb + w.extra) as u32, 1.0 / rv));
            }
        }
        let mut f = Csr {
            ptr: Vec::with_capacity(n + 1),
            col: Vec::with_capacity(nnz),
            val: Vec::with_capacity(nnz),
        };
        let push_balance = |f: &mut Csr, node: usize| {
            for &(c, s) in incidence.at(node) {
                f.col.push(c as u32);
                f.val.push(s);
            }
        };
        f.ptr.push(0);
        for i in 0..nn {
            if let Some(sw) = rows.swapped[i] {
                let b = &self.branches[sw.branch];
                f.col
                    .extend([i as u32, b.to as u32, (nn + sw.branch) as u32]);
                f.val
                    .extend([1.0 / sw.resistance, -1.0 / sw.resistance, -1.0]);
            } else if rows.fixed[i].is_some() || rows.moved[i].is_some() {
                f.col.push(i as u32);
                f.val.push(1.0);
            } else {
                push_balance(&mut f, i);
                if let Some(&Some((wall, g))) = wall_at.get(i) {
                    // the wall's flow (P − P_e)/R_v in place of C dP/dt
                    f.col.extend([i as u32, wall]);
                    f.val.extend([g, -g]);
                }
            }
            f.end_row();
        }
        // the cells of each branch (pushed in branch order, so one cursor walks them)
        let mut cell = 0;
        for (bi, b) in self.branches.iter().enumerate() {
            let first = cell;
            while cell < self.friction_cells.len() && self.friction_cells[cell].branch == bi {
                cell += 1;
            }
            let cells = &self.friction_cells[first..cell];
            let node = rows.balance_of_branch[bi];
            if node != usize::MAX {
                push_balance(&mut f, node);
            } else {
                let r_cells: f64 = cells.iter().map(|c| c.resistance).sum();
                f.col.extend([b.from as u32, b.to as u32, (nn + bi) as u32]);
                f.val.extend([-1.0, 1.0, b.resistance + r_cells]);
                for c in cells {
                    f.col.push((nn + nb + c.extra) as u32);
                    f.val.push(-c.resistance);
                }
            }
            f.end_row();
        }
        let mut owner = vec![Owner::None; self.extras.len()];
        for &(node, x) in &self.moved_rows {
            owner[x] = Owner::Node(node);
        }
        for c in &self.friction_cells {
            owner[c.extra] = Owner::Cell(*c);
        }
        for &(w, _, rv) in walls {
            owner[w.extra] = Owner::Wall(w.node, 1.0 / rv);
        }
        for (x, o) in owner.iter().enumerate() {
            match *o {
                Owner::Node(node) => push_balance(&mut f, node),
                Owner::Cell(c) => {
                    f.col
                        .extend([(nn + c.branch) as u32, (nn + nb + c.extra) as u32]);
                    f.val.extend([-c.resistance, c.resistance]);
                }
                Owner::Wall(node, g) => {
                    f.col.extend([node as u32, (nn + nb + x) as u32]);
                    f.val.extend([-g, g]);
                }
                Owner::None => {}
            }
            f.end_row();
        }
        // give back the upper bound's unused tail (~90 B per segment of heap the estimate
        // would otherwise count; a large block shrinks in place, nothing is copied)
        f.col.shrink_to_fit();
        f.val.shrink_to_fit();
        Ok(f)
    }

    /// The mass diagonal E (node capacitances, branch inductances, element unknowns' E_ii) and
    /// which node capacitances are Windkessel capacitors.
    fn mass_diagonal(
        &self,
        rows: &RowOwners,
        walls: &[(ViscousWall, f64, f64)],
    ) -> (Vec<f64>, Vec<bool>) {
        let (nn, nb) = (self.nodes.len(), self.branches.len());
        let n = self.n_unknowns();
        let mut e = vec![0.0; n];
        let mut windkessel = vec![false; n];
        for (i, node) in self.nodes.iter().enumerate() {
            if rows.fixed[i].is_none() {
                e[i] = node.capacitance;
                windkessel[i] = node.windkessel;
            }
            if let Some(sw) = rows.swapped[i] {
                e[i] = sw.capacitance;
            }
        }
        for (bi, b) in self.branches.iter().enumerate() {
            e[nn + bi] = b.inductance;
        }
        for (x, &m) in self.extras.iter().enumerate() {
            e[nn + nb + x] = m;
        }
        // a viscoelastic wall's capacitance moves to its elastic pressure
        for &(w, c, _) in walls {
            e[w.node] = 0.0;
            e[nn + nb + w.extra] = c;
        }
        (e, windkessel)
    }

    /// The forcing by row: inflows (into the row that holds the node's balance), prescribed
    /// pressures, and pressure sources in series with a branch (a branch row reads
    /// −P_from + P_to + R Q + L Q̇ = e(t)).
    fn forcing(&self, rows: &RowOwners) -> Vec<(usize, Waveform)> {
        let nn = self.nodes.len();
        let mut forcing = Vec::new();
        for (node, w) in &self.sources {
            if rows.fixed[*node].is_none() {
                forcing.push((rows.moved[*node].unwrap_or(*node), w.clone()));
            }
        }
        for (node, w) in &self.fixed_pressures {
            forcing.push((*node, w.clone()));
        }
        for (b, w) in &self.branch_sources {
            forcing.push((nn + b, w.clone()));
        }
        forcing
    }

    /// The start values (and start rates) of a zero start, by DAE unknown.
    #[allow(clippy::type_complexity)]
    fn start(&self, nn: usize, nb: usize) -> (Vec<(usize, f64)>, Vec<(usize, f64)>) {
        let index = |u: Unknown| match u {
            Unknown::Node(i) => i,
            Unknown::Branch(b) => nn + b,
        };
        let starts = |rate: bool| {
            self.start_values
                .iter()
                .filter(move |s| s.rate == rate)
                .map(move |s| (index(s.unknown), s.value))
        };
        let initial = starts(false)
            .chain(self.initial_extras.iter().map(|&(x, v)| (nn + nb + x, v)))
            .collect();
        (initial, starts(true).collect())
    }
}

/// What an element unknown's row of F holds: a moved node balance, a friction cell's
/// equation, or nothing (the element writes it).
#[derive(Clone, Copy)]
enum Owner {
    None,
    Node(usize),
    Cell(FrictionCell),
    /// A viscoelastic wall's row: (node, 1/R_v).
    Wall(usize, f64),
}

/// Which row holds each node's equation (`Circuit::row_owners`).
struct RowOwners {
    /// The node's pressure condition (index into `fixed_pressures`).
    fixed: Vec<Option<usize>>,
    /// The flow-through R–C element whose branch row takes the node's balance.
    swapped: Vec<Option<SwappedRow>>,
    /// The unknown whose row takes the node's flow balance.
    moved: Vec<Option<usize>>,
    /// Per branch: the node whose balance its row holds (`usize::MAX`: its own equation).
    balance_of_branch: Vec<usize>,
}

/// Node → (flow unknown, sign) incidences, built by counting so that assembly stays O(n).
struct Incidence {
    start: Vec<usize>,
    inc: Vec<(usize, f64)>,
}

impl Incidence {
    fn of(circuit: &Circuit) -> Self {
        let nn = circuit.nodes.len();
        let mut deg = vec![0usize; nn + 1];
        for b in &circuit.branches {
            deg[b.from] += 1;
            deg[b.to] += 1;
        }
        let mut start = vec![0usize; nn + 1];
        for i in 0..nn {
            start[i + 1] = start[i] + deg[i];
        }
        let mut inc: Vec<(usize, f64)> = vec![(0, 0.0); start[nn]];
        let mut fill = start.clone();
        for (bi, b) in circuit.branches.iter().enumerate() {
            inc[fill[b.from]] = (nn + bi, 1.0); // flow leaves `from`
            fill[b.from] += 1;
            inc[fill[b.to]] = (nn + bi, -1.0);
            fill[b.to] += 1;
        }
        Incidence { start, inc }
    }
    fn at(&self, node: usize) -> &[(usize, f64)] {
        &self.inc[self.start[node]..self.start[node + 1]]
    }
}

/// The element of `el` with DAE unknowns (flows after the `nn` pressures, element unknowns
/// after the `nb` flows).
fn resolve(el: &CircuitElement, nn: usize, nb: usize) -> Arc<dyn Element> {
    match el {
        CircuitElement::Valve {
            name,
            law,
            branch,
            from,
            to,
        } => Arc::new(Valve::new(name.clone(), *law, *from, *to, nn + branch)),
        CircuitElement::Chamber {
            name,
            elastance,
            node,
            volume,
        } => Arc::new(Chamber::new(
            name.clone(),
            elastance.clone(),
            *node,
            nn + nb + volume,
        )),
        CircuitElement::Heart {
            name,
            params,
            nodes,
            branches,
            volumes,
            pulmonary,
        } => Arc::new(HeartPulmonary::new(
            name.clone(),
            (**params).clone(),
            HeartUnknowns {
                pressure: *nodes,
                flow: branches.map(|b| nn + b),
                volume: volumes.map(|x| nn + nb + x),
                pulmonary: nn + nb + pulmonary,
            },
        )),
        CircuitElement::Coronary {
            name,
            capacitance,
            factor,
            node,
            volume,
            ventricle,
        } => Arc::new(ClosedLoopCoronary::new(
            name.clone(),
            *capacitance,
            *factor,
            *node,
            nn + nb + volume,
            *ventricle,
        )),
        CircuitElement::Sphere {
            name,
            params,
            node,
            extras,
        } => {
            let [displacement, velocity, stress, active_stress, volume] =
                extras.map(|x| nn + nb + x);
            Arc::new(ChamberSphere::new(
                name.clone(),
                *params,
                SphereUnknowns {
                    pressure: *node,
                    displacement,
                    velocity,
                    stress,
                    active_stress,
                    volume,
                },
            ))
        }
    }
}

/// E ẏ + F y + c(y) = f(t), ready for the integrators.
#[derive(Debug, Clone)]
pub struct Dae {
    pub n: usize,
    pub n_nodes: usize,
    pub e: Vec<f64>,
    pub windkessel: Vec<bool>,
    pub f: Csr,
    /// (unknown, S): c_i = S |y_i| y_i.
    pub stenosis: Vec<(usize, f64)>,
    /// Capacitor rows generalized-α writes in svZeroDSolver's form (see
    /// [`ChainRuleCapacitor`]); every other integrator uses the row E ẏ as it is.
    pub chain_rule: Vec<ChainRuleCapacitor>,
    /// (unknown, law): the time-varying diagonal D_ii(t) = R(t) − R₀ of the transient regime
    /// (zero in the steady regimes, whose resistance is the base R₀ kept in F).
    pub varying: Vec<(usize, ResistanceLaw)>,
    /// (row, waveform): f_row(t) = w(t).
    pub forcing: Vec<(usize, Waveform)>,
    /// (node, unknown): nodes whose capacitance sits behind a viscoelastic wall, and the
    /// unknown holding the wall's elastic pressure (the lumen volume follows it, not the
    /// node's pressure).
    pub walls: Vec<(usize, usize)>,
    /// Nonlinear and time-varying elements, each adding c_el(y, t) to its rows (evaluated at
    /// the true time in every regime: a chamber's elastance has no mean to stand for it).
    pub elements: Vec<Arc<dyn Element>>,
    /// (unknown, value) set at a zero start (svZeroDSolver's `initial_condition`), e.g. a
    /// chamber's volume: a closed loop has no steady state to start from.
    pub initial: Vec<(usize, f64)>,
    /// (unknown, value) of ẏ at a zero start (svZeroDSolver's `initial_condition_d`).
    pub initial_rate: Vec<(usize, f64)>,
    /// Names of the unknowns ([`Names::unknown`]), shared with the circuit.
    pub names: Arc<Names>,
}

/// Which Jacobian of the elements an iteration matrix uses (see `crate::element::Element`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JacobianKind {
    /// ∂c/∂y at the state (generalized-α's Newton).
    Exact,
    /// The stiffest state (RK4's stability bound).
    Stiffest,
    /// Every valve closed (RK4's stability bound: a closed valve behind an inductor).
    Closed,
    /// RK4's elimination of the algebraic unknowns (a safeguarded Newton matrix).
    Elimination,
    /// The exact Jacobian of the rows in their flow form (see
    /// [`crate::element::Element::flow_form_residual`]): generalized-α's retry after a
    /// Newton failure.
    FlowForm,
}

impl Dae {
    /// Some element varies in time by itself (a chamber): the circuit has no steady state of
    /// its mean boundary conditions.
    pub fn has_chambers(&self) -> bool {
        self.elements.iter().any(|e| e.period().is_some())
    }

    /// The zero state with the `initial` values set.
    pub fn initial_state(&self) -> Vec<f64> {
        let mut y = vec![0.0; self.n];
        for &(i, v) in &self.initial {
            y[i] = v;
        }
        y
    }

    /// ẏ at a zero start: zero but for the `initial_rate` values.
    pub fn initial_rate_state(&self) -> Vec<f64> {
        let mut yd = vec![0.0; self.n];
        for &(i, v) in &self.initial_rate {
            yd[i] = v;
        }
        yd
    }

    pub fn mass(&self, regime: Regime) -> Vec<f64> {
        let mut e = self.e.clone();
        if regime == Regime::SteadyNoWindkessel {
            for (ei, &w) in e.iter_mut().zip(&self.windkessel) {
                if w {
                    *ei = 0.0;
                }
            }
        }
        e
    }

    /// No stenosis term and no nonlinear element: the residual is linear in the state
    /// (possibly time-varying).
    pub fn is_linear(&self) -> bool {
        self.stenosis.is_empty() && !self.elements.iter().any(|e| e.is_nonlinear())
    }

    /// The iteration matrix of `regime` is constant in time (no time-varying coefficient acts).
    pub fn is_constant(&self, regime: Regime) -> bool {
        (self.varying.is_empty() || regime != Regime::Transient)
            && !self.elements.iter().any(|e| e.period().is_some())
    }

    /// r −= c_el(y, t): the elements' term.
    pub fn element_residual(&self, t: f64, y: &[f64], r: &mut [f64]) {
        self.element_terms(t, y, |i, c| r[i] -= c);
    }

    /// [`Dae::element_residual`] with every valve row in its flow form (`flow_form`; see
    /// [`crate::element::Element::flow_form_residual`]).
    pub fn element_residual_of(&self, t: f64, y: &[f64], r: &mut [f64], flow_form: bool) {
        if !flow_form {
            return self.element_residual(t, y, r);
        }
        let mut c = Vec::new();
        for el in &self.elements {
            let rows = el.rows();
            c.resize(rows.len(), 0.0);
            el.flow_form_residual(t, y, &mut c);
            for (&i, &ci) in rows.iter().zip(&c) {
                r[i] -= ci;
            }
        }
    }

    /// Call `visit(row, c)` for every element term c_el(y, t).
    pub fn element_terms(&self, t: f64, y: &[f64], mut visit: impl FnMut(usize, f64)) {
        let mut c = Vec::new();
        for el in &self.elements {
            let rows = el.rows();
            c.resize(rows.len(), 0.0);
            el.residual(t, y, &mut c);
            for (&i, &ci) in rows.iter().zip(&c) {
                visit(i, ci);
            }
        }
    }

    /// Call `visit(row, (∂c_el/∂y · x)_row)` entry by entry, the Jacobian of `kind` at (y, t).
    pub fn element_matvec(
        &self,
        t: f64,
        y: &[f64],
        kind: JacobianKind,
        x: &[f64],
        mut visit: impl FnMut(usize, f64),
    ) {
        let pattern = self.element_pattern();
        let mut j = vec![0.0; pattern.len()];
        self.element_jacobian(1.0, t, y, &mut j, kind);
        for (&(r, c), v) in pattern.iter().zip(&j) {
            visit(r, v * x[c]);
        }
    }

    /// The elements' Jacobian entries (row, column), in the order of
    /// [`Dae::element_jacobian`].
    pub fn element_pattern(&self) -> Vec<(usize, usize)> {
        self.elements
            .iter()
            .flat_map(|e| e.pattern().iter().copied())
            .collect()
    }

    /// a·∂c_el/∂y at (y, t) into `vals` ([`Dae::element_pattern`] order), of the `kind`
    /// an iteration needs (each element's stiffest state for RK4's stability bound).
    pub fn element_jacobian(
        &self,
        a: f64,
        t: f64,
        y: &[f64],
        vals: &mut [f64],
        kind: JacobianKind,
    ) {
        let mut k = 0;
        for el in &self.elements {
            let m = el.pattern().len();
            let out = &mut vals[k..k + m];
            match kind {
                JacobianKind::Exact => el.jacobian(t, y, out),
                JacobianKind::Stiffest => el.stiffest_jacobian(t, y, out),
                JacobianKind::Closed => el.closed_jacobian(t, y, out),
                JacobianKind::Elimination => el.elimination_jacobian(t, y, out),
                JacobianKind::FlowForm => el.flow_form_jacobian(t, y, out),
            }
            out.iter_mut().for_each(|v| *v *= a);
            k += m;
        }
    }

    /// r −= D(t) y: the time-varying coefficients' term (transient regime only).
    pub fn varying_residual(&self, t: f64, regime: Regime, y: &[f64], r: &mut [f64]) {
        if regime == Regime::Transient {
            for (i, law) in &self.varying {
                r[*i] -= law.delta(t) * y[*i];
            }
        }
    }

    /// Add a·D(t) to `diag` (the iteration matrix's diagonal slots).
    pub fn varying_jacobian(&self, a: f64, t: f64, regime: Regime, diag: &mut [f64]) {
        if regime == Regime::Transient {
            for (i, law) in &self.varying {
                diag[*i] += a * law.delta(t);
            }
        }
    }

    /// Write f(t) into `out` (zeroed first).
    pub fn forcing_into(&self, t: f64, regime: Regime, out: &mut [f64]) {
        out.iter_mut().for_each(|x| *x = 0.0);
        for (row, w) in &self.forcing {
            out[*row] += if regime == Regime::Transient {
                w.eval(t)
            } else {
                w.mean()
            };
        }
    }

    /// r = f − F y − c(y)  (the E ẏ term is added by the caller).
    pub fn static_residual(&self, y: &[f64], f: &[f64], r: &mut [f64]) {
        for i in 0..self.n {
            r[i] = f[i] - self.f.row_dot(i, y);
        }
        for &(i, s) in &self.stenosis {
            r[i] -= s * y[i].abs() * y[i];
        }
    }

    /// Period implied by the time-varying boundary conditions, checked for consistency.
    pub fn period(&self) -> Option<f64> {
        self.forcing
            .iter()
            .filter_map(|(_, w)| w.period())
            .reduce(f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The flow matrix's u32 row starts hold up to 2^32 - 1 entries; one more is a typed
    /// error naming the circuit and the count, not a wrapped index.
    #[test]
    fn a_flow_matrix_beyond_32_bit_row_starts_is_refused() {
        assert!(flow_matrix_fits(u32::MAX as usize).is_ok());
        let e = flow_matrix_fits(u32::MAX as usize + 1).unwrap_err();
        assert!(matches!(e, Error::Model { .. }), "{e}");
        assert!(
            e.to_string().contains("4294967296 flow-matrix entries"),
            "{e}"
        );
    }

    /// A released circuit keeps the names and the inflow sources a run's output and
    /// `source_flows` read, and refuses to assemble again (its tables are gone) with a typed
    /// error saying why, instead of an empty system.
    #[test]
    fn a_released_circuit_keeps_its_names_and_refuses_to_assemble() {
        let mut k = Circuit::default();
        let p = k.add_node("p", 1e-9, 1e-6);
        let out = k.add_node("out", 0.0, 0.0);
        k.add_branch("drain", p, out, 1e8, 0.0, 0.0);
        k.sources.push((p, Waveform::constant(1e-6)));
        k.fixed_pressures.push((out, Waveform::constant(0.0)));
        let dae = k.assemble().unwrap();
        k.release_tables();
        assert!(k.is_released());
        assert!(k.nodes.is_empty() && k.branches.is_empty() && k.fixed_pressures.is_empty());
        assert_eq!(
            (k.names.node(p), dae.names.node(out)),
            ("p".into(), "out".into())
        );
        assert_eq!(k.sources.len(), 1);
        let e = k.assemble().unwrap_err();
        assert!(matches!(e, Error::Model { .. }), "{e}");
        assert!(
            e.to_string().contains("not kept for a model this large"),
            "{e}"
        );
    }
}
