//! Generalized-α for E ẏ + F y + c(y) = f(t): the scheme and parameters of svZeroDSolver
//! (Jansen–Whiting–Hulbert 2000, predictor ẏ⁰ = (1 − 1/γ) ẏₙ, Newton on ẏ).
//! For a linear circuit the iteration matrix is constant, so it is factorised once per run.

use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;

/// Newton stopping rule. `atol: Some(a)` reproduces svZeroDSolver (max |residual| < a,
/// absolute and unscaled); `None` takes one exact solve for linear circuits and iterates on the
/// scaled increment for nonlinear ones.
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

pub struct GenAlpha<'a> {
    dae: &'a Dae,
    e: Vec<f64>,
    regime: Regime,
    pub dt: f64,
    am: f64,
    af: f64,
    gamma: f64,
    control: NewtonControl,
    lu: SparseLu,
    kvals: Vec<f64>,
    factored: bool,
    f: Vec<f64>,
    r: Vec<f64>,
    y_new: Vec<f64>,
    yd_new: Vec<f64>,
    y_af: Vec<f64>,
    /// Largest |pressure| and |flow| met so far in the run: the Newton increments are measured
    /// against them, not against the current state, whose flows all pass through zero together
    /// when the inflow reverses in a single path (there round-off alone would exceed a tolerance
    /// relative to the instantaneous flow).
    magnitude: [f64; 2],
}

/// Value positions of the pattern F ∪ diag (F entries in CSR order, then the n diagonal slots).
pub fn jacobian_stamps(dae: &Dae) -> Vec<(usize, usize)> {
    let mut stamps = Vec::with_capacity(dae.f.val.len() + dae.n);
    for i in 0..dae.n {
        for k in dae.f.ptr[i]..dae.f.ptr[i + 1] {
            stamps.push((i, dae.f.col[k]));
        }
    }
    stamps.extend((0..dae.n).map(|i| (i, i)));
    stamps
}

/// Fill `vals` with a·(F + dc/dy(y)) + diag(d).
pub fn jacobian_values(dae: &Dae, a: f64, diag: &[f64], y: &[f64], vals: &mut [f64]) {
    let nf = dae.f.val.len();
    for (v, fv) in vals[..nf].iter_mut().zip(&dae.f.val) {
        *v = a * fv;
    }
    vals[nf..].copy_from_slice(diag);
    for &(i, s) in &dae.stenosis {
        vals[nf + i] += a * 2.0 * s * y[i].abs();
    }
}

/// Relative size of an increment, pressures and flows scaled separately (mixed units).
pub fn scaled_increment(dae: &Dae, dy: &[f64], y: &[f64]) -> f64 {
    increment_over(dae, dy, magnitudes(dae, y))
}

fn amax(s: &[f64]) -> f64 {
    s.iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// Largest |pressure| and |flow| of a state.
fn magnitudes(dae: &Dae, y: &[f64]) -> [f64; 2] {
    let nn = dae.n_nodes;
    [amax(&y[..nn]), amax(&y[nn..])]
}

/// Largest increment of the pressures and of the flows, each relative to its `scale`.
fn increment_over(dae: &Dae, dy: &[f64], scale: [f64; 2]) -> f64 {
    let nn = dae.n_nodes;
    (amax(&dy[..nn]) / scale[0].max(1e-300)).max(amax(&dy[nn..]) / scale[1].max(1e-300))
}

impl<'a> GenAlpha<'a> {
    pub fn new(
        dae: &'a Dae,
        regime: Regime,
        dt: f64,
        rho_inf: f64,
        control: NewtonControl,
    ) -> Result<Self> {
        if !(0.0..=1.0).contains(&rho_inf) {
            return Err(Error::model(
                "simulation",
                format!("rho_infty must be in [0, 1], got {rho_inf}"),
            ));
        }
        let am = 0.5 * (3.0 - rho_inf) / (1.0 + rho_inf);
        let af = 1.0 / (1.0 + rho_inf);
        let gamma = 0.5 + am - af;
        let stamps = jacobian_stamps(dae);
        let lu = SparseLu::analyse(dae.n, &stamps)?;
        let n = dae.n;
        Ok(GenAlpha {
            dae,
            e: dae.mass(regime),
            regime,
            dt,
            am,
            af,
            gamma,
            control,
            lu,
            kvals: vec![0.0; stamps.len()],
            factored: false,
            f: vec![0.0; n],
            r: vec![0.0; n],
            y_new: vec![0.0; n],
            yd_new: vec![0.0; n],
            y_af: vec![0.0; n],
            magnitude: [0.0; 2],
        })
    }

    fn factor(&mut self, time: f64) -> Result<()> {
        let c = self.af * self.gamma * self.dt;
        let diag: Vec<f64> = self.e.iter().map(|e| self.am * e).collect();
        jacobian_values(self.dae, c, &diag, &self.y_af, &mut self.kvals);
        self.lu
            .factor(&self.kvals)
            .map_err(|m| singular(time, &m))?;
        self.factored = true;
        Ok(())
    }

    /// α_f: the level at which the residual (and so the face flows for transport) is enforced.
    pub fn alpha_f(&self) -> f64 {
        self.af
    }

    /// Advance (y, ẏ) from `time` to `time + dt` in place.
    // index loops over several parallel vectors read more clearly than zipped iterators here
    #[allow(clippy::needless_range_loop)]
    pub fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        if self.dae.is_linear() {
            return self.step_linear(time, y, yd);
        }
        let (am, af, gamma, dt) = (self.am, self.af, self.gamma, self.dt);
        let n = self.dae.n;
        let pred = (gamma - 1.0) / gamma;
        for i in 0..n {
            self.yd_new[i] = yd[i] * pred;
            self.y_new[i] = y[i];
        }
        let t_af = time + af * dt;
        self.dae.forcing_into(t_af, self.regime, &mut self.f);
        let linear = self.dae.is_linear();
        let now = magnitudes(self.dae, y);
        self.magnitude = [self.magnitude[0].max(now[0]), self.magnitude[1].max(now[1])];
        let mut converged = false;
        for it in 0..self.control.max_iter {
            for i in 0..n {
                self.y_af[i] = y[i] + af * (self.y_new[i] - y[i]);
            }
            self.dae.static_residual(&self.y_af, &self.f, &mut self.r);
            for i in 0..n {
                self.r[i] -= self.e[i] * (yd[i] + am * (self.yd_new[i] - yd[i]));
            }
            if let Some(atol) = self.control.atol {
                if self.r.iter().fold(0.0f64, |m, x| m.max(x.abs())) < atol {
                    converged = true;
                    break;
                }
                if it + 1 == self.control.max_iter {
                    break;
                }
            }
            if !linear || !self.factored {
                self.factor(t_af)?;
            }
            if !self.lu.solve_in_place(&mut self.r) {
                return Err(singular(t_af, "non-finite solution"));
            }
            for i in 0..n {
                self.yd_new[i] += self.r[i];
                self.y_new[i] += gamma * dt * self.r[i];
            }
            if self.control.atol.is_none() {
                if linear {
                    converged = true;
                    break;
                }
                self.r.iter_mut().for_each(|x| *x *= gamma * dt);
                let now = magnitudes(self.dae, &self.y_new);
                let scale = [self.magnitude[0].max(now[0]), self.magnitude[1].max(now[1])];
                if it > 0 && increment_over(self.dae, &self.r, scale) < 1e-12 {
                    converged = true;
                    break;
                }
            }
        }
        if !converged {
            return Err(Error::solver(
                t_af,
                format!(
                    "Newton did not converge in {} iterations",
                    self.control.max_iter
                ),
            ));
        }
        y.copy_from_slice(&self.y_new);
        yd.copy_from_slice(&self.yd_new);
        Ok(())
    }
}

impl GenAlpha<'_> {
    /// Linear circuits: the first Newton iterate is exact, so a step is one fused residual pass,
    /// one solve with the matrix factorised once, and one update pass. With svZeroDSolver's
    /// absolute tolerance the step is skipped when the predictor already satisfies it, exactly
    /// as svZeroDSolver does; its post-solve check always passes for a linear system.
    fn step_linear(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let (am, af, gamma, dt) = (self.am, self.af, self.gamma, self.dt);
        let pred = (gamma - 1.0) / gamma;
        let t_af = time + af * dt;
        self.dae.forcing_into(t_af, self.regime, &mut self.f);
        if !self.factored {
            self.y_af.copy_from_slice(y);
            self.factor(t_af)?;
        }
        // with y_new = y and ẏ_new = pred·ẏ: y_αf = y, ẏ_αm = ẏ (1 + αm (pred − 1))
        let c_am = 1.0 + am * (pred - 1.0);
        let f = &self.dae.f;
        let mut rmax = 0.0f64;
        for (i, r) in self.r.iter_mut().enumerate() {
            let mut v = self.f[i] - self.e[i] * yd[i] * c_am;
            for k in f.ptr[i]..f.ptr[i + 1] {
                v -= f.val[k] * y[f.col[k]];
            }
            rmax = rmax.max(v.abs());
            *r = v;
        }
        if let Some(atol) = self.control.atol {
            if rmax < atol {
                yd.iter_mut().for_each(|v| *v *= pred);
                return Ok(());
            }
        }
        if !self.lu.solve_in_place(&mut self.r) {
            return Err(singular(t_af, "non-finite solution"));
        }
        let gdt = gamma * dt;
        for ((yi, ydi), ri) in y.iter_mut().zip(yd.iter_mut()).zip(&self.r) {
            *yi += gdt * ri;
            *ydi = pred * *ydi + ri;
        }
        Ok(())
    }
}

pub fn singular(time: f64, detail: &str) -> Error {
    Error::solver(
        time,
        format!(
            "singular system ({detail}); check that every part of the network reaches a pressure, resistance or Windkessel boundary condition"
        ),
    )
}
