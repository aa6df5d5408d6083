//! Heap bytes held by the plan and by a run's state (`benches`, `examples/transport_memory`).

#[allow(unused_imports)]
use super::*;

/// Heap bytes of a container (its capacity, not its length: what the allocator holds).
trait Heap {
    fn heap(&self) -> usize;
}

impl<T: Flat> Heap for Vec<T> {
    fn heap(&self) -> usize {
        self.capacity() * std::mem::size_of::<T>()
    }
}

/// Element types without heap data of their own.
trait Flat {}
impl Flat for f64 {}
impl Flat for u32 {}
impl Flat for usize {}
impl Flat for bool {}
impl Flat for Kind {}
impl Flat for Face {}
impl Flat for Piece {}
impl Flat for Segment {}
impl Flat for OutVessel {}
impl Flat for Link {}
impl Flat for SegmentLaw {}
impl Flat for HillAnchor {}
impl Flat for [f64; 3] {}
impl Flat for SegmentWall {}
impl Flat for BoundaryLink {}
impl Flat for Option<f64> {}
impl Flat for [u32; 3] {}
impl Flat for (usize, f64, f64) {}

impl Heap for Laws {
    fn heap(&self) -> usize {
        self.laws.heap()
            + self.cell_g.heap()
            + self.cell_gcw.heap()
            + self.cell_q.heap()
            + self.cell_wc.heap()
            + self.dynamic.heap()
            + self.relax.heap()
            + self.relax_of_seg.heap()
            + self.dynamic_segs.heap()
            + self.flux_tables.as_ref().map_or(0, |t| t.heap_bytes())
    }
}

impl Plan {
    /// Heap bytes of the plan, its species' build-time laws included (the chains, sources and
    /// species settings are per vessel or per boundary, and left out).
    pub fn heap_bytes(&self) -> usize {
        self.heap_report().iter().map(|(_, b)| b).sum()
    }

    /// `heap_bytes` per field.
    pub fn heap_report(&self) -> Vec<(&'static str, usize)> {
        vec![
            ("kind", self.kind.heap()),
            ("cells", self.cells.heap()),
            ("node_cell", self.node_cell.heap()),
            ("v0, cap", self.v0.heap() + self.cap.heap()),
            ("faces", self.faces.heap()),
            ("boundary_inlet", self.boundary_inlet.heap()),
            ("mixing", self.mixing.heap()),
            ("node_ptr", self.node_ptr.heap()),
            ("node_faces", self.node_faces.heap()),
            (
                "sources",
                self.source_nodes.heap() + self.source_list.heap(),
            ),
            ("segments", self.segments.heap()),
            ("face_unknowns", self.face_unknowns.heap()),
            (
                "cell_node",
                self.cell_node.heap() + self.volume_unknown.heap(),
            ),
            ("last_sub", self.last_sub.heap()),
            (
                "pieces",
                self.pieces.heap() + self.seg_pieces.heap() + self.sub_walls.heap(),
            ),
            (
                "outputs",
                self.out_vessels.heap() + self.out_segments.heap() + self.segment_vessels.heap(),
            ),
            ("domain", self.domain.heap()),
            (
                "boundary faces",
                self.boundary_faces.heap() + self.boundary_links.heap(),
            ),
            (
                "mixing lists",
                self.simple_mixing.heap() + self.general_mixing.heap(),
            ),
            ("tree", self.tree.as_ref().map_or(0, Heap::heap)),
            (
                "laws",
                self.base_laws.iter().map(|l| l.heap()).sum::<usize>(),
            ),
        ]
    }
}

impl Transport {
    /// Heap bytes of this run's own state: scratch, per-species state, and the wall laws it
    /// does not share with the plan (those set by `set_mean_flow`). The amounts (the
    /// integrator's vector) are not part of it.
    pub fn state_heap_bytes(&self) -> usize {
        let sw = &self.sweep;
        let sweep = sw.mark.heap()
            + sw.pending.heap()
            + sw.num.heap()
            + sw.den.heap()
            + sw.lag.heap()
            + sw.queue.heap()
            + sw.d.heap()
            + sw.b.heap()
            + sw.dnode.heap()
            + sw.ya.heap()
            + sw.wnew.heap()
            + sw.wconst.heap()
            + sw.wlin.heap()
            + sw.inv_slope.heap()
            + sw.beta.heap()
            + sw.acc.heap();
        let scratch = self.vol.heap()
            + self.conc.heap()
            + self.qf.heap()
            + self.qs.heap()
            + self.bval.heap()
            + self.wvol.heap();
        let species: usize = self
            .species
            .iter()
            .zip(&self.plan.base_laws)
            .map(|(sp, base)| {
                let own_laws = if Arc::ptr_eq(&sp.laws, base) {
                    0
                } else {
                    sp.laws.heap()
                };
                own_laws
                    + sp.shear_cbrt.heap()
                    + sp.free.heap()
                    + sp.anchors.heap()
                    + sp.mixing_conc.heap()
            })
            .sum();
        sweep + scratch + species
    }
}
