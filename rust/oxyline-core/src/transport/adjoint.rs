//! The adjoint (transpose) of the species step's tangent by oxygen parameters
//! (`tangent.rs`): one backward sweep over the stored primal gives the derivative of a
//! functional J = Σ_k Σ_j w_kj · signal_j(step k) by every oxygen parameter at once.
//!
//! The tangent of a step is linear in the carried tangent (the cells' amounts z′ and the
//! lagged values x′ of the nodes that are not cells) and in the parameter:
//!
//!   c′ = z′/W,   b = z′/Δt − w_c′ − w_l′ x,   x′ = A⁻¹(b; lagged values),   z′_new = W' x′,
//!
//! with w_l′, w_c′ linear in c′ and in the parameter (the binding's slopes at the old state).
//! The adjoint runs each piece transposed in reverse order: the signals' and the
//! accumulators' weights seed λ_x (the adjoint of x′), the tree elimination is transposed
//! (its back substitution first, children before parents, then its elimination, parents
//! before children; on a network with loops the flow-order sweep's system instead,
//! `sweep_adjoint.rs`), then the rows: λ_z = λ_b/Δt + (λ of c′)/W. The parameters' terms of each
//! piece are accumulated into the gradient on the way.
//!
//! A flow parameter drives the step through its own right-hand side at a zero carried
//! tangent (`tangent_flow.rs`' [`FlowForcing`]: the face flows', volumes' and geometry's
//! terms, from the flow's tangent); its derivative is that right-hand side contracted with
//! the step's adjoint ([`StepDuals`]), summed over the cycle (the mixed mode: the flow
//! forward, the species backward).

#[allow(unused_imports)]
use super::*;

#[path = "sweep_adjoint.rs"]
mod sweep;

/// The primal of one step, as the adjoint reads it back: the step's loaded face and source
/// flows, the cells' old volumes, old total concentrations and their binding, and new
/// volumes and total concentrations.
#[derive(Debug, Clone)]
pub struct SpeciesStepRecord {
    t_af: f64,
    qf: Vec<f64>,
    qs: Vec<f64>,
    w_old: Vec<f64>,
    w_new: Vec<f64>,
    c: Vec<f64>,
    point: Vec<BindingPoint>,
    x: Vec<f64>,
    /// The step's wall conductance per cell and each shear-dependent piece's own.
    g: Vec<f64>,
    dyn_g: Vec<f64>,
    /// The cube root of the flow magnitude each shear-dependent piece's law read.
    dyn_cbrt: Vec<f64>,
    /// Every node's total concentration before and after the step (a flow parameter's
    /// forcing reads them; empty without flow parameters).
    nodes_old: Vec<f64>,
    nodes_new: Vec<f64>,
}

/// The adjoint of one step's pieces a flow parameter's forcing enters: of the rows' right
/// side (per node), of the old concentrations c′ (per cell), of the new amounts z′ (per
/// cell), the network fluxes' weights (inflow, outflow, wall), and per cell the weights of
/// the step's dg and d(g c_w) (a shear-dependent piece's g moves step by step).
#[derive(Debug, Clone, Default)]
pub struct StepDuals {
    lnum: Vec<f64>,
    ldc: Vec<f64>,
    ldz: Vec<f64>,
    net: [f64; 3],
    weights: Vec<(f64, f64)>,
}

/// The adjoint of the carried tangent: of the cells' amounts (per cell) and of the lagged
/// values of the nodes that are not cells (per node; zero on cells).
#[derive(Debug, Clone)]
pub struct SpeciesAdjointState {
    pub dz: Vec<f64>,
    pub xt: Vec<f64>,
}

/// A signal of one step, linearised: its value, its weights on the step's new total
/// concentrations x′ (node, coefficient), and its direct derivative by each parameter.
#[derive(Debug, Clone)]
pub struct SignalRow {
    pub value: f64,
    pub nodes: Vec<(usize, f64)>,
    pub direct: Vec<f64>,
    /// A flow signal's face: its derivative by a flow parameter is the face flow's.
    pub face: Option<usize>,
}

/// The parameters' terms of the adjoint steps, summed over a cycle: the fixed laws'
/// coefficients are fixed in time, so a parameter's derivative is Σ_i dg_i a_i +
/// (dq_i − d(g c_w)_i) e_i over the cells, plus `p50` for Hill's P50 (its binding's partial
/// derivatives and the inlets' total concentration). A shear-dependent piece's g follows
/// the shear step by step, but a parameter moves it by fixed logarithmic rates (of its
/// blood side and of c_w), so it keeps two sums per piece: `dyn_g`, Σ_k b g (a − c_w e)
/// (b its blood side's share), and `dyn_cw`, −Σ_k g c_w e, each over the steps.
#[derive(Debug, Clone)]
pub struct AdjointSums {
    pub a: Vec<f64>,
    pub e: Vec<f64>,
    pub p50: f64,
    pub dyn_g: Vec<f64>,
    pub dyn_cw: Vec<f64>,
}

impl AdjointSums {
    pub fn new(nc: usize) -> Self {
        AdjointSums {
            a: vec![0.0; nc],
            e: vec![0.0; nc],
            p50: 0.0,
            dyn_g: Vec::new(),
            dyn_cw: Vec::new(),
        }
    }

    /// The derivative of the functional by the parameter of `d` (without its signals'
    /// direct terms).
    pub fn gradient(&self, d: &SpeciesDerivative) -> f64 {
        let cells = (d.cell.iter().zip(&self.a).zip(&self.e))
            .map(|((&[dg, dgcw, dq], a), e)| dg * a + (dq - dgcw) * e)
            .sum::<f64>();
        let dynamic = (d.dynamic.iter().zip(&self.dyn_g).zip(&self.dyn_cw))
            .map(|((&[ln_g, ln_cw], g), cw)| ln_g * g + ln_cw * cw)
            .sum::<f64>();
        cells
            + dynamic
            + if d.kind == SpeciesParameterKind::P50 {
                self.p50
            } else {
                0.0
            }
    }
}

impl Transport {
    /// Refuse what the species adjoint does not follow: what the tangent does not
    /// ([`Transport::check_species_tangent`]; a network with loops is followed through its
    /// flow-order sweep's system transposed, `sweep_adjoint.rs`).
    pub fn check_species_adjoint(&self, s: usize, element: &str) -> Result<()> {
        self.check_species_tangent(s, element)
    }

    /// A zero adjoint state of species `s`'s tangent.
    pub fn species_adjoint_start(&self) -> SpeciesAdjointState {
        SpeciesAdjointState {
            dz: vec![0.0; self.plan.cells.len()],
            xt: vec![0.0; self.plan.kind.len()],
        }
    }

    /// The record of the step species `s` just took (`implicit_step` from amounts `z_old`,
    /// volumes `w_old` to amounts `z`; its flows still loaded); `nodes_old`, the nodes'
    /// values before it ([`Transport::species_node_values`]) when flow parameters will
    /// read the record, else empty.
    pub fn species_step_record(
        &self,
        s: usize,
        t_af: f64,
        z_old: &[f64],
        w_old: &[f64],
        z: &[f64],
        nodes_old: Vec<f64>,
    ) -> SpeciesStepRecord {
        let nc = self.plan.cells.len();
        let binding = self.plan.species[s].binding;
        let free = &self.species[s].free;
        let (mut c, mut point, mut x) = (
            Vec::with_capacity(nc),
            Vec::with_capacity(nc),
            Vec::with_capacity(nc),
        );
        for (i, n) in self.plan.cells.iter().map(|&n| n as usize).enumerate() {
            let ci = z_old[s * nc + i] / w_old[i];
            let guess = free
                .get(n)
                .copied()
                .filter(|f| f.is_finite())
                .unwrap_or(0.0);
            point.push(binding_point(&binding, ci, guess, None));
            c.push(ci);
            x.push(z[s * nc + i] / self.wvol[i]);
        }
        let dyn_g = self.dynamic_conductances(s);
        SpeciesStepRecord {
            g: self.step_cell_conductance(s, &dyn_g),
            dyn_g,
            dyn_cbrt: self.dynamic_cbrts(s),
            t_af,
            qf: self.qf.clone(),
            qs: self.qs.clone(),
            w_old: w_old[..nc].to_vec(),
            w_new: self.wvol[..nc].to_vec(),
            c,
            point,
            x,
            nodes_new: if nodes_old.is_empty() {
                Vec::new()
            } else {
                self.conc.clone()
            },
            nodes_old,
        }
    }

    /// Signal `signal` of output vessel `k` (named `name`) of species `s` after the step
    /// just taken (amounts `z`), linearised in the new total concentrations (see
    /// [`SignalRow`]); the value and derivatives agree with
    /// [`Transport::species_vessel_signal`] (`shears` as there).
    #[allow(clippy::too_many_arguments)]
    pub fn species_signal_row(
        &self,
        s: usize,
        k: usize,
        name: &str,
        signal: VesselSpeciesSignal,
        z: &[f64],
        (derivs, shears): (&[SpeciesDerivative], &[&[f64]]),
    ) -> Result<SignalRow> {
        let np = derivs.len();
        let p50 = |d: &SpeciesDerivative| d.kind == SpeciesParameterKind::P50;
        let mut row = SignalRow {
            value: 0.0,
            nodes: Vec::new(),
            direct: vec![0.0; np],
            face: None,
        };
        match signal {
            VesselSpeciesSignal::Flow => {
                // the flow does not depend on oxygen parameters; a flow parameter's
                // derivative is its face's
                let v = &self.plan.out_vessels[k];
                row.value = self.qf.get(v.last).copied().unwrap_or(f64::NAN);
                row.face = (v.last < self.plan.faces.len()).then_some(v.last);
            }
            VesselSpeciesSignal::WallUptake => {
                let v = &self.plan.out_vessels[k];
                for j in self.plan.out_segments[v.segs.clone()]
                    .iter()
                    .map(|&j| j as usize)
                {
                    for p in self.plan.seg_pieces(j) {
                        let pc = &self.plan.pieces[p];
                        let (g, cw, q, dynamic) = self.piece_law_at_step(s, p);
                        let n = pc.node as usize;
                        let (pt, _) = self.node_state(s, n, z, &[]);
                        row.value += pc.share * (g * (pt.f - cw) + q);
                        row.nodes.push((n, pc.share * g * pt.sigma));
                        let cbrt = self.species[s].shear_cbrt.get(pc.seg as usize);
                        for (pi, (dr, d)) in row.direct.iter_mut().zip(derivs).enumerate() {
                            let [dg, dgcw, dq] = match dynamic {
                                Some(k) => {
                                    let shear = shears.get(pi).copied().unwrap_or(&[]);
                                    let cbrt = cbrt.copied().unwrap_or(0.0);
                                    let (dg, dgcw) =
                                        self.dynamic_piece_derivative(s, d, k, g, cbrt, shear);
                                    [dg, dgcw, 0.0]
                                }
                                None => d.piece[p],
                            };
                            let fd = if p50(d) { pt.f_p50 } else { 0.0 };
                            *dr += pc.share * (dg * pt.f + g * fd - dgcw + dq);
                        }
                    }
                }
            }
            _ => {
                let n = self.outlet_node(k, name)?;
                let (pt, _) = self.node_state(s, n, z, &[]);
                let alpha = match self.plan.species[s].binding {
                    Binding::Hill { alpha, .. } => alpha,
                    _ if signal == VesselSpeciesSignal::Concentration => 1.0,
                    _ => {
                        return Err(Error::model(
                            format!("output '{name}'"),
                            "PO2 and saturation need haemoglobin (a Hill binding)",
                        ));
                    }
                };
                // f′ = σ x′ + ∂f/∂P50
                let (scale, value, extra) = match signal {
                    VesselSpeciesSignal::Concentration => (1.0, pt.f, 0.0),
                    VesselSpeciesSignal::Po2 => (1.0 / alpha, pt.f / alpha, 0.0),
                    _ => (pt.s_p / alpha, pt.s, pt.s_p50),
                };
                row.value = value;
                row.nodes.push((n, scale * pt.sigma));
                for (dr, d) in row.direct.iter_mut().zip(derivs) {
                    if p50(d) {
                        *dr = scale * pt.f_p50 + extra;
                    }
                }
            }
        }
        Ok(row)
    }

    /// One step of the adjoint, backwards over the step `rec` of species `s`: on entry
    /// `lam` holds the adjoint of the tangent after the step, `seed` the weights of this
    /// step's signals on the new total concentrations (per node) and `net` those of its
    /// network fluxes (inflow, outflow, wall uptake); on return `lam` holds the adjoint of
    /// the tangent before the step, and `sums` has gained the step's parameter terms;
    /// `duals` (for flow parameters) receives the step's [`StepDuals`].
    #[allow(clippy::too_many_arguments)]
    pub fn species_adjoint_step(
        &mut self,
        s: usize,
        dt: f64,
        rec: &SpeciesStepRecord,
        seed: &[f64],
        net: [f64; 3],
        lam: &mut SpeciesAdjointState,
        sums: &mut AdjointSums,
        mut duals: Option<&mut StepDuals>,
    ) {
        self.ensure_scratch();
        self.qf.copy_from_slice(&rec.qf);
        self.qs.copy_from_slice(&rec.qs);
        self.load_boundary(s, rec.t_af);
        let plan = Arc::clone(&self.plan);
        let lambda = plan.species[s].decay;
        let rate = 1.0 / dt + lambda;
        let nn = plan.kind.len();
        // λ of x′: the signals, the next step's lagged values, z′_new = W' x′, the wall flux
        let mut lx = seed.to_vec();
        for (n, l) in lx.iter_mut().enumerate() {
            if plan.node_cell.get(n).is_none_or(|&i| i == u32::MAX) {
                *l += lam.xt[n];
            }
        }
        let mut den = vec![0.0; nn];
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let wl = rec.g[i] * rec.point[i].sigma;
            lx[n] += rec.w_new[i] * lam.dz[i] + net[2] * wl;
            den[n] = rec.w_new[i] * rate + wl;
        }
        let bd = self.boundary_derivative(s, SpeciesParameterKind::P50);
        let mut lprior = vec![0.0; nn];
        sums.p50 += self.boundary_fluxes_adjoint(net, &bd, &mut lx, &mut lprior);
        let (lnum, p50) = if plan.tree.is_some() {
            self.tree_solve_adjoint(&mut den, &mut lx, &mut lprior, &bd)
        } else {
            self.sweep_solve_adjoint(&den, &lx, &mut lprior, &bd)
        };
        sums.p50 += p50;
        if let Some(du) = duals.as_deref_mut() {
            du.ldz.clone_from(&lam.dz);
            du.ldc.resize(plan.cells.len(), 0.0);
            du.net = net;
        }
        // the rows (`tangent_rows`), transposed; per cell the weights of dg and d(g c_w)
        let mut weights = vec![(0.0, 0.0); plan.cells.len()];
        for (i, n) in plan.cells.iter().map(|&n| n as usize).enumerate() {
            let g = rec.g[i];
            let pt = &rec.point[i];
            let (c, x) = (rec.c[i], rec.x[i]);
            let wl = g * pt.sigma;
            // J reads w_c′ with e = ω_wall − λ_b, w_l′ with e (x − c) (w_c′ holds −w_l′ c)
            let e = net[2] - lnum[n];
            let ldwl = e * (x - c);
            let ldc = lprior[n] + e * (g * pt.sigma - wl) + ldwl * g * pt.sigma_c;
            lam.dz[i] = lnum[n] / dt + ldc / rec.w_old[i];
            if let Some(du) = duals.as_deref_mut() {
                du.ldc[i] = ldc;
            }
            // w_l′ ∋ dg σ + g ∂σ/∂P50, w_c′ ∋ dg f + g ∂f/∂P50 − d(g c_w) + dq
            sums.a[i] += ldwl * pt.sigma + e * pt.f;
            sums.e[i] += e;
            weights[i] = (ldwl * pt.sigma + e * pt.f, e);
            sums.p50 += g * (ldwl * pt.sigma_p50 + e * pt.f_p50);
        }
        self.dynamic_sums(s, rec, &weights, sums);
        if let Some(du) = duals.as_deref_mut() {
            du.weights = weights;
        }
        for (n, l) in lam.xt.iter_mut().enumerate() {
            let cell = plan.node_cell.get(n).is_some_and(|&i| i != u32::MAX);
            *l = if cell { 0.0 } else { lprior[n] };
        }
        if let Some(du) = duals {
            du.lnum = lnum;
        }
    }

    /// The shear-dependent pieces' terms of one adjoint step ([`AdjointSums`]): `weights`
    /// per cell (the weight of dg, that of dq − d(g c_w)).
    fn dynamic_sums(
        &self,
        s: usize,
        rec: &SpeciesStepRecord,
        weights: &[(f64, f64)],
        sums: &mut AdjointSums,
    ) {
        let laws = &self.species[s].laws;
        if laws.dynamic.is_empty() {
            return;
        }
        sums.dyn_g.resize(laws.dynamic.len(), 0.0);
        sums.dyn_cw.resize(laws.dynamic.len(), 0.0);
        for (k, (&p, &g)) in laws.dynamic.iter().zip(&rec.dyn_g).enumerate() {
            let pc = &self.plan.pieces[p];
            let SegmentLaw::Instantaneous { cw, .. } = laws.laws[p] else {
                continue;
            };
            let (a, e) = weights[pc.cell as usize];
            let b = self.blood_side_share(s, p, g);
            sums.dyn_g[k] += pc.share * b * g * (a - cw * e);
            sums.dyn_cw[k] -= pc.share * g * cw * e;
        }
    }

    /// Flow parameter `d`'s term of the gradient from the step `rec` of species `s` whose
    /// adjoint step (`duals`) was just taken (its flows and boundary values still loaded):
    /// the parameter's forcing of the step ([`FlowForcing`], its flow tangent over the step
    /// `step`) contracted with the step's adjoint, plus the flow signals' weights `faces`
    /// (face, weight) on the face flows' tangent. On entry `dw` holds the transport volumes'
    /// tangent after the step, on return before it.
    #[allow(clippy::too_many_arguments)]
    pub fn species_flow_adjoint_step(
        &mut self,
        s: usize,
        dt: f64,
        rec: &SpeciesStepRecord,
        d: &SpeciesDerivative,
        step: &FlowStep<'_>,
        dw: &mut Vec<f64>,
        duals: &StepDuals,
        faces: &[(usize, f64)],
    ) -> f64 {
        let Some(f) = &d.flow else {
            return 0.0;
        };
        self.conc.copy_from_slice(&rec.nodes_new);
        *dw = self.flow_volumes_before(dt, f, step, dw);
        let cells = CellPrimal {
            w: &rec.w_old,
            c: &rec.c,
            x: &rec.x,
        };
        let fc = self.flow_forcing(s, dt, f, step, &rec.nodes_old, cells, dw);
        let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
        // the shear-dependent pieces' dg of this step, weighted as `dynamic_sums` weighs them
        let at = (&rec.dyn_g[..], &rec.dyn_cbrt[..]);
        let dynamic = (self.dynamic_cell_derivative(s, d, at, step.shear).iter())
            .zip(&duals.weights)
            .map(|(&[dg, dgcw], &(a, e))| dg * a - dgcw * e)
            .sum::<f64>();
        dynamic
            + dot(&duals.ldc, &fc.dc)
            + dot(&duals.lnum, &fc.num)
            + dot(&duals.ldz, &fc.dz)
            + duals.net[0] * fc.d_in
            + duals.net[1] * fc.d_out
            + faces.iter().map(|&(fi, w)| w * fc.dq[fi]).sum::<f64>()
    }

    /// The boundary fluxes' part of the accumulators (`implicit_boundary_fluxes` on the
    /// tangent), transposed: weights `net` (inflow, outflow) onto λ_x (a node's value
    /// leaving), λ of the lagged values (zero-gradient inflow); returns the P50 term of the
    /// prescribed inflows (`bd`: their total concentration's derivative by P50).
    fn boundary_fluxes_adjoint(
        &self,
        net: [f64; 3],
        bd: &[Option<f64>],
        lx: &mut [f64],
        lprior: &mut [f64],
    ) -> f64 {
        let plan = &*self.plan;
        let mut p50 = 0.0;
        let mut flux = |n: usize, bb: usize, inflow: f64, upwind: bool| {
            let w = if plan.boundary_inlet[bb] {
                net[0]
            } else {
                -net[1]
            };
            if w == 0.0 {
                return;
            }
            if !upwind {
                lx[n] += w * inflow;
            } else if self.bval[bb].is_none() {
                lprior[n] += w * inflow;
            } else {
                p50 += w * inflow * bd[bb].unwrap_or(0.0);
            }
        };
        for b in &plan.boundary_links {
            let q = self.qf[b.face as usize];
            flux(
                b.node as usize,
                b.boundary as usize,
                b.inflow(q),
                b.boundary_upwind(q),
            );
        }
        for (&(n, _, bb), &q) in plan.sources.iter().zip(&self.qs) {
            flux(n, bb, q, q >= 0.0);
        }
        p50
    }

    /// `tree_solve` transposed: from λ of the solution `lx` (consumed) the λ of the right
    /// sides and the P50 term of the prescribed inflows (`bd`) (returned), and of the
    /// lagged values (`lprior`: unsolvable rows and zero-gradient inflows). `den` holds the
    /// rows' own d on entry (their flows are added here, as the solve adds them).
    fn tree_solve_adjoint(
        &self,
        den: &mut [f64],
        lx: &mut [f64],
        lprior: &mut [f64],
        bd: &[Option<f64>],
    ) -> (Vec<f64>, f64) {
        let plan = &*self.plan;
        let tree = plan
            .tree
            .as_deref()
            .expect("a forest: `species_adjoint_step` sends loops to the sweep's transpose");
        let qf = &self.qf[..];
        // the boundaries' outflows, then the tree faces', into d (as `boundary_rows` and
        // the elimination add them); per link: |Q| and whether it flows to the parent
        for &fi in &plan.boundary_faces {
            if let (q, End::Node(n), _) = oriented(&plan.faces, qf, fi) {
                den[n] += q.abs();
            }
        }
        for (&(n, _, _), &q) in plan.sources.iter().zip(&self.qs) {
            if q < 0.0 {
                den[n] -= q;
            }
        }
        let links: Vec<(f64, bool)> = tree
            .iter()
            .map(|l| {
                if l.parent == u32::MAX {
                    return (0.0, false);
                }
                let q = qf[l.face() as usize];
                let to_parent = (q >= 0.0) == l.face_from_child();
                if to_parent {
                    den[l.node as usize] += q.abs();
                } else {
                    den[l.parent as usize] += q.abs();
                }
                (q.abs(), to_parent)
            })
            .collect();
        // back substitution x_n += β_n x_parent, transposed (children first)
        for (l, &(aq, to_parent)) in tree.iter().zip(&links) {
            let n = l.node as usize;
            if !to_parent && aq != 0.0 && den[n] > 1e-300 {
                lx[l.parent as usize] += aq / den[n] * lx[n];
            }
        }
        // elimination x_n = b_n / d_n, b_parent += |Q| x_n, transposed (parents first)
        let mut lnum = vec![0.0; plan.kind.len()];
        for (l, &(aq, to_parent)) in tree.iter().zip(&links).rev() {
            let n = l.node as usize;
            if to_parent {
                lx[n] += aq * lnum[l.parent as usize];
            }
            if den[n] > 1e-300 {
                lnum[n] += lx[n] / den[n];
            } else {
                lprior[n] += lx[n];
            }
        }
        // `boundary_rows`' inflows b_n += |Q| (prescribed or lagged value), transposed
        let mut p50 = 0.0;
        let mut inflow = |n: usize, bb: usize, aq: f64| {
            if self.bval[bb].is_none() {
                lprior[n] += aq * lnum[n];
            } else {
                p50 += aq * lnum[n] * bd[bb].unwrap_or(0.0);
            }
        };
        for &fi in &plan.boundary_faces {
            if let (q, End::Boundary(bb), End::Node(n)) = oriented(&plan.faces, qf, fi) {
                inflow(n, bb, q.abs());
            }
        }
        for (&(n, _, bb), &q) in plan.sources.iter().zip(&self.qs) {
            if q >= 0.0 {
                inflow(n, bb, q);
            }
        }
        (lnum, p50)
    }
}
