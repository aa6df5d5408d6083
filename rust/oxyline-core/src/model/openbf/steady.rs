//! The pressures at which openBF's importer linearises each vessel (its `linearize="mean"`):
//! the steady network of the mean inflow, iterated because the radii depend on the pressure
//! through the tube law. Each iterate is the exact steady state of the rigid network at the
//! current radii (one native model read and assembled as any other, so the steady solve and
//! its taper resistance are the run's own).

use super::Wall;
use crate::error::{Error, Result};
use crate::model::native::plain::{PlainOutlet, PlainVessel};
use crate::model::native::{self, header};
use crate::model::node::{Fields, py_g_digits};
use crate::model::{BoundarySpec, NetworkSpec, VesselSpec};
use serde::Deserialize;
use serde_json::{Map, Value, json};
use std::collections::HashMap;

/// Fixed-point iterations at most (the radii settle in two or three).
const ITERATIONS: usize = 8;
/// Relative change of every node pressure between iterates below which they have settled.
const TOLERANCE: f64 = 1e-6;

/// One vessel of the steady network: its wall, external pressure, end nodes and the names
/// a message gives it (`element`: the file's `file: vessel 'label'`; `label`).
#[derive(Debug, Clone)]
pub struct SteadyVessel {
    pub wall: Wall,
    pub external_pressure: f64,
    pub from: String,
    pub to: String,
    pub element: String,
    pub label: String,
}

/// A terminal node's total resistance [Pa s/m³] and outflow pressure [Pa].
#[derive(Debug, Clone)]
pub struct Terminal {
    pub node: String,
    pub resistance: f64,
    pub pressure: f64,
}

impl SteadyVessel {
    /// The vessel's radii at end pressures `p` (its error names the vessel as the file does).
    fn radii(&self, p: (f64, f64)) -> Result<(f64, f64)> {
        let (r_in, r_out, _) = self
            .wall
            .linearised(p.0, p.1, self.external_pressure)
            .map_err(|low| {
                Error::model(
                    &self.element,
                    format!(
                        "the tube law collapses the vessel at the linearisation pressure \
                         ({} Pa, Pext {} Pa)",
                        py_g_digits(low, 4),
                        py_g_digits(self.external_pressure, 4)
                    ),
                )
            })?;
        Ok((r_in, r_out))
    }
}

/// The steady pressures (inlet end, outlet end) of every vessel for the constant inflow
/// `flow` [m³/s] at node `inlet`, through blood of `viscosity` [Pa s] into the `terminals`,
/// with each vessel's radii on the tube law at its end pressures (starting from its external
/// pressure). Iterates until no node pressure changes by more than [`TOLERANCE`] of the
/// largest (at least 1 Pa), at most [`ITERATIONS`] times.
pub fn mean_pressures(
    vessels: &[SteadyVessel],
    inlet: &str,
    flow: f64,
    terminals: &[Terminal],
    viscosity: f64,
) -> Result<Vec<(f64, f64)>> {
    let mut p: Vec<(f64, f64)> = vessels
        .iter()
        .map(|v| (v.external_pressure, v.external_pressure))
        .collect();
    let mut last: Option<HashMap<String, f64>> = None;
    for _ in 0..ITERATIONS {
        let radii = vessels
            .iter()
            .zip(&p)
            .map(|(v, &pv)| v.radii(pv))
            .collect::<Result<Vec<_>>>()?;
        let model = steady_model(vessels, &radii, inlet, flow, terminals, viscosity);
        let nodes = node_pressures(&model).map_err(|e| named(e, vessels))?;
        let scale = nodes.values().fold(1.0_f64, |a, &x| a.max(x.abs()));
        let done = last.as_ref().is_some_and(|old| {
            let change = nodes.iter().fold(f64::NEG_INFINITY, |a, (n, x)| {
                a.max((x - old.get(n).copied().unwrap_or(f64::NAN)).abs())
            });
            change < TOLERANCE * scale
        });
        p = vessels
            .iter()
            .map(|v| (nodes[&v.from], nodes[&v.to]))
            .collect();
        last = Some(nodes);
        if done {
            break;
        }
    }
    Ok(p)
}

/// The native model of the rigid steady network: vessel `k` is `v<k>` (its label may be any
/// text), radii `radii[k]`, no output.
fn steady_model(
    vessels: &[SteadyVessel],
    radii: &[(f64, f64)],
    inlet: &str,
    flow: f64,
    terminals: &[Terminal],
    viscosity: f64,
) -> Value {
    let list: Vec<Value> = vessels
        .iter()
        .zip(radii)
        .enumerate()
        .map(|(k, (v, r))| {
            json!({"name": format!("v{k}"), "from": v.from, "to": v.to,
                   "length": v.wall.length, "radius_in": r.0, "radius_out": r.1,
                   "output": false})
        })
        .collect();
    let mut bcs = Map::new();
    bcs.insert(inlet.to_owned(), json!({"type": "flow", "value": flow}));
    for t in terminals {
        bcs.insert(
            t.node.clone(),
            json!({"type": "resistance", "resistance": t.resistance, "pressure": t.pressure}),
        );
    }
    json!({"name": "openbf-steady", "units": "SI", "blood": {"viscosity": viscosity},
           "vessels": list, "boundary_conditions": bcs})
}

/// A core error with the steady network's vessel names `v<k>` put back as the file's labels.
fn named(e: Error, vessels: &[SteadyVessel]) -> Error {
    let rename = |mut s: String| {
        for (k, v) in vessels.iter().enumerate() {
            s = s.replace(&format!("vessel 'v{k}'"), &format!("vessel '{}'", v.label));
        }
        s
    };
    match e {
        Error::Model { element, message } => Error::Model {
            element: rename(element),
            message: rename(message),
        },
        other => other,
    }
}

/// The exact steady pressure of every graph node of a native model (read as a model dict is:
/// plain vessels and outlets by serde, anything else by the full check).
fn node_pressures(model: &Value) -> Result<HashMap<String, f64>> {
    let spec = read(model)?;
    let m = crate::ensemble::Member::build(&spec)?;
    let y = crate::integrate::steady::steady_state(&m.dae)?;
    let names = &m.assembled.circuit.names;
    Ok((0..m.assembled.summary.nodes)
        .map(|i| (names.node(i).to_string(), y[i]))
        .collect())
}

/// A native model of vessels and conditions alone as the core's spec.
fn read(model: &Value) -> Result<NetworkSpec> {
    let h = header(model)?;
    let units = h.units;
    let items = model["vessels"].as_array().cloned().unwrap_or_default();
    let mut vessels = Vec::with_capacity(items.len());
    for (i, v) in items.iter().enumerate() {
        let plain = PlainVessel::deserialize(v).ok().and_then(|p| p.spec(units));
        let spec = match plain {
            Some(s) => s,
            None => {
                let c = native::vessel(&Fields::new(v.clone()), i, units)?;
                serde_json::from_value::<VesselSpec>(c)
                    .map_err(|e| Error::model(format!("vessel #{i}"), e.to_string()))?
            }
        };
        vessels.push(spec);
    }
    let mut outlets: Vec<(String, BoundarySpec)> = Vec::new();
    let mut slow = Map::new();
    for (node, bc) in model["boundary_conditions"]
        .as_object()
        .into_iter()
        .flatten()
    {
        match PlainOutlet::deserialize(bc)
            .ok()
            .and_then(|o| o.spec(units))
        {
            Some(s) => outlets.push((node.clone(), s)),
            None => {
                let el = format!("boundary condition '{node}'");
                let c = native::boundary_condition(&Fields::new(bc.clone()), units, &el)?;
                slow.insert(node.clone(), c);
            }
        }
    }
    let mut rest = h.canonical;
    rest.insert("vessels".into(), Value::Array(Vec::new()));
    rest.insert("boundary_conditions".into(), Value::Object(slow));
    let mut spec: NetworkSpec = serde_json::from_value(Value::Object(rest))
        .map_err(|e| Error::model("model", e.to_string()))?;
    spec.vessels = vessels;
    spec.boundary_conditions.extend(outlets);
    Ok(spec)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn vessel(from: &str, to: &str, r: f64, label: &str) -> SteadyVessel {
        SteadyVessel {
            wall: Wall {
                length: 0.1,
                radius: (r, r),
                youngs_modulus: 4e5,
                wall_thickness: Some(3e-4),
            },
            external_pressure: 0.0,
            from: from.into(),
            to: to.into(),
            element: format!("f.yaml: vessel '{label}'"),
            label: label.into(),
        }
    }

    /// One uniform vessel into a resistance: Q (R_t + 8 μ L/(π r⁴)) = p_in − p_out with r on
    /// the tube law r = R₀ (1 + p̄/β′) at the vessel's mean pressure p̄ (exact for a straight
    /// tube: the linearised radius is uniform when both end pressures are equal, so check the
    /// fixed point the iteration must reach against its own equations, solved here by
    /// bisection on the inlet pressure).
    #[test]
    fn one_vessel_reaches_the_fixed_point_of_poiseuille_and_the_tube_law() {
        let (q, rt, pout, mu) = (5e-6, 1.5e9, 1000.0, 4e-3);
        let v = vessel("n1", "n2", 3e-3, "cca");
        let t = Terminal {
            node: "n2".into(),
            resistance: rt,
            pressure: pout,
        };
        let got = mean_pressures(std::slice::from_ref(&v), "n1", q, &[t], mu).unwrap();
        let (p_in, p_out) = got[0];
        // outlet end: the terminal alone
        assert!((p_out - (pout + q * rt)).abs() < 1e-9 * p_out, "{p_out}");
        // inlet end: Poiseuille through the linear taper between the tube-law radii
        let beta = 4e5 * 3e-4 / (0.75 * 3e-3);
        let (a, b) = (3e-3 * (1.0 + p_in / beta), 3e-3 * (1.0 + p_out / beta));
        // ∫ dx / r(x)⁴ of a linear taper: L (a² + ab + b²)/(3 a³ b³)
        let r_taper = 8.0 * mu / PI * 0.1 * (a * a + a * b + b * b) / (3.0 * a.powi(3) * b.powi(3));
        let drop = p_in - p_out;
        assert!(
            (drop / (q * r_taper) - 1.0).abs() < 1e-5,
            "{drop} vs {}",
            q * r_taper
        );
    }

    #[test]
    fn an_error_of_the_steady_network_names_the_file_label() {
        // a negative length is refused by the model check, which names the steady network's
        // `v0`: the message names the file's label instead
        let mut v = vessel("n1", "n2", 3e-3, "left carotid");
        let t = Terminal {
            node: "n2".into(),
            resistance: 1e9,
            pressure: 0.0,
        };
        v.wall.length = -0.1;
        let text = mean_pressures(
            std::slice::from_ref(&v),
            "n1",
            5e-6,
            std::slice::from_ref(&t),
            4e-3,
        )
        .unwrap_err()
        .to_string();
        assert!(text.starts_with("vessel 'left carotid': "), "{text}");
        // a vessel collapsed by the tube law: the file's element and both pressures at 4 digits
        v.wall.length = 0.1;
        let t = Terminal {
            pressure: -1e7,
            ..t
        };
        let e = mean_pressures(&[v], "n1", 5e-6, &[t], 4e-3).unwrap_err();
        let text = e.to_string();
        assert!(
            text.starts_with("f.yaml: vessel 'left carotid': the tube law collapses"),
            "{text}"
        );
        assert!(text.ends_with("(-9.995e+06 Pa, Pext 0 Pa)"), "{text}");
    }
}
