//! The signals a calibration output reads, by its name (the names are listed in
//! [`super::targets`] and in docs/calibration.md): each as (vessel, variable), checked against
//! the model. A vessel is one of the model's vessels or a heart block's valve
//! (`<vessel>:<tricuspid|pulmonary|mitral|aortic>`: the pressures behind and in front of it and
//! its flow); an oxygen output needs the model's oxygen section. An error names the output
//! and what does not fit (the vessel, variable or statistic, with the choices).

use super::targets::pulse_wave_path;
use crate::error::{Error, Result};
use crate::model::node::py_quote;
use crate::model::{BoundarySpec, NetworkSpec};
use crate::output::VESSEL_VARIABLES;
use std::collections::HashSet;

/// A vessel's oxygen signals (the core's species tangent).
pub const O2_VARIABLES: [&str; 3] = ["po2_out", "saturation_out", "wall_uptake"];
/// A statistic of one signal over the cycle, or the signal itself (`series`).
pub const STATISTICS: [&str; 5] = ["min", "max", "mean", "pulse", "series"];
/// A heart block's valves, in the order its layout lists them.
pub const HEART_VALVES: [&str; 4] = ["tricuspid", "pulmonary", "mitral", "aortic"];

/// One signal: (vessel, variable); the network's oxygen consumption is ("", "consumption").
pub type Signal = (String, String);

/// What an output's name is checked against: the model's vessel and valve names, the
/// vessels fed by its flow conditions and the heart blocks' aortic valves.
struct Names<'a> {
    spec: &'a NetworkSpec,
    vessels: HashSet<&'a str>,
    valves: Vec<String>,
}

impl<'a> Names<'a> {
    fn of(spec: &'a NetworkSpec) -> Self {
        let vessels = spec.vessels.iter().map(|v| v.name.as_str()).collect();
        let valves = spec
            .vessels
            .iter()
            .filter(|v| v.heart_pulmonary.is_some())
            .flat_map(|v| HEART_VALVES.map(|part| format!("{}:{part}", v.name)))
            .collect();
        Names {
            spec,
            vessels,
            valves,
        }
    }

    /// A vessel or a heart block's valve.
    fn has(&self, name: &str) -> bool {
        self.vessels.contains(name) || self.valves.iter().any(|v| v == name)
    }

    /// The vessels that start at a flow condition, in the model's order.
    fn inlets(&self) -> Vec<&'a str> {
        let bcs = &self.spec.boundary_conditions;
        let inflow = |node: &str| matches!(bcs.get(node), Some(BoundarySpec::Flow { .. }));
        (self.spec.vessels.iter())
            .filter(|v| inflow(&v.from))
            .map(|v| v.name.as_str())
            .collect()
    }

    fn no_vessel(&self, name: &str) -> String {
        format!(
            "no vessel named {} in model '{}'",
            py_quote(name),
            self.spec.name
        )
    }
}

fn signal(vessel: &str, variable: &str) -> Signal {
    (vessel.to_owned(), variable.to_owned())
}

fn unknown_statistic(stat: &str) -> String {
    format!(
        "unknown statistic {} (one of {})",
        py_quote(stat),
        STATISTICS.join(", ")
    )
}

/// The (vessel, variable) signals the output `output` reads in the model `spec`; an error
/// naming the output when its vessel, variable or statistic does not exist there.
pub fn signals_of(spec: &NetworkSpec, output: &str) -> Result<Vec<Signal>> {
    let fail = |why: String| Error::model(format!("output '{output}'"), why);
    let names = Names::of(spec);
    let parts: Vec<&str> = output.split('.').collect();
    if matches!(parts[0], "SvO2" | "VO2") || (parts.len() == 3 && O2_VARIABLES.contains(&parts[1]))
    {
        return oxygen_signals(&names, &parts).map_err(fail);
    }
    if output == "cardiac_output" {
        let mut inlets: Vec<&str> = names.inlets();
        if inlets.is_empty() {
            // a closed loop: the flow through its heart blocks' aortic valves
            let aortic = names.valves.iter().filter(|v| v.ends_with(":aortic"));
            inlets = aortic.map(String::as_str).collect();
        }
        if inlets.is_empty() {
            return Err(fail(
                "the model has no flow condition or heart block".into(),
            ));
        }
        return Ok(inlets.iter().map(|v| signal(v, "flow_in")).collect());
    }
    match parts[0] {
        "pwv" => {
            if parts.len() != 3 {
                return Err(fail(
                    "expected pwv.<proximal vessel>.<distal vessel>".into(),
                ));
            }
            pulse_wave_path(spec, output)?;
            Ok(vec![
                signal(parts[1], "pressure_in"),
                signal(parts[2], "pressure_out"),
            ])
        }
        "amplification" | "augmentation_index" => shape_signals(&names, &parts).map_err(fail),
        "flow_split" => {
            if parts.len() != 3 {
                return Err(fail("expected flow_split.<vessel>.<parent>".into()));
            }
            known(&names, &parts[1..]).map_err(fail)?;
            Ok(vec![
                signal(parts[1], "flow_in"),
                signal(parts[2], "flow_in"),
            ])
        }
        _ => vessel_signal(&names, &parts).map_err(fail),
    }
}

/// Every name in `vessels` is a vessel or valve of the model.
fn known(names: &Names, vessels: &[&str]) -> std::result::Result<(), String> {
    match vessels.iter().find(|v| !names.has(v)) {
        Some(v) => Err(names.no_vessel(v)),
        None => Ok(()),
    }
}

/// `<vessel>.<variable>.<statistic>` of a flow variable.
fn vessel_signal(names: &Names, parts: &[&str]) -> std::result::Result<Vec<Signal>, String> {
    let [vessel, variable, stat] = parts[..] else {
        return Err(
            "expected <vessel>.<variable>.<statistic>, flow_split.<vessel>.<parent>, \
                    pwv.<proximal>.<distal>, amplification.<central>.<peripheral>, \
                    augmentation_index.<vessel> or cardiac_output"
                .into(),
        );
    };
    known(names, &[vessel])?;
    if !VESSEL_VARIABLES.contains(&variable) {
        let all: Vec<&str> = VESSEL_VARIABLES
            .iter()
            .chain(&O2_VARIABLES)
            .copied()
            .collect();
        return Err(format!(
            "unknown variable {} (one of {})",
            py_quote(variable),
            all.join(", ")
        ));
    }
    if !STATISTICS.contains(&stat) {
        return Err(unknown_statistic(stat));
    }
    Ok(vec![signal(vessel, variable)])
}

/// The pressures of `amplification.<central>.<peripheral>` (the inlet of `central`, the
/// outlet of `peripheral`) or `augmentation_index.<vessel>` (its inlet).
fn shape_signals(names: &Names, parts: &[&str]) -> std::result::Result<Vec<Signal>, String> {
    let amplification = parts[0] == "amplification";
    if parts.len() != if amplification { 3 } else { 2 } {
        return Err(if amplification {
            "expected amplification.<central vessel>.<peripheral vessel>"
        } else {
            "expected augmentation_index.<vessel>"
        }
        .into());
    }
    known(names, &parts[1..])?;
    let mut out = vec![signal(parts[1], "pressure_in")];
    if amplification {
        out.push(signal(parts[2], "pressure_out"));
    }
    Ok(out)
}

/// The signals of an oxygen output (`SvO2.<vessel>`, `VO2[.<vessel>...]`,
/// `<vessel>.<oxygen variable>.<statistic>`); its vessels are the model's (no valves).
fn oxygen_signals(names: &Names, parts: &[&str]) -> std::result::Result<Vec<Signal>, String> {
    let spec = names.spec;
    if spec.transport.as_ref().is_none_or(|t| t.species.is_empty()) {
        return Err(format!("model '{}' has no oxygen section", spec.name));
    }
    let whole = matches!(parts[0], "SvO2" | "VO2");
    let vessels = if whole { &parts[1..] } else { &parts[..1] };
    if let Some(v) = vessels.iter().find(|v| !names.vessels.contains(*v)) {
        return Err(names.no_vessel(v));
    }
    match parts[0] {
        "SvO2" if parts.len() != 2 => Err("expected SvO2.<vessel>".into()),
        "SvO2" => Ok(vec![
            signal(parts[1], "saturation_out"),
            signal(parts[1], "flow_out"),
        ]),
        "VO2" if parts.len() == 1 => Ok(vec![signal("", "consumption")]),
        "VO2" => Ok(parts[1..]
            .iter()
            .map(|v| signal(v, "wall_uptake"))
            .collect()),
        _ if !STATISTICS.contains(&parts[2]) => Err(unknown_statistic(parts[2])),
        _ => Ok(vec![signal(parts[0], parts[1])]),
    }
}

#[cfg(test)]
#[path = "target_signals_tests.rs"]
mod tests;
