//! Wall closures of a species (docs/physics.md §3): none, a prescribed flux (a number, one
//! value per segment, a table or a front-end callable sampled over the run), mass transfer,
//! permeability, and the Lévêque and Graetz boundary layers with their haemoglobin
//! facilitation (§3.4).

use super::*;

/// E_Hb of the wall layer between inlet PO2 `p_in` and wall PO2 `p_w` (docs/physics.md §3.4):
/// the secant factor for linearised binding, the nonlinear Lévêque layer's for Hill binding;
/// its canonical record (`closure::Facilitation`: the factor, α P_in and D_Hb) beside it.
fn facilitation<N: Node>(
    spec: &N,
    h: Option<Hill>,
    d: f64,
    p_in: f64,
    p_w: f64,
    el: &str,
) -> Result<(f64, Value)> {
    let Some(h) = h else {
        return Err(err(
            el,
            "hb_facilitation needs hemoglobin: hill or linearized",
        ));
    };
    let fel = format!("{el} hb_facilitation");
    let d_hb = if spec.is_map() {
        check(spec, &["d_hb"], &fel)?;
        num_or(spec, "d_hb", D_HB_DEFAULT, el, "d_hb", Bound::NonNegative)?
    } else {
        D_HB_DEFAULT
    };
    let layer = Layer {
        alpha: h.alpha,
        d,
        d_hb,
        capacity: h.capacity,
        p50: h.p50,
        n: h.n,
    };
    let factor = if h.linearized {
        facilitation::secant_factor(p_in, p_w, &layer)
    } else {
        facilitation::hill_factor(p_in, p_w, &layer)
    };
    let record = json!({"factor": factor, "inlet_concentration": h.alpha * p_in, "d_hb": d_hb});
    Ok((factor, record))
}

/// One row of a prescribed wall flux: a number, or one value per segment.
fn flux_row<N: Node>(v: &N, el: &str) -> Result<Vec<f64>> {
    if matches!(v.kind(), Kind::Int | Kind::Float | Kind::Str) {
        return Ok(vec![num(Some(v), el, "flux", Bound::Any)?]);
    }
    let vals = v
        .items()
        .filter(|_| v.kind() != Kind::Bool)
        .ok_or_else(|| {
            err(
                el,
                format!(
                    "'flux' must be a number or a list of numbers, got {}",
                    v.repr()
                ),
            )
        })?;
    if vals.is_empty() {
        return Err(err(el, "'flux' needs at least one value"));
    }
    vals.iter()
        .map(|x| num(Some(x), el, "flux", Bound::Any))
        .collect()
}

fn same_lengths(rows: &[Vec<f64>]) -> bool {
    rows.windows(2).all(|w| w[0].len() == w[1].len())
}

/// Canonical prescribed wall flux (mol m⁻² s⁻¹): a number, one value per segment, a
/// `{time, flux}` table (rows of one value or one per segment; linear in time, repeating with
/// its own length) or a front-end callable f(t) sampled every period/200 over the whole run.
fn flux<N: Node>(spec: &N, el: &str, ctx: &Context) -> Result<Value> {
    if spec.callable() {
        let p = ctx.period.unwrap_or(1.0);
        let end = ctx.duration.filter(|d| *d != 0.0).unwrap_or(p).max(p) + p;
        let n = (end / p * FLUX_SAMPLES_PER_PERIOD).ceil() as usize + 1;
        let times: Vec<f64> = (0..n).map(|i| end * i as f64 / (n - 1) as f64).collect();
        let rows = times
            .iter()
            .map(|&t| {
                let v = spec.call(t).map_err(|e| {
                    err(
                        el,
                        format!("the flux callable failed at t = {}: {e}", py_repr(t)),
                    )
                })?;
                flux_row(&v, el)
            })
            .collect::<Result<Vec<_>>>()?;
        if !same_lengths(&rows) {
            return Err(err(
                el,
                "the flux callable must return the same number of values at every time",
            ));
        }
        return Ok(json!({"time": times, "values": rows}));
    }
    if spec.is_map() {
        check(spec, &["time", "flux"], &format!("{el} flux"))?;
        let (Some(time), Some(fl)) = (spec.get("time"), spec.get("flux")) else {
            return Err(err(el, "a flux table needs 'time' and 'flux'"));
        };
        let t = items(&time, el, "time")?
            .iter()
            .map(|x| num(Some(x), el, "time", Bound::Any))
            .collect::<Result<Vec<_>>>()?;
        let rows = items(&fl, el, "flux")?
            .iter()
            .map(|r| flux_row(r, el))
            .collect::<Result<Vec<_>>>()?;
        if t.len() != rows.len() || t.len() < 2 {
            return Err(err(el, "flux 'time' and 'flux' need the same length >= 2"));
        }
        if !strictly_increasing(&t) {
            return Err(err(el, "flux 'time' must be strictly increasing"));
        }
        if !same_lengths(&rows) {
            return Err(err(
                el,
                "every row of a flux table needs the same number of values",
            ));
        }
        return Ok(json!({"time": t, "values": rows}));
    }
    let row = flux_row(spec, el)?;
    Ok(if spec.kind() != Kind::List && row.len() == 1 {
        json!(row[0])
    } else {
        json!(row)
    })
}

/// How a wall closure reads its wall value: oxygen's PO2 (mmHg, as concentration α P) or a
/// species' concentration.
pub(super) enum WallValue<'a> {
    Oxygen { alpha: f64, el: &'a str },
    Species { el: &'a str },
}

impl WallValue<'_> {
    fn read<N: Node>(&self, spec: &N) -> Result<f64> {
        match *self {
            WallValue::Oxygen { alpha, el } => {
                if let Some(p) = spec.get("po2") {
                    Ok(alpha * num(Some(&p), el, "po2", Bound::NonNegative)?)
                } else if let Some(c) = spec.get("concentration") {
                    num(Some(&c), el, "concentration", Bound::NonNegative)
                } else {
                    Err(err(el, "wall needs 'po2' (mmHg)"))
                }
            }
            WallValue::Species { el } => num_or(
                spec,
                "concentration",
                0.0,
                el,
                "concentration",
                Bound::NonNegative,
            ),
        }
    }
}

/// What a wall closure of one species is read with.
pub(super) struct WallContext<'a> {
    pub(super) value: WallValue<'a>,
    pub(super) hill: Option<Hill>,
    pub(super) diffusivity: f64,
    /// The inlet PO2 of the facilitation secant (None: not constant).
    pub(super) p_in: Option<f64>,
}

/// `hb_facilitation` switched off: None or a false value (`false`, `0`).
fn off<N: Node>(v: &N) -> bool {
    match v.kind() {
        Kind::Null => true,
        Kind::Bool => !v.truthy(),
        Kind::Int | Kind::Float => v.number() == Some(0.0),
        _ => false,
    }
}

/// Canonical wall closure of `spec` (None, a model name or a mapping with `model`).
pub(super) fn wall<N: Node>(
    spec: Option<&N>,
    el: &str,
    w: &WallContext,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<Value> {
    let Some(spec) = spec.filter(|s| s.kind() != Kind::Null) else {
        return Ok(json!({"model": "none"}));
    };
    if let Some(name) = spec.text() {
        if name == "none" {
            return Ok(json!({"model": "none"}));
        }
        return wall_of(&json!({ "model": name }), el, w, ctx, warnings);
    }
    wall_of(spec, el, w, ctx, warnings)
}

pub(super) fn wall_of<N: Node>(
    spec: &N,
    el: &str,
    w: &WallContext,
    ctx: &Context,
    warnings: &mut Vec<String>,
) -> Result<Value> {
    let Some(model) = spec
        .get("model")
        .filter(|_| spec.is_map())
        .map(|m| m.show())
    else {
        return Err(err(
            el,
            "wall needs a 'model' (none, flux, mass-transfer, leveque, graetz, permeability)",
        ));
    };
    let Some((_, keys)) = WALL_KEYS.iter().find(|(m, _)| *m == model) else {
        let names: Vec<&str> = WALL_KEYS.iter().map(|(m, _)| *m).collect();
        return Err(err(
            el,
            format!(
                "unknown wall model '{model}' (expected {})",
                names.join(", ")
            ),
        ));
    };
    check(spec, keys, &format!("{el} wall"))?;
    let mut out = Map::new();
    out.insert("model".into(), json!(model));
    match model.as_str() {
        "none" => return Ok(Value::Object(out)),
        "flux" => {
            let Some(f) = spec.get("flux") else {
                return Err(err(el, "the flux wall model needs 'flux' (mol m^-2 s^-1)"));
            };
            out.insert("flux".into(), flux(&f, el, ctx)?);
            return Ok(Value::Object(out));
        }
        _ => {}
    }
    let cw = w.value.read(spec)?;
    if model == "permeability" {
        let p = num(
            spec.get("permeability").as_ref(),
            el,
            "permeability",
            Bound::NonNegative,
        )?;
        out.insert("permeability".into(), json!(p));
        out.insert("tissue_concentration".into(), json!(cw));
        return Ok(Value::Object(out));
    }
    out.insert("wall_concentration".into(), json!(cw));
    if let Some(p) = spec.get("permeability") {
        out.insert(
            "permeability".into(),
            json!(num(Some(&p), el, "permeability", Bound::Positive)?),
        );
    }
    if model == "mass-transfer" {
        let k = num(spec.get("k").as_ref(), el, "k", Bound::NonNegative)?;
        out.insert("k".into(), json!(k));
        return Ok(Value::Object(out));
    }
    let (enh, record) = enhancement(spec, &model, cw, el, w, warnings)?;
    out.insert("enhancement".into(), json!(enh));
    if let Some(r) = record {
        out.insert("facilitation".into(), r);
    }
    layer_options(spec, &model, el, ctx, &mut out)?;
    Ok(Value::Object(out))
}

/// The enhancement of a Lévêque or Graetz wall: the given factor times the haemoglobin
/// facilitation E_Hb (on by default with haemoglobin, docs/physics.md §3.4; switched off, a
/// warning) at wall concentration `cw`, and the facilitation's record when it is on.
fn enhancement<N: Node>(
    spec: &N,
    model: &str,
    cw: f64,
    el: &str,
    w: &WallContext,
    warnings: &mut Vec<String>,
) -> Result<(f64, Option<Value>)> {
    let enh = num_or(
        spec,
        "enhancement",
        1.0,
        el,
        "enhancement",
        Bound::NonNegative,
    )?;
    // haemoglobin: facilitated boundary-layer transport by default (docs/physics.md §3.4)
    let fac = spec
        .get("hb_facilitation")
        .filter(|f| f.kind() != Kind::Null);
    let explicit_false = fac
        .as_ref()
        .is_some_and(|f| f.kind() == Kind::Bool && !f.truthy());
    if explicit_false && w.hill.is_some() {
        warnings.push(format!(
            "{el}: hb_facilitation is off with haemoglobin: the {model} wall flux comes from \
             the dissolved O2 only and under-predicts the uptake 2.6-3.1x (docs/physics.md §3.4)"
        ));
    }
    let on = match &fac {
        None => w.hill.is_some().then_some(None),
        Some(f) if off(f) => None,
        Some(f) => Some(Some(f)),
    };
    if let Some(f) = on {
        let Some(p_in) = w.p_in else {
            return Err(err(el, "hb_facilitation needs a constant inlet PO2"));
        };
        let p_w = w.hill.map_or(0.0, |h| cw / h.alpha);
        let empty = json!({});
        let (factor, record) = match f {
            Some(f) => facilitation(f, w.hill, w.diffusivity, p_in, p_w, el)?,
            None => facilitation(&empty, w.hill, w.diffusivity, p_in, p_w, el)?,
        };
        return Ok((enh * factor, Some(record)));
    }
    Ok((enh, None))
}

/// A Graetz wall's mean flow and the blood's kinematic viscosity; a Lévêque wall's shear.
fn layer_options<N: Node>(
    spec: &N,
    model: &str,
    el: &str,
    ctx: &Context,
    out: &mut Map<String, Value>,
) -> Result<()> {
    if model == "graetz" {
        if let Some(flow) = spec.get("flow") {
            if !flow
                .text()
                .is_some_and(|f| MEAN_FLOWS.contains(&f.as_str()))
            {
                return Err(err(
                    el,
                    format!(
                        "flow must be one of {}, got {}",
                        py_tuple(MEAN_FLOWS),
                        flow.repr()
                    ),
                ));
            }
            out.insert("flow".into(), to_value(&flow));
        }
        // the inlet renewal's Womersley numbers (docs/physics.md §3.6)
        if let Some(nu) = ctx.kinematic_viscosity {
            out.insert("kinematic_viscosity".into(), json!(nu));
        }
    }
    if model == "leveque" {
        let shear = spec.get("shear");
        let ok = shear.as_ref().is_none_or(|s| {
            s.text()
                .is_some_and(|t| ["cycle-mean", "instantaneous", "relaxed"].contains(&t.as_str()))
        });
        if !ok {
            let got = shear.map_or_else(String::new, |s| s.repr());
            return Err(err(
                el,
                format!("shear must be 'cycle-mean', 'instantaneous' or 'relaxed', got {got}"),
            ));
        }
        out.insert(
            "shear".into(),
            shear.map_or_else(|| json!("cycle-mean"), |s| to_value(&s)),
        );
    }
    Ok(())
}
