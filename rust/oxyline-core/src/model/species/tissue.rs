//! `wall: {model: tissue}` of the oxygen section: a consuming wall layer behind a luminal
//! closure (docs/physics.md §3.7). SI except PO2 (mmHg): thickness m, diffusivity m²/s,
//! solubility mol m⁻³ mmHg⁻¹ (default: the blood's), consumption `{vmax, km}`
//! (Michaelis–Menten) or `{rate}` (zero order), outer `{po2}` or no-flux, hypoxic_po2 mmHg.
//! The core works in wall concentrations u = α_t P and the partition φ = α_t/α.

use super::{
    Bound, Context, HYPOXIC_PO2, Hill, TISSUE_BOUNDARY_LAYERS, TISSUE_KEYS, TISSUE_RADIAL_CELLS,
    WallContext, WallValue, check, num, num_or, to_value, wall_of,
};
use crate::error::Result;
use crate::model::native::err;
use crate::model::node::{Kind, Node};
use serde_json::{Value, json};

/// The oxygen section's values a tissue wall is read with.
pub(super) struct Oxygen {
    pub alpha: f64,
    pub hill: Option<Hill>,
    pub d: f64,
    /// The constant inlet PO2 (None: a tabulated inlet).
    pub p_in: Option<f64>,
}

/// (canonical luminal closure, canonical tissue layer) of a tissue wall `spec`.
pub(super) fn read<N: Node>(
    spec: &N,
    element: &str,
    o: &Oxygen,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<(Value, Value)> {
    let el = format!("{element} wall (tissue)");
    if spec.text().is_some() {
        // `wall: tissue`: a tissue wall with every key missing
        return layer(&json!({"model": "tissue"}), &el, o, ctx, warnings);
    }
    layer(spec, &el, o, ctx, warnings)
}

fn layer<N: Node>(
    t: &N,
    el: &str,
    o: &Oxygen,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<(Value, Value)> {
    check(t, TISSUE_KEYS, el)?;
    for key in ["thickness", "diffusivity", "consumption"] {
        if !t.has(key) {
            return Err(err(el, format!("needs '{key}'")));
        }
    }
    let alpha_t = num_or(t, "solubility", o.alpha, el, "solubility", Bound::Positive)?;
    let consumption = consumption(&t.get("consumption").expect("checked"), alpha_t, el)?;
    let outer = outer(t.get("outer"), alpha_t, el)?;
    let cells = radial_cells(t.get("radial_cells"), el)?;
    let thickness = num(
        t.get("thickness").as_ref(),
        el,
        "thickness",
        Bound::Positive,
    )?;
    let diffusivity = num(
        t.get("diffusivity").as_ref(),
        el,
        "diffusivity",
        Bound::Positive,
    )?;
    let hypoxic = num_or(
        t,
        "hypoxic_po2",
        HYPOXIC_PO2,
        el,
        "hypoxic_po2",
        Bound::NonNegative,
    )?;
    let tissue = json!({
        "thickness": thickness, "diffusivity": diffusivity, "partition": alpha_t / o.alpha,
        "consumption": consumption, "outer": outer, "radial_cells": cells,
        "hypoxic_threshold": alpha_t * hypoxic,
    });
    let lumen = boundary_layer(t.get("boundary_layer"), el, o, ctx, warnings)?;
    Ok((lumen, tissue))
}

fn consumption<N: Node>(cons: &N, alpha_t: f64, el: &str) -> Result<Value> {
    let cel = format!("{el} consumption");
    if cons.is_map() && cons.has("rate") {
        check(cons, &["rate"], &cel)?;
        let rate = num(cons.get("rate").as_ref(), el, "rate", Bound::NonNegative)?;
        return Ok(json!({"kind": "zero-order", "rate": rate}));
    }
    if cons.is_map() && cons.has("vmax") {
        check(cons, &["vmax", "km"], &cel)?;
        let vmax = num(cons.get("vmax").as_ref(), el, "vmax", Bound::NonNegative)?;
        let km = num(cons.get("km").as_ref(), el, "km (mmHg)", Bound::NonNegative)?;
        return Ok(json!({"kind": "michaelis-menten", "vmax": vmax, "km": alpha_t * km}));
    }
    Err(err(
        el,
        format!(
            "consumption must be {{vmax, km}} (Michaelis–Menten) or {{rate}} (zero order), got {}",
            cons.repr()
        ),
    ))
}

fn outer<N: Node>(outer: Option<N>, alpha_t: f64, el: &str) -> Result<Value> {
    let Some(outer) = outer else {
        return Ok(json!({"kind": "no-flux"}));
    };
    if outer.text().as_deref() == Some("no-flux") {
        return Ok(json!({"kind": "no-flux"}));
    }
    let keys: Vec<String> = outer.entries().into_iter().map(|(k, _)| k).collect();
    if outer.is_map() && keys == ["po2"] {
        let p = num(
            outer.get("po2").as_ref(),
            el,
            "outer po2",
            Bound::NonNegative,
        )?;
        return Ok(json!({"kind": "concentration", "value": alpha_t * p}));
    }
    Err(err(
        el,
        format!(
            "outer must be 'no-flux' or {{po2: mmHg}}, got {}",
            outer.repr()
        ),
    ))
}

/// `radial_cells`: a whole number between 1 and 1000 (an int or a whole float).
fn radial_cells<N: Node>(v: Option<N>, el: &str) -> Result<i64> {
    let Some(v) = v else {
        return Ok(TISSUE_RADIAL_CELLS);
    };
    let x = match v.kind() {
        Kind::Int | Kind::Float => v.number().filter(|x| x.fract() == 0.0),
        _ => None,
    };
    match x {
        Some(x) if (1.0..=1000.0).contains(&x) => Ok(x as i64),
        _ => Err(err(
            el,
            format!(
                "'radial_cells' must be an integer between 1 and 1000, got {}",
                v.repr()
            ),
        )),
    }
}

/// The luminal closure in front of the layer, read as a wall closure at wall PO2 0 (the
/// layer's innermost PO2 is the wall value).
fn boundary_layer<N: Node>(
    bl: Option<N>,
    el: &str,
    o: &Oxygen,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<Value> {
    let mut spec = match &bl {
        None => json!({"model": "leveque"}),
        Some(b) if b.kind() == Kind::Str => json!({ "model": b.text() }),
        Some(b) => to_value(b),
    };
    let shown = match &bl {
        Some(b) if b.kind() != Kind::Str => b.repr(),
        _ => spec.repr(),
    };
    let model = spec.get("model").and_then(Value::as_str).unwrap_or("");
    if !spec.is_object() || !TISSUE_BOUNDARY_LAYERS.contains(&model) {
        return Err(err(
            el,
            format!(
                "boundary_layer must be one of {}, got {shown}",
                TISSUE_BOUNDARY_LAYERS.join(", ")
            ),
        ));
    }
    for key in ["po2", "concentration", "hb_facilitation"] {
        if spec.get(key).is_some() {
            return Err(err(
                el,
                format!(
                    "boundary_layer takes no '{key}' (the wall's innermost PO2 is the wall \
                     value; give the enhancement directly)"
                ),
            ));
        }
    }
    if spec
        .get("shear")
        .is_some_and(|s| s.as_str() != Some("cycle-mean"))
    {
        return Err(err(
            el,
            "boundary_layer shear must be cycle-mean with a tissue wall",
        ));
    }
    spec["po2"] = json!(0.0);
    let w = WallContext {
        value: WallValue::Oxygen { alpha: o.alpha, el },
        hill: o.hill,
        diffusivity: o.d,
        p_in: o.p_in,
    };
    let quiet = Context {
        period: None,
        duration: None,
        ..*ctx
    };
    wall_of(&spec, el, &w, &quiet, warnings)
}
