//! Classical fixed-step RK4 on the differential unknowns (E_ii > 0); the algebraic unknowns
//! (capacitance-free nodes, inductance-free branches, prescribed pressures) are eliminated at
//! every stage by a sparse solve whose matrix is factorised once for linear circuits (see
//! `algebraic`, which also holds the index reduction). The RK4 tableau lives here once, as the
//! stage and combination kernels [`rk4_stage`] and [`rk4_combine`], used by the flow, by the
//! coupled species state and by plain ODEs ([`rk4_ode`]).

use super::algebraic::{Algebraic, Elimination, Reduction, reduce_prescribed_inductors};
use super::newton::{self, NewtonControl, singular};
use super::stiff::{self, STIFF_RATE, StiffBranch};
use crate::circuit::{Dae, JacobianKind, Regime};
use crate::error::{Error, Result};

/// A state integrated together with the flow in the same RK4 step (species amounts): its
/// derivative is evaluated at every stage from that stage's consistent flow state, so the
/// coupled system is advanced as one ODE (docs/physics.md §2.5, "monolithic").
pub trait Coupled {
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()>;

    /// The derivative at (t, y, the sink's stage state), each entry handed to `sink` as it is
    /// computed (a state that can do so saves storing the four stage derivatives and the
    /// separate stage and combination passes over them). By default: [`Coupled::derivative`]
    /// into the sink's scratch, then every entry to the sink.
    fn stage_derivative(&mut self, time: f64, y: &[f64], sink: &mut StageSink<'_>) -> Result<()> {
        stage_derivative_stored(self, time, y, sink)
    }
}

/// Flow only.
pub struct Uncoupled;
impl Coupled for Uncoupled {
    #[inline]
    fn derivative(&mut self, _: f64, _: &[f64], _: &[f64], _: &mut [f64]) -> Result<()> {
        Ok(())
    }
}

/// Stage storage of an RK4 step: the stage state and the running weighted sum of the stage
/// derivatives (coupled states, see [`StageSink`]); the four stage derivatives of a plain ODE
/// ([`rk4_ode`]; the first one is the scratch of [`Coupled::stage_derivative`]'s default).
#[derive(Debug, Clone, Default)]
pub struct CoupledStages {
    k: [Vec<f64>; 4],
    stage: Vec<f64>,
    acc: Vec<f64>,
}

impl CoupledStages {
    pub fn new(n: usize) -> Self {
        CoupledStages {
            k: [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            stage: vec![0.0; n],
            acc: vec![0.0; n],
        }
    }

    /// Storage for a coupled state only (no stage derivatives kept: [`StageSink`]).
    pub fn coupled(n: usize) -> Self {
        CoupledStages {
            k: Default::default(),
            stage: vec![0.0; n],
            acc: vec![0.0; n],
        }
    }
}

/// The classical RK4 weights (1, 2, 2, 1) summed stage by stage: the running sum after stage
/// `s` (0-based) given the one before (`acc`, ignored at stage 0) and stage `s`'s derivative
/// `k`. Summed left to right, ((k1 + 2 k2) + 2 k3) + k4, as the combination always was, so
/// folding it one stage at a time rounds exactly as the four-term expression.
#[inline(always)]
fn rk4_weighted_sum(acc: f64, k: f64, s: usize) -> f64 {
    match s {
        0 => k,
        1 | 2 => acc + 2.0 * k,
        _ => acc + k,
    }
}

/// The increment Δt/6 · (weighted sum of the four stage derivatives) of the RK4 combination.
#[inline(always)]
fn rk4_increment(dt: f64, weighted_sum: f64) -> f64 {
    dt / 6.0 * weighted_sum
}

/// Stage `s` of a coupled state's RK4 step, applied entry by entry as the stage derivative is
/// computed ([`StageSink::sweep`]), so that the derivative is never stored: stages 1–3 add the entry to the running
/// weighted sum and write the next stage state base + c Δt k in place of the stage state just
/// read (an entry's stage value is read only for its own derivative, before it is handed
/// over); stage 4 completes the sum and advances the base state. Bit for bit the stage and
/// combination kernels [`rk4_stage`] and [`rk4_combine`].
pub struct StageSink<'a> {
    s: usize,
    dt: f64,
    c_dt: f64,
    base: &'a mut [f64],
    acc: &'a mut [f64],
    stage: &'a mut [f64],
    scratch: &'a mut Vec<f64>,
}

impl StageSink<'_> {
    /// The stage state at which this stage's derivative is evaluated.
    #[inline]
    pub fn z(&self) -> &[f64] {
        self.stage
    }

    /// Entries `start..start + n` in one pass: `rate(j, z)` is the derivative of entry
    /// `start + j` at its stage value `z`. (One call site of `rate`, so that it is inlined; the
    /// branch on the stage is the same for every entry.)
    #[inline(always)]
    pub fn sweep(&mut self, start: usize, n: usize, mut rate: impl FnMut(usize, f64) -> f64) {
        let r = start..start + n;
        let (base, acc) = (&mut self.base[r.clone()], &mut self.acc[r.clone()]);
        let stage = &mut self.stage[r];
        let (s, dt, c_dt) = (self.s, self.dt, self.c_dt);
        for (j, ((b, a), st)) in base.iter_mut().zip(acc.iter_mut()).zip(stage).enumerate() {
            let k = rate(j, *st);
            let sum = rk4_weighted_sum(*a, k, s);
            if s < 3 {
                *a = sum;
                *st = *b + c_dt * k;
            } else {
                *b += rk4_increment(dt, sum);
            }
        }
    }
}

/// [`Coupled::stage_derivative`] by way of the stored derivative (the trait's default, also
/// the fallback of a state whose derivative cannot be handed over entry by entry).
pub fn stage_derivative_stored<C: Coupled + ?Sized>(
    coupled: &mut C,
    time: f64,
    y: &[f64],
    sink: &mut StageSink<'_>,
) -> Result<()> {
    let mut k = std::mem::take(sink.scratch);
    k.resize(sink.stage.len(), 0.0);
    let done = coupled.derivative(time, y, sink.stage, &mut k);
    if done.is_ok() {
        sink.sweep(0, k.len(), |j, _| k[j]);
    }
    *sink.scratch = k;
    done
}

/// Stage times (fractions of the step) of stages 2–4 of the classical RK4 tableau; stage s + 1
/// is evaluated at base + c_s Δt k_s.
pub const RK4_STAGE: [f64; 3] = [0.5, 0.5, 1.0];

/// Which entries of a state an RK4 kernel updates.
#[derive(Debug, Clone, Copy)]
pub enum Rows<'a> {
    All,
    /// Only these (the differential unknowns of a DAE).
    Only(&'a [usize]),
}

/// Stage state of the classical RK4: `stage_i = base_i + c·Δt·k_i` for the `rows` (c from
/// [`RK4_STAGE`], `c_dt` = c·Δt). The RK4 stage kernel of the flow and of the species.
#[inline]
pub fn rk4_stage(stage: &mut [f64], base: &[f64], k: &[f64], c_dt: f64, rows: Rows<'_>) {
    match rows {
        Rows::All => {
            for ((s, b), ki) in stage.iter_mut().zip(base).zip(k) {
                *s = b + c_dt * ki;
            }
        }
        Rows::Only(idx) => {
            for &i in idx {
                stage[i] = base[i] + c_dt * k[i];
            }
        }
    }
}

/// The classical RK4 combination `y_i += Δt/6 (k1 + 2 k2 + 2 k3 + k4)_i` for the `rows`.
#[inline]
pub fn rk4_combine(y: &mut [f64], k: &[Vec<f64>; 4], dt: f64, rows: Rows<'_>) {
    let increment = |i: usize| {
        let sum = (0..4).fold(0.0, |acc, s| rk4_weighted_sum(acc, k[s][i], s));
        rk4_increment(dt, sum)
    };
    match rows {
        Rows::All => {
            for (i, yi) in y.iter_mut().enumerate() {
                *yi += increment(i);
            }
        }
        Rows::Only(idx) => {
            for &i in idx {
                y[i] += increment(i);
            }
        }
    }
}

/// Right-hand side f(t, z, dz) of a plain ODE.
pub type OdeRhs<'f> = dyn FnMut(f64, &[f64], &mut [f64]) -> Result<()> + 'f;

/// Classical RK4 step of a plain ODE z' = f(t, z), with the stage storage of a coupled state.
pub fn rk4_ode(
    time: f64,
    dt: f64,
    z: &mut [f64],
    st: &mut CoupledStages,
    f: &mut OdeRhs<'_>,
) -> Result<()> {
    if st.stage.len() != z.len() {
        *st = CoupledStages::new(z.len());
    }
    st.stage.copy_from_slice(z);
    f(time, &st.stage, &mut st.k[0])?;
    for (s, c) in RK4_STAGE.into_iter().enumerate() {
        rk4_stage(&mut st.stage, z, &st.k[s], c * dt, Rows::All);
        f(time + c * dt, &st.stage, &mut st.k[s + 1])?;
    }
    rk4_combine(z, &st.k, dt, Rows::All);
    Ok(())
}

/// The step, as a fraction of the RK4 step, of the left difference that gives the explicit time
/// dependence of time-varying coefficients and elements in [`Rk4::full_rate`] (its truncation
/// error is this fraction of the step times their second derivative; its round-off, 1e-16 of
/// their value over it, stays far below the rates).
pub const TIME_PARTIAL_STEP: f64 = 1e-6;

/// Classical RK4 on the differential unknowns of E ẏ + F y + c(y) = f(t), the algebraic ones
/// eliminated at every stage (see the module documentation).
pub struct Rk4<'a> {
    dae: &'a Dae,
    regime: Regime,
    pub dt: f64,
    /// E of the circuit with the index reduction applied (zero on algebraic rows).
    e: Vec<f64>,
    /// Forcing-slope terms of the index reduction (see `Reduction`).
    rate: Vec<(usize, f64, usize)>,
    pub diff: Vec<usize>,
    alg: Option<Algebraic>,
    f: Vec<f64>,
    /// Stages of the flow state.
    st: CoupledStages,
    /// 2 S |Q| of stenoses on differential unknowns at the linearisation point of
    /// `linear_operator` (zero: the linear circuit).
    lin_stenosis: Vec<(usize, f64)>,
    /// The time at which `linear_operator` freezes time-varying coefficients, and the state at
    /// which it linearises stenoses (empty: zero).
    lin_time: f64,
    lin_state: Vec<f64>,
    /// The elements' state in `linear_operator`: stiffest (valves open) or valves closed.
    lin_kind: JacobianKind,
    /// E of the index reduction with every stiff branch differential (empty without stiff
    /// branches: no other mode is ever built).
    base_e: Vec<f64>,
    /// Valves behind inductors (see `stiff`), and which of them are algebraic now (bit i).
    stiff: Vec<StiffBranch>,
    mask: u64,
    /// The (E, differential unknowns, algebraic part) of the other masks met so far.
    parked: Vec<Mode>,
}

/// E, the differential unknowns and the algebraic part for one set of algebraic stiff
/// branches.
struct Mode {
    mask: u64,
    e: Vec<f64>,
    diff: Vec<usize>,
    alg: Option<Algebraic>,
}

impl<'a> Rk4<'a> {
    /// The integrator of `dae` in `regime` with step `dt`. A circuit whose algebraic part stays
    /// singular after the index reduction (index 2) is a model error.
    pub fn new(dae: &'a Dae, regime: Regime, dt: f64) -> Result<Self> {
        if let Some((el, why)) = dae
            .elements
            .iter()
            .find_map(|el| el.rk4_unsupported().map(|why| (el.name(), why)))
        {
            return Err(Error::model(el, format!("RK4 cannot integrate it: {why}")));
        }
        let Reduction { e, rate } = reduce_prescribed_inductors(dae, regime);
        let n = dae.n;
        for el in &dae.elements {
            if el.switched_unknowns().iter().any(|&i| e[i] == 0.0) {
                return Err(Error::model(
                    el.name(),
                    "RK4 cannot integrate it: a valve without inductance has no flow state to \
                     hold while closed; give every valve an inductance or use \
                     method=\"generalized-alpha\"",
                ));
            }
        }
        let Mode { e, diff, alg, .. } = Self::mode(dae, regime, &e, &[], 0)?;
        let stiff = stiff::find(dae, &e);
        // (read only to build another stiff branches' mode: none without stiff branches)
        let base_e = if stiff.is_empty() {
            Vec::new()
        } else {
            e.clone()
        };
        Ok(Rk4 {
            dae,
            regime,
            dt,
            stiff,
            base_e,
            mask: 0,
            parked: Vec::new(),
            diff,
            e,
            rate,
            alg,
            f: vec![0.0; n],
            // the first stage's slot only: a generalized-α run builds this integrator just to
            // make its start consistent (`derivative`), and the other stages' five state-sized
            // vectors (~100 B per segment) would sit on top of the run's setup for nothing;
            // `step_coupled` sizes them at the first step (the same zeros)
            st: CoupledStages {
                k: [vec![0.0; n], Vec::new(), Vec::new(), Vec::new()],
                stage: Vec::new(),
                acc: Vec::new(),
            },
            lin_stenosis: Vec::new(),
            lin_time: 0.0,
            lin_state: Vec::new(),
            lin_kind: JacobianKind::Stiffest,
        })
    }

    /// The mode with the stiff branches of `mask` algebraic. A singular algebraic part (after
    /// the index reduction: index 2) is a model error.
    fn mode(
        dae: &Dae,
        regime: Regime,
        base_e: &[f64],
        stiff: &[StiffBranch],
        mask: u64,
    ) -> Result<Mode> {
        let mut e = base_e.to_vec();
        for (i, b) in stiff.iter().enumerate() {
            if mask & (1 << i) != 0 {
                e[b.inductor] = 0.0;
            }
        }
        let mut alg = Algebraic::analyse(dae, &e, regime)?;
        if let Some(a) = alg.as_mut() {
            a.check_index1(dae)?;
        }
        Ok(Mode {
            mask,
            diff: (0..dae.n).filter(|&i| e[i] != 0.0).collect(),
            e,
            alg,
        })
    }

    /// Whether the elimination of the algebraic unknowns is nonlinear (a stenosis or a valve
    /// law on an algebraic row): every stage then runs a Newton iteration.
    pub fn eliminates_by_newton(&self) -> bool {
        self.alg.as_ref().is_some_and(|a| !a.is_linear())
    }

    /// The element index of the first stiff branch's valve (None without one).
    pub fn stiff_valve(&self) -> Option<usize> {
        self.stiff.first().map(|b| b.valve)
    }

    /// Number of stiff branches (valves behind inductors, see `stiff`).
    pub fn stiff_branches(&self) -> usize {
        self.stiff.len()
    }

    /// Make the stiff branches of `mask` (bit i: branch i) algebraic: the current E, the
    /// differential unknowns and the algebraic part are parked and the mask's taken (built on
    /// first use). The algebraic Newton's running scale carries over.
    pub fn set_stiff_mask(&mut self, mask: u64) -> Result<()> {
        if mask == self.mask {
            return Ok(());
        }
        let next = match self.parked.iter().position(|m| m.mask == mask) {
            Some(k) => self.parked.swap_remove(k),
            None => Self::mode(self.dae, self.regime, &self.base_e, &self.stiff, mask)?,
        };
        let scale = self.alg.as_ref().map(|a| a.magnitude);
        let Mode { e, diff, alg, .. } = next;
        let old = Mode {
            mask: self.mask,
            e: std::mem::replace(&mut self.e, e),
            diff: std::mem::replace(&mut self.diff, diff),
            alg: std::mem::replace(&mut self.alg, alg),
        };
        self.parked.push(old);
        self.mask = mask;
        if let (Some(a), Some(s)) = (self.alg.as_mut(), scale) {
            a.magnitude = s;
        }
        Ok(())
    }

    /// The mask whose branches are algebraic at state `y` and step `dt`: R(ΔP) Δt > L, or a
    /// flow that the inductor's rate at `y` (the forcing last set) reverses within the step,
    /// Q (Q + Δt Q̇) < 0: the valve closes in this step, and its flow through the closing
    /// valve is the quasi-steady one (explicit stages would drive it backwards through the
    /// switch, where the elimination has no well-posed start).
    ///
    /// A valve that reads R(ΔP) Δt > L at no or forward flow while the branch's whole drop
    /// (chamber to the valve's far side, ΔP + L Q̇) opens it is opening: its inductor is
    /// accelerating the flow from rest (a zero start's 0, svZeroDSolver's start), and the
    /// branch stays differential (docs/physics.md §1.8). Its closed reading is the tanh's
    /// switch width, |Q| ≤ width/R, which one explicit stage crosses; quasi-steady, the
    /// branch would instead jump to the open valve's flow (1.2 of the aortic flow's range
    /// at closedLoopHeart_singleVessel_decomposed's start).
    fn stiff_mask_at(&self, y: &[f64], dt: f64) -> u64 {
        (self.stiff.iter().enumerate())
            .filter(|(_, b)| {
                let valve = &self.dae.elements[b.valve];
                let j = b.inductor;
                let rate = (self.f[j] - self.dae.f.row_dot(j, y)) / b.inductance;
                let stiff =
                    |lift: f64| valve.valve_resistance(y, lift) * dt > STIFF_RATE * b.inductance;
                if stiff(0.0) {
                    let opening =
                        b.orientation * y[j] >= 0.0 && !stiff(b.orientation * b.inductance * rate);
                    if !opening {
                        return true;
                    }
                }
                y[j] * (y[j] + dt * rate) < 0.0
            })
            .fold(0, |m, (i, _)| m | (1 << i))
    }

    /// The mask of the branches that stay algebraic at step `dt` even with the valve fully
    /// open (R_min Δt > L): the others can be differential at that step.
    pub fn stiff_mask_open(&self, dt: f64) -> u64 {
        (self.stiff.iter().enumerate())
            .filter(|(_, b)| b.r_min * dt > STIFF_RATE * b.inductance)
            .fold(0, |m, (i, _)| m | (1 << i))
    }

    /// The mask of every stiff branch.
    pub fn stiff_mask_all(&self) -> u64 {
        (0..self.stiff.len()).fold(0, |m, i| m | (1 << i))
    }

    /// [`Rk4::set_stiff_mask`] for `linear_operator` (the stability bound): the algebraic part
    /// is refactorised at the linearisation point.
    pub fn set_operator_mask(&mut self, mask: u64) -> Result<()> {
        self.set_stiff_mask(mask)?;
        self.refactor_linearization()
    }

    /// Take the stiff branches' mode of state `y` at this integrator's step. A branch turning
    /// algebraic starts its elimination from its quasi-steady state (see
    /// [`StiffBranch::quasi_steady`]); `y` holds the elimination's start values only.
    fn select_mode(&mut self, y: &mut [f64]) -> Result<()> {
        if self.stiff.is_empty() {
            return Ok(());
        }
        let mask = self.stiff_mask_at(y, self.dt);
        let fresh = mask & !self.mask;
        for (_, b) in (self.stiff.iter().enumerate()).filter(|(i, _)| fresh & (1 << i) != 0) {
            b.quasi_steady(self.dae, &self.f, y);
        }
        self.set_stiff_mask(mask)
    }

    /// The forcing at `time`, with the index reduction's slope terms.
    fn forcing(&mut self, time: f64) {
        self.dae.forcing_into(time, self.regime, &mut self.f);
        // a periodic waveform's mean slope is zero
        if self.regime == Regime::Transient {
            for &(row, scale, k) in &self.rate {
                self.f[row] += scale * self.dae.forcing[k].1.slope(time);
            }
        }
    }

    /// Make the algebraic unknowns of `y` consistent with its differential ones at the forcing
    /// last set by `forcing`.
    fn solve_algebraic(&mut self, y: &mut [f64], time: f64) -> Result<()> {
        let Some(alg) = self.alg.as_mut() else {
            return Ok(());
        };
        let (mut r, mut scale) = (std::mem::take(&mut alg.r), alg.magnitude);
        let mut p = Elimination {
            dae: self.dae,
            alg,
            f: &self.f,
            y,
            time,
        };
        let done = newton::solve(&mut p, &mut r, &NewtonControl::default(), &mut scale, time);
        (alg.r, alg.magnitude) = (r, scale);
        done
    }

    /// ẏ of the differential unknowns at (t, y) into stage slot `out`; the algebraic unknowns
    /// of `y` are updated.
    fn rhs(&mut self, time: f64, y: &mut [f64], out: usize) -> Result<()> {
        self.forcing(time);
        self.solve_algebraic(y, time)?;
        let k = &mut self.st.k[out];
        for &i in &self.diff {
            k[i] = (self.f[i] - self.dae.f.row_dot(i, y)) / self.e[i];
        }
        for &(i, s) in &self.dae.stenosis {
            if self.e[i] != 0.0 {
                k[i] -= s * y[i].abs() * y[i] / self.e[i];
            }
        }
        if self.regime == Regime::Transient {
            for (i, law) in &self.dae.varying {
                if self.e[*i] != 0.0 {
                    k[*i] -= law.delta(time) * y[*i] / self.e[*i];
                }
            }
        }
        let e = &self.e;
        self.dae.element_terms(time, y, |i, c| {
            if e[i] != 0.0 {
                k[i] -= c / e[i];
            }
        });
        // switching laws in their explicit form: a closed valve's flow keeps its value
        for el in &self.dae.elements {
            el.rk4_held(y, &mut |i| k[i] = 0.0);
        }
        Ok(())
    }

    /// ẏ of the differential unknowns at (t, y) into `out` (its other entries untouched);
    /// the algebraic unknowns of `y` are made consistent first (the stages of an explicit
    /// pair, `explicit_pair`).
    pub fn rate_into(&mut self, time: f64, y: &mut [f64], out: &mut [f64]) -> Result<()> {
        self.rhs(time, y, 0)?;
        for &i in &self.diff {
            out[i] = self.st.k[0][i];
        }
        Ok(())
    }

    /// Time derivative of the differential unknowns at (t, y) (zero for algebraic ones);
    /// the algebraic unknowns of `y` are made consistent first.
    /// The stiff branches keep their mode (`y` may not be consistent yet: a zero start's
    /// pressures would read every valve half-closed).
    pub fn derivative(&mut self, time: f64, y: &mut [f64]) -> Result<Vec<f64>> {
        self.rhs(time, y, 0)?;
        let mut out = vec![0.0; self.dae.n];
        for &i in &self.diff {
            out[i] = self.st.k[0][i];
        }
        Ok(out)
    }

    /// ẏ of every unknown at (t, y), the rate an output reports (svZeroDSolver's
    /// `output_derivative`): the differential rows as [`Rk4::derivative`], the algebraic ones
    /// from the time derivative of their equations F y + c(t, y) = f(t) along the solution,
    /// J_aa ẏ_a = ∂f_a/∂t − ∂c_a/∂t − J_ad ẏ_d (J = F + ∂c/∂y with the stenosis and
    /// time-varying terms). The forcing's slopes are exact, taken [`TIME_PARTIAL_STEP`] of the
    /// step before `time` (the left one at a table's kink, as svZeroDSolver's ẏ there); the
    /// explicit time dependence of time-varying coefficients and elements is a left difference
    /// over that step at fixed y. `y`
    /// is made consistent (pass a copy of the run's state); the algebraic Newton's running
    /// scale is left as it was, so recording the rates never changes the run.
    pub fn full_rate(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let scale = self.alg.as_ref().map(|a| a.magnitude);
        let d = self.derivative(time, y);
        if let (Some(a), Some(s)) = (self.alg.as_mut(), scale) {
            a.magnitude = s;
        }
        yd.copy_from_slice(&d?);
        if self.alg.is_none() {
            return Ok(());
        }
        let dae = self.dae;
        let b = self.explicit_time_rate(time, y);
        let alg = self.alg.as_mut().expect("algebraic part");
        let mut r: Vec<f64> = alg.rows.iter().map(|&g| b[g]).collect();
        let e = &self.e;
        let mut local = vec![usize::MAX; dae.n];
        for (l, &g) in alg.rows.iter().enumerate() {
            local[g] = l;
            for k in dae.f.row(g) {
                let c = dae.f.col[k] as usize;
                if e[c] != 0.0 {
                    r[l] -= dae.f.val[k] * yd[c];
                }
            }
        }
        if !dae.elements.is_empty() {
            let pattern = dae.element_pattern();
            let mut jac = vec![0.0; pattern.len()];
            dae.element_jacobian(1.0, time, y, &mut jac, JacobianKind::Exact);
            for (&(row, c), v) in pattern.iter().zip(&jac) {
                if local[row] != usize::MAX && e[c] != 0.0 {
                    r[local[row]] -= v * yd[c];
                }
            }
        }
        if !alg.is_constant() {
            alg.factor(dae, y, time, JacobianKind::Exact)
                .map_err(|m| singular(time, &m))?;
        }
        if !alg.lu.solve_in_place(&mut r) {
            return Err(singular(time, "algebraic rates"));
        }
        for (&g, v) in alg.rows.iter().zip(&r) {
            yd[g] = *v;
        }
        Ok(())
    }

    /// ∂/∂t of f(t) − D(t) y − c(t, y) at fixed y, every row: the forcing's slopes (with the
    /// index reduction's slope terms' curvature), the time-varying coefficients' and the
    /// elements' explicit time dependence by a left difference.
    fn explicit_time_rate(&self, time: f64, y: &[f64]) -> Vec<f64> {
        let dae = self.dae;
        let mut b = vec![0.0; dae.n];
        let h = TIME_PARTIAL_STEP * self.dt;
        if self.regime == Regime::Transient {
            // the slopes just before `time`: the left ones at a table's kink even where the
            // output time's round-off lands past the knot
            let before = time - h;
            for (row, w) in &dae.forcing {
                b[*row] += w.slope(before);
            }
            for &(row, scale, k) in &self.rate {
                b[row] += scale * dae.forcing[k].1.curvature(before);
            }
            for (i, law) in &dae.varying {
                b[*i] -= (law.delta(time) - law.delta(time - h)) / h * y[*i];
            }
        }
        if dae.elements.iter().any(|el| el.period().is_some()) {
            dae.element_terms(time, y, |i, c| b[i] -= c / h);
            dae.element_terms(time - h, y, |i, c| b[i] += c / h);
        }
        b
    }

    /// Bring the algebraic unknowns of an initial state in line with the forcing at `time`.
    /// The running scale of the algebraic Newton solve (None without algebraic unknowns),
    /// carried by a checkpoint.
    pub fn newton_scale(&self) -> Option<&super::newton::Magnitude> {
        self.alg.as_ref().map(|a| &a.magnitude)
    }

    pub fn newton_scale_mut(&mut self) -> Option<&mut super::newton::Magnitude> {
        self.alg.as_mut().map(|a| &mut a.magnitude)
    }

    pub fn make_consistent(&mut self, time: f64, y: &mut [f64]) -> Result<()> {
        self.forcing(time);
        // the given flows of the stiff branches' inductors are start values (a zero start's
        // 0), as for every differential unknown: the valves' state follows from them
        if !self.stiff.is_empty() {
            self.set_stiff_mask(0)?;
        }
        self.solve_algebraic(y, time)?;
        // the valves' resistances follow the consistent pressures
        let mask = self.mask;
        self.select_mode(y)?;
        if self.mask != mask {
            self.solve_algebraic(y, time)?;
        }
        Ok(())
    }

    /// The stages after the first, sized at the first step (see `Rk4::new`); the flow's
    /// running sum `acc` is never used (its stages are combined by `rk4_combine`).
    fn size_stages(&mut self) {
        let n = self.dae.n;
        if self.st.stage.len() != n {
            for k in &mut self.st.k[1..] {
                *k = vec![0.0; n];
            }
            self.st.stage = vec![0.0; n];
        }
    }

    pub fn step(&mut self, time: f64, y: &mut [f64]) -> Result<()> {
        self.step_coupled(
            time,
            y,
            &mut [],
            &mut CoupledStages::default(),
            &mut Uncoupled,
        )
    }

    /// One RK4 step of the flow state `y` and a coupled state `z` (same stages, same weights).
    pub fn step_coupled<C: Coupled>(
        &mut self,
        time: f64,
        y: &mut [f64],
        z: &mut [f64],
        zk: &mut CoupledStages,
        coupled: &mut C,
    ) -> Result<()> {
        let dt = self.dt;
        let coupled_on = !z.is_empty();
        // stiff branches: algebraic for the whole step when R(ΔP) Δt > L at its start (or the
        // valve closes within it)
        if !self.stiff.is_empty() {
            self.forcing(time);
            self.select_mode(y)?;
        }
        self.size_stages();
        let mut stage = std::mem::take(&mut self.st.stage);
        stage.copy_from_slice(y);
        self.rhs(time, &mut stage, 0)?;
        if coupled_on {
            if zk.stage.len() != z.len() || zk.acc.len() != z.len() {
                *zk = CoupledStages::coupled(z.len());
            }
            zk.stage.copy_from_slice(z);
        }
        // the coupled state's stage s derivative is evaluated at the flow's stage s state; its
        // sink writes the coupled stage s + 1 state (or, at the last stage, the new state)
        let mut coupled_stage = |s: usize, ts: f64, y_stage: &[f64], z: &mut [f64]| {
            if !coupled_on {
                return Ok(());
            }
            let c_dt = RK4_STAGE.get(s).map_or(0.0, |c| c * dt);
            let mut sink = StageSink {
                s,
                dt,
                c_dt,
                base: z,
                acc: &mut zk.acc,
                stage: &mut zk.stage,
                scratch: &mut zk.k[0],
            };
            coupled.stage_derivative(ts, y_stage, &mut sink)
        };
        coupled_stage(0, time, &stage, z)?;
        for (s, c) in RK4_STAGE.into_iter().enumerate() {
            rk4_stage(&mut stage, y, &self.st.k[s], c * dt, Rows::Only(&self.diff));
            let ts = time + c * dt;
            self.rhs(ts, &mut stage, s + 1)?;
            coupled_stage(s + 1, ts, &stage, z)?;
        }
        rk4_combine(y, &self.st.k, dt, Rows::Only(&self.diff));
        // algebraic unknowns of the last stage are the best warm start
        if let Some(alg) = &self.alg {
            for &g in &alg.rows {
                y[g] = stage[g];
            }
        }
        self.st.stage = stage;
        self.forcing(time + dt);
        self.solve_algebraic(y, time + dt)?;
        // a valve that closed during the step: its flow is clamped at zero (docs/physics.md
        // §1.10), and the algebraic unknowns follow
        let mut clamped = false;
        for el in &self.dae.elements {
            clamped |= el.rk4_after_step(y);
        }
        if clamped {
            self.solve_algebraic(y, time + dt)?;
        }
        Ok(())
    }

    /// The circuit this integrator steps.
    pub fn dae(&self) -> &'a Dae {
        self.dae
    }

    /// The state `linear_operator` linearises at (empty: zero).
    pub fn linearization_state(&self) -> &[f64] {
        &self.lin_state
    }

    /// E_ii of the differential unknowns, in `diff` order.
    pub fn mass_diagonal(&self) -> Vec<f64> {
        self.diff.iter().map(|&i| self.e[i]).collect()
    }

    /// Linearise stenoses (S|Q|Q → 2S|Q| per unit flow) at state `y` for `linear_operator`:
    /// a stenosis on an inductor adds −2S|Q|/L to that branch's eigenvalue.
    pub fn set_linearization(&mut self, y: &[f64]) -> Result<()> {
        self.lin_stenosis = self
            .dae
            .stenosis
            .iter()
            .filter(|(i, _)| self.e[*i] != 0.0)
            .map(|&(i, s)| (i, 2.0 * s * y[i].abs()))
            .collect();
        self.lin_state = y.to_vec();
        self.refactor_linearization()
    }

    /// Whether time-varying coefficients act (the operator of `linear_operator` then depends
    /// on the time set by [`Rk4::set_operator_time`]).
    pub fn is_time_varying(&self) -> bool {
        !self.dae.is_constant(self.regime)
    }

    /// The times within a period at which the stability limit of a time-varying circuit is
    /// sampled: `n` evenly spaced, plus every law's breakpoints (its extremes and phase ends).
    pub fn operator_times(&self, n: usize) -> Vec<f64> {
        let mut times = Vec::new();
        for (_, law) in &self.dae.varying {
            let p = law.period();
            times.extend((0..n).map(|k| p * k as f64 / n as f64));
            times.extend(law.breakpoints());
        }
        for el in &self.dae.elements {
            if let Some(p) = el.period() {
                times.extend((0..n).map(|k| p * k as f64 / n as f64));
                times.extend(el.breakpoints());
            }
        }
        times.sort_by(f64::total_cmp);
        times.dedup();
        times
    }

    /// Whether an element has a closed state for the stability bound (a valve).
    pub fn has_closed_states(&self) -> bool {
        self.dae.elements.iter().any(|e| e.has_closed_state())
    }

    /// Take the elements' closed state (`true`) or their stiffest one in `linear_operator`.
    pub fn set_valves_closed(&mut self, closed: bool) -> Result<()> {
        self.lin_kind = if closed {
            JacobianKind::Closed
        } else {
            JacobianKind::Stiffest
        };
        self.refactor_linearization()
    }

    /// Freeze time-varying coefficients at `t` for `linear_operator`.
    pub fn set_operator_time(&mut self, t: f64) -> Result<()> {
        self.lin_time = t;
        self.refactor_linearization()
    }

    /// Refactorise the algebraic part at the linearisation point (state and time) when it is
    /// not constant.
    fn refactor_linearization(&mut self) -> Result<()> {
        if let Some(alg) = self.alg.as_mut().filter(|a| !a.is_constant()) {
            let zero;
            let y = if self.lin_state.is_empty() {
                zero = vec![0.0; self.dae.n];
                &zero
            } else {
                &self.lin_state
            };
            alg.factor(self.dae, y, self.lin_time, self.lin_kind)
                .map_err(|m| singular(self.lin_time, &m))?;
        }
        Ok(())
    }

    /// Apply the linearised ODE operator (zero forcing, stenosis ignored) to a differential vector.
    pub fn linear_operator(&mut self, x: &[f64], out: &mut [f64]) -> Result<()> {
        let n = self.dae.n;
        let mut y = vec![0.0; n];
        for (j, &i) in self.diff.iter().enumerate() {
            y[i] = x[j];
        }
        // the elements' Jacobian at their stiffest state, at the operator's time and state
        // (built only for circuits with elements: the probe of a large tree applies this
        // operator many times)
        let has_elements = !self.dae.elements.is_empty();
        let lin = match (has_elements, self.lin_state.is_empty()) {
            (false, _) => Vec::new(),
            (true, true) => vec![0.0; n],
            (true, false) => self.lin_state.clone(),
        };
        if let Some(alg) = self.alg.as_mut() {
            for (rl, &g) in alg.r.iter_mut().zip(&alg.rows) {
                *rl = -self.dae.f.row_dot(g, &y);
            }
            if has_elements {
                let mut jx = vec![0.0; n];
                self.dae
                    .element_matvec(self.lin_time, &lin, self.lin_kind, &y, |r, v| jx[r] += v);
                for (rl, &g) in alg.r.iter_mut().zip(&alg.rows) {
                    *rl -= jx[g];
                }
            }
            alg.lu.solve_in_place(&mut alg.r);
            for (rl, &g) in alg.r.iter().zip(&alg.rows) {
                y[g] = *rl;
            }
        }
        let mut jy = vec![0.0; if has_elements { n } else { 0 }];
        if has_elements {
            self.dae
                .element_matvec(self.lin_time, &lin, self.lin_kind, &y, |r, v| jy[r] += v);
        }
        for (j, &i) in self.diff.iter().enumerate() {
            let el = if has_elements { jy[i] } else { 0.0 };
            out[j] = -(self.dae.f.row_dot(i, &y) + el) / self.e[i];
        }
        if !self.lin_stenosis.is_empty() {
            for (j, &i) in self.diff.iter().enumerate() {
                if let Ok(k) = self.lin_stenosis.binary_search_by_key(&i, |&(u, _)| u) {
                    out[j] -= self.lin_stenosis[k].1 * y[i] / self.e[i];
                }
            }
        }
        if self.is_time_varying() {
            for (j, &i) in self.diff.iter().enumerate() {
                if let Some((_, law)) = self.dae.varying.iter().find(|(u, _)| *u == i) {
                    out[j] -= law.delta(self.lin_time) * y[i] / self.e[i];
                }
            }
        }
        Ok(())
    }
}
