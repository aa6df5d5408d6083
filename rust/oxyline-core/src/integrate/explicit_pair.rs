//! Dormand–Prince 5(4): an explicit embedded Runge–Kutta pair with a continuous extension, for
//! error-controlled runs of non-stiff circuits (docs/physics.md §10.4).
//!
//! * **Tableau.** Seven stages, the last evaluated at the new state (first same as last: six
//!   right-hand sides per accepted step); the fifth-order solution is propagated (local
//!   extrapolation), the difference to the embedded fourth-order one is the local error
//!   estimate (Dormand & Prince 1980; Hairer, Nørsett & Wanner, *Solving ODEs I*, §II.5).
//! * **Stages on the DAE.** Every stage evaluates the rate of the differential unknowns with the
//!   algebraic ones eliminated at that stage's time, by the same evaluator RK4 uses (`Rk4`:
//!   forcing, index reduction, sparse elimination); a coupled state (species amounts) is
//!   advanced in the same stages from each stage's consistent flow state, as RK4's monolithic
//!   step does.
//! * **Dense output.** Shampine's fourth-order continuous extension (the `dopri5` dense output
//!   of Hairer & Wanner): exact at both ends, from the step's seven stage rates, no extra
//!   right-hand side. Algebraic unknowns are not interpolated: they are solved at the output
//!   time from the interpolated differential state.
//! * **Stability.** R(z) = Σ_{m≤5} z^m/m! + z⁶/600; [`dp5_step_limit`] is the largest stable
//!   step along an eigenvalue's ray (3.31/|λ| on the negative real axis, 2.79 for RK4).
//!
//! Written here rather than taken from a crate: diffsol's explicit pair (Tsit45) integrates
//! an ODE whose right-hand side it owns, with one scalar rtol and an atol vector; here the
//! stages must run the circuit's algebraic elimination and the coupled species in the same
//! stages, and the error is judged per vessel against running amplitudes (`run::explicit`).

use super::rk4::{Coupled, Rk4};
use crate::circuit::Dae;
use crate::error::{Error, Result};
use nalgebra::Complex;

/// Stage times c₂…c₇.
const C: [f64; 6] = [1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0];

/// The coefficients a_{s,j} of stages 2…7 (row s − 2, j < s − 1); row 7 is the fifth-order
/// solution's weights b (b₇ = 0).
const A: [&[f64]; 6] = [
    &[1.0 / 5.0],
    &[3.0 / 40.0, 9.0 / 40.0],
    &[44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0],
    &[
        19372.0 / 6561.0,
        -25360.0 / 2187.0,
        64448.0 / 6561.0,
        -212.0 / 729.0,
    ],
    &[
        9017.0 / 3168.0,
        -355.0 / 33.0,
        46732.0 / 5247.0,
        49.0 / 176.0,
        -5103.0 / 18656.0,
    ],
    &[
        35.0 / 384.0,
        0.0,
        500.0 / 1113.0,
        125.0 / 192.0,
        -2187.0 / 6784.0,
        11.0 / 84.0,
    ],
];

/// b − b̂: the fifth-order weights minus the embedded fourth-order ones (the local error).
const E: [f64; 7] = [
    71.0 / 57600.0,
    0.0,
    -71.0 / 16695.0,
    71.0 / 1920.0,
    -17253.0 / 339200.0,
    22.0 / 525.0,
    -1.0 / 40.0,
];

/// The continuous extension's fifth coefficient weights d (Shampine; Hairer's `dopri5`).
const D: [f64; 7] = [
    -12715105075.0 / 11282082432.0,
    0.0,
    87487479700.0 / 32700410799.0,
    -10690763975.0 / 1880347072.0,
    701980252875.0 / 199316789632.0,
    -1453857185.0 / 822651844.0,
    69997945.0 / 29380423.0,
];

/// |C| of the estimate C z⁵ + O(z⁶) on ẏ = λy, z = λh (exactly 97/120000 from the tableau).
pub const ESTIMATE_CONSTANT: f64 = 97.0 / 120000.0;

/// The method's name as a run reports it.
pub const NAME: &str = "dopri5";

/// |R(z)| of the fifth-order solution.
pub fn dp5_amplification(z: Complex<f64>) -> f64 {
    let one = Complex::new(1.0, 0.0);
    let tail = one / 120.0 + z / 600.0;
    (one + z * (one + z * (one / 2.0 + z * (one / 6.0 + z * (one / 24.0 + z * tail))))).norm()
}

/// The largest h with |R(λh')| ≤ 1 for every h' ≤ h (a march from the origin in steps of
/// 1/400 of 4/|λ|, then bisection): the region is not star-shaped near the imaginary axis,
/// where it leaves the axis at |λh| ≈ 1.
pub fn dp5_step_limit(lambda: Complex<f64>) -> f64 {
    let m = lambda.norm();
    if m == 0.0 {
        return f64::INFINITY;
    }
    let stable = |h: f64| dp5_amplification(lambda * h) <= 1.0 + 1e-12;
    let dh = 4.0 / (400.0 * m);
    let mut lo = 0.0;
    while lo < 4.0 / m && stable(lo + dh) {
        lo += dh;
    }
    let mut hi = lo + dh;
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if stable(mid) { lo = mid } else { hi = mid }
    }
    lo
}

/// Whether the explicit pair can step this circuit. Valves are stepped with their events
/// located (`run::events`), except a valve behind an inductor through a capacitance-free node
/// (a chamber's outlet: RK4's stiff branch, whose closed R_max/L rate no explicit step
/// resolves and whose quasi-steady mode the pair's fixed stages do not switch): named in the
/// refusal.
pub fn check_supported(dae: &Dae) -> Result<()> {
    if !dae.elements.iter().any(|el| !el.switches().is_empty()) {
        return Ok(());
    }
    let rk = Rk4::new(dae, crate::circuit::Regime::Transient, 1.0)?;
    match rk.stiff_valve() {
        Some(k) => Err(Error::model(
            dae.elements[k].name(),
            format!(
                "method '{NAME}' does not step a valve behind an inductance through a node \
                 without capacitance: the closed valve relaxes its branch at R_max/L, an \
                 explicit step of at most 3.3·L/R_max (a stiff branch, not an index-2 \
                 constraint: RK4 takes it quasi-steady, which the pair's stages cannot switch \
                 to); use 'generalized-alpha' or 'auto'"
            ),
        )),
        None => Ok(()),
    }
}

/// Stage storage of one state (flow or coupled): the stage rates, the stage state, the start.
#[derive(Debug, Default)]
struct Stages {
    k: [Vec<f64>; 7],
    stage: Vec<f64>,
    start: Vec<f64>,
    /// The local error estimate of the step just taken.
    err: Vec<f64>,
}

impl Stages {
    fn sized(&mut self, n: usize) {
        if self.stage.len() != n {
            for k in &mut self.k {
                *k = vec![0.0; n];
            }
            self.stage = vec![0.0; n];
            self.start = vec![0.0; n];
            self.err = vec![0.0; n];
        }
    }

    /// stage = start + h Σ_j a_j k_j over `rows` (every entry when None).
    fn combine(&mut self, a: &[f64], h: f64, rows: Option<&[usize]>) {
        let one = |i: usize, stage: &mut [f64]| {
            let sum = a.iter().enumerate().fold(0.0, |acc, (j, &w)| {
                if w == 0.0 {
                    acc
                } else {
                    acc + w * self.k[j][i]
                }
            });
            stage[i] = self.start[i] + h * sum;
        };
        match rows {
            Some(rows) => rows.iter().for_each(|&i| one(i, &mut self.stage)),
            None => (0..self.stage.len()).for_each(|i| one(i, &mut self.stage)),
        }
    }

    /// err = h Σ e_j k_j over `rows`.
    fn estimate(&mut self, h: f64, rows: Option<&[usize]>) {
        let one = |i: usize| h * E.iter().zip(&self.k).map(|(e, k)| e * k[i]).sum::<f64>();
        match rows {
            Some(rows) => rows.iter().for_each(|&i| self.err[i] = one(i)),
            None => (0..self.err.len()).for_each(|i| self.err[i] = one(i)),
        }
    }

    /// The continuous extension of entry `i` at θ of the step of `h` that ended in `end`.
    fn dense(&self, i: usize, theta: f64, h: f64, end: f64) -> f64 {
        let y0 = self.start[i];
        let r2 = end - y0;
        let r3 = h * self.k[0][i] - r2;
        let r4 = r2 - h * self.k[6][i] - r3;
        let r5 = h * D.iter().zip(&self.k).map(|(d, k)| d * k[i]).sum::<f64>();
        let s1 = 1.0 - theta;
        y0 + theta * (r2 + s1 * (r3 + theta * (r4 + s1 * r5)))
    }
}

/// Dormand–Prince 5(4) on the circuit DAE, with an optional coupled state.
pub struct Dopri5<'a> {
    /// The rate evaluator (forcing, elimination) shared with RK4.
    pub rk: Rk4<'a>,
    y: Stages,
    z: Stages,
    /// The first stage's rate is that of the current state (first same as last).
    fsal: bool,
    /// The differential unknowns (the evaluator's; fixed: a valve's branch that RK4 would
    /// switch to algebraic is refused, see [`check_supported`]).
    diff: Vec<usize>,
}

impl<'a> Dopri5<'a> {
    pub fn new(rk: Rk4<'a>) -> Self {
        Dopri5 {
            diff: rk.diff.clone(),
            rk,
            y: Stages::default(),
            z: Stages::default(),
            fsal: false,
        }
    }

    /// The local error estimate of the differential unknowns (zero elsewhere) and of the
    /// coupled state, of the step just taken.
    pub fn errors(&self) -> (&[f64], &[f64]) {
        (&self.y.err, &self.z.err)
    }

    /// The state's rate ẏ at the start of the step just taken (exact, the first stage's).
    pub fn start_rate(&self) -> &[f64] {
        &self.y.k[0]
    }

    /// The rate at the end of the step just taken (the last stage's).
    pub fn end_rate(&self) -> &[f64] {
        &self.y.k[6]
    }

    /// One step of `h` from `t`: `y` (and the coupled `z`) advanced by the fifth-order
    /// solution, the local error estimates kept ([`Dopri5::errors`]). The last stage
    /// leaves the algebraic unknowns of `y` consistent at t + h.
    pub fn step<Cp: Coupled + ?Sized>(
        &mut self,
        t: f64,
        h: f64,
        y: &mut [f64],
        z: &mut [f64],
        coupled: &mut Cp,
    ) -> Result<()> {
        let (n, nz) = (y.len(), z.len());
        self.y.sized(n);
        self.z.sized(nz);
        self.y.start.copy_from_slice(y);
        self.z.start.copy_from_slice(z);
        if !self.fsal {
            self.y.stage.copy_from_slice(y);
            self.z.stage.copy_from_slice(z);
            self.rate(0, t, nz > 0, coupled)?;
            y.copy_from_slice(&self.y.stage);
            self.y.start.copy_from_slice(y);
            self.fsal = true;
        }
        let diff = std::mem::take(&mut self.diff);
        let done = self.stages(t, h, &diff, nz > 0, coupled);
        self.diff = diff;
        if let Err(e) = done {
            self.fsal = false;
            return Err(e);
        }
        y.copy_from_slice(&self.y.stage);
        z.copy_from_slice(&self.z.stage);
        Ok(())
    }

    /// Stages 2…7 (the seventh at the new state), and the error estimates.
    fn stages<Cp: Coupled + ?Sized>(
        &mut self,
        t: f64,
        h: f64,
        diff: &[usize],
        coupled_on: bool,
        coupled: &mut Cp,
    ) -> Result<()> {
        // the algebraic unknowns of each stage start from the step's start (warm start)
        self.y.stage.copy_from_slice(&self.y.start);
        for (s, (a, c)) in A.iter().zip(C).enumerate() {
            self.y.combine(a, h, Some(diff));
            if coupled_on {
                self.z.combine(a, h, None);
            }
            self.rate(s + 1, t + c * h, coupled_on, coupled)?;
        }
        self.y.estimate(h, Some(diff));
        if coupled_on {
            self.z.estimate(h, None);
        }
        Ok(())
    }

    /// The rates of stage `s` at time `ts` from the stage states (the flow's algebraic
    /// unknowns made consistent first).
    fn rate<Cp: Coupled + ?Sized>(
        &mut self,
        s: usize,
        ts: f64,
        coupled_on: bool,
        coupled: &mut Cp,
    ) -> Result<()> {
        self.rk.rate_into(ts, &mut self.y.stage, &mut self.y.k[s])?;
        if coupled_on {
            coupled.derivative(ts, &self.y.stage, &self.z.stage, &mut self.z.k[s])?;
        }
        Ok(())
    }

    /// Back to the start of a rejected step (the first stage's rate still holds).
    pub fn reject(&mut self, y: &mut [f64], z: &mut [f64]) {
        y.copy_from_slice(&self.y.start);
        z.copy_from_slice(&self.z.start);
    }

    /// An accepted step: its last stage's rate is the next step's first.
    pub fn accept(&mut self) {
        self.y.k.swap(0, 6);
        self.z.k.swap(0, 6);
    }

    /// The state was set from outside (a new start): the first stage is evaluated again.
    pub fn reset(&mut self) {
        self.fsal = false;
    }

    /// The dense output of differential unknown `i` at θ of the step of `h` that ended in
    /// `y` (before [`Dopri5::accept`]).
    pub fn dense_flow(&self, i: usize, theta: f64, h: f64, y: &[f64]) -> f64 {
        self.y.dense(i, theta, h, y[i])
    }

    /// The dense output of the whole state at θ into `yi` (differential unknowns
    /// interpolated, algebraic ones solved at `time`) and `ydi` (its rate), and of the
    /// coupled state into `zi`.
    #[allow(clippy::too_many_arguments)]
    pub fn dense_state(
        &mut self,
        time: f64,
        theta: f64,
        h: f64,
        (y, z): (&[f64], &[f64]),
        yi: &mut Vec<f64>,
        ydi: &mut Vec<f64>,
        zi: &mut Vec<f64>,
    ) -> Result<()> {
        yi.clear();
        // algebraic unknowns start from the linear interpolation (the elimination's warm start)
        let lin = (0..y.len()).map(|i| self.y.start[i] + theta * (y[i] - self.y.start[i]));
        yi.extend(lin);
        for &i in &self.diff {
            yi[i] = self.y.dense(i, theta, h, y[i]);
        }
        ydi.clear();
        ydi.resize(y.len(), 0.0);
        // the elimination's running Newton scale is put back: output times never change
        // the solution
        let scale = self.rk.newton_scale().copied();
        let done = self.rk.rate_into(time, yi, ydi);
        if let (Some(s), Some(m)) = (scale, self.rk.newton_scale_mut()) {
            *m = s;
        }
        done?;
        zi.clear();
        zi.extend((0..z.len()).map(|i| self.z.dense(i, theta, h, z[i])));
        Ok(())
    }
}

impl super::Integrator for Dopri5<'_> {
    fn method(&self) -> &'static str {
        NAME
    }
    fn dt(&self) -> f64 {
        self.rk.dt
    }
    fn alpha_f(&self) -> f64 {
        1.0
    }
    fn set_dt(&mut self, dt: f64) {
        self.rk.dt = dt;
    }
    /// One step of the current dt, accepted whatever its estimate.
    fn step(&mut self, time: f64, y: &mut [f64], _yd: &mut [f64]) -> Result<()> {
        let h = self.rk.dt;
        Dopri5::step(self, time, h, y, &mut [], &mut super::rk4::Uncoupled)?;
        self.accept();
        Ok(())
    }
    fn rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let d = self.rk.derivative(time, y)?;
        yd.copy_from_slice(&d);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pair on a plain ODE (no algebraic unknowns): the flow-free coupled state of an
    /// empty circuit would need a Dae, so the tableau is checked on its own here.
    fn tableau_step(f: impl Fn(f64, f64) -> f64, t: f64, y: f64, h: f64) -> (f64, f64, [f64; 7]) {
        let mut k = [0.0; 7];
        k[0] = f(t, y);
        let mut y1 = y;
        for (s, (a, c)) in A.iter().zip(C).enumerate() {
            y1 = y + h * a.iter().zip(&k).map(|(w, kj)| w * kj).sum::<f64>();
            k[s + 1] = f(t + c * h, y1);
        }
        let err = h * E.iter().zip(&k).map(|(e, kj)| e * kj).sum::<f64>();
        (y1, err, k)
    }

    #[test]
    fn the_pair_is_fifth_order_and_its_estimate_fourth() {
        // y' = cos(t) y: y = exp(sin t); one step's error falls 2^6× per halving (order 5),
        // the estimate's 2^5× (order 4)
        let f = |t: f64, y: f64| t.cos() * y;
        let exact = |t: f64| t.sin().exp();
        let (t0, y0) = (0.3, exact(0.3));
        let errs: Vec<(f64, f64)> = [0.2, 0.1, 0.05]
            .iter()
            .map(|&h| {
                let (y1, est, _) = tableau_step(f, t0, y0, h);
                ((y1 - exact(t0 + h)).abs(), est.abs())
            })
            .collect();
        for w in errs.windows(2) {
            let (r_true, r_est) = (w[0].0 / w[1].0, w[0].1 / w[1].1);
            assert!((50.0..80.0).contains(&r_true), "local error ratio {r_true}");
            assert!((25.0..40.0).contains(&r_est), "estimate ratio {r_est}");
        }
    }

    #[test]
    fn the_estimate_constant_is_the_tableaus() {
        for z in [1e-2, -1e-2] {
            let (_, est, _) = tableau_step(|_, y| y, 0.0, 1.0, z);
            let c = est.abs() / z.abs().powi(5);
            assert!(
                (c - ESTIMATE_CONSTANT).abs() < 0.01 * ESTIMATE_CONSTANT,
                "{c}"
            );
        }
    }

    #[test]
    fn the_continuous_extension_is_fourth_order_between_steps() {
        let f = |t: f64, y: f64| t.cos() * y;
        let exact = |t: f64| t.sin().exp();
        let worst = |h: f64| {
            let (t0, y0) = (0.3, exact(0.3));
            let (y1, _, k) = tableau_step(f, t0, y0, h);
            let st = Stages {
                k: k.map(|v| vec![v]),
                stage: vec![y1],
                start: vec![y0],
                err: vec![0.0],
            };
            (1..10)
                .map(|j| {
                    let theta = j as f64 / 10.0;
                    (st.dense(0, theta, h, y1) - exact(t0 + theta * h)).abs()
                })
                .fold(0.0f64, f64::max)
        };
        // the interpolant's error is O(h⁵) locally: 2^5× per halving
        let r = worst(0.2) / worst(0.1);
        assert!((24.0..40.0).contains(&r), "dense output error ratio {r}");
        assert!(worst(0.1) < 1e-7, "{}", worst(0.1));
    }

    #[test]
    fn the_stability_limits_are_those_of_the_polynomial() {
        // negative real axis: 3.3066 (Hairer & Wanner's figure of the dopri5 region)
        let h = dp5_step_limit(Complex::new(-1.0, 0.0));
        assert!((h - 3.3066).abs() < 1e-3, "{h}");
        // the imaginary axis leaves the region at |z| ≈ 1 (RK4 holds it to 2.83)
        let h = dp5_step_limit(Complex::new(0.0, 1.0));
        assert!(h < 1.1, "{h}");
        // a rate of 100/s: 3.3e-2 s
        let h = dp5_step_limit(Complex::new(-100.0, 0.0));
        assert!((h - 3.3066e-2).abs() < 1e-5, "{h}");
    }
}
