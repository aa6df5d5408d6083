//! Explicit right-hand side (monolithic RK4 with the flow, docs/physics.md §2.5: the
//! conservative finite-volume form, V = V0 + C (P − P_ref), upwind face fluxes).
//!
//! Per stage and species: one pass over the cells (volumes on the first species, total and
//! free concentrations), the face fluxes, and one pass over the cells for their rates. In the
//! RK4 step the rates are handed straight to the integrator's stage kernel
//! ([`crate::rk4::StageSink`]): no stage derivative is stored, and the stage state and the
//! weighted sum are written in the same pass.

#[allow(unused_imports)]
use super::*;
use crate::rk4::StageSink;

/// Where the cell pass's rates go: stored in `dz` (with the state `z` they are evaluated at),
/// or handed to an RK4 stage.
enum Rates<'a, 'b> {
    Stored { z: &'a [f64], dz: &'a mut [f64] },
    Stage(&'a mut StageSink<'b>),
}

impl Rates<'_, '_> {
    #[inline]
    fn z(&self) -> &[f64] {
        match self {
            Rates::Stored { z, .. } => z,
            Rates::Stage(sink) => sink.z(),
        }
    }
}

/// Net rate of one cell (mol/s): the face balance `dnode`, minus the fixed laws' wall uptake
/// at free concentration `free` (`wall`: the species has a wall) and the decay of the amount
/// `z`; the uptake and decay are added to their accumulators.
#[inline(always)]
fn cell_rate(
    dnode: f64,
    wall: Option<(&Laws, usize, f64)>,
    lambda: f64,
    z: f64,
    i_wall: &mut f64,
    i_decay: &mut f64,
) -> f64 {
    let mut v = dnode;
    if let Some((laws, i, free)) = wall {
        let w = laws.fixed_uptake(i, free);
        v -= w;
        *i_wall += w;
    }
    if lambda != 0.0 {
        v -= lambda * z;
        *i_decay += lambda * z;
    }
    v
}

impl Transport {
    /// Explicit right-hand side dz/dt at (t, y) for the monolithic RK4 step.
    pub fn rhs(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.rates(time, y, Rates::Stored { z, dz })
    }

    /// Whether the rates can be handed to the RK4 stage entry by entry: every entry of the
    /// state is a cell amount or an accumulator, each finished in one pass (no tissue, whose
    /// hook corrects the cells' rates afterwards; no dynamic wall pieces, added per piece).
    fn rates_in_one_pass(&self) -> bool {
        self.tissue_len() == 0
            && self
                .species
                .iter()
                .all(|sp| sp.laws.dynamic.is_empty() && sp.laws.relax.is_empty())
    }

    fn rates(&mut self, time: f64, y: &[f64], mut out: Rates<'_, '_>) -> Result<()> {
        self.ensure_scratch();
        self.update_wall_flux(time);
        if self.species.is_empty() {
            return self.volumes(y, time);
        }
        self.load_flows(time, y);
        let mut dnode = std::mem::take(&mut self.sweep.dnode);
        dnode.resize(self.plan.kind.len(), 0.0);
        let mut res = Ok(());
        for s in 0..self.species.len() {
            res = self.concentrations(s, time, y, out.z(), &mut dnode);
            if res.is_err() {
                break;
            }
            self.load_boundary(s, time);
            res = self.mix(s);
            if res.is_err() {
                break;
            }
            self.load_shear(s, y, out.z());
            let (i_in, i_out) = self.face_fluxes(&mut dnode);
            self.cell_rates(s, y, &dnode, &mut out, [i_in, i_out]);
            if let Rates::Stored { z, dz } = &mut out {
                self.tissue_rhs(s, z, dz); // tissue hook (nothing without tissue)
            }
        }
        self.sweep.dnode = dnode;
        res
    }

    /// One pass over the cells for species `s`: the lumen volumes (first species; V = V0 +
    /// C (P − P_ref)), the total concentrations z/V, the free ones when a wall reads them, and
    /// `dnode` zeroed on every node that receives face fluxes.
    fn concentrations(
        &mut self,
        s: usize,
        time: f64,
        y: &[f64],
        z: &[f64],
        dnode: &mut [f64],
    ) -> Result<()> {
        let nc = self.plan.cells.len();
        let zs = &z[s * nc..(s + 1) * nc];
        let plan = &*self.plan;
        let sp = &mut self.species[s];
        let binding = plan.species[s].binding;
        let free = sp.laws.has_wall && !binding.is_identity();
        let (vol, conc) = (&mut self.vol, &mut self.conc);
        let mut bad_volume = false;
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let v = if s == 0 {
                let v = plan.v0[i] + plan.cap[i] * (y[plan.volume_unknown(i)] - plan.p_ref);
                bad_volume |= v.is_nan() || v <= 0.0;
                vol[i] = v;
                v
            } else {
                vol[i]
            };
            let c = zs[i] / v;
            conc[n] = c;
            dnode[n] = 0.0;
            if free {
                // the binding inversion, warm-started at the last value (and Hill's anchor)
                sp.free[n] = match sp.anchors.get_mut(n) {
                    Some(anchor) => binding.free_anchored(c, sp.free[n], anchor),
                    None => binding.free(c, sp.free[n]),
                };
            }
        }
        if bad_volume {
            // the typed error naming the first bad cell
            return self.volumes(y, time);
        }
        for &m in &self.plan.mixing {
            dnode[m] = 0.0;
        }
        Ok(())
    }

    /// The advective fluxes of the loaded face flows and concentrations into the net rate per
    /// node (`dnode`, zeroed by the caller); the boundary inflow and outflow rates.
    fn face_fluxes(&self, dnode: &mut [f64]) -> (f64, f64) {
        // node-to-node faces: the bulk of the work, branch-free apart from the upwind pick;
        // fluxes into mixing points and out of them cancel there (they hold no amount)
        let conc = &self.conc;
        for [fi, a, b] in self.plan.internal() {
            let q = self.qf[fi as usize];
            let (a, b) = (a as usize, b as usize);
            let flux = q * if q >= 0.0 { conc[a] } else { conc[b] };
            dnode[a] -= flux;
            dnode[b] += flux;
        }
        let (mut i_in, mut i_out) = (0.0, 0.0);
        let inlet = &self.plan.boundary_inlet;
        // the boundary faces as their 16-byte links (the same faces in the same order, see
        // `Plan::boundary_links`), not the faces themselves: a tree has one per outlet, and
        // reading each outlet's `Face` cost a cache miss per face and stage. The flux into
        // the node, q_in·c with q_in = ±q, is the ±(q·c) of the face's orientation exactly.
        debug_assert_eq!(
            self.plan.boundary_links.len(),
            self.plan.boundary_faces.len()
        );
        for b in &self.plan.boundary_links {
            let (n, bb, q) = (
                b.node as usize,
                b.boundary as usize,
                self.qf[b.face as usize],
            );
            let flux_in = b.flux_in(q, self.conc[n], || self.boundary_conc(bb, End::Node(n)));
            dnode[n] += flux_in;
            account(inlet[bb], flux_in, &mut i_in, &mut i_out);
        }
        for ((n, _, b), &q) in self.plan.sources.iter().zip(&self.qs) {
            let flux = upwind_flux_in(q, true, self.conc[*n], || {
                self.boundary_conc(*b, End::Node(*n))
            });
            dnode[*n] += flux;
            account(inlet[*b], flux, &mut i_in, &mut i_out);
        }
        (i_in, i_out)
    }

    /// The rates of species `s` in one pass over the cells (face balance, wall uptake, decay),
    /// then its accumulators' rates (I_in, I_out from `boundary`, I_wall, I_decay); stored, the
    /// dynamic wall pieces and the relaxed shears' dQ̃/dt = (|Q| − Q̃)/τ_BL as well.
    fn cell_rates(
        &mut self,
        s: usize,
        y: &[f64],
        dnode: &[f64],
        out: &mut Rates<'_, '_>,
        boundary: [f64; 2],
    ) {
        let (nc, nsp) = (self.plan.cells.len(), self.species.len());
        let set = &self.plan.species[s];
        let sp = &self.species[s];
        let (laws, free) = (&*sp.laws, self.free_of(s));
        let (has_wall, lambda) = (laws.has_wall, set.decay);
        let cells = &self.plan.cells;
        let (mut i_wall, mut i_decay) = (0.0, 0.0);
        // a macro, not a shared closure, so that each pass inlines it
        macro_rules! rate {
            ($i:expr, $z:expr) => {{
                let (i, n) = ($i, cells[$i] as usize);
                let wall = if has_wall {
                    Some((laws, i, free[n]))
                } else {
                    None
                };
                cell_rate(dnode[n], wall, lambda, $z, &mut i_wall, &mut i_decay)
            }};
        }
        let acc = nsp * nc + 4 * s;
        match out {
            Rates::Stage(sink) => {
                sink.sweep(s * nc, nc, |i, z| rate!(i, z));
                let [i_in, i_out] = boundary;
                let acc_rates = [i_in, i_out, i_wall, i_decay];
                sink.sweep(acc, 4, |j, _| acc_rates[j]);
            }
            Rates::Stored { z, dz } => {
                let zs = &z[s * nc..(s + 1) * nc];
                for (i, d) in dz[s * nc..(s + 1) * nc].iter_mut().enumerate() {
                    *d = rate!(i, zs[i]);
                }
                let dzs = &mut dz[s * nc..(s + 1) * nc];
                for &p in &laws.dynamic {
                    let w = laws.piece_uptake(&self.plan.pieces, p, free, &sp.shear_cbrt);
                    dzs[self.plan.pieces[p].cell as usize] -= w;
                    i_wall += w;
                }
                let [i_in, i_out] = boundary;
                dz[acc..acc + 4].copy_from_slice(&[i_in, i_out, i_wall, i_decay]);
                for (k, &(j, tau, _)) in laws.relax.iter().enumerate() {
                    let i = laws.relax_offset + k;
                    dz[i] = (y[self.plan.segments[j].branch_unknown as usize].abs() - z[i]) / tau;
                }
            }
        }
    }
}

impl crate::rk4::Coupled for Transport {
    #[inline]
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()> {
        self.rhs(time, y, z, dz)
    }

    fn stage_derivative(&mut self, time: f64, y: &[f64], sink: &mut StageSink<'_>) -> Result<()> {
        if self.rates_in_one_pass() {
            self.rates(time, y, Rates::Stage(sink))
        } else {
            crate::rk4::stage_derivative_stored(self, time, y, sink)
        }
    }
}
