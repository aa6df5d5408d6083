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
trait Inversion {
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64);
}

/// Hill's law: the node's anchored series (every Hill node has an anchor), the exact
/// inversion only when the series is out of its tolerance.
struct Anchored<'a> {
    binding: Binding,
    free: &'a [f64],
    anchors: &'a mut [HillAnchor],
}

impl Inversion for Anchored<'_> {
    #[inline(always)]
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64) {
        self.binding
            .free_and_inv_slope_anchored(c, self.free[n], &mut self.anchors[n])
    }
}

/// Any other binding (affine: closed form), by the exact inversion.
struct Exact<'a> {
    binding: Binding,
    free: &'a [f64],
}

impl Inversion for Exact<'_> {
    #[inline(always)]
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64) {
        let f = self.binding.free(c, self.free[n]);
        (f, 1.0 / self.binding.capacity_slope(f))
    }
}

/// What the linearisation of a binding's wall reads per cell.
struct Cells<'a> {
    cells: &'a [usize],
    zs: &'a [f64],
    wvol: &'a [f64],
    laws: &'a Laws,
}

impl Cells<'_> {
    /// Per cell: the old total concentration c = N/W, its free concentration and dc/dC_t by
    /// `inversion`, and the wall's linearisation (`Laws::linearised_uptake`) into `wlin`,
    /// `wconst`; returns Σ wconst.
    #[inline(always)]
    fn linearise<I: Inversion>(
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
            let c = zi / v;
            let (f, inv_slope) = inversion.free_and_inv_slope(n, c);
            (*wl, *wc) = self.laws.linearised_uptake(i, f, inv_slope, c);
            sum += *wc;
        }
        sum
    }
}

/// Where the forward pass takes the flow of a tree face.
trait FaceFlows {
    fn flow(&mut self, face: usize) -> f64;
}

/// The face flows as loaded (`Transport::qf`).
struct Loaded<'a>(&'a [f64]);

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
struct Carried<'a> {
    y1: &'a [f64],
    unknowns: &'a [u32],
    q0: &'a mut [f64],
    alpha_f: f64,
}

impl FaceFlows for Carried<'_> {
    #[inline(always)]
    fn flow(&mut self, face: usize) -> f64 {
        let (q0, q1) = (self.q0[face], self.y1[self.unknowns[face] as usize]);
        self.q0[face] = q1;
        q0 + self.alpha_f * (q1 - q0)
    }
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

impl Forward<'_> {
    /// The forward pass (see the module doc); with `first` the new volumes W' = W + dt·(net
    /// inflow) into `wnew` (else read from it). Returns whether every new volume is positive.
    fn run<F: FaceFlows>(self, rows: &LinearRows, flows: &mut F, first: bool) -> bool {
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
        // (NaN fails the test too)
        let mut positive = true;
        // the terms a node leaves in the row of its parent when that parent is eliminated
        // next (`Link::parent_is_next`): in registers, not in the parent's accumulator
        let mut carry = [0.0; 3];
        for (l, beta) in tree.iter().zip(beta.iter_mut()) {
            let n = l.node as usize;
            let carried = std::mem::take(&mut carry);
            // (a + carried: the same sums, in the same order, as the terms added to `acc`)
            let [mut net, acc_d, acc_b] = if l.reads_acc() {
                let a = std::mem::take(&mut acc[n]);
                [a[0] + carried[0], a[1] + carried[1], a[2] + carried[2]]
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
                let w = if first {
                    let w = wvol[cell] + dt * net;
                    positive &= w > 0.0;
                    wnew[cell] = w;
                    w
                } else {
                    wnew[cell]
                };
                let (d0, b0) = rows.row(cell, zs[cell], w);
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
                (zs[cell] / wvol[cell], 0.0)
            } else {
                (x[n], 0.0)
            };
            x[n] = xn;
            *beta = if to_parent { 0.0 } else { aq * inv_d };
            if has_parent {
                // the parent's row: net inflow, and the outflow into d (parent upwind) or
                // the inflow into b (n upwind)
                let terms = if to_parent {
                    [-q_in, 0.0, aq * xn]
                } else {
                    [-q_in, aq, 0.0]
                };
                if l.parent_is_next() {
                    carry = terms;
                } else {
                    let a = &mut acc[l.parent as usize];
                    a[0] -= q_in;
                    if to_parent {
                        a[2] += terms[2];
                    } else {
                        a[1] += aq;
                    }
                }
            }
        }
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
    fn forward<F: FaceFlows>(self, fwd: Forward, flows: &mut F, first: bool) -> bool {
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
        fwd.run(&rows, flows, first)
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
    /// (wc per cell, or left to the caller: `None`) and the decay flux Σ λ W' x.
    #[inline(always)]
    fn run(self, wl: &[f64], wc: Option<&[f64]>) -> (f64, f64) {
        let Backward {
            tree,
            beta,
            x,
            wnew,
            zs,
            lambda,
        } = self;
        let (mut i_wall, mut i_decay) = (0.0, 0.0);
        for (l, &beta) in tree.iter().zip(beta).rev() {
            let n = l.node as usize;
            let mut xn = x[n];
            if beta != 0.0 {
                xn += beta * x[l.parent as usize];
                x[n] = xn;
            }
            if l.cell != u32::MAX {
                let i = l.cell as usize;
                let w = wnew[i];
                i_wall += match wc {
                    Some(wc) => wl[i] * xn + wc[i],
                    None => wl[i] * xn,
                };
                i_decay += lambda * w * xn;
                zs[i] = w * xn;
            }
        }
        (i_wall, i_decay)
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
            && p.internal.len() + p.boundary_links.len() == p.n_flow_faces
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
            usize::MAX => conc[n],
            i => zs[i] / wvol[i],
        };
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
            cells: &self.plan.cells,
            zs: &z[s * nc..(s + 1) * nc],
            wvol: &self.wvol[..nc],
            laws: &sp.laws,
        };
        let sw = &mut self.sweep;
        let (wlin, wconst) = (&mut sw.wlin[..nc], &mut sw.wconst[..nc]);
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
            StepFlows::Loaded => rows.forward(fwd, &mut Loaded(&self.qf), s == 0),
            StepFlows::Carried { y1, alpha_f } => {
                let mut carried = Carried {
                    y1,
                    unknowns: &plan.face_unknowns,
                    q0: &mut sw.q_start,
                    alpha_f,
                };
                rows.forward(fwd, &mut carried, s == 0)
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
            pass.run(&laws.cell_g[..nc], Some(&laws.cell_wc[..nc]))
        } else {
            let (i_wall, i_decay) = pass.run(&sw.wlin[..nc], None);
            (i_wall + sw.wc_sum, i_decay)
        };
        let (i_in, i_out) = self.implicit_boundary_fluxes();
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
