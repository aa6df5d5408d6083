//! Stamp one vessel's segments into the circuit: its chain of interior points and series R–L
//! branches, each segment's capacitance, volume and wall area shared between the branch's end
//! nodes as the arrangement says (a junction node collects the shares of every vessel end
//! meeting there), the segment geometry transport needs, and the vessel's output probes.

use super::segments::SegmentRow;
use crate::circuit::{ChainRuleCapacitor, Circuit, Label, Part, SegmentGeom};
use crate::model::{Arrangement, StenosisForm};
use crate::output::Probes;
use crate::segment::WallFriction;

/// The circuit nodes along a vessel (inlet node, interior points, outlet node) and its branches.
#[derive(Default)]
pub(crate) struct Chain {
    pub points: Vec<usize>,
    pub branches: Vec<usize>,
}

/// Stamp vessel `name` (index `vessel` in `circuit.vessel_names`) between graph nodes
/// `p_from` and `p_to`; `form` says how generalized-α writes an RCL vessel's stenosis,
/// `friction` whether each segment's branch carries Womersley friction cells, `relaxation`
/// the wall's η/E (s; 0: elastic, else a Kelvin–Voigt wall behind each capacitance). The
/// vessel's points and branches are written into `chain` (cleared first: one buffer serves
/// every vessel of a network, instead of two small allocations per vessel).
pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    segs: &[SegmentRow],
    (arrangement, form, friction, relaxation): (Arrangement, StenosisForm, WallFriction, f64),
    (p_from, p_to): (usize, usize),
    chain: &mut Chain,
) {
    let vessel = circuit.add_vessel(name);
    let n = segs.len();
    // points 0..=n along the vessel; RCL has one interior point
    let interior = if arrangement == Arrangement::Rcl {
        1
    } else {
        n - 1
    };
    let Chain { points, branches } = chain;
    points.clear();
    branches.clear();
    points.push(p_from);
    for k in 0..interior {
        let label = label(vessel, Part::Point, k + 1);
        points.push(circuit.add_node(label, 0.0, 0.0));
    }
    points.push(p_to);
    if arrangement == Arrangement::Rcl {
        stamp_rcl(circuit, vessel, &segs[0], points, form, branches);
    } else {
        stamp_segments(circuit, vessel, segs, arrangement, points, branches);
    }
    if relaxation > 0.0 && arrangement != Arrangement::Rcl {
        let (cp, cd) = shares(arrangement);
        for (k, s) in segs.iter().enumerate() {
            circuit.add_wall_viscosity(points[k], cp * s.compliance, relaxation);
            circuit.add_wall_viscosity(points[k + 1], cd * s.compliance, relaxation);
        }
    }
    if friction == WallFriction::Womersley && arrangement != Arrangement::Rcl {
        stamp_friction_cells(circuit, vessel, segs, branches);
    }
}

fn label(vessel: usize, part: Part, k: usize) -> Label {
    Label::Vessel {
        vessel: vessel as u32,
        part,
        k: k as u32,
    }
}

/// svZeroDSolver's BloodVessel: R (and stenosis), then C at the interior point, then L. In
/// svZeroDSolver's form a stenosis with a capacitor also registers the capacitor row for
/// generalized-α's chain-rule form (docs/svzerod.md, "C + stenosis").
fn stamp_rcl(
    circuit: &mut Circuit,
    vessel: usize,
    s: &SegmentRow,
    points: &[usize],
    form: StenosisForm,
    branches: &mut Vec<usize>,
) {
    let b0 = circuit.add_branch(
        label(vessel, Part::Resistance, 0),
        points[0],
        points[1],
        s.resistance,
        0.0,
        s.stenosis,
    );
    circuit.nodes[points[1]].capacitance += s.compliance;
    circuit.nodes[points[1]].volume += s.volume;
    if form == StenosisForm::SvZeroD && s.stenosis != 0.0 && s.compliance > 0.0 {
        circuit.chain_rule.push(ChainRuleCapacitor {
            node: points[1],
            inlet: points[0],
            flow: b0,
            capacitance: s.compliance,
            resistance: s.resistance,
            stenosis: s.stenosis,
        });
    }
    let b1 = circuit.add_branch(
        label(vessel, Part::Inductance, 0),
        points[1],
        points[2],
        0.0,
        s.inductance,
        0.0,
    );
    circuit.segments.push(SegmentGeom {
        vessel,
        branch: b1,
        nodes: [(points[1], 1.0), (points[1], 0.0)],
        radius: 0.0,
        x0: 0.0,
        x1: 0.0,
        volume: s.volume,
        compliance: s.compliance,
    });
    branches.extend([b0, b1]);
}

/// The shares of a segment's C, volume and wall area at its (proximal, distal) node.
fn shares(arrangement: Arrangement) -> (f64, f64) {
    match arrangement {
        Arrangement::InvertedL => (1.0, 0.0),
        Arrangement::L => (0.0, 1.0),
        _ => (0.5, 0.5),
    }
}

/// One R–L branch per segment; C, volume and wall area at the ends by the arrangement.
fn stamp_segments(
    circuit: &mut Circuit,
    vessel: usize,
    segs: &[SegmentRow],
    arrangement: Arrangement,
    points: &[usize],
    branches: &mut Vec<usize>,
) {
    let n = segs.len();
    let (cp, cd) = shares(arrangement);
    for (k, s) in segs.iter().enumerate() {
        let label = if n == 1 {
            label(vessel, Part::Whole, 0)
        } else {
            label(vessel, Part::Segment, k + 1)
        };
        let (a, b) = (points[k], points[k + 1]);
        let branch = circuit.add_branch(label, a, b, s.resistance, s.inductance, s.stenosis);
        branches.push(branch);
        circuit.nodes[a].capacitance += cp * s.compliance;
        circuit.nodes[b].capacitance += cd * s.compliance;
        circuit.nodes[a].volume += cp * s.volume;
        circuit.nodes[b].volume += cd * s.volume;
        let radius = s.mean_radius();
        let area = 2.0 * std::f64::consts::PI * radius * (s.x1 - s.x0);
        circuit.nodes[a].wall_area += cp * area;
        circuit.nodes[b].wall_area += cd * area;
        if k == 0 {
            circuit.end_capacitors.push((a, branch, cp * s.compliance));
        }
        if k + 1 == n {
            circuit.end_capacitors.push((b, branch, cd * s.compliance));
        }
        circuit.segments.push(SegmentGeom {
            vessel,
            branch,
            nodes: [(a, cp), (b, cd)],
            radius,
            x0: s.x0,
            x1: s.x1,
            volume: s.volume,
            compliance: s.compliance,
        });
    }
}

/// Womersley friction (`crate::womersley`): each segment's branch gets the flat-profile
/// inertance and Poiseuille resistance (as the row says) in series with its R‖L cells.
fn stamp_friction_cells(
    circuit: &mut Circuit,
    vessel: usize,
    segs: &[SegmentRow],
    branches: &[usize],
) {
    for (k, (s, &b)) in segs.iter().zip(branches).enumerate() {
        let f = crate::womersley::cells(s.resistance, s.inductance);
        circuit.branches[b].inductance = f.inductance;
        for (r, l) in f.cells {
            circuit.add_friction_cell(label(vessel, Part::FrictionCell, k + 1), b, r, l);
        }
    }
}

/// Record the vessel's probes: its end pressures and flows and, with `segments`, every
/// segment's end pressures and flow (branch indices; shifted to unknowns once all nodes exist).
pub(crate) fn record_probes(
    probes: &mut Probes,
    name: &str,
    chain: &Chain,
    segs: &[SegmentRow],
    arrangement: Arrangement,
    segments: bool,
) {
    let (points, branches) = (&chain.points, &chain.branches);
    probes.vessels.push(name.to_owned());
    probes.vessel_unknowns.extend([
        points[0],
        points[points.len() - 1],
        branches[0],
        branches[branches.len() - 1],
    ]);
    if !segments {
        return;
    }
    if arrangement == Arrangement::Rcl {
        probes.segment_count.push(1);
        probes
            .segment_unknowns
            .extend([points[0], points[2], branches[0]].map(index32));
        probes.segment_position.push(f64::NAN);
    } else {
        probes.segment_count.push(segs.len());
        for (k, s) in segs.iter().enumerate() {
            probes
                .segment_unknowns
                .extend([points[k], points[k + 1], branches[k]].map(index32));
            probes.segment_position.push(s.position);
        }
    }
}

/// A circuit index as stored in the probes (the circuit is refused beyond 2^32 unknowns).
fn index32(i: usize) -> u32 {
    u32::try_from(i).expect("more than 2^32 circuit elements")
}
