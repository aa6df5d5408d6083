//! The species' own stiffness (wall exchange, decay) for the explicit RK4 step: the advection
//! Courant bound (`max_outflow_rate`) does not see it.

#[allow(unused_imports)]
use super::*;

/// The largest reaction rate of a run's species and where it sits.
#[derive(Debug, Clone, PartialEq)]
pub struct ReactionRate {
    /// Rate (1/s): RK4 on that cell alone needs dt ≤ 2.785 / rate.
    pub rate: f64,
    pub species: String,
    /// Cell index in the species block of the state.
    pub cell: usize,
}

impl Transport {
    /// max over species and cells of decay + G_i / V_i (1/s), at flow state `y`: G_i is the
    /// cell's summed wall conductance of its fixed wall laws (uptake G c − …, linear in the free
    /// concentration). Binding only lowers the free share of the amount (d free / d total ≤ 1),
    /// so the bound holds with it too. Shear-dependent (dynamic) wall pieces are evaluated at
    /// the run's shear and are not included. None when no species has a rate or the volumes
    /// are not positive (left to the run to report).
    pub fn max_reaction_rate(&mut self, y: &[f64], time: f64) -> Option<ReactionRate> {
        self.ensure_scratch();
        self.volumes(y, time).ok()?;
        let mut best: Option<ReactionRate> = None;
        for (sp, settings) in self.species.iter().zip(&self.plan.species) {
            let laws = &sp.laws;
            for (i, v) in self.vol.iter().enumerate() {
                let wall = if laws.has_wall {
                    laws.cell_g[i] / v
                } else {
                    0.0
                };
                let rate = settings.decay + wall;
                if rate > best.as_ref().map_or(0.0, |b| b.rate) {
                    best = Some(ReactionRate {
                        rate,
                        species: settings.name.clone(),
                        cell: i,
                    });
                }
            }
        }
        self.tissue_max_rate(&mut best); // tissue hook: radial diffusion and consumption
        best
    }
}

impl Transport {
    /// The vessel (index in the circuit's vessel names) of transport cell `cell`: that of a
    /// segment whose volume the cell holds (for messages; a linear scan). None for a cell of
    /// a node without vessel segments.
    pub fn cell_vessel(&self, cell: usize) -> Option<usize> {
        (0..self.plan.segments.len())
            .find(|&j| self.segment_cells(j).is_some_and(|c| c.contains(&cell)))
            .or_else(|| {
                // a junction cell holds the end shares of several segments
                let node = *self.plan.cell_node.get(cell)? as usize;
                self.plan
                    .segments
                    .iter()
                    .position(|s| s.nodes.contains(&(node as u32)))
            })
            .map(|j| self.plan.segment_vessels[j] as usize)
    }

    /// A cheap check of the species amounts `z` (once per output row): the first non-finite
    /// one is a solver error naming the species, the place (the cell's node: vessel and
    /// segment) and the time, so a step too large for a stiff exchange, decay or binding stops
    /// the run with its partial result instead of writing NaN.
    /// `vessel_name` names a vessel index of the circuit (the error names the vessel too).
    pub fn check_finite(
        &self,
        z: &[f64],
        time: f64,
        vessel_name: &dyn Fn(usize) -> Option<String>,
    ) -> Result<()> {
        let nc = self.plan.cells.len();
        for (s, sp) in self.plan.species.iter().enumerate() {
            let block = &z[s * nc..(s + 1) * nc];
            if let Some(i) = block.iter().position(|v| !v.is_finite()) {
                let vessel = self
                    .cell_vessel(i)
                    .and_then(vessel_name)
                    .map_or_else(String::new, |v| format!("vessel '{v}', "));
                return Err(Error::solver(
                    time,
                    format!(
                        "species '{}': amount {} in {vessel}the cell of node '{}' (t = {time:.6} s): the step is too large \
                         for its wall exchange, decay or binding; lower dt or use \
                         generalized-alpha",
                        sp.name,
                        block[i],
                        self.plan.circuit_node_name(self.plan.cell_node[i] as usize)
                    ),
                ));
            }
        }
        Ok(())
    }
}
