//! Scans of one chunk of recorded rows: the value farthest outside a range, the largest value
//! of a table. Row-major, the first of equal values kept (the earliest time, then the lowest
//! column), so that a run fed in chunks finds what it finds fed whole.

/// A (time, column) table of recorded values, read in place (a view of the output's rows).
pub trait Table {
    fn rows(&self) -> usize;
    fn columns(&self) -> usize;
    fn at(&self, t: usize, k: usize) -> f64;
}

/// (time index, column, value) of the value farthest outside [lo − tol, hi + tol], or None
/// when every value (NaN passed over) lies inside.
pub fn worst_outside(
    values: &dyn Table,
    lo: f64,
    hi: f64,
    tol: f64,
) -> Option<(usize, usize, f64)> {
    let (upper, lower) = (hi + tol, lo - tol);
    let mut best: Option<(f64, usize, usize, f64)> = None;
    for t in 0..values.rows() {
        for k in 0..values.columns() {
            let v = values.at(t, k);
            let excess = (v - upper).max(lower - v);
            // NaN never compares greater: a NaN value is passed over
            if excess > 0.0 && best.is_none_or(|b| excess > b.0) {
                best = Some((excess, t, k, v));
            }
        }
    }
    best.map(|(_, t, k, v)| (t, k, v))
}

/// (time index, column, value) of the largest of `f(value)` over the table (NaN passed over;
/// +inf counts), or None when no value is finite.
pub fn largest(values: &dyn Table, f: impl Fn(f64) -> f64) -> Option<(usize, usize, f64)> {
    let mut best: Option<(usize, usize, f64)> = None;
    let mut any_finite = false;
    for t in 0..values.rows() {
        for k in 0..values.columns() {
            let v = f(values.at(t, k));
            any_finite |= v.is_finite();
            if !v.is_nan() && best.is_none_or(|b| v > b.2) {
                best = Some((t, k, v));
            }
        }
    }
    best.filter(|_| any_finite)
}

/// The vessel of recorded segment column `k`, given the recorded segments per vessel.
pub fn segment_vessel(segment_count: &[usize], k: usize) -> usize {
    let mut end = 0;
    for (i, n) in segment_count.iter().enumerate() {
        end += n;
        if k < end {
            return i;
        }
    }
    segment_count.len()
}

/// A row-major (time, column) table in a slice (tests, and callers holding contiguous rows).
pub struct RowMajor<'a> {
    pub data: &'a [f64],
    pub columns: usize,
}

impl Table for RowMajor<'_> {
    fn rows(&self) -> usize {
        self.data.len().checked_div(self.columns).unwrap_or(0)
    }
    fn columns(&self) -> usize {
        self.columns
    }
    fn at(&self, t: usize, k: usize) -> f64 {
        self.data[t * self.columns + k]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_worst_value_is_the_farthest_outside_and_the_first_of_ties() {
        let data = [1.0, 5.0, f64::NAN, -2.0, 5.0, 0.5];
        let t = RowMajor {
            data: &data,
            columns: 3,
        };
        // excess 1.0 at (0, 1) and (1, 1), 2.0 at (1, 0): the value −2
        assert_eq!(worst_outside(&t, 0.0, 4.0, 0.0), Some((1, 0, -2.0)));
        assert_eq!(worst_outside(&t, -3.0, 4.0, 0.0), Some((0, 1, 5.0)));
        assert_eq!(worst_outside(&t, -3.0, 5.0, 1e-6), None);
    }

    #[test]
    fn the_largest_value_passes_over_nan_and_needs_a_finite_one() {
        let data = [f64::NAN, 3.0, 3.0, f64::INFINITY];
        let t = RowMajor {
            data: &data,
            columns: 2,
        };
        assert_eq!(largest(&t, f64::abs), Some((1, 1, f64::INFINITY)));
        let none = [f64::NAN, f64::INFINITY];
        assert_eq!(
            largest(
                &RowMajor {
                    data: &none,
                    columns: 2
                },
                f64::abs
            ),
            None
        );
        assert_eq!(segment_vessel(&[2, 0, 3], 1), 0);
        assert_eq!(segment_vessel(&[2, 0, 3], 2), 2);
    }
}
