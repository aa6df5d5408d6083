//! Calibration targets over one run's signals: every target's value(s) and Jacobian rows
//! from the tangent's cycle ([`target_values`]), or from one adjoint run
//! ([`target_adjoint`]), where each target's derivative is a fixed linear functional of its
//! signals' derivatives ([`targets::evaluate`]) and that functional applied to a unit basis
//! of the signals it reads gives the adjoint's output weights ([`output_weights`]). A
//! pulse-wave velocity's path length and its derivative by the parameters come from the
//! model ([`path_length`]).

use super::outputs::{SignalAdjoint, signal_adjoint_with};
use super::tangent::TangentSettings;
use super::targets::{self, CycleSignals, PathLength, TargetValue};
use crate::error::{Error, Result};
use crate::model::NetworkSpec;

/// One target as a run reads it.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetRead {
    /// the output's name ([`targets::Reduction::of`])
    pub output: String,
    /// the columns of the run's signals it reads, in the order the output reads them
    pub columns: Vec<usize>,
    /// a series' times (s from the cycle's start); None: the cycle's step times
    pub at: Option<Vec<f64>>,
}

/// A pulse-wave velocity's path length (m) and its derivative by each parameter path (1 for
/// the `vessels.<name>.length` of a vessel on the path, else 0); None for another output.
pub fn path_length(
    spec: &NetworkSpec,
    output: &str,
    paths: &[String],
) -> Result<Option<(f64, Vec<f64>)>> {
    if !output.starts_with("pwv.") {
        return Ok(None);
    }
    let path = targets::pulse_wave_path(spec, output)?;
    let on: Vec<String> = path
        .iter()
        .map(|(name, _)| format!("vessels.{name}.length"))
        .collect();
    let length = path.iter().map(|(_, l)| l).sum();
    let dlength = paths
        .iter()
        .map(|p| if on.contains(p) { 1.0 } else { 0.0 })
        .collect();
    Ok(Some((length, dlength)))
}

/// The run's columns `cols` of the n_steps × `n_signals` rows `x` (row-major).
fn pick_columns(x: &[f64], n_signals: usize, cols: &[usize]) -> Vec<f64> {
    x.chunks(n_signals)
        .flat_map(|row| cols.iter().map(move |&c| row[c]))
        .collect()
}

/// Checks a target's columns against the run's `n_signals`.
fn check_columns(t: &TargetRead, n_signals: usize) -> Result<()> {
    match t.columns.iter().find(|&&c| c >= n_signals) {
        Some(c) => Err(Error::model(
            format!("output '{}'", t.output),
            format!("signal column {c} of a run of {n_signals} signals"),
        )),
        None => Ok(()),
    }
}

/// Every target's value(s) and Jacobian (n_values × n_params) from the tangent's cycle
/// (`cycle`: all the run's signals by `paths`), a pulse-wave velocity with its path length
/// from `spec`.
pub fn target_values(
    spec: &NetworkSpec,
    paths: &[String],
    targets: &[TargetRead],
    cycle: &CycleSignals,
) -> Result<Vec<TargetValue>> {
    let nsig = cycle.n_signals;
    targets
        .iter()
        .map(|t| {
            check_columns(t, nsig)?;
            let values = pick_columns(cycle.values, nsig, &t.columns);
            let derivs = pick_columns(cycle.derivs, nsig, &t.columns);
            let own = CycleSignals {
                times: cycle.times,
                values: &values,
                derivs: &derivs,
                n_signals: t.columns.len(),
            };
            let length = path_length(spec, &t.output, paths)?;
            let path = length.as_ref().map(|(length, dlength)| PathLength {
                length: *length,
                dlength,
            });
            targets::evaluate(
                &t.output,
                &own,
                Some(t.at.as_deref().unwrap_or(cycle.times)),
                path,
            )
        })
        .collect()
}

/// The most unit-basis entries evaluated at once (a bound on the memory of the weights of a
/// target reading many signals: 32 MiB of them).
const BASIS_ENTRIES: usize = 1 << 22;

/// A target's value(s) and its weights on the run's signals, n_values × n_steps ×
/// `n_signals` (a signal the target reads twice adds up): its derivative by a unit change
/// of each sample of each signal it reads, the basis taken in chunks (each basis vector's
/// row is computed on its own, so the chunks change no number).
fn weights_of_target(
    t: &TargetRead,
    times: &[f64],
    signals: &[f64],
    n_signals: usize,
    length: Option<f64>,
    most_entries: usize,
) -> Result<(Vec<f64>, Vec<f64>)> {
    check_columns(t, n_signals)?;
    let (ns, k) = (times.len(), t.columns.len());
    let n_basis = ns * k;
    let values = pick_columns(signals, n_signals, &t.columns);
    let chunk = (most_entries / n_basis.max(1)).clamp(1, n_basis.max(1));
    let (mut out, mut full) = (Vec::new(), Vec::new());
    for start in (0..n_basis).step_by(chunk) {
        let rows = chunk.min(n_basis - start);
        let mut basis = vec![0.0; rows * n_basis];
        for r in 0..rows {
            basis[r * n_basis + start + r] = 1.0;
        }
        let zeros = vec![0.0; rows];
        let cycle = CycleSignals {
            times,
            values: &values,
            derivs: &basis,
            n_signals: k,
        };
        let path = length.map(|length| PathLength {
            length,
            dlength: &zeros,
        });
        let tv = targets::evaluate(
            &t.output,
            &cycle,
            Some(t.at.as_deref().unwrap_or(times)),
            path,
        )?;
        let nv = tv.values.len();
        if full.is_empty() {
            full = vec![0.0; nv * ns * n_signals];
        }
        for v in 0..nv {
            for r in 0..rows {
                let (step, i) = ((start + r) / k, (start + r) % k);
                full[(v * ns + step) * n_signals + t.columns[i]] += tv.jacobian[v * rows + r];
            }
        }
        out = tv.values;
    }
    Ok((out, full))
}

/// Every target's value(s) and the adjoint's output weights, flat n_rows × n_steps ×
/// `n_signals` (the targets' rows in order), from the primal cycle's step end `times` and
/// `signals` (n_steps × `n_signals`); `lengths`, each target's pulse-wave path length.
pub fn output_weights(
    targets: &[TargetRead],
    lengths: &[Option<f64>],
    times: &[f64],
    signals: &[f64],
    n_signals: usize,
) -> Result<(Vec<Vec<f64>>, Vec<f64>)> {
    let (mut values, mut weights) = (Vec::new(), Vec::new());
    for (t, length) in targets.iter().zip(lengths) {
        let (v, w) = weights_of_target(t, times, signals, n_signals, *length, BASIS_ENTRIES)?;
        values.push(v);
        weights.extend(w);
    }
    Ok((values, weights))
}

/// The targets' value(s) and gradients by one adjoint run of `spec` (one backward sweep per
/// target value, whatever the number of parameters).
#[derive(Debug, Clone)]
pub struct TargetAdjoint {
    /// each target's value(s)
    pub values: Vec<Vec<f64>>,
    /// d value / d parameter, every target's rows in order (n_rows × n_params)
    pub gradients: Vec<f64>,
    /// the adjoint run (the parameters' SI values, its cycles; its `gradients` without a
    /// pulse-wave velocity's path-length term)
    pub run: SignalAdjoint,
}

/// [`target_values`] by the adjoint: the targets' weights chosen from the one primal cycle
/// ([`output_weights`]), then a pulse-wave velocity L/τ's own path-length term (v/L) dL/dθ
/// added to its rows.
pub fn target_adjoint(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    targets: &[TargetRead],
    settings: TangentSettings,
) -> Result<TargetAdjoint> {
    let lengths = targets
        .iter()
        .map(|t| path_length(spec, &t.output, paths))
        .collect::<Result<Vec<_>>>()?;
    let only: Vec<Option<f64>> = lengths.iter().map(|l| l.as_ref().map(|l| l.0)).collect();
    let mut values = Vec::new();
    let run = signal_adjoint_with(
        spec,
        paths,
        signals,
        |times: &[f64], sig: &[f64]| {
            let (v, w) = output_weights(targets, &only, times, sig, signals.len())?;
            values = v;
            Ok(w)
        },
        settings,
    )?;
    let np = paths.len();
    let mut gradients = run.gradients.clone();
    let mut row = 0;
    for (v, length) in values.iter().zip(&lengths) {
        if let Some((l, dl)) = length {
            for (i, &x) in v.iter().enumerate() {
                let g = &mut gradients[(row + i) * np..(row + i + 1) * np];
                for (g, d) in g.iter_mut().zip(dl) {
                    *g += (x / l) * d;
                }
            }
        }
        row += v.len();
    }
    Ok(TargetAdjoint {
        values,
        gradients,
        run,
    })
}

#[cfg(test)]
#[path = "target_runs_tests.rs"]
mod tests;
