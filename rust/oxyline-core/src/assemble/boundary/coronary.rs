//! `coronary`: a coronary bed under intramyocardial pressure (docs/physics.md §1.7; the
//! lumped model of svZeroDSolver's `CORONARY` / `CORONARY_VAR_RES` outlets):
//!
//!   vessel end ─R_a─ (C_a) ─R_am─ (C_im, under P_im(t)) ─R_v─ P_v(t)
//!
//! The intramyocardial capacitor holds V_im = C_im (P_c − P_im): its node's unknown is the
//! transmural pressure u = P_c − P_im, and P_im enters as series pressure sources on the two
//! branches at that node (−P_im on R_am, +P_im on R_v). The circuit stays linear with constant
//! coefficients, and P_im needs no time derivative (a table's kinks stay harmless); the
//! equations are those of svZeroDSolver's block with its eliminated flows restored, so
//! generalized-α gives its discretisation. A varying microvascular resistance is a
//! [`ResistanceLaw`] on the R_am branch (base R_min, also the steady value).

use super::Site;
use crate::assemble::checks::{check_nonnegative, check_positive};
use crate::circuit::{Circuit, Part};
use crate::coefficients::ResistanceLaw;
use crate::error::{Error, Result};
use crate::model::CoronarySpec;
use crate::waveform::Waveform;

/// Returns the bed's capacitance C_a + C_im (for the summary's total compliance).
pub(super) fn stamp(circuit: &mut Circuit, site: &Site, c: &CoronarySpec) -> Result<f64> {
    let el = &site.element;
    if site.inlet {
        return Err(Error::model(
            el,
            "a coronary condition must sit at a vessel's outlet end",
        ));
    }
    check_nonnegative(el, "arterial_resistance", c.arterial_resistance)?;
    check_nonnegative(el, "arterial_capacitance", c.arterial_capacitance)?;
    check_nonnegative(el, "microvascular_resistance", c.microvascular_resistance)?;
    check_nonnegative(
        el,
        "intramyocardial_capacitance",
        c.intramyocardial_capacitance,
    )?;
    check_positive(el, "venous_resistance", c.venous_resistance)?;
    let pim = Waveform::from_spec(&c.intramyocardial_pressure, el)?;
    let law = law(c, &pim, el)?;
    let pv = site.waveform(&c.pressure)?;

    let a = circuit.add_node(site.label(Part::Capacitor), c.arterial_capacitance, 0.0);
    let m = circuit.add_node(
        site.label(Part::Intramyocardial),
        c.intramyocardial_capacitance,
        0.0,
    );
    let g = circuit.add_node(site.label(Part::Distal), 0.0, 0.0);
    for node in [a, m, g] {
        circuit.nodes[node].boundary = Some(site.tag as u32);
    }
    // svZeroDSolver's steady start assembles the bed without its capacitors
    circuit.nodes[a].windkessel = true;
    circuit.nodes[m].windkessel = true;
    circuit.fixed_pressures.push((g, pv));
    let ra = site.label(Part::ProximalResistance);
    circuit.add_branch(ra, site.node, a, c.arterial_resistance, 0.0, 0.0);
    let ram = site.label(Part::MicrovascularResistance);
    let b_am = circuit.add_branch(ram, a, m, c.microvascular_resistance, 0.0, 0.0);
    let rv = site.label(Part::DistalResistance);
    let b_v = circuit.add_branch(rv, m, g, c.venous_resistance, 0.0, 0.0);
    // P_c = u + P_im: the pressure falls by P_im into the compartment node and rises by it out
    circuit.branch_sources.push((b_am, pim.clone().negated()));
    circuit.branch_sources.push((b_v, pim));
    if let Some(law) = law {
        circuit.resistance_laws.push((b_am, law));
    }
    Ok(c.arterial_capacitance + c.intramyocardial_capacitance)
}

/// The contraction law of a varying microvascular resistance, if one is asked for.
fn law(c: &CoronarySpec, pim: &Waveform, el: &str) -> Result<Option<ResistanceLaw>> {
    let any = c.contraction_time.is_some() || c.relaxation_time.is_some();
    let Some(max) = c.microvascular_resistance_max else {
        if any || c.cycle_period.is_some() {
            return Err(Error::model(
                el,
                "contraction_time, relaxation_time and cycle_period need microvascular_resistance_max",
            ));
        }
        return Ok(None);
    };
    let (Some(tc), Some(tr)) = (c.contraction_time, c.relaxation_time) else {
        return Err(Error::model(
            el,
            "a varying microvascular resistance needs contraction_time and relaxation_time",
        ));
    };
    let Some(period) = c.cycle_period.or_else(|| pim.period()) else {
        return Err(Error::model(
            el,
            "a varying microvascular resistance needs cycle_period (or a tabulated intramyocardial_pressure)",
        ));
    };
    ResistanceLaw::contraction(el, c.microvascular_resistance, max, tc, tr, period).map(Some)
}

#[cfg(test)]
mod tests {
    use crate::integrate::steady_state;
    use crate::model::parse;

    #[test]
    fn steady_bed_is_its_three_resistances_in_series() {
        // constant inflow Q through the bed: the pressures are those of R_a, R_am, R_v in series
        // to P_v, whatever the intramyocardial pressure (it only sets the compartment's
        // transmural pressure)
        let model = r#"{
            "vessels": [{"name": "v", "from": "in", "to": "out", "arrangement": "RCL",
                         "lumped": {"resistance": 1e8}}],
            "boundary_conditions": {
                "in": {"type": "flow", "flow": {"kind": "constant", "value": 2e-6}},
                "out": {"type": "coronary", "arterial_resistance": 1e9,
                        "arterial_capacitance": 1e-10, "microvascular_resistance": 2e9,
                        "intramyocardial_capacitance": 1e-10, "venous_resistance": 3e9,
                        "intramyocardial_pressure": {"kind": "constant", "value": 4000.0},
                        "pressure": {"kind": "constant", "value": 700.0}}}
        }"#;
        let a = parse(model).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let y = steady_state(&dae).unwrap();
        // behind R_a: P_a = Q (R_am + R_v) + P_v
        let p_a = 2e-6 * 5e9 + 700.0;
        let a_node = (0..dae.n_nodes)
            .find(|&i| dae.names.node(i) == "boundary condition 'out' capacitor")
            .unwrap();
        // one sparse solve: round-off of a few ulps of the largest term
        assert!(
            (y[a_node] - p_a).abs() < 1e-12 * p_a,
            "{} vs {p_a}",
            y[a_node]
        );
        // the compartment's unknown is the transmural pressure P_c − P_im
        let m = (0..dae.n_nodes)
            .find(|&i| dae.names.node(i).contains("intramyocardial"))
            .unwrap();
        let pc = 2e-6 * 3e9 + 700.0;
        assert!((y[m] - (pc - 4000.0)).abs() < 1e-12 * pc, "{}", y[m]);
    }
}
