//! Backward-Euler transport step after each generalized-α flow step: tree elimination or
//! flow-order sweep.

use super::boundary_chunks;
use super::fused::StepFlows;
#[allow(unused_imports)]
use super::*;

/// How the rows of a species are built, and so which wall linearisation the update after the
/// solve reads (W = wlin·C_t + wconst per cell).
#[derive(Clone, Copy, PartialEq, Eq)]
enum Rows {
    /// A wall linear in C_t (`fixed_rows`): wlin = `cell_g`, wconst = `cell_wc`.
    Fixed,
    /// A binding with fixed laws (`binding_rows`), linearised into `sweep.wlin`, `wconst`.
    Binding,
    /// Shear-dependent walls (`general_rows`), linearised likewise.
    General,
}

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
        self.ensure_scratch();
        let t_af = time + alpha_f * dt;
        self.load_flows_between(t_af, y0, y1, alpha_f);
        if self.needs_step_state() {
            let ya = &mut self.sweep.ya;
            ya.clear();
            ya.extend(y0.iter().zip(y1).map(|(a, b)| a + alpha_f * (b - a)));
        }
        self.step_with_loaded_flows(t_af, dt, z)
    }

    /// Whether a step reads the whole α_f-level flow state (shear-dependent walls, relaxed or
    /// instantaneous), not only the face flows: then the caller keeps the step's start state
    /// and calls [`Transport::implicit_step`], else it may use
    /// [`Transport::implicit_step_carried`].
    pub fn needs_step_state(&self) -> bool {
        !self.fused_applies()
            && self
                .species
                .iter()
                .any(|sp| !sp.laws.relax.is_empty() || !sp.laws.dynamic_segs.is_empty())
    }

    /// The face flows of `y` as the start of the next [`Transport::implicit_step_carried`]
    /// (a run calls it once before its first step and after anything that sets the flow
    /// state other than a step, such as a checkpoint restore).
    pub fn set_step_start(&mut self, y: &[f64]) {
        self.ensure_scratch();
        let nf = self.plan.n_flow_faces;
        let q0 = &mut self.sweep.q_start;
        q0.clear();
        q0.extend(self.plan.face_unknowns[..nf].iter().map(|&u| y[u as usize]));
    }

    /// [`Transport::implicit_step`] with the step's start flows carried from the previous
    /// step's end (or [`Transport::set_step_start`]) instead of read from a copy of the flow
    /// state: the same face flows bit for bit (Q_0 is the same number), without copying y
    /// every step. The end flows become the next step's start.
    pub fn implicit_step_carried(
        &mut self,
        time: f64,
        dt: f64,
        alpha_f: f64,
        y1: &[f64],
        z: &mut [f64],
    ) -> Result<()> {
        self.ensure_scratch();
        debug_assert!(!self.needs_step_state());
        let t_af = time + alpha_f * dt;
        let mut q0 = std::mem::take(&mut self.sweep.q_start);
        let nf = self.plan.n_flow_faces;
        assert_eq!(q0.len(), nf, "set_step_start before the first carried step");
        let unknowns = &self.plan.face_unknowns[..nf];
        let gather = |q: &mut f64, q0: &mut f64, u: u32| {
            let q1 = y1[u as usize];
            *q = *q0 + alpha_f * (q1 - *q0);
            *q0 = q1;
        };
        if self.gathers_in_forward() {
            // the boundary faces here, the tree faces where the forward pass reads them
            let links = &self.plan.boundary_links[..];
            match boundary_chunks::split(self.sweep.boundary.as_ref()) {
                Some((chunks, pool)) => {
                    let flows = (y1, unknowns, alpha_f);
                    chunks.gather(&pool, links, flows, &mut self.qf, &mut q0);
                }
                None => {
                    for b in links {
                        let f = b.face as usize;
                        gather(&mut self.qf[f], &mut q0[f], unknowns[f]);
                    }
                }
            }
            self.sweep.q_start = q0;
            self.load_source_and_chain_flows(t_af);
            self.update_wall_flux(t_af);
            return self.fused_tree_step(t_af, dt, z, StepFlows::Carried { y1, alpha_f });
        }
        for ((q, q0), &u) in self.qf[..nf].iter_mut().zip(q0.iter_mut()).zip(unknowns) {
            gather(q, q0, u);
        }
        self.sweep.q_start = q0;
        self.load_source_and_chain_flows(t_af);
        self.step_with_loaded_flows(t_af, dt, z)
    }

    /// The step after the face flows of its α_f level are loaded.
    fn step_with_loaded_flows(&mut self, t_af: f64, dt: f64, z: &mut [f64]) -> Result<()> {
        self.update_wall_flux(t_af);
        if self.fused_applies() {
            return self.fused_tree_step(t_af, dt, z, StepFlows::Loaded);
        }
        // the α_f-level state (`implicit_step`; only read by shear-dependent walls)
        let ya = std::mem::take(&mut self.sweep.ya);
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
        let net = self.net_inflow();
        let mut w_new = std::mem::take(&mut self.sweep.wnew);
        w_new.clear();
        w_new.resize(self.plan.cells.len(), 0.0);
        // (NaN fails the test too)
        let mut positive = true;
        for ((w, &n), &w0) in w_new.iter_mut().zip(&self.plan.cells).zip(&self.wvol) {
            *w = w0 + dt * net[n as usize];
            positive &= *w > 0.0;
        }
        self.sweep.dnode = net;
        self.sweep.wnew = w_new;
        if positive {
            Ok(())
        } else {
            Err(self.volume_error(t_af))
        }
    }

    /// The error for the first cell whose new transport volume (`sweep.wnew`) is not positive.
    #[cold]
    pub(super) fn volume_error(&self, t_af: f64) -> Error {
        let w = &self.sweep.wnew;
        let i = w.iter().position(|&w| w.is_nan() || w <= 0.0).unwrap_or(0);
        Error::solver(
            t_af,
            format!(
                "transport volume of cell '{}' became {:.3e} m³: reduce dt",
                self.plan.node_name(self.plan.cells[i] as usize),
                w.get(i).copied().unwrap_or(f64::NAN)
            ),
        )
    }

    /// Net inflow of every node with the loaded face flows (in `sweep.dnode`'s storage).
    fn net_inflow(&mut self) -> Vec<f64> {
        let mut net = std::mem::take(&mut self.sweep.dnode);
        net.clear();
        net.resize(self.plan.kind.len(), 0.0);
        let qf = &self.qf[..];
        for [fi, a, b] in self.plan.internal() {
            let q = qf[fi as usize];
            net[a as usize] -= q;
            net[b as usize] += q;
        }
        for &fi in &self.plan.boundary_faces {
            let (f, q) = (&self.plan.faces[fi], self.qf[fi]);
            if let End::Node(n) = f.tail() {
                net[n] -= q;
            }
            if let End::Node(n) = f.head() {
                net[n] += q;
            }
        }
        for ((n, _, _), &q) in self.plan.sources.iter().zip(&self.qs) {
            net[*n] += q;
        }
        net
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
        self.sweep.size_rows(self.plan.kind.len());
        let (mut wconst, mut wlin) = (
            std::mem::take(&mut self.sweep.wconst),
            std::mem::take(&mut self.sweep.wlin),
        );
        wconst.resize(nc, 0.0);
        wlin.resize(nc, 0.0);
        let w_new = std::mem::take(&mut self.sweep.wnew);
        let mut res = Ok(());
        for s in 0..self.species.len() {
            self.load_boundary(s, t_af);
            self.relax_shears(s, dt, ya, z);
            self.restore_mixing(s);
            let sw = &mut self.sweep;
            for &m in &self.plan.mixing {
                (sw.den[m], sw.num[m], sw.lag[m]) = (0.0, 0.0, self.conc[m]);
            }
            let rows = self.implicit_rows(s, dt, ya, z, &w_new, &mut wconst, &mut wlin);
            let mut x = std::mem::take(&mut self.conc);
            if self.plan.tree.is_some() {
                self.tree_solve(&mut x);
            } else if self.plan.core.is_some() {
                let plan = Arc::clone(&self.plan);
                res = self.core_solve(plan.core.as_ref().expect("checked"), &mut x);
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
            let laws = Arc::clone(&self.species[s].laws);
            let (wl, wc) = match rows {
                Rows::Fixed => (&laws.cell_g[..], &laws.cell_wc[..]),
                Rows::Binding | Rows::General => (&wlin[..], &wconst[..]),
            };
            self.implicit_update(s, dt, &w_new, wl, wc, z);
            self.tissue_update(s, dt, z); // tissue hook: back-substitute the wall columns
        }
        let sc = &mut self.sweep;
        (sc.wconst, sc.wlin, sc.wnew) = (wconst, wlin, w_new);
        res
    }

    /// After the solve of species `s`: the new amounts N = W' x, and the step's boundary, wall
    /// (W = wl·x + wc per cell) and decay fluxes into the accumulators.
    fn implicit_update(
        &mut self,
        s: usize,
        dt: f64,
        w_new: &[f64],
        wl: &[f64],
        wc: &[f64],
        z: &mut [f64],
    ) {
        let (nc, nsp) = (self.plan.cells.len(), self.species.len());
        let quasi = self.plan.formulation == Formulation::TlQuasisteady;
        let lambda = self.plan.species[s].decay;
        let (i_in, i_out) = self.implicit_boundary_fluxes();
        let (mut i_wall, mut i_decay) = (0.0, 0.0);
        let (conc, zs) = (&self.conc[..], &mut z[s * nc..(s + 1) * nc]);
        let (wl, wc, w_new) = (&wl[..nc], &wc[..nc], &w_new[..nc]);
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            let x = conc[n];
            i_wall += wl[i] * x + wc[i];
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

    /// The rows (d_n + Σ_out |Q|) x_n − Σ_in |Q| x_up = b_n of species `s` into `sweep.den`
    /// (d) and `sweep.num` (b), and the old concentrations into `conc`: one fused pass over
    /// the cells for fixed laws (with a binding, the wall linearised about the old state),
    /// the general path for shear-dependent walls.
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
    ) -> Rows {
        let rows = self.rows_kind(s);
        match rows {
            Rows::Fixed => self.fixed_rows(s, dt, z, w_new),
            Rows::Binding => self.binding_rows(s, dt, z, w_new, wconst, wlin),
            Rows::General => self.general_rows(s, dt, ya, z, w_new, wconst, wlin),
        }
        rows
    }

    /// Which rows species `s` takes (see [`Rows`]).
    fn rows_kind(&self, s: usize) -> Rows {
        let laws = &self.species[s].laws;
        // tissue hook: a tissue wall's law is linearised per step (`tissue_rows`)
        if !laws.dynamic.is_empty() || self.tissue_of(s).is_some() {
            Rows::General
        } else if self.plan.species[s].binding.is_identity() || !laws.has_wall {
            Rows::Fixed
        } else {
            Rows::Binding
        }
    }

    /// Rows with a wall linear in C_t (fixed laws, no binding, or no wall): W = g C + (q − g
    /// c_w), so d = W'(1/dt + λ) + g, b = N/dt − (q − g c_w) (quasi-steady: d = g,
    /// b = −(q − g c_w)). The lagged values the solve needs are the old concentrations it
    /// reads from `conc`.
    fn fixed_rows(&mut self, s: usize, dt: f64, z: &[f64], w_new: &[f64]) {
        let nc = self.plan.cells.len();
        if self.plan.formulation == Formulation::TlQuasisteady {
            let (zs, laws) = (&z[s * nc..(s + 1) * nc], &self.species[s].laws);
            for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
                self.conc[n] = zs[i] / self.wvol[i];
                (self.sweep.den[n], self.sweep.num[n]) = (laws.cell_g[i], -laws.cell_wc[i]);
            }
            return;
        }
        let rate = 1.0 / dt + self.plan.species[s].decay;
        let laws = &self.species[s].laws;
        // local slices: the loop keeps its pointers in registers
        let zs = &z[s * nc..(s + 1) * nc];
        let conc = &mut self.conc[..];
        let (den, num) = (&mut self.sweep.den[..], &mut self.sweep.num[..]);
        let (g, wc) = (&laws.cell_g[..nc], &laws.cell_wc[..nc]);
        let (wvol, w_new) = (&self.wvol[..nc], &w_new[..nc]);
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            conc[n] = zs[i] / wvol[i];
            den[n] = w_new[i] * rate + g[i];
            num[n] = zs[i] / dt - wc[i];
        }
    }

    /// Rows with a binding and fixed laws, in one pass: free concentration and capacity slope
    /// at the old state (anchored inversion), W = g (c − c_w) + q linearised in C_t about it.
    fn binding_rows(
        &mut self,
        s: usize,
        dt: f64,
        z: &[f64],
        w_new: &[f64],
        wconst: &mut [f64],
        wlin: &mut [f64],
    ) {
        let nc = self.plan.cells.len();
        let quasi = self.plan.formulation == Formulation::TlQuasisteady;
        let set = &self.plan.species[s];
        let rate = 1.0 / dt + set.decay;
        let sp = &mut self.species[s];
        let (laws, free, anchors) = (&sp.laws, &mut sp.free, &mut sp.anchors);
        let has_wall = laws.has_wall;
        let zs = &z[s * nc..(s + 1) * nc];
        let sw = &mut self.sweep;
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            let c = zs[i] / self.wvol[i];
            self.conc[n] = c;
            let (wl, wc) = if has_wall {
                let (f, inv_slope) = match anchors.get_mut(n) {
                    Some(a) => set.binding.free_and_inv_slope_anchored(c, free[n], a),
                    None => set.binding.free_and_inv_slope_anchored(
                        c,
                        free[n],
                        &mut HillAnchor::default(),
                    ),
                };
                free[n] = f;
                laws.linearised_uptake(i, f, inv_slope, c)
            } else {
                (0.0, 0.0)
            };
            (wlin[i], wconst[i]) = (wl, wc);
            (sw.den[n], sw.num[n]) = if quasi {
                (wl, -wc)
            } else {
                (w_new[i] * rate + wl, zs[i] / dt - wc)
            };
            sw.lag[n] = c;
        }
    }

    /// Rows with shear-dependent walls (or the quasi-steady formulation with them): old
    /// concentrations, the shears, the wall linearised about the old state, then d and b.
    #[allow(clippy::too_many_arguments)]
    fn general_rows(
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
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            self.conc[n] = zs[i] / self.wvol[i];
        }
        self.load_shear(s, ya, z);
        self.linearised_wall(s, wconst, wlin);
        self.tissue_rows(s, dt, z, wconst, wlin); // tissue hook: eliminate the wall columns
        let quasi = self.plan.formulation == Formulation::TlQuasisteady;
        let rate = 1.0 / dt + self.plan.species[s].decay;
        let sw = &mut self.sweep;
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
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
        let laws = &self.species[s].laws;
        for (k, &(j, tau, _)) in laws.relax.iter().enumerate() {
            let q = ya[self.plan.segments[j].branch_unknown as usize].abs();
            let v = &mut z[laws.relax_offset + k];
            *v = q + (*v - q) * (-dt / tau).exp();
        }
    }

    /// Wall uptake of species `s` linearised about the current state: W = wlin·C_t + wconst
    /// per cell (exact for linear binding); zero without a wall.
    pub(super) fn linearised_wall(&mut self, s: usize, wconst: &mut [f64], wlin: &mut [f64]) {
        let laws = Arc::clone(&self.species[s].laws);
        if !laws.has_wall {
            wlin.iter_mut().for_each(|v| *v = 0.0);
            wconst.iter_mut().for_each(|v| *v = 0.0);
            return;
        }
        let binding = self.plan.species[s].binding;
        // free concentrations and 1/(dC_t/dc) there (the slope of W in C_t per unit g)
        let mut inv_slope = std::mem::take(&mut self.sweep.inv_slope);
        inv_slope.clear();
        inv_slope.resize(self.plan.cells.len(), 1.0);
        if !binding.is_identity() {
            let sp = &mut self.species[s];
            for (n, v) in (self.plan.cells.iter().map(|&n| n as usize)).zip(inv_slope.iter_mut()) {
                let mut scratch = HillAnchor::default();
                let anchor = sp.anchors.get_mut(n).unwrap_or(&mut scratch);
                let (f, inv) =
                    binding.free_and_inv_slope_anchored(self.conc[n], sp.free[n], anchor);
                sp.free[n] = f;
                *v = inv;
            }
        }
        self.wall_uptake(s, wconst);
        wlin.copy_from_slice(&laws.cell_g);
        let shear = &self.species[s].shear_cbrt;
        for &p in &laws.dynamic {
            let pc = &self.plan.pieces[p];
            let (gj, _, _) = laws.laws[p].eval_cbrt(shear[pc.seg as usize]);
            wlin[pc.cell as usize] += pc.share * gj;
        }
        if !binding.is_identity() {
            wlin.iter_mut().zip(&inv_slope).for_each(|(w, v)| *w *= v);
        }
        self.sweep.inv_slope = inv_slope;
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            wconst[i] -= wlin[i] * self.conc[n];
        }
    }

    /// Boundary inflow (I_in) and outflow (I_out) rates of the solved implicit field: the same
    /// fluxes that entered the solve.
    pub(super) fn implicit_boundary_fluxes(&self) -> (f64, f64) {
        let (mut i_in, mut i_out) = (0.0, 0.0);
        let (qf, conc) = (&self.qf[..], &self.conc[..]);
        for b in &self.plan.boundary_links {
            let (n, bb, q) = (b.node as usize, b.boundary as usize, qf[b.face as usize]);
            let flux_in = b.flux_in(q, conc[n], || self.lagged_boundary(bb, End::Node(n)));
            account(self.plan.boundary_inlet[bb], flux_in, &mut i_in, &mut i_out);
        }
        self.source_fluxes(i_in, i_out)
    }

    /// `implicit_boundary_fluxes` with the boundary faces' fluxes in chunks on the run's
    /// threads (`boundary_chunks`) when the tree has them: the same sums in the same order.
    pub(super) fn step_boundary_fluxes(&mut self) -> (f64, f64) {
        let Some((_, pool)) = boundary_chunks::split(self.sweep.boundary.as_ref()) else {
            return self.implicit_boundary_fluxes();
        };
        let (sw, bval) = (&mut self.sweep, &self.bval);
        let (lag, Some(chunks)) = (&sw.lag, sw.boundary.as_mut()) else {
            return (0.0, 0.0); // (`pool_for` found the chunks)
        };
        let flows = (&self.qf[..], &self.conc[..]);
        let links = &self.plan.boundary_links[..];
        let boundary = |bb: usize, n: usize| inflow_value(bval[bb], lag[n]);
        let (i_in, i_out) = chunks.fluxes(&pool, links, flows, boundary);
        self.source_fluxes(i_in, i_out)
    }

    /// The flow sources' fluxes added to the boundary faces' (`i_in`, `i_out`).
    fn source_fluxes(&self, mut i_in: f64, mut i_out: f64) -> (f64, f64) {
        for ((n, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
            let flux_in = upwind_flux_in(q, true, self.conc[*n], || {
                self.lagged_boundary(*bb, End::Node(*n))
            });
            account(
                self.plan.boundary_inlet[*bb],
                flux_in,
                &mut i_in,
                &mut i_out,
            );
        }
        (i_in, i_out)
    }

    /// Inflow value of a boundary in the implicit solve: prescribed, or (zero-gradient) the
    /// neighbour's lagged value — stored in `lag` by the solve for every node a boundary
    /// flows into.
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
    /// On entry `sweep.den`, `sweep.num` hold d and b, and `x` the previous values (the lagged
    /// values of the rows: `lag` is written only for the nodes boundaries flow into).
    pub(super) fn tree_solve(&mut self, x: &mut [f64]) {
        if self.plan.tree.is_none() {
            return;
        }
        self.sweep.size_rows(self.plan.kind.len());
        self.boundary_rows(x);
        let Some(tree) = self.plan.tree.as_deref() else {
            return;
        };
        tree_forward(&mut self.sweep, &self.qf, tree, x, false);
        tree_backward(&self.sweep, tree, x);
    }

    /// The boundary faces' and sources' terms of the tree solve's rows: outflow into d, inflow
    /// (prescribed or the node's lagged value `x`, recorded in `lag`) into b.
    pub(super) fn boundary_rows(&mut self, x: &[f64]) {
        let sw = &mut self.sweep;
        for &fi in &self.plan.boundary_faces {
            let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
            match (up, down) {
                (End::Node(n), _) => sw.den[n] += q.abs(),
                (End::Boundary(bb), End::Node(n)) => {
                    sw.lag[n] = x[n];
                    sw.num[n] += q.abs() * inflow_value(self.bval[bb], sw.lag[n])
                }
                _ => {}
            }
        }
        for (&(n, _, bb), &q) in self.plan.sources.iter().zip(&self.qs) {
            if q >= 0.0 {
                sw.lag[n] = x[n];
                sw.num[n] += q * inflow_value(self.bval[bb], sw.lag[n]);
            } else {
                sw.den[n] -= q;
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
        self.sweep.size_rows(self.plan.kind.len());
        for &n in unknowns {
            (self.sweep.num[n], self.sweep.den[n]) = (b[n], d[n]);
        }
        self.sweep_solve_loaded(unknowns, x)
    }

    /// `sweep_solve` with d and b of the unknowns already in `sweep.den` and `sweep.num`.
    pub(super) fn sweep_solve_loaded(&mut self, unknowns: &[usize], x: &mut [f64]) -> Result<()> {
        self.sweep.size_rows(self.plan.kind.len());
        self.sweep_rows(unknowns, x);
        let solved = self.kahn(unknowns, x);
        let result = if solved < unknowns.len() {
            self.gauss_seidel(unknowns, x)
        } else {
            Ok(())
        };
        for &n in unknowns {
            self.sweep.mark[n] = false;
        }
        result
    }

    /// The rows of `sweep_solve`: marks, lagged values, pending upwind counts, denominators,
    /// and the inflows from known nodes, boundaries and sources (d and b of the unknowns in
    /// `sweep.den` and `sweep.num`).
    fn sweep_rows(&mut self, unknowns: &[usize], x: &[f64]) {
        let nn = self.plan.kind.len();
        let sw = &mut self.sweep;
        if sw.mark.len() != nn {
            (sw.mark, sw.pending) = (vec![false; nn], vec![0; nn]);
        }
        for &n in unknowns {
            sw.mark[n] = true;
            sw.lag[n] = x[n];
            sw.pending[n] = 0;
        }
        let plan = &*self.plan;
        for &n in unknowns {
            for fi in plan.faces_at(n) {
                let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
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
            for &k in plan.node_sources(n) {
                let (q, bb) = (self.qs[k as usize], plan.sources[k as usize].2);
                if q >= 0.0 {
                    sw.num[n] += q * inflow_value(self.bval[bb], sw.lag[n]);
                } else {
                    sw.den[n] -= q;
                }
            }
        }
    }

    /// Kahn's flow-order pass of `sweep_solve`: every node whose upwind unknowns are solved is
    /// solved in turn. Returns the number of nodes solved (all, unless flow circulates).
    fn kahn(&mut self, unknowns: &[usize], x: &mut [f64]) -> usize {
        let sw = &mut self.sweep;
        let plan = &*self.plan;
        sw.queue.clear();
        sw.queue
            .extend(unknowns.iter().copied().filter(|&n| sw.pending[n] == 0));
        let mut head = 0;
        while head < sw.queue.len() {
            let n = sw.queue[head];
            head += 1;
            x[n] = if sw.den[n] > 1e-300 {
                sw.num[n] / sw.den[n]
            } else {
                sw.lag[n]
            };
            for fi in plan.faces_at(n) {
                let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
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
        head
    }

    /// The nodes Kahn's pass left (directed flow cycles): Gauss–Seidel, which converges for
    /// the M-matrix of the upwind rows.
    fn gauss_seidel(&mut self, unknowns: &[usize], x: &mut [f64]) -> Result<()> {
        let sw = &self.sweep;
        let plan = &*self.plan;
        let rest: Vec<usize> = unknowns
            .iter()
            .copied()
            .filter(|&n| sw.pending[n] > 0)
            .collect();
        for _ in 0..10_000 {
            let mut change = 0.0f64;
            let mut scale = 0.0f64;
            for &n in &rest {
                let mut num = sw.num[n];
                for fi in plan.faces_at(n) {
                    let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
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
                return Ok(());
            }
        }
        Err(Error::solver(
            0.0,
            "transport sweep did not converge on a flow loop".to_string(),
        ))
    }
}

#[derive(Debug, Clone, Default)]
pub(super) struct Sweep {
    /// Flow-order sweep only (sized on first use): unknowns of the current solve, and their
    /// upwind unknowns not yet solved.
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
    /// Fused tree step (`fused.rs`): per node, its net inflow and the d and b terms of its
    /// row left by its children and the boundaries; zero between steps.
    pub(super) acc: Vec<[f64; 3]>,
    /// Face flows at the start of the next step (`Transport::implicit_step_carried`).
    pub(super) q_start: Vec<f64>,
    /// Fused tree step with a binding: Σ wc of the cells' linearised walls (`fused.rs`).
    pub(super) wc_sum: f64,
    /// Fused tree step of a large tree: its blocks for the run's threads (`parallel`).
    pub(super) partition: Option<Arc<super::parallel::TreePartition>>,
    /// Fused tree step of a tree with many outlets: its boundary faces' chunks for the
    /// run's threads (`boundary_chunks`).
    pub(super) boundary: Option<super::boundary_chunks::BoundaryChunks>,
}

impl Sweep {
    pub(super) fn new(nn: usize) -> Self {
        Sweep {
            lag: vec![0.0; nn],
            ..Sweep::default()
        }
    }

    /// The rows' `num` and `den` of `nn` nodes, zero, sized on first use: the row-by-row
    /// passes and the flow-order sweep read them, the fused tree step never does (16 bytes
    /// per node of a large tree's run held for nothing).
    pub(super) fn size_rows(&mut self, nn: usize) {
        if self.num.len() != nn {
            self.num = vec![0.0; nn];
            self.den = vec![0.0; nn];
        }
    }
}
