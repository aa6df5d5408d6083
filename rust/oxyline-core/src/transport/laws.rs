//! The wall laws of every species, evaluated per wall piece and summed per cell.

#[allow(unused_imports)]
use super::*;

/// The cycle means of every segment's flow that the closures read (two-pass run).
#[derive(Clone, Copy)]
pub(super) struct MeanFlows<'a> {
    /// ⟨|Q|⟩.
    pub abs: &'a [f64],
    /// ⟨max(±Q, 0)⟩ in the direction of the net flow (= `abs` without reversal).
    pub forward: &'a [f64],
    /// Per species, per segment: the inlet-renewal factor on the Graetz law of the net mean
    /// flow (`closure::renewal::segment_factors`); empty (or an empty species entry) without
    /// the flow harmonics, and then `flow: inlet-renewal` walls read the forward mean.
    pub renewal: &'a [Vec<f64>],
}

/// Position of every segment in its vessel, counted in segment order (from the inlet).
fn segment_index_in_vessel(segment_vessels: &[u32], n_vessels: usize) -> Vec<usize> {
    let mut count = vec![0usize; n_vessels];
    segment_vessels
        .iter()
        .map(|&v| {
            let k = count[v as usize];
            count[v as usize] += 1;
            k
        })
        .collect()
}

/// A segment with a wall to exchange through (a radius and a length).
fn has_area(seg: &Segment) -> bool {
    seg.wall.radius > 0.0 && seg.dx() > 0.0
}

/// The segments of relaxed-shear walls, each with its relaxation time and cycle-mean |Q|.
fn relaxed_segments(plan: &Plan, sp: &SpeciesPlan, mean_abs: &[f64]) -> Vec<(usize, f64, f64)> {
    let mut relax = Vec::new();
    for (j, seg) in plan.segments.iter().enumerate() {
        if sp.walls[plan.segment_vessels[j] as usize].is_relaxed() && has_area(seg) {
            let tau = closure::relaxation_time(&seg.wall, sp.diffusivity, mean_abs[j]);
            relax.push((j, tau, mean_abs[j]));
        }
    }
    relax
}

/// The mean flow a wall's closure reads at segment `j` and the renewal factor it scales by.
pub(super) fn closure_mean_flow(
    wall: &WallSpec,
    j: usize,
    mean: MeanFlows<'_>,
    renewal: &[f64],
) -> (f64, f64) {
    match wall.mean_flow() {
        closure::MeanFlow::CycleMean => (mean.abs[j], 1.0),
        closure::MeanFlow::InletRenewal if !renewal.is_empty() => (
            closure::renewal::net_mean(mean.abs[j], mean.forward[j]),
            renewal[j],
        ),
        closure::MeanFlow::ForwardMean | closure::MeanFlow::InletRenewal => (mean.forward[j], 1.0),
    }
}

impl Laws {
    /// The laws of every species of `plan` for the cycle means `mean` (per segment: ⟨|Q|⟩
    /// and the forward-flow mean, see `closure::MeanFlow`). Before the final pass
    /// (`final_pass` false: at build, before the mean flow is known) the closures that need
    /// the mean flow get a zero wall and no relaxed shear.
    pub(super) fn evaluate_all(
        plan: &Plan,
        mean: MeanFlows<'_>,
        final_pass: bool,
    ) -> Result<Vec<Laws>> {
        let mut offset = plan.species.len() * (plan.cells.len() + 4);
        let mut all = Vec::with_capacity(plan.species.len());
        for (k, sp) in plan.species.iter().enumerate() {
            let renewal = mean.renewal.get(k).map_or(&[][..], |r| &r[..]);
            let mut laws = Laws::evaluate(plan, sp, mean, renewal, final_pass)?;
            laws.relax_offset = offset;
            offset += laws.relax.len();
            all.push(laws);
        }
        Ok(all)
    }

    fn evaluate(
        plan: &Plan,
        sp: &SpeciesPlan,
        mean: MeanFlows<'_>,
        renewal: &[f64],
        final_pass: bool,
    ) -> Result<Laws> {
        let nc = plan.cells.len();
        let mut l = Laws {
            cell_g: vec![0.0; nc],
            cell_gcw: vec![0.0; nc],
            cell_q: vec![0.0; nc],
            ..Laws::default()
        };
        if final_pass {
            l.relax = relaxed_segments(plan, sp, mean.abs);
        }
        let element = format!("species '{}' wall", sp.name);
        l.laws.reserve_exact(plan.pieces.len());
        let index = segment_index_in_vessel(&plan.segment_vessels, sp.walls.len());
        let mut tables = wall_flux::TableBuilder::new(sp.walls.len());
        for (p, piece) in plan.pieces.iter().enumerate() {
            let j = piece.seg as usize;
            let seg = &plan.segments[j];
            let vessel = plan.segment_vessels[j] as usize;
            let vessel_wall = &sp.walls[vessel];
            if let WallSpec::Flux { flux } = vessel_wall {
                if has_area(seg) && flux.table().is_some() {
                    tables.add(vessel, flux, (p, piece, plan.piece_wall(piece)), index[j]);
                }
            }
            let law = if !has_area(seg) || (vessel_wall.needs_mean_flow() && !final_pass) {
                SegmentLaw::Fixed {
                    g: 0.0,
                    cw: 0.0,
                    q: 0.0,
                }
            } else {
                let (q_mean, scale) = closure_mean_flow(vessel_wall, j, mean, renewal);
                vessel_wall.segment_law_scaled(
                    &plan.piece_wall(piece),
                    index[j],
                    sp.diffusivity,
                    q_mean,
                    scale,
                    &element,
                )?
            };
            l.push_law(p, piece, law);
        }
        l.finish(plan.segments.len(), tables);
        Ok(l)
    }

    /// Adds piece `p`'s law: a fixed law to its cell's sums (by the piece's share), an
    /// instantaneous one to the pieces evaluated each step.
    fn push_law(&mut self, p: usize, piece: &Piece, law: SegmentLaw) {
        let j = piece.seg as usize;
        match law {
            SegmentLaw::Fixed { g, cw, q } => {
                let (c, share) = (piece.cell as usize, piece.share);
                self.cell_g[c] += share * g;
                self.cell_gcw[c] += share * g * cw;
                self.cell_q[c] += share * q;
            }
            SegmentLaw::Instantaneous { .. } => {
                self.dynamic.push(p);
                // pieces are contiguous per segment
                if self.dynamic_segs.last() != Some(&j) {
                    self.dynamic_segs.push(j);
                }
            }
        }
        self.laws.push(law);
    }

    /// The per-cell and per-segment indexes once every piece's law is in.
    fn finish(&mut self, n_segments: usize, tables: wall_flux::TableBuilder) {
        if !self.relax.is_empty() {
            self.relax_of_seg = vec![u32::MAX; n_segments];
            for (k, &(j, _, _)) in self.relax.iter().enumerate() {
                self.relax_of_seg[j] = k as u32;
            }
        }
        self.cell_wc = self
            .cell_q
            .iter()
            .zip(&self.cell_gcw)
            .map(|(q, gcw)| q - gcw)
            .collect();
        self.flux_tables = tables.finish(&self.cell_q);
        self.has_wall = !self.dynamic.is_empty()
            || self.flux_tables.is_some()
            || self.cell_g.iter().any(|&g| g != 0.0)
            || self.cell_q.iter().any(|&q| q != 0.0);
    }

    /// Wall uptake (mol/s) of cell `i` from its fixed laws at free concentration `free`:
    /// Σ share·(g (c − c_w) + q) = G c − Σ share g c_w + Q (the wall-uptake law, docs/physics.md §3).
    #[inline]
    pub(super) fn fixed_uptake(&self, i: usize, free: f64) -> f64 {
        self.cell_g[i] * free - self.cell_gcw[i] + self.cell_q[i]
    }

    /// The fixed wall uptake of cell `i` linearised in the total concentration about the old
    /// state (total `c`, free `free`, dc/dC_t = `inv_slope` there): W ≈ wl·C_t + wc, returns
    /// (wl, wc) (the implicit step's binding rows, docs/physics.md §4).
    #[inline(always)]
    pub(super) fn linearised_uptake(
        &self,
        i: usize,
        free: f64,
        inv_slope: f64,
        c: f64,
    ) -> (f64, f64) {
        let wl = self.cell_g[i] * inv_slope;
        (wl, self.fixed_uptake(i, free) - wl * c)
    }

    /// Wall uptake (mol/s) of wall piece `p` with its own law (any kind) at the current shear
    /// (`shear_cbrt` per segment, read by dynamic laws only), `free` the free concentration
    /// per node.
    #[inline]
    pub(super) fn piece_uptake(
        &self,
        pieces: &[Piece],
        p: usize,
        free: &[f64],
        shear_cbrt: &[f64],
    ) -> f64 {
        let pc = &pieces[p];
        let (g, cw, q) = match self.laws[p] {
            SegmentLaw::Fixed { g, cw, q } => (g, cw, q),
            law => law.eval_cbrt(shear_cbrt[pc.seg as usize]),
        };
        pc.share * (g * (free[pc.node as usize] - cw) + q)
    }
}
