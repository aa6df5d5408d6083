//! What the O2 loop reads from its closed-loop heart's run, by unknown name (the heart models
//! of `oxyline.closed_loop.heart_model`): the branch flows in the loop's branch order, the
//! named series recorded for the caller and the arterial tree's inflow and venous pressure.
//!
//! svZeroDSolver's block (docs/physics.md §1.10): a valve's flow counts only while it is open
//! (closed when the pressure behind does not exceed the pressure in front and its flow is not
//! positive; a closed valve's inductor flow is left out of the volume balances). The lungs'
//! flow is the pulmonary bed's drain through R_pd, (P_pul − P_LA)/R_pd (its capacitor C_p
//! smooths the right ventricle's ejection; over a periodic cycle both carry the same volume).
//! The native two-ventricle heart: its valves' and resistances' flows. The shunt takes
//! `shunt_fraction` of the lungs' flow.

use super::closed_loop_heart::{HeartSpec, Series};
use crate::error::{Error, Result};
use serde::Deserialize;
use serde_json::Value;

/// The closed-loop heart of `oxyline.closed_loop.heart_model`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum HeartKind {
    SvzerodBlock,
    TwoVentricle,
}

/// The loop a heart drives: its heart, organ beds (in order), shunt fraction and whether an
/// arterial tree replaces the arterial pool.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeriesOf {
    pub heart: HeartKind,
    pub organs: Vec<String>,
    pub shunt_fraction: f64,
    #[serde(default)]
    pub tree: bool,
}

const BLOCK: &str = "heart_pulmonary";

fn one(name: impl Into<String>) -> Series {
    Series {
        terms: vec![(name.into(), 1.0)],
        valve: None,
    }
}

fn scaled(s: &Series, factor: f64) -> Series {
    Series {
        terms: s
            .terms
            .iter()
            .map(|(n, c)| (n.clone(), c * factor))
            .collect(),
        valve: s.valve.clone(),
    }
}

/// The block's series by name; R_pd (SI) is read from the heart's canonical model.
fn block(model: &Value) -> Result<Vec<(&'static str, Series)>> {
    let pr = |k: &str| format!("pressure at {BLOCK}: {k}");
    let pulmonary = format!("volume of {BLOCK}: pulmonary"); // P_pul (Pa), an element unknown
    let valve = |name: &str, behind: String, front: String| Series {
        terms: vec![(format!("flow in {BLOCK}: {name} valve"), 1.0)],
        valve: Some((behind, front)),
    };
    let r_pd = model["vessels"]
        .as_array()
        .and_then(|vs| {
            vs.iter()
                .find_map(|v| v.get(BLOCK)?.get("pulmonary_resistance")?.as_f64())
        })
        .ok_or_else(|| {
            Error::model(
                "closed-loop heart",
                format!("its model has no '{BLOCK}' element with a 'pulmonary_resistance'"),
            )
        })?;
    let lungs = Series {
        terms: vec![
            (pulmonary.clone(), 1.0 / r_pd),
            (pr("left atrium"), -1.0 / r_pd),
        ],
        valve: None,
    };
    Ok(vec![
        ("aortic", valve("aortic", pr("left ventricle"), pr("aorta"))),
        (
            "aortic_outflow",
            one(format!("flow in {BLOCK}: aortic outflow")),
        ),
        (
            "tricuspid",
            valve("tricuspid", pr("right atrium"), pr("right ventricle")),
        ),
        (
            "pulmonary",
            valve("pulmonary", pr("right ventricle"), pulmonary),
        ),
        (
            "mitral",
            valve("mitral", pr("left atrium"), pr("left ventricle")),
        ),
        ("veins", one("pressure at veins_in")),
        ("lungs", lungs),
    ])
}

fn two_ventricle() -> Vec<(&'static str, Series)> {
    let q = |name: &str| one(format!("flow in vessel '{name}'"));
    vec![
        ("aortic", q("aortic_valve")),
        ("aortic_outflow", q("aortic_valve")),
        ("tricuspid", q("tricuspid_valve")),
        ("pulmonary", q("pulmonary_valve")),
        ("mitral", q("mitral_valve")),
        ("lungs", one("flow in vessel 'lungs' resistance")),
        ("veins", one("pressure at veins_in")),
    ]
}

impl HeartSpec {
    /// Fills `branches`, `record` and the tree's series from `series_of` (when given): the
    /// left heart ejects through the aortic valve into the arterial pool (into the tree: its
    /// root's own flow, the aortic outflow).
    pub fn derive_series(&mut self) -> Result<()> {
        let Some(of) = self.series_of.take() else {
            return Ok(());
        };
        let mut named: Vec<(String, Series)> = match of.heart {
            HeartKind::SvzerodBlock => block(&self.model)?,
            HeartKind::TwoVentricle => two_ventricle(),
        }
        .into_iter()
        .map(|(n, s)| (n.to_string(), s))
        .collect();
        named.extend(
            of.organs
                .iter()
                .map(|k| (k.clone(), one(format!("flow in vessel '{k}' resistance")))),
        );
        let get = |name: &str| -> &Series {
            &named
                .iter()
                .find(|(n, _)| n == name)
                .expect("every series is named above")
                .1
        };
        let organs: Vec<Series> = of.organs.iter().map(|k| get(k).clone()).collect();
        let mut branches = Vec::new();
        if !of.tree {
            branches.push(get("aortic").clone());
            branches.extend(organs.iter().cloned());
        }
        branches.extend(organs);
        branches.extend([
            get("tricuspid").clone(),
            get("pulmonary").clone(),
            scaled(get("lungs"), 1.0 - of.shunt_fraction),
            scaled(get("lungs"), of.shunt_fraction),
            get("mitral").clone(),
        ]);
        self.branches = branches;
        self.tree_inflow = Some(get("aortic_outflow").clone());
        self.tree_venous_pressure = Some(get("veins").clone());
        self.record = named;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn spec(heart: &str, tree: bool) -> HeartSpec {
        serde_json::from_value(json!({
            "model": {"vessels": [{"name": "heart", "heart_pulmonary":
                                   {"pulmonary_resistance": 4.0}}]},
            "dt": 1e-3, "cycles": 2,
            "series_of": {"heart": heart, "organs": ["brain", "gut"], "shunt_fraction": 0.25,
                          "tree": tree}
        }))
        .unwrap()
    }

    /// The pool loop's branches: ejection, organ inflows, organ outflows, venous return,
    /// right ejection, lungs split by the shunt fraction, filling; the two lung branches add
    /// up to the pulmonary drain (P_pul − P_LA)/R_pd.
    #[test]
    fn block_branches_follow_the_loops_order_and_split_the_lungs() {
        let mut s = spec("svzerod-block", false);
        s.derive_series().unwrap();
        assert_eq!(s.branches.len(), 1 + 2 + 2 + 5);
        assert_eq!(
            s.branches[1].terms[0].0,
            "flow in vessel 'brain' resistance"
        );
        let (cap, shunt) = (&s.branches[7], &s.branches[8]);
        assert_eq!(
            cap.terms[0],
            ("volume of heart_pulmonary: pulmonary".into(), 0.75 / 4.0)
        );
        assert_eq!(
            shunt.terms[1],
            (
                "pressure at heart_pulmonary: left atrium".into(),
                -0.25 / 4.0
            )
        );
        assert!(s.branches[0].valve.is_some());
        assert_eq!(s.record.len(), 7 + 2);
    }

    #[test]
    fn tree_loop_has_no_arterial_branches_and_the_block_needs_its_resistance() {
        let mut s = spec("two-ventricle", true);
        s.derive_series().unwrap();
        assert_eq!(s.branches.len(), 2 + 5);
        assert_eq!(
            s.tree_inflow.unwrap().terms[0].0,
            "flow in vessel 'aortic_valve'"
        );
        let mut s = spec("svzerod-block", true);
        s.model = json!({"vessels": []});
        let e = s.derive_series().unwrap_err().to_string();
        assert!(e.contains("pulmonary_resistance"), "{e}");
    }
}
