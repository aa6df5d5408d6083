//! Forward (tangent-linear) sensitivities of generalized-α on a linear circuit
//! E ẏ + F y = f(t), through to its periodic state.
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
//! The periodic state: cycles are repeated until y and every p·s at a cycle start repeat to
//! `tol` relative to the state's scale (p·s is the state's response to a 100 % change of p;
//! the tangent cycle map has the primal's contraction).

use super::parameter::DaeTangent;
use crate::circuit::Dae;
use crate::error::{Error, Result};
use crate::integrate::newton::{jacobian_stamps, jacobian_values, singular};
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
}

struct Scheme {
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
        for k in f.ptr[i]..f.ptr[i + 1] {
            v -= f.val[k] * y[f.col[k] as usize];
        }
        *ri = v;
    }
}

/// The nonzero entries of a [`DaeTangent`]: a parameter touches a few elements, so its right
/// side costs O(its entries) per step instead of a pass over the whole matrix.
struct SparseTangent {
    /// (row, dE_row)
    e: Vec<(usize, f64)>,
    /// (row, col, dF_row,col)
    f: Vec<(usize, usize, f64)>,
    forcing: Vec<(usize, f64)>,
}

impl SparseTangent {
    fn of(dae: &Dae, t: &DaeTangent) -> SparseTangent {
        let e = (0..dae.n)
            .filter(|&i| t.de[i] != 0.0)
            .map(|i| (i, t.de[i]))
            .collect();
        let mut f = Vec::new();
        for i in 0..dae.n {
            for k in dae.f.ptr[i]..dae.f.ptr[i + 1] {
                if t.df[k] != 0.0 {
                    f.push((i, dae.f.col[k] as usize, t.df[k]));
                }
            }
        }
        SparseTangent {
            e,
            f,
            forcing: t.dforcing.clone(),
        }
    }
}

/// The tangent right side df − dE (c ẏ + α_m Δ) − dF (y + α_f γ Δt Δ) at one step, added to
/// `r` (which holds −c E ṡ − F s on entry).
fn tangent_source(
    dae: &Dae,
    t: &SparseTangent,
    s: &Scheme,
    c: f64,
    (y, yd, delta): (&[f64], &[f64], &[f64]),
    forcing: &[f64],
    r: &mut [f64],
) {
    let gdt = s.af * s.gamma * s.dt;
    for &(i, de) in &t.e {
        r[i] -= de * (c * yd[i] + s.am * delta[i]);
    }
    for &(i, j, df) in &t.f {
        r[i] -= df * (y[j] + gdt * delta[j]);
    }
    for &(k, factor) in &t.forcing {
        r[dae.forcing[k].0] += factor * forcing[k];
    }
}

/// The primal state (y, ẏ), the tangents (s_p, ṡ_p) and the one factorisation they share.
struct Stepper<'a> {
    dae: &'a Dae,
    lu: SparseLu,
    scheme: Scheme,
    /// c = 1 + α_m (pred − 1): the weight of ẏ in a step's residual
    c: f64,
    params: Vec<SparseTangent>,
    forcing: Vec<f64>,
    r: Vec<f64>,
    rs: Vec<f64>,
    y: Vec<f64>,
    yd: Vec<f64>,
    s: Vec<Vec<f64>>,
    sd: Vec<Vec<f64>>,
}

impl<'a> Stepper<'a> {
    fn new(dae: &'a Dae, params: &[DaeTangent], scheme: Scheme) -> Result<Stepper<'a>> {
        let n = dae.n;
        let stamps = jacobian_stamps(dae);
        let mut lu = SparseLu::analyse(n, &stamps)?;
        let am_e: Vec<f64> = dae.e.iter().map(|e| scheme.am * e).collect();
        let mut kvals = vec![0.0; stamps.len()];
        let a = scheme.af * scheme.gamma * scheme.dt;
        jacobian_values(dae, a, &am_e, &vec![0.0; n], 0.0, &mut kvals);
        lu.factor(&kvals).map_err(|m| singular(0.0, &m))?;
        let pred = (scheme.gamma - 1.0) / scheme.gamma;
        let np = params.len();
        Ok(Stepper {
            dae,
            lu,
            c: 1.0 + scheme.am * (pred - 1.0),
            scheme,
            params: params.iter().map(|t| SparseTangent::of(dae, t)).collect(),
            forcing: vec![0.0; dae.forcing.len()],
            r: vec![0.0; n],
            rs: vec![0.0; n],
            y: dae.initial_state(),
            yd: vec![0.0; n],
            s: vec![vec![0.0; n]; np],
            sd: vec![vec![0.0; n]; np],
        })
    }

    /// One step from `time`: the primal's increment Δ, then each tangent's on the same
    /// factors (it needs the primal's Δ and pre-step state), then both advance.
    fn step(&mut self, time: f64) -> Result<()> {
        let (dae, sc) = (self.dae, &self.scheme);
        let t_af = time + sc.af * sc.dt;
        self.r.iter_mut().for_each(|v| *v = 0.0);
        for (fk, (row, w)) in dae.forcing.iter().enumerate() {
            self.forcing[fk] = w.eval(t_af);
            self.r[*row] += self.forcing[fk];
        }
        residual(dae, self.c, &self.y, &self.yd, &mut self.r);
        if !self.lu.solve_in_place(&mut self.r) {
            return Err(singular(t_af, "non-finite solution"));
        }
        for (p, t) in self.params.iter().enumerate() {
            self.rs.iter_mut().for_each(|v| *v = 0.0);
            residual(dae, self.c, &self.s[p], &self.sd[p], &mut self.rs);
            let primal = (&self.y[..], &self.yd[..], &self.r[..]);
            tangent_source(dae, t, sc, self.c, primal, &self.forcing, &mut self.rs);
            if !self.lu.solve_in_place(&mut self.rs) {
                return Err(singular(t_af, "non-finite tangent"));
            }
            advance(sc, &mut self.s[p], &mut self.sd[p], &self.rs);
        }
        advance(sc, &mut self.y, &mut self.yd, &self.r);
        Ok(())
    }

    /// The state at a cycle start: y, then each s_p.
    fn snapshot(&self) -> Vec<Vec<f64>> {
        std::iter::once(self.y.clone())
            .chain(self.s.iter().cloned())
            .collect()
    }

    /// The change since `start`: a tangent is measured as p·s, the state's response to a
    /// 100 % change of p, against the state's own scale (a part of s that is only rounding
    /// then never holds the test back).
    fn change(&self, start: &[Vec<f64>], values: &[f64]) -> f64 {
        let k = self.dae.n_nodes.min(self.dae.n);
        let scale = |v: &[f64]| v.iter().fold(1e-300f64, |m, x| m.max(x.abs()));
        let floor = [scale(&self.y[..k]), scale(&self.y[k..])];
        std::iter::once(1.0)
            .chain(values.iter().copied())
            .zip(
                start
                    .iter()
                    .zip(std::iter::once(&self.y).chain(self.s.iter())),
            )
            .map(|(p, (a, b))| relative_change(a, b, k, p.abs(), floor))
            .fold(0.0, f64::max)
    }
}

/// Run generalized-α with the tangents of `params` to the periodic state and record the
/// unknowns `signals` (and their derivatives) over the last cycle.
pub fn periodic_tangent(
    dae: &Dae,
    params: &[DaeTangent],
    signals: &[usize],
    set: TangentSettings,
) -> Result<PeriodicTangent> {
    if set.max_cycles == 0 {
        return Err(Error::model(
            "sensitivities",
            "max_cycles must be at least 1",
        ));
    }
    let ns = set.steps_per_cycle.max(1);
    let scheme = Scheme::new(set.rho_infty, set.period / ns as f64)?;
    let dt = scheme.dt;
    let mut st = Stepper::new(dae, params, scheme)?;
    let values: Vec<f64> = params.iter().map(|t| t.value).collect();
    let (np, nsig) = (params.len(), signals.len());
    let mut change = f64::INFINITY;
    for cycle in 1..=set.max_cycles {
        let last = change <= set.tol || cycle == set.max_cycles;
        let start = st.snapshot();
        if !last {
            for k in 0..ns {
                st.step(k as f64 * dt)?;
            }
            change = st.change(&start, &values);
            continue;
        }
        let mut rec = PeriodicTangent {
            times: Vec::with_capacity(ns),
            values: Vec::with_capacity(ns * nsig),
            derivs: vec![0.0; np * ns * nsig],
            cycles: cycle,
            periodic_change: change,
        };
        for k in 0..ns {
            st.step(k as f64 * dt)?;
            rec.times.push((k + 1) as f64 * dt);
            rec.values.extend(signals.iter().map(|&u| st.y[u]));
            for (p, s) in st.s.iter().enumerate() {
                for (j, &u) in signals.iter().enumerate() {
                    rec.derivs[(p * ns + k) * nsig + j] = s[u];
                }
            }
        }
        rec.periodic_change = st.change(&start, &values);
        return Ok(rec);
    }
    unreachable!("the last cycle returns")
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
