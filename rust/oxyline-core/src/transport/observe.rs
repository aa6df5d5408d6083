//! Observation: the recorded species columns.

#[allow(unused_imports)]
use super::*;

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
        let nc = self.plan.cells.len();
        let nsp = self.species.len();
        self.volumes(y, time)?;
        if implicit && !self.wvol.is_empty() {
            self.vol.copy_from_slice(&self.wvol);
        }
        self.load_flows(time, y);
        for s in 0..nsp {
            for (i, &n) in self.plan.cells.iter().enumerate() {
                self.conc[n] = z[s * nc + i] / self.vol[i];
            }
            self.load_boundary(s, time);
            self.mix(s)?;
            // free concentration of every non-exterior node
            {
                let sp = &mut self.species[s];
                for n in 0..self.plan.kind.len() {
                    sp.free[n] = match self.plan.kind[n] {
                        Kind::Exterior => f64::NAN,
                        _ => sp.binding.free(
                            self.conc[n],
                            if sp.free[n].is_finite() {
                                sp.free[n]
                            } else {
                                0.0
                            },
                        ),
                    };
                }
            }
            self.load_shear(s, y, z);
            let sp = &self.species[s];
            let face_flux = |tr: &Self, unknown: usize| -> (f64, f64) {
                let fi = tr
                    .plan
                    .face_of_unknown
                    .get(unknown)
                    .copied()
                    .unwrap_or(usize::MAX);
                if fi == usize::MAX {
                    return (f64::NAN, f64::NAN);
                }
                let (q, c) = tr.upwind(fi);
                (q * c, sp.binding.free(c, c))
            };
            let seg_wall = |j: usize| -> f64 {
                self.plan.seg_pieces[j]
                    .clone()
                    .map(|p| sp.piece_uptake(&self.plan.pieces, p, &sp.free))
                    .sum()
            };
            for v in &self.plan.out_vessels {
                let (j_in, c_in) = face_flux(self, v.first);
                let (j_out, c_out) = face_flux(self, v.last);
                let wall: f64 = self.plan.out_segments[v.segs.clone()]
                    .iter()
                    .map(|&j| seg_wall(j))
                    .sum();
                out.extend([c_in, c_out, j_in, j_out, wall]);
            }
            let segs: &[usize] = if self.segment_output {
                &self.plan.out_segments
            } else {
                &[]
            };
            for &j in segs {
                let seg = &self.plan.segments[j];
                let (flux, _) = face_flux(self, seg.branch_unknown);
                let (mut c, mut wsum, mut vseg, mut dvseg) = (0.0, 0.0, 0.0, 0.0);
                for &(n, share) in &seg.nodes {
                    if share > 0.0 {
                        // a refined node reports its last sub-cell: the value its
                        // outgoing faces carry
                        c += share * sp.free[self.plan.last_sub[n]];
                        wsum += share;
                        vseg += share * (seg.volume + seg.compliance * (y[n] - self.plan.p_ref));
                        if let Some(yd) = ydot {
                            dvseg += share * seg.compliance * yd[n];
                        }
                    }
                }
                let c = if wsum > 0.0 { c / wsum } else { f64::NAN };
                // transmission-line elements (docs/physics.md §2.6): v = Q/A, A = V_seg/dx,
                // L = −dx/v, R = dL/dt = dx v̇/v²
                let q = y[seg.branch_unknown];
                let (mut r_tl, mut l_tl) = (f64::NAN, f64::NAN);
                if seg.dx > 0.0 && vseg > 0.0 {
                    let a = vseg / seg.dx;
                    let v = q / a;
                    if v.abs() >= self.plan.v_eps {
                        l_tl = -seg.dx / v;
                        if let Some(yd) = ydot {
                            let vdot = yd[seg.branch_unknown] / a - q * (dvseg / seg.dx) / (a * a);
                            r_tl = seg.dx * vdot / (v * v);
                        }
                    }
                }
                out.extend([c, flux, seg_wall(j), r_tl, l_tl]);
            }
            let stored: f64 = z[s * nc..(s + 1) * nc].iter().sum();
            let acc = &z[nsp * nc + 4 * s..nsp * nc + 4 * s + 4];
            out.extend([stored, acc[0], acc[1], acc[2], acc[3]]);
        }
        Ok(())
    }
}
