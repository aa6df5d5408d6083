//! The derivatives of any signals, flow and oxygen alike, by any parameters, flow and oxygen
//! alike: the one tangent and the one adjoint the bindings call (`oxyline.sensitivities`,
//! `oxyline.calibrate`). A flow signal (a vessel's pressure or flow, a heart valve's) is the
//! flow tangent's ([`super::sensitivities`]); an oxygen signal (a vessel's PO2, saturation,
//! concentration or wall uptake, the network's balance fluxes) the species tangent's
//! ([`super::species_sensitivities`]), by oxygen and flow parameters alike (a flow parameter
//! reaches the oxygen through the flow's own tangent). Oxygen parameters do not change the
//! flow: a flow signal's rows by them are 0.

use super::*;
use crate::output::VESSEL_VARIABLES;

/// The signals over the periodic cycle and their derivatives, flow and oxygen merged.
#[derive(Debug, Clone)]
pub struct SignalSensitivities {
    /// The parameters' SI values.
    pub values: Vec<f64>,
    /// Step end times of the cycle (n_steps).
    pub times: Vec<f64>,
    /// n_steps × n_signals.
    pub signals: Vec<f64>,
    /// n_params × n_steps × n_signals.
    pub derivs: Vec<f64>,
    /// The forward run's cycles to its periodic state (the flow's).
    pub cycles: usize,
    /// Cycles of the tangents alone (the flow's), or of the transport with its tangents:
    /// the larger.
    pub tangent_cycles: usize,
    /// The largest last relative change of the runs.
    pub periodic_change: f64,
}

/// The result of [`signal_adjoint_with`]: [`PeriodicAdjoint`]'s, with the transport's cycles.
#[derive(Debug, Clone)]
pub struct SignalAdjoint {
    /// The parameters' SI values.
    pub values: Vec<f64>,
    /// J_f over the periodic cycle.
    pub functionals: Vec<f64>,
    /// dJ_f/dθ_p, n_functionals × n_params.
    pub gradients: Vec<f64>,
    pub cycles: usize,
    /// The transport's cycles to its periodic state (0 without oxygen signals).
    pub transport_cycles: usize,
    /// Backward cycles per functional.
    pub adjoint_cycles: Vec<usize>,
    pub periodic_change: f64,
}

/// Whether the species transport gives `signal` (every name but the flow's four).
fn is_oxygen_signal((_, variable): &(String, String)) -> bool {
    !VESSEL_VARIABLES.contains(&variable.as_str())
}

/// Whether `path` names an oxygen parameter (`oxygen.…`).
fn is_oxygen_path(path: &str) -> bool {
    path.split('.').next() == Some("oxygen")
}

/// The positions of the oxygen signals, of the flow signals and of the flow parameters.
struct Split {
    oxygen: Vec<usize>,
    flow: Vec<usize>,
    flow_params: Vec<usize>,
}

impl Split {
    /// The split of `paths` and `signals`; None when neither names oxygen (the flow alone).
    fn of(paths: &[String], signals: &[(String, String)]) -> Option<Split> {
        let oxygen: Vec<usize> = (0..signals.len())
            .filter(|&k| is_oxygen_signal(&signals[k]))
            .collect();
        let flow_params: Vec<usize> = (0..paths.len())
            .filter(|&k| !is_oxygen_path(&paths[k]))
            .collect();
        if oxygen.is_empty() && flow_params.len() == paths.len() {
            return None;
        }
        let flow = (0..signals.len()).filter(|k| !oxygen.contains(k)).collect();
        Some(Split {
            oxygen,
            flow,
            flow_params,
        })
    }
}

/// The items of `all` at `at`.
fn pick<T: Clone>(all: &[T], at: &[usize]) -> Vec<T> {
    at.iter().map(|&k| all[k].clone()).collect()
}

/// d(signal)/d(parameter) over the periodic cycle of `spec`, flow and oxygen signals by flow
/// and oxygen parameters (see the module doc): the species tangent by every parameter when
/// there are oxygen signals (else by the oxygen parameters, for their values), the flow
/// tangent of the flow signals by the flow parameters.
pub fn signal_sensitivities(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    settings: TangentSettings,
) -> Result<SignalSensitivities> {
    let Some(split) = Split::of(paths, signals) else {
        let out = sensitivities(spec, paths, signals, settings)?;
        let c = out.cycle;
        return Ok(SignalSensitivities {
            values: out.values,
            times: c.times,
            signals: c.values,
            derivs: c.derivs,
            cycles: c.cycles,
            tangent_cycles: c.tangent_cycles,
            periodic_change: c.periodic_change,
        });
    };
    let rows: Vec<usize> = (0..paths.len())
        .filter(|k| !split.oxygen.is_empty() || !split.flow_params.contains(k))
        .collect();
    let species = species_sensitivities(
        spec,
        &pick(paths, &rows),
        &pick(signals, &split.oxygen),
        settings,
    )?;
    let (np, nt, nsig) = (paths.len(), species.times.len(), signals.len());
    let mut out = SignalSensitivities {
        values: vec![0.0; np],
        times: species.times.clone(),
        signals: vec![0.0; nt * nsig],
        derivs: vec![0.0; np * nt * nsig],
        cycles: species.cycles,
        tangent_cycles: species.transport_cycles,
        periodic_change: species.periodic_change,
    };
    let part = Part {
        values: &species.values,
        signals: &species.signals,
        derivs: &species.derivs,
    };
    out.place(&part, &rows, &split.oxygen);
    if !split.flow.is_empty() {
        // the flow tangent's values of the flow parameters replace the species'
        let flow = sensitivities(
            spec,
            &pick(paths, &split.flow_params),
            &pick(signals, &split.flow),
            settings,
        )?;
        let c = &flow.cycle;
        let part = Part {
            values: &flow.values,
            signals: &c.values,
            derivs: &c.derivs,
        };
        out.place(&part, &split.flow_params, &split.flow);
        out.tangent_cycles = out.tangent_cycles.max(c.tangent_cycles);
        out.periodic_change = out.periodic_change.max(c.periodic_change);
    }
    Ok(out)
}

/// One tangent's values, signals (n_steps × its signals) and derivatives (its parameters ×
/// n_steps × its signals).
struct Part<'a> {
    values: &'a [f64],
    signals: &'a [f64],
    derivs: &'a [f64],
}

impl SignalSensitivities {
    /// `part`'s parameters at the rows `rows` and its signals at the columns `cols`.
    fn place(&mut self, part: &Part<'_>, rows: &[usize], cols: &[usize]) {
        let (nt, nsig, nc) = (
            self.times.len(),
            self.signals.len() / self.times.len().max(1),
            cols.len(),
        );
        for (i, &p) in rows.iter().enumerate() {
            self.values[p] = part.values[i];
        }
        for k in 0..nt {
            for (j, &c) in cols.iter().enumerate() {
                self.signals[k * nsig + c] = part.signals[k * nc + j];
                for (i, &p) in rows.iter().enumerate() {
                    self.derivs[(p * nt + k) * nsig + c] = part.derivs[(i * nt + k) * nc + j];
                }
            }
        }
    }
}

/// The gradients of functionals J_f = Σ_k Σ_j w[(f n_steps + k) n_signals + j] · signal j
/// after step k of the periodic cycle, flow and oxygen signals by flow and oxygen parameters:
/// `weights_of(times, values)` gets the step end times and every signal (n_steps × n_signals)
/// of the one primal cycle. Without oxygen, the flow's adjoint ([`adjoint_with`]). With it,
/// the species transport's adjoint of the oxygen signals' weights (a flow parameter's flow
/// tangent forward, the species adjoint backward); the flow signals (an SvO2's outflow) are
/// read from the flow's periodic cycle with their tangents by the flow parameters, for the
/// weights and for their own terms Σ w dQ/dθ of the flow parameters' gradients. At least one
/// oxygen signal is needed beside oxygen parameters (they do not change the flow: the
/// forward tangent gives those zero rows).
pub fn signal_adjoint_with<W>(
    spec: &NetworkSpec,
    paths: &[String],
    signals: &[(String, String)],
    weights_of: W,
    settings: TangentSettings,
) -> Result<SignalAdjoint>
where
    W: FnOnce(&[f64], &[f64]) -> Result<Vec<f64>>,
{
    let Some(split) = Split::of(paths, signals) else {
        let (values, out) = adjoint_with(spec, paths, signals, weights_of, settings)?;
        return Ok(SignalAdjoint {
            values,
            functionals: out.values,
            gradients: out.gradients,
            cycles: out.cycles,
            transport_cycles: 0,
            adjoint_cycles: out.adjoint_cycles,
            periodic_change: out.periodic_change,
        });
    };
    if split.oxygen.is_empty() {
        let names: Vec<String> = signals.iter().map(|(v, n)| format!("{v}.{n}")).collect();
        return Err(Error::model(
            "adjoint",
            format!(
                "oxygen parameters do not change the flow outputs {} (use the forward \
                 tangents for their zero rows)",
                names.join(", ")
            ),
        ));
    }
    let flow = if split.flow.is_empty() {
        None
    } else {
        let flow_paths = pick(paths, &split.flow_params);
        Some(sensitivities(
            spec,
            &flow_paths,
            &pick(signals, &split.flow),
            settings,
        )?)
    };
    let nsig = signals.len();
    let mut flow_weights: Vec<f64> = Vec::new();
    let oxygen_weights = |times: &[f64], o2: &[f64]| -> Result<Vec<f64>> {
        let nt = times.len();
        let mut full = vec![0.0; nt * nsig];
        scatter(&mut full, o2, &split.oxygen, nsig);
        if let Some(f) = &flow {
            scatter(&mut full, &f.cycle.values, &split.flow, nsig);
        }
        let w = weights_of(times, &full)?;
        flow_weights = gather(&w, &split.flow, nsig);
        Ok(gather(&w, &split.oxygen, nsig))
    };
    let (values, out) = species_adjoint_with(
        spec,
        paths,
        &pick(signals, &split.oxygen),
        oxygen_weights,
        settings,
    )?;
    let (mut functionals, mut gradients) = (out.functionals, out.gradients);
    if let Some(f) = &flow {
        add_flow_terms(&mut functionals, &mut gradients, &flow_weights, f, &split);
    }
    Ok(SignalAdjoint {
        values,
        functionals,
        gradients,
        cycles: out.cycles,
        transport_cycles: out.transport_cycles,
        adjoint_cycles: out.adjoint_cycles,
        periodic_change: out.periodic_change,
    })
}

/// Rows of `part` (… × its columns) into the columns `cols` of `full` (… × `nsig`).
fn scatter(full: &mut [f64], part: &[f64], cols: &[usize], nsig: usize) {
    if cols.is_empty() {
        return;
    }
    for (row, from) in full.chunks_mut(nsig).zip(part.chunks(cols.len())) {
        for (&c, &x) in cols.iter().zip(from) {
            row[c] = x;
        }
    }
}

/// The columns `cols` of `full` (… × `nsig`), as rows of their own.
fn gather(full: &[f64], cols: &[usize], nsig: usize) -> Vec<f64> {
    full.chunks(nsig)
        .flat_map(|row| cols.iter().map(move |&c| row[c]))
        .collect()
}

/// The flow signals' terms of the functionals, Σ_kj w[f, k, j] Q_j(k), and of the flow
/// parameters' gradients (n_functionals × n_params), Σ_kj w[f, k, j] dQ_j(k)/dθ_p:
/// `weights` n_functionals × n_steps × flow signals, the flow tangent's signals n_steps ×
/// flow signals and derivatives flow parameters × n_steps × flow signals.
fn add_flow_terms(
    functionals: &mut [f64],
    gradients: &mut [f64],
    weights: &[f64],
    flow: &Sensitivities,
    split: &Split,
) {
    let (values, derivs) = (&flow.cycle.values, &flow.cycle.derivs);
    let per = flow.cycle.times.len() * split.flow.len();
    if per == 0 {
        return;
    }
    let np = gradients.len() / functionals.len().max(1);
    for (f, w) in weights.chunks(per).enumerate() {
        functionals[f] += w.iter().zip(values).map(|(a, b)| a * b).sum::<f64>();
        for (i, &p) in split.flow_params.iter().enumerate() {
            let d = &derivs[i * per..(i + 1) * per];
            gradients[f * np + p] += w.iter().zip(d).map(|(a, b)| a * b).sum::<f64>();
        }
    }
}

#[cfg(test)]
#[path = "outputs_tests.rs"]
mod tests;
