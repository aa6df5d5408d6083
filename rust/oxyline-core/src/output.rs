//! What a run records: the probes (where each output variable lives in the unknown vector),
//! the column schema (the names of every result variable, exported to Python so that no
//! column name is written twice) and the output selection (variables × vessels × segments).
//!
//! Row layout of the flow output: for every selected vessel its selected vessel variables, then
//! for every segment of every selected vessel its selected segment variables. Row layout of one
//! species block: the same with the species variables, then the mass-balance columns.

use crate::error::{Error, Result};
use std::collections::HashMap;

mod heart;
pub use heart::{HeartColumns, HeartRows, valve_status};

/// Flow variables of a vessel, in the order of `Probes::vessel_unknowns`.
pub const VESSEL_VARIABLES: [&str; 4] = ["pressure_in", "pressure_out", "flow_in", "flow_out"];
/// Flow variables of a segment, in the order of `Probes::segment_unknowns`.
pub const SEGMENT_VARIABLES: [&str; 3] = [
    "segment_pressure_in",
    "segment_pressure_out",
    "segment_flow",
];
/// Species variables of a vessel, in the order `Transport::observe` writes them.
pub const SPECIES_VESSEL_VARIABLES: [&str; 5] = [
    "concentration_in",
    "concentration_out",
    "flux_in",
    "flux_out",
    "wall_flux",
];
/// Species variables of a segment, in the order `Transport::observe` writes them.
pub const SPECIES_SEGMENT_VARIABLES: [&str; 5] = [
    "segment_concentration",
    "segment_flux",
    "segment_wall_flux",
    "segment_tl_resistance",
    "segment_tl_inductance",
];
/// Cumulative mass-balance columns of a species (always recorded: five numbers per row).
pub const BALANCE_VARIABLES: [&str; 5] = ["stored", "inflow", "outflow", "wall_uptake", "decay"];
/// Tissue-wall variables (docs/physics.md §3.7), written after the balance columns of every
/// species block when a species has a tissue wall: per output vessel, per output segment
/// (lumen-equivalent free concentrations, mol/m³; hypoxic volume fraction, 1), then the wall's
/// cumulative balance (mol).
pub const TISSUE_VESSEL_VARIABLES: [&str; 4] = [
    "wall_concentration_inner",
    "wall_concentration_outer",
    "wall_concentration_min",
    "hypoxic_fraction",
];
pub const TISSUE_SEGMENT_VARIABLES: [&str; 4] = [
    "segment_wall_concentration_inner",
    "segment_wall_concentration_outer",
    "segment_wall_concentration_min",
    "segment_hypoxic_fraction",
];
pub const TISSUE_BALANCE_VARIABLES: [&str; 4] = [
    "wall_stored",
    "wall_influx",
    "wall_consumed",
    "wall_outer_inflow",
];

/// Where each output variable lives in the unknown vector.
#[derive(Debug, Clone, Default)]
pub struct Probes {
    /// Vessels with output, in model order.
    pub vessels: Vec<String>,
    /// Unknown indices: for each output vessel [pressure_in, pressure_out, flow_in, flow_out].
    pub vessel_unknowns: Vec<usize>,
    /// Per output vessel, the number of segments and its first segment in the segment list.
    pub segment_count: Vec<usize>,
    /// For every segment of output vessels: [pressure_in, pressure_out, flow].
    /// (u32: the circuit refuses more than 2^32 unknowns; 12 B per segment less.)
    pub segment_unknowns: Vec<u32>,
    /// Segment positions (m from the vessel inlet, centre of the segment; NaN for lumped).
    pub segment_position: Vec<f64>,
    /// Each chamber's name and the unknown index of its blood volume (svZeroDSolver's `Vc`);
    /// a heart block's four chambers as `<vessel>:right_atrium` … `<vessel>:left_ventricle`.
    pub chamber_volumes: Vec<(String, usize)>,
    /// Other element unknowns by svZeroDSolver's variable name (a spherical chamber's
    /// `radius:<name>`, `velo`, `stress`, `tau`, `volume`) and their unknown index.
    pub element_unknowns: Vec<(String, usize)>,
    /// Each valve's status inputs (see [`ValveProbe`]).
    pub valves: Vec<ValveProbe>,
}

/// The vessel name inside a valve element's name `valve '<vessel>'`.
fn valve_vessel(element: &str) -> String {
    element
        .strip_prefix("valve '")
        .and_then(|s| s.strip_suffix('\''))
        .unwrap_or(element)
        .to_owned()
}

/// Where a valve's status is read (docs/physics.md §1.8, §1.10): the pressures behind and in
/// front of it and its flow, as unknown indices.
#[derive(Debug, Clone)]
pub struct ValveProbe {
    /// The valve vessel's name, or `<heart vessel>:<tricuspid|pulmonary|mitral|aortic>`.
    pub name: String,
    /// [pressure behind, pressure in front, flow].
    pub unknowns: [usize; 3],
    /// The heart block's on/off rule (open also while its flow is positive); else a `valve`
    /// element, open while the pressure behind exceeds the pressure in front.
    pub on_off: bool,
    /// A `valve` element's law (its `closure` is svZeroDSolver's `valve_status`); None for
    /// the heart block's on/off valves.
    pub law: Option<crate::element::valve::ValveLaw>,
}

impl Probes {
    pub fn all(&self) -> Vec<usize> {
        let mut v = self.vessel_unknowns.clone();
        v.extend(self.segment_unknowns.iter().map(|&u| u as usize));
        v
    }

    /// Chamber volumes were recorded as element-unknown indices: they follow the node
    /// pressures and branch flows.
    pub(crate) fn shift_extras(&mut self, n_nodes_and_branches: usize) {
        for (_, x) in self
            .chamber_volumes
            .iter_mut()
            .chain(self.element_unknowns.iter_mut())
        {
            *x += n_nodes_and_branches;
        }
    }

    /// The valves' status inputs of the assembled circuit's elements (unknown indices: nodes,
    /// then branches after `n_nodes`, then element unknowns after `n_nodes_and_branches`).
    pub(crate) fn record_valves(
        &mut self,
        circuit: &crate::circuit::Circuit,
        vessel_names: &[(String, usize)],
    ) {
        use crate::circuit::CircuitElement;
        let nn = circuit.nodes.len();
        let nx = nn + circuit.branches.len();
        let mut hearts = vessel_names.iter();
        for el in &circuit.elements {
            match el {
                CircuitElement::Valve {
                    name,
                    law,
                    branch,
                    from,
                    to,
                } => self.valves.push(ValveProbe {
                    name: valve_vessel(name),
                    unknowns: [*from, *to, nn + branch],
                    on_off: false,
                    law: Some(*law),
                }),
                CircuitElement::Heart {
                    nodes,
                    branches,
                    pulmonary,
                    ..
                } => {
                    let Some((vessel, _)) = hearts.next() else {
                        continue;
                    };
                    let ends = [
                        (nodes[0], nodes[1]),
                        (nodes[1], nx + pulmonary),
                        (nodes[2], nodes[3]),
                        (nodes[3], nodes[4]),
                    ];
                    for (k, part) in ["tricuspid", "pulmonary", "mitral", "aortic"]
                        .into_iter()
                        .enumerate()
                    {
                        self.valves.push(ValveProbe {
                            name: format!("{vessel}:{part}"),
                            unknowns: [ends[k].0, ends[k].1, nn + branches[k]],
                            on_off: true,
                            law: None,
                        });
                    }
                }
                _ => {}
            }
        }
    }

    /// Release spare capacity once every probe is recorded.
    pub(crate) fn shrink_to_fit(&mut self) {
        self.vessel_unknowns.shrink_to_fit();
        self.segment_count.shrink_to_fit();
        self.segment_unknowns.shrink_to_fit();
        self.segment_position.shrink_to_fit();
    }

    /// Branch (flow) probes were recorded as branch indices: flow unknowns follow the
    /// `n_nodes` pressure unknowns.
    pub(crate) fn shift_branches(&mut self, n_nodes: usize) {
        for (i, x) in self.vessel_unknowns.iter_mut().enumerate() {
            if i % 4 >= 2 {
                *x += n_nodes;
            }
        }
        let shift = u32::try_from(n_nodes).expect("more than 2^32 circuit nodes");
        for (i, x) in self.segment_unknowns.iter_mut().enumerate() {
            if i % 3 == 2 {
                *x += shift;
            }
        }
    }

    /// First segment of every output vessel, and the total (prefix sums of `counts`).
    fn starts(counts: &[usize]) -> Vec<usize> {
        let mut s = Vec::with_capacity(counts.len() + 1);
        s.push(0);
        for c in counts {
            s.push(s[s.len() - 1] + c);
        }
        s
    }
}

/// A resolved output selection. Indices refer to `Probes::vessels` and to the variable lists.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Selection {
    pub vessels: Vec<usize>,
    pub vessel_variables: Vec<usize>,
    pub segment_variables: Vec<usize>,
    pub species_vessel_variables: Vec<usize>,
    pub species_segment_variables: Vec<usize>,
}

const ELEMENT: &str = "simulation output";

impl Selection {
    /// Resolve the user's selection. `variables`/`vessels` None select everything (the
    /// default); `segments` false drops every segment variable. Unknown names are model errors
    /// naming them; species variables need a model with species.
    pub fn resolve(
        probes: &Probes,
        variables: Option<&[String]>,
        vessels: Option<&[String]>,
        segments: bool,
        has_species: bool,
    ) -> Result<Selection> {
        let all = |n: usize| (0..n).collect::<Vec<_>>();
        let mut sel = Selection {
            vessels: all(probes.vessels.len()),
            vessel_variables: all(VESSEL_VARIABLES.len()),
            segment_variables: all(SEGMENT_VARIABLES.len()),
            species_vessel_variables: all(SPECIES_VESSEL_VARIABLES.len()),
            species_segment_variables: all(SPECIES_SEGMENT_VARIABLES.len()),
        };
        if let Some(vars) = variables {
            sel.select_variables(vars, has_species)?;
        }
        if let Some(names) = vessels {
            let index: HashMap<&str, usize> = probes
                .vessels
                .iter()
                .enumerate()
                .map(|(i, n)| (n.as_str(), i))
                .collect();
            let mut chosen = Vec::with_capacity(names.len());
            for name in names {
                match index.get(name.as_str()) {
                    Some(&i) => chosen.push(i),
                    None => {
                        return Err(Error::model(
                            ELEMENT,
                            format!(
                                "unknown vessel '{name}' (not in the model, or `output: false`)"
                            ),
                        ));
                    }
                }
            }
            // model order, each once: the columns then follow the full run's order
            chosen.sort_unstable();
            chosen.dedup();
            sel.vessels = chosen;
        }
        if !segments {
            sel.segment_variables.clear();
            sel.species_segment_variables.clear();
        }
        Ok(sel)
    }

    fn select_variables(&mut self, vars: &[String], has_species: bool) -> Result<()> {
        let lists: [(&[&str], bool); 4] = [
            (&VESSEL_VARIABLES, false),
            (&SEGMENT_VARIABLES, false),
            (&SPECIES_VESSEL_VARIABLES, true),
            (&SPECIES_SEGMENT_VARIABLES, true),
        ];
        let mut chosen: [Vec<usize>; 4] = Default::default();
        for v in vars {
            let hit = lists
                .iter()
                .enumerate()
                .find_map(|(l, (names, _))| names.iter().position(|n| n == v).map(|i| (l, i)));
            let Some((l, i)) = hit else {
                let known: Vec<&str> = lists.iter().flat_map(|(n, _)| n.iter().copied()).collect();
                return Err(Error::model(
                    ELEMENT,
                    format!("unknown variable '{v}' (known: {})", known.join(", ")),
                ));
            };
            if lists[l].1 && !has_species {
                return Err(Error::model(
                    ELEMENT,
                    format!("variable '{v}' needs species transport, which the model has not"),
                ));
            }
            chosen[l].push(i);
        }
        for c in &mut chosen {
            c.sort_unstable();
            c.dedup();
        }
        let [a, b, c, d] = chosen;
        self.vessel_variables = a;
        self.segment_variables = b;
        self.species_vessel_variables = c;
        self.species_segment_variables = d;
        Ok(())
    }

    /// Segments recorded per selected vessel (empty when no segment variable is selected).
    /// The flow's counts (`species` false) are given when any segment variable is, flow or
    /// species: the segments' coordinates of a species-only segment output are the flow's.
    pub fn segment_count(&self, counts: &[usize], species: bool) -> Vec<usize> {
        let any = if species {
            !self.species_segment_variables.is_empty()
        } else {
            self.any_segment_variable()
        };
        if !any {
            return Vec::new();
        }
        self.vessels.iter().map(|&v| counts[v]).collect()
    }

    /// Unknown indices of the flow columns, in the row layout of the module docs.
    pub fn flow_columns(&self, probes: &Probes) -> Vec<usize> {
        let mut out = Vec::new();
        for &v in &self.vessels {
            out.extend(
                self.vessel_variables
                    .iter()
                    .map(|&j| probes.vessel_unknowns[4 * v + j]),
            );
        }
        if !self.segment_variables.is_empty() {
            let starts = Probes::starts(&probes.segment_count);
            for &v in &self.vessels {
                for s in starts[v]..starts[v + 1] {
                    out.extend(
                        self.segment_variables
                            .iter()
                            .map(|&j| probes.segment_unknowns[3 * s + j] as usize),
                    );
                }
            }
        }
        out
    }

    /// Whether any segment variable, flow or species, is selected.
    fn any_segment_variable(&self) -> bool {
        !self.segment_variables.is_empty() || !self.species_segment_variables.is_empty()
    }

    /// Segment positions of the selected vessels' segments (when any segment variable is
    /// selected, see `segment_count`).
    pub fn segment_position(&self, probes: &Probes) -> Vec<f64> {
        let starts = Probes::starts(&probes.segment_count);
        let mut out = Vec::new();
        if self.any_segment_variable() {
            for &v in &self.vessels {
                out.extend_from_slice(&probes.segment_position[starts[v]..starts[v + 1]]);
            }
        }
        out
    }

    /// Positions, within one species block of `Transport::observe` (vessels with
    /// `segment_counts` segments each), of the selected species columns.
    pub fn species_columns(&self, segment_counts: &[usize]) -> Vec<usize> {
        let (kv, ks) = (
            SPECIES_VESSEL_VARIABLES.len(),
            SPECIES_SEGMENT_VARIABLES.len(),
        );
        let starts = Probes::starts(segment_counts);
        let nv = segment_counts.len();
        let mut out = Vec::new();
        for &v in &self.vessels {
            out.extend(self.species_vessel_variables.iter().map(|&j| kv * v + j));
        }
        if !self.species_segment_variables.is_empty() {
            for &v in &self.vessels {
                for s in starts[v]..starts[v + 1] {
                    out.extend(
                        self.species_segment_variables
                            .iter()
                            .map(|&j| kv * nv + ks * s + j),
                    );
                }
            }
        }
        let balance = kv * nv + ks * starts[nv];
        out.extend((0..BALANCE_VARIABLES.len()).map(|j| balance + j));
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn probes() -> Probes {
        Probes {
            vessels: vec!["a".into(), "b".into()],
            vessel_unknowns: (0..8).collect(),
            segment_count: vec![2, 1],
            segment_unknowns: (100..109).collect(),
            segment_position: vec![0.5, 1.5, 0.5],
            chamber_volumes: Vec::new(),
            element_unknowns: Vec::new(),
            valves: Vec::new(),
        }
    }

    #[test]
    fn the_default_selection_is_every_probe_and_every_species_column() {
        let p = probes();
        let s = Selection::resolve(&p, None, None, true, true).unwrap();
        assert_eq!(s.flow_columns(&p), p.all());
        // 2 vessels × 5 + 3 segments × 5 + 5 balance columns
        assert_eq!(s.species_columns(&[2, 1]), (0..30).collect::<Vec<_>>());
    }

    #[test]
    fn a_selection_keeps_the_full_layout_order() {
        let p = probes();
        let vars: Vec<String> = ["flow_out", "segment_flow", "wall_flux"]
            .map(String::from)
            .to_vec();
        let s = Selection::resolve(&p, Some(&vars), Some(&["b".into()]), true, true).unwrap();
        assert_eq!(s.flow_columns(&p), vec![7, 108]);
        assert_eq!(s.segment_position(&p), vec![0.5]);
        assert_eq!(s.species_columns(&[2, 1]), vec![9, 25, 26, 27, 28, 29]);
        let none = Selection::resolve(&p, None, Some(&[]), true, true).unwrap();
        assert!(none.flow_columns(&p).is_empty());
    }

    #[test]
    fn unknown_names_are_model_errors_naming_them() {
        let p = probes();
        let e = Selection::resolve(&p, Some(&["flux".into()]), None, true, true).unwrap_err();
        assert!(e.to_string().contains("unknown variable 'flux'"), "{e}");
        let e = Selection::resolve(&p, None, Some(&["c".into()]), true, true).unwrap_err();
        assert!(e.to_string().contains("unknown vessel 'c'"), "{e}");
        let e = Selection::resolve(&p, Some(&["flux_in".into()]), None, true, false).unwrap_err();
        assert!(e.to_string().contains("needs species transport"), "{e}");
    }
}
