//! The signals of each output kind on small models whose vessels, inlets and valves are known
//! by construction, and the errors naming the output.

use super::*;
use crate::model::{HeartPulmonarySpec, parse};
use serde_json::{Map, Value, json};

/// Flow into `parent` from `in`, which splits at `j` into `d1` and the lumped `d2`.
const TREE: &str = r#"{
  "name": "y",
  "vessels": [
    {"name": "parent", "from": "in", "to": "j", "segments": 2,
     "geometry": {"length": 0.1, "radius_in": 0.005, "radius_out": 0.005,
                  "wall_thickness": 0.0005, "youngs_modulus": 4e5}},
    {"name": "d1", "from": "j", "to": "o1", "segments": 2,
     "geometry": {"length": 0.08, "radius_in": 0.0035, "radius_out": 0.0035,
                  "wall_thickness": 0.0005, "youngs_modulus": 6e5}},
    {"name": "d2", "from": "j", "to": "o2", "segments": 2,
     "lumped": {"resistance": 3e7, "inductance": 1e5, "capacitance": 2e-10}}
  ],
  "boundary_conditions": {
    "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 5e-6,
                                    "cos": [3e-6], "sin": [4e-6]}},
    "o1": {"type": "resistance", "resistance": 1.6e9},
    "o2": {"type": "resistance", "resistance": 1.6e9}
  }
}"#;

fn tree() -> NetworkSpec {
    parse(TREE).unwrap()
}

/// The tree fed by pressure instead (no flow condition), its `d2` a heart block: the valves
/// `d2:tricuspid` … `d2:aortic` (the values do not matter here, only the element's kind).
fn heart_tree() -> NetworkSpec {
    let mut spec = tree();
    spec.boundary_conditions
        .insert("in".into(), parse_pressure_inlet());
    let keys = [
        "period",
        "atrial_systole_fraction",
        "p_wave_divisor",
        "right_ventricle_elastance",
        "left_ventricle_elastance",
        "right_ventricle_rest_volume",
        "left_ventricle_rest_volume",
        "right_atrium_elastance",
        "left_atrium_elastance",
        "right_atrium_passive_pressure",
        "left_atrium_passive_pressure",
        "right_atrium_passive_volume_coefficient",
        "left_atrium_passive_volume_coefficient",
        "right_atrium_rest_volume",
        "left_atrium_rest_volume",
        "tricuspid_resistance",
        "tricuspid_inductance",
        "pulmonary_valve_resistance",
        "pulmonary_valve_inductance",
        "mitral_resistance",
        "mitral_inductance",
        "aortic_valve_resistance",
        "aortic_valve_inductance",
        "pulmonary_resistance",
        "pulmonary_capacitance",
        "aortic_capacitance",
    ];
    let block: Map<String, Value> = keys.iter().map(|k| (k.to_string(), json!(1.0))).collect();
    let block: HeartPulmonarySpec = serde_json::from_value(Value::Object(block)).unwrap();
    spec.vessels[2].heart_pulmonary = Some(Box::new(block));
    spec
}

fn parse_pressure_inlet() -> BoundarySpec {
    serde_json::from_value(json!({"type": "pressure", "pressure": {"kind": "fourier",
        "period": 0.8, "mean": 1e4, "cos": [], "sin": []}}))
    .unwrap()
}

fn pairs(signals: &[Signal]) -> Vec<(&str, &str)> {
    signals
        .iter()
        .map(|(v, x)| (v.as_str(), x.as_str()))
        .collect()
}

#[test]
fn each_flow_output_reads_the_signals_its_name_states() {
    let spec = tree();
    let cases: [(&str, &[(&str, &str)]); 7] = [
        ("d1.pressure_out.max", &[("d1", "pressure_out")]),
        ("d2.flow_in.series", &[("d2", "flow_in")]),
        (
            "flow_split.d1.parent",
            &[("d1", "flow_in"), ("parent", "flow_in")],
        ),
        ("cardiac_output", &[("parent", "flow_in")]),
        (
            "pwv.parent.d1",
            &[("parent", "pressure_in"), ("d1", "pressure_out")],
        ),
        (
            "amplification.parent.d1",
            &[("parent", "pressure_in"), ("d1", "pressure_out")],
        ),
        ("augmentation_index.d1", &[("d1", "pressure_in")]),
    ];
    for (output, expected) in cases {
        assert_eq!(
            pairs(&signals_of(&spec, output).unwrap()),
            expected,
            "{output}"
        );
    }
}

#[test]
fn a_heart_blocks_valves_are_outputs_and_its_aortic_valve_gives_the_cardiac_output() {
    let spec = heart_tree();
    let got = signals_of(&spec, "d2:aortic.pressure_in.max").unwrap();
    assert_eq!(pairs(&got), [("d2:aortic", "pressure_in")]);
    // no flow condition: the closed loop's output is the aortic valve's flow
    let got = signals_of(&spec, "cardiac_output").unwrap();
    assert_eq!(pairs(&got), [("d2:aortic", "flow_in")]);
    let e = signals_of(&tree(), "d2:aortic.pressure_in.max").unwrap_err();
    assert!(e.to_string().contains("no vessel named 'd2:aortic'"), "{e}");
    // neither a flow condition nor a heart block
    let mut spec = tree();
    spec.boundary_conditions
        .insert("in".into(), parse_pressure_inlet());
    let e = signals_of(&spec, "cardiac_output").unwrap_err().to_string();
    assert_eq!(
        e,
        "output 'cardiac_output': the model has no flow condition or heart block"
    );
}

#[test]
fn a_name_that_does_not_fit_the_model_is_an_error_naming_the_output() {
    let spec = tree();
    for (output, why) in [
        ("zz.pressure_in.mean", "no vessel named 'zz' in model 'y'"),
        (
            "d1.volume.mean",
            "unknown variable 'volume' (one of pressure_in, pressure_out, flow_in, flow_out, \
             po2_out, saturation_out, wall_uptake)",
        ),
        (
            "d1.flow_in.median",
            "unknown statistic 'median' (one of min, max, mean, pulse, series)",
        ),
        (
            "d1.flow_in",
            "expected <vessel>.<variable>.<statistic>, flow_split.",
        ),
        ("flow_split.d1", "expected flow_split.<vessel>.<parent>"),
        ("flow_split.d1.zz", "no vessel named 'zz'"),
        (
            "pwv.parent",
            "expected pwv.<proximal vessel>.<distal vessel>",
        ),
        ("pwv.d1.parent", "not downstream"),
        (
            "amplification.d1",
            "expected amplification.<central vessel>.",
        ),
        (
            "augmentation_index.d1.d2",
            "expected augmentation_index.<vessel>",
        ),
        ("augmentation_index.it's", "no vessel named \"it's\""),
        ("SvO2.d1", "model 'y' has no oxygen section"),
        ("VO2", "model 'y' has no oxygen section"),
        ("d1.po2_out.mean", "model 'y' has no oxygen section"),
    ] {
        let e = signals_of(&spec, output).unwrap_err().to_string();
        assert!(e.starts_with(&format!("output '{output}': ")), "{e}");
        assert!(e.contains(why), "{output}: {e}");
    }
}

/// The tree with an oxygen section (Hill binding, a mass-transfer wall).
fn oxygen_tree() -> NetworkSpec {
    let mut model: Value = serde_json::from_str(TREE).unwrap();
    model["transport"] = json!({"species": [{
        "name": "o2", "diffusivity": 1.5e-9,
        "binding": {"kind": "hill", "solubility": 1e-5, "p50": 3573.04, "n": 2.7,
                    "capacity": 9.0},
        "inlet": {"kind": "constant", "value": 0.113324},
        "wall": {"model": "mass-transfer", "k": 5e-3, "wall_concentration": 0.0533288}
    }]});
    parse(&model.to_string()).unwrap()
}

#[test]
fn oxygen_outputs_read_the_species_signals_of_the_named_vessels() {
    let spec = oxygen_tree();
    let cases: [(&str, &[(&str, &str)]); 5] = [
        ("SvO2.d1", &[("d1", "saturation_out"), ("d1", "flow_out")]),
        ("VO2", &[("", "consumption")]),
        ("VO2.d1.d2", &[("d1", "wall_uptake"), ("d2", "wall_uptake")]),
        ("d1.po2_out.mean", &[("d1", "po2_out")]),
        (
            "parent.saturation_out.series",
            &[("parent", "saturation_out")],
        ),
    ];
    for (output, expected) in cases {
        assert_eq!(
            pairs(&signals_of(&spec, output).unwrap()),
            expected,
            "{output}"
        );
    }
    for (output, why) in [
        ("SvO2.d1.d2", "expected SvO2.<vessel>"),
        ("SvO2.zz", "no vessel named 'zz'"),
        ("VO2.d1.zz", "no vessel named 'zz'"),
        ("d1.po2_out.median", "unknown statistic 'median'"),
    ] {
        let e = signals_of(&spec, output).unwrap_err().to_string();
        assert!(e.contains(why) && e.contains(output), "{output}: {e}");
    }
}
