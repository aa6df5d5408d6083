//! Parameter paths on JSON models: each expected value is written out by hand from the
//! documented rules (docs/calibration.md, "Parameters"), never taken from the code's output.

use super::{base_value, set_values};
use crate::model::patch::{Merged, Patched};
use serde_json::{Value, json};

fn model() -> Value {
    json!({
        "name": "heart", "units": "SI", "period": 1.0,
        "vessels": [
            {"name": "a", "from": "in", "to": "j", "length": 0.1, "radius": 0.004,
             "youngs_modulus": 4e5},
            {"name": "t", "from": "j", "to": "out1", "length": 0.05, "radius_in": 0.003,
             "radius_out": 0.002, "youngs_modulus": "5.0e5"},
            {"name": "c", "from": "j", "to": "out2",
             "lumped": {"resistance": 1e7, "capacitance": 1e-9}},
            {"name": "lv", "from": "v", "to": "in",
             "chamber": {"law": "elastance-inductor", "max_elastance": 2e8,
                         "activation": {"kind": "half-cosine", "t_active": 0.2}}}],
        "boundary_conditions": {
            "in": {"type": "flow", "time": [0.0, 0.5], "flow": [1.0, 3.0]},
            "in2": {"type": "Flow", "fourier": {"mean": 2.0, "cos": [1.0, 0.5], "sin": [0.25]},
                    "interpolation": "linear"},
            "out1": {"type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-9,
                     "distal_resistance": 1e9},
            "out2": {"type": "coronary", "arterial_resistance": 1e9,
                     "intramyocardial_pressure": {"time": [0.0, 1.0], "pressure": [10.0, 20.0],
                                                  "fourier": {"mean": 4.0, "cos": [2.0],
                                                              "period": 1.0}}},
            "out3": {"type": "coronary", "intramyocardial_pressure": 100.0}},
        "oxygen": {"wall": {"model": "graetz", "po2": 45.0}},
    })
}

/// A merged value as JSON, to compare with the expected one.
fn plain(m: &Merged<Value>) -> Value {
    match m {
        Merged::Node(n) => n.clone(),
        Merged::Number(x) => json!(x),
        Merged::Numbers(v) => json!(v),
        Merged::Map(e) => Value::Object(e.iter().map(|(k, v)| (k.clone(), plain(v))).collect()),
    }
}

fn set(paths: &[&str], values: &[f64]) -> Patched<Value> {
    let paths: Vec<String> = paths.iter().map(|p| (*p).to_owned()).collect();
    set_values(&model(), &paths, values).expect("the paths are set")
}

fn vessel(p: &Patched<Value>, i: usize) -> Value {
    plain(&p.vessels.iter().find(|(j, _)| *j == i).expect("replaced").1)
}

fn condition(p: &Patched<Value>, node: &str) -> Value {
    plain(
        &p.conditions
            .iter()
            .find(|(n, _)| n == node)
            .expect("replaced")
            .1,
    )
}

fn refused(paths: &[&str], values: &[f64]) -> String {
    let paths: Vec<String> = paths.iter().map(|p| (*p).to_owned()).collect();
    match set_values(&model(), &paths, values) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("{paths:?} were set"),
    }
}

#[test]
fn base_values_in_the_models_units() {
    let m = model();
    let value = |path: &str| base_value(&m, path).expect(path);
    assert_eq!(value("vessels.a.radius"), 0.004);
    assert_eq!(value("vessels.t.radius"), 0.003); // no radius: its radius_in
    assert_eq!(value("vessels.t.youngs_modulus"), 5e5); // YAML 1.1's text, read as a number
    assert_eq!(value("vessels.c.lumped.resistance"), 1e7);
    assert_eq!(value("vessels.c.lumped.stenosis_coefficient"), 0.0); // no stenosis: S = 0
    assert_eq!(value("vessels.lv.chamber.activation.t_active"), 0.2);
    assert_eq!(value("boundary_conditions.out1.capacitance"), 1e-9);
    assert_eq!(
        value("boundary_conditions.out2.intramyocardial_pressure.scale"),
        1.0
    );
    assert_eq!(value("scale.inflow"), 1.0);
    assert_eq!(value("scale.resistance"), 1.0);
    assert_eq!(value("oxygen.wall.po2"), 45.0);
}

#[test]
fn a_base_value_that_names_nothing_names_its_path() {
    let m = model();
    let message = |path: &str| base_value(&m, path).expect_err(path).to_string();
    assert_eq!(
        message("vessels.zz.radius"),
        "parameter 'vessels.zz.radius': no vessel named 'zz'"
    );
    for path in [
        "vessels.a.colour",
        "vessels.a",
        "vessels.a.lumped.stenosis_coefficient", // not a lumped vessel
        "boundary_conditions.nowhere.resistance",
        "boundary_conditions.out1.intramyocardial_pressure.scale",
        "boundary_conditions.out1.resistance",
        "oxygen.wall.model",
        "blood",
    ] {
        assert_eq!(
            message(path),
            format!("parameter '{path}': no such number in the model")
        );
    }
}

#[test]
fn patch_paths_follow_the_patch_rules() {
    let p = set(
        &[
            "vessels.t.radius",
            "vessels.c.lumped.resistance",
            "oxygen.wall.po2",
        ],
        &[0.0025, 2e7, 50.0],
    );
    // a radius replaces radius_in and radius_out
    assert_eq!(
        vessel(&p, 1),
        json!({"name": "t", "from": "j", "to": "out1", "length": 0.05, "radius": 0.0025,
               "youngs_modulus": "5.0e5"})
    );
    assert_eq!(
        vessel(&p, 2)["lumped"],
        json!({"resistance": 2e7, "capacitance": 1e-9})
    );
    let oxygen = &p
        .sections
        .iter()
        .find(|(s, _)| s == "oxygen")
        .expect("oxygen")
        .1;
    assert_eq!(
        plain(oxygen),
        json!({"wall": {"model": "graetz", "po2": 50.0}})
    );
    assert!(p.conditions.is_empty());
}

/// A taper's end radii: read and set one at a time; on a vessel given by one `radius` each
/// end is that radius, and setting one end keeps the other at it (the patch rule).
#[test]
fn end_radii_are_read_and_set_one_at_a_time() {
    let m = model();
    let value = |path: &str| base_value(&m, path).expect(path);
    assert_eq!(value("vessels.t.radius_in"), 0.003);
    assert_eq!(value("vessels.t.radius_out"), 0.002);
    assert_eq!(value("vessels.a.radius_in"), 0.004);
    assert_eq!(value("vessels.a.radius_out"), 0.004);
    let p = set(
        &["vessels.t.radius_out", "vessels.a.radius_in"],
        &[0.0021, 0.0041],
    );
    assert_eq!(vessel(&p, 1)["radius_in"], json!(0.003));
    assert_eq!(vessel(&p, 1)["radius_out"], json!(0.0021));
    let a = vessel(&p, 0);
    assert_eq!(
        (&a["radius_in"], &a["radius_out"]),
        (&json!(0.0041), &json!(0.004))
    );
    assert!(a.get("radius").is_none());
}

#[test]
fn a_scale_multiplies_the_values_set_explicitly() {
    // 2e8 set, then the resistance factor 1.5: 3e8 (and the distal one 1e9 · 1.5)
    let p = set(
        &[
            "scale.resistance",
            "boundary_conditions.out1.proximal_resistance",
        ],
        &[1.5, 2e8],
    );
    let bc = condition(&p, "out1");
    assert_eq!(bc["proximal_resistance"], json!(3e8));
    assert_eq!(bc["distal_resistance"], json!(1.5e9));
}

#[test]
fn the_inflow_factor_scales_every_flow_waveform() {
    let p = set(&["scale.inflow"], &[2.0]);
    assert_eq!(
        condition(&p, "in"),
        json!({"type": "flow", "time": [0.0, 0.5], "flow": [2.0, 6.0]})
    );
    // any case of the type; the Fourier mean and coefficients, not its other keys
    assert_eq!(
        condition(&p, "in2"),
        json!({"type": "Flow", "fourier": {"mean": 4.0, "cos": [2.0, 1.0], "sin": [0.5]},
               "interpolation": "linear"})
    );
    assert_eq!(p.conditions.len(), 2); // the outlets stay
    assert!(p.has_conditions);
}

#[test]
fn an_inflow_without_a_waveform_is_named() {
    let mut m = model();
    m["boundary_conditions"]["in"] = json!({"type": "flow", "steady": true});
    let Err(err) = set_values(&m, &["scale.inflow".to_owned()], &[2.0]) else {
        panic!("a flow condition without a waveform was scaled");
    };
    assert_eq!(
        err.to_string(),
        "parameter 'scale.inflow': the flow condition at 'in' has no 'value', 'flow' or \
         'fourier' to scale"
    );
}

#[test]
fn the_intramyocardial_factor_scales_its_waveform() {
    let p = set(
        &[
            "boundary_conditions.out2.intramyocardial_pressure.scale",
            "boundary_conditions.out3.intramyocardial_pressure.scale",
            "boundary_conditions.out2.arterial_resistance",
        ],
        &[0.5, 3.0, 2e9],
    );
    assert_eq!(
        condition(&p, "out2"),
        json!({"type": "coronary", "arterial_resistance": 2e9,
               "intramyocardial_pressure": {"time": [0.0, 1.0], "pressure": [5.0, 10.0],
                                            "fourier": {"mean": 2.0, "cos": [1.0],
                                                        "period": 1.0}}})
    );
    assert_eq!(
        condition(&p, "out3")["intramyocardial_pressure"],
        json!(300.0)
    );
    let err = refused(
        &["boundary_conditions.out1.intramyocardial_pressure.scale"],
        &[2.0],
    );
    assert_eq!(
        err,
        "parameter 'boundary_conditions.out1.intramyocardial_pressure.scale': the condition \
         at node 'out1' has no intramyocardial pressure"
    );
}

#[test]
fn a_heart_value_is_set_where_the_element_holds_it() {
    let p = set(
        &[
            "vessels.lv.chamber.activation.t_active",
            "vessels.lv.chamber.max_elastance",
        ],
        &[0.25, 3e8],
    );
    assert_eq!(
        vessel(&p, 3)["chamber"],
        json!({"law": "elastance-inductor", "max_elastance": 3e8,
               "activation": {"kind": "half-cosine", "t_active": 0.25}})
    );
    assert!(p.has_vessels);
    assert_eq!(
        refused(&["vessels.lv.valve.min_resistance"], &[1.0]),
        "parameter 'vessels.lv.valve.min_resistance': no such number in the model"
    );
    assert_eq!(
        refused(&["vessels.rv.chamber.max_elastance"], &[1.0]),
        "parameter 'vessels.rv.chamber.max_elastance': no vessel named 'rv'"
    );
}

#[test]
fn a_refused_patch_path_is_named() {
    let err = refused(&["vessels.a.radius", "vessels.a.colour"], &[0.003, 1.0]);
    assert!(
        err.starts_with("parameter 'vessels.a.colour': unknown vessel property (allowed: "),
        "{err}"
    );
    let err = refused(&["vessels.zz.length"], &[0.1]);
    assert_eq!(
        err,
        "parameter 'vessels.zz.length': no vessel named 'zz' in model 'heart'"
    );
    assert_eq!(
        refused(&["scale.compliance"], &[0.0]),
        "parameter 'scale.compliance': factor 0.0 makes youngs_modulus of vessel 'a' \
         400000.0 / 0.0 = inf, not a finite number (a compliance factor must not be 0)"
    );
    assert_eq!(
        refused(&["scale.inflow"], &[1.0, 2.0]),
        "parameters: 1 paths but 2 values"
    );
}
