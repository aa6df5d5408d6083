//! The steady state of the mean boundary conditions, F y + c(y) = f̄, by the shared Newton
//! solver; and a once-per-run cache of it, because the run needs it for the start, the
//! stability linearisation of stenoses and the transport step.

use super::newton::{
    self, Magnitude, NewtonControl, NewtonProblem, jacobian_pattern, jacobian_values,
};
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;
use std::cell::OnceCell;

/// At most this many Newton iterations: the steady state starts from zero, far from the
/// solution when stenoses dominate.
const STEADY_MAX_ITER: usize = 50;

struct Steady<'d> {
    dae: &'d Dae,
    lu: SparseLu,
    vals: Vec<f64>,
    f: Vec<f64>,
    y: Vec<f64>,
    zero: Vec<f64>,
}

fn no_steady_state() -> Error {
    Error::model(
        "network",
        "has no steady state: some part is not connected through resistances to a pressure, resistance or Windkessel boundary condition",
    )
}

impl NewtonProblem for Steady<'_> {
    fn residual(&mut self, r: &mut [f64]) {
        self.dae.static_residual(&self.y, &self.f, r);
        // elements at t = 0 (a chamber's elastance has no mean)
        self.dae.element_residual(0.0, &self.y, r);
    }
    fn factor(&mut self, _: usize) -> Result<()> {
        // (the first iterate is y = 0, where the stenosis term's slope 2S|Q| vanishes: the first
        // step is that of the circuit without stenoses)
        jacobian_values(self.dae, 1.0, &self.zero, &self.y, 0.0, &mut self.vals);
        let name = |i: usize| self.dae.names.unknown(i);
        self.lu
            .factor_naming(&self.vals, &name)
            .map_err(|_| no_steady_state())
    }
    fn solve(&mut self, r: &mut [f64]) -> Result<()> {
        if self.lu.solve_in_place(r) {
            Ok(())
        } else {
            Err(no_steady_state())
        }
    }
    fn update(&mut self, dx: &mut [f64]) {
        for (yi, d) in self.y.iter_mut().zip(dx.iter()) {
            *yi += d;
        }
    }
    fn state(&self) -> &[f64] {
        &self.y
    }
    fn unknowns(&self) -> Option<&[usize]> {
        None
    }
    fn is_linear(&self) -> bool {
        self.dae.is_linear()
    }
}

/// Exact steady state: F y + c(y) = f̄ (Newton when stenoses are present).
pub fn steady_state(dae: &Dae) -> Result<Vec<f64>> {
    let n = dae.n;
    // the pattern is needed only to analyse it: dropped before the values and the Newton's
    // vectors are allocated (8 bytes a stamp, ~70 per segment, was held through the solve)
    let (lu, n_stamps) = {
        let stamps = jacobian_pattern(dae);
        (SparseLu::analyse(n, &stamps)?, stamps.len())
    };
    let mut p = Steady {
        dae,
        lu,
        vals: vec![0.0; n_stamps],
        f: vec![0.0; n],
        y: vec![0.0; n],
        zero: vec![0.0; n],
    };
    dae.forcing_into(0.0, Regime::Steady, &mut p.f);
    let control = NewtonControl {
        atol: None,
        max_iter: STEADY_MAX_ITER,
    };
    let mut r = vec![0.0; n];
    newton::solve(&mut p, &mut r, &control, &mut Magnitude::new(dae), 0.0)?;
    Ok(p.y)
}

/// The steady state of one circuit, solved on first use and then shared by every part of a
/// run that needs it (a failure is kept and returned again, not retried).
pub struct SteadyCache<'d> {
    dae: &'d Dae,
    value: OnceCell<Result<Vec<f64>>>,
}

impl<'d> SteadyCache<'d> {
    pub fn new(dae: &'d Dae) -> Self {
        SteadyCache {
            dae,
            value: OnceCell::new(),
        }
    }

    /// Forget the solved state once no pass will start from it again: a state-sized vector
    /// (~20 B per segment) that would otherwise stay resident through the whole run.
    pub fn release(&mut self) {
        self.value.take();
    }

    /// The steady state, solved on the first call.
    pub fn get(&self) -> Result<&[f64]> {
        match self.value.get_or_init(|| steady_state(self.dae)) {
            Ok(y) => Ok(y),
            Err(e) => Err(e.clone()),
        }
    }
}
