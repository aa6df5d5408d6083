//! The closed loop's circulation, built from its parameter set (docs/oxygen.md "Oxygen around
//! a closed loop"): the native model of the closed-loop heart whose run gives the O2 loop its
//! flows (the heart between the venous return and the aorta, the systemic arteries as a pool
//! or as the segment-resolved arterial tree, the organ beds as parallel resistances, the
//! systemic veins) and the arterial tree's own open model. Both are native model dicts in SI
//! (the heart block's values in their published mmHg and mL, `units: mmHg-mL`), read by the
//! core's schema like any model (`model::native::canonical`).

use super::closed_loop_params::{Layout, LoopParams};
use crate::error::{Error, Result};
use crate::model::node::Node;
use crate::model::units::MMHG;
use serde_json::{Map, Value, json};

/// The heart kinds a parameter set may name (`heart`).
pub const HEARTS: &[&str] = &["svzerod-block", "two-ventricle"];
const DEFAULT_HEART: &str = "two-ventricle";
const BLOCK: &str = "svzerod-block";
/// The heart run's flow step (s) when the set gives no `flow_dt`.
const FLOW_DT: f64 = 1e-3;
/// The heart run's least cycles (its last one is read): the native heart runs on until the
/// cycle-to-cycle change of its state is below `HEART_TOL`, at most `HEART_MAX_CYCLES` cycles
/// (`heart_until_periodic`).
pub const HEART_CYCLES: usize = 30;
/// The heart run's periodicity (the relative change of its state over a cycle, as a run's
/// `until_periodic`): its flows' derivatives by heart parameters are those of the periodic
/// state (`closed_loop_heart_tangent`), so the run that gives the flows must be periodic to
/// well below the 1e-6 those derivatives are checked to.
pub const HEART_TOL: f64 = 1e-10;
/// The heart run's most cycles by default (the set's `heart_max_cycles` sets its own); a run
/// that stops there without meeting `HEART_TOL` says so (the O2 run's `heart_periodic`, a
/// warning).
pub const HEART_MAX_CYCLES: usize = 500;
/// svZeroDSolver's block needs an absolute Newton tolerance (its on/off valves, docs/physics.md
/// §1.10); Pa, m³/s and m³ residuals here, 1e-10 is far below their discretisation error.
pub const BLOCK_NEWTON_ATOL: f64 = 1e-10;
/// The venous pressure (mmHg) the tree's outlets drain to before a heart run gives it.
const VENOUS_MMHG: f64 = 7.0;

pub(crate) fn err(message: impl Into<String>) -> Error {
    Error::model("closed loop", message)
}

/// `p[key]`, a model error naming the key when it is missing.
pub(crate) fn field<'a>(p: &'a Value, key: &str) -> Result<&'a Value> {
    p.get(key)
        .ok_or_else(|| err(format!("the parameter set needs '{key}'")))
}

/// `p[key]` as a number.
fn number(p: &Value, key: &str) -> Result<f64> {
    let v = field(p, key)?;
    v.as_f64()
        .ok_or_else(|| err(format!("'{key}' must be a number, got {}", v.repr())))
}

/// The set's heart (`heart`, the native two-ventricle heart by default), checked.
pub fn heart_kind(p: &Value) -> Result<&str> {
    match p.get("heart") {
        None => Ok(DEFAULT_HEART),
        Some(Value::String(s)) if HEARTS.contains(&s.as_str()) => Ok(s.as_str()),
        Some(v) => Err(err(format!(
            "heart must be one of {}, got {}",
            HEARTS.join(", "),
            v.repr()
        ))),
    }
}

/// The heart run's flow step (s) as given (`flow_dt`, 1 ms by default).
pub fn flow_dt(p: &Value) -> Value {
    p.get("flow_dt").cloned().unwrap_or(json!(FLOW_DT))
}

/// The blood and segment layout shared by the closed loop and its tree's own model (the same
/// equations for the tree's segments in both).
fn with_blood(mut m: Value) -> Value {
    m["blood"] = json!({"density": 1060.0, "viscosity": 0.004});
    m["arrangement"] = json!("inverted-L");
    m
}

/// The closed circulation (no boundary condition) whose flows drive the O2 loop: the heart
/// between the venous return (node `venous_return`) and the aorta (`aorta_in`), the systemic
/// arteries (a pool of 1.5 mL/mmHg, or the tree with `arteries: "tree"`), the organs as
/// parallel resistances sharing the cardiac output by `flow_fraction` at a mean arterial
/// pressure of 93 mmHg, and the systemic veins (100 mL/mmHg); run with generalized-α at
/// `flow_dt` (`HEART_CYCLES` cycles; the native heart on to its periodic state,
/// `heart_until_periodic`), the last cycle recorded. The set's `heart_values` are written over the built values
/// (`closed_loop_heart_values`).
pub fn heart_model(p: &Value, params: &LoopParams, layout: &Layout) -> Result<Value> {
    let heart = if heart_kind(p)? == BLOCK {
        block_heart(p)?
    } else {
        two_ventricle_heart(p)?
    };
    let mut vessels = systemic(p, params, layout)?;
    vessels.extend(heart);
    let fdt = flow_dt(p);
    let mut simulation = json!({"cycles": HEART_CYCLES, "dt": fdt,
                                "method": "generalized-alpha",
                                "output": {"cycles": "last", "every": fdt}});
    if let Some(tol) = heart_until_periodic(p)? {
        simulation["until_periodic"] = json!(tol);
        simulation["max_cycles"] = json!(heart_max_cycles(p)?);
    }
    let mut model = with_blood(json!({
        "name": "closed-loop-heart", "units": "SI", "period": field(p, "period")?,
        "vessels": vessels, "boundary_conditions": {}, "simulation": simulation
    }));
    super::closed_loop_heart_values::apply(&mut model, p)?;
    Ok(model)
}

/// The heart run's periodicity tolerance: `HEART_TOL` for the native two-ventricle heart
/// (smooth: 51 cycles reach it on `closed-loop-o2`); None (a fixed `HEART_CYCLES` cycles) for
/// svZeroDSolver's block, whose on/off valves hold its cycle-to-cycle change at ~2e-6
/// (2.5e-6 after 2,000 cycles on `closed-loop-o2`, 2.6e-5 with the arterial tree).
pub fn heart_until_periodic(p: &Value) -> Result<Option<f64>> {
    Ok((heart_kind(p)? != BLOCK).then_some(HEART_TOL))
}

/// The heart run's most cycles (`heart_max_cycles`, `HEART_MAX_CYCLES` by default), at least
/// `HEART_CYCLES`.
pub fn heart_max_cycles(p: &Value) -> Result<usize> {
    match p.get("heart_max_cycles") {
        None => Ok(HEART_MAX_CYCLES),
        Some(v) => v
            .as_u64()
            .filter(|&n| n as usize >= HEART_CYCLES && n as f64 <= 1e9)
            .map(|n| n as usize)
            .ok_or_else(|| {
                err(format!(
                    "heart_max_cycles must be a whole number from {HEART_CYCLES} to 1e+09, \
                     got {}",
                    v.repr()
                ))
            }),
    }
}

/// The heart run's Newton tolerance (None: the default control).
pub fn heart_newton_atol(p: &Value) -> Result<Option<f64>> {
    Ok((heart_kind(p)? == BLOCK).then_some(BLOCK_NEWTON_ATOL))
}

fn lumped(name: &str, from: &str, to: &str, values: Value) -> Value {
    json!({"name": name, "from": from, "to": to, "arrangement": "RCL", "lumped": values})
}

/// From the aorta (`aorta_in`) to the venous return (`venous_return`): arteries, organs,
/// veins.
fn systemic(p: &Value, params: &LoopParams, layout: &Layout) -> Result<Vec<Value>> {
    let beds = params.organs.iter().zip(&layout.organ_resistances);
    let mut v =
        if params.has_tree() {
            // the segment-resolved tree in place of the arterial pool; organs at its outlets
            let mut v = tree_vessels(p)?;
            v.extend(beds.map(|((k, _), r)| {
                lumped(k, &format!("{k}_a"), "veins_in", json!({"resistance": r}))
            }));
            v
        } else {
            let arteries = json!({"resistance": 1e6, "capacitance": 1.5e-8, "inductance": 1e5});
            let mut v = vec![lumped("arteries", "aorta_in", "arteries_out", arteries)];
            v.extend(beds.map(|((k, _), r)| {
                lumped(k, "arteries_out", "veins_in", json!({"resistance": r}))
            }));
            v
        };
    let veins = json!({"resistance": 1e6, "capacitance": 7.5e-7});
    v.push(lumped("veins", "veins_in", "venous_return", veins));
    Ok(v)
}

/// svZeroDSolver's ClosedLoopHeartAndPulmonary (docs/physics.md §1.10) with the set's
/// `heart_block` values in their published units (mmHg, mL, s: the schema converts them),
/// beating at the loop's period.
fn block_heart(p: &Value) -> Result<Vec<Value>> {
    let mut values: Map<String, Value> = field(p, "heart_block")?
        .as_object()
        .cloned()
        .ok_or_else(|| err("'heart_block' must be a mapping of the block's values"))?;
    // the stressed blood volume the circulation needs beyond the cases' start volumes, put
    // into the ventricles at the start (their law is linear: it empties into the loop within
    // a few beats; the atria's exponential passive law would not take it smoothly)
    let stressed = number(p, "stressed_volume")?;
    for side in ["left", "right"] {
        let key = format!("initial_{side}_ventricle_volume");
        let start = values
            .get(&key)
            .and_then(Value::as_f64)
            .ok_or_else(|| err(format!("'heart_block' needs a number '{key}' (mL)")))?;
        values.insert(key, json!(start + 0.5 * stressed));
    }
    let mut block = json!({"units": "mmHg-mL", "period": field(p, "period")?});
    if let Value::Object(m) = &mut block {
        m.extend(values);
    }
    Ok(vec![
        json!({"name": "heart_pulmonary", "from": "venous_return", "to": "aorta_in",
                   "heart_pulmonary": block}),
    ])
}

/// The native two-ventricle heart (docs/physics.md §1.8: `chamber` and `valve` elements):
/// left and right ventricles (linear elastance, piecewise-cosine activation), four tanh
/// valves, pulmonary arteries, lungs, pulmonary veins. The chambers are the `chambers`
/// branch's minimal closed loop (LV) and a right ventricle with a fifth of its active
/// elastance; SI units.
fn two_ventricle_heart(p: &Value) -> Result<Vec<Value>> {
    let period = field(p, "period")?;
    let scale = number(p, "period")? / 0.8;
    let activation = json!({"kind": "piecewise-cosine", "contract_start": 0.0,
                            "relax_start": 0.25 * scale, "contract_duration": 0.25 * scale,
                            "relax_duration": 0.2 * scale});
    let chamber = |e_max: f64, e_pass: f64| {
        json!({"law": "linear", "max_elastance": e_max, "passive_elastance": e_pass,
               "rest_volume": 1e-5, "period": period, "initial_volume": 0.6e-3,
               "activation": activation})
    };
    let valve = json!({"law": "tanh", "min_resistance": 1.0e6, "max_resistance": 1.0e11,
                       "steepness": 0.05});
    let valve_at = |name: &str, from: &str, to: &str| json!({"name": name, "from": from, "to": to, "valve": valve});
    let chamber_at = |name: &str, from: &str, to: &str, c: Value| json!({"name": name, "from": from, "to": to, "chamber": c});
    Ok(vec![
        chamber_at("lv", "mitral_out", "lv_out", chamber(3.3e8, 1.2e7)),
        valve_at("aortic_valve", "lv_out", "aorta_in"),
        valve_at("tricuspid_valve", "venous_return", "rv_in"),
        chamber_at("rv", "rv_in", "rv_out", chamber(0.6e8, 0.6e7)),
        valve_at("pulmonary_valve", "rv_out", "pa_in"),
        lumped(
            "pulmonary_arteries",
            "pa_in",
            "pa_out",
            json!({"resistance": 1e6, "capacitance": 2.25e-8}),
        ),
        lumped("lungs", "pa_out", "pv_in", json!({"resistance": 1.2e7})),
        lumped(
            "pulmonary_veins",
            "pv_in",
            "mitral_in",
            json!({"resistance": 1e6, "capacitance": 6e-8}),
        ),
        valve_at("mitral_valve", "mitral_in", "mitral_out"),
    ])
}

/// The arterial tree's vessels (SI) from the set's `tree: vessels` ([name, from, to, length,
/// radius]), each cut into ceil(length / max_segment_length) segments.
fn tree_vessels(p: &Value) -> Result<Vec<Value>> {
    let t = field(p, "tree")?;
    let ratio = number(t, "wall_ratio")?;
    let longest = number(t, "max_segment_length")?;
    let modulus = field(t, "youngs_modulus")?;
    let list = field(t, "vessels")?
        .as_array()
        .ok_or_else(|| err("tree: 'vessels' must be a list of [name, from, to, length, radius]"))?;
    list.iter()
        .map(|v| {
            let item = v.as_array().filter(|a| a.len() == 5);
            let nums = item.and_then(|a| Some((a[3].as_f64()?, a[4].as_f64()?)));
            let (Some(a), Some((length, radius))) = (item, nums) else {
                return Err(err(format!(
                    "tree: a vessel must be [name, from, to, length, radius], got {}",
                    v.repr()
                )));
            };
            let segments = ((length / longest - 1e-9).ceil() as i64).max(1);
            Ok(
                json!({"name": a[0], "from": a[1], "to": a[2], "length": a[3],
                      "radius": a[4], "wall_thickness": ratio * radius,
                      "youngs_modulus": modulus, "poisson_ratio": 0.5,
                      "segments": segments}),
            )
        })
        .collect()
}

/// The tree as an open network driven by the closed-loop heart: a flow table into its root
/// (`aorta_in`) and, at every outlet (`<organ>_a`), its organ bed's resistance to a venous
/// pressure table. Here the tables hold the cardiac output and 7 mmHg over one cycle; the
/// loop writes those of its heart run into them (`closed_loop_heart`). Its `oxygen` section
/// carries the loop's blood (Hill binding) and the tree's wall closure.
pub fn tree_model(p: &Value, params: &LoopParams, layout: &Layout) -> Result<Value> {
    let period = field(p, "period")?;
    let time = json!([0.0, number(p, "period")?]);
    let inflow = json!([layout.cardiac_output, layout.cardiac_output]);
    let venous = json!([VENOUS_MMHG * MMHG, VENOUS_MMHG * MMHG]);
    let mut bcs = Map::new();
    bcs.insert(
        "aorta_in".into(),
        json!({"type": "flow", "time": time, "flow": inflow}),
    );
    for ((k, _), r) in params.organs.iter().zip(&layout.organ_resistances) {
        bcs.insert(
            format!("{k}_a"),
            json!({"type": "resistance", "resistance": r,
                   "pressure": {"time": time, "pressure": venous}}),
        );
    }
    let b = field(p, "blood")?;
    let hill = json!({"p50": field(b, "p50")?, "n": field(b, "hill_n")?,
                      "hb": field(b, "hemoglobin")?, "huefner": field(b, "hufner")?});
    let wall = field(field(p, "tree")?, "wall")?;
    Ok(with_blood(json!({
        "name": "closed-loop-arterial-tree", "units": "SI", "period": period,
        "vessels": tree_vessels(p)?, "boundary_conditions": bcs,
        "oxygen": {"inlet": {"po2": 95.0}, "hemoglobin": "hill", "hill": hill,
                   "solubility": layout.solubility_per_mmhg,  // mol m⁻³ mmHg⁻¹
                   "diffusivity": 2.0e-9, "wall": wall, "reference_pressure": 93.0}
    })))
}

#[cfg(test)]
mod tests {
    use super::super::closed_loop_run::{RunSettings, check_times};
    use super::*;
    use crate::model::native::canonical;

    const SET: &str = r#"{"period": 0.8, "dt": 1e-3, "cardiac_output": 6.0,
        "blood": {"solubility": 0.003, "hemoglobin": 150.0, "hufner": 1.34, "p50": 26.8,
                  "hill_n": 2.7},
        "lungs": {"alveolar_po2": 100.0, "diffusing_capacity": 21.0, "shunt_fraction": 0.02},
        "pools": {"left_heart": 0.15, "arteries": 0.75, "veins": 3.0, "right_heart": 0.15,
                  "pulmonary_arteries": 0.15, "pulmonary_veins": 0.3},
        "km": 1.0, "stressed_volume": 1000.0,
        "heart_block": {"initial_left_ventricle_volume": 96.0,
                        "initial_right_ventricle_volume": 90.0},
        "organs": {"muscle": {"flow_fraction": 0.75, "vo2": 50.0, "volume": 0.2},
                   "brain": {"flow_fraction": 0.25, "vo2": 50.0, "volume": 0.075}},
        "tree": {"youngs_modulus": 2.5e5, "wall_ratio": 0.1, "max_segment_length": 0.02,
                 "flow_cycles": 10, "wall": {"model": "none"},
                 "vessels": [["root", "aorta_in", "split", 0.15, 0.01],
                             ["leg", "split", "muscle_a", 0.02, 0.005],
                             ["head", "split", "brain_a", 0.3, 0.004]]}}"#;

    fn set(changes: Value) -> (Value, LoopParams) {
        let mut p: Value = serde_json::from_str(SET).unwrap();
        if let (Value::Object(m), Value::Object(c)) = (&mut p, changes) {
            m.extend(c);
        }
        let params = LoopParams::from_json(&p.to_string()).unwrap();
        (p, params)
    }

    fn vessel<'a>(m: &'a Value, name: &str) -> &'a Value {
        m["vessels"]
            .as_array()
            .unwrap()
            .iter()
            .find(|v| v["name"] == name)
            .unwrap()
    }

    /// The organ beds share the cardiac output at 93 mmHg: R = 93 mmHg / (fraction × CO); the
    /// model reads through the core's schema as a closed circulation.
    #[test]
    fn organ_beds_take_their_share_of_the_output_at_the_mean_pressure() {
        let (p, params) = set(json!({"heart": "two-ventricle"}));
        let m = heart_model(&p, &params, &params.layout()).unwrap();
        let co = 6.0e-3 / 60.0;
        for (organ, share) in [("muscle", 0.75), ("brain", 0.25)] {
            let r = vessel(&m, organ)["lumped"]["resistance"].as_f64().unwrap();
            let expected = 93.0 * 133.322368 / (share * co);
            assert!(
                (r / expected - 1.0).abs() < 1e-14,
                "{organ}: {r} vs {expected}"
            );
        }
        let (canon, _) = canonical(&m).unwrap();
        assert_eq!(canon["vessels"].as_array().unwrap().len(), 4 + 9);
    }

    /// The block's ventricles start with half the stressed volume each on top of the given
    /// start volumes (mL, as given); an unknown heart is named with the kinds.
    #[test]
    fn block_ventricles_take_half_the_stressed_volume_each() {
        let (p, params) = set(json!({"heart": "svzerod-block"}));
        let m = heart_model(&p, &params, &params.layout()).unwrap();
        let block = &vessel(&m, "heart_pulmonary")["heart_pulmonary"];
        assert_eq!(block["initial_left_ventricle_volume"], 596.0);
        assert_eq!(block["initial_right_ventricle_volume"], 590.0);
        assert_eq!(block["units"], "mmHg-mL");
        let (p, params) = set(json!({"heart": "three-ventricle"}));
        let e = heart_model(&p, &params, &params.layout())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("heart must be one of svzerod-block, two-ventricle, got 'three-ventricle'"),
            "{e}"
        );
    }

    /// Segments per tree vessel: ceil(length / max_segment_length), at least one (a length
    /// of exactly 0.02 m is one segment, not two from rounding); the tree's outlets drain
    /// into their organ beds.
    #[test]
    fn tree_vessels_are_cut_by_the_longest_segment() {
        let (p, params) = set(json!({"arteries": "tree", "heart": "two-ventricle"}));
        let lay = params.layout();
        let m = heart_model(&p, &params, &lay).unwrap();
        for (name, n) in [("root", 8), ("leg", 1), ("head", 15)] {
            assert_eq!(vessel(&m, name)["segments"], n, "{name}");
        }
        assert_eq!(vessel(&m, "muscle")["from"], "muscle_a");
        let tree = tree_model(&p, &params, &lay).unwrap();
        let bcs = &tree["boundary_conditions"];
        let q = bcs["aorta_in"]["flow"][0].as_f64().unwrap();
        assert!((q / (6.0e-3 / 60.0) - 1.0).abs() < 1e-15, "{q}");
        assert!(bcs["brain_a"]["resistance"].as_f64().unwrap() > 0.0);
        let (canon, _) = canonical(&tree).unwrap();
        assert!(canon["transport"].is_object());
    }

    /// The run settings are named with their values as the caller wrote them.
    #[test]
    fn run_settings_out_of_range_are_named() {
        let msg = |p: Value| check_times(&p).unwrap_err().to_string();
        assert!(
            msg(json!({"period": 0, "dt": 1e-3}))
                .contains("period must be a number in (0, inf), got 0")
        );
        assert!(
            msg(json!({"period": 0.8, "dt": true}))
                .contains("dt must be a number in (0, inf), got True")
        );
        assert!(
            msg(json!({"period": 0.8, "dt": 5.0}))
                .contains("dt = 5 s is longer than the period 0.8 s")
        );
        let e = check_times(&json!({"period": 1e9, "dt": 0.5})).unwrap_err();
        assert!(matches!(e, Error::Resource { .. }), "{e}");
        assert!(e.to_string().contains("= 2e+09 steps per cycle"), "{e}");
        let read = |c: Value, t: Value, s: Value| RunSettings::read(&c, &t, &s).map(|_| ());
        let e = read(json!(2.5), json!(1e-13), json!("anderson")).unwrap_err();
        assert!(
            e.to_string()
                .contains("max_cycles must be a whole number from 1 to 1e+09, got 2.5")
        );
        let e = read(json!(3), json!(1.0), json!("anderson")).unwrap_err();
        assert!(
            e.to_string()
                .contains("tol must be a number in (0, 1), got 1.0")
        );
        let e = read(json!(3), json!(1e-13), json!("secant")).unwrap_err();
        assert!(
            e.to_string()
                .contains("shooting must be 'anderson' or 'newton', got 'secant'")
        );
        assert!(read(json!(3), json!(1e-13), json!("newton")).is_ok());
    }
}
