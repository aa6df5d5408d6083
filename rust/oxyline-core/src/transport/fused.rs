//! The backward-Euler transport step of generalized-α on a tree in two passes over the domain
//! nodes in elimination order (`Plan::tree`), for walls whose rows need no shear: the same
//! upwind rows as `implicit_step`'s general path (docs/physics.md §2.5), built where they
//! are eliminated.
//!
//! * Forward (children before parents): the node's net inflow and new transport volume, its
//!   row (volume, wall, and the face terms its children and the boundaries left in the
//!   node's accumulators), and its elimination x_n = α_n + β_n x_parent.
//! * Backward (parents first): back-substitution, the new amounts N = W' x and the wall and
//!   decay fluxes.
//!
//! The per-node accumulators (net inflow, d, b) are packed in one entry, read and zeroed by
//! the forward pass, so each node's row costs one cache line and no pass clears them. Along a
//! vessel the parent is the next node eliminated (`Link::parent_is_next`, the chain order of
//! `tree_order`): there the terms pass in registers and the accumulator is not touched at
//! all. The sums at a junction (a node with several children) add in another order than the
//! general path's, so results agree with it to round-off.

use super::boundary_chunks::{self, BoundaryChunks};
use super::parallel::{SharedBackward, SharedForward, SharedMut, TreePartition};
#[allow(unused_imports)]
use super::*;

/// A cell's row with its wall linear in C_t, W = wl·C_t + wc (see `fixed_rows`): the laws'
/// (g, q − g c_w) of a wall without binding, or a binding's wall linearised about the old
/// state (`linearise_binding_wall`): d = W'(1/dt + λ) + wl, b = N/dt − wc.
struct LinearRows<'a> {
    wl: &'a [f64],
    wc: &'a [f64],
    rate: f64,
    inv_dt: f64,
}

impl LinearRows<'_> {
    /// d and b of cell `i` before the face terms, from its old amount `zi` and new
    /// transport volume `w`.
    #[inline(always)]
    fn row(&self, i: usize, zi: f64, w: f64) -> (f64, f64) {
        (w * self.rate + self.wl[i], zi * self.inv_dt - self.wc[i])
    }
}

/// The free concentration of node `n` at total `c` and dc/dC_t there.
pub(super) trait Inversion {
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64);
}

/// Hill's law: the node's anchored series (every Hill node has an anchor), the exact
/// inversion only when the series is out of its tolerance.
pub(super) struct Anchored<'a> {
    pub(super) binding: Binding,
    pub(super) free: &'a [f64],
    pub(super) anchors: &'a mut [HillAnchor],
}

impl Inversion for Anchored<'_> {
    #[inline(always)]
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64) {
        self.binding
            .free_and_inv_slope_anchored(c, self.free[n], &mut self.anchors[n])
    }
}

/// Any other binding (affine: closed form), by the exact inversion.
#[derive(Clone, Copy)]
pub(super) struct Exact<'a> {
    pub(super) binding: Binding,
    pub(super) free: &'a [f64],
}

impl Inversion for Exact<'_> {
    #[inline(always)]
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64) {
        let f = self.binding.free(c, self.free[n]);
        (f, 1.0 / self.binding.capacity_slope(f))
    }
}

/// What the linearisation of a binding's wall reads per cell: the cells `first..` (a chunk
/// of them on several threads, `parallel::linearise_chunks`).
#[derive(Clone, Copy)]
pub(super) struct Cells<'a> {
    pub(super) first: usize,
    pub(super) cells: &'a [u32],
    pub(super) zs: &'a [f64],
    pub(super) wvol: &'a [f64],
    pub(super) laws: &'a Laws,
}

impl Cells<'_> {
    /// Per cell: the old total concentration c = N/W, its free concentration and dc/dC_t by
    /// `inversion`, and the wall's linearisation (`Laws::linearised_uptake`) into `wlin`,
    /// `wconst`; returns Σ wconst.
    #[inline(always)]
    pub(super) fn linearise<I: Inversion>(
        self,
        mut inversion: I,
        wlin: &mut [f64],
        wconst: &mut [f64],
    ) -> f64 {
        let mut sum = 0.0;
        let rows = wlin.iter_mut().zip(wconst.iter_mut());
        for (i, ((&n, (&zi, &v)), (wl, wc))) in self
            .cells
            .iter()
            .zip(self.zs.iter().zip(self.wvol))
            .zip(rows)
            .enumerate()
        {
            let (n, c) = (n as usize, zi / v);
            let (f, inv_slope) = inversion.free_and_inv_slope(n, c);
            (*wl, *wc) = self.laws.linearised_uptake(self.first + i, f, inv_slope, c);
            sum += *wc;
        }
        sum
    }
}

/// Where the forward pass takes the flow of a tree face.
pub(super) trait FaceFlows {
    fn flow(&mut self, face: usize) -> f64;
}

/// The face flows as loaded (`Transport::qf`).
#[derive(Clone, Copy)]
pub(super) struct Loaded<'a>(pub(super) &'a [f64]);

impl FaceFlows for Loaded<'_> {
    #[inline(always)]
    fn flow(&mut self, face: usize) -> f64 {
        self.0[face]
    }
}

/// The α_f-level flow Q = Q_0 + α_f (Q_1 − Q_0) of a face from the step's end state `y1` and
/// its start flow carried in `q0`, which becomes the end flow (the gather of
/// `Transport::implicit_step_carried`, done where the forward pass reads the face, so that
/// no pass writes the tree faces' flows and another reads them back).
///
/// The start flows are shared by the threads of a parallel forward pass: each tree face is
/// the face of one node to its parent, read and written only where that node is eliminated.
#[derive(Clone, Copy)]
struct Carried<'a> {
    y1: &'a [f64],
    unknowns: &'a [u32],
    q0: SharedMut<'a, f64>,
    alpha_f: f64,
}

impl FaceFlows for Carried<'_> {
    #[inline(always)]
    fn flow(&mut self, face: usize) -> f64 {
        let q1 = self.y1[self.unknowns[face] as usize];
        // SAFETY: only the node whose link to its parent is `face` reads and writes it (see
        // above); `SharedMut` checks the index
        let q0 = unsafe { self.q0.replace(face, q1) };
        q0 + self.alpha_f * (q1 - q0)
    }
}

/// What a node leaves in its parent's row: the net-inflow, d and b terms, and whether the
/// node is upwind of its parent (its term goes into b, else its outflow into d).
#[derive(Clone, Copy)]
pub(super) struct ParentTerms {
    pub(super) terms: [f64; 3],
    to_parent: bool,
}

impl ParentTerms {
    /// Into the parent's accumulator (a[0] + (−q_in) is the same number as a[0] − q_in).
    #[inline(always)]
    pub(super) fn add_to(&self, a: &mut [f64; 3]) {
        a[0] += self.terms[0];
        if self.to_parent {
            a[2] += self.terms[2];
        } else {
            a[1] += self.terms[1];
        }
    }
}

/// The per-node arrays the forward pass writes: slices on one thread, the shared arrays of
/// the blocks on several (`parallel::SharedForward`).
pub(super) trait ForwardArrays {
    /// Node `n`'s accumulator, zeroed.
    fn take_acc(&mut self, n: usize) -> [f64; 3];
    fn add_to_acc(&mut self, n: usize, t: &ParentTerms);
    fn set_beta(&mut self, k: usize, v: f64);
    fn x(&self, n: usize) -> f64;
    fn set_x(&mut self, n: usize, v: f64);
    fn wnew(&self, cell: usize) -> f64;
    fn set_wnew(&mut self, cell: usize, v: f64);
}

/// The slices the forward pass reads and writes (split from `Transport` so that the row
/// builder can borrow the species state at the same time).
struct Forward<'a> {
    tree: &'a [Link],
    acc: &'a mut [[f64; 3]],
    beta: &'a mut [f64],
    x: &'a mut [f64],
    wvol: &'a [f64],
    wnew: &'a mut [f64],
    zs: &'a [f64],
    dt: f64,
}

/// The forward pass's arrays as slices (one thread).
struct ForwardSlices<'a> {
    acc: &'a mut [[f64; 3]],
    beta: &'a mut [f64],
    x: &'a mut [f64],
    wnew: &'a mut [f64],
}

impl ForwardArrays for ForwardSlices<'_> {
    #[inline(always)]
    fn take_acc(&mut self, n: usize) -> [f64; 3] {
        std::mem::take(&mut self.acc[n])
    }
    #[inline(always)]
    fn add_to_acc(&mut self, n: usize, t: &ParentTerms) {
        t.add_to(&mut self.acc[n]);
    }
    #[inline(always)]
    fn set_beta(&mut self, k: usize, v: f64) {
        self.beta[k] = v;
    }
    #[inline(always)]
    fn x(&self, n: usize) -> f64 {
        self.x[n]
    }
    #[inline(always)]
    fn set_x(&mut self, n: usize, v: f64) {
        self.x[n] = v;
    }
    #[inline(always)]
    fn wnew(&self, cell: usize) -> f64 {
        self.wnew[cell]
    }
    #[inline(always)]
    fn set_wnew(&mut self, cell: usize, v: f64) {
        self.wnew[cell] = v;
    }
}

/// One node's elimination in the forward pass (see the module doc), the same on one thread
/// and on several.
pub(super) struct NodeRows<'r, 'a> {
    rows: &'r LinearRows<'a>,
    wvol: &'a [f64],
    zs: &'a [f64],
    dt: f64,
    /// Species 0: the new volumes W' = W + dt·(net inflow) into `wnew` (else read from it).
    first: bool,
}

impl NodeRows<'_, '_> {
    /// Eliminate the node at position `k` (link `l`), with the terms its previous sibling in
    /// the chain handed over in `carried`; the terms it leaves in its parent's row (None for
    /// a root). `positive` turns false at a new volume that is not.
    #[inline(always)]
    pub(super) fn eliminate<A: ForwardArrays, F: FaceFlows>(
        &self,
        a: &mut A,
        flows: &mut F,
        (k, l): (usize, &Link),
        carried: [f64; 3],
        positive: &mut bool,
    ) -> Option<ParentTerms> {
        let n = l.node as usize;
        // (a + carried: the same sums, in the same order, as the terms added to `acc`)
        let [mut net, acc_d, acc_b] = if l.reads_acc() {
            let s = a.take_acc(n);
            [s[0] + carried[0], s[1] + carried[1], s[2] + carried[2]]
        } else {
            carried
        };
        let (mut q_in, mut aq, mut to_parent) = (0.0, 0.0, false);
        let has_parent = l.parent != u32::MAX;
        if has_parent {
            let q = flows.flow(l.face() as usize);
            // inflow into n through the face to the parent
            q_in = if l.face_from_child() { -q } else { q };
            net += q_in;
            aq = q.abs();
            to_parent = (q >= 0.0) == l.face_from_child();
        }
        let (mut d, b);
        let cell = l.cell as usize;
        if l.cell != u32::MAX {
            let w = if self.first {
                let w = self.wvol[cell] + self.dt * net;
                // (NaN fails the test too)
                *positive &= w > 0.0;
                a.set_wnew(cell, w);
                w
            } else {
                a.wnew(cell)
            };
            let (d0, b0) = self.rows.row(cell, self.zs[cell], w);
            (d, b) = (d0 + acc_d, b0 + acc_b);
        } else {
            // a mixing point: no storage
            (d, b) = (acc_d, acc_b);
        }
        if to_parent {
            d += aq;
        }
        // one division per node (the divider, not the memory, bounds this loop): x and β
        // use 1/d; without outflow or storage the node keeps its old value (a mixing
        // point its restored lagged value)
        let (xn, inv_d) = if d > 1e-300 {
            let inv_d = 1.0 / d;
            (b * inv_d, inv_d)
        } else if l.cell != u32::MAX {
            (self.zs[cell] / self.wvol[cell], 0.0)
        } else {
            (a.x(n), 0.0)
        };
        a.set_x(n, xn);
        a.set_beta(k, if to_parent { 0.0 } else { aq * inv_d });
        // the parent's row: net inflow, and the outflow into d (parent upwind) or the inflow
        // into b (n upwind)
        has_parent.then(|| ParentTerms {
            terms: if to_parent {
                [-q_in, 0.0, aq * xn]
            } else {
                [-q_in, aq, 0.0]
            },
            to_parent,
        })
    }
}

/// One step of a forward pass, by position in elimination order.
#[derive(Clone, Copy)]
pub(super) enum Step {
    /// Eliminate the node at this position.
    Eliminate(usize),
    /// The node at this position was eliminated elsewhere (a block's root, on the block's
    /// thread) and left these terms for its parent's row.
    Eliminated(usize, Option<ParentTerms>),
}

impl NodeRows<'_, '_> {
    /// The forward elimination of the nodes of `steps` (in elimination order: the whole tree,
    /// a block, or the top tree with the blocks' roots), the one loop of the serial pass and
    /// of the partition's (`parallel`). Each node's terms go to its parent's row: in
    /// registers when the parent is the next position (`Link::parent_is_next`), else into
    /// the parent's accumulator; the last node's are returned instead (a block root's, for
    /// the serial phase; None at a root of the tree).
    #[inline(always)]
    pub(super) fn eliminate_run<A: ForwardArrays, F: FaceFlows>(
        &self,
        a: &mut A,
        flows: &mut F,
        tree: &[Link],
        steps: impl Iterator<Item = Step>,
        positive: &mut bool,
    ) -> Option<ParentTerms> {
        let mut carry = [0.0; 3];
        // the previous node's terms and link, handed on before the next node is eliminated
        let mut pending: Option<(ParentTerms, &Link)> = None;
        for step in steps {
            if let Some((t, l)) = pending.take() {
                if l.parent_is_next() {
                    carry = t.terms;
                } else {
                    a.add_to_acc(l.parent as usize, &t);
                }
            }
            let (k, terms) = match step {
                Step::Eliminate(k) => {
                    let carried = std::mem::take(&mut carry);
                    let terms = self.eliminate(a, flows, (k, &tree[k]), carried, positive);
                    (k, terms)
                }
                Step::Eliminated(k, terms) => (k, terms),
            };
            pending = terms.map(|t| (t, &tree[k]));
        }
        pending.map(|(t, _)| t)
    }
}

impl Forward<'_> {
    /// The forward pass (see the module doc); with `first` the new volumes W' = W + dt·(net
    /// inflow) into `wnew` (else read from it). Returns whether every new volume is positive.
    /// With a partition of the tree and the run's threads, its blocks in parallel
    /// (`parallel`: the same operations on every value, so the same bits).
    fn run<F: FaceFlows + Clone + Send + Sync>(
        self,
        rows: &LinearRows,
        flows: &mut F,
        first: bool,
        part: Option<&TreePartition>,
    ) -> bool {
        let Forward {
            tree,
            acc,
            beta,
            x,
            wvol,
            wnew,
            zs,
            dt,
        } = self;
        let node = NodeRows {
            rows,
            wvol,
            zs,
            dt,
            first,
        };
        if let Some((part, pool)) = part.and_then(|p| p.pool().map(|pool| (p, pool))) {
            let shared = SharedForward::new(acc, beta, x, wnew);
            return pool.install(|| part.forward(tree, &node, shared, flows));
        }
        let mut a = ForwardSlices { acc, beta, x, wnew };
        let mut positive = true;
        let steps = (0..tree.len()).map(Step::Eliminate);
        // (the last position is a root: no terms are left over)
        let left = node.eliminate_run(&mut a, flows, tree, steps, &mut positive);
        debug_assert!(left.is_none());
        positive
    }
}

/// What the row builder of one species borrows (split from `Transport` beside `Forward`).
struct RowState<'a> {
    set: &'a SpeciesPlan,
    laws: &'a Laws,
    /// A binding's wall linearised per cell (`linearise_binding_wall`), or None: the laws'.
    linearised: Option<(&'a [f64], &'a [f64])>,
    nc: usize,
    dt: f64,
}

impl RowState<'_> {
    /// The forward pass with this species' rows: W = wl·C_t + wc with (wl, wc) the laws'
    /// (g, q − g c_w) of a wall linear in C_t, or a binding's linearisation.
    fn forward<F: FaceFlows + Clone + Send + Sync>(
        self,
        fwd: Forward,
        flows: &mut F,
        first: bool,
        part: Option<&TreePartition>,
    ) -> bool {
        let RowState {
            set,
            laws,
            linearised,
            nc,
            dt,
        } = self;
        let inv_dt = 1.0 / dt;
        let (wl, wc) = linearised.unwrap_or((&laws.cell_g[..nc], &laws.cell_wc[..nc]));
        let rows = LinearRows {
            wl,
            wc,
            rate: inv_dt + set.decay,
            inv_dt,
        };
        fwd.run(&rows, flows, first, part)
    }
}

/// The per-node arrays the backward pass writes: slices on one thread, shared on several.
pub(super) trait BackwardArrays {
    fn x(&self, n: usize) -> f64;
    fn set_x(&mut self, n: usize, v: f64);
    fn set_z(&mut self, cell: usize, v: f64);
}

struct BackwardSlices<'a> {
    x: &'a mut [f64],
    zs: &'a mut [f64],
}

impl BackwardArrays for BackwardSlices<'_> {
    #[inline(always)]
    fn x(&self, n: usize) -> f64 {
        self.x[n]
    }
    #[inline(always)]
    fn set_x(&mut self, n: usize, v: f64) {
        self.x[n] = v;
    }
    #[inline(always)]
    fn set_z(&mut self, cell: usize, v: f64) {
        self.zs[cell] = v;
    }
}

/// One node's back-substitution (see `Backward`), the same on one thread and on several.
pub(super) struct NodeBack<'a> {
    beta: &'a [f64],
    wnew: &'a [f64],
    wl: &'a [f64],
    wc: Option<&'a [f64]>,
    lambda: f64,
}

impl NodeBack<'_> {
    /// Back-substitute the node at position `k` after its parent; its wall and decay fluxes
    /// (0 for a mixing point) added to `sums`.
    #[inline(always)]
    pub(super) fn substitute<A: BackwardArrays>(
        &self,
        a: &mut A,
        (k, l): (usize, &Link),
        sums: &mut (f64, f64),
    ) {
        let n = l.node as usize;
        let beta = self.beta[k];
        let mut xn = a.x(n);
        if beta != 0.0 {
            xn += beta * a.x(l.parent as usize);
            a.set_x(n, xn);
        }
        if l.cell != u32::MAX {
            let i = l.cell as usize;
            let w = self.wnew[i];
            sums.0 += match self.wc {
                Some(wc) => self.wl[i] * xn + wc[i],
                None => self.wl[i] * xn,
            };
            sums.1 += self.lambda * w * xn;
            a.set_z(i, w * xn);
        }
    }
}

/// The slices the backward pass reads and writes.
struct Backward<'a> {
    tree: &'a [Link],
    beta: &'a [f64],
    x: &'a mut [f64],
    wnew: &'a [f64],
    zs: &'a mut [f64],
    lambda: f64,
}

impl Backward<'_> {
    /// Back-substitution parents first and N = W' x; returns the wall flux Σ (wl x + wc)
    /// (wc per cell, or left to the caller: `None`) and the decay flux Σ λ W' x. With a
    /// partition, the sums are taken block by block in the partition's order, whether on
    /// one thread or several (`parallel`).
    #[inline(always)]
    fn run(self, wl: &[f64], wc: Option<&[f64]>, part: Option<&TreePartition>) -> (f64, f64) {
        let Backward {
            tree,
            beta,
            x,
            wnew,
            zs,
            lambda,
        } = self;
        let node = NodeBack {
            beta,
            wnew,
            wl,
            wc,
            lambda,
        };
        if let Some(part) = part {
            let shared = SharedBackward::new(x, zs);
            return match part.pool() {
                Some(pool) => pool.install(|| part.backward(tree, &node, shared)),
                None => part.backward(tree, &node, shared),
            };
        }
        let mut a = BackwardSlices { x, zs };
        let mut sums = (0.0, 0.0);
        for (k, l) in tree.iter().enumerate().rev() {
            node.substitute(&mut a, (k, l), &mut sums);
        }
        sums
    }
}

/// The α_f-level face flows of a fused step.
#[derive(Clone, Copy)]
pub(super) enum StepFlows<'a> {
    /// Loaded into `Transport::qf`.
    Loaded,
    /// The boundary faces' flows loaded, the tree faces' computed by the forward pass from
    /// the step's end state (`Carried`; see `Transport::gathers_in_forward`).
    Carried { y1: &'a [f64], alpha_f: f64 },
}

impl Transport {
    /// Whether `implicit_step_carried` leaves the tree faces' flows to the fused forward
    /// pass: one species (its forward pass reads each face once), no refined cells (their
    /// interior faces' flows are derived from the loaded ones), and every face a flow face
    /// either in the tree or at a boundary (so each start flow is carried exactly once).
    pub(super) fn gathers_in_forward(&self) -> bool {
        let p = &*self.plan;
        self.species.len() == 1
            && p.chains.is_empty()
            && p.faces.len() == p.n_flow_faces
            && p.n_internal + p.boundary_links.len() == p.n_flow_faces
            && self.fused_applies()
    }

    /// Whether `implicit_step` takes the fused tree step: a forest, the conservative
    /// formulation, no species whose wall follows the shear, and no tissue wall (its columns
    /// are eliminated in the row-by-row sweep, `tissue_rows`).
    pub(super) fn fused_applies(&self) -> bool {
        self.plan.tree.is_some()
            && self.plan.formulation == Formulation::Conservative
            && self.plan.tissue.is_empty()
            && (0..self.species.len()).all(|s| self.species[s].laws.dynamic.is_empty())
    }

    /// The implicit step of every species by the fused tree passes (see the module doc), the
    /// face flows being loaded.
    pub(super) fn fused_tree_step(
        &mut self,
        t_af: f64,
        dt: f64,
        z: &mut [f64],
        flows: StepFlows,
    ) -> Result<()> {
        let (nn, nc) = (self.plan.kind.len(), self.plan.cells.len());
        let ntree = self.plan.tree.as_ref().map_or(0, |t| t.len());
        let sw = &mut self.sweep;
        if sw.acc.len() != nn {
            sw.acc = vec![[0.0; 3]; nn];
            // large trees: the blocks of the passes on the run's threads (`parallel`)
            sw.partition = self
                .plan
                .tree
                .as_deref()
                .and_then(|t| TreePartition::of(t, nn));
            // and the boundary faces' chunks (`boundary_chunks`)
            let p = &*self.plan;
            sw.boundary = BoundaryChunks::of(&p.boundary_links, nn, &p.boundary_inlet);
        }
        sw.beta.resize(ntree, 0.0);
        sw.wnew.resize(nc, 0.0);
        if self.species.iter().any(|sp| !sp.free.is_empty()) {
            sw.wlin.resize(nc, 0.0);
            sw.wconst.resize(nc, 0.0);
        }
        for s in 0..self.species.len() {
            self.load_boundary(s, t_af);
            self.restore_mixing(s);
            self.fused_boundary_terms(s, z);
            if !self.fixed_rows_of(s) {
                self.linearise_binding_wall(s, z);
            }
            if !self.fused_forward(s, dt, z, flows) {
                return Err(self.volume_error(t_af));
            }
            self.fused_backward(s, dt, z);
            self.save_mixing(s);
        }
        std::mem::swap(&mut self.wvol, &mut self.sweep.wnew);
        Ok(())
    }

    /// The boundary faces' and sources' terms of species `s` into the accumulators of the
    /// nodes they touch (outflow into d, inflow — prescribed, or the node's old value,
    /// recorded in `lag` — into b), and their flows into the net inflow.
    fn fused_boundary_terms(&mut self, s: usize, z: &[f64]) {
        let nc = self.plan.cells.len();
        let zs = &z[s * nc..(s + 1) * nc];
        let plan = &*self.plan;
        let (sw, conc, wvol) = (&mut self.sweep, &self.conc, &self.wvol);
        let old = |n: usize| match plan.node_cell[n] {
            u32::MAX => conc[n],
            i => zs[i as usize] / wvol[i as usize],
        };
        if let Some((chunks, pool)) = boundary_chunks::split(sw.boundary.as_ref()) {
            let links = &plan.boundary_links[..];
            let flows = (&self.qf[..], &self.bval[..]);
            chunks.terms(&pool, links, flows, old, &mut sw.acc, &mut sw.lag);
        } else {
            for b in &plan.boundary_links {
                let (n, q) = (b.node as usize, self.qf[b.face as usize]);
                let acc = &mut sw.acc[n];
                acc[0] += b.inflow(q);
                if b.boundary_upwind(q) {
                    sw.lag[n] = old(n);
                    acc[2] += q.abs() * inflow_value(self.bval[b.boundary as usize], sw.lag[n]);
                } else {
                    acc[1] += q.abs();
                }
            }
        }
        for (&(n, _, bb), &q) in plan.sources.iter().zip(&self.qs) {
            sw.acc[n][0] += q;
            if q >= 0.0 {
                sw.lag[n] = old(n);
                sw.acc[n][2] += q * inflow_value(self.bval[bb], sw.lag[n]);
            } else {
                sw.acc[n][1] -= q;
            }
        }
    }

    /// The wall of binding species `s` (a wall with fixed laws, see `fixed_rows_of`)
    /// linearised in C_t about the old state, cell by cell, into `sweep.wlin` and
    /// `sweep.wconst`, and Σ wconst into `sweep.wc_sum` (the backward pass adds it to
    /// Σ wl x). A pass of its own before the forward pass: the cells are independent here,
    /// so their inversions (a division, the series, its slope) overlap, where inside the
    /// forward pass each cell's chain of two divisions and the series stalled the
    /// elimination.
    fn linearise_binding_wall(&mut self, s: usize, z: &[f64]) {
        let nc = self.plan.cells.len();
        let binding = self.plan.species[s].binding;
        let sp = &mut self.species[s];
        let cells = Cells {
            first: 0,
            cells: &self.plan.cells,
            zs: &z[s * nc..(s + 1) * nc],
            wvol: &self.wvol[..nc],
            laws: &sp.laws,
        };
        let sw = &mut self.sweep;
        let (wlin, wconst) = (&mut sw.wlin[..nc], &mut sw.wconst[..nc]);
        if let Some(part) = sw.partition.as_deref() {
            // in fixed chunks of cells, Σ wconst chunk by chunk (the same bits on any
            // number of threads)
            sw.wc_sum =
                part.linearise_chunks(cells, binding, &sp.free, &mut sp.anchors, wlin, wconst);
            return;
        }
        sw.wc_sum = if matches!(binding, Binding::Hill { .. }) {
            let inversion = Anchored {
                binding,
                free: &sp.free,
                anchors: &mut sp.anchors,
            };
            cells.linearise(inversion, wlin, wconst)
        } else {
            let inversion = Exact {
                binding,
                free: &sp.free,
            };
            cells.linearise(inversion, wlin, wconst)
        };
    }

    /// The forward pass of species `s` with its row builder and face flows; false if a new
    /// volume is not positive (species 0 computes the volumes).
    fn fused_forward(&mut self, s: usize, dt: f64, z: &[f64], flows: StepFlows) -> bool {
        let nc = self.plan.cells.len();
        let plan = &*self.plan;
        let Some(tree) = plan.tree.as_deref() else {
            return true;
        };
        let fixed = self.fixed_rows_of(s);
        let sw = &mut self.sweep;
        let part = sw.partition.as_deref();
        let fwd = Forward {
            tree,
            acc: &mut sw.acc,
            beta: &mut sw.beta,
            x: &mut self.conc,
            wvol: &self.wvol,
            wnew: &mut sw.wnew,
            zs: &z[s * nc..(s + 1) * nc],
            dt,
        };
        let laws = &*self.species[s].laws;
        let rows = RowState {
            set: &plan.species[s],
            laws,
            // (lazily: without a binding the scratch arrays are empty)
            linearised: (!fixed).then(|| (&sw.wlin[..nc], &sw.wconst[..nc])),
            nc,
            dt,
        };
        match flows {
            StepFlows::Loaded => rows.forward(fwd, &mut Loaded(&self.qf), s == 0, part),
            StepFlows::Carried { y1, alpha_f } => {
                let mut carried = Carried {
                    y1,
                    unknowns: &plan.face_unknowns,
                    q0: SharedMut::new(&mut sw.q_start),
                    alpha_f,
                };
                rows.forward(fwd, &mut carried, s == 0, part)
            }
        }
    }

    /// The backward pass of species `s`: back-substitution parents first, the new amounts
    /// N = W' x, and the step's boundary, wall (W = wl·x + wc, as in the rows) and decay
    /// fluxes into the accumulators of the state.
    fn fused_backward(&mut self, s: usize, dt: f64, z: &mut [f64]) {
        let (nc, nsp) = (self.plan.cells.len(), self.species.len());
        let plan = &*self.plan;
        let Some(tree) = plan.tree.as_deref() else {
            return;
        };
        let laws = &*self.species[s].laws;
        let fixed = self.fixed_rows_of(s);
        let sw = &self.sweep;
        let part = sw.partition.as_deref();
        let pass = Backward {
            tree,
            beta: &sw.beta,
            x: &mut self.conc[..],
            wnew: &sw.wnew[..nc],
            zs: &mut z[s * nc..(s + 1) * nc],
            lambda: plan.species[s].decay,
        };
        // fixed rows: the per-cell wc of the laws; a binding: wc summed by the forward pass
        let (i_wall, i_decay) = if fixed {
            pass.run(&laws.cell_g[..nc], Some(&laws.cell_wc[..nc]), part)
        } else {
            let (i_wall, i_decay) = pass.run(&sw.wlin[..nc], None, part);
            (i_wall + sw.wc_sum, i_decay)
        };
        let (i_in, i_out) = self.step_boundary_fluxes();
        let acc = &mut z[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
        for (a, v) in acc.iter_mut().zip([i_in, i_out, i_wall, i_decay]) {
            *a += dt * v;
        }
    }

    /// Species `s` has rows with a wall linear in C_t (no binding, or no wall).
    fn fixed_rows_of(&self, s: usize) -> bool {
        self.plan.species[s].binding.is_identity() || !self.species[s].laws.has_wall
    }
}
