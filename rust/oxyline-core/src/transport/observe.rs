//! Observation: the recorded species columns.

use super::parallel::SharedMut;
#[allow(unused_imports)]
use super::*;

/// Output vessels per task of a row's observation on the run's threads (and half the least
/// number of vessels for which it is split): a vessel takes ~0.1 µs, a task a few µs to start.
const OBSERVE_CHUNK: usize = 2048;

impl Transport {
    /// Append the recorded columns of every species at (t, y) to `out`.
    /// `ydot`: flow derivative (for R_i = dL_i/dt); `implicit`: use the transport volumes.
    pub fn observe(
        &mut self,
        time: f64,
        y: &[f64],
        ydot: Option<&[f64]>,
        z: &[f64],
        implicit: bool,
        out: &mut Vec<f64>,
    ) -> Result<()> {
        self.ensure_scratch();
        self.update_wall_flux(time);
        let nc = self.plan.cells.len();
        let nsp = self.species.len();
        self.volumes(y, time)?;
        if implicit && !self.wvol.is_empty() {
            self.vol.copy_from_slice(&self.wvol);
        }
        self.load_flows(time, y);
        for s in 0..nsp {
            let (cells, vol, zs) = (
                &self.plan.cells[..],
                &self.vol[..],
                &z[s * nc..(s + 1) * nc],
            );
            let conc = SharedMut::new(&mut self.conc);
            crate::threads::for_ranges(nc, |range| {
                for i in range {
                    // SAFETY: every cell is its own node, and in this range alone
                    unsafe { *conc.get_mut(cells[i] as usize) = zs[i] / vol[i] };
                }
            });
            self.load_boundary(s, time);
            self.mix(s)?;
            self.free_of_nodes(s);
            self.load_shear(s, y, z);
            if !self.plan.tissue.is_empty() {
                self.tissue_wall_fluxes(s, z); // tissue hook: W − g c per segment
            }
            self.observe_vessels(s, out);
            // not recorded (see `set_recorded_columns`): neither computed nor written (the
            // recorder knows the gap: `unwritten_columns`)
            if self.segment_output {
                self.observe_segments(s, y, ydot, out);
            }
            let stored: f64 = z[s * nc..(s + 1) * nc].iter().sum();
            let acc = &z[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            out.extend([stored, acc[0], acc[1], acc[2], acc[3]]);
            if !self.plan.tissue.is_empty() {
                self.observe_tissue(s, z, out); // tissue hook
            }
        }
        Ok(())
    }

    /// Free concentration of every non-exterior node of species `s` (NaN outside the
    /// domain): Hill's by the anchored series where it is within its tolerance (1e-12 mmHg,
    /// the cells' anchors of the steps), else the exact inversion, warm-started. Without
    /// binding it is the total one, read from `conc` where needed (`free_at`).
    fn free_of_nodes(&mut self, s: usize) {
        let binding = self.plan.species[s].binding;
        if binding.is_identity() {
            return;
        }
        let sp = &mut self.species[s];
        for (n, kind) in self.plan.kind.iter().enumerate() {
            sp.free[n] = match kind {
                Kind::Exterior => f64::NAN,
                _ => {
                    let guess = if sp.free[n].is_finite() {
                        sp.free[n]
                    } else {
                        0.0
                    };
                    match sp.anchors.get_mut(n) {
                        Some(a) => binding.free_anchored(self.conc[n], guess, a),
                        None => binding.free(self.conc[n], guess),
                    }
                }
            };
        }
    }

    /// Free concentration of node `n` for species `s` after `free_of_nodes` (NaN outside the
    /// domain).
    #[inline]
    fn free_at(&self, s: usize, n: usize) -> f64 {
        match self.plan.kind[n] {
            Kind::Exterior => f64::NAN,
            _ => self.free_of(s)[n],
        }
    }

    /// Advective flux and upwind free concentration of face `fi` (NaN without a face). An
    /// upwind domain node's free concentration is the one `free_of_nodes` found for its total
    /// (the same inversion within its tolerance, docs/oxygen.md): re-inverting Hill's law from
    /// a cold start at every vessel end cost more than the whole observation otherwise.
    fn face_flux(&self, s: usize, fi: usize) -> (f64, f64) {
        if fi >= self.plan.faces.len() {
            return (f64::NAN, f64::NAN);
        }
        let (q, c) = self.upwind(fi);
        let free = self.free_upwind(s, oriented(&self.plan.faces, &self.qf, fi).1, c);
        (q * c, free)
    }

    /// Free concentration of the total `c` carried from the upwind end `up`: a domain node's
    /// own inversion (`free_of_nodes`), a boundary's value inverted here.
    fn free_upwind(&self, s: usize, up: End, c: f64) -> f64 {
        let binding = self.plan.species[s].binding;
        match up {
            End::Node(n) if !binding.is_identity() && self.plan.kind[n] != Kind::Exterior => {
                self.species[s].free[n]
            }
            _ => binding.free(c, c),
        }
    }

    /// Total and free concentration carried into node `n` by the faces and flow sources that
    /// bring flow into it (flow-weighted), or the node's own when nothing flows in. The
    /// interior faces of a refined cell are not inflows from outside it.
    fn carried_into(&self, s: usize, n: usize) -> (f64, f64) {
        let p = &self.plan;
        let (mut q_in, mut j_in, mut count, mut free) = (0.0, 0.0, 0usize, f64::NAN);
        for fi in p.faces_at(n) {
            let (q, up, _) = oriented(&p.faces, &self.qf, fi);
            if fi >= p.n_flow_faces || q == 0.0 || up == End::Node(n) {
                continue;
            }
            let c = self.upwind(fi).1;
            (q_in, j_in, count) = (q_in + q.abs(), j_in + q.abs() * c, count + 1);
            free = self.free_upwind(s, up, c);
        }
        for &k in p.node_sources(n) {
            let q = self.qs[k as usize];
            if q > 0.0 {
                let c = self.boundary_conc(p.sources[k as usize].2, End::Node(n));
                (q_in, j_in, count) = (q_in + q, j_in + q * c, count + 1);
                free = self.free_upwind(s, End::Boundary(0), c);
            }
        }
        match count {
            0 => (self.conc[n], self.free_at(s, n)),
            1 => (j_in / q_in, free),
            _ => {
                let c = j_in / q_in;
                let binding = self.plan.species[s].binding;
                (c, binding.free(c, self.free_at(s, n)))
            }
        }
    }

    /// Flux and free concentration at a vessel's inlet: with a cell holding its first
    /// segment's share at the inlet, the value carried into that cell (the upwind value of
    /// the faces entering it) at forward flow, the cell's own at backflow; else its first
    /// face's.
    fn vessel_inlet(&self, s: usize, v: &OutVessel) -> (f64, f64) {
        if v.inlet_cell == u32::MAX || v.first >= self.plan.faces.len() {
            return self.face_flux(s, v.first);
        }
        let (n, q) = (v.inlet_cell as usize, self.qf[v.first]);
        let (c, free) = if q >= 0.0 {
            self.carried_into(s, n)
        } else {
            (self.conc[n], self.free_at(s, n))
        };
        (q * c, free)
    }

    /// Flux and free concentration at a vessel's outlet: with a cell holding its last
    /// segment's share at the outlet, that cell's value at forward flow (what leaves it), the
    /// value carried into it at backflow; else its last face's.
    fn vessel_outlet(&self, s: usize, v: &OutVessel) -> (f64, f64) {
        if v.outlet_cell == u32::MAX || v.last >= self.plan.faces.len() {
            return self.face_flux(s, v.last);
        }
        let (n, q) = (self.plan.last_sub(v.outlet_cell as usize), self.qf[v.last]);
        let (c, free) = if q >= 0.0 {
            (self.conc[n], self.free_at(s, n))
        } else {
            self.carried_into(s, n)
        };
        (q * c, free)
    }

    /// Wall uptake of segment `j` for species `s` (mol/s).
    fn segment_wall(&self, s: usize, j: usize) -> f64 {
        let sp = &self.species[s];
        let free = self.free_of(s);
        let w: f64 = self
            .plan
            .seg_pieces(j)
            .map(|p| {
                sp.laws
                    .piece_uptake(&self.plan.pieces, p, free, &sp.shear_cbrt)
            })
            .sum();
        // tissue hook: the closure's g c corrected to the flux into the wall
        match self.tissue.seg_corr.get(j) {
            Some(corr) => w + corr,
            None => w,
        }
    }

    /// Per output vessel: inlet and outlet concentration and flux, wall uptake. A large
    /// tree's vessels go in fixed chunks on the run's threads (`crate::threads`): each
    /// vessel's five values are computed from the loaded state alone and written to its own
    /// place in the row, so the row is the same on any number of threads.
    fn observe_vessels(&self, s: usize, out: &mut Vec<f64>) {
        use rayon::prelude::*;
        let vessels = &self.plan.out_vessels;
        let start = out.len();
        out.resize(start + VESSEL_COLUMNS * vessels.len(), 0.0);
        let rows = &mut out[start..];
        let chunk = |(c, rows): (usize, &mut [f64])| {
            let first = c * OBSERVE_CHUNK;
            for (v, row) in vessels[first..]
                .iter()
                .zip(rows.chunks_exact_mut(VESSEL_COLUMNS))
            {
                row.copy_from_slice(&self.vessel_values(s, v));
            }
        };
        let width = VESSEL_COLUMNS * OBSERVE_CHUNK;
        match crate::threads::pool().filter(|_| vessels.len() >= 2 * OBSERVE_CHUNK) {
            Some(pool) => {
                pool.install(|| rows.par_chunks_mut(width).enumerate().for_each(chunk));
            }
            None => rows.chunks_mut(width).enumerate().for_each(chunk),
        }
    }

    /// One output vessel's inlet and outlet concentration and flux, and wall uptake.
    fn vessel_values(&self, s: usize, v: &OutVessel) -> [f64; VESSEL_COLUMNS] {
        let (j_in, c_in) = self.vessel_inlet(s, v);
        let (j_out, c_out) = self.vessel_outlet(s, v);
        let wall: f64 = self.plan.out_segments[v.segs.clone()]
            .iter()
            .map(|&j| self.segment_wall(s, j as usize))
            .sum();
        [c_in, c_out, j_in, j_out, wall]
    }

    /// Per output segment: concentration, flux, wall uptake and the transmission-line
    /// elements R_i, L_i.
    fn observe_segments(&self, s: usize, y: &[f64], ydot: Option<&[f64]>, out: &mut Vec<f64>) {
        for j in self.plan.out_segments.iter().map(|&j| j as usize) {
            let seg = &self.plan.segments[j];
            let (flux, _) = self.face_flux(s, seg.face as usize);
            let (mut c, mut wsum, mut vseg, mut dvseg) = (0.0, 0.0, 0.0, 0.0);
            for (n, share) in seg.node_shares() {
                if share > 0.0 {
                    // a refined node reports its last sub-cell: the value its outgoing faces
                    // carry
                    c += share * self.free_at(s, self.plan.last_sub(n));
                    wsum += share;
                    vseg += share * (seg.volume + seg.compliance * (y[n] - self.plan.p_ref));
                    if let Some(yd) = ydot {
                        dvseg += share * seg.compliance * yd[n];
                    }
                }
            }
            let c = if wsum > 0.0 { c / wsum } else { f64::NAN };
            let (r_tl, l_tl) = self.line_elements(seg, y, ydot, vseg, dvseg);
            out.extend([c, flux, self.segment_wall(s, j), r_tl, l_tl]);
        }
    }

    /// Transmission-line elements of a segment (docs/physics.md §2.6): v = Q/A, A = V_seg/dx,
    /// L = −dx/v, R = dL/dt = dx v̇/v²; NaN below the velocity threshold.
    fn line_elements(
        &self,
        seg: &Segment,
        y: &[f64],
        ydot: Option<&[f64]>,
        vseg: f64,
        dvseg: f64,
    ) -> (f64, f64) {
        let (dx, u) = (seg.dx(), seg.branch_unknown as usize);
        let q = y[u];
        let (mut r_tl, mut l_tl) = (f64::NAN, f64::NAN);
        if dx > 0.0 && vseg > 0.0 {
            let a = vseg / dx;
            let v = q / a;
            if v.abs() >= self.plan.v_eps {
                l_tl = -dx / v;
                if let Some(yd) = ydot {
                    let vdot = yd[u] / a - q * (dvseg / dx) / (a * a);
                    r_tl = dx * vdot / (v * v);
                }
            }
        }
        (r_tl, l_tl)
    }
}
