//! Calibration of element values from observed states (svZeroDSolver's calibrator): the DAE
//! residual E(α) ẏ + F(α) y + c(α, y) of a network's RCL vessels and junction branches,
//! evaluated at observed y and ẏ, and its exact derivatives with respect to the element values
//! α. No forward simulation: the observations fix the state, the residual is what the element
//! values leave unexplained, and a Gauss–Newton/Levenberg–Marquardt fit drives it to its least
//! squares. Each block's values act on that block's rows only, so JᵀJ is block diagonal and
//! [`normal_equations`] returns one small dense block per element.
//!
//! The rows are the core's own stamps ([`crate::assemble`]'s RCL vessel in svZeroDSolver's
//! form, [`crate::circuit::ChainRuleCapacitor`]), with the capacitor's interior pressure
//! eliminated through the R branch, P_c = P_in − (R + S|Q|) Q, because the observations hold the
//! pressures and flows at the element ends only:
//! * R–L branch (momentum): P_in − P_out − (R + S|Q|) Q − L dQ_out/dt = 0;
//! * capacitor (mass): Q − Q_out − C (dP_in/dt − (R + 2S|Q|) dQ/dt) = 0.
//!
//! A junction branch (R + S|Q| then L, no capacitor) has the momentum row only. The rows are
//! evaluated in the observations' own units: the least-squares weighting of a pressure row
//! against a flow row depends on them, and a calibrator reproduces another's answer only in
//! the same units.

use crate::error::{Error, Result};

#[cfg(test)]
mod tests;

/// A block of the calibration problem: which observed variables it reads and which slots of
/// the element-value vector α it owns.
#[derive(Debug, Clone)]
pub enum Block {
    /// An RCL vessel (R with stenosis S|Q|, then C, then L). `vars`: the observed
    /// (P_in, Q_in, P_out, Q_out); `params`: the α slots of (R, C, L, S).
    Vessel {
        name: String,
        vars: [usize; 4],
        params: [usize; 4],
    },
    /// One R(+S)–L branch of a junction from its inlet to an outlet. `vars`: the observed
    /// (P_in, P_out, Q_out); `params`: the α slots of (R, L, S).
    Branch {
        name: String,
        vars: [usize; 3],
        params: [usize; 3],
    },
}

impl Block {
    pub fn name(&self) -> &str {
        match self {
            Block::Vessel { name, .. } | Block::Branch { name, .. } => name,
        }
    }
    /// The α slots this block owns, in the order of its block of JᵀJ.
    pub fn params(&self) -> &[usize] {
        match self {
            Block::Vessel { params, .. } => params,
            Block::Branch { params, .. } => params,
        }
    }
    fn vars(&self) -> &[usize] {
        match self {
            Block::Vessel { vars, .. } => vars,
            Block::Branch { vars, .. } => vars,
        }
    }
}

/// Observed states: `y` and `dy` hold `n_obs` samples of each of `n_var` variables,
/// variable-major (variable v's samples at `v * n_obs .. (v + 1) * n_obs`).
#[derive(Debug, Clone, Copy)]
pub struct Observations<'a> {
    pub y: &'a [f64],
    pub dy: &'a [f64],
    pub n_obs: usize,
}

impl Observations<'_> {
    fn n_var(&self) -> usize {
        self.y.len().checked_div(self.n_obs).unwrap_or(0)
    }
    fn at(&self, v: usize, k: usize) -> (f64, f64) {
        let i = v * self.n_obs + k;
        (self.y[i], self.dy[i])
    }
}

/// The Gauss–Newton quantities at α: the cost Σ r², the gradient Jᵀr by α slot, and each
/// block's dense JᵀJ (row-major, blocks in order, k×k for a block of k slots).
#[derive(Debug, Clone)]
pub struct NormalEquations {
    pub cost: f64,
    pub gradient: Vec<f64>,
    pub gram: Vec<f64>,
}

/// Check the blocks against the observations and α: every variable and slot in range, the
/// observations and values finite. Errors name the block.
pub fn check(blocks: &[Block], obs: &Observations, n_params: usize) -> Result<()> {
    if obs.n_obs == 0 || obs.y.len() % obs.n_obs != 0 || obs.y.len() != obs.dy.len() {
        return Err(Error::model(
            "calibration observations",
            format!(
                "y ({} values) and dy ({} values) are not {} samples per variable",
                obs.y.len(),
                obs.dy.len(),
                obs.n_obs
            ),
        ));
    }
    let n_var = obs.n_var();
    for b in blocks {
        if let Some(&v) = b.vars().iter().find(|&&v| v >= n_var) {
            return Err(Error::model(
                b.name(),
                format!("observed variable {v} out of range ({n_var} variables)"),
            ));
        }
        if let Some(&p) = b.params().iter().find(|&&p| p >= n_params) {
            return Err(Error::model(
                b.name(),
                format!("parameter slot {p} out of range ({n_params} slots)"),
            ));
        }
        for &v in b.vars() {
            let k = (0..obs.n_obs).find(|&k| {
                let (y, dy) = obs.at(v, k);
                !(y.is_finite() && dy.is_finite())
            });
            if let Some(k) = k {
                let (y, dy) = obs.at(v, k);
                return Err(Error::model(
                    b.name(),
                    format!("observation {k} of variable {v} is not finite (y = {y}, dy = {dy})"),
                ));
            }
        }
    }
    Ok(())
}

/// The rows of block `b` at observation `k` for values `a` (its slots' values in order): the
/// residuals and their derivatives with respect to the block's slots (`jac[row][slot]`).
/// Returns the number of rows (2 for a vessel, 1 for a branch).
fn rows(
    b: &Block,
    obs: &Observations,
    k: usize,
    a: &[f64],
    r: &mut [f64; 2],
    jac: &mut [[f64; 4]; 2],
) -> usize {
    match b {
        Block::Vessel { vars, .. } => {
            let [(p_in, dp_in), (q, dq), (p_out, _), (q_out, dq_out)] = vars.map(|v| obs.at(v, k));
            let [res, cap, ind, sten] = [a[0], a[1], a[2], a[3]];
            // the R branch's chord and tangent resistances: (R + S|Q|) and (R + 2S|Q|)
            let chord = res + sten * q.abs();
            let slope = res + 2.0 * sten * q.abs();
            r[0] = p_in - p_out - chord * q - ind * dq_out;
            jac[0] = [-q, 0.0, -dq_out, -q.abs() * q];
            r[1] = q - q_out - cap * (dp_in - slope * dq);
            jac[1] = [
                cap * dq,
                -(dp_in - slope * dq),
                0.0,
                2.0 * cap * q.abs() * dq,
            ];
            2
        }
        Block::Branch { vars, .. } => {
            let [(p_in, _), (p_out, _), (q, dq)] = vars.map(|v| obs.at(v, k));
            let [res, ind, sten] = [a[0], a[1], a[2]];
            r[0] = p_in - p_out - (res + sten * q.abs()) * q - ind * dq;
            jac[0] = [-q, -dq, -q.abs() * q, 0.0];
            1
        }
    }
}

/// A sparse matrix as (row, column, value) entries.
pub type Triplets = Vec<(usize, usize, f64)>;

/// The residual of every block at every observation, row by row (block-major, then
/// observation, then the block's rows), and its Jacobian as (row, slot, value) triplets.
pub fn residual(
    blocks: &[Block],
    obs: &Observations,
    alpha: &[f64],
) -> Result<(Vec<f64>, Triplets)> {
    check(blocks, obs, alpha.len())?;
    let mut res = Vec::new();
    let mut triplets = Vec::new();
    let (mut r, mut jac) = ([0.0; 2], [[0.0; 4]; 2]);
    for b in blocks {
        let a: Vec<f64> = b.params().iter().map(|&p| alpha[p]).collect();
        for k in 0..obs.n_obs {
            let m = rows(b, obs, k, &a, &mut r, &mut jac);
            for i in 0..m {
                for (j, &p) in b.params().iter().enumerate() {
                    triplets.push((res.len(), p, jac[i][j]));
                }
                res.push(r[i]);
            }
        }
    }
    Ok((res, triplets))
}

/// Cost, gradient Jᵀr and the blocks of JᵀJ at α (see [`NormalEquations`]). The values must be
/// finite: a non-finite value is reported with its block.
pub fn normal_equations(
    blocks: &[Block],
    obs: &Observations,
    alpha: &[f64],
) -> Result<NormalEquations> {
    check(blocks, obs, alpha.len())?;
    let mut out = NormalEquations {
        cost: 0.0,
        gradient: vec![0.0; alpha.len()],
        gram: Vec::with_capacity(blocks.iter().map(|b| b.params().len().pow(2)).sum()),
    };
    let (mut r, mut jac) = ([0.0; 2], [[0.0; 4]; 2]);
    for b in blocks {
        let slots = b.params();
        let a: Vec<f64> = slots.iter().map(|&p| alpha[p]).collect();
        if let Some(v) = a.iter().find(|v| !v.is_finite()) {
            return Err(Error::model(
                b.name(),
                format!("element value {v} is not finite"),
            ));
        }
        let n = slots.len();
        let (mut g, mut h) = ([0.0; 4], [[0.0; 4]; 4]);
        for k in 0..obs.n_obs {
            let m = rows(b, obs, k, &a, &mut r, &mut jac);
            for (ri, ji) in r.iter().zip(&jac).take(m) {
                out.cost += ri * ri;
                for i in 0..n {
                    g[i] += ji[i] * ri;
                    for j in 0..=i {
                        h[i][j] += ji[i] * ji[j];
                    }
                }
            }
        }
        for (i, &p) in slots.iter().enumerate() {
            out.gradient[p] += g[i];
        }
        // the lower triangle was summed: mirror it
        for i in 0..n {
            out.gram.extend((0..n).map(|j| h[i.max(j)][i.min(j)]));
        }
    }
    Ok(out)
}

/// svZeroDSolver's Levenberg–Marquardt settings (its `calibration_parameters`).
#[derive(Debug, Clone, Copy)]
pub struct FitSettings {
    pub max_iterations: usize,
    pub initial_damping: f64,
    pub tolerance_gradient: f64,
    pub tolerance_increment: f64,
}

/// Where a fit ended: the values, the iterations taken and whether both tolerances were met
/// (or the observations held exactly) before `max_iterations`.
#[derive(Debug, Clone)]
pub struct Fit {
    pub alpha: Vec<f64>,
    pub iterations: usize,
    pub converged: bool,
}

/// svZeroDSolver's Levenberg–Marquardt iteration from `start`, fitting the slots marked in
/// `active`: every step taken, the damping scaled by the ratio of successive gradient norms
/// (over the fitted slots), a stop when the gradient norm and the step norm are both below
/// their tolerances. The same iteration, not another optimiser, because the calibrator's
/// files stop it early (`maximum_iterations: 20` in the VMR cases): the answer to reproduce
/// is that iterate. A step the data do not determine is a solver error naming the block.
pub fn fit(
    blocks: &[Block],
    obs: &Observations,
    start: &[f64],
    active: &[bool],
    s: &FitSettings,
) -> Result<Fit> {
    let mut alpha = start.to_vec();
    let mut damping = s.initial_damping;
    let mut norm_old = f64::NAN;
    for it in 0..s.max_iterations {
        let ne = normal_equations(blocks, obs, &alpha)?;
        let norm_grad = (ne.gradient.iter().zip(active))
            .filter(|&(_, &a)| a)
            .map(|(g, _)| g * g)
            .sum::<f64>()
            .sqrt();
        if norm_grad == 0.0 {
            // the observations hold exactly: no step to take
            return Ok(Fit {
                alpha,
                iterations: it,
                converged: true,
            });
        }
        if it > 0 {
            damping *= norm_grad / norm_old;
        }
        norm_old = norm_grad;
        let mut inc2 = 0.0;
        let mut offset = 0;
        for b in blocks {
            let slots = b.params();
            let k = slots.len();
            let gram = &ne.gram[offset..offset + k * k];
            offset += k * k;
            for (&p, d) in slots
                .iter()
                .zip(block_step(b, gram, &ne.gradient, active, damping)?)
            {
                alpha[p] -= d;
                inc2 += d * d;
            }
        }
        if norm_grad < s.tolerance_gradient && inc2.sqrt() < s.tolerance_increment {
            return Ok(Fit {
                alpha,
                iterations: it + 1,
                converged: true,
            });
        }
    }
    Ok(Fit {
        alpha,
        iterations: s.max_iterations,
        converged: false,
    })
}

/// The damped Gauss–Newton step of one block, (H + λ diag H) δ = g, on the slots the data
/// determine (fitted, and a non-zero column of J: L under steady data has none); the other
/// slots take no step (their rows of the system are the identity's).
fn block_step(
    b: &Block,
    gram: &[f64],
    gradient: &[f64],
    active: &[bool],
    damping: f64,
) -> Result<Vec<f64>> {
    let slots = b.params();
    let k = slots.len();
    let free: Vec<bool> = (0..k)
        .map(|i| active[slots[i]] && gram[i * k + i] > 0.0)
        .collect();
    let mut m = vec![0.0; k * k];
    let mut rhs = vec![0.0; k];
    for i in 0..k {
        if !free[i] {
            m[i * k + i] = 1.0;
            continue;
        }
        rhs[i] = gradient[slots[i]];
        for j in (0..k).filter(|&j| free[j]) {
            m[i * k + j] = gram[i * k + j]
                + if i == j {
                    damping * gram[i * k + i]
                } else {
                    0.0
                };
        }
    }
    // (LU with partial pivoting: a zero pivot or a non-finite step is a singular block)
    if crate::sparse::lu_solve(&m, &mut rhs, k, 0.0) {
        return Ok(rhs);
    }
    Err(Error::solver(
        0.0,
        format!(
            "svZeroD calibration: the step of '{}' is singular (its values are not \
             determined by the observations)",
            b.name()
        ),
    ))
}
