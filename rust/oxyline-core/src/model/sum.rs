//! Sums in the order of numpy's pairwise summation (`numpy/_core/src/umath/loops_utils.h`):
//! the formulas moved here from the Python importers keep the exact bits of the values they
//! produced there (a table's trapezoid integral, a Gauss–Legendre quadrature), so the models
//! they write are unchanged.

/// Below this many terms numpy sums in eight interleaved partial sums, above it it halves.
const BLOCK: usize = 128;

/// Σ `a` in numpy's order: a plain loop under 8 terms, eight interleaved partial sums up to
/// 128, otherwise the two halves (the first a multiple of 8) summed apart.
pub fn pairwise(a: &[f64]) -> f64 {
    let n = a.len();
    if n < 8 {
        return a.iter().fold(0.0, |s, x| s + x);
    }
    if n <= BLOCK {
        let mut r = [0.0; 8];
        r.copy_from_slice(&a[..8]);
        let whole = n - n % 8;
        for chunk in a[8..whole].chunks_exact(8) {
            for (acc, x) in r.iter_mut().zip(chunk) {
                *acc += x;
            }
        }
        let mut s = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for x in &a[whole..] {
            s += x;
        }
        return s;
    }
    let half = n / 2;
    let half = half - half % 8;
    pairwise(&a[..half]) + pairwise(&a[half..])
}

/// ∫ y dx of the table (`x`, `y`) by the trapezoid rule, as numpy's `trapezoid` evaluates it:
/// Σ (x[i+1] − x[i]) (y[i+1] + y[i]) / 2 summed pairwise.
pub fn trapezoid(x: &[f64], y: &[f64]) -> f64 {
    let terms: Vec<f64> = x
        .windows(2)
        .zip(y.windows(2))
        .map(|(x, y)| (x[1] - x[0]) * (y[1] + y[0]) / 2.0)
        .collect();
    pairwise(&terms)
}

/// The mean of a table over its span: [`trapezoid`] / (`x[last]` − `x[0]`), as numpy's
/// `np.trapezoid(y, x) / (x[-1] - x[0])` (an inflow table's cycle mean).
pub fn cycle_mean(x: &[f64], y: &[f64]) -> f64 {
    match (x.first(), x.last()) {
        (Some(first), Some(last)) => trapezoid(x, y) / (last - first),
        _ => f64::NAN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_of_integers_are_exact_at_every_size() {
        // integers below 2^53 add exactly in any order: the blocked order must lose none
        for n in [0usize, 1, 7, 8, 9, 16, 127, 128, 129, 310, 1000] {
            let a: Vec<f64> = (1..=n).map(|k| k as f64).collect();
            assert_eq!(pairwise(&a), (n * (n + 1) / 2) as f64, "n = {n}");
        }
    }

    #[test]
    fn the_trapezoid_rule_is_exact_for_a_line() {
        // ∫_0^2 (3x + 1) dx = 8, exactly representable at these nodes
        let x = [0.0, 0.5, 1.0, 1.5, 2.0];
        let y: Vec<f64> = x.iter().map(|x| 3.0 * x + 1.0).collect();
        assert_eq!(trapezoid(&x, &y), 8.0);
    }

    #[test]
    fn the_cycle_mean_of_a_half_sine_is_its_amplitude_times_two_over_pi() {
        // a half-sine of amplitude 1 over half of the span [0, 1]: ∫ = 1/π; the trapezoid
        // rule at 2001 nodes is within (Δt²/12)·max|y''| ≈ 1e-6 of it
        let x: Vec<f64> = (0..2001).map(|k| k as f64 / 2000.0).collect();
        let y: Vec<f64> = x
            .iter()
            .map(|t| {
                if *t < 0.5 {
                    (2.0 * std::f64::consts::PI * t).sin()
                } else {
                    0.0
                }
            })
            .collect();
        assert!((cycle_mean(&x, &y) - 1.0 / std::f64::consts::PI).abs() < 1e-6);
        assert!(cycle_mean(&[], &[]).is_nan());
    }

    #[test]
    fn the_order_is_numpys_not_left_to_right() {
        // 1 then fifteen 1e-16: left to right each 1e-16 is lost (below half an ulp of 1);
        // numpy's eight partial sums add the small terms among themselves first
        // (numpy 2.4: `a = np.full(16, 1e-16); a[0] = 1; a.sum()` = 1.0000000000000016)
        let mut a = vec![1e-16; 16];
        a[0] = 1.0;
        assert_eq!(a.iter().fold(0.0, |s, x| s + x), 1.0);
        assert_eq!(pairwise(&a), 1.0000000000000016);
    }

    #[test]
    fn long_sums_match_numpy_bit_for_bit() {
        // a_k = ±(1 + k mod 7)/(k + 1), minus every third: numpy 2.4's `a[:n].sum()`, which
        // differs from the left-to-right sum in the last bits at each of these sizes
        let a: Vec<f64> = (0..1000)
            .map(|k| {
                let sign = if k % 3 == 0 { -1.0 } else { 1.0 };
                (1.0 / (k as f64 + 1.0)) * sign * (1.0 + (k % 7) as f64)
            })
            .collect();
        for (n, numpy) in [
            (100, 4.402272456999389),
            (310, 5.93119776431313),
            (1000, 7.497469283046745),
        ] {
            assert_eq!(pairwise(&a[..n]), numpy, "n = {n}");
            assert_ne!(a[..n].iter().fold(0.0, |s, x| s + x), numpy);
        }
    }
}
