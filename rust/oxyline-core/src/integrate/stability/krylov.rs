//! Restarted Arnoldi (Krylov–Schur style thick restart, real arithmetic) for the few
//! eigenvalues of a large real operator that maximise a user weight — for the RK4 bound, the
//! eigenvalues that leave the RK4 stability region first. Only matrix-vector products are
//! needed, so the operator may include a sparse elimination (the algebraic unknowns).
//!
//! Restart: the wanted Ritz vectors (real and imaginary parts of each conjugate pair, which span
//! a real invariant subspace of the projected matrix H) are orthonormalised into Q, the basis
//! becomes V Q, H becomes Qᵀ H Q with the old residual direction as the next basis vector and
//! `β Qᵀ e_m` as its coupling row. The Arnoldi relation A V_m = V_m H_m + β v_{m+1} e_mᵀ then
//! holds after every expansion, so the Ritz residual ‖A x − θ x‖ = β |e_mᵀ y| stays available.

use crate::error::{Error, Result};
use faer::Mat;
use nalgebra::Complex;

/// y = A x of the operator whose eigenvalues are sought.
pub type Operator<'a> = dyn FnMut(&[f64], &mut [f64]) -> Result<()> + 'a;

/// A Ritz value θ (≈ eigenvalue), its residual ‖A x − θ x‖ (x = V y, ‖x‖ = 1) and the Ritz
/// vector's component magnitudes |x_i|.
pub struct Ritz {
    pub value: Complex<f64>,
    pub residual: f64,
    pub vector: Vec<f64>,
}

/// Krylov dimension, number of conjugate-pair Ritz values kept at a restart, restart cap.
pub struct KrylovControl {
    pub dim: usize,
    pub keep: usize,
    pub max_restarts: usize,
    /// Stop when the weight of every kept Ritz value pushed outward by its residual is within
    /// this relative amount of the largest weight of the un-pushed Ritz values.
    pub tol: f64,
}

impl Default for KrylovControl {
    fn default() -> Self {
        KrylovControl {
            dim: 48,
            keep: 10,
            max_restarts: 300,
            tol: 1e-3,
        }
    }
}

/// Result of [`largest_by`]: the kept Ritz values (Im θ ≥ 0), best weight first. At the
/// restart cap the stopping test may not have passed: the residual push still makes the
/// reported values conservative for a near-normal operator, only less tight.
pub struct KrylovResult {
    pub ritz: Vec<Ritz>,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// θ pushed outward (away from the origin) by r: |θ| → |θ| + r along the same ray. For a normal
/// operator the disc of radius r about θ holds an eigenvalue; the outward point is the worst one.
pub fn pushed(value: Complex<f64>, r: f64) -> Complex<f64> {
    let m = value.norm();
    if m == 0.0 {
        Complex::new(-r, 0.0)
    } else {
        value * ((m + r) / m)
    }
}

/// Gram–Schmidt of `w` against `basis`, twice (CGS2: orthogonal to working precision); the
/// coefficients summed over both passes go to `coef`.
fn orthogonalise(basis: &[Vec<f64>], w: &mut [f64], coef: &mut [f64]) {
    coef.iter_mut().for_each(|c| *c = 0.0);
    for _ in 0..2 {
        for (c, v) in coef.iter_mut().zip(basis) {
            let h = dot(v, w);
            *c += h;
            w.iter_mut().zip(v).for_each(|(wi, vi)| *wi -= h * vi);
        }
    }
}

/// The `control.keep` conjugate-pair eigenvalue estimates of `op` (an n×n real operator) with
/// the largest `weight`, by restarted Arnoldi from a fixed pseudo-random start vector.
pub fn largest_by(
    n: usize,
    op: &mut Operator<'_>,
    weight: &dyn Fn(Complex<f64>) -> f64,
    control: &KrylovControl,
) -> Result<KrylovResult> {
    let m = control.dim.min(n).max(1);
    // deterministic, non-smooth start: no eigenvector of a regular chain is orthogonal to it
    let mut v0: Vec<f64> = (0..n)
        .map(|i| {
            let h = (i as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 11;
            h as f64 / (1u64 << 53) as f64 - 0.5
        })
        .collect();
    let nv = norm(&v0);
    v0.iter_mut().for_each(|x| *x /= nv);
    let mut basis = vec![v0];
    let mut h = Mat::<f64>::zeros(m + 1, m);
    let mut start = 0usize;
    let mut w = vec![0.0; n];
    let mut coef = vec![0.0; m + 1];
    for restart in 0..=control.max_restarts {
        // expand to m columns (or stop at an invariant subspace)
        let mut size = m;
        for j in start..m {
            op(&basis[j], &mut w)?;
            orthogonalise(&basis, &mut w, &mut coef[..=j]);
            for (i, c) in coef[..=j].iter().enumerate() {
                h[(i, j)] = *c;
            }
            let beta = norm(&w);
            h[(j + 1, j)] = beta;
            let scale = coef[..=j].iter().fold(beta, |a, c| a.max(c.abs()));
            if !beta.is_finite() {
                return Err(Error::solver(0.0, "stability: non-finite Krylov vector"));
            }
            if beta <= 1e-13 * scale || j + 1 == n {
                size = j + 1; // invariant subspace: its Ritz values are eigenvalues
                break;
            }
            basis.push(w.iter().map(|x| x / beta).collect());
        }
        let beta = if size < m || size == n {
            0.0
        } else {
            h[(m, m - 1)]
        };
        let ritz = ritz_pairs(&h, size, beta, weight)?;
        let kept: Vec<usize> = ritz.order.iter().copied().take(control.keep).collect();
        let best = weight(ritz.values[kept[0]]);
        let worst_pushed = kept
            .iter()
            .map(|&i| weight(pushed(ritz.values[i], ritz.residuals[i])))
            .fold(0.0, f64::max);
        let converged = beta == 0.0 || worst_pushed <= best * (1.0 + control.tol);
        if converged || restart == control.max_restarts {
            let ritz = kept
                .iter()
                .map(|&i| Ritz {
                    value: ritz.values[i],
                    residual: ritz.residuals[i],
                    vector: ritz_vector(&basis[..size], &ritz.vectors, i),
                })
                .collect();
            return Ok(KrylovResult { ritz });
        }
        start = thick_restart(&mut basis, &mut h, &ritz, &kept, m);
    }
    unreachable!("the loop returns at its last restart")
}

/// Ritz values of the leading `size` × `size` block of `h`, their residuals β|e_mᵀ y| and
/// the indices with Im θ ≥ 0 ordered by decreasing weight.
struct RitzPairs {
    values: Vec<Complex<f64>>,
    residuals: Vec<f64>,
    vectors: Mat<faer::c64>,
    order: Vec<usize>,
}

fn ritz_pairs(
    h: &Mat<f64>,
    size: usize,
    beta: f64,
    weight: &dyn Fn(Complex<f64>) -> f64,
) -> Result<RitzPairs> {
    let hm = Mat::<f64>::from_fn(size, size, |i, j| h[(i, j)]);
    let evd = hm
        .eigen()
        .map_err(|e| Error::solver(0.0, format!("stability: Ritz values: {e:?}")))?;
    let (s, u) = (evd.S(), evd.U());
    let mut vectors = Mat::<faer::c64>::zeros(size, size);
    let mut values = Vec::with_capacity(size);
    let mut residuals = Vec::with_capacity(size);
    for j in 0..size {
        let nrm = (0..size).map(|i| u[(i, j)].norm_sqr()).sum::<f64>().sqrt();
        for i in 0..size {
            vectors[(i, j)] = u[(i, j)] / nrm;
        }
        values.push(Complex::new(s[j].re, s[j].im));
        residuals.push(beta * vectors[(size - 1, j)].norm());
    }
    let mut order: Vec<usize> = (0..size).filter(|&j| values[j].im >= 0.0).collect();
    order.sort_by(|&a, &b| weight(values[b]).total_cmp(&weight(values[a])));
    Ok(RitzPairs {
        values,
        residuals,
        vectors,
        order,
    })
}

/// |x_i| of the Ritz vector x = V y (complex y).
fn ritz_vector(basis: &[Vec<f64>], y: &Mat<faer::c64>, j: usize) -> Vec<f64> {
    let n = basis[0].len();
    let (mut re, mut im) = (vec![0.0; n], vec![0.0; n]);
    for (i, v) in basis.iter().enumerate() {
        let c = y[(i, j)];
        for ((r, q), x) in re.iter_mut().zip(im.iter_mut()).zip(v) {
            *r += c.re * x;
            *q += c.im * x;
        }
    }
    re.iter().zip(&im).map(|(r, q)| r.hypot(*q)).collect()
}

/// Keep the span of the `kept` Ritz vectors (real and imaginary parts): rewrites `basis` and
/// `h` in place and returns the column where the expansion resumes.
fn thick_restart(
    basis: &mut Vec<Vec<f64>>,
    h: &mut Mat<f64>,
    ritz: &RitzPairs,
    kept: &[usize],
    m: usize,
) -> usize {
    let beta = h[(m, m - 1)];
    // real basis of the kept invariant subspace of H, orthonormalised (MGS, twice)
    let mut q: Vec<Vec<f64>> = Vec::new();
    for &j in kept {
        let parts: &[fn(faer::c64) -> f64] = if ritz.values[j].im.abs() > 0.0 {
            &[|c| c.re, |c| c.im]
        } else {
            &[|c| c.re]
        };
        for part in parts {
            let mut z: Vec<f64> = (0..m).map(|i| part(ritz.vectors[(i, j)])).collect();
            let before = norm(&z);
            let mut coef = vec![0.0; q.len()];
            orthogonalise(&q, &mut z, &mut coef);
            let after = norm(&z);
            if after > 1e-8 * before && q.len() + 1 < m {
                q.push(z.iter().map(|x| x / after).collect());
            }
        }
    }
    let k = q.len();
    // new basis V Q, then the old residual direction v_{m+1}
    let n = basis[0].len();
    let mut new_basis: Vec<Vec<f64>> = (0..k)
        .map(|c| {
            let mut x = vec![0.0; n];
            for (i, v) in basis[..m].iter().enumerate() {
                let w = q[c][i];
                x.iter_mut().zip(v).for_each(|(a, b)| *a += w * b);
            }
            x
        })
        .collect();
    new_basis.push(basis[m].clone());
    *basis = new_basis;
    // T = Qᵀ H Q and the coupling row β Qᵀ e_m
    let hq: Vec<Vec<f64>> = (0..k)
        .map(|c| {
            (0..m)
                .map(|i| (0..m).map(|l| h[(i, l)] * q[c][l]).sum())
                .collect()
        })
        .collect();
    let mut t = Mat::<f64>::zeros(m + 1, m);
    for r in 0..k {
        for c in 0..k {
            t[(r, c)] = dot(&q[r], &hq[c]);
        }
        t[(k, r)] = beta * q[r][m - 1];
    }
    *h = t;
    k
}
