//! The inlet-renewal closure's per-vessel data (docs/physics.md §3.6): which flow unknowns
//! the first pass must resolve in time (one per vessel with a `flow: inlet-renewal` wall), and
//! the per-segment factors it gives once their harmonics are known (`run::flow_harmonics`).

use super::laws::MeanFlows;
use super::tangent::{FlowGeometry, MeanFlowTangent};
use super::*;
use crate::closure::renewal::tangent::{
    GeometryTangent, PeriodicFlowTangent, SegmentMeans, net_mean_tangent,
    segment_factor_tangents_into,
};
use crate::closure::renewal::{PeriodicFlow, net_mean, segment_factors_into};
use nalgebra::Complex;

/// The periodic inlet flows of the renewal vessels, measured by the first pass: vessel
/// `vessels[i]` has Q(t) = means[i] + Re Σ_{k=1}^{H} harmonics[i H + k − 1] e^{ikωt}, H =
/// `per_vessel` (one flat array: no allocation per vessel).
#[derive(Debug, Clone, Copy)]
pub struct VesselFlows<'a> {
    pub vessels: &'a [usize],
    pub means: &'a [f64],
    pub harmonics: &'a [Complex<f64>],
    pub per_vessel: usize,
}

impl<'a> VesselFlows<'a> {
    /// The `i`-th vessel's flow over `period`.
    pub fn flow(&self, i: usize, period: f64) -> PeriodicFlow<'a> {
        let h = self.per_vessel;
        PeriodicFlow {
            period,
            mean: self.means[i],
            harmonics: &self.harmonics[i * h..(i + 1) * h],
        }
    }
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
        flows: VesselFlows<'_>,
    ) -> Result<()> {
        let renewal = self.renewal_factors(mean_abs, mean_forward, period, flows)?;
        self.set_mean_flows_with_renewal(mean_abs, mean_forward, &renewal)
    }

    /// The laws of the cycle means with the renewal factors `renewal` (per species, per
    /// segment: [`Transport::renewal_factors`]), as [`Transport::set_mean_flows_renewed`].
    pub fn set_mean_flows_with_renewal(
        &mut self,
        mean_abs: &[f64],
        mean_forward: &[f64],
        renewal: &[Vec<f64>],
    ) -> Result<()> {
        self.set_laws(MeanFlows {
            abs: mean_abs,
            forward: mean_forward,
            renewal,
        })
    }

    /// Per species, per segment: the renewal factor (1 where the wall does not renew). The
    /// vessels' segment lists, walls and means live in buffers reused from vessel to vessel.
    pub fn renewal_factors(
        &self,
        mean_abs: &[f64],
        mean_forward: &[f64],
        period: f64,
        flows: VesselFlows<'_>,
    ) -> Result<Vec<Vec<f64>>> {
        let p = &self.plan;
        let (start, list) = segments_by_vessel(
            &p.segment_vessels,
            p.species.first().map_or(0, |s| s.walls.len()),
        );
        let (mut walls, mut net, mut abs, mut fs) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut all = Vec::with_capacity(p.species.len());
        for sp in &p.species {
            let mut factors = vec![1.0; p.segments.len()];
            for (i, &vessel) in flows.vessels.iter().enumerate() {
                let Some(nu) = renewal_viscosity(&sp.walls[vessel]) else {
                    continue;
                };
                let js = &list[start[vessel]..start[vessel + 1]];
                walls.clear();
                walls.extend(js.iter().map(|&j| p.segments[j as usize].wall));
                net.clear();
                net.extend(
                    js.iter()
                        .map(|&j| net_mean(mean_abs[j as usize], mean_forward[j as usize])),
                );
                abs.clear();
                abs.extend(js.iter().map(|&j| mean_abs[j as usize]));
                let element = || format!("species '{}' wall of vessel #{vessel}", sp.name);
                segment_factors_into(
                    &element,
                    &walls,
                    &net,
                    &abs,
                    &flows.flow(i, period),
                    nu,
                    sp.diffusivity,
                    &mut fs,
                )?;
                for (&j, &v) in js.iter().zip(&fs) {
                    factors[j as usize] = v;
                }
            }
            all.push(factors);
        }
        Ok(all)
    }

    /// Per species, per segment: d ln(renewal factor) by one flow parameter (0 where the
    /// wall does not renew), from the cycle means' tangent `means`, the inlet flows'
    /// harmonics `flows` and their tangent `dflows` (same layout: d means, d harmonics), and
    /// the vessel geometry the parameter sets (`closure::renewal::tangent`). The primal
    /// factors were computed on the same arguments ([`Transport::renewal_factors`]), which
    /// checked them.
    pub fn renewal_factor_tangents(
        &self,
        means: MeanFlowTangent<'_>,
        period: f64,
        flows: VesselFlows<'_>,
        dflows: VesselFlows<'_>,
        geometry: Option<FlowGeometry>,
    ) -> Vec<Vec<f64>> {
        let p = &self.plan;
        let (start, list) = segments_by_vessel(
            &p.segment_vessels,
            p.species.first().map_or(0, |s| s.walls.len()),
        );
        let mut all = Vec::with_capacity(p.species.len());
        let mut out = Vec::new();
        for sp in &p.species {
            let mut d_ln = vec![0.0; p.segments.len()];
            for (i, &vessel) in flows.vessels.iter().enumerate() {
                let Some(nu) = renewal_viscosity(&sp.walls[vessel]) else {
                    continue;
                };
                let js: Vec<usize> = list[start[vessel]..start[vessel + 1]]
                    .iter()
                    .map(|&j| j as usize)
                    .collect();
                let walls: Vec<_> = js.iter().map(|&j| p.segments[j].wall).collect();
                let net: Vec<f64> = (js.iter())
                    .map(|&j| net_mean(means.abs[j], means.forward[j]))
                    .collect();
                let d_net: Vec<f64> = (js.iter())
                    .map(|&j| {
                        net_mean_tangent(
                            means.abs[j],
                            means.forward[j],
                            means.d_abs[j],
                            means.d_forward[j],
                        )
                    })
                    .collect();
                let abs: Vec<f64> = js.iter().map(|&j| means.abs[j]).collect();
                let d_abs: Vec<f64> = js.iter().map(|&j| means.d_abs[j]).collect();
                let dflow = dflows.flow(i, period);
                // each segment's own d ln r (a taper's end radius moves them unalike)
                let own_geometry = geometry.filter(|g| g.vessel == vessel);
                let ln_radius: Vec<f64> = own_geometry
                    .map(|g| walls.iter().map(|w| g.at(w).radius).collect())
                    .unwrap_or_default();
                let own = own_geometry.map_or(GeometryTangent::default(), |g| GeometryTangent {
                    ln_radius: &ln_radius,
                    ln_length: g.length,
                });
                let seg_means = SegmentMeans {
                    net: &net,
                    abs: &abs,
                    d_net: &d_net,
                    d_abs: &d_abs,
                };
                segment_factor_tangents_into(
                    &walls,
                    seg_means,
                    &flows.flow(i, period),
                    &PeriodicFlowTangent {
                        mean: dflow.mean,
                        harmonics: dflow.harmonics,
                    },
                    own,
                    nu,
                    sp.diffusivity,
                    &mut out,
                );
                for (&j, &v) in js.iter().zip(&out) {
                    d_ln[j] = v;
                }
            }
            all.push(d_ln);
        }
        all
    }
}

/// The kinematic viscosity of a wall that renews at its inlet (None: any other wall).
fn renewal_viscosity(wall: &WallSpec) -> Option<f64> {
    match wall {
        WallSpec::Graetz {
            flow: closure::MeanFlow::InletRenewal,
            kinematic_viscosity,
            ..
        } => Some(*kinematic_viscosity),
        _ => None,
    }
}

/// The segments of every vessel in segment order, as one list with offsets: vessel v's are
/// `list[start[v]..start[v + 1]]` (two arrays instead of a vector per vessel).
fn segments_by_vessel(segment_vessels: &[u32], n_vessels: usize) -> (Vec<usize>, Vec<u32>) {
    let mut start = vec![0usize; n_vessels + 1];
    for &v in segment_vessels {
        if let Some(c) = start.get_mut(v as usize + 1) {
            *c += 1;
        }
    }
    for v in 0..n_vessels {
        start[v + 1] += start[v];
    }
    let mut next = start.clone();
    let mut list = vec![0u32; start[n_vessels]];
    for (j, &v) in segment_vessels.iter().enumerate() {
        if let Some(k) = next
            .get_mut(v as usize)
            .filter(|_| (v as usize) < n_vessels)
        {
            list[*k] = j as u32;
            *k += 1;
        }
    }
    (start, list)
}
