//! Time integration of the circuit DAE E ẏ + F y + c(y) = f(t) (see `crate::circuit`).
//!
//! * [`rk4`] — classical explicit RK4 on the differential unknowns, the algebraic ones
//!   eliminated at every stage (with an index reduction for inductors whose flow a flow
//!   condition fixes), and the RK4 stage/combination kernels shared with species transport;
//! * [`genalpha`] — svZeroDSolver's implicit generalized-α;
//! * [`newton`] — the one Newton solver both use (and the steady state), with svZeroDSolver's
//!   absolute-residual rule or one scaled-increment rule;
//! * [`steady`] — the steady state of the mean boundary conditions;
//! * [`periodic`] — the periodic state at t = 0 of a linear circuit (the `periodic` start);
//! * [`stability`] — the largest stable RK4 step and the element that sets it;
//! * [`adaptive`] — error control for generalized-α: tolerances, local error estimate,
//!   step-size controller, dense output;
//! * [`index2`] — the index-2 algebraic unknowns and their values consistent with the
//!   constraint (reported in place of generalized-α's own);
//! * [`explicit_pair`] — Dormand–Prince 5(4) with its continuous extension, for error-controlled
//!   runs of non-stiff circuits.
//!
//! The run loop drives either through [`Integrator`].

pub mod adaptive;
mod algebraic;
pub mod explicit_pair;
pub mod genalpha;
pub mod index2;
mod leaves;
pub mod newton;
pub mod periodic;
pub mod rk4;
pub mod stability;
pub mod steady;
mod stiff;

use crate::error::Result;
pub use genalpha::GenAlpha;
pub use newton::NewtonControl;
pub use rk4::{CoupledStages, RK4_STAGE, Rk4, Rows, rk4_combine, rk4_stage};
pub use steady::{SteadyCache, steady_state};

/// What the run loop needs from a flow integrator.
///
/// The state is (y, ẏ): generalized-α carries ẏ from step to step (it is part of its state),
/// RK4 carries only y and derives ẏ on demand ([`Integrator::rate`]).
pub trait Integrator {
    /// The method's name as reported in a run's outcome.
    fn method(&self) -> &'static str;

    /// The step Δt (s).
    fn dt(&self) -> f64;

    /// The level within a step, as a fraction of Δt, at which the step's flow balance holds:
    /// α_f for generalized-α, 1 for RK4 (whose end-of-step state is consistent). An implicit
    /// transport step uses face flows interpolated at this level, so that species are carried by
    /// the same flows that conserve volume.
    fn alpha_f(&self) -> f64;

    /// Change the step Δt (error-controlled runs).
    fn set_dt(&mut self, dt: f64);

    /// Filter a local error estimate of the step just taken through the step's iteration
    /// matrix, v ← (α_m E + α_f γ Δt J)⁻¹ α_m E v (Shampine's filter: unchanged for modes
    /// slow against Δt, damped for stiff ones). Integrators without one leave v as it is.
    fn filter_error(&mut self, _v: &mut [f64]) {}

    /// Newton with a line search (true) or plain (false) from the next step: an
    /// error-controlled run's retry after a Newton failure. Integrators without Newton ignore it.
    fn set_damped_newton(&mut self, _on: bool) {}

    /// Factorise now what the first step from (`time`, `y`) would, if that factorisation
    /// depends on neither (a linear, time-constant circuit's one factorisation): a run
    /// calls it before its species and output state are allocated, so that the matrix's
    /// values, alive only while they are factorised, do not add to those. The first step
    /// then finds the factors made. Integrators without factors do nothing.
    fn factor_ahead(&mut self, _time: f64, _y: &[f64]) -> Result<()> {
        Ok(())
    }

    /// Advance (y, ẏ) from `time` to `time + dt` in place. RK4 leaves `yd` untouched.
    fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()>;

    /// [`Integrator::step`] from the state `start` = (y, ẏ), the step's end written into `y`
    /// and `yd` (whatever they held): for a caller that keeps the start anyway (an
    /// error-controlled run, to go back on a rejection) and so exchanges buffers instead of
    /// copying. By default the start is copied and stepped in place.
    fn step_from(
        &mut self,
        time: f64,
        start: (&[f64], &[f64]),
        y: &mut [f64],
        yd: &mut [f64],
    ) -> Result<()> {
        y.copy_from_slice(start.0);
        yd.copy_from_slice(start.1);
        self.step(time, y, yd)
    }

    /// The rate ẏ that goes with `y` at `time`, e.g. for outputs that need dV/dt. RK4 makes the
    /// algebraic unknowns of `y` consistent with the forcing and evaluates ẏ into `yd`;
    /// generalized-α's carried ẏ is already that rate, so (y, ẏ) are left as they are.
    fn rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()>;

    /// The rate ẏ of every unknown that goes with `y` at `time`, for an output that reports it
    /// (svZeroDSolver's `output_derivative`): RK4's [`Rk4::full_rate`] (algebraic rows
    /// included; `y` is made consistent); by default [`Integrator::rate`].
    fn full_rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        self.rate(time, y, yd)
    }

    /// Whether [`Integrator::rate`] leaves (y, ẏ) as they are (the carried ẏ is the rate):
    /// then an observer may read the run's own vectors instead of copies.
    fn rate_is_carried(&self) -> bool {
        false
    }

    /// What the integrator carries from step to step besides (y, ẏ) and that changes its
    /// results (e.g. the running scale of its Newton convergence test), for a checkpoint: a run
    /// resumed with [`Integrator::restore_carried`] continues bit for bit.
    fn carried(&self) -> Vec<f64> {
        Vec::new()
    }

    /// Restore [`Integrator::carried`] of a checkpoint.
    fn restore_carried(&mut self, carried: &[f64]) -> Result<()> {
        restore_peaks(carried, None)
    }
}

/// Restore the Newton scale `peaks` of a checkpoint into `magnitude` (None: the integrator
/// carries nothing, and the checkpoint must not either).
fn restore_peaks(carried: &[f64], magnitude: Option<&mut newton::Magnitude>) -> Result<()> {
    match (carried, magnitude) {
        ([], None) => Ok(()),
        (&[p, q], Some(m)) => {
            m.set_peaks([p, q]);
            Ok(())
        }
        _ => Err(crate::error::Error::model(
            "checkpoint",
            format!(
                "the integrator state has {} values, expected {}",
                carried.len(),
                if carried.is_empty() { 2 } else { 0 }
            ),
        )),
    }
}

impl Integrator for Rk4<'_> {
    fn method(&self) -> &'static str {
        "rk4"
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn alpha_f(&self) -> f64 {
        1.0
    }
    fn set_dt(&mut self, dt: f64) {
        self.dt = dt;
    }
    fn step(&mut self, time: f64, y: &mut [f64], _yd: &mut [f64]) -> Result<()> {
        Rk4::step(self, time, y)
    }
    fn rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let d = self.derivative(time, y)?;
        yd.copy_from_slice(&d);
        Ok(())
    }
    fn full_rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        Rk4::full_rate(self, time, y, yd)
    }
    fn carried(&self) -> Vec<f64> {
        self.newton_scale()
            .map_or_else(Vec::new, |m| m.peaks().to_vec())
    }
    fn restore_carried(&mut self, carried: &[f64]) -> Result<()> {
        restore_peaks(carried, self.newton_scale_mut())
    }
}

impl Integrator for GenAlpha<'_> {
    fn method(&self) -> &'static str {
        "generalized-alpha"
    }
    fn dt(&self) -> f64 {
        self.dt
    }
    fn alpha_f(&self) -> f64 {
        GenAlpha::alpha_f(self)
    }
    fn set_dt(&mut self, dt: f64) {
        GenAlpha::set_dt(self, dt);
    }
    fn filter_error(&mut self, v: &mut [f64]) {
        GenAlpha::filter_error(self, v);
    }
    fn set_damped_newton(&mut self, on: bool) {
        GenAlpha::set_damped(self, on);
    }
    fn factor_ahead(&mut self, time: f64, y: &[f64]) -> Result<()> {
        GenAlpha::factor_ahead(self, time, y)
    }
    fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        GenAlpha::step(self, time, y, yd)
    }
    fn step_from(
        &mut self,
        time: f64,
        start: (&[f64], &[f64]),
        y: &mut [f64],
        yd: &mut [f64],
    ) -> Result<()> {
        GenAlpha::step_from(self, time, start, y, yd)
    }
    fn rate(&mut self, _time: f64, _y: &mut [f64], _yd: &mut [f64]) -> Result<()> {
        Ok(())
    }
    fn rate_is_carried(&self) -> bool {
        true
    }
    fn carried(&self) -> Vec<f64> {
        self.newton_scale().peaks().to_vec()
    }
    fn restore_carried(&mut self, carried: &[f64]) -> Result<()> {
        restore_peaks(carried, Some(self.newton_scale_mut()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::circuit::{Circuit, Regime};
    use crate::waveform::Waveform;

    /// Node `p` of capacitance `c` drained through `r` (plus stenosis `s`) into a zero pressure,
    /// fed by the constant inflow `q`.
    fn rc(c: f64, r: f64, s: f64, q: f64) -> crate::circuit::Dae {
        let mut k = Circuit::default();
        let p = k.add_node("p", c, 0.0);
        let out = k.add_node("out", 0.0, 0.0);
        k.add_branch("drain", p, out, r, 0.0, s);
        k.sources.push((p, Waveform::constant(q)));
        k.fixed_pressures.push((out, Waveform::constant(0.0)));
        k.assemble().unwrap()
    }

    #[test]
    fn rk4_kernels_give_the_rk4_amplification_factor() {
        // on z' = λz one classical RK4 step multiplies z by the Taylor polynomial
        // R(λh) = Σ_{m≤4} (λh)^m/m! exactly (up to round-off)
        let (lambda, h) = (-3.0, 0.1);
        let mut z = [1.0, 2.0];
        let mut st = CoupledStages::new(2);
        rk4::rk4_ode(0.0, h, &mut z, &mut st, &mut |_, z, dz| {
            dz.iter_mut().zip(z).for_each(|(d, v)| *d = lambda * v);
            Ok(())
        })
        .unwrap();
        let x: f64 = lambda * h;
        let r = 1.0 + x + x * x / 2.0 + x.powi(3) / 6.0 + x.powi(4) / 24.0;
        assert!(
            (z[0] - r).abs() < 1e-15 && (z[1] - 2.0 * r).abs() < 2e-15,
            "{z:?} vs {r}"
        );
    }

    #[test]
    fn steady_state_solves_the_stenosis_quadratic() {
        // P = R q + S q² at the node; the flow is the inflow (the Newton solves the quadratic)
        let (r, s, q) = (1e8, 1e13, 3e-6);
        let y = steady_state(&rc(1e-9, r, s, q)).unwrap();
        let p = r * q + s * q * q;
        // round-off of the Newton iterates: a few ulps of the largest term
        assert!((y[0] - p).abs() < 1e-12 * p, "{} vs {p}", y[0]);
        assert!((y[2] - q).abs() < 1e-12 * q, "{} vs {q}", y[2]);
    }

    /// A sine inflow through a stenosis (R = 0, S = 1) into a capacitor (C = 1) that a wire
    /// ties to a zero pressure, so Q_out = Q_in exactly. Returns max |Q_out − Q_in| over the
    /// second period with generalized-α at step `dt`, the capacitor row in the branch form or
    /// in svZeroDSolver's chain-rule form (docs/svzerod.md, "C + stenosis").
    fn stenosis_into_tied_capacitor(chain_rule: bool, dt: f64) -> f64 {
        use crate::circuit::ChainRuleCapacitor;
        use crate::waveform::WaveformSpec;
        let mut k = Circuit::default();
        let (p_in, c, out) = (
            k.add_node("in", 0.0, 0.0),
            k.add_node("c", 1.0, 0.0),
            k.add_node("out", 0.0, 0.0),
        );
        let b = k.add_branch("stenosis", p_in, c, 0.0, 0.0, 1.0);
        k.add_branch("wire", c, out, 0.0, 0.0, 0.0);
        let sine = WaveformSpec::Fourier {
            period: 1.0,
            mean: 0.0,
            cos: vec![],
            sin: vec![1.0],
        };
        k.sources
            .push((p_in, Waveform::from_spec(&sine, "inflow").unwrap()));
        k.fixed_pressures.push((out, Waveform::constant(0.0)));
        if chain_rule {
            k.chain_rule.push(ChainRuleCapacitor {
                node: c,
                inlet: p_in,
                flow: b,
                capacitance: 1.0,
                resistance: 0.0,
                stenosis: 1.0,
            });
        }
        let dae = k.assemble().unwrap();
        let mut ga =
            GenAlpha::new(&dae, Regime::Transient, dt, 0.5, NewtonControl::default()).unwrap();
        let (mut y, mut yd) = (vec![0.0; dae.n], vec![0.0; dae.n]);
        let steps = (1.0 / dt).round() as usize;
        let mut worst = 0.0f64;
        for i in 0..2 * steps {
            ga.step(i as f64 * dt, &mut y, &mut yd).unwrap();
            if i >= steps {
                worst = worst.max((y[4] - y[3]).abs());
            }
        }
        worst
    }

    #[test]
    fn svzerod_stenosis_form_is_first_order_and_the_branch_form_exact() {
        // the branch form: Q_out = Q_in up to the Newton tolerance (1e-12 of the flow scale)
        assert!(stenosis_into_tied_capacitor(false, 1.0 / 200.0) < 1e-10);
        // the chain-rule form: a first-order error where Q changes sign, halving with Δt
        let (coarse, fine) = (
            stenosis_into_tied_capacitor(true, 1.0 / 200.0),
            stenosis_into_tied_capacitor(true, 1.0 / 400.0),
        );
        assert!(coarse > 1e-3, "{coarse}");
        let ratio = coarse / fine;
        assert!((1.8..2.2).contains(&ratio), "{coarse} / {fine} = {ratio}");
    }

    /// Discharge of an RC node from P0: P(t) = P0 e^{−t/RC}, by any integrator.
    fn discharge(ig: &mut dyn Integrator, steps: usize) -> f64 {
        let mut y = vec![1e4, 0.0, 0.0];
        let mut yd = vec![0.0; 3];
        ig.rate(0.0, &mut y, &mut yd).unwrap();
        if ig.method() == "generalized-alpha" {
            yd[0] = -y[0] / (1e8 * 1e-9); // generalized-α carries ẏ: start it consistent
        }
        for i in 0..steps {
            ig.step(i as f64 * ig.dt(), &mut y, &mut yd).unwrap();
        }
        y[0]
    }

    #[test]
    fn both_integrators_discharge_an_rc_node() {
        // τ = RC = 0.1 s, 100 steps of 1 ms to t = τ: RK4 error O(h⁴) ~ 1e-10 relative,
        // generalized-α (second order) O(h²) ~ 1e-5 relative
        let dae = rc(1e-9, 1e8, 0.0, 0.0);
        let exact = 1e4 * (-1.0f64).exp();
        let mut rk = Rk4::new(&dae, Regime::Transient, 1e-3).unwrap();
        assert_eq!(Integrator::alpha_f(&rk), 1.0);
        let p = discharge(&mut rk, 100);
        assert!((p - exact).abs() < 1e-9 * exact, "rk4 {p} vs {exact}");
        let control = NewtonControl::default();
        let mut ga = GenAlpha::new(&dae, Regime::Transient, 1e-3, 0.5, control).unwrap();
        let p = discharge(&mut ga, 100);
        assert!(
            (p - exact).abs() < 1e-4 * exact,
            "generalized-alpha {p} vs {exact}"
        );
    }

    #[test]
    fn a_factorisation_made_ahead_serves_the_steps() {
        // the RC discharge above with the linear circuit's one factorisation made before the
        // first step (as a fixed-step run does): the exact decay within generalized-α's
        // second-order error, 1e-4 relative at 100 steps of τ/100
        let dae = rc(1e-9, 1e8, 0.0, 0.0);
        let exact = 1e4 * (-1.0f64).exp();
        let control = NewtonControl::default();
        let mut ga = GenAlpha::new(&dae, Regime::Transient, 1e-3, 0.5, control).unwrap();
        Integrator::factor_ahead(&mut ga, 0.0, &[1e4, 0.0, 0.0]).unwrap();
        let p = discharge(&mut ga, 100);
        assert!((p - exact).abs() < 1e-4 * exact, "ahead {p} vs {exact}");
        // a step changed after it refactorises: τ/200 steps to the same time, same bound
        let mut ga = GenAlpha::new(&dae, Regime::Transient, 1e-3, 0.5, control).unwrap();
        Integrator::factor_ahead(&mut ga, 0.0, &[1e4, 0.0, 0.0]).unwrap();
        ga.set_dt(5e-4);
        let p = discharge(&mut ga, 200);
        assert!(
            (p - exact).abs() < 1e-4 * exact,
            "ahead, step changed {p} vs {exact}"
        );
    }
}
