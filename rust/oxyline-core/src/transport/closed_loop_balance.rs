//! Periodic volumes for a closed loop's flow table (docs/oxygen.md "Oxygen around a closed
//! loop"): flows sampled from a flow run close each compartment's volume over the cycle only
//! to that run's discretisation and periodicity error, while the O2 loop needs every volume
//! periodic. The least-norm constant per-branch corrections δ that close them are δ = Aᵀφ,
//! A the compartment–branch incidence, with (A Aᵀ) φ = −net: A Aᵀ is the loop's graph
//! Laplacian, singular by the constant, so one compartment is grounded (φ = 0) and the
//! consistent part of `net` (its mean removed) is solved for — the least-norm solution the
//! pseudo-inverse gives, by a small dense linear solve.

use crate::error::{Error, Result};

/// Adds to every branch b of the row-major `flows` table (steps × branches) the constant δ_b
/// that makes each compartment's cycle-mean net inflow vanish, counting `fixed_net` (the
/// cycle-mean net inflow per compartment of flows that stay as they are, e.g. an arterial
/// tree's). Branch b runs from compartment `from[b]` to `to[b]`.
pub fn balance_flows(
    flows: &mut [f64],
    from: &[usize],
    to: &[usize],
    fixed_net: &[f64],
) -> Result<()> {
    let (nb, nc) = (from.len(), fixed_net.len());
    if nb == 0 || flows.len() % nb != 0 || to.len() != nb {
        return Err(Error::model(
            "closed loop",
            "flow table does not match its branches",
        ));
    }
    let steps = (flows.len() / nb) as f64;
    let mut net = fixed_net.to_vec();
    for b in 0..nb {
        let mean = flows.iter().skip(b).step_by(nb).sum::<f64>() / steps;
        net[from[b]] -= mean;
        net[to[b]] += mean;
    }
    let shift = net.iter().sum::<f64>() / nc as f64;
    // the Laplacian without compartment 0's row and column (grounded)
    let m = nc - 1;
    let mut lap = vec![0.0; m * m];
    for (&f, &t) in from.iter().zip(to) {
        for (i, j, v) in [(f, f, 1.0), (t, t, 1.0), (f, t, -1.0), (t, f, -1.0)] {
            if f != t && i > 0 && j > 0 {
                lap[(i - 1) * m + (j - 1)] += v;
            }
        }
    }
    let mut phi: Vec<f64> = net[1..].iter().map(|x| -(x - shift)).collect();
    solve_dense(&lap, &mut phi, m)?;
    let potential = |c: usize| if c == 0 { 0.0 } else { phi[c - 1] };
    for (b, (&f, &t)) in from.iter().zip(to).enumerate() {
        let delta = potential(t) - potential(f);
        flows
            .iter_mut()
            .skip(b)
            .step_by(nb)
            .for_each(|q| *q += delta);
    }
    Ok(())
}

/// Solves a · x = b in place (row-major m × m) by nalgebra's LU with partial pivoting;
/// a singular matrix (compartments the branches do not connect) is a model error.
fn solve_dense(a: &[f64], b: &mut [f64], m: usize) -> Result<()> {
    let scale = a.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    if !crate::sparse::lu_solve(a, b, m, 1e-12 * scale) {
        return Err(Error::model(
            "closed loop",
            "the branches do not connect every compartment: no flow correction closes \
             their volumes",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn corrections_close_every_volume_with_least_norm() {
        // a ring 0 → 1 → 2 → 0 with a chord 0 → 2; unequal mean flows over 2 steps
        let (from, to) = ([0, 1, 2, 0], [1, 2, 0, 2]);
        let mut flows = vec![1.0, 0.9, 1.3, 0.2, 1.2, 1.1, 1.5, 0.4];
        let orig = flows.clone();
        balance_flows(&mut flows, &from, &to, &[0.0; 3]).unwrap();
        let mut net = [0.0; 3];
        for b in 0..4 {
            let mean = 0.5 * (flows[b] + flows[4 + b]);
            net[from[b]] -= mean;
            net[to[b]] += mean;
        }
        assert!(net.iter().all(|x| x.abs() < 1e-14), "{net:?}");
        // least norm: δ = Aᵀφ is orthogonal to every circulation, here the ring (branches
        // 0, 1, 2) and the loop of the chord and branch 2 (0 → 2 → 0)
        let delta: Vec<f64> = (0..4).map(|b| flows[b] - orig[b]).collect();
        let ring = delta[0] + delta[1] + delta[2];
        let chord = delta[3] + delta[2];
        assert!(ring.abs() < 1e-14 && chord.abs() < 1e-14, "{delta:?}");
    }

    #[test]
    fn disconnected_compartments_are_a_model_error() {
        let mut flows = vec![1.0, 2.0];
        let e = balance_flows(&mut flows, &[0, 2], &[1, 3], &[0.0; 4]).unwrap_err();
        assert!(e.to_string().contains("do not connect"), "{e}");
    }
}
