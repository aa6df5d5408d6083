//! The native reader against hand-written canonical forms and the messages users read.

use super::*;
use serde_json::json;

fn vessel_error(v: Value) -> String {
    vessel(&v, 0, Units::Si).unwrap_err().to_string()
}

#[test]
fn a_cgs_vessel_is_converted_to_si() {
    let v = json!({"name": "a", "from": "in", "to": "J", "length": 6.0, "radius": 0.3,
                   "youngs_modulus": 5e6, "segments": 3});
    let c = vessel(&v, 0, Units::Cgs).unwrap();
    assert_eq!(
        c,
        json!({"name": "a", "from": "in", "to": "J", "segments": 3,
               "geometry": {"length": 0.06, "radius_in": 0.003, "radius_out": 0.003,
                            "youngs_modulus": 5e5}})
    );
}

#[test]
fn vessel_errors_name_the_vessel_key_and_value() {
    let base = json!({"name": "left", "from": "J", "to": "out", "length": 0.05});
    let with = |k: &str, x: Value| {
        let mut v = base.clone();
        v[k] = x;
        vessel_error(v)
    };
    assert_eq!(
        with("radius", json!(-0.001)),
        "vessel 'left': radius must be a finite number > 0, got -0.001"
    );
    assert_eq!(
        with("radius", json!("wide")),
        "vessel 'left': 'radius' must be a number, got 'wide'"
    );
    assert_eq!(
        with("segments", json!(2.5)),
        "vessel 'left': 'segments' must be an integer >= 1 or 'auto', got 2.5"
    );
    assert_eq!(
        with("segments", json!("autox")),
        "vessel 'left': 'segments' must be an integer >= 1 or 'auto', got 'autox'"
    );
    assert_eq!(
        with("radiuss", json!(1)),
        "vessel 'left': unknown key 'radiuss' (allowed: arrangement, chamber, chamber_sphere, \
         coronary_bed, description, from, heart_pulmonary, initial, initial_rate, length, \
         lumped, name, output, poisson_ratio, radius, radius_in, radius_out, segments, through_rc, \
         to, valve, wall_friction, wall_thickness, wall_viscosity, youngs_modulus)"
    );
    assert_eq!(
        vessel_error(json!({"name": "shunt", "from": "J", "to": "o",
                            "lumped": {"resistance": -1e8}})),
        "vessel 'shunt': resistance must be a finite number >= 0, got -1e+08"
    );
}

#[test]
fn waveform_tables_are_checked_and_read() {
    let bc = json!({"type": "flow", "time": [0.0, 0.6, 0.4, 1.0], "flow": [1, 2, 3, 4]});
    let e = boundary_condition(&bc, Units::Si, "boundary condition 'in'").unwrap_err();
    assert_eq!(
        e.to_string(),
        "boundary condition 'in': 'time' must be strictly increasing: t[2] = 0.4 <= t[1] = 0.6"
    );
    let bc = json!({"type": "pressure", "time": [0.0, 0.5], "pressure": [1, 2]});
    let c = boundary_condition(&bc, Units::Cgs, "bc").unwrap();
    assert_eq!(c["pressure"]["value"], json!([0.1, 0.2]));
    assert_eq!(condition_periods(&c, "bc"), vec![(0.5, "bc".to_owned())]);
}

#[test]
fn a_period_mismatch_names_both_sources() {
    let p = [(0.8, "boundary condition 'inlet'".to_owned())];
    let e = check_periods(Some(1.0), &p).unwrap_err().to_string();
    assert_eq!(
        e,
        "boundary condition 'inlet': period mismatch: it repeats every 0.8 s but the model \
         period is 1 s"
    );
}
