//! The blood volume a closed loop conserves, and the row it adds to the periodic problem.
//!
//! A circuit without pressure conditions or inflows (a closed loop, e.g. svZeroDSolver's
//! closedLoopHeart cases) has flow-balance rows whose sum m (1 on each node's balance row: its
//! own, or the chamber volume's row it moved to) annihilates every flow term: mᵀ F = 0 and
//! mᵀ ∂c/∂y = 0 (a branch's flow leaves one balance and enters another; a closed valve's
//! correction does the same). Then mᵀ E ẏ = 0 along any run: the blood volume
//! V = mᵀ E y = Σ C P + Σ V_chamber is conserved. Generalized-α keeps it exactly (to the
//! Newton tolerance): from mᵀ E (c ẏ + α_m Δ) = 0 each step,
//! ℓ(y, ẏ) = mᵀ E (y − γ Δt c ẏ) is invariant (the ẏ part decays by 1 − 1/α_m a step).
//!
//! So the cycle map has the eigenvalue 1 with the left eigenvector ℓ, and the periodic
//! tangent's fixed point (I − Φ) x = b is only set up to the periodic orbits' family by volume
//! (the right eigenvector v: the periodic tangent of a unit volume). The row that closes it is
//! the tangent of ℓ, which the tangent run conserves as well: from a start s = ṡ = 0 at the
//! start values y₀ (ẏ₀ = 0, whatever the parameter),
//!
//!   ℓ·x = mᵀ dE (y₀ − y_T + γ Δt c ẏ_T)
//!
//! at the periodic cycle's start (y_T, ẏ_T): the blood volume is that of the start values
//! (a capacitance parameter changes it by dC·P₀, as a run from the same start values does).

use crate::circuit::{Circuit, Dae, JacobianKind};

/// The conserved volume's weights m on the DAE's rows (1 on the balance rows).
#[derive(Debug, Clone)]
pub struct ConservedVolume {
    m: Vec<f64>,
    /// m_i E_i
    me: Vec<f64>,
    /// The start values' volume mᵀ E y₀ (m³): the scale of a unit-volume tangent.
    pub total: f64,
}

/// A column sum this far below its terms' magnitudes counts as zero (rounding of ±1 sums).
const CANCELS: f64 = 1e-12;

impl ConservedVolume {
    /// The conserved volume of `dae` when the circuit is a closed loop whose balance rows
    /// cancel every flow term (checked on F, the forcing and the elements' Jacobians at the
    /// start state with their valves as found there, all open and all closed); None for an
    /// open circuit.
    pub fn of(circuit: &Circuit, dae: &Dae) -> Option<ConservedVolume> {
        if !circuit.fixed_pressures.is_empty() || !circuit.sources.is_empty() {
            return None;
        }
        let (nn, nb, n) = (circuit.nodes.len(), circuit.branches.len(), dae.n);
        let mut row: Vec<usize> = (0..nn).collect();
        for &(node, x) in &circuit.moved_rows {
            row[node] = nn + nb + x;
        }
        for sw in &circuit.swapped_rows {
            row[sw.node] = nn + sw.branch;
        }
        let mut m = vec![0.0; n];
        for r in row {
            *m.get_mut(r)? = 1.0;
        }
        let forced = dae.forcing.iter().map(|(r, _)| *r);
        let stenosed = dae.stenosis.iter().map(|(r, _)| *r);
        let varying = dae.varying.iter().map(|(r, _)| *r);
        if forced.chain(stenosed).chain(varying).any(|r| m[r] != 0.0) {
            return None;
        }
        let (mut sum, mut size) = (vec![0.0; n], vec![0.0; n]);
        for i in (0..n).filter(|&i| m[i] != 0.0) {
            for k in dae.f.row(i) {
                let j = dae.f.col[k] as usize;
                sum[j] += dae.f.val[k];
                size[j] += dae.f.val[k].abs();
            }
        }
        if !cancels(&sum, &size) || !elements_cancel(dae, &m) {
            return None;
        }
        let me: Vec<f64> = m.iter().zip(&dae.e).map(|(a, e)| a * e).collect();
        let total = me.iter().zip(dae.initial_state()).map(|(a, y)| a * y).sum();
        me.iter()
            .any(|&v| v != 0.0)
            .then_some(ConservedVolume { m, me, total })
    }

    /// ℓ·x over a tangent state x = (s, ṡ): Σ m E (s − k ṡ), k = γ Δt c.
    pub(crate) fn dot(&self, x: &[f64], k: f64) -> f64 {
        let n = self.me.len();
        (self.me.iter().enumerate())
            .map(|(i, w)| w * (x[i] - k * x[n + i]))
            .sum()
    }

    /// ℓ as a vector over (s, ṡ) (the adjoint's side).
    pub(crate) fn row(&self, k: f64) -> Vec<f64> {
        let it = self.me.iter();
        it.clone().copied().chain(it.map(|w| -k * w)).collect()
    }

    /// A direction e with ℓ·e = 1: a volume spread over the balance rows by their E.
    pub(crate) fn unit(&self) -> Vec<f64> {
        let n = self.me.len();
        let norm: f64 = self.me.iter().map(|w| w * w).sum();
        let mut e: Vec<f64> = self.me.iter().map(|w| w / norm).collect();
        e.resize(2 * n, 0.0);
        e
    }

    /// ℓ·x a parameter's periodic tangent must have: mᵀ dE (y₀ − y_T + k ẏ_T), with the
    /// start values y₀ and the periodic cycle's start (y_T, ẏ_T) = `start`.
    pub(crate) fn start_change(&self, de: &[f64], y0: &[f64], start: &[f64], k: f64) -> f64 {
        let n = self.m.len();
        (0..n)
            .filter(|&i| self.m[i] != 0.0 && de[i] != 0.0)
            .map(|i| self.m[i] * de[i] * (y0[i] - start[i] + k * start[n + i]))
            .sum()
    }

    /// A parameter with this dE changes the volume's weights (a capacitance on a balance row).
    pub(crate) fn moves(&self, de: &[f64]) -> bool {
        self.m.iter().zip(de).any(|(m, d)| *m != 0.0 && *d != 0.0)
    }

    /// Move `x` along `e` (= [`Self::unit`]) so that ℓ·x = `target` (the rounding of the
    /// fixed-point iteration would otherwise drift along the neutral mode).
    pub(crate) fn hold(&self, x: &mut [f64], e: &[f64], k: f64, target: f64) {
        let d = target - self.dot(x, k);
        for (xi, ei) in x.iter_mut().zip(e) {
            *xi += d * ei;
        }
    }
}

fn cancels(sum: &[f64], size: &[f64]) -> bool {
    sum.iter().zip(size).all(|(s, z)| s.abs() <= CANCELS * z)
}

/// mᵀ ∂c/∂y = 0 for every element at the start state (valves as found there), with every
/// valve open and with every valve closed, at a few times of the cycle.
fn elements_cancel(dae: &Dae, m: &[f64]) -> bool {
    let pattern = dae.element_pattern();
    if pattern.is_empty() {
        return true;
    }
    let y = dae.initial_state();
    let mut vals = vec![0.0; pattern.len()];
    let kinds = [
        JacobianKind::Exact,
        JacobianKind::Stiffest,
        JacobianKind::Closed,
    ];
    let period = dae.elements.iter().find_map(|e| e.period()).unwrap_or(1.0);
    for kind in kinds {
        for t in [0.0, 0.3 * period, 0.7 * period] {
            vals.iter_mut().for_each(|v| *v = 0.0);
            dae.element_jacobian(1.0, t, &y, &mut vals, kind);
            let (mut sum, mut size) = (vec![0.0; dae.n], vec![0.0; dae.n]);
            for (&(r, c), v) in pattern.iter().zip(&vals) {
                sum[c] += m[r] * v;
                size[c] += (m[r] * v).abs();
            }
            if !cancels(&sum, &size) {
                return false;
            }
        }
    }
    true
}
