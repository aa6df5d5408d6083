//! Physical-bounds monitor of the recorded species output (docs/physics.md §2.8), on the
//! output side of a run: fed the recorded rows chunk by chunk (a whole in-memory run is one
//! chunk, a streamed run the chunks it hands over, an ensemble variant its rows), it keeps a
//! few numbers per species and vessel between chunks, never the output, and finds the same
//! whether fed whole or in chunks. The checks:
//!
//! * **Maximum principle.** For a species without sources (no prescribed `flux` wall; decay
//!   only lowers concentrations) every free concentration lies in [min, max] of its inlet,
//!   backflow, initial and wall values ([`bounds::species_bounds`], computed once from the
//!   model). A recorded value outside, beyond [`BOUNDS_RTOL`] of that range, is reported with
//!   its vessel, time and value.
//! * **Mass balance.** The residual stored − (inflow − outflow − wall uptake − decay) over the
//!   recorded window beyond [`BALANCE_RTOL`] of the window's throughput (network-wide).
//! * **`tl-quasisteady`** (the paper read literally, docs/physics.md §2.7): where the run
//!   leaves the range in which a quasi-steady line holds.

pub mod bounds;
pub mod scan;
pub mod text;

pub use bounds::{species_bounds, waveform_range};
pub use scan::{RowMajor, Table};

use crate::error::Result;
use crate::model::transport::{Formulation, TransportSpec};
use text::format_g;

/// Tolerance of the maximum-principle check, relative to the largest bound magnitude: the
/// conservative scheme is monotone (upwind fluxes; backward Euler is an M-matrix; RK4 runs far
/// below its positivity limit), so only round-off (~1e-15) and the Hill inversion (1e-12 mmHg)
/// move values past a bound.
pub const BOUNDS_RTOL: f64 = 1e-6;
/// Tolerance of the mass balance, relative to the throughput of the recorded window (the
/// larger of its in- and outflow): the conservative formulation keeps it to ~1e-14
/// (docs/physics.md §2.5).
pub const BALANCE_RTOL: f64 = 1e-6;
/// tl-quasisteady validity (docs/physics.md §2.7): the segment transit time L_i = −dx/v must
/// change slowly, |R_i| = |dL_i/dt| below this ...
pub const QS_TRANSIT_RATE: f64 = 0.1;
/// ... and a vessel's compliant storage flow |Q_in − Q_out| must be below this fraction of its
/// flow (the literal form has no storage term: c_i = J_i/Q_i is off by about that fraction).
pub const QS_STORAGE: f64 = 1e-3;

/// One species' recorded rows of a chunk (free concentrations in mol/m³).
pub struct SpeciesRows<'a> {
    pub name: &'a str,
    /// The recorded end-face concentrations (`concentration_in`, `concentration_out`),
    /// (time, vessel) each.
    pub ends: Vec<&'a dyn Table>,
    /// The recorded segment concentrations (time, segment), if any segment is recorded.
    pub segments: Option<&'a dyn Table>,
    /// The recorded segment `tl_resistance` R_i (time, segment), if any.
    pub tl_resistance: Option<&'a dyn Table>,
    /// Cumulative amounts since t = 0 (time, `output::BALANCE_VARIABLES`).
    pub balance: &'a dyn Table,
    /// The amount in the network at t = 0 (mol).
    pub initial_stored: f64,
    /// mmHg per mol/m³ for oxygen (the messages speak PO2), else None.
    pub po2_per_concentration: Option<f64>,
}

/// Consecutive recorded rows of a run.
pub struct Chunk<'a> {
    pub time: &'a [f64],
    pub vessels: &'a [String],
    /// Recorded segments per vessel (the segment columns' vessels).
    pub segment_count: &'a [usize],
    pub species: Vec<SpeciesRows<'a>>,
    /// (`flow_in`, `flow_out`), (time, vessel) each, when both are recorded.
    pub flows: Option<(&'a dyn Table, &'a dyn Table)>,
    /// The oxygen species' name (its `tl_resistance` is the one checked), if any.
    pub oxygen: Option<&'a str>,
}

/// A recorded value outside its species' range: how far, where, when and what.
#[derive(Debug, Clone, PartialEq)]
pub struct Outside {
    pub excess: f64,
    pub vessel: String,
    pub time: f64,
    pub value: f64,
}

/// What the monitor keeps of one species between chunks.
#[derive(Debug, Clone, Default)]
struct SpeciesState {
    name: String,
    bounds: Option<(f64, f64)>,
    worst: Option<Outside>,
    po2_per_concentration: Option<f64>,
    /// (inflow, outflow, residual) of the first recorded row, and of the last.
    first: Option<[f64; 3]>,
    last: [f64; 3],
    /// The largest |Δresidual| since the first row: (its size, time, signed value).
    imbalance: Option<(f64, f64, f64)>,
}

/// A vessel's first low-flow row: (time, Q_in, Q_out).
type LowFlow = (f64, f64, f64);

/// What the monitor keeps for the tl-quasisteady validity criteria.
#[derive(Debug, Clone, Default)]
struct Validity {
    /// Σ Q_in per vessel over the recorded rows (the sign of the mean flow).
    flow_sum: Option<Vec<f64>>,
    /// Per vessel, the first low-flow row for each sign of the mean flow (+, −, 0):
    /// (time, Q_in, Q_out).
    low: std::collections::BTreeMap<usize, [Option<LowFlow>; 3]>,
    /// The largest storage ratio |Q_in − Q_out|/|Q| and |R_i|: (value, vessel, time).
    storage: Option<(f64, String, f64)>,
    transit: Option<(f64, String, f64)>,
    vessels: Vec<String>,
}

/// The physical-bounds monitor of one run (see the module's description).
#[derive(Debug, Clone, Default)]
pub struct Monitor {
    species: Vec<SpeciesState>,
    quasisteady: bool,
    t0: Option<f64>,
    validity: Validity,
}

mod feed;

impl Monitor {
    /// The monitor of a model's transport section (None: no species): every species' range
    /// computed once.
    pub fn new(transport: Option<&TransportSpec>) -> Result<Self> {
        let Some(transport) = transport else {
            return Ok(Monitor::default());
        };
        let species = transport
            .species
            .iter()
            .map(|sp| {
                Ok(SpeciesState {
                    name: sp.name.clone(),
                    bounds: species_bounds(sp)?,
                    ..SpeciesState::default()
                })
            })
            .collect::<Result<_>>()?;
        Ok(Monitor {
            species,
            quasisteady: transport.formulation == Formulation::TlQuasisteady,
            ..Monitor::default()
        })
    }

    /// The range of species `name` (mol/m³), None without one.
    pub fn bounds(&self, name: &str) -> Option<(f64, f64)> {
        self.species.iter().find(|s| s.name == name)?.bounds
    }

    /// Every finding so far, species by species (bounds, then balance), then the
    /// tl-quasisteady validity.
    pub fn messages(&self) -> Vec<String> {
        let mut found = Vec::new();
        for s in &self.species {
            found.extend(s.bounds_message());
            found.extend(s.balance_message(self.t0.unwrap_or(f64::NAN)));
        }
        if self.quasisteady
            && let Some(why) = self.validity.message()
        {
            found.push(format!(
                "formulation tl-quasisteady (the paper read literally) is outside its validity \
                 range: {why}. Use the default conservative formulation for predictions \
                 (docs/physics.md §2.7)."
            ));
        }
        found
    }
}

impl SpeciesState {
    fn bounds_message(&self) -> Option<String> {
        let (lo, hi) = self.bounds?;
        let w = self.worst.as_ref()?;
        let (scale, unit) = match self.po2_per_concentration {
            Some(s) if s != 0.0 => (s, "mmHg"),
            _ => (1.0, "mol/m^3"),
        };
        Some(format!(
            "species '{}': vessel '{}' at t = {} s has {} {unit}, outside the physical range \
             [{}, {}] {unit} of its inlet, initial and wall values (maximum principle, \
             tolerance {} of the range)",
            self.name,
            w.vessel,
            format_g(w.time, 6),
            format_g(w.value * scale, 6),
            format_g(lo * scale, 6),
            format_g(hi * scale, 6),
            format_g(BOUNDS_RTOL, 6),
        ))
    }

    /// Over the recorded window: the cumulative amounts count from the run's start, which
    /// the output may not include.
    fn balance_message(&self, t0: f64) -> Option<String> {
        let (dres, t, signed) = self.imbalance?;
        let (first, last) = (self.first?, self.last);
        let (dq_in, dq_out) = ((last[0] - first[0]).abs(), (last[1] - first[1]).abs());
        let throughput = if dq_out > dq_in { dq_out } else { dq_in };
        let rel = if throughput > 0.0 {
            dres / throughput
        } else {
            0.0
        };
        (rel > BALANCE_RTOL).then(|| {
            format!(
                "species '{}': the mass balance is off by {} of the throughput ({} mol since \
                 t = {} s) at t = {} s (network-wide; tolerance {})",
                self.name,
                format_g(rel, 3),
                format_g(signed, 6),
                format_g(t0, 6),
                format_g(t, 6),
                format_g(BALANCE_RTOL, 6),
            )
        })
    }
}

impl Validity {
    /// The first criterion the run violates, in the order of docs/physics.md §2.7.
    fn message(&self) -> Option<String> {
        if let Some(sum) = &self.flow_sum {
            let hit = self
                .low
                .iter()
                .filter(|(k, _)| sum[**k].is_finite())
                .filter_map(|(k, entry)| {
                    let sign = sum[*k].signum();
                    let i = if sum[*k] == 0.0 {
                        2
                    } else if sign > 0.0 {
                        0
                    } else {
                        1
                    };
                    entry[i].map(|h| (h, *k))
                })
                .min_by(|a, b| a.0.0.total_cmp(&b.0.0).then(a.1.cmp(&b.1)));
            if let Some(((t, qi, qo), k)) = hit {
                return Some(format!(
                    "criterion 1 (forward flow): vessel '{}' has flow {} → {} m^3/s at t = {} s \
                     (reversal or zero flow, where the literal transmission line is singular)",
                    self.vessels[k],
                    format_g(qi, 4),
                    format_g(qo, 4),
                    format_g(t, 6)
                ));
            }
        }
        if let Some((rel, vessel, t)) = self.storage.as_ref().filter(|s| s.0 > QS_STORAGE) {
            return Some(format!(
                "criterion 2 (no storage): vessel '{vessel}' stores |Q_in − Q_out|/|Q| = {} of \
                 its flow at t = {} s (> {}; the literal form neglects the compliant volume \
                 change)",
                format_g(*rel, 3),
                format_g(*t, 6),
                format_g(QS_STORAGE, 6)
            ));
        }
        let (r, vessel, t) = self.transit.as_ref().filter(|s| s.0 > QS_TRANSIT_RATE)?;
        Some(format!(
            "criterion 3 (slow transit time): vessel '{vessel}' has |R_i| = |dL_i/dt| = {} at \
             t = {} s (> {})",
            format_g(*r, 3),
            format_g(*t, 6),
            format_g(QS_TRANSIT_RATE, 6)
        ))
    }
}

#[cfg(test)]
mod tests;
