//! Replacing a model's terminal elements by structured trees of the same steady resistance:
//! the steady resistance of a lumped terminal compartment (a tree of lumped vessels down to
//! pressure outlets, dead ends held at zero flow carrying no steady flow), the root radius of
//! a terminal by Murray's law, and the root vessel that keeps a terminal's name
//! (docs/structured-tree.md).

use super::{Stiffness, Units, element, fmt_g, poiseuille_resistance, wall_at};
use crate::error::{Error, Result};
use std::collections::{BTreeSet, HashMap};

/// A vessel as the compartment walk sees it: its ends and, for a lumped vessel, its
/// resistance (None: not a lumped element).
#[derive(Debug, Clone)]
pub struct Link {
    pub name: String,
    pub from: String,
    pub to: String,
    pub lumped_resistance: Option<f64>,
}

/// The condition at a compartment's node, as far as the walk reads it.
#[derive(Debug, Clone, PartialEq)]
pub enum End {
    /// No condition: an inner node.
    Open,
    /// A pressure outlet at this pressure [Pa].
    Pressure(f64),
    /// Zero flow: a dead end (a wall branch).
    ZeroFlow,
    /// Any other condition, as the user wrote it (for the message).
    Other(String),
}

/// A lumped terminal compartment: its vessels, its nodes, its steady resistance to its
/// pressure outlets [Pa s/m³] and their one pressure [Pa].
#[derive(Debug, Clone, PartialEq)]
pub struct Compartment {
    pub vessels: BTreeSet<String>,
    pub nodes: BTreeSet<String>,
    pub resistance: f64,
    pub pressure: f64,
}

fn err(node: &str, message: impl Into<String>) -> Error {
    Error::model(element(node), message)
}

/// The walk below one compartment's first vessel.
struct Walk<'a> {
    first: &'a str,
    leaving: HashMap<&'a str, Vec<&'a Link>>,
    ends: &'a dyn Fn(&str) -> End,
    out: Compartment,
    pressures: Vec<f64>,
}

impl Walk<'_> {
    /// Steady resistance from `v`'s inlet to the outlets (infinite: no steady flow): the
    /// vessel's resistance in series with the parallel combination of what its end feeds.
    fn below(&mut self, v: &Link) -> Result<f64> {
        let first = self.first;
        let Some(r) = v
            .lumped_resistance
            .filter(|_| !self.out.vessels.contains(&v.name))
        else {
            return Err(err(
                first,
                format!(
                    "terminal compartment vessel '{}' is not a lumped element of a tree",
                    v.name
                ),
            ));
        };
        self.out.vessels.insert(v.name.clone());
        self.out.nodes.insert(v.to.clone());
        let rest = match (self.ends)(&v.to) {
            End::ZeroFlow => return Ok(f64::INFINITY),
            End::Pressure(p) => {
                if !self.pressures.contains(&p) {
                    self.pressures.push(p);
                }
                0.0
            }
            End::Open if self.leaving.contains_key(v.to.as_str()) => {
                let mut g = 0.0;
                for w in self.leaving[v.to.as_str()].clone() {
                    g += 1.0 / self.below(w)?;
                }
                if g == 0.0 { f64::INFINITY } else { 1.0 / g }
            }
            end => {
                let shown = match end {
                    End::Other(text) => text,
                    _ => "None".into(),
                };
                return Err(err(
                    first,
                    format!(
                        "terminal compartment node '{}' has condition {shown} (only pressure \
                         outlets and zero-flow dead ends are replaced)",
                        v.to
                    ),
                ));
            }
        };
        Ok(r + rest)
    }
}

/// The lumped terminal compartment that starts with vessel `first` of `links` (every vessel
/// downstream of it); `ends(node)` is the condition at a node. Its outlets must share one
/// pressure and carry steady flow.
pub fn compartment(first: &str, links: &[Link], ends: &dyn Fn(&str) -> End) -> Result<Compartment> {
    let mut leaving: HashMap<&str, Vec<&Link>> = HashMap::new();
    for l in links {
        leaving.entry(l.from.as_str()).or_default().push(l);
    }
    let start = links
        .iter()
        .find(|l| l.name == first)
        .ok_or_else(|| err(first, "no such terminal vessel"))?;
    let mut walk = Walk {
        first,
        leaving,
        ends,
        out: Compartment {
            vessels: BTreeSet::new(),
            nodes: BTreeSet::new(),
            resistance: 0.0,
            pressure: 0.0,
        },
        pressures: Vec::new(),
    };
    let total = walk.below(start)?;
    if walk.pressures.len() != 1 || !total.is_finite() {
        let mut p = walk.pressures.clone();
        p.sort_by(f64::total_cmp);
        let shown: Vec<String> = p.iter().map(|x| fmt_g(*x)).collect();
        return Err(err(
            first,
            format!(
                "terminal compartment has outlet pressures [{}]",
                shown.join(", ")
            ),
        ));
    }
    walk.out.resistance = total;
    walk.out.pressure = walk.pressures[0];
    Ok(walk.out)
}

/// Murray's law (flow ∝ r³): the root radius of terminal `name` that carries `flow` of its
/// parent's `parent_flow` at parent radius `parent_radius`: r₀ = r_parent (Q / Q_parent)^(1/3).
pub fn murray_radius(
    name: &str,
    parent: &str,
    parent_radius: f64,
    flow: f64,
    parent_flow: f64,
) -> Result<f64> {
    let share = flow / parent_flow;
    if !(share > 0.0 && share <= 1.0) {
        return Err(err(
            name,
            format!("steady flow share {} of parent '{parent}'", fmt_g(share)),
        ));
    }
    Ok(parent_radius * share.powf(1.0 / 3.0))
}

/// A structured tree's root vessel of radius `r0` (SI): Olufsen's length `length_ratio` r0,
/// the tree's wall at r0, the tree vessels' segment count when `max_length` cuts them, and its
/// steady Poiseuille resistance at `viscosity`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RootVessel {
    pub length: f64,
    pub youngs_modulus: f64,
    pub wall_thickness: f64,
    pub segments: Option<usize>,
    pub resistance: f64,
}

/// The root vessel of radius `r0` that replaces terminal `name` (see [`RootVessel`]).
pub fn root_vessel(
    name: &str,
    r0: f64,
    length_ratio: f64,
    stiffness: Option<Stiffness>,
    max_length: Option<f64>,
    viscosity: f64,
) -> Result<RootVessel> {
    if !(r0 > 0.0 && r0 < f64::INFINITY) {
        return Err(err(
            name,
            format!("'root radius' must be in (0, inf), got {}", fmt_g(r0)),
        ));
    }
    let (e, h) = wall_at(name, stiffness, r0, Units::SI)?;
    let length = length_ratio * r0;
    // the tree vessels' rule (1e-9: a length a rounding above whole pieces is not cut again)
    let segments = max_length.map(|dx| ((length / dx - 1e-9).ceil() as usize).max(1));
    Ok(RootVessel {
        length,
        youngs_modulus: e,
        wall_thickness: h,
        segments,
        resistance: poiseuille_resistance(length, r0, r0, viscosity),
    })
}
