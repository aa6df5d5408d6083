//! Stamp a `chamber` element: the chamber's volume unknown (which takes the flow balance of the
//! element's inlet node), its pressure law at that node and an inductor to the outlet node
//! (`crate::element::chamber`, docs/physics.md §1.8).

use super::checks::{check_nonnegative, check_positive};
use super::vessel::Chain;
use crate::circuit::{Circuit, CircuitElement, Label, Part};
use crate::element::activation::Activation;
use crate::element::chamber::{Elastance, ElastanceLaw};
use crate::error::Result;
use crate::model::{ActivationSpec, ChamberLawSpec, ChamberSpec};

fn activation(el: &str, spec: &ActivationSpec, period: f64) -> Result<Activation> {
    Ok(match *spec {
        ActivationSpec::HalfCosine { t_active, t_twitch } => {
            check_nonnegative(el, "t_active", t_active)?;
            check_positive(el, "t_twitch", t_twitch)?;
            Activation::HalfCosine { t_active, t_twitch }
        }
        ActivationSpec::PiecewiseCosine {
            contract_start,
            relax_start,
            contract_duration,
            relax_duration,
        } => {
            check_positive(el, "contract_duration", contract_duration)?;
            check_positive(el, "relax_duration", relax_duration)?;
            Activation::PiecewiseCosine {
                contract_start,
                relax_start,
                contract_duration,
                relax_duration,
            }
        }
        ActivationSpec::TwoHill {
            t_shift,
            tau_1,
            tau_2,
            m1,
            m2,
        } => {
            check_positive(el, "tau_1", tau_1)?;
            check_positive(el, "tau_2", tau_2)?;
            Activation::two_hill(el, period, [t_shift, tau_1, tau_2, m1, m2])?
        }
        ActivationSpec::WrappingCosine {
            systole_fraction,
            p_wave_divisor,
        } => {
            check_positive(el, "systole_fraction", systole_fraction)?;
            check_positive(el, "p_wave_divisor", p_wave_divisor)?;
            Activation::WrappingCosine {
                systole_fraction,
                p_wave_divisor,
            }
        }
        ActivationSpec::Fourier {} => Activation::fourier(period),
    })
}

/// The elastance law E(t), V_rest(t) of chamber `name` (checked).
pub fn chamber_elastance(name: &str, spec: &ChamberSpec) -> Result<Elastance> {
    let el = format!("chamber '{name}'");
    check_positive(&el, "period", spec.period)?;
    check_nonnegative(&el, "inductance", spec.inductance)?;
    let law = match spec.law {
        ChamberLawSpec::ElastanceInductor {
            max_elastance,
            min_elastance,
            rest_volume_diastole,
            rest_volume_systole,
        } => {
            check_positive(&el, "min_elastance", min_elastance)?;
            check_positive(&el, "max_elastance", max_elastance)?;
            ElastanceLaw::ElastanceInductor {
                e_max: max_elastance,
                e_min: min_elastance,
                v_rest_diastole: rest_volume_diastole,
                v_rest_systole: rest_volume_systole,
            }
        }
        ChamberLawSpec::Linear {
            max_elastance,
            passive_elastance,
            rest_volume,
        } => {
            check_positive(&el, "passive_elastance", passive_elastance)?;
            check_nonnegative(&el, "max_elastance", max_elastance)?;
            ElastanceLaw::Linear {
                e_max: max_elastance,
                e_pass: passive_elastance,
                v_rest: rest_volume,
            }
        }
        ChamberLawSpec::Exponential {
            max_elastance,
            passive_pressure,
            passive_volume_coefficient,
            rest_volume,
        } => {
            check_nonnegative(&el, "max_elastance", max_elastance)?;
            check_nonnegative(&el, "passive_pressure", passive_pressure)?;
            ElastanceLaw::Exponential {
                e_max: max_elastance,
                k_pressure: passive_pressure,
                k_volume: passive_volume_coefficient,
                v_aso: rest_volume,
            }
        }
    };
    Ok(Elastance {
        law,
        activation: activation(&el, &spec.activation, spec.period)?,
        period: spec.period,
    })
}

pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    spec: &ChamberSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let elastance = chamber_elastance(name, spec)?;
    let el = format!("chamber '{name}'");
    let vessel = circuit.add_vessel(name) as u32;
    let label = |part| Label::Vessel { vessel, part, k: 0 };
    // the chamber's own pressure node behind a wire from the inlet node: the wire carries the
    // inflow Q_in (recorded as the element's flow_in), and the inlet node keeps its ordinary
    // flow balance (other vessels' capacitance or a boundary condition may sit there)
    let node = circuit.add_node(label(Part::Point), 0.0, 0.0);
    let wire = circuit.add_branch(label(Part::Resistance), from, node, 0.0, 0.0, 0.0);
    let volume = circuit.add_extra(label(Part::Volume), 1.0);
    circuit.moved_rows.push((node, volume));
    circuit.initial_extras.push((volume, spec.initial_volume));
    let branch = circuit.add_branch(label(Part::Inductance), node, to, 0.0, spec.inductance, 0.0);
    circuit.elements.push(CircuitElement::Chamber {
        name: el,
        elastance,
        node,
        volume,
    });
    Ok(Chain {
        points: vec![from, node, to],
        branches: vec![wire, branch],
    })
}

#[cfg(test)]
mod tests {
    use crate::circuit::Regime;
    use crate::integrate::{GenAlpha, Integrator, NewtonControl, Rk4};
    use crate::model::parse;

    /// A left ventricle, two tanh valves, an artery and a vein in a loop: no boundary
    /// condition (docs/physics.md §1.8).
    const LOOP: &str = r#"{
        "vessels": [
            {"name": "lv", "from": "mi", "to": "lv_out",
             "chamber": {"law": "linear", "max_elastance": 3.3e8, "passive_elastance": 1.2e7,
                         "rest_volume": 1e-5, "period": 0.8, "initial_volume": 1e-3,
                         "activation": {"kind": "piecewise-cosine", "contract_start": 0.1,
                                        "relax_start": 0.35, "contract_duration": 0.25,
                                        "relax_duration": 0.2}}},
            {"name": "av", "from": "lv_out", "to": "ao",
             "valve": {"law": "tanh", "min_resistance": 1e6, "max_resistance": 1e11,
                       "steepness": 0.05}},
            {"name": "aorta", "from": "ao", "to": "art", "arrangement": "RCL",
             "lumped": {"resistance": 1e6, "capacitance": 1.5e-8, "inductance": 1e5}},
            {"name": "sys", "from": "art", "to": "ven", "arrangement": "RCL",
             "lumped": {"resistance": 1.3e8}},
            {"name": "veins", "from": "ven", "to": "mv_in", "arrangement": "RCL",
             "lumped": {"resistance": 1e6, "capacitance": 7.5e-7}},
            {"name": "mv", "from": "mv_in", "to": "mi",
             "valve": {"law": "tanh", "min_resistance": 1e6, "max_resistance": 1e11,
                       "steepness": 0.05}}],
        "boundary_conditions": {}
    }"#;

    /// Blood volume: the capacitors' C·P plus the chamber volumes (rows whose E is a
    /// capacitance or a chamber's dV/dt).
    fn blood_volume(dae: &crate::circuit::Dae, nb: usize, y: &[f64]) -> f64 {
        let chambers = dae.n_nodes + nb..dae.n;
        (0..dae.n_nodes)
            .chain(chambers)
            .map(|i| dae.e[i] * y[i])
            .sum()
    }

    #[test]
    fn a_closed_loop_conserves_blood_volume_with_both_integrators() {
        let a = parse(LOOP).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let (v0, nb) = (1e-3, a.circuit.branches.len());
        let steps = 4 * 800; // four cycles of 1 ms
        // the run's start: the chamber's volume, algebraic unknowns and ẏ made consistent
        let mut rk = Rk4::new(&dae, Regime::Transient, 1e-4).unwrap();
        let mut y0 = dae.initial_state();
        rk.make_consistent(0.0, &mut y0).unwrap();
        let yd0 = rk.derivative(0.0, &mut y0).unwrap();
        assert!((blood_volume(&dae, nb, &y0) - v0).abs() < 1e-15 * v0);
        let mut ga =
            GenAlpha::new(&dae, Regime::Transient, 1e-3, 0.5, NewtonControl::default()).unwrap();
        let (mut y, mut yd) = (y0.clone(), yd0);
        for i in 0..steps {
            ga.step(i as f64 * 1e-3, &mut y, &mut yd).unwrap();
        }
        // every flow balance holds to the Newton tolerance (1e-12 of the scales) at every
        // step: a linear invariant of generalized-α
        let v = blood_volume(&dae, nb, &y);
        assert!((v - v0).abs() < 1e-9 * v0, "{v} vs {v0}");
        // the heart pumps: the aorta's inlet pressure is well above zero
        assert!(y[a.probes.vessel_unknowns[4 * 2]] > 1e3, "{:?}", &y[..4]);
        let mut y = y0;
        for i in 0..10 * steps {
            Integrator::step(&mut rk, i as f64 * 1e-4, &mut y, &mut []).unwrap();
        }
        let v = blood_volume(&dae, nb, &y);
        assert!((v - v0).abs() < 1e-9 * v0, "rk4 {v} vs {v0}");
    }
}
