//! The immutable transport plan: grid (cells, mixing points, exterior nodes), faces,
//! refinement chains, wall pieces, the implicit elimination order and the output layout.
//! Built once per model in linear time (`build.rs`); many runs share it through an `Arc`.

#[allow(unused_imports)]
use super::*;

/// One domain node in the elimination order of [`tree_order`]: its parent in the spanning
/// forest (`u32::MAX` for a root) and the face joining them. 16 bytes: the fused step reads
/// every link twice per step, so the face index shares its word with the three flags.
#[derive(Debug, Clone, Copy)]
pub(super) struct Link {
    pub(super) node: u32,
    pub(super) parent: u32,
    /// The node's cell (`u32::MAX`: a mixing point), so the fused step reads the cell arrays
    /// without a lookup.
    pub(super) cell: u32,
    /// The face to the parent (low 29 bits, [`Link::NO_FACE`] for a root) and the flags
    /// `FROM_CHILD`, `TO_NEXT`, `READS_ACC` (see their accessors).
    bits: u32,
}

impl Link {
    const FACE: u32 = (1 << 29) - 1;
    /// The face of a root (no parent).
    pub(super) const NO_FACE: u32 = Self::FACE;
    const FROM_CHILD: u32 = 1 << 29;
    const TO_NEXT: u32 = 1 << 30;
    const READS_ACC: u32 = 1 << 31;

    /// The link of `node` to `parent` through `face` (`face` < [`Link::NO_FACE`], checked by
    /// `tree_order`).
    pub(super) fn new(node: u32, parent: u32, face: u32, from_child: bool) -> Link {
        debug_assert!(face <= Self::FACE);
        let flag = if from_child { Self::FROM_CHILD } else { 0 };
        Link {
            node,
            parent,
            cell: u32::MAX,
            bits: (face & Self::FACE) | flag,
        }
    }

    #[inline(always)]
    pub(super) fn face(&self) -> u32 {
        self.bits & Self::FACE
    }

    /// The face points from this node to its parent (positive flow runs child → parent).
    #[inline(always)]
    pub(super) fn face_from_child(&self) -> bool {
        self.bits & Self::FROM_CHILD != 0
    }

    /// The parent is the next node eliminated (a chain along a vessel): the fused step hands
    /// this node's terms of the parent's row over in registers (`Plan::link_carries`).
    #[inline(always)]
    pub(super) fn parent_is_next(&self) -> bool {
        self.bits & Self::TO_NEXT != 0
    }

    /// Terms of this node's row wait in the fused step's accumulator (boundary faces, flow
    /// sources, or a child not eliminated just before it).
    #[inline(always)]
    pub(super) fn reads_acc(&self) -> bool {
        self.bits & Self::READS_ACC != 0
    }

    pub(super) fn set_parent_is_next(&mut self, v: bool) {
        self.bits = (self.bits & !Self::TO_NEXT) | if v { Self::TO_NEXT } else { 0 };
    }

    pub(super) fn set_reads_acc(&mut self, v: bool) {
        self.bits = (self.bits & !Self::READS_ACC) | if v { Self::READS_ACC } else { 0 };
    }
}

/// A face between a domain node and a boundary (every boundary face is one), compact for the
/// per-step passes.
#[derive(Debug, Clone, Copy)]
pub(super) struct BoundaryLink {
    pub(super) face: u32,
    pub(super) node: u32,
    pub(super) boundary: u32,
    /// The face points from the boundary into the node (positive flow enters the domain).
    pub(super) into_node: bool,
}

impl BoundaryLink {
    /// The flow into the node (m³/s) of the face flow `q`: ±q by the face's orientation.
    #[inline]
    pub(super) fn inflow(&self, q: f64) -> f64 {
        if self.into_node { q } else { -q }
    }

    /// Whether the boundary is upwind of the node at face flow `q`: then it carries its own
    /// value in, else the node's value leaves through it.
    #[inline]
    pub(super) fn boundary_upwind(&self, q: f64) -> bool {
        (q >= 0.0) == self.into_node
    }

    /// Upwind species flux into the node (mol/s) at face flow `q`: the boundary's value
    /// (`boundary`, asked only when it is upwind) or the node's `node_conc`.
    #[inline]
    pub(super) fn flux_in(&self, q: f64, node_conc: f64, boundary: impl FnOnce() -> f64) -> f64 {
        upwind_flux_in(q, self.into_node, node_conc, boundary)
    }
}

/// Upwind species flux into a node (mol/s) across a boundary carrying flow `q`, positive into
/// the node when `into_node` (an inward boundary face, or any point flow source) and out of it
/// otherwise: the boundary's value when it is upwind (`boundary`, asked only then), else the
/// node's `node_conc`. The one upwind rule of boundary faces and flow sources alike.
#[inline]
pub(super) fn upwind_flux_in(
    q: f64,
    into_node: bool,
    node_conc: f64,
    boundary: impl FnOnce() -> f64,
) -> f64 {
    let (inflow, boundary_upwind) = if into_node {
        (q, q >= 0.0)
    } else {
        (-q, q < 0.0)
    };
    inflow
        * if boundary_upwind {
            boundary()
        } else {
            node_conc
        }
}

/// Children-before-parents order of the domain nodes when the undirected graph of the internal
/// faces is a forest (no loops, no parallel faces): then the upwind system can be eliminated
/// leaves first for any flow directions (`Transport::tree_solve`). None otherwise. Linear time.
pub(super) fn tree_order(nt: usize, domain: &[usize], internal: &[[u32; 3]]) -> Option<Vec<Link>> {
    tree_order_held(nt, domain, internal, &[], &[])
}

/// [`tree_order`] of the forest left when the faces between two nodes of a loop-carrying core
/// (`in_core`, per node; empty: none) are taken out, with the core's `roots` first, each the
/// root of its pendant trees (`core::CoreOrder`).
pub(super) fn tree_order_held(
    nt: usize,
    domain: &[usize],
    internal: &[[u32; 3]],
    roots: &[usize],
    in_core: &[bool],
) -> Option<Vec<Link>> {
    // (a face index must fit a link's 29 bits; beyond, the general sweep takes over)
    if internal.iter().any(|e| e[0] >= Link::NO_FACE) {
        return None;
    }
    let held = |a: u32, b: u32| !in_core.is_empty() && in_core[a as usize] && in_core[b as usize];
    let forest = || internal.iter().filter(|e| !held(e[1], e[2]));
    let mut ptr = vec![0u32; nt + 1];
    for &[_, a, b] in forest() {
        ptr[a as usize + 1] += 1;
        ptr[b as usize + 1] += 1;
    }
    for i in 0..nt {
        ptr[i + 1] += ptr[i];
    }
    let mut fill = ptr.clone();
    let mut adj = vec![(0u32, 0u32); ptr[nt] as usize];
    for &[f, a, b] in forest() {
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
    // breadth first over chains: a chain (a node and its single-child descendants) is
    // emitted whole, and the children of its last node start new chains, queued. Reversed,
    // the order runs leaves first and walks each vessel's nodes (numbered consecutively
    // along it by the assembly) in one sequence, so the elimination's accesses to every
    // node-, cell- and face-indexed array are near-sequential streams. A plain breadth-first
    // order interleaves the vessels of a generation (a stride of one vessel per access,
    // each cache line fetched once per segment position: the step's cost per node grew
    // with the tree once a generation no longer fitted the cache), a depth-first one jumps
    // at every vessel.
    let mut order: Vec<Link> = Vec::with_capacity(domain.len());
    let mut heads: Vec<Link> = Vec::new();
    for &r in roots.iter().chain(domain) {
        if seen[r] {
            continue;
        }
        seen[r] = true;
        heads.clear();
        heads.push(Link::new(r as u32, u32::MAX, Link::NO_FACE, false));
        let mut head = 0;
        while head < heads.len() {
            let mut l = heads[head];
            head += 1;
            loop {
                order.push(l);
                let n = l.node as usize;
                let (mut first, mut children) = (None, 0);
                for &(f, o) in &adj[ptr[n] as usize..ptr[n + 1] as usize] {
                    if l.parent != u32::MAX && f == l.face() {
                        continue;
                    }
                    if seen[o as usize] {
                        return None; // a loop (or two faces between the same nodes)
                    }
                    seen[o as usize] = true;
                    let child = Link::new(o, l.node, f, internal_from(internal, f) == o);
                    children += 1;
                    match children {
                        1 => first = Some(child),
                        2 => heads.extend(first.take().into_iter().chain([child])),
                        _ => heads.push(child),
                    }
                }
                // a single child continues the chain
                match first {
                    Some(c) => l = c,
                    None => break,
                }
            }
        }
    }
    order.reverse();
    Some(order)
}

/// The faces between two nodes as [face, from node, to node], in face order: read from the
/// faces themselves (a list of them beside the faces was 12 bytes a face for the network's
/// life).
pub(super) fn internal_faces(faces: &[Face]) -> impl Iterator<Item = [u32; 3]> + '_ {
    faces
        .iter()
        .enumerate()
        .filter(|(_, f)| (f.from | f.to) & Face::BOUNDARY == 0)
        .map(|(fi, f)| [fi as u32, f.from, f.to])
}

impl Plan {
    /// The faces between two nodes as [face, from node, to node], in face order (see
    /// [`internal_faces`]).
    pub(super) fn internal(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        internal_faces(&self.faces)
    }
}

/// `from` node of internal face `f` (faces are listed in `internal` in face order, so a binary
/// search finds it).
pub(super) fn internal_from(internal: &[[u32; 3]], f: u32) -> u32 {
    let k = internal.partition_point(|e| e[0] < f);
    internal[k][1]
}

/// The wall of piece `pc`: its segment's own, or its refined sub-interval in `sub_walls`.
#[inline]
pub(super) fn piece_wall(
    segments: &[Segment],
    sub_walls: &[SegmentWall],
    pc: &Piece,
) -> SegmentWall {
    match sub_walls.get(pc.sub as usize) {
        Some(&w) => w,
        None => segments[pc.seg as usize].wall,
    }
}

/// Topology, layout and species settings of a transport model; never changed after
/// `Transport::build`.
#[derive(Debug)]
pub struct Plan {
    pub(super) kind: Vec<Kind>,
    /// Per cell its transport node, per transport node its cell (`u32::MAX`: none); u32 as
    /// every per-node index of the plan (a network of 2^31 nodes is refused when built).
    pub(super) cells: Vec<u32>,
    pub(super) node_cell: Vec<u32>,
    pub(super) v0: Vec<f64>,
    pub(super) cap: Vec<f64>,
    pub(super) p_ref: f64,
    pub(super) faces: Vec<Face>,
    pub(super) sources: Vec<(usize, Waveform, usize)>,
    pub(super) boundary_inlet: Vec<bool>,
    pub(super) mixing: Vec<usize>,
    /// CSR node → incident faces (u32: a plan of 2^32 faces is refused when built).
    pub(super) node_ptr: Vec<u32>,
    pub(super) node_faces: Vec<u32>,
    /// The flow sources by node: `source_list[k]` is a source of node `source_nodes[k]`,
    /// sorted by node (a node's sources in source order). A model has a few sources: a row
    /// start per node was 4 bytes per node for them.
    pub(super) source_nodes: Vec<u32>,
    pub(super) source_list: Vec<u32>,
    pub(super) segments: Vec<Segment>,
    /// Faces 0..n_flow_faces carry a flow unknown; the rest are interior faces of `chains`.
    pub(super) n_flow_faces: usize,
    /// The flow unknown of faces 0..n_flow_faces (a compact copy for the per-step gather).
    pub(super) face_unknowns: Vec<u32>,
    pub(super) chains: Vec<Chain>,
    /// Per cell: the circuit node whose pressure sets its volume.
    pub(super) cell_node: Vec<u32>,
    /// Per cell: the unknown setting its volume where that is not `cell_node` (a viscoelastic
    /// wall's elastic pressure); empty when no cell has one.
    pub(super) volume_unknown: Vec<usize>,
    /// Per circuit node: its last sub-cell (itself unless refined; empty without
    /// refinement, see `last_sub`).
    pub(super) last_sub: Vec<usize>,
    /// Wall pieces, contiguous per segment (`seg_pieces[j]..seg_pieces[j + 1]`).
    pub(super) pieces: Vec<Piece>,
    pub(super) seg_pieces: Vec<u32>,
    /// The walls of the pieces of refined nodes' sub-cells (a sub-interval of their
    /// segment's wall); the other pieces read their segment's (`piece_wall`).
    pub(super) sub_walls: Vec<SegmentWall>,
    pub(super) formulation: Formulation,
    pub(super) v_eps: f64,
    pub(super) out_vessels: Vec<OutVessel>,
    pub(super) out_segments: Vec<u32>,
    pub(super) segment_vessels: Vec<u32>,
    /// Names of the circuit nodes (error messages; refined sub-cells are named after them).
    /// Shared with the circuit and its DAE: a name is written only when a message needs it
    /// (a copy of every node's name cost 40 B per segment and ~0.1 µs per segment to write).
    pub(super) node_names: Arc<crate::circuit::Names>,
    /// Nodes solved by the implicit sweep (cells and mixing points); empty when `tree` is
    /// set (a forest is solved in that order).
    pub(super) domain: Vec<usize>,
    /// The number of faces between two nodes (listed by [`Plan::internal`]); the other faces:
    pub(super) n_internal: usize,
    pub(super) boundary_faces: Vec<usize>,
    /// The boundary faces in the same order, as (face, node, boundary, direction).
    pub(super) boundary_links: Vec<BoundaryLink>,
    /// Mixing points with two faces, no source and non-mixing neighbours: evaluated directly.
    pub(super) simple_mixing: Vec<usize>,
    /// The other mixing points (solved by the flow-order sweep).
    pub(super) general_mixing: Vec<usize>,
    /// Elimination order of the implicit solve when the domain graph is a forest (always on
    /// trees): None sends it to the flow-order sweep, which also handles loops.
    pub(super) tree: Option<Vec<Link>>,
    /// A domain with loops: its pendant trees' elimination around its loop-carrying core
    /// (`core::CoreOrder`); None for a forest or a domain that is all core.
    pub(super) core: Option<CoreOrder>,
    /// Species settings, and their wall laws as built (final unless a closure needs the
    /// cycle-mean flow, which a run then sets with `set_mean_flow`).
    pub(super) species: Vec<SpeciesPlan>,
    pub(super) base_laws: Vec<Arc<Laws>>,
    /// Tissue walls per species (empty when no species has one).
    pub(super) tissue: Vec<Option<tissue::TissuePlan>>,
}

impl Plan {
    /// The unknown whose value sets cell `i`'s volume (its node's pressure, or its
    /// viscoelastic wall's elastic pressure).
    #[inline]
    pub(super) fn volume_unknown(&self, i: usize) -> usize {
        match self.volume_unknown.get(i) {
            Some(&u) => u,
            None => self.cell_node[i] as usize,
        }
    }

    /// The last sub-cell of circuit node `n` (itself unless refined): the donor of the faces
    /// leaving the node, and the value reported for its segments.
    #[inline]
    pub(super) fn last_sub(&self, n: usize) -> usize {
        self.last_sub.get(n).copied().unwrap_or(n)
    }

    /// The faces incident to node `n`.
    #[inline]
    pub(super) fn faces_at(&self, n: usize) -> impl ExactSizeIterator<Item = usize> + '_ {
        let faces = &self.node_faces[self.node_ptr[n] as usize..self.node_ptr[n + 1] as usize];
        faces.iter().map(|&f| f as usize)
    }

    /// Flow sources of node `n`.
    #[inline]
    pub(super) fn node_sources(&self, n: usize) -> &[u32] {
        let n = n as u32;
        let start = self.source_nodes.partition_point(|&m| m < n);
        let end = start + self.source_nodes[start..].partition_point(|&m| m == n);
        &self.source_list[start..end]
    }

    /// The wall of piece `pc` (see [`piece_wall`]).
    #[inline]
    pub(super) fn piece_wall(&self, pc: &Piece) -> SegmentWall {
        piece_wall(&self.segments, &self.sub_walls, pc)
    }

    /// Wall pieces of segment `j`.
    #[inline]
    pub(super) fn seg_pieces(&self, j: usize) -> std::ops::Range<usize> {
        self.seg_pieces[j] as usize..self.seg_pieces[j + 1] as usize
    }

    /// Name of transport node `n`: its circuit node's, or for a sub-cell of a refined node
    /// that node's name and the sub-cell's position.
    pub(super) fn node_name(&self, n: usize) -> String {
        let Some(&i) = self.node_cell.get(n) else {
            return format!("node {n}");
        };
        if n < self.node_names.n_nodes() || i == u32::MAX {
            return self.circuit_node_name(n);
        }
        // sub-cells of a node are contiguous, sub-cell 0 being the node itself
        let parent = self.cell_node[i as usize] as usize;
        let first = self.node_cell[parent];
        let m = self.node_cell[self.last_sub(parent)] - first + 1;
        let name = self.circuit_node_name(parent);
        format!("{name} (transport cell {}/{m})", i - first + 1)
    }

    /// Name of circuit node `n` ("node n" past the circuit's nodes).
    pub(super) fn circuit_node_name(&self, n: usize) -> String {
        if n < self.node_names.n_nodes() {
            self.node_names.node(n)
        } else {
            format!("node {n}")
        }
    }
}

// runs on other threads share one plan
const _: fn() = || {
    fn shared<T: Send + Sync>() {}
    shared::<Plan>();
};

#[cfg(test)]
mod tests {
    use super::*;

    /// Two vessels of three nodes each below a root chain (0–1–2 then 2–3–4 and 2–5–6, faces
    /// numbered along the vessels), plus a loop case.
    #[test]
    fn tree_order_eliminates_children_first_and_walks_each_chain_in_one_run() {
        let internal: Vec<[u32; 3]> = vec![
            [0, 0, 1],
            [1, 1, 2],
            [2, 2, 3],
            [3, 3, 4],
            [4, 2, 5],
            [5, 5, 6],
        ];
        let domain: Vec<usize> = (0..7).collect();
        let order = tree_order(7, &domain, &internal).expect("a tree");
        assert_eq!(order.len(), 7);
        let pos: Vec<usize> = (0..7)
            .map(|n| order.iter().position(|l| l.node as usize == n).unwrap())
            .collect();
        // every node before its parent, joined by the face between them
        for l in &order {
            if l.parent != u32::MAX {
                assert!(pos[l.node as usize] < pos[l.parent as usize]);
                let f = internal[l.face() as usize];
                assert!((f[1], f[2]) == (l.node, l.parent) || (f[1], f[2]) == (l.parent, l.node));
                assert_eq!(l.face_from_child(), f[1] == l.node);
            }
        }
        // each chain's nodes are eliminated one after the other (4 then 3, 6 then 5, 2–1–0)
        for (a, b) in [(4, 3), (6, 5), (2, 1), (1, 0)] {
            assert_eq!(pos[a] + 1, pos[b], "{a} then {b}");
        }
        // a loop has no tree order
        let mut looped = internal.clone();
        looped.push([6, 4, 6]);
        assert!(tree_order(7, &domain, &looped).is_none());
    }
}
