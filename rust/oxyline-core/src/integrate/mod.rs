//! Time integration of the circuit DAE E ẏ + F y + c(y) = f(t) (see `crate::circuit`).
//!
//! * [`rk4`] — classical explicit RK4 on the differential unknowns, the algebraic ones
//!   eliminated at every stage (with an index reduction for inductors whose flow a flow
//!   condition fixes), and the RK4 stage/combination kernels shared with species transport;
//! * [`genalpha`] — svZeroDSolver's implicit generalized-α;
//! * [`newton`] — the one Newton solver both use (and the steady state), with svZeroDSolver's
//!   absolute-residual rule or one scaled-increment rule;
//! * [`steady`] — the steady state of the mean boundary conditions;
//! * [`stability`] — the largest stable RK4 step and the element that sets it.
//!
//! The run loop drives either through [`Integrator`].

pub mod genalpha;
pub mod newton;
pub mod rk4;
pub mod stability;
pub mod steady;

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

    /// Advance (y, ẏ) from `time` to `time + dt` in place. RK4 leaves `yd` untouched.
    fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()>;

    /// The rate ẏ that goes with `y` at `time`, e.g. for outputs that need dV/dt. RK4 makes the
    /// algebraic unknowns of `y` consistent with the forcing and evaluates ẏ into `yd`;
    /// generalized-α's carried ẏ is already that rate, so (y, ẏ) are left as they are.
    fn rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()>;
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
    fn step(&mut self, time: f64, y: &mut [f64], _yd: &mut [f64]) -> Result<()> {
        Rk4::step(self, time, y)
    }
    fn rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let d = self.derivative(time, y)?;
        yd.copy_from_slice(&d);
        Ok(())
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
    fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        GenAlpha::step(self, time, y, yd)
    }
    fn rate(&mut self, _time: f64, _y: &mut [f64], _yd: &mut [f64]) -> Result<()> {
        Ok(())
    }
}
