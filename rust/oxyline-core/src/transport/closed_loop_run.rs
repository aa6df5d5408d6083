//! The closed loop's run in one call (docs/oxygen.md "Oxygen around a closed loop"): the
//! parameter set (its published units) and the caller's choice of flows in; the run settings
//! checked, the circulation built (`closed_loop_circulation`), the closed-loop heart run when
//! it gives the flows, then the O2 loop run to its periodic state (`closed_loop::run_periodic`).

use super::closed_loop::{ClosedLoopRun, ClosedLoopSpec, Shooting, TreeOutlet, TreeSpec};
use super::closed_loop_circulation::{
    HEART_CYCLES, err, field, flow_dt, heart_kind, heart_max_cycles, heart_model,
    heart_newton_atol, heart_until_periodic, tree_model,
};
use super::closed_loop_heart::HeartSpec;
use super::closed_loop_params::{Layout, LoopParams};
use super::closed_loop_summary::{LoopSummary, summarise};
use crate::error::{Error, Result};
use crate::model::native::canonical;
use crate::model::node::{Kind, Node, py_g, py_g_digits, py_list, py_quote};
use serde_json::{Value, json};

/// Most steps per cycle (and cycles) a run may plan, as the core's run plan.
const MOST_STEPS: f64 = 1e9;
/// The tree's Hill inversions are warm-started (tolerance 1e-12 mmHg): its cycle map repeats
/// to ~1e-11, so the confirming cycles stop at this tolerance (Fick then holds to ~2e-12).
const TREE_TOL: f64 = 1e-10;

/// Where the O2 loop's flows come from.
#[derive(Debug, Clone, PartialEq)]
pub enum Flows {
    /// The parameter set's `flows` ("table" when it has none).
    Default,
    /// "table": the prescribed table (`LoopParams::flow_table`); "heart": a run of the set's
    /// closed-loop heart.
    Named(String),
    /// A caller's table (m³/s, steps × branches, row-major) of this shape, balanced first.
    Table { values: Vec<f64>, shape: Vec<usize> },
}

/// The run's controls, checked.
#[derive(Debug, Clone, Copy)]
pub struct RunSettings {
    pub max_cycles: usize,
    pub tol: f64,
    pub shooting: Shooting,
}

/// A number in (low, high), named by `key` when it is not one.
fn between<N: Node>(key: &str, value: Option<&N>, low: f64, high: f64) -> Result<f64> {
    let x = value
        .filter(|v| matches!(v.kind(), Kind::Int | Kind::Float))
        .and_then(Node::number);
    match x {
        Some(x) if low < x && x < high => Ok(x),
        _ => Err(err(format!(
            "{key} must be a number in ({}, {}), got {}",
            py_g(low),
            py_g(high),
            value.map_or_else(|| "None".to_owned(), Node::repr)
        ))),
    }
}

/// The loop's period and step, each named when it is not a usable number (a period below the
/// step would read as "0 recorded intervals", a step count beyond the run plan's as a failed
/// allocation).
pub fn check_times<N: Node>(params: &N) -> Result<()> {
    let period = between("period", params.get("period").as_ref(), 0.0, f64::INFINITY)?;
    let dt = between("dt", params.get("dt").as_ref(), 0.0, f64::INFINITY)?;
    if dt > period {
        return Err(err(format!(
            "dt = {} s is longer than the period {} s",
            py_g(dt),
            py_g(period)
        )));
    }
    if period / dt > MOST_STEPS {
        return Err(Error::Resource {
            what: "closed loop".into(),
            bytes: 0,
            message: format!(
                "period {} s / dt {} s = {} steps per cycle, more than the 1e+09 a run may \
                 plan; use a larger dt or a shorter period",
                py_g(period),
                py_g(dt),
                py_g_digits(period / dt, 3)
            ),
        });
    }
    Ok(())
}

impl RunSettings {
    /// The controls as the caller gave them: `max_cycles` a whole number from 1 to 1e9, `tol`
    /// in (0, 1), `shooting` "anderson" or "newton".
    pub fn read<N: Node>(max_cycles: &N, tol: &N, shooting: &N) -> Result<Self> {
        let cycles = (max_cycles.kind() == Kind::Int)
            .then(|| max_cycles.integer())
            .flatten()
            .filter(|&n| n >= 1 && n as f64 <= MOST_STEPS)
            .ok_or_else(|| {
                err(format!(
                    "max_cycles must be a whole number from 1 to 1e+09, got {}",
                    max_cycles.repr()
                ))
            })?;
        let tol = between("tol", Some(tol), 0.0, 1.0)?;
        let shooting = match shooting.text().as_deref() {
            Some("anderson") => Shooting::Anderson,
            Some("newton") => Shooting::Newton,
            _ => {
                return Err(err(format!(
                    "shooting must be 'anderson' or 'newton', got {}",
                    shooting.repr()
                )));
            }
        };
        Ok(RunSettings {
            max_cycles: cycles as usize,
            tol,
            shooting,
        })
    }
}

/// The run's record and what names its columns.
pub struct LoopRun {
    pub run: ClosedLoopRun,
    pub compartments: Vec<String>,
    pub branches: Vec<String>,
    /// The recorded cycle's summary (`closed_loop_summary`).
    pub summary: LoopSummary,
    /// For the user (a tree wall without haemoglobin facilitation).
    pub warnings: Vec<String>,
}

fn names(list: &[Value]) -> Vec<String> {
    list.iter()
        .map(|c| c["name"].as_str().unwrap_or_default().to_owned())
        .collect()
}

/// Runs O2 around the closed loop of the parameter set `params_json` to its periodic steady
/// state, on the flows `flows` (with an arterial tree always those of the heart run).
pub fn simulate(params_json: &str, flows: Flows, settings: &RunSettings) -> Result<LoopRun> {
    let p: Value = serde_json::from_str(params_json).map_err(|e| err(e.to_string()))?;
    check_times(&p)?;
    let params = LoopParams::from_json(params_json)?;
    let layout = params.layout();
    let compartments = names(&layout.compartments);
    let mut spec: ClosedLoopSpec = serde_json::from_value(json!({
        "compartments": &layout.compartments, "branches": &layout.branches,
        "binding": &layout.binding}))
    .map_err(|e| err(e.to_string()))?;
    spec.shooting = settings.shooting;
    let mut tol = settings.tol;
    let mut warnings = Vec::new();
    let mut flows = flows;
    if params.has_tree() {
        if !matches!(&flows, Flows::Default) && flows != Flows::Named("heart".into()) {
            return Err(err(
                "with an arterial tree the flows come from the heart run (flows='heart')",
            ));
        }
        let (tree, w) = tree_spec(&p, &params, &layout, &compartments)?;
        spec.tree = Some(tree);
        warnings = w;
        flows = Flows::Named("heart".into());
        tol = tol.max(TREE_TOL);
    }
    let (table, balance) = chosen_table(&p, &params, &layout, flows)?;
    spec.balance = balance;
    if table.is_none() {
        // the core runs the heart, then O2 on its flows
        spec.heart = Some(heart_spec(&p, &params, &layout)?);
        spec.period = Some(params.period);
    }
    let table = table.unwrap_or_default();
    let run = super::closed_loop::run_periodic(&spec, &table, params.dt, settings.max_cycles, tol)?;
    let branches = names(&layout.branches);
    let organs: Vec<String> = params.organs.iter().map(|(k, _)| k.clone()).collect();
    let summary = summarise(&run, &compartments, &branches, &organs, params.dt)?;
    Ok(LoopRun {
        run,
        compartments,
        branches,
        summary,
        warnings,
    })
}

/// The native model of the set's closed-loop heart (`closed_loop_circulation::heart_model`).
pub fn heart_model_of(params_json: &str) -> Result<Value> {
    let p: Value = serde_json::from_str(params_json).map_err(|e| err(e.to_string()))?;
    let params = LoopParams::from_json(params_json)?;
    heart_model(&p, &params, &params.layout())
}

/// The absolute Newton tolerance the set's closed-loop heart runs with (`heart_newton_atol`:
/// svZeroDSolver's block needs one; None for the native heart).
pub fn heart_newton_atol_of(params_json: &str) -> Result<Option<f64>> {
    let p: Value = serde_json::from_str(params_json).map_err(|e| err(e.to_string()))?;
    heart_newton_atol(&p)
}

/// A shape as Python prints a tuple: `(5,)`, `(200, 3)`.
fn py_shape(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => {
            let dims: Vec<String> = shape.iter().map(usize::to_string).collect();
            format!("({})", dims.join(", "))
        }
    }
}

/// A table given in the parameter set itself (a list of rows).
fn listed_table(v: &Value) -> Result<Flows> {
    let bad = || {
        err(format!(
            "flows must be a table, 'table' or 'heart', got {}",
            v.repr()
        ))
    };
    let rows = v.as_array().ok_or_else(bad)?;
    let mut values = Vec::new();
    let mut width = None;
    for row in rows {
        let row = row.as_array().ok_or_else(bad)?;
        if *width.get_or_insert(row.len()) != row.len() {
            return Err(bad());
        }
        for x in row {
            values.push(x.as_f64().ok_or_else(bad)?);
        }
    }
    let shape = vec![rows.len(), width.unwrap_or(0)];
    Ok(Flows::Table { values, shape })
}

/// The loop's flow table and whether the core balances it: the prescribed table is periodic
/// by construction; a caller's table is balanced first; None: the heart run gives it
/// (balanced).
fn chosen_table(
    p: &Value,
    params: &LoopParams,
    layout: &Layout,
    flows: Flows,
) -> Result<(Option<Vec<f64>>, bool)> {
    let flows = match flows {
        Flows::Default => match p.get("flows") {
            None => Flows::Named("table".into()),
            Some(Value::String(s)) => Flows::Named(s.clone()),
            Some(v) => listed_table(v)?,
        },
        given => given,
    };
    match flows {
        Flows::Named(s) if s == "table" => Ok((Some(params.flow_table(layout)?.0), false)),
        Flows::Named(s) if s == "heart" => Ok((None, true)),
        Flows::Named(s) => Err(err(format!(
            "flows must be a table, 'table' or 'heart', got {}",
            py_quote(&s)
        ))),
        Flows::Table { values, shape } => {
            let nb = layout.branches.len();
            if shape.len() != 2 || shape[1] != nb {
                let branches = py_list(names(&layout.branches).iter().map(|n| py_quote(n)));
                return Err(err(format!(
                    "flows must be (steps, {nb}) for the branches {branches}, got {}",
                    py_shape(&shape)
                )));
            }
            Ok((Some(values), true))
        }
        Flows::Default => Ok((None, true)),
    }
}

/// The core's closed-loop heart run (`heart_model`, `HEART_CYCLES` cycles, the native heart
/// on to its periodic state, `heart_until_periodic`; every unknown of the last one
/// recorded); the O2 loop's branch flows are read from it by unknown name
/// (`closed_loop_heart_series`: on/off valves gated, the shunt taking `shunt_fraction` of
/// the lungs' flow), each step's flow the mean of the recorded intervals it spans.
pub(crate) fn heart_spec(p: &Value, params: &LoopParams, layout: &Layout) -> Result<HeartSpec> {
    let (model, _) = canonical(&heart_model(p, params, layout)?)?;
    let organs: Vec<&str> = params.organs.iter().map(|(k, _)| k.as_str()).collect();
    let mut heart: HeartSpec = serde_json::from_value(json!({
        "model": model, "dt": flow_dt(p), "cycles": HEART_CYCLES,
        "until_periodic": heart_until_periodic(p)?, "max_cycles": heart_max_cycles(p)?,
        "newton_atol": heart_newton_atol(p)?,
        "series_of": {"heart": heart_kind(p)?, "organs": organs,
                      "shunt_fraction": params.lungs.shunt_fraction, "tree": params.has_tree()}
    }))
    .map_err(|e| Error::model("closed-loop heart", e.to_string()))?;
    heart.derive_series()?;
    Ok(heart)
}

/// The arterial tree of the loop (`tree_model`; its inlet and outlet tables are then those of
/// the heart run), fed by the left heart and draining into the organ beds; with the warnings
/// of its oxygen section.
fn tree_spec(
    p: &Value,
    params: &LoopParams,
    layout: &Layout,
    compartments: &[String],
) -> Result<(TreeSpec, Vec<String>)> {
    let (model, warnings) = canonical(&tree_model(p, params, layout)?)?;
    let index = |name: &str| {
        compartments
            .iter()
            .position(|c| c == name)
            .ok_or_else(|| err(format!("the loop has no compartment '{name}'")))
    };
    let cycles = field(field(p, "tree")?, "flow_cycles")?;
    let flow_cycles = cycles
        .as_f64()
        .filter(|c| *c >= 0.0 && c.is_finite())
        .ok_or_else(|| {
            err(format!(
                "tree: flow_cycles must be a whole number >= 0, got {}",
                cycles.repr()
            ))
        })?;
    let outlets = params
        .organs
        .iter()
        .map(|(k, _)| {
            Ok(TreeOutlet {
                boundary: format!("{k}_a"),
                to: index(k)?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    let tree = TreeSpec {
        model: model.to_string(),
        inlet: "aorta_in".into(),
        from: index("left_heart")?,
        outlets,
        flow_cycles: flow_cycles as usize,
    };
    Ok((tree, warnings))
}
