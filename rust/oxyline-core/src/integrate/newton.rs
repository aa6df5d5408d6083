//! The one Newton solver of the integrators. Generalized-α's implicit step, RK4's elimination of
//! the algebraic rows with stenoses and the steady state all solve G(x) = 0 for a part of the
//! circuit state; they differ only in the residual, the iteration matrix and how a correction
//! maps to the state, which a [`NewtonProblem`] supplies. The stopping rule is shared: either
//! svZeroDSolver's absolute residual (bit-compatible with it) or one scaled-increment rule.

use crate::circuit::{Dae, JacobianKind};
use crate::error::{Error, Result};
use crate::sparse::Stamp;
use std::cmp::Ordering;

/// Newton stopping rule. `atol: Some(a)` reproduces svZeroDSolver (max |residual| < a,
/// absolute and unscaled); `None` takes one exact solve for linear circuits and iterates on the
/// scaled increment (see [`Magnitude::increment`]) for nonlinear ones.
#[derive(Debug, Clone, Copy)]
pub struct NewtonControl {
    pub atol: Option<f64>,
    pub max_iter: usize,
}

impl Default for NewtonControl {
    fn default() -> Self {
        NewtonControl {
            atol: None,
            max_iter: 30,
        }
    }
}

/// Converged when the last correction changed every pressure and every flow by less than this,
/// relative to the largest pressure and flow seen (see [`Magnitude`]). Newton converges
/// quadratically, so an increment this small leaves an error at round-off level.
pub const INCREMENT_TOL: f64 = 1e-12;

/// Largest |pressure| and |flow| seen so far. Pressures and flows differ by many decades in SI,
/// so increments are judged on each kind's own scale. The scale is a running maximum, not the
/// current state: when the inflow reverses in a single path all flows pass through zero
/// together, and round-off alone would then exceed a tolerance relative to the instantaneous
/// flow.
#[derive(Debug, Clone, Copy)]
pub struct Magnitude {
    n_nodes: usize,
    peak: [f64; 2],
}

fn amax(s: &[f64]) -> f64 {
    s.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

impl Magnitude {
    pub fn new(dae: &Dae) -> Self {
        Magnitude {
            n_nodes: dae.n_nodes,
            peak: [0.0; 2],
        }
    }

    /// The running maxima (pressure, flow): the part of the scale a checkpoint carries.
    pub fn peaks(&self) -> [f64; 2] {
        self.peak
    }

    /// Restore the running maxima of a checkpoint (see [`Magnitude::peaks`]).
    pub fn set_peaks(&mut self, peak: [f64; 2]) {
        self.peak = peak;
    }

    /// Include a full state `y` (pressures first, then flows) in the running maximum.
    pub fn observe(&mut self, y: &[f64]) {
        let nn = self.n_nodes;
        self.peak[0] = self.peak[0].max(amax(&y[..nn]));
        self.peak[1] = self.peak[1].max(amax(&y[nn..]));
    }

    /// The scaled increment: largest change of a pressure and of a flow, each relative to its
    /// running maximum. `dx[l]` is the change of state unknown `unknowns[l]` (of unknown `l`
    /// when `unknowns` is None).
    pub fn increment(&self, unknowns: Option<&[usize]>, dx: &[f64]) -> f64 {
        let nn = self.n_nodes;
        let (mut dp, mut dq) = (0.0f64, 0.0f64);
        for (l, d) in dx.iter().enumerate() {
            if unknowns.map_or(l, |u| u[l]) < nn {
                dp = dp.max(d.abs());
            } else {
                dq = dq.max(d.abs());
            }
        }
        (dp / self.peak[0].max(1e-300)).max(dq / self.peak[1].max(1e-300))
    }
}

/// Relative size of a state change `dy` against the state `y` (the scaled-increment rule with
/// `y` as the only state seen; also the cycle-to-cycle periodicity measure).
pub fn scaled_increment(dae: &Dae, dy: &[f64], y: &[f64]) -> f64 {
    let mut m = Magnitude::new(dae);
    m.observe(y);
    m.increment(None, dy)
}

/// One Newton iteration's ingredients for [`solve`].
pub trait NewtonProblem {
    /// Write the residual at the current iterate into `r`.
    fn residual(&mut self, r: &mut [f64]);
    /// Factorise the iteration matrix at the current iterate before iteration `it`'s solve (a
    /// linear problem may keep an earlier factorisation).
    fn factor(&mut self, it: usize) -> Result<()>;
    /// Replace `r` by the Newton correction.
    fn solve(&mut self, r: &mut [f64]) -> Result<()>;
    /// Apply the correction `dx`, leaving in `dx` the resulting change of the state unknowns.
    fn update(&mut self, dx: &mut [f64]);
    /// The full circuit state of the current iterate.
    fn state(&self) -> &[f64];
    /// The state unknowns the entries of `dx` belong to (None: all, in order).
    fn unknowns(&self) -> Option<&[usize]>;
    /// A linear problem is solved exactly by the first correction.
    fn is_linear(&self) -> bool;
    /// Halve a correction that did not pass the natural monotonicity test before taking the
    /// next one: a backtracking line search for strongly nonlinear rows (RK4's elimination of
    /// steep valve laws, docs/physics.md §1.8). Default: plain Newton.
    fn backtracks(&self) -> bool {
        false
    }
}

/// Halvings of one correction before the line search gives up and takes the next Newton
/// correction from where it stands (2⁻³⁰ of a step is below any useful change).
const MAX_HALVINGS: usize = 30;

/// Newton's method on `problem` with the residual buffer `r`. `scale` carries the running
/// magnitudes of the scaled-increment rule between calls. Not converging in
/// `control.max_iter` iterations is a solver error at `time`.
///
/// A problem that [`NewtonProblem::backtracks`] takes a correction only when the simplified
/// correction at the new iterate, J_old⁻¹ r_new, is smaller than the correction itself (both
/// as scaled increments of the solve's own unknowns, before [`NewtonProblem::update`] maps
/// them to the state): Deuflhard's natural monotonicity test, invariant under the scaling
/// of the rows (a residual norm would mix Pa and m³/s rows, and a valve's KCL residual of
/// 1e-6 m³/s would count for nothing against its pressure rows); otherwise the correction is
/// halved (half of it is taken back).
pub fn solve<P: NewtonProblem>(
    problem: &mut P,
    r: &mut [f64],
    control: &NewtonControl,
    scale: &mut Magnitude,
    time: f64,
) -> Result<()> {
    // the scaled size of the last correction of a backtracking problem, that correction and
    // the simplified correction
    let mut before: Option<f64> = None;
    let (mut dx, mut simplified, mut back): (Vec<f64>, Vec<f64>, Vec<f64>) =
        (Vec::new(), Vec::new(), Vec::new());
    let mut halvings = 0;
    let mut it = 0;
    while it < control.max_iter {
        problem.residual(r);
        if let Some(before) = before {
            simplified.clear();
            simplified.extend_from_slice(r);
            // the factorisation is still that of the last correction's iterate
            let now = match problem.solve(&mut simplified) {
                Ok(()) => scale.increment(problem.unknowns(), &simplified),
                Err(_) => f64::NAN,
            };
            // an overflow (NaN) is halved too
            let worse = matches!(now.partial_cmp(&before), Some(Ordering::Greater) | None);
            if worse && halvings < MAX_HALVINGS {
                // `dx` is the correction as solved (the update maps it to the state)
                for d in dx.iter_mut() {
                    *d *= 0.5;
                }
                back.clear();
                back.extend(dx.iter().map(|d| -d));
                problem.update(&mut back);
                halvings += 1;
                continue;
            }
        }
        halvings = 0;
        it += 1;
        if let Some(atol) = control.atol {
            // svZeroDSolver checks the residual before each solve and gives up without a
            // last correction
            if amax(r) < atol {
                return Ok(());
            }
            if it == control.max_iter {
                break;
            }
        }
        problem.factor(it - 1)?;
        problem.solve(r)?;
        if problem.backtracks() {
            dx.clear();
            dx.extend_from_slice(r);
        }
        problem.update(r);
        if problem.backtracks() {
            scale.observe(problem.state());
            before = Some(scale.increment(problem.unknowns(), &dx));
        }
        if control.atol.is_none() {
            if problem.is_linear() {
                return Ok(());
            }
            scale.observe(problem.state());
            if scale.increment(problem.unknowns(), r) < INCREMENT_TOL {
                return Ok(());
            }
        }
    }
    Err(Error::solver(
        time,
        format!("Newton did not converge in {} iterations", control.max_iter),
    ))
}

/// Value positions of the pattern F ∪ diag ∪ elements (F entries in CSR order, then the n
/// diagonal slots, then the elements' Jacobian entries): the pattern of every iteration
/// matrix a·(F + dc/dy) + diag(d) of the circuit.
pub fn jacobian_stamps(dae: &Dae) -> Vec<(usize, usize)> {
    jacobian_pattern(dae).iter().map(|s| s.at()).collect()
}

/// [`jacobian_stamps`] as 32-bit pairs (the circuit has fewer than 2^32 unknowns), for the
/// run's own analyses: 8 bytes a stamp instead of 16 (~8 stamps per segment, alive while the
/// elimination is analysed, when a large run's memory peaks).
pub fn jacobian_pattern(dae: &Dae) -> Vec<(u32, u32)> {
    let elements = dae.element_pattern();
    let mut stamps = Vec::with_capacity(dae.f.val.len() + dae.n + elements.len());
    for i in 0..dae.n {
        for k in dae.f.row(i) {
            stamps.push((i as u32, dae.f.col[k]));
        }
    }
    stamps.extend((0..dae.n as u32).map(|i| (i, i)));
    stamps.extend(elements.iter().map(|&(r, c)| (r as u32, c as u32)));
    stamps
}

/// Fill `vals` (in [`jacobian_stamps`] order) with a·(F + dc/dy(y, t)) + diag(d).
pub fn jacobian_values(dae: &Dae, a: f64, diag: &[f64], y: &[f64], t: f64, vals: &mut [f64]) {
    jacobian_values_of(dae, (a, diag), y, t, JacobianKind::Exact, vals);
}

/// [`jacobian_values`] with the elements' Jacobian of `kind`: `Elimination` is the
/// safeguarded one of a valve's row (its 1 + Q R′ held ≥ 1/2, which every solution meets
/// with room: `element::valve`), the same Newton near the solution and a regular matrix away
/// from it.
pub fn jacobian_values_of(
    dae: &Dae,
    (a, diag): (f64, &[f64]),
    y: &[f64],
    t: f64,
    kind: JacobianKind,
    vals: &mut [f64],
) {
    let nf = dae.f.val.len();
    vals[nf..nf + dae.n].copy_from_slice(diag);
    jacobian_values_around_diagonal(dae, a, y, t, kind, vals);
}

/// [`jacobian_values_of`] with the diagonal d = m·e written from its factor and vector (the
/// same products as a vector m·e built first, without that state-sized vector beside the
/// values: generalized-α's first factorisation is where a large run's memory peaks).
pub fn jacobian_values_scaled(
    dae: &Dae,
    (a, (m, e)): (f64, (f64, &[f64])),
    y: &[f64],
    t: f64,
    kind: JacobianKind,
    vals: &mut [f64],
) {
    let nf = dae.f.val.len();
    for (v, ei) in vals[nf..nf + dae.n].iter_mut().zip(e) {
        *v = m * ei;
    }
    jacobian_values_around_diagonal(dae, a, y, t, kind, vals);
}

/// The values of [`jacobian_values_of`] but the diagonal's own d, already in place: a·F,
/// the stenoses' slopes added to the diagonal, the elements' Jacobian.
fn jacobian_values_around_diagonal(
    dae: &Dae,
    a: f64,
    y: &[f64],
    t: f64,
    kind: JacobianKind,
    vals: &mut [f64],
) {
    let nf = dae.f.val.len();
    for (v, fv) in vals[..nf].iter_mut().zip(&dae.f.val) {
        *v = a * fv;
    }
    for &(i, s) in &dae.stenosis {
        vals[nf + i] += a * 2.0 * s * y[i].abs();
    }
    if !dae.elements.is_empty() {
        dae.element_jacobian(a, t, y, &mut vals[nf + dae.n..], kind);
    }
}

/// The error of a singular iteration matrix at `time`.
pub fn singular(time: f64, detail: &str) -> Error {
    Error::solver(
        time,
        format!(
            "singular system ({detail}); check that every part of the network reaches a pressure, resistance or Windkessel boundary condition"
        ),
    )
}
