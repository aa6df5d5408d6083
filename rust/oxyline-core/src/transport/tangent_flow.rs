//! The species step's tangent by a flow parameter (a radius, a length, a wall stiffness, a
//! Windkessel value, the inflow scale, …): such a parameter changes the face flows the step
//! reads (the flow's own tangent gives them step by step), the cells' transport volumes W
//! (V(P₀) = V₀ + C (P₀ − P_ref) at the start, then W' = W + Δt · net inflow), and for a
//! vessel's geometry its reference volumes and its walls' coefficients (every law the species
//! tangent follows is proportional to the wall area: g, g c_w and q ∝ 2π r Δx).
//!
//! The step's rows (d_n + Σ_out |Q|) x_n − Σ_in |Q| x_up = b_n are linear in the face flows at
//! fixed upwind directions, so at the primal's solution x the derivative of the residual by
//! the flows is the divergence of the flux change: a face carrying Φ = |Q| x_up from `up` to
//! `down` moves d|Q| x_up out of `up`'s row and into `down`'s (x_up a node's new value, or the
//! value a boundary carries in: prescribed, or zero gradient's lagged old value). With the
//! volumes' derivative W'′ = W′ + Δt (net inflow)′ and c′ = (z′ − c W′)/W the tangent solves
//!
//!   A x′ = z′/Δt − w_c′ − w_l′ x − W'′ (1/Δt + λ) x + (flux divergence)′,
//!
//! on the primal's matrix A, and the new amounts' tangent is z′ = W'′ x + W' x′.

use super::*;
use crate::closure::renewal::tangent::net_mean_tangent;

/// What a flow parameter changes in the transport besides the face flows, given by the
/// sensitivity layer from the parameter's derivative of the DAE.
#[derive(Debug, Clone, Copy)]
pub struct FlowEffect<'a> {
    /// The vessel (circuit index) whose geometry the parameter sets, if any.
    pub geometry: Option<FlowGeometry>,
    /// dE/dθ of the DAE: the nodes' compliances (the cells' C).
    pub de: &'a [f64],
    /// (circuit node, d ln(inflow)/dθ) of flow conditions whose waveform the parameter scales.
    pub sources: &'a [(usize, f64)],
    /// The segments' cycle-mean flows over the periodic cycle and their derivatives by the
    /// parameter, for the walls whose law reads them (None: no such wall).
    pub mean_flows: Option<MeanFlowTangent<'a>>,
}

/// The logarithmic derivatives by the parameter of a vessel's wall area and lumen volume,
/// and of its segments' radius and distances from the inlet (the cycle-mean laws'): the same
/// for every segment of a uniform vessel's radius or length, or each segment's own for an
/// end radius of a taper (`taper`; [`FlowGeometry::at`]).
#[derive(Debug, Clone, Copy)]
pub struct FlowGeometry {
    pub vessel: usize,
    pub area: f64,
    pub volume: f64,
    pub radius: f64,
    pub length: f64,
    pub taper: Option<TaperEnd>,
}

/// One end radius of a vessel's linear taper r(x) = r_in + (r_out − r_in) x/L as the
/// parameter (the other end and the length held): r(x) moves by x/L (`outlet`) or 1 − x/L.
#[derive(Debug, Clone, Copy)]
pub struct TaperEnd {
    pub radius_in: f64,
    pub radius_out: f64,
    pub length: f64,
    pub outlet: bool,
}

/// d ln/dθ of a wall piece's (or segment's) area, lumen volume, mean radius and length.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PieceLogs {
    pub(crate) area: f64,
    pub(crate) volume: f64,
    pub(crate) radius: f64,
    pub(crate) length: f64,
}

impl FlowGeometry {
    /// The logarithmic derivatives of the piece of wall `w` (its ends x0, x1 from the
    /// vessel's inlet). On a taper the piece runs from r₀ = r(x0) to r₁ = r(x1), which move
    /// by w₀ and w₁ per unit of the end radius: its area 2π (r₀ + r₁)/2 Δx and mean radius
    /// by (w₀ + w₁)/(r₀ + r₁), its frustum volume π Δx (r₀² + r₀r₁ + r₁²)/3 by
    /// (w₀ (2r₀ + r₁) + w₁ (r₀ + 2r₁))/(r₀² + r₀r₁ + r₁²), its length not at all.
    pub(crate) fn at(&self, w: &SegmentWall) -> PieceLogs {
        let Some(t) = self.taper else {
            return PieceLogs {
                area: self.area,
                volume: self.volume,
                radius: self.radius,
                length: self.length,
            };
        };
        let r = |x: f64| t.radius_in + (t.radius_out - t.radius_in) * x / t.length;
        let by = |x: f64| {
            if t.outlet {
                x / t.length
            } else {
                1.0 - x / t.length
            }
        };
        let (r0, r1, w0, w1) = (r(w.x0), r(w.x1), by(w.x0), by(w.x1));
        let mean = (w0 + w1) / (r0 + r1);
        PieceLogs {
            area: mean,
            volume: (w0 * (2.0 * r0 + r1) + w1 * (r0 + 2.0 * r1)) / (r0 * r0 + r0 * r1 + r1 * r1),
            radius: mean,
            length: 0.0,
        }
    }
}

/// Per segment: the cycle means of |Q| and of the forward flow (`laws::MeanFlows`) and
/// their derivatives by one flow parameter; per species and segment, the inlet renewal's
/// factors (`laws::MeanFlows::renewal`; empty without them) and their d ln by the parameter
/// (`Transport::renewal_factor_tangents`; empty: held).
#[derive(Debug, Clone, Copy)]
pub struct MeanFlowTangent<'a> {
    pub abs: &'a [f64],
    pub forward: &'a [f64],
    pub d_abs: &'a [f64],
    pub d_forward: &'a [f64],
    pub renewal: &'a [Vec<f64>],
    pub d_ln_renewal: &'a [Vec<f64>],
}

/// A flow parameter's fixed effects per cell and per flow source.
#[derive(Debug, Clone)]
pub(crate) struct FlowDerivative {
    /// d(reference volume V₀) and d(compliance C) per cell.
    dv0: Vec<f64>,
    dcap: Vec<f64>,
    /// d ln(q_s)/dθ per flow source of the plan.
    source: Vec<f64>,
}

/// One step of the flow's tangent for one parameter: the derivatives of the flow unknowns
/// [`Transport::flow_tangent_unknowns`] at the step's start and end, the level α_f the
/// step reads its face flows at, and per shear-dependent piece the d ln/dθ of the flow
/// magnitude its law reads at the step (|Q| or the relaxed Q̃: one step of
/// [`Transport::shear_tangents`]; empty without such pieces).
#[derive(Debug, Clone, Copy)]
pub struct FlowStep<'a> {
    pub start: &'a [f64],
    pub end: &'a [f64],
    pub alpha_f: f64,
    pub shear: &'a [f64],
}

/// A flow parameter's terms in one step: face flows' derivatives (every face), the nodes'
/// net inflow's and the residual's (the flux divergence), and the boundary fluxes' change
/// at the primal's concentrations (inflow, outflow).
struct FlowStepTerms {
    dq: Vec<f64>,
    dnet: Vec<f64>,
    r: Vec<f64>,
    d_in: f64,
    d_out: f64,
}

/// A flow parameter's right-hand side of one species step at a zero carried tangent
/// (z′ = 0, lagged x′ = 0): what the parameter itself drives. The step's tangent is this
/// plus the carried tangent's linear part, so the forward tangent adds it to its rows and
/// the adjoint contracts it with the step's adjoint (`adjoint.rs`).
#[derive(Debug, Clone)]
pub(crate) struct FlowForcing {
    /// The new transport volumes' tangent W'′ = W′ + Δt (net inflow)′, per cell.
    pub(super) dw_new: Vec<f64>,
    /// The old concentrations' tangent at z′ = 0, c′ = −c W′/W, per cell.
    pub(super) dc: Vec<f64>,
    /// The rows' right side: the flux divergence′ − W'′ (1/Δt + λ) x, per node.
    pub(super) num: Vec<f64>,
    /// The new amounts' part W'′ x, per cell.
    pub(super) dz: Vec<f64>,
    /// The face flows' tangent (every face), and the boundary fluxes' (inflow, outflow).
    pub(super) dq: Vec<f64>,
    pub(super) d_in: f64,
    pub(super) d_out: f64,
}

/// The primal of one step's cells a flow parameter's forcing reads: old volumes W, old
/// total concentrations c, new total concentrations x.
#[derive(Debug, Clone, Copy)]
pub(super) struct CellPrimal<'a> {
    pub(super) w: &'a [f64],
    pub(super) c: &'a [f64],
    pub(super) x: &'a [f64],
}

impl Transport {
    /// The flow unknowns whose tangent the species tangent of a flow parameter reads: every
    /// flow face's unknown (in face order), then each cell's volume unknown.
    pub fn flow_tangent_unknowns(&self) -> Vec<usize> {
        let p = &self.plan;
        let faces = p.face_unknowns[..p.n_flow_faces]
            .iter()
            .map(|&u| u as usize);
        faces
            .chain((0..p.cells.len()).map(|i| p.volume_unknown(i)))
            .collect()
    }

    /// The derivative of species `s`'s step by a flow parameter with effects `e`.
    pub fn species_flow_derivative(&self, s: usize, e: &FlowEffect<'_>) -> SpeciesDerivative {
        let (plan, laws) = (&*self.plan, &self.species[s].laws);
        let nc = plan.cells.len();
        let mut piece = vec![[0.0; 3]; laws.laws.len()];
        let mut cell = vec![[0.0; 3]; nc];
        let mut dvol = vec![0.0; plan.kind.len()];
        for (p, (law, pc)) in laws.laws.iter().zip(&plan.pieces).enumerate() {
            let SegmentLaw::Fixed { g: gl, cw, q } = *law else {
                continue;
            };
            let j = pc.seg as usize;
            let own = e
                .geometry
                .filter(|g| plan.segment_vessels[j] as usize == g.vessel);
            let d = match self.mean_flow_law_derivative(s, p, e, own) {
                Some(dg) => [dg, dg * cw, 0.0],
                None => match own {
                    Some(g) => {
                        let a = g.at(&plan.piece_wall(pc)).area;
                        [gl * a, gl * cw * a, q * a]
                    }
                    None => continue,
                },
            };
            piece[p] = d;
            for (c, dk) in cell[pc.cell as usize].iter_mut().zip(d) {
                *c += pc.share * dk;
            }
        }
        if let Some(g) = e.geometry {
            let of = |seg: usize| plan.segment_vessels[seg] as usize == g.vessel;
            for (_, seg) in plan.segments.iter().enumerate().filter(|(j, _)| of(*j)) {
                for (n, share) in seg.node_shares() {
                    dvol[n] += share * seg.volume * g.at(&seg.wall).volume;
                }
            }
        }
        // a node refined into m sub-cells gives each V₀/m and C/m
        let mut m = vec![0.0f64; plan.kind.len()];
        for n in plan.cell_node.iter().map(|&n| n as usize) {
            m[n] += 1.0;
        }
        let dv0 = plan
            .cell_node
            .iter()
            .map(|&n| dvol[n as usize] / m[n as usize])
            .collect();
        let dcap = (plan.cell_node.iter().enumerate())
            .map(|(i, &n)| e.de.get(plan.volume_unknown(i)).copied().unwrap_or(0.0) / m[n as usize])
            .collect();
        let source = (plan.sources.iter())
            .map(|(n, _, _)| e.sources.iter().filter(|(k, _)| k == n).map(|x| x.1).sum())
            .collect();
        SpeciesDerivative {
            kind: SpeciesParameterKind::Flow,
            piece,
            cell,
            dynamic: vec![[0.0; 2]; laws.dynamic.len()],
            flow_dynamic: self.shear_law_geometry(s, e.geometry),
            flow: Some(FlowDerivative { dv0, dcap, source }),
        }
    }

    /// Per shear-dependent piece of species `s`: d ln/dθ of its Lévêque coefficient, Graetz
    /// floor and permeability conductance when the parameter sets its vessel's geometry
    /// (`geometry`). coef ∝ r (|Q|/r³)^{1/3} (x1^{2/3} − x0^{2/3}) is free of r, the floor
    /// Sh π D Δx too; G_p ∝ the wall area.
    fn shear_law_geometry(&self, s: usize, geometry: Option<FlowGeometry>) -> Vec<[f64; 3]> {
        let plan = &*self.plan;
        (self.species[s].laws.dynamic.iter())
            .map(|&p| {
                let pc = &plan.pieces[p];
                match geometry {
                    Some(g) if plan.segment_vessels[pc.seg as usize] as usize == g.vessel => {
                        let l = g.at(&plan.piece_wall(pc));
                        [2.0 * l.length / 3.0, l.length, l.area]
                    }
                    _ => [0.0; 3],
                }
            })
            .collect()
    }

    /// Per step of the flow's periodic cycle (`ys`: its n + 1 states, steps of `dt` read at
    /// level `alpha_f`), per shear-dependent piece of species `s`: d ln/dθ of the flow
    /// magnitude its law reads, by a flow parameter whose tangent of the recorded unknowns
    /// at each step end is `dys` (n + 1, as `ys`) over the flow unknowns `recorded` (which
    /// hold the branch flows the walls read: [`Transport::shear_unknowns`], or every
    /// segment's for the walls that read the mean flow); `mean` the cycle means' tangent (the
    /// relaxation times read ⟨|Q|⟩), `geometry` the vessel whose geometry it sets.
    ///
    /// Instantaneous shear: |Q_a| at the step's α_f level, d ln |Q_a| = Q_a′/Q_a. Relaxed:
    /// Q̃ ← |Q_a| + (Q̃ − |Q_a|) e, e = exp(−Δt/τ) (`relax_shears`), so
    /// Q̃′ ← (1 − e) sgn(Q_a) Q_a′ + e Q̃′ + (Q̃ − |Q_a|) e′, e′ = e (Δt/τ) d ln τ, with
    /// τ ∝ (x r³/⟨|Q|⟩)^{2/3} (`closure::relaxation_time`); the tangent starts at its
    /// periodic value Q̃′* = B′/(1 − e^n) (B′ one pass from zero), as the primal does.
    #[allow(clippy::too_many_arguments)]
    pub fn shear_tangents(
        &self,
        s: usize,
        ys: &[Vec<f64>],
        dys: &[&[f64]],
        recorded: &[usize],
        (dt, alpha_f): (f64, f64),
        mean: Option<&MeanFlowTangent<'_>>,
        geometry: Option<FlowGeometry>,
    ) -> Result<Vec<f64>> {
        let laws = &self.species[s].laws;
        let n = ys.len().saturating_sub(1);
        let mut per_seg = vec![vec![0.0; n]; laws.dynamic_segs.len()];
        for (m, &j) in laws.dynamic_segs.iter().enumerate() {
            let u = self.plan.segments[j].branch_unknown as usize;
            let Some(at) = recorded.iter().position(|&r| r == u) else {
                return Err(Error::model(
                    "sensitivities",
                    format!("the flow cycle does not hold segment {j}'s branch flow"),
                ));
            };
            let q = |k: usize| ys[k][u] + alpha_f * (ys[k + 1][u] - ys[k][u]);
            let dq = |k: usize| dys[k][at] + alpha_f * (dys[k + 1][at] - dys[k][at]);
            let relaxed = (laws.relax_of_seg.get(j).copied()).filter(|&r| r != u32::MAX);
            let Some(r) = relaxed else {
                for (k, v) in per_seg[m].iter_mut().enumerate() {
                    let qa = q(k);
                    *v = if qa != 0.0 { dq(k) / qa } else { 0.0 };
                }
                continue;
            };
            let (_, tau, _) = laws.relax[r as usize];
            let e = (-dt / tau).exp();
            if e.is_nan() || e >= 1.0 {
                continue; // no mean flow: the layer keeps its start
            }
            let seg = &self.plan.segments[j];
            let (ln_r, ln_x) = geometry
                .filter(|g| self.plan.segment_vessels[j] as usize == g.vessel)
                .map_or((0.0, 0.0), |g| {
                    let l = g.at(&seg.wall);
                    (l.radius, l.length)
                });
            let ln_mean = mean
                .filter(|m| m.abs[j] > 0.0)
                .map_or(0.0, |m| m.d_abs[j] / m.abs[j]);
            let de = e * (dt / tau) * (2.0 / 3.0) * (ln_x + 3.0 * ln_r - ln_mean);
            let big_e = e.powi(n as i32);
            // the primal's periodic start (`set_periodic_relaxed_shears`)
            let mut v = 0.0;
            for k in 0..n {
                let qa = q(k).abs();
                v = qa + (v - qa) * e;
            }
            let start = v / (1.0 - big_e);
            // one step of the tangent's recursion from (Q̃, Q̃′)
            let step = |k: usize, qt: f64, dqt: f64| {
                let qa = q(k);
                let sgn = if qa < 0.0 { -1.0 } else { 1.0 };
                let dnew = (1.0 - e) * sgn * dq(k) + e * dqt + (qt - qa.abs()) * de;
                (qa.abs() + (qt - qa.abs()) * e, dnew)
            };
            let (mut qt, mut dqt) = (start, 0.0);
            for k in 0..n {
                (qt, dqt) = step(k, qt, dqt);
            }
            (qt, dqt) = (start, dqt / (1.0 - big_e));
            for (k, v) in per_seg[m].iter_mut().enumerate() {
                (qt, dqt) = step(k, qt, dqt);
                *v = if qt > 0.0 { dqt / qt } else { 0.0 };
            }
        }
        let nd = laws.dynamic.len();
        let mut out = vec![0.0; n * nd];
        for (kk, &p) in laws.dynamic.iter().enumerate() {
            let j = self.plan.pieces[p].seg as usize;
            let Some(m) = laws.dynamic_segs.iter().position(|&x| x == j) else {
                continue;
            };
            for (k, v) in per_seg[m].iter().enumerate() {
                out[k * nd + kk] = *v;
            }
        }
        Ok(out)
    }

    /// The derivative of wall piece `p`'s conductance (species `s`) when its law reads the
    /// cycle-mean flow (None otherwise: its coefficients are ∝ the wall area): by the mean
    /// flow's tangent, and by the segment's radius and length when the parameter sets its
    /// vessel's geometry (`own`); the law's own slopes (`WallSpec::mean_flow_law_slopes`).
    fn mean_flow_law_derivative(
        &self,
        s: usize,
        p: usize,
        e: &FlowEffect<'_>,
        own: Option<FlowGeometry>,
    ) -> Option<f64> {
        let (plan, sp) = (&*self.plan, &self.plan.species[s]);
        let pc = &plan.pieces[p];
        let j = pc.seg as usize;
        let wall = &sp.walls[plan.segment_vessels[j] as usize];
        if !wall.needs_mean_flow() {
            return None;
        }
        let m = e.mean_flows?;
        let mean = laws::MeanFlows {
            abs: m.abs,
            forward: m.forward,
            renewal: m.renewal,
        };
        let factors = m.renewal.get(s).map_or(&[][..], |r| &r[..]);
        let (q_mean, renewal) = laws::closure_mean_flow(wall, j, mean, factors);
        let slopes =
            wall.mean_flow_law_slopes(&plan.piece_wall(pc), sp.diffusivity, q_mean, renewal)?;
        let d_mean = match wall.mean_flow() {
            closure::MeanFlow::CycleMean => m.d_abs[j],
            // the net mean |⟨Q⟩| (`laws::closure_mean_flow`)
            closure::MeanFlow::InletRenewal if !factors.is_empty() => {
                net_mean_tangent(m.abs[j], m.forward[j], m.d_abs[j], m.d_forward[j])
            }
            _ => m.d_forward[j],
        };
        let d_ln_renewal = (m.d_ln_renewal.get(s))
            .and_then(|d| d.get(j))
            .copied()
            .unwrap_or(0.0);
        let (dr, dl) = own.map_or((0.0, 0.0), |g| {
            let l = g.at(&plan.piece_wall(pc));
            (l.radius, l.length)
        });
        Some(
            slopes.mean_flow * d_mean
                + slopes.ln_radius * dr
                + slopes.ln_length * dl
                + slopes.ln_renewal * d_ln_renewal,
        )
    }

    /// The tangent of a flow parameter at the start of a run from flow state `y0` (its
    /// tangent `dflow0` over [`Transport::flow_tangent_unknowns`]) and amounts `z` of species
    /// `s`: the start volumes' derivative dV(P₀) = dV₀ + dC (P₀ − P_ref) + C dP₀, the
    /// concentrations held.
    pub fn species_flow_tangent_start(
        &self,
        s: usize,
        d: &SpeciesDerivative,
        y0: &[f64],
        dflow0: &[f64],
        z: &[f64],
    ) -> SpeciesTangent {
        let mut t = self.species_tangent_start();
        let Some(dw) = self.flow_volumes_start(d, y0, dflow0) else {
            return t;
        };
        let nc = self.plan.cells.len();
        t.dw = dw;
        for (i, dz) in t.dz.iter_mut().enumerate() {
            *dz = t.dw[i] * z[s * nc + i] / self.wvol[i];
        }
        t.dq = vec![0.0; self.plan.faces.len()];
        t
    }

    /// The transport volumes' tangent of a flow parameter (`d`; None for an oxygen one) at
    /// flow state `y0` (its tangent `dflow0` over [`Transport::flow_tangent_unknowns`]):
    /// dV(P₀) = dV₀ + dC (P₀ − P_ref) + C dP₀, per cell.
    pub fn flow_volumes_start(
        &self,
        d: &SpeciesDerivative,
        y0: &[f64],
        dflow0: &[f64],
    ) -> Option<Vec<f64>> {
        let f = d.flow.as_ref()?;
        let p = &*self.plan;
        let nf = p.n_flow_faces;
        let dw = (0..p.cells.len())
            .map(|i| {
                let u = p.volume_unknown(i);
                f.dv0[i] + f.dcap[i] * (y0[u] - p.p_ref) + p.cap[i] * dflow0[nf + i]
            })
            .collect();
        Some(dw)
    }

    /// The total concentration of every node of species `s` in state `z` before a step: the
    /// cells' z/W, the mixing points' carried values (the values the step's lagged terms read).
    pub fn species_node_values(&self, s: usize, z: &[f64]) -> Vec<f64> {
        let (p, nc) = (&*self.plan, self.plan.cells.len());
        let mut x = vec![0.0; p.kind.len()];
        for (i, n) in p.cells.iter().map(|&n| n as usize).enumerate() {
            x[n] = z[s * nc + i] / self.wvol[i];
        }
        for (&m, &c) in p.mixing.iter().zip(&self.species[s].mixing_conc) {
            x[m] = c;
        }
        x
    }

    /// The face flows' tangent of the step (flow faces from the flow's tangent at the α_f
    /// level, sources scaled, refined cells' interior faces by their rule).
    fn face_flow_tangent(&self, f: &FlowDerivative, step: &FlowStep<'_>) -> (Vec<f64>, Vec<f64>) {
        let p = &*self.plan;
        let mut dq = vec![0.0; p.faces.len()];
        for (k, d) in dq[..p.n_flow_faces].iter_mut().enumerate() {
            *d = step.start[k] + step.alpha_f * (step.end[k] - step.start[k]);
        }
        let dqs: Vec<f64> = self.qs.iter().zip(&f.source).map(|(q, k)| q * k).collect();
        for ch in &p.chains {
            let q_a = ch.in_faces.iter().map(|&f| dq[f]).sum::<f64>()
                + ch.sources.iter().map(|&k| dqs[k]).sum::<f64>();
            let q_b: f64 = ch.out_faces.iter().map(|&f| dq[f]).sum();
            for k in 1..ch.m {
                dq[ch.first_face + k - 1] = q_a - (k as f64 / ch.m as f64) * (q_a - q_b);
            }
        }
        (dq, dqs)
    }

    /// Flow parameter `f`'s forcing of the step species `s` (loaded face flows, boundary
    /// values and new node values) just took: `x_old` the nodes' values before it
    /// ([`Transport::species_node_values`]), `cells` its cells' primal, `dw_old` the old
    /// transport volumes' tangent W′ (see the module doc).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn flow_forcing(
        &self,
        s: usize,
        dt: f64,
        f: &FlowDerivative,
        step: &FlowStep<'_>,
        x_old: &[f64],
        cells: CellPrimal<'_>,
        dw_old: &[f64],
    ) -> FlowForcing {
        let terms = self.flow_step_terms(f, step, x_old);
        let rate = 1.0 / dt + self.plan.species[s].decay;
        let plan = &*self.plan;
        let nc = plan.cells.len();
        let mut out = FlowForcing {
            dw_new: Vec::with_capacity(nc),
            dc: Vec::with_capacity(nc),
            num: terms.r,
            dz: Vec::with_capacity(nc),
            dq: terms.dq,
            d_in: terms.d_in,
            d_out: terms.d_out,
        };
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let dw = dw_old.get(i).copied().unwrap_or(0.0);
            let dw_new = dw + dt * terms.dnet[n];
            out.dc.push(-cells.c[i] * dw / cells.w[i]);
            out.num[n] -= dw_new * rate * cells.x[i];
            out.dz.push(dw_new * cells.x[i]);
            out.dw_new.push(dw_new);
        }
        out
    }

    /// The old transport volumes' tangent W′ of a step from the new one's (W′ = W'′ − Δt
    /// (net inflow)′), for the adjoint's sweep backwards over the cycle.
    pub(super) fn flow_volumes_before(
        &self,
        dt: f64,
        f: &FlowDerivative,
        step: &FlowStep<'_>,
        dw_new: &[f64],
    ) -> Vec<f64> {
        let (dq, dqs) = self.face_flow_tangent(f, step);
        let dnet = self.net_inflow_tangent(&dq, &dqs);
        (self.plan.cells.iter().zip(dw_new))
            .map(|(&n, dw)| dw - dt * dnet[n as usize])
            .collect()
    }

    /// The nodes' net inflow's tangent from the faces' `dq` and the sources' `dqs`.
    fn net_inflow_tangent(&self, dq: &[f64], dqs: &[f64]) -> Vec<f64> {
        let p = &*self.plan;
        let mut dnet = vec![0.0; p.kind.len()];
        let faces = p.internal().map(|e| e[0] as usize);
        for fi in faces.chain(p.boundary_faces.iter().copied()) {
            let face = &p.faces[fi];
            if let End::Node(n) = face.tail() {
                dnet[n] -= dq[fi];
            }
            if let End::Node(n) = face.head() {
                dnet[n] += dq[fi];
            }
        }
        for (&(n, _, _), &dqk) in p.sources.iter().zip(dqs) {
            dnet[n] += dqk;
        }
        dnet
    }

    /// A flow parameter's terms of the step species `s` (loaded boundary values) just took,
    /// `x_old` the nodes' values before it ([`Transport::species_node_values`]).
    fn flow_step_terms(
        &self,
        f: &FlowDerivative,
        step: &FlowStep<'_>,
        x_old: &[f64],
    ) -> FlowStepTerms {
        let p = &*self.plan;
        let (dq, dqs) = self.face_flow_tangent(f, step);
        let dnet = self.net_inflow_tangent(&dq, &dqs);
        let mut r = vec![0.0; p.kind.len()];
        // the value a face's upwind end carries: a node's new value, or a boundary's
        let carried = |up: End, down: End| match (up, down) {
            (End::Node(u), _) => self.conc[u],
            (End::Boundary(b), End::Node(n)) => inflow_value(self.bval[b], x_old[n]),
            (End::Boundary(b), End::Boundary(_)) => inflow_value(self.bval[b], 0.0),
        };
        let faces = p.internal().map(|e| e[0] as usize);
        for fi in faces.chain(p.boundary_faces.iter().copied()) {
            let (q, up, down) = oriented(&p.faces, &self.qf, fi);
            let flux = if q >= 0.0 { dq[fi] } else { -dq[fi] } * carried(up, down);
            if let End::Node(u) = up {
                r[u] -= flux;
            }
            if let End::Node(n) = down {
                r[n] += flux;
            }
        }
        let (mut d_in, mut d_out) = (0.0, 0.0);
        for ((&(n, _, bb), &q), &dqk) in p.sources.iter().zip(&self.qs).zip(&dqs) {
            let v = if q >= 0.0 {
                inflow_value(self.bval[bb], x_old[n])
            } else {
                self.conc[n]
            };
            r[n] += dqk * v;
            account(p.boundary_inlet[bb], dqk * v, &mut d_in, &mut d_out);
        }
        for b in &p.boundary_links {
            let (n, bb, fi) = (b.node as usize, b.boundary as usize, b.face as usize);
            let v = if b.boundary_upwind(self.qf[fi]) {
                inflow_value(self.bval[bb], x_old[n])
            } else {
                self.conc[n]
            };
            account(
                p.boundary_inlet[bb],
                b.inflow(dq[fi]) * v,
                &mut d_in,
                &mut d_out,
            );
        }
        FlowStepTerms {
            dq,
            dnet,
            r,
            d_in,
            d_out,
        }
    }
}
