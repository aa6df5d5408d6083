//! Prescribed wall fluxes that vary in time: a `flux` wall given as a time table (per vessel,
//! uniform or per segment; docs/physics.md §3.1 C1). The fixed part of the wall laws
//! (`cell_q`, `cell_wc`) of the cells they touch is set to the table's value at the time of
//! every right-hand side, implicit step and observation, so the wall-uptake accumulator and
//! the cell balances see the same flux and the mass balance stays exact.

#[allow(unused_imports)]
use super::*;
use crate::closure::FluxSpec;

/// One vessel's flux table, as it acts on the cells.
#[derive(Debug, Clone)]
struct FluxTable {
    time: Vec<f64>,
    /// `rows[k * width + col]`: the flux (mol m⁻² s⁻¹) at `time[k]` of column `col`.
    rows: Vec<f64>,
    width: usize,
    /// Every wall piece of the vessel.
    pieces: Vec<TimedPiece>,
}

/// A wall piece whose flux follows a table.
#[derive(Debug, Clone, Copy)]
struct TimedPiece {
    piece: u32,
    cell: u32,
    share: f64,
    /// Lumen wall area of the piece (m²).
    area: f64,
    column: u32,
}

/// The flux tables of one species.
#[derive(Debug, Clone)]
pub(super) struct FluxTables {
    tables: Vec<FluxTable>,
    /// The cells the tables act on, and their time-independent Σ share·q.
    cells: Vec<u32>,
    base_q: Vec<f64>,
}

/// Collects the wall pieces of the vessels whose flux is a time table.
pub(super) struct TableBuilder {
    of_vessel: Vec<u32>,
    tables: Vec<FluxTable>,
}

impl TableBuilder {
    pub(super) fn new(n_vessels: usize) -> Self {
        TableBuilder {
            of_vessel: vec![u32::MAX; n_vessels],
            tables: Vec::new(),
        }
    }

    /// Wall piece `p` (with its wall) of `vessel` on segment `index` of the vessel; `flux`
    /// holds a table (validated: width 1 or the vessel's segment count).
    pub(super) fn add(
        &mut self,
        vessel: usize,
        flux: &FluxSpec,
        (p, piece, wall): (usize, &Piece, SegmentWall),
        index: usize,
    ) {
        let Some((time, values)) = flux.table() else {
            return;
        };
        if self.of_vessel[vessel] == u32::MAX {
            self.of_vessel[vessel] = self.tables.len() as u32;
            self.tables.push(FluxTable {
                time: time.to_vec(),
                rows: values.iter().flatten().copied().collect(),
                width: flux.width(),
                pieces: Vec::new(),
            });
        }
        let t = &mut self.tables[self.of_vessel[vessel] as usize];
        t.pieces.push(TimedPiece {
            piece: p as u32,
            cell: piece.cell,
            share: piece.share,
            area: wall.area(),
            column: flux.column(index) as u32,
        });
    }

    /// The tables, with the fixed flux `cell_q` of the cells they touch (None: no table).
    pub(super) fn finish(self, cell_q: &[f64]) -> Option<Arc<FluxTables>> {
        if self.tables.is_empty() {
            return None;
        }
        let mut cells: Vec<u32> = self
            .tables
            .iter()
            .flat_map(|t| t.pieces.iter().map(|p| p.cell))
            .collect();
        cells.sort_unstable();
        cells.dedup();
        let base_q = cells.iter().map(|&c| cell_q[c as usize]).collect();
        Some(Arc::new(FluxTables {
            tables: self.tables,
            cells,
            base_q,
        }))
    }
}

impl FluxTables {
    /// Set the pieces' fixed flux, and `cell_q`, `cell_wc` of the touched cells, to their
    /// values at `time` (linear in time, each table repeating with its own length like the
    /// inlet tables).
    fn apply(&self, time: f64, laws: &mut Laws) {
        for (&c, &b) in self.cells.iter().zip(&self.base_q) {
            laws.cell_q[c as usize] = b;
        }
        for t in &self.tables {
            let (k, a, b, _) = crate::waveform::table_locate(&t.time, time);
            let lo = &t.rows[(k - 1) * t.width..k * t.width];
            let hi = &t.rows[k * t.width..(k + 1) * t.width];
            for tp in &t.pieces {
                let col = tp.column as usize;
                let q = tp.area * (a * lo[col] + b * hi[col]);
                // the piece's own law (observation reads it) and its cell's sum
                laws.laws[tp.piece as usize] = SegmentLaw::Fixed { g: 0.0, cw: 0.0, q };
                laws.cell_q[tp.cell as usize] += tp.share * q;
            }
        }
        for &c in &self.cells {
            let c = c as usize;
            laws.cell_wc[c] = laws.cell_q[c] - laws.cell_gcw[c];
        }
    }

    pub(super) fn heap_bytes(&self) -> usize {
        let f = std::mem::size_of::<f64>();
        self.tables
            .iter()
            .map(|t| {
                (t.time.capacity() + t.rows.capacity()) * f
                    + t.pieces.capacity() * std::mem::size_of::<TimedPiece>()
            })
            .sum::<usize>()
            + self.cells.capacity() * 4
            + self.base_q.capacity() * f
    }
}

impl Transport {
    /// Hook of the stepping code: the prescribed time-table wall fluxes at `time` (a no-op
    /// without tables). The laws are copied once per run on the first call (copy on write).
    #[inline]
    pub(super) fn update_wall_flux(&mut self, time: f64) {
        for sp in &mut self.species {
            let Some(tables) = sp.laws.flux_tables.clone() else {
                continue;
            };
            tables.apply(time, Arc::make_mut(&mut sp.laws));
        }
    }
}
