//! Stamp a `valve` element: one branch between the element's end nodes whose resistance the
//! valve law sets (`crate::element::valve`, docs/physics.md §1.8).

use super::checks::{check_nonnegative, check_positive};
use super::vessel::Chain;
use crate::circuit::{Circuit, CircuitElement, Label, Part};
use crate::element::valve::ValveLaw;
use crate::error::{Error, Result};
use crate::model::{ThroughRcSpec, ValveSpec};

pub(crate) fn stamp(
    circuit: &mut Circuit,
    name: &str,
    spec: &ValveSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let el = format!("valve '{name}'");
    let law = match *spec {
        ValveSpec::Tanh {
            min_resistance,
            max_resistance,
            steepness,
        } => {
            check_positive(&el, "steepness", steepness)?;
            ValveLaw::Tanh {
                r_min: min_resistance,
                r_max: max_resistance,
                steepness,
            }
        }
        ValveSpec::Piecewise {
            min_resistance,
            max_resistance,
        } => ValveLaw::Piecewise {
            r_min: min_resistance,
            r_max: max_resistance,
        },
    };
    let (r_min, r_max) = match law {
        ValveLaw::Tanh { r_min, r_max, .. } | ValveLaw::Piecewise { r_min, r_max } => {
            (r_min, r_max)
        }
    };
    check_nonnegative(&el, "min_resistance", r_min)?;
    check_positive(&el, "max_resistance", r_max)?;
    if r_max < r_min {
        return Err(Error::model(
            &el,
            format!("max_resistance {r_max} is below min_resistance {r_min}"),
        ));
    }
    let vessel = circuit.add_vessel(name);
    let label = Label::Vessel {
        vessel: vessel as u32,
        part: Part::Whole,
        k: 0,
    };
    let branch = circuit.add_branch(label, from, to, 0.0, 0.0, 0.0);
    circuit.elements.push(CircuitElement::Valve {
        name: el,
        law,
        branch,
        from,
        to,
    });
    Ok(Chain {
        points: vec![from, to],
        branches: vec![branch],
    })
}

/// Stamp a `through_rc` element (svZeroDSolver's `BloodVesselRC`): one branch whose flow Q
/// obeys C dP_from/dt + (P_from − P_to)/R = Q. That row carries the derivative of the
/// `from` pressure, so it takes the `from` node's row (E stays diagonal) and the node's flow
/// balance moves to the branch's row (`Circuit::swapped_rows`).
pub(crate) fn stamp_through_rc(
    circuit: &mut Circuit,
    name: &str,
    spec: &ThroughRcSpec,
    (from, to): (usize, usize),
) -> Result<Chain> {
    let el = format!("through_rc '{name}'");
    check_positive(&el, "resistance", spec.resistance)?;
    check_nonnegative(&el, "capacitance", spec.capacitance)?;
    let vessel = circuit.add_vessel(name);
    let label = Label::Vessel {
        vessel: vessel as u32,
        part: Part::Whole,
        k: 0,
    };
    let branch = circuit.add_branch(label, from, to, 0.0, 0.0, 0.0);
    circuit.swapped_rows.push(crate::circuit::SwappedRow {
        node: from,
        branch,
        capacitance: spec.capacitance,
        resistance: spec.resistance,
    });
    Ok(Chain {
        points: vec![from, to],
        branches: vec![branch],
    })
}
