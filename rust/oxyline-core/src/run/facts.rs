//! The settings and facts a run records with its result (`result.settings`, the NetCDF
//! attributes `solver_*`): what was asked (period, cycles, method, output interval, ρ∞,
//! `until_periodic`, `rtol`), how the steps were chosen (the step-control text shown to
//! users) and, after the run, what it did (the method chosen, dt, cycles run, the
//! cycle-to-cycle change and, under error control, its steps, rejections, step range and
//! largest error estimates). One schema for `simulate`, `simulate_to_zarr` and the ensembles.

use crate::integrate::adaptive::KINDS;
use crate::model::node::py_g;

/// A recorded value, typed as the front end keeps it.
#[derive(Debug, Clone, PartialEq)]
pub enum Fact {
    Real(f64),
    Count(i64),
    Text(String),
    Flag(bool),
    /// Not applicable (`until_periodic` of a fixed number of cycles, RK4's limit of another
    /// method).
    Absent,
}

impl From<Option<f64>> for Fact {
    fn from(x: Option<f64>) -> Self {
        x.map_or(Fact::Absent, Fact::Real)
    }
}

/// The settings a run was asked for (the resolved ones, `model::settings::Settings`).
#[derive(Debug, Clone, PartialEq)]
pub struct Requested {
    pub period: f64,
    pub cycles: i64,
    pub method: String,
    pub output_every: f64,
    pub rho_infty: f64,
    pub until_periodic: Option<f64>,
    /// Error control's relative tolerance (None: a fixed step).
    pub rtol: Option<f64>,
    /// The fixed step given (None: automatic).
    pub dt: Option<f64>,
    /// How the run starts (`model::settings::STARTS`; the default's rule:
    /// `model::settings::default_start`).
    pub start: String,
}

/// What a finished (or stopped) run did.
#[derive(Debug, Clone, PartialEq)]
pub struct Ran {
    /// The method that ran (`auto` resolved).
    pub method: String,
    /// The step (the mean step under error control).
    pub dt: f64,
    pub cycles_run: i64,
    /// The last cycle-to-cycle change of the state (relative).
    pub periodic_error: f64,
    /// RK4's largest stable step, where it was estimated.
    pub rk4_dt_max: Option<f64>,
    /// The error control's record (None for a fixed step).
    pub control: Option<Controlled>,
}

/// An error-controlled run's steps and its largest estimates by kind.
#[derive(Debug, Clone, PartialEq)]
pub struct Controlled {
    pub steps: i64,
    pub rejected_steps: i64,
    pub dt_min: f64,
    pub dt_max: f64,
    /// (kind, largest estimate relative to its tolerance), kinds of
    /// `integrate::adaptive::KINDS`.
    pub error_estimate: Vec<(String, f64)>,
}

/// How a run of the settings `s` chose its steps, as recorded in `result.settings`
/// (`step_control`) and the NetCDF attribute `solver_step_control`: error control, or a
/// fixed step and why. `valves`: the circuit has valves, whose switches an error-controlled
/// step locates as events (docs/physics.md §10, "The default run").
pub fn step_control(s: &Requested, valves: bool) -> String {
    if let Some(rtol) = s.rtol {
        let events = if valves {
            "; valve switches located as events"
        } else {
            ""
        };
        return format!("error control (rtol {}){events}", py_g(rtol));
    }
    if s.dt.is_some() {
        return "fixed step (dt)".into();
    }
    if s.method == "rk4" {
        return "fixed step (method rk4 has no error estimate; dopri5 is its error-controlled pair)"
            .into();
    }
    // the default tolerance dropped: a checkpointed run (a checkpoint does not carry the
    // controller's state)
    "fixed step (checkpoints need a fixed step: give dt to choose it)".into()
}

/// The settings and facts recorded with a result, in the order they are shown: the requested
/// settings and the step control, then (`ran`: after the run) what the run did. An error
/// estimate of a kind the circuit has none of (0) is left out, pressure and flow always kept;
/// `periodic_reached` only for a run `until_periodic` (the stopping rule's own test).
pub fn recorded(s: &Requested, ran: Option<&Ran>, valves: bool) -> Vec<(String, Fact)> {
    let mut facts: Vec<(String, Fact)> = vec![
        ("period".into(), Fact::Real(s.period)),
        ("cycles".into(), Fact::Count(s.cycles)),
        ("method".into(), Fact::Text(s.method.clone())),
        ("output_every".into(), Fact::Real(s.output_every)),
        ("rho_infty".into(), Fact::Real(s.rho_infty)),
        ("until_periodic".into(), s.until_periodic.into()),
        ("rtol".into(), s.rtol.into()),
        ("start".into(), Fact::Text(s.start.clone())),
        ("step_control".into(), Fact::Text(step_control(s, valves))),
    ];
    let Some(ran) = ran else {
        return facts;
    };
    facts[2].1 = Fact::Text(ran.method.clone()); // the method chosen, in the asked one's place
    facts.extend([
        ("dt".into(), Fact::Real(ran.dt)),
        ("cycles_run".into(), Fact::Count(ran.cycles_run)),
        ("periodic_error".into(), Fact::Real(ran.periodic_error)),
        ("rk4_dt_max".into(), ran.rk4_dt_max.into()),
    ]);
    if let Some(c) = &ran.control {
        facts.extend([
            ("steps".into(), Fact::Count(c.steps)),
            ("rejected_steps".into(), Fact::Count(c.rejected_steps)),
            ("dt_min".into(), Fact::Real(c.dt_min)),
            ("dt_max".into(), Fact::Real(c.dt_max)),
        ]);
        let always = &KINDS[..2]; // pressure and flow
        for (kind, v) in &c.error_estimate {
            if *v > 0.0 || always.contains(&kind.as_str()) {
                facts.push((format!("error_estimate_{kind}"), Fact::Real(*v)));
            }
        }
    }
    if let Some(tol) = s.until_periodic {
        // the core stops on change < tolerance; NaN is not reached
        facts.push((
            "periodic_reached".into(),
            Fact::Flag(ran.periodic_error < tol),
        ));
    }
    facts
}

/// How a model's vessels were cut, recorded with a result and printed by the CLI:
/// `segments_total`, `segments_auto` (those of vessels cut by the `auto` rule, the default
/// where a vessel states no `segments` and the model no `max_length`), `segmentation`
/// (`auto`, `explicit` or `auto+explicit`) and the rule's `segmentation_rtol` (absent when no
/// vessel is cut by it).
pub fn segmentation(total: i64, auto: i64, auto_rtol: Option<f64>) -> Vec<(String, Fact)> {
    let how = match auto {
        0 => "explicit",
        a if a == total => "auto",
        _ => "auto+explicit",
    };
    vec![
        ("segments_total".into(), Fact::Count(total)),
        ("segments_auto".into(), Fact::Count(auto)),
        ("segmentation".into(), Fact::Text(how.into())),
        ("segmentation_rtol".into(), auto_rtol.into()),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asked() -> Requested {
        Requested {
            period: 0.8,
            cycles: 3,
            method: "auto".into(),
            output_every: 8e-4,
            rho_infty: 0.5,
            until_periodic: None,
            rtol: Some(1e-3),
            dt: None,
            start: "steady".into(),
        }
    }

    fn get<'a>(facts: &'a [(String, Fact)], key: &str) -> Option<&'a Fact> {
        facts.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }

    #[test]
    fn the_step_control_says_why_a_step_is_fixed() {
        let mut s = asked();
        assert_eq!(step_control(&s, false), "error control (rtol 0.001)");
        assert_eq!(
            step_control(&s, true),
            "error control (rtol 0.001); valve switches located as events"
        );
        s.rtol = None;
        s.dt = Some(1e-4);
        assert_eq!(step_control(&s, true), "fixed step (dt)");
        s.dt = None;
        s.method = "rk4".into();
        assert!(step_control(&s, false).starts_with("fixed step (method rk4 has no error"));
        s.method = "generalized-alpha".into();
        assert!(step_control(&s, false).starts_with("fixed step (checkpoints need"));
    }

    #[test]
    fn segmentation_says_which_rule_cut_the_vessels() {
        let how = |total, auto| segmentation(total, auto, Some(0.01))[2].1.clone();
        assert_eq!(how(100, 0), Fact::Text("explicit".into()));
        assert_eq!(how(100, 100), Fact::Text("auto".into()));
        assert_eq!(how(100, 40), Fact::Text("auto+explicit".into()));
        assert_eq!(segmentation(5, 0, None)[3].1, Fact::Absent);
    }

    #[test]
    fn before_the_run_only_the_request_is_recorded() {
        let facts = recorded(&asked(), None, false);
        let keys: Vec<&str> = facts.iter().map(|(k, _)| k.as_str()).collect();
        assert_eq!(
            keys,
            [
                "period",
                "cycles",
                "method",
                "output_every",
                "rho_infty",
                "until_periodic",
                "rtol",
                "start",
                "step_control"
            ]
        );
        assert_eq!(get(&facts, "until_periodic"), Some(&Fact::Absent));
        assert_eq!(get(&facts, "cycles"), Some(&Fact::Count(3)));
    }

    #[test]
    fn after_the_run_its_facts_follow_and_empty_kinds_are_left_out() {
        let mut s = asked();
        s.until_periodic = Some(1e-3);
        let ran = Ran {
            method: "generalized-alpha".into(),
            dt: 2e-3,
            cycles_run: 7,
            periodic_error: 5e-4,
            rk4_dt_max: None,
            control: Some(Controlled {
                steps: 400,
                rejected_steps: 12,
                dt_min: 1e-5,
                dt_max: 1e-2,
                error_estimate: KINDS
                    .iter()
                    .zip([0.4, 0.0, 0.0, 0.7])
                    .map(|(k, v)| (k.to_string(), v))
                    .collect(),
            }),
        };
        let facts = recorded(&s, Some(&ran), false);
        // the chosen method replaces the asked one in its place
        assert_eq!(
            facts[2],
            ("method".to_string(), Fact::Text("generalized-alpha".into()))
        );
        assert_eq!(get(&facts, "steps"), Some(&Fact::Count(400)));
        assert_eq!(get(&facts, "rk4_dt_max"), Some(&Fact::Absent));
        // pressure and flow always; volume (0: no chambers) left out; species kept
        assert_eq!(get(&facts, "error_estimate_flow"), Some(&Fact::Real(0.0)));
        assert_eq!(get(&facts, "error_estimate_volume"), None);
        assert_eq!(
            get(&facts, "error_estimate_species"),
            Some(&Fact::Real(0.7))
        );
        assert_eq!(get(&facts, "periodic_reached"), Some(&Fact::Flag(true)));
        let not = Ran {
            periodic_error: f64::NAN,
            control: None,
            ..ran
        };
        let facts = recorded(&s, Some(&not), false);
        assert_eq!(get(&facts, "periodic_reached"), Some(&Fact::Flag(false)));
        assert_eq!(get(&facts, "steps"), None);
    }
}
