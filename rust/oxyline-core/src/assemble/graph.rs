//! The vessel graph: nodes named by the vessels' ends, in order of first appearance, and the
//! checks on its shape (unique vessel names, boundary conditions on free ends only, every free
//! end closed by a condition, one connected piece, a pressure level fixed somewhere).
//!
//! Junctions need no element of their own: a node shared by several vessel ends is one circuit
//! node, and each vessel's arrangement puts its end capacitance there (see `vessel.rs`).

use crate::error::{Error, Result};
use crate::model::{BoundarySpec, NetworkSpec};
use std::collections::HashMap;

/// Graph nodes and, per node, the vessel ends meeting there.
pub(crate) struct Graph<'a> {
    pub index: HashMap<&'a str, usize>,
    pub names: Vec<&'a str>,
    /// Per node: (vessel, is the vessel's inlet end).
    pub ends: Vec<Vec<(usize, bool)>>,
    /// Per vessel: its (from, to) nodes (looked up once).
    pub vessel_ends: Vec<(usize, usize)>,
}

impl Graph<'_> {
    /// Nodes where three or more vessel ends meet.
    pub fn junctions(&self) -> usize {
        self.ends.iter().filter(|e| e.len() >= 3).count()
    }
}

/// Build the node graph of `spec` and check its shape.
pub(crate) fn build(spec: &NetworkSpec) -> Result<Graph<'_>> {
    if spec.vessels.is_empty() {
        return Err(Error::model("model", "has no vessels"));
    }
    let graph = collect_nodes(spec)?;
    check_boundary_ends(spec, &graph)?;
    check_connected(spec, &graph)?;
    check_pressure_level(spec)?;
    Ok(graph)
}

fn collect_nodes(spec: &NetworkSpec) -> Result<Graph<'_>> {
    let nv = spec.vessels.len();
    let mut g = Graph {
        index: HashMap::with_capacity(nv + 1),
        names: Vec::with_capacity(nv + 1),
        ends: Vec::with_capacity(nv + 1),
        vessel_ends: Vec::with_capacity(nv),
    };
    let mut seen_vessel: HashMap<&str, usize> = HashMap::with_capacity(nv);
    for (vi, v) in spec.vessels.iter().enumerate() {
        let el = || format!("vessel '{}'", v.name);
        if v.name.is_empty() {
            return Err(Error::model(format!("vessel #{vi}"), "has an empty name"));
        }
        if let Some(prev) = seen_vessel.insert(&v.name, vi) {
            return Err(Error::model(
                el(),
                format!("name used twice (vessels #{prev} and #{vi})"),
            ));
        }
        if v.from == v.to {
            return Err(Error::model(
                el(),
                format!("starts and ends at the same node '{}'", v.from),
            ));
        }
        let mut ends = [0; 2];
        for (e, (name, inlet)) in [(&v.from, true), (&v.to, false)].into_iter().enumerate() {
            let k = *g.index.entry(name.as_str()).or_insert_with(|| {
                g.names.push(name.as_str());
                g.ends.push(Vec::new());
                g.names.len() - 1
            });
            g.ends[k].push((vi, inlet));
            ends[e] = k;
        }
        g.vessel_ends.push((ends[0], ends[1]));
    }
    Ok(g)
}

/// Boundary conditions sit on free vessel ends, and every free end has one.
fn check_boundary_ends(spec: &NetworkSpec, g: &Graph<'_>) -> Result<()> {
    for node in spec.boundary_conditions.keys() {
        let Some(&k) = g.index.get(node.as_str()) else {
            return Err(Error::model(
                format!("boundary condition '{node}'"),
                "names a node that no vessel starts or ends at",
            ));
        };
        if g.ends[k].len() > 1 {
            let names: Vec<&str> = g.ends[k]
                .iter()
                .map(|(v, _)| spec.vessels[*v].name.as_str())
                .collect();
            return Err(Error::model(
                format!("boundary condition '{node}'"),
                format!(
                    "is on an internal node joining vessels {}",
                    names.join(", ")
                ),
            ));
        }
    }
    for (k, e) in g.ends.iter().enumerate() {
        if e.len() == 1 && !spec.boundary_conditions.contains_key(g.names[k]) {
            let v = &spec.vessels[e[0].0];
            return Err(Error::model(
                format!("vessel '{}'", v.name),
                format!(
                    "its {} end at node '{}' is free and has no boundary condition",
                    if e[0].1 { "inlet" } else { "outlet" },
                    g.names[k]
                ),
            ));
        }
    }
    Ok(())
}

struct Dsu(Vec<usize>);
impl Dsu {
    fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }
    fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        self.0[ra] = rb;
    }
}

fn check_connected(spec: &NetworkSpec, g: &Graph<'_>) -> Result<()> {
    let mut dsu = Dsu((0..g.names.len()).collect());
    for &(a, b) in &g.vessel_ends {
        dsu.union(a, b);
    }
    let root = dsu.find(g.vessel_ends[0].0);
    for (v, &(a, _)) in spec.vessels.iter().zip(&g.vessel_ends) {
        if dsu.find(a) != root {
            return Err(Error::model(
                format!("vessel '{}'", v.name),
                format!(
                    "is not connected to the rest of the network (vessel '{}' is in another part)",
                    spec.vessels[0].name
                ),
            ));
        }
    }
    Ok(())
}

/// Flow conditions alone leave the pressure level undetermined; a chamber's pressure law
/// P = E(t)(V − V_rest) fixes it (a closed loop needs no boundary condition).
fn check_pressure_level(spec: &NetworkSpec) -> Result<()> {
    if spec
        .boundary_conditions
        .values()
        .any(|b| !matches!(b, BoundarySpec::Flow { .. }))
        || spec.vessels.iter().any(|v| {
            v.chamber.is_some() || v.chamber_sphere.is_some() || v.heart_pulmonary.is_some()
        })
    {
        return Ok(());
    }
    let nodes: Vec<String> = spec
        .boundary_conditions
        .keys()
        .map(|n| format!("'{n}'"))
        .collect();
    Err(Error::model(
        "boundary conditions",
        format!(
            "none fixes a pressure level (all of {} are flow conditions): add a pressure, resistance or rcr outlet",
            nodes.join(", ")
        ),
    ))
}
