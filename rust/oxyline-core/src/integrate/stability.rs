//! Largest stable RK4 step of the (linear, time-invariant) flow circuit, and the element
//! that sets it. Exact from the dense spectrum for small circuits, power iteration otherwise.

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
    /// Whether the limit is exact (dense spectrum) or an estimate (power iteration).
    pub exact: bool,
}

const DENSE_LIMIT: usize = 600;

/// Largest stable RK4 step of `rk`'s circuit and the unknown (named by `names`) that sets it:
/// exact for up to `DENSE_LIMIT` differential unknowns, a power-iteration estimate beyond.
pub fn rk4_limit(rk: &mut Rk4<'_>, names: &Names) -> Result<StabilityLimit> {
    if rk.diff.is_empty() {
        return Ok(StabilityLimit {
            dt_max: f64::INFINITY,
            eigenvalue: (0.0, 0.0),
            element: "none".into(),
            exact: true,
        });
    }
    let (limit, at) = if rk.diff.len() <= DENSE_LIMIT {
        dense_limit(rk)?
    } else {
        power_limit(rk)?
    };
    Ok(StabilityLimit {
        element: names.unknown(rk.diff[at]),
        ..limit
    })
}

/// From the dense spectrum; also returns the position (in `diff`) of the unknown with the
/// largest share of the limiting mode.
fn dense_limit(rk: &mut Rk4<'_>) -> Result<(StabilityLimit, usize)> {
    let nd = rk.diff.len();
    let mut a = faer::Mat::<f64>::zeros(nd, nd);
    let mut x = vec![0.0; nd];
    let mut col = vec![0.0; nd];
    // Energy scaling x̃ = √E x (a similarity, eigenvalues unchanged): capacitances ~1e-12
    // and inertances ~1e5 otherwise spread the entries over ~20 decades, and the dense
    // eigensolver then returns spurious Re λ > 0 for lightly damped LC modes.
    let scale: Vec<f64> = rk.mass_diagonal().iter().map(|e| e.sqrt()).collect();
    for j in 0..nd {
        x.iter_mut().for_each(|v| *v = 0.0);
        x[j] = 1.0;
        rk.linear_operator(&x, &mut col)?;
        for i in 0..nd {
            a[(i, j)] = col[i] * scale[i] / scale[j];
        }
    }
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

/// Power iteration: spectral radius estimate; the RK4 region contains the left half-disc of
/// radius 2.78, so h = 2.78/ρ is stable for the passive (Re λ ≤ 0) circuits built here.
fn power_limit(rk: &mut Rk4<'_>) -> Result<(StabilityLimit, usize)> {
    let nd = rk.diff.len();
    let mut x: Vec<f64> = (0..nd)
        .map(|i| 1.0 + ((i * 7919) % 13) as f64 / 13.0)
        .collect();
    let mut y = vec![0.0; nd];
    let mut rho = 0.0f64;
    for it in 0..400 {
        rk.linear_operator(&x, &mut y)?;
        let ny = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        let nx = x.iter().map(|v| v * v).sum::<f64>().sqrt();
        if ny == 0.0 || !ny.is_finite() {
            break;
        }
        if it >= 300 {
            rho = rho.max(ny / nx);
        }
        for (a, b) in x.iter_mut().zip(&y) {
            *a = b / ny;
        }
    }
    let rho = rho * 1.05;
    let j = (0..nd)
        .max_by(|&p, &q| x[p].abs().total_cmp(&x[q].abs()))
        .unwrap_or(0);
    let limit = StabilityLimit {
        dt_max: if rho > 0.0 { 2.78 / rho } else { f64::INFINITY },
        eigenvalue: (-rho, 0.0),
        element: String::new(),
        exact: false,
    };
    Ok((limit, j))
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
}
