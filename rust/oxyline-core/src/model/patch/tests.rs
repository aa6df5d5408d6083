//! Patch semantics on JSON models: each expected value is written out by hand from the
//! documented rules (docs/ensembles.md), never taken from the code's own output.

use super::{Merged, PatchError, Patched, merge};
use serde_json::{Value, json};

fn tube() -> Value {
    json!({
        "name": "tube", "units": "SI", "period": 1.0,
        "vessels": [
            {"name": "a.b", "from": "in", "to": "j", "length": 0.1, "radius": 0.004,
             "wall_thickness": 5e-4, "youngs_modulus": 4e5},
            {"name": "c", "from": "j", "to": "out1",
             "lumped": {"resistance": 1e7, "capacitance": 1e-9}},
            {"name": "d", "from": "j", "to": "out2", "length": 0.05, "radius_in": 0.003,
             "radius_out": 0.002, "youngs_modulus": "5.0e5"}],
        "boundary_conditions": {
            "in": {"type": "flow", "time": [0.0, 0.5, 1.0], "flow": [1e-6, 3e-6, 1e-6]},
            "out1": {"type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-9,
                     "distal_resistance": 1e9},
            "out2": {"type": "resistance", "resistance": 2e9, "pressure": 0.0}},
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

fn vessel(p: &Patched<Value>, i: usize) -> Value {
    plain(
        &p.vessels
            .iter()
            .find(|(j, _)| *j == i)
            .expect("vessel replaced")
            .1,
    )
}

fn condition(p: &Patched<Value>, node: &str) -> Value {
    plain(
        &p.conditions
            .iter()
            .find(|(n, _)| n == node)
            .expect("condition replaced")
            .1,
    )
}

fn message(r: Result<Patched<Value>, PatchError>) -> (bool, String) {
    match r {
        Err(PatchError::Name(e)) => (true, e.to_string()),
        Err(PatchError::Value(e)) => (false, e.to_string()),
        Ok(_) => panic!("the patch was accepted"),
    }
}

#[test]
fn radius_replaces_both_ends_and_an_end_splits_the_radius() {
    let p = merge(
        &tube(),
        &json!({"vessels": {"d": {"radius": 0.0025},
                                               "a.b": {"radius_in": 0.005}}}),
        0,
    )
    .unwrap();
    let d = vessel(&p, 2);
    assert_eq!(d["radius"], json!(0.0025));
    assert!(d.get("radius_in").is_none() && d.get("radius_out").is_none());
    let a = vessel(&p, 0);
    assert_eq!(
        (a["radius_in"].clone(), a["radius_out"].clone()),
        (json!(0.005), json!(0.004))
    );
    assert!(a.get("radius").is_none());
    assert_eq!(
        p.vessel_paths,
        vec![
            // a JSON object's keys in sorted order
            (0, vec!["vessels.a.b.radius_in = 0.005".to_owned()]),
            (2, vec!["vessels.d.radius = 0.0025".to_owned()])
        ]
    );
}

#[test]
fn waveforms_and_condition_types_replace_as_a_whole() {
    let p = merge(
        &tube(),
        &json!({"boundary_conditions": {
        "in": {"fourier": {"period": 1.0, "mean": 2e-6}},
        "out2": {"type": "rcr", "proximal_resistance": 1.0, "capacitance": 2e-9,
                 "distal_resistance": 3.0},
        "out1": {"distal_resistance": 5e8}}}),
        0,
    )
    .unwrap();
    assert_eq!(
        condition(&p, "in"),
        json!({"type": "flow", "fourier": {"period": 1.0, "mean": 2e-6}})
    );
    assert_eq!(
        condition(&p, "out2"),
        json!({"type": "rcr", "proximal_resistance": 1.0,
                                             "capacitance": 2e-9, "distal_resistance": 3.0})
    );
    assert_eq!(
        condition(&p, "out1"),
        json!({"type": "rcr", "proximal_resistance": 1e8,
                                             "capacitance": 1e-9, "distal_resistance": 5e8})
    );
}

#[test]
fn scale_multiplies_the_selected_vessels_and_their_end_conditions() {
    let p = merge(
        &tube(),
        &json!({"scale": {"resistance": 2.0, "compliance": 0.5,
                                             "vessels": ["c"]}}),
        0,
    )
    .unwrap();
    assert_eq!(
        vessel(&p, 1)["lumped"],
        json!({"resistance": 2e7, "capacitance": 5e-10})
    );
    assert_eq!(
        condition(&p, "out1"),
        json!({"type": "rcr", "proximal_resistance": 2e8,
                                             "capacitance": 5e-10, "distal_resistance": 2e9})
    );
    assert!(p.conditions.iter().all(|(n, _)| n != "out2" && n != "in"));
    // every vessel: C ∝ 1/E, so the modulus is divided (a YAML 1.1 text number too)
    let p = merge(&tube(), &json!({"scale": {"compliance": 0.5}}), 0).unwrap();
    assert_eq!(vessel(&p, 0)["youngs_modulus"], json!(8e5));
    assert_eq!(vessel(&p, 2)["youngs_modulus"], json!(1e6));
}

#[test]
fn a_compliance_factor_zero_fails_its_variant_naming_the_path_and_value() {
    let (name, text) = message(merge(&tube(), &json!({"scale": {"compliance": 0}}), 3));
    assert!(!name, "a value error, not a naming mistake");
    assert!(
        text.starts_with("variant 3: scale.compliance: factor 0.0 "),
        "{text}"
    );
    assert!(
        text.contains("youngs_modulus of vessel 'a.b' 400000.0 / 0.0 = inf"),
        "{text}"
    );
    let (name, text) = message(merge(&tube(), &json!({"scale": {"resistance": "x"}}), 1));
    assert!(
        !name && text.contains("variant 1: scale.resistance: expected a number, got 'x'"),
        "{text}"
    );
    let (name, text) = message(merge(
        &tube(),
        &json!({"scale": {"resistance": 1e302, "vessels": ["c"]}}),
        0,
    ));
    assert!(
        !name && text.contains("scale.resistance: factor 1e+302 makes resistance of vessel 'c'"),
        "{text}"
    );
}

#[test]
fn unknown_names_are_naming_mistakes() {
    for (patch, start) in [
        (
            json!({"vessels": {"nope": {"radius": 1.0}}}),
            "variant 1: vessels.nope: no vessel named 'nope'",
        ),
        (
            json!({"vessels": {"c": {"to": "x"}}}),
            "variant 1: vessels.c.to: a variant cannot change",
        ),
        (
            json!({"vessels": {"c": {"lumped": {"inductanse": 1.0}}}}),
            "variant 1: vessels.c.lumped.inductanse: unknown lumped property",
        ),
        (
            json!({"vessels": {"a.b": {"radius": {"x": 1.0}}}}),
            "variant 1: vessels.a.b.radius: expected a number, got the mapping",
        ),
        (
            json!({"boundary_conditions": {"out1": {"resistance": 1.0}}}),
            "variant 1: boundary_conditions.out1.resistance: unknown property of a rcr condition",
        ),
        (
            json!({"oxygen": {"wall": {"k": 5e-6}}}),
            "variant 1: oxygen.wall.k: unknown property of a graetz wall",
        ),
        (
            json!({"transport": {"cells": 2}}),
            "variant 1: transport: the model has no 'transport' section",
        ),
        (
            json!({"scale": {"vessels": ["c", "zz"]}}),
            "variant 1: scale.vessels.zz: no vessel named 'zz'",
        ),
        (
            json!({"simulation": {}}),
            "variant 1: simulation: unknown patch section",
        ),
    ] {
        let (name, text) = message(merge(&tube(), &patch, 1));
        assert!(name && text.starts_with(start), "{patch}: {text}");
    }
}

#[test]
fn another_wall_closure_replaces_the_wall() {
    let wall = json!({"model": "mass-transfer", "k": 5e-6, "po2": 55.5});
    let p = merge(&tube(), &json!({"oxygen": {"wall": wall.clone()}}), 0).unwrap();
    assert_eq!(plain(&p.sections[0].1)["wall"], wall);
    let p = merge(&tube(), &json!({"oxygen": {"wall": {"po2": 50.0}}}), 0).unwrap();
    assert_eq!(
        plain(&p.sections[0].1)["wall"],
        json!({"model": "graetz", "po2": 50.0})
    );
}

/// A heart element's key is checked against its law (the patch's, else the base vessel's)
/// and a chamber's activation against its kind: a typo is a naming mistake, raised before
/// anything runs, with the schema's nearest key; the keys the law has pass.
#[test]
fn a_heart_elements_unknown_key_is_a_naming_mistake_with_the_nearest() {
    let mut model = tube();
    model["vessels"][1] = json!({"name": "c", "from": "j", "to": "out1",
        "chamber": {"law": "linear", "max_elastance": 2e8, "passive_elastance": 1e7,
                    "rest_volume": 1e-5,
                    "activation": {"kind": "half-cosine", "t_active": 0.2, "t_twitch": 0.3}}});
    let patch = json!({"vessels": {"c": {"chamber": {"max_elastanse": 1.0}}}});
    let (name, text) = message(merge(&model, &patch, 2));
    assert!(name, "{text}");
    assert!(
        text.starts_with(
            "variant 2: vessels.c.chamber.max_elastanse: unknown property of a linear chamber \
             (allowed: activation, inductance, initial_volume, law, max_elastance, \
             passive_elastance, period, rest_volume; nearest: max_elastance)"
        ),
        "{text}"
    );
    let patch = json!({"vessels": {"c": {"chamber": {"activation": {"t_twich": 0.3}}}}});
    let (name, text) = message(merge(&model, &patch, 2));
    assert!(name, "{text}");
    assert!(
        text.starts_with(
            "variant 2: vessels.c.chamber.activation.t_twich: unknown property of a \
             half-cosine activation (allowed: kind, t_active, t_twitch; nearest: t_twitch)"
        ),
        "{text}"
    );
    // another law in the patch: its keys
    let patch = json!({"vessels": {"c": {"chamber": {"law": "exponential",
                                                     "passive_pressure": 1.0}}}});
    assert!(merge(&model, &patch, 2).is_ok());
    let patch = json!({"vessels": {"c": {"chamber": {"max_elastance": 3e8,
                                          "activation": {"t_active": 0.25}}}}});
    assert!(merge(&model, &patch, 2).is_ok());
    // a valve's key by the law the patch gives
    let patch = json!({"vessels": {"c": {"valve": {"law": "tanh", "steepnes": 1.0}}}});
    let (name, text) = message(merge(&model, &patch, 2));
    assert!(
        name && text.contains("unknown property of a tanh valve"),
        "{text}"
    );
    assert!(text.ends_with("; nearest: steepness)"), "{text}");
}
