//! The closed-loop heart's flow table's derivative by the heart model's parameters (docs/
//! calibration.md "A closed loop's oxygen"): the tangent-linear run of the heart model at the
//! heart run's step and ρ∞ to its periodic state (`sensitivity::unknown_sensitivities`, the
//! recorded unknowns by name), read into the O2 loop's branches as the run's flows are
//! (`closed_loop_heart`): each branch's terms, an on/off valve's flow only while the primal
//! valve is open (its state held: the derivative of the open or closed branch), each O2 step
//! the mean of the intervals it spans. The loop's balance is linear in the table, so the
//! balanced table's derivative is the balance of this one (`ClosedLoop::balance_direction`).

use super::closed_loop_circulation::HEART_TOL;
use super::closed_loop_heart::{HeartSpec, Series};
use crate::error::{Error, Result};
use crate::model::NetworkSpec;
use crate::sensitivity::{TangentSettings, unknown_sensitivities};

/// The heart parameters' SI values and, per parameter, the derivative of the O2 loop's flow
/// table (steps of `dt` × branches, row-major, before the balance) by it.
pub struct HeartTangent {
    pub values: Vec<f64>,
    pub tables: Vec<Vec<f64>>,
}

/// The derivative of the flow table the heart run of `spec` gives the O2 loop (step `dt`,
/// cycle `period`) by the heart model's parameters `paths` (`vessels.<name>.chamber.<key>`
/// ..., as `sensitivity::Parameter`), at the periodic state of the heart run's tolerance
/// (`until_periodic`, `HEART_TOL` without one) reached within its most cycles.
pub fn heart_tangent(
    spec: &HeartSpec,
    paths: &[String],
    dt: f64,
    period: f64,
) -> Result<HeartTangent> {
    let max_cycles = spec.max_cycles.unwrap_or(spec.cycles).max(spec.cycles);
    let tol = spec.until_periodic.unwrap_or(HEART_TOL);
    let model: NetworkSpec = serde_json::from_value(spec.model.clone())
        .map_err(|e| Error::model("closed-loop heart", e.to_string()))?;
    let names = unknowns_of(&spec.branches);
    let ns = (period / spec.dt).round().max(1.0) as usize;
    let settings = TangentSettings {
        period,
        steps_per_cycle: ns,
        rho_infty: spec.rho_infty,
        max_cycles,
        tol,
    };
    let sens = unknown_sensitivities(&model, paths, &names, settings)?;
    let k = (dt / spec.dt).round() as usize;
    if k == 0 || ns % k != 0 {
        return Err(Error::model(
            "closed-loop heart",
            format!(
                "the O2 step {dt} s is not a whole number of its flow steps {} s over its \
                 {ns} steps",
                spec.dt
            ),
        ));
    }
    let cyc = &sens.cycle;
    let nsig = names.len();
    let column = |name: &str| names.iter().position(|n| n == name).unwrap_or(0);
    let primal = |i: usize| &cyc.values[i * nsig..(i + 1) * nsig];
    let tables = (0..paths.len())
        .map(|p| {
            let deriv = |i: usize| &cyc.derivs[(p * ns + i) * nsig..(p * ns + i + 1) * nsig];
            let nb = spec.branches.len();
            let mut table = vec![0.0; ns / k * nb];
            for (b, series) in spec.branches.iter().enumerate() {
                // the cycle's points 0 ..= ns; point 0 is the periodic cycle's end, point ns
                let at = |j: usize| (j + ns - 1) % ns;
                let x: Vec<f64> = (0..=ns)
                    .map(|j| branch_tangent(series, &column, primal(at(j)), deriv(at(j))))
                    .collect();
                for s in 0..ns / k {
                    let sum: f64 = (s * k..(s + 1) * k).map(|i| 0.5 * (x[i] + x[i + 1])).sum();
                    table[s * nb + b] = sum / k as f64;
                }
            }
            table
        })
        .collect();
    Ok(HeartTangent {
        values: sens.values,
        tables,
    })
}

/// Every unknown the branches read (their terms and their valves' pressures), once each.
fn unknowns_of(branches: &[Series]) -> Vec<String> {
    let mut names: Vec<String> = Vec::new();
    for s in branches {
        let valve = s.valve.iter().flat_map(|(b, f)| [b, f]);
        for n in s.terms.iter().map(|t| &t.0).chain(valve) {
            if !names.contains(n) {
                names.push(n.clone());
            }
        }
    }
    names
}

/// A branch's flow derivative at one recorded point: Σ coefficient × d(unknown), zero while
/// its on/off valve is closed at the primal state (`closed_loop_heart::Recorded::eval`'s rule).
fn branch_tangent(
    s: &Series,
    column: &dyn Fn(&str) -> usize,
    primal: &[f64],
    deriv: &[f64],
) -> f64 {
    let q: f64 = s.terms.iter().map(|(n, c)| c * primal[column(n)]).sum();
    if let Some((b, f)) = &s.valve
        && primal[column(b)] <= primal[column(f)]
        && q <= 0.0
    {
        return 0.0;
    }
    s.terms.iter().map(|(n, c)| c * deriv[column(n)]).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed on/off valve carries no derivative; open, its terms' derivatives add up.
    #[test]
    fn a_closed_valve_holds_its_flow_derivative_at_zero() {
        let names = ["q".to_string(), "behind".into(), "front".into()];
        let column = |n: &str| names.iter().position(|x| x == n).unwrap();
        let s = Series {
            terms: vec![("q".into(), 0.5)],
            valve: Some(("behind".into(), "front".into())),
        };
        // closed: behind ≤ front and q ≤ 0
        assert_eq!(
            branch_tangent(&s, &column, &[-1.0, 1.0, 2.0], &[4.0, 1.0, 1.0]),
            0.0
        );
        // open by the pressures, or by a forward flow
        assert_eq!(
            branch_tangent(&s, &column, &[-1.0, 3.0, 2.0], &[4.0, 1.0, 1.0]),
            2.0
        );
        assert_eq!(
            branch_tangent(&s, &column, &[1.0, 1.0, 2.0], &[4.0, 1.0, 1.0]),
            2.0
        );
        assert_eq!(unknowns_of(&[s.clone(), s]), names.to_vec());
    }
}
