//! A `species:` entry other than oxygen, all SI (concentrations in mol/m³): diffusivity,
//! first-order decay, binding (none, linear partition, or saturable: the Hill law with α = 1),
//! inlet(s), backflow, initial value and wall closures (docs/physics.md §5).

use super::{
    Bound, Context, SPECIES_KEYS, WallContext, WallValue, check, num, num_or, wall, wave, waves,
};
use crate::error::Result;
use crate::model::native::err;
use crate::model::node::Node;
use serde_json::{Map, Value, json};

/// The canonical description of species entry `i`.
pub(super) fn species<N: Node>(
    sp: &N,
    i: usize,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<Value> {
    let el = match sp.get("name").filter(|_| sp.is_map()) {
        Some(n) => format!("species '{}'", n.show()),
        None if sp.is_map() => format!("species '#{i}'"),
        None => format!("species #{i}"),
    };
    let el = el.as_str();
    check(sp, SPECIES_KEYS, el)?;
    let Some(name) = sp.get("name") else {
        return Err(err(el, "needs a 'name'"));
    };
    let d = num_or(
        sp,
        "diffusivity",
        0.0,
        el,
        "diffusivity",
        Bound::NonNegative,
    )?;
    let binding = binding(sp.get("binding"), el)?;
    let Some(inlet) = sp.get("inlet") else {
        return Err(err(el, "needs 'inlet' (e.g. {concentration: 1.0})"));
    };
    let w = WallContext {
        value: WallValue::Species { el },
        hill: None,
        diffusivity: d,
        p_in: None,
    };
    let mut out = Map::new();
    out.insert("name".into(), json!(name.show()));
    out.insert("diffusivity".into(), json!(d));
    let decay = num_or(sp, "decay", 0.0, el, "decay", Bound::NonNegative)?;
    out.insert("decay".into(), json!(decay));
    out.insert("binding".into(), binding);
    let key = "concentration";
    out.insert(
        "inlet".into(),
        wave(&inlet, key, 1.0, &format!("{el} inlet"), ctx)?,
    );
    out.insert(
        "wall".into(),
        wall(sp.get("wall").as_ref(), el, &w, ctx, warnings)?,
    );
    if let Some(inlets) = sp.get("inlets") {
        out.insert(
            "inlets".into(),
            waves(&inlets, key, 1.0, el, "inlet", ctx, el)?,
        );
    }
    if let Some(back) = sp.get("backflow") {
        out.insert(
            "backflow".into(),
            waves(&back, key, 1.0, el, "backflow", ctx, el)?,
        );
    }
    if let Some(ini) = sp.get("initial") {
        out.insert(
            "initial".into(),
            json!(num(Some(&ini), el, "initial", Bound::NonNegative)?),
        );
    }
    if let Some(pv) = sp.get("per_vessel") {
        out.insert("per_vessel".into(), per_vessel(&pv, el, &w, ctx, warnings)?);
    }
    Ok(Value::Object(out))
}

/// The walls of `per_vessel: {name: {wall: ..}}`.
fn per_vessel<N: Node>(
    pv: &N,
    el: &str,
    w: &WallContext,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<Value> {
    if !pv.is_map() {
        return Err(err(
            el,
            format!("'per_vessel' must be a mapping, got {}", pv.repr()),
        ));
    }
    let mut walls = Map::new();
    for (n, o) in pv.entries() {
        let vel = format!("{el} per_vessel '{n}'");
        if !o.is_map() {
            return Err(err(&vel, format!("expected a mapping, got {}", o.repr())));
        }
        walls.insert(n, wall(o.get("wall").as_ref(), &vel, w, ctx, warnings)?);
    }
    Ok(Value::Object(walls))
}

/// `binding`: none, `{kind: linear, partition}` or `{kind: saturable, b_max, k_d, n}`
/// (C_t = c + B_max cⁿ/(cⁿ + K_dⁿ): the Hill law with α = 1).
fn binding<N: Node>(b: Option<N>, el: &str) -> Result<Value> {
    let Some(b) = b.filter(|b| !b.is_null_or("none")) else {
        return Ok(json!({"kind": "none"}));
    };
    check(
        &b,
        &["kind", "partition", "b_max", "k_d", "n"],
        &format!("{el} binding"),
    )?;
    let kind = b.get("kind");
    match kind.as_ref().and_then(Node::text).as_deref() {
        Some("linear") => {
            let p = num(
                b.get("partition").as_ref(),
                el,
                "partition",
                Bound::NonNegative,
            )?;
            Ok(json!({"kind": "linear", "partition": p}))
        }
        Some("saturable") => {
            let p50 = num(b.get("k_d").as_ref(), el, "k_d", Bound::Positive)?;
            let n = num_or(&b, "n", 1.0, el, "n", Bound::Positive)?;
            let capacity = num(b.get("b_max").as_ref(), el, "b_max", Bound::Positive)?;
            Ok(
                json!({"kind": "hill", "solubility": 1.0, "p50": p50, "n": n,
                      "capacity": capacity}),
            )
        }
        _ => Err(err(
            el,
            format!(
                "binding kind must be none, linear or saturable, got {}",
                kind.map_or_else(|| "None".to_owned(), |k| k.repr())
            ),
        )),
    }
}

trait NoneLike {
    fn is_null_or(&self, text: &str) -> bool;
}

impl<N: Node> NoneLike for N {
    /// Null, or the text `text`.
    fn is_null_or(&self, text: &str) -> bool {
        self.kind() == crate::model::node::Kind::Null || self.text().as_deref() == Some(text)
    }
}
