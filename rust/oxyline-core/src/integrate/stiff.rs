//! Stiff branches of RK4 (docs/physics.md §1.8, "stiff branches"): a valve in series with an
//! inductor through a capacitance-free node (a chamber's outlet inductor and the valve behind
//! it). The branch's flow relaxes at R(ΔP)/L, which a closed valve's R_max makes a nanosecond
//! time constant (chamber_elastance_inductor: 2.8e8 1/s). When that rate exceeds 1/Δt the branch
//! is a singular perturbation: its flow follows the quasi-steady valve law to O(L/R), so RK4
//! drops the inductor's L dQ/dt for that step and eliminates the flow with the algebraic
//! unknowns. The choice is made per step from the valve's instantaneous resistance.

use crate::circuit::Dae;

/// A differential inductor row in series with a valve.
#[derive(Debug, Clone)]
pub(super) struct StiffBranch {
    /// The inductor's flow unknown (its row carries L dQ/dt).
    pub(super) inductor: usize,
    /// L (the row's mass entry).
    pub(super) inductance: f64,
    /// Index of the valve in `Dae::elements`.
    pub(super) valve: usize,
    /// The valve's flow unknown and the capacitance-free node between inductor and valve.
    pub(super) flow: usize,
    pub(super) node: usize,
    pub(super) r_min: f64,
    /// +1 when the inductor's flow is the valve's (both along the branch), −1 when opposed:
    /// the branch's whole pressure drop is the valve's plus `orientation` · L dQ/dt.
    pub(super) orientation: f64,
}

impl StiffBranch {
    /// Put the branch at the quasi-steady state of its algebraic mode: the node at the
    /// pressure for which the inductor's row reads L dQ/dt = 0 (the chamber's), both flows
    /// the valve law's at that pressure. The elimination's Newton starts there when the branch
    /// turns algebraic: from an open valve's state a closing valve's R jumps by R_max/R_min
    /// within one correction (k ΔP of ~1e3 at the aortic closure of svZeroDSolver's
    /// closedLoopHeart_singleVessel_decomposed), which the damped Newton's monotonicity test
    /// rejects at every halving.
    pub(super) fn quasi_steady(&self, dae: &Dae, f: &[f64], y: &mut [f64]) {
        let j = self.inductor;
        let Some(c) = dae
            .f
            .row(j)
            .find(|&k| dae.f.col[k] as usize == self.node)
            .map(|k| dae.f.val[k])
            .filter(|&c| c != 0.0)
        else {
            return;
        };
        y[self.node] += (f[j] - dae.f.row_dot(j, y)) / c;
        let q = dae.elements[self.valve].valve_flow(y);
        y[self.flow] = q;
        y[j] = self.orientation * q;
    }
}

/// At most this many stiff branches switch (one bit each of a mode mask); further ones stay
/// differential, and the stability bound's closed state then covers them.
pub(super) const MAX_STIFF: usize = 64;

/// A branch is algebraic for a step when R(ΔP) Δt > `STIFF_RATE` L, i.e. its relaxation rate
/// R/L exceeds 1/Δt: its flow then settles within a step, and the quasi-steady law's error
/// O(L/R) is below Δt. While it stays differential its own rate R/L ≤ 1/Δt lies well inside
/// RK4's real-axis stability interval (2.785/Δt).
pub(super) const STIFF_RATE: f64 = 1.0;

/// The stiff-branch candidates of `dae` given the mass diagonal `e` of the index reduction:
/// a valve whose flow is algebraic and a capacitance-free node whose flow balance reads
/// ±Q_valve ± Q_inductor = 0 with nothing else.
pub(super) fn find(dae: &Dae, e: &[f64]) -> Vec<StiffBranch> {
    let valves: Vec<(usize, usize, f64)> = (dae.elements.iter().enumerate())
        .filter_map(|(k, el)| el.valve_branch().map(|(q, r_min, _)| (k, q, r_min)))
        .filter(|&(_, q, _)| e[q] == 0.0)
        .collect();
    if valves.is_empty() {
        return Vec::new();
    }
    let mut element_row = vec![false; dae.n];
    for el in &dae.elements {
        for &r in el.rows() {
            element_row[r] = true;
        }
    }
    let mut out = Vec::new();
    for r in (0..dae.n_nodes).filter(|&r| e[r] == 0.0 && !element_row[r]) {
        let cols: Vec<(usize, f64)> = dae
            .f
            .row(r)
            .filter(|&k| dae.f.val[k] != 0.0)
            .map(|k| (dae.f.col[k] as usize, dae.f.val[k]))
            .collect();
        let [(a, ca), (b, cb)] = cols[..] else {
            continue;
        };
        // a flow balance ±Q_a ± Q_b = 0: the flows run along each other when the signs differ
        let orientation = -(ca * cb).signum();
        for (q, j) in [(a, b), (b, a)] {
            let Some(&(valve, _, r_min)) = valves.iter().find(|v| v.1 == q) else {
                continue;
            };
            if e[j] > 0.0 && j >= dae.n_nodes && !element_row[j] && out.len() < MAX_STIFF {
                out.push(StiffBranch {
                    inductor: j,
                    inductance: e[j],
                    valve,
                    flow: q,
                    node: r,
                    r_min,
                    orientation,
                });
            }
        }
    }
    out
}
