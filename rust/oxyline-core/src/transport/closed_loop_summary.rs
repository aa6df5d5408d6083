//! The closed loop's summary over its recorded (periodic) cycle (docs/oxygen.md "Oxygen around
//! a closed loop"): arterial and mixed-venous PO2, saturation and content (the blood the left
//! and right hearts eject, flow-weighted over the cycle), VO2 per organ and in total, the lungs'
//! uptake, the cardiac output, Fick's principle's residual and the loop's per-step mass-balance
//! residual; and every compartment variable's flow-weighted cycle mean by every branch.
//!
//! Units are the parameter set's published ones (mmHg, mL O2 per L blood, mL/min, L/min), the
//! units the loop is specified in. Every sum runs in numpy's pairwise order (`model::sum`), so
//! the values are bit for bit those of the former numpy reductions of the same record.

use super::closed_loop::ClosedLoopRun;
use super::closed_loop_params::ML_O2;
use crate::error::{Error, Result};
use crate::model::sum::pairwise;
use crate::model::units::MMHG;

/// The compartment variables recorded per step, in the order of [`LoopSummary::weighted`].
pub const WEIGHTED: [&str; 5] = ["volume", "total", "po2", "saturation", "vo2"];

/// The loop's cycle summary (published units) and the flow-weighted table.
#[derive(Debug, Clone, PartialEq)]
pub struct LoopSummary {
    /// Saturation of the left heart's ejection (into the arteries or the tree's root).
    pub sao2: f64,
    /// Saturation of the right heart's ejection (mixed venous).
    pub svo2: f64,
    /// PO2 (mmHg) of those ejections.
    pub pao2: f64,
    pub pvo2: f64,
    /// O2 content (mL O2 per L blood): arterial the net O2 ejected per volume ejected.
    pub cao2: f64,
    pub cvo2: f64,
    /// The loop's consumption (mL/min): its compartments' and the tree wall's.
    pub vo2: f64,
    /// Every consuming compartment's cycle-mean VO2 (mL/min), in compartment order.
    pub vo2_organs: Vec<(String, f64)>,
    pub vo2_tree_wall: f64,
    /// The lungs' cycle-mean uptake (mL/min).
    pub lung_uptake: f64,
    /// L/min.
    pub cardiac_output: f64,
    /// |VO2 − CO (CaO2 − CvO2)| / VO2.
    pub fick_residual: f64,
    /// Largest |ΔN − dt (uptake − VO2 − wall)| of a step over the largest amount N.
    pub mass_balance_residual: f64,
    /// With a tree: the O2 each outlet delivers to its organ (mL/min), in organ order.
    pub do2_organs: Vec<(String, f64)>,
    /// With a tree: the cycle-mean PO2 (mmHg) of every segment, by vessel (in the order the
    /// tree's segments first name it; its segments in flow order).
    pub po2_along: Vec<(String, Vec<f64>)>,
    /// Per variable of [`WEIGHTED`] (PO2 in mmHg): the cycle mean of every compartment's value
    /// weighted by every branch's flow, row-major branches × compartments.
    pub weighted: Vec<Vec<f64>>,
}

/// The record's shape and names.
struct Shape<'a> {
    steps: usize,
    compartments: &'a [String],
    branches: &'a [String],
}

impl Shape<'_> {
    fn compartment(&self, name: &str) -> Result<usize> {
        position(self.compartments, name, "compartment")
    }

    fn branch(&self, name: &str) -> Result<usize> {
        position(self.branches, name, "branch")
    }
}

fn position(names: &[String], name: &str, what: &str) -> Result<usize> {
    names.iter().position(|n| n == name).ok_or_else(|| {
        Error::model(
            "closed-loop summary",
            format!("the loop has no {what} '{name}'"),
        )
    })
}

/// Column `k` of a row-major table of `width` columns.
fn column(table: &[f64], width: usize, k: usize) -> Vec<f64> {
    table.iter().skip(k).step_by(width).copied().collect()
}

/// Every row's sum of a row-major table of `width` columns (numpy's `sum(axis=1)`).
fn row_sums(table: &[f64], width: usize) -> Vec<f64> {
    table.chunks_exact(width).map(pairwise).collect()
}

fn mean(a: &[f64]) -> f64 {
    pairwise(a) / a.len() as f64
}

/// Σ q x / Σ q over the cycle.
fn weighted_mean(q: &[f64], x: &[f64]) -> f64 {
    let products: Vec<f64> = q.iter().zip(x).map(|(q, x)| q * x).collect();
    pairwise(&products) / pairwise(q)
}

/// The recorded variable `name` of [`WEIGHTED`] per step × compartment (PO2 in mmHg).
fn variable(run: &ClosedLoopRun, name: &str) -> Vec<f64> {
    match name {
        "volume" => run.volume.clone(),
        "total" => run.total.clone(),
        "po2" => run.po2.iter().map(|p| p / MMHG).collect(),
        "saturation" => run.saturation.clone(),
        _ => run.vo2.clone(),
    }
}

/// The flow-weighted table of one variable: branches × compartments.
fn weighted_table(run: &ClosedLoopRun, shape: &Shape, values: &[f64]) -> Vec<f64> {
    let (nc, nb) = (shape.compartments.len(), shape.branches.len());
    let columns: Vec<Vec<f64>> = (0..nc).map(|c| column(values, nc, c)).collect();
    let mut out = Vec::with_capacity(nb * nc);
    for b in 0..nb {
        let q = column(&run.flow, nb, b);
        out.extend(columns.iter().map(|x| weighted_mean(&q, x)));
    }
    out
}

/// The loop's consumption, uptake and mass balance per step: (VO2 of the compartments, the
/// tree's wall uptake, the lungs' uptake), each per step (mol/s).
struct Rates {
    vo2: Vec<f64>,
    wall: Vec<f64>,
    uptake: Vec<f64>,
}

impl Rates {
    fn of(run: &ClosedLoopRun, shape: &Shape) -> Self {
        let wall = if run.tree_wall.is_empty() {
            vec![0.0; shape.steps]
        } else {
            run.tree_wall.clone()
        };
        Rates {
            vo2: row_sums(&run.vo2, shape.compartments.len()),
            wall,
            uptake: row_sums(&run.uptake, shape.branches.len()),
        }
    }

    /// max |ΔN − dt (uptake − VO2 − wall)| / max N over the cycle's steps.
    fn mass_balance_residual(&self, run: &ClosedLoopRun, dt: f64) -> f64 {
        let mut before = run.amount_start;
        let mut worst: f64 = 0.0;
        let mut largest = run.amount_start;
        for (s, &n) in run.amount.iter().enumerate() {
            let rate = self.uptake[s] - self.vo2[s] - self.wall[s];
            worst = worst.max(((n - before) - dt * rate).abs());
            largest = largest.max(n);
            before = n;
        }
        worst / largest
    }
}

/// The arterial flow per step (into the tree's root, else the left heart's ejection) and its
/// flow-weighted content (mol/m³; into a tree the root's flux over its flow: a closing tanh
/// valve leaks back a little blood of the root's content, not the left heart's: the left
/// heart's flow-weighted content is off by ~5e-8 of VO2 there).
struct Arterial {
    flow: Vec<f64>,
    content: f64,
}

impl Arterial {
    fn of(run: &ClosedLoopRun, shape: &Shape, total: &[f64]) -> Result<Self> {
        if !run.tree_inflow.is_empty() {
            let content = pairwise(&run.tree_in_flux) / pairwise(&run.tree_inflow);
            return Ok(Arterial {
                flow: run.tree_inflow.clone(),
                content,
            });
        }
        let flow = column(
            &run.flow,
            shape.branches.len(),
            shape.branch("ejection_left")?,
        );
        let content = weighted_mean(&flow, total);
        Ok(Arterial { flow, content })
    }
}

/// Every consuming compartment's cycle-mean VO2 (mL/min).
fn organ_vo2(run: &ClosedLoopRun, shape: &Shape, to_ml_min: f64) -> Vec<(String, f64)> {
    let nc = shape.compartments.len();
    (0..nc)
        .map(|c| (c, column(&run.vo2, nc, c)))
        .filter(|(_, v)| v.iter().any(|x| *x != 0.0))
        .map(|(c, v)| (shape.compartments[c].clone(), mean(&v) * to_ml_min))
        .collect()
}

/// The O2 each tree outlet delivers (mL/min), named by its organ (none without a tree).
fn organ_delivery(run: &ClosedLoopRun, organs: &[String], to_ml_min: f64) -> Vec<(String, f64)> {
    if run.tree_out_flux.is_empty() {
        return Vec::new();
    }
    organs
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let flux = column(&run.tree_out_flux, organs.len(), k);
            (name.clone(), mean(&flux) * to_ml_min)
        })
        .collect()
}

/// The cycle-mean PO2 (mmHg) of every tree segment (named `vessel:k`), grouped by vessel
/// (none without a tree). The recorded rows are added in step order and the sums divided by
/// the steps: numpy's `mean(axis=0)` of the [step, segment] table in mmHg, bit for bit.
fn po2_along(run: &ClosedLoopRun, steps: usize) -> Vec<(String, Vec<f64>)> {
    let n = run.tree_segments.len();
    if n == 0 || steps == 0 {
        return Vec::new();
    }
    let mut sums = vec![0.0; n];
    for row in run.tree_po2.chunks_exact(n) {
        for (sum, p) in sums.iter_mut().zip(row) {
            *sum += p / MMHG;
        }
    }
    let mut out: Vec<(String, Vec<f64>)> = Vec::new();
    let mut at: std::collections::HashMap<&str, usize> = std::collections::HashMap::new();
    for (name, sum) in run.tree_segments.iter().zip(sums) {
        let vessel = name.rsplit_once(':').map_or(name.as_str(), |(v, _)| v);
        let k = *at.entry(vessel).or_insert_with(|| {
            out.push((vessel.to_owned(), Vec::new()));
            out.len() - 1
        });
        out[k].1.push(sum / steps as f64);
    }
    out
}

/// The summary of the recorded cycle `run` of a loop with these compartments, branches and
/// organs (the tree's outlets, in order), stepped at `dt` (s).
pub fn summarise(
    run: &ClosedLoopRun,
    compartments: &[String],
    branches: &[String],
    organs: &[String],
    dt: f64,
) -> Result<LoopSummary> {
    let shape = Shape {
        steps: run.time.len(),
        compartments,
        branches,
    };
    let nc = compartments.len();
    let weighted: Vec<Vec<f64>> = WEIGHTED
        .iter()
        .map(|name| weighted_table(run, &shape, &variable(run, name)))
        .collect();
    let (lh, rh) = (
        shape.compartment("left_heart")?,
        shape.compartment("right_heart")?,
    );
    let venous = shape.branch("ejection_right")? * nc + rh;
    let [_, total, po2, saturation, _] = [0, 1, 2, 3, 4].map(|k| &weighted[k]);
    let arterial = Arterial::of(run, &shape, &column(&run.total, nc, lh))?;
    let at_left = |values: &[f64]| weighted_mean(&arterial.flow, &column(values, nc, lh));
    let rates = Rates::of(run, &shape);
    let to_ml_min = 60.0 / ML_O2;
    let vo2 = mean(&rates.vo2) + mean(&rates.wall);
    let co = mean(&arterial.flow);
    let (ca, cv) = (arterial.content, total[venous]);
    Ok(LoopSummary {
        sao2: at_left(&run.saturation),
        svo2: saturation[venous],
        pao2: at_left(&variable(run, "po2")),
        pvo2: po2[venous],
        cao2: ca / ML_O2 * 1e-3,
        cvo2: cv / ML_O2 * 1e-3,
        vo2: vo2 * to_ml_min,
        vo2_organs: organ_vo2(run, &shape, to_ml_min),
        vo2_tree_wall: mean(&rates.wall) * to_ml_min,
        lung_uptake: mean(&rates.uptake) * to_ml_min,
        cardiac_output: co * 6e4,
        fick_residual: (vo2 - co * (ca - cv)).abs() / vo2,
        mass_balance_residual: rates.mass_balance_residual(run, dt),
        do2_organs: organ_delivery(run, organs, to_ml_min),
        po2_along: po2_along(run, shape.steps),
        weighted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A loop of three compartments (left heart, organ, right heart) and three branches over
    /// four steps of 0.25 s, with values whose summary is worked out by hand.
    fn record() -> (ClosedLoopRun, Vec<String>, Vec<String>) {
        let names = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let comps = names(&["left_heart", "organ", "right_heart"]);
        let branches = names(&["ejection_left", "organ_out", "ejection_right"]);
        let vo2 = 2e-6; // mol/s, the organ's
        let uptake = 2e-6; // mol/s, the lungs' (through the right heart's ejection)
        let mut run = ClosedLoopRun {
            time: vec![0.25, 0.5, 0.75, 1.0],
            // per step: ejection_left, organ_out, ejection_right (m³/s)
            flow: vec![
                1e-4, 1e-4, 0.0, //
                3e-4, 1e-4, 1e-4, //
                0.0, 1e-4, 3e-4, //
                0.0, 1e-4, 0.0,
            ],
            saturation: vec![
                0.9, 0.7, 0.6, //
                0.98, 0.7, 0.8, //
                0.5, 0.7, 0.7, //
                0.5, 0.7, 0.6,
            ],
            po2: [
                95.0, 40.0, 35.0, 97.0, 40.0, 45.0, 20.0, 40.0, 40.0, 20.0, 40.0, 35.0,
            ]
            .iter()
            .map(|p| p * MMHG)
            .collect(),
            // mol/m³: arterial 8 then 9 while ejecting, venous 6 then 5
            total: vec![
                8.0, 0.0, 1.0, //
                9.0, 0.0, 6.0, //
                0.0, 0.0, 5.0, //
                0.0, 0.0, 1.0,
            ],
            vo2: [0.0, vo2, 0.0].repeat(4),
            volume: [1e-4, 2e-4, 1e-4].repeat(4),
            uptake: [0.0, 0.0, uptake].repeat(4),
            amount_start: 1e-3,
            ..Default::default()
        };
        // the amount follows the balance exactly: uptake − VO2 = 0
        run.amount = vec![1e-3; 4];
        (run, comps, branches)
    }

    #[test]
    fn arterial_and_mixed_venous_values_are_the_ejections_flow_weighted_means() {
        let (run, comps, branches) = record();
        let s = summarise(&run, &comps, &branches, &[], 0.25).unwrap();
        // (1 · 0.9 + 3 · 0.98) / 4 and (1 · 0.8 + 3 · 0.7) / 4
        assert!((s.sao2 - 0.96).abs() < 1e-15, "{}", s.sao2);
        assert!((s.svo2 - 0.725).abs() < 1e-15, "{}", s.svo2);
        assert!((s.pao2 - 96.5).abs() < 1e-12, "{}", s.pao2);
        assert!((s.pvo2 - 41.25).abs() < 1e-12, "{}", s.pvo2);
        // contents: (8 + 27) / 4 and (6 + 15) / 4 mol/m³, in mL O2 per L
        assert!((s.cao2 - 8.75 / ML_O2 * 1e-3).abs() < 1e-12);
        assert!((s.cvo2 - 5.25 / ML_O2 * 1e-3).abs() < 1e-12);
        // cardiac output 1e-4 m³/s = 6 L/min
        assert!((s.cardiac_output - 6.0).abs() < 1e-12);
        let ml_min = 2e-6 * 60.0 / ML_O2;
        assert_eq!(s.vo2_organs.len(), 1);
        assert_eq!(s.vo2_organs[0].0, "organ");
        assert!((s.vo2_organs[0].1 - ml_min).abs() < 1e-12 * ml_min);
        assert!((s.vo2 - ml_min).abs() < 1e-12 * ml_min);
        assert!((s.lung_uptake - ml_min).abs() < 1e-12 * ml_min);
        assert_eq!(s.vo2_tree_wall, 0.0);
        assert!(s.do2_organs.is_empty());
        assert_eq!(s.mass_balance_residual, 0.0);
        // Fick: VO2 − CO (Ca − Cv) = 2e-6 − 1e-4 · 3.5 mol/s, over VO2
        let fick = (2e-6f64 - 1e-4 * 3.5).abs() / 2e-6;
        assert!((s.fick_residual - fick).abs() < 1e-12 * fick);
    }

    #[test]
    fn the_weighted_table_weights_every_compartment_by_every_branch() {
        let (run, comps, branches) = record();
        let s = summarise(&run, &comps, &branches, &[], 0.25).unwrap();
        let k = WEIGHTED.iter().position(|n| *n == "saturation").unwrap();
        let table = &s.weighted[k];
        assert_eq!(table.len(), 9);
        // the organ's flow is steady: the organ's saturation 0.7, the right heart's the mean
        assert!((table[3 + 1] - 0.7).abs() < 1e-15);
        assert!((table[3 + 2] - (0.6 + 0.8 + 0.7 + 0.6) / 4.0).abs() < 1e-15);
        assert_eq!(table[2 * 3 + 2], s.svo2);
    }

    #[test]
    fn a_step_off_the_balance_is_its_residual_over_the_largest_amount() {
        let (mut run, comps, branches) = record();
        run.amount[2] += 1e-9; // two steps off: into step 3 and out of step 4
        let s = summarise(&run, &comps, &branches, &[], 0.25).unwrap();
        let want = 1e-9 / (1e-3 + 1e-9);
        assert!((s.mass_balance_residual - want).abs() < 1e-6 * want);
    }

    #[test]
    fn po2_along_is_every_segments_cycle_mean_grouped_by_vessel() {
        let (mut run, comps, branches) = record();
        // two vessels over the four steps: 'a' constant 80 mmHg in both its segments,
        // 'b' a ramp 10, 20, 30, 40 mmHg (mean 25) in its one segment
        run.tree_segments = vec!["a:0".into(), "a:1".into(), "b:0".into()];
        run.tree_po2 = (1..=4)
            .flat_map(|s| [80.0, 80.0, 10.0 * f64::from(s)])
            .map(|p| p * MMHG)
            .collect();
        let s = summarise(&run, &comps, &branches, &[], 0.25).unwrap();
        assert_eq!(s.po2_along.len(), 2);
        let (a, b) = (&s.po2_along[0], &s.po2_along[1]);
        assert_eq!(
            (a.0.as_str(), a.1.len(), b.0.as_str(), b.1.len()),
            ("a", 2, "b", 1)
        );
        // a constant profile's mean is the constant, to the rounding of the mmHg conversion
        for x in &a.1 {
            assert!((x - 80.0).abs() < 1e-12, "{x}");
        }
        assert!((b.1[0] - 25.0).abs() < 1e-12, "{}", b.1[0]);
        // without a tree there is nothing along it
        let (run, ..) = record();
        let s = summarise(&run, &comps, &branches, &[], 0.25).unwrap();
        assert!(s.po2_along.is_empty());
    }

    #[test]
    fn a_loop_without_its_hearts_is_named() {
        let (run, _, branches) = record();
        let comps = vec!["a".to_string(), "organ".into(), "right_heart".into()];
        let e = summarise(&run, &comps, &branches, &[], 0.25).unwrap_err();
        assert!(e.to_string().contains("no compartment 'left_heart'"), "{e}");
    }
}
