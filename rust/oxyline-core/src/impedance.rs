//! Input impedance over many frequencies in O(n) each: the frequency-domain matrix iωE + F has
//! the pattern of the time stepping's iteration matrices, so it gets the same elimination
//! (`sparse::SparseLu`: leaves-to-root on a tree, faer sparse LU where there are loops),
//! analysed once and refactorised per frequency. The dense `frequency::input_impedance` stays
//! as the independent check of small circuits.

use crate::circuit::{Circuit, Dae};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;
use crate::waveform::Waveform;
use faer::c64;

const ELEMENT: &str = "input_impedance";

/// Z(ω) = P_node / Q_injected (Pa·s/m³) for a unit flow injected at unknown `node`, boundary
/// pressures held at zero, at each angular frequency of `omegas` (rad/s, finite, >= 0).
pub fn input_impedances(dae: &Dae, node: usize, omegas: &[f64]) -> Result<Vec<c64>> {
    let n = dae.n;
    if node >= n {
        return Err(Error::model(ELEMENT, format!("unknown {node} out of {n}")));
    }
    if let Some(w) = omegas.iter().find(|w| !(w.is_finite() && **w >= 0.0)) {
        return Err(Error::model(
            ELEMENT,
            format!("angular frequency {w} must be finite and >= 0"),
        ));
    }
    let mut system = FrequencySystem::new(dae);
    // at ω = 0 capacitor rows have no pivot and the elimination falls back to faer's LU for
    // good, so zero frequency gets its own solver and the others keep the O(n) one
    let mut lu_ac = SparseLu::<c64>::analyse(n, &system.stamps)?;
    let mut lu_dc = match omegas.contains(&0.0) {
        true => Some(SparseLu::<c64>::analyse(n, &system.stamps)?),
        false => None,
    };
    let mut rhs = vec![c64::new(0.0, 0.0); n];
    omegas
        .iter()
        .map(|&omega| {
            system.set_frequency(dae, omega);
            let singular = |why: String| {
                Error::solver(
                    0.0,
                    format!("frequency-domain system at ω = {omega}: {why}"),
                )
            };
            let lu = match lu_dc.as_mut() {
                Some(dc) if omega == 0.0 => dc,
                _ => &mut lu_ac,
            };
            lu.factor(&system.vals).map_err(singular)?;
            rhs.iter_mut().for_each(|x| *x = c64::new(0.0, 0.0));
            rhs[node] = c64::new(1.0, 0.0);
            if !lu.solve_in_place(&mut rhs) {
                return Err(singular("singular matrix".into()));
            }
            Ok(rhs[node])
        })
        .collect()
}

/// Which part of the network an input impedance looks into from its node. Branches are
/// oriented along the flow path (vessels from `from` to `to`, boundary elements outwards), so
/// the branches leaving the node lead downstream and those entering it upstream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Direction {
    /// The branches leaving the node and what lies beyond them (the vessels starting there,
    /// an outlet condition), with the share of the node's capacitance of the segments that
    /// start there.
    #[default]
    Downstream,
    /// The branches entering the node and what lies behind them (the vessels ending there,
    /// an inlet condition), with the capacitance share of the segments that end there.
    Upstream,
    /// Every branch at the node: the parallel combination of both views.
    Both,
}

impl Direction {
    /// The direction named `name` ("downstream", "upstream", "both").
    pub fn parse(name: &str) -> Result<Direction> {
        match name {
            "downstream" => Ok(Direction::Downstream),
            "upstream" => Ok(Direction::Upstream),
            "both" => Ok(Direction::Both),
            _ => Err(Error::model(
                ELEMENT,
                format!("direction must be 'downstream', 'upstream' or 'both', got '{name}'"),
            )),
        }
    }
}

/// [`input_impedances_toward`] at frequencies in Hz (the unit users give), each checked to be
/// finite and >= 0 with the frequency as given in the message.
pub fn input_impedances_at_hz(
    circuit: &Circuit,
    dae: &Dae,
    node: usize,
    direction: Direction,
    frequencies: &[f64],
) -> Result<Vec<c64>> {
    if let Some(f) = frequencies.iter().find(|f| !(f.is_finite() && **f >= 0.0)) {
        return Err(Error::model(
            "impedance",
            format!("frequencies must be finite and >= 0 Hz, got {f}"),
        ));
    }
    let omegas: Vec<f64> = frequencies
        .iter()
        .map(|f| 2.0 * std::f64::consts::PI * f)
        .collect();
    input_impedances_toward(circuit, dae, node, direction, &omegas)
}

/// Z(ω) seen from circuit node `node` in `direction`, at each angular frequency of `omegas`
/// (see [`input_impedances`]). `dae` is the circuit's own DAE, used as it is for
/// [`Direction::Both`]; the other views solve a copy of the circuit in which every branch on
/// the other side is detached from the node and ends at a node of zero pressure instead (so
/// the part behind it, left without excitation, stays regular and carries nothing), and the
/// node keeps only the capacitance of its side's segments.
pub fn input_impedances_toward(
    circuit: &Circuit,
    dae: &Dae,
    node: usize,
    direction: Direction,
    omegas: &[f64],
) -> Result<Vec<c64>> {
    if direction == Direction::Both {
        return input_impedances(dae, node, omegas);
    }
    if node >= circuit.nodes.len() {
        return Err(Error::model(
            ELEMENT,
            format!("node {node} out of {}", circuit.nodes.len()),
        ));
    }
    let mut cut = circuit.clone();
    let downstream = direction == Direction::Downstream;
    // the capacitance the vessel ends on the other side put on the node
    let other_side: f64 = circuit
        .end_capacitors
        .iter()
        .filter(|&&(n, bi, _)| {
            let b = &circuit.branches[bi];
            n == node && (if downstream { b.to } else { b.from }) == node
        })
        .map(|&(_, _, c)| c)
        .sum();
    let c = &mut cut.nodes[node].capacitance;
    // (exactly zero when nothing else is left: rounding must not leave a tiny capacitor)
    *c = if (*c - other_side).abs() <= 1e-12 * c.abs() {
        0.0
    } else {
        *c - other_side
    };
    let mut ground = None;
    for bi in 0..cut.branches.len() {
        let b = &cut.branches[bi];
        if b.from == b.to || (if downstream { b.to } else { b.from }) != node {
            continue;
        }
        let g = *ground.get_or_insert_with(|| {
            let g = cut.add_node("impedance: detached side", 0.0, 0.0);
            cut.fixed_pressures.push((g, Waveform::constant(0.0)));
            g
        });
        let b = &mut cut.branches[bi];
        if downstream {
            b.to = g;
        } else {
            b.from = g;
        }
    }
    let side_branches = cut
        .branches
        .iter()
        .filter(|b| b.from != b.to && (b.from == node || b.to == node))
        .count();
    if side_branches == 0 && cut.nodes[node].capacitance == 0.0 {
        let side = if downstream { "downstream" } else { "upstream" };
        return Err(Error::model(
            circuit.names.node(node),
            format!("has nothing {side} of it (direction '{side}'): its impedance is infinite"),
        ));
    }
    if omegas.contains(&0.0) && !reaches_a_pressure(&cut, node, ground) {
        let side = if downstream { "downstream" } else { "upstream" };
        return Err(Error::model(
            circuit.names.node(node),
            format!(
                "its {side} side reaches no pressure boundary (a closed line): its impedance at \
                 0 Hz is infinite; ask for frequencies > 0"
            ),
        ));
    }
    let dae = cut.assemble()?;
    input_impedances(&dae, node, omegas)
}

/// Whether a prescribed-pressure node other than `ground` is reachable from `node` through
/// the branches of `circuit` (else nothing holds the side's mean pressure: Z(0) is infinite).
fn reaches_a_pressure(circuit: &Circuit, node: usize, ground: Option<usize>) -> bool {
    let nn = circuit.nodes.len();
    let mut fixed = vec![false; nn];
    for &(n, _) in &circuit.fixed_pressures {
        fixed[n] = Some(n) != ground;
    }
    let mut adj = vec![Vec::new(); nn];
    for b in &circuit.branches {
        adj[b.from].push(b.to);
        adj[b.to].push(b.from);
    }
    let mut seen = vec![false; nn];
    let mut stack = vec![node];
    seen[node] = true;
    while let Some(n) = stack.pop() {
        if fixed[n] {
            return true;
        }
        for &m in &adj[n] {
            if !seen[m] && Some(m) != ground {
                seen[m] = true;
                stack.push(m);
            }
        }
    }
    false
}

/// The frequency-domain matrix iωE + F in the stamp form `SparseLu` takes: F's entries, then
/// one diagonal stamp per row for iωE (duplicates are summed). Shared by the input impedance
/// and the periodic start (`integrate::periodic`), which solve the same system per frequency.
pub(crate) struct FrequencySystem {
    /// (row, column) of every value, in `vals` order
    pub stamps: Vec<(usize, usize)>,
    /// F's values, then the diagonal iωE of the frequency last set
    pub vals: Vec<c64>,
    nnz: usize,
}

impl FrequencySystem {
    pub fn new(dae: &Dae) -> Self {
        let n = dae.n;
        let nnz = dae.f.ptr[n] as usize;
        let mut stamps: Vec<(usize, usize)> = Vec::with_capacity(nnz + n);
        for i in 0..n {
            for k in dae.f.row(i) {
                stamps.push((i, dae.f.col[k] as usize));
            }
        }
        stamps.extend((0..n).map(|i| (i, i)));
        let mut vals: Vec<c64> = dae.f.val[..nnz].iter().map(|&v| c64::new(v, 0.0)).collect();
        vals.resize(nnz + n, c64::new(0.0, 0.0));
        FrequencySystem { stamps, vals, nnz }
    }

    /// Sets the diagonal stamps to iωE (ω in rad/s).
    pub fn set_frequency(&mut self, dae: &Dae, omega: f64) {
        for (v, &e) in self.vals[self.nnz..].iter_mut().zip(&dae.e) {
            *v = c64::new(0.0, omega * e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::parse;

    /// A bifurcation with a loop-free tree and the same with a loop: the O(n) elimination and
    /// faer's LU must reproduce the dense solve of `frequency::input_impedance`.
    #[test]
    fn matches_the_dense_solve() {
        let vessel = |name: &str, a: &str, b: &str, r: f64| {
            format!(
                r#"{{"name":"{name}","from":"{a}","to":"{b}","segments":5,"geometry":
                {{"length":0.05,"radius_in":{r},"radius_out":{r},"wall_thickness":2e-4,
                "youngs_modulus":1e6}}}}"#
            )
        };
        let bc = r#""in":{"type":"flow","flow":{"kind":"constant","value":1e-6}},
            "o1":{"type":"resistance","resistance":1e9,"pressure":{"kind":"constant","value":0}},
            "o2":{"type":"rcr","proximal_resistance":1e8,"capacitance":1e-10,
                  "distal_resistance":1e9,"pressure":{"kind":"constant","value":0}}"#;
        for looped in [false, true] {
            let mut vs = vec![
                vessel("p", "in", "j", 2e-3),
                vessel("d1", "j", "o1", 1.5e-3),
                vessel("d2", "j", "k", 1.2e-3),
                vessel("d3", "k", "o2", 1.2e-3),
            ];
            if looped {
                vs.push(vessel("x", "j", "k", 1e-3));
            }
            let json = format!(
                r#"{{"name":"t","blood":{{"density":1050,"viscosity":0.0035}},
                "vessels":[{}],"boundary_conditions":{{{bc}}}}}"#,
                vs.join(",")
            );
            let assembled = parse(&json).unwrap().assemble().unwrap();
            let dae = assembled.circuit.assemble().unwrap();
            let circuit = &assembled.circuit;
            let node = (0..circuit.nodes.len())
                .position(|i| circuit.names.node(i) == "in")
                .unwrap();
            let omegas = [0.0, 2.0, 30.0, 120.0];
            let z = input_impedances(&dae, node, &omegas).unwrap();
            for (&w, zs) in omegas.iter().zip(&z) {
                let zd = crate::frequency::input_impedance(&dae, node, w).unwrap();
                // two LU factorisations (no pivoting vs partial pivoting) of a ~100-unknown
                // system with entries over ~20 decades: agree to rounding times conditioning
                assert!(
                    (zs - zd).norm() <= 1e-9 * zd.norm(),
                    "{looped} {w}: {zs} vs {zd}"
                );
            }
        }
    }

    #[test]
    fn bad_frequencies_are_model_errors() {
        let dae_json = r#"{"name":"t","blood":{"density":1050,"viscosity":0.0035},
            "vessels":[{"name":"v","from":"a","to":"b","geometry":{"length":0.1,
            "radius_in":0.003,"radius_out":0.003}}],
            "boundary_conditions":{"a":{"type":"flow","flow":{"kind":"constant","value":1e-6}},
            "b":{"type":"resistance","resistance":1e9,"pressure":{"kind":"constant","value":0}}}}"#;
        let assembled = parse(dae_json).unwrap().assemble().unwrap();
        let dae = assembled.circuit.assemble().unwrap();
        assert!(input_impedances(&dae, 0, &[1.0, f64::NAN]).is_err());
        assert!(input_impedances(&dae, 0, &[-1.0]).is_err());
        assert!(input_impedances(&dae, dae.n, &[1.0]).is_err());
    }
}

#[cfg(test)]
mod direction_tests {
    use super::*;
    use crate::model::parse;

    /// A feed vessel into a junction with two daughters, lumped, in arrangement `arr`.
    fn junction(arr: &str) -> (crate::assemble::Assembled, usize) {
        let v = |name: &str, a: &str, b: &str, c: f64| {
            format!(
                r#"{{"name":"{name}","from":"{a}","to":"{b}","segments":3,"lumped":
                {{"resistance":5e7,"inductance":2e6,"capacitance":{c}}}}}"#
            )
        };
        let json = format!(
            r#"{{"name":"t","arrangement":"{arr}","vessels":[{},{},{}],
            "boundary_conditions":{{"in":{{"type":"flow","flow":{{"kind":"constant","value":1e-6}}}},
            "o1":{{"type":"resistance","resistance":1e9,"pressure":{{"kind":"constant","value":0}}}},
            "o2":{{"type":"resistance","resistance":2e9,"pressure":{{"kind":"constant","value":0}}}}}}}}"#,
            v("p", "in", "j", 6e-11),
            v("a", "j", "o1", 3e-11),
            v("b", "j", "o2", 2e-11)
        );
        let assembled = parse(&json).unwrap().assemble().unwrap();
        let c = &assembled.circuit;
        let j = (0..c.nodes.len())
            .position(|i| c.names.node(i) == "j")
            .unwrap();
        (assembled, j)
    }

    /// Kirchhoff at the node: the admittances of the two sides add up to the node's,
    /// whatever the arrangement puts at the node.
    #[test]
    fn the_two_sides_add_up_to_the_node() {
        for arr in ["inverted-L", "L", "pi"] {
            let (mut a, j) = junction(arr);
            // as a model holds it: the per-segment geometry is released after the build
            a.circuit.segments = Vec::new();
            let dae = a.circuit.assemble().unwrap();
            let omegas = [0.5, 3.0, 20.0];
            let z = |d| input_impedances_toward(&a.circuit, &dae, j, d, &omegas).unwrap();
            let (down, up, both) = (
                z(Direction::Downstream),
                z(Direction::Upstream),
                z(Direction::Both),
            );
            for k in 0..omegas.len() {
                let y = down[k].inv() + up[k].inv();
                let err = (y - both[k].inv()).norm() / both[k].inv().norm();
                assert!(err <= 1e-10, "{arr} {}: {err}", omegas[k]);
                assert!((down[k] - both[k]).norm() > 0.01 * both[k].norm());
            }
        }
    }

    #[test]
    fn an_empty_side_is_a_model_error() {
        let (a, _) = junction("L");
        let dae = a.circuit.assemble().unwrap();
        let c = &a.circuit;
        let inlet = (0..c.nodes.len())
            .position(|i| c.names.node(i) == "in")
            .unwrap();
        let e = input_impedances_toward(c, &dae, inlet, Direction::Upstream, &[1.0])
            .unwrap_err()
            .to_string();
        assert!(e.contains("nothing upstream"), "{e}");
    }

    #[test]
    fn unknown_directions_are_model_errors() {
        let e = Direction::parse("sideways").unwrap_err().to_string();
        assert!(e.contains("direction") && e.contains("sideways"), "{e}");
        assert_eq!(Direction::parse("both").unwrap(), Direction::Both);
    }
}
