//! The run settings of a model: its `simulation` section (and `simulation: output:`) with the
//! caller's overrides (`oxyline.simulate`'s keywords), each checked and defaulted here. A
//! message names the setting and where it came from (`simulate: cycles` for a keyword,
//! `simulation: cycles` or `simulation output: every` for the file) and the value.

use super::native::{METHODS, err, py_list};
use super::node::{Kind, Node, py_g};
use crate::error::{Error, Result};

/// The keywords `oxyline.simulate` takes.
pub const OPTIONS: &[&str] = &[
    "cycles",
    "dt",
    "method",
    "output_every",
    "output_cycles",
    "until_periodic",
    "max_cycles",
    "rho_infty",
    "start",
    "segments",
    "progress",
    "newton_atol",
    "max_iterations",
    "transport",
    "variables",
    "vessels",
    "max_memory",
    "checkpoint",
    "checkpoint_every",
    "cancel",
    "rtol",
    "atol",
    "threads",
    // an impedance refinement after the run (the Python run), checked with the settings
    "estimate_space_error",
    // the accumulated time-integration error (the Python run: the core's second integration
    // of the last cycle), checked with the settings
    "estimate_time_error",
    // run again at the tolerance the estimate says meets rtol in every vessel (the Python run)
    "meet_rtol",
];
/// How a run starts.
pub const STARTS: &[&str] = &[
    "steady",
    "zero",
    "svzerod-steady",
    "svzerod-zero",
    "periodic",
];

/// The start of a run that names none: `periodic` (the core's estimate of the periodic state,
/// `integrate::periodic`) for an error-controlled run to periodicity, which it brings to its
/// tolerance in fewer cycles and steps than the steady start (docs/physics.md §10, "The default
/// start"); `steady` otherwise, so that a fixed step (a given `dt`, `rk4`) and a run of exactly
/// `cycles` keep their outputs bit for bit. A circuit the harmonic solve does not apply to
/// (nonlinear, time-varying, chambers) starts steady either way.
pub fn default_start(until_periodic: bool, error_controlled: bool) -> &'static str {
    if until_periodic && error_controlled {
        "periodic"
    } else {
        "steady"
    }
}

/// The resolved run settings (defaults: `oxyline.simulate`'s documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub period: f64,
    pub cycles: i64,
    pub dt: Option<f64>,
    pub method: String,
    pub output_every: f64,
    pub output_all_cycles: bool,
    pub until_periodic: Option<f64>,
    pub max_cycles: i64,
    pub rho_infty: f64,
    pub start: String,
    pub segments: bool,
    pub newton_atol: Option<f64>,
    pub max_iterations: i64,
    pub transport: bool,
    /// Error control's relative tolerance (None: fixed steps); the run checks 0 < rtol < 1.
    /// [`DEFAULT_RTOL`] where neither `rtol` nor a fixed `dt` is given and the method has an
    /// error estimate (every method but `rk4`).
    pub rtol: Option<f64>,
    /// `rtol` is the default, not given: a run that cannot be error-controlled (a checkpointed
    /// one) may fall back to the automatic fixed step, saying so, instead of being refused.
    pub rtol_default: bool,
    /// Error control's absolute tolerance per kind of unknown (SI); the run names an unknown
    /// kind.
    pub atol: Option<AbsoluteTolerances>,
    /// Threads of one run (None: every core; 1: the serial code path; see `crate::threads`).
    pub threads: Option<i64>,
    /// Estimate the spatial error after the run (the Python run refines every vessel once and
    /// compares the inlet impedance); not a setting of the core's run.
    pub estimate_space_error: bool,
    /// Estimate the accumulated time-integration error (docs/solvers.md, "The accumulated
    /// error"): the keyword or the file's `simulation: {estimate_time_error: true}`.
    pub estimate_time_error: bool,
    /// Meet rtol in every vessel: after the estimate, run again at the tolerance it asks
    /// (the keyword or the file's `simulation: {meet_rtol: true}`).
    pub meet_rtol: bool,
}

/// A setting's value: given (by the caller or the file) or the default.
enum Val<N> {
    Given(N),
    Int(i64),
    Float(f64),
    Text(&'static str),
    Flag(bool),
    Null,
}

impl<N: Node> Val<N> {
    fn kind(&self) -> Kind {
        match self {
            Val::Given(n) => n.kind(),
            Val::Int(_) => Kind::Int,
            Val::Float(_) => Kind::Float,
            Val::Text(_) => Kind::Str,
            Val::Flag(_) => Kind::Bool,
            Val::Null => Kind::Null,
        }
    }
    fn number(&self) -> Option<f64> {
        match self {
            Val::Given(n) => n.number(),
            Val::Int(i) => Some(*i as f64),
            Val::Float(x) => Some(*x),
            _ => None,
        }
    }
    fn integer(&self) -> Option<i64> {
        match self {
            Val::Given(n) => n.integer(),
            Val::Int(i) => Some(*i),
            _ => None,
        }
    }
    fn text(&self) -> Option<String> {
        match self {
            Val::Given(n) => n.text(),
            Val::Text(t) => Some((*t).to_owned()),
            _ => None,
        }
    }
    fn repr(&self) -> String {
        match self {
            Val::Given(n) => n.repr(),
            Val::Int(i) => i.to_string(),
            Val::Float(x) => super::node::py_repr(*x),
            Val::Text(t) => format!("'{t}'"),
            Val::Flag(b) => if *b { "True" } else { "False" }.into(),
            Val::Null => "None".into(),
        }
    }
    fn truthy(&self) -> bool {
        match self {
            Val::Given(n) => n.truthy(),
            Val::Flag(b) => *b,
            _ => true,
        }
    }
}

/// The settings of a model's `simulation` section `sim` (a mapping, maybe empty) with the
/// caller's `overrides` (a mapping); `period`: the model's (1 s if it has none).
pub fn resolve<N: Node>(sim: &N, overrides: &N, period: Option<f64>) -> Result<Settings> {
    let unknown: Vec<String> = {
        let mut u: Vec<String> = overrides
            .entries()
            .into_iter()
            .map(|(k, _)| k)
            .filter(|k| !OPTIONS.contains(&k.as_str()))
            .collect();
        u.sort();
        u
    };
    if !unknown.is_empty() {
        return Err(Error::model(
            "simulate",
            format!("unknown option(s) {}", unknown.join(", ")),
        ));
    }
    let out = sim.get("output").filter(Node::truthy);
    // (value, where it came from) of a setting: the keyword, else the file's key, else default
    let get = |key: &str, section: Option<&N>, file_key: &str, default: Val<N>| {
        if let Some(v) = overrides.get(key) {
            return (Val::Given(v), format!("simulate: {key}"));
        }
        let in_output = ["output_every", "output_cycles", "segments"].contains(&key);
        let place = if in_output {
            format!("simulation output: {}", key.trim_start_matches("output_"))
        } else {
            format!("simulation: {key}")
        };
        let given = section.and_then(|s| s.get(file_key));
        (given.map_or(default, Val::Given), place)
    };
    let period = period.unwrap_or(1.0);
    let (v, w) = get("cycles", Some(sim), "cycles", Val::Int(10));
    let cycles = integer(&v, &w, 1)?;
    let (dt, w) = get("dt", Some(sim), "dt", Val::Text("auto"));
    let dt = match (dt.kind(), dt.text()) {
        (Kind::Null, _) => None,
        (_, Some(t)) if t == "auto" => None,
        (Kind::Str, _) => {
            return Err(setting(
                &w,
                format!("must be 'auto' or a number > 0, got {}", dt.repr()),
            ));
        }
        _ => Some(real(&dt, &w, 0.0, f64::INFINITY, true)?),
    };
    let (m, w) = get("method", Some(sim), "method", Val::Text("auto"));
    let method = m
        .text()
        .filter(|t| METHODS.contains(&t.as_str()))
        .ok_or_else(|| {
            setting(
                &w,
                format!("must be one of {}, got {}", py_list(METHODS), m.repr()),
            )
        })?;
    let (v, w) = get(
        "output_every",
        out.as_ref(),
        "every",
        Val::Float(period / 1000.0),
    );
    let output_every = real(&v, &w, 0.0, f64::INFINITY, true)?;
    let (c, w) = get("output_cycles", out.as_ref(), "cycles", Val::Text("last"));
    let all_cycles = match c.text().as_deref() {
        Some("last") => false,
        Some("all") => true,
        _ => {
            return Err(setting(
                &w,
                format!("must be 'last' or 'all', got {}", c.repr()),
            ));
        }
    };
    let (u, w) = get("until_periodic", Some(sim), "until_periodic", Val::Null);
    let until = match u.kind() {
        Kind::Null => None,
        _ => Some(real(&u, &w, 0.0, f64::INFINITY, true)?),
    };
    let (mc, w) = get("max_cycles", Some(sim), "max_cycles", Val::Null);
    let max_cycles = match mc.kind() {
        Kind::Null => cycles.max(100),
        _ => {
            let m = integer(&mc, &w, 1)?;
            if until.is_some() && m < cycles {
                return Err(setting(
                    &w,
                    format!(
                        "({m}) is less than cycles ({cycles}), the least number of cycles a run \
                         until_periodic takes"
                    ),
                ));
            }
            m
        }
    };
    let (atol, atol_where) = get("newton_atol", None, "", Val::Null);
    let (r, w) = get("rho_infty", Some(sim), "rho_infty", Val::Float(0.5));
    let rho_infty = real(&r, &w, 0.0, 1.0, false)?;
    let (f, w) = get("segments", out.as_ref(), "segments", Val::Flag(true));
    let segments = flag(&f, &w)?;
    let newton_atol = match atol.kind() {
        Kind::Null => None,
        _ => Some(real(&atol, &atol_where, 0.0, f64::INFINITY, true)?),
    };
    let (n, w) = get("max_iterations", None, "", Val::Int(30));
    let max_iterations = integer(&n, &w, 1)?;
    let (t, w) = get("transport", None, "", Val::Flag(true));
    let transport = flag(&t, &w)?;
    let rtol = get("rtol", Some(sim), "rtol", Val::Null);
    let atol = get("atol", Some(sim), "atol", Val::Null);
    let (given, atol) = tolerances(&rtol, &atol, dt.is_none() && method != "rk4")?;
    let rtol_default = given.is_none() && dt.is_none() && method != "rk4";
    let rtol = given.or(Some(DEFAULT_RTOL).filter(|_| rtol_default));
    let (s, w) = get(
        "start",
        Some(sim),
        "start",
        Val::Text(default_start(until.is_some(), rtol.is_some())),
    );
    let start = s
        .text()
        .filter(|t| STARTS.contains(&t.as_str()))
        .ok_or_else(|| {
            setting(
                &w,
                format!("must be one of {}, got {}", STARTS.join(", "), s.repr()),
            )
        })?;
    // read by the Python run (one impedance refinement after it), checked here with the rest
    let (e, w) = get("estimate_space_error", None, "", Val::Flag(false));
    let estimate_space_error = flag(&e, &w)?;
    let (e, w) = get(
        "estimate_time_error",
        Some(sim),
        "estimate_time_error",
        Val::Flag(false),
    );
    let estimate_time_error = flag(&e, &w)?;
    let (e, w) = get("meet_rtol", Some(sim), "meet_rtol", Val::Flag(false));
    let meet_rtol = flag(&e, &w)?;
    let (th, w) = get("threads", Some(sim), "threads", Val::Null);
    let threads = match th.kind() {
        Kind::Null => None,
        _ => Some(integer(&th, &w, 1)?),
    };
    progress(overrides)?;
    Ok(Settings {
        period,
        cycles,
        dt,
        method,
        output_every,
        output_all_cycles: all_cycles,
        until_periodic: until,
        max_cycles,
        rho_infty,
        start,
        segments,
        newton_atol,
        max_iterations,
        transport,
        rtol,
        rtol_default,
        atol,
        threads,
        estimate_space_error,
        estimate_time_error,
        meet_rtol,
    })
}

/// `progress` (a keyword only): true, false (or None) or a callback `f(t, t_end)`; the
/// front end shows or calls it.
fn progress<N: Node>(overrides: &N) -> Result<()> {
    match overrides.get("progress") {
        Some(p) if !matches!(p.kind(), Kind::Null | Kind::Bool) && !p.callable() => Err(err(
            "simulate",
            format!(
                "progress must be true, false or a callback f(t, t_end), got {}",
                p.repr()
            ),
        )),
        _ => Ok(()),
    }
}

/// The relative tolerance of a run that gives neither `rtol` nor a fixed `dt`: the default
/// run is error-controlled, so the output interval never changes its solution
/// (docs/physics.md §10).
pub const DEFAULT_RTOL: f64 = 1e-3;

type Tolerance<N> = (Val<N>, String);
/// Error control's `atol`: (kind, value) pairs.
type AbsoluteTolerances = Vec<(String, f64)>;

/// Error control's `rtol` (a finite number > 0) and `atol` (a mapping of kind to a finite
/// number > 0), each named by where it came from; `controlled`: the run is error-controlled
/// without `rtol` (at the default), so `atol` alone is taken.
fn tolerances<N: Node>(
    rtol: &Tolerance<N>,
    atol: &Tolerance<N>,
    controlled: bool,
) -> Result<(Option<f64>, Option<AbsoluteTolerances>)> {
    let r = match rtol.0.kind() {
        Kind::Null => None,
        _ => Some(real(&rtol.0, &rtol.1, 0.0, f64::INFINITY, true)?),
    };
    let a = match (&atol.0, atol.0.kind()) {
        (_, Kind::Null) => None,
        (Val::Given(n), Kind::Map) => {
            let mut out = Vec::new();
            for (k, v) in n.entries() {
                let place = format!("{}.{k}", atol.1);
                out.push((k, real(&Val::Given(v), &place, 0.0, f64::INFINITY, true)?));
            }
            Some(out)
        }
        _ => {
            return Err(setting(
                &atol.1,
                format!(
                    "must be a mapping of kind (pressure, flow, volume, species) to a number in \
                     SI units, got {}",
                    atol.0.repr()
                ),
            ));
        }
    };
    if r.is_none() && a.is_some() && !controlled {
        // checked here, where every source of settings passes (a checkpoint's stored ones too)
        return Err(setting(
            &atol.1,
            "needs error control (rtol, without a fixed dt or method 'rk4')".to_string(),
        ));
    }
    Ok((r, a))
}

/// An error of the setting `place` ("simulate: cycles"): its two parts are element and key.
fn setting(place: &str, message: String) -> Error {
    let (element, key) = place.split_once(": ").unwrap_or((place, ""));
    err(element, format!("{key} {message}"))
}

/// The largest count a setting takes (2⁵³: every count below is exact as a float, and no run
/// gets near it).
pub const MAX_COUNT: i64 = 1 << 53;

/// An integer from `minimum` to [`MAX_COUNT`]: integers (and whole floats, read as the
/// integer); bools and text are refused, and so are integers beyond the range (never
/// saturated into it).
fn integer<N: Node>(v: &Val<N>, place: &str, minimum: i64) -> Result<i64> {
    let beyond = || {
        let shown: String = v.repr().chars().take(40).collect();
        setting(
            place,
            format!("must be an integer from {minimum} to 2**53, got {shown}"),
        )
    };
    let whole = match v.kind() {
        Kind::Int => Some(v.integer().ok_or_else(beyond)?),
        Kind::Float => v
            .number()
            .filter(|x| x.fract() == 0.0)
            .map(|x| {
                if x.abs() <= MAX_COUNT as f64 {
                    Ok(x as i64)
                } else {
                    Err(beyond())
                }
            })
            .transpose()?,
        _ => None,
    };
    match whole {
        Some(n) if n > MAX_COUNT => Err(beyond()),
        Some(n) if n >= minimum => Ok(n),
        Some(n) if v.kind() == Kind::Float => Err(setting(
            place,
            format!("must be an integer >= {minimum}, got {n}"),
        )),
        _ => Err(setting(
            place,
            format!("must be an integer >= {minimum}, got {}", v.repr()),
        )),
    }
}

/// A finite number in (low, high] (or [low, high] with `low_open` false); bools, text, NaN
/// and infinities are refused.
fn real<N: Node>(v: &Val<N>, place: &str, low: f64, high: f64, low_open: bool) -> Result<f64> {
    let Some(x) = v
        .number()
        .filter(|_| matches!(v.kind(), Kind::Int | Kind::Float))
    else {
        return Err(setting(
            place,
            format!("must be a number, got {}", v.repr()),
        ));
    };
    let inside = (if low_open { x > low } else { x >= low }) && x <= high;
    if !x.is_finite() || !inside {
        let op = if low_open { ">" } else { ">=" };
        let upper = if high < f64::INFINITY {
            format!(" and <= {}", py_g(high))
        } else {
            String::new()
        };
        return Err(setting(
            place,
            format!(
                "must be a finite number {op} {}{upper}, got {}",
                py_g(low),
                v.repr()
            ),
        ));
    }
    Ok(x)
}

/// A true/false setting: `segments: "no"` is an error, not true.
fn flag<N: Node>(v: &Val<N>, place: &str) -> Result<bool> {
    if v.kind() != Kind::Bool {
        return Err(setting(
            place,
            format!("must be true or false, got {}", v.repr()),
        ));
    }
    Ok(v.truthy())
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn defaults_and_overrides() {
        let s = resolve(&json!({"cycles": 3}), &json!({"dt": 1e-4}), Some(0.8)).unwrap();
        assert_eq!((s.cycles, s.dt, s.max_cycles), (3, Some(1e-4), 100));
        assert_eq!(s.output_every, 0.8 / 1000.0);
        assert_eq!((s.method.as_str(), s.start.as_str()), ("auto", "steady"));
        assert!(s.segments && s.transport && !s.output_all_cycles);
    }

    #[test]
    fn the_default_start_is_periodic_only_for_an_error_controlled_run_to_periodicity() {
        let start = |sim: serde_json::Value, o: serde_json::Value| {
            resolve(&sim, &o, Some(0.8)).unwrap().start
        };
        let to_periodic = json!({"cycles": 2, "until_periodic": 1e-4});
        assert_eq!(start(to_periodic.clone(), json!({})), "periodic");
        assert_eq!(
            start(to_periodic.clone(), json!({"rtol": 1e-4})),
            "periodic"
        );
        // a fixed step, or exactly `cycles`, keeps the steady start (and its outputs)
        assert_eq!(start(to_periodic.clone(), json!({"dt": 1e-3})), "steady");
        assert_eq!(
            start(to_periodic.clone(), json!({"method": "rk4"})),
            "steady"
        );
        assert_eq!(
            start(to_periodic.clone(), json!({"until_periodic": null})),
            "steady"
        );
        assert_eq!(start(json!({"cycles": 2}), json!({})), "steady");
        // a start given wins, from the file or the keyword
        let file_steady = json!({"cycles": 2, "until_periodic": 1e-4, "start": "steady"});
        assert_eq!(start(file_steady, json!({})), "steady");
        assert_eq!(start(to_periodic, json!({"start": "zero"})), "zero");
    }

    #[test]
    fn estimate_space_error_is_a_flag_named_when_not_one() {
        let r = |o: serde_json::Value| resolve(&json!({}), &o, None);
        assert!(!r(json!({})).unwrap().estimate_space_error);
        assert!(
            r(json!({"estimate_space_error": true}))
                .unwrap()
                .estimate_space_error
        );
        let e = r(json!({"estimate_space_error": "yes"}))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("simulate: estimate_space_error must be true or false, got 'yes'"),
            "{e}"
        );
    }

    #[test]
    fn a_run_without_dt_is_error_controlled_at_the_default_rtol() {
        let r = |sim: serde_json::Value, o: serde_json::Value| resolve(&sim, &o, None).unwrap();
        // no dt (or dt: auto), any method with an error estimate: the default tolerance
        for sim in [
            json!({}),
            json!({"dt": "auto", "method": "generalized-alpha"}),
        ] {
            let s = r(sim, json!({}));
            assert_eq!(
                (s.rtol, s.rtol_default, s.dt),
                (Some(DEFAULT_RTOL), true, None)
            );
        }
        // a fixed dt (file or keyword) or RK4 (no error estimate): fixed steps as before
        let s = r(json!({"dt": 1e-3}), json!({}));
        assert_eq!((s.rtol, s.rtol_default), (None, false));
        let s = r(json!({}), json!({"method": "rk4"}));
        assert_eq!((s.rtol, s.rtol_default), (None, false));
        // a given rtol is not the default; atol alone joins the default rtol
        let s = r(json!({"rtol": 1e-4}), json!({}));
        assert_eq!((s.rtol, s.rtol_default), (Some(1e-4), false));
        let s = r(json!({}), json!({"atol": {"pressure": 0.5}}));
        assert_eq!(s.rtol, Some(DEFAULT_RTOL));
        assert_eq!(s.atol, Some(vec![("pressure".to_owned(), 0.5)]));
        // ... but not a fixed step, which has no tolerance to meet
        let e = resolve(&json!({"dt": 1e-3}), &json!({"atol": {"flow": 1e-9}}), None);
        assert!(
            e.unwrap_err()
                .to_string()
                .contains("atol needs error control")
        );
    }

    #[test]
    fn errors_name_the_setting_its_place_and_value() {
        let e = |sim: serde_json::Value, o: serde_json::Value| {
            resolve(&sim, &o, None).unwrap_err().to_string()
        };
        assert_eq!(
            e(json!({}), json!({"cycles": -2.0})),
            "simulate: cycles must be an integer >= 1, got -2"
        );
        assert_eq!(
            e(json!({"output": {"every": 0}}), json!({})),
            "simulation output: every must be a finite number > 0, got 0"
        );
        assert_eq!(
            e(json!({}), json!({"rho_infty": 2})),
            "simulate: rho_infty must be a finite number >= 0 and <= 1, got 2"
        );
        assert_eq!(
            e(json!({}), json!({"segmnts": true, "a": 1})),
            "simulate: unknown option(s) a, segmnts"
        );
    }

    #[test]
    fn progress_is_a_flag_or_a_callback() {
        let r = |o: serde_json::Value| resolve(&json!({}), &o, None).map_err(|e| e.to_string());
        assert!(r(json!({"progress": true})).is_ok());
        assert!(r(json!({"progress": null})).is_ok());
        assert_eq!(
            r(json!({"progress": "yes"})).unwrap_err(),
            "simulate: progress must be true, false or a callback f(t, t_end), got 'yes'"
        );
        assert!(r(json!({"progress": 1})).unwrap_err().contains("got 1"));
    }

    #[test]
    fn counts_beyond_the_range_are_refused_not_saturated() {
        let e = |o: serde_json::Value| resolve(&json!({}), &o, None).unwrap_err().to_string();
        assert_eq!(
            e(json!({"max_cycles": u64::MAX})),
            "simulate: max_cycles must be an integer from 1 to 2**53, got 18446744073709551615"
        );
        assert!(e(json!({"cycles": 1e30})).starts_with("simulate: cycles must be an integer"));
        assert!(e(json!({"max_iterations": (1u64 << 53) + 1})).contains("max_iterations"));
        let s = resolve(&json!({}), &json!({"cycles": 1u64 << 53}), None).unwrap();
        assert_eq!(s.cycles, 1 << 53);
    }
}
