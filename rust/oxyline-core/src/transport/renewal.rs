//! The inlet-renewal closure's per-vessel data (docs/physics.md §3.6): which flow unknowns
//! the first pass must resolve in time (one per vessel with a `flow: inlet-renewal` wall), and
//! the per-segment factors it gives once their harmonics are known (`run::flow_harmonics`).

use super::laws::MeanFlows;
use super::*;
use crate::closure::renewal::{PeriodicFlow, net_mean, segment_factors};
use nalgebra::Complex;

/// One vessel's periodic inlet flow measured by the first pass: Q(t) = mean + Re Σ_k
/// harmonics[k − 1] e^{ikωt}.
#[derive(Debug, Clone)]
pub struct VesselFlow {
    pub vessel: usize,
    pub mean: f64,
    pub harmonics: Vec<Complex<f64>>,
}

impl Transport {
    /// (vessel, flow unknown of its first segment) of every vessel whose wall, for any
    /// species, uses the inlet renewal: the flows whose harmonics the first pass records.
    pub fn renewal_inlets(&self) -> Vec<(usize, usize)> {
        let p = &self.plan;
        let renews = |v: usize| {
            p.species.iter().any(|s| {
                s.walls
                    .get(v)
                    .is_some_and(|w| w.mean_flow() == closure::MeanFlow::InletRenewal)
                    && matches!(s.walls[v], WallSpec::Graetz { .. })
            })
        };
        let mut seen = vec![false; p.species.first().map_or(0, |s| s.walls.len())];
        let mut out = Vec::new();
        for (j, seg) in p.segments.iter().enumerate() {
            let v = p.segment_vessels[j] as usize;
            if v < seen.len() && !seen[v] && seg.branch_unknown != u32::MAX && renews(v) {
                seen[v] = true;
                out.push((v, seg.branch_unknown as usize));
            }
        }
        out
    }

    /// [`Transport::set_mean_flows`] with the inlet renewal of every vessel in `flows` (the
    /// first pass's periodic inlet flow, period `period`): per species and segment the factor
    /// of `closure::renewal::segment_factors` on the Graetz law of the net mean flow.
    pub fn set_mean_flows_renewed(
        &mut self,
        mean_abs: &[f64],
        mean_forward: &[f64],
        period: f64,
        flows: &[VesselFlow],
    ) -> Result<()> {
        let renewal = self.renewal_factors(mean_abs, mean_forward, period, flows)?;
        self.set_laws(MeanFlows {
            abs: mean_abs,
            forward: mean_forward,
            renewal: &renewal,
        })
    }

    fn renewal_factors(
        &self,
        mean_abs: &[f64],
        mean_forward: &[f64],
        period: f64,
        flows: &[VesselFlow],
    ) -> Result<Vec<Vec<f64>>> {
        let p = &self.plan;
        let mut segs_of = vec![Vec::new(); p.species.first().map_or(0, |s| s.walls.len())];
        for (j, &v) in p.segment_vessels.iter().enumerate() {
            if let Some(s) = segs_of.get_mut(v as usize) {
                s.push(j);
            }
        }
        let mut all = Vec::with_capacity(p.species.len());
        for sp in &p.species {
            let mut factors = vec![1.0; p.segments.len()];
            for f in flows {
                let WallSpec::Graetz {
                    flow: closure::MeanFlow::InletRenewal,
                    kinematic_viscosity,
                    ..
                } = sp.walls[f.vessel]
                else {
                    continue;
                };
                let js = &segs_of[f.vessel];
                let walls: Vec<_> = js.iter().map(|&j| p.segments[j].wall).collect();
                let net: Vec<f64> = js
                    .iter()
                    .map(|&j| net_mean(mean_abs[j], mean_forward[j]))
                    .collect();
                let abs: Vec<f64> = js.iter().map(|&j| mean_abs[j]).collect();
                let flow = PeriodicFlow {
                    period,
                    mean: f.mean,
                    harmonics: &f.harmonics,
                };
                let element = format!("species '{}' wall of vessel #{}", sp.name, f.vessel);
                let fs = segment_factors(
                    &element,
                    &walls,
                    &net,
                    &abs,
                    &flow,
                    kinematic_viscosity,
                    sp.diffusivity,
                )?;
                for (&j, v) in js.iter().zip(fs) {
                    factors[j] = v;
                }
            }
            all.push(factors);
        }
        Ok(all)
    }
}
