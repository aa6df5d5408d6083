//! The calibration residual of observed states (`oxyline_core::calibration`): the binding of
//! `oxyline.svzerod.calibrate`'s Gauss–Newton quantities.

use crate::errors::{ModelError, SolverError, to_py};
use numpy::{IntoPyArray, PyArray1, PyReadonlyArray1};
use oxyline_core::Error;
use oxyline_core::calibration::{Block, FitSettings, Observations, fit, normal_equations};
use pyo3::prelude::*;

/// A calibration problem: the blocks (RCL vessels and junction branches) and the observations
/// `y`, `dy` (variable-major, `n_obs` samples per variable), kept for the optimiser's repeated
/// evaluations.
#[pyclass(module = "oxyline._core", frozen)]
pub struct CalibrationProblem {
    blocks: Vec<Block>,
    y: Vec<f64>,
    dy: Vec<f64>,
    n_obs: usize,
}

type Vessel = (String, [usize; 4], [usize; 4]);
type Branch = (String, [usize; 3], [usize; 3]);

#[oxyline_py_guard::guard]
#[pymethods]
impl CalibrationProblem {
    /// `vessels`: (name, (P_in, Q_in, P_out, Q_out) variable indices, (R, C, L, S) slots);
    /// `branches`: (name, (P_in, P_out, Q_out) variable indices, (R, L, S) slots). The blocks
    /// of JᵀJ come in this order: vessels, then branches.
    #[new]
    fn new(
        vessels: Vec<Vessel>,
        branches: Vec<Branch>,
        y: PyReadonlyArray1<'_, f64>,
        dy: PyReadonlyArray1<'_, f64>,
        n_obs: usize,
    ) -> PyResult<Self> {
        let blocks: Vec<Block> = (vessels.into_iter())
            .map(|(name, vars, params)| Block::Vessel { name, vars, params })
            .chain(
                (branches.into_iter()).map(|(name, vars, params)| Block::Branch {
                    name,
                    vars,
                    params,
                }),
            )
            .collect();
        let (y, dy) = (y.as_slice()?.to_vec(), dy.as_slice()?.to_vec());
        if n_obs == 0 {
            return Err(ModelError::new_err("calibration: no observations"));
        }
        let n_params = blocks
            .iter()
            .flat_map(|b| b.params())
            .max()
            .map_or(0, |p| p + 1);
        let obs = Observations {
            y: &y,
            dy: &dy,
            n_obs,
        };
        oxyline_core::calibration::check(&blocks, &obs, n_params).map_err(to_py)?;
        Ok(CalibrationProblem {
            blocks,
            y,
            dy,
            n_obs,
        })
    }

    /// (cost Σr², gradient Jᵀr by slot, the blocks of JᵀJ concatenated row-major) at `alpha`.
    #[allow(clippy::type_complexity)]
    fn normal_equations<'py>(
        &self,
        py: Python<'py>,
        alpha: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<(f64, Bound<'py, PyArray1<f64>>, Bound<'py, PyArray1<f64>>)> {
        let obs = Observations {
            y: &self.y,
            dy: &self.dy,
            n_obs: self.n_obs,
        };
        let ne = normal_equations(&self.blocks, &obs, alpha.as_slice()?).map_err(to_py)?;
        Ok((
            ne.cost,
            ne.gradient.into_pyarray(py),
            ne.gram.into_pyarray(py),
        ))
    }

    /// svZeroDSolver's Levenberg–Marquardt fit from `start`, fitting the slots of `active`
    /// (`oxyline_core::calibration::fit`): (values, iterations, converged). A singular step
    /// is a `SolverError` naming its block.
    #[allow(clippy::too_many_arguments)]
    fn fit<'py>(
        &self,
        py: Python<'py>,
        start: PyReadonlyArray1<'_, f64>,
        active: Vec<bool>,
        max_iterations: usize,
        initial_damping: f64,
        tolerance_gradient: f64,
        tolerance_increment: f64,
    ) -> PyResult<(Bound<'py, PyArray1<f64>>, usize, bool)> {
        let start = start.as_slice()?;
        if active.len() != start.len() {
            return Err(ModelError::new_err(format!(
                "calibration: {} fitted flags for {} values",
                active.len(),
                start.len()
            )));
        }
        let obs = Observations {
            y: &self.y,
            dy: &self.dy,
            n_obs: self.n_obs,
        };
        let settings = FitSettings {
            max_iterations,
            initial_damping,
            tolerance_gradient,
            tolerance_increment,
        };
        let out = fit(&self.blocks, &obs, start, &active, &settings).map_err(|e| match e {
            // the calibration's own wording, without the time stepping's "at t = 0"
            Error::Solver { message, .. } => SolverError::new_err(message),
            e => to_py(e),
        })?;
        Ok((out.alpha.into_pyarray(py), out.iterations, out.converged))
    }
}
