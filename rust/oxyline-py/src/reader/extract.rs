//! The bulk of a large model handed over as Python objects instead of JSON text: the canonical
//! vessel dicts and the plain outlet conditions (resistance, RCR with a constant pressure), read
//! key by key into the core's spec types. At a million segments this replaces writing and
//! parsing ~100 MB of text (`float.__repr__` of every value, then the JSON parse). Any
//! unexpected key or value is a model error naming the vessel or condition, as the JSON path
//! would give.

use oxyline_core::Error;
use oxyline_core::model::{
    Arrangement, BoundarySpec, GeometrySpec, LumpedSpec, StenosisForm, VesselSpec,
};
use oxyline_core::waveform::WaveformSpec;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

type Res<T> = Result<T, Error>;

fn key<'a>(k: &'a Bound<'_, PyAny>, element: &dyn Fn() -> String) -> Res<&'a str> {
    k.cast::<PyString>()
        .ok()
        .and_then(|s| s.to_str().ok())
        .ok_or_else(|| Error::model(element(), format!("key {k} is not a string")))
}

fn number(v: &Bound<'_, PyAny>, element: &dyn Fn() -> String, what: &str) -> Res<f64> {
    v.extract::<f64>()
        .map_err(|_| Error::model(element(), format!("'{what}' must be a number, got {v}")))
}

fn text(v: &Bound<'_, PyAny>, element: &dyn Fn() -> String, what: &str) -> Res<String> {
    v.extract::<String>()
        .map_err(|_| Error::model(element(), format!("'{what}' must be a string, got {v}")))
}

fn dict<'a, 'py>(
    v: &'a Bound<'py, PyAny>,
    element: &dyn Fn() -> String,
    what: &str,
) -> Res<&'a Bound<'py, PyDict>> {
    v.cast::<PyDict>()
        .map_err(|_| Error::model(element(), format!("'{what}' must be a mapping, got {v}")))
}

fn unknown(element: &dyn Fn() -> String, k: &str) -> Error {
    Error::model(element(), format!("unknown field `{k}`"))
}

fn missing(element: &dyn Fn() -> String, k: &str) -> Error {
    Error::model(element(), format!("missing field `{k}`"))
}

fn geometry(d: &Bound<'_, PyDict>, element: &dyn Fn() -> String) -> Res<GeometrySpec> {
    let (mut length, mut r_in, mut r_out) = (None, None, None);
    let mut g = GeometrySpec {
        length: 0.0,
        radius_in: 0.0,
        radius_out: 0.0,
        wall_thickness: None,
        youngs_modulus: None,
        poisson_ratio: 0.5,
        wall_viscosity: 0.0,
    };
    for (k, v) in d.iter() {
        let k = key(&k, element)?;
        let x = number(&v, element, k)?;
        match k {
            "length" => length = Some(x),
            "radius_in" => r_in = Some(x),
            "radius_out" => r_out = Some(x),
            "wall_thickness" => g.wall_thickness = Some(x),
            "youngs_modulus" => g.youngs_modulus = Some(x),
            "poisson_ratio" => g.poisson_ratio = x,
            "wall_viscosity" => g.wall_viscosity = x,
            _ => return Err(unknown(element, k)),
        }
    }
    g.length = length.ok_or_else(|| missing(element, "length"))?;
    g.radius_in = r_in.ok_or_else(|| missing(element, "radius_in"))?;
    g.radius_out = r_out.ok_or_else(|| missing(element, "radius_out"))?;
    Ok(g)
}

fn lumped(d: &Bound<'_, PyDict>, element: &dyn Fn() -> String) -> Res<LumpedSpec> {
    let mut resistance = None;
    let mut l = LumpedSpec {
        resistance: 0.0,
        inductance: 0.0,
        capacitance: 0.0,
        stenosis_coefficient: 0.0,
        stenosis_form: StenosisForm::default(),
    };
    for (k, v) in d.iter() {
        let k = key(&k, element)?;
        if k == "stenosis_form" {
            l.stenosis_form = stenosis_form(&v, element)?;
            continue;
        }
        let x = number(&v, element, k)?;
        match k {
            "resistance" => resistance = Some(x),
            "inductance" => l.inductance = x,
            "capacitance" => l.capacitance = x,
            "stenosis_coefficient" => l.stenosis_coefficient = x,
            _ => return Err(unknown(element, k)),
        }
    }
    l.resistance = resistance.ok_or_else(|| missing(element, "resistance"))?;
    Ok(l)
}

fn stenosis_form(v: &Bound<'_, PyAny>, element: &dyn Fn() -> String) -> Res<StenosisForm> {
    match text(v, element, "stenosis_form")?.as_str() {
        "branch" => Ok(StenosisForm::Branch),
        "svzerod" => Ok(StenosisForm::SvZeroD),
        other => Err(Error::model(
            element(),
            format!("unknown stenosis_form `{other}` (expected branch or svzerod)"),
        )),
    }
}

fn arrangement(v: &Bound<'_, PyAny>, element: &dyn Fn() -> String) -> Res<Arrangement> {
    match text(v, element, "arrangement")?.as_str() {
        "inverted-L" => Ok(Arrangement::InvertedL),
        "L" => Ok(Arrangement::L),
        "pi" => Ok(Arrangement::Pi),
        "RCL" => Ok(Arrangement::Rcl),
        other => Err(Error::model(
            element(),
            format!("unknown arrangement `{other}` (expected inverted-L, L, pi or RCL)"),
        )),
    }
}

/// Vessel `i` from its canonical dict (the fields of `VesselSpec`).
pub fn vessel(i: usize, item: &Bound<'_, PyAny>) -> Res<VesselSpec> {
    let name_of = || match item
        .cast::<PyDict>()
        .ok()
        .and_then(|d| d.get_item("name").ok().flatten())
    {
        Some(n) => format!("vessel '{n}'"),
        None => format!("vessel #{i}"),
    };
    let element: &dyn Fn() -> String = &name_of;
    let d = dict(item, element, "vessel")?;
    let (mut name, mut from, mut to) = (None, None, None);
    let mut v = VesselSpec::blank();
    for (k, val) in d.iter() {
        let k = key(&k, element)?;
        match k {
            "name" => name = Some(text(&val, element, k)?),
            "from" => from = Some(text(&val, element, k)?),
            "to" => to = Some(text(&val, element, k)?),
            "segments" => {
                v.segments = Some(val.extract::<usize>().map_err(|_| {
                    Error::model(
                        element(),
                        format!("'segments' must be an integer >= 0, got {val}"),
                    )
                })?)
            }
            "segments_auto" => v.segments_auto = val.extract::<bool>().unwrap_or(false),
            "geometry" => v.geometry = Some(geometry(dict(&val, element, k)?, element)?),
            "lumped" => v.lumped = Some(lumped(dict(&val, element, k)?, element)?),
            "arrangement" => v.arrangement = Some(arrangement(&val, element)?),
            "wall_friction" => v.wall_friction = Some(via_json(&val, element, k)?),
            // heart elements are few: read through their JSON form
            "valve" => v.valve = Some(via_json(&val, element, k)?),
            "heart_pulmonary" => v.heart_pulmonary = Some(via_json(&val, element, k)?),
            "coronary_bed" => v.coronary_bed = Some(via_json(&val, element, k)?),
            "chamber" => v.chamber = Some(via_json(&val, element, k)?),
            "through_rc" => v.through_rc = Some(via_json(&val, element, k)?),
            "chamber_sphere" => v.chamber_sphere = Some(via_json(&val, element, k)?),
            "initial" => v.initial = Some(via_json(&val, element, k)?),
            "initial_rate" => v.initial_rate = Some(via_json(&val, element, k)?),
            "output" => {
                v.output = val.extract::<bool>().map_err(|_| {
                    Error::model(element(), format!("'output' must be a bool, got {val}"))
                })?
            }
            _ => return Err(unknown(element, k)),
        }
    }
    v.name = name.ok_or_else(|| missing(element, "name"))?;
    v.from = from.ok_or_else(|| missing(element, "from"))?;
    v.to = to.ok_or_else(|| missing(element, "to"))?;
    Ok(v)
}

/// A small nested spec read through its JSON text (`json.dumps`, then the core's parser).
fn via_json<T: oxyline_core::model::DeserializeOwned>(
    v: &Bound<'_, PyAny>,
    element: &dyn Fn() -> String,
    what: &str,
) -> Res<T> {
    let bad = |e: String| Error::model(element(), format!("'{what}': {e}"));
    let text: String = v
        .py()
        .import("json")
        .and_then(|j| j.call_method1("dumps", (v,)))
        .and_then(|s| s.extract())
        .map_err(|e| bad(e.to_string()))?;
    oxyline_core::model::from_json(&text).map_err(|e| bad(e.to_string()))
}

/// Every vessel of the canonical `vessels` list.
pub fn vessels(list: &Bound<'_, PyList>) -> Res<Vec<VesselSpec>> {
    let mut out = Vec::with_capacity(list.len());
    for (i, item) in list.iter().enumerate() {
        out.push(vessel(i, &item)?);
    }
    Ok(out)
}

/// A constant distal pressure `{"kind": "constant", "value": p}`.
fn constant_pressure(d: &Bound<'_, PyDict>, element: &dyn Fn() -> String) -> Res<WaveformSpec> {
    let mut value = None;
    for (k, v) in d.iter() {
        match key(&k, element)? {
            "kind" => {
                if text(&v, element, "kind")? != "constant" {
                    return Err(Error::model(
                        element(),
                        "only a constant pressure can be handed over as an outlet",
                    ));
                }
            }
            "value" => value = Some(number(&v, element, "value")?),
            k => return Err(unknown(element, k)),
        }
    }
    Ok(WaveformSpec::Constant {
        value: value.ok_or_else(|| missing(element, "value"))?,
    })
}

/// A resistance or RCR condition with an optional constant pressure, from its canonical dict.
pub fn outlet(node: &str, item: &Bound<'_, PyAny>) -> Res<BoundarySpec> {
    let name_of = || format!("boundary condition '{node}'");
    let element: &dyn Fn() -> String = &name_of;
    let d = dict(item, element, "boundary condition")?;
    let (mut kind, mut r, mut rp, mut c, mut rd, mut pressure) =
        (None, None, None, None, None, None);
    for (k, v) in d.iter() {
        let k = key(&k, element)?;
        match k {
            "type" => kind = Some(text(&v, element, k)?),
            "resistance" => r = Some(number(&v, element, k)?),
            "proximal_resistance" => rp = Some(number(&v, element, k)?),
            "capacitance" => c = Some(number(&v, element, k)?),
            "distal_resistance" => rd = Some(number(&v, element, k)?),
            "pressure" => pressure = Some(constant_pressure(dict(&v, element, k)?, element)?),
            _ => return Err(unknown(element, k)),
        }
    }
    match kind.as_deref() {
        Some("resistance") if rp.is_none() && c.is_none() && rd.is_none() => {
            Ok(BoundarySpec::Resistance {
                resistance: r.ok_or_else(|| missing(element, "resistance"))?,
                pressure,
            })
        }
        Some("rcr") if r.is_none() => Ok(BoundarySpec::Rcr {
            proximal_resistance: rp.ok_or_else(|| missing(element, "proximal_resistance"))?,
            capacitance: c.ok_or_else(|| missing(element, "capacitance"))?,
            distal_resistance: rd.ok_or_else(|| missing(element, "distal_resistance"))?,
            pressure,
        }),
        _ => Err(Error::model(
            element(),
            "an outlet handed over as a mapping must be a resistance or rcr condition with its own fields",
        )),
    }
}
