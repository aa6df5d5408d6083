//! Backward-Euler transport step after each generalized-α flow step: tree elimination or
//! flow-order sweep.

#[allow(unused_imports)]
use super::*;

impl Transport {
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
    pub(super) fn transport_volumes(&mut self, t_af: f64, dt: f64) -> Result<()> {
        let mut net = std::mem::take(&mut self.sweep.dnode);
        net.clear();
        net.resize(self.plan.kind.len(), 0.0);
        let qf = &self.qf[..];
        for &[fi, a, b] in &self.plan.internal {
            let q = qf[fi as usize];
            net[a as usize] -= q;
            net[b as usize] += q;
        }
        for &fi in &self.plan.boundary_faces {
            let (f, q) = (&self.plan.faces[fi], self.qf[fi]);
            if let End::Node(n) = f.from {
                net[n] -= q;
            }
            if let End::Node(n) = f.to {
                net[n] += q;
            }
        }
        for ((n, _, _), &q) in self.plan.sources.iter().zip(&self.qs) {
            net[*n] += q;
        }
        let mut w_new = std::mem::take(&mut self.sweep.wnew);
        w_new.clear();
        w_new.extend(
            self.plan
                .cells
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
                    self.node_name(self.plan.cells[i]),
                    self.sweep.wnew[i]
                ),
            )),
        }
    }

    /// The backward-Euler solve of every species over the step (see `implicit_step`), with the
    /// face flows and new volumes loaded; `ya` is the α_f-level state (for shear-dependent walls).
    pub(super) fn implicit_species(
        &mut self,
        t_af: f64,
        dt: f64,
        ya: &[f64],
        z: &mut [f64],
    ) -> Result<()> {
        let nc = self.plan.cells.len();
        let nsp = self.species.len();
        let (mut wconst, mut wlin) = (
            std::mem::take(&mut self.sweep.wconst),
            std::mem::take(&mut self.sweep.wlin),
        );
        wconst.resize(nc, 0.0);
        wlin.resize(nc, 0.0);
        let w_new = std::mem::take(&mut self.sweep.wnew);
        let quasi = self.plan.formulation == Formulation::TlQuasisteady;
        let mut res = Ok(());
        for s in 0..nsp {
            self.load_boundary(s, t_af);
            let lambda = self.species[s].decay;
            self.relax_shears(s, dt, ya, z);
            self.restore_mixing(s);
            let sp = &self.species[s];
            let (sw, zs) = (&mut self.sweep, &z[s * nc..(s + 1) * nc]);
            for &m in &self.plan.mixing {
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
                for (i, &n) in self.plan.cells.iter().enumerate() {
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
            if self.plan.tree.is_some() {
                self.tree_solve(&mut x);
            } else {
                // the plan is shared, so hold it by its own handle while `self` is mutated
                let plan = Arc::clone(&self.plan);
                let (d, b) = (self.sweep.den.clone(), self.sweep.num.clone());
                res = self.sweep_solve(&plan.domain, &d, &b, &mut x);
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
            for (i, &n) in self.plan.cells.iter().enumerate() {
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
    pub(super) fn implicit_rows(
        &mut self,
        s: usize,
        dt: f64,
        ya: &[f64],
        z: &[f64],
        w_new: &[f64],
        wconst: &mut [f64],
        wlin: &mut [f64],
    ) {
        let nc = self.plan.cells.len();
        let zs = &z[s * nc..(s + 1) * nc];
        for (i, &n) in self.plan.cells.iter().enumerate() {
            self.conc[n] = zs[i] / self.wvol[i];
        }
        self.load_shear(s, ya, z);
        self.linearised_wall(s, wconst, wlin);
        let quasi = self.plan.formulation == Formulation::TlQuasisteady;
        let rate = 1.0 / dt + self.species[s].decay;
        let sw = &mut self.sweep;
        for (i, &n) in self.plan.cells.iter().enumerate() {
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
    pub(super) fn relax_shears(&self, s: usize, dt: f64, ya: &[f64], z: &mut [f64]) {
        let sp = &self.species[s];
        for (k, &(j, tau)) in sp.relax.iter().enumerate() {
            let q = ya[self.plan.segments[j].branch_unknown].abs();
            let v = &mut z[sp.relax_offset + k];
            *v = q + (*v - q) * (-dt / tau).exp();
        }
    }

    /// Wall uptake of species `s` linearised about the current state: W = wlin·C_t + wconst
    /// per cell (exact for linear binding); zero without a wall.
    pub(super) fn linearised_wall(&mut self, s: usize, wconst: &mut [f64], wlin: &mut [f64]) {
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
        inv_slope.resize(self.plan.cells.len(), 1.0);
        if !sp.binding.is_identity() {
            for (&n, v) in self.plan.cells.iter().zip(inv_slope.iter_mut()) {
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
            let pc = &self.plan.pieces[p];
            let (gj, _, _) = sp.laws[p].eval_cbrt(sp.shear_cbrt[pc.seg]);
            wlin[pc.cell] += pc.share * gj;
        }
        if !sp.binding.is_identity() {
            wlin.iter_mut().zip(&inv_slope).for_each(|(w, v)| *w *= v);
        }
        self.sweep.inv_slope = inv_slope;
        for (i, &n) in self.plan.cells.iter().enumerate() {
            wconst[i] -= wlin[i] * self.conc[n];
        }
    }

    /// Boundary inflow (I_in) and outflow (I_out) rates of the solved implicit field: the same
    /// fluxes that entered the solve.
    pub(super) fn implicit_boundary_fluxes(&self) -> (f64, f64) {
        let (mut i_in, mut i_out) = (0.0, 0.0);
        for &fi in &self.plan.boundary_faces {
            let (f, q) = (&self.plan.faces[fi], self.qf[fi]);
            let (from_b, to_b) = (f.from, f.to);
            if let End::Boundary(bb) = from_b {
                let c = if q >= 0.0 {
                    self.lagged_boundary(bb, to_b)
                } else {
                    self.end_conc(to_b)
                };
                account(self.plan.boundary_inlet[bb], q * c, &mut i_in, &mut i_out);
            }
            if let End::Boundary(bb) = to_b {
                let c = if q < 0.0 {
                    self.lagged_boundary(bb, from_b)
                } else {
                    self.end_conc(from_b)
                };
                account(self.plan.boundary_inlet[bb], -q * c, &mut i_in, &mut i_out);
            }
        }
        for ((n, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
            let c = if q >= 0.0 {
                self.lagged_boundary(*bb, End::Node(*n))
            } else {
                self.conc[*n]
            };
            account(self.plan.boundary_inlet[*bb], q * c, &mut i_in, &mut i_out);
        }
        (i_in, i_out)
    }

    #[inline]
    pub(super) fn end_conc(&self, e: End) -> f64 {
        match e {
            End::Node(n) => self.conc[n],
            End::Boundary(_) => 0.0,
        }
    }

    /// Inflow value of a boundary in the implicit solve: prescribed, or (zero-gradient) the
    /// neighbour's lagged value — stored in `lag` during the sweep.
    #[inline]
    pub(super) fn lagged_boundary(&self, b: usize, n: End) -> f64 {
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
    pub(super) fn tree_solve(&mut self, x: &mut [f64]) {
        let Some(tree) = self.plan.tree.as_deref() else {
            return;
        };
        let sw = &mut self.sweep;
        sw.beta.resize(tree.len(), 0.0);
        for &fi in &self.plan.boundary_faces {
            let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
            match (up, down) {
                (End::Node(n), _) => sw.den[n] += q.abs(),
                (End::Boundary(bb), End::Node(n)) => {
                    sw.num[n] += q.abs() * inflow_value(self.bval[bb], sw.lag[n])
                }
                _ => {}
            }
        }
        for (&(n, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
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
    pub(super) fn sweep_solve(
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
            for &fi in &self.plan.node_faces[self.plan.node_ptr[n]..self.plan.node_ptr[n + 1]] {
                let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
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
            for &k in &self.plan.node_sources[n] {
                let q = self.qs[k];
                if q >= 0.0 {
                    sw.num[n] += q * inflow_value(self.bval[self.plan.sources[k].2], sw.lag[n]);
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
            for &fi in &self.plan.node_faces[self.plan.node_ptr[n]..self.plan.node_ptr[n + 1]] {
                let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
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
                    for &fi in
                        &self.plan.node_faces[self.plan.node_ptr[n]..self.plan.node_ptr[n + 1]]
                    {
                        let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
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
}

#[derive(Debug, Clone)]
pub(super) struct Sweep {
    pub(super) mark: Vec<bool>,
    pub(super) pending: Vec<u32>,
    pub(super) num: Vec<f64>,
    pub(super) den: Vec<f64>,
    pub(super) lag: Vec<f64>,
    pub(super) queue: Vec<usize>,
    pub(super) d: Vec<f64>,
    pub(super) b: Vec<f64>,
    pub(super) dnode: Vec<f64>,
    /// Implicit step: α_f-level state, new transport volumes, linearised wall uptake, and the
    /// coupling to the parent of every node in the tree elimination.
    pub(super) ya: Vec<f64>,
    pub(super) wnew: Vec<f64>,
    pub(super) wconst: Vec<f64>,
    pub(super) wlin: Vec<f64>,
    pub(super) inv_slope: Vec<f64>,
    pub(super) beta: Vec<f64>,
}

impl Sweep {
    pub(super) fn new(nn: usize) -> Self {
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
