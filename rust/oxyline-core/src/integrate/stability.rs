//! Largest stable RK4 step of the (linear, time-invariant) flow circuit, and the element
//! that sets it. Exact from the dense spectrum for small circuits, restarted Arnoldi on the
//! same operator otherwise (`krylov`). A circuit that may grow (a negative stenosis
//! coefficient) is refused by name where it has a growing mode (`growth`).

pub mod growth;
mod krylov;

use super::rk4::Rk4;
use crate::circuit::Names;
use crate::error::Result;
use nalgebra::Complex;

/// RK4 amplification factor R(z) = 1 + z + z²/2 + z³/6 + z⁴/24.
pub fn rk4_amplification(z: Complex<f64>) -> f64 {
    let one = Complex::new(1.0, 0.0);
    (one + z * (one + z * (one / 2.0 + z * (one / 6.0 + z / 24.0)))).norm()
}

/// Largest h with |R(λh)| ≤ 1, for Re λ ≤ 0 (bisection along the ray from the origin).
pub fn rk4_step_limit(lambda: Complex<f64>) -> f64 {
    let m = lambda.norm();
    if m == 0.0 {
        return f64::INFINITY;
    }
    let (mut lo, mut hi) = (0.0, 3.0 / m);
    if rk4_amplification(lambda * hi) <= 1.0 + 1e-12 {
        return hi;
    }
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if rk4_amplification(lambda * mid) <= 1.0 + 1e-12 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

#[derive(Debug, Clone)]
pub struct StabilityLimit {
    /// Largest stable RK4 step (s).
    pub dt_max: f64,
    /// Eigenvalue (1/s) that sets it.
    pub eigenvalue: (f64, f64),
    /// Unknown with the largest share of the limiting mode.
    pub element: String,
    /// Whether the limit is exact (dense spectrum) or a Krylov estimate (made conservative by
    /// the Ritz residual, see [`krylov_limit`]).
    pub exact: bool,
}

/// How [`rk4_limit_by`] finds the spectrum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpectrumMethod {
    /// Dense up to `DENSE_LIMIT` differential unknowns, Krylov beyond.
    Auto,
    Dense,
    Krylov,
}

const DENSE_LIMIT: usize = 600;

/// Largest stable RK4 step of `rk`'s circuit and the unknown (named by `names`) that sets it:
/// exact for up to `DENSE_LIMIT` differential unknowns, a Krylov estimate beyond.
pub fn rk4_limit(rk: &mut Rk4<'_>, names: &Names) -> Result<StabilityLimit> {
    rk4_limit_by(rk, names, SpectrumMethod::Auto)
}

/// Frozen-coefficient samples per period of a time-varying circuit (plus its laws' breakpoints).
const TIME_SAMPLES: usize = 48;

/// Share of the smallest sampled frozen-coefficient limit that a time-varying circuit may use.
/// The frozen limit is exact only for coefficients that stay put within a step; with R(t)
/// changing over a cycle (≫ one step) the error of that approximation is O(Δt/T), and between
/// samples the limit can dip below the sampled values by the limit's change over 1/48 period.
/// 0.9 is a judgement, not a proof: it covers a 10 % dip between samples of a law that is
/// continuous over the period (tests/test_svzerod_heart.py checks the varying coronary case
/// against the peer with RK4 at half the reported limit).
const TIME_VARYING_MARGIN: f64 = 0.9;

/// [`rk4_limit`] with the spectrum method chosen. A circuit with time-varying coefficients
/// (docs/physics.md §1.7) is judged on its instantaneous operator: the smallest limit over the
/// sampled times of a period, times [`TIME_VARYING_MARGIN`].
///
/// Circuits with valves are judged in two states, every valve open (R_min: the fastest R–C
/// modes) and every valve closed (R_max: the fastest R/L mode of a valve behind an inductor,
/// e.g. a chamber's outlet, docs/physics.md §1.8), and take the smaller limit.
///
/// Stiff branches (a valve behind an inductor, docs/physics.md §1.8) are algebraic in the step
/// whenever R(ΔP) Δt > L, so the closed state is judged with all of them algebraic (limit A);
/// the branches that can still be differential at a step of A with the valve fully open
/// (R_min A ≤ L) are then put back differential for the open state (limit B), and the smaller
/// of A and B is the limit. While differential a branch's own rate R/L ≤ 1/Δt is inside RK4's
/// real-axis interval by construction.
pub fn rk4_limit_by(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
) -> Result<StabilityLimit> {
    rk4_limit_probed(rk, names, method, &mut || true)
}

/// What an estimate asks between its pieces of work (each matrix-vector product, each
/// sampled time): false stops it with [`Error::Interrupted`], so that a cancelled run stops
/// during the estimate of its step too, not only once it steps.
pub type KeepGoing<'a> = dyn FnMut() -> bool + 'a;

fn interrupted() -> crate::Error {
    crate::Error::Interrupted { time: 0.0 }
}

/// [`rk4_limit_by`], asking `go` between its pieces of work.
pub fn rk4_limit_probed(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
    go: &mut KeepGoing<'_>,
) -> Result<StabilityLimit> {
    let limit = limit_stiff_or_not(rk, names, method, go)?;
    refuse_growth(rk, &limit, go)?;
    Ok(limit)
}

/// A growing mode is a model error naming its cause (`growth`): the dense spectrum shows it
/// as the limiting eigenvalue (Re λ > 0, a vanishing RK4 step); the Krylov estimate seeks the
/// fastest modes and misses a slow one, so a circuit that may grow is searched for it.
fn refuse_growth(rk: &Rk4<'_>, limit: &StabilityLimit, go: &mut KeepGoing<'_>) -> Result<()> {
    let dae = rk.dae();
    if !growth::may_grow(dae) {
        return Ok(());
    }
    let zero;
    let y = match rk.linearization_state() {
        [] => {
            zero = vec![0.0; dae.n];
            &zero[..]
        }
        y => y,
    };
    let (re, im) = limit.eigenvalue;
    let lam = Complex::new(re, im);
    // the dense spectrum's round-off on the energy-scaled operator is ~1e-15 of its norm
    let mode = if limit.exact {
        (re > 1e-9 * lam.norm()).then(|| growth::GrowingMode {
            eigenvalue: lam,
            unknown: limit.element.clone(),
        })
    } else {
        growth::growing_mode(dae, y, 0.0, lam.norm(), go)?
    };
    match mode {
        Some(m) => Err(growth::growing_error(dae, y, m)),
        None => Ok(()),
    }
}

/// [`rk4_limit_probed`] without the growth check.
fn limit_stiff_or_not(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
    go: &mut KeepGoing<'_>,
) -> Result<StabilityLimit> {
    if rk.stiff_branches() == 0 {
        return limit_open_closed(rk, names, method, go);
    }
    rk.set_operator_mask(rk.stiff_mask_all())?;
    let all = limit_open_closed(rk, names, method, go);
    let all = all.and_then(|a| {
        let open_mask = rk.stiff_mask_open(a.dt_max);
        if open_mask == rk.stiff_mask_all() {
            return Ok(a);
        }
        rk.set_operator_mask(open_mask)?;
        let open = limit_over_period(rk, names, method, go)?;
        Ok(if open.dt_max < a.dt_max { open } else { a })
    });
    rk.set_operator_mask(0)?;
    all
}

/// The smaller limit of the valves open and closed (the stiff branches as set).
fn limit_open_closed(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
    go: &mut KeepGoing<'_>,
) -> Result<StabilityLimit> {
    let open = limit_over_period(rk, names, method, go)?;
    if !rk.has_closed_states() {
        return Ok(open);
    }
    rk.set_valves_closed(true)?;
    let closed = limit_over_period(rk, names, method, go);
    rk.set_valves_closed(false)?;
    let closed = closed?;
    Ok(if closed.dt_max < open.dt_max {
        closed
    } else {
        open
    })
}

/// The limit of the elements' current state: frozen, or over the sampled times of a period.
fn limit_over_period(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
    go: &mut KeepGoing<'_>,
) -> Result<StabilityLimit> {
    if !rk.is_time_varying() {
        return rk4_limit_frozen(rk, names, method, go);
    }
    let mut worst: Option<StabilityLimit> = None;
    for t in rk.operator_times(TIME_SAMPLES) {
        rk.set_operator_time(t)?;
        let lim = rk4_limit_frozen(rk, names, method, go);
        let lim = match lim {
            Ok(lim) => lim,
            Err(e) => {
                rk.set_operator_time(0.0)?;
                return Err(e);
            }
        };
        if worst.as_ref().is_none_or(|w| lim.dt_max < w.dt_max) {
            worst = Some(lim);
        }
    }
    rk.set_operator_time(0.0)?;
    let worst = worst.expect("a time-varying circuit has at least one sample time");
    Ok(StabilityLimit {
        dt_max: TIME_VARYING_MARGIN * worst.dt_max,
        ..worst
    })
}

/// The limit of the operator with its coefficients frozen at the time last set.
fn rk4_limit_frozen(
    rk: &mut Rk4<'_>,
    names: &Names,
    method: SpectrumMethod,
    go: &mut KeepGoing<'_>,
) -> Result<StabilityLimit> {
    if !go() {
        return Err(interrupted());
    }
    if rk.diff.is_empty() {
        return Ok(StabilityLimit {
            dt_max: f64::INFINITY,
            eigenvalue: (0.0, 0.0),
            element: "none".into(),
            exact: true,
        });
    }
    let dense = match method {
        SpectrumMethod::Auto => rk.diff.len() <= DENSE_LIMIT,
        SpectrumMethod::Dense => true,
        SpectrumMethod::Krylov => false,
    };
    // the eigensolver's matrix products take the linear algebra's scratch only above faer's
    // small-product size (both branches factor at most max(n, 48)-square matrices)
    if rk.diff.len() > crate::run::memory::SMALL_PRODUCT_ORDER {
        crate::run::memory::check_scratch()?;
    }
    let (limit, at) = if dense {
        dense_limit(rk)?
    } else {
        krylov_limit(rk, go)?
    };
    Ok(StabilityLimit {
        element: names.unknown(rk.diff[at]),
        ..limit
    })
}

/// Matrix-vector products of [`rk4_step_ceiling`]'s power iteration: each is one operator
/// application (O(n)); the estimate only has to be within [`NON_NORMAL_MARGIN`] of the
/// spectral radius, and on a tree the stiffest level holds half the segments.
const CEILING_PRODUCTS: usize = 8;

/// How far below ‖A v‖ (v a unit vector) the spectral radius of the energy-scaled operator
/// is taken to lie at most. For a normal operator ρ(A) = ‖A‖ ≥ ‖A v‖; the energy-scaled
/// passive circuit is a skew part (L–C coupling) minus a positive semidefinite one
/// (resistances), close to normal but not exactly (the resistances sit on the flows only), so
/// ‖A v‖ may exceed ρ by a little: 2 is a margin, checked against dense eigenvalues of chains,
/// trees and built-in models (tests/test_stability.py).
const NON_NORMAL_MARGIN: f64 = 2.0;

/// The largest |z| of RK4's stability region in the closed left half-plane, over its rays
/// (z = h λ, `rk4_step_limit(λ)·|λ|`): about 2.96 near 98° (2√2 on the imaginary axis, 2.785
/// on the real one), sampled on 181 rays and rounded up by 1 % for what the sampling misses
/// between them.
pub fn rk4_reach() -> f64 {
    ray_reach(rk4_step_limit)
}

/// The largest value of `on_ray(λ)` over 181 unit λ on the rays of the left half-plane, 1 %
/// above the sampled maximum: with a step limit, its region's largest |z| (`limit(λ)·|λ|`).
pub fn ray_reach(on_ray: impl Fn(Complex<f64>) -> f64) -> f64 {
    let rays = 180;
    let most = (0..=rays)
        .map(|k| {
            let theta = std::f64::consts::FRAC_PI_2 * (1.0 + k as f64 / rays as f64);
            on_ray(Complex::from_polar(1.0, theta))
        })
        .fold(0.0, f64::max);
    1.01 * most
}

/// An upper bound of RK4's stable step on `rk`'s operator as it is set (coefficients frozen,
/// valves as set) that needs no eigen-iteration over the whole circuit: a few power
/// iterations give ‖A v‖ ≤ ~ρ(A) of the energy-scaled operator, and no eigenvalue of modulus
/// ρ lets RK4 step further than [`rk4_reach`]/ρ along its ray, whatever its direction. With
/// [`NON_NORMAL_MARGIN`] on ρ. O(n) per product, no Krylov basis: for deciding that a large
/// circuit is not worth the explicit pair without the probe ([`rk4_limit_probed`]).
/// Infinite without differential unknowns.
pub fn rk4_step_ceiling(rk: &mut Rk4<'_>, go: &mut KeepGoing<'_>) -> Result<f64> {
    let nd = rk.diff.len();
    if nd == 0 {
        return Ok(f64::INFINITY);
    }
    let scale = energy_scale(rk);
    // the Krylov estimate's deterministic, non-smooth start
    let mut v: Vec<f64> = (0..nd)
        .map(|i| {
            let h = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
            h as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect();
    let (mut x, mut out) = (vec![0.0; nd], vec![0.0; nd]);
    let mut radius: f64 = 0.0;
    for _ in 0..CEILING_PRODUCTS {
        if !go() {
            return Err(interrupted());
        }
        let nv = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if !(nv > 0.0 && nv.is_finite()) {
            break;
        }
        for ((xi, vi), s) in x.iter_mut().zip(&v).zip(&scale) {
            *xi = vi / (nv * s);
        }
        rk.linear_operator(&x, &mut out)?;
        out.iter_mut().zip(&scale).for_each(|(o, s)| *o *= s);
        let grown = out.iter().map(|a| a * a).sum::<f64>().sqrt();
        radius = radius.max(grown);
        std::mem::swap(&mut v, &mut out);
    }
    Ok(if radius > 0.0 && radius.is_finite() {
        rk4_reach() * NON_NORMAL_MARGIN / radius
    } else {
        f64::INFINITY
    })
}

/// Energy scaling √E_ii of the differential unknowns: x̃ = √E x is a similarity (eigenvalues
/// unchanged) under which the passive circuit's operator is a skew part (the L–C coupling) minus
/// a positive semidefinite part (the resistances), hence close to normal. Unscaled, capacitances
/// ~1e-12 and inertances ~1e5 spread the entries over ~20 decades: dense eigensolvers return
/// spurious Re λ > 0 for lightly damped LC modes, and norm-based iterations (the old power
/// iteration) overestimate the spectral radius by orders of magnitude.
///
/// √|E_ii|: an `svzerod-inlet` Windkessel's capacitance is negative (svZeroDSolver's equations
/// at an inlet, docs/svzerod.md); any positive diagonal scaling is a similarity.
fn energy_scale(rk: &Rk4<'_>) -> Vec<f64> {
    rk.mass_diagonal().iter().map(|e| e.abs().sqrt()).collect()
}

/// The RK4 iteration operator of the differential unknowns (algebraic unknowns eliminated,
/// stenoses linearised) in energy-scaled coordinates, as a dense matrix (for small circuits and
/// for checking the Krylov estimate against an independent dense eigensolver).
pub fn scaled_operator(rk: &mut Rk4<'_>) -> Result<faer::Mat<f64>> {
    let nd = rk.diff.len();
    let mut a = faer::Mat::<f64>::zeros(nd, nd);
    let mut x = vec![0.0; nd];
    let mut col = vec![0.0; nd];
    let scale = energy_scale(rk);
    for j in 0..nd {
        x.iter_mut().for_each(|v| *v = 0.0);
        x[j] = 1.0;
        rk.linear_operator(&x, &mut col)?;
        for i in 0..nd {
            a[(i, j)] = col[i] * scale[i] / scale[j];
        }
    }
    Ok(a)
}

/// From the dense spectrum; also returns the position (in `diff`) of the unknown with the
/// largest share of the limiting mode.
fn dense_limit(rk: &mut Rk4<'_>) -> Result<(StabilityLimit, usize)> {
    let nd = rk.diff.len();
    let a = scaled_operator(rk)?;
    // faer's dense eigensolver (nalgebra's complex_eigenvalues is unreliable for
    // non-normal matrices)
    let evd = a
        .eigen()
        .map_err(|e| crate::error::Error::solver(0.0, format!("eigenvalues: {e:?}")))?;
    let (s, u) = (evd.S(), evd.U());
    let (mut best, mut jbest) = (f64::INFINITY, 0);
    for j in 0..nd {
        let l = s[j];
        let h = rk4_step_limit(Complex::new(l.re, l.im));
        if h < best {
            best = h;
            jbest = j;
        }
    }
    let v = u.col(jbest);
    let i = (0..nd)
        .max_by(|&p, &q| v[p].norm().total_cmp(&v[q].norm()))
        .unwrap_or(0);
    let lam = s[jbest];
    let limit = StabilityLimit {
        dt_max: best,
        eigenvalue: (lam.re, lam.im),
        element: String::new(),
        exact: true,
    };
    Ok((limit, i))
}

/// Restarted Arnoldi on the energy-scaled RK4 operator (the same operator as the dense branch,
/// applied as matrix-vector products with the sparse algebraic elimination), seeking the
/// eigenvalues that leave the RK4 stability region first: largest 1/h(λ), where h(λ) is the
/// largest stable step along λ's ray (so an RC mode on the negative real axis and an LC mode near
/// the imaginary axis are weighed by their own boundary distance, not by |λ| alone).
///
/// Margin: each kept Ritz value θ is pushed outward along its ray by its residual
/// r = ‖A x − θ x‖ before h is evaluated. The energy-scaled passive operator is close to normal,
/// for which the disc |λ − θ| ≤ r holds an eigenvalue; the pushed point bounds that eigenvalue's
/// reach. Iteration stops when pushing changes the limit by less than 0.1 %; the result is then
/// conservative by at most that much. Checked against dense eigenvalues from 100 to 5,000
/// unknowns (tests/test_stability.py).
fn krylov_limit(rk: &mut Rk4<'_>, go: &mut KeepGoing<'_>) -> Result<(StabilityLimit, usize)> {
    let nd = rk.diff.len();
    let scale = energy_scale(rk);
    let mut x = vec![0.0; nd];
    let mut op = |v: &[f64], out: &mut [f64]| -> Result<()> {
        if !go() {
            return Err(interrupted());
        }
        for ((xi, vi), s) in x.iter_mut().zip(v).zip(&scale) {
            *xi = vi / s;
        }
        rk.linear_operator(&x, out)?;
        out.iter_mut().zip(&scale).for_each(|(o, s)| *o *= s);
        Ok(())
    };
    let weight = |l: Complex<f64>| 1.0 / rk4_step_limit(l);
    let res = krylov::largest_by(nd, &mut op, &weight, &krylov::KrylovControl::default())?;
    // the most limiting pushed Ritz value
    let (mut best, mut at) = (f64::INFINITY, 0);
    for (i, r) in res.ritz.iter().enumerate() {
        let h = rk4_step_limit(krylov::pushed(r.value, r.residual));
        if h < best {
            (best, at) = (h, i);
        }
    }
    let r = &res.ritz[at];
    let i = (0..nd)
        .max_by(|&p, &q| r.vector[p].total_cmp(&r.vector[q]))
        .unwrap_or(0);
    let limit = StabilityLimit {
        dt_max: best,
        eigenvalue: (r.value.re, r.value.im),
        element: String::new(),
        exact: false,
    };
    Ok((limit, i))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_axis_and_imaginary_axis_limits() {
        let h = rk4_step_limit(Complex::new(-1.0, 0.0));
        assert!((h - 2.785293563405282).abs() < 1e-9, "{h}");
        let h = rk4_step_limit(Complex::new(-1e-12, 1.0));
        assert!((h - 2.0 * 2f64.sqrt()).abs() < 1e-5, "{h}");
    }

    #[test]
    fn the_reach_bounds_every_ray_of_the_left_half_plane() {
        // the region's largest |z| lies off both axes (~2.96 near 98°, where the real axis
        // gives 2.785 and the imaginary one 2√2): a finer scan of the rays stays below it
        let reach = rk4_reach();
        assert!(reach > 2.0 * 2f64.sqrt() && reach < 3.1, "{reach}");
        for k in 0..=2000 {
            let theta = std::f64::consts::FRAC_PI_2 * (1.0 + k as f64 / 2000.0);
            let h = rk4_step_limit(Complex::from_polar(1.0, theta));
            assert!(h <= reach, "{theta}: {h} > {reach}");
        }
    }
}
