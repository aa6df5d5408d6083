//! Error-controlled runs with the explicit pair (docs/physics.md §10.4): Dormand–Prince 5(4)
//! (`integrate::explicit_pair`) with its step chosen from the embedded estimate, judged in
//! the norm of the implicit error control (`adaptive`: atol per kind, rtol of each unknown's
//! running peak, a vessel's flows of its own amplitude, errors per unit step accumulated over
//! 1/ω_i), RK4's spectral bound as the ceiling, and output rows from the continuous extension.
//!
//! `method: auto` with a tolerance chooses between this pair and generalized-α by the
//! predicted cost of a cycle at that tolerance ([`choose`]), among the methods able to run
//! the circuit: the pair only where its stages need no Newton iteration.

use super::adaptive::{ACCUMULATION, NO_VESSEL, flow_groups};
use super::coupling::{Flow, State};
use super::cycle::{CycleRows, Cycles, toward_end};
use super::events::{Cut, Events, Located, Next, decide};
use super::settings::{Method, RunSettings};
use crate::assemble::auto_segments::{UNFORCED_FREQUENCY, waveform_frequency};
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::integrate::adaptive::{SAFETY, Tolerances, local_error_constant};
use crate::integrate::explicit_pair::{self, Dopri5, dp5_step_limit};
use crate::integrate::rk4::{Rk4, Uncoupled};
use crate::integrate::stability::{
    SpectrumMethod, StabilityLimit, growth, ray_reach, rk4_limit_probed, rk4_step_ceiling,
    rk4_step_limit,
};
use crate::integrate::steady::SteadyCache;
use nalgebra::Complex;
use std::cell::{OnceCell, RefCell};

/// The largest step of the pair as a fraction of the period: its six stages sample the
/// forcing 24 times a cycle at the least, and its fifth order needs no finer ceiling (the
/// implicit control's T/32 held a sinusoidally forced RC line 3e-6 below rtol 1e-2, T/8
/// still 5e-3 below).
const MAX_STEP_PER_PERIOD: f64 = 1.0 / 4.0;
/// The implicit control's largest step (`adaptive`), for the cost prediction.
const IMPLICIT_MAX_STEP_PER_PERIOD: f64 = 1.0 / 32.0;
/// Right-hand sides per accepted explicit step (seven stages, the first the last's).
const EXPLICIT_STAGES: f64 = 6.0;
/// The cost of one error-controlled generalized-α step in right-hand sides of the explicit
/// pair: a residual, a solve with the kept factorisation, the error estimate and, one step
/// in a few, its filter solve or a refactorisation. An estimate from the profile of the
/// controlled step (docs/physics.md §10, "Where the cost goes": about 2.4 fixed steps), not a
/// timing of the explicit pair against it.
const IMPLICIT_STEP_COST: f64 = 4.0;
/// Step growth at most 5×, shrinking at most 5× per step.
const GROW: f64 = 5.0;
const SHRINK: f64 = 0.2;
/// Safety on the stability ceiling (its eigenvalue is an estimate for large circuits).
const STABILITY_SAFETY: f64 = 0.9;

/// The explicit pair's plan: its step ceiling and RK4's probed stability limit.
pub(super) struct ExplicitPlan {
    pub ceiling: f64,
    pub stability: StabilityLimit,
}

/// Whether an error-controlled run steps the explicit pair: always for `dopri5` (a circuit
/// it cannot step is a model error naming the element), by predicted cost for `auto` where
/// the pair can run the circuit without a Newton iteration in its stages, never for
/// `generalized-alpha`. `transport_dt` is the species' explicit step limit, `quasi` a
/// quasi-steady species field (not an ODE the stages can carry).
pub(super) fn choose(
    dae: &Dae,
    steady: &SteadyCache<'_>,
    s: &RunSettings,
    (transport_dt, quasi): (f64, bool),
    go: &mut dyn FnMut() -> bool,
) -> Result<Option<ExplicitPlan>> {
    let asked = match s.method {
        Method::Dopri5 => true,
        Method::Auto { .. } => false,
        _ => return Ok(None),
    };
    // valves are events for both integrators: `auto` weighs the pair's cost for them too,
    // unless it cannot step the circuit (then generalized-α, without an error)
    let supported = explicit_pair::check_supported(dae).and_then(|()| quasi_refused(quasi));
    if let Err(e) = supported {
        return if asked { Err(e) } else { Ok(None) };
    }
    // the forcing's highest significant frequency (a transform of each waveform), once
    let omega = OnceCell::new();
    let pays =
        |ceiling: f64| explicit_pays(s, *omega.get_or_init(|| forcing_omega(dae, s)), ceiling);
    let probed = operator(dae, steady).and_then(|mut rk| {
        // without a growing mode to refuse, `auto` skips the probe where the implicit
        // method wins whatever it would find: a Newton iteration in the stages, or a
        // stability ceiling (bounded from above cheaply) below the implicit step's worth
        let certain = !asked
            && !growth::may_grow(dae)
            && (rk.eliminates_by_newton()
                || implicit_wins_at_most(&mut rk, transport_dt, &pays, go)?);
        if certain {
            return Ok(None);
        }
        probe(rk, dae, go).map(Some)
    });
    let (stability, by_newton) = match probed {
        Ok(Some(found)) => found,
        Ok(None) => return Ok(None),
        // a growing mode: no method runs the circuit
        Err(e) if asked || growth::is_growing_mode(&e) => return Err(e),
        Err(_) => return Ok(None),
    };
    // a Newton iteration in every stage (a nonlinear elimination: valve laws or stenoses on
    // algebraic rows) can fail where no step length helps it (the algebraic rows do not
    // shrink with the step), and the pair has no other answer to it: `auto` takes the
    // implicit method, whose failures shrink or damp its step (`retry`)
    if by_newton && !asked {
        return Ok(None);
    }
    let (re, im) = stability.eigenvalue;
    let lambda = Complex::new(re, im);
    // RK4's limit moved to the pair's along the limiting eigenvalue's ray
    let ratio = dp5_step_limit(lambda) / rk4_step_limit(lambda);
    let ceiling = (STABILITY_SAFETY * stability.dt_max * ratio).min(transport_dt);
    let take = asked || pays(ceiling);
    Ok(take.then_some(ExplicitPlan { ceiling, stability }))
}

/// The run's tolerance (rtol 1e-3 without one).
fn run_rtol(s: &RunSettings) -> f64 {
    s.adaptive().map_or(1e-3, |t| t.rtol)
}

/// The forcing's highest significant angular frequency at the run's rtol (rad/s).
fn forcing_omega(dae: &Dae, s: &RunSettings) -> f64 {
    2.0 * std::f64::consts::PI * forcing_frequency(dae, run_rtol(s))
}

/// The cost rule of `auto` ([`explicit_is_cheaper`]) at the run's tolerance and the forcing's
/// angular frequency `omega`, for the pair's stability ceiling `ceiling`.
fn explicit_pays(s: &RunSettings, omega: f64, ceiling: f64) -> bool {
    let rtol = run_rtol(s);
    let h_max = [MAX_STEP_PER_PERIOD, IMPLICIT_MAX_STEP_PER_PERIOD].map(|f| f * s.period);
    explicit_is_cheaper(rtol, omega, ceiling, h_max, s.method.rho_inf())
}

/// Circuits above the dense spectrum's size whose Krylov probe [`auto`'s choice] may skip:
/// below it the probe is the exact dense spectrum and cheap.
const PROBE_SKIP_UNKNOWNS: usize = 600;

/// Whether the implicit method wins the cost rule even at an upper bound of the pair's
/// stability ceiling (`stability::rk4_step_ceiling`: a few O(n) products, no Krylov basis),
/// so that the probe cannot change the choice. Only for a large circuit in one operator
/// state (no valves' closed states, stiff branches or time-varying coefficients, where the
/// probe's limit is the smallest over several operators, each of which this bound does not
/// see): otherwise false, and the probe decides as before.
fn implicit_wins_at_most(
    rk: &mut Rk4<'_>,
    transport_dt: f64,
    pays: &dyn Fn(f64) -> bool,
    go: &mut dyn FnMut() -> bool,
) -> Result<bool> {
    let one_state = !rk.has_closed_states() && rk.stiff_branches() == 0 && !rk.is_time_varying();
    if !one_state || rk.diff.len() <= PROBE_SKIP_UNKNOWNS {
        return Ok(false);
    }
    let rk4_ceiling = rk4_step_ceiling(rk, go)?;
    // the probe's ceiling is RK4's limit (at most `rk4_ceiling`) times the pair's limit over
    // RK4's on the limiting eigenvalue's ray, whichever ray that is (not the largest |λ|'s)
    let ratio = ray_reach(|l| dp5_step_limit(l) / rk4_step_limit(l));
    let ceiling = (STABILITY_SAFETY * rk4_ceiling * ratio).min(transport_dt);
    Ok(!pays(ceiling))
}

fn quasi_refused(quasi: bool) -> Result<()> {
    if quasi {
        return Err(Error::model(
            "transport",
            format!(
                "method '{}' carries species in its stages: the quasi-steady formulation has \
                 none (use the conservative one, or 'generalized-alpha')",
                explicit_pair::NAME
            ),
        ));
    }
    Ok(())
}

/// RK4's operator of the circuit, its stenoses linearised at the steady state.
fn operator<'a>(dae: &'a Dae, steady: &SteadyCache<'_>) -> Result<Rk4<'a>> {
    let mut rk = Rk4::new(dae, Regime::Transient, 1.0)?;
    if !dae.is_linear() {
        if let Ok(ys) = steady.get() {
            rk.set_linearization(ys)?;
        }
    }
    Ok(rk)
}

/// RK4's stability limit, and whether the stages eliminate the algebraic unknowns by Newton.
fn probe(
    mut rk: Rk4<'_>,
    dae: &Dae,
    go: &mut dyn FnMut() -> bool,
) -> Result<(StabilityLimit, bool)> {
    let by_newton = rk.eliminates_by_newton();
    let limit = rk4_limit_probed(&mut rk, &dae.names, SpectrumMethod::Auto, go)?;
    Ok((limit, by_newton))
}

/// The highest significant frequency of the forcing at `rtol` (Hz; the unforced default
/// without a periodic waveform).
fn forcing_frequency(dae: &Dae, rtol: f64) -> f64 {
    let each = dae
        .forcing
        .iter()
        .filter_map(|(_, w)| waveform_frequency(w, rtol));
    each.fold(None, |m: Option<f64>, f| Some(m.map_or(f, |m| m.max(f))))
        .unwrap_or(UNFORCED_FREQUENCY)
}

/// The cost rule of `method: auto` under error control (docs/physics.md §10.4). A harmonic
/// ω of the solution held to rtol per unit step (accumulated over ACCUMULATION/ω, as the
/// control judges it) allows the step h with ACCUMULATION·C·(hω)^p = rtol: p = 4 and C the
/// pair's estimate constant for the explicit pair, p = 2 and generalized-α's |C| for the
/// implicit one; each capped by its largest step (`h_max`: explicit, implicit), the explicit
/// one by its stability ceiling too. The explicit pair is taken when its right-hand sides per cycle (6 a step) cost less
/// than the implicit steps (`IMPLICIT_STEP_COST` each).
pub(super) fn explicit_is_cheaper(
    rtol: f64,
    omega: f64,
    ceiling: f64,
    h_max: [f64; 2],
    rho_inf: f64,
) -> bool {
    let (explicit, implicit) = predicted_steps(rtol, omega, ceiling, h_max, rho_inf);
    EXPLICIT_STAGES / explicit < IMPLICIT_STEP_COST / implicit
}

/// The explicit and implicit steps the rule of [`explicit_is_cheaper`] predicts.
pub(super) fn predicted_steps(
    rtol: f64,
    omega: f64,
    ceiling: f64,
    h_max: [f64; 2],
    rho_inf: f64,
) -> (f64, f64) {
    let c_explicit = ACCUMULATION * explicit_pair::ESTIMATE_CONSTANT;
    let c_implicit = ACCUMULATION * local_error_constant(rho_inf);
    let explicit = (rtol / c_explicit).powf(0.25) / omega;
    let implicit = (rtol / c_implicit).sqrt() / omega;
    (explicit.min(h_max[0]).min(ceiling), implicit.min(h_max[1]))
}

/// The carried state of an explicit error-controlled run: the error weights (as the
/// implicit control's), the controller and its account.
pub(super) struct Explicit {
    tol: Tolerances,
    h_min: f64,
    h_max: f64,
    /// ω₁/ACCUMULATION: errors per unit step accumulate over at most its inverse.
    omega: f64,
    pub h: f64,
    pub out_per_cycle: usize,
    kind_end: [usize; 2],
    diff: Vec<bool>,
    /// The largest |y|, |ẏ|, |ÿ| over the previous cycle and the current one so far (the
    /// implicit control's rule: `adaptive::Adaptive::start_cycle`), and over the current
    /// cycle so far.
    peak: Vec<f64>,
    rate_peak: Vec<f64>,
    accel_peak: Vec<f64>,
    cycle_peak: Vec<f64>,
    cycle_rate: Vec<f64>,
    cycle_accel: Vec<f64>,
    inv_omega: Vec<f64>,
    atol: Vec<f64>,
    scale: Vec<f64>,
    flow_group: Vec<u32>,
    /// Each vessel's flow amplitude over the previous cycle and the current one so far, and
    /// over the current cycle so far.
    group_peak: Vec<f64>,
    group_cycle: Vec<f64>,
    /// The largest scale per kind (pressure, flow, volume): a kind's default atol is its
    /// largest unknown's, the others' scaled by their share (`Tolerances::atol_of`).
    kind_largest: [f64; 3],
    /// The species cells' amounts: atol·V₀ per cell (a concentration tolerance, the
    /// species' default scaled by the cell's largest concentration over the species'
    /// largest), V₀, the largest |N| so far; the number of species.
    z_atol: Vec<f64>,
    z_volume: Vec<f64>,
    z_peak: Vec<f64>,
    z_cycle: Vec<f64>,
    n_species: usize,
    /// A step was just rejected: the next may not grow.
    rejected_last: bool,
    pub estimate: [f64; 4],
    pub steps: usize,
    pub rejected: usize,
    pub h_smallest: f64,
    pub h_largest: f64,
    yi: Vec<f64>,
    ydi: Vec<f64>,
    zi: Vec<f64>,
    obs: Vec<f64>,
}

impl Explicit {
    pub fn new(dae: &Dae, tol: Tolerances, s: &RunSettings, ceiling: f64) -> Self {
        let n_nodes = dae.n_nodes;
        let h_max = (s.period * MAX_STEP_PER_PERIOD).min(ceiling);
        Explicit {
            tol,
            h_min: s.period * 1e-9,
            h_max,
            omega: 2.0 * std::f64::consts::PI / (ACCUMULATION * s.period),
            // the first estimate is as good as any: start small and grow 5× a step
            h: (s.period * 1e-3).min(h_max),
            out_per_cycle: (s.period / s.output_every).round().max(1.0) as usize,
            kind_end: [n_nodes, n_nodes + dae.names.n_branches()],
            diff: dae.e.iter().map(|&e| e != 0.0).collect(),
            peak: Vec::new(),
            rate_peak: Vec::new(),
            accel_peak: Vec::new(),
            cycle_peak: Vec::new(),
            cycle_rate: Vec::new(),
            cycle_accel: Vec::new(),
            inv_omega: Vec::new(),
            atol: Vec::new(),
            scale: Vec::new(),
            flow_group: flow_groups(dae),
            group_peak: Vec::new(),
            group_cycle: Vec::new(),
            kind_largest: [0.0; 3],
            z_atol: Vec::new(),
            z_volume: Vec::new(),
            z_peak: Vec::new(),
            z_cycle: Vec::new(),
            n_species: 0,
            rejected_last: false,
            estimate: [0.0; 4],
            steps: 0,
            rejected: 0,
            h_smallest: f64::INFINITY,
            h_largest: 0.0,
            yi: Vec::new(),
            ydi: Vec::new(),
            zi: Vec::new(),
            obs: Vec::new(),
        }
    }

    /// A fresh controller for the accumulated-error estimate's second integration of a cycle
    /// (`Cycles::finer_last_cycle`): rtol / `factor`, and the step ceiling over
    /// `factor`^(1/5). Where the stability bound, not the tolerance, sets the run's steps, a
    /// tighter rtol alone takes the same steps and measures nothing (an estimate of 0); the
    /// pair's fifth-order error falls by 1/`factor` when its steps shrink by `factor`^(1/5),
    /// so the second integration's error is about 1/`factor` of the run's whichever limit
    /// holds, as the estimate assumes.
    pub(super) fn tighter(&self, dae: &Dae, s: &RunSettings, factor: f64) -> Explicit {
        let tol = Tolerances {
            rtol: self.tol.rtol / factor,
            ..self.tol
        };
        Explicit::new(dae, tol, s, self.h_max * factor.powf(-0.2))
    }

    /// The weights from the start state (the first cycle), or from the largest values over
    /// the cycle just ended (every later cycle: `start_cycle`).
    fn start(&mut self, st: &State<'_, '_>) {
        if !self.peak.is_empty() {
            self.start_cycle(st);
            return;
        }
        let n = st.y.len();
        self.peak = st.y.iter().map(|v| v.abs()).collect();
        self.rate_peak = vec![0.0; n];
        self.accel_peak = vec![0.0; n];
        self.cycle_peak.clone_from(&self.peak);
        self.cycle_rate = vec![0.0; n];
        self.cycle_accel = vec![0.0; n];
        self.inv_omega = vec![1.0 / self.omega; n];
        self.atol = vec![0.0; n];
        self.scale.clone_from(&self.peak);
        self.set_tolerances(&st.y);
        if let Some(sp) = st.species.as_ref() {
            let vol = sp.tr.cell_transport_volumes();
            self.n_species = sp.tr.species_names().len();
            let cells = vol.len() * self.n_species;
            self.z_volume = (0..cells).map(|k| vol[k % vol.len()]).collect();
            self.z_atol = vec![0.0; cells];
            self.z_peak = sp.z[..cells].iter().map(|z| z.abs()).collect();
            self.z_cycle.clone_from(&self.z_peak);
            self.species_tolerances();
        }
    }

    /// At a later cycle's start: the scales become the largest values over the cycle just
    /// ended, and the current cycle's start again from the state (as the implicit control's,
    /// `adaptive::Adaptive::start_cycle`): every scale, signal frequency and tolerance follows.
    fn start_cycle(&mut self, st: &State<'_, '_>) {
        std::mem::swap(&mut self.peak, &mut self.cycle_peak);
        std::mem::swap(&mut self.rate_peak, &mut self.cycle_rate);
        std::mem::swap(&mut self.accel_peak, &mut self.cycle_accel);
        for (c, y) in self.cycle_peak.iter_mut().zip(&st.y) {
            *c = y.abs();
        }
        self.cycle_rate.fill(0.0);
        self.cycle_accel.fill(0.0);
        for (i, w) in self.inv_omega.iter_mut().enumerate() {
            let (rp, ap) = (self.rate_peak[i], self.accel_peak[i]);
            *w = if rp > 0.0 {
                1.0 / (ap / rp / ACCUMULATION).max(self.omega)
            } else {
                1.0 / self.omega
            };
        }
        std::mem::swap(&mut self.group_peak, &mut self.group_cycle);
        self.group_cycle.fill(0.0);
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        for (&g, q) in self.flow_group.iter().zip(&st.y[n0..n1]) {
            if g != NO_VESSEL {
                let a = &mut self.group_cycle[g as usize];
                *a = a.max(q.abs());
            }
        }
        // (the vessels' amplitudes from the state, with every scale and tolerance)
        self.set_tolerances(&st.y);
        if let Some(sp) = st.species.as_ref() {
            std::mem::swap(&mut self.z_peak, &mut self.z_cycle);
            let cells = self.z_cycle.len();
            for (c, z) in self.z_cycle.iter_mut().zip(&sp.z[..cells]) {
                *c = z.abs();
            }
            self.species_tolerances();
        }
    }

    /// The cells' amount tolerances: V₀ times the species' atol of the cell's largest
    /// concentration |N|/V₀ so far (`Tolerances::atol_of`, against the species' largest).
    fn species_tolerances(&mut self) {
        let cells = self.z_peak.len() / self.n_species.max(1);
        for s in 0..self.n_species {
            let r = s * cells..(s + 1) * cells;
            let conc = self.z_peak[r.clone()].iter().zip(&self.z_volume[r.clone()]);
            let largest = conc.clone().fold(0.0f64, |m, (&z, &v)| m.max(z / v));
            for (a, (&z, &v)) in self.z_atol[r].iter_mut().zip(conc) {
                *a = v * self.tol.atol_of(3, z / v, largest);
            }
        }
    }

    fn kind_of(&self, i: usize) -> usize {
        (i >= self.kind_end[0]) as usize + (i >= self.kind_end[1]) as usize
    }

    /// The largest scaled error per kind (pressure, flow, volume, species) of the step of
    /// `h` that ended in (y, z) with the local error estimates (ey, ez).
    fn scaled_errors(&self, y: &[f64], (ey, ez): (&[f64], &[f64]), z: &[f64], h: f64) -> [f64; 4] {
        let mut kinds = [0.0f64; 4];
        let rtol = self.tol.rtol;
        for (i, (&yi, &e)) in y.iter().zip(ey).enumerate() {
            if !self.diff[i] {
                continue;
            }
            let per_step = (self.inv_omega[i] / h).max(1.0);
            let weight = self.atol[i] + rtol * yi.abs().max(self.scale[i]);
            let k = &mut kinds[self.kind_of(i)];
            *k = k.max(e.abs() * per_step / weight);
        }
        let per_step = (1.0 / (self.omega * h)).max(1.0);
        let cells = self.z_atol.iter().zip(&self.z_peak).zip(ez.iter().zip(z));
        for ((&a, &p), (&e, &zk)) in cells {
            kinds[3] = kinds[3].max(e.abs() * per_step / (a + rtol * p.max(zk.abs())));
        }
        kinds
    }

    /// The step after one of `h` with the scaled error `err` (order 4 per unit step).
    fn next_step(&self, h: f64, err: f64) -> f64 {
        let factor = if err > 0.0 {
            SAFETY * err.powf(-0.25)
        } else {
            GROW
        };
        let cap = if self.rejected_last { 1.0 } else { GROW };
        (h * factor.clamp(SHRINK, cap)).clamp(self.h_min, self.h_max)
    }

    /// An accepted step of `h`: the estimates, the peaks (|y|, |ẏ| from the first stage,
    /// |ÿ| from the two ends' rates) and the next step.
    fn accept(&mut self, y: &[f64], z: &[f64], rates: (&[f64], &[f64]), h: f64, kinds: [f64; 4]) {
        let rtol = self.tol.rtol;
        for (e, k) in self.estimate.iter_mut().zip(kinds) {
            *e = e.max(k * rtol);
        }
        let err = kinds.iter().fold(0.0f64, |m, &k| m.max(k));
        self.steps += 1;
        self.h_smallest = self.h_smallest.min(h);
        self.h_largest = self.h_largest.max(h);
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        let mut grown = false;
        for (i, (&yi, (&r0, &r1))) in y.iter().zip(rates.0.iter().zip(rates.1)).enumerate() {
            let c = &mut self.cycle_peak[i];
            *c = c.max(yi.abs());
            if (n0..n1).contains(&i) {
                let g = self.flow_group[i - n0];
                if g != NO_VESSEL && !self.group_cycle.is_empty() {
                    let a = &mut self.group_cycle[g as usize];
                    *a = a.max(yi.abs());
                }
            }
            if yi.abs() > self.peak[i] {
                self.peak[i] = yi.abs();
                grown = true;
                if !(n0..n1).contains(&i) {
                    self.scale[i] = yi.abs();
                }
            }
            if !self.diff[i] {
                continue;
            }
            let (r, a) = (r0.abs().max(r1.abs()), (r1 - r0).abs() / h);
            let (cr, ca) = (&mut self.cycle_rate[i], &mut self.cycle_accel[i]);
            (*cr, *ca) = (cr.max(r), ca.max(a));
            let (rp, ap) = (&mut self.rate_peak[i], &mut self.accel_peak[i]);
            *rp = rp.max(r);
            *ap = ap.max(a);
            if *rp > 0.0 {
                self.inv_omega[i] = 1.0 / (*ap / *rp / ACCUMULATION).max(self.omega);
            }
        }
        if grown {
            self.set_tolerances(y);
        }
        for ((p, c), zk) in self.z_peak.iter_mut().zip(&mut self.z_cycle).zip(z) {
            *p = p.max(zk.abs());
            *c = c.max(zk.abs());
        }
        self.species_tolerances();
        self.h = self.next_step(h, err);
        self.rejected_last = false;
    }

    fn reject(&mut self, h: f64, err: f64) {
        self.rejected += 1;
        let next = if err.is_finite() {
            self.next_step(h, err)
        } else {
            SHRINK * h
        };
        self.h = next.min(0.5 * h).max(self.h_min);
        self.rejected_last = true;
    }

    /// Every vessel's flow amplitude, every kind's largest scale, and every unknown's scale
    /// and absolute tolerance (the implicit control's rule: a vessel's flow against the
    /// vessel's amplitude; the default atol scaled by the unknown's share of its kind's
    /// largest scale, at least `SHARE_FLOOR`, a given one as it is: `Tolerances::atol_of`).
    fn set_tolerances(&mut self, y: &[f64]) {
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        if self.group_peak.is_empty() {
            let vessels = self.flow_group.iter().filter(|&&g| g != NO_VESSEL);
            let groups = vessels.map(|&g| g as usize + 1).max().unwrap_or(0);
            self.group_peak = vec![0.0; groups];
            self.group_cycle = vec![0.0; groups];
        }
        for (&g, q) in self.flow_group.iter().zip(&y[n0..n1]) {
            if g != NO_VESSEL {
                let p = &mut self.group_peak[g as usize];
                *p = p.max(q.abs());
            }
        }
        let ends = [0, n0, n1, self.peak.len()];
        for k in 0..3 {
            let peaks = self.peak[ends[k]..ends[k + 1]].iter();
            self.kind_largest[k] = peaks.fold(0.0f64, |m, &p| m.max(p));
        }
        for i in 0..self.peak.len() {
            let k = self.kind_of(i);
            let g = if k == 1 {
                self.flow_group[i - n0]
            } else {
                NO_VESSEL
            };
            let a = if g == NO_VESSEL {
                self.peak[i]
            } else {
                self.group_peak[g as usize]
            };
            self.scale[i] = self.peak[i].max(a);
            // (a flow that is no vessel's keeps the kind's flow atol, as in the implicit
            // control)
            self.atol[i] = if k == 1 && g == NO_VESSEL {
                self.tol.kind_atol(1, self.kind_largest[1])
            } else {
                self.tol.atol_of(k, a, self.kind_largest[k])
            };
        }
    }
}

impl Cycles<'_, '_> {
    /// One cycle of an explicit error-controlled run: steps chosen by the pair's estimate,
    /// the last ending on the cycle's end, rows from the continuous extension.
    pub(super) fn explicit_cycle(
        &mut self,
        ex: &mut Explicit,
        rows: &CycleRows,
        progress: &mut dyn FnMut(f64, f64) -> bool,
    ) -> Result<()> {
        let period = self.s.period;
        let (t0, t_end) = (rows.t0, rows.t0 + period);
        let n_out = ex.out_per_cycle;
        let mut next_out = 1;
        let mut t = t0;
        ex.start(&self.state);
        // (the pair replays no steps: its accepted steps are the step-size history only)
        self.periodic_steps.start_cycle(false);
        self.cycle_start = t0;
        // a step taken again to end on a valve event
        let mut cut: Option<Cut> = None;
        while t < t_end {
            let rem = t_end - t;
            let h = match cut {
                Some(c) => c.h,
                None => toward_end(ex.h, rem),
            };
            let kinds = match step(&mut self.state, t, h) {
                Ok(()) => {
                    let (dp, y, z) = parts(&mut self.state);
                    ex.scaled_errors(y, dp.errors(), z, h)
                }
                Err(e) if h <= ex.h_min => return Err(e),
                Err(_) => [f64::INFINITY; 4],
            };
            // a non-finite state (NaN estimate) is an error to reject, not one `max` skips
            let err = if kinds.iter().any(|k| k.is_nan()) {
                f64::INFINITY
            } else {
                kinds.iter().fold(0.0f64, |m, &k| m.max(k))
            };
            if err > 1.0 && h > ex.h_min {
                let (dp, y, z) = parts(&mut self.state);
                dp.reject(y, z);
                ex.reject(h, err);
                cut = None;
                continue;
            }
            let rtol = ex.tol.rtol;
            let next = match self.events.as_ref() {
                Some(ev) => {
                    let found = locate_event(ev, &mut self.state, t, h, rtol);
                    decide(found, (h, ex.h_min, rtol), ex.h, cut.take())
                }
                None => Next::Go,
            };
            if let Next::Redo(c) = next {
                let (dp, y, z) = parts(&mut self.state);
                dp.reject(y, z);
                cut = Some(c);
                continue;
            }
            let t_new = if h == rem { t_end } else { t + h };
            for tau in rows.due(period, n_out, &mut next_out, t_new) {
                self.explicit_row(ex, rows, ((tau - t) / h).clamp(0.0, 1.0), h, tau)?;
            }
            let (dp, y, z) = parts(&mut self.state);
            ex.accept(y, z, (dp.start_rate(), dp.end_rate()), h, kinds);
            dp.accept();
            self.periodic_steps.accepted(h);
            match next {
                Next::Switch(k, proposed) => {
                    self.switch_valves(k, t_new);
                    // the pair starts again at the event: a new first stage (the algebraic
                    // unknowns solved with the valves' new state)
                    parts(&mut self.state).0.reset();
                    ex.h = ex.h.max(proposed).min(ex.h_max);
                }
                Next::Approach(h_next) => {
                    ex.h = ex.h.min(h_next);
                    self.settle_events();
                }
                _ => self.settle_events(),
            }
            self.steps += 1;
            t = t_new;
            if ex.steps % 64 == 0 || t == t_end {
                self.state.check(t)?;
            }
            if self.steps % 256 == 0 && !progress(t, t_end) {
                return Err(Error::Interrupted { time: t });
            }
        }
        Ok(())
    }

    /// The output row at `time`, θ into the step of `h` just taken: the whole state from the
    /// continuous extension (algebraic unknowns solved there), the species outputs of it.
    fn explicit_row(
        &mut self,
        ex: &mut Explicit,
        rows: &CycleRows,
        theta: f64,
        h: f64,
        time: f64,
    ) -> Result<()> {
        if !rows.recorded {
            return Ok(());
        }
        let t = rows.output_time(time, self.s.output_all_cycles);
        let st = &mut self.state;
        let Flow::Explicit(dp) = &mut st.flow else {
            unreachable!("an explicit run steps the explicit pair");
        };
        let z = st.species.as_ref().map_or(&[][..], |sp| &sp.z[..]);
        let (yi, ydi, zi) = (&mut ex.yi, &mut ex.ydi, &mut ex.zi);
        dp.dense_state(time, theta, h, (&st.y, z), yi, ydi, zi)?;
        self.rec.record_with(t, |i| ex.yi[i])?;
        if rows.species {
            if let Some(sp) = self.state.species.as_mut() {
                let names = &self.state.dae.names;
                sp.tr
                    .check_finite(&ex.zi, time, &|v| names.vessel(v).map(str::to_owned))?;
                // what the transport carries between steps is put back (as `observe_at`)
                let carried = sp.tr.carried();
                // `observe` appends: one row per call (a row left in the buffer would be
                // recorded again in front of this one)
                ex.obs.clear();
                let seen = sp
                    .tr
                    .observe(time, &ex.yi, Some(&ex.ydi), &ex.zi, false, &mut ex.obs);
                sp.tr.restore_carried(&carried)?;
                seen?;
                self.rec.push_species(&ex.obs);
            }
        }
        if rows.committed && !self.rec.flush(false) {
            return Err(Error::Interrupted { time });
        }
        Ok(())
    }
}

/// The first valve event within the step of `h` from `t` just taken (see
/// [`Events::locate`]): the switching functions on the continuous extension, the algebraic
/// unknowns (a valve's node pressures) solved at each θ the root finder asks for.
fn locate_event(ev: &Events, st: &mut State<'_, '_>, t: f64, h: f64, rtol: f64) -> Option<Located> {
    let (dp, y, _) = parts(st);
    let y: &[f64] = y;
    let dense = RefCell::new((dp, Vec::new(), Vec::new(), Vec::new()));
    let at = |th: f64| {
        let mut d = dense.borrow_mut();
        let (dp, yi, ydi, zi) = &mut *d;
        let v = match dp.dense_state(t + th * h, th, h, (y, &[]), yi, ydi, zi) {
            Ok(()) => yi.clone(),
            // no state there: read as switched (the bracket closes in on the step's start)
            Err(_) => vec![f64::NAN; y.len()],
        };
        move |i: usize| v[i]
    };
    ev.locate(&|i| y[i], at, rtol)
}

/// One step of the explicit pair from `t`, the species (if any) in its stages.
fn step(st: &mut State<'_, '_>, t: f64, h: f64) -> Result<()> {
    st.dt = h;
    let Flow::Explicit(dp) = &mut st.flow else {
        unreachable!("an explicit run steps the explicit pair");
    };
    match st.species.as_mut() {
        Some(sp) => dp.step(t, h, &mut st.y, &mut sp.z, &mut *sp.tr),
        None => dp.step(t, h, &mut st.y, &mut [], &mut Uncoupled),
    }
}

/// The pair, the flow state and the species amounts (empty without species).
fn parts<'s, 'd>(st: &'s mut State<'d, '_>) -> (&'s mut Dopri5<'d>, &'s mut [f64], &'s mut [f64]) {
    let State {
        flow, species, y, ..
    } = st;
    let Flow::Explicit(dp) = flow else {
        unreachable!("an explicit run steps the explicit pair");
    };
    let z = species.as_mut().map_or(&mut [][..], |sp| &mut sp.z[..]);
    (dp, y, z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_takes_the_pair_when_non_stiff_and_the_implicit_method_when_stiff() {
        let (omega, h_max) = (2.0 * std::f64::consts::PI * 10.0, [1.0 / 4.0, 1.0 / 32.0]);
        // non-stiff (ceiling 10 ms): the pair's fourth-order step wins at every tolerance
        for rtol in [1e-2, 1e-3, 1e-4, 1e-6] {
            assert!(explicit_is_cheaper(rtol, omega, 1e-2, h_max, 0.5), "{rtol}");
        }
        // stiff (ceiling 10 µs): the implicit step at rtol 1e-2 is 1.7 ms
        for rtol in [1e-2, 1e-3, 1e-4] {
            assert!(
                !explicit_is_cheaper(rtol, omega, 1e-5, h_max, 0.5),
                "{rtol}"
            );
        }
        // the predicted steps follow rtol^(1/4) and rtol^(1/2)
        let (e1, i1) = predicted_steps(1e-4, omega, 1.0, [1.0; 2], 0.5);
        let (e2, i2) = predicted_steps(1e-8, omega, 1.0, [1.0; 2], 0.5);
        assert!((e1 / e2 - 10.0).abs() < 1e-9 && (i1 / i2 - 100.0).abs() < 1e-9);
    }
}
