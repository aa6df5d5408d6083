//! The wall/tissue compartment (docs/physics.md §3.7): behind the luminal boundary layer of
//! every wall piece, a radial diffusion–consumption column of `radial_cells` finite volumes in
//! cylindrical coordinates,
//!
//!   ∂u/∂t = D_t (1/r) ∂/∂r (r ∂u/∂r) − R(u),   r_i < r < r_i + h,
//!
//! u the wall-phase concentration (mol/m³ of wall), R Michaelis–Menten or zero order. The
//! lumen couples to the innermost cell through the closure's conductance g in series with the
//! half cell's, W = G (c − u_0/φ), G = 1/(1/g + 1/(φ G_½)), φ = u/c at equilibrium (for O2 the
//! ratio of the solubilities). The outer face is no-flux or held at a fixed concentration.
//!
//! The luminal closure is evaluated as usual with a zero wall concentration (so the lumen's own
//! rows take g c), and the hooks here add the rest: W − g c = (G − g) c − G u_0/φ.
//! * RK4 (`tissue_rhs`): the column's rates from the stage state.
//! * Backward Euler (`tissue_rows`, `tissue_update`): each column is eliminated per piece,
//!   u = a + b c (one tridiagonal solve with two right-hand sides, the consumption linearised
//!   about the old state), so the lumen sees a wall law linear in its own free concentration
//!   and the tree sweep is unchanged; after the solve the columns are back-substituted.
//!
//! State (after the relaxed shears): per species with a tissue wall, the amounts (mol) of its
//! wall cells, then three accumulators: lumen → wall, consumed, outer inflow (mol). Exact
//! balance: Σ N_wall(t) − Σ N_wall(0) = I_lumen→wall − I_consumed + I_outer.

#[allow(unused_imports)]
use super::*;
use crate::closure::finite_number;
use crate::model::transport::{ConsumptionSpec, OuterSpec, TissueSpec};
use std::f64::consts::PI;

/// Per output vessel and per output segment: innermost, outermost and minimum wall
/// concentration (lumen-equivalent free concentration u/φ, mol/m³), hypoxic volume fraction.
pub const TISSUE_VESSEL_COLUMNS: usize = 4;
pub const TISSUE_SEGMENT_COLUMNS: usize = 4;
/// Wall amount (mol), cumulative lumen → wall, consumed and outer inflow (mol).
pub const TISSUE_BALANCE_COLUMNS: usize = 4;
/// Accumulators per tissue species in the state.
const ACC: usize = 3;
/// Largest accepted `radial_cells`.
const MAX_RADIAL_CELLS: f64 = 1000.0;

/// Consumption per unit wall volume (mol m⁻³ s⁻¹).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Consumption {
    MichaelisMenten { vmax: f64, km: f64 },
    ZeroOrder { rate: f64 },
}

impl Consumption {
    /// R(u) and dR/du. Both laws stop where the wall is anoxic (u ≤ 0); Michaelis–Menten with
    /// km = 0 is the zero-order law.
    #[inline]
    pub(super) fn rate_slope(self, u: f64) -> (f64, f64) {
        if u <= 0.0 {
            return (0.0, 0.0);
        }
        match self {
            Consumption::MichaelisMenten { vmax, km } => {
                let d = km + u;
                (vmax * u / d, vmax * km / (d * d))
            }
            Consumption::ZeroOrder { rate } => (rate, 0.0),
        }
    }

    /// Largest dR/du (at u → 0+), for the RK4 stiffness bound.
    fn max_slope(self) -> f64 {
        match self {
            Consumption::MichaelisMenten { vmax, km } if km > 0.0 => vmax / km,
            _ => 0.0,
        }
    }
}

/// Settings of one tissue wall (one per distinct vessel spec).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct WallKind {
    consumption: Consumption,
    /// Fixed outer concentration (wall phase), None: no flux.
    outer: Option<f64>,
    phi: f64,
    threshold: f64,
}

/// The radial column behind one wall piece; its cells are `start..start + n` of the flat
/// per-wall-cell arrays (and of the species' wall state).
#[derive(Debug, Clone)]
pub(super) struct Column {
    piece: u32,
    start: u32,
    n: u32,
    kind: u32,
    /// Half-cell conductance between the lumen face and cell 0's centre (m³/s, wall phase).
    g_half: f64,
    /// Half-cell conductance between the last cell's centre and the outer face (0: no flux).
    g_out: f64,
    /// The wall's diffusive conductance from the lumen face to a fixed outer concentration
    /// (lumen units; 0 with a no-flux outer face), which the conjugate correction of a
    /// developing boundary layer reads; ∞ for the other closures (no correction).
    g_shell: f64,
}

/// The tissue walls of one species (part of the immutable [`Plan`]).
#[derive(Debug, Clone)]
pub(super) struct TissuePlan {
    kinds: Vec<WallKind>,
    columns: Vec<Column>,
    /// Per wall cell: volume (m³) and the conductance to the next cell outward (m³/s; 0 for
    /// the last cell of a column).
    vol: Vec<f64>,
    g: Vec<f64>,
    /// Columns of segment j: `seg_cols[j]..seg_cols[j + 1]` (columns follow the pieces).
    seg_cols: Vec<u32>,
}

impl TissuePlan {
    fn n_cells(&self) -> usize {
        self.vol.len()
    }
}

/// Per-run scratch of the implicit elimination: per wall cell u = a + b c, and per column the
/// linearisation of the lumen's free concentration in its total one, c ≈ f + σ (C − C_old).
#[derive(Debug, Clone, Default)]
pub(super) struct TissueScratch {
    a: Vec<f64>,
    b: Vec<f64>,
    lin: Vec<[f64; 3]>,
    diag: Vec<f64>,
    /// Observation: per segment, the flux into its wall minus the closure's g c (empty for a
    /// species without tissue wall).
    pub(super) seg_corr: Vec<f64>,
}

fn bad_value(element: &str, key: &str, v: f64, rule: &str) -> Error {
    Error::model(
        element,
        format!("tissue wall {key} must be {rule}, got {v}"),
    )
}

fn positive(element: &str, key: &str, v: f64) -> Result<f64> {
    finite_number(element, &format!("tissue wall {key}"), v, false)
}

fn non_negative(element: &str, key: &str, v: f64) -> Result<f64> {
    finite_number(element, &format!("tissue wall {key}"), v, true)
}

/// Validated settings of one tissue spec: (kind, thickness, diffusivity, radial cells).
fn wall_kind(t: &TissueSpec, element: &str) -> Result<(WallKind, f64, f64, usize)> {
    let h = positive(element, "thickness", t.thickness)?;
    let d = positive(element, "diffusivity", t.diffusivity)?;
    let phi = positive(element, "partition", t.partition)?;
    let n = t.radial_cells;
    if !(n.is_finite() && n >= 1.0 && n.fract() == 0.0 && n <= MAX_RADIAL_CELLS) {
        return Err(bad_value(
            element,
            "radial_cells",
            n,
            &format!("an integer between 1 and {MAX_RADIAL_CELLS}"),
        ));
    }
    let consumption = match t.consumption {
        ConsumptionSpec::MichaelisMenten { vmax, km } => Consumption::MichaelisMenten {
            vmax: non_negative(element, "vmax", vmax)?,
            km: non_negative(element, "km", km)?,
        },
        ConsumptionSpec::ZeroOrder { rate } => Consumption::ZeroOrder {
            rate: non_negative(element, "rate", rate)?,
        },
    };
    let outer = match t.outer {
        OuterSpec::NoFlux => None,
        OuterSpec::Concentration { value } => Some(non_negative(element, "outer value", value)?),
    };
    let threshold = non_negative(element, "hypoxic_threshold", t.hypoxic_threshold)?;
    let kind = WallKind {
        consumption,
        outer,
        phi,
        threshold,
    };
    Ok((kind, h, d, n as usize))
}

/// The luminal closure of a tissue wall must be a fixed conductance against a zero wall
/// concentration (the innermost wall cell takes the wall concentration's place).
fn check_lumen_closure(w: &WallSpec, element: &str) -> Result<()> {
    let ok = match w {
        WallSpec::None => true,
        WallSpec::MassTransfer {
            wall_concentration, ..
        }
        | WallSpec::Graetz {
            wall_concentration, ..
        } => *wall_concentration == 0.0,
        WallSpec::Leveque {
            wall_concentration,
            shear,
            ..
        } => *wall_concentration == 0.0 && *shear == closure::Shear::CycleMean,
        WallSpec::Permeability {
            tissue_concentration,
            ..
        } => *tissue_concentration == 0.0,
        WallSpec::Flux { .. } => false,
    };
    if ok {
        Ok(())
    } else {
        Err(Error::model(
            element,
            format!(
                "a tissue wall's luminal closure must be none, mass-transfer, leveque (cycle-mean \
                 shear), graetz or permeability against a zero wall concentration, got {w:?}"
            ),
        ))
    }
}

/// The tissue walls of every species (empty when no species has one: the default path).
pub(super) fn plans(
    spec: &TransportSpec,
    species: &[SpeciesPlan],
    vessel_names: &[String],
    segments: &[Segment],
    segment_vessels: &[u32],
    (pieces, seg_pieces, sub_walls): (&[Piece], &[u32], &[SegmentWall]),
) -> Result<Vec<Option<TissuePlan>>> {
    if spec
        .species
        .iter()
        .all(|s| s.tissue.is_none() && s.per_vessel_tissue.values().all(Option::is_none))
    {
        return Ok(Vec::new());
    }
    let geo = Geometry {
        segments,
        segment_vessels,
        pieces,
        seg_pieces,
        sub_walls,
    };
    spec.species
        .iter()
        .zip(species)
        .map(|(sp, set)| species_plan(spec, sp, set, vessel_names, &geo))
        .collect()
}

struct Geometry<'a> {
    segments: &'a [Segment],
    segment_vessels: &'a [u32],
    pieces: &'a [Piece],
    seg_pieces: &'a [u32],
    sub_walls: &'a [SegmentWall],
}

/// The tissue wall of one species: its kind per vessel (None: no tissue there), and a radial
/// column behind every wall piece of those vessels.
fn species_plan(
    spec: &TransportSpec,
    sp: &SpeciesSpec,
    set: &SpeciesPlan,
    vessel_names: &[String],
    geo: &Geometry<'_>,
) -> Result<Option<TissuePlan>> {
    let el = format!("species '{}'", sp.name);
    for name in sp.per_vessel_tissue.keys() {
        if !vessel_names.iter().any(|n| n == name) {
            return Err(bad(
                &el,
                format!("per_vessel names vessel '{name}', which the network does not have"),
            ));
        }
    }
    let mut kinds: Vec<WallKind> = Vec::new();
    let mut geo_of_kind: Vec<(f64, f64, usize)> = Vec::new();
    let mut of_vessel = vec![u32::MAX; vessel_names.len()];
    for (vi, vname) in vessel_names.iter().enumerate() {
        let t = match sp.per_vessel_tissue.get(vname) {
            Some(t) => t.as_ref(),
            None => sp.tissue.as_ref(),
        };
        let Some(t) = t else { continue };
        let element = format!("{el} wall of vessel '{vname}'");
        if spec.formulation != Formulation::Conservative {
            return Err(bad(
                &element,
                "a tissue wall needs formulation: conservative".into(),
            ));
        }
        check_lumen_closure(&set.walls[vi], &element)?;
        let (kind, h, d, n) = wall_kind(t, &element)?;
        let k = match kinds
            .iter()
            .zip(&geo_of_kind)
            .position(|(k, g)| *k == kind && *g == (h, d, n))
        {
            Some(k) => k,
            None => {
                kinds.push(kind);
                geo_of_kind.push((h, d, n));
                kinds.len() - 1
            }
        };
        of_vessel[vi] = k as u32;
    }
    if kinds.is_empty() {
        return Ok(None);
    }
    let mut tp = TissuePlan {
        kinds,
        columns: Vec::new(),
        vol: Vec::new(),
        g: Vec::new(),
        seg_cols: vec![0],
    };
    for j in 0..geo.segments.len() {
        let vi = geo.segment_vessels[j] as usize;
        let k = of_vessel[vi];
        if k != u32::MAX {
            let developing = matches!(
                set.walls[vi],
                WallSpec::Leveque { .. } | WallSpec::Graetz { .. }
            );
            let (h, d, n) = geo_of_kind[k as usize];
            let pieces = geo.seg_pieces[j] as usize..geo.seg_pieces[j + 1] as usize;
            for p in pieces {
                let pc = &geo.pieces[p];
                let wall = piece_wall(geo.segments, geo.sub_walls, pc);
                tp.push_column(p, (pc, wall), k, (h, d, n), developing);
            }
        }
        tp.seg_cols.push(tp.columns.len() as u32);
    }
    Ok(Some(tp))
}

impl TissuePlan {
    /// The column behind wall piece `p`: n equal radial cells over [r_i, r_i + h] along the
    /// piece's length (share × its wall's length); the wall does not follow the lumen's
    /// pressure (docs/physics.md §3.7).
    /// `developing`: the luminal closure is a developing layer (Lévêque, Graetz), which gets
    /// the conjugate correction (`closure::conjugate_conductance`).
    fn push_column(
        &mut self,
        p: usize,
        (pc, wall): (&Piece, SegmentWall),
        kind: u32,
        (h, d, n): (f64, f64, usize),
        developing: bool,
    ) {
        let (ri, len) = (wall.radius, pc.share * (wall.x1 - wall.x0));
        if !(ri > 0.0 && len > 0.0) {
            return;
        }
        let dr = h / n as f64;
        let start = self.vol.len() as u32;
        for k in 0..n {
            let (r0, r1) = (ri + k as f64 * dr, ri + (k + 1) as f64 * dr);
            self.vol.push(PI * (r1 * r1 - r0 * r0) * len);
            let g = if k + 1 < n {
                d * 2.0 * PI * r1 * len / dr
            } else {
                0.0
            };
            self.g.push(g);
        }
        let ro = ri + h;
        let wk = &self.kinds[kind as usize];
        let g_out = if wk.outer.is_some() {
            d * 2.0 * PI * ro * len / (0.5 * dr)
        } else {
            0.0
        };
        // steady diffusion through the shell, 2π D ℓ/ln(r_o/r_i), in lumen units (× φ)
        let g_shell = match (developing, wk.outer) {
            (false, _) => f64::INFINITY,
            (true, Some(_)) => wk.phi * d * 2.0 * PI * len / (ro / ri).ln(),
            (true, None) => 0.0,
        };
        self.columns.push(Column {
            piece: p as u32,
            start,
            n: n as u32,
            kind,
            g_half: d * 2.0 * PI * ri * len / (0.5 * dr),
            g_out,
            g_shell,
        });
    }
}

/// Conductance of the luminal closure's piece `p` (m³/s, share included).
#[inline]
fn piece_g(laws: &Laws, pieces: &[Piece], p: usize) -> f64 {
    match laws.laws[p] {
        SegmentLaw::Fixed { g, .. } => pieces[p].share * g,
        SegmentLaw::Instantaneous { .. } => 0.0,
    }
}

/// The closure's g (with the conjugate correction of a developing layer, `g_shell`) in
/// series with the half cell φ G_½ (lumen units).
#[inline]
fn coupling(g: f64, g_shell: f64, phi_g_half: f64) -> f64 {
    let g = closure::conjugate_conductance(g, g_shell);
    if g <= 0.0 {
        0.0
    } else {
        1.0 / (1.0 / g + 1.0 / phi_g_half)
    }
}

impl Transport {
    #[inline]
    pub(super) fn tissue_of(&self, s: usize) -> Option<&TissuePlan> {
        self.plan.tissue.get(s).and_then(Option::as_ref)
    }

    /// Length of the tissue state of every species.
    pub(super) fn tissue_len(&self) -> usize {
        self.plan
            .tissue
            .iter()
            .flatten()
            .map(|t| t.n_cells() + ACC)
            .sum()
    }

    /// Start of species `s`'s tissue state (after the amounts, accumulators, relaxed shears).
    fn tissue_offset(&self, s: usize) -> usize {
        let base = self.species.len() * (self.plan.cells.len() + 4)
            + self
                .species
                .iter()
                .map(|sp| sp.laws.relax.len())
                .sum::<usize>();
        base + self.plan.tissue[..s]
            .iter()
            .flatten()
            .map(|t| t.n_cells() + ACC)
            .sum::<usize>()
    }

    /// Largest relative change of the wall amounts between two states (the periodicity check:
    /// the wall's time scale h²/D_t can be much longer than the lumen's).
    pub(super) fn tissue_relative_change(&self, a: &[f64], b: &[f64]) -> f64 {
        let mut worst = 0.0f64;
        for s in 0..self.plan.tissue.len() {
            let Some(tp) = self.tissue_of(s) else {
                continue;
            };
            let start = self.tissue_offset(s);
            let r = start..start + tp.n_cells();
            let scale = a[r.clone()]
                .iter()
                .fold(0.0f64, |m, x| m.max(x.abs()))
                .max(1e-300);
            let change = a[r.clone()]
                .iter()
                .zip(&b[r])
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            worst = worst.max(change / scale);
        }
        worst
    }

    /// Columns the tissue adds to every species block of `observe` (0 without tissue).
    pub fn tissue_columns(&self) -> usize {
        if self.plan.tissue.is_empty() {
            0
        } else {
            TISSUE_VESSEL_COLUMNS * self.plan.out_vessels.len()
                + TISSUE_SEGMENT_COLUMNS * self.plan.out_segments.len()
                + TISSUE_BALANCE_COLUMNS
        }
    }

    /// Initial wall state: every wall cell in equilibrium with the lumen's initial free
    /// concentration (u = φ c₀), accumulators zero.
    pub(super) fn tissue_initial(&self, z: &mut [f64]) {
        for s in 0..self.plan.tissue.len() {
            let Some(tp) = self.tissue_of(s) else {
                continue;
            };
            let off = self.tissue_offset(s);
            let c0 = self.plan.species[s].initial_free;
            for col in &tp.columns {
                let phi = tp.kinds[col.kind as usize].phi;
                for k in col.start as usize..(col.start + col.n) as usize {
                    z[off + k] = phi * c0 * tp.vol[k];
                }
            }
            z[off + tp.n_cells()..off + tp.n_cells() + ACC].fill(0.0);
        }
    }

    /// RK4 hook (after `cell_rates` of species `s`): the wall columns' rates, and the lumen's
    /// wall uptake corrected from the closure's g c to W = G (c − u_0/φ).
    pub(super) fn tissue_rhs(&mut self, s: usize, z: &[f64], dz: &mut [f64]) {
        if self.tissue_of(s).is_none() {
            return;
        }
        if !self.species[s].laws.has_wall {
            self.free_of_cells(s);
        }
        let plan = Arc::clone(&self.plan);
        let Some(tp) = plan.tissue[s].as_ref() else {
            return;
        };
        let (nc, nsp, off) = (plan.cells.len(), self.species.len(), self.tissue_offset(s));
        let (laws, free) = (&*self.species[s].laws, self.free_of(s));
        let (mut acc, mut corr_sum) = ([0.0; ACC], 0.0);
        for col in &tp.columns {
            let p = col.piece as usize;
            let pc = &plan.pieces[p];
            let kind = &tp.kinds[col.kind as usize];
            let g = piece_g(laws, &plan.pieces, p);
            let geff = coupling(g, col.g_shell, kind.phi * col.g_half);
            let cells = col.start as usize..(col.start + col.n) as usize;
            let u = |k: usize| z[off + k] / tp.vol[k];
            let c = free[pc.node as usize];
            let w = geff * (c - u(cells.start) / kind.phi);
            let corr = w - g * c;
            dz[s * nc + pc.cell as usize] -= corr;
            corr_sum += corr;
            acc[0] += w;
            let mut inflow = w;
            for k in cells.clone() {
                let uk = u(k);
                let out = if k + 1 < cells.end {
                    tp.g[k] * (uk - u(k + 1))
                } else {
                    kind.outer.map_or(0.0, |uo| col.g_out * (uk - uo))
                };
                let (r, _) = kind.consumption.rate_slope(uk);
                dz[off + k] = inflow - out - r * tp.vol[k];
                acc[1] += r * tp.vol[k];
                inflow = out;
            }
            // what leaves the last cell outward (0 with a no-flux outer face)
            acc[2] -= inflow;
        }
        dz[nsp * nc + 4 * s + 2] += corr_sum;
        dz[off + tp.n_cells()..off + tp.n_cells() + ACC].copy_from_slice(&acc);
    }

    /// Backward-Euler hook (after `linearised_wall` of species `s`, whose wall law is W =
    /// wlin·C_t + wconst per cell): eliminate every column, u = a + b c with c the lumen's
    /// free concentration at the end of the step, and add W − g c linearised in C_t.
    pub(super) fn tissue_rows(
        &mut self,
        s: usize,
        dt: f64,
        z: &[f64],
        wconst: &mut [f64],
        wlin: &mut [f64],
    ) {
        let Some(tp) = self.plan.tissue.get(s).and_then(Option::as_ref) else {
            return;
        };
        let off = self.tissue_offset(s);
        let mut sc = std::mem::take(&mut self.tissue);
        sc.a.resize(tp.n_cells(), 0.0);
        sc.b.resize(tp.n_cells(), 0.0);
        sc.lin.resize(tp.columns.len(), [0.0; 3]);
        let laws = &*self.species[s].laws;
        let has_wall = laws.has_wall;
        let free = self.free_of(s);
        for (ci, col) in tp.columns.iter().enumerate() {
            let p = col.piece as usize;
            let pc = &self.plan.pieces[p];
            let kind = &tp.kinds[col.kind as usize];
            let (n, i) = (pc.node as usize, pc.cell as usize);
            // the lumen's linearisation of its wall law (`linearised_wall`): c ≈ f + σ (C − C_old)
            let (f, sigma, c_old) = if has_wall {
                (free[n], self.sweep.inv_slope[i], self.conc[n])
            } else {
                (self.conc[n], 1.0, self.conc[n]) // no coupling: any value does
            };
            sc.lin[ci] = [f, sigma, c_old];
            let g = piece_g(laws, &self.plan.pieces, p);
            let geff = coupling(g, col.g_shell, kind.phi * col.g_half);
            let cells = col.start as usize..(col.start + col.n) as usize;
            eliminate(tp, col, kind, geff, dt, &z[off..], &mut sc, cells);
            // W = G (c − u_0/φ) = λ' c + μ with u_0 = a_0 + b_0 c; minus the closure's g c
            let k0 = col.start as usize;
            let lambda = geff * (1.0 - sc.b[k0] / kind.phi) - g;
            let mu = -geff * sc.a[k0] / kind.phi;
            wlin[i] += lambda * sigma;
            wconst[i] += lambda * (f - sigma * c_old) + mu;
        }
        self.tissue = sc;
    }

    /// Backward-Euler hook (after the solve and update of species `s`): back-substitute every
    /// column with the lumen's solved concentration, and accumulate the step's fluxes.
    pub(super) fn tissue_update(&mut self, s: usize, dt: f64, z: &mut [f64]) {
        let Some(tp) = self.plan.tissue.get(s).and_then(Option::as_ref) else {
            return;
        };
        let off = self.tissue_offset(s);
        let sc = &self.tissue;
        let laws = &*self.species[s].laws;
        let mut acc = [0.0; ACC];
        for (ci, col) in tp.columns.iter().enumerate() {
            let p = col.piece as usize;
            let kind = &tp.kinds[col.kind as usize];
            let [f, sigma, c_old] = sc.lin[ci];
            let c = f + sigma * (self.conc[self.plan.pieces[p].node as usize] - c_old);
            let geff = coupling(
                piece_g(laws, &self.plan.pieces, p),
                col.g_shell,
                kind.phi * col.g_half,
            );
            let cells = col.start as usize..(col.start + col.n) as usize;
            let mut last = 0.0;
            for k in cells.clone() {
                let u = sc.a[k] + sc.b[k] * c;
                let u_old = z[off + k] / tp.vol[k];
                let (r, dr) = kind.consumption.rate_slope(u_old);
                acc[1] += tp.vol[k] * (r + dr * (u - u_old));
                z[off + k] = u * tp.vol[k];
                last = u;
            }
            acc[0] += geff * (c - (sc.a[cells.start] + sc.b[cells.start] * c) / kind.phi);
            if let Some(uo) = kind.outer {
                acc[2] += col.g_out * (uo - last);
            }
        }
        let a = &mut z[off + tp.n_cells()..off + tp.n_cells() + ACC];
        for (a, v) in a.iter_mut().zip(acc) {
            *a += dt * v;
        }
    }

    /// RK4 stiffness of the wall columns (1/s): max over wall cells of (Σ conductances + V
    /// max dR/du)/V, the lumen coupling at the closure's conductance. Raises `best`.
    pub(super) fn tissue_max_rate(&self, best: &mut Option<ReactionRate>) {
        for (s, tp) in self.plan.tissue.iter().enumerate() {
            let Some(tp) = tp else { continue };
            let laws = &*self.species[s].laws;
            for col in &tp.columns {
                let kind = &tp.kinds[col.kind as usize];
                let g = piece_g(laws, &self.plan.pieces, col.piece as usize);
                let geff = coupling(g, col.g_shell, kind.phi * col.g_half);
                let cells = col.start as usize..(col.start + col.n) as usize;
                let mut g_in = geff / kind.phi;
                for k in cells.clone() {
                    let g_next = if k + 1 < cells.end {
                        tp.g[k]
                    } else {
                        col.g_out
                    };
                    let rate = (g_in + g_next) / tp.vol[k] + kind.consumption.max_slope();
                    if rate > best.as_ref().map_or(0.0, |b| b.rate) {
                        *best = Some(ReactionRate {
                            rate,
                            species: format!("{} (tissue wall)", self.plan.species[s].name),
                            cell: self.plan.pieces[col.piece as usize].cell as usize,
                        });
                    }
                    g_in = tp.g[k];
                }
            }
        }
    }

    /// Observation hook (before species `s`'s wall fluxes are observed): per segment, the flux
    /// into its tissue wall W = G (c − u_0/φ) minus the closure's g c, which the observed wall
    /// flux adds (empty for a species without tissue wall).
    pub(super) fn tissue_wall_fluxes(&mut self, s: usize, z: &[f64]) {
        let mut corr = std::mem::take(&mut self.tissue.seg_corr);
        corr.clear();
        if let Some(tp) = self.tissue_of(s) {
            let off = self.tissue_offset(s);
            let (laws, free) = (&*self.species[s].laws, self.free_of(s));
            corr.resize(self.plan.segments.len(), 0.0);
            for (j, c) in corr.iter_mut().enumerate() {
                for col in &tp.columns[tp.seg_cols[j] as usize..tp.seg_cols[j + 1] as usize] {
                    let p = col.piece as usize;
                    let kind = &tp.kinds[col.kind as usize];
                    let g = piece_g(laws, &self.plan.pieces, p);
                    let geff = coupling(g, col.g_shell, kind.phi * col.g_half);
                    let cl = free[self.plan.pieces[p].node as usize];
                    let u0 = z[off + col.start as usize] / tp.vol[col.start as usize];
                    *c += geff * (cl - u0 / kind.phi) - g * cl;
                }
            }
        }
        self.tissue.seg_corr = corr;
    }

    /// Observation hook (after species `s`'s balance columns): per output vessel and segment
    /// the innermost, outermost and minimum wall value (u/φ, lumen-equivalent free
    /// concentration) and the hypoxic volume fraction, then the wall balance. NaN where there
    /// is no tissue wall.
    pub(super) fn observe_tissue(&self, s: usize, z: &[f64], out: &mut Vec<f64>) {
        let Some(tp) = self.tissue_of(s) else {
            out.extend(std::iter::repeat_n(f64::NAN, self.tissue_columns()));
            return;
        };
        let off = self.tissue_offset(s);
        let stats = |segs: &[u32]| -> [f64; 4] {
            let mut w = WallStats::default();
            for j in segs.iter().map(|&j| j as usize) {
                for ci in tp.seg_cols[j] as usize..tp.seg_cols[j + 1] as usize {
                    w.add(tp, &tp.columns[ci], &z[off..]);
                }
            }
            w.values()
        };
        for v in &self.plan.out_vessels {
            out.extend(stats(&self.plan.out_segments[v.segs.clone()]));
        }
        for &j in &self.plan.out_segments {
            out.extend(stats(&[j]));
        }
        let n = tp.n_cells();
        let stored: f64 = z[off..off + n].iter().sum();
        let acc = &z[off + n..off + n + ACC];
        out.extend([stored, acc[0], acc[1], acc[2]]);
    }
}

/// Volume-weighted wall statistics of a set of columns.
#[derive(Default)]
struct WallStats {
    inner: f64,
    outer: f64,
    weight: f64,
    min: f64,
    hypoxic: f64,
    volume: f64,
}

impl WallStats {
    fn add(&mut self, tp: &TissuePlan, col: &Column, z: &[f64]) {
        let kind = &tp.kinds[col.kind as usize];
        let cells = col.start as usize..(col.start + col.n) as usize;
        let u = |k: usize| z[k] / tp.vol[k];
        // the innermost and outermost cells weighted by the column's wall area (its volume)
        let vcol: f64 = tp.vol[cells.clone()].iter().sum();
        if self.weight == 0.0 {
            self.min = f64::INFINITY;
        }
        self.inner += vcol * u(cells.start) / kind.phi;
        self.outer += vcol * u(cells.end - 1) / kind.phi;
        self.weight += vcol;
        for k in cells {
            let uk = u(k);
            self.min = self.min.min(uk / kind.phi);
            if uk < kind.threshold {
                self.hypoxic += tp.vol[k];
            }
            self.volume += tp.vol[k];
        }
    }

    fn values(&self) -> [f64; 4] {
        if self.weight > 0.0 {
            [
                self.inner / self.weight,
                self.outer / self.weight,
                self.min,
                self.hypoxic / self.volume,
            ]
        } else {
            [f64::NAN; 4]
        }
    }
}

/// Backward-Euler rows of one column for a lumen free concentration c (unknown), the
/// consumption linearised about the old state, solved by the Thomas algorithm for the two
/// right-hand sides of u = a + b c (into `sc.a`, `sc.b` over `cells`).
#[allow(clippy::too_many_arguments)]
fn eliminate(
    tp: &TissuePlan,
    col: &Column,
    kind: &WallKind,
    geff: f64,
    dt: f64,
    zt: &[f64],
    sc: &mut TissueScratch,
    cells: std::ops::Range<usize>,
) {
    sc.diag.resize(col.n as usize, 0.0);
    let mut g_in = geff / kind.phi;
    // forward elimination: row k reads −g_{k−1} u_{k−1} + d_k u_k − g_k u_{k+1} = r_k
    for (i, k) in cells.clone().enumerate() {
        let v = tp.vol[k];
        let u_old = zt[k] / v;
        let (r, dr) = kind.consumption.rate_slope(u_old);
        let last = k + 1 == cells.end;
        let g_next = if last { col.g_out } else { tp.g[k] };
        let mut d = v / dt + v * dr + g_in + g_next;
        let mut ra = v * u_old / dt - v * (r - dr * u_old);
        let mut rb = 0.0;
        if i == 0 {
            rb = geff;
        } else {
            // subtract (−g_{k−1}/d_{k−1}) × row k−1
            let gp = tp.g[k - 1];
            let m = gp / sc.diag[i - 1];
            d -= m * gp;
            ra += m * sc.a[k - 1];
            rb += m * sc.b[k - 1];
        }
        if last {
            if let Some(uo) = kind.outer {
                ra += col.g_out * uo;
            }
        }
        sc.diag[i] = d;
        sc.a[k] = ra;
        sc.b[k] = rb;
        g_in = g_next;
    }
    // back substitution
    for (i, k) in cells.clone().enumerate().rev() {
        let (mut ra, mut rb) = (sc.a[k], sc.b[k]);
        if k + 1 < cells.end {
            ra += tp.g[k] * sc.a[k + 1];
            rb += tp.g[k] * sc.b[k + 1];
        }
        sc.a[k] = ra / sc.diag[i];
        sc.b[k] = rb / sc.diag[i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One column of n cells over [ri, ri + h], unit length, zero-order consumption `rate`.
    fn column(ri: f64, h: f64, d: f64, n: usize, outer: Option<f64>, c: Consumption) -> TissuePlan {
        let mut tp = TissuePlan {
            kinds: vec![WallKind {
                consumption: c,
                outer,
                phi: 1.0,
                threshold: 0.0,
            }],
            columns: Vec::new(),
            vol: Vec::new(),
            g: Vec::new(),
            seg_cols: vec![0],
        };
        let piece = Piece {
            seg: 0,
            node: 0,
            cell: 0,
            sub: Piece::OWN_WALL,
            share: 1.0,
        };
        let wall = SegmentWall {
            radius: ri,
            x0: 0.0,
            x1: 1.0,
        };
        tp.push_column(0, (&piece, wall), 0, (h, d, n), false);
        tp
    }

    /// Steady column for an inner face held at `ui` (an infinite luminal conductance): backward
    /// Euler steps with a long dt until nothing changes.
    fn steady(tp: &TissuePlan, ui: f64) -> Vec<f64> {
        let col = &tp.columns[0];
        let kind = &tp.kinds[0];
        let geff = coupling(f64::INFINITY, f64::INFINITY, kind.phi * col.g_half);
        let n = col.n as usize;
        let mut z: Vec<f64> = tp.vol.iter().map(|v| ui * v).collect();
        let mut sc = TissueScratch {
            a: vec![0.0; n],
            b: vec![0.0; n],
            ..TissueScratch::default()
        };
        for _ in 0..50 {
            eliminate(tp, col, kind, geff, 1e9, &z, &mut sc, 0..n);
            for (k, zk) in z.iter_mut().enumerate() {
                *zk = (sc.a[k] + sc.b[k] * ui) * tp.vol[k];
            }
        }
        z.iter().zip(&tp.vol).map(|(z, v)| z / v).collect()
    }

    /// Closed-form steady profile of zero-order consumption R in a cylindrical shell,
    /// D (1/r)(r u')' = R, u(ri) = ui, with u'(ro) = 0 or u(ro) = uo:
    /// u = ui + R (r² − ri²)/(4D) + A ln(r/ri).
    fn exact(r: f64, ri: f64, ro: f64, d: f64, rate: f64, ui: f64, uo: Option<f64>) -> f64 {
        let a = match uo {
            None => -rate * ro * ro / (2.0 * d),
            Some(uo) => (uo - ui - rate * (ro * ro - ri * ri) / (4.0 * d)) / (ro / ri).ln(),
        };
        ui + rate * (r * r - ri * ri) / (4.0 * d) + a * (r / ri).ln()
    }

    /// Max error of the cell-centre values against the closed form, relative to the drop
    /// across the wall.
    fn profile_error(n: usize, uo: Option<f64>) -> f64 {
        // arterial-wall scales: r 5 mm, h 0.3 mm, D 1.5e-9 m²/s, 80 → ~20 mmHg across the wall
        let (ri, h, d, rate, ui) = (5e-3, 3e-4, 1.5e-9, 1.5e-3, 0.112);
        let tp = column(ri, h, d, n, uo, Consumption::ZeroOrder { rate });
        let u = steady(&tp, ui);
        let dr = h / n as f64;
        let drop = ui - exact(ri + h, ri, ri + h, d, rate, ui, uo);
        assert!(drop > 0.05 * ui, "the test needs a real drop: {drop}");
        (0..n)
            .map(|k| {
                let rc = ri + (k as f64 + 0.5) * dr;
                (u[k] - exact(rc, ri, ri + h, d, rate, ui, uo)).abs() / drop
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn zero_order_shell_matches_the_closed_form_at_second_order() {
        for uo in [None, Some(0.05)] {
            let errs: Vec<f64> = [4, 8, 16, 32]
                .iter()
                .map(|&n| profile_error(n, uo))
                .collect();
            eprintln!("outer {uo:?}: errors {errs:?}");
            // 4 radial cells (the default) are within 2 % of the drop across the wall, and the
            // error falls 4× per doubling (second order: cell-centre values of the FV scheme)
            assert!(errs[0] < 2e-2, "{errs:?}");
            for w in errs.windows(2) {
                let order = (w[0] / w[1]).log2();
                assert!(
                    (1.8..2.3).contains(&order),
                    "observed order {order}: {errs:?}"
                );
            }
        }
    }

    #[test]
    fn michaelis_menten_tends_to_zero_order_as_km_vanishes() {
        let (ri, h, d, vmax) = (5e-3, 3e-4, 1.5e-9, 1.5e-3);
        let zero = steady(
            &column(ri, h, d, 8, None, Consumption::ZeroOrder { rate: vmax }),
            0.112,
        );
        let mut last = f64::INFINITY;
        for km in [1e-3, 1e-5, 1e-7, 1e-9] {
            let mm = Consumption::MichaelisMenten { vmax, km };
            let u = steady(&column(ri, h, d, 8, None, mm), 0.112);
            let diff = u
                .iter()
                .zip(&zero)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            // the difference shrinks with km (≈ km per unit: R = vmax (1 − km/(km + u)))
            assert!(diff < last, "km {km}: {diff} ≥ {last}");
            last = diff;
        }
        assert!(last < 1e-8 * 0.112, "{last}");
        // km = 0 is the zero-order law exactly
        let (r, s) = Consumption::MichaelisMenten { vmax, km: 0.0 }.rate_slope(0.05);
        assert_eq!((r, s), (vmax, 0.0));
    }
}
