//! The run settings that `Network.simulate` and `Ensemble.run` share: one keyword list
//! ([`KEYS`], exported as `_core.RUN_SETTINGS`), read from their `**settings` by one parser,
//! and one place that turns them into the core's [`RunSettings`].

use crate::errors::ModelError;
use oxyline_core::RunSettings;
use oxyline_core::genalpha::NewtonControl;
use oxyline_core::integrate::adaptive::{Atol, KINDS, Tolerances};
use oxyline_core::run::facts::{Controlled, Fact, Ran, Requested, recorded, segmentation};
use oxyline_core::{Method, Start};
use pyo3::conversion::FromPyObjectOwned;
use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::collections::HashMap;

/// The keywords of [`Shared`], in the order of the `_core.pyi` stub's `RunOptions`.
pub(crate) const KEYS: [&str; 17] = [
    "cycles",
    "method",
    "rho_infty",
    "dt",
    "until_periodic",
    "max_cycles",
    "output_all_cycles",
    "start",
    "newton_atol",
    "max_iterations",
    "segments",
    "transport",
    "variables",
    "vessels",
    "rtol",
    "atol",
    "threads",
];

/// The shared settings (defaults: those of `oxyline.simulate`'s documentation).
pub(crate) struct Shared {
    pub cycles: usize,
    method: String,
    rho_infty: f64,
    dt: Option<f64>,
    until_periodic: Option<f64>,
    max_cycles: usize,
    output_all_cycles: bool,
    start: String,
    newton_atol: Option<f64>,
    max_iterations: usize,
    /// Record the segment columns.
    pub segments: bool,
    /// Run the species transport (if the model has one).
    pub transport: bool,
    /// The output selection (None: every variable / every output vessel).
    pub variables: Option<Vec<String>>,
    pub vessels: Option<Vec<String>>,
    /// Error control (docs/physics.md §10): the relative tolerance, and absolute ones by kind
    /// (`oxyline_core::integrate::adaptive::KINDS`; absent kinds keep the core's defaults).
    rtol: Option<f64>,
    /// `rtol` was among the keywords (also as None: a fixed step asked for).
    rtol_given: bool,
    atol: Option<HashMap<String, f64>>,
    /// Threads of a single run (None: every core; see `oxyline_core::threads`). An ensemble
    /// runs its variants one per thread and each variant serially.
    pub threads: Option<usize>,
}

impl Default for Shared {
    fn default() -> Self {
        Shared {
            cycles: 10,
            method: "auto".to_owned(),
            rho_infty: 0.5,
            dt: None,
            until_periodic: None,
            max_cycles: 100,
            output_all_cycles: false,
            start: "steady".to_owned(),
            newton_atol: None,
            max_iterations: 30,
            segments: true,
            transport: true,
            variables: None,
            vessels: None,
            rtol: None,
            rtol_given: false,
            atol: None,
            threads: None,
        }
    }
}

/// `value` as a `T`, a `TypeError` naming the keyword otherwise (as pyo3 names an argument).
fn arg<'py, T: FromPyObjectOwned<'py>>(key: &str, value: &Bound<'py, PyAny>) -> PyResult<T> {
    value.extract::<T>().map_err(|e| {
        let e: PyErr = e.into();
        PyTypeError::new_err(format!("argument '{key}': {e}"))
    })
}

impl Shared {
    /// The settings of `kwargs` (the `**settings` of the caller); an unknown keyword is a
    /// `TypeError`, as for any Python function.
    pub fn from_kwargs(kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<Shared> {
        let mut s = Shared::default();
        for (k, v) in kwargs.into_iter().flat_map(|d| d.iter()) {
            let key: String = k.extract()?;
            match key.as_str() {
                "cycles" => s.cycles = arg(&key, &v)?,
                "method" => s.method = arg(&key, &v)?,
                "rho_infty" => s.rho_infty = arg(&key, &v)?,
                "dt" => s.dt = arg(&key, &v)?,
                "until_periodic" => s.until_periodic = arg(&key, &v)?,
                "max_cycles" => s.max_cycles = arg(&key, &v)?,
                "output_all_cycles" => s.output_all_cycles = arg(&key, &v)?,
                "start" => s.start = arg(&key, &v)?,
                "newton_atol" => s.newton_atol = arg(&key, &v)?,
                "max_iterations" => s.max_iterations = arg(&key, &v)?,
                "segments" => s.segments = arg(&key, &v)?,
                "transport" => s.transport = arg(&key, &v)?,
                "variables" => s.variables = arg(&key, &v)?,
                "vessels" => s.vessels = arg(&key, &v)?,
                "rtol" => {
                    s.rtol = arg(&key, &v)?;
                    s.rtol_given = true;
                }
                "atol" => s.atol = atol_arg(&v)?,
                "threads" => s.threads = arg(&key, &v)?,
                _ => {
                    return Err(PyTypeError::new_err(format!(
                        "unexpected keyword argument '{key}'"
                    )));
                }
            }
        }
        Ok(s)
    }

    /// `oxyline.simulate`'s default step control (`model::settings::DEFAULT_RTOL`) where the
    /// keywords choose none: no `rtol` keyword (an explicit None keeps the fixed step), no
    /// `dt`, a method with an error estimate (not `rk4`), and no checkpoints (`checkpointing`:
    /// a checkpoint does not carry the controller's state, so such a run keeps the automatic
    /// fixed step, as `oxyline.simulate` does).
    pub fn default_step_control(&mut self, checkpointing: bool) {
        if !self.rtol_given && self.dt.is_none() && self.method != "rk4" && !checkpointing {
            self.rtol = Some(oxyline_core::model::settings::DEFAULT_RTOL);
        }
    }

    /// The core's settings of a run with these settings over `period`, recording every
    /// `output_every` seconds (`probes` and `species_columns` empty: the caller selects).
    pub fn run_settings(
        &self,
        period: f64,
        output_every: f64,
        keep_current_cycle: bool,
    ) -> PyResult<RunSettings> {
        Ok(RunSettings {
            method: parse_method(&self.method, self.rho_infty)?,
            dt: self.dt,
            period,
            cycles: self.cycles,
            until_periodic: self.until_periodic,
            max_cycles: self.max_cycles,
            output_every,
            output_all_cycles: self.output_all_cycles,
            keep_current_cycle,
            start: parse_start(&self.start, self.rho_infty)?,
            newton: NewtonControl {
                atol: self.newton_atol,
                max_iter: self.max_iterations,
            },
            probes: Vec::new(),
            species_columns: None,
            tolerances: self.tolerances()?,
            svzerod: Default::default(),
            finer_last_cycle: None,
        })
    }

    /// The core's tolerances of `rtol` and `atol` (None without `rtol`; `atol` alone is an
    /// error naming it).
    fn tolerances(&self) -> PyResult<Option<Tolerances>> {
        let Some(rtol) = self.rtol else {
            if self.atol.is_some() {
                return Err(ModelError::new_err(
                    "simulation: atol needs rtol (error control)",
                ));
            }
            return Ok(None);
        };
        let mut atol = Atol::default();
        for (kind, &v) in self.atol.iter().flatten() {
            // (a given kind is absolute as given: `Atol::of`)
            let slot = match kind.as_str() {
                "pressure" => &mut atol.pressure,
                "flow" => &mut atol.flow,
                "volume" => &mut atol.volume,
                "species" => &mut atol.species,
                _ => {
                    return Err(ModelError::new_err(format!(
                        "simulation: atol has no kind '{kind}' (kinds: {})",
                        KINDS.join(", ")
                    )));
                }
            };
            *slot = v;
            if let Some(k) = KINDS.iter().position(|k| k == kind) {
                atol.given[k] = true;
            }
        }
        Ok(Some(Tolerances { rtol, atol }))
    }
}

/// `atol`: a mapping of kind → number; anything else is a `ModelError` naming the setting.
fn atol_arg(value: &Bound<'_, PyAny>) -> PyResult<Option<HashMap<String, f64>>> {
    if value.is_none() {
        return Ok(None);
    }
    value
        .extract::<HashMap<String, f64>>()
        .map(Some)
        .map_err(|_| {
            ModelError::new_err(format!(
                "simulation: atol must be a mapping of kind ({}) to a number, got {}",
                KINDS.join(", "),
                value.repr().map_or_else(|_| "?".into(), |r| r.to_string())
            ))
        })
}

pub(crate) fn parse_method(method: &str, rho_infty: f64) -> PyResult<Method> {
    Ok(match method {
        "rk4" => Method::Rk4,
        "generalized-alpha" => Method::GeneralizedAlpha { rho_inf: rho_infty },
        "auto" => Method::Auto { rho_inf: rho_infty },
        "dopri5" => Method::Dopri5,
        other => {
            return Err(ModelError::new_err(format!(
                "simulation: unknown method '{other}' (expected rk4, generalized-alpha, dopri5 \
                 or auto)"
            )));
        }
    })
}

pub(crate) fn parse_start(start: &str, rho_infty: f64) -> PyResult<Start> {
    Ok(match start {
        "steady" => Start::Steady,
        "periodic" => Start::Periodic,
        "svzerod-steady" => Start::SvZeroDSteady { rho_inf: rho_infty },
        "zero" => Start::Zero,
        "svzerod-zero" => Start::SvZeroDZero,
        other => {
            return Err(ModelError::new_err(format!(
                "simulation: unknown start '{other}' (expected steady, periodic, zero, svzerod-steady or svzerod-zero)"
            )));
        }
    })
}

/// A field of a dict of settings or of a run's outcome, as `T` (a `KeyError` when missing).
fn field<'py, T: FromPyObjectOwned<'py>>(d: &Bound<'py, PyDict>, key: &str) -> PyResult<T> {
    let value = d
        .get_item(key)?
        .ok_or_else(|| pyo3::exceptions::PyKeyError::new_err(key.to_owned()))?;
    arg(key, &value)
}

/// What a run did, read from its outcome dict (`results::outcome_dict`).
fn ran(r: &Bound<'_, PyDict>) -> PyResult<Ran> {
    let control = match r.get_item("error_estimate")? {
        None => None,
        Some(est) => Some(Controlled {
            steps: field(r, "steps")?,
            rejected_steps: field(r, "rejected_steps")?,
            dt_min: field(r, "dt_min")?,
            dt_max: field(r, "dt_max")?,
            error_estimate: est
                .cast::<PyDict>()?
                .iter()
                .map(|(kind, v)| Ok((kind.extract()?, v.extract()?)))
                .collect::<PyResult<_>>()?,
        }),
    };
    Ok(Ran {
        method: field(r, "method")?,
        dt: field(r, "dt")?,
        cycles_run: field(r, "cycles_run")?,
        periodic_error: field(r, "periodic_error")?,
        rk4_dt_max: match r.get_item("rk4_dt_max")? {
            Some(v) => arg("rk4_dt_max", &v)?,
            None => None,
        },
        control,
    })
}

/// The settings and facts a run records with its result (`oxyline_core::run::facts`), in
/// the order shown: of the resolved `settings` (`resolve_settings`'s dict) and, after the
/// run, of its outcome `run`; `valves`: the circuit has valves.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (settings, run = None, valves = false))]
pub(crate) fn run_facts<'py>(
    py: Python<'py>,
    settings: Bound<'py, PyDict>,
    run: Option<Bound<'py, PyDict>>,
    valves: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let asked = Requested {
        period: field(&settings, "period")?,
        cycles: field(&settings, "cycles")?,
        method: field(&settings, "method")?,
        output_every: field(&settings, "output_every")?,
        rho_infty: field(&settings, "rho_infty")?,
        until_periodic: field(&settings, "until_periodic")?,
        rtol: field(&settings, "rtol")?,
        dt: field(&settings, "dt")?,
        start: field(&settings, "start")?,
    };
    let ran = run.as_ref().map(ran).transpose()?;
    facts_dict(py, recorded(&asked, ran.as_ref(), valves))
}

/// How the model's vessels were cut (`oxyline_core::run::facts::segmentation`), from the
/// network's `summary()`: recorded with a result, printed by the CLI.
#[oxyline_py_guard::guard]
#[pyfunction]
pub(crate) fn segmentation_facts<'py>(
    py: Python<'py>,
    summary: Bound<'py, PyDict>,
) -> PyResult<Bound<'py, PyDict>> {
    let facts = segmentation(
        field(&summary, "segments")?,
        field(&summary, "auto_segments")?,
        field(&summary, "auto_rtol")?,
    );
    facts_dict(py, facts)
}

/// Recorded facts as a dict, in their order (an absent one as None).
fn facts_dict(py: Python<'_>, facts: Vec<(String, Fact)>) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
    for (key, fact) in facts {
        match fact {
            Fact::Real(x) => d.set_item(key, x)?,
            Fact::Count(n) => d.set_item(key, n)?,
            Fact::Text(t) => d.set_item(key, t)?,
            Fact::Flag(b) => d.set_item(key, b)?,
            Fact::Absent => d.set_item(key, py.None())?,
        }
    }
    Ok(d)
}
