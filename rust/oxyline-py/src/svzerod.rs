//! The drop-in's run settings (`Network.simulate(svzerod=...)`): svZeroDSolver's derived
//! columns, rates and cycle-to-cycle stop rule (`oxyline_core::run::SvZeroDRules`), read
//! from a dict of plain values.

use crate::errors::ModelError;
use oxyline_core::Probes;
use oxyline_core::run::{CycleMeanStop, Derived, SvZeroDRules};
use pyo3::prelude::*;
use pyo3::types::PyDict;

/// The rules of `d`: `derived` (a list of `("valve_status", valve name)` or
/// `("from_start", unknown, scale)`), `rates` (bool) and `cycle_mean_stop` (a dict of `caps`,
/// unknown indices, `tolerance` and `max_extra`).
pub(crate) fn rules(d: &Bound<'_, PyDict>, probes: &Probes) -> PyResult<SvZeroDRules> {
    let mut out = SvZeroDRules {
        drop_in: true,
        ..Default::default()
    };
    for (k, v) in d.iter() {
        let key: String = k.extract()?;
        match key.as_str() {
            "rates" => out.rates = v.extract()?,
            "derived" => {
                for item in v.try_iter()? {
                    out.derived.push(derived(&item?, probes)?);
                }
            }
            "cycle_mean_stop" if v.is_none() => {}
            "cycle_mean_stop" => {
                let s = v.cast::<PyDict>()?;
                let get = |name: &str| {
                    s.get_item(name)?.ok_or_else(|| {
                        ModelError::new_err(format!("svzerod: cycle_mean_stop needs '{name}'"))
                    })
                };
                out.cycle_mean_stop = Some(CycleMeanStop {
                    caps: get("caps")?.extract()?,
                    tolerance: get("tolerance")?.extract()?,
                    max_extra: get("max_extra")?.extract()?,
                });
            }
            other => {
                return Err(ModelError::new_err(format!(
                    "svzerod: unknown setting '{other}' (rates, derived, cycle_mean_stop)"
                )));
            }
        }
    }
    Ok(out)
}

fn derived(item: &Bound<'_, PyAny>, probes: &Probes) -> PyResult<Derived> {
    let kind: String = item.get_item(0)?.extract()?;
    match kind.as_str() {
        "valve_status" => {
            let name: String = item.get_item(1)?.extract()?;
            let valve = (probes.valves.iter())
                .find(|v| v.name == name && v.law.is_some())
                .ok_or_else(|| {
                    ModelError::new_err(format!("svzerod: '{name}' is not a valve element"))
                })?;
            Ok(Derived::ValveStatus {
                behind: valve.unknowns[0],
                front: valve.unknowns[1],
                law: valve.law.expect("checked above"),
            })
        }
        "from_start" => Ok(Derived::FromStart {
            unknown: item.get_item(1)?.extract()?,
            scale: item.get_item(2)?.extract()?,
        }),
        other => Err(ModelError::new_err(format!(
            "svzerod: unknown derived column '{other}' (valve_status, from_start)"
        ))),
    }
}
