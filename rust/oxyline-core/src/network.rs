//! The validated network model (vessels joined at named nodes, boundary conditions at free
//! ends) and its assembly into a circuit with output probes. Input is the canonical SI JSON
//! written by the Python layer (or any other front end).

use crate::circuit::{BoundaryTag, Circuit, SegmentGeom};
use crate::error::{Error, Result};
use crate::segment::{Blood, InertanceProfile, Wall, WallModel, segment_rlc};
use crate::waveform::{Waveform, WaveformSpec};
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
pub enum Arrangement {
    /// Capacitor at the proximal node, then R–L to the next node (default; flow-in/pressure-out).
    #[default]
    #[serde(rename = "inverted-L")]
    InvertedL,
    /// R–L, then the capacitor at the distal node.
    #[serde(rename = "L")]
    L,
    /// Half the capacitance at each end of the R–L branch.
    #[serde(rename = "pi")]
    Pi,
    /// svZeroDSolver's BloodVessel: R (and stenosis), then the capacitor, then L.
    #[serde(rename = "RCL")]
    Rcl,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BloodSpec {
    #[serde(default = "default_density")]
    pub density: f64,
    #[serde(default = "default_viscosity")]
    pub viscosity: f64,
}
fn default_density() -> f64 {
    1050.0
}
fn default_viscosity() -> f64 {
    3.5e-3
}
impl Default for BloodSpec {
    fn default() -> Self {
        BloodSpec {
            density: default_density(),
            viscosity: default_viscosity(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometrySpec {
    pub length: f64,
    pub radius_in: f64,
    pub radius_out: f64,
    #[serde(default)]
    pub wall_thickness: Option<f64>,
    #[serde(default)]
    pub youngs_modulus: Option<f64>,
    #[serde(default = "default_poisson")]
    pub poisson_ratio: f64,
}
fn default_poisson() -> f64 {
    0.5
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LumpedSpec {
    pub resistance: f64,
    #[serde(default)]
    pub inductance: f64,
    #[serde(default)]
    pub capacitance: f64,
    #[serde(default)]
    pub stenosis_coefficient: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VesselSpec {
    pub name: String,
    pub from: String,
    pub to: String,
    #[serde(default)]
    pub segments: Option<usize>,
    #[serde(default)]
    pub geometry: Option<GeometrySpec>,
    #[serde(default)]
    pub lumped: Option<LumpedSpec>,
    #[serde(default)]
    pub arrangement: Option<Arrangement>,
    #[serde(default = "yes")]
    pub output: bool,
}
fn yes() -> bool {
    true
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BoundarySpec {
    Flow {
        flow: WaveformSpec,
    },
    Pressure {
        pressure: WaveformSpec,
    },
    Resistance {
        resistance: f64,
        #[serde(default)]
        pressure: Option<WaveformSpec>,
    },
    Rcr {
        proximal_resistance: f64,
        capacitance: f64,
        distal_resistance: f64,
        #[serde(default)]
        pressure: Option<WaveformSpec>,
    },
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSpec {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub blood: BloodSpec,
    #[serde(default)]
    pub arrangement: Arrangement,
    #[serde(default)]
    pub wall_model: WallModel,
    #[serde(default)]
    pub inertance_profile: InertanceProfile,
    #[serde(default)]
    pub max_segment_length: Option<f64>,
    pub vessels: Vec<VesselSpec>,
    pub boundary_conditions: BTreeMap<String, BoundarySpec>,
    #[serde(default = "yes")]
    pub output_segments: bool,
    /// Species transport (oxygen and other solutes); absent for flow-only models.
    #[serde(default)]
    pub transport: Option<crate::transport::TransportSpec>,
}

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
    pub segment_unknowns: Vec<usize>,
    /// Segment positions (m from the vessel inlet, centre of the segment; NaN for lumped).
    pub segment_position: Vec<f64>,
}

impl Probes {
    pub fn all(&self) -> Vec<usize> {
        let mut v = self.vessel_unknowns.clone();
        v.extend(&self.segment_unknowns);
        v
    }
}

/// Summary figures for `oxyline validate`.
#[derive(Debug, Clone, Default)]
pub struct Summary {
    pub vessels: usize,
    pub segments: usize,
    pub nodes: usize,
    pub junctions: usize,
    pub inlets: usize,
    pub outlets: usize,
    pub total_compliance: f64,
    pub total_volume: f64,
    pub period: Option<f64>,
}

pub struct Assembled {
    pub circuit: Circuit,
    pub probes: Probes,
    pub summary: Summary,
}

/// A value as users write it: plain for ordinary magnitudes, exponent form for tiny or huge
/// ones (`{}` prints 1e-12 as 0.000000000001).
fn num(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() || (1e-4..1e7).contains(&a) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}
fn check_positive(element: &str, key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        return Err(Error::model(
            element,
            format!("{key} must be a finite number > 0, got {}", num(v)),
        ));
    }
    Ok(())
}
fn check_nonnegative(element: &str, key: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        return Err(Error::model(
            element,
            format!("{key} must be a finite number >= 0, got {}", num(v)),
        ));
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

pub fn parse(json: &str) -> Result<NetworkSpec> {
    serde_json::from_str(json).map_err(|e| Error::model("model", e.to_string()))
}

impl NetworkSpec {
    pub fn assemble(&self) -> Result<Assembled> {
        let blood = Blood {
            density: self.blood.density,
            viscosity: self.blood.viscosity,
        };
        check_positive("blood", "density", blood.density)?;
        check_positive("blood", "viscosity", blood.viscosity)?;
        if let Some(m) = self.max_segment_length {
            check_positive("segmentation", "max_length", m)?;
        }
        if self.vessels.is_empty() {
            return Err(Error::model("model", "has no vessels"));
        }
        // graph nodes in order of first appearance
        let mut node_index: HashMap<&str, usize> = HashMap::new();
        let mut node_names: Vec<&str> = Vec::new();
        let mut ends: Vec<Vec<(usize, bool)>> = Vec::new(); // (vessel, is_inlet_end)
        let mut seen_vessel: HashMap<&str, usize> = HashMap::new();
        for (vi, v) in self.vessels.iter().enumerate() {
            let el = format!("vessel '{}'", v.name);
            if v.name.is_empty() {
                return Err(Error::model(format!("vessel #{vi}"), "has an empty name"));
            }
            if let Some(prev) = seen_vessel.insert(&v.name, vi) {
                return Err(Error::model(
                    &el,
                    format!("name used twice (vessels #{prev} and #{vi})"),
                ));
            }
            if v.from == v.to {
                return Err(Error::model(
                    &el,
                    format!("starts and ends at the same node '{}'", v.from),
                ));
            }
            for (name, inlet) in [(&v.from, true), (&v.to, false)] {
                let k = *node_index.entry(name.as_str()).or_insert_with(|| {
                    node_names.push(name.as_str());
                    ends.push(Vec::new());
                    node_names.len() - 1
                });
                ends[k].push((vi, inlet));
            }
        }
        // boundary conditions sit on free vessel ends
        for node in self.boundary_conditions.keys() {
            let Some(&k) = node_index.get(node.as_str()) else {
                return Err(Error::model(
                    format!("boundary condition '{node}'"),
                    "names a node that no vessel starts or ends at",
                ));
            };
            if ends[k].len() > 1 {
                let names: Vec<&str> = ends[k]
                    .iter()
                    .map(|(v, _)| self.vessels[*v].name.as_str())
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
        for (k, e) in ends.iter().enumerate() {
            if e.len() == 1 && !self.boundary_conditions.contains_key(node_names[k]) {
                let v = &self.vessels[e[0].0];
                return Err(Error::model(
                    format!("vessel '{}'", v.name),
                    format!(
                        "its {} end at node '{}' is free and has no boundary condition",
                        if e[0].1 { "inlet" } else { "outlet" },
                        node_names[k]
                    ),
                ));
            }
        }
        let mut dsu = Dsu((0..node_names.len()).collect());
        for v in &self.vessels {
            dsu.union(node_index[v.from.as_str()], node_index[v.to.as_str()]);
        }
        let root = dsu.find(node_index[self.vessels[0].from.as_str()]);
        for v in &self.vessels {
            if dsu.find(node_index[v.from.as_str()]) != root {
                return Err(Error::model(
                    format!("vessel '{}'", v.name),
                    format!(
                        "is not connected to the rest of the network (vessel '{}' is in another part)",
                        self.vessels[0].name
                    ),
                ));
            }
        }
        if !self
            .boundary_conditions
            .values()
            .any(|b| !matches!(b, BoundarySpec::Flow { .. }))
        {
            let nodes: Vec<String> = self
                .boundary_conditions
                .keys()
                .map(|n| format!("'{n}'"))
                .collect();
            return Err(Error::model(
                "boundary conditions",
                format!(
                    "none fixes a pressure level (all of {} are flow conditions): add a pressure, resistance or rcr outlet",
                    nodes.join(", ")
                ),
            ));
        }

        let mut circuit = Circuit::default();
        for name in &node_names {
            circuit.add_node(*name, 0.0, 0.0);
        }
        let mut probes = Probes::default();
        let mut summary = Summary {
            vessels: self.vessels.len(),
            nodes: node_names.len(),
            ..Default::default()
        };
        for v in &self.vessels {
            let el = format!("vessel '{}'", v.name);
            let arrangement = v.arrangement.unwrap_or(self.arrangement);
            let p_from = node_index[v.from.as_str()];
            let p_to = node_index[v.to.as_str()];
            // per-segment (R, L, C, S, V, centre position) and (mean radius, x0, x1) for transport
            let mut segs: Vec<(f64, f64, f64, f64, f64, f64)> = Vec::new();
            let mut seg_geom: Vec<(f64, f64, f64)> = Vec::new();
            match (&v.geometry, &v.lumped) {
                (Some(_), Some(_)) => {
                    return Err(Error::model(
                        &el,
                        "give either geometry or lumped values, not both",
                    ));
                }
                (None, None) => return Err(Error::model(&el, "needs geometry or lumped values")),
                (None, Some(l)) => {
                    check_nonnegative(&el, "resistance", l.resistance)?;
                    check_nonnegative(&el, "inductance", l.inductance)?;
                    check_nonnegative(&el, "capacitance", l.capacitance)?;
                    // calibrated svZeroDSolver models carry negative coefficients: only finiteness is checked
                    if !l.stenosis_coefficient.is_finite() {
                        return Err(Error::model(
                            &el,
                            format!(
                                "stenosis_coefficient must be finite, got {}",
                                l.stenosis_coefficient
                            ),
                        ));
                    }
                    let n = if arrangement == Arrangement::Rcl {
                        1
                    } else {
                        v.segments.unwrap_or(1)
                    };
                    if n == 0 {
                        return Err(Error::model(&el, "segments must be >= 1, got 0"));
                    }
                    let nf = n as f64;
                    for _ in 0..n {
                        segs.push((
                            l.resistance / nf,
                            l.inductance / nf,
                            l.capacitance / nf,
                            l.stenosis_coefficient / nf,
                            0.0,
                            f64::NAN,
                        ));
                        seg_geom.push((0.0, 0.0, 0.0));
                    }
                }
                (Some(g), None) => {
                    if arrangement == Arrangement::Rcl {
                        return Err(Error::model(&el, "the RCL arrangement needs lumped values"));
                    }
                    check_positive(&el, "length", g.length)?;
                    check_positive(&el, "radius_in", g.radius_in)?;
                    check_positive(&el, "radius_out", g.radius_out)?;
                    let wall = match (g.wall_thickness, g.youngs_modulus) {
                        (Some(h), Some(e)) => {
                            check_positive(&el, "wall_thickness", h)?;
                            check_positive(&el, "youngs_modulus", e)?;
                            if !(g.poisson_ratio.is_finite()
                                && (0.0..0.5 + 1e-12).contains(&g.poisson_ratio))
                            {
                                return Err(Error::model(
                                    &el,
                                    format!(
                                        "poisson_ratio must be in [0, 0.5], got {}",
                                        g.poisson_ratio
                                    ),
                                ));
                            }
                            Some(Wall {
                                thickness: h,
                                youngs_modulus: e,
                                poisson_ratio: g.poisson_ratio,
                                model: self.wall_model,
                            })
                        }
                        (None, None) => None,
                        _ => {
                            return Err(Error::model(
                                &el,
                                "give both wall_thickness and youngs_modulus (or neither for a rigid tube)",
                            ));
                        }
                    };
                    let n = match (v.segments, self.max_segment_length) {
                        (Some(0), _) => {
                            return Err(Error::model(&el, "segments must be >= 1, got 0"));
                        }
                        (Some(n), _) => n,
                        (None, Some(m)) => {
                            ((g.length / m) * (1.0 - 1e-12)).ceil().max(1.0) as usize
                        }
                        (None, None) => 1,
                    };
                    let dx = g.length / n as f64;
                    for k in 0..n {
                        let r0 = g.radius_in + (g.radius_out - g.radius_in) * k as f64 / n as f64;
                        let r1 =
                            g.radius_in + (g.radius_out - g.radius_in) * (k + 1) as f64 / n as f64;
                        let s = segment_rlc(dx, r0, r1, blood, wall, self.inertance_profile);
                        segs.push((
                            s.resistance,
                            s.inductance,
                            s.compliance,
                            0.0,
                            s.volume,
                            (k as f64 + 0.5) * dx,
                        ));
                        seg_geom.push((0.5 * (r0 + r1), k as f64 * dx, (k + 1) as f64 * dx));
                    }
                }
            }
            let n = segs.len();
            summary.segments += n;
            let vessel_index = circuit.vessel_names.len();
            circuit.vessel_names.push(v.name.clone());
            // points 0..=n along the vessel; RCL has one interior point
            let mut points = vec![p_from];
            let interior = if arrangement == Arrangement::Rcl {
                1
            } else {
                n - 1
            };
            for k in 0..interior {
                points.push(circuit.add_node(
                    format!("vessel '{}' point {}", v.name, k + 1),
                    0.0,
                    0.0,
                ));
            }
            points.push(p_to);
            let mut branches = Vec::with_capacity(n);
            if arrangement == Arrangement::Rcl {
                let (r, l, c, s, vol, _) = segs[0];
                branches.push(circuit.add_branch(
                    format!("vessel '{}' resistance", v.name),
                    points[0],
                    points[1],
                    r,
                    0.0,
                    s,
                ));
                circuit.nodes[points[1]].capacitance += c;
                circuit.nodes[points[1]].volume += vol;
                branches.push(circuit.add_branch(
                    format!("vessel '{}' inductance", v.name),
                    points[1],
                    points[2],
                    0.0,
                    l,
                    0.0,
                ));
                circuit.segments.push(SegmentGeom {
                    vessel: vessel_index,
                    branch: branches[1],
                    nodes: [(points[1], 1.0), (points[1], 0.0)],
                    radius: 0.0,
                    x0: 0.0,
                    x1: 0.0,
                    volume: vol,
                    compliance: c,
                });
                summary.total_compliance += c;
                summary.total_volume += vol;
            } else {
                for (k, &(r, l, c, s, vol, _)) in segs.iter().enumerate() {
                    let name = if n == 1 {
                        format!("vessel '{}'", v.name)
                    } else {
                        format!("vessel '{}' segment {}", v.name, k + 1)
                    };
                    branches.push(circuit.add_branch(name, points[k], points[k + 1], r, l, s));
                    let (cp, cd) = match arrangement {
                        Arrangement::InvertedL => (1.0, 0.0),
                        Arrangement::L => (0.0, 1.0),
                        _ => (0.5, 0.5),
                    };
                    circuit.nodes[points[k]].capacitance += cp * c;
                    circuit.nodes[points[k + 1]].capacitance += cd * c;
                    circuit.nodes[points[k]].volume += cp * vol;
                    circuit.nodes[points[k + 1]].volume += cd * vol;
                    let (radius, x0, x1) = seg_geom[k];
                    let area = 2.0 * std::f64::consts::PI * radius * (x1 - x0);
                    circuit.nodes[points[k]].wall_area += cp * area;
                    circuit.nodes[points[k + 1]].wall_area += cd * area;
                    circuit.segments.push(SegmentGeom {
                        vessel: vessel_index,
                        branch: branches[k],
                        nodes: [(points[k], cp), (points[k + 1], cd)],
                        radius,
                        x0,
                        x1,
                        volume: vol,
                        compliance: c,
                    });
                    summary.total_compliance += c;
                    summary.total_volume += vol;
                }
            }
            if v.output {
                probes.vessels.push(v.name.clone());
                probes.vessel_unknowns.extend([
                    points[0],
                    points[points.len() - 1],
                    branches[0],
                    branches[branches.len() - 1],
                ]);
                if self.output_segments {
                    let ns = if arrangement == Arrangement::Rcl {
                        1
                    } else {
                        n
                    };
                    probes.segment_count.push(ns);
                    if arrangement == Arrangement::Rcl {
                        probes
                            .segment_unknowns
                            .extend([points[0], points[2], branches[0]]);
                        probes.segment_position.push(f64::NAN);
                    } else {
                        for k in 0..n {
                            probes
                                .segment_unknowns
                                .extend([points[k], points[k + 1], branches[k]]);
                            probes.segment_position.push(segs[k].5);
                        }
                    }
                }
            }
        }
        // boundary conditions
        for (node, bc) in &self.boundary_conditions {
            let k = node_index[node.as_str()];
            let inlet = ends[k][0].1;
            let el = format!("boundary condition '{node}'");
            let tag = circuit.boundaries.len();
            circuit.boundaries.push(BoundaryTag {
                name: node.clone(),
                inlet,
            });
            let wave = |spec: &Option<WaveformSpec>| -> Result<Waveform> {
                match spec {
                    Some(s) => Waveform::from_spec(s, &el),
                    None => Ok(Waveform::constant(0.0)),
                }
            };
            match bc {
                BoundarySpec::Flow { flow } => {
                    let w = Waveform::from_spec(flow, &el)?;
                    // positive flow runs along the vessel: into the network at an inlet end
                    let w = if inlet { w } else { negate(w) };
                    circuit.sources.push((k, w));
                    circuit.source_boundary.push(tag);
                    if inlet {
                        summary.inlets += 1;
                    } else {
                        summary.outlets += 1;
                    }
                }
                BoundarySpec::Pressure { pressure } => {
                    circuit
                        .fixed_pressures
                        .push((k, Waveform::from_spec(pressure, &el)?));
                    circuit.nodes[k].boundary = Some(tag);
                    if inlet {
                        summary.inlets += 1;
                    } else {
                        summary.outlets += 1;
                    }
                }
                BoundarySpec::Resistance {
                    resistance,
                    pressure,
                } => {
                    check_nonnegative(&el, "resistance", *resistance)?;
                    let g = circuit.add_node(format!("{el} distal"), 0.0, 0.0);
                    circuit.nodes[g].boundary = Some(tag);
                    circuit.fixed_pressures.push((g, wave(pressure)?));
                    let (a, b) = if inlet { (g, k) } else { (k, g) };
                    circuit.add_branch(format!("{el} resistance"), a, b, *resistance, 0.0, 0.0);
                    summary.outlets += usize::from(!inlet);
                    summary.inlets += usize::from(inlet);
                }
                BoundarySpec::Rcr {
                    proximal_resistance,
                    capacitance,
                    distal_resistance,
                    pressure,
                } => {
                    check_nonnegative(&el, "proximal_resistance", *proximal_resistance)?;
                    check_nonnegative(&el, "capacitance", *capacitance)?;
                    check_positive(&el, "distal_resistance", *distal_resistance)?;
                    let wk = circuit.add_node(format!("{el} capacitor"), *capacitance, 0.0);
                    circuit.nodes[wk].windkessel = true;
                    circuit.nodes[wk].boundary = Some(tag);
                    let g = circuit.add_node(format!("{el} distal"), 0.0, 0.0);
                    circuit.nodes[g].boundary = Some(tag);
                    circuit.fixed_pressures.push((g, wave(pressure)?));
                    if inlet {
                        circuit.add_branch(
                            format!("{el} distal resistance"),
                            g,
                            wk,
                            *distal_resistance,
                            0.0,
                            0.0,
                        );
                        circuit.add_branch(
                            format!("{el} proximal resistance"),
                            wk,
                            k,
                            *proximal_resistance,
                            0.0,
                            0.0,
                        );
                    } else {
                        circuit.add_branch(
                            format!("{el} proximal resistance"),
                            k,
                            wk,
                            *proximal_resistance,
                            0.0,
                            0.0,
                        );
                        circuit.add_branch(
                            format!("{el} distal resistance"),
                            wk,
                            g,
                            *distal_resistance,
                            0.0,
                            0.0,
                        );
                    }
                    summary.total_compliance += capacitance;
                    summary.outlets += usize::from(!inlet);
                    summary.inlets += usize::from(inlet);
                }
            }
        }
        summary.junctions = ends.iter().filter(|e| e.len() >= 3).count();
        // branch unknowns follow the node unknowns
        let nn = circuit.nodes.len();
        let shift = |u: &mut Vec<usize>, stride: usize| {
            for (i, x) in u.iter_mut().enumerate() {
                if i % stride >= stride - if stride == 4 { 2 } else { 1 } {
                    *x += nn;
                }
            }
        };
        shift(&mut probes.vessel_unknowns, 4);
        shift(&mut probes.segment_unknowns, 3);
        let periods: Vec<f64> = circuit
            .sources
            .iter()
            .chain(&circuit.fixed_pressures)
            .filter_map(|(_, w)| w.period())
            .collect();
        summary.period = periods.first().copied();
        Ok(Assembled {
            circuit,
            probes,
            summary,
        })
    }
}

fn negate(w: Waveform) -> Waveform {
    match w {
        Waveform::Constant(v) => Waveform::Constant(-v),
        Waveform::Table { t, v, m, mean } => Waveform::Table {
            t,
            v: v.iter().map(|x| -x).collect(),
            m: m.map(|m| m.iter().map(|x| -x).collect()),
            mean: -mean,
        },
        Waveform::Fourier {
            omega,
            mean,
            cos,
            sin,
        } => Waveform::Fourier {
            omega,
            mean: -mean,
            cos: cos.iter().map(|x| -x).collect(),
            sin: sin.iter().map(|x| -x).collect(),
        },
    }
}
