//! Segment discretisation: a vessel's geometry or lumped values → its segments' R, L, C, S and
//! volume (docs/physics.md §1.1). This table is the one source of the per-segment physics; the
//! Python layer reads it through the binding (`Network.segment_table`).

use super::auto_segments::AutoRule;
use super::checks::{check_nonnegative, check_positive};
use crate::error::{Error, Result};
use crate::model::{Arrangement, GeometrySpec, LumpedSpec, NetworkSpec, VesselSpec};
use crate::segment::{Blood, InertanceProfile, Wall, WallFriction, segment_rlc};

/// One flow segment of a vessel, as assembled (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SegmentRow {
    /// Vessel index in model order (u32 as every circuit index: 8 B per segment less).
    pub vessel: u32,
    /// Position of the segment in its vessel, from the inlet (0-based).
    pub index: u32,
    pub resistance: f64,
    pub inductance: f64,
    pub compliance: f64,
    /// Stenosis coefficient S of the pressure drop (R + S|Q|)Q.
    pub stenosis: f64,
    /// Lumen volume at the reference pressure (0 for lumped vessels).
    pub volume: f64,
    /// Segment length (0 for lumped vessels).
    pub length: f64,
    /// Radius at the segment's inlet and outlet ends (NaN for lumped vessels).
    pub radius_in: f64,
    pub radius_out: f64,
    /// Distance of the segment ends from the vessel inlet (0 for lumped vessels).
    pub x0: f64,
    pub x1: f64,
    /// Centre of the segment along the vessel (NaN for lumped vessels).
    pub position: f64,
}

impl SegmentRow {
    /// Mean radius (0 for lumped segments: no wall exchange).
    pub fn mean_radius(&self) -> f64 {
        if self.length > 0.0 {
            0.5 * (self.radius_in + self.radius_out)
        } else {
            0.0
        }
    }
}

/// How a vessel's segments are made: what the segment table keeps of each vessel.
#[derive(Debug, Clone, Copy)]
enum Recipe {
    /// A linear taper cut into equal lengths (docs/physics.md §1.1).
    Geometric {
        length: f64,
        radius_in: f64,
        radius_out: f64,
        blood: Blood,
        wall: Option<Wall>,
        profile: InertanceProfile,
    },
    /// Lumped values split evenly over the segments.
    Lumped {
        resistance: f64,
        inductance: f64,
        capacitance: f64,
        stenosis: f64,
    },
}

/// One vessel's segments: `count` rows of `recipe`, written when asked for.
#[derive(Debug, Clone, Copy)]
pub(crate) struct VesselRows {
    vessel: u32,
    count: u32,
    recipe: Recipe,
}

impl VesselRows {
    /// Row `k` (0-based from the inlet): the assembly stamps these very numbers.
    fn row(&self, k: usize) -> SegmentRow {
        let n = self.count as usize;
        let (vessel, index) = (self.vessel, k as u32);
        match self.recipe {
            Recipe::Geometric {
                length,
                radius_in,
                radius_out,
                blood,
                wall,
                profile,
            } => {
                let dx = length / n as f64;
                let r0 = radius_in + (radius_out - radius_in) * k as f64 / n as f64;
                let r1 = radius_in + (radius_out - radius_in) * (k + 1) as f64 / n as f64;
                let s = segment_rlc(dx, r0, r1, blood, wall, profile);
                SegmentRow {
                    vessel,
                    index,
                    resistance: s.resistance,
                    inductance: s.inductance,
                    compliance: s.compliance,
                    stenosis: 0.0,
                    volume: s.volume,
                    length: dx,
                    radius_in: r0,
                    radius_out: r1,
                    x0: k as f64 * dx,
                    x1: (k + 1) as f64 * dx,
                    position: (k as f64 + 0.5) * dx,
                }
            }
            Recipe::Lumped {
                resistance,
                inductance,
                capacitance,
                stenosis,
            } => {
                let nf = n as f64;
                SegmentRow {
                    vessel,
                    index,
                    resistance: resistance / nf,
                    inductance: inductance / nf,
                    compliance: capacitance / nf,
                    stenosis: stenosis / nf,
                    volume: 0.0,
                    length: 0.0,
                    radius_in: f64::NAN,
                    radius_out: f64::NAN,
                    x0: 0.0,
                    x1: 0.0,
                    position: f64::NAN,
                }
            }
        }
    }

    /// The vessel's rows, inlet first.
    pub(crate) fn rows(&self) -> impl Iterator<Item = SegmentRow> + '_ {
        (0..self.count as usize).map(|k| self.row(k))
    }
}

/// The segment table: every flow segment of every vessel in model order. Kept as each
/// vessel's recipe (its geometry or lumped values and its count, ~100 bytes a vessel) and
/// written row by row when asked for, by the formulas the assembly stamped: the same numbers
/// without 96 bytes a segment held for the whole life of the network.
#[derive(Debug, Clone, Default)]
pub struct SegmentTable {
    vessels: Vec<VesselRows>,
    len: usize,
}

impl SegmentTable {
    pub(crate) fn with_capacity(vessels: usize) -> Self {
        SegmentTable {
            vessels: Vec::with_capacity(vessels),
            len: 0,
        }
    }

    pub(crate) fn push(&mut self, v: VesselRows) {
        self.len += v.count as usize;
        self.vessels.push(v);
    }

    pub(crate) fn shrink_to_fit(&mut self) {
        self.vessels.shrink_to_fit();
    }

    /// Number of segments.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Every row, in model order.
    pub fn rows(&self) -> impl Iterator<Item = SegmentRow> + '_ {
        self.vessels.iter().flat_map(VesselRows::rows)
    }

    /// Heap bytes held (profiling, `examples/mem_stages`).
    pub fn heap_bytes(&self) -> usize {
        self.vessels.capacity() * std::mem::size_of::<VesselRows>()
    }
}

/// How many segments vessel `v` gets (as [`discretise`] decides, for a valid vessel): used to
/// size the circuit's tables before stamping, so that they are allocated once.
pub(crate) fn count(spec: &NetworkSpec, v: &VesselSpec, auto: Option<&AutoRule>) -> usize {
    let arrangement = arrangement(spec, v);
    if let (Some(rule), true) = (auto, is_auto(spec, v)) {
        return auto_count(spec, v, rule, arrangement).unwrap_or(1);
    }
    match (&v.geometry, arrangement) {
        (_, Arrangement::Rcl) => 1,
        (Some(g), _) => match (v.segments, spec.max_segment_length) {
            (Some(n), _) => n,
            (None, Some(m)) if m > 0.0 && g.length.is_finite() => {
                ((g.length / m) * (1.0 - 1e-12)).ceil().max(1.0) as usize
            }
            _ => 1,
        },
        (None, _) => v.segments.unwrap_or(1),
    }
    .max(1)
}

/// Whether vessel `v` is cut by the `auto` rule: its own `segments: auto`, else any geometric
/// vessel without its own `segments` unless the model gives a `max_length` (the default, as
/// `segmentation: {segments: auto}` says explicitly). A lumped vessel is an element its author
/// sized (svZeroDSolver's blocks): split only when it says `segments: auto` itself.
pub(crate) fn is_auto(spec: &NetworkSpec, v: &VesselSpec) -> bool {
    let by_model = spec.segments_auto || spec.max_segment_length.is_none();
    v.segments_auto || (by_model && v.segments.is_none() && v.geometry.is_some())
}

/// Vessel `v`'s arrangement: its own, else the model's, else π where the `auto` rule cuts it
/// (second order: the tolerance at about the square root of a first-order ladder's count,
/// docs/solvers.md "Space"), else inverted-L (the seed paper's section).
pub fn arrangement(spec: &NetworkSpec, v: &VesselSpec) -> Arrangement {
    match v.arrangement.or(spec.arrangement) {
        Some(a) => a,
        None if is_auto(spec, v) => Arrangement::Pi,
        None => Arrangement::InvertedL,
    }
}

/// The `auto` count of vessel `v` from its whole length's R, L, C (None: a value the
/// discretisation refuses, reported there).
fn auto_count(
    spec: &NetworkSpec,
    v: &VesselSpec,
    rule: &AutoRule,
    arrangement: Arrangement,
) -> Option<usize> {
    let (r, l, c) = match (&v.geometry, &v.lumped) {
        (Some(g), None) => {
            let ok = |x: f64| x.is_finite() && x > 0.0;
            if !(ok(g.length) && ok(g.radius_in) && ok(g.radius_out)) {
                return None;
            }
            let el = format!("vessel '{}'", v.name);
            let blood = Blood {
                density: spec.blood.density,
                viscosity: spec.blood.viscosity,
            };
            let s = segment_rlc(
                g.length,
                g.radius_in,
                g.radius_out,
                blood,
                wall(spec, g, &el).ok()?,
                spec.inertance_profile,
            );
            (s.resistance, s.inductance, s.compliance)
        }
        (None, Some(lp)) => (lp.resistance, lp.inductance, lp.capacitance),
        _ => return None,
    };
    Some(rule.count(r, l, c, arrangement))
}

/// Vessel `v`'s friction and inertia: its own `wall_friction` or the model's.
pub(crate) fn friction(spec: &NetworkSpec, v: &VesselSpec) -> WallFriction {
    v.wall_friction.unwrap_or(spec.wall_friction)
}

/// The segments of vessel `vi` of `spec`: the segment table's entry and its rows.
pub(crate) fn discretise(
    spec: &NetworkSpec,
    vi: usize,
    blood: Blood,
    arrangement: Arrangement,
    auto: Option<&AutoRule>,
) -> Result<(VesselRows, Vec<SegmentRow>)> {
    // the element's name is written only when a check fails (a structured tree has up to
    // millions of vessels): the checks are run again with it
    discretise_as(spec, vi, blood, arrangement, auto, "").or_else(|_| {
        let el = format!("vessel '{}'", spec.vessels[vi].name);
        discretise_as(spec, vi, blood, arrangement, auto, &el)
    })
}

/// [`discretise`], its errors naming the element `el`.
fn discretise_as(
    spec: &NetworkSpec,
    vi: usize,
    blood: Blood,
    arrangement: Arrangement,
    auto: Option<&AutoRule>,
    el: &str,
) -> Result<(VesselRows, Vec<SegmentRow>)> {
    let v = &spec.vessels[vi];
    match (&v.geometry, &v.lumped) {
        (Some(_), Some(_)) => Err(Error::model(
            el,
            "give either geometry or lumped values, not both",
        )),
        (None, None) => Err(Error::model(el, "needs geometry or lumped values")),
        (None, Some(l)) => {
            let n = auto
                .filter(|_| is_auto(spec, v))
                .map(|_| count(spec, v, auto));
            let made = lumped(v, vi, l, arrangement, el, n)?;
            Ok((made, made.rows().collect()))
        }
        (Some(g), None) => {
            let n = auto
                .filter(|_| is_auto(spec, v))
                .map(|_| count(spec, v, auto));
            geometric(spec, v, vi, g, blood, arrangement, el, n)
        }
    }
}

/// Lumped values split evenly over `segments` (one for RCL, svZeroDSolver's BloodVessel).
fn lumped(
    v: &VesselSpec,
    vi: usize,
    l: &LumpedSpec,
    arrangement: Arrangement,
    el: &str,
    auto: Option<usize>,
) -> Result<VesselRows> {
    check_nonnegative(el, "resistance", l.resistance)?;
    check_nonnegative(el, "inductance", l.inductance)?;
    check_nonnegative(el, "capacitance", l.capacitance)?;
    // calibrated svZeroDSolver models carry negative coefficients: only finiteness is checked
    if !l.stenosis_coefficient.is_finite() {
        return Err(Error::model(
            el,
            format!(
                "stenosis_coefficient must be finite, got {}",
                l.stenosis_coefficient
            ),
        ));
    }
    let n = if arrangement == Arrangement::Rcl {
        1
    } else {
        auto.or(v.segments).unwrap_or(1)
    };
    if n == 0 {
        return Err(Error::model(el, "segments must be >= 1, got 0"));
    }
    Ok(VesselRows {
        vessel: index32(vi)?,
        count: index32(n)?,
        recipe: Recipe::Lumped {
            resistance: l.resistance,
            inductance: l.inductance,
            capacitance: l.capacitance,
            stenosis: l.stenosis_coefficient,
        },
    })
}

fn wall(spec: &NetworkSpec, g: &GeometrySpec, el: &str) -> Result<Option<Wall>> {
    match (g.wall_thickness, g.youngs_modulus) {
        (Some(h), Some(e)) => {
            check_positive(el, "wall_thickness", h)?;
            check_positive(el, "youngs_modulus", e)?;
            if !(g.poisson_ratio.is_finite() && (0.0..0.5 + 1e-12).contains(&g.poisson_ratio)) {
                return Err(Error::model(
                    el,
                    format!("poisson_ratio must be in [0, 0.5], got {}", g.poisson_ratio),
                ));
            }
            Ok(Some(Wall {
                thickness: h,
                youngs_modulus: e,
                poisson_ratio: g.poisson_ratio,
                model: spec.wall_model,
            }))
        }
        (None, None) => Ok(None),
        _ => Err(Error::model(
            el,
            "give both wall_thickness and youngs_modulus (or neither for a rigid tube)",
        )),
    }
}

/// Equal-length segments along a linear taper, each integrated exactly (`auto`: the count
/// the `auto` rule gave).
#[allow(clippy::too_many_arguments)]
fn geometric(
    spec: &NetworkSpec,
    v: &VesselSpec,
    vi: usize,
    g: &GeometrySpec,
    blood: Blood,
    arrangement: Arrangement,
    el: &str,
    auto: Option<usize>,
) -> Result<(VesselRows, Vec<SegmentRow>)> {
    if arrangement == Arrangement::Rcl {
        return Err(Error::model(el, "the RCL arrangement needs lumped values"));
    }
    check_positive(el, "length", g.length)?;
    check_positive(el, "radius_in", g.radius_in)?;
    check_positive(el, "radius_out", g.radius_out)?;
    let wall = wall(spec, g, el)?;
    let n = match (auto.or(v.segments), spec.max_segment_length) {
        (Some(0), _) => return Err(Error::model(el, "segments must be >= 1, got 0")),
        (Some(n), _) => n,
        (None, Some(m)) => ((g.length / m) * (1.0 - 1e-12)).ceil().max(1.0) as usize,
        (None, None) => 1,
    };
    // a Womersley segment's series inertance is the flat profile's: its cells add the rest
    let profile = match friction(spec, v) {
        WallFriction::Womersley => InertanceProfile::Flat,
        WallFriction::Poiseuille => spec.inertance_profile,
    };
    let made = VesselRows {
        vessel: index32(vi)?,
        count: index32(n)?,
        recipe: Recipe::Geometric {
            length: g.length,
            radius_in: g.radius_in,
            radius_out: g.radius_out,
            blood,
            wall,
            profile,
        },
    };
    let rows: Vec<SegmentRow> = made.rows().collect();
    check_coefficients(el, g, &rows)?;
    Ok((made, rows))
}

/// Radii or lengths at the ends of the double range (1e-300 m, 1e300 m) give segments whose
/// R = 8μ dx/(π r⁴), L or C overflow or vanish: refused here, naming the vessel and its
/// geometry, instead of surfacing later as a network "with no steady state" or NaN.
fn check_coefficients(el: &str, g: &GeometrySpec, rows: &[SegmentRow]) -> Result<()> {
    // normal (not subnormal) numbers: a coefficient of 1e-310 has lost its precision
    let usable = |s: &SegmentRow| {
        s.resistance.is_normal()
            && s.resistance > 0.0
            && s.inductance.is_normal()
            && s.inductance > 0.0
            && (s.compliance == 0.0 || s.compliance.is_normal())
            && s.compliance >= 0.0
    };
    match rows.iter().find(|s| !usable(s)) {
        Some(s) => Err(Error::model(
            el,
            format!(
                "radius {:e} to {:e} m and length {:e} m give a segment with R = {:e}, L = {:e}, \
                 C = {:e} (not positive normal numbers): check the radius, length and units",
                g.radius_in, g.radius_out, g.length, s.resistance, s.inductance, s.compliance
            ),
        )),
        None => Ok(()),
    }
}

/// A vessel or segment index as u32, the segment table's index type: a model beyond it is
/// refused with a typed error before anything of its size is allocated.
fn index32(i: usize) -> Result<u32> {
    u32::try_from(i).map_err(|_| Error::Resource {
        what: format!("{i} vessels or segments"),
        bytes: 0,
        message: "more than 2^32 vessels, or segments in one vessel, than a network can \
                  index; use fewer segments (segmentation max_length, a vessel's segments)"
            .into(),
    })
}
