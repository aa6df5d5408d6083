//! The vessel graph: nodes named by the vessels' ends, in order of first appearance, and the
//! checks on its shape (unique vessel names, boundary conditions on free ends only, every free
//! end closed by a condition, one connected piece, a pressure level fixed somewhere).
//!
//! Junctions need no element of their own: a node shared by several vessel ends is one circuit
//! node, and each vessel's arrangement puts its end capacitance there (see `vessel.rs`).

use crate::error::{Error, Result};
use crate::model::{BoundarySpec, NetworkSpec};
use rustc_hash::FxHashMap;

/// Graph nodes, interned once to dense ids (names hashed once per vessel end, with a fast
/// non-cryptographic hasher: the keys are the model's own names), and per node the vessel
/// ends meeting there in compressed rows (one allocation for the whole graph).
pub(crate) struct Graph<'a> {
    pub names: Vec<&'a str>,
    /// Node k's vessel ends are `end_list[end_start[k]..end_start[k + 1]]`, in vessel order.
    end_start: Vec<u32>,
    /// (vessel, is the vessel's inlet end).
    end_list: Vec<(u32, bool)>,
    /// Per vessel: its (from, to) nodes (looked up once).
    pub vessel_ends: Vec<(usize, usize)>,
    /// Per boundary condition, in the model's (sorted) order: its node.
    pub condition_nodes: Vec<usize>,
}

impl Graph<'_> {
    /// The vessel ends meeting at node `k`: (vessel, is its inlet end).
    pub fn ends(&self, k: usize) -> &[(u32, bool)] {
        &self.end_list[self.end_start[k] as usize..self.end_start[k + 1] as usize]
    }
    /// Nodes where three or more vessel ends meet.
    pub fn junctions(&self) -> usize {
        self.end_start
            .windows(2)
            .filter(|w| w[1] - w[0] >= 3)
            .count()
    }
}

/// Build the node graph of `spec` and check its shape.
pub(crate) fn build(spec: &NetworkSpec) -> Result<Graph<'_>> {
    if spec.vessels.is_empty() {
        return Err(Error::model("model", "has no vessels"));
    }
    let (mut graph, index) = collect_nodes(spec)?;
    check_boundary_ends(spec, &mut graph, &index)?;
    check_connected(spec, &graph)?;
    check_pressure_level(spec)?;
    Ok(graph)
}

/// The nodes in order of first appearance, each vessel's (from, to) ids, and the vessel ends
/// per node; the name → id index is returned for the boundary conditions' lookup.
fn collect_nodes<'a>(spec: &'a NetworkSpec) -> Result<(Graph<'a>, FxHashMap<&'a str, u32>)> {
    let nv = spec.vessels.len();
    if u32::try_from(2 * nv + 1).is_err() {
        return Err(Error::model(
            "model",
            format!("has {nv} vessels, more than 2^31"),
        ));
    }
    let mut index: FxHashMap<&'a str, u32> =
        FxHashMap::with_capacity_and_hasher(nv + 1, Default::default());
    let mut names = Vec::with_capacity(nv + 1);
    let mut vessel_ends = Vec::with_capacity(nv);
    let mut seen_vessel: FxHashMap<&str, usize> =
        FxHashMap::with_capacity_and_hasher(nv, Default::default());
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
        let mut id = |name: &'a str| -> usize {
            *index.entry(name).or_insert_with(|| {
                names.push(name);
                (names.len() - 1) as u32
            }) as usize
        };
        let ends = (id(v.from.as_str()), id(v.to.as_str()));
        vessel_ends.push(ends);
    }
    let (end_start, end_list) = ends_by_node(names.len(), &vessel_ends);
    let graph = Graph {
        names,
        end_start,
        end_list,
        vessel_ends,
        condition_nodes: Vec::with_capacity(spec.boundary_conditions.len()),
    };
    Ok((graph, index))
}

/// Compressed rows of the vessel ends per node, each node's ends in vessel order (inlet end
/// before outlet end of a vessel), as the per-node lists they replace.
fn ends_by_node(nodes: usize, vessel_ends: &[(usize, usize)]) -> (Vec<u32>, Vec<(u32, bool)>) {
    let mut start = vec![0u32; nodes + 1];
    for &(a, b) in vessel_ends {
        start[a + 1] += 1;
        start[b + 1] += 1;
    }
    for k in 0..nodes {
        start[k + 1] += start[k];
    }
    let mut fill: Vec<u32> = start[..nodes].to_vec();
    let mut list = vec![(0u32, false); 2 * vessel_ends.len()];
    for (vi, &(a, b)) in vessel_ends.iter().enumerate() {
        for (k, inlet) in [(a, true), (b, false)] {
            list[fill[k] as usize] = (vi as u32, inlet);
            fill[k] += 1;
        }
    }
    (start, list)
}

/// Boundary conditions sit on free vessel ends, and every free end has one. Records each
/// condition's node (`condition_nodes`), so that no name is looked up again.
fn check_boundary_ends(
    spec: &NetworkSpec,
    g: &mut Graph<'_>,
    index: &FxHashMap<&str, u32>,
) -> Result<()> {
    let mut has_condition = vec![false; g.names.len()];
    for node in spec.boundary_conditions.keys() {
        let Some(&k) = index.get(node.as_str()) else {
            return Err(Error::model(
                format!("boundary condition '{node}'"),
                "names a node that no vessel starts or ends at",
            ));
        };
        let k = k as usize;
        if g.ends(k).len() > 1 {
            let names: Vec<&str> = g
                .ends(k)
                .iter()
                .map(|(v, _)| spec.vessels[*v as usize].name.as_str())
                .collect();
            return Err(Error::model(
                format!("boundary condition '{node}'"),
                format!(
                    "is on an internal node joining vessels {}",
                    names.join(", ")
                ),
            ));
        }
        has_condition[k] = true;
        g.condition_nodes.push(k);
    }
    for (k, &closed) in has_condition.iter().enumerate() {
        let e = g.ends(k);
        if e.len() == 1 && !closed {
            let v = &spec.vessels[e[0].0 as usize];
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
