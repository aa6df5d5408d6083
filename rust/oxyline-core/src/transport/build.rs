//! Building the transport from the spec and the assembled circuit: cells, faces,
//! refinement chains, wall pieces, output layout (linear time).

#[allow(unused_imports)]
use super::*;

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

impl Species {
    /// Validate one species of the transport section against the circuit: binding, boundary
    /// values of every boundary condition, walls per vessel, initial value. `sizes` = (cells,
    /// segments, transport nodes).
    pub(super) fn build(
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

impl Transport {
    /// Validate the transport section against the assembled circuit.
    pub fn build(
        spec: &TransportSpec,
        circuit: &Circuit,
        dae: &Dae,
        probes: &Probes,
    ) -> Result<Self> {
        let nn = circuit.nodes.len();
        check_settings(spec, circuit)?;
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
                        &circuit.names.node(i),
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
                        &circuit.names.branch(bi),
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
        let mut node_names: Vec<String> = (0..nn).map(|i| circuit.names.node(i)).collect();
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
        let (node_ptr, node_faces, node_sources) = incidence(nn, &faces, &sources);
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
        let mut p = Plan {
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
            formulation: spec.formulation,
            v_eps: spec.velocity_threshold,
            out_vessels,
            out_segments,
            segment_vessels: circuit.segments.iter().map(|s| s.vessel).collect(),
            node_names,
            domain: Vec::new(),
            internal: Vec::new(),
            boundary_faces: Vec::new(),
            simple_mixing: Vec::new(),
            general_mixing: Vec::new(),
            tree: None,
        };
        p.finish()?;
        let mut t = Transport {
            species,
            mean_abs: Vec::new(),
            segment_output: true,
            vol: vec![0.0; ncells],
            conc: vec![0.0; nn],
            qf: vec![0.0; p.faces.len()],
            qs: vec![0.0; p.sources.len()],
            bval: vec![None; p.boundary_inlet.len()],
            sweep: Sweep::new(nn),
            wvol: Vec::new(),
            plan: Arc::new(p),
        };
        // laws that do not need the mean flow are final now
        let zero = vec![0.0; t.plan.segments.len()];
        t.set_laws(&zero, false)?;
        Ok(t)
    }
}

/// The output vessels of the flow probes (first and last face, segment range) and their
/// segments in order. One pass: segments grouped by vessel, names looked up in a map.
pub(super) fn output_layout(circuit: &Circuit, probes: &Probes) -> (Vec<OutVessel>, Vec<usize>) {
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
pub(super) fn wall_pieces(
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

/// CSR node → incident faces, and the flow sources of every node. Linear time.
fn incidence(
    nn: usize,
    faces: &[Face],
    sources: &[(usize, Waveform, usize)],
) -> (Vec<usize>, Vec<usize>, Vec<Vec<usize>>) {
    let mut deg = vec![0usize; nn + 1];
    for f in faces {
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
    (node_ptr, node_faces, node_sources)
}

impl Plan {
    /// The solver lists derived from the grid: domain nodes, internal and boundary faces,
    /// simple and general mixing points, the tree elimination order, the face unknowns.
    fn finish(&mut self) -> Result<()> {
        let nn = self.kind.len();
        self.domain = (0..nn)
            .filter(|&n| self.kind[n] != Kind::Exterior)
            .collect();
        if self.faces.len() >= u32::MAX as usize || nn >= u32::MAX as usize {
            return Err(bad("transport", "network too large".into()));
        }
        for (fi, f) in self.faces.iter().enumerate() {
            match (f.from, f.to) {
                (End::Node(a), End::Node(b)) => self.internal.push([fi as u32, a as u32, b as u32]),
                _ => self.boundary_faces.push(fi),
            }
        }
        for &m in &self.mixing {
            let faces = &self.node_faces[self.node_ptr[m]..self.node_ptr[m + 1]];
            let neighbours_known = faces.iter().all(|&fi| {
                let f = &self.faces[fi];
                let other = if f.from == End::Node(m) { f.to } else { f.from };
                !matches!(other, End::Node(o) if self.kind[o] == Kind::Mixing)
            });
            if faces.len() == 2 && self.node_sources[m].is_empty() && neighbours_known {
                self.simple_mixing.push(m);
            } else {
                self.general_mixing.push(m);
            }
        }
        self.tree = tree_order(nn, &self.domain, &self.internal);
        self.face_unknowns = self.faces[..self.n_flow_faces]
            .iter()
            .map(|f| f.unknown)
            .collect();
        Ok(())
    }
}
