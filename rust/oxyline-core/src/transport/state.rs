//! Per-run state updates: wall laws, volumes, face flows, boundary values, mixing points.

use super::parallel::SharedMut;
#[allow(unused_imports)]
use super::*;

/// Mixing points per chunk of their passes on the run's threads (a point takes ~1 ns).
const MIXING_CHUNK: usize = 8192;

impl Transport {
    /// Initial state: uniform initial concentration of every species in V(P0).
    pub fn initial_state(&mut self, y: &[f64]) -> Result<Vec<f64>> {
        self.ensure_scratch();
        self.volumes(y, 0.0)?;
        let nc = self.plan.cells.len();
        // the largest per-run buffer: a fallible allocation (a typed error, not an abort)
        let mut z = Vec::new();
        crate::error::try_reserve(&mut z, self.state_len(), "transport state")?;
        z.resize(self.state_len(), 0.0);
        let nmix = self.plan.mixing.len();
        for (s, (sp, set)) in self.species.iter_mut().zip(&self.plan.species).enumerate() {
            let ct = set.binding.total(set.initial_free);
            sp.mixing_conc = vec![ct; nmix];
            for i in 0..nc {
                z[s * nc + i] = self.vol[i] * ct;
            }
            let laws = &sp.laws;
            for (k, &(_, _, q_mean)) in laws.relax.iter().enumerate() {
                z[laws.relax_offset + k] = q_mean;
            }
        }
        self.wvol = self.vol.clone();
        self.tissue_initial(&mut z); // tissue hook
        Ok(z)
    }

    /// The cells' lumen volumes V = V0 + C (P − P_ref) at the flow state `y` into `vol`
    /// (in chunks on the run's threads: each cell's own value); an error naming the first
    /// cell whose volume is not positive.
    pub(super) fn volumes(&mut self, y: &[f64], time: f64) -> Result<()> {
        let plan = &*self.plan;
        let volume = |i: usize| plan.v0[i] + plan.cap[i] * (y[plan.volume_unknown(i)] - plan.p_ref);
        let vol = SharedMut::new(&mut self.vol[..plan.cell_node.len()]);
        crate::threads::for_ranges(plan.cell_node.len(), |cells| {
            for i in cells {
                // SAFETY: cell i is in this range alone
                unsafe { *vol.get_mut(i) = volume(i) };
            }
        });
        let nc = plan.cell_node.len();
        let Some(i) = self.vol[..nc].iter().position(|v| v.is_nan() || *v <= 0.0) else {
            return Ok(());
        };
        let (v, n) = (self.vol[i], plan.cell_node[i] as usize);
        Err(Error::solver(
            time,
            format!(
                "lumen volume of transport cell '{}' is {v:.3e} m³ (V0 {:.3e} m³, pressure {:.1} Pa, reference pressure {:.1} Pa): set oxygen reference_pressure closer to the working pressure",
                plan.node_name(n),
                plan.v0[i],
                y[n],
                plan.p_ref
            ),
        ))
    }

    pub(super) fn load_flows(&mut self, time: f64, y: &[f64]) {
        self.load_flows_with(time, |u| y[u]);
    }

    /// Face flows at the α_f level of a step from `y0` to `y1`: Q = Q_0 + α_f (Q_1 − Q_0).
    pub(super) fn load_flows_between(&mut self, time: f64, y0: &[f64], y1: &[f64], alpha_f: f64) {
        self.load_flows_with(time, |u| y0[u] + alpha_f * (y1[u] - y0[u]));
    }

    /// Face flows from `flow(unknown)`, source flows at `time`, and the interior faces of
    /// refined cells.
    pub(super) fn load_flows_with(&mut self, time: f64, flow: impl Fn(usize) -> f64 + Sync + Send) {
        let nf = self.plan.n_flow_faces;
        let unknowns = &self.plan.face_unknowns[..nf];
        crate::threads::for_chunks(&mut self.qf[..nf], |first, qf| {
            for (q, &u) in qf.iter_mut().zip(&unknowns[first..]) {
                *q = flow(u as usize);
            }
        });
        self.load_source_and_chain_flows(time);
    }

    /// Source flows at `time` and the interior faces of refined cells, the flow faces being
    /// loaded.
    pub(super) fn load_source_and_chain_flows(&mut self, time: f64) {
        for (q, (_, w, _)) in self.qs.iter_mut().zip(&self.plan.sources) {
            *q = w.eval(time);
        }
        // interior faces of refined cells: Q_k = Q_A − (k/m)(Q_A − Q_B)
        for ch in &self.plan.chains {
            let q_a = ch.in_faces.iter().map(|&f| self.qf[f]).sum::<f64>()
                + ch.sources.iter().map(|&k| self.qs[k]).sum::<f64>();
            let q_b: f64 = ch.out_faces.iter().map(|&f| self.qf[f]).sum();
            for k in 1..ch.m {
                self.qf[ch.first_face + k - 1] = q_a - (k as f64 / ch.m as f64) * (q_a - q_b);
            }
        }
    }

    /// The values the boundaries carry into the domain for species `s` at `time` into `bval`
    /// (None: zero gradient). When `bval` already holds species `s`, only the prescribed
    /// values change (a tree has thousands of zero-gradient outlets).
    pub(super) fn load_boundary(&mut self, s: usize, time: f64) {
        let sp = &self.plan.species[s];
        let value = |b: &BoundaryValue| match b {
            BoundaryValue::Wave(w) => Some(sp.binding.total(w.eval(time))),
            BoundaryValue::ZeroGradient => None,
        };
        if self.bval_species == s {
            for &k in &sp.waves {
                self.bval[k] = value(&sp.boundary[k]);
            }
        } else {
            for (v, b) in self.bval.iter_mut().zip(&sp.boundary) {
                *v = value(b);
            }
            self.bval_species = s;
        }
        if let Some((k, total)) = self.inflow_override {
            self.bval[k] = Some(total); // closed-loop hook (`closed_loop_tree`)
        }
    }

    /// Total concentration carried by a face from the boundary end `b` next to node `n`:
    /// prescribed, or zero-gradient (the neighbour's value; for a mixing point the value its
    /// sweep used, so that the point stays exactly balanced).
    /// Flow and upwind (donor) concentration of face `fi`.
    #[inline]
    pub(super) fn upwind(&self, fi: usize) -> (f64, f64) {
        let (q, up, other) = oriented(&self.plan.faces, &self.qf, fi);
        let c = match up {
            End::Node(n) => self.conc[n],
            End::Boundary(b) => self.boundary_conc(b, other),
        };
        (q, c)
    }

    #[inline]
    pub(super) fn boundary_conc(&self, b: usize, n: End) -> f64 {
        match n {
            End::Node(n) if self.plan.kind[n] == Kind::Mixing => {
                inflow_value(self.bval[b], self.sweep.lag[n])
            }
            End::Node(n) => inflow_value(self.bval[b], self.conc[n]),
            End::Boundary(_) => inflow_value(self.bval[b], 0.0),
        }
    }

    /// Free concentration of every cell of species `s` (binding inversion, warm-started).
    /// (Without binding the free concentration is the total one: nothing to do.)
    pub(super) fn free_of_cells(&mut self, s: usize) {
        let sp = &mut self.species[s];
        let binding = self.plan.species[s].binding;
        if binding.is_identity() {
            return;
        }
        if sp.anchors.is_empty() {
            for n in self.plan.cells.iter().map(|&n| n as usize) {
                sp.free[n] = binding.free(self.conc[n], sp.free[n]);
            }
        } else {
            for n in self.plan.cells.iter().map(|&n| n as usize) {
                sp.free[n] = binding.free_anchored(self.conc[n], sp.free[n], &mut sp.anchors[n]);
            }
        }
    }

    /// Wall uptake of every cell for species `s` into `w` (mol/s), from the current free
    /// concentrations and branch flows `y`.
    pub(super) fn wall_uptake(&self, s: usize, w: &mut [f64]) {
        let sp = &self.species[s];
        let free = self.free_of(s);
        let laws = &sp.laws;
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            w[i] = laws.fixed_uptake(i, free[n]);
        }
        for &p in &laws.dynamic {
            w[self.plan.pieces[p].cell as usize] +=
                laws.piece_uptake(&self.plan.pieces, p, free, &sp.shear_cbrt);
        }
    }

    /// |Q|^{1/3} seen by the dynamic laws of species `s`, per segment: the branch flow
    /// (instantaneous shear) or the relaxed equivalent flow Q̃ held in the state `z`.
    pub(super) fn load_shear(&mut self, s: usize, y: &[f64], z: &[f64]) {
        let sp = &mut self.species[s];
        let laws = &sp.laws;
        for &j in &laws.dynamic_segs {
            let q = match laws.relax_of_seg.get(j) {
                Some(&k) if k != u32::MAX => z[laws.relax_offset + k as usize],
                _ => y[self.plan.segments[j].branch_unknown as usize],
            };
            sp.shear_cbrt[j] = q.abs().cbrt();
        }
    }

    /// Free concentration per node of species `s`: without binding the total one (no copy).
    #[inline]
    pub(super) fn free_of(&self, s: usize) -> &[f64] {
        if self.plan.species[s].binding.is_identity() {
            &self.conc
        } else {
            &self.species[s].free
        }
    }

    /// Concentrations of the mixing points from their upwind neighbours (flux-weighted).
    pub(super) fn mix(&mut self, s: usize) -> Result<()> {
        if self.plan.mixing.is_empty() {
            return Ok(());
        }
        self.restore_mixing(s);
        // two-face pass-through points next to cells or boundaries: c = Σ_in |Q| C_up / Σ_out |Q|
        for &m in &self.plan.simple_mixing {
            let lag = self.conc[m];
            self.sweep.lag[m] = lag;
            let (mut num, mut den) = (0.0, 0.0);
            for fi in self.plan.faces_at(m) {
                let (q, up, down) = oriented(&self.plan.faces, &self.qf, fi);
                if up == End::Node(m) {
                    den += q.abs();
                } else if down == End::Node(m) {
                    let c = match up {
                        End::Node(u) => self.conc[u],
                        End::Boundary(b) => inflow_value(self.bval[b], lag),
                    };
                    num += q.abs() * c;
                }
            }
            self.conc[m] = if den > 1e-300 { num / den } else { lag };
        }
        if self.plan.general_mixing.is_empty() {
            self.save_mixing(s);
            return Ok(());
        }
        let nn = self.plan.kind.len();
        let mut d = std::mem::take(&mut self.sweep.d);
        let mut b = std::mem::take(&mut self.sweep.b);
        d.resize(nn, 0.0);
        b.resize(nn, 0.0);
        for &m in &self.plan.mixing {
            d[m] = 0.0;
            b[m] = 0.0;
        }
        let mut x = std::mem::take(&mut self.conc);
        let plan = Arc::clone(&self.plan);
        let res = self.sweep_solve(&plan.general_mixing, &d, &b, &mut x);
        self.conc = x;
        self.sweep.d = d;
        self.sweep.b = b;
        self.save_mixing(s);
        res
    }

    /// The mixing points' values of species `s` back into `conc` (in chunks on the run's
    /// threads: every point its own node).
    pub(super) fn restore_mixing(&mut self, s: usize) {
        let (mc, mixing) = (&self.species[s].mixing_conc, &self.plan.mixing);
        if mc.len() == mixing.len() {
            let conc = SharedMut::new(&mut self.conc);
            crate::threads::for_ranges_of(mixing.len(), MIXING_CHUNK, |points| {
                for k in points {
                    // SAFETY: each mixing point is its own node, in this range alone
                    unsafe { *conc.get_mut(mixing[k]) = mc[k] };
                }
            });
        }
    }

    /// The mixing points' values of species `s` kept (in chunks on the run's threads).
    pub(super) fn save_mixing(&mut self, s: usize) {
        let (mixing, conc) = (&self.plan.mixing, &self.conc);
        let mc = &mut self.species[s].mixing_conc;
        mc.resize(mixing.len(), 0.0);
        let saved = SharedMut::new(mc);
        crate::threads::for_ranges_of(mixing.len(), MIXING_CHUNK, |points| {
            for k in points {
                // SAFETY: element k is in this range alone
                unsafe { *saved.get_mut(k) = conc[mixing[k]] };
            }
        });
    }
}

impl Transport {
    /// Everything a run carries from step to step outside the amounts `z` that changes its
    /// results: volumes, concentrations (warm starts and the lagged values of mixing points and
    /// boundaries), free concentrations and Hill anchors (warm starts of the binding
    /// inversion). A run restored from it with [`Transport::restore_carried`] continues bit
    /// for bit (checkpoints, `run::checkpoint`).
    pub fn carried(&self) -> Vec<f64> {
        let mut out = Vec::new();
        out.extend_from_slice(&self.vol);
        out.extend_from_slice(&self.wvol);
        out.extend_from_slice(&self.conc);
        out.extend_from_slice(&self.sweep.lag);
        for sp in &self.species {
            out.extend_from_slice(&sp.free);
            out.extend_from_slice(&sp.mixing_conc);
            out.extend(sp.anchors.iter().flat_map(|a| a.to_array()));
        }
        out
    }

    /// Restore [`Transport::carried`] into a run started with the same model and settings
    /// (its buffers then have the lengths the checkpoint's had).
    pub fn restore_carried(&mut self, carried: &[f64]) -> Result<()> {
        let expected = self.carried_len();
        if carried.len() != expected {
            return Err(Error::model(
                "checkpoint",
                format!(
                    "the transport state has {} values, this model's has {expected}: the \
                     checkpoint is of another model",
                    carried.len()
                ),
            ));
        }
        let mut rest = carried;
        let fill = |rest: &mut &[f64], dst: &mut [f64]| dst.copy_from_slice(next(rest, dst.len()));
        fill(&mut rest, &mut self.vol);
        fill(&mut rest, &mut self.wvol);
        fill(&mut rest, &mut self.conc);
        fill(&mut rest, &mut self.sweep.lag);
        for sp in &mut self.species {
            fill(&mut rest, &mut sp.free);
            fill(&mut rest, &mut sp.mixing_conc);
            let flat = next(&mut rest, sp.anchors.len() * HillAnchor::CARRIED);
            for (a, v) in sp.anchors.iter_mut().zip(flat.chunks(HillAnchor::CARRIED)) {
                *a = HillAnchor::from_array(v);
            }
        }
        Ok(())
    }

    /// The length of [`Transport::carried`] (without building it: an error-controlled run
    /// restores the carried state after every species output row).
    fn carried_len(&self) -> usize {
        let species = self.species.iter().map(|sp| {
            sp.free.len() + sp.mixing_conc.len() + sp.anchors.len() * HillAnchor::CARRIED
        });
        self.vol.len()
            + self.wvol.len()
            + self.conc.len()
            + self.sweep.lag.len()
            + species.sum::<usize>()
    }
}

/// The first `n` values of `rest`, which moves past them.
fn next<'a>(rest: &mut &'a [f64], n: usize) -> &'a [f64] {
    let (head, tail) = rest.split_at(n);
    *rest = tail;
    head
}
