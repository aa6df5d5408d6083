//! A vessel's `initial` and `initial_rate` (docs/physics.md §1.9): start values of its end
//! pressures and flows, spread to the unknowns inside the vessel so that a start given at the
//! ends is one the vessel's own equations accept (svZeroDSolver's `initial_condition` names
//! only the ends: its blocks have no interior unknowns).

use super::vessel::Chain;
use crate::circuit::{Circuit, StartValue, Unknown};
use crate::model::EndValues;

/// How the unknowns between a vessel's ends follow its end values.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Interior {
    /// svZeroDSolver's BloodVessel (RCL): the capacitor node sits behind R + S|Q| from the
    /// inlet, P_c = P_in − (R + S|Q_in|) Q_in (its rate: Ṗ_in − (R + 2S|Q_in|) Q̇_in).
    Rcl { resistance: f64, stenosis: f64 },
    /// A chamber: its pressure node is wired to the inlet (P = P_in).
    Inlet,
    /// Segments: linear in the point (branch) index between the two ends.
    Linear,
}

/// Record the start values of `chain` from `values` (`rate`: values of ẏ).
pub(crate) fn record(
    circuit: &mut Circuit,
    chain: &Chain,
    values: &EndValues,
    interior: Interior,
    rate: bool,
    flow_at_inlet: Option<f64>,
) {
    let (points, branches) = (&chain.points, &chain.branches);
    let mut push = |unknown, value: Option<f64>| {
        if let Some(value) = value {
            circuit.start_values.push(StartValue {
                unknown,
                value,
                rate,
            });
        }
    };
    let (np, nb) = (points.len(), branches.len());
    push(Unknown::Node(points[0]), values.pressure_in);
    push(Unknown::Node(points[np - 1]), values.pressure_out);
    push(Unknown::Branch(branches[0]), values.flow_in);
    if nb > 1 {
        push(Unknown::Branch(branches[nb - 1]), values.flow_out);
    }
    // an absent end value is 0 (docs/physics.md §1.9), so one given end still sets the
    // interior: leaving it at 0 would start the vessel with a jump its equations reject
    let lerp = |a: Option<f64>, b: Option<f64>, k: usize, n: usize| match (a, b) {
        (None, None) => None,
        (a, b) => {
            let (a, b) = (a.unwrap_or(0.0), b.unwrap_or(0.0));
            Some(a + (b - a) * k as f64 / n as f64)
        }
    };
    for (k, &p) in points.iter().enumerate().take(np - 1).skip(1) {
        let value = match interior {
            Interior::Rcl {
                resistance,
                stenosis,
            } => match (values.pressure_in, values.flow_in) {
                (None, None) => None,
                // absent values are 0 (§1.9): a given P_in alone puts the capacitor at P_in
                (p_in, q) => {
                    let (p_in, q) = (p_in.unwrap_or(0.0), q.unwrap_or(0.0));
                    if rate {
                        // the rate of (R + S|Q|)Q is (R + 2S|Q|)Q̇, with Q the start flow
                        let q0 = flow_at_inlet.unwrap_or(0.0);
                        Some(p_in - (resistance + 2.0 * stenosis * q0.abs()) * q)
                    } else {
                        Some(p_in - (resistance + stenosis * q.abs()) * q)
                    }
                }
            },
            Interior::Inlet => values.pressure_in,
            Interior::Linear => lerp(values.pressure_in, values.pressure_out, k, np - 1),
        };
        push(Unknown::Node(p), value);
    }
    for (k, &b) in branches
        .iter()
        .enumerate()
        .take(nb.saturating_sub(1))
        .skip(1)
    {
        push(
            Unknown::Branch(b),
            lerp(values.flow_in, values.flow_out, k, nb - 1),
        );
    }
}

#[cfg(test)]
mod tests {
    use crate::model::parse;

    #[test]
    fn an_rcl_vessel_starts_with_its_capacitor_behind_r_plus_s_q() {
        let m = r#"{
            "vessels": [{"name": "v", "from": "in", "to": "out", "arrangement": "RCL",
                         "lumped": {"resistance": 1e8, "stenosis_coefficient": 1e12,
                                    "capacitance": 1e-10, "inductance": 1e5},
                         "initial": {"pressure_in": 1e4, "flow_in": 1e-6, "flow_out": 2e-6},
                         "initial_rate": {"pressure_in": 5.0, "flow_in": 1e-7}}],
            "boundary_conditions": {
                "in": {"type": "flow", "flow": {"kind": "constant", "value": 1e-6}},
                "out": {"type": "resistance", "resistance": 1e9}}
        }"#;
        let a = parse(m).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let (y, yd) = (dae.initial_state(), dae.initial_rate_state());
        let [p_in, p_out, q_in, q_out] = a.probes.vessel_unknowns[..4] else {
            unreachable!()
        };
        let p_c = (0..dae.n)
            .find(|&i| dae.names.unknown(i).contains("point 1"))
            .unwrap();
        assert_eq!(
            (y[p_in], y[p_out], y[q_in], y[q_out]),
            (1e4, 0.0, 1e-6, 2e-6)
        );
        // P_c = P_in − (R + S|Q|)Q = 1e4 − (1e8 + 1e6)·1e-6; its rate Ṗ_in − (R + 2S|Q|)Q̇
        assert!((y[p_c] - (1e4 - 101.0)).abs() < 1e-9, "{}", y[p_c]);
        assert!(
            (yd[p_c] - (5.0 - 1.02e8 * 1e-7)).abs() < 1e-9,
            "{}",
            yd[p_c]
        );
        assert_eq!((yd[p_in], yd[q_in]), (5.0, 1e-7));
    }
}
