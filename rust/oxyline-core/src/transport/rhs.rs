//! Explicit right-hand side (monolithic RK4 with the flow).

#[allow(unused_imports)]
use super::*;

impl Species {
    /// Wall uptake (mol/s) of cell `i` from its fixed laws at free concentration `free`:
    /// Σ share·(g (c − c_w) + q) = G c − Σ share g c_w + Q (the wall-uptake law, docs/physics.md §3).
    #[inline]
    pub(super) fn fixed_uptake(&self, i: usize, free: f64) -> f64 {
        self.cell_g[i] * free - self.cell_gcw[i] + self.cell_q[i]
    }

    /// Wall uptake (mol/s) of wall piece `p` with its own law (any kind) at the current shear,
    /// `free` the free concentration per node.
    #[inline]
    pub(super) fn piece_uptake(&self, pieces: &[Piece], p: usize, free: &[f64]) -> f64 {
        let pc = &pieces[p];
        let (g, cw, q) = self.laws[p].eval_cbrt(self.shear_cbrt[pc.seg]);
        pc.share * (g * (free[pc.node] - cw) + q)
    }
}

impl Transport {
    /// Explicit right-hand side dz/dt at (t, y) for the monolithic RK4 step.
    pub fn rhs(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        let nc = self.plan.cells.len();
        let nsp = self.species.len();
        self.volumes(y, time)?;
        self.load_flows(time, y);
        let mut dnode = std::mem::take(&mut self.sweep.dnode);
        dnode.resize(self.plan.kind.len(), 0.0);
        for s in 0..nsp {
            let (zs, dzs) = (&z[s * nc..(s + 1) * nc], &mut dz[s * nc..(s + 1) * nc]);
            for (i, &n) in self.plan.cells.iter().enumerate() {
                self.conc[n] = zs[i] / self.vol[i];
                dnode[n] = 0.0;
            }
            for &m in &self.plan.mixing {
                dnode[m] = 0.0;
            }
            self.load_boundary(s, time);
            self.mix(s)?;
            self.load_shear(s, y, z);
            // node-to-node faces: the bulk of the work, branch-free apart from the upwind pick;
            // fluxes into mixing points and out of them cancel there (they hold no amount)
            let conc = &self.conc;
            for &[fi, a, b] in &self.plan.internal {
                let q = self.qf[fi as usize];
                let (a, b) = (a as usize, b as usize);
                let flux = q * if q >= 0.0 { conc[a] } else { conc[b] };
                dnode[a] -= flux;
                dnode[b] += flux;
            }
            let (mut i_in, mut i_out) = (0.0, 0.0);
            for &fi in &self.plan.boundary_faces {
                let f = &self.plan.faces[fi];
                let (q, c) = self.upwind(fi);
                let flux = q * c;
                match f.from {
                    End::Node(n) => dnode[n] -= flux,
                    End::Boundary(b) => {
                        account(self.plan.boundary_inlet[b], flux, &mut i_in, &mut i_out)
                    }
                }
                match f.to {
                    End::Node(n) => dnode[n] += flux,
                    End::Boundary(b) => {
                        account(self.plan.boundary_inlet[b], -flux, &mut i_in, &mut i_out)
                    }
                }
            }
            for ((n, _, b), &q) in self.plan.sources.iter().zip(&self.qs) {
                let c = if q >= 0.0 {
                    self.boundary_conc(*b, End::Node(*n))
                } else {
                    self.conc[*n]
                };
                let flux = q * c;
                dnode[*n] += flux;
                account(self.plan.boundary_inlet[*b], flux, &mut i_in, &mut i_out);
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
            for (i, (d, &n)) in dzs.iter_mut().zip(&self.plan.cells).enumerate() {
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
                let w = sp.piece_uptake(&self.plan.pieces, p, free);
                dzs[self.plan.pieces[p].cell] -= w;
                i_wall += w;
            }
            let acc = &mut dz[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            acc.copy_from_slice(&[i_in, i_out, i_wall, i_decay]);
            // relaxed shears: dQ̃/dt = (|Q| − Q̃)/τ_BL
            for (k, &(j, tau)) in sp.relax.iter().enumerate() {
                let i = sp.relax_offset + k;
                dz[i] = (y[self.plan.segments[j].branch_unknown].abs() - z[i]) / tau;
            }
        }
        self.sweep.dnode = dnode;
        Ok(())
    }
}

impl crate::rk4::Coupled for Transport {
    #[inline]
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.rhs(time, y, z, dz)
    }
}
