//! Feeding the monitor a chunk of recorded rows: O(rows × columns) per chunk, a few numbers
//! per species and vessel kept.

use super::scan::{Table, largest, segment_vessel, worst_outside};
use super::{BOUNDS_RTOL, Chunk, Monitor, Outside, SpeciesRows, SpeciesState, Validity};

/// max(a, b) with NaN propagated (numpy's `maximum`).
fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

impl Monitor {
    /// Take the next rows of the run's output.
    pub fn update(&mut self, chunk: &Chunk<'_>) {
        if chunk.time.is_empty() {
            return;
        }
        self.t0.get_or_insert(chunk.time[0]);
        self.validity.vessels = chunk.vessels.to_vec();
        for state in &mut self.species {
            if let Some(rows) = chunk.species.iter().find(|r| r.name == state.name) {
                state.update(chunk, rows);
            }
        }
        if self.quasisteady {
            self.validity.update(chunk);
        }
    }
}

impl SpeciesState {
    fn update(&mut self, chunk: &Chunk<'_>, rows: &SpeciesRows<'_>) {
        self.po2_per_concentration = rows.po2_per_concentration;
        if let Some((lo, hi)) = self.bounds {
            let tol = BOUNDS_RTOL * lo.abs().max(hi.abs()).max(hi - lo);
            if let Some(w) = worst_of_chunk(chunk, rows, lo, hi, tol)
                && self.worst.as_ref().is_none_or(|old| w.excess > old.excess)
            {
                self.worst = Some(w);
            }
        }
        self.update_balance(chunk.time, rows);
    }

    /// The largest |Δresidual| from the first recorded row (the mass balance).
    fn update_balance(&mut self, time: &[f64], rows: &SpeciesRows<'_>) {
        let b = rows.balance;
        // stored − (inflow − outflow − wall uptake − decay), stored counted from t = 0
        let residual = |t: usize| {
            let stored = b.at(t, 0) - rows.initial_stored;
            stored - (b.at(t, 1) - b.at(t, 2) - b.at(t, 3) - b.at(t, 4))
        };
        let row = |t: usize| [b.at(t, 1), b.at(t, 2), residual(t)];
        let first = *self.first.get_or_insert_with(|| row(0));
        let mut best: Option<(usize, f64)> = None;
        let mut any_finite = false;
        for t in 0..b.rows() {
            let d = (residual(t) - first[2]).abs();
            any_finite |= d.is_finite();
            if !d.is_nan() && best.is_none_or(|(_, v)| d > v) {
                best = Some((t, d));
            }
        }
        if let Some((t, d)) = best.filter(|_| any_finite)
            && self.imbalance.is_none_or(|(old, _, _)| d > old)
        {
            self.imbalance = Some((d, time[t], residual(t) - first[2]));
        }
        self.last = row(b.rows() - 1);
    }
}

/// The recorded value of a species farthest outside [lo, hi] (beyond `tol`) in a chunk: end
/// faces, then segments, the first of equal excesses kept.
fn worst_of_chunk(
    chunk: &Chunk<'_>,
    rows: &SpeciesRows<'_>,
    lo: f64,
    hi: f64,
    tol: f64,
) -> Option<Outside> {
    let tables = rows.ends.iter().map(|t| (*t, false));
    let tables = tables.chain(rows.segments.map(|t| (t, true)));
    let mut worst: Option<Outside> = None;
    for (values, by_segment) in tables {
        let Some((t, k, v)) = worst_outside(values, lo, hi, tol) else {
            continue;
        };
        let excess = (v - hi).max(lo - v);
        if worst.as_ref().is_none_or(|w| excess > w.excess) {
            let vessel = if by_segment {
                segment_vessel(chunk.segment_count, k)
            } else {
                k
            };
            worst = Some(Outside {
                excess,
                vessel: chunk.vessels[vessel].clone(),
                time: chunk.time[t],
                value: v,
            });
        }
    }
    worst
}

impl Validity {
    fn update(&mut self, chunk: &Chunk<'_>) {
        if let Some((qi, qo)) = chunk.flows {
            self.update_flows(chunk, qi, qo);
        }
        // the oxygen species' (else the first species') segment R_i
        let ox = chunk.oxygen.or(chunk.species.first().map(|s| s.name));
        let sp = ox.and_then(|n| chunk.species.iter().find(|s| s.name == n));
        if let Some(r) = sp.and_then(|s| s.tl_resistance)
            && let Some((t, k, v)) = largest(r, f64::abs)
            && self.transit.as_ref().is_none_or(|old| v > old.0)
        {
            let vessel = &chunk.vessels[segment_vessel(chunk.segment_count, k)];
            self.transit = Some((v, vessel.clone(), chunk.time[t]));
        }
    }

    fn update_flows(&mut self, chunk: &Chunk<'_>, qi: &dyn Table, qo: &dyn Table) {
        let (rows, n) = (qi.rows(), qi.columns());
        let sum = self.flow_sum.get_or_insert_with(|| vec![0.0; n]);
        for (k, s) in sum.iter_mut().enumerate() {
            *s += (0..rows).fold(0.0, |acc, t| acc + qi.at(t, k));
        }
        // the first low-flow row of every vessel for each sign of the mean flow (+, −, 0)
        for k in 0..n {
            for (i, sign) in [1.0, -1.0, 0.0].into_iter().enumerate() {
                let low = |t: usize| qi.at(t, k) * sign <= 0.0 || qo.at(t, k) * sign <= 0.0;
                if self.low.get(&k).is_some_and(|e| e[i].is_some()) {
                    continue;
                }
                if let Some(t) = (0..rows).find(|&t| low(t)) {
                    let entry = self.low.entry(k).or_default();
                    entry[i] = Some((chunk.time[t], qi.at(t, k), qo.at(t, k)));
                }
            }
        }
        // the largest storage ratio |Q_in − Q_out| / max(|Q_in|, |Q_out|)
        let ratio = StorageRatio { qi, qo };
        if let Some((t, k, rel)) = largest(&ratio, |v| v)
            && self.storage.as_ref().is_none_or(|old| rel > old.0)
        {
            self.storage = Some((rel, chunk.vessels[k].clone(), chunk.time[t]));
        }
    }
}

/// |Q_in − Q_out| / max(|Q_in|, |Q_out|) as a table (NaN at zero flow).
struct StorageRatio<'a> {
    qi: &'a dyn Table,
    qo: &'a dyn Table,
}

impl Table for StorageRatio<'_> {
    fn rows(&self) -> usize {
        self.qi.rows()
    }
    fn columns(&self) -> usize {
        self.qi.columns()
    }
    fn at(&self, t: usize, k: usize) -> f64 {
        let (a, b) = (self.qi.at(t, k), self.qo.at(t, k));
        (a - b).abs() / nan_max(a.abs(), b.abs())
    }
}
