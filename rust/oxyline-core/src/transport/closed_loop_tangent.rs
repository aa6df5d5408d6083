//! Exact derivatives of the closed loop's periodic O2 state (docs/calibration.md "A closed
//! loop's oxygen"): by the organs' Michaelis–Menten vmax and km, the lungs' diffusing
//! capacity, haemoglobin's P50 and capacity, a scale of the whole flow table, and any
//! direction of the flow table (a heart run's flow parameter through the heart's tangent).
//!
//! Each backward-Euler step solves, for every compartment n (`compartment::step`, the
//! Gauss–Seidel sweeps converged),
//!
//! ```text
//! F_n = a_n C_n + dt VO2_n(C_n) − V0_n C0_n − dt Σ_in |q_b| c_b(C_up) = 0,   a_n = V1_n + dt q_out,n
//! ```
//!
//! so its tangent is one small dense solve M dC = r with the step's own Jacobian M. Carried
//! over one cycle from the nc unit changes of the cycle-start contents it gives the cycle
//! map's Jacobian Φ_x, from zero by each parameter Φ_θ; the periodic fixed point x = Φ(x, θ)
//! then moves by dx/dθ = (I − Φ_x)⁻¹ Φ_θ (the implicit function theorem: one solve), and the
//! recorded cycle's tangent is the parameter's own plus the state directions' combination.
//!
//! The lungs' end-capillary content is differentiated as the solution of its Bohr ODE
//! Q dC_t/ds = D_L (P_A − P) (`lung.rs`, which integrates it by RK4 to ≤ 1e-9): ∂C_out/∂C_in
//! = (P_A − P_out)/(P_A − P_in), ∂C_out/∂D_L = (P_A − P_out)/Q, ∂C_out/∂Q = −D_L (P_A −
//! P_out)/Q², and by a binding parameter θ through Bohr's integral (a quadrature in
//! ln(P_A − P)).

use super::ClosedLoop;
use crate::error::{Error, Result};
use crate::hemoglobin::{Binding, hill};
use crate::transport::compartment::Consumption;

/// A parameter of the O2 loop, in SI.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoopParameter {
    /// The Michaelis–Menten vmax (mol/s) of one compartment.
    Vmax(usize),
    /// The Michaelis–Menten km (Pa) of every consuming compartment at once.
    Km,
    /// The diffusing capacity (mol s⁻¹ Pa⁻¹) of every lung branch at once.
    DiffusingCapacity,
    /// The alveolar PO2 (Pa) of every lung branch at once.
    AlveolarPo2,
    /// Haemoglobin's P50 (Pa).
    P50,
    /// Haemoglobin's O2 capacity (mol/m³).
    Capacity,
    /// A factor on every flow of the table (the derivative is by the factor, at 1).
    FlowScale,
    /// A direction of the flow table: every step's branch flows move by
    /// `Cycle::flow_tangents[k]` (m³/s per unit of the parameter; a heart run's flow
    /// parameter through the heart's own tangent).
    Flow(usize),
}

/// The recorded periodic cycle the tangent linearises: per step its flows (steps ×
/// branches), end volumes and end total contents (steps × compartments), and the cycle
/// start's volumes; the flow table's directions [`LoopParameter::Flow`] reads (each steps ×
/// branches, every compartment's cycle-mean net inflow zero, as the balanced table's).
pub struct Cycle<'a> {
    pub dt: f64,
    pub flow: &'a [f64],
    pub volume: &'a [f64],
    pub total: &'a [f64],
    pub start_volume: &'a [f64],
    pub flow_tangents: &'a [Vec<f64>],
}

impl Cycle<'_> {
    pub fn steps(&self, nc: usize) -> usize {
        self.total.len() / nc
    }

    /// d q_b / dθ at step `s` by parameter `param` (the table's own flow for the scale).
    fn flow_by(&self, param: LoopParameter, s: usize, b: usize) -> f64 {
        let nb = self.flow.len() / self.steps(self.start_volume.len());
        match param {
            LoopParameter::FlowScale => self.flow[s * nb + b],
            LoopParameter::Flow(k) => self.flow_tangents[k][s * nb + b],
            _ => 0.0,
        }
    }
}

/// The tangent of the recorded cycle: d C_t at every step end by each parameter
/// (steps × parameters × compartments), periodic.
pub struct CycleTangent {
    pub d_total: Vec<f64>,
    pub n_params: usize,
}

/// The Hill law of the loop's binding: (α, p50, n, capacity).
fn hill_of(b: &Binding) -> Result<(f64, f64, f64, f64)> {
    match *b {
        Binding::Hill {
            alpha,
            p50,
            n,
            capacity,
        } => Ok((alpha, p50, n, capacity)),
        _ => Err(Error::model("closed loop", "binding must be 'hill'")),
    }
}

/// ∂C_t/∂θ at a fixed PO2 `p` (Pa) for a binding parameter θ (0 for the others).
fn total_by(param: LoopParameter, h: (f64, f64, f64, f64), p: f64) -> f64 {
    let (_, p50, n, cap) = h;
    let (s, _) = hill(p, p50, n);
    match param {
        LoopParameter::P50 => -cap * n / p50 * s * (1.0 - s),
        LoopParameter::Capacity => s,
        _ => 0.0,
    }
}

/// ∂/∂θ of dC_t/dP at a fixed PO2 `p` (Pa) for a binding parameter θ.
fn slope_by(param: LoopParameter, h: (f64, f64, f64, f64), p: f64) -> f64 {
    let (_, p50, n, cap) = h;
    let (s, ds) = hill(p, p50, n);
    match param {
        LoopParameter::P50 if p > 0.0 => -cap * n * n / (p * p50) * s * (1.0 - s) * (1.0 - 2.0 * s),
        LoopParameter::Capacity => ds,
        _ => 0.0,
    }
}

/// dC_t/dP at PO2 `p`.
fn slope(h: (f64, f64, f64, f64), p: f64) -> f64 {
    let (alpha, p50, n, cap) = h;
    alpha + cap * hill(p, p50, n).1
}

/// A lung branch's end-capillary content at forward flow and its derivatives: by the
/// entering content, by the flow, and by each parameter.
struct LungLinear {
    content: f64,
    by_inflow: f64,
    by_flow: f64,
    by_param: Vec<f64>,
}

/// Simpson intervals of Bohr's integral in u = ln|P_A − P| (its integrand is smooth there).
const BOHR_INTERVALS: usize = 1024;

impl ClosedLoop {
    /// The tangent of lung branch `b` at forward flow `q` for blood entering at total
    /// content `c_in`.
    fn lung_linear(&self, b: usize, q: f64, c_in: f64, params: &[LoopParameter]) -> LungLinear {
        let l = self.lungs[b].as_ref().expect("a lung branch");
        let h = hill_of(&self.binding).expect("the loop's binding is Hill's");
        let content = l.end_capillary(&self.binding, self.alpha, c_in, q);
        let pa = l.alveolar_po2;
        let p_in = self.binding.free(c_in, self.alpha * pa) / self.alpha;
        let p_out = self.binding.free(content, self.alpha * pa) / self.alpha;
        let (y_in, y_out) = (pa - p_in, pa - p_out);
        if y_in == 0.0 {
            return LungLinear {
                content,
                by_inflow: 1.0,
                by_flow: 0.0,
                by_param: vec![0.0; params.len()],
            };
        }
        let dl = l.diffusing_capacity;
        let by_param = params
            .iter()
            .map(|&p| match p {
                LoopParameter::DiffusingCapacity => y_out / q,
                // Bohr's integral by P_A at fixed ends: −∫ C'(P)/(P_A − P)² dP = I_A, so
                // dP_out/dP_A = −I_A/K_out and dC_out/dP_A = C'(P_out) dP_out/dP_A
                LoopParameter::AlveolarPo2 => -bohr_by_alveolar(h, pa, y_in, y_out) * y_out,
                LoopParameter::P50 | LoopParameter::Capacity => {
                    // Bohr's integral ∫ C'(P)/(P_A − P) dP from P_in to P_out is D_L/Q
                    let (k_in, k_out) = (slope(h, p_in) / y_in, slope(h, p_out) / y_out);
                    let dp_in = -total_by(p, h, p_in) / slope(h, p_in);
                    let integral = bohr_by(p, h, pa, y_in, y_out);
                    let dp_out = (k_in * dp_in - integral) / k_out;
                    slope(h, p_out) * dp_out + total_by(p, h, p_out)
                }
                _ => 0.0,
            })
            .collect();
        LungLinear {
            content,
            by_inflow: y_out / y_in,
            by_flow: -dl * y_out / (q * q),
            by_param,
        }
    }
}

/// ∫ ∂θC'(P)/(P_A − P) dP from P_in to P_out, as −∫ ∂θC'(P_A − sign e^u) du over u from
/// ln|y_in| to ln|y_out| (Simpson).
fn bohr_by(param: LoopParameter, h: (f64, f64, f64, f64), pa: f64, y_in: f64, y_out: f64) -> f64 {
    let sign = y_in.signum();
    let (u0, u1) = (y_in.abs().ln(), y_out.abs().max(1e-300).ln());
    let n = BOHR_INTERVALS;
    let du = (u1 - u0) / n as f64;
    let f = |u: f64| slope_by(param, h, (pa - sign * u.exp()).max(0.0));
    let mut sum = f(u0) + f(u1);
    for k in 1..n {
        sum += if k % 2 == 1 { 4.0 } else { 2.0 } * f(u0 + du * k as f64);
    }
    -sum * du / 3.0
}

/// −∫ C'(P)/(P_A − P)² dP from P_in to P_out, as sign ∫ C'(P_A − sign e^u) e^{−u} du over u
/// from ln|y_in| to ln|y_out| (Simpson).
fn bohr_by_alveolar(h: (f64, f64, f64, f64), pa: f64, y_in: f64, y_out: f64) -> f64 {
    let sign = y_in.signum();
    let (u0, u1) = (y_in.abs().ln(), y_out.abs().max(1e-300).ln());
    let n = BOHR_INTERVALS;
    let du = (u1 - u0) / n as f64;
    let f = |u: f64| slope(h, (pa - sign * u.exp()).max(0.0)) * (-u).exp();
    let mut sum = f(u0) + f(u1);
    for k in 1..n {
        sum += if k % 2 == 1 { 4.0 } else { 2.0 } * f(u0 + du * k as f64);
    }
    sign * sum * du / 3.0
}

/// A compartment's consumption linearised at its end-of-step content: dVO2/dC_t, and
/// ∂VO2/∂θ at fixed C_t for each parameter.
fn consumption_linear(
    lp: &ClosedLoop,
    n: usize,
    c: f64,
    params: &[LoopParameter],
) -> (f64, Vec<f64>) {
    let law = lp.consumption[n];
    let h = hill_of(&lp.binding).expect("the loop's binding is Hill's");
    let p = c / lp.alpha;
    let (_, dvo2_dp) = law.rate(p);
    let dp_dct = 1.0 / slope(h, p);
    let by = params
        .iter()
        .map(|&q| match (q, law) {
            (LoopParameter::Vmax(k), Consumption::MichaelisMenten { km, .. }) if k == n => {
                let p = p.max(0.0);
                p / (km + p)
            }
            (LoopParameter::Km, Consumption::MichaelisMenten { vmax, km }) => {
                let p = p.max(0.0);
                -vmax * p / ((km + p) * (km + p))
            }
            (LoopParameter::P50 | LoopParameter::Capacity, _) => {
                -dvo2_dp * total_by(q, h, p) * dp_dct
            }
            _ => 0.0,
        })
        .collect();
    (dvo2_dp * dp_dct, by)
}

/// One step's linearisation: the step Jacobian M (row-major nc × nc) and, per direction,
/// the right side's parts that do not depend on the start tangent.
struct StepLinear {
    m: Vec<f64>,
    /// per direction (only parameter directions are non-zero) the source r_θ (nc)
    source: Vec<Vec<f64>>,
    /// per direction: d|q_b|/dθ (the flow direction), used for the volumes
    dq: Vec<Vec<f64>>,
}

impl ClosedLoop {
    /// The linearised step `s` of `cycle` (start contents `c0`, start volumes `v0`) for
    /// `nd` directions, the last `params.len()` of them the parameters'.
    fn step_linear(
        &self,
        cycle: &Cycle,
        s: usize,
        params: &[LoopParameter],
        nd: usize,
    ) -> StepLinear {
        let (nc, nb) = (self.volume.len(), self.from.len());
        let dt = cycle.dt;
        let q = &cycle.flow[s * nb..(s + 1) * nb];
        let c1 = &cycle.total[s * nc..(s + 1) * nc];
        let v1 = &cycle.volume[s * nc..(s + 1) * nc];
        let np = params.len();
        let first = nd - np;
        let mut m = vec![0.0; nc * nc];
        let mut source = vec![vec![0.0; nc]; nd];
        let mut dq = vec![vec![0.0; nb]; nd];
        let mut q_out = vec![0.0; nc];
        for (b, &qb) in q.iter().enumerate() {
            let up = if qb >= 0.0 { self.from[b] } else { self.to[b] };
            q_out[up] += qb.abs();
            // d|q| = sign(q) dq; at q = 0 (a closed valve, whose tangent is zero too) the
            // upstream side does not change
            for (j, &p) in params.iter().enumerate() {
                dq[first + j][b] = qb.signum() * cycle.flow_by(p, s, b) * f64::from(qb != 0.0);
            }
        }
        for n in 0..nc {
            let c = self.binding.free(c1[n], self.free[n]);
            let (by_c, by) = consumption_linear(self, n, c, params);
            m[n * nc + n] += v1[n] + dt * q_out[n] + dt * by_c;
            for j in 0..np {
                source[first + j][n] -= dt * by[j];
            }
        }
        for (b, &qb) in q.iter().enumerate() {
            if qb == 0.0 {
                continue;
            }
            let (up, down) = if qb > 0.0 {
                (self.from[b], self.to[b])
            } else {
                (self.to[b], self.from[b])
            };
            let (content, by_c, by_q, by) = if self.lungs[b].is_some() && qb > 0.0 {
                let l = self.lung_linear(b, qb, c1[up], params);
                (l.content, l.by_inflow, l.by_flow, l.by_param)
            } else {
                (c1[up], 1.0, 0.0, vec![0.0; np])
            };
            m[down * nc + up] -= dt * qb.abs() * by_c;
            for j in 0..np {
                let dqb = dq[first + j][b];
                source[first + j][down] += dt * (dqb * content + qb.abs() * (by[j] + by_q * dqb));
            }
        }
        StepLinear { m, source, dq }
    }

    /// The tangent of the recorded periodic `cycle` by each of `params`: the cycle map's
    /// Jacobians by the start contents and by the parameters, then the implicit function
    /// theorem on the periodic fixed point. An error when I − Φ_x is singular (a neutral
    /// mode: the loop's O2 amount is then not set by its parameters).
    pub fn cycle_tangent(&self, cycle: &Cycle, params: &[LoopParameter]) -> Result<CycleTangent> {
        let nc = self.volume.len();
        let steps = cycle.steps(nc);
        let (np, nd) = (params.len(), nc + params.len());
        let mut dc = vec![0.0; nd * nc]; // direction-major
        for k in 0..nc {
            dc[k * nc + k] = 1.0;
        }
        let mut dv = vec![0.0; nd * nc];
        let mut record = vec![0.0; steps * nd * nc];
        for s in 0..steps {
            let c0: Vec<f64> = if s == 0 {
                cycle.total[(steps - 1) * nc..].to_vec()
            } else {
                cycle.total[(s - 1) * nc..s * nc].to_vec()
            };
            let v0 = if s == 0 {
                cycle.start_volume
            } else {
                &cycle.volume[(s - 1) * nc..s * nc]
            };
            let lin = self.step_linear(cycle, s, params, nd);
            let lu = nalgebra::DMatrix::from_row_slice(nc, nc, &lin.m).lu();
            let c1 = &cycle.total[s * nc..(s + 1) * nc];
            for d in 0..nd {
                let mut dv1 = dv[d * nc..(d + 1) * nc].to_vec();
                let mut dq_out = vec![0.0; nc];
                for (b, &g) in lin.dq[d].iter().enumerate() {
                    let qb = cycle.flow[s * self.from.len() + b];
                    let (up, down) = if qb >= 0.0 {
                        (self.from[b], self.to[b])
                    } else {
                        (self.to[b], self.from[b])
                    };
                    dv1[up] -= cycle.dt * g;
                    dv1[down] += cycle.dt * g;
                    dq_out[up] += g;
                }
                let r = nalgebra::DVector::from_iterator(
                    nc,
                    (0..nc).map(|n| {
                        v0[n] * dc[d * nc + n] + c0[n] * dv[d * nc + n]
                            - c1[n] * (dv1[n] + cycle.dt * dq_out[n])
                            + lin.source[d][n]
                    }),
                );
                let x = lu.solve(&r).ok_or_else(|| {
                    Error::model("closed-loop sensitivities", "a step's Jacobian is singular")
                })?;
                dc[d * nc..(d + 1) * nc].copy_from_slice(x.as_slice());
                dv[d * nc..(d + 1) * nc].copy_from_slice(&dv1);
            }
            record[s * nd * nc..(s + 1) * nd * nc].copy_from_slice(&dc);
        }
        fixed_point(&record, steps, nc, np)
    }
}

/// The implicit function theorem on the cycle map: dx/dθ = (I − Φ_x)⁻¹ Φ_θ from the last
/// step's tangents, then every step's tangent by θ as its own plus Σ_k (state k's) dx_k/dθ.
fn fixed_point(record: &[f64], steps: usize, nc: usize, np: usize) -> Result<CycleTangent> {
    let nd = nc + np;
    let last = &record[(steps - 1) * nd * nc..];
    // column k of Φ_x is direction k's tangent at the cycle end
    let a = nalgebra::DMatrix::from_fn(nc, nc, |i, k| {
        (if i == k { 1.0 } else { 0.0 }) - last[k * nc + i]
    });
    let rhs = nalgebra::DMatrix::from_fn(nc, np, |i, j| last[(nc + j) * nc + i]);
    let lu = a.lu();
    let x = lu.solve(&rhs).filter(|x| x.iter().all(|v| v.is_finite()));
    let x = x.ok_or_else(|| {
        Error::model(
            "closed-loop sensitivities",
            "the periodic state is not isolated (I − Φ_x is singular): the loop's O2 \
             amount is not set by its lungs and consumption",
        )
    })?;
    let mut d_total = vec![0.0; steps * np * nc];
    for s in 0..steps {
        let r = &record[s * nd * nc..(s + 1) * nd * nc];
        for j in 0..np {
            for i in 0..nc {
                let mut v = r[(nc + j) * nc + i];
                for k in 0..nc {
                    v += r[k * nc + i] * x[(k, j)];
                }
                d_total[(s * np + j) * nc + i] = v;
            }
        }
    }
    Ok(CycleTangent {
        d_total,
        n_params: np,
    })
}

/// An output of the loop's periodic cycle (SI): the flow-weighted saturation and PO2 of the
/// blood the left heart ejects (arterial) and the right heart ejects (mixed venous), the
/// cycle-mean O2 consumption of the loop or of one compartment, the cycle-mean left-heart
/// ejection (the cardiac output).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LoopOutput {
    SaO2,
    SvO2,
    PaO2,
    PvO2,
    Vo2,
    OrganVo2(usize),
    CardiacOutput,
}

/// A compartment's state at a step end and its tangent by one parameter: PO2 (Pa),
/// saturation, VO2 (mol/s).
struct Linearised {
    po2: (f64, f64),
    saturation: (f64, f64),
    vo2: (f64, f64),
}

impl ClosedLoop {
    /// Compartment n's state from its total content `ct` and that content's tangent `dct` by
    /// parameter `param`.
    fn linearised(&self, n: usize, ct: f64, dct: f64, param: LoopParameter) -> Linearised {
        let h = hill_of(&self.binding).expect("the loop's binding is Hill's");
        let (alpha, _, _, cap) = h;
        let c = self.binding.free(ct, self.free[n]);
        let p = c / alpha;
        // C_t(c; θ): dc = (dC_t − ∂θC_t)/(dC_t/dc)
        let dc = (dct - total_by(param, h, p)) * alpha / slope(h, p);
        let s = (ct - c) / cap;
        let dcap = if param == LoopParameter::Capacity {
            1.0
        } else {
            0.0
        };
        let ds = (dct - dc) / cap - s * dcap / cap;
        let law = self.consumption[n];
        let (vo2, dvo2_dp) = law.rate(p);
        let pp = p.max(0.0);
        let direct = match (param, law) {
            (LoopParameter::Vmax(k), Consumption::MichaelisMenten { km, .. }) if k == n => {
                pp / (km + pp)
            }
            (LoopParameter::Km, Consumption::MichaelisMenten { vmax, km }) => {
                -vmax * pp / ((km + pp) * (km + pp))
            }
            _ => 0.0,
        };
        Linearised {
            po2: (p, dc / alpha),
            saturation: (s, ds),
            vo2: (vo2, dvo2_dp * dc / alpha + direct),
        }
    }

    /// The output's value over the recorded `cycle` and its derivative by each of `params`
    /// (from `tangent`); an error naming a compartment or branch the loop lacks.
    pub fn output(
        &self,
        cycle: &Cycle,
        tangent: &CycleTangent,
        params: &[LoopParameter],
        out: LoopOutput,
    ) -> Result<(f64, Vec<f64>)> {
        let nc = self.volume.len();
        let nb = self.from.len();
        let steps = cycle.steps(nc);
        let np = tangent.n_params;
        let state = |s: usize, n: usize, j: usize| {
            let dct = tangent.d_total[(s * np + j) * nc + n];
            self.linearised(n, cycle.total[s * nc + n], dct, params[j])
        };
        let branch = |name: &str| self.index_of(&self.branch_names, name, "branch");
        let compartment = |name: &str| self.index_of(&self.names, name, "compartment");
        let weighted = |b: usize, n: usize, pick: fn(&Linearised) -> (f64, f64)| {
            let q: Vec<f64> = (0..steps).map(|s| cycle.flow[s * nb + b]).collect();
            let sq: f64 = q.iter().sum();
            let value = (0..steps)
                .map(|s| q[s] * pick(&self.at_rest(n, cycle.total[s * nc + n])).0)
                .sum::<f64>()
                / sq;
            let derivs = (0..np)
                .map(|j| {
                    // a flow parameter moves the weights: d(Σ q x/Σ q)
                    // = Σ (dq x + q dx)/Σ q − value Σ dq/Σ q
                    (0..steps)
                        .map(|s| {
                            let (x, dx) = pick(&state(s, n, j));
                            cycle.flow_by(params[j], s, b) * (x - value) + q[s] * dx
                        })
                        .sum::<f64>()
                        / sq
                })
                .collect();
            (value, derivs)
        };
        let mean_vo2 = |ns: &[usize]| {
            let mut value = 0.0;
            let mut derivs = vec![0.0; np];
            for s in 0..steps {
                for &n in ns {
                    value += self.at_rest(n, cycle.total[s * nc + n]).vo2.0;
                    for (j, d) in derivs.iter_mut().enumerate() {
                        *d += state(s, n, j).vo2.1;
                    }
                }
            }
            let k = steps as f64;
            (value / k, derivs.iter().map(|d| d / k).collect())
        };
        Ok(match out {
            LoopOutput::SaO2 => {
                weighted(branch("ejection_left")?, compartment("left_heart")?, |l| {
                    l.saturation
                })
            }
            LoopOutput::SvO2 => weighted(
                branch("ejection_right")?,
                compartment("right_heart")?,
                |l| l.saturation,
            ),
            LoopOutput::PaO2 => {
                weighted(branch("ejection_left")?, compartment("left_heart")?, |l| {
                    l.po2
                })
            }
            LoopOutput::PvO2 => weighted(
                branch("ejection_right")?,
                compartment("right_heart")?,
                |l| l.po2,
            ),
            LoopOutput::Vo2 => mean_vo2(&(0..nc).collect::<Vec<_>>()),
            LoopOutput::OrganVo2(n) => mean_vo2(&[n]),
            LoopOutput::CardiacOutput => {
                let b = branch("ejection_left")?;
                let mean = (0..steps).map(|s| cycle.flow[s * nb + b]).sum::<f64>() / steps as f64;
                let dmean = |j: usize| {
                    (0..steps)
                        .map(|s| cycle.flow_by(params[j], s, b))
                        .sum::<f64>()
                        / steps as f64
                };
                (mean, (0..np).map(dmean).collect())
            }
        })
    }

    /// Compartment n's state from its total content, no tangent (the flow scale moves no
    /// binding or consumption term).
    fn at_rest(&self, n: usize, ct: f64) -> Linearised {
        self.linearised(n, ct, 0.0, LoopParameter::FlowScale)
    }

    fn index_of(&self, list: &[String], name: &str, what: &str) -> Result<usize> {
        list.iter().position(|x| x == name).ok_or_else(|| {
            Error::model(
                "closed-loop sensitivities",
                format!("the loop has no {what} '{name}'"),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::transport::closed_loop::ClosedLoopSpec;

    const MMHG: f64 = 133.322368;

    /// A two-compartment loop through the lungs with Hill binding (haemoglobin's numbers).
    fn lung_loop(p50: f64, capacity: f64, dl: f64, pa: f64) -> ClosedLoop {
        let spec = ClosedLoopSpec::from_json(&format!(
            r#"{{"compartments": [{{"name": "venous", "volume": 1e-3, "initial_po2": 5000}},
                 {{"name": "arterial", "volume": 1e-3, "initial_po2": 13000}}],
              "branches": [{{"name": "lungs", "from": 0, "to": 1,
                             "lungs": {{"alveolar_po2": {pa}, "diffusing_capacity": {dl}}}}},
                           {{"name": "back", "from": 1, "to": 0}}],
              "binding": {{"kind": "hill", "solubility": {a}, "p50": {p50}, "n": 2.7,
                          "capacity": {capacity}}}}}"#,
            a = 1.34e-3 / MMHG,
        ))
        .unwrap();
        ClosedLoop::new(&spec).unwrap()
    }

    /// The end-capillary content's derivatives (those of Bohr's ODE, and by P50 and the
    /// capacity through Bohr's integral) against central differences of the lung's RK4
    /// integration: it reproduces the ODE to ≤ 1e-9, the differences' error is ~h².
    #[test]
    fn lung_derivatives_match_central_differences_of_the_rk4_integration() {
        let (p50, cap, dl) = (26.8 * MMHG, 8.97, 1.5e-8);
        let params = [
            LoopParameter::DiffusingCapacity,
            LoopParameter::P50,
            LoopParameter::Capacity,
            LoopParameter::AlveolarPo2,
        ];
        let pa = 100.0 * MMHG;
        let (q, c_in) = (8e-5, 6.5);
        let lp = lung_loop(p50, cap, dl, 100.0 * MMHG);
        let lin = lp.lung_linear(0, q, c_in, &params);
        let end_at = |p50: f64, cap: f64, dl: f64, pa: f64, q: f64, c: f64| {
            let l = lung_loop(p50, cap, dl, pa);
            l.lungs[0]
                .as_ref()
                .unwrap()
                .end_capillary(&l.binding, l.alpha, c, q)
        };
        let end = |p50: f64, cap: f64, dl: f64, q: f64, c: f64| end_at(p50, cap, dl, pa, q, c);
        let h = 1e-4;
        let fd =
            |f: &dyn Fn(f64) -> f64, x: f64| (f(x * (1.0 + h)) - f(x * (1.0 - h))) / (2.0 * h * x);
        let checks = [
            (lin.by_inflow, fd(&|c| end(p50, cap, dl, q, c), c_in)),
            (lin.by_flow, fd(&|q| end(p50, cap, dl, q, c_in), q)),
            (lin.by_param[0], fd(&|d| end(p50, cap, d, q, c_in), dl)),
            (lin.by_param[1], fd(&|p| end(p, cap, dl, q, c_in), p50)),
            (lin.by_param[2], fd(&|k| end(p50, k, dl, q, c_in), cap)),
            (
                lin.by_param[3],
                fd(&|a| end_at(p50, cap, dl, a, q, c_in), pa),
            ),
        ];
        for (k, (exact, diff)) in checks.iter().enumerate() {
            assert!(
                (exact - diff).abs() <= 1e-6 * diff.abs(),
                "derivative {k}: {exact} vs {diff}"
            );
        }
    }
}

#[cfg(test)]
#[path = "closed_loop_flow_tests.rs"]
mod flow_tests;
