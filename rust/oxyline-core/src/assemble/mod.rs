//! Graph → circuit. `NetworkSpec::assemble` runs the steps in order: the node graph and its
//! checks (`graph`), each vessel's segments (`segments`) stamped into the circuit with its
//! probes (`vessel`), then one stamp per boundary condition (`boundary`, one file per type).
//! Every step is linear in the network size.

pub mod auto_segments;
pub(crate) mod boundary;
mod chamber;
pub(crate) mod checks;
mod graph;
mod heart;
mod initial;
pub mod segments;
mod sphere;
mod valve;
mod vessel;

use crate::circuit::Circuit;
use crate::error::Result;
use crate::model::{Arrangement, NetworkSpec};
use crate::output::Probes;
use crate::segment::Blood;

/// A heart block's chambers, in the order of its volume unknowns (output names).
const HEART_CHAMBERS: [&str; 4] = [
    "right_atrium",
    "right_ventricle",
    "left_atrium",
    "left_ventricle",
];
pub use chamber::chamber_elastance;
pub use segments::{SegmentRow, SegmentTable, arrangement};

/// Summary figures for `oxyline validate`.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub vessels: usize,
    pub segments: usize,
    /// Of those, the segments of vessels cut by the `auto` rule (the rest: counts the model
    /// states, `segments` or `max_length`, and one per lumped element).
    pub auto_segments: usize,
    /// The vessels cut by the `auto` rule.
    pub auto_vessels: usize,
    /// The `auto` rule's tolerance (None: no vessel is cut by it).
    pub auto_rtol: Option<f64>,
    pub nodes: usize,
    pub junctions: usize,
    /// The model's boundary conditions (the memory estimate counts them as elements).
    pub boundary_conditions: usize,
    pub inlets: usize,
    pub outlets: usize,
    pub total_compliance: f64,
    pub total_volume: f64,
    pub period: Option<f64>,
}

/// The assembled network: the circuit, where its outputs live, its segment table.
pub struct Assembled {
    pub circuit: Circuit,
    pub probes: Probes,
    pub summary: Summary,
    /// Every flow segment of every vessel, in model order (the segment table, its rows
    /// written on demand).
    pub segments: SegmentTable,
    /// Each vessel's arrangement as assembled (stated, or resolved by
    /// [`segments::arrangement`]), in `circuit.vessel_names` order (a heart element's names
    /// take its entry's): what a writer of the circuit reads.
    pub arrangements: Vec<crate::model::Arrangement>,
}

impl NetworkSpec {
    /// Graph → circuit: the node graph, each vessel (segments, or a heart element) with its
    /// probes, the heart blocks' links, then one stamp per boundary condition.
    pub fn assemble(&self) -> Result<Assembled> {
        let blood = self.checked_blood()?;
        let graph = graph::build(self)?;
        let mut st = Stamping::new(self, &graph)?;
        for vi in 0..self.vessels.len() {
            if is_heart_element(&self.vessels[vi]) {
                st.heart_element(vi)?;
            } else {
                st.segmented_vessel(vi, blood)?;
            }
            let a = segments::arrangement(self, &self.vessels[vi]);
            st.arrangements.resize(st.circuit.vessel_names.len(), a);
        }
        heart::resolve(&mut st.circuit, &st.links.hearts, &st.links.beds)?;
        st.boundary_conditions()?;
        Ok(st.finish())
    }

    /// The blood's properties and the segmentation setting, checked.
    fn checked_blood(&self) -> Result<Blood> {
        let blood = Blood {
            density: self.blood.density,
            viscosity: self.blood.viscosity,
        };
        checks::check_positive("blood", "density", blood.density)?;
        checks::check_positive("blood", "viscosity", blood.viscosity)?;
        if let Some(m) = self.max_segment_length {
            checks::check_positive("segmentation", "max_length", m)?;
        }
        if let Some(r) = self.segmentation_rtol.filter(|r| !(*r > 0.0 && *r < 1.0)) {
            return Err(crate::error::Error::model(
                "segmentation",
                format!("rtol must be in (0, 1), got {r}"),
            ));
        }
        Ok(blood)
    }
}

/// `segments: auto` stops its search at `MAX_AUTO_SEGMENTS`: a vessel that reaches it is not
/// within the tolerance, so it is refused (naming the vessel and rtol) instead of run at an
/// accuracy the rule did not give (e.g. rtol 1e-8 with first-order sections: every vessel).
fn check_auto_counts(
    spec: &NetworkSpec,
    counts: &[usize],
    rule: &auto_segments::AutoRule,
) -> Result<()> {
    let capped = spec
        .vessels
        .iter()
        .zip(counts)
        .find(|(v, n)| **n >= auto_segments::MAX_AUTO_SEGMENTS && segments::is_auto(spec, v));
    match capped {
        Some((v, _)) => Err(crate::error::Error::model(
            format!("vessel '{}'", v.name),
            format!(
                "segments: auto needs {} or more segments to stay within segmentation rtol =                  {:e}: raise rtol, use arrangement 'pi' (second order), or give its segments",
                auto_segments::MAX_AUTO_SEGMENTS,
                rule.rtol
            ),
        )),
        None => Ok(()),
    }
}

/// A `vessel` entry that is a heart element (valve, chamber, through-RC, sphere, heart block,
/// coronary bed) rather than a segmented vessel.
fn is_heart_element(v: &crate::model::VesselSpec) -> bool {
    v.valve.is_some()
        || v.chamber.is_some()
        || v.through_rc.is_some()
        || v.chamber_sphere.is_some()
        || v.heart_pulmonary.is_some()
        || v.coronary_bed.is_some()
}

/// The circuit, probes and segment table while the network's parts are stamped into them.
struct Stamping<'a> {
    spec: &'a NetworkSpec,
    graph: &'a graph::Graph<'a>,
    circuit: Circuit,
    probes: Probes,
    summary: Summary,
    table: SegmentTable,
    links: HeartLinks,
    hearts: Vec<(String, usize)>,
    /// The `segments: auto` rule (None: no vessel asks for it).
    auto: Option<auto_segments::AutoRule>,
    /// The points and branches of the vessel being stamped (one buffer for all).
    chain: vessel::Chain,
    /// `Assembled::arrangements`.
    arrangements: Vec<crate::model::Arrangement>,
}

impl<'a> Stamping<'a> {
    /// Storage for the whole network, allocated once at upper bounds (after the memory the
    /// model will need is checked against what it allows).
    fn new(spec: &'a NetworkSpec, graph: &'a graph::Graph<'a>) -> Result<Self> {
        let auto = auto_segments::AutoRule::of(spec);
        let counts: Vec<usize> = spec
            .vessels
            .iter()
            .map(|v| segments::count(spec, v, auto.as_ref()))
            .collect();
        if let Some(rule) = &auto {
            check_auto_counts(spec, &counts, rule)?;
        }
        let segments: usize = counts.iter().sum();
        // a segment adds one branch and (but for the last of its vessel) one node; a boundary
        // condition at most two nodes and two branches
        let bcs = spec.boundary_conditions.len();
        // refuse a model too large for the memory allowed before allocating for it
        crate::run::memory::check_model(
            &spec.name,
            segments,
            spec.vessels.len() + bcs,
            spec.transport
                .as_ref()
                .map(|t| (t.cells_per_segment.max(1.0), t.species.len())),
            spec.max_memory,
        )?;
        let mut circuit = Circuit::try_with_capacity(
            graph.names.len() + segments + 2 * bcs,
            segments + 2 * bcs,
            segments,
        )?;
        circuit.reserve_names(graph.names.len(), spec.vessels.len());
        for name in &graph.names {
            circuit.add_node(*name, 0.0, 0.0);
        }
        let mut probes = Probes::default();
        let with_output = spec.vessels.iter().filter(|v| v.output).count();
        probes.vessels.reserve(with_output);
        probes.vessel_unknowns.reserve(4 * with_output);
        if spec.output_segments {
            probes.segment_count.reserve(with_output);
            probes.segment_unknowns.reserve(3 * segments);
            probes.segment_position.reserve(segments);
        }
        let summary = Summary {
            vessels: spec.vessels.len(),
            nodes: graph.names.len(),
            junctions: graph.junctions(),
            boundary_conditions: bcs,
            auto_rtol: auto.map(|rule| rule.rtol),
            ..Default::default()
        };
        Ok(Stamping {
            spec,
            graph,
            circuit,
            probes,
            summary,
            table: SegmentTable::with_capacity(spec.vessels.len()),
            links: HeartLinks::default(),
            hearts: Vec::new(),
            auto,
            chain: vessel::Chain::default(),
            arrangements: Vec::with_capacity(spec.vessels.len()),
        })
    }

    /// A heart element and the probes of its element unknowns (chamber volumes, a sphere's
    /// wall, a coronary bed's intramyocardial volume, a heart block's volumes).
    fn heart_element(&mut self, vi: usize) -> Result<()> {
        let v = &self.spec.vessels[vi];
        let (circuit, probes) = (&mut self.circuit, &mut self.probes);
        let ends = self.graph.vessel_ends[vi];
        let chain = heart_element(circuit, v, ends, &mut self.links)?;
        if v.chamber.is_some() {
            // the chamber's volume is the element unknown it just added
            let volume = circuit.extras.len() - 1;
            probes.chamber_volumes.push((v.name.clone(), volume));
        }
        if v.chamber_sphere.is_some() {
            // its five wall unknowns, the last element unknowns it added
            let first = circuit.extras.len() - 5;
            for (k, var) in ["radius", "velo", "stress", "tau", "volume"]
                .iter()
                .enumerate()
            {
                probes
                    .element_unknowns
                    .push((format!("{var}:{}", v.name), first + k));
            }
        }
        if v.coronary_bed.is_some() {
            // its intramyocardial volume, the one element unknown it adds
            // (svZeroDSolver's `volume_im`)
            let volume = circuit.extras.len() - 1;
            (probes.element_unknowns).push((format!("volume_im:{}", v.name), volume));
        }
        if v.heart_pulmonary.is_some() {
            // its four volumes, then the pulmonary pressure, are its element unknowns
            let first = circuit.extras.len() - 5;
            for (k, part) in HEART_CHAMBERS.into_iter().enumerate() {
                let name = format!("{}:{part}", v.name);
                probes.chamber_volumes.push((name, first + k));
            }
            self.hearts.push((v.name.clone(), vi));
        }
        let interior = if v.chamber.is_some() || v.chamber_sphere.is_some() {
            initial::Interior::Inlet
        } else {
            initial::Interior::Linear
        };
        record_start(circuit, v, &chain, interior);
        if v.output {
            vessel::record_probes(
                probes,
                &v.name,
                &chain,
                &[],
                Arrangement::InvertedL,
                self.spec.output_segments,
            );
        }
        Ok(())
    }

    /// A vessel cut into segments (docs/physics.md §1), stamped with its probes; its rows go
    /// to the segment table.
    fn segmented_vessel(&mut self, vi: usize, blood: Blood) -> Result<()> {
        let (spec, v) = (self.spec, &self.spec.vessels[vi]);
        let arrangement = segments::arrangement(spec, v);
        let (made, segs) = segments::discretise(spec, vi, blood, arrangement, self.auto.as_ref())?;
        let ends = self.graph.vessel_ends[vi];
        let form = v
            .lumped
            .as_ref()
            .map(|l| l.stenosis_form)
            .unwrap_or_default();
        let circuit = &mut self.circuit;
        let friction = segments::friction(spec, v);
        // Kelvin–Voigt wall: relaxation time η/E (0: elastic)
        let relaxation = v
            .geometry
            .as_ref()
            .and_then(|g| g.youngs_modulus.map(|e| g.wall_viscosity / e))
            .unwrap_or(0.0);
        let physics = (arrangement, form, friction, relaxation);
        let chain = &mut self.chain;
        vessel::stamp(circuit, &v.name, &segs, physics, ends, chain);
        let interior = match arrangement {
            Arrangement::Rcl => initial::Interior::Rcl {
                resistance: segs[0].resistance,
                stenosis: segs[0].stenosis,
            },
            _ => initial::Interior::Linear,
        };
        record_start(circuit, v, chain, interior);
        if v.output {
            vessel::record_probes(
                &mut self.probes,
                &v.name,
                chain,
                &segs,
                arrangement,
                spec.output_segments,
            );
        }
        self.summary.segments += segs.len();
        if self.auto.is_some() && segments::is_auto(spec, v) {
            self.summary.auto_segments += segs.len();
            self.summary.auto_vessels += 1;
        }
        for s in &segs {
            self.summary.total_compliance += s.compliance;
            self.summary.total_volume += s.volume;
        }
        self.table.push(made);
        Ok(())
    }

    /// One stamp per boundary condition (`boundary`, one file per type).
    fn boundary_conditions(&mut self) -> Result<()> {
        let conditions = self.spec.boundary_conditions.iter();
        for ((node, bc), &k) in conditions.zip(&self.graph.condition_nodes) {
            let inlet = self.graph.ends(k)[0].1;
            let c = boundary::stamp(&mut self.circuit, node, k, inlet, bc)?;
            self.summary.total_compliance += c;
            self.summary.inlets += usize::from(inlet);
            self.summary.outlets += usize::from(!inlet);
        }
        Ok(())
    }

    /// The probes moved to DAE unknowns, the valves recorded, storage trimmed.
    fn finish(self) -> Assembled {
        let Stamping {
            arrangements,
            mut circuit,
            mut probes,
            mut summary,
            mut table,
            hearts,
            ..
        } = self;
        circuit.place_friction_cells();
        probes.shift_branches(circuit.nodes.len());
        probes.shift_extras(circuit.nodes.len() + circuit.branches.len());
        probes.record_valves(&circuit, &hearts);
        // the capacities above are upper bounds (a vessel's last segment adds no node)
        circuit.shrink_to_fit();
        probes.shrink_to_fit();
        table.shrink_to_fit();
        summary.period = circuit
            .sources
            .iter()
            .chain(&circuit.fixed_pressures)
            .find_map(|(_, w)| w.period());
        Assembled {
            circuit,
            probes,
            summary,
            segments: table,
            arrangements,
        }
    }
}

/// The vessel's `initial` and `initial_rate` values, if any.
fn record_start(
    circuit: &mut Circuit,
    v: &crate::model::VesselSpec,
    chain: &vessel::Chain,
    interior: initial::Interior,
) {
    let q0 = v.initial.as_ref().and_then(|x| x.flow_in);
    if let Some(values) = &v.initial {
        initial::record(circuit, chain, values, interior, false, q0);
    }
    if let Some(values) = &v.initial_rate {
        initial::record(circuit, chain, values, interior, true, q0);
    }
}

/// Heart blocks and the coronary beds that refer to them (resolved once all are stamped).
#[derive(Default)]
struct HeartLinks {
    hearts: Vec<(String, [usize; 2])>,
    beds: Vec<(usize, String, crate::model::CoronaryBedSpec)>,
}

/// Stamp a heart element (a `vessel` entry with `valve`, `chamber`, `through_rc`,
/// `heart_pulmonary` or `coronary_bed`).
fn heart_element(
    circuit: &mut Circuit,
    v: &crate::model::VesselSpec,
    ends: (usize, usize),
    links: &mut HeartLinks,
) -> Result<vessel::Chain> {
    let el = format!("vessel '{}'", v.name);
    let kinds = [
        v.geometry.is_some(),
        v.lumped.is_some(),
        v.valve.is_some(),
        v.chamber.is_some(),
        v.through_rc.is_some(),
        v.chamber_sphere.is_some(),
        v.heart_pulmonary.is_some(),
        v.coronary_bed.is_some(),
    ];
    if kinds.iter().filter(|&&k| k).count() != 1 {
        return Err(crate::error::Error::model(
            el,
            "give one of geometry, lumped, valve, chamber, through_rc, chamber_sphere, heart_pulmonary or coronary_bed",
        ));
    }
    if let Some(s) = &v.heart_pulmonary {
        let (chain, ventricles) = heart::stamp(circuit, &v.name, s, ends)?;
        links.hearts.push((v.name.clone(), ventricles));
        return Ok(chain);
    }
    if let Some(s) = &v.coronary_bed {
        let chain = heart::stamp_coronary(circuit, &v.name, s, ends)?;
        links
            .beds
            .push((circuit.elements.len() - 1, v.name.clone(), (**s).clone()));
        return Ok(chain);
    }
    if let Some(s) = &v.chamber_sphere {
        return sphere::stamp(circuit, &v.name, s, ends);
    }
    match (&v.valve, &v.chamber, &v.through_rc) {
        (Some(s), _, _) => valve::stamp(circuit, &v.name, s, ends),
        (_, Some(s), _) => chamber::stamp(circuit, &v.name, s, ends),
        (_, _, Some(s)) => valve::stamp_through_rc(circuit, &v.name, s, ends),
        _ => unreachable!("called for valves, chambers and through-RC elements only"),
    }
}

#[cfg(test)]
mod tests {
    use crate::model::parse;

    const MODEL: &str = r#"{
        "vessels": [
            {"name": "g", "from": "in", "to": "j", "segments": 4,
             "geometry": {"length": 0.1, "radius_in": 0.003, "radius_out": 0.002}},
            {"name": "l", "from": "j", "to": "out", "segments": 3,
             "lumped": {"resistance": 3e8, "inductance": 3e6, "capacitance": 3e-10,
                        "stenosis_coefficient": -3e11}},
            {"name": "r", "from": "j", "to": "out2", "segments": 5, "arrangement": "RCL",
             "lumped": {"resistance": 1e8, "capacitance": 1e-10}}],
        "boundary_conditions": {
            "in": {"type": "flow", "flow": {"kind": "constant", "value": 1e-6}},
            "out": {"type": "resistance", "resistance": 1e9},
            "out2": {"type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-9,
                     "distal_resistance": 1e9}}
    }"#;

    #[test]
    fn the_segment_table_is_the_circuit() {
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let counts: Vec<usize> = (0..3)
            .map(|v| a.segments.rows().filter(|s| s.vessel as usize == v).count())
            .collect();
        // RCL is svZeroDSolver's one BloodVessel whatever `segments` says
        assert_eq!(counts, vec![4, 3, 1]);
        assert_eq!(a.summary.segments, 8);
        // every segment's R and S is on a circuit branch, its C on a node
        let branch_r: f64 = a.circuit.branches.iter().map(|b| b.resistance).sum();
        let table_r: f64 = a.segments.rows().map(|s| s.resistance).sum();
        assert!((branch_r - (table_r + 1e9 + 1e8 + 1e9)).abs() <= 1e-12 * branch_r);
        let s: f64 = a.circuit.branches.iter().map(|b| b.stenosis).sum();
        assert!((s - -3e11).abs() <= 1e-12 * 3e11);
        let node_c: f64 = a.circuit.nodes.iter().map(|n| n.capacitance).sum();
        let table_c: f64 = a.segments.rows().map(|s| s.compliance).sum();
        assert!((node_c - table_c - 1e-9).abs() <= 1e-12 * node_c);
        assert!((a.summary.total_compliance - node_c).abs() <= 1e-12 * node_c);
        assert_eq!(
            (a.summary.inlets, a.summary.outlets, a.summary.junctions),
            (1, 2, 1)
        );
    }

    /// The rows written from the table's recipes tile each vessel: a geometric vessel's
    /// segments start where the one before ends and end at its length, their end radii follow
    /// the linear taper, and their volumes add up to the frustum's π L (r₀² + r₀r₁ + r₁²)/3;
    /// a lumped vessel's values are split evenly (3e8 Pa·s/m³ over 3 segments).
    #[test]
    fn rows_written_from_the_recipes_tile_the_vessels() {
        let a = parse(MODEL).unwrap().assemble().unwrap();
        assert_eq!(a.segments.len(), 8);
        let rows: Vec<_> = a.segments.rows().collect();
        let g: Vec<_> = rows.iter().filter(|s| s.vessel == 0).collect();
        let (l, r0, r1) = (0.1, 0.003, 0.002);
        for (k, s) in g.iter().enumerate() {
            assert_eq!(s.index as usize, k);
            let x = |k: usize| k as f64 * l / 4.0;
            assert!((s.x0 - x(k)).abs() <= 1e-15 && (s.x1 - x(k + 1)).abs() <= 1e-15);
            let taper = |x: f64| r0 + (r1 - r0) * x / l;
            assert!((s.radius_in - taper(s.x0)).abs() <= 1e-15);
            assert!((s.radius_out - taper(s.x1)).abs() <= 1e-15);
        }
        let volume: f64 = g.iter().map(|s| s.volume).sum();
        let frustum = std::f64::consts::PI * l * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0;
        assert!(
            (volume - frustum).abs() <= 1e-12 * frustum,
            "{volume} {frustum}"
        );
        let lumped: Vec<_> = rows.iter().filter(|s| s.vessel == 1).collect();
        assert_eq!(lumped.len(), 3);
        for s in lumped {
            assert!((s.resistance - 1e8).abs() <= 1e-6 && s.radius_in.is_nan());
        }
    }

    /// The default segmentation: a compliant geometric vessel that states no `segments` is cut
    /// by the `auto` rule (more than one segment: a 0.3 m artery at the 10 Hz of a model forced
    /// by a constant), a lumped one stays one segment, and a model-wide `max_length` (or the
    /// vessel's own `segments`) keeps the count it states.
    #[test]
    fn vessels_that_state_no_segments_are_cut_by_the_auto_rule() {
        let model = |seg: &str, own: &str| {
            format!(
                r#"{{"vessels": [
                {{"name": "g", "from": "in", "to": "j" {own},
                 "geometry": {{"length": 0.3, "radius_in": 0.004, "radius_out": 0.004,
                              "wall_thickness": 4e-4, "youngs_modulus": 4e5}}}},
                {{"name": "l", "from": "j", "to": "out",
                 "lumped": {{"resistance": 3e8, "inductance": 3e6, "capacitance": 3e-10}}}}],
                "boundary_conditions": {{
                    "in": {{"type": "flow", "flow": {{"kind": "constant", "value": 1e-6}}}},
                    "out": {{"type": "resistance", "resistance": 1e9}}}} {seg}}}"#
            )
        };
        let counts = |text: String| {
            let a = parse(&text).unwrap().assemble().unwrap();
            let per = |v: u32| a.segments.rows().filter(|s| s.vessel == v).count();
            (per(0), per(1), a.summary.auto_segments, a.summary.auto_rtol)
        };
        let (g, l, auto, rtol) = counts(model("", ""));
        assert!(g > 1 && l == 1 && auto == g, "{g} {l} {auto}");
        assert_eq!(rtol, Some(super::auto_segments::DEFAULT_RTOL));
        assert_eq!(
            counts(model(r#", "max_segment_length": 0.1"#, "")),
            (3, 1, 0, None)
        );
        assert_eq!(counts(model("", r#", "segments": 2"#)), (2, 1, 0, None));
    }

    /// The arrangement of a vessel that states none: π where the `auto` rule cuts it and the
    /// model states none either (the π ladder's count is about the square root of the
    /// inverted-L one at the same tolerance), inverted-L where it states its segments, and a
    /// stated arrangement (the model's or its own) is kept.
    #[test]
    fn auto_vessels_without_a_stated_arrangement_are_pi_ladders() {
        use crate::model::Arrangement::{InvertedL, L, Pi};
        let model = |top: &str, own: &str| {
            format!(
                r#"{{"vessels": [{{"name": "g", "from": "in", "to": "out" {own},
                 "geometry": {{"length": 0.3, "radius_in": 0.004, "radius_out": 0.004,
                              "wall_thickness": 4e-4, "youngs_modulus": 4e5}}}}],
                "boundary_conditions": {{
                    "in": {{"type": "flow", "flow": {{"kind": "constant", "value": 1e-6}}}},
                    "out": {{"type": "resistance", "resistance": 1e9}}}} {top}}}"#
            )
        };
        let of = |top: &str, own: &str| {
            let spec = parse(&model(top, own)).unwrap();
            let n = spec.assemble().unwrap().segments.len();
            (super::segments::arrangement(&spec, &spec.vessels[0]), n)
        };
        let (pi, n_pi) = of("", "");
        let (inv, n_inv) = of(r#", "arrangement": "inverted-L""#, "");
        assert_eq!((pi, inv), (Pi, InvertedL));
        assert!(n_pi * n_pi < 4 * n_inv && n_pi > 1, "{n_pi} {n_inv}");
        assert_eq!(of("", r#", "arrangement": "L""#).0, L);
        assert_eq!(of("", r#", "segments": 3"#), (InvertedL, 3));
    }
}
