//! Oxygen around a closed circulation (docs/oxygen.md "Oxygen around a closed loop"): well-mixed
//! compartments (heart chambers, arterial and venous pools, organ beds; `compartment.rs`)
//! joined by branches that carry blood at the flows of the circulation's flow solution, one of
//! them (or more) through the lungs (`lung.rs`). There is no inlet: the loop's O2 amount
//! N = Σ V C_t changes only by the lungs' uptake and the organs' consumption,
//!
//! ```text
//! N(t₁) − N(t₀) = ∫ (Σ lung uptake − Σ VO2) dt,
//! ```
//!
//! exactly per step (every branch flux leaves one compartment and enters another with the same
//! value). Fick's principle follows at periodic steady state: over a cycle the systemic
//! compartments store nothing, so Σ VO2 equals the O2 pumped into the systemic arteries minus
//! the O2 returned by the veins.
//!
//! A step is backward Euler in the concentrations (upwind branch fluxes on the sign of the
//! flow): compartment volumes follow dV/dt = net inflow, and the coupled implicit system is
//! solved by Gauss–Seidel sweeps in the listed order (listing the compartments in flow order
//! makes one sweep nearly exact; the loop closes with a contraction factor ≈ Π dt q/(V + dt q)).

use super::closed_loop_tree::ArterialTree;
use super::compartment::{self, Consumption};
use super::lung::LungExchange;
use crate::error::{Error, Result};
use crate::hemoglobin::{Binding, BindingSpec};
use serde::Deserialize;

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ConsumptionSpec {
    None,
    Fixed { rate: f64 },
    MichaelisMenten { vmax: f64, km: f64 },
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompartmentSpec {
    pub name: String,
    /// Blood volume at the start (m³).
    pub volume: f64,
    /// Initial free PO2 (Pa): with the volumes, it sets the loop's initial O2 amount.
    pub initial_po2: f64,
    #[serde(default = "none_consumption")]
    pub consumption: ConsumptionSpec,
}

fn none_consumption() -> ConsumptionSpec {
    ConsumptionSpec::None
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LungSpec {
    pub alveolar_po2: f64,
    pub diffusing_capacity: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BranchSpec {
    pub name: String,
    pub from: usize,
    pub to: usize,
    #[serde(default)]
    pub lungs: Option<LungSpec>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosedLoopSpec {
    pub compartments: Vec<CompartmentSpec>,
    pub branches: Vec<BranchSpec>,
    /// Oxygen binding of blood (SI: solubility mol m⁻³ Pa⁻¹, p50 Pa); `hill` for haemoglobin.
    pub binding: BindingSpec,
    /// A segment-resolved arterial tree between compartment `from` and the organs (None: the
    /// branches join the compartments directly).
    #[serde(default)]
    pub tree: Option<TreeSpec>,
    /// How the periodic steady state is found (`run_periodic`).
    #[serde(default)]
    pub shooting: Shooting,
    /// Correct the flow table first so that every compartment's volume is periodic, the
    /// tree's flows counted (`closed_loop_balance`); the run's `flow` is the table it used.
    #[serde(default)]
    pub balance: bool,
    /// The closed-loop heart whose run gives the flow table (and the tree's boundary tables);
    /// its table is always balanced (`closed_loop_heart`).
    #[serde(default)]
    pub heart: Option<super::closed_loop_heart::HeartSpec>,
    /// The heart run's period (s); the O2 loop's cycle is the same.
    #[serde(default)]
    pub period: Option<f64>,
}

/// The periodic-state solver of `run_periodic`: Anderson acceleration of the cycle map (one
/// cycle per iteration), or Newton with a finite-difference Jacobian (one cycle per unknown
/// and iteration; the earlier method, kept for comparison).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Shooting {
    #[default]
    Anderson,
    Newton,
}

/// The arterial tree of a closed loop (`closed_loop_tree`): an open network model (canonical
/// SI JSON with an `oxygen` section) whose root boundary `inlet` is fed by compartment `from`
/// and whose outlet boundaries feed compartments.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TreeSpec {
    pub model: String,
    pub inlet: String,
    pub from: usize,
    pub outlets: Vec<TreeOutlet>,
    /// Flow cycles run before the recorded one (the tree forgets its zero start).
    #[serde(default = "default_flow_cycles")]
    pub flow_cycles: usize,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TreeOutlet {
    pub boundary: String,
    pub to: usize,
}

impl TreeSpec {
    /// Parses the JSON form; a malformed spec is a model error.
    pub fn from_json(json: &str) -> Result<Self> {
        serde_json::from_str(json).map_err(|e| Error::model("arterial tree", e.to_string()))
    }
}

fn default_flow_cycles() -> usize {
    40
}

impl ClosedLoopSpec {
    /// Parses the JSON form (the binding's and Python's); a malformed spec is a model error.
    /// A heart given by its kind has its series derived here.
    pub fn from_json(json: &str) -> Result<Self> {
        let mut spec: Self =
            serde_json::from_str(json).map_err(|e| Error::model("closed loop", e.to_string()))?;
        if let Some(heart) = spec.heart.as_mut() {
            heart.derive_series()?;
        }
        Ok(spec)
    }
}

/// What a step's sweeps hold fixed: its length and index, the compartments' end volumes and
/// outflow rates, and the branches entering each compartment.
struct StepPlan {
    dt: f64,
    s: usize,
    v1: Vec<f64>,
    q_out: Vec<f64>,
    incoming: Vec<Vec<usize>>,
}

/// What a step's sweeps carry from one to the next: the lungs' last end-capillary contents
/// (inflow content, end content), the tree's step-start state and the root content its step
/// last saw.
struct SweepState {
    lung_cache: Vec<(f64, f64)>,
    tree_start: Option<(Vec<f64>, Vec<f64>)>,
    tree_c_in: f64,
}

/// A closed circulation's O2 state.
pub struct ClosedLoop {
    pub names: Vec<String>,
    pub branch_names: Vec<String>,
    consumption: Vec<Consumption>,
    from: Vec<usize>,
    to: Vec<usize>,
    lungs: Vec<Option<LungExchange>>,
    binding: Binding,
    alpha: f64,
    /// Volume (m³), total and free concentration (mol/m³) per compartment.
    pub volume: Vec<f64>,
    pub total: Vec<f64>,
    pub free: Vec<f64>,
    /// Last step: O2 consumption per compartment, lung uptake and flux per branch (mol/s).
    pub vo2: Vec<f64>,
    pub uptake: Vec<f64>,
    pub flux: Vec<f64>,
    next: Vec<f64>,
    /// The arterial tree (`closed_loop_tree`), the compartment feeding its root and the
    /// compartment of every outlet.
    pub tree: Option<ArterialTree>,
    tree_from: usize,
    tree_to: Vec<usize>,
}

impl ClosedLoop {
    pub fn new(spec: &ClosedLoopSpec) -> Result<Self> {
        let binding = Binding::from_spec(&spec.binding, "closed loop")?;
        let alpha = match spec.binding {
            BindingSpec::Hill { solubility, .. } => solubility,
            _ => {
                return Err(Error::model(
                    "closed loop",
                    "binding must be 'hill' (haemoglobin)",
                ));
            }
        };
        let nc = spec.compartments.len();
        let mut consumption = Vec::with_capacity(nc);
        let (mut volume, mut total, mut free) = (vec![0.0; nc], vec![0.0; nc], vec![0.0; nc]);
        for (i, c) in spec.compartments.iter().enumerate() {
            let el = format!("compartment '{}'", c.name);
            if !(c.volume.is_finite() && c.volume > 0.0) {
                return Err(Error::model(
                    &el,
                    format!("volume must be a finite number > 0, got {}", c.volume),
                ));
            }
            if !(c.initial_po2.is_finite() && c.initial_po2 >= 0.0) {
                return Err(Error::model(
                    &el,
                    format!(
                        "initial_po2 must be a finite number >= 0, got {}",
                        c.initial_po2
                    ),
                ));
            }
            let law = match c.consumption {
                ConsumptionSpec::None => Consumption::None,
                ConsumptionSpec::Fixed { rate } => Consumption::Fixed { rate },
                ConsumptionSpec::MichaelisMenten { vmax, km } => {
                    Consumption::MichaelisMenten { vmax, km }
                }
            };
            law.validate(&el)?;
            consumption.push(law);
            volume[i] = c.volume;
            free[i] = alpha * c.initial_po2;
            total[i] = binding.total(free[i]);
        }
        let nb = spec.branches.len();
        let (mut from, mut to, mut lungs) = (Vec::new(), Vec::new(), Vec::new());
        for b in &spec.branches {
            let el = format!("branch '{}'", b.name);
            for (k, v) in [("from", b.from), ("to", b.to)] {
                if v >= nc {
                    return Err(Error::model(
                        &el,
                        format!("{k} = {v} is not a compartment (there are {nc})"),
                    ));
                }
            }
            from.push(b.from);
            to.push(b.to);
            lungs.push(match &b.lungs {
                Some(l) => Some(LungExchange::new(
                    l.alveolar_po2,
                    l.diffusing_capacity,
                    &el,
                )?),
                None => None,
            });
        }
        Ok(Self {
            names: spec.compartments.iter().map(|c| c.name.clone()).collect(),
            branch_names: spec.branches.iter().map(|b| b.name.clone()).collect(),
            consumption,
            from,
            to,
            lungs,
            binding,
            alpha,
            volume,
            total,
            free,
            vo2: vec![0.0; nc],
            uptake: vec![0.0; nb],
            flux: vec![0.0; nb],
            next: vec![0.0; nc],
            tree: None,
            tree_from: 0,
            tree_to: Vec::new(),
        })
    }

    /// Puts the arterial tree of `spec.tree` (built at step dt over `steps` steps per cycle)
    /// between its feeding compartment and its outlets' compartments.
    pub fn attach_tree(&mut self, spec: &TreeSpec, dt: f64, steps: usize) -> Result<()> {
        let nc = self.volume.len();
        let mut targets = vec![spec.from];
        targets.extend(spec.outlets.iter().map(|o| o.to));
        if let Some(&v) = targets.iter().find(|&&v| v >= nc) {
            return Err(Error::model(
                "arterial tree",
                format!("compartment {v} does not exist (there are {nc})"),
            ));
        }
        let names: Vec<String> = spec.outlets.iter().map(|o| o.boundary.clone()).collect();
        let tree = ArterialTree::new(
            &spec.model,
            &spec.inlet,
            &names,
            dt,
            steps,
            spec.flow_cycles,
        )?;
        self.tree_from = spec.from;
        self.tree_to = spec.outlets.iter().map(|o| o.to).collect();
        self.tree = Some(tree);
        Ok(())
    }

    /// The loop's O2 amount Σ V C_t (mol).
    pub fn amount(&self) -> f64 {
        let tree = self.tree.as_ref().map_or(0.0, |t| t.amount());
        self.volume
            .iter()
            .zip(&self.total)
            .map(|(v, c)| v * c)
            .sum::<f64>()
            + tree
    }

    /// Free PO2 of a compartment (Pa) and its haemoglobin saturation.
    pub fn po2(&self, i: usize) -> f64 {
        self.free[i] / self.alpha
    }

    pub fn saturation(&self, i: usize) -> f64 {
        match self.binding {
            Binding::Hill { capacity, .. } => (self.total[i] - self.free[i]) / capacity,
            _ => 0.0,
        }
    }

    /// Content carried by branch b at flow q, from the current iterate (and the lungs' uptake).
    fn carried(&self, b: usize, q: f64, ct: &[f64]) -> (f64, f64) {
        if q >= 0.0 {
            let c_up = ct[self.from[b]];
            match &self.lungs[b] {
                Some(l) => {
                    let c = l.end_capillary(&self.binding, self.alpha, c_up, q);
                    (c, q * (c - c_up))
                }
                None => (c_up, 0.0),
            }
        } else {
            (ct[self.to[b]], 0.0)
        }
    }

    /// Sets the state at a cycle start (volumes and total concentrations).
    pub fn set_state(&mut self, volume: &[f64], total: &[f64]) {
        self.volume.copy_from_slice(volume);
        self.total.copy_from_slice(total);
        for (f, &t) in self.free.iter_mut().zip(total) {
            *f = self.binding.free(t, *f);
        }
    }

    /// One step of length dt with branch flows `q` (m³/s, positive from → to) held over it
    /// (a loop without arterial tree; see [`ClosedLoop::step_at`]).
    pub fn step(&mut self, dt: f64, q: &[f64], time: f64) -> Result<()> {
        self.step_at(dt, q, time, 0)
    }

    /// Step `s` of the cycle: branch flows `q` held over it, and the arterial tree's step `s`.
    /// Backward Euler in the concentrations, solved by Gauss–Seidel sweeps in the listed order
    /// until no content changes by more than 1e-15 of the largest.
    pub fn step_at(&mut self, dt: f64, q: &[f64], time: f64, s: usize) -> Result<()> {
        let plan = self.step_plan(dt, q, s);
        if let Some(i) = (0..plan.v1.len()).find(|&i| plan.v1[i].is_nan() || plan.v1[i] <= 0.0) {
            return Err(Error::Solver {
                time,
                message: format!(
                    "compartment '{}': its volume would become {:.3e} m³ (the flows empty it)",
                    self.names[i], plan.v1[i]
                ),
            });
        }
        self.next.copy_from_slice(&self.total);
        let mut sweep = SweepState {
            // the lungs' end-capillary content, recomputed only when the blood entering changes
            lung_cache: vec![(f64::NAN, 0.0); q.len()],
            tree_start: self.tree.as_ref().map(|t| t.snapshot()),
            // the root concentration the tree's step last saw (NaN: not run yet)
            tree_c_in: f64::NAN,
        };
        self.tree_step(s, &sweep.tree_start, &mut sweep.tree_c_in)?;
        for _sweep in 0..200 {
            let change = self.sweep(&plan, q, &mut sweep)?;
            let scale = self.next.iter().fold(0.0_f64, |m, c| m.max(c.abs()));
            if change <= 1e-15 * scale {
                break;
            }
        }
        self.finish_step(q, plan.v1, time)
    }

    /// The step's end volumes (dV/dt = net inflow), the outflow rate of every compartment and
    /// the branches entering it at this step's flow directions; the tree's root flow leaves its
    /// compartment as a branch does, its outlets' flows enter theirs.
    fn step_plan(&self, dt: f64, q: &[f64], s: usize) -> StepPlan {
        let nc = self.volume.len();
        let mut v1 = self.volume.clone();
        let mut q_out = vec![0.0; nc];
        let mut incoming: Vec<Vec<usize>> = vec![Vec::new(); nc];
        for (b, &qb) in q.iter().enumerate() {
            let (up, down) = if qb >= 0.0 {
                (self.from[b], self.to[b])
            } else {
                (self.to[b], self.from[b])
            };
            v1[up] -= dt * qb.abs();
            v1[down] += dt * qb.abs();
            q_out[up] += qb.abs();
            if qb != 0.0 {
                incoming[down].push(b);
            }
        }
        // the tree's root flow leaves its compartment at the new concentration (implicit, as
        // a branch); a backflow through the root and the outlets' fluxes are the tree's own
        if let Some(t) = &self.tree {
            let q_root = t.inflow[s];
            v1[self.tree_from] -= dt * q_root;
            q_out[self.tree_from] += q_root.max(0.0);
            for (&to, &qo) in self.tree_to.iter().zip(&t.outflow[s]) {
                v1[to] += dt * qo;
            }
        }
        StepPlan {
            dt,
            s,
            v1,
            q_out,
            incoming,
        }
    }

    /// One Gauss–Seidel sweep over the compartments (each compartment's backward-Euler step
    /// with the latest contents of its upstream neighbours; the tree reruns its step when the
    /// content of its root compartment changed). Returns the largest content change.
    fn sweep(&mut self, plan: &StepPlan, q: &[f64], st: &mut SweepState) -> Result<f64> {
        let mut change = 0.0_f64;
        for n in 0..self.volume.len() {
            let inflow = self.inflow(n, &plan.incoming[n], q, &mut st.lung_cache);
            let (ct, vo2) = compartment::step(
                &self.binding,
                &self.consumption[n],
                self.alpha,
                (self.volume[n], self.total[n]),
                plan.v1[n],
                plan.dt,
                plan.q_out[n],
                inflow,
                self.free[n],
            );
            change = change.max((ct - self.next[n]).abs());
            self.next[n] = ct;
            self.vo2[n] = vo2;
            if self.tree.is_some() && n == self.tree_from {
                self.tree_step(plan.s, &st.tree_start, &mut st.tree_c_in)?;
            }
        }
        Ok(change)
    }

    /// O2 entering compartment n (mol/s) from the current iterate: the tree's outlets and
    /// root backflow, then every incoming branch (upwind content; the lungs' end-capillary
    /// content through a lung branch).
    fn inflow(&self, n: usize, incoming: &[usize], q: &[f64], cache: &mut [(f64, f64)]) -> f64 {
        let mut inflow = self.tree_inflow(n);
        for &b in incoming {
            let c_up = if q[b] >= 0.0 {
                self.next[self.from[b]]
            } else {
                self.next[self.to[b]]
            };
            if self.lungs[b].is_some() && q[b] > 0.0 {
                if cache[b].0 != c_up {
                    cache[b] = (c_up, self.carried(b, q[b], &self.next).0);
                }
                inflow += q[b] * cache[b].1;
            } else {
                inflow += q[b].abs() * c_up;
            }
        }
        inflow
    }

    /// Records the solved step's branch fluxes and lung uptakes and moves the state to the
    /// step's end (volumes `v1`, the solved contents and their free concentrations).
    fn finish_step(&mut self, q: &[f64], v1: Vec<f64>, time: f64) -> Result<()> {
        for (b, &qb) in q.iter().enumerate() {
            let (c, up) = self.carried(b, qb, &self.next);
            self.flux[b] = qb * c;
            self.uptake[b] = up;
        }
        let nc = self.volume.len();
        if let Some(i) = (0..nc).find(|&i| !(self.next[i].is_finite() && self.next[i] >= 0.0)) {
            return Err(Error::Solver {
                time,
                message: format!(
                    "compartment '{}': O2 content {:.3e} mol/m³ (a fixed VO2 above what the flow brings)",
                    self.names[i], self.next[i]
                ),
            });
        }
        self.volume = v1;
        self.total.copy_from_slice(&self.next);
        for n in 0..nc {
            self.free[n] = self.binding.free(self.total[n], self.free[n]);
        }
        Ok(())
    }

    /// (Re)runs the tree's step `s` from its step-start state when the concentration of the
    /// compartment feeding its root has changed since the last run (`c_in`): the tree then
    /// carries in exactly what that compartment's implicit outflow removes.
    fn tree_step(
        &mut self,
        s: usize,
        start: &Option<(Vec<f64>, Vec<f64>)>,
        c_in: &mut f64,
    ) -> Result<()> {
        let (Some(tree), Some(start)) = (self.tree.as_mut(), start) else {
            return Ok(());
        };
        let c = self.next[self.tree_from];
        if c == *c_in {
            return Ok(());
        }
        if !c_in.is_nan() {
            tree.restore(start)?;
        }
        tree.step(s, c)?;
        *c_in = c;
        Ok(())
    }

    /// Restores the tree's state of a snapshot (nothing without a tree).
    fn restore_tree(&mut self, snap: &Option<(Vec<f64>, Vec<f64>)>) -> Result<()> {
        match (self.tree.as_mut(), snap) {
            (Some(t), Some(s)) => t.restore(s),
            _ => Ok(()),
        }
    }

    /// O2 the tree brings compartment n over the step (mol/s): its outlets' fluxes, and a
    /// backflow through its root.
    fn tree_inflow(&self, n: usize) -> f64 {
        let Some(t) = &self.tree else { return 0.0 };
        let mut j = 0.0;
        for (&to, &f) in self.tree_to.iter().zip(&t.out_flux) {
            if to == n {
                j += f;
            }
        }
        if n == self.tree_from && t.in_flux < 0.0 {
            j -= t.in_flux;
        }
        j
    }

    /// The tree's wall uptake over the last step (mol/s; 0 without a tree).
    pub fn tree_wall(&self) -> f64 {
        self.tree.as_ref().map_or(0.0, |t| t.wall)
    }
}

/// The recorded last cycle of a periodic closed-loop O2 run (row-major, one row per step end).
#[derive(Debug, Clone, Default)]
pub struct ClosedLoopRun {
    pub cycles: usize,
    /// max |ΔC_t| between the starts of the last two cycles, relative to max C_t.
    pub periodic_error: f64,
    pub time: Vec<f64>,
    pub volume: Vec<f64>,
    pub total: Vec<f64>,
    pub po2: Vec<f64>,
    pub saturation: Vec<f64>,
    pub vo2: Vec<f64>,
    pub flux: Vec<f64>,
    pub uptake: Vec<f64>,
    /// Loop amount at each recorded step end and at the start of the last cycle (mol).
    pub amount: Vec<f64>,
    pub amount_start: f64,
    /// With an arterial tree: per step its wall uptake (mol/s), its O2 amount (mol), the flux
    /// into its root and out of every outlet (mol/s), the PO2 (Pa) of every segment.
    pub tree_wall: Vec<f64>,
    pub tree_amount: Vec<f64>,
    pub tree_in_flux: Vec<f64>,
    pub tree_out_flux: Vec<f64>,
    pub tree_po2: Vec<f64>,
    pub tree_segments: Vec<String>,
    pub tree_flow_periodic_error: f64,
    /// The tree's flow per step into its root and out of every outlet (m³/s).
    pub tree_inflow: Vec<f64>,
    pub tree_outflow: Vec<f64>,
    /// The flow table the run used (row-major steps × branches; balanced with `balance`).
    pub flow: Vec<f64>,
    /// With a heart: its recorded times (from 0) and named series over the last flow cycle.
    pub heart_time: Vec<f64>,
    pub heart_series: Vec<(String, Vec<f64>)>,
    /// With a heart: its run's cycles, last cycle-to-cycle change and whether that met the
    /// run's periodicity (a run stopped at its most cycles did not; true without a heart).
    pub heart_cycles: usize,
    pub heart_periodic_error: f64,
    pub heart_periodic: bool,
}

/// One cycle of the flow table from the loop's current state; records into `out` if given.
fn cycle(
    lp: &mut ClosedLoop,
    flows: &[f64],
    dt: f64,
    t0: f64,
    mut out: Option<&mut ClosedLoopRun>,
) -> Result<()> {
    let (nc, nb) = (lp.volume.len(), lp.flux.len());
    let steps = flows.len() / nb;
    if let Some(o) = out.as_deref_mut() {
        o.amount_start = lp.amount();
    }
    for s in 0..steps {
        let t = t0 + dt * (s + 1) as f64;
        lp.step_at(dt, &flows[s * nb..(s + 1) * nb], t, s)?;
        if let Some(o) = out.as_deref_mut() {
            if let Some(tree) = &lp.tree {
                o.tree_wall.push(tree.wall);
                o.tree_amount.push(tree.amount());
                o.tree_in_flux.push(tree.in_flux);
                o.tree_out_flux.extend_from_slice(&tree.out_flux);
                o.tree_po2
                    .extend(tree.segment_free().iter().map(|c| c / lp.alpha));
            }
            o.time[s] = t;
            for n in 0..nc {
                let k = s * nc + n;
                o.volume[k] = lp.volume[n];
                o.total[k] = lp.total[n];
                o.po2[k] = lp.po2(n);
                o.saturation[k] = lp.saturation(n);
                o.vo2[k] = lp.vo2[n];
            }
            o.flux[s * nb..(s + 1) * nb].copy_from_slice(&lp.flux);
            o.uptake[s * nb..(s + 1) * nb].copy_from_slice(&lp.uptake);
            o.amount[s] = lp.amount();
        }
    }
    Ok(())
}

/// The shooting state: the compartments' total concentrations, then the tree's cell amounts.
fn shooting_state(lp: &ClosedLoop) -> Vec<f64> {
    let mut x = lp.total.clone();
    if let Some(t) = &lp.tree {
        x.extend_from_slice(t.cells());
    }
    x
}

/// Starts a cycle from shooting state `x` (volumes `v0`; the tree's carried state, i.e. its
/// volumes and warm starts, from `tree_base`).
fn load_state(
    lp: &mut ClosedLoop,
    v0: &[f64],
    x: &[f64],
    tree_base: &Option<(Vec<f64>, Vec<f64>)>,
) -> Result<()> {
    let nc = lp.volume.len();
    lp.set_state(v0, &x[..nc]);
    lp.restore_tree(tree_base)?;
    if let Some(t) = lp.tree.as_mut() {
        t.set_cells(&x[nc..]);
    }
    Ok(())
}

/// Anderson acceleration of the cycle map x ↦ Φ(x) of the shooting state (docs/oxygen.md
/// "periodic steady state"): x_{k+1} = Φ(x_k) − ΔG γ with γ minimising the weighted residual
/// ‖W (f_k − ΔF γ)‖ over the last `m` differences of residuals f = Φ(x) − x (ΔF) and of
/// images (ΔG). For a map that is affine in x (the loop is, for a fixed flow, except Hill
/// binding and Michaelis–Menten) this is GMRES on (I − J) x = b with one cycle per iteration:
/// it needs about as many cycles as the map has slow modes (the pools' washouts, ~12), where
/// a finite-difference Newton Jacobian needs one cycle per unknown (the tree's cells included:
/// ~70) per iteration; the tree's cells wash out within a few cycles by the plain map itself.
/// Leaves the loop at the last image Φ(x) and returns the cycles run (at most `budget`).
fn shoot(
    lp: &mut ClosedLoop,
    flows: &[f64],
    dt: f64,
    v0: &[f64],
    budget: usize,
    tol: f64,
) -> Result<usize> {
    let nc = lp.volume.len();
    let mut x = shooting_state(lp);
    let n = x.len();
    // each block (concentrations, tree amounts) weighted by the inverse of its largest value
    let w: Vec<f64> = (0..n).map(|i| 1.0 / block_scale(&x, nc, i)).collect();
    let mut tree_base = lp.tree.as_ref().map(|t| t.snapshot());
    let mut hist = AndersonHistory::new(ANDERSON_MEMORY.min(n));
    let mut cycles = 0;
    let mut last: Option<(Vec<f64>, Vec<f64>)> = None; // (f, g) of the previous iterate
    while cycles < budget {
        let g = cycle_image(lp, flows, dt, v0, &x, &tree_base)?;
        cycles += 1;
        tree_base = lp.tree.as_ref().map(|t| t.snapshot());
        let f: Vec<f64> = g.iter().zip(&x).map(|(a, b)| a - b).collect();
        if f.iter().zip(&w).all(|(fi, wi)| (fi * wi).abs() <= tol) {
            return Ok(cycles);
        }
        if let Some((f0, g0)) = &last {
            let df: Vec<f64> = f
                .iter()
                .zip(f0)
                .zip(&w)
                .map(|((a, b), wi)| (a - b) * wi)
                .collect();
            let dg: Vec<f64> = g.iter().zip(g0).map(|(a, b)| a - b).collect();
            hist.push(df, dg);
        }
        let wf: Vec<f64> = f.iter().zip(&w).map(|(a, b)| a * b).collect();
        let gamma = hist.solve(&wf);
        x = g.clone();
        for (k, gk) in gamma.iter().enumerate() {
            for (xi, dgi) in x.iter_mut().zip(&hist.dg[k]) {
                *xi -= gk * dgi;
            }
        }
        for xi in x.iter_mut() {
            *xi = xi.max(0.0);
        }
        last = Some((f, g));
    }
    Ok(cycles)
}

/// The cycle map Φ of both shooting methods: loads the shooting state `x` (and the tree's
/// snapshot), runs one cycle and returns the state at its end.
fn cycle_image(
    lp: &mut ClosedLoop,
    flows: &[f64],
    dt: f64,
    v0: &[f64],
    x: &[f64],
    tree_base: &Option<(Vec<f64>, Vec<f64>)>,
) -> Result<Vec<f64>> {
    load_state(lp, v0, x, tree_base)?;
    cycle(lp, flows, dt, 0.0, None)?;
    Ok(shooting_state(lp))
}

/// Differences kept by the Anderson acceleration: enough for the loop's slow modes and the
/// tree's transit (a linear map of that many modes converges in about that many cycles).
const ANDERSON_MEMORY: usize = 40;

/// The scale of shooting-state entry i: the largest magnitude in its block (the
/// compartments' concentrations, the tree's cell amounts).
fn block_scale(x: &[f64], nc: usize, i: usize) -> f64 {
    let r = if i < nc { &x[..nc] } else { &x[nc..] };
    r.iter().fold(0.0_f64, |m, c| m.max(c.abs())).max(1e-300)
}

/// The weighted residual differences ΔF (columns, oldest first) and image differences ΔG of
/// Anderson's last `m` iterates.
struct AndersonHistory {
    m: usize,
    df: Vec<Vec<f64>>,
    dg: Vec<Vec<f64>>,
}

impl AndersonHistory {
    fn new(m: usize) -> Self {
        Self {
            m,
            df: Vec::new(),
            dg: Vec::new(),
        }
    }

    fn push(&mut self, df: Vec<f64>, dg: Vec<f64>) {
        if self.df.len() == self.m {
            self.df.remove(0);
            self.dg.remove(0);
        }
        self.df.push(df);
        self.dg.push(dg);
    }

    /// γ minimising ‖f − ΔF γ‖ (modified Gram–Schmidt QR). A difference column that is, to
    /// 1e-10 of its norm, a combination of the later ones would make the problem singular:
    /// the oldest columns go until none is.
    fn solve(&mut self, f: &[f64]) -> Vec<f64> {
        loop {
            match least_squares(&self.df, f) {
                Some(g) => return g,
                None => {
                    self.df.remove(0);
                    self.dg.remove(0);
                }
            }
        }
    }
}

/// min ‖f − A γ‖ over γ for the columns A (modified Gram–Schmidt, newest column first so
/// that a dependent column found is an old one); None when a column is dependent.
fn least_squares(cols: &[Vec<f64>], f: &[f64]) -> Option<Vec<f64>> {
    let k = cols.len();
    let order: Vec<usize> = (0..k).rev().collect();
    let mut q: Vec<Vec<f64>> = Vec::with_capacity(k);
    let mut r = vec![0.0; k * k];
    for (j, &c) in order.iter().enumerate() {
        let mut v = cols[c].clone();
        let norm0 = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        for (i, qi) in q.iter().enumerate() {
            let d: f64 = qi.iter().zip(&v).map(|(a, b)| a * b).sum();
            r[i * k + j] = d;
            for (vv, qq) in v.iter_mut().zip(qi) {
                *vv -= d * qq;
            }
        }
        let norm = v.iter().map(|a| a * a).sum::<f64>().sqrt();
        if norm.is_nan() || norm <= 1e-10 * norm0 {
            return None;
        }
        r[j * k + j] = norm;
        q.push(v.iter().map(|a| a / norm).collect());
    }
    // R y = Qᵀ f, back substitution; y is in `order`
    let mut y: Vec<f64> = q
        .iter()
        .map(|qi| qi.iter().zip(f).map(|(a, b)| a * b).sum())
        .collect();
    for j in (0..k).rev() {
        let s: f64 = (j + 1..k).map(|l| r[j * k + l] * y[l]).sum();
        y[j] = (y[j] - s) / r[j * k + j];
    }
    let mut gamma = vec![0.0; k];
    for (j, &c) in order.iter().enumerate() {
        gamma[c] = y[j];
    }
    Some(gamma)
}

/// `shooting: newton` (the earlier method, kept for comparison): Newton shooting on the cycle
/// map x ↦ Φ(x) of the shooting state (finite-difference Jacobian, one cycle per unknown), at most `budget` cycles; leaves the loop at the last
/// iterate and returns the cycles run. The tree's cells are unknowns too: its transit takes
/// ~3 cycles and its numerical diffusion a long tail, so holding it fixed while the
/// compartments converge would converge only at that tail's rate.
fn shoot_newton(
    lp: &mut ClosedLoop,
    flows: &[f64],
    dt: f64,
    v0: &[f64],
    budget: usize,
    tol: f64,
) -> Result<usize> {
    let nc = lp.volume.len();
    let mut x = shooting_state(lp);
    let n = x.len();
    let mut tree_base = lp.tree.as_ref().map(|t| t.snapshot());
    let mut cycles = 0;
    // each block (concentrations, tree amounts) is scaled by its own largest value
    for _newton in 0..6 {
        if cycles + n + 1 > budget {
            break;
        }
        let gx = cycle_image(lp, flows, dt, v0, &x, &tree_base)?;
        cycles += 1;
        let tree_end = lp.tree.as_ref().map(|t| t.snapshot());
        let fx: Vec<f64> = gx.iter().zip(&x).map(|(p, q)| p - q).collect();
        let scales: Vec<f64> = (0..n).map(|i| block_scale(&x, nc, i)).collect();
        if fx.iter().zip(&scales).all(|(f, s)| f.abs() <= tol * s) {
            break;
        }
        let mut jac = vec![0.0; n * n]; // J − I, column by column
        for j in 0..n {
            let eps = 1e-7 * x[j].abs().max(1e-3 * scales[j]);
            let mut xp = x.clone();
            xp[j] += eps;
            let gp = cycle_image(lp, flows, dt, v0, &xp, &tree_base)?;
            cycles += 1;
            for (i, xi) in gp.iter().enumerate() {
                jac[i * n + j] = (xi - xp[i] - fx[i]) / eps;
            }
        }
        let mut delta: Vec<f64> = fx.iter().map(|f| -f).collect();
        if !crate::sparse::lu_solve(&jac, &mut delta, n, 0.0) {
            break;
        }
        for (xi, d) in x.iter_mut().zip(&delta) {
            *xi = (*xi + d).max(0.0);
        }
        tree_base = tree_end;
    }
    load_state(lp, v0, &x, &tree_base)?;
    Ok(cycles)
}

/// Runs the loop on the periodic flow table `flows` (one row of branch flows per step of
/// length dt) to its periodic steady state and records the last cycle. The loop's slowest
/// modes are washouts of the large pools (τ = V/Q ≈ 30 s: hundreds of cycles), so the periodic
/// state is found by Anderson acceleration of the cycle map x ↦ Φ(x) of the total
/// concentrations (and the tree's cell amounts) at a cycle start ([`shoot`]), then confirmed by
/// plain cycles until the start-of-cycle state repeats to `tol` (relative) or `max_cycles`.
pub fn run_periodic(
    spec: &ClosedLoopSpec,
    flows: &[f64],
    dt: f64,
    max_cycles: usize,
    tol: f64,
) -> Result<ClosedLoopRun> {
    let mut lp = ClosedLoop::new(spec)?;
    let mut tree = spec.tree.clone();
    let heart = match &spec.heart {
        Some(h) => {
            let period = spec
                .period
                .ok_or_else(|| Error::model("closed-loop heart", "needs the loop's period"))?;
            Some(super::closed_loop_heart::heart_flows(
                h,
                dt,
                period,
                tree.as_mut(),
            )?)
        }
        None => None,
    };
    let flows = heart.as_ref().map_or(flows, |h| h.table.as_slice());
    let steps = check_table(&lp, flows, dt)?;
    let period = dt * steps as f64;
    if let Some(t) = &tree {
        lp.attach_tree(t, dt, steps)?;
    }
    let mut table = flows.to_vec();
    if spec.balance || heart.is_some() {
        balance_with_tree(&lp, &mut table)?;
    }
    let flows = table.as_slice();
    let v0 = lp.volume.clone();
    check_periodic_volumes(&lp, flows, dt, &v0)?;
    let mut cycles = 0;
    // two plain cycles bring the state near the attractor, then the accelerated shooting
    for _ in 0..2.min(max_cycles) {
        cycle(&mut lp, flows, dt, period * cycles as f64, None)?;
        cycles += 1;
    }
    let budget = max_cycles.saturating_sub(cycles);
    cycles += match spec.shooting {
        Shooting::Anderson => shoot(&mut lp, flows, dt, &v0, budget, tol)?,
        Shooting::Newton => shoot_newton(&mut lp, flows, dt, &v0, budget, tol)?,
    };
    let mut out = ClosedLoopRun::empty(&lp, steps);
    confirm(&mut lp, flows, dt, (cycles, max_cycles), tol, &mut out)?;
    out.flow = table;
    if let Some(h) = heart {
        out.heart_time = h.time;
        out.heart_series = h.record;
        out.heart_cycles = h.cycles;
        out.heart_periodic_error = h.periodic_error;
        out.heart_periodic = h.periodic;
    }
    Ok(out)
}

impl ClosedLoop {
    /// The derivative of [`balance_flows`](super::closed_loop_balance::balance_flows) along
    /// `dflows` (a direction of the flow table, steps × branches): the balance is linear in
    /// the table, so its derivative is the balance of the direction with nothing held fixed.
    pub fn balance_direction(&self, dflows: &mut [f64]) -> Result<()> {
        let fixed = vec![0.0; self.volume.len()];
        super::closed_loop_balance::balance_flows(dflows, &self.from, &self.to, &fixed)
    }
}

/// [`balance_flows`](super::closed_loop_balance::balance_flows) of the loop's table, the
/// attached tree's cycle-mean inflow and outflows held as they are.
fn balance_with_tree(lp: &ClosedLoop, flows: &mut [f64]) -> Result<()> {
    let mut fixed = vec![0.0; lp.volume.len()];
    if let Some(t) = &lp.tree {
        let n = t.inflow.len().max(1) as f64;
        fixed[lp.tree_from] -= t.inflow.iter().sum::<f64>() / n;
        for (k, &to) in lp.tree_to.iter().enumerate() {
            fixed[to] += t.outflow.iter().map(|q| q[k]).sum::<f64>() / n;
        }
    }
    super::closed_loop_balance::balance_flows(flows, &lp.from, &lp.to, &fixed)
}

/// Checks the flow table and the step; returns the steps per cycle.
fn check_table(lp: &ClosedLoop, flows: &[f64], dt: f64) -> Result<usize> {
    let nb = lp.flux.len();
    if nb == 0 || flows.len() % nb != 0 || flows.is_empty() {
        return Err(Error::model(
            "closed loop",
            format!(
                "flow table has {} values, not a multiple of {nb} branches",
                flows.len()
            ),
        ));
    }
    if !(dt.is_finite() && dt > 0.0) {
        return Err(Error::model(
            "closed loop",
            format!("dt must be a finite number > 0, got {dt}"),
        ));
    }
    if let Some(x) = flows.iter().find(|x| !x.is_finite()) {
        return Err(Error::model(
            "closed loop",
            format!("flow table holds a non-finite value {x}"),
        ));
    }
    Ok(flows.len() / nb)
}

/// Periodic volumes: the table's (and the tree's) net inflow over a cycle must vanish in every
/// compartment, else no periodic state exists and Fick's balance would include the volume
/// drift.
fn check_periodic_volumes(lp: &ClosedLoop, flows: &[f64], dt: f64, v0: &[f64]) -> Result<()> {
    let (nc, nb) = (lp.volume.len(), lp.flux.len());
    let mut net = vec![0.0; nc];
    for row in flows.chunks(nb) {
        for (b, &qb) in row.iter().enumerate() {
            net[lp.from[b]] -= dt * qb;
            net[lp.to[b]] += dt * qb;
        }
    }
    if let Some(t) = &lp.tree {
        for (qi, qo) in t.inflow.iter().zip(&t.outflow) {
            net[lp.tree_from] -= dt * qi;
            for (&to, &q) in lp.tree_to.iter().zip(qo) {
                net[to] += dt * q;
            }
        }
    }
    if let Some(i) = (0..nc).find(|&i| net[i].abs() > 1e-9 * v0[i]) {
        return Err(Error::model(
            format!("compartment '{}'", lp.names[i]),
            format!(
                "the flow table's net inflow over a cycle is {:.3e} m³ ({:.1e} of its volume): \
                     balance the flows so that the volumes are periodic",
                net[i],
                net[i] / v0[i]
            ),
        ));
    }
    Ok(())
}

impl ClosedLoopRun {
    /// An empty record of `steps` steps for the loop `lp` (the tree's static fields filled).
    fn empty(lp: &ClosedLoop, steps: usize) -> Self {
        let (nc, nb) = (lp.volume.len(), lp.flux.len());
        let tree = lp.tree.as_ref();
        ClosedLoopRun {
            cycles: 0,
            periodic_error: f64::INFINITY,
            time: vec![0.0; steps],
            volume: vec![0.0; steps * nc],
            total: vec![0.0; steps * nc],
            po2: vec![0.0; steps * nc],
            saturation: vec![0.0; steps * nc],
            vo2: vec![0.0; steps * nc],
            flux: vec![0.0; steps * nb],
            uptake: vec![0.0; steps * nb],
            amount: vec![0.0; steps],
            amount_start: 0.0,
            tree_wall: Vec::new(),
            tree_amount: Vec::new(),
            tree_in_flux: Vec::new(),
            tree_out_flux: Vec::new(),
            tree_po2: Vec::new(),
            tree_segments: tree.map_or(Vec::new(), |t| t.segment_names.clone()),
            tree_flow_periodic_error: tree.map_or(0.0, |t| t.flow_periodic_error),
            tree_inflow: tree.map_or(Vec::new(), |t| t.inflow.clone()),
            tree_outflow: tree.map_or(Vec::new(), |t| t.outflow.concat()),
            flow: Vec::new(),
            heart_time: Vec::new(),
            heart_series: Vec::new(),
            heart_cycles: 0,
            heart_periodic_error: 0.0,
            heart_periodic: true,
        }
    }

    fn clear_tree(&mut self) {
        for v in [
            &mut self.tree_wall,
            &mut self.tree_amount,
            &mut self.tree_in_flux,
            &mut self.tree_out_flux,
            &mut self.tree_po2,
        ] {
            v.clear();
        }
    }
}

/// Plain recorded cycles until the start-of-cycle state repeats to `tol` (relative; the tree's
/// cell amounts too) or `max_cycles` in all; (cycles run so far, max_cycles).
fn confirm(
    lp: &mut ClosedLoop,
    flows: &[f64],
    dt: f64,
    (mut cycles, max_cycles): (usize, usize),
    tol: f64,
    out: &mut ClosedLoopRun,
) -> Result<()> {
    let period = dt * (flows.len() / lp.flux.len()) as f64;
    loop {
        let start = lp.total.clone();
        let tree_start = lp.tree.as_ref().map(|t| t.snapshot());
        out.clear_tree();
        cycle(lp, flows, dt, period * cycles as f64, Some(out))?;
        cycles += 1;
        let scale = lp.total.iter().fold(0.0_f64, |m, c| m.max(c.abs()));
        out.periodic_error = lp
            .total
            .iter()
            .zip(&start)
            .fold(0.0_f64, |m, (a, b)| m.max((a - b).abs()))
            / scale;
        if let (Some(t), Some(a)) = (&lp.tree, &tree_start) {
            out.periodic_error = out.periodic_error.max(t.relative_change(a, &t.snapshot()));
        }
        if out.periodic_error <= tol || cycles >= max_cycles {
            break;
        }
    }
    out.cycles = cycles;
    Ok(())
}

/// Exact derivatives of the periodic O2 state (a child module: it linearises the step).
#[path = "closed_loop_tangent.rs"]
pub mod tangent;
