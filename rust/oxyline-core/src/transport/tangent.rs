//! Tangent-linear species step: the derivative of the backward-Euler transport step
//! (`implicit_step`) with respect to an oxygen parameter, over a given flow.
//!
//! Oxygen parameters (wall conductance, wall concentration, prescribed wall flux, Hill's P50)
//! do not change the flow, so the step's face flows, volumes W, W' and the upwind matrix are
//! the primal's. The step (binding rows, docs/physics.md §4) solves
//!
//!   A x = z/Δt − w_c,   A = diag(W'(1/Δt + λ) + w_l) + upwind flows,
//!
//! with the wall uptake G f − GC_w + Q linearised in the total concentration about the old
//! state c = z/W: w_l = G σ, w_c = G f − GC_w + Q − w_l c (f the free concentration,
//! σ = df/dC_t). Differentiating (′ = d/dθ, with c′ = z′/W):
//!
//!   A x′ = z′/Δt − w_c′ − w_l′ x,   w_l′ = G′σ + G σ′,
//!   w_c′ = G′f + G f′ − (GC_w)′ + Q′ − w_l′ c − w_l c′,
//!   f′ = σ c′ + ∂f/∂θ,   σ′ = (dσ/dC_t) c′ + ∂σ/∂θ,
//!
//! the same matrix A, so each parameter costs one more solve per step on the primal's tree
//! elimination (on a network with loops, its pendant trees' elimination around the loops'
//! core, `core.rs`, or the flow-order sweep when it is all core); the inflow of a prescribed boundary carries the
//! derivative of its total concentration (P50 changes the bound part of a given inlet PO2),
//! a zero-gradient one the tangent of its neighbour. The free concentration and its slopes
//! are those of the exact inversion of the binding (the primal's anchored series agrees with
//! it to its 1e-12 mmHg tolerance).
//!
//! A flow parameter changes the face flows, the transport volumes and (a vessel's geometry)
//! its walls: its extra terms on the same matrix are in `tangent_flow.rs`.

#[allow(unused_imports)]
use super::*;

#[path = "adjoint.rs"]
mod adjoint;
pub use adjoint::{AdjointSums, SignalRow, SpeciesAdjointState, SpeciesStepRecord, StepDuals};

#[path = "tangent_flow.rs"]
mod flow;
use flow::{CellPrimal, FlowDerivative, FlowForcing};
pub use flow::{FlowEffect, FlowGeometry, FlowStep, MeanFlowTangent, TaperEnd};

/// What an oxygen parameter changes in the step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpeciesParameterKind {
    /// A wall's conductance factor (mass-transfer k): g and g c_w ∝ θ.
    Conductance,
    /// A wall's concentration (or its PO2): g c_w ∝ θ.
    WallConcentration,
    /// A prescribed wall flux: q ∝ θ.
    Flux,
    /// Hill's P50 (the binding, and so the inlets' total concentration).
    P50,
    /// A flow parameter: face flows, transport volumes and (geometry) the walls
    /// (`tangent_flow.rs`).
    Flow,
}

/// The binding at a total concentration: free concentration f, σ = df/dC_t, dσ/dC_t, and
/// the partial derivatives ∂f/∂θ, ∂σ/∂θ by P50 at fixed C_t (zero for other parameters).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct BindingPoint {
    pub f: f64,
    pub sigma: f64,
    pub sigma_c: f64,
    pub f_p50: f64,
    pub sigma_p50: f64,
    /// Hill's saturation S and its derivatives dS/dP, ∂S/∂P50 (0 without Hill).
    pub s: f64,
    pub s_p: f64,
    pub s_p50: f64,
}

/// [`BindingPoint`] of `binding` at the total `ct` (`guess`: warm start of the inversion;
/// `anchor`: the node's local series inverse, as the run's own step inverts, else the exact
/// Newton solve). Hill: C_t = c + H S(c/α), so S = (C_t − c)/H at the free c, and
/// S_P = n S (1 − S)/P, S_PP = S_P (n (1 − 2S) − 1)/P, ∂S/∂P50 = −(P/P50) S_P,
/// ∂S_P/∂P50 = −(P S_PP + S_P)/P50: no further power of P after the inversion.
pub(crate) fn binding_point(
    binding: &Binding,
    ct: f64,
    guess: f64,
    anchor: Option<&mut HillAnchor>,
) -> BindingPoint {
    match *binding {
        Binding::None => BindingPoint {
            f: ct,
            sigma: 1.0,
            ..BindingPoint::default()
        },
        Binding::Affine { slope, .. } => BindingPoint {
            f: binding.free(ct, guess),
            sigma: 1.0 / slope,
            ..BindingPoint::default()
        },
        Binding::Hill {
            alpha,
            p50,
            n,
            capacity,
        } => {
            let f = match anchor {
                Some(a) => binding.free_anchored(ct, guess, a),
                None => binding.free(ct, guess),
            };
            let p = f / alpha;
            let (s, s_p, s_pp) = if p > 0.0 {
                let s = ((ct - f) / capacity).clamp(0.0, 1.0);
                let s_p = n * s * (1.0 - s) / p;
                (s, s_p, s_p * (n * (1.0 - 2.0 * s) - 1.0) / p)
            } else {
                (0.0, 0.0, 0.0)
            };
            let sigma = 1.0 / (1.0 + capacity * s_p / alpha);
            let sigma_c = -sigma.powi(3) * capacity * s_pp / (alpha * alpha);
            let s_p50 = -(p / p50) * s_p;
            let sp_p50 = -(p * s_pp + s_p) / p50;
            let f_p50 = -sigma * capacity * s_p50;
            let sigma_p50 = -sigma * sigma * (capacity / alpha) * (s_pp * f_p50 / alpha + sp_p50);
            BindingPoint {
                f,
                sigma,
                sigma_c,
                f_p50,
                sigma_p50,
                s,
                s_p,
                s_p50,
            }
        }
    }
}

/// The derivative of the wall laws of one species by one parameter: per wall piece
/// (dg, d(g c_w), dq) and summed per cell (dG, d(GC_w), dQ).
#[derive(Debug, Clone)]
pub struct SpeciesDerivative {
    pub kind: SpeciesParameterKind,
    piece: Vec<[f64; 3]>,
    cell: Vec<[f64; 3]>,
    /// Per shear-dependent piece (`Laws::dynamic`): d ln g/dθ of its blood side and
    /// d ln c_w/dθ, which scale the step's own g and g c_w (the law follows the shear).
    dynamic: Vec<[f64; 2]>,
    /// A flow parameter's per shear-dependent piece: d ln/dθ of its Lévêque coefficient, of
    /// its Graetz floor and of its permeability's conductance (its vessel's geometry); the
    /// shear's own change comes per step ([`FlowStep::shear`]). Empty for an oxygen one.
    flow_dynamic: Vec<[f64; 3]>,
    /// A flow parameter's volumes and sources (None for an oxygen parameter).
    flow: Option<FlowDerivative>,
}

/// The tangent of one parameter carried from step to step: amounts z′ of the species' cells,
/// its accumulators' (inflow, outflow, wall, decay) and the total concentration of every node
/// (the lagged values of mixing points and zero-gradient boundaries); for a flow parameter
/// also the cells' transport volumes W′ and the last step's face flows Q′ (else empty).
#[derive(Debug, Clone)]
pub struct SpeciesTangent {
    pub dz: Vec<f64>,
    pub dacc: [f64; 4],
    xt: Vec<f64>,
    dw: Vec<f64>,
    dq: Vec<f64>,
}

/// One step's primal values of the species' cells the tangent reads.
struct StepPrimal {
    /// old volume, old total concentration and its binding, new total concentration, per cell
    w: Vec<f64>,
    /// the step's wall conductance per cell (fixed laws and shear-dependent pieces) and
    /// each shear-dependent piece's own
    g: Vec<f64>,
    dyn_g: Vec<f64>,
    /// the cube root of the flow magnitude each shear-dependent piece's law read
    dyn_cbrt: Vec<f64>,
    c: Vec<f64>,
    point: Vec<BindingPoint>,
    x: Vec<f64>,
}

impl Transport {
    /// Refuse what the species tangent does not follow: the quasi-steady formulation, tissue
    /// walls, shear-dependent or tabulated walls, a closed-loop inflow (`element`: the
    /// sensitivity asked for, for the message).
    pub fn check_species_tangent(&self, s: usize, element: &str) -> Result<()> {
        let why = if self.plan.formulation != Formulation::Conservative {
            Some("the tl-quasisteady formulation")
        } else if !self.plan.tissue.is_empty() {
            Some("a tissue wall")
        } else if self.species[s].laws.flux_tables.is_some() {
            Some("a wall flux tabulated in time")
        } else if self.inflow_override.is_some() {
            Some("a closed circulation")
        } else {
            None
        };
        match why {
            Some(w) => Err(Error::model(
                element,
                format!("oxygen sensitivities do not follow {w} yet"),
            )),
            None => Ok(()),
        }
    }

    /// The index of the species named `name`.
    pub fn species_index(&self, name: &str) -> Option<usize> {
        self.plan.species.iter().position(|sp| sp.name == name)
    }

    /// The binding law of species `s`.
    pub fn species_binding(&self, s: usize) -> Binding {
        self.plan.species[s].binding
    }

    /// The derivative of the wall laws of species `s` by a parameter of `kind` and SI value
    /// `value` that scales every fixed law's coefficient it names (conductance: g, g c_w;
    /// wall concentration: g c_w; flux: q; the laws are linear in them, so the derivative is
    /// the coefficient over `value`; a conductance factor behind a permeability in series
    /// moves g by its blood side's share, 1 − g/G_p) on the pieces of the vessels `on` (by
    /// circuit vessel index: those whose wall the parameter is). P50 leaves the laws alone.
    pub fn species_derivative(
        &self,
        s: usize,
        kind: SpeciesParameterKind,
        value: f64,
        on: &[bool],
    ) -> SpeciesDerivative {
        let laws = &self.species[s].laws;
        let nc = self.plan.cells.len();
        let mut piece = vec![[0.0; 3]; laws.laws.len()];
        let mut cell = vec![[0.0; 3]; nc];
        for (p, (law, pc)) in laws.laws.iter().zip(&self.plan.pieces).enumerate() {
            let SegmentLaw::Fixed { g, cw, q } = *law else {
                continue;
            };
            let vessel = self.plan.segment_vessels[pc.seg as usize] as usize;
            if !on.get(vessel).copied().unwrap_or(false) {
                continue;
            }
            let d = match kind {
                SpeciesParameterKind::Conductance => {
                    // a permeability in series takes its share of the relative change
                    let dg = self.blood_side_share(s, p, g) * g / value;
                    [dg, dg * cw, 0.0]
                }
                SpeciesParameterKind::WallConcentration => [0.0, g * cw / value, 0.0],
                SpeciesParameterKind::Flux => [0.0, 0.0, q / value],
                SpeciesParameterKind::P50 | SpeciesParameterKind::Flow => [0.0; 3],
            };
            piece[p] = d;
            for (c, dk) in cell[pc.cell as usize].iter_mut().zip(d) {
                *c += pc.share * dk;
            }
        }
        // a shear-dependent piece's g and g c_w scale with the enhancement and c_w alike
        let dynamic = (laws.dynamic.iter())
            .map(|&p| {
                let seg = self.plan.pieces[p].seg as usize;
                let vessel = self.plan.segment_vessels[seg] as usize;
                match kind {
                    _ if !on.get(vessel).copied().unwrap_or(false) => [0.0; 2],
                    SpeciesParameterKind::Conductance => [1.0 / value, 0.0],
                    SpeciesParameterKind::WallConcentration => [0.0, 1.0 / value],
                    _ => [0.0; 2],
                }
            })
            .collect();
        SpeciesDerivative {
            kind,
            piece,
            cell,
            dynamic,
            flow_dynamic: Vec::new(),
            flow: None,
        }
    }

    /// The conductance of every shear-dependent piece of species `s` at the step just
    /// taken (its shear loaded), in the order of `Laws::dynamic`.
    pub(super) fn dynamic_conductances(&self, s: usize) -> Vec<f64> {
        let sp = &self.species[s];
        (sp.laws.dynamic.iter())
            .map(|&p| {
                let seg = self.plan.pieces[p].seg as usize;
                sp.laws.laws[p].eval_cbrt(sp.shear_cbrt[seg]).0
            })
            .collect()
    }

    /// The cube root of the flow magnitude (|Q| or Q̃) each shear-dependent piece of
    /// species `s` read at the step just taken, in the order of `Laws::dynamic`.
    pub(super) fn dynamic_cbrts(&self, s: usize) -> Vec<f64> {
        let sp = &self.species[s];
        (sp.laws.dynamic.iter())
            .map(|&p| sp.shear_cbrt[self.plan.pieces[p].seg as usize])
            .collect()
    }

    /// (dg, d(g c_w)) of shear-dependent piece `k` (of `Laws::dynamic`, piece `p`) by the
    /// parameter of `d` at the step's conductance `g`, the law having read a flow magnitude
    /// of cube root `cbrt`: an oxygen parameter by its fixed rates (a permeability in series
    /// takes its share of the blood side's relative change); a flow parameter by its
    /// geometry's and by the step's d ln|Q| (or d ln Q̃) of the shear, `shear[k]`
    /// ([`FlowStep::shear`]): with G = max(coef |Q|^{1/3}, floor) and g = 1/(1/G + 1/G_p),
    /// d ln g = b d ln G + (1 − b) d ln G_p, b = 1 − g/G_p.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn dynamic_piece_derivative(
        &self,
        s: usize,
        d: &SpeciesDerivative,
        k: usize,
        g: f64,
        cbrt: f64,
        shear: &[f64],
    ) -> (f64, f64) {
        let [ln_g, ln_cw] = d.dynamic.get(k).copied().unwrap_or([0.0; 2]);
        let flow = d.flow_dynamic.get(k).copied();
        if ln_g == 0.0 && ln_cw == 0.0 && flow.is_none() {
            return (0.0, 0.0);
        }
        let p = self.species[s].laws.dynamic[k];
        let SegmentLaw::Instantaneous {
            coef, floor, cw, ..
        } = self.species[s].laws.laws[p]
        else {
            return (0.0, 0.0);
        };
        let b = self.blood_side_share(s, p, g);
        let mut dg = ln_g * b * g;
        if let Some([ln_coef, ln_floor, ln_gp]) = flow {
            // the branch of the max the law took at this step
            let ln_blood = if coef * cbrt > floor {
                ln_coef + shear.get(k).copied().unwrap_or(0.0) / 3.0
            } else {
                ln_floor
            };
            dg += g * (b * ln_blood + (1.0 - b) * ln_gp);
        }
        (dg, (dg + ln_cw * g) * cw)
    }

    /// Per cell: the step's (dg, d(g c_w)) of the shear-dependent pieces by the parameter of
    /// `d` (`dyn_g`, `dyn_cbrt`: their conductances and the cube roots of the flows their
    /// laws read at the step; `shear`: a flow parameter's d ln of those flows); empty without
    /// such pieces.
    fn dynamic_cell_derivative(
        &self,
        s: usize,
        d: &SpeciesDerivative,
        (dyn_g, dyn_cbrt): (&[f64], &[f64]),
        shear: &[f64],
    ) -> Vec<[f64; 2]> {
        let laws = &self.species[s].laws;
        if laws.dynamic.is_empty() {
            return Vec::new();
        }
        let mut out = vec![[0.0; 2]; self.plan.cells.len()];
        for (k, ((&p, &g), &cbrt)) in laws.dynamic.iter().zip(dyn_g).zip(dyn_cbrt).enumerate() {
            let pc = &self.plan.pieces[p];
            let (dg, dgcw) = self.dynamic_piece_derivative(s, d, k, g, cbrt, shear);
            let c = &mut out[pc.cell as usize];
            c[0] += pc.share * dg;
            c[1] += pc.share * dgcw;
        }
        out
    }

    /// The step's wall conductance per cell of species `s`: the fixed laws' and the
    /// shear-dependent pieces' at their conductances `dyn_g`.
    pub(super) fn step_cell_conductance(&self, s: usize, dyn_g: &[f64]) -> Vec<f64> {
        let laws = &self.species[s].laws;
        let mut g = laws.cell_g.clone();
        for (&p, &gp) in laws.dynamic.iter().zip(dyn_g) {
            let pc = &self.plan.pieces[p];
            g[pc.cell as usize] += pc.share * gp;
        }
        g
    }

    /// d ln g/d ln G of wall piece `p` of species `s` (law conductance `g`) by its blood
    /// side's conductance G ([`WallSpec::blood_side_share`]: 1 without a permeability in
    /// series).
    fn blood_side_share(&self, s: usize, p: usize, g: f64) -> f64 {
        let pc = &self.plan.pieces[p];
        let vessel = self.plan.segment_vessels[pc.seg as usize] as usize;
        self.plan.species[s].walls[vessel].blood_side_share(g, self.plan.piece_wall(pc).area())
    }

    /// Add to `d` the derivative of the fixed laws whose blood-side conductance the parameter
    /// moves in proportion: on the pieces of vessel v (by circuit index), with a =
    /// `ln_slope[v]` = d ln G/dθ (a boundary layer's haemoglobin facilitation), dg = a b g and
    /// d(g c_w) = a b g c_w, b = d ln g/d ln G (1 without a permeability in series).
    pub fn add_conductance_slopes(&self, s: usize, d: &mut SpeciesDerivative, ln_slope: &[f64]) {
        let laws = &self.species[s].laws;
        for (p, (law, pc)) in laws.laws.iter().zip(&self.plan.pieces).enumerate() {
            let SegmentLaw::Fixed { g, cw, .. } = *law else {
                continue;
            };
            let vessel = self.plan.segment_vessels[pc.seg as usize] as usize;
            let a = ln_slope.get(vessel).copied().unwrap_or(0.0);
            if a == 0.0 {
                continue;
            }
            let dg = a * self.blood_side_share(s, p, g) * g;
            let add = [dg, dg * cw, 0.0];
            for (k, v) in add.iter().enumerate() {
                d.piece[p][k] += v;
                d.cell[pc.cell as usize][k] += pc.share * v;
            }
        }
        // a shear-dependent piece: the same relative change of its step's blood side
        for (k, &p) in laws.dynamic.iter().enumerate() {
            let seg = self.plan.pieces[p].seg as usize;
            let a = ln_slope
                .get(self.plan.segment_vessels[seg] as usize)
                .copied()
                .unwrap_or(0.0);
            if let Some(x) = d.dynamic.get_mut(k) {
                x[0] += a;
            }
        }
    }

    /// Set the relaxed shears' states in `z` to their periodic values over the flow cycle
    /// `ys` (n_steps + 1 flow states, steps of `dt` read at level `alpha_f`, as
    /// `relax_shears` reads them): over a cycle Q̃ → E Q̃ + b (E = e^n, e = exp(−Δt/τ_BL)),
    /// so Q̃* = b/(1 − E) from one pass of the recursion from zero. The layer relaxes over
    /// ~τ_BL, often many cycles, so the oxygen field would meet its own tolerance long before
    /// the shear it reads repeats; the sensitivities need the periodic state of both.
    pub fn set_periodic_relaxed_shears(
        &self,
        ys: &[Vec<f64>],
        dt: f64,
        alpha_f: f64,
        z: &mut [f64],
    ) {
        for sp in &self.species {
            let laws = &sp.laws;
            for (k, &(j, tau, _)) in laws.relax.iter().enumerate() {
                let e = (-dt / tau).exp();
                if e.is_nan() || e >= 1.0 {
                    continue; // no mean flow: the layer keeps its start
                }
                let u = self.plan.segments[j].branch_unknown as usize;
                let mut v = 0.0;
                for w in ys.windows(2) {
                    let q = (w[0][u] + alpha_f * (w[1][u] - w[0][u])).abs();
                    v = q + (v - q) * e;
                }
                z[laws.relax_offset + k] = v / (1.0 - e.powi((ys.len() - 1) as i32));
            }
        }
    }

    /// A zero tangent of species `s` (the periodic fixed point is found from there).
    pub fn species_tangent_start(&self) -> SpeciesTangent {
        SpeciesTangent {
            dz: vec![0.0; self.plan.cells.len()],
            dacc: [0.0; 4],
            xt: vec![0.0; self.plan.kind.len()],
            dw: Vec::new(),
            dq: Vec::new(),
        }
    }

    /// Advance the tangents of species `s` over the step [t, t + Δt] the primal just took
    /// (`implicit_step`, not carried: its face flows are loaded), from its start amounts
    /// `z_old` and volumes `w_old`; `z` holds the new amounts. `flows`: per parameter, a flow
    /// parameter's flow tangent over the step (None for an oxygen parameter); `x_old`: the
    /// nodes' values before the step ([`Transport::species_node_values`]; read only with
    /// flows). `anchors`: the tangent's own series inverses of the binding per node (kept
    /// from step to step).
    #[allow(clippy::too_many_arguments)]
    pub fn species_tangent_step(
        &mut self,
        s: usize,
        t_af: f64,
        dt: f64,
        z_old: &[f64],
        w_old: &[f64],
        z: &[f64],
        derivs: &[SpeciesDerivative],
        flows: &[Option<FlowStep<'_>>],
        x_old: &[f64],
        tangents: &mut [SpeciesTangent],
        anchors: &mut Vec<HillAnchor>,
    ) -> Result<()> {
        let nc = self.plan.cells.len();
        let binding = self.plan.species[s].binding;
        let zs_old = &z_old[s * nc..(s + 1) * nc];
        let zs = &z[s * nc..(s + 1) * nc];
        let free = &self.species[s].free;
        let guess = |n: usize| {
            free.get(n)
                .copied()
                .filter(|f| f.is_finite())
                .unwrap_or(0.0)
        };
        if anchors.len() != self.plan.kind.len() {
            anchors.resize(self.plan.kind.len(), HillAnchor::default());
        }
        let dyn_g = self.dynamic_conductances(s);
        let mut primal = StepPrimal {
            w: w_old[..nc].to_vec(),
            g: self.step_cell_conductance(s, &dyn_g),
            dyn_g,
            dyn_cbrt: self.dynamic_cbrts(s),
            c: Vec::with_capacity(nc),
            point: Vec::with_capacity(nc),
            x: Vec::with_capacity(nc),
        };
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            let c = zs_old[i] / w_old[i];
            let g = guess(n);
            primal
                .point
                .push(binding_point(&binding, c, g, Some(&mut anchors[n])));
            primal.c.push(c);
            primal.x.push(zs[i] / self.wvol[i]);
        }
        self.load_boundary(s, t_af);
        for (k, (d, t)) in derivs.iter().zip(tangents.iter_mut()).enumerate() {
            let step = flows.get(k).copied().flatten();
            let shear = step.map_or(&[][..], |f| f.shear);
            let forcing = match (&d.flow, step) {
                (Some(f), Some(step)) => {
                    let cells = CellPrimal {
                        w: &primal.w,
                        c: &primal.c,
                        x: &primal.x,
                    };
                    Some(self.flow_forcing(s, dt, f, &step, x_old, cells, &t.dw))
                }
                _ => None,
            };
            self.tangent_solve(s, dt, &primal, (d, shear), t, forcing)?;
        }
        Ok(())
    }

    /// The inflow values of the tangent of parameter `d`: prescribed totals' derivatives,
    /// zero-gradient boundaries as they are (None).
    fn tangent_boundary(&self, s: usize, d: &SpeciesDerivative) -> Vec<Option<f64>> {
        self.boundary_derivative(s, d.kind)
    }

    /// The inflow values' derivative by a parameter of `kind`: prescribed totals' (P50
    /// changes the bound part of a given PO2), zero-gradient boundaries None.
    fn boundary_derivative(&self, s: usize, kind: SpeciesParameterKind) -> Vec<Option<f64>> {
        let binding = self.plan.species[s].binding;
        self.bval
            .iter()
            .map(|b| {
                b.map(|total| match (kind, binding) {
                    (SpeciesParameterKind::P50, Binding::Hill { capacity, .. }) => {
                        capacity * binding_point(&binding, total, total, None).s_p50
                    }
                    _ => 0.0,
                })
            })
            .collect()
    }

    /// One parameter's tangent over the step (see the module doc; a flow parameter's
    /// `forcing`: `tangent_flow.rs`).
    fn tangent_solve(
        &mut self,
        s: usize,
        dt: f64,
        primal: &StepPrimal,
        (d, shear): (&SpeciesDerivative, &[f64]),
        t: &mut SpeciesTangent,
        forcing: Option<FlowForcing>,
    ) -> Result<()> {
        let plan = Arc::clone(&self.plan);
        self.sweep.size_rows(plan.kind.len());
        let mut wall = self.tangent_rows(s, dt, primal, (d, shear), t, forcing.as_ref());
        for &m in &plan.mixing {
            let sw = &mut self.sweep;
            (sw.den[m], sw.num[m], sw.lag[m]) = (0.0, 0.0, t.xt[m]);
        }
        if let Some(f) = &forcing {
            for (b, r) in self.sweep.num.iter_mut().zip(&f.num) {
                *b += r;
            }
        }
        let mut bval = self.tangent_boundary(s, d);
        std::mem::swap(&mut self.bval, &mut bval);
        let mut xt = std::mem::take(&mut t.xt);
        let res = if plan.tree.is_some() {
            self.tree_solve(&mut xt);
            Ok(())
        } else if let Some(core) = &plan.core {
            // the primal's matrix with its pendant trees eliminated around the loops' core
            self.core_solve(core, &mut xt)
        } else {
            let (den, num) = (self.sweep.den.clone(), self.sweep.num.clone());
            self.sweep_solve(&plan.domain, &den, &num, &mut xt)
        };
        // the boundary fluxes of the tangent: the same upwind rule on x′ and the inflows′
        std::mem::swap(&mut self.conc, &mut xt);
        let (mut d_in, mut d_out) = self.implicit_boundary_fluxes();
        std::mem::swap(&mut self.conc, &mut xt);
        std::mem::swap(&mut self.bval, &mut bval);
        res?;
        let lambda = self.plan.species[s].decay;
        let mut decay = 0.0;
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let wl = primal.g[i] * primal.point[i].sigma;
            wall += wl * xt[n];
            // z′ = W' x′ + W'′ x
            let dz = self.wvol[i] * xt[n] + forcing.as_ref().map_or(0.0, |f| f.dz[i]);
            decay += lambda * dz;
            t.dz[i] = dz;
        }
        t.xt = xt;
        if let Some(f) = forcing {
            (d_in, d_out) = (d_in + f.d_in, d_out + f.d_out);
            (t.dw, t.dq) = (f.dw_new, f.dq);
        }
        for (a, v) in t.dacc.iter_mut().zip([d_in, d_out, wall, decay]) {
            *a += dt * v;
        }
        Ok(())
    }

    /// The cells' rows of one parameter's tangent into `sweep.den`, `sweep.num` (the
    /// primal's matrix, the right side of the module doc without a flow parameter's
    /// `forcing`, whose old concentrations' part is added here), the old concentrations'
    /// tangent into `t.xt`; returns the wall flux's part known before the solve (without
    /// w_l x′).
    fn tangent_rows(
        &mut self,
        s: usize,
        dt: f64,
        primal: &StepPrimal,
        (d, shear): (&SpeciesDerivative, &[f64]),
        t: &mut SpeciesTangent,
        forcing: Option<&FlowForcing>,
    ) -> f64 {
        let rate = 1.0 / dt + self.plan.species[s].decay;
        let p50 = d.kind == SpeciesParameterKind::P50;
        let mut wall = 0.0;
        let plan = Arc::clone(&self.plan);
        let at = (&primal.dyn_g[..], &primal.dyn_cbrt[..]);
        let dynamic = self.dynamic_cell_derivative(s, d, at, shear);
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let g = primal.g[i];
            let [mut dg, mut dgcw, dq] = d.cell[i];
            if let Some([a, b]) = dynamic.get(i) {
                (dg, dgcw) = (dg + a, dgcw + b);
            }
            let pt = &primal.point[i];
            // c′ = z′/W − c W′/W
            let dc = t.dz[i] / primal.w[i] + forcing.map_or(0.0, |f| f.dc[i]);
            let (fd, sd) = if p50 {
                (pt.f_p50, pt.sigma_p50)
            } else {
                (0.0, 0.0)
            };
            let df = pt.sigma * dc + fd;
            let dsigma = pt.sigma_c * dc + sd;
            let wl = g * pt.sigma;
            let dwl = dg * pt.sigma + g * dsigma;
            let dwc = dg * pt.f + g * df - dgcw + dq - dwl * primal.c[i] - wl * dc;
            self.sweep.den[n] = self.wvol[i] * rate + wl;
            self.sweep.num[n] = t.dz[i] / dt - dwc - dwl * primal.x[i];
            t.xt[n] = dc;
            wall += dwl * primal.x[i] + dwc; // (+ w_l x′ after the solve)
        }
        wall
    }
}

/// A vessel's species signal the tangent reports (at the end of each step).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VesselSpeciesSignal {
    /// Free concentration at the outlet (mol/m³).
    Concentration,
    /// PO2 at the outlet (Pa; Hill binding).
    Po2,
    /// Haemoglobin saturation at the outlet (Hill binding).
    Saturation,
    /// The step's flow through the outlet face (m³/s; a flow parameter changes it).
    Flow,
    /// Wall uptake of the vessel's segments (mol/s).
    WallUptake,
}

impl Transport {
    /// The domain node whose value leaves output vessel `k` (named `name`) at forward flow:
    /// its last cell, or the upwind node of its last face; an error at backflow (the value
    /// carried into the outlet is not differentiated).
    fn outlet_node(&self, k: usize, name: &str) -> Result<usize> {
        let v = &self.plan.out_vessels[k];
        let refuse = |why: &str| {
            Error::model(
                format!("output '{name}'"),
                format!("oxygen sensitivities at this outlet: {why}"),
            )
        };
        if v.last >= self.plan.faces.len() {
            return Err(refuse("the vessel has no outlet face"));
        }
        if self.qf[v.last] < 0.0 {
            return Err(refuse("backflow through it is not differentiated yet"));
        }
        let n = if v.outlet_cell != u32::MAX {
            self.plan.last_sub(v.outlet_cell as usize)
        } else {
            match oriented(&self.plan.faces, &self.qf, v.last).1 {
                End::Node(n) => n,
                End::Boundary(_) => return Err(refuse("no cell upstream of it")),
            }
        };
        match self.plan.node_cell.get(n) {
            Some(&i) if i != u32::MAX => Ok(n),
            _ => Err(refuse("no cell upstream of it")),
        }
    }

    /// Total concentration, its tangents and the binding of domain node `n` of species `s`
    /// at the end of a step (amounts `z`).
    fn node_state(
        &self,
        s: usize,
        n: usize,
        z: &[f64],
        tangents: &[SpeciesTangent],
    ) -> (BindingPoint, Vec<f64>) {
        let nc = self.plan.cells.len();
        let i = self.plan.node_cell[n] as usize;
        let x = z[s * nc + i] / self.wvol[i];
        let guess = self.species[s].free.get(n).copied().unwrap_or(0.0);
        let pt = binding_point(&self.plan.species[s].binding, x, guess, None);
        (pt, tangents.iter().map(|t| t.xt[n]).collect())
    }

    /// The value of `signal` of output vessel `k` (named `name`) of species `s` after the
    /// step the tangents just took, and its derivative by each parameter (`shears`: per
    /// parameter, a flow parameter's [`FlowStep::shear`] of the step, else empty).
    #[allow(clippy::too_many_arguments)]
    pub fn species_vessel_signal(
        &self,
        s: usize,
        k: usize,
        name: &str,
        signal: VesselSpeciesSignal,
        z: &[f64],
        derivs: &[SpeciesDerivative],
        (tangents, shears): (&[SpeciesTangent], &[&[f64]]),
    ) -> Result<(f64, Vec<f64>)> {
        let binding = self.plan.species[s].binding;
        let p50 = |d: &SpeciesDerivative| d.kind == SpeciesParameterKind::P50;
        match signal {
            VesselSpeciesSignal::Flow => {
                let v = &self.plan.out_vessels[k];
                let q = self.qf.get(v.last).copied().unwrap_or(f64::NAN);
                let dq = |t: &SpeciesTangent| t.dq.get(v.last).copied().unwrap_or(0.0);
                Ok((q, tangents.iter().map(dq).collect()))
            }
            VesselSpeciesSignal::WallUptake => {
                Ok(self.vessel_uptake(s, k, z, derivs, (tangents, shears)))
            }
            _ => {
                let n = self.outlet_node(k, name)?;
                let (pt, xt) = self.node_state(s, n, z, tangents);
                let df = |(d, x): (&SpeciesDerivative, &f64)| {
                    pt.sigma * x + if p50(d) { pt.f_p50 } else { 0.0 }
                };
                let dfs: Vec<f64> = derivs.iter().zip(&xt).map(df).collect();
                let alpha = match binding {
                    Binding::Hill { alpha, .. } => alpha,
                    _ if signal == VesselSpeciesSignal::Concentration => 1.0,
                    _ => {
                        return Err(Error::model(
                            format!("output '{name}'"),
                            "PO2 and saturation need haemoglobin (a Hill binding)",
                        ));
                    }
                };
                Ok(match signal {
                    VesselSpeciesSignal::Concentration => (pt.f, dfs),
                    VesselSpeciesSignal::Po2 => {
                        (pt.f / alpha, dfs.iter().map(|d| d / alpha).collect())
                    }
                    _ => {
                        let ds = derivs.iter().zip(&dfs).map(|(d, df)| {
                            pt.s_p * df / alpha + if p50(d) { pt.s_p50 } else { 0.0 }
                        });
                        (pt.s, ds.collect())
                    }
                })
            }
        }
    }

    /// Wall uptake of output vessel `k`'s segments, Σ share (g (f − c_w) + q) over their
    /// pieces at the end-of-step free concentrations, and its derivatives.
    fn vessel_uptake(
        &self,
        s: usize,
        k: usize,
        z: &[f64],
        derivs: &[SpeciesDerivative],
        (tangents, shears): (&[SpeciesTangent], &[&[f64]]),
    ) -> (f64, Vec<f64>) {
        let v = &self.plan.out_vessels[k];
        let (mut w, mut dw) = (0.0, vec![0.0; derivs.len()]);
        for j in self.plan.out_segments[v.segs.clone()]
            .iter()
            .map(|&j| j as usize)
        {
            for p in self.plan.seg_pieces(j) {
                let pc = &self.plan.pieces[p];
                let (g, cw, q, k) = self.piece_law_at_step(s, p);
                let n = pc.node as usize;
                let (pt, xt) = self.node_state(s, n, z, tangents);
                w += pc.share * (g * (pt.f - cw) + q);
                let cbrt = self.species[s].shear_cbrt.get(pc.seg as usize);
                for (pi, (d, x)) in derivs.iter().zip(&xt).enumerate() {
                    let [dg, dgcw, dq] = match k {
                        Some(k) => {
                            let shear = shears.get(pi).copied().unwrap_or(&[]);
                            let cbrt = cbrt.copied().unwrap_or(0.0);
                            let (dg, dgcw) = self.dynamic_piece_derivative(s, d, k, g, cbrt, shear);
                            [dg, dgcw, 0.0]
                        }
                        None => d.piece[p],
                    };
                    let p50 = if d.kind == SpeciesParameterKind::P50 {
                        pt.f_p50
                    } else {
                        0.0
                    };
                    let df = pt.sigma * x + p50;
                    dw[pi] += pc.share * (dg * pt.f + g * df - dgcw + dq);
                }
            }
        }
        (w, dw)
    }
}

impl Transport {
    /// Wall piece `p`'s law of species `s` at the step just taken, (g, c_w, q), and its
    /// index among the shear-dependent pieces (None: a fixed law).
    pub(super) fn piece_law_at_step(&self, s: usize, p: usize) -> (f64, f64, f64, Option<usize>) {
        let sp = &self.species[s];
        match sp.laws.laws[p] {
            SegmentLaw::Fixed { g, cw, q } => (g, cw, q, None),
            law => {
                let seg = self.plan.pieces[p].seg as usize;
                let (g, cw, q) = law.eval_cbrt(sp.shear_cbrt[seg]);
                (g, cw, q, sp.laws.dynamic.binary_search(&p).ok())
            }
        }
    }

    /// The transport volumes W of the cells (m³) after the last implicit step.
    pub fn cell_volumes(&self) -> &[f64] {
        &self.wvol
    }
}
