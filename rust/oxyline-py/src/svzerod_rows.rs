//! Binding of svZeroDSolver's output rows of a run extended by its cycle-to-cycle rule
//! (`oxyline_core::run::svzerod_output_rows`) and of its cycle count with RCR outlets.

use numpy::PyArray1;
use pyo3::prelude::*;

/// (global step indices, output times in units of Δt) svZeroDSolver writes.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn svzerod_output_rows<'py>(
    py: Python<'py>,
    cycles: usize,
    steps: usize,
    extra: usize,
    interval: usize,
    all_cycles: bool,
) -> (Bound<'py, PyArray1<isize>>, Bound<'py, PyArray1<f64>>) {
    let (rows, times) =
        oxyline_core::run::svzerod_output_rows(cycles, steps, extra, interval, all_cycles);
    let rows: Vec<isize> = rows.into_iter().map(|r| r as isize).collect();
    (PyArray1::from_vec(py, rows), PyArray1::from_vec(py, times))
}

/// (cycles before rounding up, largest time constant τ [s]) of svZeroDSolver's
/// `use_cycle_to_cycle_error` with RCR `outlets` (capacitance, distal resistance).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn svzerod_rcr_cycles(outlets: Vec<(f64, f64)>, period: f64, percent: f64) -> (f64, f64) {
    oxyline_core::run::svzerod_rcr_cycles(&outlets, period, percent)
}
