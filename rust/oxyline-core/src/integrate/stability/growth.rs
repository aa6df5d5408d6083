//! Growing modes (eigenvalues with Re λ > 0) of the linearised circuit, at any size.
//!
//! A passive circuit (R, L, C ≥ 0) has none: its energy only decays. A negative stenosis
//! coefficient (svZeroDSolver's calibrator writes them) makes a branch's incremental resistance
//! R + 2S|Q| negative where the flow is large enough, and that negative resistance can feed a
//! mode that grows at every step length and under every integrator. The RK4 bound's Krylov
//! estimate seeks the modes that leave RK4's stability region first, the fastest ones; a
//! growing mode is usually slow, inside the cluster of slow modes, where it does not converge.
//!
//! So a circuit that may grow (a negative stenosis coefficient) is searched on the Cayley
//! transform of its generalized eigenproblem λ E v = −K v (K = F + ∂c/∂y at the linearisation
//! state): C = (σE + K)⁻¹(σE − K) has the eigenvalues μ = (σ + λ)/(σ − λ), and |μ| > 1 exactly
//! when Re λ > 0 (σ > 0), whatever |λ|; the algebraic unknowns (E = 0) map to μ = −1 and drop
//! out of C restricted to the differential unknowns. A growing λ stands out most for σ near |λ|
//! (real λ = a: |μ| ≥ 1.93 for σ within √10 of a), so σ runs over decades below the fastest
//! mode, each with one sparse factorisation of σE + K (the integrators' own pattern, an O(n)
//! elimination on a tree) and restarted Arnoldi (`krylov`) for the largest |μ|. A Ritz value
//! counts only when its disc of radius its residual lies outside the unit circle (the
//! energy-scaled operator is close to normal, as for the RK4 bound).

use super::krylov::{self, KrylovControl};
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::integrate::newton::{jacobian_stamps, jacobian_values};
use crate::sparse::SparseLu;
use nalgebra::Complex;

/// Decades of σ searched below the fastest mode: a mode 1e-8 of the fastest grows by less
/// than e over 1e8 of the fastest time constants, which no run of a few cycles sees.
const DECADES: i32 = 9;

/// What the model error of a growing mode begins with (see [`is_growing_mode`]).
pub const GROWING: &str = "the circuit has a growing mode";

/// A growing mode: its eigenvalue (1/s) and the unknown with the largest share of it.
#[derive(Debug, Clone)]
pub struct GrowingMode {
    pub eigenvalue: Complex<f64>,
    pub unknown: String,
}

/// Whether the circuit may have a growing mode: it has a negative stenosis coefficient (every
/// other coefficient of the linearised circuit is passive).
pub fn may_grow(dae: &Dae) -> bool {
    dae.stenosis.iter().any(|&(_, s)| s < 0.0)
}

/// A stenosis whose incremental resistance R + 2S|Q| at `y` is below zero: its flow unknown,
/// S, R + 2S|Q| and Q.
#[derive(Debug, Clone, Copy)]
pub struct NegativeResistance {
    pub unknown: usize,
    pub coefficient: f64,
    pub resistance: f64,
    pub flow: f64,
}

/// The stenosis of the most negative incremental resistance at `y` (None: every one ≥ 0).
pub fn negative_resistance(dae: &Dae, y: &[f64]) -> Option<NegativeResistance> {
    let each = dae
        .stenosis
        .iter()
        .filter(|&&(i, _)| i < y.len())
        .map(|&(i, s)| {
            let diagonal = dae
                .f
                .row(i)
                .filter(|&k| dae.f.col[k] as usize == i)
                .map(|k| dae.f.val[k])
                .sum::<f64>();
            NegativeResistance {
                unknown: i,
                coefficient: s,
                resistance: diagonal + 2.0 * s * y[i].abs(),
                flow: y[i],
            }
        });
    each.filter(|n| n.resistance < 0.0)
        .min_by(|a, b| a.resistance.total_cmp(&b.resistance))
}

/// The cause of a failure at state `y`, if a negative incremental resistance explains it
/// (empty otherwise): appended to a solver error's message.
pub fn cause_at(dae: &Dae, y: &[f64]) -> String {
    match negative_resistance(dae, y) {
        Some(n) => format!(
            "; cause: {} has a negative incremental resistance R + 2S|Q| = {:.3e} (stenosis \
             coefficient S = {:.3e} at Q = {:.3e} m^3/s), which feeds a growing mode",
            dae.names.unknown(n.unknown),
            n.resistance,
            n.coefficient,
            n.flow
        ),
        None => String::new(),
    }
}

/// Whether `e` is the model error of a growing mode (a refusal no other method avoids).
pub fn is_growing_mode(e: &Error) -> bool {
    matches!(e, Error::Model { message, .. } if message.starts_with(GROWING))
}

/// The model error of the growing mode `m` of the circuit linearised at `y`: named by the
/// stenosis of negative incremental resistance (the cause) where there is one, else by the
/// unknown with the largest share of the mode.
pub fn growing_error(dae: &Dae, y: &[f64], m: GrowingMode) -> Error {
    let lam = m.eigenvalue;
    let share = m.unknown;
    let head = format!(
        "{GROWING} (eigenvalue {:.4e} {} {:.4e}i 1/s: its amplitude grows e-fold every {:.3e} \
         s, largest at {share})",
        lam.re,
        if lam.im < 0.0 { '-' } else { '+' },
        lam.im.abs(),
        1.0 / lam.re
    );
    match negative_resistance(dae, y) {
        Some(n) => Error::model(
            dae.names.unknown(n.unknown),
            format!(
                "{head}, fed by its negative incremental resistance R + 2S|Q| = {:.3e} \
                 (stenosis_coefficient {:.3e} at the steady flow {:.3e} m^3/s); no time step \
                 or method follows it: check the stenosis coefficient",
                n.resistance, n.coefficient, n.flow
            ),
        ),
        None => Error::model(share, head),
    }
}

/// The growing mode of `dae` linearised at (`y`, `t`) with the largest |μ| at the first σ
/// (from `fastest`, the magnitude of the fastest eigenvalue, down by decades) that finds one;
/// None when no σ finds one. `go` is asked before each product.
pub fn growing_mode(
    dae: &Dae,
    y: &[f64],
    t: f64,
    fastest: f64,
    go: &mut dyn FnMut() -> bool,
) -> Result<Option<GrowingMode>> {
    let n = dae.n;
    let diff: Vec<usize> = (0..n).filter(|&i| dae.e[i] != 0.0).collect();
    if diff.is_empty() || !(fastest.is_finite() && fastest > 0.0) {
        return Ok(None);
    }
    let stamps = jacobian_stamps(dae);
    let mut lu = SparseLu::<f64>::analyse(n, &stamps)?;
    let mut vals = vec![0.0; stamps.len()];
    let nf = dae.f.val.len();
    for d in 0..DECADES {
        let sigma = fastest * 10f64.powi(-d);
        let diag: Vec<f64> = dae.e.iter().map(|e| sigma * e).collect();
        jacobian_values(dae, 1.0, &diag, y, t, &mut vals);
        dae.varying_jacobian(1.0, t, Regime::Transient, &mut vals[nf..nf + n]);
        // σ an eigenvalue itself (singular σE + K): the next decade
        if lu.factor(&vals).is_err() {
            continue;
        }
        if let Some(m) = search(dae, &diff, &lu, sigma, go)? {
            return Ok(Some(m));
        }
    }
    Ok(None)
}

/// Arnoldi on the Cayley operator of shift `sigma` restricted to the differential unknowns
/// `diff`, energy-scaled (√|E_ii|).
fn search(
    dae: &Dae,
    diff: &[usize],
    lu: &SparseLu<f64>,
    sigma: f64,
    go: &mut dyn FnMut() -> bool,
) -> Result<Option<GrowingMode>> {
    let scale: Vec<f64> = diff.iter().map(|&i| dae.e[i].abs().sqrt()).collect();
    let mut full = vec![0.0; dae.n];
    let mut op = |v: &[f64], out: &mut [f64]| -> Result<()> {
        if !go() {
            return Err(Error::Interrupted { time: 0.0 });
        }
        full.iter_mut().for_each(|x| *x = 0.0);
        for ((&i, x), s) in diff.iter().zip(v).zip(&scale) {
            full[i] = 2.0 * sigma * dae.e[i] * x / s;
        }
        if !lu.solve_in_place(&mut full) {
            return Err(Error::solver(0.0, "stability: singular Cayley shift"));
        }
        for (((&i, o), x), s) in diff.iter().zip(out.iter_mut()).zip(v).zip(&scale) {
            *o = full[i] * s - x;
        }
        Ok(())
    };
    let control = KrylovControl {
        dim: 32,
        keep: 4,
        max_restarts: 20,
        tol: 1e-3,
    };
    let res = krylov::largest_by(diff.len(), &mut op, &|mu: Complex<f64>| mu.norm(), &control)?;
    let found = res
        .ritz
        .iter()
        .find(|r| r.value.norm() - r.residual > 1.0 + 1e-9);
    Ok(found.map(|r| {
        let mu = r.value;
        let one = Complex::new(1.0, 0.0);
        let lam = (mu - one) / (mu + one) * sigma;
        let j = (0..diff.len())
            .max_by(|&p, &q| r.vector[p].total_cmp(&r.vector[q]))
            .unwrap_or(0);
        GrowingMode {
            eigenvalue: lam,
            unknown: dae.names.unknown(diff[j]),
        }
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::circuit::Circuit;
    use crate::integrate::rk4::Rk4;
    use crate::integrate::stability::scaled_operator;
    use crate::waveform::Waveform;

    /// A ladder of `n` R–L–C sections from a fixed pressure to a fixed pressure; section
    /// `k_s` has the stenosis coefficient `s`. The state: 1e-5 m³/s in every branch.
    fn ladder(n: usize, k_s: usize, s: f64) -> (crate::circuit::Dae, Vec<f64>) {
        let mut k = Circuit::default();
        let inlet = k.add_node("in", 0.0, 0.0);
        let mut prev = inlet;
        for i in 0..n {
            let node = k.add_node(format!("n{i}").as_str(), 1e-10, 0.0);
            let sten = if i == k_s { s } else { 0.0 };
            k.add_branch(format!("b{i}").as_str(), prev, node, 1e6, 1e4, sten);
            prev = node;
        }
        let out = k.add_node("out", 0.0, 0.0);
        k.add_branch("drain", prev, out, 1e7, 0.0, 0.0);
        k.fixed_pressures.push((inlet, Waveform::constant(1e3)));
        k.fixed_pressures.push((out, Waveform::constant(0.0)));
        let dae = k.assemble().unwrap();
        let mut y = vec![0.0; dae.n];
        y[dae.n_nodes..].iter_mut().for_each(|q| *q = 1e-5);
        (dae, y)
    }

    /// The eigenvalues of the dense energy-scaled RK4 operator (an independent path: the
    /// algebraic unknowns eliminated, a dense eigensolver) linearised at `y`.
    fn dense_eigenvalues(dae: &crate::circuit::Dae, y: &[f64]) -> Vec<Complex<f64>> {
        let mut rk = Rk4::new(dae, Regime::Transient, 1.0).unwrap();
        rk.set_linearization(y).unwrap();
        let a = scaled_operator(&mut rk).unwrap();
        let evd = a.eigen().unwrap();
        let s = evd.S();
        (0..a.nrows())
            .map(|j| Complex::new(s[j].re, s[j].im))
            .collect()
    }

    #[test]
    fn the_cayley_search_finds_the_growing_mode_of_the_dense_spectrum() {
        // R + 2S|Q| = 1e6 − 2e12·1e-5 = −1.9e7 in section 40 of 120
        let (dae, y) = ladder(120, 40, -1e12);
        let dense = dense_eigenvalues(&dae, &y);
        let fastest = dense.iter().map(|l| l.norm()).fold(0.0, f64::max);
        let growing: Vec<_> = dense.iter().filter(|l| l.re > 1e-9 * fastest).collect();
        assert!(!growing.is_empty());
        let m = growing_mode(&dae, &y, 0.0, fastest, &mut || true)
            .unwrap()
            .expect("a growing mode");
        // the Arnoldi residual test stops at 1e-3 of the weight: the eigenvalue to ~1e-3
        let near = growing
            .iter()
            .map(|l| (m.eigenvalue - **l).norm() / l.norm())
            .fold(f64::INFINITY, f64::min);
        assert!(near < 1e-3, "{:?} against {growing:?}", m.eigenvalue);
        let e = growth_named(&dae, &y, m);
        assert!(e.contains("flow in b40") && e.contains("-1.900e7"), "{e}");
    }

    #[test]
    fn a_positive_incremental_resistance_has_no_growing_mode() {
        // R + 2S|Q| = 1e6 − 2e10·1e-5 = 8e5 > 0: passive, as the dense spectrum says
        let (dae, y) = ladder(120, 40, -1e10);
        let dense = dense_eigenvalues(&dae, &y);
        let fastest = dense.iter().map(|l| l.norm()).fold(0.0, f64::max);
        assert!(dense.iter().all(|l| l.re <= 1e-9 * fastest));
        assert!(negative_resistance(&dae, &y).is_none());
        let m = growing_mode(&dae, &y, 0.0, fastest, &mut || true).unwrap();
        assert!(m.is_none(), "{m:?}");
    }

    fn growth_named(dae: &crate::circuit::Dae, y: &[f64], m: GrowingMode) -> String {
        let e = growing_error(dae, y, m);
        assert!(is_growing_mode(&e));
        e.to_string()
    }
}
