//! `svzerod-inlet`: svZeroDSolver's `RESISTANCE` or `RCR` block at a vessel inlet, with the
//! equations svZeroDSolver writes for it (docs/svzerod.md). Its blocks take Q as the flow of
//! their node along the vessel, so at an inlet the condition reads as an outlet condition
//! would with the flow reversed: P_in = P_d + R Q, and for an RCR P_in = P_c + R_p Q,
//! C dP_c/dt = Q − (P_c − P_d)/R_d (the Windkessel fills as the vessel draws from it).
//!
//! As a circuit this is the ordinary stamp with every element negated: a branch row reads
//! P_from − P_to = R Q, so a branch from the distal node to the inlet with −R gives
//! P_in = P_d + R Q, and a capacitor node of −C whose flow balance is
//! −C dP_c/dt = Q_d − Q gives C dP_c/dt = Q − Q_d with Q_d = (P_c − P_d)/R_d through a −R_d
//! branch. The equations are linear with constant coefficients; only their signs are unusual.

use super::Site;
use crate::assemble::checks::{check_nonnegative, check_positive};
use crate::circuit::{Circuit, Part};
use crate::error::{Error, Result};
use crate::model::SvzerodInletSpec;

pub(super) fn stamp(circuit: &mut Circuit, site: &Site, s: &SvzerodInletSpec) -> Result<()> {
    let el = &site.element;
    if !site.inlet {
        return Err(Error::model(
            el,
            "an svzerod-inlet condition must sit at a vessel's inlet end (at an outlet use \
             resistance or rcr)",
        ));
    }
    let g = circuit.add_node(site.label(Part::Distal), 0.0, 0.0);
    circuit.nodes[g].boundary = Some(site.tag as u32);
    circuit
        .fixed_pressures
        .push((g, site.waveform(&s.pressure)?));
    match (
        s.resistance,
        s.proximal_resistance,
        s.capacitance,
        s.distal_resistance,
    ) {
        (Some(r), None, None, None) => {
            check_nonnegative(el, "resistance", r)?;
            circuit.add_branch(site.label(Part::Resistance), g, site.node, -r, 0.0, 0.0);
        }
        (None, Some(rp), Some(c), Some(rd)) => {
            check_nonnegative(el, "proximal_resistance", rp)?;
            check_nonnegative(el, "capacitance", c)?;
            check_positive(el, "distal_resistance", rd)?;
            let wk = circuit.add_node(site.label(Part::Capacitor), -c, 0.0);
            circuit.nodes[wk].windkessel = true;
            circuit.nodes[wk].boundary = Some(site.tag as u32);
            let distal = site.label(Part::DistalResistance);
            circuit.add_branch(distal, g, wk, -rd, 0.0, 0.0);
            let proximal = site.label(Part::ProximalResistance);
            circuit.add_branch(proximal, wk, site.node, -rp, 0.0, 0.0);
        }
        _ => {
            return Err(Error::model(
                el,
                "an svzerod-inlet condition needs either resistance, or proximal_resistance, \
                 capacitance and distal_resistance",
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use crate::integrate::steady_state;
    use crate::model::parse;

    fn model(inlet: &str) -> String {
        format!(
            r#"{{
            "vessels": [{{"name": "v", "from": "in", "to": "out", "arrangement": "RCL",
                         "lumped": {{"resistance": 1e8, "capacitance": 1e-10}}}}],
            "boundary_conditions": {{
                "in": {inlet},
                "out": {{"type": "flow", "flow": {{"kind": "constant", "value": 2e-6}}}}}}
        }}"#
        )
    }

    #[test]
    fn steady_inlet_pressure_is_svzerods_pd_plus_r_q() {
        // 2e-6 m³/s drawn along the vessel: svZeroDSolver's P_in = P_d + R Q (not P_d − R Q),
        // for an RCR with R = R_p + R_d (the capacitor carries no steady flow)
        for (inlet, r) in [
            (
                r#"{"type": "svzerod-inlet", "resistance": 1e9,
                    "pressure": {"kind": "constant", "value": 1000.0}}"#,
                1e9,
            ),
            (
                r#"{"type": "svzerod-inlet", "proximal_resistance": 1e8, "capacitance": 1e-9,
                    "distal_resistance": 9e8, "pressure": {"kind": "constant", "value": 1000.0}}"#,
                1e9,
            ),
        ] {
            let a = parse(&model(inlet)).unwrap().assemble().unwrap();
            let dae = a.circuit.assemble().unwrap();
            let y = steady_state(&dae).unwrap();
            let [p_in, p_out, q_in, _] = a.probes.vessel_unknowns[..4] else {
                unreachable!()
            };
            let expected = 1000.0 + r * 2e-6;
            // one sparse solve: a few ulps of the largest term
            assert!((y[p_in] - expected).abs() < 1e-12 * expected, "{}", y[p_in]);
            assert!((y[q_in] - 2e-6).abs() < 1e-12 * 2e-6);
            assert!((y[p_out] - (expected - 1e8 * 2e-6)).abs() < 1e-12 * expected);
        }
    }

    #[test]
    fn rk4_keeps_the_negative_capacitance_row_differential() {
        // inlet RCR → rigid resistance R_v → outlet pressure 0: the only state is P_c, with
        // Q = P_in/R_v, P_in = P_c + R_p Q and C dP_c/dt = Q − (P_c − P_d)/R_d, so
        // λ = (1/(R_v − R_p) − 1/R_d)/C. Eliminating the −C row as algebraic (the old RK4)
        // turned the inlet into a negative resistance and λ > 0 (no stable step at all).
        use crate::integrate::Rk4;
        use crate::integrate::stability::rk4_limit;
        let m = r#"{
            "vessels": [{"name": "v", "from": "in", "to": "out", "arrangement": "RCL",
                         "lumped": {"resistance": 1e9}}],
            "boundary_conditions": {
                "in": {"type": "svzerod-inlet", "proximal_resistance": 1e8,
                       "capacitance": 1e-9, "distal_resistance": 1e8,
                       "pressure": {"kind": "constant", "value": 1000.0}},
                "out": {"type": "pressure", "pressure": {"kind": "constant", "value": 0.0}}}
        }"#;
        let a = parse(m).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let mut rk = Rk4::new(&dae, crate::circuit::Regime::Transient, 1e-3).unwrap();
        assert_eq!(rk.diff.len(), 1);
        let lambda: f64 = (1.0 / (1e9 - 1e8) - 1.0 / 1e8) / 1e-9;
        let lim = rk4_limit(&mut rk, &dae.names).unwrap();
        // RK4's real-axis limit 2.7853/|λ|; the dense eigenvalue of a 1×1 operator: round-off
        let exact = 2.785293563405282 / lambda.abs();
        assert!(
            (lim.dt_max - exact).abs() < 1e-9 * exact,
            "{} vs {exact}",
            lim.dt_max
        );
    }

    #[test]
    fn an_svzerod_inlet_at_an_outlet_is_a_model_error() {
        let m = r#"{
            "vessels": [{"name": "v", "from": "in", "to": "out", "lumped": {"resistance": 1e8}}],
            "boundary_conditions": {
                "in": {"type": "flow", "flow": {"kind": "constant", "value": 2e-6}},
                "out": {"type": "svzerod-inlet", "resistance": 1e9}}
        }"#;
        let e = parse(m).unwrap().assemble().err().unwrap().to_string();
        assert!(e.contains("inlet end"), "{e}");
    }
}
