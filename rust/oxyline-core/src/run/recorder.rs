//! The output table under construction, and the sink that streams it during the run.

use crate::error::{Error, Result, try_reserve};

/// Output rows handed to an [`OutputSink`]: `times.len()` rows of the recorded unknowns
/// (row-major, time × probe) and, for transport runs, of the species outputs (row-major,
/// time × species columns as in [`super::TransportOutcome::data`]; NaN rows where the run
/// stopped before they were computed).
pub struct Chunk<'a> {
    pub times: &'a [f64],
    pub data: &'a [f64],
    /// Empty for flow-only runs.
    pub transport: &'a [f64],
    /// Σ N of each species at t = 0 (the mass-balance reference; empty for flow-only runs).
    pub initial_stored: &'a [f64],
}

/// Streams the output instead of collecting it: the driver hands every `rows` output rows to
/// `write` as soon as they are certain to be part of the output and then forgets them, so a
/// long all-cycles run holds at most one chunk. Last-cycle output holds at most one cycle, as
/// without a sink: the rows of a cycle that may be superseded (with `until_periodic`, or an
/// interrupted run's partial cycle) are handed over once they are known to be the output.
/// When the run stops early (error or interruption) the rows recorded so far are handed over
/// in a last, shorter chunk. `write` returning false stops the run as an interruption and is
/// not called again.
pub struct OutputSink<'a> {
    pub rows: usize,
    pub write: &'a mut dyn FnMut(Chunk<'_>) -> bool,
}

/// The output table under construction: flow probes and species outputs of the same rows,
/// optionally streamed to a sink.
pub(super) struct Recorder<'p, 's, 'f> {
    probes: &'p [usize],
    pub times: Vec<f64>,
    pub data: Vec<f64>,
    /// Species columns, one row per `observe` call (0 for flow-only runs).
    transport_cols: usize,
    pub transport: Vec<f64>,
    /// Selected columns of every species block of `block` columns (None: all).
    species_select: Option<&'p [usize]>,
    block: usize,
    /// Columns of each species block the rows leave out (first, count: the per-segment columns
    /// nobody records, `Transport::unwritten_columns`): a row's block is `block - count` long.
    unwritten: (usize, usize),
    /// Σ N of each species at t = 0, handed to the sink with every chunk.
    pub initial_stored: Vec<f64>,
    sink: Option<&'s mut OutputSink<'f>>,
    /// Most rows held at once.
    pub max_rows: usize,
    /// Columns after the probes (svZeroDSolver's derived columns and rates: `record_extra`).
    extra: usize,
}

impl<'p, 's, 'f> Recorder<'p, 's, 'f> {
    /// A recorder of the `probes` and, for a transport run with `species` (number of species,
    /// columns per species of `Transport::observe`), of the `species_columns` of each species
    /// block (all when None).
    pub fn new(
        probes: &'p [usize],
        species: Option<(usize, usize)>,
        species_columns: Option<&'p [usize]>,
        initial_stored: Vec<f64>,
        sink: Option<&'s mut OutputSink<'f>>,
    ) -> Result<Self> {
        let (n_species, block) = species.unwrap_or((0, 0));
        // the flow-only first pass of a transport run has no species to select
        let species_select = species_columns.filter(|_| species.is_some());
        if let Some(&c) = species_select.and_then(|sel| sel.iter().find(|&&c| c >= block)) {
            return Err(Error::model(
                "simulation output",
                format!("species column {c} out of range (0..{block})"),
            ));
        }
        let kept = species_select.map_or(block, <[usize]>::len);
        Ok(Recorder {
            probes,
            times: Vec::new(),
            data: Vec::new(),
            transport_cols: n_species * kept,
            transport: Vec::new(),
            species_select,
            block,
            unwritten: (0, 0),
            initial_stored,
            sink,
            max_rows: 0,
            extra: 0,
        })
    }

    /// Record `extra` more columns per row, after the probes (see `record_extra`).
    pub fn with_extra_columns(mut self, extra: usize) -> Self {
        self.extra = extra;
        self
    }

    /// The species rows handed to `push_species` leave out `count` columns of each block from
    /// column `first` on (`Transport::unwritten_columns`); they are recorded as NaN if selected.
    pub fn with_unwritten_species_columns(mut self, (first, count): (usize, usize)) -> Self {
        if first + count <= self.block {
            self.unwritten = (first, count);
        }
        self
    }

    /// Values per row: the probes and the extra columns.
    fn width(&self) -> usize {
        self.probes.len() + self.extra
    }

    /// Make room for `rows` rows at once (the whole table is then one allocation of its final
    /// size, not grown by doubling). Nothing with a sink, which holds at most a chunk.
    /// The allocation is fallible: a table the memory left cannot hold is a typed
    /// [`Error::Resource`], not an abort.
    pub fn reserve_rows(&mut self, rows: usize) -> Result<()> {
        if self.sink.is_none() {
            self.reserve(rows)?;
        }
        Ok(())
    }

    /// Room for `rows` more rows of every table (fallible).
    fn reserve(&mut self, rows: usize) -> Result<()> {
        let np = self.width();
        try_reserve(&mut self.times, rows, "output times")?;
        try_reserve(&mut self.data, rows.saturating_mul(np), "output rows")?;
        try_reserve(
            &mut self.transport,
            rows.saturating_mul(self.transport_cols),
            "species output rows",
        )
    }

    /// Values per row (the probes and the extra columns).
    pub fn n_probes(&self) -> usize {
        self.width()
    }

    /// Recorded columns per species.
    pub fn columns_per_species(&self) -> usize {
        self.species_select.map_or(self.block, <[usize]>::len)
    }

    /// Rows the tables first make room for: 64, or a sink's chunk if smaller (a sink takes
    /// the rows chunk by chunk: 64 rows of a 262 k-segment model's summary were 101 MB and
    /// 67 MB of heap, the flow and species tables, that a 16 MB chunk never used).
    fn first_rows(&self) -> usize {
        self.sink.as_ref().map_or(64, |s| s.rows.clamp(1, 64))
    }

    /// Record one row; the tables grow by doubling, with fallible allocation.
    pub fn record(&mut self, t: f64, y: &[f64]) -> Result<()> {
        if self.times.len() == self.times.capacity() {
            self.reserve(self.times.len().max(self.first_rows()))?;
        }
        self.times.push(t);
        self.data.extend(self.probes.iter().map(|&i| y[i]));
        self.max_rows = self.max_rows.max(self.times.len());
        Ok(())
    }

    /// The extra columns of the row just recorded (exactly `extra` values).
    pub fn record_extra(&mut self, values: impl Iterator<Item = f64>) {
        self.data.extend(values.take(self.extra));
    }

    /// Record one row whose value of unknown `i` is `value(i)` (dense output: only the
    /// probes are interpolated).
    pub fn record_with(&mut self, t: f64, value: impl Fn(usize) -> f64) -> Result<()> {
        if self.times.len() == self.times.capacity() {
            self.reserve(self.times.len().max(self.first_rows()))?;
        }
        self.times.push(t);
        self.data.extend(self.probes.iter().map(|&i| value(i)));
        self.max_rows = self.max_rows.max(self.times.len());
        Ok(())
    }

    /// Record one row that `fill` appends to the table from the probes (dense output: the
    /// interpolant's weights applied to all the probes in one pass).
    pub fn record_row(&mut self, t: f64, fill: impl FnOnce(&[usize], &mut Vec<f64>)) -> Result<()> {
        if self.times.len() == self.times.capacity() {
            self.reserve(self.times.len().max(self.first_rows()))?;
        }
        self.times.push(t);
        fill(self.probes, &mut self.data);
        self.max_rows = self.max_rows.max(self.times.len());
        Ok(())
    }

    /// Keep the selected columns of one `observe` row (all species blocks); the unwritten
    /// columns read as NaN.
    pub fn push_species(&mut self, row: &[f64]) {
        let (first, count) = self.unwritten;
        let written = (self.block - count).max(1);
        match self.species_select {
            None if count == 0 => self.transport.extend_from_slice(row),
            None => {
                for b in row.chunks(written) {
                    self.transport.extend_from_slice(&b[..first]);
                    self.transport.extend(std::iter::repeat_n(f64::NAN, count));
                    self.transport.extend_from_slice(&b[first..]);
                }
            }
            Some(sel) => {
                let after = first + count;
                for b in row.chunks(written) {
                    self.transport.extend(sel.iter().map(|&c| match c {
                        c if c < first => b[c],
                        c if c >= after => b[c - count],
                        _ => f64::NAN,
                    }));
                }
            }
        }
    }

    /// The rows and Σ N(0) of a checkpoint (see `Cycles::restore`).
    pub fn restore(&mut self, snap: &super::checkpoint::Snapshot) -> Result<()> {
        let np = self.width();
        let rows = snap.times.len();
        // species rows may be fewer (cycles whose species outputs are not computed)
        let nt = snap.transport_rows.len();
        let species_ok = match self.transport_cols {
            0 => nt == 0,
            c => nt % c == 0 && nt <= rows * c,
        };
        if snap.data.len() != rows * np || !species_ok {
            return Err(Error::model(
                "checkpoint",
                "its output rows do not have this run's columns: the checkpoint is of another \
                 model or output selection",
            ));
        }
        self.clear();
        self.reserve(rows)?;
        self.times.extend_from_slice(&snap.times);
        self.data.extend_from_slice(&snap.data);
        self.transport.extend_from_slice(&snap.transport_rows);
        self.initial_stored.clone_from(&snap.initial_stored);
        self.max_rows = self.max_rows.max(rows);
        Ok(())
    }

    pub fn clear(&mut self) {
        self.times.clear();
        self.data.clear();
        self.transport.clear();
    }

    /// One species row per flow row: rows the run stopped before computing (an error in
    /// `observe`, or an interruption in a cycle whose species outputs were being skipped)
    /// become NaN, so the two tables always describe the same times.
    pub fn align(&mut self) {
        if self.transport_cols > 0 {
            self.transport
                .resize(self.times.len() * self.transport_cols, f64::NAN);
        }
    }

    /// Hand the buffered rows to the sink in chunks of `rows`: only whole chunks unless `all`.
    /// Returns false if the sink stopped the run (it is then dropped, the rows kept).
    pub fn flush(&mut self, all: bool) -> bool {
        if self.sink.is_none() {
            return true;
        }
        self.align();
        let Some(sink) = self.sink.as_deref_mut() else {
            return true;
        };
        let rows = sink.rows.max(1);
        let n = self.times.len();
        if !all && n < rows {
            return true;
        }
        let end = if all { n } else { n - n % rows };
        let (np, nc) = (self.probes.len() + self.extra, self.transport_cols);
        let mut done = 0;
        while done < end {
            let upto = (done + rows).min(end);
            let ok = (sink.write)(Chunk {
                times: &self.times[done..upto],
                data: &self.data[done * np..upto * np],
                transport: &self.transport[done * nc..upto * nc],
                initial_stored: &self.initial_stored,
            });
            if !ok {
                self.sink = None;
                break;
            }
            done = upto;
        }
        self.times.drain(..done);
        self.data.drain(..done * np);
        self.transport.drain(..done * nc);
        self.sink.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two species blocks of 8 columns, columns 2..6 not written: the rows handed over hold
    /// 4 values per block. Expected records written out by hand: a selected column reads its
    /// own value, the unwritten ones NaN, for a selection and for every column.
    #[test]
    fn unwritten_species_columns_are_recorded_in_place() {
        let probes: [usize; 0] = [];
        // block k: columns 0, 1, 6, 7 hold 10k + column
        let row = [0.0, 1.0, 6.0, 7.0, 10.0, 11.0, 16.0, 17.0];
        let sel = [7, 0, 3];
        let mut rec = Recorder::new(&probes, Some((2, 8)), Some(&sel), Vec::new(), None)
            .unwrap()
            .with_unwritten_species_columns((2, 4));
        rec.push_species(&row);
        let got = &rec.transport;
        assert_eq!(got.len(), 6);
        assert_eq!([got[0], got[1], got[3], got[4]], [7.0, 0.0, 17.0, 10.0]);
        assert!(got[2].is_nan() && got[5].is_nan());

        let mut all = Recorder::new(&probes, Some((2, 8)), None, Vec::new(), None)
            .unwrap()
            .with_unwritten_species_columns((2, 4));
        all.push_species(&row);
        let want = [0.0, 1.0, f64::NAN, f64::NAN, f64::NAN, f64::NAN, 6.0, 7.0];
        for (k, block) in all.transport.chunks(8).enumerate() {
            for (c, (&g, &w)) in block.iter().zip(&want).enumerate() {
                let w = if w.is_nan() { w } else { w + 10.0 * k as f64 };
                assert!(
                    g == w || (g.is_nan() && w.is_nan()),
                    "block {k} column {c}: {g}"
                );
            }
        }
        assert_eq!(all.transport.len(), 16);
    }

    /// A sink takes the rows five at a time: the tables hold room for one chunk, not 64 rows
    /// (64 rows of a 262 k-segment summary were 101 MB of heap), and every row
    /// reaches the sink once, in order.
    #[test]
    fn a_sinks_tables_hold_one_chunk() {
        let probes = [0usize, 1, 2];
        let mut got: Vec<(f64, f64)> = Vec::new();
        let mut write = |c: Chunk<'_>| -> bool {
            got.extend(
                c.times
                    .iter()
                    .zip(c.data.chunks(3))
                    .map(|(&t, r)| (t, r[2])),
            );
            true
        };
        let mut sink = OutputSink {
            rows: 5,
            write: &mut write,
        };
        let mut rec = Recorder::new(&probes, None, None, Vec::new(), Some(&mut sink)).unwrap();
        for k in 0..12 {
            let t = k as f64;
            rec.record(t, &[0.0, 1.0, 2.0 * t]).unwrap();
            assert!(rec.flush(false));
            assert!(rec.times.capacity() <= 5 && rec.data.capacity() <= 15);
        }
        assert!(rec.flush(true));
        drop(rec);
        let want: Vec<(f64, f64)> = (0..12).map(|k| (k as f64, 2.0 * k as f64)).collect();
        assert_eq!(got, want);
    }
}
