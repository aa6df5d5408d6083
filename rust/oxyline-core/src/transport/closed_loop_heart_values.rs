//! A parameter set's own values of its closed-loop heart's model (`heart_values`, docs/oxygen.md
//! "Oxygen around a closed loop"): a mapping of the heart model's parameter paths
//! (`vessels.<name>.<key>...`, `boundary_conditions.<node>.<key>`, the patch paths of
//! docs/ensembles.md) to numbers in the model's own units, written over the values the set's
//! heart is built with. They are what a calibration of the heart's half of the loop changes
//! (`closed_loop_sensitivity` differentiates by the same paths).

use super::closed_loop_circulation::err;
use crate::error::Result;
use crate::model::node::Node;
use crate::model::path::nearest;
use serde_json::Value;

/// Writes the set's `heart_values` (if any) into the heart model `model` (native, as
/// `closed_loop_circulation::heart_model` builds it); a path that does not name one of its
/// numbers is a model error naming the path and the nearest key.
pub fn apply(model: &mut Value, p: &Value) -> Result<()> {
    let Some(values) = p.get("heart_values") else {
        return Ok(());
    };
    let values = values.as_object().ok_or_else(|| {
        err(format!(
            "heart_values must be a mapping of heart model paths to numbers, got {}",
            values.repr()
        ))
    })?;
    for (path, value) in values {
        let x = value.as_f64().filter(|x| x.is_finite()).ok_or_else(|| {
            err(format!(
                "heart_values: '{path}' must be a finite number, got {}",
                value.repr()
            ))
        })?;
        *number_at(model, path)? = Value::from(x);
    }
    Ok(())
}

/// The heart model's number at `path` (`vessels.<name>.<key>...` or
/// `boundary_conditions.<node>.<key>...`).
pub fn number_at<'m>(model: &'m mut Value, path: &str) -> Result<&'m mut Value> {
    let parts: Vec<&str> = path.split('.').collect();
    let name = model
        .get("name")
        .and_then(Value::as_str)
        .unwrap_or("closed-loop-heart")
        .to_owned();
    let (mut node, rest) = match parts.as_slice() {
        ["vessels", vessel, rest @ ..] if !rest.is_empty() => {
            (vessel_of(model, path, vessel, &name)?, rest)
        }
        ["boundary_conditions", bc, rest @ ..] if !rest.is_empty() => {
            let Some(conditions) = model
                .get_mut("boundary_conditions")
                .and_then(Value::as_object_mut)
            else {
                return Err(missing(path, "boundary condition", bc, &[], &name));
            };
            let keys: Vec<String> = conditions.keys().cloned().collect();
            match conditions.get_mut(*bc) {
                Some(c) => (c, rest),
                None => {
                    return Err(missing(path, "boundary condition", bc, &keys, &name));
                }
            }
        }
        _ => {
            return Err(err(format!(
                "heart parameter '{path}': expected vessels.<name>.<key> or \
                 boundary_conditions.<node>.<key>"
            )));
        }
    };
    for key in rest {
        let keys: Vec<String> = node
            .as_object()
            .map(|m| m.keys().cloned().collect())
            .unwrap_or_default();
        node = match node.get_mut(*key) {
            Some(n) => n,
            None => return Err(missing(path, "key", key, &keys, &name)),
        };
    }
    if !node.is_number() {
        return Err(err(format!(
            "heart parameter '{path}': not a number of model '{name}' (it holds {})",
            node.repr()
        )));
    }
    Ok(node)
}

/// The vessel `vessel` of the heart model, by name.
fn vessel_of<'m>(
    model: &'m mut Value,
    path: &str,
    vessel: &str,
    name: &str,
) -> Result<&'m mut Value> {
    let list = model
        .get_mut("vessels")
        .and_then(Value::as_array_mut)
        .ok_or_else(|| err(format!("heart model '{name}' has no vessels")))?;
    let names: Vec<String> = list
        .iter()
        .filter_map(|v| v.get("name")?.as_str().map(str::to_owned))
        .collect();
    match list
        .iter()
        .position(|v| v.get("name").and_then(Value::as_str) == Some(vessel))
    {
        Some(i) => Ok(&mut list[i]),
        None => Err(missing(path, "vessel", vessel, &names, name)),
    }
}

/// "heart parameter 'path': no <what> '<key>' in model '<name>' (nearest: ...; one of ...)".
fn missing(path: &str, what: &str, key: &str, keys: &[String], name: &str) -> crate::error::Error {
    let allowed: Vec<&str> = keys.iter().map(String::as_str).collect();
    let near = nearest(key, &allowed);
    let hint = if near.is_empty() {
        format!("one of {}", allowed.join(", "))
    } else {
        format!("nearest: {}", near.join(", "))
    };
    let hint = if allowed.is_empty() {
        "it has none".to_owned()
    } else {
        hint
    };
    err(format!(
        "heart parameter '{path}': no {what} '{key}' in model '{name}' ({hint})"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn model() -> Value {
        json!({"name": "closed-loop-heart", "boundary_conditions": {},
               "vessels": [{"name": "lv", "chamber": {"max_elastance": 3.3e8,
                                                       "activation": {"kind": "x"}}}]})
    }

    #[test]
    fn a_value_is_written_over_the_built_one() {
        let mut m = model();
        apply(
            &mut m,
            &json!({"heart_values": {"vessels.lv.chamber.max_elastance": 3.0e8}}),
        )
        .unwrap();
        assert_eq!(m["vessels"][0]["chamber"]["max_elastance"], 3.0e8);
    }

    #[test]
    fn a_path_naming_nothing_names_the_path_and_the_nearest_key() {
        let e = |path: &str| {
            let mut m = model();
            number_at(&mut m, path).unwrap_err().to_string()
        };
        let m = e("vessels.lv.chamber.max_elastanse");
        assert!(
            m.contains(
                "heart parameter 'vessels.lv.chamber.max_elastanse': no key \
                        'max_elastanse' in model 'closed-loop-heart' (nearest: max_elastance)"
            ),
            "{m}"
        );
        let m = e("vessels.vl.chamber.max_elastance");
        assert!(
            // two edits from 'lv' is beyond a 2-letter name's reach: the names are listed
            m.contains("no vessel 'vl'") && m.contains("(one of lv)"),
            "{m}"
        );
        let m = e("boundary_conditions.inlet.flow");
        assert!(
            m.contains("no boundary condition 'inlet'") && m.contains("it has none"),
            "{m}"
        );
        let m = e("vessels.lv.chamber.activation");
        assert!(m.contains("not a number"), "{m}");
        let mut m = model();
        let bad = apply(
            &mut m,
            &json!({"heart_values": {"vessels.lv.chamber.max_elastance": "x"}}),
        );
        assert!(
            bad.unwrap_err()
                .to_string()
                .contains("must be a finite number, got 'x'")
        );
    }
}
