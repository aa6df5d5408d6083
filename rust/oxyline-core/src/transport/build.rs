//! Building the transport from the spec and the assembled circuit: cells, faces,
//! refinement chains, wall pieces, output layout (linear time).

#[allow(unused_imports)]
use super::*;
use crate::circuit::SegmentGeom;

/// Largest accepted `cells_per_segment` (a guard against typos that would allocate millions
/// of cells per segment).
pub(super) const MAX_CELLS_PER_SEGMENT: f64 = 10_000.0;

pub(super) fn cells_per_segment(v: f64, element: &str, key: &str) -> Result<usize> {
    if v.is_finite() && v >= 1.0 && v.fract() == 0.0 && v <= MAX_CELLS_PER_SEGMENT {
        Ok(v as usize)
    } else {
        Err(Error::model(
            element,
            format!("{key} must be an integer between 1 and {MAX_CELLS_PER_SEGMENT}, got {v}"),
        ))
    }
}

impl SpeciesPlan {
    /// Validate one species of the transport section against the circuit: binding, boundary
    /// values of every boundary condition, walls per vessel, initial value.
    pub(super) fn build(
        sp: &SpeciesSpec,
        circuit: &Circuit,
        segment_vessels: &[u32],
    ) -> Result<Self> {
        let el = format!("species '{}'", sp.name);
        for (key, v) in [("decay", sp.decay), ("diffusivity", sp.diffusivity)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(
                    &el,
                    format!("{key} must be a finite number >= 0, got {v}"),
                ));
            }
        }
        let binding = Binding::from_spec(&sp.binding, &el)?;
        let inlet = Waveform::from_spec(&sp.inlet, &format!("{el} inlet"))?;
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
        let boundary = boundary_values(sp, circuit, &inlet, &el)?;
        Ok(SpeciesPlan {
            name: sp.name.clone(),
            binding,
            decay: sp.decay,
            diffusivity: sp.diffusivity,
            waves: (0..boundary.len())
                .filter(|&k| matches!(boundary[k], BoundaryValue::Wave(_)))
                .collect(),
            boundary,
            walls: vessel_walls(sp, circuit, segment_vessels, &el)?,
            initial_free,
        })
    }
}

/// The value every boundary condition carries into the domain for species `sp`: its inlet
/// waveform (the species' default inlet unless named), or at outlets the prescribed backflow
/// value or zero gradient.
fn boundary_values(
    sp: &SpeciesSpec,
    circuit: &Circuit,
    inlet: &Waveform,
    el: &str,
) -> Result<Vec<BoundaryValue>> {
    for name in sp.inlets.keys().chain(sp.backflow.keys()) {
        if !circuit.boundaries.iter().any(|b| &b.name == name) {
            return Err(bad(
                el,
                format!("names boundary condition '{name}', which the network does not have"),
            ));
        }
    }
    let wave = |w, what: &str, name: &str| {
        Waveform::from_spec(w, &format!("{el} {what} '{name}'")).map(BoundaryValue::Wave)
    };
    circuit
        .boundaries
        .iter()
        .map(
            |b| match (b.inlet, sp.inlets.get(&b.name), sp.backflow.get(&b.name)) {
                (true, Some(w), _) => wave(w, "inlet", &b.name),
                (true, None, _) => Ok(BoundaryValue::Wave(inlet.clone())),
                (false, _, Some(w)) => wave(w, "backflow", &b.name),
                (false, _, None) => Ok(BoundaryValue::ZeroGradient),
            },
        )
        .collect()
}

/// The wall of every vessel for species `sp`: its `wall`, or the vessel's `per_vessel` entry.
fn vessel_walls(
    sp: &SpeciesSpec,
    circuit: &Circuit,
    segment_vessels: &[u32],
    el: &str,
) -> Result<Vec<WallSpec>> {
    sp.wall.validate(&format!("{el} wall"))?;
    let mut walls = vec![sp.wall.clone(); circuit.vessel_names.len()];
    let mut segments = vec![0usize; circuit.vessel_names.len()];
    for &v in segment_vessels {
        segments[v as usize] += 1;
    }
    for (vname, w) in &sp.per_vessel {
        let Some(vi) = circuit.vessel_names.iter().position(|n| n == vname) else {
            return Err(bad(
                el,
                format!("per_vessel names vessel '{vname}', which the network does not have"),
            ));
        };
        w.validate(&format!("{el} wall of vessel '{vname}'"))?;
        walls[vi] = w.clone();
    }
    for ((w, name), &n) in walls.iter().zip(&circuit.vessel_names).zip(&segments) {
        if let WallSpec::Flux { flux } = w {
            if flux.width() != 1 && flux.width() != n {
                return Err(bad(
                    &format!("{el} wall of vessel '{name}'"),
                    format!(
                        "wall flux has {} values per time but the vessel has {n} segments \
                         (give one value, or one per segment)",
                        flux.width()
                    ),
                ));
            }
        }
    }
    Ok(walls)
}

/// The species of the section, with unique non-empty names.
fn species_plans(
    spec: &TransportSpec,
    circuit: &Circuit,
    segment_vessels: &[u32],
) -> Result<Vec<SpeciesPlan>> {
    let mut seen = std::collections::HashSet::new();
    spec.species
        .iter()
        .map(|sp| {
            if sp.name.is_empty() || !seen.insert(sp.name.as_str()) {
                let el = format!("species '{}'", sp.name);
                return Err(bad(&el, "needs a unique, non-empty name".into()));
            }
            SpeciesPlan::build(sp, circuit, segment_vessels)
        })
        .collect()
}

impl Transport {
    /// Validate the transport section against the assembled circuit and build its plan
    /// (linear time); the result is an unrun transport of that plan.
    pub fn build(
        spec: &TransportSpec,
        circuit: &Circuit,
        dae: &Dae,
        probes: &Probes,
    ) -> Result<Self> {
        Self::build_from(spec, circuit, circuit.segments.clone(), dae, probes)
    }

    /// [`Transport::build`] taking the circuit's segment geometry (`circuit.segments` is left
    /// empty): the plan's segments are written over it in place, so a large network never
    /// holds both (88 + 72 bytes per segment at the load's peak). The circuit's other tables
    /// are untouched.
    pub fn build_taking_segments(
        spec: &TransportSpec,
        circuit: &mut Circuit,
        dae: &Dae,
        probes: &Probes,
    ) -> Result<Self> {
        let geoms = std::mem::take(&mut circuit.segments);
        Self::build_from(spec, circuit, geoms, dae, probes)
    }

    fn build_from(
        spec: &TransportSpec,
        circuit: &Circuit,
        mut geoms: Vec<SegmentGeom>,
        dae: &Dae,
        probes: &Probes,
    ) -> Result<Self> {
        check_settings(spec, circuit)?;
        // (a face's ends are 31-bit node and boundary indices, its unknown a u32)
        if dae.n >= Face::BOUNDARY as usize {
            return Err(bad("transport", "network too large".into()));
        }
        let mut kind = exterior_nodes(circuit);
        // the shares are written into the segments' own node list (no second table of them)
        let volume = move_shares(circuit, &mut geoms, &kind)?;
        classify_nodes(circuit, dae, &volume, &mut kind)?;
        let (mut faces, sources) = flow_faces(circuit, &kind)?;
        contract_boundary_points(circuit, &mut kind, &mut faces);
        let mut face_of_unknown = vec![u32::MAX; dae.n];
        for (fi, f) in faces.iter().enumerate() {
            face_of_unknown[f.unknown()] = fi as u32;
        }
        let m_node = refinement(spec, circuit, &kind, &geoms)?;
        // (refined sub-cells are nodes too: their indices must fit a face's 31 bits)
        let sub_cells: usize = m_node.iter().map(|&m| m as usize - 1).sum();
        if kind.len() + sub_cells >= Face::BOUNDARY as usize {
            return Err(bad("transport", "network too large".into()));
        }
        let n_flow_faces = faces.len();
        let refined = Refined::new(&mut kind, &mut faces, &sources, &m_node);
        let layout = CellLayout::new(&volume, dae, &kind, &m_node, &refined.first_extra);
        drop(volume);
        let segment_vessels: Vec<u32> = geoms.iter().map(|s| s.vessel as u32).collect();
        let segments = segments(geoms, circuit.nodes.len(), &face_of_unknown);
        let (pieces, seg_pieces, sub_walls) =
            wall_pieces(&segments, &m_node, &layout.node_cell, &refined.first_extra);
        drop(m_node);
        let species = species_plans(spec, circuit, &segment_vessels)?;
        // tissue hook: a radial wall column behind every wall piece of a tissue wall
        let tissue = tissue::plans(
            spec,
            &species,
            &circuit.vessel_names,
            &segments,
            &segment_vessels,
            (&pieces, &seg_pieces, &sub_walls),
        )?;
        let (mut out_vessels, out_segments) =
            output_layout(circuit, probes, &face_of_unknown, &segment_vessels);
        end_cells(&mut out_vessels, &out_segments, &segments, &kind);
        drop(face_of_unknown);
        let nn = kind.len();
        let (node_ptr, node_faces, source_nodes, source_list) = incidence(nn, &faces, &sources)?;
        // the identity without refinement: left empty (see `Plan::last_sub`)
        let last_sub = if refined.chains.is_empty() {
            Vec::new()
        } else {
            refined.last_sub
        };
        drop(refined.first_extra);
        let mut p = Plan {
            mixing: (0..nn).filter(|&i| kind[i] == Kind::Mixing).collect(),
            kind,
            cells: layout.cells,
            node_cell: layout.node_cell,
            v0: layout.v0,
            cap: layout.cap,
            p_ref: spec.reference_pressure,
            faces,
            sources,
            boundary_inlet: circuit.boundaries.iter().map(|b| b.inlet).collect(),
            node_ptr,
            node_faces,
            source_nodes,
            source_list,
            segments,
            n_flow_faces,
            face_unknowns: Vec::new(),
            chains: refined.chains,
            cell_node: layout.cell_node,
            volume_unknown: layout.volume_unknown,
            last_sub,
            pieces,
            seg_pieces,
            sub_walls,
            formulation: spec.formulation,
            v_eps: spec.velocity_threshold,
            out_vessels,
            out_segments,
            segment_vessels,
            node_names: circuit.names.clone(),
            domain: Vec::new(),
            n_internal: 0,
            boundary_faces: Vec::new(),
            boundary_links: Vec::new(),
            simple_mixing: Vec::new(),
            general_mixing: Vec::new(),
            tree: None,
            core: None,
            species,
            base_laws: Vec::new(),
            tissue,
        };
        p.finish()?;
        Ok(Transport::from_plan(Arc::new(p)))
    }
}

/// The nodes outside the transport domain (boundary-condition and prescribed-pressure
/// nodes: `Exterior`); every other node starts as a mixing point.
fn exterior_nodes(circuit: &Circuit) -> Vec<Kind> {
    let mut kind = vec![Kind::Mixing; circuit.nodes.len()];
    for (n, _) in &circuit.fixed_pressures {
        kind[*n] = Kind::Exterior;
    }
    for (i, node) in circuit.nodes.iter().enumerate() {
        if node.boundary.is_some() {
            kind[i] = Kind::Exterior;
        }
    }
    kind
}

/// Every segment's (node, share) of its lumen volume and wall as transport holds them,
/// written into `geoms` in place, and the lumen volume per circuit node that follows. The
/// arrangement puts a segment's capacitor, volume and wall at its end nodes; where an end is a
/// prescribed-pressure node (a `pressure` condition: the first segment of an inverted-L vessel
/// fed by an inlet pressure, half of it for π, the last of an L vessel at an outlet pressure)
/// that node is outside the transport domain, and the share moves to the segment's other end.
/// The flow circuit keeps its capacitor where it was (at a prescribed pressure it carries no
/// dynamics of the network); the moved volume is rigid in its new cell, whose volume changes
/// by the net inflow exactly as before. A segment with both ends outside the domain (one
/// segment between two prescribed pressures) has no cell for its volume: an error.
fn move_shares(circuit: &Circuit, geoms: &mut [SegmentGeom], kind: &[Kind]) -> Result<Vec<f64>> {
    // the circuit's node volumes, with the moved shares' volume added in segment order
    let mut volume: Vec<f64> = circuit.nodes.iter().map(|n| n.volume).collect();
    for j in 0..geoms.len() {
        let moved = moved_shares(circuit, geoms, j, kind)?;
        let s = &mut geoms[j];
        for (&(n, before), &(_, after)) in s.nodes.iter().zip(&moved) {
            if before != after {
                volume[n] += (after - before) * s.volume;
            }
        }
        s.nodes = moved;
    }
    Ok(volume)
}

/// Segment `j`'s (node, share) pair with the shares on prescribed-pressure ends moved (see
/// [`move_shares`]).
fn moved_shares(
    circuit: &Circuit,
    geoms: &[SegmentGeom],
    j: usize,
    kind: &[Kind],
) -> Result<[(usize, f64); 2]> {
    let s = &geoms[j];
    let [(a, sa), (b, sb)] = s.nodes;
    let (ea, eb) = (kind[a] == Kind::Exterior, kind[b] == Kind::Exterior);
    match (ea && sa > 0.0, eb && sb > 0.0) {
        (false, false) => Ok(s.nodes),
        _ if ea && eb && (s.volume > 0.0 || s.radius > 0.0) => Err(bad(
            &format!("vessel '{}'", circuit.vessel_names[s.vessel]),
            format!(
                "segment {} joins two prescribed-pressure nodes, so transport has no \
                 cell for its volume and wall; give the vessel at least 2 segments",
                segment_number(geoms, j)
            ),
        )),
        _ if ea && eb => Ok(s.nodes),
        (true, _) => Ok([(a, 0.0), (b, sa + sb)]),
        (false, true) => Ok([(a, sa + sb), (b, 0.0)]),
    }
}

/// 1-based position of segment `j` within its vessel (for messages).
fn segment_number(geoms: &[SegmentGeom], j: usize) -> usize {
    let v = geoms[j].vessel;
    geoms[..j].iter().filter(|s| s.vessel == v).count() + 1
}

/// Cells among the domain nodes: those holding lumen volume. A compliant node without lumen
/// volume is an error (it would store blood but no solute).
fn classify_nodes(circuit: &Circuit, dae: &Dae, volume: &[f64], kind: &mut [Kind]) -> Result<()> {
    for i in 0..circuit.nodes.len() {
        if kind[i] == Kind::Exterior {
            continue;
        }
        if volume[i] > 0.0 {
            kind[i] = Kind::Cell;
        } else if dae.e[i] > 0.0 {
            return Err(bad(
                &circuit.names.node(i),
                "has compliance but no lumen volume, so transport cannot conserve mass there; give the vessel geometry instead of lumped values".into(),
            ));
        }
    }
    Ok(())
}

/// One face per branch with a domain end (its ends: domain nodes or boundary conditions),
/// and the flow sources into the domain.
#[allow(clippy::type_complexity)]
fn flow_faces(
    circuit: &Circuit,
    kind: &[Kind],
) -> Result<(Vec<Face>, Vec<(usize, Waveform, usize)>)> {
    let nn = circuit.nodes.len();
    let end = |n: usize| -> End {
        match circuit.nodes[n].boundary {
            Some(b) if kind[n] == Kind::Exterior => End::Boundary(b as usize),
            _ => End::Node(n),
        }
    };
    let mut faces = Vec::with_capacity(circuit.branches.len());
    for (bi, b) in circuit.branches.iter().enumerate() {
        let (ka, kb) = (kind[b.from], kind[b.to]);
        if ka == Kind::Exterior && kb == Kind::Exterior {
            continue;
        }
        let (from, to) = (end(b.from), end(b.to));
        // a prescribed-pressure node without a tag cannot happen from network.rs; be explicit
        for (k, e) in [(ka, from), (kb, to)] {
            if k == Kind::Exterior && matches!(e, End::Node(_)) {
                return Err(bad(
                    &circuit.names.branch(bi),
                    "connects to a prescribed-pressure node without a boundary condition".into(),
                ));
            }
        }
        faces.push(Face::new(nn + bi, from, to));
    }
    let sources = circuit
        .sources
        .iter()
        .zip(&circuit.source_boundary)
        .filter(|((n, _), _)| kind[*n] != Kind::Exterior)
        .map(|((n, w), b)| (*n, w.clone(), *b))
        .collect();
    Ok((faces, sources))
}

/// Contract pass-through points at boundaries: a volume-free node joining one face to a cell
/// and one face to a boundary (the end node of an inverted-L vessel at a resistance or
/// Windkessel outlet) carries the same flow on both (KCL), so the cell's face leads straight
/// to the boundary. Zero-gradient backflow then carries the cell's own value, and the hot
/// loop has one point less per outlet.
fn contract_boundary_points(circuit: &Circuit, kind: &mut [Kind], faces: &mut Vec<Face>) {
    let nn = circuit.nodes.len();
    // incident faces per node: up to two are needed (more disqualifies the node)
    let mut inc = vec![[u32::MAX; 2]; nn];
    let mut deg = vec![0u8; nn];
    for (fi, f) in faces.iter().enumerate() {
        for e in [f.tail(), f.head()] {
            if let End::Node(n) = e {
                if deg[n] < 2 {
                    inc[n][deg[n] as usize] = fi as u32;
                }
                deg[n] = deg[n].saturating_add(1);
            }
        }
    }
    for ((n, _), _) in circuit.sources.iter().zip(&circuit.source_boundary) {
        deg[*n] = u8::MAX; // a node with a source stays
    }
    let other = |f: &Face, m: usize| {
        if f.tail() == End::Node(m) {
            f.head()
        } else {
            f.tail()
        }
    };
    let mut dropped = vec![false; faces.len()];
    for m in 0..nn {
        if kind[m] != Kind::Mixing || deg[m] != 2 {
            continue;
        }
        let (fa, fb) = (inc[m][0] as usize, inc[m][1] as usize);
        let (f_net, f_bnd, b) = match (other(&faces[fa], m), other(&faces[fb], m)) {
            (End::Node(n), End::Boundary(b)) if kind[n] == Kind::Cell => (fa, fb, b),
            (End::Boundary(b), End::Node(n)) if kind[n] == Kind::Cell => (fb, fa, b),
            _ => continue,
        };
        let f = &mut faces[f_net];
        if f.tail() == End::Node(m) {
            f.set_tail(End::Boundary(b));
        } else {
            f.set_head(End::Boundary(b));
        }
        dropped[f_bnd] = true;
        kind[m] = Kind::Exterior;
    }
    let mut k = 0;
    faces.retain(|_| {
        k += 1;
        !dropped[k - 1]
    });
}

/// Sub-cells per circuit node (docs/physics.md §5): `cells_per_segment`, per vessel
/// `cells_per_vessel`; a node shared by vessels (a junction cell) takes the finest.
fn refinement(
    spec: &TransportSpec,
    circuit: &Circuit,
    kind: &[Kind],
    geoms: &[SegmentGeom],
) -> Result<Vec<u32>> {
    let m_default = cells_per_segment(spec.cells_per_segment, "transport", "cells_per_segment")?;
    let mut m_vessel = vec![m_default; circuit.vessel_names.len()];
    for (name, &v) in &spec.cells_per_vessel {
        let Some(vi) = circuit.vessel_names.iter().position(|n| n == name) else {
            return Err(bad(
                "transport",
                format!("cells_per_vessel names vessel '{name}', which the network does not have"),
            ));
        };
        m_vessel[vi] = cells_per_segment(v, &format!("vessel '{name}'"), "cells_per_segment")?;
    }
    // (m <= MAX_CELLS_PER_SEGMENT: a u32)
    let mut m_node = vec![1u32; circuit.nodes.len()];
    for sg in geoms {
        for &(n, share) in &sg.nodes {
            if share > 0.0 && kind[n] == Kind::Cell {
                m_node[n] = m_node[n].max(m_vessel[sg.vessel] as u32);
            }
        }
    }
    Ok(m_node)
}

/// The refined graph (see `Chain`): every volume node with m > 1 becomes a chain of m
/// sub-cells. Sub-cell 0 is the node itself; the others are new transport nodes nn.., so the
/// face, upwind and sweep machinery works unchanged on the refined graph.
struct Refined {
    /// Per circuit node: its first extra sub-cell (`usize::MAX`: not refined; empty when no
    /// node is refined).
    first_extra: Vec<usize>,
    last_sub: Vec<usize>,
    chains: Vec<Chain>,
}

impl Refined {
    fn new(
        kind: &mut Vec<Kind>,
        faces: &mut Vec<Face>,
        sources: &[(usize, Waveform, usize)],
        m_node: &[u32],
    ) -> Refined {
        let nn = kind.len();
        if m_node.iter().all(|&m| m == 1) {
            // nothing refined: no per-node tables (read only for nodes with m > 1)
            return Refined {
                first_extra: Vec::new(),
                last_sub: Vec::new(),
                chains: Vec::new(),
            };
        }
        let mut r = Refined {
            first_extra: vec![usize::MAX; nn],
            last_sub: (0..nn).collect(),
            chains: Vec::new(),
        };
        let (mut ins, mut outs) = (vec![Vec::new(); nn], vec![Vec::new(); nn]);
        for (fi, f) in faces.iter().enumerate() {
            if let End::Node(n) = f.head() {
                ins[n].push(fi);
            }
            if let End::Node(n) = f.tail() {
                outs[n].push(fi);
            }
        }
        let mut node_src = vec![Vec::new(); nn];
        for (k, (n, _, _)) in sources.iter().enumerate() {
            node_src[*n].push(k);
        }
        for n in (0..nn).filter(|&n| m_node[n] > 1) {
            let m = m_node[n] as usize;
            r.first_extra[n] = kind.len();
            kind.extend(std::iter::repeat_n(Kind::Cell, m - 1));
            let sub = |k: usize| if k == 0 { n } else { r.first_extra[n] + k - 1 };
            r.last_sub[n] = sub(m - 1);
            for &fi in &outs[n] {
                faces[fi].set_tail(End::Node(r.last_sub[n]));
            }
            let first_face = faces.len();
            faces.extend(
                (1..m).map(|k| Face::new(usize::MAX, End::Node(sub(k - 1)), End::Node(sub(k)))),
            );
            r.chains.push(Chain {
                in_faces: std::mem::take(&mut ins[n]),
                out_faces: std::mem::take(&mut outs[n]),
                sources: std::mem::take(&mut node_src[n]),
                first_face,
                m,
            });
        }
        r
    }
}

/// Cells in node order, the sub-cells of a node contiguous (unchanged order when m = 1), with
/// their circuit node, reference volume and compliance (V_n/m, C_n/m).
struct CellLayout {
    cells: Vec<u32>,
    node_cell: Vec<u32>,
    cell_node: Vec<u32>,
    v0: Vec<f64>,
    cap: Vec<f64>,
    /// Per cell: the unknown its volume follows (empty: its node's pressure, as always without
    /// viscoelastic walls).
    volume_unknown: Vec<usize>,
}

impl CellLayout {
    fn new(
        volume: &[f64],
        dae: &Dae,
        kind: &[Kind],
        m_node: &[u32],
        first_extra: &[usize],
    ) -> CellLayout {
        let mut l = CellLayout {
            cells: Vec::new(),
            node_cell: vec![u32::MAX; kind.len()],
            cell_node: Vec::new(),
            v0: Vec::new(),
            cap: Vec::new(),
            volume_unknown: Vec::new(),
        };
        // a viscoelastic wall's volume follows its elastic pressure (`Dae::walls`)
        let walls: std::collections::HashMap<usize, usize> = dae.walls.iter().copied().collect();
        for n in (0..volume.len()).filter(|&n| kind[n] == Kind::Cell) {
            let m = m_node[n] as usize;
            let u = walls.get(&n).copied().unwrap_or(n);
            for k in 0..m {
                let c = if k == 0 { n } else { first_extra[n] + k - 1 };
                // (nodes and cells below 2^31: checked before the layout is made)
                l.node_cell[c] = l.cells.len() as u32;
                l.cells.push(c as u32);
                l.cell_node.push(n as u32);
                l.v0.push(volume[n] / m as f64);
                l.cap.push(dae.e[u] / m as f64);
                if !walls.is_empty() {
                    l.volume_unknown.push(u);
                }
            }
        }
        l
    }
}

/// The flow segments as the transport sees them (branch unknown and face, nodes and their
/// shares as `move_shares` placed them, wall), written over the circuit's segment geometry
/// in place (a `Segment` is smaller than a `SegmentGeom` of the same alignment, so the
/// collect reuses the buffer) and trimmed to their size.
fn segments(geoms: Vec<SegmentGeom>, nc_nodes: usize, face_of_unknown: &[u32]) -> Vec<Segment> {
    let mut segments: Vec<Segment> = geoms
        .into_iter()
        .map(|s| Segment {
            branch_unknown: (nc_nodes + s.branch) as u32,
            face: face_of_unknown[nc_nodes + s.branch],
            nodes: s.nodes.map(|(n, _)| n as u32),
            shares: s.nodes.map(|(_, share)| share),
            wall: SegmentWall {
                radius: s.radius,
                x0: s.x0,
                x1: s.x1,
            },
            volume: s.volume,
            compliance: s.compliance,
        })
        .collect();
    segments.shrink_to_fit();
    segments
}

/// The output vessels of the flow probes (first and last face, segment range) and their
/// segments in order. One pass: segments grouped by vessel, names looked up in a map.
fn output_layout(
    circuit: &Circuit,
    probes: &Probes,
    face_of_unknown: &[u32],
    segment_vessels: &[u32],
) -> (Vec<OutVessel>, Vec<u32>) {
    let vessel_index: std::collections::HashMap<&str, usize> = circuit
        .vessel_names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    let mut segs_of_vessel: Vec<Vec<usize>> = vec![Vec::new(); circuit.vessel_names.len()];
    for (j, &vessel) in segment_vessels.iter().enumerate() {
        if let Some(v) = segs_of_vessel.get_mut(vessel as usize) {
            v.push(j);
        }
    }
    let face = |u: usize| match face_of_unknown.get(u) {
        Some(&f) if f != u32::MAX => f as usize,
        _ => usize::MAX,
    };
    let mut out_vessels = Vec::new();
    let mut out_segments = Vec::new();
    for (k, name) in probes.vessels.iter().enumerate() {
        let start = out_segments.len();
        if let Some(&vi) = vessel_index.get(name.as_str()) {
            out_segments.extend(segs_of_vessel[vi].iter().map(|&j| j as u32));
        }
        out_vessels.push(OutVessel {
            first: face(probes.vessel_unknowns[4 * k + 2]),
            last: face(probes.vessel_unknowns[4 * k + 3]),
            segs: start..out_segments.len(),
            inlet_cell: u32::MAX,
            outlet_cell: u32::MAX,
        });
    }
    (out_vessels, out_segments)
}

/// The cells at the ends of every output vessel that hold a share of its first (last)
/// segment: the vessel's inlet (outlet) value is then the one carried into (out of) that cell,
/// not the one of the vessel's first (last) branch, which lies inside the vessel.
fn end_cells(
    out_vessels: &mut [OutVessel],
    out_segments: &[u32],
    segments: &[Segment],
    kind: &[Kind],
) {
    let cell_with_share = |j: u32, end: usize| {
        let sg = &segments[j as usize];
        let n = sg.nodes[end];
        if sg.shares[end] > 0.0 && kind[n as usize] == Kind::Cell {
            n
        } else {
            u32::MAX
        }
    };
    for v in out_vessels.iter_mut().filter(|v| !v.segs.is_empty()) {
        v.inlet_cell = cell_with_share(out_segments[v.segs.start], 0);
        v.outlet_cell = cell_with_share(out_segments[v.segs.end - 1], 1);
    }
}

/// Wall pieces: a segment's share in each cell; a refined node's share of the segment
/// (for a node at the segment's start [x0, x0 + share dx], at its end
/// [x1 − share dx, x1]) is split into m equal sub-intervals in flow order, with the law
/// integrated over each (exact for Lévêque's x^{-1/3}, by area for constant laws). Returns
/// the pieces, contiguous per segment, the CSR offsets of every segment's pieces and the
/// walls of the refined pieces (the others read their segment's: `Piece::sub`).
fn wall_pieces(
    segments: &[Segment],
    m_node: &[u32],
    node_cell: &[u32],
    first_extra: &[usize],
) -> (Vec<Piece>, Vec<u32>, Vec<SegmentWall>) {
    let mut pieces = Vec::with_capacity(2 * segments.len());
    let mut seg_pieces = Vec::with_capacity(segments.len() + 1);
    let mut sub_walls = Vec::new();
    seg_pieces.push(0);
    for (j, sg) in segments.iter().enumerate() {
        for (end, (n, share)) in sg.node_shares().into_iter().enumerate() {
            if share <= 0.0 || node_cell[n] == u32::MAX {
                continue;
            }
            let m = m_node[n] as usize;
            let piece = |c: usize, share: f64, sub: u32| Piece {
                seg: j as u32,
                node: c as u32,
                cell: node_cell[c],
                sub,
                share,
            };
            if m == 1 {
                // unrefined: the whole segment's law times the share (as before refinement)
                pieces.push(piece(n, share, Piece::OWN_WALL));
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
                let wall = SegmentWall {
                    radius: w.radius,
                    x0: xa,
                    x1: xb,
                };
                sub_walls.push(wall);
                pieces.push(piece(c, 1.0, (sub_walls.len() - 1) as u32));
            }
        }
        seg_pieces.push(pieces.len() as u32);
    }
    pieces.shrink_to_fit();
    sub_walls.shrink_to_fit();
    (pieces, seg_pieces, sub_walls)
}

/// Section-wide settings: at least one species, a finite reference pressure, a valid velocity
/// threshold, flow sources tagged with their boundary conditions.
fn check_settings(spec: &TransportSpec, circuit: &Circuit) -> Result<()> {
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
    Ok(())
}

/// CSR node → incident faces, and CSR node → flow sources, with u32 indices (a plan of more
/// than 2^32 face ends is refused with a typed error). Linear time.
#[allow(clippy::type_complexity)]
fn incidence(
    nn: usize,
    faces: &[Face],
    sources: &[(usize, Waveform, usize)],
) -> Result<(Vec<u32>, Vec<u32>, Vec<u32>, Vec<u32>)> {
    if 2 * faces.len() > u32::MAX as usize {
        return Err(Error::Resource {
            what: format!("transport plan ({} faces)", faces.len()),
            bytes: 0,
            message: "more faces than the plan's 32-bit indices hold; use fewer segments \
                      (segmentation max_length, a vessel's segments)"
                .into(),
        });
    }
    let mut node_ptr = vec![0u32; nn + 1];
    for f in faces {
        for e in [f.tail(), f.head()] {
            if let End::Node(n) = e {
                node_ptr[n + 1] += 1;
            }
        }
    }
    for i in 0..nn {
        node_ptr[i + 1] += node_ptr[i];
    }
    let mut node_faces = vec![0u32; node_ptr[nn] as usize];
    let mut fill = node_ptr.clone();
    for (fi, f) in faces.iter().enumerate() {
        for e in [f.tail(), f.head()] {
            if let End::Node(n) = e {
                node_faces[fill[n] as usize] = fi as u32;
                fill[n] += 1;
            }
        }
    }
    // (node, source) by node, each node's sources in source order (as a per-node CSR lists
    // them): a model has a few sources, and a row start per node cost 4 bytes per node
    let mut by_node: Vec<(u32, u32)> = (sources.iter().enumerate())
        .map(|(k, (n, _, _))| (*n as u32, k as u32))
        .collect();
    by_node.sort_unstable();
    let (source_nodes, source_list) = by_node.into_iter().unzip();
    Ok((node_ptr, node_faces, source_nodes, source_list))
}

impl Plan {
    /// `parent_is_next` and `reads_acc` of the elimination order (see [`Link`]): a node hands its
    /// terms to its parent in registers when the parent is eliminated next; the parent then
    /// reads its accumulator only if something else left terms there.
    fn link_carries(&mut self) {
        let Some(tree) = self.tree.as_mut() else {
            return;
        };
        let mut reads = vec![false; self.kind.len()];
        for b in &self.boundary_links {
            reads[b.node as usize] = true;
        }
        for &(n, _, _) in &self.sources {
            reads[n] = true;
        }
        for k in 0..tree.len() {
            let next = tree.get(k + 1).map_or(u32::MAX, |l| l.node);
            let l = &mut tree[k];
            l.set_parent_is_next(l.parent != u32::MAX && l.parent == next);
            if l.parent != u32::MAX && !l.parent_is_next() {
                reads[l.parent as usize] = true;
            }
        }
        for l in tree.iter_mut() {
            l.set_reads_acc(reads[l.node as usize]);
        }
    }

    /// The solver lists derived from the grid: domain nodes, internal and boundary faces,
    /// simple and general mixing points, the tree elimination order, the face unknowns, and
    /// the build's wall laws.
    fn finish(&mut self) -> Result<()> {
        let nn = self.kind.len();
        self.domain = (0..nn)
            .filter(|&n| self.kind[n] != Kind::Exterior)
            .collect();
        // (faces, nodes, cells, segments and pieces are indexed by u32 in the plan)
        let most = (self.faces.len().max(nn)).max(self.pieces.len().max(self.segments.len()));
        if most >= u32::MAX as usize {
            return Err(bad("transport", "network too large".into()));
        }
        // the internal faces' list for the orders below, dropped after them (the solvers read
        // them from the faces, `Plan::internal`)
        let internal: Vec<[u32; 3]> = internal_faces(&self.faces).collect();
        self.n_internal = internal.len();
        for (fi, f) in self.faces.iter().enumerate() {
            if !matches!((f.tail(), f.head()), (End::Node(_), End::Node(_))) {
                self.boundary_faces.push(fi);
            }
            match (f.tail(), f.head()) {
                (End::Boundary(b), End::Node(n)) | (End::Node(n), End::Boundary(b)) => {
                    self.boundary_links.push(BoundaryLink {
                        face: fi as u32,
                        node: n as u32,
                        boundary: b as u32,
                        into_node: matches!(f.tail(), End::Boundary(_)),
                    })
                }
                // (`flow_faces` drops branches between two exterior nodes)
                _ => {}
            }
        }
        for &m in &self.mixing {
            let two = self.faces_at(m).len() == 2;
            let neighbours_known = self.faces_at(m).all(|fi| {
                let f = &self.faces[fi];
                let other = if f.tail() == End::Node(m) {
                    f.head()
                } else {
                    f.tail()
                };
                !matches!(other, End::Node(o) if self.kind[o] == Kind::Mixing)
            });
            if two && self.node_sources(m).is_empty() && neighbours_known {
                self.simple_mixing.push(m);
            } else {
                self.general_mixing.push(m);
            }
        }
        self.tree = tree_order(nn, &self.domain, &internal);
        if self.tree.is_none() {
            self.core = CoreOrder::of(nn, &self.domain, &internal);
        }
        drop(internal);
        if self.tree.is_some() {
            // a forest is solved in `tree` order; the domain list is read only by the
            // flow-order sweep of a network with loops (8 bytes per cell kept for nothing)
            self.domain = Vec::new();
        }
        for l in self.tree.iter_mut().flatten() {
            // (cells < nodes < u32::MAX, checked above)
            l.cell = self.node_cell[l.node as usize];
        }
        self.link_carries();
        self.face_unknowns = self.faces[..self.n_flow_faces]
            .iter()
            .map(|f| f.unknown)
            .collect();
        // laws that do not need the mean flow are final now
        let zero = vec![0.0; self.segments.len()];
        let mean = MeanFlows {
            abs: &zero,
            forward: &zero,
            renewal: &[],
        };
        let laws = Laws::evaluate_all(self, mean, false)?;
        self.base_laws = laws.into_iter().map(Arc::new).collect();
        Ok(())
    }
}

#[cfg(test)]
mod segment_tests {
    use super::*;

    /// The plan's segments are written over the circuit's segment geometry: the same buffer
    /// (never both tables at once), each segment's branch unknown, face, shared nodes and wall
    /// as the geometry gave them.
    #[test]
    fn plan_segments_take_the_geometry_buffer_over() {
        let nc_nodes = 7;
        let geoms: Vec<SegmentGeom> = (0..1000)
            .map(|j| SegmentGeom {
                vessel: j / 4,
                branch: j,
                nodes: [(j, 0.25), (j + 1, 0.75)],
                radius: 1e-3 * (j + 1) as f64,
                x0: 0.01 * j as f64,
                x1: 0.01 * (j + 1) as f64,
                volume: 2.0 * j as f64,
                compliance: 3.0 * j as f64,
            })
            .collect();
        let buffer = geoms.as_ptr() as usize;
        let face_of_unknown: Vec<u32> = (0..nc_nodes + 1000).map(|u| 10 * u as u32).collect();
        let segs = segments(geoms, nc_nodes, &face_of_unknown);
        assert_eq!(segs.as_ptr() as usize, buffer);
        assert_eq!(segs.len(), 1000);
        assert_eq!(segs.capacity(), 1000);
        for (j, s) in segs.iter().enumerate() {
            assert_eq!(s.branch_unknown as usize, nc_nodes + j);
            assert_eq!(s.face as usize, 10 * (nc_nodes + j));
            assert_eq!(s.nodes, [j as u32, j as u32 + 1]);
            assert_eq!(s.shares, [0.25, 0.75]);
            assert_eq!(s.wall.radius, 1e-3 * (j + 1) as f64);
            assert_eq!(
                (s.wall.x0, s.wall.x1),
                (0.01 * j as f64, 0.01 * (j + 1) as f64)
            );
            assert_eq!((s.volume, s.compliance), (2.0 * j as f64, 3.0 * j as f64));
        }
    }
}
