//! Explicit right-hand side (monolithic RK4 with the flow).

#[allow(unused_imports)]
use super::*;

impl Transport {
    /// Explicit right-hand side dz/dt at (t, y) for the monolithic RK4 step.
    pub fn rhs(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.ensure_scratch();
        self.update_wall_flux(time);
        let nc = self.plan.cells.len();
        self.volumes(y, time)?;
        self.load_flows(time, y);
        let mut dnode = std::mem::take(&mut self.sweep.dnode);
        dnode.resize(self.plan.kind.len(), 0.0);
        let mut res = Ok(());
        for s in 0..self.species.len() {
            let zs = &z[s * nc..(s + 1) * nc];
            for (i, &n) in self.plan.cells.iter().enumerate() {
                self.conc[n] = zs[i] / self.vol[i];
                dnode[n] = 0.0;
            }
            for &m in &self.plan.mixing {
                dnode[m] = 0.0;
            }
            self.load_boundary(s, time);
            res = self.mix(s);
            if res.is_err() {
                break;
            }
            self.load_shear(s, y, z);
            let (i_in, i_out) = self.face_fluxes(&mut dnode);
            self.cell_rates(s, y, z, &dnode, dz, i_in, i_out);
            self.tissue_rhs(s, z, dz); // tissue hook (nothing without tissue)
        }
        self.sweep.dnode = dnode;
        res
    }

    /// The advective fluxes of the loaded face flows and concentrations into the net rate per
    /// node (`dnode`, zeroed by the caller); the boundary inflow and outflow rates.
    fn face_fluxes(&self, dnode: &mut [f64]) -> (f64, f64) {
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
        let inlet = &self.plan.boundary_inlet;
        for &fi in &self.plan.boundary_faces {
            let f = &self.plan.faces[fi];
            let (q, c) = self.upwind(fi);
            let flux = q * c;
            match f.from {
                End::Node(n) => dnode[n] -= flux,
                End::Boundary(b) => account(inlet[b], flux, &mut i_in, &mut i_out),
            }
            match f.to {
                End::Node(n) => dnode[n] += flux,
                End::Boundary(b) => account(inlet[b], -flux, &mut i_in, &mut i_out),
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
            account(inlet[*b], flux, &mut i_in, &mut i_out);
        }
        (i_in, i_out)
    }

    /// dz/dt of species `s` in one pass over the cells: the face balance, wall uptake and
    /// decay; the accumulators' rates, and the relaxed shears' dQ̃/dt = (|Q| − Q̃)/τ_BL.
    #[allow(clippy::too_many_arguments)]
    fn cell_rates(
        &mut self,
        s: usize,
        y: &[f64],
        z: &[f64],
        dnode: &[f64],
        dz: &mut [f64],
        i_in: f64,
        i_out: f64,
    ) {
        let (nc, nsp) = (self.plan.cells.len(), self.species.len());
        if self.species[s].laws.has_wall {
            self.free_of_cells(s);
        }
        let set = &self.plan.species[s];
        let sp = &self.species[s];
        let (laws, free) = (&*sp.laws, self.free_of(s));
        let (has_wall, lambda) = (laws.has_wall, set.decay);
        let (zs, dzs) = (&z[s * nc..(s + 1) * nc], &mut dz[s * nc..(s + 1) * nc]);
        let (mut i_wall, mut i_decay) = (0.0, 0.0);
        for (i, (d, &n)) in dzs.iter_mut().zip(&self.plan.cells).enumerate() {
            let mut v = dnode[n];
            if has_wall {
                let w = laws.fixed_uptake(i, free[n]);
                v -= w;
                i_wall += w;
            }
            if lambda != 0.0 {
                v -= lambda * zs[i];
                i_decay += lambda * zs[i];
            }
            *d = v;
        }
        for &p in &laws.dynamic {
            let w = laws.piece_uptake(&self.plan.pieces, p, free, &sp.shear_cbrt);
            dzs[self.plan.pieces[p].cell as usize] -= w;
            i_wall += w;
        }
        let acc = &mut dz[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
        acc.copy_from_slice(&[i_in, i_out, i_wall, i_decay]);
        for (k, &(j, tau, _)) in laws.relax.iter().enumerate() {
            let i = laws.relax_offset + k;
            dz[i] = (y[self.plan.segments[j].branch_unknown as usize].abs() - z[i]) / tau;
        }
    }
}

impl crate::rk4::Coupled for Transport {
    #[inline]
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.rhs(time, y, z, dz)
    }
}
