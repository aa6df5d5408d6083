//! Species transport on the flow circuit (physics spec §2.5): the conservative finite-volume
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
//!   on the free concentration c = binding⁻¹(C_t) (physics §4.3).
//!
//! Two integrations share this description: the explicit right-hand side (`rhs`), integrated
//! monolithically with the flow by RK4, and a backward-Euler step (`implicit_step`) used after
//! each generalized-α flow step, solved by one sweep in flow order (an M-matrix that is
//! triangular whenever the directed flow graph is acyclic, e.g. on every tree).

use crate::circuit::{Circuit, Dae};
use crate::closure::{self, SegmentLaw, SegmentWall, WallSpec};
use crate::error::{Error, Result};
use crate::hemoglobin::{Binding, HillAnchor};
use crate::output::Probes;
pub use crate::spec::transport::{Formulation, SpeciesSpec, TransportSpec};
use crate::waveform::Waveform;

/// Largest accepted `cells_per_segment` (a guard against typos that would allocate millions
/// of cells per segment).
const MAX_CELLS_PER_SEGMENT: f64 = 10_000.0;

fn cells_per_segment(v: f64, element: &str, key: &str) -> Result<usize> {
    if v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= MAX_CELLS_PER_SEGMENT {
        Ok(v as usize)
    } else {
        Err(Error::model(
            element,
            format!("{key} must be an integer between 1 and {MAX_CELLS_PER_SEGMENT}, got {v}"),
        ))
    }
}

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

#[derive(Debug, Clone)]
struct Face {
    /// Flow unknown (index into y); `usize::MAX` for the interior faces of a refined cell,
    /// whose flows `Chain::flows` derives from the unknowns.
    unknown: usize,
    from: End,
    to: End,
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
#[derive(Debug, Clone)]
struct Piece {
    seg: usize,
    node: usize,
    cell: usize,
    share: f64,
    wall: SegmentWall,
}

#[derive(Debug, Clone)]
enum BoundaryValue {
    Wave(Waveform),
    ZeroGradient,
}

#[derive(Debug, Clone)]
struct Species {
    name: String,
    binding: Binding,
    decay: f64,
    diffusivity: f64,
    boundary: Vec<BoundaryValue>,
    walls: Vec<WallSpec>,
    /// Law of every wall piece.
    laws: Vec<SegmentLaw>,
    /// Per cell: Σ share·g, Σ share·g·c_w, Σ share·q of its segments' fixed laws.
    cell_g: Vec<f64>,
    cell_gcw: Vec<f64>,
    cell_q: Vec<f64>,
    /// Wall pieces whose conductance follows a time-dependent shear.
    dynamic: Vec<usize>,
    /// Segments with a relaxed Lévêque shear: (segment, τ_BL); their equivalent flows
    /// Q̃ = π r³ γ̃/4 are state entries `relax_offset + k`.
    relax: Vec<(usize, f64)>,
    relax_of_seg: Vec<usize>,
    relax_offset: usize,
    /// Segments with dynamic pieces, and per segment the cube root of the flow magnitude its
    /// dynamic laws see (|Q| or Q̃), see `load_shear`.
    dynamic_segs: Vec<usize>,
    shear_cbrt: Vec<f64>,
    has_wall: bool,
    initial_free: f64,
    /// Free concentration per node: warm start of the binding inversion, and reporting.
    free: Vec<f64>,
    /// Per node: Taylor anchor of the Hill inversion (cells change little between stages).
    anchors: Vec<HillAnchor>,
    /// Total concentration of the mixing points: their lagged value (used when a point has
    /// no outflow, and for zero-gradient backflow into it) is per species.
    mixing_conc: Vec<f64>,
}

impl Species {
    /// Wall uptake (mol/s) of cell `i` from its fixed laws at free concentration `free`:
    /// Σ share·(g (c − c_w) + q) = G c − Σ share g c_w + Q (the wall-uptake law, physics §3).
    #[inline]
    fn fixed_uptake(&self, i: usize, free: f64) -> f64 {
        self.cell_g[i] * free - self.cell_gcw[i] + self.cell_q[i]
    }

    /// Wall uptake (mol/s) of wall piece `p` with its own law (any kind) at the current shear,
    /// `free` the free concentration per node.
    #[inline]
    fn piece_uptake(&self, pieces: &[Piece], p: usize, free: &[f64]) -> f64 {
        let pc = &pieces[p];
        let (g, cw, q) = self.laws[p].eval_cbrt(self.shear_cbrt[pc.seg]);
        pc.share * (g * (free[pc.node] - cw) + q)
    }
}

impl Species {
    /// Validate one species of the transport section against the circuit: binding, boundary
    /// values of every boundary condition, walls per vessel, initial value. `sizes` = (cells,
    /// segments, transport nodes).
    fn build(
        sp: &SpeciesSpec,
        circuit: &Circuit,
        boundary_names: &[String],
        boundary_inlet: &[bool],
        sizes: (usize, usize, usize),
    ) -> Result<Self> {
        let (ncells, nsegs, nnodes) = sizes;
        let el = format!("species '{}'", sp.name);
        if !(sp.decay.is_finite() && sp.decay >= 0.0) {
            return Err(bad(
                &el,
                format!("decay must be a finite number >= 0, got {}", sp.decay),
            ));
        }
        if !(sp.diffusivity.is_finite() && sp.diffusivity >= 0.0) {
            return Err(bad(
                &el,
                format!(
                    "diffusivity must be a finite number >= 0, got {}",
                    sp.diffusivity
                ),
            ));
        }
        let binding = Binding::from_spec(&sp.binding, &el)?;
        let inlet = Waveform::from_spec(&sp.inlet, &format!("{el} inlet"))?;
        for name in sp.inlets.keys().chain(sp.backflow.keys()) {
            if !boundary_names.contains(name) {
                return Err(bad(
                    &el,
                    format!("names boundary condition '{name}', which the network does not have"),
                ));
            }
        }
        let mut boundary = Vec::new();
        for (b, name) in boundary_names.iter().enumerate() {
            let v = if boundary_inlet[b] {
                match sp.inlets.get(name) {
                    Some(w) => BoundaryValue::Wave(Waveform::from_spec(
                        w,
                        &format!("{el} inlet '{name}'"),
                    )?),
                    None => BoundaryValue::Wave(inlet.clone()),
                }
            } else {
                match sp.backflow.get(name) {
                    Some(w) => BoundaryValue::Wave(Waveform::from_spec(
                        w,
                        &format!("{el} backflow '{name}'"),
                    )?),
                    None => BoundaryValue::ZeroGradient,
                }
            };
            boundary.push(v);
        }
        sp.wall.validate(&format!("{el} wall"))?;
        let mut walls = vec![sp.wall.clone(); circuit.vessel_names.len()];
        for (vname, w) in &sp.per_vessel {
            let Some(vi) = circuit.vessel_names.iter().position(|n| n == vname) else {
                return Err(bad(
                    &el,
                    format!("per_vessel names vessel '{vname}', which the network does not have"),
                ));
            };
            w.validate(&format!("{el} wall of vessel '{vname}'"))?;
            walls[vi] = w.clone();
        }
        let initial_free = match sp.initial {
            Some(c) if c.is_finite() && c >= 0.0 => c,
            Some(c) => {
                return Err(bad(
                    &el,
                    format!("initial concentration must be >= 0, got {c}"),
                ));
            }
            None => inlet.eval(0.0),
        };
        Ok(Species {
            name: sp.name.clone(),
            binding,
            decay: sp.decay,
            diffusivity: sp.diffusivity,
            boundary,
            walls,
            laws: Vec::new(),
            cell_g: vec![0.0; ncells],
            cell_gcw: vec![0.0; ncells],
            cell_q: vec![0.0; ncells],
            dynamic: Vec::new(),
            relax: Vec::new(),
            relax_of_seg: vec![usize::MAX; nsegs],
            relax_offset: 0,
            dynamic_segs: Vec::new(),
            shear_cbrt: vec![0.0; nsegs],
            has_wall: false,
            initial_free,
            free: vec![initial_free; nnodes],
            anchors: vec![HillAnchor::default(); nnodes],
            mixing_conc: Vec::new(),
        })
    }
}

#[derive(Debug, Clone)]
struct Segment {
    branch_unknown: usize,
    nodes: [(usize, f64); 2],
    wall: SegmentWall,
    dx: f64,
    volume: f64,
    compliance: f64,
}

/// Outputs of one vessel: first and last face (flow unknowns) and its segment range.
#[derive(Debug, Clone)]
struct OutVessel {
    first: usize,
    last: usize,
    segs: std::ops::Range<usize>,
}

pub const VESSEL_COLUMNS: usize = 5;
pub const SEGMENT_COLUMNS: usize = 5;
pub const BALANCE_COLUMNS: usize = 5;

/// Runtime transport: topology, closures, scratch. Cloned per run.
#[derive(Debug, Clone)]
pub struct Transport {
    kind: Vec<Kind>,
    cells: Vec<usize>,
    node_cell: Vec<usize>,
    v0: Vec<f64>,
    cap: Vec<f64>,
    p_ref: f64,
    faces: Vec<Face>,
    face_of_unknown: Vec<usize>,
    sources: Vec<(usize, Waveform, usize)>,
    boundary_inlet: Vec<bool>,
    mixing: Vec<usize>,
    /// CSR node → incident faces; sources listed separately.
    node_ptr: Vec<usize>,
    node_faces: Vec<usize>,
    node_sources: Vec<Vec<usize>>,
    segments: Vec<Segment>,
    /// Faces 0..n_flow_faces carry a flow unknown; the rest are interior faces of `chains`.
    n_flow_faces: usize,
    /// The flow unknown of faces 0..n_flow_faces (a compact copy for the per-step gather).
    face_unknowns: Vec<usize>,
    chains: Vec<Chain>,
    /// Per cell: the circuit node whose pressure sets its volume.
    cell_node: Vec<usize>,
    /// Per circuit node: its last sub-cell (itself unless refined): the donor of the faces
    /// leaving the node, and the value reported for its segments.
    last_sub: Vec<usize>,
    /// Wall pieces, contiguous per segment (`seg_pieces`).
    pieces: Vec<Piece>,
    seg_pieces: Vec<std::ops::Range<usize>>,
    species: Vec<Species>,
    /// Cycle-mean |Q| per segment (set by `set_mean_flow`): the relaxed shears start there.
    mean_abs: Vec<f64>,
    formulation: Formulation,
    v_eps: f64,
    out_vessels: Vec<OutVessel>,
    out_segments: Vec<usize>,
    /// Record the per-segment columns (off: vessel and balance columns only).
    segment_output: bool,
    segment_vessels: Vec<usize>,
    node_names: Vec<String>,
    /// Nodes solved by the implicit sweep (cells and mixing points).
    domain: Vec<usize>,
    /// Faces between two domain nodes as [face, from node, to node], and the other faces.
    internal: Vec<[u32; 3]>,
    boundary_faces: Vec<usize>,
    /// Mixing points with two faces, no source and non-mixing neighbours: evaluated directly.
    simple_mixing: Vec<usize>,
    /// The other mixing points (solved by the flow-order sweep).
    general_mixing: Vec<usize>,
    /// Elimination order of the implicit solve when the domain graph is a forest (always on
    /// trees): None sends it to the flow-order sweep, which also handles loops.
    tree: Option<Vec<Link>>,
    // scratch
    vol: Vec<f64>,
    conc: Vec<f64>,
    qf: Vec<f64>,
    qs: Vec<f64>,
    bval: Vec<Option<f64>>,
    sweep: Sweep,
    /// Transport volumes of the implicit path (evolved with the face flows).
    wvol: Vec<f64>,
}

fn bad(element: &str, msg: String) -> Error {
    Error::model(element, msg)
}

impl Transport {
    /// Validate the transport section against the assembled circuit.
    pub fn build(
        spec: &TransportSpec,
        circuit: &Circuit,
        dae: &Dae,
        probes: &Probes,
    ) -> Result<Self> {
        let nn = circuit.nodes.len();
        if spec.species.is_empty() {
            return Err(bad("transport", "has no species".into()));
        }
        if !spec.reference_pressure.is_finite() {
            return Err(bad(
                "transport",
                format!(
                    "reference_pressure must be finite, got {}",
                    spec.reference_pressure
                ),
            ));
        }
        if !(spec.velocity_threshold.is_finite() && spec.velocity_threshold >= 0.0) {
            return Err(bad(
                "transport",
                format!(
                    "velocity_threshold must be >= 0, got {}",
                    spec.velocity_threshold
                ),
            ));
        }
        if circuit.source_boundary.len() != circuit.sources.len() {
            return Err(bad(
                "transport",
                "the circuit's flow sources are not tagged with boundary conditions".into(),
            ));
        }
        let fixed: Vec<bool> = {
            let mut f = vec![false; nn];
            for (n, _) in &circuit.fixed_pressures {
                f[*n] = true;
            }
            f
        };
        let mut kind = vec![Kind::Mixing; nn];
        for (i, node) in circuit.nodes.iter().enumerate() {
            kind[i] = if node.boundary.is_some() || fixed[i] {
                Kind::Exterior
            } else if node.volume > 0.0 {
                Kind::Cell
            } else {
                if dae.e[i] > 0.0 {
                    // a compliant node with no lumen volume would store blood but no solute
                    return Err(bad(
                        &node.name,
                        "has compliance but no lumen volume, so transport cannot conserve mass there; give the vessel geometry instead of lumped values".into(),
                    ));
                }
                Kind::Mixing
            };
        }
        let boundary_of = |n: usize| -> End {
            match circuit.nodes[n].boundary {
                Some(b) if kind[n] == Kind::Exterior => End::Boundary(b),
                _ => End::Node(n),
            }
        };
        let mut faces = Vec::new();
        let mut face_of_unknown = vec![usize::MAX; dae.n];
        for (bi, b) in circuit.branches.iter().enumerate() {
            let (ka, kb) = (kind[b.from], kind[b.to]);
            if ka == Kind::Exterior && kb == Kind::Exterior {
                continue;
            }
            let (from, to) = (boundary_of(b.from), boundary_of(b.to));
            // a prescribed-pressure node without a tag cannot happen from network.rs; be explicit
            for (k, e) in [(ka, from), (kb, to)] {
                if k == Kind::Exterior && matches!(e, End::Node(_)) {
                    return Err(bad(
                        &b.name,
                        "connects to a prescribed-pressure node without a boundary condition"
                            .into(),
                    ));
                }
            }
            face_of_unknown[nn + bi] = faces.len();
            faces.push(Face {
                unknown: nn + bi,
                from,
                to,
            });
        }
        let sources: Vec<(usize, Waveform, usize)> = circuit
            .sources
            .iter()
            .zip(&circuit.source_boundary)
            .filter(|((n, _), _)| kind[*n] != Kind::Exterior)
            .map(|((n, w), b)| (*n, w.clone(), *b))
            .collect();
        // Contract pass-through points at boundaries: a volume-free node joining one face to a
        // cell and one face to a boundary (the end node of an inverted-L vessel at a resistance
        // or Windkessel outlet) carries the same flow on both (KCL), so the cell's face leads
        // straight to the boundary. Zero-gradient backflow then carries the cell's own value,
        // and the hot loop has one point less per outlet.
        {
            let mut inc: Vec<Vec<usize>> = vec![Vec::new(); nn];
            for (fi, f) in faces.iter().enumerate() {
                for e in [f.from, f.to] {
                    if let End::Node(n) = e {
                        inc[n].push(fi);
                    }
                }
            }
            let mut has_source = vec![false; nn];
            for ((n, _), _) in circuit.sources.iter().zip(&circuit.source_boundary) {
                has_source[*n] = true;
            }
            let other = |f: &Face, m: usize| if f.from == End::Node(m) { f.to } else { f.from };
            let mut dropped = vec![false; faces.len()];
            for m in 0..nn {
                if kind[m] != Kind::Mixing || inc[m].len() != 2 || has_source[m] {
                    continue;
                }
                let (fa, fb) = (inc[m][0], inc[m][1]);
                let (f_net, f_bnd, b) = match (other(&faces[fa], m), other(&faces[fb], m)) {
                    (End::Node(n), End::Boundary(b)) if kind[n] == Kind::Cell => (fa, fb, b),
                    (End::Boundary(b), End::Node(n)) if kind[n] == Kind::Cell => (fb, fa, b),
                    _ => continue,
                };
                let f = &mut faces[f_net];
                if f.from == End::Node(m) {
                    f.from = End::Boundary(b);
                } else {
                    f.to = End::Boundary(b);
                }
                dropped[f_bnd] = true;
                kind[m] = Kind::Exterior;
            }
            let mut k = 0;
            faces.retain(|_| {
                k += 1;
                !dropped[k - 1]
            });
            face_of_unknown.iter_mut().for_each(|v| *v = usize::MAX);
            for (fi, f) in faces.iter().enumerate() {
                face_of_unknown[f.unknown] = fi;
            }
        }
        // Refinement (physics §5): every volume node becomes a chain of m sub-cells (see
        // `Chain`). Sub-cell 0 is the node itself; the others are new transport nodes nn.., so
        // the face, upwind and sweep machinery below works unchanged on the refined graph.
        let m_default =
            cells_per_segment(spec.cells_per_segment, "transport", "cells_per_segment")?;
        let mut m_vessel = vec![m_default; circuit.vessel_names.len()];
        for (name, &v) in &spec.cells_per_vessel {
            let Some(vi) = circuit.vessel_names.iter().position(|n| n == name) else {
                return Err(bad(
                    "transport",
                    format!(
                        "cells_per_vessel names vessel '{name}', which the network does not have"
                    ),
                ));
            };
            m_vessel[vi] = cells_per_segment(v, &format!("vessel '{name}'"), "cells_per_segment")?;
        }
        // a node shared by vessels (a junction cell) takes the finest of their refinements
        let mut m_node = vec![1usize; nn];
        for sg in &circuit.segments {
            for &(n, share) in &sg.nodes {
                if share > 0.0 && kind[n] == Kind::Cell {
                    m_node[n] = m_node[n].max(m_vessel[sg.vessel]);
                }
            }
        }
        let n_flow_faces = faces.len();
        let mut node_names: Vec<String> = circuit.nodes.iter().map(|n| n.name.clone()).collect();
        let mut first_extra = vec![usize::MAX; nn];
        let mut last_sub: Vec<usize> = (0..nn).collect();
        let mut chains = Vec::new();
        if m_node.iter().any(|&m| m > 1) {
            let (mut ins, mut outs) = (vec![Vec::new(); nn], vec![Vec::new(); nn]);
            for (fi, f) in faces.iter().enumerate() {
                if let End::Node(n) = f.to {
                    ins[n].push(fi);
                }
                if let End::Node(n) = f.from {
                    outs[n].push(fi);
                }
            }
            let mut node_src = vec![Vec::new(); nn];
            for (k, (n, _, _)) in sources.iter().enumerate() {
                node_src[*n].push(k);
            }
            for n in 0..nn {
                let m = m_node[n];
                if m == 1 {
                    continue;
                }
                first_extra[n] = kind.len();
                for k in 1..m {
                    kind.push(Kind::Cell);
                    node_names.push(format!("{} (transport cell {}/{m})", node_names[n], k + 1));
                }
                let sub = |k: usize| if k == 0 { n } else { first_extra[n] + k - 1 };
                last_sub[n] = sub(m - 1);
                for &fi in &outs[n] {
                    faces[fi].from = End::Node(last_sub[n]);
                }
                let first_face = faces.len();
                for k in 1..m {
                    faces.push(Face {
                        unknown: usize::MAX,
                        from: End::Node(sub(k - 1)),
                        to: End::Node(sub(k)),
                    });
                }
                chains.push(Chain {
                    in_faces: std::mem::take(&mut ins[n]),
                    out_faces: std::mem::take(&mut outs[n]),
                    sources: std::mem::take(&mut node_src[n]),
                    first_face,
                    m,
                });
            }
        }
        let nt = kind.len();
        // cells in node order, the sub-cells of a node contiguous (unchanged order when m = 1)
        let mut cells = Vec::new();
        let mut node_cell = vec![usize::MAX; nt];
        let mut cell_node = Vec::new();
        let mut v0 = Vec::new();
        let mut cap = Vec::new();
        for n in 0..nn {
            if kind[n] != Kind::Cell {
                continue;
            }
            let m = m_node[n];
            for k in 0..m {
                let c = if k == 0 { n } else { first_extra[n] + k - 1 };
                node_cell[c] = cells.len();
                cells.push(c);
                cell_node.push(n);
                v0.push(circuit.nodes[n].volume / m as f64);
                cap.push(dae.e[n] / m as f64);
            }
        }
        let nn = nt;
        let mixing: Vec<usize> = (0..nn).filter(|&i| kind[i] == Kind::Mixing).collect();
        let mut deg = vec![0usize; nn + 1];
        for f in &faces {
            for e in [f.from, f.to] {
                if let End::Node(n) = e {
                    deg[n] += 1;
                }
            }
        }
        let mut node_ptr = vec![0usize; nn + 1];
        for i in 0..nn {
            node_ptr[i + 1] = node_ptr[i] + deg[i];
        }
        let mut node_faces = vec![0usize; node_ptr[nn]];
        let mut fill = node_ptr.clone();
        for (fi, f) in faces.iter().enumerate() {
            for e in [f.from, f.to] {
                if let End::Node(n) = e {
                    node_faces[fill[n]] = fi;
                    fill[n] += 1;
                }
            }
        }
        let mut node_sources = vec![Vec::new(); nn];
        for (k, (n, _, _)) in sources.iter().enumerate() {
            node_sources[*n].push(k);
        }
        let nc_nodes = circuit.nodes.len();
        let segments: Vec<Segment> = circuit
            .segments
            .iter()
            .map(|s| Segment {
                branch_unknown: nc_nodes + s.branch,
                nodes: s.nodes,
                wall: SegmentWall {
                    radius: s.radius,
                    x0: s.x0,
                    x1: s.x1,
                },
                dx: s.x1 - s.x0,
                volume: s.volume,
                compliance: s.compliance,
            })
            .collect();
        let (pieces, seg_pieces) = wall_pieces(&segments, &m_node, &node_cell, &first_extra);

        let boundary_inlet: Vec<bool> = circuit.boundaries.iter().map(|b| b.inlet).collect();
        let boundary_names: Vec<String> =
            circuit.boundaries.iter().map(|b| b.name.clone()).collect();
        let mut species = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let sizes = (cells.len(), segments.len(), kind.len());
        for sp in &spec.species {
            if sp.name.is_empty() || !seen.insert(sp.name.clone()) {
                let el = format!("species '{}'", sp.name);
                return Err(bad(&el, "needs a unique, non-empty name".into()));
            }
            species.push(Species::build(
                sp,
                circuit,
                &boundary_names,
                &boundary_inlet,
                sizes,
            )?);
        }
        let (out_vessels, out_segments) = output_layout(circuit, probes);
        let ncells = cells.len();
        let mut t = Transport {
            kind,
            cells,
            node_cell,
            v0,
            cap,
            p_ref: spec.reference_pressure,
            faces,
            face_of_unknown,
            sources,
            boundary_inlet,
            mixing,
            node_ptr,
            node_faces,
            node_sources,
            segments,
            n_flow_faces,
            face_unknowns: Vec::new(),
            chains,
            cell_node,
            last_sub,
            pieces,
            seg_pieces,
            species,
            mean_abs: Vec::new(),
            formulation: spec.formulation,
            v_eps: spec.velocity_threshold,
            out_vessels,
            out_segments,
            segment_output: true,
            segment_vessels: circuit.segments.iter().map(|s| s.vessel).collect(),
            node_names,
            domain: Vec::new(),
            internal: Vec::new(),
            boundary_faces: Vec::new(),
            simple_mixing: Vec::new(),
            general_mixing: Vec::new(),
            tree: None,
            vol: vec![0.0; ncells],
            conc: vec![0.0; nn],
            qf: Vec::new(),
            qs: Vec::new(),
            bval: Vec::new(),
            sweep: Sweep::new(nn),
            wvol: Vec::new(),
        };
        t.qf = vec![0.0; t.faces.len()];
        t.qs = vec![0.0; t.sources.len()];
        t.bval = vec![None; t.boundary_inlet.len()];
        t.domain = (0..nn).filter(|&n| t.kind[n] != Kind::Exterior).collect();
        if t.faces.len() >= u32::MAX as usize || nn >= u32::MAX as usize {
            return Err(bad("transport", "network too large".into()));
        }
        for (fi, f) in t.faces.iter().enumerate() {
            match (f.from, f.to) {
                (End::Node(a), End::Node(b)) => t.internal.push([fi as u32, a as u32, b as u32]),
                _ => t.boundary_faces.push(fi),
            }
        }
        for &m in &t.mixing {
            let faces = &t.node_faces[t.node_ptr[m]..t.node_ptr[m + 1]];
            let neighbours_known = faces.iter().all(|&fi| {
                let f = &t.faces[fi];
                let other = if f.from == End::Node(m) { f.to } else { f.from };
                !matches!(other, End::Node(o) if t.kind[o] == Kind::Mixing)
            });
            if faces.len() == 2 && t.node_sources[m].is_empty() && neighbours_known {
                t.simple_mixing.push(m);
            } else {
                t.general_mixing.push(m);
            }
        }
        t.tree = tree_order(nn, &t.domain, &t.internal);
        t.face_unknowns = t.faces[..t.n_flow_faces]
            .iter()
            .map(|f| f.unknown)
            .collect();
        // laws that do not need the mean flow are final now
        let zero = vec![0.0; t.segments.len()];
        t.set_laws(&zero, false)?;
        Ok(t)
    }

    pub fn species_names(&self) -> Vec<String> {
        self.species.iter().map(|s| s.name.clone()).collect()
    }
    pub fn n_cells(&self) -> usize {
        self.cells.len()
    }
    /// Length of the coupled state: amounts per cell and species, then 4 accumulators per
    /// species (I_in, I_out, I_wall, I_decay), then the relaxed shears of every species.
    pub fn state_len(&self) -> usize {
        self.species.len() * (self.cells.len() + 4)
            + self.species.iter().map(|s| s.relax.len()).sum::<usize>()
    }
    pub fn formulation(&self) -> Formulation {
        self.formulation
    }
    /// Columns recorded per species at every output time.
    pub fn columns_per_species(&self) -> usize {
        let segments = if self.segment_output {
            self.out_segments.len()
        } else {
            0
        };
        VESSEL_COLUMNS * self.out_vessels.len() + SEGMENT_COLUMNS * segments + BALANCE_COLUMNS
    }
    /// Record the per-segment columns (default) or only the vessel and balance columns, which
    /// keeps the output of large trees small.
    pub fn set_segment_output(&mut self, on: bool) {
        self.segment_output = on;
    }
    /// Recorded segments of every output vessel.
    pub fn out_segment_counts(&self) -> Vec<usize> {
        self.out_vessels.iter().map(|v| v.segs.len()).collect()
    }

    /// Flow unknowns whose cycle-mean |Q| the closures need (empty: single pass).
    pub fn mean_flow_unknowns(&self) -> Vec<usize> {
        if self
            .species
            .iter()
            .any(|s| s.walls.iter().any(|w| w.needs_mean_flow()))
        {
            self.segments.iter().map(|s| s.branch_unknown).collect()
        } else {
            Vec::new()
        }
    }

    /// Evaluate the segment laws; `mean_abs[j]` is segment j's cycle-mean |Q|.
    pub fn set_mean_flow(&mut self, mean_abs: &[f64]) -> Result<()> {
        self.mean_abs = mean_abs.to_vec();
        self.set_laws(mean_abs, true)
    }

    fn set_laws(&mut self, mean_abs: &[f64], final_pass: bool) -> Result<()> {
        let nc = self.cells.len();
        let mut offset = self.species.len() * (nc + 4);
        for sp in &mut self.species {
            sp.laws.clear();
            sp.dynamic.clear();
            sp.dynamic_segs.clear();
            sp.relax.clear();
            sp.relax_of_seg.iter_mut().for_each(|k| *k = usize::MAX);
            if final_pass {
                for (j, seg) in self.segments.iter().enumerate() {
                    if sp.walls[self.segment_vessels[j]].is_relaxed()
                        && seg.wall.radius > 0.0
                        && seg.dx > 0.0
                    {
                        sp.relax_of_seg[j] = sp.relax.len();
                        let tau = closure::relaxation_time(&seg.wall, sp.diffusivity, mean_abs[j]);
                        sp.relax.push((j, tau));
                    }
                }
            }
            sp.relax_offset = offset;
            offset += sp.relax.len();
            sp.cell_g = vec![0.0; nc];
            sp.cell_gcw = vec![0.0; nc];
            sp.cell_q = vec![0.0; nc];
            for (p, piece) in self.pieces.iter().enumerate() {
                let j = piece.seg;
                let seg = &self.segments[j];
                let vessel_wall = &sp.walls[self.segment_vessels[j]];
                let law = if seg.wall.radius <= 0.0
                    || seg.dx <= 0.0
                    || (vessel_wall.needs_mean_flow() && !final_pass)
                {
                    SegmentLaw::Fixed {
                        g: 0.0,
                        cw: 0.0,
                        q: 0.0,
                    }
                } else {
                    vessel_wall.segment_law(
                        &piece.wall,
                        sp.diffusivity,
                        mean_abs[j],
                        &format!("species '{}' wall", sp.name),
                    )?
                };
                match law {
                    SegmentLaw::Fixed { g, cw, q } => {
                        let (c, share) = (piece.cell, piece.share);
                        sp.cell_g[c] += share * g;
                        sp.cell_gcw[c] += share * g * cw;
                        sp.cell_q[c] += share * q;
                    }
                    SegmentLaw::Instantaneous { .. } => {
                        sp.dynamic.push(p);
                        // pieces are contiguous per segment
                        if sp.dynamic_segs.last() != Some(&j) {
                            sp.dynamic_segs.push(j);
                        }
                    }
                }
                sp.laws.push(law);
            }
            sp.has_wall = !sp.dynamic.is_empty()
                || sp.cell_g.iter().any(|&g| g != 0.0)
                || sp.cell_q.iter().any(|&q| q != 0.0);
        }
        Ok(())
    }

    /// Initial state: uniform initial concentration of every species in V(P0).
    pub fn initial_state(&mut self, y: &[f64]) -> Result<Vec<f64>> {
        self.volumes(y, 0.0)?;
        let nc = self.cells.len();
        let mut z = vec![0.0; self.state_len()];
        let nmix = self.mixing.len();
        for (s, sp) in self.species.iter_mut().enumerate() {
            let ct = sp.binding.total(sp.initial_free);
            sp.mixing_conc = vec![ct; nmix];
            for i in 0..nc {
                z[s * nc + i] = self.vol[i] * ct;
            }
            for (k, &(j, _)) in sp.relax.iter().enumerate() {
                z[sp.relax_offset + k] = self.mean_abs.get(j).copied().unwrap_or(0.0);
            }
        }
        self.wvol = self.vol.clone();
        Ok(z)
    }

    fn volumes(&mut self, y: &[f64], time: f64) -> Result<()> {
        for (i, &n) in self.cell_node.iter().enumerate() {
            let v = self.v0[i] + self.cap[i] * (y[n] - self.p_ref);
            if v.is_nan() || v <= 0.0 {
                return Err(Error::solver(
                    time,
                    format!(
                        "lumen volume of transport cell '{}' is {v:.3e} m³ (V0 {:.3e} m³, pressure {:.1} Pa, reference pressure {:.1} Pa): set oxygen reference_pressure closer to the working pressure",
                        self.node_name(n),
                        self.v0[i],
                        y[n],
                        self.p_ref
                    ),
                ));
            }
            self.vol[i] = v;
        }
        Ok(())
    }

    fn node_name(&self, n: usize) -> String {
        self.node_names
            .get(n)
            .cloned()
            .unwrap_or_else(|| format!("node {n}"))
    }

    fn load_flows(&mut self, time: f64, y: &[f64]) {
        self.load_flows_with(time, |u| y[u]);
    }

    /// Face flows at the α_f level of a step from `y0` to `y1`: Q = Q_0 + α_f (Q_1 − Q_0).
    fn load_flows_between(&mut self, time: f64, y0: &[f64], y1: &[f64], alpha_f: f64) {
        self.load_flows_with(time, |u| y0[u] + alpha_f * (y1[u] - y0[u]));
    }

    /// Face flows from `flow(unknown)`, source flows at `time`, and the interior faces of
    /// refined cells.
    fn load_flows_with(&mut self, time: f64, flow: impl Fn(usize) -> f64) {
        let nf = self.n_flow_faces;
        for (q, &u) in self.qf[..nf].iter_mut().zip(&self.face_unknowns) {
            *q = flow(u);
        }
        for (q, (_, w, _)) in self.qs.iter_mut().zip(&self.sources) {
            *q = w.eval(time);
        }
        // interior faces of refined cells: Q_k = Q_A − (k/m)(Q_A − Q_B)
        for ch in &self.chains {
            let q_a = ch.in_faces.iter().map(|&f| self.qf[f]).sum::<f64>()
                + ch.sources.iter().map(|&k| self.qs[k]).sum::<f64>();
            let q_b: f64 = ch.out_faces.iter().map(|&f| self.qf[f]).sum();
            for k in 1..ch.m {
                self.qf[ch.first_face + k - 1] = q_a - (k as f64 / ch.m as f64) * (q_a - q_b);
            }
        }
    }

    fn load_boundary(&mut self, s: usize, time: f64) {
        let sp = &self.species[s];
        for (v, b) in self.bval.iter_mut().zip(&sp.boundary) {
            *v = match b {
                BoundaryValue::Wave(w) => Some(sp.binding.total(w.eval(time))),
                BoundaryValue::ZeroGradient => None,
            };
        }
    }

    /// Total concentration carried by a face from the boundary end `b` next to node `n`:
    /// prescribed, or zero-gradient (the neighbour's value; for a mixing point the value its
    /// sweep used, so that the point stays exactly balanced).
    /// Flow and upwind (donor) concentration of face `fi`.
    #[inline]
    fn upwind(&self, fi: usize) -> (f64, f64) {
        let (q, up, other) = oriented(&self.faces, &self.qf, fi);
        let c = match up {
            End::Node(n) => self.conc[n],
            End::Boundary(b) => self.boundary_conc(b, other),
        };
        (q, c)
    }

    #[inline]
    fn boundary_conc(&self, b: usize, n: End) -> f64 {
        match n {
            End::Node(n) if self.kind[n] == Kind::Mixing => {
                inflow_value(self.bval[b], self.sweep.lag[n])
            }
            End::Node(n) => inflow_value(self.bval[b], self.conc[n]),
            End::Boundary(_) => inflow_value(self.bval[b], 0.0),
        }
    }

    /// Free concentration of every cell of species `s` (binding inversion, warm-started).
    fn free_of_cells(&mut self, s: usize) {
        let sp = &mut self.species[s];
        if sp.binding.is_identity() {
            for &n in &self.cells {
                sp.free[n] = self.conc[n];
            }
        } else {
            for &n in &self.cells {
                sp.free[n] = sp
                    .binding
                    .free_anchored(self.conc[n], sp.free[n], &mut sp.anchors[n]);
            }
        }
    }

    /// Wall uptake of every cell for species `s` into `w` (mol/s), from the current free
    /// concentrations and branch flows `y`.
    fn wall_uptake(&self, s: usize, w: &mut [f64]) {
        let sp = &self.species[s];
        // without binding the free concentration is the total one (no copy)
        let free = if sp.binding.is_identity() {
            &self.conc
        } else {
            &sp.free
        };
        for (i, &n) in self.cells.iter().enumerate() {
            w[i] = sp.fixed_uptake(i, free[n]);
        }
        for &p in &sp.dynamic {
            w[self.pieces[p].cell] += sp.piece_uptake(&self.pieces, p, free);
        }
    }

    /// |Q|^{1/3} seen by the dynamic laws of species `s`, per segment: the branch flow
    /// (instantaneous shear) or the relaxed equivalent flow Q̃ held in the state `z`.
    fn load_shear(&mut self, s: usize, y: &[f64], z: &[f64]) {
        let sp = &mut self.species[s];
        for &j in &sp.dynamic_segs {
            let k = sp.relax_of_seg[j];
            let q = if k == usize::MAX {
                y[self.segments[j].branch_unknown]
            } else {
                z[sp.relax_offset + k]
            };
            sp.shear_cbrt[j] = q.abs().cbrt();
        }
    }

    /// Concentrations of the mixing points from their upwind neighbours (flux-weighted).
    fn mix(&mut self, s: usize) -> Result<()> {
        if self.mixing.is_empty() {
            return Ok(());
        }
        self.restore_mixing(s);
        // two-face pass-through points next to cells or boundaries: c = Σ_in |Q| C_up / Σ_out |Q|
        for &m in &self.simple_mixing {
            let lag = self.conc[m];
            self.sweep.lag[m] = lag;
            let (mut num, mut den) = (0.0, 0.0);
            for &fi in &self.node_faces[self.node_ptr[m]..self.node_ptr[m + 1]] {
                let (q, up, down) = oriented(&self.faces, &self.qf, fi);
                if up == End::Node(m) {
                    den += q.abs();
                } else if down == End::Node(m) {
                    let c = match up {
                        End::Node(u) => self.conc[u],
                        End::Boundary(b) => inflow_value(self.bval[b], lag),
                    };
                    num += q.abs() * c;
                }
            }
            self.conc[m] = if den > 1e-300 { num / den } else { lag };
        }
        if self.general_mixing.is_empty() {
            self.save_mixing(s);
            return Ok(());
        }
        let nn = self.kind.len();
        let mut d = std::mem::take(&mut self.sweep.d);
        let mut b = std::mem::take(&mut self.sweep.b);
        d.resize(nn, 0.0);
        b.resize(nn, 0.0);
        for &m in &self.mixing {
            d[m] = 0.0;
            b[m] = 0.0;
        }
        let mut x = std::mem::take(&mut self.conc);
        let mixing = std::mem::take(&mut self.general_mixing);
        let res = self.sweep_solve(&mixing, &d, &b, &mut x);
        self.general_mixing = mixing;
        self.conc = x;
        self.sweep.d = d;
        self.sweep.b = b;
        self.save_mixing(s);
        res
    }

    fn restore_mixing(&mut self, s: usize) {
        let mc = &self.species[s].mixing_conc;
        if mc.len() == self.mixing.len() {
            for (&m, &c) in self.mixing.iter().zip(mc) {
                self.conc[m] = c;
            }
        }
    }

    fn save_mixing(&mut self, s: usize) {
        let sp = &mut self.species[s];
        sp.mixing_conc.clear();
        sp.mixing_conc
            .extend(self.mixing.iter().map(|&m| self.conc[m]));
    }

    /// Explicit right-hand side dz/dt at (t, y) for the monolithic RK4 step.
    pub fn rhs(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        let nc = self.cells.len();
        let nsp = self.species.len();
        self.volumes(y, time)?;
        self.load_flows(time, y);
        let mut dnode = std::mem::take(&mut self.sweep.dnode);
        dnode.resize(self.kind.len(), 0.0);
        for s in 0..nsp {
            let (zs, dzs) = (&z[s * nc..(s + 1) * nc], &mut dz[s * nc..(s + 1) * nc]);
            for (i, &n) in self.cells.iter().enumerate() {
                self.conc[n] = zs[i] / self.vol[i];
                dnode[n] = 0.0;
            }
            for &m in &self.mixing {
                dnode[m] = 0.0;
            }
            self.load_boundary(s, time);
            self.mix(s)?;
            self.load_shear(s, y, z);
            // node-to-node faces: the bulk of the work, branch-free apart from the upwind pick;
            // fluxes into mixing points and out of them cancel there (they hold no amount)
            let conc = &self.conc;
            for &[fi, a, b] in &self.internal {
                let q = self.qf[fi as usize];
                let (a, b) = (a as usize, b as usize);
                let flux = q * if q >= 0.0 { conc[a] } else { conc[b] };
                dnode[a] -= flux;
                dnode[b] += flux;
            }
            let (mut i_in, mut i_out) = (0.0, 0.0);
            for &fi in &self.boundary_faces {
                let f = &self.faces[fi];
                let (q, c) = self.upwind(fi);
                let flux = q * c;
                match f.from {
                    End::Node(n) => dnode[n] -= flux,
                    End::Boundary(b) => {
                        account(self.boundary_inlet[b], flux, &mut i_in, &mut i_out)
                    }
                }
                match f.to {
                    End::Node(n) => dnode[n] += flux,
                    End::Boundary(b) => {
                        account(self.boundary_inlet[b], -flux, &mut i_in, &mut i_out)
                    }
                }
            }
            for ((n, _, b), &q) in self.sources.iter().zip(&self.qs) {
                let c = if q >= 0.0 {
                    self.boundary_conc(*b, End::Node(*n))
                } else {
                    self.conc[*n]
                };
                let flux = q * c;
                dnode[*n] += flux;
                account(self.boundary_inlet[*b], flux, &mut i_in, &mut i_out);
            }
            // one pass over the cells: gather the face balance, wall uptake, decay
            if self.species[s].has_wall && !self.species[s].binding.is_identity() {
                self.free_of_cells(s);
            }
            let sp = &self.species[s];
            let free = if sp.binding.is_identity() {
                &self.conc
            } else {
                &sp.free
            };
            let (has_wall, lambda) = (sp.has_wall, sp.decay);
            let (mut i_wall, mut i_decay) = (0.0, 0.0);
            for (i, (d, &n)) in dzs.iter_mut().zip(&self.cells).enumerate() {
                let mut v = dnode[n];
                if has_wall {
                    let w = sp.fixed_uptake(i, free[n]);
                    v -= w;
                    i_wall += w;
                }
                if lambda != 0.0 {
                    v -= lambda * zs[i];
                    i_decay += lambda * zs[i];
                }
                *d = v;
            }
            for &p in &sp.dynamic {
                let w = sp.piece_uptake(&self.pieces, p, free);
                dzs[self.pieces[p].cell] -= w;
                i_wall += w;
            }
            let acc = &mut dz[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            acc.copy_from_slice(&[i_in, i_out, i_wall, i_decay]);
            // relaxed shears: dQ̃/dt = (|Q| − Q̃)/τ_BL
            for (k, &(j, tau)) in sp.relax.iter().enumerate() {
                let i = sp.relax_offset + k;
                dz[i] = (y[self.segments[j].branch_unknown].abs() - z[i]) / tau;
            }
        }
        self.sweep.dnode = dnode;
        Ok(())
    }

    /// Backward-Euler upwind transport over [t, t + dt] after a generalized-α flow step, with
    /// the face flows of the step's α_f level, Q = Q_n + α_f (Q_{n+1} − Q_n), and sources at
    /// t + α_f dt. The transport volumes W evolve with the same face flows, W' = W + dt·(net
    /// inflow), so a uniform field stays uniform and Σ N changes by exactly dt × (boundary − wall
    /// − decay fluxes). Generalized-α enforces the capacitor rows at the α levels, which gives
    /// W_n − V(P_n) = (γ − α_m) dt C (Ṗ_n − Ṗ_0): an O(dt) offset that does not drift.
    pub fn implicit_step(
        &mut self,
        time: f64,
        dt: f64,
        alpha_f: f64,
        y0: &[f64],
        y1: &[f64],
        z: &mut [f64],
    ) -> Result<()> {
        let t_af = time + alpha_f * dt;
        self.load_flows_between(t_af, y0, y1, alpha_f);
        // the α_f-level state is only needed by shear-dependent walls (relaxed or instantaneous)
        let mut ya = std::mem::take(&mut self.sweep.ya);
        if self
            .species
            .iter()
            .any(|sp| !sp.relax.is_empty() || !sp.dynamic_segs.is_empty())
        {
            ya.clear();
            ya.extend(y0.iter().zip(y1).map(|(a, b)| a + alpha_f * (b - a)));
        }
        let res = self
            .transport_volumes(t_af, dt)
            .and_then(|()| self.implicit_species(t_af, dt, &ya, z));
        self.sweep.ya = ya;
        if res.is_ok() {
            std::mem::swap(&mut self.wvol, &mut self.sweep.wnew);
        }
        res
    }

    /// W' = W + dt (net inflow) of every cell with the loaded face flows, into `sweep.wnew`.
    fn transport_volumes(&mut self, t_af: f64, dt: f64) -> Result<()> {
        let mut net = std::mem::take(&mut self.sweep.dnode);
        net.clear();
        net.resize(self.kind.len(), 0.0);
        let qf = &self.qf[..];
        for &[fi, a, b] in &self.internal {
            let q = qf[fi as usize];
            net[a as usize] -= q;
            net[b as usize] += q;
        }
        for &fi in &self.boundary_faces {
            let (f, q) = (&self.faces[fi], self.qf[fi]);
            if let End::Node(n) = f.from {
                net[n] -= q;
            }
            if let End::Node(n) = f.to {
                net[n] += q;
            }
        }
        for ((n, _, _), &q) in self.sources.iter().zip(&self.qs) {
            net[*n] += q;
        }
        let mut w_new = std::mem::take(&mut self.sweep.wnew);
        w_new.clear();
        w_new.extend(
            self.cells
                .iter()
                .zip(&self.wvol)
                .map(|(&n, &w)| w + dt * net[n]),
        );
        self.sweep.dnode = net;
        let bad = w_new.iter().position(|&w| w.is_nan() || w <= 0.0);
        self.sweep.wnew = w_new;
        match bad {
            None => Ok(()),
            Some(i) => Err(Error::solver(
                t_af,
                format!(
                    "transport volume of cell '{}' became {:.3e} m³: reduce dt",
                    self.node_name(self.cells[i]),
                    self.sweep.wnew[i]
                ),
            )),
        }
    }

    /// The backward-Euler solve of every species over the step (see `implicit_step`), with the
    /// face flows and new volumes loaded; `ya` is the α_f-level state (for shear-dependent walls).
    fn implicit_species(&mut self, t_af: f64, dt: f64, ya: &[f64], z: &mut [f64]) -> Result<()> {
        let nc = self.cells.len();
        let nsp = self.species.len();
        let (mut wconst, mut wlin) = (
            std::mem::take(&mut self.sweep.wconst),
            std::mem::take(&mut self.sweep.wlin),
        );
        wconst.resize(nc, 0.0);
        wlin.resize(nc, 0.0);
        let w_new = std::mem::take(&mut self.sweep.wnew);
        let quasi = self.formulation == Formulation::TlQuasisteady;
        let mut res = Ok(());
        for s in 0..nsp {
            self.load_boundary(s, t_af);
            let lambda = self.species[s].decay;
            self.relax_shears(s, dt, ya, z);
            self.restore_mixing(s);
            let sp = &self.species[s];
            let (sw, zs) = (&mut self.sweep, &z[s * nc..(s + 1) * nc]);
            for &m in &self.mixing {
                (sw.den[m], sw.num[m], sw.lag[m]) = (0.0, 0.0, self.conc[m]);
            }
            if !quasi && sp.binding.is_identity() && sp.dynamic.is_empty() {
                // one fused pass: old concentration, wall W = g C + (q − g c_w) (linear), and
                // the rows (d_n + Σ_out |Q|) x_n − Σ_in |Q| x_up = b_n into den and num
                let rate = 1.0 / dt + lambda;
                // local slices: the loop keeps its pointers in registers
                let (conc, lag) = (&mut self.conc[..], &mut sw.lag[..]);
                let (den, num) = (&mut sw.den[..], &mut sw.num[..]);
                let (g, q, gcw) = (&sp.cell_g[..nc], &sp.cell_q[..nc], &sp.cell_gcw[..nc]);
                let (wvol, w_new) = (&self.wvol[..nc], &w_new[..nc]);
                let (wlin, wconst) = (&mut wlin[..nc], &mut wconst[..nc]);
                for (i, &n) in self.cells.iter().enumerate() {
                    let c = zs[i] / wvol[i];
                    let wc = q[i] - gcw[i];
                    (conc[n], lag[n]) = (c, c);
                    (wlin[i], wconst[i]) = (g[i], wc);
                    den[n] = w_new[i] * rate + g[i];
                    num[n] = zs[i] / dt - wc;
                }
            } else {
                self.implicit_rows(s, dt, ya, z, &w_new, &mut wconst, &mut wlin);
            }
            let mut x = std::mem::take(&mut self.conc);
            if self.tree.is_some() {
                self.tree_solve(&mut x);
            } else {
                let unknowns = std::mem::take(&mut self.domain);
                let (d, b) = (self.sweep.den.clone(), self.sweep.num.clone());
                res = self.sweep_solve(&unknowns, &d, &b, &mut x);
                self.domain = unknowns;
            }
            self.conc = x;
            self.save_mixing(s);
            if res.is_err() {
                break;
            }
            let (i_in, i_out) = self.implicit_boundary_fluxes();
            let (mut i_wall, mut i_decay) = (0.0, 0.0);
            let (conc, zs) = (&self.conc[..], &mut z[s * nc..(s + 1) * nc]);
            let (wlin, wconst, w_new) = (&wlin[..nc], &wconst[..nc], &w_new[..nc]);
            for (i, &n) in self.cells.iter().enumerate() {
                let x = conc[n];
                i_wall += wlin[i] * x + wconst[i];
                if !quasi {
                    i_decay += lambda * w_new[i] * x;
                }
                zs[i] = w_new[i] * x;
            }
            let acc = &mut z[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            for (a, v) in acc.iter_mut().zip([i_in, i_out, i_wall, i_decay]) {
                *a += dt * v;
            }
            // (free concentrations of the new state: the next step's linearisation and
            // `observe` invert it, warm-started from this step's values)
        }
        let sc = &mut self.sweep;
        (sc.wconst, sc.wlin, sc.wnew) = (wconst, wlin, w_new);
        res
    }

    /// The rows of species `s` in the general case (binding, shear-dependent walls, or the
    /// quasi-steady formulation): old concentrations, the wall linearised about them, and
    /// d, b into `sweep.den`, `sweep.num`.
    #[allow(clippy::too_many_arguments)]
    fn implicit_rows(
        &mut self,
        s: usize,
        dt: f64,
        ya: &[f64],
        z: &[f64],
        w_new: &[f64],
        wconst: &mut [f64],
        wlin: &mut [f64],
    ) {
        let nc = self.cells.len();
        let zs = &z[s * nc..(s + 1) * nc];
        for (i, &n) in self.cells.iter().enumerate() {
            self.conc[n] = zs[i] / self.wvol[i];
        }
        self.load_shear(s, ya, z);
        self.linearised_wall(s, wconst, wlin);
        let quasi = self.formulation == Formulation::TlQuasisteady;
        let rate = 1.0 / dt + self.species[s].decay;
        let sw = &mut self.sweep;
        for (i, &n) in self.cells.iter().enumerate() {
            (sw.den[n], sw.num[n]) = if quasi {
                (wlin[i], -wconst[i])
            } else {
                (w_new[i] * rate + wlin[i], zs[i] / dt - wconst[i])
            };
            sw.lag[n] = self.conc[n];
        }
    }

    /// Relaxed shears of species `s` over the step, exactly for the step's frozen |Q|, so that
    /// the wall law of the solve uses the end-of-step boundary layer, like backward Euler.
    fn relax_shears(&self, s: usize, dt: f64, ya: &[f64], z: &mut [f64]) {
        let sp = &self.species[s];
        for (k, &(j, tau)) in sp.relax.iter().enumerate() {
            let q = ya[self.segments[j].branch_unknown].abs();
            let v = &mut z[sp.relax_offset + k];
            *v = q + (*v - q) * (-dt / tau).exp();
        }
    }

    /// Wall uptake of species `s` linearised about the current state: W = wlin·C_t + wconst
    /// per cell (exact for linear binding); zero without a wall.
    fn linearised_wall(&mut self, s: usize, wconst: &mut [f64], wlin: &mut [f64]) {
        if !self.species[s].has_wall {
            wlin.iter_mut().for_each(|v| *v = 0.0);
            wconst.iter_mut().for_each(|v| *v = 0.0);
            return;
        }
        let sp = &self.species[s];
        if sp.binding.is_identity() && sp.dynamic.is_empty() {
            // W = g C + (q − g c_w): already linear
            for (i, (wl, wc)) in wlin.iter_mut().zip(wconst.iter_mut()).enumerate() {
                *wl = sp.cell_g[i];
                *wc = sp.cell_q[i] - sp.cell_gcw[i];
            }
            return;
        }
        // free concentrations and 1/(dC_t/dc) there (the slope of W in C_t per unit g)
        let sp = &mut self.species[s];
        let mut inv_slope = std::mem::take(&mut self.sweep.inv_slope);
        inv_slope.clear();
        inv_slope.resize(self.cells.len(), 1.0);
        if !sp.binding.is_identity() {
            for (&n, v) in self.cells.iter().zip(inv_slope.iter_mut()) {
                let (f, slope) = sp.binding.free_and_slope_anchored(
                    self.conc[n],
                    sp.free[n],
                    &mut sp.anchors[n],
                );
                sp.free[n] = f;
                *v = 1.0 / slope;
            }
        }
        self.wall_uptake(s, wconst);
        let sp = &self.species[s];
        wlin.copy_from_slice(&sp.cell_g);
        for &p in &sp.dynamic {
            let pc = &self.pieces[p];
            let (gj, _, _) = sp.laws[p].eval_cbrt(sp.shear_cbrt[pc.seg]);
            wlin[pc.cell] += pc.share * gj;
        }
        if !sp.binding.is_identity() {
            wlin.iter_mut().zip(&inv_slope).for_each(|(w, v)| *w *= v);
        }
        self.sweep.inv_slope = inv_slope;
        for (i, &n) in self.cells.iter().enumerate() {
            wconst[i] -= wlin[i] * self.conc[n];
        }
    }

    /// Boundary inflow (I_in) and outflow (I_out) rates of the solved implicit field: the same
    /// fluxes that entered the solve.
    fn implicit_boundary_fluxes(&self) -> (f64, f64) {
        let (mut i_in, mut i_out) = (0.0, 0.0);
        for &fi in &self.boundary_faces {
            let (f, q) = (&self.faces[fi], self.qf[fi]);
            let (from_b, to_b) = (f.from, f.to);
            if let End::Boundary(bb) = from_b {
                let c = if q >= 0.0 {
                    self.lagged_boundary(bb, to_b)
                } else {
                    self.end_conc(to_b)
                };
                account(self.boundary_inlet[bb], q * c, &mut i_in, &mut i_out);
            }
            if let End::Boundary(bb) = to_b {
                let c = if q < 0.0 {
                    self.lagged_boundary(bb, from_b)
                } else {
                    self.end_conc(from_b)
                };
                account(self.boundary_inlet[bb], -q * c, &mut i_in, &mut i_out);
            }
        }
        for ((n, _, bb), &q) in self.sources.iter().zip(&self.qs) {
            let c = if q >= 0.0 {
                self.lagged_boundary(*bb, End::Node(*n))
            } else {
                self.conc[*n]
            };
            account(self.boundary_inlet[*bb], q * c, &mut i_in, &mut i_out);
        }
        (i_in, i_out)
    }

    #[inline]
    fn end_conc(&self, e: End) -> f64 {
        match e {
            End::Node(n) => self.conc[n],
            End::Boundary(_) => 0.0,
        }
    }

    /// Inflow value of a boundary in the implicit solve: prescribed, or (zero-gradient) the
    /// neighbour's lagged value — stored in `lag` during the sweep.
    #[inline]
    fn lagged_boundary(&self, b: usize, n: End) -> f64 {
        match n {
            End::Node(n) => inflow_value(self.bval[b], self.sweep.lag[n]),
            End::Boundary(_) => inflow_value(self.bval[b], 0.0),
        }
    }

    /// The system of `sweep_solve` on the whole domain when it is a forest (`tree`): eliminated
    /// leaves first, each row becoming x_n = α_n + β_n x_parent — β_n ≠ 0 only when the parent
    /// is upwind of n, since an upwind row never references its downstream neighbour — then
    /// back-substituted parents first. Exact and O(n) for any flow directions, with no queue.
    /// On entry `sweep.den`, `sweep.num` hold d and b, and `sweep.lag` the previous values.
    fn tree_solve(&mut self, x: &mut [f64]) {
        let Some(tree) = self.tree.as_deref() else {
            return;
        };
        let sw = &mut self.sweep;
        sw.beta.resize(tree.len(), 0.0);
        for &fi in &self.boundary_faces {
            let (q, up, down) = oriented(&self.faces, &self.qf, fi);
            match (up, down) {
                (End::Node(n), _) => sw.den[n] += q.abs(),
                (End::Boundary(bb), End::Node(n)) => {
                    sw.num[n] += q.abs() * inflow_value(self.bval[bb], sw.lag[n])
                }
                _ => {}
            }
        }
        for (&(n, _, bb), &q) in self.sources.iter().zip(&self.qs) {
            if q >= 0.0 {
                sw.num[n] += q * inflow_value(self.bval[bb], sw.lag[n]);
            } else {
                sw.den[n] -= q;
            }
        }
        // local slices: the loops keep their pointers in registers
        let (num, den, lag, qf) = (&mut sw.num[..], &mut sw.den[..], &sw.lag[..], &self.qf[..]);
        for (l, beta) in tree.iter().zip(sw.beta.iter_mut()) {
            let n = l.node as usize;
            let (mut aq, mut to_parent) = (0.0, false);
            if l.parent != u32::MAX {
                let q = qf[l.face as usize];
                aq = q.abs();
                to_parent = (q >= 0.0) == l.from_child;
                if to_parent {
                    den[n] += aq;
                } else {
                    den[l.parent as usize] += aq;
                }
            }
            let d = den[n];
            let solvable = d > 1e-300;
            let xn = if solvable { num[n] / d } else { lag[n] };
            x[n] = xn;
            *beta = 0.0;
            if to_parent {
                num[l.parent as usize] += aq * xn;
            } else if solvable && aq != 0.0 {
                *beta = aq / d;
            }
        }
        for (l, &beta) in tree.iter().zip(&sw.beta).rev() {
            if beta != 0.0 {
                x[l.node as usize] += beta * x[l.parent as usize];
            }
        }
    }

    /// Solve, for the nodes in `unknowns`,
    ///   (d_n + Σ_out |Q|) x_n − Σ_in |Q| x_up = b_n + (inflows from known nodes and boundaries),
    /// visiting the nodes in flow order (Kahn): on an acyclic directed flow graph the system is
    /// triangular and one pass solves it exactly, O(n). Zero-gradient backflow carries the
    /// node's previous value, keeping the matrix an M-matrix. Nodes left on directed cycles
    /// (circulating loop flow) are solved by Gauss–Seidel, which converges for M-matrices.
    /// Nodes with no outflow and no storage keep their previous value.
    fn sweep_solve(
        &mut self,
        unknowns: &[usize],
        d: &[f64],
        b: &[f64],
        x: &mut [f64],
    ) -> Result<()> {
        let sw = &mut self.sweep;
        for &n in unknowns {
            sw.mark[n] = true;
            sw.lag[n] = x[n];
            sw.pending[n] = 0;
            sw.num[n] = b[n];
            sw.den[n] = d[n];
        }
        // pass 1: denominators, known inflows, pending counts
        for &n in unknowns {
            for &fi in &self.node_faces[self.node_ptr[n]..self.node_ptr[n + 1]] {
                let (q, up, down) = oriented(&self.faces, &self.qf, fi);
                let aq = q.abs();
                if up == End::Node(n) {
                    sw.den[n] += aq;
                    continue;
                }
                if down != End::Node(n) || aq == 0.0 {
                    continue;
                }
                match up {
                    End::Node(u) if sw.mark[u] => sw.pending[n] += 1,
                    End::Node(u) => sw.num[n] += aq * x[u],
                    End::Boundary(bb) => sw.num[n] += aq * inflow_value(self.bval[bb], sw.lag[n]),
                }
            }
            for &k in &self.node_sources[n] {
                let q = self.qs[k];
                if q >= 0.0 {
                    sw.num[n] += q * inflow_value(self.bval[self.sources[k].2], sw.lag[n]);
                } else {
                    sw.den[n] -= q;
                }
            }
        }
        sw.queue.clear();
        for &n in unknowns {
            if sw.pending[n] == 0 {
                sw.queue.push(n);
            }
        }
        let mut head = 0;
        let mut solved = 0;
        while head < sw.queue.len() {
            let n = sw.queue[head];
            head += 1;
            solved += 1;
            x[n] = if sw.den[n] > 1e-300 {
                sw.num[n] / sw.den[n]
            } else {
                sw.lag[n]
            };
            for &fi in &self.node_faces[self.node_ptr[n]..self.node_ptr[n + 1]] {
                let (q, up, down) = oriented(&self.faces, &self.qf, fi);
                if up != End::Node(n) || q == 0.0 {
                    continue;
                }
                if let End::Node(m) = down {
                    if sw.mark[m] {
                        sw.num[m] += q.abs() * x[n];
                        sw.pending[m] -= 1;
                        if sw.pending[m] == 0 {
                            sw.queue.push(m);
                        }
                    }
                }
            }
        }
        let mut result = Ok(());
        if solved < unknowns.len() {
            // directed cycles: Gauss–Seidel on the remaining nodes
            let rest: Vec<usize> = unknowns
                .iter()
                .copied()
                .filter(|&n| sw.pending[n] > 0)
                .collect();
            let mut converged = false;
            for _ in 0..10_000 {
                let mut change = 0.0f64;
                let mut scale = 0.0f64;
                for &n in &rest {
                    let mut num = sw.num[n];
                    for &fi in &self.node_faces[self.node_ptr[n]..self.node_ptr[n + 1]] {
                        let (q, up, down) = oriented(&self.faces, &self.qf, fi);
                        if down != End::Node(n) {
                            continue;
                        }
                        if let End::Node(u) = up {
                            if sw.mark[u] && sw.pending[u] > 0 {
                                num += q.abs() * x[u];
                            }
                        }
                    }
                    let v = if sw.den[n] > 1e-300 {
                        num / sw.den[n]
                    } else {
                        sw.lag[n]
                    };
                    change = change.max((v - x[n]).abs());
                    scale = scale.max(v.abs());
                    x[n] = v;
                }
                if change <= 1e-15 * scale.max(1e-300) {
                    converged = true;
                    break;
                }
            }
            if !converged {
                result = Err(Error::solver(
                    0.0,
                    "transport sweep did not converge on a flow loop".to_string(),
                ));
            }
        }
        for &n in unknowns {
            sw.mark[n] = false;
        }
        result
    }

    /// Append the recorded columns of every species at (t, y) to `out`.
    /// `ydot`: flow derivative (for R_i = dL_i/dt); `implicit`: use the transport volumes.
    pub fn observe(
        &mut self,
        time: f64,
        y: &[f64],
        ydot: Option<&[f64]>,
        z: &[f64],
        implicit: bool,
        out: &mut Vec<f64>,
    ) -> Result<()> {
        let nc = self.cells.len();
        let nsp = self.species.len();
        self.volumes(y, time)?;
        if implicit && !self.wvol.is_empty() {
            self.vol.copy_from_slice(&self.wvol);
        }
        self.load_flows(time, y);
        for s in 0..nsp {
            for (i, &n) in self.cells.iter().enumerate() {
                self.conc[n] = z[s * nc + i] / self.vol[i];
            }
            self.load_boundary(s, time);
            self.mix(s)?;
            // free concentration of every non-exterior node
            {
                let sp = &mut self.species[s];
                for n in 0..self.kind.len() {
                    sp.free[n] = match self.kind[n] {
                        Kind::Exterior => f64::NAN,
                        _ => sp.binding.free(
                            self.conc[n],
                            if sp.free[n].is_finite() {
                                sp.free[n]
                            } else {
                                0.0
                            },
                        ),
                    };
                }
            }
            self.load_shear(s, y, z);
            let sp = &self.species[s];
            let face_flux = |tr: &Self, unknown: usize| -> (f64, f64) {
                let fi = tr
                    .face_of_unknown
                    .get(unknown)
                    .copied()
                    .unwrap_or(usize::MAX);
                if fi == usize::MAX {
                    return (f64::NAN, f64::NAN);
                }
                let (q, c) = tr.upwind(fi);
                (q * c, sp.binding.free(c, c))
            };
            let seg_wall = |j: usize| -> f64 {
                self.seg_pieces[j]
                    .clone()
                    .map(|p| sp.piece_uptake(&self.pieces, p, &sp.free))
                    .sum()
            };
            for v in &self.out_vessels {
                let (j_in, c_in) = face_flux(self, v.first);
                let (j_out, c_out) = face_flux(self, v.last);
                let wall: f64 = self.out_segments[v.segs.clone()]
                    .iter()
                    .map(|&j| seg_wall(j))
                    .sum();
                out.extend([c_in, c_out, j_in, j_out, wall]);
            }
            let segs: &[usize] = if self.segment_output {
                &self.out_segments
            } else {
                &[]
            };
            for &j in segs {
                let seg = &self.segments[j];
                let (flux, _) = face_flux(self, seg.branch_unknown);
                let (mut c, mut wsum, mut vseg, mut dvseg) = (0.0, 0.0, 0.0, 0.0);
                for &(n, share) in &seg.nodes {
                    if share > 0.0 {
                        // a refined node reports its last sub-cell: the value its
                        // outgoing faces carry
                        c += share * sp.free[self.last_sub[n]];
                        wsum += share;
                        vseg += share * (seg.volume + seg.compliance * (y[n] - self.p_ref));
                        if let Some(yd) = ydot {
                            dvseg += share * seg.compliance * yd[n];
                        }
                    }
                }
                let c = if wsum > 0.0 { c / wsum } else { f64::NAN };
                // transmission-line elements (physics §2.6): v = Q/A, A = V_seg/dx,
                // L = −dx/v, R = dL/dt = dx v̇/v²
                let q = y[seg.branch_unknown];
                let (mut r_tl, mut l_tl) = (f64::NAN, f64::NAN);
                if seg.dx > 0.0 && vseg > 0.0 {
                    let a = vseg / seg.dx;
                    let v = q / a;
                    if v.abs() >= self.v_eps {
                        l_tl = -seg.dx / v;
                        if let Some(yd) = ydot {
                            let vdot = yd[seg.branch_unknown] / a - q * (dvseg / seg.dx) / (a * a);
                            r_tl = seg.dx * vdot / (v * v);
                        }
                    }
                }
                out.extend([c, flux, seg_wall(j), r_tl, l_tl]);
            }
            let stored: f64 = z[s * nc..(s + 1) * nc].iter().sum();
            let acc = &z[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            out.extend([stored, acc[0], acc[1], acc[2], acc[3]]);
        }
        Ok(())
    }

    /// max over cells of (total outflow rate)/V (1/s): dt × this is the upwind Courant number.
    pub fn max_outflow_rate(&mut self, y: &[f64], time: f64) -> f64 {
        if self.volumes(y, time).is_err() {
            return f64::INFINITY;
        }
        self.load_flows(time, y);
        let mut out = vec![0.0; self.cells.len()];
        for (f, &q) in self.faces.iter().zip(&self.qf) {
            let up = if q >= 0.0 { f.from } else { f.to };
            if let End::Node(n) = up {
                if self.node_cell[n] != usize::MAX {
                    out[self.node_cell[n]] += q.abs();
                }
            }
        }
        for ((n, _, _), &q) in self.sources.iter().zip(&self.qs) {
            if q < 0.0 && self.node_cell[*n] != usize::MAX {
                out[self.node_cell[*n]] -= q;
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
        let seg = self.segments.get(j)?;
        let (n, _) = seg
            .nodes
            .iter()
            .copied()
            .fold((usize::MAX, -1.0), |a, b| if b.1 > a.1 { b } else { a });
        let (a, b) = (self.node_cell[n], self.node_cell[self.last_sub[n]]);
        (a != usize::MAX).then_some(a..b + 1)
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
        let n = self.species.len() * self.cells.len();
        let scale = a[..n]
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()))
            .max(1e-300);
        a[..n]
            .iter()
            .zip(&b[..n])
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / scale
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

#[derive(Debug, Clone)]
struct Sweep {
    mark: Vec<bool>,
    pending: Vec<u32>,
    num: Vec<f64>,
    den: Vec<f64>,
    lag: Vec<f64>,
    queue: Vec<usize>,
    d: Vec<f64>,
    b: Vec<f64>,
    dnode: Vec<f64>,
    /// Implicit step: α_f-level state, new transport volumes, linearised wall uptake, and the
    /// coupling to the parent of every node in the tree elimination.
    ya: Vec<f64>,
    wnew: Vec<f64>,
    wconst: Vec<f64>,
    wlin: Vec<f64>,
    inv_slope: Vec<f64>,
    beta: Vec<f64>,
}

impl Sweep {
    fn new(nn: usize) -> Self {
        Sweep {
            mark: vec![false; nn],
            pending: vec![0; nn],
            num: vec![0.0; nn],
            den: vec![0.0; nn],
            lag: vec![0.0; nn],
            queue: Vec::with_capacity(nn),
            d: Vec::new(),
            b: Vec::new(),
            dnode: Vec::new(),
            ya: Vec::new(),
            wnew: Vec::new(),
            wconst: Vec::new(),
            wlin: Vec::new(),
            inv_slope: Vec::new(),
            beta: Vec::new(),
        }
    }
}

impl crate::rk4::Coupled for Transport {
    #[inline]
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.rhs(time, y, z, dz)
    }
}

/// Flow of face `fi` and its ends ordered along the flow (upstream, downstream). A free function so
/// that callers holding a mutable borrow of other transport fields can use it.
#[inline]
fn oriented(faces: &[Face], qf: &[f64], fi: usize) -> (f64, End, End) {
    let f = &faces[fi];
    let q = qf[fi];
    if q >= 0.0 {
        (q, f.from, f.to)
    } else {
        (q, f.to, f.from)
    }
}

/// One domain node in the elimination order of [`tree_order`]: its parent in the spanning
/// forest (`u32::MAX` for a root) and the face joining them.
#[derive(Debug, Clone, Copy)]
struct Link {
    node: u32,
    parent: u32,
    face: u32,
    /// The face points from this node to its parent (positive flow runs child → parent).
    from_child: bool,
}

/// Children-before-parents order of the domain nodes when the undirected graph of the internal
/// faces is a forest (no loops, no parallel faces): then the upwind system can be eliminated
/// leaves first for any flow directions (`Transport::tree_solve`). None otherwise. Linear time.
fn tree_order(nt: usize, domain: &[usize], internal: &[[u32; 3]]) -> Option<Vec<Link>> {
    let mut ptr = vec![0u32; nt + 1];
    for &[_, a, b] in internal {
        ptr[a as usize + 1] += 1;
        ptr[b as usize + 1] += 1;
    }
    for i in 0..nt {
        ptr[i + 1] += ptr[i];
    }
    let mut fill = ptr.clone();
    let mut adj = vec![(0u32, 0u32); ptr[nt] as usize];
    for &[f, a, b] in internal {
        adj[fill[a as usize] as usize] = (f, b);
        fill[a as usize] += 1;
        adj[fill[b as usize] as usize] = (f, a);
        fill[b as usize] += 1;
    }
    // nodes outside the domain count as seen: meeting one sends the solve to the general sweep
    let mut seen = vec![true; nt];
    for &n in domain {
        seen[n] = false;
    }
    let mut pre: Vec<Link> = Vec::with_capacity(domain.len());
    let mut stack: Vec<Link> = Vec::new();
    for &r in domain {
        if seen[r] {
            continue;
        }
        seen[r] = true;
        stack.push(Link {
            node: r as u32,
            parent: u32::MAX,
            face: u32::MAX,
            from_child: false,
        });
        while let Some(l) = stack.pop() {
            let n = l.node as usize;
            for &(f, o) in &adj[ptr[n] as usize..ptr[n + 1] as usize] {
                if f == l.face {
                    continue;
                }
                if seen[o as usize] {
                    return None; // a loop (or two faces between the same nodes)
                }
                seen[o as usize] = true;
                let from_child = internal_from(internal, f) == o;
                stack.push(Link {
                    node: o,
                    parent: l.node,
                    face: f,
                    from_child,
                });
            }
            pre.push(l);
        }
    }
    pre.reverse();
    Some(pre)
}

/// `from` node of internal face `f` (faces are listed in `internal` in face order, so a binary
/// search finds it).
fn internal_from(internal: &[[u32; 3]], f: u32) -> u32 {
    let k = internal.partition_point(|e| e[0] < f);
    internal[k][1]
}

/// The output vessels of the flow probes (first and last face, segment range) and their
/// segments in order. One pass: segments grouped by vessel, names looked up in a map.
fn output_layout(circuit: &Circuit, probes: &Probes) -> (Vec<OutVessel>, Vec<usize>) {
    let vessel_index: std::collections::HashMap<&str, usize> = circuit
        .vessel_names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let mut segs_of_vessel: Vec<Vec<usize>> = vec![Vec::new(); circuit.vessel_names.len()];
    for (j, sg) in circuit.segments.iter().enumerate() {
        if let Some(v) = segs_of_vessel.get_mut(sg.vessel) {
            v.push(j);
        }
    }
    let mut out_vessels = Vec::new();
    let mut out_segments = Vec::new();
    for (k, name) in probes.vessels.iter().enumerate() {
        let start = out_segments.len();
        if let Some(&vi) = vessel_index.get(name.as_str()) {
            out_segments.extend_from_slice(&segs_of_vessel[vi]);
        }
        out_vessels.push(OutVessel {
            first: probes.vessel_unknowns[4 * k + 2],
            last: probes.vessel_unknowns[4 * k + 3],
            segs: start..out_segments.len(),
        });
    }
    (out_vessels, out_segments)
}

/// Wall pieces: a segment's share in each cell; a refined node's share of the segment
/// (for a node at the segment's start [x0, x0 + share dx], at its end
/// [x1 − share dx, x1]) is split into m equal sub-intervals in flow order, with the law
/// integrated over each (exact for Lévêque's x^{-1/3}, by area for constant laws)
fn wall_pieces(
    segments: &[Segment],
    m_node: &[usize],
    node_cell: &[usize],
    first_extra: &[usize],
) -> (Vec<Piece>, Vec<std::ops::Range<usize>>) {
    let mut pieces = Vec::new();
    let mut seg_pieces = Vec::new();
    for (j, sg) in segments.iter().enumerate() {
        let start = pieces.len();
        for (end, &(n, share)) in sg.nodes.iter().enumerate() {
            if share <= 0.0 || node_cell[n] == usize::MAX {
                continue;
            }
            let m = m_node[n];
            if m == 1 {
                // unrefined: the whole segment's law times the share (as before refinement)
                pieces.push(Piece {
                    seg: j,
                    node: n,
                    cell: node_cell[n],
                    share,
                    wall: sg.wall,
                });
                continue;
            }
            let w = sg.wall;
            let len = share * (w.x1 - w.x0);
            let (a, b) = if end == 0 {
                (w.x0, w.x0 + len)
            } else {
                (w.x1 - len, w.x1)
            };
            for k in 0..m {
                let c = if k == 0 { n } else { first_extra[n] + k - 1 };
                let xa = a + (b - a) * k as f64 / m as f64;
                let xb = if k + 1 == m {
                    b
                } else {
                    a + (b - a) * (k + 1) as f64 / m as f64
                };
                pieces.push(Piece {
                    seg: j,
                    node: c,
                    cell: node_cell[c],
                    share: 1.0,
                    wall: SegmentWall {
                        radius: w.radius,
                        x0: xa,
                        x1: xb,
                    },
                });
            }
        }
        seg_pieces.push(start..pieces.len());
    }
    (pieces, seg_pieces)
}
