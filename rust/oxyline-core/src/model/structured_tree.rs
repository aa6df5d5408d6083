//! Structured-tree outlets (Olufsen 1999, Ann Biomed Eng 27; Olufsen et al. 2000): below an
//! outlet, an asymmetric binary tree of small arteries down to a minimum radius, grown by the
//! core into ordinary vessels when it reads the model (docs/structured-tree.md).
//!
//! Growth rule: the tree's root is the outlet node, of radius `root_radius`. A node of radius
//! r has daughters of radius α·r (path letter `a`) and β·r (`b`); a daughter exists only if
//! its radius is ≥ `min_radius`, and a tree vessel without daughters ends at the `terminal`
//! condition. A vessel of radius r has length `length_ratio`·r and is named `<node>/st/<path>`;
//! its distal node has the same name. Only geometry and wall data are written here: the
//! assembly computes every segment's R, L and C from them like any other vessel's.
//!
//! Radii only shrink along a path, so the tree holds exactly the paths with
//! α^i β^j r0 ≥ min_radius, C(i + j, i) of them per radius class (i, j): the vessel count and
//! the steady resistance are computed per class, without growing the tree.

use crate::error::{Error, Result};
use crate::model::{GeometrySpec, VesselSpec};
use crate::run::memory;
use crate::segment::{Blood, InertanceProfile, WallFriction, segment_rlc};

/// The boundary condition's `type`.
pub const TYPE: &str = "structured-tree";
/// The condition's keys, sorted.
pub const KEYS: [&str; 13] = [
    "alpha",
    "beta",
    "length_ratio",
    "max_length",
    "max_vessels",
    "min_radius",
    "root_radius",
    "segments",
    "stiffness",
    "stopping",
    "terminal",
    "type",
    "wall_friction",
];
/// The values `stopping` may take (docs/structured-tree.md).
pub const STOPPINGS: [&str; 2] = ["min-radius", "olufsen"];

/// Where a tree stops growing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Stopping {
    /// A daughter exists only if its radius is >= `min_radius`: every vessel is at least
    /// `min_radius`.
    #[default]
    MinRadius,
    /// Olufsen's code: a vessel above `min_radius` always has both daughters, and the first
    /// vessel at or below `min_radius` on a path is a leaf.
    Olufsen,
}

impl Stopping {
    /// The rule named `name` (one of [`STOPPINGS`]).
    pub fn parse(name: &str) -> Option<Stopping> {
        match name {
            "min-radius" => Some(Stopping::MinRadius),
            "olufsen" => Some(Stopping::Olufsen),
            _ => None,
        }
    }
}
/// Olufsen et al. (2000) E·h/r = k1 exp(k2 r) + k3, converted to SI (Pa, 1/m, Pa).
pub const OLUFSEN_STIFFNESS: Stiffness = Stiffness::KLaw {
    k1: 2.0e6,
    k2: -2253.0,
    k3: 8.65e4,
};
/// Wall thickness / radius written with the {k1, k2, k3} law, whose value fixes only E·h/r
/// (all that the thin-wall compliance depends on).
pub const K_LAW_THICKNESS_RATIO: f64 = 0.1;
/// The default guard on the number of tree vessels.
pub const MAX_VESSELS: f64 = 2.0e6;
/// No tree may have more vessels than this, whatever `max_vessels` says (10⁸ vessels need tens
/// of GB while the model is built).
pub const HARD_MAX_VESSELS: f64 = 1.0e8;
/// Radius classes (i, j) visited at most when counting: beyond, α or β is so close to 1 that
/// the count is reported as a lower bound.
const MAX_CLASSES: usize = 10_000_000;
/// Radius classes visited to give the exact count of a tree the closed-form bound already
/// refuses (the message names it when it is cheap to get).
const REFUSED_CLASSES: usize = 100_000;

/// The element a tree's errors name.
pub fn element(node: &str) -> String {
    format!("boundary condition '{node}' ({TYPE})")
}

fn err(node: &str, message: impl Into<String>) -> Error {
    Error::model(element(node), message)
}

/// A number as Python's `%g` writes it (6 significant digits): the messages name the value as
/// the other checks of the model do.
pub fn fmt_g(x: f64) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    if x == 0.0 {
        return if x.is_sign_negative() { "-0" } else { "0" }.into();
    }
    let sci = format!("{x:.5e}"); // mantissa rounded to 6 digits, then its exponent
    let (mantissa, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    let trim = |s: &str| -> String {
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s.to_string()
        }
    };
    if (-4..6).contains(&exp) {
        trim(&format!("{x:.*}", (5 - exp) as usize))
    } else {
        let sign = if exp < 0 { '-' } else { '+' };
        format!("{}e{sign}{:02}", trim(mantissa), exp.abs())
    }
}

/// A wall law as the user gives it (model units: k1, k3 and the modulus as moduli, k2 per
/// length).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Stiffness {
    /// E·h/r = k1 exp(k2 r) + k3; h = 0.1 r.
    KLaw { k1: f64, k2: f64, k3: f64 },
    /// One modulus, h = thickness_ratio · r.
    Modulus {
        youngs_modulus: f64,
        thickness_ratio: f64,
    },
}

/// The model's unit factors (SI per model unit) that a tree's values take.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Units {
    pub length: f64,
    pub modulus: f64,
}

impl Units {
    pub const SI: Units = Units {
        length: 1.0,
        modulus: 1.0,
    };
}

/// A structured-tree condition's values as written (model units); None: the default.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TreeInput {
    pub alpha: Option<f64>,
    pub beta: Option<f64>,
    pub length_ratio: Option<f64>,
    pub min_radius: Option<f64>,
    pub root_radius: Option<f64>,
    pub stiffness: Option<Stiffness>,
    pub segments: Option<i64>,
    /// `segments: auto`: each tree vessel cut by the `auto` rule.
    pub segments_auto: bool,
    pub max_length: Option<f64>,
    pub max_vessels: Option<f64>,
    pub stopping: Option<Stopping>,
    /// The tree vessels' `wall_friction` (None: the model's).
    pub wall_friction: Option<WallFriction>,
}

/// A finite number in (lo, hi), named by its key (Python's messages).
fn number(node: &str, key: &str, v: f64, lo: f64, hi: f64) -> Result<f64> {
    if !v.is_finite() {
        return Err(err(
            node,
            format!("'{key}' must be a finite number, got {}", fmt_g(v)),
        ));
    }
    if v <= lo || v >= hi {
        return Err(err(
            node,
            format!(
                "'{key}' must be in ({}, {}), got {}",
                fmt_g(lo),
                fmt_g(hi),
                fmt_g(v)
            ),
        ));
    }
    Ok(v)
}

/// The wall law in SI.
#[derive(Debug, Clone, Copy, PartialEq)]
enum WallLaw {
    KLaw { k1: f64, k2: f64, k3: f64 },
    Modulus { e: f64, ratio: f64 },
}

impl WallLaw {
    /// The law of `stiffness` (model units; None: Olufsen's, already SI).
    fn new(node: &str, stiffness: Option<Stiffness>, u: Units) -> Result<Self> {
        let inf = f64::INFINITY;
        Ok(match stiffness {
            None => match OLUFSEN_STIFFNESS {
                Stiffness::KLaw { k1, k2, k3 } => WallLaw::KLaw { k1, k2, k3 },
                Stiffness::Modulus { .. } => unreachable!("Olufsen's law is a k-law"),
            },
            Some(Stiffness::KLaw { k1, k2, k3 }) => WallLaw::KLaw {
                k1: u.modulus * number(node, "stiffness.k1", k1, -inf, inf)?,
                k2: number(node, "stiffness.k2", k2, -inf, inf)? / u.length,
                k3: u.modulus * number(node, "stiffness.k3", k3, -inf, inf)?,
            },
            Some(Stiffness::Modulus {
                youngs_modulus,
                thickness_ratio,
            }) => WallLaw::Modulus {
                e: u.modulus * number(node, "stiffness.youngs_modulus", youngs_modulus, 0.0, inf)?,
                ratio: number(node, "stiffness.thickness_ratio", thickness_ratio, 0.0, inf)?,
            },
        })
    }

    /// (Young's modulus, wall thickness) of a tree vessel of radius `r` (SI).
    fn at(&self, node: &str, r: f64) -> Result<(f64, f64)> {
        match *self {
            WallLaw::KLaw { k1, k2, k3 } => {
                let ehr = k1 * (k2 * r).exp() + k3;
                // an overflowing law (k2·r beyond ln f64::MAX) is refused, not an infinite wall
                if !(ehr / K_LAW_THICKNESS_RATIO).is_finite() {
                    return Err(err(
                        node,
                        format!(
                            "stiffness gives E·h/r = {} Pa at radius {} m, not a finite number \
                             (k1 = {}, k2 = {} 1/m, k3 = {})",
                            fmt_g(ehr),
                            fmt_g(r),
                            fmt_g(k1),
                            fmt_g(k2),
                            fmt_g(k3)
                        ),
                    ));
                }
                if ehr <= 0.0 {
                    return Err(err(
                        node,
                        format!(
                            "stiffness gives E·h/r = {} Pa <= 0 at radius {} m",
                            fmt_g(ehr),
                            fmt_g(r)
                        ),
                    ));
                }
                Ok((ehr / K_LAW_THICKNESS_RATIO, K_LAW_THICKNESS_RATIO * r))
            }
            WallLaw::Modulus { e, ratio } => Ok((e, ratio * r)),
        }
    }
}

/// (Young's modulus, wall thickness) in SI of a vessel of radius `r` (SI) under `stiffness`
/// (model units; None: Olufsen's law): the wall a tree vessel of that radius gets.
pub fn wall_at(
    node: &str,
    stiffness: Option<Stiffness>,
    r: f64,
    units: Units,
) -> Result<(f64, f64)> {
    WallLaw::new(node, stiffness, units)?.at(node, r)
}

/// How tree vessels are cut into segments.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Segmentation {
    /// The model's default.
    Model,
    Count(usize),
    /// At most this length (m).
    MaxLength(f64),
    /// By the `auto` rule (`assemble::auto_segments`).
    Auto,
}

/// The number of vessels of a tree, counted per radius class; `exact` is false when the count
/// overflowed or the classes were too many to visit (then `n` is a lower bound).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Count {
    pub n: u128,
    pub exact: bool,
}

/// A lower bound of [`vessel_count`] in closed form (no counting): every vessel down to depth
/// D = ⌊ln(r0/rmin) / ln(1/min(α, β))⌋ exists (a full binary tree of 2^(D+1) − 2 vessels), and
/// so do the pure α and pure β chains (I + J vessels, I = ⌊ln(r0/rmin) / ln(1/α)⌋, J
/// likewise); one depth less for rounding. Infinite when the full tree is deeper than 1000.
pub fn vessel_count_bound(alpha: f64, beta: f64, root_radius: f64, min_radius: f64) -> f64 {
    let inside = |f: f64| f > 0.0 && f < 1.0;
    if !(inside(alpha) && inside(beta)) || root_radius.is_nan() || root_radius < min_radius {
        return 0.0;
    }
    let span = (root_radius / min_radius).ln();
    let depth = |f: f64| (span / -f.ln()).floor().max(1.0) - 1.0;
    let full = depth(alpha.min(beta));
    let chains = depth(alpha) + depth(beta);
    let full_count = if full > 1000.0 {
        f64::INFINITY
    } else {
        2f64.powf(full + 1.0) - 2.0
    };
    full_count.max(chains)
}

/// Number of tree vessels, counted without growing the tree: a vessel exists iff its own
/// radius α^i β^j r0 ≥ `min_radius`, and C(i + j, i) paths have i a's and j b's.
pub fn vessel_count(alpha: f64, beta: f64, root_radius: f64, min_radius: f64) -> Count {
    vessel_count_within(alpha, beta, root_radius, min_radius, MAX_CLASSES)
}

/// [`vessel_count`] under `stopping`. Olufsen's tree has both daughters of the root and of
/// every vessel above `min_radius`: 2 (1 + N₊), N₊ the vessels of radius > `min_radius`
/// (counted as today's rule counts, with the strict comparison), none if r0 <= `min_radius`.
pub fn vessel_count_by(
    stopping: Stopping,
    (alpha, beta): (f64, f64),
    root_radius: f64,
    min_radius: f64,
    max_classes: usize,
) -> Count {
    match stopping {
        Stopping::MinRadius => {
            vessel_count_within(alpha, beta, root_radius, min_radius, max_classes)
        }
        Stopping::Olufsen if root_radius <= min_radius => Count { n: 0, exact: true },
        Stopping::Olufsen => {
            let above = classes_within(alpha, beta, root_radius, min_radius, true, max_classes);
            Count {
                n: above.n.saturating_add(1).saturating_mul(2),
                exact: above.exact && above.n < u128::MAX / 2,
            }
        }
    }
}

/// [`vessel_count`], stopped (inexact, a lower bound) after `max_classes` radius classes: the
/// work is per class, never per vessel.
pub fn vessel_count_within(
    alpha: f64,
    beta: f64,
    root_radius: f64,
    min_radius: f64,
    max_classes: usize,
) -> Count {
    classes_within(alpha, beta, root_radius, min_radius, false, max_classes)
}

/// Vessels of radius >= `min_radius` (> with `strict`), per radius class.
fn classes_within(
    alpha: f64,
    beta: f64,
    root_radius: f64,
    min_radius: f64,
    strict: bool,
    max_classes: usize,
) -> Count {
    let keep = |r: f64| {
        if strict {
            r > min_radius
        } else {
            r >= min_radius
        }
    };
    let (mut n, mut exact, mut classes) = (0u128, true, 0usize);
    let mut i = 0i32;
    while keep(alpha.powf(f64::from(i)) * root_radius) {
        let mut j = 0i32;
        let mut paths = 1u128; // C(i + j, i) at j = 0
        while keep(alpha.powf(f64::from(i)) * beta.powf(f64::from(j)) * root_radius) {
            classes += 1;
            if classes > max_classes {
                return Count { n, exact: false };
            }
            if i + j > 0 {
                n = n.saturating_add(paths);
            }
            j += 1;
            // C(i + j, i) = C(i + j − 1, i) (i + j) / j, exact in integers
            match paths.checked_mul((i + j) as u128) {
                Some(p) => paths = p / j as u128,
                None => {
                    exact = false;
                    paths = u128::MAX / 2;
                }
            }
        }
        i += 1;
    }
    Count {
        n,
        exact: exact && n < u128::MAX,
    }
}

/// The radius of a tree's root.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Root {
    /// The condition's `root_radius` (model units).
    Given(f64),
    /// The radius of the vessel end at the node (SI, checked with the vessel).
    Vessel(f64),
}

/// The radius (SI) of the first vessel end at `node` (a vessel's distal end is looked at before
/// its proximal one): the default root radius of a tree there.
pub fn root_radius<'v>(
    node: &str,
    vessels: impl IntoIterator<Item = &'v VesselSpec>,
) -> Result<f64> {
    end_radius(
        node,
        vessels.into_iter().map(|v| VesselEnds {
            name: &v.name,
            from: Some(&v.from),
            to: Some(&v.to),
            radius_in: v.geometry.as_ref().map(|g| g.radius_in),
            radius_out: v.geometry.as_ref().map(|g| g.radius_out),
        }),
    )
}

/// A checked structured tree below one outlet node (SI).
#[derive(Debug, Clone, PartialEq)]
pub struct Tree {
    node: String,
    pub alpha: f64,
    pub beta: f64,
    pub length_ratio: f64,
    pub min_radius: f64,
    pub root_radius: f64,
    wall: WallLaw,
    segmentation: Segmentation,
    pub stopping: Stopping,
    wall_friction: Option<WallFriction>,
    /// Its vessel count.
    pub count: u128,
}

/// A grown tree: its vessels (parents before daughters, the a-subtree before the b-subtree)
/// and its leaves (the distal nodes no tree vessel leaves), in the same order.
#[derive(Debug, Clone)]
pub struct Grown {
    pub vessels: Vec<VesselSpec>,
    pub leaves: Vec<String>,
}

/// How a tree's vessels are cut into segments: `segments` or `max_length` (in the model's
/// units), else the model's own segmentation.
fn segmentation(node: &str, input: &TreeInput, u: Units) -> Result<Segmentation> {
    if input.segments_auto {
        if input.max_length.is_some() {
            return Err(err(node, "give 'segments' or 'max_length', not both"));
        }
        return Ok(Segmentation::Auto);
    }
    Ok(match (input.segments, input.max_length) {
        (Some(_), Some(_)) => {
            return Err(err(node, "give 'segments' or 'max_length', not both"));
        }
        (Some(n), None) if n < 1 => {
            return Err(err(
                node,
                format!("'segments' must be an integer >= 1, got {n}"),
            ));
        }
        (Some(n), None) => Segmentation::Count(n as usize),
        (None, Some(dx)) => {
            Segmentation::MaxLength(u.length * number(node, "max_length", dx, 0.0, f64::INFINITY)?)
        }
        (None, None) => Segmentation::Model,
    })
}

/// The vessel count of the tree (α, β) from `r0` down to `rmin`, refused (`too_many`, given
/// the count as the message says it) above `max_vessels`.
fn checked_count(
    stopping: Stopping,
    (alpha, beta): (f64, f64),
    r0: f64,
    rmin: f64,
    max_vessels: f64,
    too_many: impl Fn(String) -> Error,
) -> Result<Count> {
    // the closed-form bound first: trees of α, β near 1 are refused without counting
    let bound = vessel_count_bound(alpha, beta, r0, rmin);
    if bound > max_vessels {
        // the message gives the exact count when few classes hold it
        let c = vessel_count_by(stopping, (alpha, beta), r0, rmin, REFUSED_CLASSES);
        return Err(too_many(if c.exact {
            c.n.to_string()
        } else {
            format!("at least {}", fmt_g(bound.max(c.n as f64)))
        }));
    }
    // counted per radius class (at most MAX_CLASSES of them: never for ever)
    let count = vessel_count_by(stopping, (alpha, beta), r0, rmin, MAX_CLASSES);
    if count.n as f64 > max_vessels || !count.exact {
        let n = if count.exact {
            count.n.to_string()
        } else {
            format!("at least {}", count.n)
        };
        return Err(too_many(n));
    }
    Ok(count)
}

impl Tree {
    /// The tree of `input` below `node` whose root has radius `root`, checked in the order of
    /// the keys, and refused above `max_vessels` before anything is grown.
    pub fn new(node: &str, input: &TreeInput, root: Root, u: Units) -> Result<Tree> {
        let inf = f64::INFINITY;
        let alpha = number(node, "alpha", input.alpha.unwrap_or(0.9), 0.0, 1.0)?;
        let beta = number(node, "beta", input.beta.unwrap_or(0.6), 0.0, 1.0)?;
        let lrr = number(
            node,
            "length_ratio",
            input.length_ratio.unwrap_or(50.0),
            0.0,
            inf,
        )?;
        let rmin = u.length
            * number(
                node,
                "min_radius",
                input.min_radius.unwrap_or(1e-4),
                0.0,
                inf,
            )?;
        let r0 = match root {
            Root::Given(r) => u.length * number(node, "root_radius", r, 0.0, inf)?,
            Root::Vessel(r) => r,
        };
        let max_vessels = input.max_vessels.unwrap_or(MAX_VESSELS);
        if !(1.0..=HARD_MAX_VESSELS).contains(&max_vessels) {
            return Err(err(
                node,
                format!(
                    "'max_vessels' must be a number from 1 to {}, got {}",
                    fmt_g(HARD_MAX_VESSELS),
                    fmt_g(max_vessels)
                ),
            ));
        }
        let segmentation = segmentation(node, input, u)?;
        let wall = WallLaw::new(node, input.stiffness, u)?;
        let too_many = |n: String| {
            err(
                node,
                format!(
                    "the tree has {n} vessels, more than max_vessels = {} (alpha = {}, beta = {}; \
                     raise min_radius = {} m or max_vessels)",
                    fmt_g(max_vessels),
                    fmt_g(alpha),
                    fmt_g(beta),
                    fmt_g(rmin)
                ),
            )
        };
        let stopping = input.stopping.unwrap_or_default();
        let count = checked_count(stopping, (alpha, beta), r0, rmin, max_vessels, too_many)?;
        if count.n == 0 {
            return Err(err(
                node,
                format!(
                    "no daughter reaches min_radius = {} m (root radius {} m, alpha = {})",
                    fmt_g(rmin),
                    fmt_g(r0),
                    fmt_g(alpha)
                ),
            ));
        }
        Ok(Tree {
            node: node.to_string(),
            alpha,
            beta,
            length_ratio: lrr,
            min_radius: rmin,
            root_radius: r0,
            wall,
            segmentation,
            stopping,
            wall_friction: input.wall_friction,
            count: count.n,
        })
    }

    /// Refuse the tree (a typed resource error) when its vessels' estimated memory exceeds
    /// `limit` (bytes; None: no limit), before any of them is made: the core's per-vessel and
    /// per-segment bytes of `run::memory` (segments known before growing: a fixed count, else
    /// one per vessel, a lower bound).
    pub fn check_memory(&self, limit: Option<f64>) -> Result<()> {
        let Some(limit) = limit else {
            return Ok(());
        };
        let per_vessel = match self.segmentation {
            Segmentation::Count(n) => n,
            Segmentation::Model | Segmentation::MaxLength(_) | Segmentation::Auto => 1,
        };
        let n = usize::try_from(self.count).unwrap_or(usize::MAX);
        let need = memory::model_bytes(n.saturating_mul(per_vessel), n, 0.0, 0);
        if need > limit {
            return Err(Error::over_limit(
                format!("{}: the tree's {n} vessels", element(&self.node)),
                need,
                limit,
                "raise min_radius or lower max_vessels",
            ));
        }
        Ok(())
    }

    /// The tree's vessels, depth first (SI; the wall law may still refuse a radius).
    pub fn grow(&self) -> Result<Grown> {
        let cap = usize::try_from(self.count).unwrap_or(0);
        let mut out = Grown {
            vessels: Vec::with_capacity(cap),
            leaves: Vec::new(),
        };
        self.grow_into(|v, leaf| {
            if leaf {
                out.leaves.push(v.name.clone());
            }
            out.vessels.push(v);
        })?;
        Ok(out)
    }

    /// Hand each tree vessel, depth first, to `sink` with whether it is a leaf. Names are
    /// built by appending one path letter to the parent's name (no formatting per vessel: a
    /// tree has up to millions of them).
    pub fn grow_into(&self, mut sink: impl FnMut(VesselSpec, bool)) -> Result<()> {
        let prefix = format!("{}/st/", self.node);
        let daughter = |parent: &str, letter: char| {
            let mut name = String::with_capacity(parent.len() + 1);
            name.push_str(parent);
            name.push(letter);
            name
        };
        // popped a first: the a-subtree before the b-subtree
        let mut stack = vec![
            (daughter(&prefix, 'b'), self.beta * self.root_radius),
            (daughter(&prefix, 'a'), self.alpha * self.root_radius),
        ];
        let olufsen = self.stopping == Stopping::Olufsen;
        if olufsen && self.root_radius <= self.min_radius {
            stack.clear();
        }
        while let Some((name, r)) = stack.pop() {
            // Olufsen's daughters all exist (their parent is above min_radius)
            if !olufsen && r < self.min_radius {
                continue;
            }
            // the parent's name is this one without its last path letter
            let from = if name.len() == prefix.len() + 1 {
                self.node.clone()
            } else {
                name[..name.len() - 1].to_string()
            };
            let (a, b) = (self.alpha * r, self.beta * r);
            let leaf = if olufsen {
                r <= self.min_radius
            } else {
                a < self.min_radius && b < self.min_radius
            };
            if !(olufsen && leaf) {
                stack.push((daughter(&name, 'b'), b));
                stack.push((daughter(&name, 'a'), a));
            }
            sink(self.vessel(name, from, r)?, leaf);
        }
        Ok(())
    }

    /// The tree vessel `name` of radius `r` from node `from`.
    fn vessel(&self, name: String, from: String, r: f64) -> Result<VesselSpec> {
        let length = self.length_ratio * r;
        let (e, h) = self.wall.at(&self.node, r)?;
        let mut v = VesselSpec::blank();
        v.wall_friction = self.wall_friction;
        v.to = name.clone();
        v.name = name;
        v.from = from;
        v.segments_auto = self.segmentation == Segmentation::Auto;
        v.segments = match self.segmentation {
            Segmentation::Model | Segmentation::Auto => None,
            Segmentation::Count(n) => Some(n),
            // (1e-9: a length a rounding above a whole number of pieces is not cut once more)
            Segmentation::MaxLength(dx) => Some(((length / dx - 1e-9).ceil() as usize).max(1)),
        };
        v.geometry = Some(GeometrySpec {
            length,
            radius_in: r,
            radius_out: r,
            wall_thickness: Some(h),
            youngs_modulus: Some(e),
            poisson_ratio: 0.5,
            wall_viscosity: 0.0,
        });
        Ok(v)
    }
}

/// Steady Poiseuille resistance ∫ 8μ/(π r⁴) dx of a tube tapered linearly from `r_in` to
/// `r_out` (SI), in the closed form 8μ/(3π k) (r_in⁻³ − r_out⁻³), k = (r_out − r_in)/length,
/// and 8μ l/(π r⁴) when uniform: the resistance of docs/physics.md §1.1 (the segment
/// resistance of `segment::segment_rlc` is the same integral in a form stable as r_out → r_in;
/// the two agree to rounding, test below), written as the importers' calibrations were.
pub fn poiseuille_resistance(length: f64, r_in: f64, r_out: f64, viscosity: f64) -> f64 {
    let pi = std::f64::consts::PI;
    if (r_out - r_in).abs() < 1e-12 * r_in {
        return 8.0 * viscosity * length / (pi * r_in.powf(4.0));
    }
    let k = (r_out - r_in) / length;
    8.0 * viscosity / (pi * 3.0 * k) * (r_in.powf(-3.0) - r_out.powf(-3.0))
}

/// Steady resistance of a tree vessel of radius `r`: the core's segment resistance of one
/// segment of the whole length (docs/physics.md §1.1).
fn vessel_resistance(length: f64, r: f64, viscosity: f64) -> f64 {
    let blood = Blood {
        density: 0.0,
        viscosity,
    };
    segment_rlc(length, r, r, blood, None, InertanceProfile::Flat).resistance
}

/// A tree's radius classes: the shape for the steady resistance.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    pub alpha: f64,
    pub beta: f64,
    pub length_ratio: f64,
    pub root_radius: f64,
    pub viscosity: f64,
}

impl Shape {
    /// Radius of class (i, j): α^i β^j r0.
    fn radius(&self, i: usize, j: usize) -> f64 {
        self.alpha.powf(i as f64) * self.beta.powf(j as f64) * self.root_radius
    }

    /// Steady resistance below the root (tree grown to `min_radius`) with every leaf ending
    /// at `r_leaf`.
    pub fn resistance(&self, min_radius: f64, r_leaf: f64) -> f64 {
        self.classes(min_radius).resistance(r_leaf)
    }

    /// The radius classes of the tree grown to `min_radius`, with each class's vessel
    /// resistance (None: no vessel of that class).
    fn classes(&self, min_radius: f64) -> Classes {
        let exists = |i: usize, j: usize| self.radius(i, j) >= min_radius;
        let mut imax = 0;
        while exists(imax + 1, 0) && imax < MAX_CLASSES {
            imax += 1;
        }
        let mut jmax = 0;
        while exists(0, jmax + 1) && jmax < MAX_CLASSES {
            jmax += 1;
        }
        let cols = jmax + 2;
        let mut vessel = vec![None; (imax + 2) * cols];
        for i in 0..imax + 2 {
            for j in 0..cols {
                if i + j > 0 && exists(i, j) {
                    let r = self.radius(i, j);
                    vessel[i * cols + j] =
                        Some(vessel_resistance(self.length_ratio * r, r, self.viscosity));
                }
            }
        }
        Classes { imax, cols, vessel }
    }

    /// The structured tree below `node` whose steady resistance is `total` (SI): (min_radius,
    /// terminal resistance). The tree grows to `min_radius` (at most α·r0), raised by factors
    /// of 1.05 until the tree alone (leaves at the outlet pressure) has at most
    /// `tree_fraction` of `total`; every leaf ends at one terminal resistance that supplies
    /// the rest, by bisection to rounding (R(leaf) is increasing).
    pub fn matched(
        &self,
        node: &str,
        total: f64,
        min_radius: f64,
        tree_fraction: f64,
    ) -> Result<(f64, f64)> {
        if total.is_nan() || total <= 0.0 {
            return Err(err(
                node,
                format!(
                    "the resistance to match is {} Pa s/m^3, not > 0",
                    fmt_g(total)
                ),
            ));
        }
        let alpha = number(node, "alpha", self.alpha, 0.0, 1.0)?;
        let beta = number(node, "beta", self.beta, 0.0, 1.0)?;
        let largest = alpha * self.root_radius;
        let mut rmin = min_radius.min(largest); // at least the a-daughter
        // the class table's size in closed form: α, β near 1 are refused, not tabulated
        let span = (self.root_radius / rmin).ln();
        let table = (span / -alpha.ln() + 2.0) * (span / -beta.ln() + 2.0);
        if table.is_nan() || table > MAX_CLASSES as f64 {
            return Err(err(
                node,
                format!(
                    "a tree with alpha = {}, beta = {} down to min_radius = {} m has about {} \
                     radius classes, more than {} (raise min_radius or lower alpha, beta)",
                    fmt_g(alpha),
                    fmt_g(beta),
                    fmt_g(rmin),
                    fmt_g(table),
                    fmt_g(MAX_CLASSES as f64)
                ),
            ));
        }
        let mut classes = self.classes(rmin);
        while classes.resistance(0.0) > tree_fraction * total {
            rmin *= 1.05;
            if rmin > largest {
                return Err(err(
                    node,
                    format!(
                        "no tree below root radius {} m has at most {} of the resistance {} Pa s/m^3",
                        fmt_g(self.root_radius),
                        fmt_g(tree_fraction),
                        fmt_g(total)
                    ),
                ));
            }
            classes = self.classes(rmin);
        }
        let (mut lo, mut hi) = (0.0, total * 2f64.powi(20));
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if classes.resistance(mid) < total {
                lo = mid;
            } else {
                hi = mid;
            }
            if hi - lo <= 1e-15 * hi {
                break;
            }
        }
        Ok((rmin, 0.5 * (lo + hi)))
    }
}

/// The radius classes (i, j) of a tree, row-major with `cols` columns, and each one's vessel
/// resistance: a subtree depends only on its root radius α^i β^j r0, so the steady resistance
/// is computed once per class, deepest classes first.
struct Classes {
    imax: usize,
    cols: usize,
    vessel: Vec<Option<f64>>,
}

impl Classes {
    /// Steady resistance below the root with every leaf ending at `r_leaf`.
    fn resistance(&self, r_leaf: f64) -> f64 {
        let cols = self.cols;
        let mut below = vec![0.0; self.vessel.len()];
        for i in (0..=self.imax).rev() {
            for j in (0..cols - 1).rev() {
                if i + j > 0 && self.vessel[i * cols + j].is_none() {
                    continue;
                }
                let mut g = 0.0;
                for c in [(i + 1) * cols + j, i * cols + j + 1] {
                    if let Some(vessel) = self.vessel[c] {
                        g += 1.0 / (vessel + below[c]);
                    }
                }
                below[i * cols + j] = if g == 0.0 { r_leaf } else { 1.0 / g };
            }
        }
        below[0]
    }
}

pub mod terminal;
pub mod windkessel;
pub use windkessel::{VesselEnds, end_radius, windkessel_tree};

#[cfg(test)]
mod tests;
