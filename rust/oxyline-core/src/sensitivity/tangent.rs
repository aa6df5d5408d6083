//! Forward (tangent-linear) sensitivities of generalized-α on a linear circuit
//! E ẏ + F y = f(t), at its periodic state.
//!
//! A step of `integrate::genalpha` (linear path) solves K Δ = r with K = α_m E + α_f γ Δt F and
//! r = f(t + α_f Δt) − c E ẏ − F y (c = 1 + α_m (pred − 1), pred = (γ − 1)/γ), then
//! y ← y + γ Δt Δ, ẏ ← pred ẏ + Δ. Differentiating with respect to a parameter p (s = dy/dp,
//! ṡ = dẏ/dp, dE, dF, df the derivatives of the DAE):
//!
//!   K dΔ = df − dE (c ẏ + α_m Δ) − dF (y + α_f γ Δt Δ) − c E ṡ − F s,
//!
//! the same matrix K, so each parameter costs one more solve per step on the one
//! factorisation. The tangent is exact for the discrete scheme: it is the derivative of the
//! numbers the run computes, not of the ODE's solution.
//!
//! The periodic state: the forward run repeats cycles until y at a cycle start repeats to
//! `tol` relative to the state's scale. Its periodic cycle is then run once more with every
//! tangent, which records each parameter's source (the terms of the primal above; they touch
//! few rows) per step. The periodic tangent is the fixed point of the tangent's cycle map
//! x ↦ Φ x + b_p (Φ the monodromy, shared with the primal; b_p the cycle's response to the
//! recorded source from x = 0), found by [`super::krylov`] in a few cycles of the tangent alone
//! (no primal, no re-run of the forward loop) instead of the forward run's count. A tangent
//! counts as periodic when p·s at a cycle start repeats to `tol` (p·s is the state's response
//! to a 100 % change of p); the last such cycle is the one recorded.
//!
//! Stenoses add c(y) = S |Q| Q to their branch rows. The primal is then the run loop's own
//! Newton step (`integrate::genalpha`), and the converged step satisfies
//! E (c ẏ + α_m Δ) + F y_αf + c(y_αf) = f with y_αf = y + α_f γ Δt Δ, whose derivative is
//!
//!   K_k dΔ = df − dE (c ẏ + α_m Δ) − dF y_αf − (dS) |Q_αf| Q_αf − c E ṡ − (F + J_k) s,
//!
//! K_k = α_m E + α_f γ Δt (F + J_k), J_k = diag(2 S |Q_αf|) at step k of the periodic cycle.
//! The tangent's cycle map is still linear in (s, ṡ) and the same for every parameter (its Φ
//! is the linearised monodromy), so the fixed-point iteration is unchanged; only K_k varies
//! along the cycle, so each tangent cycle refactorises once per step (the slopes 2 S |Q_αf|
//! are recorded with the sources) and solves every active parameter on that factorisation.
//!
//! Heart chambers and valves add c_el(y, t) the same way: J_k gains their Jacobian
//! ∂c_el/∂y at (y_αf, t_αf) of step k (recorded with the slopes), and a parameter of an
//! element adds −∂c_el/∂θ (y_αf, t_αf) to its source. A chamber's elastance varies in time,
//! so K_k varies along the cycle even for a linear chamber.

#[path = "adjoint.rs"]
mod adjoint;
#[path = "chain_rule.rs"]
mod chain_rule;
pub use adjoint::{PeriodicAdjoint, periodic_adjoint, periodic_adjoint_in, periodic_adjoint_with};

use super::krylov::Subspace;
use super::parameter::{DaeTangent, LawValue};
use super::volume::ConservedVolume;
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::integrate::genalpha::GenAlpha;
use crate::integrate::newton::{NewtonControl, jacobian_stamps, jacobian_values, singular};
use crate::sparse::SparseLu;

/// How the periodic tangent is run.
#[derive(Debug, Clone, Copy)]
pub struct TangentSettings {
    pub period: f64,
    pub steps_per_cycle: usize,
    pub rho_infty: f64,
    pub max_cycles: usize,
    /// Relative change between cycle starts at which the state counts as periodic.
    pub tol: f64,
}

impl TangentSettings {
    /// The settings both the tangent and the adjoint sweep refuse.
    pub(crate) fn check(&self) -> Result<()> {
        if self.max_cycles == 0 {
            return Err(Error::model(
                "sensitivities",
                "max_cycles must be at least 1",
            ));
        }
        Ok(())
    }

    /// Generalized-α's α_f = 1/(1 + ρ∞): the level a step's face flows are read at.
    pub(crate) fn alpha_f(&self) -> f64 {
        1.0 / (1.0 + self.rho_infty)
    }
}

/// Values and derivatives of the chosen unknowns over the last (periodic) cycle.
#[derive(Debug, Clone)]
pub struct PeriodicTangent {
    /// Step end times within the cycle (s; Δt … T).
    pub times: Vec<f64>,
    /// values[k * n_signals + j]: unknown j at times[k].
    pub values: Vec<f64>,
    /// derivs[(p * n_steps + k) * n_signals + j]: d values[k, j] / d parameter p.
    pub derivs: Vec<f64>,
    pub cycles: usize,
    /// The largest relative change between the last two cycle starts.
    pub periodic_change: f64,
    /// Cycles of the tangents alone (after the forward run's `cycles`) to their periodic state.
    pub tangent_cycles: usize,
}

struct Scheme {
    rho: f64,
    am: f64,
    af: f64,
    gamma: f64,
    dt: f64,
}

impl Scheme {
    fn new(rho: f64, dt: f64) -> Result<Scheme> {
        if !(0.0..=1.0).contains(&rho) {
            return Err(Error::model(
                "sensitivities",
                format!("rho_infty must be in [0, 1], got {rho}"),
            ));
        }
        let am = 0.5 * (3.0 - rho) / (1.0 + rho);
        let af = 1.0 / (1.0 + rho);
        Ok(Scheme {
            rho,
            am,
            af,
            gamma: 0.5 + am - af,
            dt,
        })
    }
}

/// y ← y + γΔt Δ, ẏ ← pred ẏ + Δ.
fn advance(s: &Scheme, y: &mut [f64], yd: &mut [f64], delta: &[f64]) {
    let pred = (s.gamma - 1.0) / s.gamma;
    let gdt = s.gamma * s.dt;
    for ((yi, ydi), d) in y.iter_mut().zip(yd.iter_mut()).zip(delta) {
        *yi += gdt * d;
        *ydi = pred * *ydi + d;
    }
}

/// r − F y − c E ẏ, written into `r` (which holds the forcing on entry).
fn residual(dae: &Dae, c: f64, y: &[f64], yd: &[f64], r: &mut [f64]) {
    let f = &dae.f;
    for (i, ri) in r.iter_mut().enumerate() {
        let mut v = *ri - c * dae.e[i] * yd[i];
        for k in f.row(i) {
            v -= f.val[k] * y[f.col[k] as usize];
        }
        *ri = v;
    }
}

/// A parameter's source df − dE (c ẏ + α_m Δ) − dF (y + α_f γ Δt Δ) at each step of the
/// periodic cycle: it touches the few rows of the parameter's elements, so it is stored
/// (per step, on those rows) once and reused by every tangent cycle.
struct Source {
    rows: Vec<usize>,
    /// (position in `rows`, unknown i, dE_ii)
    e: Vec<(usize, usize, f64)>,
    /// (position in `rows`, column j, dF_ij)
    f: Vec<(usize, usize, f64)>,
    /// (position in `rows`, index into `Dae::forcing`, d f / dp over f)
    forcing: Vec<(usize, usize, f64)>,
    /// (position in `rows`, branch unknown i, dS_i/dp)
    sten: Vec<(usize, usize, f64)>,
    /// (element index, key, position in `rows` of each of its rows)
    elem: Vec<(usize, String, Vec<usize>)>,
    /// svZeroDSolver-form stenoses' capacitor rows (`chain_rule`)
    chain: chain_rule::ChainSource,
    /// (position in `rows`, index into `Dae::varying`, which law value): −∂R(t_αf) Q_αf
    varying: Vec<(usize, usize, LawValue)>,
    /// step k's values on `rows` at k·rows.len()
    vals: Vec<f64>,
    /// steps captured
    steps: usize,
}

impl Source {
    /// No source over `steps` steps: the tangent of a start state alone.
    fn empty(steps: usize) -> Source {
        Source {
            rows: Vec::new(),
            e: Vec::new(),
            f: Vec::new(),
            forcing: Vec::new(),
            sten: Vec::new(),
            elem: Vec::new(),
            chain: chain_rule::ChainSource { terms: Vec::new() },
            varying: Vec::new(),
            vals: Vec::new(),
            steps,
        }
    }

    fn of(dae: &Dae, t: &DaeTangent, steps: usize) -> Source {
        let mut rows = Vec::new();
        let mut index = vec![usize::MAX; dae.n];
        let mut at = |row: usize| {
            if index[row] == usize::MAX {
                index[row] = rows.len();
                rows.push(row);
            }
            index[row]
        };
        let mut e = Vec::new();
        for i in (0..dae.n).filter(|&i| t.de[i] != 0.0) {
            e.push((at(i), i, t.de[i]));
        }
        let mut f = Vec::new();
        for i in 0..dae.n {
            for k in dae.f.row(i) {
                if t.df[k] != 0.0 {
                    f.push((at(i), dae.f.col[k] as usize, t.df[k]));
                }
            }
        }
        let forcing = t
            .dforcing
            .iter()
            .map(|&(k, factor)| (at(dae.forcing[k].0), k, factor))
            .collect();
        let sten = t.dstenosis.iter().map(|&(i, d)| (at(i), i, d)).collect();
        let elem = (t.delements.iter())
            .map(|(el, key)| {
                let pos = dae.elements[*el].rows().iter().map(|&r| at(r)).collect();
                (*el, key.clone(), pos)
            })
            .collect();
        let chain = chain_rule::ChainSource::of(dae, t, &mut at);
        let varying = (t.dvarying.iter())
            .map(|&(law, which)| (at(dae.varying[law].0), law, which))
            .collect();
        let vals = Vec::with_capacity(steps * rows.len());
        Source {
            rows,
            e,
            f,
            forcing,
            sten,
            elem,
            chain,
            varying,
            vals,
            steps: 0,
        }
    }

    /// Append one step's source, from the primal's pre-step state, increment and forcing,
    /// the step starting at `time` (its α_f level y_αf for the element terms).
    fn capture(&mut self, pr: &Primal, time: f64) {
        let (s, c, forcing) = (&pr.scheme, pr.c, &pr.forcing);
        let (y, yd, delta) = (&pr.y, &pr.yd, &pr.r);
        self.steps += 1;
        let base = self.vals.len();
        self.vals.resize(base + self.rows.len(), 0.0);
        let v = &mut self.vals[base..];
        let gdt = s.af * s.gamma * s.dt;
        for &(at, i, de) in &self.e {
            v[at] -= de * (c * yd[i] + s.am * delta[i]);
        }
        for &(at, j, df) in &self.f {
            v[at] -= df * (y[j] + gdt * delta[j]);
        }
        for &(at, k, factor) in &self.forcing {
            v[at] += factor * forcing[k];
        }
        for &(at, i, ds) in &self.sten {
            let q = y[i] + gdt * delta[i];
            v[at] -= ds * q.abs() * q;
        }
        if !self.elem.is_empty() {
            let y_af: Vec<f64> = y.iter().zip(delta).map(|(a, d)| a + gdt * d).collect();
            let t_af = time + s.af * s.dt;
            let mut dc = Vec::new();
            for (el, key, pos) in &self.elem {
                dc.clear();
                dc.resize(pos.len(), 0.0);
                // (the key was resolved against the element's law when the path was parsed)
                pr.dae.elements[*el].parameter_derivative(key, t_af, &y_af, &mut dc);
                for (&at, d) in pos.iter().zip(&dc) {
                    v[at] -= d;
                }
            }
        }
        self.chain.capture(pr, v);
        let t_af = time + s.af * s.dt;
        for &(at, law, which) in &self.varying {
            let (i, law) = &pr.dae.varying[law];
            v[at] -= which.slope(law, t_af) * (y[*i] + gdt * delta[*i]);
        }
    }

    /// Step k's source · `u` (the adjoint's contribution of the step).
    fn dot(&self, k: usize, u: &[f64]) -> f64 {
        let m = self.rows.len();
        self.rows
            .iter()
            .zip(&self.vals[k * m..(k + 1) * m])
            .map(|(&row, v)| u[row] * v)
            .sum()
    }

    /// Add step k's source to `r`.
    fn add(&self, k: usize, r: &mut [f64]) {
        let m = self.rows.len();
        for (&row, v) in self.rows.iter().zip(&self.vals[k * m..(k + 1) * m]) {
            r[row] += v;
        }
    }
}

/// The forward run: the primal state (y, ẏ), its increment Δ and the one factorisation.
struct Primal<'a> {
    dae: &'a Dae,
    lu: SparseLu,
    scheme: Scheme,
    /// c = 1 + α_m (pred − 1): the weight of ẏ in a step's residual
    c: f64,
    forcing: Vec<f64>,
    /// the step's increment Δ after `increment`
    r: Vec<f64>,
    y: Vec<f64>,
    yd: Vec<f64>,
    /// The run loop's Newton step when the circuit has stenoses (None: linear, `lu` holds
    /// the one factorisation), and the state it steps to.
    newton: Option<GenAlpha<'a>>,
    next: (Vec<f64>, Vec<f64>),
    /// 2 S |Q_αf| of each `Dae::stenosis` entry at each recorded step (`record_slopes`).
    slopes: Vec<f64>,
    /// D(t_αf) = R(t_αf) − R₀ of each `Dae::varying` entry (a time-varying resistance's
    /// part beyond F) at each recorded step.
    varying: Vec<f64>,
    /// (σ, g) of each `Dae::chain_rule` capacitor at each recorded step (`chain_rule`).
    chain: Vec<[f64; 2]>,
    /// The index in `dae.f` of each capacitor's (node, inflow) entry.
    chain_entry: Vec<usize>,
    /// ∂c_el/∂y at (y_αf, t_αf) of each recorded step, `Dae::element_pattern` order.
    element_jac: Vec<f64>,
    /// The elements' Jacobian entries (row, column).
    element_pattern: Vec<(usize, usize)>,
    /// The unknowns an element resets after each Newton correction (a closed valve's flow
    /// of the heart block) at each recorded step: step k's at `held_rows[held_at[k]..held_at[k + 1]]`.
    held_rows: Vec<usize>,
    held_at: Vec<usize>,
    /// The elements that may reset unknowns, and a scratch state of ones to find them.
    resetting: Vec<usize>,
    marker: Vec<f64>,
}

impl<'a> Primal<'a> {
    fn new(dae: &'a Dae, scheme: Scheme) -> Result<Primal<'a>> {
        let n = dae.n;
        let stamps = jacobian_stamps(dae);
        let mut lu = SparseLu::analyse(n, &stamps)?;
        let am_e: Vec<f64> = dae.e.iter().map(|e| scheme.am * e).collect();
        let mut kvals = vec![0.0; stamps.len()];
        let a = scheme.af * scheme.gamma * scheme.dt;
        jacobian_values(dae, a, &am_e, &vec![0.0; n], 0.0, &mut kvals);
        // (a time-varying resistance makes the step's matrix vary: the Newton step holds it)
        let newton = if dae.stenosis.is_empty() && dae.elements.is_empty() && dae.varying.is_empty()
        {
            lu.factor(&kvals).map_err(|m| singular(0.0, &m))?;
            None
        } else {
            let control = NewtonControl::default();
            Some(GenAlpha::new(
                dae,
                Regime::Transient,
                scheme.dt,
                scheme.rho,
                control,
            )?)
        };
        let pred = (scheme.gamma - 1.0) / scheme.gamma;
        Ok(Primal {
            dae,
            lu,
            c: 1.0 + scheme.am * (pred - 1.0),
            scheme,
            forcing: vec![0.0; dae.forcing.len()],
            r: vec![0.0; n],
            y: dae.initial_state(),
            yd: vec![0.0; n],
            newton,
            next: (Vec::new(), Vec::new()),
            slopes: Vec::new(),
            varying: Vec::new(),
            chain: Vec::new(),
            chain_entry: Self::chain_entries(dae),
            element_jac: Vec::new(),
            element_pattern: dae.element_pattern(),
            held_rows: Vec::new(),
            held_at: vec![0],
            resetting: (0..dae.elements.len())
                .filter(|&e| !dae.elements[e].switched_unknowns().is_empty())
                .collect(),
            marker: vec![1.0; n],
        })
    }

    /// The iteration matrix's values without the stenosis slopes and element Jacobians (in
    /// `jacobian_stamps` order): a step's matrix adds α_f γ Δt · 2 S |Q_αf| on the stenosis
    /// diagonals and α_f γ Δt · ∂c_el/∂y on the elements' entries.
    fn base_values(&self) -> Vec<f64> {
        let (dae, sc) = (self.dae, &self.scheme);
        let am_e: Vec<f64> = dae.e.iter().map(|e| sc.am * e).collect();
        let mut kvals = vec![0.0; jacobian_stamps(dae).len()];
        let a = sc.af * sc.gamma * sc.dt;
        jacobian_values(dae, a, &am_e, &vec![0.0; dae.n], 0.0, &mut kvals);
        kvals[dae.f.val.len() + dae.n..].fill(0.0);
        kvals
    }

    /// Append this step's stenosis slopes 2 S |Q_αf| and element Jacobian at (y_αf, t_αf)
    /// (after `increment` of the step from `time`).
    fn record_slopes(&mut self, time: f64) {
        let gdt = self.scheme.af * self.scheme.gamma * self.scheme.dt;
        for &(i, s) in &self.dae.stenosis {
            let q = self.y[i] + gdt * self.r[i];
            self.slopes.push(2.0 * s * q.abs());
        }
        let t_af = time + self.scheme.af * self.scheme.dt;
        for (_, law) in &self.dae.varying {
            self.varying.push(law.delta(t_af));
        }
        self.record_chain();
        if !self.element_pattern.is_empty() {
            let y_af: Vec<f64> = (self.y.iter().zip(&self.r))
                .map(|(a, d)| a + gdt * d)
                .collect();
            let t_af = time + self.scheme.af * self.scheme.dt;
            let base = self.element_jac.len();
            self.element_jac
                .resize(base + self.element_pattern.len(), 0.0);
            let out = &mut self.element_jac[base..];
            self.dae
                .element_jacobian(1.0, t_af, &y_af, out, crate::circuit::JacobianKind::Exact);
            self.record_held(&y_af);
        }
        self.held_at.push(self.held_rows.len());
    }

    /// The unknowns the elements reset at this step's α_f level: a closed valve's flow is
    /// set to zero after every Newton correction, so the converged step's flow is zero
    /// whatever the parameters and its tangent row is zero too. The level is y + α_f γ Δt Δ
    /// (Δ from ẏ, which the reset leaves alone): the iterate of the last residual, whose
    /// valve positions the converged step's equations hold, as the recorded Jacobian does.
    fn record_held(&mut self, y_af: &[f64]) {
        for &e in &self.resetting {
            let el = &self.dae.elements[e];
            el.after_correction(y_af, &mut self.marker);
            for i in el.switched_unknowns() {
                if self.marker[i] == 0.0 {
                    self.held_rows.push(i);
                    self.marker[i] = 1.0;
                }
            }
        }
    }

    /// The unknowns held at zero after step k (see [`Primal::record_held`]).
    fn held(&self, k: usize) -> &[usize] {
        match (self.held_at.get(k), self.held_at.get(k + 1)) {
            (Some(&a), Some(&b)) => &self.held_rows[a..b],
            _ => &[],
        }
    }

    /// Step k's local Jacobian J_k beyond F: (stenosis slopes, element Jacobian).
    fn local(&self, k: usize) -> (&[f64], &[f64]) {
        let (m, e) = (self.dae.stenosis.len(), self.element_pattern.len());
        (
            self.slopes.get(k * m..(k + 1) * m).unwrap_or(&[]),
            self.element_jac.get(k * e..(k + 1) * e).unwrap_or(&[]),
        )
    }

    /// Step k's time-varying resistances D(t_αf) beyond F, by `Dae::varying` entry: a
    /// diagonal like the stenosis slopes (the law depends on time alone, so it adds no
    /// source and its transpose is itself).
    fn varying_at(&self, k: usize) -> &[f64] {
        let m = self.dae.varying.len();
        self.varying.get(k * m..(k + 1) * m).unwrap_or(&[])
    }

    /// The iteration matrix's values of step k: `base` plus α_f γ Δt J_k.
    fn step_values(&self, base: &[f64], k: usize) -> Vec<f64> {
        let a = self.scheme.af * self.scheme.gamma * self.scheme.dt;
        let (nf, n) = (self.dae.f.val.len(), self.dae.n);
        let (slopes, jac) = self.local(k);
        let mut vals = base.to_vec();
        for (&(i, _), slope) in self.dae.stenosis.iter().zip(slopes) {
            vals[nf + i] += a * slope;
        }
        for (&(i, _), d) in self.dae.varying.iter().zip(self.varying_at(k)) {
            vals[nf + i] += a * d;
        }
        for (v, j) in vals[nf + n..].iter_mut().zip(jac) {
            *v += a * j;
        }
        self.chain_values(k, &mut vals);
        vals
    }

    /// r −= J_k x (transposed: Jᵀ_k x), J_k beyond F at step k.
    fn local_apply(&self, k: usize, x: &[f64], r: &mut [f64], transposed: bool) {
        let (slopes, jac) = self.local(k);
        for (&(i, _), slope) in self.dae.stenosis.iter().zip(slopes) {
            r[i] -= slope * x[i];
        }
        for (&(i, _), d) in self.dae.varying.iter().zip(self.varying_at(k)) {
            r[i] -= d * x[i];
        }
        for (&(row, col), j) in self.element_pattern.iter().zip(jac) {
            if transposed {
                r[col] -= j * x[row];
            } else {
                r[row] -= j * x[col];
            }
        }
    }

    /// The increment Δ of the step from `time` (into `r`; the state is not advanced).
    fn increment(&mut self, time: f64) -> Result<()> {
        let (dae, sc) = (self.dae, &self.scheme);
        let t_af = time + sc.af * sc.dt;
        self.r.iter_mut().for_each(|v| *v = 0.0);
        for (fk, (row, w)) in dae.forcing.iter().enumerate() {
            self.forcing[fk] = w.eval(t_af);
            self.r[*row] += self.forcing[fk];
        }
        if let Some(ga) = &mut self.newton {
            // the run loop's Newton step; Δ = ẏ_{n+1} − pred ẏ_n
            let (y1, yd1) = &mut self.next;
            y1.clone_from(&self.y);
            yd1.clone_from(&self.yd);
            ga.step(time, y1, yd1)?;
            let pred = (sc.gamma - 1.0) / sc.gamma;
            for ((d, a), b) in self.r.iter_mut().zip(yd1.iter()).zip(&self.yd) {
                *d = a - pred * b;
            }
            return Ok(());
        }
        residual(dae, self.c, &self.y, &self.yd, &mut self.r);
        if !self.lu.solve_in_place(&mut self.r) {
            return Err(singular(t_af, "non-finite solution"));
        }
        Ok(())
    }

    fn advance(&mut self) {
        if self.newton.is_some() {
            std::mem::swap(&mut self.y, &mut self.next.0);
            std::mem::swap(&mut self.yd, &mut self.next.1);
            return;
        }
        advance(&self.scheme, &mut self.y, &mut self.yd, &self.r);
    }

    /// (y, ẏ) in one vector: the cycle map's state.
    fn state(&self) -> Vec<f64> {
        self.y.iter().chain(&self.yd).copied().collect()
    }

    /// The scales of y's node rows (pressures) and other rows (flows).
    fn floor(&self) -> [f64; 2] {
        let k = self.dae.n_nodes.min(self.dae.n);
        let scale = |v: &[f64]| v.iter().fold(1e-300f64, |m, x| m.max(x.abs()));
        [scale(&self.y[..k]), scale(&self.y[k..])]
    }
}

/// The tangents' iteration matrices along the periodic cycle: the primal's one factorisation
/// for a linear circuit, else one per step from the recorded stenosis slopes.
struct StepMatrices {
    /// (stamps without the local Jacobians, LU)
    varying: Option<(Vec<f64>, SparseLu)>,
}

impl StepMatrices {
    fn of(pr: &Primal) -> Result<StepMatrices> {
        if pr.newton.is_none() {
            return Ok(StepMatrices { varying: None });
        }
        let dae = pr.dae;
        let lu = SparseLu::analyse(dae.n, &jacobian_stamps(dae))?;
        Ok(StepMatrices {
            varying: Some((pr.base_values(), lu)),
        })
    }

    /// The matrix of step k (refactorised when it varies), to solve with.
    fn at<'m>(&'m mut self, pr: &'m Primal, k: usize) -> Result<&'m SparseLu> {
        let Some((base, lu)) = &mut self.varying else {
            return Ok(&pr.lu);
        };
        let vals = pr.step_values(base, k);
        let t = k as f64 * pr.scheme.dt;
        lu.factor(&vals).map_err(|msg| singular(t, &msg))?;
        Ok(lu)
    }
}

/// One tangent cycle of each job (parameter p, its state x = (s, ṡ) advanced in place, its
/// record: s at the chosen unknowns after each step, n_steps × signals), step by step so
/// that a varying matrix is factorised once per step for all of them.
fn tangent_cycles(
    pr: &Primal,
    mats: &mut StepMatrices,
    sources: &[Source],
    jobs: &mut [(usize, Vec<f64>, &mut [f64])],
    signals: &[usize],
) -> Result<()> {
    let (dae, n, nsig) = (pr.dae, pr.dae.n, signals.len());
    let mut rs = vec![0.0; n];
    for k in 0..sources.first().map_or(0, |s| s.steps) {
        let lu = mats.at(pr, k)?;
        for (p, x, rec) in jobs.iter_mut() {
            let (s, sd) = x.split_at_mut(n);
            rs.iter_mut().for_each(|v| *v = 0.0);
            residual(dae, pr.c, s, sd, &mut rs);
            // −J_k s: the stenosis slopes and element Jacobian at this step
            pr.local_apply(k, s, &mut rs, false);
            sources[*p].add(k, &mut rs);
            pr.chain_tangent(k, s, sd, &mut rs);
            if !lu.solve_in_place(&mut rs) {
                return Err(singular(k as f64 * pr.scheme.dt, "non-finite tangent"));
            }
            advance(&pr.scheme, s, sd, &rs);
            // a reset flow's row: the converged step sets it to zero (ṡ is left, as is ẏ)
            for &i in pr.held(k) {
                s[i] = 0.0;
            }
            for (o, &u) in rec[k * nsig..(k + 1) * nsig].iter_mut().zip(signals) {
                *o = s[u];
            }
        }
    }
    Ok(())
}

/// The forward run's cycles to the periodic state (at most `max_cycles` − 1, the last cycle
/// being the recorded one): the cycles run.
fn forward_to_periodic(pr: &mut Primal, ns: usize, set: &TangentSettings) -> Result<usize> {
    let mut change = f64::INFINITY;
    let mut cycles = 0;
    while change > set.tol && cycles + 1 < set.max_cycles {
        let start = pr.y.clone();
        for k in 0..ns {
            pr.increment(k as f64 * pr.scheme.dt)?;
            pr.advance();
        }
        cycles += 1;
        let n = pr.dae.n;
        change = relative_change(&start, &pr.y, pr.dae.n_nodes.min(n), 1.0, pr.floor());
    }
    Ok(cycles)
}

/// Run generalized-α with the tangents of `params` to the periodic state and record the
/// unknowns `signals` (and their derivatives) over the periodic cycle.
pub fn periodic_tangent(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    set: TangentSettings,
) -> Result<PeriodicTangent> {
    periodic_tangent_in(dae, params, signals, set, None)
}

/// [`periodic_tangent`] of a closed loop conserving `volume` (`super::volume`): each tangent's
/// fixed point is the one whose volume row holds the start values' volume.
pub fn periodic_tangent_in(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    set: TangentSettings,
    volume: Option<&ConservedVolume>,
) -> Result<PeriodicTangent> {
    set.check()?;
    let ns = set.steps_per_cycle.max(1);
    let scheme = Scheme::new(set.rho_infty, set.period / ns as f64)?;
    let dt = scheme.dt;
    let mut pr = Primal::new(dae, scheme)?;
    let cycles = forward_to_periodic(&mut pr, ns, &set)?;
    // the periodic cycle: the primal's signals and every parameter's source
    let mut sources: Vec<Source> = params.iter().map(|t| Source::of(dae, t, ns)).collect();
    let (np, nsig) = (params.len(), signals.len());
    let mut rec = PeriodicTangent {
        times: (1..=ns).map(|k| k as f64 * dt).collect(),
        values: Vec::with_capacity(ns * nsig),
        derivs: vec![0.0; np * ns * nsig],
        cycles: cycles + 1,
        periodic_change: 0.0,
        tangent_cycles: 0,
    };
    let start = pr.state();
    let n = dae.n;
    let mut rate_scale = [1e-300f64; 2];
    for k in 0..ns {
        pr.increment(k as f64 * dt)?;
        for src in &mut sources {
            src.capture(&pr, k as f64 * dt);
        }
        pr.record_slopes(k as f64 * dt);
        pr.advance();
        rec.values.extend(signals.iter().map(|&u| pr.y[u]));
        let kn = dae.n_nodes.min(n);
        for (m, part) in rate_scale.iter_mut().zip([&pr.yd[..kn], &pr.yd[kn..]]) {
            *m = part.iter().fold(*m, |m, v| m.max(v.abs()));
        }
    }
    let floor = pr.floor();
    rec.periodic_change = relative_change(&start[..n], &pr.y, dae.n_nodes.min(n), 1.0, floor);
    let weights = weights(dae, floor, rate_scale);
    let values: Vec<f64> = params.iter().map(|t| t.value).collect();
    let mut sub = Subspace::new(weights, 256);
    let mut hold = volume.map(|vol| Hold::of(vol, &pr, params, &start));
    if let Some(h) = &mut hold
        && params.iter().any(|t| h.vol.moves(&t.de))
    {
        h.v = Some(unit_volume_tangent(&pr, h.vol, signals, &set)?.0);
    }
    let mut run = TangentRun {
        pr: &pr,
        mats: StepMatrices::of(&pr)?,
        sources: &sources,
        values: &values,
        signals,
        floor,
        hold,
        starts: Vec::new(),
    };
    let (tcycles, change) = run.run_to_periodic(&mut sub, &set, &mut rec.derivs)?;
    rec.tangent_cycles = tcycles;
    rec.periodic_change = rec.periodic_change.max(change);
    Ok(rec)
}

/// The inner product's weights over (s, ṡ): each row by the inverse square of its group's
/// scale (node rows and others, of y and of ẏ), so pressures and flows count alike.
fn weights(dae: &Dae, floor: [f64; 2], rate: [f64; 2]) -> Vec<f64> {
    let (n, k) = (dae.n, dae.n_nodes.min(dae.n));
    let w = |i: usize, scale: [f64; 2]| {
        let s = if i < k { scale[0] } else { scale[1] };
        1.0 / (s * s)
    };
    (0..n)
        .map(|i| w(i, floor))
        .chain((0..n).map(|i| w(i, rate)))
        .collect()
}

/// A closed loop's volume row (`super::volume`): ℓ·x of each tangent is held at its target.
struct Hold<'v> {
    vol: &'v ConservedVolume,
    /// the direction moved along, ℓ·e = 1
    e: Vec<f64>,
    /// ℓ's weight of ṡ, γ Δt c
    k: f64,
    /// each job's ℓ·x
    targets: Vec<f64>,
    /// The unit-volume tangent v, when some parameter changes the volume (a capacitance):
    /// its source's ℓ·b = mᵀ dE (w_start − w_end) is the primal cycle's own mismatch, which
    /// no fixed point can absorb; it is taken out along v, as the adjoint does.
    v: Option<Vec<f64>>,
}

impl<'v> Hold<'v> {
    /// The targets of `params`' tangents, the periodic cycle starting at `start` = (y, ẏ).
    fn of(vol: &'v ConservedVolume, pr: &Primal, params: &[DaeTangent], start: &[f64]) -> Self {
        let k = pr.scheme.gamma * pr.scheme.dt * pr.c;
        let y0 = pr.dae.initial_state();
        Hold {
            vol,
            e: vol.unit(),
            k,
            targets: (params.iter())
                .map(|t| vol.start_change(&t.de, &y0, start, k))
                .collect(),
            v: None,
        }
    }

    fn apply(&self, p: usize, x: &mut [f64]) {
        self.vol.hold(x, &self.e, self.k, self.targets[p]);
    }

    /// g ← g − (ℓ·g − ℓ·x) v: a cycle's end `g` from `x` without its source's volume change.
    fn settle(&self, x: &[f64], g: &mut [f64]) {
        if let Some(v) = &self.v {
            let d = self.vol.dot(g, self.k) - self.vol.dot(x, self.k);
            g.iter_mut().zip(v).for_each(|(gi, vi)| *gi -= d * vi);
        }
    }
}

/// The periodic tangent of a unit change of a closed loop's volume (no parameter source, ℓ·x
/// = 1): the right eigenvector v of the cycle map's eigenvalue 1, as the cycle-start state and
/// its signals over the cycle (n_steps × signals).
fn unit_volume_tangent(
    pr: &Primal,
    vol: &ConservedVolume,
    signals: &[usize],
    set: &TangentSettings,
) -> Result<(Vec<f64>, Vec<f64>)> {
    let ns = set.steps_per_cycle.max(1);
    let floor = pr.floor();
    let rate = floor.map(|f| f / set.period);
    let mut sub = Subspace::new(weights(pr.dae, floor, rate), 256);
    let k = pr.scheme.gamma * pr.scheme.dt * pr.c;
    let sources = [Source::empty(ns)];
    let mut run = TangentRun {
        pr,
        mats: StepMatrices::of(pr)?,
        sources: &sources,
        values: &[vol.total],
        signals,
        floor,
        hold: Some(Hold {
            vol,
            e: vol.unit(),
            k,
            targets: vec![1.0],
            v: None,
        }),
        starts: Vec::new(),
    };
    let mut rec = vec![0.0; ns * signals.len()];
    run.run_to_periodic(&mut sub, set, &mut rec)?;
    Ok((run.starts.swap_remove(0), rec))
}

/// The tangents' cycles along the recorded periodic primal.
struct TangentRun<'r, 'a> {
    pr: &'r Primal<'a>,
    mats: StepMatrices,
    sources: &'r [Source],
    values: &'r [f64],
    signals: &'r [usize],
    floor: [f64; 2],
    /// a closed loop's volume row
    hold: Option<Hold<'r>>,
    /// each job's start of its recorded cycle (after `run_to_periodic`)
    starts: Vec<Vec<f64>>,
}

impl TangentRun<'_, '_> {
    /// Anderson iterations on the shared basis from x = 0 until every tangent is periodic
    /// (or `max_cycles` tangent cycles); each parameter's last cycle is recorded into
    /// `derivs`. Returns the tangent cycles run and the largest remaining change.
    fn run_to_periodic(
        &mut self,
        sub: &mut Subspace,
        set: &TangentSettings,
        derivs: &mut [f64],
    ) -> Result<(usize, f64)> {
        let n = self.pr.dae.n;
        let kn = self.pr.dae.n_nodes.min(n);
        let np = self.sources.len();
        let block = derivs.len().checked_div(np).unwrap_or(0).max(1);
        let mut recs: Vec<&mut [f64]> = derivs.chunks_mut(block).collect();
        let mut x = vec![vec![0.0; 2 * n]; np];
        if let Some(h) = &self.hold {
            x.iter_mut().enumerate().for_each(|(p, xp)| h.apply(p, xp));
        }
        let mut r: Vec<Vec<f64>> = vec![Vec::new(); np];
        let mut change = vec![f64::INFINITY; np];
        let mut cycles = 0;
        while cycles < set.max_cycles && change.iter().any(|&c| c > set.tol) {
            let active: Vec<usize> = (0..np).filter(|&p| change[p] > set.tol).collect();
            let starts: Vec<Vec<f64>> = active
                .iter()
                .map(|&p| {
                    if cycles == 0 {
                        return x[p].clone();
                    }
                    let mut xn = sub.next(&x[p], &r[p]);
                    if let Some(h) = &self.hold {
                        h.apply(p, &mut xn);
                    }
                    xn
                })
                .collect();
            // each active parameter's record, taken out of `recs` for the cycle
            let mut jobs: Vec<(usize, Vec<f64>, &mut [f64])> = active
                .iter()
                .zip(&starts)
                .map(|(&p, xn)| (p, xn.clone(), std::mem::take(&mut recs[p])))
                .collect();
            let ran = tangent_cycles(
                self.pr,
                &mut self.mats,
                self.sources,
                &mut jobs,
                self.signals,
            );
            let mut next = Vec::with_capacity(active.len());
            for ((p, mut g, rec), xn) in jobs.into_iter().zip(starts) {
                recs[p] = rec;
                if let Some(h) = &self.hold {
                    h.settle(&xn, &mut g);
                }
                let rn: Vec<f64> = g.iter().zip(&xn).map(|(a, b)| a - b).collect();
                let p_abs = scale_of(self.values[p]);
                change[p] = relative_change(&xn[..n], &g[..n], kn, p_abs, self.floor);
                next.push((p, xn, rn));
            }
            ran?;
            for (p, xn, rn) in next {
                if cycles > 0 {
                    let dx = xn.iter().zip(&x[p]).map(|(a, b)| a - b).collect();
                    let df = rn.iter().zip(&r[p]).map(|(a, b)| a - b).collect();
                    sub.add(dx, df);
                }
                (x[p], r[p]) = (xn, rn);
            }
            cycles += 1;
        }
        self.starts = x;
        Ok((cycles, change.iter().fold(0.0, |m: f64, &c| m.max(c))))
    }
}

/// The scale p·s of a tangent is judged on: |p|, or 1 for a parameter at zero (a stenosis
/// coefficient of a vessel without one), whose 100 % change is no change.
fn scale_of(value: f64) -> f64 {
    if value != 0.0 && value.is_finite() {
        value.abs()
    } else {
        1.0
    }
}

/// The change of a state vector over one cycle, `p` times `b − a`, relative to the larger of
/// `p` |b| and `floor`, taken apart for the node rows (pressures, before `k`) and the rest
/// (flows, whose scale is another).
fn relative_change(a: &[f64], b: &[f64], k: usize, p: f64, floor: [f64; 2]) -> f64 {
    let part = |a: &[f64], b: &[f64], floor: f64| {
        let scale = b.iter().fold(floor, |m, v| m.max(p * v.abs()));
        p * a
            .iter()
            .zip(b)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
            / scale
    };
    part(&a[..k], &b[..k], floor[0]).max(part(&a[k..], &b[k..], floor[1]))
}
