//! The error-controlled cycle loop (docs/physics.md §10): generalized-α with a variable step
//! chosen from a local error estimate, output rows from the dense output at the requested
//! times, so the output interval never changes the solution. The estimates, the controller
//! and the interpolant are in `integrate::adaptive`; here they meet the run's state.

use super::coupling::State;
use crate::circuit::Dae;
use crate::element::FlowLaw;
use crate::integrate::adaptive::{
    StepControl, Tolerances, hermite, local_error_constant, quadratic_extrapolation, rate_shift,
};
use crate::integrate::index2::{Balance, Index2, Levels, quadratic_slope_error, slope_at};
use crate::threads::CHUNK;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// The local errors of a forced periodic response's harmonic at ω accumulate over 1/ω
/// (|iω − λ| ≥ ω) for a normal, non-resonant circuit; coupled circuits amplify them more (the
/// RLC line of tests/test_error_control.py by up to 2.6× at 1/ω₁, 2.0× at 2/ω₁): the
/// accumulation time is taken as 3/ω (measured there: 0.1–1.6 rtol over rtol 1e-2 … 1e-6).
///
/// Each unknown's ω is its signal frequency ω_i = peak|ÿ_i|/peak|ẏ_i| (at least the
/// fundamental ω₁). For a sum of harmonics of amplitudes A_m, the local error C h³ Σ A_m ω_m³
/// over h ω_i bounds the harmonics' accumulated errors C h² Σ A_m ω_m² from above (Cauchy–
/// Schwarz: (Σ A ω³)(Σ A ω) ≥ (Σ A ω²)²), where a single 1/ω₁ for every unknown overstated
/// the errors of fast, small components (a small vessel's segment flows) by ω_m/ω₁ and let
/// them set the step.
pub(super) const ACCUMULATION: f64 = 3.0;

/// The flow group of a branch that is no vessel's.
pub(super) const NO_VESSEL: u32 = u32::MAX;

/// Fixed steps of the scout pass over the first cycle (see `Adaptive::scout`): ~10 % of a
/// controlled cycle's steps at rtol 1e-3, each cheaper (no estimate).
pub(super) const SCOUT_STEPS: usize = 128;

/// The growth of a flow group's amplitude, or of a kind's largest scale (relative), that
/// renews the scales and absolute tolerances it sets.
const RESCALE: f64 = 0.01;

/// The carried state of an error-controlled run.
pub(super) struct Adaptive {
    tol: Tolerances,
    control: StepControl,
    /// ω₁/3: the error per unit step is scaled to the fundamental at the least (see the
    /// module of `integrate::adaptive`, and `ACCUMULATION`).
    omega: f64,
    c_local: f64,
    /// ρ∞/(2(1 + ρ∞)²): an algebraic unknown's error per h² y''.
    c_algebraic: f64,
    /// α_f = 1/(1 + ρ∞): where in a step generalized-α meets its algebraic rows (see
    /// [`Dense::polynomial`]).
    alpha_f: f64,
    delta: f64,
    /// Unknowns without a rate in the DAE (E = 0), and their indices.
    algebraic: Vec<bool>,
    algebraic_index: Vec<u32>,
    /// The index-2 unknowns among them (see `integrate::index2`): their rows are their
    /// balance rows' values consistent with the constraint. The error control judges them by
    /// their own step-end values as every algebraic unknown (left out, the steps grew where
    /// those values change fast: closed-loop-o2's heart inflow rows 0.11 of its range off at
    /// rtol 1e-3 and the other vessels' flows 3.4e-3, against 1.4e-3 judged).
    index2: Index2,
    /// The α_f levels of the index-2 balances' rate unknowns over the last three accepted
    /// steps (see `index2_errors`).
    levels: Levels,
    /// The times the current step was refused for its index-2 error (see `index2_errors`).
    index2_rejections: AtomicU32,
    /// The largest |ẏ_i| and |ÿ_i| over the previous cycle and the current one so far: their
    /// ratio is the unknown's signal frequency ω_i, over which its local errors accumulate
    /// (see `Adaptive::flow_error`).
    rate_peak: Vec<f64>,
    accel_peak: Vec<f64>,
    /// The largest |y_i| over the previous cycle and the current one so far: rtol is relative
    /// to it (a pulsatile flow is judged against its peak, not against its zero crossings).
    /// Not over the whole run: a start-up transient (the Windkessels charging from the
    /// steady start) would hold every later cycle to a tolerance looser than asked (see
    /// [`Adaptive::start_cycle`]).
    peak: Vec<f64>,
    /// The largest |y_i|, |ẏ_i| and |ÿ_i| over the current cycle so far (each at most the
    /// matching peak above): at a cycle's start they become the previous cycle's.
    cycle_peak: Vec<f64>,
    cycle_rate: Vec<f64>,
    cycle_accel: Vec<f64>,
    /// The three maxima over the current cycle with the step just judged (the estimate's
    /// pass writes them, in its vectors, while it reads every unknown anyway): an accepted
    /// step whose pass's record holds (`blocks_known`) takes them as the cycle's, and the
    /// tracking pass then visits only the unknowns whose peak (over the previous cycle and
    /// this one) grows. Recording the cycle's maxima unknown by unknown in the tracking pass
    /// visited most unknowns in every step of a systole (each cycle's maxima start again from
    /// the state, |ẏ| and |ÿ| from 0): 12 % of adan56's default run.
    next_peak: Vec<f64>,
    next_rate: Vec<f64>,
    next_accel: Vec<f64>,
    /// Each flow unknown's vessel (`NO_VESSEL` for a boundary condition's or an element's
    /// own branch): a vessel's flow is judged against its vessel's amplitude, so a small
    /// vessel's flow meets rtol of its own amplitude (and atol scaled by its share of the
    /// largest), where one flow scale for all vessels let a small vessel's flow err by the
    /// large vessels' absolute tolerance. Other flows are judged against their own peak.
    flow_group: Vec<u32>,
    /// The largest |Q| so far per group; the groups' largest |Q| when the flows' scales were
    /// last set (see `track_flow_peaks`).
    group_peak: Vec<f64>,
    group_set: Vec<f64>,
    /// The largest scale per kind (pressure, flow, volume) when the absolute tolerances were
    /// last set: a kind's default atol is its largest unknown's (at most rtol of it), every
    /// other unknown's is scaled by its share (`Tolerances::atol_of`), renewed when the
    /// largest grew by more than `RESCALE`.
    kind_set: [f64; 3],
    /// Per species, its cells' largest |c| so far (the species' default atol is that cell's).
    species_largest: Vec<f64>,
    /// The scaled local error of the species step just taken (see `after_species`).
    species_step_error: f64,
    /// 1/(atol_i + rtol·s_i): an unknown's error weight, with its absolute tolerance atol_i
    /// (the kind's default scaled by the unknown's share of its kind's largest scale, or the
    /// user's as given: `Tolerances::atol_of`) and the scale s_i rtol is relative to (its largest |y| so
    /// far, a vessel's flow's its group's amplitude), at the scale of the step's start
    /// (the step's own |y| loosened it only while a peak grows; without it the estimate is
    /// one multiplication per unknown). Neither atol_i nor s_i is kept: an unknown that is
    /// no vessel's flow has s_i = its peak; a vessel's flow the scale and tolerance its
    /// group's amplitude gave at the last renewal (`track_flow_peaks`).
    inv_weight: Vec<f64>,
    /// A differential unknown's weights of its local error in one pass (0 for an algebraic
    /// unknown, judged apart): `inv_weight`, and `inv_weight`/ω_i·ACCUMULATION (per unit
    /// step, see `inv_omega`).
    w_step: Vec<f64>,
    w_unit: Vec<f64>,
    /// Whether the step just judged may grow a peak (of |y|, |ẏ| or |ÿ| over the previous
    /// cycle and the current one): the estimate's pass finds out, and an accepted step that
    /// grows none skips the tracking pass.
    may_grow: bool,
    /// Per block of `BLOCK` unknowns, the unknowns in which the estimate's pass of the step
    /// just judged saw a peak grow (bit k: the block's k-th unknown); `blocks_known` while
    /// that pass's record holds for the state the step is accepted with (the tracking pass
    /// then visits those unknowns only).
    grow_blocks: Vec<AtomicU32>,
    blocks_known: bool,
    /// The differential unknowns' local error estimate of the current step (scratch).
    le: Vec<f64>,
    /// Output rows per cycle.
    pub out_per_cycle: usize,
    /// The step to try next.
    pub h: f64,
    /// Unknowns below `kind_end[0]` are pressures, then flows up to `kind_end[1]`, then
    /// volumes (element unknowns).
    kind_end: [usize; 2],
    /// (y, ẏ) at the start of the current step; the two accepted states before it.
    y0: Vec<f64>,
    yd0: Vec<f64>,
    ym1: Vec<f64>,
    ym2: Vec<f64>,
    /// The steps that ended at y0 and at ym1.
    h1: f64,
    h2: f64,
    /// Accepted states before y0 (0, 1, 2 or more).
    history: usize,
    /// The species amounts at the start of the step; the cells' concentrations (amount over
    /// transport volume, species-major) at the start of the step and at the state before.
    z0: Vec<f64>,
    c0: Vec<f64>,
    cm1: Vec<f64>,
    /// The concentrations at the end of the step just taken.
    c1: Vec<f64>,
    /// The largest |c| per cell and species over the previous cycle and the current one so
    /// far, and over the current cycle so far (see `peak`, `cycle_peak`).
    c_peak: Vec<f64>,
    c_cycle: Vec<f64>,
    /// Largest scaled error per kind over the run (pressure, flow, volume, species), × rtol.
    pub estimate: [f64; 4],
    pub steps: usize,
    pub rejected: usize,
    /// The flow error of the last accepted step (the PI controller's memory).
    err_old: f64,
    pub h_smallest: f64,
    pub h_largest: f64,
    /// Interpolated (y, ẏ, z) of species output rows (sized on first use).
    yi: Vec<f64>,
    ydi: Vec<f64>,
    zi: Vec<f64>,
    /// The cells' transport volumes at the step's start, and interpolated.
    v0: Vec<f64>,
    vi: Vec<f64>,
    /// The valves whose flow is an algebraic unknown, by that unknown (see `Dense::algebraic`).
    flow_laws: Vec<FlowLaw>,
    /// The positions of the algebraic unknowns among the output's probes (set on the first
    /// row: a pass records the same probes throughout; see `Dense::row_into`).
    algebraic_probes: Option<Vec<u32>>,
}

/// A dense row interpolates the whole state first where its probes are at least 1/this of
/// the unknowns (see [`Dense::row_into`]): a contiguous pass costs ~5 instructions an unknown
/// and reading a probe from it ~6, against ~27 a probe interpolated by index.
const WHOLE_STATE_SHARE: usize = 2;

/// The dense output of one row (see [`Adaptive::dense`]): the Hermite weights at θ and
/// the rate shifts of the step's ends.
pub(super) struct Dense<'s> {
    ad: &'s Adaptive,
    y: &'s [f64],
    yd: &'s [f64],
    h: f64,
    /// θh: the time into the step.
    x: f64,
    b: [f64; 4],
    db: [f64; 4],
    s0: f64,
    s1: f64,
    inv_span: f64,
    /// A value's weights of (y₀, y₁, ẏ₀, ẏ₁) with the rate shifts folded in (see `value`).
    w: [f64; 4],
    /// Whether algebraic unknowns may take their quadratic or α_f-level line (the step has an
    /// accepted step before it on the same side of every event), else their chord (see
    /// [`Dense::polynomial`]).
    quadratic: bool,
}

impl Dense<'_> {
    /// The interpolated value of unknown `i`: a differential unknown's Hermite cubic, an
    /// algebraic unknown's value of [`Dense::algebraic`].
    #[inline]
    pub fn value(&self, i: usize) -> f64 {
        if self.ad.algebraic[i] {
            return self.algebraic(i).0;
        }
        self.cubic(i)
    }

    /// A row of the unknowns `probes` appended to `out`, each the value [`Dense::value`]
    /// gives: every probe's Hermite cubic without a branch, then the algebraic probes, at
    /// their positions `algebraic_at` in `probes`, over theirs. Where the probes are at least
    /// a `WHOLE_STATE_SHARE` of the unknowns, the cubic of every unknown goes into `state` in
    /// one contiguous pass (vectorised, no index) and the probes are read from it as a fixed
    /// step's row reads the state; else each probe's four vectors are indexed. (adan56's
    /// 3 100 probes, with repeats, of 1 987 unknowns: 27 instructions per value indexed, a
    /// row 4× a fixed step's.) The same sums in the same order either way: the same bits.
    pub fn row_into(
        &self,
        probes: &[usize],
        algebraic_at: &[u32],
        state: &mut Vec<f64>,
        out: &mut Vec<f64>,
    ) {
        let n = self.y.len();
        let (y0, y1) = (&self.ad.y0[..n], &self.y[..n]);
        let (d0, d1) = (&self.ad.yd0[..n], &self.yd[..n]);
        let w = self.w;
        let start = out.len();
        // (the same sum, in the same order, as `cubic`)
        let cubic = |a: f64, b: f64, c: f64, d: f64| w[0] * a + w[1] * b + w[2] * c + w[3] * d;
        if probes.len() * WHOLE_STATE_SHARE >= n {
            cubic_all(w, [y0, y1, d0, d1], state);
            // (from a slice: a vector's length would be read again at every probe)
            let state = &state[..];
            out.extend(probes.iter().map(|&i| state[i]));
        } else {
            out.extend(probes.iter().map(|&i| cubic(y0[i], y1[i], d0[i], d1[i])));
        }
        let row = &mut out[start..];
        for &k in algebraic_at {
            let k = k as usize;
            row[k] = self.algebraic(probes[k]).0;
        }
    }

    /// The Hermite cubic b₀y₀ + b₁h d₀ + b₂y₁ + b₃h d₁ with the shifted rates d = ẏ + s (ẏ₁ −
    /// ẏ₀)/span, its weights gathered per row (one value is four products: a 1 ms output of a
    /// fast run writes a row every step or two).
    #[inline]
    fn cubic(&self, i: usize) -> f64 {
        let w = &self.w;
        w[0] * self.ad.y0[i] + w[1] * self.y[i] + w[2] * self.ad.yd0[i] + w[3] * self.yd[i]
    }

    /// The interpolated value and rate of unknown `i`.
    pub fn value_and_rate(&self, i: usize) -> (f64, f64) {
        let ad = self.ad;
        if ad.algebraic[i] {
            return self.algebraic(i);
        }
        let (y0, y1, h) = (ad.y0[i], self.y[i], self.h);
        let ydd = (self.yd[i] - ad.yd0[i]) * self.inv_span;
        let d0 = ad.yd0[i] + self.s0 * ydd;
        let d1 = self.yd[i] + self.s1 * ydd;
        let (b, db) = (&self.b, &self.db);
        let v = b[0] * y0 + b[1] * h * d0 + b[2] * y1 + b[3] * h * d1;
        let dv = (db[0] * y0 + db[2] * y1) / h + db[1] * d0 + db[3] * d1;
        (v, dv)
    }

    /// An algebraic unknown's value and rate: see [`Dense::polynomial`]. A valve's flow is
    /// moved toward its law's flow at the interpolated pressures of its ends by the share
    /// w = δQ²/(δQ² + (Q′ δΔP)²) of the difference: δQ the flow's tolerance, δΔP the sum of the
    /// two pressures' and Q′ the law's dQ/dΔP, so that the law decides where it fixes the flow
    /// more closely than the interpolant (a closed valve: Q′ = 1/R_max, w ≈ 1) and the
    /// interpolant where the pressures' own tolerance would move the law's flow by more
    /// (an open valve: a small ΔP between two large pressures, w ≈ 0). Measured on the
    /// minimal closed loop at rtol 1e-3: the interpolant alone reads 1 % of the peak flow
    /// through the closed valve (generalized-α's algebraic values oscillate by −ρ∞ per step
    /// after its closing); the law's flow alone was 10 % off the open valve's.
    fn algebraic(&self, i: usize) -> (f64, f64) {
        if let Some(b) = self.ad.index2.balance(i) {
            return self.consistent(b, i);
        }
        let (v, rate) = self.polynomial(i);
        let Some(law) = self.ad.flow_law(i) else {
            return (v, rate);
        };
        let [_, from, to] = law.unknowns;
        let (q_law, slope) = law.flow(self.pressure(from), self.pressure(to));
        let iw = &self.ad.inv_weight;
        if iw.is_empty() {
            return (q_law, rate);
        }
        let (tq, tp) = (1.0 / iw[i], 1.0 / iw[from] + 1.0 / iw[to]);
        let spread = slope * tp;
        let w = tq * tq / (tq * tq + spread * spread);
        (v + w * (q_law - v), rate)
    }

    /// An index-2 unknown's value from its balance row (`integrate::index2`), the row's
    /// constrained unknown's rate the slope of the quadratic through the last three α_f-level
    /// values of it (at −h₁ − h₂ + α_f h₂, −h₁ + α_f h₁ and α_f h), its value at the restart
    /// standing for the first of them in the first two steps after one (the line through it
    /// and the step's level in the first); its rate the chord's.
    fn consistent(&self, b: &Balance, i: usize) -> (f64, f64) {
        let ad = self.ad;
        let r = b.rate_unknown;
        let (af, h, h1, h2) = (ad.alpha_f, self.h, ad.h1, ad.h2);
        let level = |a: f64, c: f64| a + af * (c - a);
        let end = (af * h, level(ad.y0[r], self.y[r]));
        let points = match ad.history {
            0 => [(0.0, ad.y0[r]), end, end],
            1 => [
                (-h1, ad.ym1[r]),
                (-h1 + af * h1, level(ad.ym1[r], ad.y0[r])),
                end,
            ],
            _ => [
                (-h1 - h2 + af * h2, level(ad.ym2[r], ad.ym1[r])),
                (-h1 + af * h1, level(ad.ym1[r], ad.y0[r])),
                end,
            ],
        };
        let n = if ad.history == 0 { 2 } else { 3 };
        let rate = slope_at(&points[..n], self.x);
        let value = b.value(rate, |k| self.value(k));
        (value, (self.y[i] - ad.y0[i]) / h)
    }

    /// A pressure's interpolated value (no valve's flow).
    fn pressure(&self, i: usize) -> f64 {
        if self.ad.algebraic[i] {
            self.polynomial(i).0
        } else {
            self.cubic(i)
        }
    }

    /// An algebraic unknown's value and rate between the step's ends. Generalized-α meets an
    /// algebraic row at the α_f level, at y_αf = y₀ + α_f (y₁ − y₀) and t₀ + α_f h: that
    /// value solves the circuit's constraint; the step-end value y₁ is its extrapolation by
    /// 1/α_f, which oscillates by −ρ∞ per step (the spurious root) after any disturbance.
    /// The row takes the quadratic through the last three step-end values (third order where
    /// they are smooth: a prescribed pressure's, which the valve events' root finding reads)
    /// where the step before is at least `QUADRATIC_SPACING` of this one and the quadratic
    /// stays within `QUADRATIC_AGREEMENT` of the line through the last two steps' α_f-level
    /// values (in their difference); else that line (second order; within the step it interpolates, past
    /// t₀ + α_f h it extrapolates by at most ρ∞ of the two levels' spacing, so a row stays
    /// within the accepted steps' constrained values). With no step before it on the same
    /// side of an event (the run's first step, the first after an event or a leap): the
    /// chord. (The quadratic alone, divided by a 10 ns step before, read the heart block's
    /// inflow, an index-2 unknown whose step-end values oscillate after a valve's opening,
    /// 44× its range off at rtol 1e-3.)
    fn polynomial(&self, i: usize) -> (f64, f64) {
        let ad = self.ad;
        let (b, c) = (ad.y0[i], self.y[i]);
        let (x, h, h1, af) = (self.x, self.h, ad.h1, ad.alpha_f);
        let s12 = (c - b) / h;
        if !self.quadratic {
            // (no state before the run's first step)
            return (b + x * s12, s12);
        }
        let a = ad.ym1[i];
        // the line through the α_f levels at −(1 − α_f) h₁ and α_f h
        let (x1, v1, x2) = (-(1.0 - af) * h1, a + af * (b - a), af * h);
        let level = b + af * (c - b);
        let slope = (level - v1) / (x2 - x1);
        let line = (level + (x - x2) * slope, slope);
        if h1 < QUADRATIC_SPACING * h {
            return line;
        }
        let s01 = (b - a) / h1;
        let curv = (s12 - s01) / (h + h1);
        let quad = (b + x * (s01 + curv * (x + h1)), s01 + curv * (2.0 * x + h1));
        if (quad.0 - line.0).abs() <= QUADRATIC_AGREEMENT * (level - v1).abs() {
            quad
        } else {
            line
        }
    }
}

/// `state` = the Hermite cubic w₀y₀ + w₁y₁ + w₂d₀ + w₃d₁ of every unknown from the vectors
/// `[y0, y1, d0, d1]` (of one length): the sum of `Dense::cubic` in its order, so the same
/// bits; four unknowns to an AVX2 vector where the CPU has them (as the estimate's pass,
/// `simd_block`).
fn cubic_all(w: [f64; 4], ends: [&[f64]; 4], state: &mut Vec<f64>) {
    let [y0, y1, d0, d1] = ends;
    let n = y0.len();
    let cubic = |a: f64, b: f64, c: f64, d: f64| w[0] * a + w[1] * b + w[2] * c + w[3] * d;
    #[cfg(target_arch = "x86_64")]
    if let Some(simd) = pulp::x86::V3::try_new() {
        use pulp::cast;
        if state.len() != n {
            // (every value is written below)
            state.clear();
            state.resize(n, 0.0);
        }
        simd.vectorize(|| {
            let (out, _) = pulp::as_arrays_mut::<LANES, f64>(&mut state[..]);
            let g = out.len();
            let groups = |x| &groups_of(x, n)[..g];
            let (a, b, c, d) = (groups(y0), groups(y1), groups(d0), groups(d1));
            let [w0, w1, w2, w3] = w.map(|x| simd.splat_f64x4(x));
            for k in 0..g {
                let ab = simd.add_f64x4(
                    simd.mul_f64x4(w0, cast(a[k])),
                    simd.mul_f64x4(w1, cast(b[k])),
                );
                let abc = simd.add_f64x4(ab, simd.mul_f64x4(w2, cast(c[k])));
                out[k] = cast(simd.add_f64x4(abc, simd.mul_f64x4(w3, cast(d[k]))));
            }
            for j in LANES * g..n {
                state[j] = cubic(y0[j], y1[j], d0[j], d1[j]);
            }
        });
        return;
    }
    state.clear();
    let ends = y0.iter().zip(y1).zip(d0.iter().zip(d1));
    state.extend(ends.map(|((&a, &b), (&c, &d))| cubic(a, b, c, d)));
}

/// The judgements of one step that may refuse it for its index-2 error (a refused step is
/// judged twice, by the estimate's pass and after the filter: two refusals); then that error
/// lets it pass. Near a kink of the constrained unknown's rate (a time law's) the quadratic
/// through the last levels straddles the kink whatever the step, until three steps have
/// passed it: refused without end, the steps would fall to the smallest.
const INDEX2_REJECTIONS: u32 = 4;

/// The least ratio of the step before to the step for an algebraic unknown's quadratic (see
/// [`Dense::polynomial`]): a shorter step before would set its curvature by a difference of
/// two values over a short span (its weights reach 1 at this ratio).
const QUADRATIC_SPACING: f64 = 0.25;

/// The largest difference between an algebraic unknown's quadratic and the line through its
/// α_f levels, in the change of the α_f levels across the line, for the quadratic to be read
/// (see [`Dense::polynomial`]): a smooth unknown's curvature term over a step (~h² y''/4) is
/// below its change (~h y') except near its turning points, where both are small; step-end
/// values oscillating on the spurious root part the two by several times the levels' change.
/// (Not the unknown's tolerance: its scale follows its peaks, which the oscillation raises.)
const QUADRATIC_AGREEMENT: f64 = 2.0;

/// The scout pass of an error-controlled run taken from another pass's fixed steps over the
/// same first cycle from the same start: a transport run's flow-only first pass (the cycle-mean
/// flows of the closures, `two_pass`) steps the flow at period/125 from the state the
/// controlled run starts from, which is what the scout's 128 steps would do again. Its peaks
/// seed the run's error control (see [`Scouted::seeded`]); the run then takes no scout pass.
pub(super) struct Scouted {
    ad: Adaptive,
    /// The state (y, ẏ) the pass started from: a run from another start is not seeded.
    start: (Vec<f64>, Vec<f64>),
    /// The steps taken and the steps of the first cycle.
    taken: usize,
    steps: usize,
}

impl Scouted {
    /// `ad`: the error control of the run to seed, as that run creates it.
    pub fn new(ad: Adaptive) -> Self {
        Scouted {
            ad,
            start: (Vec::new(), Vec::new()),
            taken: 0,
            steps: 0,
        }
    }

    /// The pass's first cycle of `steps` steps of `h` starts at (y, ẏ).
    pub fn start(&mut self, y: &[f64], yd: &[f64], h: f64, steps: usize) {
        self.ad.scout_start(y, h);
        self.start = (y.to_vec(), yd.to_vec());
        (self.taken, self.steps) = (0, steps);
    }

    /// The pass's next step ended in `y` (after its first cycle: nothing).
    pub fn step(&mut self, y: &[f64]) {
        if self.taken < self.steps {
            self.ad.scout_step(y, self.taken);
            self.taken += 1;
        }
    }

    /// The seeded error control for a run that starts from (y, ẏ), as after its own scout
    /// pass; None if the pass did not complete its first cycle or started elsewhere (the
    /// run then scouts for itself).
    pub fn seeded(self, y: &[f64], yd: &[f64]) -> Option<Adaptive> {
        let same = |a: &[f64], b: &[f64]| {
            a.len() == b.len() && a.iter().zip(b).all(|(u, v)| u.to_bits() == v.to_bits())
        };
        let complete = self.steps > 0 && self.taken == self.steps;
        if !complete || !same(&self.start.0, y) || !same(&self.start.1, yd) {
            return None;
        }
        let mut ad = self.ad;
        (ad.history, ad.h1) = (0, 0.0);
        Some(ad)
    }
}

/// What one flow step's estimate found: the largest scaled error and its value per kind.
struct FlowError {
    max: f64,
    kinds: [f64; 3],
}

impl Adaptive {
    pub fn new(dae: &Dae, tol: Tolerances, rho_inf: f64, period: f64, output_every: f64) -> Self {
        let out_per_cycle = (period / output_every).round().max(1.0) as usize;
        let n_nodes = dae.n_nodes;
        let index2 = Index2::find(dae);
        Adaptive {
            tol,
            control: StepControl {
                h_min: period * 1e-9,
                h_max: period / 32.0,
            },
            omega: 2.0 * std::f64::consts::PI / (ACCUMULATION * period),
            c_local: local_error_constant(rho_inf),
            c_algebraic: rho_inf / (2.0 * (1.0 + rho_inf).powi(2)),
            alpha_f: 1.0 / (1.0 + rho_inf),
            algebraic: dae.e.iter().map(|&e| e == 0.0).collect(),
            algebraic_index: (0..dae.n)
                .filter(|&i| dae.e[i] == 0.0)
                .map(|i| u32::try_from(i).expect("2^32 unknowns"))
                .collect(),
            index2,
            levels: Levels::default(),
            index2_rejections: AtomicU32::new(0),
            peak: Vec::new(),
            rate_peak: Vec::new(),
            accel_peak: Vec::new(),
            cycle_peak: Vec::new(),
            cycle_rate: Vec::new(),
            cycle_accel: Vec::new(),
            next_peak: Vec::new(),
            next_rate: Vec::new(),
            next_accel: Vec::new(),
            flow_group: flow_groups(dae),
            group_peak: Vec::new(),
            group_set: Vec::new(),
            kind_set: [0.0; 3],
            species_largest: Vec::new(),
            species_step_error: 0.0,
            inv_weight: Vec::new(),
            w_step: Vec::new(),
            w_unit: Vec::new(),
            may_grow: true,
            grow_blocks: Vec::new(),
            blocks_known: false,
            le: Vec::new(),
            delta: rate_shift(rho_inf),
            out_per_cycle,
            // a small first step: its estimate is first order (no history yet)
            h: period * 1e-3 * (tol.rtol / 1e-3).sqrt().min(1.0),
            kind_end: [n_nodes, n_nodes + dae.names.n_branches()],
            y0: Vec::new(),
            yd0: Vec::new(),
            ym1: Vec::new(),
            ym2: Vec::new(),
            h1: 0.0,
            h2: 0.0,
            history: 0,
            z0: Vec::new(),
            c0: Vec::new(),
            cm1: Vec::new(),
            c1: Vec::new(),
            c_peak: Vec::new(),
            c_cycle: Vec::new(),
            estimate: [0.0; 4],
            steps: 0,
            rejected: 0,
            err_old: 1.0,
            h_smallest: f64::INFINITY,
            h_largest: 0.0,
            yi: Vec::new(),
            ydi: Vec::new(),
            zi: Vec::new(),
            v0: Vec::new(),
            vi: Vec::new(),
            flow_laws: algebraic_flow_laws(dae),
            algebraic_probes: None,
        }
    }

    /// The law of the valve whose flow is the algebraic unknown `i`, if any.
    #[inline]
    fn flow_law(&self, i: usize) -> Option<&FlowLaw> {
        if self.flow_laws.is_empty() {
            return None;
        }
        let k = self.flow_laws.binary_search_by_key(&i, |l| l.unknowns[0]);
        k.ok().map(|k| &self.flow_laws[k])
    }

    /// The relative tolerance.
    pub fn rtol(&self) -> f64 {
        self.tol.rtol
    }

    /// After a valve event at the end of the step just accepted: the estimates start again
    /// from the event's state (first order, as at the run's start; the extrapolation through
    /// the last three states would straddle the kink), with the larger of the step the
    /// controller proposes and `proposed`, its proposal before the event.
    pub fn restart(&mut self, proposed: f64) {
        self.history = 0;
        self.h = self.h.max(proposed).min(self.control.h_max);
    }

    /// The smallest step the controller takes (a step there is accepted whatever its error).
    pub fn h_min(&self) -> f64 {
        self.control.h_min
    }

    /// The largest step the controller takes.
    pub fn h_max(&self) -> f64 {
        self.control.h_max
    }

    /// Before the first cycle of a run without valves (whose statuses a pass of fixed steps
    /// would not follow): a scout pass of `SCOUT_STEPS` fixed steps over one cycle from the
    /// start state seeds every unknown's peaks of |y|, |ẏ| and |ÿ|, hence its scale and signal
    /// frequency, which the controlled run otherwise learns during its first cycle, judging the
    /// flows before their systolic peak against a smaller amplitude and every unknown against
    /// the fundamental's frequency (the first cycle took 2.5× the steps of the later ones). The
    /// coarse pass underestimates peaks (its divided differences smooth them): the stricter
    /// side; the run goes on learning from its own steps. The run's state and the integrator's
    /// carried state are left as they were.
    pub fn scout(&mut self, st: &mut State<'_, '_>, t0: f64, period: f64) {
        if !self.peak.is_empty() {
            return;
        }
        let h = period / SCOUT_STEPS as f64;
        self.scout_start(&st.y, h);
        let ig = st.flow.integrator();
        let carried = ig.carried();
        ig.set_dt(h);
        // the history buffers (allocated for the run anyway) hold the pass's states
        let mut y = std::mem::take(&mut self.ym2);
        let mut yd = std::mem::take(&mut self.yd0);
        y.clone_from(&st.y);
        yd.clone_from(&st.yd);
        for k in 0..SCOUT_STEPS {
            if ig.step(t0 + k as f64 * h, &mut y, &mut yd).is_err() {
                break;
            }
            self.scout_step(&y, k);
        }
        // (a carried state the integrator gave out restores)
        let _ = ig.restore_carried(&carried);
        (self.ym2, self.yd0) = (y, yd);
        (self.history, self.h1) = (0, 0.0);
    }

    /// A scout pass of steps of `h` begins at the start state `y` (see `Adaptive::scout`).
    fn scout_start(&mut self, y: &[f64], h: f64) {
        self.init_scales(y);
        copy_into(&mut self.y0, y);
        copy_into(&mut self.ym1, y);
        self.h1 = h;
    }

    /// The scout pass's step `k` (from 0) ended in `y`: the peaks it grows.
    fn scout_step(&mut self, y: &[f64], k: usize) {
        // rates from the second step on (the first has no step before it)
        self.history = usize::from(k > 0);
        let grown = self.track_peaks(y, self.h1);
        self.track_flow_peaks(y, grown);
        std::mem::swap(&mut self.ym1, &mut self.y0);
        copy_into(&mut self.y0, y);
    }

    /// Every unknown's peaks, scales and weights from the start state `y`.
    fn init_scales(&mut self, y: &[f64]) {
        // (every flow is read: no estimate's record holds for the start)
        self.blocks_known = false;
        let n = y.len();
        self.peak = y.iter().map(|v| v.abs()).collect();
        self.rate_peak = vec![0.0; n];
        self.accel_peak = vec![0.0; n];
        self.cycle_peak.clone_from(&self.peak);
        self.cycle_rate = vec![0.0; n];
        self.cycle_accel = vec![0.0; n];
        self.inv_weight = vec![0.0; n];
        self.w_step = vec![0.0; n];
        self.w_unit = vec![0.0; n];
        // (every unknown's weights, the vessels' flows from their groups' scales)
        self.renew_kind_scales();
        self.track_flow_peaks(y, true);
    }

    /// Every kind's largest scale from the peaks, and every unknown's absolute tolerance and
    /// weights from it (`Tolerances::atol_of`; the vessels' flows from their groups' amplitudes): when
    /// a kind's largest peak grew by more than `RESCALE` since they were last set (an unknown's
    /// tolerance is then at most that share too tight: the stricter side). In chunks on the
    /// run's threads, each unknown its own.
    fn renew_kind_scales(&mut self) {
        let ends = [0, self.kind_end[0], self.kind_end[1], self.peak.len()];
        for k in 0..3 {
            let (peak, first) = (&self.peak, ends[k]);
            self.kind_set[k] = crate::threads::max_over(ends[k + 1] - first, |r| {
                let r = first + r.start..first + r.end;
                peak[r].iter().fold(0.0f64, |m, &p| m.max(p))
            });
        }
        let mut v = [
            std::mem::take(&mut self.inv_weight),
            std::mem::take(&mut self.w_step),
            std::mem::take(&mut self.w_unit),
        ];
        let this = &*self;
        let [iw, ws, wu] = &mut v;
        let mut tasks = chunk_tasks(0, [&mut iw[..], ws, wu]);
        for_tasks(&mut tasks, |(first, [iw, ws, wu])| {
            for (j, iw) in iw.iter_mut().enumerate() {
                let i = *first + j;
                if !this.is_vessel_flow(i) {
                    *iw = this.own_weight(i, this.peak[i]);
                    (ws[j], wu[j]) =
                        this.weights_from(i, *iw, this.rate_peak[i], this.accel_peak[i]);
                }
            }
            false
        });
        drop(tasks);
        [self.inv_weight, self.w_step, self.w_unit] = v;
        if !self.group_peak.is_empty() {
            self.renew_flow_weights();
        }
    }

    /// Whether unknown `i` is a vessel's flow (judged against its vessel's amplitude).
    fn is_vessel_flow(&self, i: usize) -> bool {
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        (n0..n1).contains(&i) && self.flow_group[i - n0] != NO_VESSEL
    }

    /// 1/(atol_i + rtol·peak) of unknown `i` (no vessel's flow) of largest |y| `peak`, its
    /// atol from its share of its kind's largest scale (`Tolerances::atol_of`); a flow that is
    /// no vessel's (a boundary condition's or an element's own branch) keeps the kind's flow
    /// atol (`Tolerances::kind_atol`): judged against a share of the largest, a heart
    /// circuit's near-zero internal flows held the closed loop to three times the steps.
    #[inline]
    fn own_weight(&self, i: usize, peak: f64) -> f64 {
        let k = self.kind_of(i);
        let atol = if k == 1 {
            self.tol.kind_atol(1, self.kind_set[1])
        } else {
            self.tol.atol_of(k, peak, self.kind_set[k])
        };
        1.0 / (atol + self.tol.rtol * peak)
    }

    /// Keep the state at the start of a step: the state's vectors are exchanged with the
    /// buffers of the start (y0, ẏ0), no copy; the step then reads its start from
    /// [`Adaptive::start`] and writes its end into the state's vectors
    /// (`State::advance_flow`).
    pub fn save_start(&mut self, st: &mut State<'_, '_>) {
        if self.peak.is_empty() {
            self.init_scales(&st.y);
        }
        (self.may_grow, self.blocks_known) = (true, false);
        let n = st.y.len();
        // (the first step's buffers; afterwards they keep their length)
        self.y0.resize(n, 0.0);
        self.yd0.resize(n, 0.0);
        std::mem::swap(&mut self.y0, &mut st.y);
        std::mem::swap(&mut self.yd0, &mut st.yd);
        if let Some(sp) = st.species.as_ref() {
            if self.c0.is_empty() {
                concentrations(st, &mut self.c0);
                self.c_peak = self.c0.iter().map(|c| c.abs()).collect();
                self.c_cycle.clone_from(&self.c_peak);
                self.species_largest = vec![0.0; sp.tr.species_names().len()];
                self.renew_species_largest();
            }
        }
    }

    /// Keep the species amounts and the cells' transport volumes before the species step about
    /// to be taken: only a step with a species output row needs them (its dense output
    /// interpolates from them to the step's end), so the other steps skip the copies.
    pub fn keep_species_start(&mut self, st: &State<'_, '_>) {
        if let Some(sp) = st.species.as_ref() {
            copy_into(&mut self.z0, &sp.z);
            copy_into(&mut self.v0, sp.tr.cell_transport_volumes());
        }
    }

    /// The state was changed after its step was judged (a closed valve's flow held): the
    /// estimate pass's record of where peaks grow no longer holds for it.
    pub fn state_changed(&mut self) {
        self.blocks_known = false;
    }

    /// The start (y, ẏ) of the step being taken (see [`Adaptive::save_start`]).
    pub fn start(&self) -> (&[f64], &[f64]) {
        (&self.y0, &self.yd0)
    }

    /// Back to the start of a rejected step (the species have not moved yet): the buffers
    /// exchanged back (the next `save_start` exchanges them again).
    pub fn restore(&mut self, st: &mut State<'_, '_>) {
        std::mem::swap(&mut self.y0, &mut st.y);
        std::mem::swap(&mut self.yd0, &mut st.yd);
    }

    /// A rejected step (or a failed Newton iteration): the step to try instead.
    pub fn reject(&mut self, h: f64, err: f64) {
        self.rejected += 1;
        self.h = self.control.after_rejection(h, err);
    }

    /// The scaled error of the flow step of `h` that ended in `y` (≤ 1 meets the tolerances).
    /// Differential unknowns: Milne's device on the last three accepted states (a first-order,
    /// larger estimate while fewer are known), filtered through the step's iteration matrix
    /// (Shampine's filter: a stiff mode's oscillation under the damped roots is not an error
    /// of the solution), per unit step. Algebraic unknowns hold their constraint at the α_f
    /// level, so their error does not accumulate: it is the fixed point ρ∞/(1 + ρ∞)² · h² y''/2
    /// of one step's, y'' from the last three states (none at the first step).
    ///
    /// The filter costs a solve (as much as the step's own): it is skipped where the unfiltered
    /// estimate (a valid, usually larger one) already accepts the step, which is most steps;
    /// the controller then proposes the next step from that larger estimate (on adan56 at
    /// rtol 1e-3: 16 % less CPU at the same error).
    fn flow_error(&mut self, st: &mut State<'_, '_>, h: f64) -> FlowError {
        let raw = if self.history >= 2 {
            self.fused_errors(&st.y, h)
        } else {
            self.may_grow = true;
            self.local_errors(&st.y, h);
            self.scaled_errors(&st.y, h)
        };
        if raw.max <= 1.0 {
            return raw;
        }
        if self.history >= 2 {
            self.local_errors(&st.y, h);
        }
        st.flow.integrator().filter_error(&mut self.le);
        self.zero_algebraic();
        self.scaled_errors(&st.y, h)
    }

    /// The differential unknowns' local errors of the step of `h` that ended in `y` into
    /// `le` (0 for algebraic unknowns).
    fn local_errors(&mut self, y: &[f64], h: f64) {
        let (h1, h2, history) = (self.h1, self.h2, self.history);
        self.le.resize(y.len(), 0.0);
        let (y0, yd0, ym1, ym2) = (&self.y0, &self.yd0, &self.ym1, &self.ym2);
        let extrapolation = quadratic_extrapolation(h, h1, h2, self.c_local);
        // (in chunks on the run's threads: each entry its own)
        crate::threads::for_chunks(&mut self.le, |a, le| {
            let r = a..a + le.len();
            let (y, y0) = (&y[r.clone()], &y0[r.clone()]);
            match history {
                0 => {
                    let start = y.iter().zip(y0).zip(&yd0[r]);
                    for (e, ((&y1, &y0), &d0)) in le.iter_mut().zip(start) {
                        *e = y1 - y0 - h * d0;
                    }
                }
                1 => {
                    let r_h = h / h1;
                    let past = y.iter().zip(y0).zip(&ym1[r]);
                    for (e, ((&y1, &y0), &ym)) in le.iter_mut().zip(past) {
                        *e = y1 - y0 - r_h * (y0 - ym);
                    }
                }
                _ => {
                    let ([la, lb, lc], f) = extrapolation;
                    let past = ym2[r.clone()].iter().zip(&ym1[r]).zip(y0);
                    for (e, (&y1, ((&a, &b), &c))) in le.iter_mut().zip(y.iter().zip(past)) {
                        *e = f * (y1 - (la * a + lb * b + lc * c));
                    }
                }
            }
        });
        self.zero_algebraic();
    }

    /// The algebraic unknowns' entries of `le` to 0 (their error is judged apart).
    fn zero_algebraic(&mut self) {
        for &i in &self.algebraic_index {
            self.le[i as usize] = 0.0;
        }
    }

    /// The largest scaled error per kind of the local errors in `le` (see `flow_error`),
    /// each unknown weighted by its absolute tolerance plus rtol of its scale. One branch-free
    /// pass per kind over the differential unknowns (the algebraic ones' weights are 0), then
    /// the few algebraic unknowns by their index.
    fn scaled_errors(&self, y: &[f64], h: f64) -> FlowError {
        // accumulated over 1/ω_i, and over one step at the least; the first two steps'
        // estimates are first order: judged as they are, one step's error, or the start
        // would crawl (a zero 1/h leaves the step's weight)
        let inv_h = if self.history < 2 { 0.0 } else { 1.0 / h };
        let mut kinds = [0.0f64; 3];
        let ends = [0, self.kind_end[0], self.kind_end[1], y.len()];
        for (k, worst) in kinds.iter_mut().enumerate() {
            // (in chunks on the run's threads: a maximum is the same in any grouping)
            let first = ends[k];
            *worst = crate::threads::max_over(ends[k + 1] - first, |c| {
                let r = first + c.start..first + c.end;
                let weights = self.w_unit[r.clone()].iter().zip(&self.w_step[r.clone()]);
                self.le[r]
                    .iter()
                    .zip(weights)
                    .fold(0.0f64, |m, (&e, (&wu, &ws))| {
                        m.max(e.abs() * (wu * inv_h).max(ws))
                    })
            });
        }
        self.algebraic_errors(y, h, &mut kinds);
        FlowError {
            max: kinds.iter().fold(0.0f64, |m, &e| m.max(e)),
            kinds,
        }
    }

    /// `local_errors` and `scaled_errors` in one pass from the third step on (Milne's device on
    /// the last three states), the estimate not stored: the pass also finds whether the step
    /// would grow one of the peaks `track_peaks` follows (the same comparisons), so that an
    /// accepted step growing none skips that pass. (The estimate, the peak test and a fixed
    /// step's own work each read every unknown once: apart they were a third of a step.)
    /// In chunks on the run's threads: a maximum and an "any" are the same in any grouping.
    fn fused_errors(&mut self, y: &[f64], h: f64) -> FlowError {
        let n = y.len();
        let (l, f) = quadratic_extrapolation(h, self.h1, self.h2, self.c_local);
        let c = Fused {
            l,
            f,
            inv_h: 1.0 / h,
            inv_h1: 1.0 / self.h1,
            inv_span: 2.0 / (h + self.h1),
        };
        if self.grow_blocks.len() == n.div_ceil(BLOCK) {
            self.grow_blocks.iter_mut().for_each(|b| *b.get_mut() = 0);
        } else {
            self.grow_blocks = (0..n.div_ceil(BLOCK)).map(|_| AtomicU32::new(0)).collect();
        }
        let mut next = [
            std::mem::take(&mut self.next_peak),
            std::mem::take(&mut self.next_rate),
            std::mem::take(&mut self.next_accel),
        ];
        // (every value is written below: a buffer of the right length is not cleared first)
        next.iter_mut().for_each(|v| v.resize(n, 0.0));
        let ends = [0, self.kind_end[0], self.kind_end[1], n];
        let this = &*self;
        let [np, nr, na] = &mut next;
        let mut tasks = chunk_tasks(0, [&mut np[..], nr, na]);
        // (in chunks on the run's threads, each its own part of every kind: a maximum and an
        // "any" are the same in any grouping)
        let (mut kinds, grows) = kind_maxima(&mut tasks, |(first, out)| {
            let (mut worst, mut grows) = ([0.0f64; 3], false);
            for (k, w) in worst.iter_mut().enumerate() {
                let at = ends[k].max(*first)..ends[k + 1].min(*first + out[0].len());
                if at.start < at.end {
                    let local = at.start - *first..at.end - *first;
                    let [p, r, a] = out;
                    let out = [&mut p[local.clone()], &mut r[local.clone()], &mut a[local]];
                    let (m, g) = this.fused_range(at, y, &c, out);
                    (*w, grows) = (m, grows | g);
                }
            }
            (worst, grows)
        });
        drop(tasks);
        [self.next_peak, self.next_rate, self.next_accel] = next;
        (self.may_grow, self.blocks_known) = (grows, true);
        self.algebraic_errors(y, h, &mut kinds);
        FlowError {
            max: kinds.iter().fold(0.0f64, |m, &e| m.max(e)),
            kinds,
        }
    }

    /// `fused_errors` over the unknowns `r`: the largest scaled error, and whether a peak grows
    /// (the unknowns where one does recorded in `grow_blocks`), the maxima over the cycle with
    /// the step into `out` (|y|, |ẏ|, |ÿ|: `next_peak` ..., of `r`). Block by block, each in groups
    /// of `LANES` unknowns, each lane its own maximum (one chain of dependent maxima through
    /// every unknown otherwise), the maxima as compare-and-select (`f64::max` also orders NaNs:
    /// no NaN comes here but through a NaN state, which the run refuses at its check); a
    /// maximum is the same in any grouping, so the result is the same number as one running
    /// maximum's. On x86-64 with AVX2 (detected at run time) a group is one 4-lane vector
    /// per operation (`simd_block`): the same operations on the same values, so the same
    /// numbers (no fused multiply-add).
    fn fused_range(
        &self,
        r: Range<usize>,
        y: &[f64],
        c: &Fused,
        out: [&mut [f64]; 3],
    ) -> (f64, bool) {
        #[cfg(target_arch = "x86_64")]
        if let Some(simd) = pulp::x86::V3::try_new() {
            return simd
                .vectorize(|| self.fused_blocks(r, y, out, |v, o| simd_block(simd, v, c, o)));
        }
        self.fused_blocks(r, y, out, |v, o| v.block(c, o))
    }

    /// The unknowns `r` block by block (see `fused_range`): `block` gives a block's largest
    /// scaled error and its unknowns that grow a peak (bit k: its k-th), and writes its
    /// maxima over the cycle into the block's part of `out`.
    #[inline(always)]
    fn fused_blocks(
        &self,
        r: Range<usize>,
        y: &[f64],
        out: [&mut [f64]; 3],
        block: impl Fn(&FusedSlices<'_>, [&mut [f64]; 3]) -> (f64, u32),
    ) -> (f64, bool) {
        let (mut m, mut grows, mut at) = (0.0f64, false, r.start);
        let [op, or, oa] = out;
        while at < r.end {
            let end = ((at / BLOCK + 1) * BLOCK).min(r.end);
            let o = at - r.start..end - r.start;
            let o = [&mut op[o.clone()], &mut or[o.clone()], &mut oa[o]];
            let (block_max, mask) = block(&self.fused_slices(at..end, y), o);
            if mask != 0 {
                // (a range's blocks are its own but at its ends, which a kind's boundary may
                // share with the next range)
                let bits = mask << (at % BLOCK);
                self.grow_blocks[at / BLOCK].fetch_or(bits, Ordering::Relaxed);
            }
            (m, grows) = (larger(block_max, m), grows | (mask != 0));
            at = end;
        }
        (m, grows)
    }

    /// The vectors of the estimate's pass over the unknowns `r`.
    #[inline(always)]
    fn fused_slices<'a>(&'a self, r: Range<usize>, y: &'a [f64]) -> FusedSlices<'a> {
        FusedSlices {
            y: &y[r.clone()],
            ym2: &self.ym2[r.clone()],
            ym1: &self.ym1[r.clone()],
            y0: &self.y0[r.clone()],
            wu: &self.w_unit[r.clone()],
            ws: &self.w_step[r.clone()],
            pk: &self.peak[r.clone()],
            rp: &self.rate_peak[r.clone()],
            ap: &self.accel_peak[r.clone()],
            cp: &self.cycle_peak[r.clone()],
            cr: &self.cycle_rate[r.clone()],
            ca: &self.cycle_accel[r],
        }
    }

    /// The algebraic unknowns' errors into `kinds` (see `flow_error`; none at the first step),
    /// in chunks of their index on the run's threads (maxima: the same in any grouping).
    fn algebraic_errors(&self, y: &[f64], h: f64, kinds: &mut [f64; 3]) {
        if self.history == 0 {
            return;
        }
        let (h1, alg) = (self.h1, self.c_algebraic);
        let index = &self.algebraic_index;
        let chunks = map_chunks(index.len(), |r| {
            let mut worst = [0.0f64; 3];
            for &i in &index[r] {
                let i = i as usize;
                let (a, b, c) = (self.ym1[i], self.y0[i], y[i]);
                let curvature = 2.0 * ((c - b) / h - (b - a) / h1) / (h + h1);
                let k = &mut worst[self.kind_of(i)];
                *k = k.max(alg * h * h * curvature.abs() * self.inv_weight[i]);
            }
            worst
        });
        for worst in chunks {
            for (k, w) in kinds.iter_mut().zip(worst) {
                *k = k.max(w);
            }
        }
        self.index2_errors(y, h, kinds);
    }

    /// The index-2 unknowns' errors into `kinds`: their rows are their balance rows' values
    /// with the constrained unknown's rate the slope of the quadratic through its last three
    /// α_f levels (`Dense::consistent`), one order below the values the step's own estimate
    /// judges (a value's error h³y''' per step is a rate's h²y'''). The step is judged by that
    /// slope's error over the step, the cubic through four levels less the quadratic
    /// (`quadratic_slope_error`), against the constrained unknown's own tolerance over 1/ω₁:
    /// of order 2, as the controller takes the flows' errors. (Unjudged, closed-loop-o2's heart
    /// inflow took one step of 13 ms over the onset of the atrium's contraction, a kink of its
    /// pressure's rate, and its rows erred by 0.11 of their range at rtol 1e-3; its own weight
    /// comes from its step-end values, whose ringing set its scale ~1e5 times its range.)
    /// From the third step after a restart (four levels).
    fn index2_errors(&self, y: &[f64], h: f64, kinds: &mut [f64; 3]) {
        if self.history < 3 {
            return;
        }
        // ω₁: the fundamental (`omega` is ω₁/ACCUMULATION)
        let omega = ACCUMULATION * self.omega;
        for (k, b) in self.index2.balances.iter().enumerate() {
            let r = b.rate_unknown;
            let points = self.levels.with_step(k, r, self.alpha_f, h, &self.y0, y);
            // the rate held to the constrained unknown's own tolerance over 1/ω₁ (the value's
            // tolerance e/coefficient times that: not the unknown's own, whose scale its
            // ringing step-end values set)
            let mut e = quadratic_slope_error(&points, h) * self.inv_weight[r] / omega;
            if e > 1.0 {
                let n = self.index2_rejections.load(Ordering::Relaxed);
                if n >= INDEX2_REJECTIONS {
                    e = 1.0;
                } else {
                    self.index2_rejections.store(n + 1, Ordering::Relaxed);
                }
            }
            let kind = self.kind_of(b.unknown);
            kinds[kind] = kinds[kind].max(e);
        }
    }

    /// Every species' largest |c| over its cells (`c_peak` is species-major).
    fn renew_species_largest(&mut self) {
        let n = self.species_largest.len();
        if n == 0 {
            return;
        }
        let cells = self.c_peak.len() / n;
        for (s, largest) in self.species_largest.iter_mut().enumerate() {
            let peak = &self.c_peak[s * cells..(s + 1) * cells];
            *largest =
                crate::threads::max_over(cells, |r| peak[r].iter().fold(0.0f64, |m, &p| m.max(p)));
        }
    }

    /// After the accepted species step of `h`, in one pass over the cells (species by species,
    /// in chunks on the run's threads): the cells' concentrations at its end (amount over
    /// transport volume, species-major), the step's scaled local error, and every cell's
    /// largest |c| and every species' largest over its cells renewed with them. Called before
    /// the step's dense rows, which move the transport volumes (and put them back).
    ///
    /// The local error of the species step (backward Euler) is h/(2h + h₁) times the
    /// difference to the linear extrapolation, on the cells' concentrations (the amounts also
    /// follow the volume's pulsation, which the flow step carries), weighted by
    /// atol + rtol·(largest |c| so far), the species' default atol scaled by that over its
    /// cells' largest before the step (`Tolerances::atol_of`).
    pub fn after_species(&mut self, st: &State<'_, '_>, h: f64) {
        self.species_step_error = 0.0;
        let Some(sp) = st.species.as_ref() else {
            return;
        };
        let vol = sp.tr.cell_transport_volumes();
        let nc = vol.len();
        // (every value is written below: a buffer of the right length is not cleared first)
        self.c1.resize(self.c_peak.len(), 0.0);
        let judged = self.history > 0;
        let (rtol, tol) = (self.tol.rtol, &self.tol);
        let (r, f) = (h / self.h1, h / (2.0 * h + self.h1));
        let per_step = self.omega * h;
        let (mut c1, mut c_peak, mut c_cycle) = (
            std::mem::take(&mut self.c1),
            std::mem::take(&mut self.c_peak),
            std::mem::take(&mut self.c_cycle),
        );
        let mut worst = 0.0f64;
        for (s, largest) in self.species_largest.iter_mut().enumerate() {
            let cells = s * nc..(s + 1) * nc;
            let (z, c0, cm1) = (&sp.z[cells.clone()], &self.c0[cells.clone()], &self.cm1[..]);
            let cm1 = if judged { &cm1[cells.clone()] } else { &[][..] };
            let old_largest = *largest;
            let mut tasks = chunk_tasks(
                0,
                [
                    &mut c1[cells.clone()],
                    &mut c_peak[cells.clone()],
                    &mut c_cycle[cells],
                ],
            );
            let (e, l) = fold_tasks(&mut tasks, |(first, [c1, pk, cc])| {
                let (mut e, mut l) = (0.0f64, 0.0f64);
                let k = *first..*first + c1.len();
                let cells = c1.iter_mut().zip(pk.iter_mut().zip(cc.iter_mut()));
                for (j, (c, (p, cc))) in k.clone().zip(cells) {
                    *c = z[j] / vol[j];
                    *cc = cc.max(c.abs());
                    // (the same expressions as when the error and the peaks were passes of
                    // their own: `species_error`)
                    let s = p.max(c.abs());
                    if judged {
                        let le = f * (*c - c0[j] - r * (c0[j] - cm1[j]));
                        let a = tol.atol_of(3, s, old_largest);
                        e = e.max(le.abs() / (per_step * (a + rtol * s)));
                    }
                    *p = s;
                    l = l.max(s);
                }
                (e, l)
            });
            drop(tasks);
            worst = worst.max(e);
            *largest = l;
        }
        (self.c1, self.c_peak, self.c_cycle) = (c1, c_peak, c_cycle);
        self.species_step_error = worst;
    }

    /// The errors of the flow step just taken (before the species follow it).
    pub fn judge_flow(&mut self, st: &mut State<'_, '_>, h: f64) -> (f64, [f64; 3]) {
        let e = self.flow_error(st, h);
        (e.max, e.kinds)
    }

    /// An accepted step of `h`: record its estimates, shift the history, propose the next step.
    pub fn accept(&mut self, st: &State<'_, '_>, h: f64, flow: f64, kinds: [f64; 3]) {
        let species = self.species_step_error;
        let rtol = self.tol.rtol;
        for (e, k) in self.estimate.iter_mut().zip(kinds.iter().chain([&species])) {
            *e = e.max(k * rtol);
        }
        if self.blocks_known {
            // the maxima over the cycle with this step, from its estimate's pass
            std::mem::swap(&mut self.cycle_peak, &mut self.next_peak);
            std::mem::swap(&mut self.cycle_rate, &mut self.next_rate);
            std::mem::swap(&mut self.cycle_accel, &mut self.next_accel);
        }
        // (a step that grows no peak leaves the peaks, scales and weights as they are)
        let grown = self.may_grow && self.track_peaks(&st.y, h);
        self.track_flow_peaks(&st.y, grown);
        self.steps += 1;
        self.h_smallest = self.h_smallest.min(h);
        self.h_largest = self.h_largest.max(h);
        // y_{n-2} ← y_{n-1} ← y_n (buffers swapped, no copies)
        std::mem::swap(&mut self.ym2, &mut self.ym1);
        std::mem::swap(&mut self.ym1, &mut self.y0);
        // c_{n-1} ← c_n ← c_{n+1}
        std::mem::swap(&mut self.cm1, &mut self.c0);
        std::mem::swap(&mut self.c0, &mut self.c1);
        if !self.index2.is_empty() {
            // (y0 is the state before the step now: the buffers were swapped)
            self.levels
                .accepted(&self.index2, self.alpha_f, h, &self.ym1, &st.y);
        }
        self.index2_rejections.store(0, Ordering::Relaxed);
        (self.h2, self.h1) = (self.h1, h);
        self.history += 1;
        self.h = self.control.next(h, flow, self.err_old, species);
        self.err_old = flow;
    }

    /// Every group's flow amplitude from the flows of `y`, and (when a peak of `y` grew) the
    /// flows' scales and absolute tolerances: rtol of the group's amplitude A_g, the default
    /// atol scaled by A_g over the largest flow scale (at least `SHARE_FLOOR`; a given atol as
    /// it is: `Tolerances::atol_of`). The scales and
    /// tolerances are renewed when some A_g grew by more than `RESCALE` since they were last
    /// set (a pass over every flow per step while the amplitudes still grow cost as much as
    /// the estimate): a flow's scale stays within that share below its amplitude, the
    /// stricter side. Both passes go in chunks on the run's threads: the flows above their
    /// group's amplitude are found chunk by chunk and applied in order (maxima: the same in
    /// any grouping), the renewal writes each flow's weights from its own values.
    fn track_flow_peaks(&mut self, y: &[f64], grown: bool) {
        if !grown {
            return;
        }
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        if self.group_peak.is_empty() {
            let vessels = self.flow_group.iter().filter(|&&g| g != NO_VESSEL);
            let groups = vessels.map(|&g| g as usize + 1).max();
            self.group_peak = vec![0.0; groups.unwrap_or(0)];
            self.group_set = vec![-1.0; self.group_peak.len()];
        }
        let (groups, q) = (&self.flow_group, &y[n0..n1]);
        let peaks = &self.group_peak;
        // a flow above its group's amplitude is above its own peak |Q| too (which the group's
        // bounds): where the estimate's pass recorded the unknowns whose peak grows, only
        // those flows are read (the group's maximum over the cycle alone is its flows' own,
        // taken at the cycle's end: `start_cycle`)
        let this = &*self;
        let raised = map_chunks(groups.len(), |r| {
            let mut up = Vec::new();
            this.visit(n0 + r.start..n0 + r.end, |i| {
                let (g, q) = (groups[i - n0], q[i - n0].abs());
                if g != NO_VESSEL && q > peaks[g as usize] {
                    up.push((g, q));
                }
            });
            up
        });
        let mut renew = false;
        for (g, v) in raised.into_iter().flatten() {
            let g = g as usize;
            let (p, set) = (&mut self.group_peak[g], self.group_set[g]);
            if v > *p {
                *p = v;
                renew |= *p > set * (1.0 + RESCALE);
            }
        }
        if renew {
            self.renew_flow_weights();
        }
    }

    /// The vessels' flows' weights from their groups' amplitudes (see `track_flow_peaks`).
    // (one index into several slices of the same length)
    #[allow(clippy::needless_range_loop)]
    fn renew_flow_weights(&mut self) {
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        self.group_set.clone_from(&self.group_peak);
        let amplitudes = self.group_peak.iter().fold(0.0f64, |m, &p| m.max(p));
        let (tol, largest, rtol) = (&self.tol, self.kind_set[1].max(amplitudes), self.tol.rtol);
        let (mut iw, mut ws, mut wu) = (
            std::mem::take(&mut self.inv_weight),
            std::mem::take(&mut self.w_step),
            std::mem::take(&mut self.w_unit),
        );
        let this = &*self;
        let weights = |i: usize, w: &mut f64| {
            let g = this.flow_group[i - n0];
            if g != NO_VESSEL {
                let a = this.group_peak[g as usize];
                let s = this.peak[i].max(a);
                *w = 1.0 / (tol.atol_of(1, a, largest) + rtol * s);
            }
        };
        let mut tasks = chunk_tasks(n0, [&mut iw[n0..n1], &mut ws[n0..n1], &mut wu[n0..n1]]);
        for_tasks(&mut tasks, |(first, [iw, ws, wu])| {
            for j in 0..iw.len() {
                let i = *first + j;
                weights(i, &mut iw[j]);
                (ws[j], wu[j]) = this.weights_from(i, iw[j], this.rate_peak[i], this.accel_peak[i]);
            }
            false
        });
        drop(tasks);
        (self.inv_weight, self.w_step, self.w_unit) = (iw, ws, wu);
    }

    /// The local error weights of unknown `i` of weight `inv_weight` and peaks |ẏ|, |ÿ| of
    /// `rate_peak`, `accel_peak` (0 for an algebraic unknown, judged apart).
    #[inline]
    fn weights_from(
        &self,
        i: usize,
        inv_weight: f64,
        rate_peak: f64,
        accel_peak: f64,
    ) -> (f64, f64) {
        let w = if self.algebraic[i] { 0.0 } else { inv_weight };
        (w, w * inv_omega(rate_peak, accel_peak, self.omega))
    }

    /// The kind of unknown `i` (0 pressure, 1 flow, 2 volume: the index into `KINDS`).
    fn kind_of(&self, i: usize) -> usize {
        if i < self.kind_end[0] {
            0
        } else if i < self.kind_end[1] {
            1
        } else {
            2
        }
    }

    /// One pass after an accepted step (in chunks on the run's threads, each unknown its own):
    /// every unknown's largest |y| over the cycle so far and its peak (and its weight, for all
    /// but the vessels' flows, which `track_flow_peaks` sets; every weight when a kind's
    /// largest scale grew: `renew_kind_scales`), and from the divided differences of the last
    /// three accepted states (not from the carried rates, which follow the damped spurious
    /// root at a start) the largest |ẏ| and |ÿ| over the cycle so far and their peaks, hence
    /// the signal frequency. True when some largest |y| over the cycle grew.
    // (one index into several slices of the same length)
    #[allow(clippy::needless_range_loop)]
    fn track_peaks(&mut self, y: &[f64], h: f64) -> bool {
        let h1 = self.h1;
        let (inv_h, inv_h1, inv_span) = (1.0 / h, 1.0 / h1, 2.0 / (h + h1));
        let rates = self.history > 0;
        let renew = AtomicBool::new(false);
        let mut v = [
            std::mem::take(&mut self.peak),
            std::mem::take(&mut self.rate_peak),
            std::mem::take(&mut self.accel_peak),
            std::mem::take(&mut self.cycle_peak),
            std::mem::take(&mut self.cycle_rate),
            std::mem::take(&mut self.cycle_accel),
            std::mem::take(&mut self.inv_weight),
            std::mem::take(&mut self.w_step),
            std::mem::take(&mut self.w_unit),
        ];
        let this = &*self;
        // an unknown in which the step's estimate pass saw no peak grow changes nothing here
        // (the same comparisons; its maxima over the cycle that pass took): only the others
        // are visited (`visit`)
        let [pk, rp, ap, cp, cr, ca, iw, ws, wu] = &mut v;
        let mut tasks = chunk_tasks(0, [&mut pk[..], rp, ap, cp, cr, ca, iw, ws, wu]);
        let grown = for_tasks(
            &mut tasks,
            |(first, [pk, rp, ap, cp, cr, ca, iw, ws, wu])| {
                let mut grown = false;
                this.visit(*first..*first + pk.len(), |i| {
                    let j = i - *first;
                    let a = y[i].abs();
                    let mut reweigh = false;
                    // (a peak is at least the cycle's maximum: what grows the peak grows the
                    // cycle's maximum, which the estimate's pass may have taken already)
                    if a > cp[j] {
                        cp[j] = a;
                        grown = true;
                    }
                    if a > pk[j] {
                        pk[j] = a;
                        grown = true;
                        if a > this.kind_set[this.kind_of(i)] * (1.0 + RESCALE) {
                            renew.store(true, Ordering::Relaxed);
                        }
                        if !this.is_vessel_flow(i) {
                            iw[j] = this.own_weight(i, a);
                            reweigh = true;
                        }
                    }
                    if rates {
                        let (s1, s0) = (
                            (y[i] - this.y0[i]) * inv_h,
                            (this.y0[i] - this.ym1[i]) * inv_h1,
                        );
                        let (r, acc) = (s1.abs(), ((s1 - s0) * inv_span).abs());
                        if r > cr[j] || acc > ca[j] {
                            cr[j] = cr[j].max(r);
                            ca[j] = ca[j].max(acc);
                        }
                        if r > rp[j] || acc > ap[j] {
                            rp[j] = rp[j].max(r);
                            ap[j] = ap[j].max(acc);
                            reweigh = true;
                        }
                    }
                    if reweigh {
                        (ws[j], wu[j]) = this.weights_from(i, iw[j], rp[j], ap[j]);
                    }
                });
                grown
            },
        );
        drop(tasks);
        let [pk, rp, ap, cp, cr, ca, iw, ws, wu] = v;
        (self.peak, self.rate_peak, self.accel_peak) = (pk, rp, ap);
        (self.cycle_peak, self.cycle_rate, self.cycle_accel) = (cp, cr, ca);
        (self.inv_weight, self.w_step, self.w_unit) = (iw, ws, wu);
        if renew.into_inner() {
            self.renew_kind_scales();
        }
        grown
    }

    /// At the start of a cycle after the first (or of the first, after its scout pass): the
    /// scales become the largest values over the cycle just ended, and the current cycle's
    /// start again from the state `y` (|ẏ|, |ÿ| from the next steps), so that a scale is the
    /// largest |y| (|ẏ|, |ÿ|; a vessel's amplitude; a cell's |c|) over the previous cycle and
    /// the current one so far; every kind's largest scale, atol and weight follow. A periodic
    /// solution keeps its scales (its cycles' maxima are the same); a start-up transient
    /// leaves them two cycles after it ends, where over the whole run it loosened every later
    /// cycle's tolerance by its peak over the periodic one's (docs/physics.md §10,
    /// "Settings"). Nothing before the scales are first set (a run with valves sets them at
    /// its first step).
    pub fn start_cycle(&mut self, y: &[f64]) {
        if self.peak.is_empty() {
            return;
        }
        let (n0, n1) = (self.kind_end[0], self.kind_end[1]);
        if !self.group_peak.is_empty() {
            // each group's amplitude over the cycle just ended: its flows' largest maximum
            self.group_peak.fill(0.0);
            for (&g, p) in self.flow_group.iter().zip(&self.cycle_peak[n0..n1]) {
                if g != NO_VESSEL {
                    let c = &mut self.group_peak[g as usize];
                    *c = c.max(*p);
                }
            }
        }
        std::mem::swap(&mut self.peak, &mut self.cycle_peak);
        std::mem::swap(&mut self.rate_peak, &mut self.cycle_rate);
        std::mem::swap(&mut self.accel_peak, &mut self.cycle_accel);
        copy_into(&mut self.cycle_peak, y);
        crate::threads::for_chunks(&mut self.cycle_peak, |_, c| {
            c.iter_mut().for_each(|v| *v = v.abs());
        });
        crate::threads::for_chunks(&mut self.cycle_rate, |_, c| c.fill(0.0));
        crate::threads::for_chunks(&mut self.cycle_accel, |_, c| c.fill(0.0));
        if !self.c_peak.is_empty() {
            std::mem::swap(&mut self.c_peak, &mut self.c_cycle);
            copy_into(&mut self.c_cycle, &self.c0);
            crate::threads::for_chunks(&mut self.c_cycle, |_, c| {
                c.iter_mut().for_each(|v| *v = v.abs());
            });
            self.renew_species_largest();
        }
        self.blocks_known = false;
        self.renew_kind_scales();
    }

    /// `f` of the unknowns of `r`, in order, that the tracking after an accepted step visits:
    /// those in which the step's estimate pass saw a peak grow while its record holds
    /// (`blocks_known`), else all of them.
    #[inline]
    fn visit(&self, r: Range<usize>, mut f: impl FnMut(usize)) {
        if !self.blocks_known {
            r.for_each(f);
            return;
        }
        for b in blocks_of(r) {
            let base = b.start / BLOCK * BLOCK;
            // (the block's bits of the unknowns within `b`)
            let within = ((1u64 << (b.end - base)) - (1u64 << (b.start - base))) as u32;
            let mut bits = self.grow_blocks[base / BLOCK].load(Ordering::Relaxed) & within;
            while bits != 0 {
                f(base + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
    }

    /// The rate shifts (s₀, s₁) of the carried ẏ at the two ends of a step of `h` that starts
    /// after a step of `h1` (none for the start's consistent rate).
    fn shifts(&self, h: f64) -> (f64, f64) {
        let s0 = if self.history == 0 {
            0.0
        } else {
            self.delta * self.h1
        };
        (s0, self.delta * h)
    }

    /// The dense output at θ of the step of `h` from (y0, ẏ0) to (y, ẏ): its weights are
    /// computed once for a row's unknowns. Call before [`Adaptive::accept`] (which moves y0
    /// into the history).
    pub fn dense<'s>(&'s self, theta: f64, h: f64, y: &'s [f64], yd: &'s [f64]) -> Dense<'s> {
        let (s0, s1) = self.shifts(h);
        let (b, db) = hermite(theta);
        let inv_span = 1.0 / (h - s1 + s0);
        let k = h * (b[1] * s0 + b[3] * s1) * inv_span;
        Dense {
            ad: self,
            y,
            yd,
            h,
            x: theta * h,
            b,
            db,
            s0,
            s1,
            inv_span,
            w: [b[0], b[2], h * b[1] - k, h * b[3] + k],
            quadratic: self.history > 0,
        }
    }

    /// The output row at θ of the step of `h` from (y0, ẏ0) to (y, ẏ) appended to `out`: the
    /// values of the unknowns `probes` (see [`Dense::row_into`]).
    pub fn dense_row(
        &mut self,
        (theta, h): (f64, f64),
        (y, yd): (&[f64], &[f64]),
        probes: &[usize],
        out: &mut Vec<f64>,
    ) {
        if self.algebraic_probes.is_none() {
            let at = (probes.iter().enumerate()).filter(|&(_, &i)| self.algebraic[i]);
            let at = at.map(|(k, _)| u32::try_from(k).expect("2^32 probes"));
            self.algebraic_probes = Some(at.collect());
        }
        let at = self.algebraic_probes.as_deref().unwrap_or_default();
        // (the interpolated state's buffer, which a species row also fills whole)
        let mut state = std::mem::take(&mut self.yi);
        self.dense(theta, h, y, yd)
            .row_into(probes, at, &mut state, out);
        self.yi = state;
    }

    /// The whole interpolated state at θ (flow by Hermite, species amounts linearly, as
    /// backward Euler is first order), for a species output row.
    pub fn interpolate_all(
        &mut self,
        theta: f64,
        h: f64,
        st: &State<'_, '_>,
    ) -> (&[f64], &[f64], &[f64], &[f64]) {
        let n = st.y.len();
        self.yi.resize(n, 0.0);
        self.ydi.resize(n, 0.0);
        let (mut yi, mut ydi) = (std::mem::take(&mut self.yi), std::mem::take(&mut self.ydi));
        let dense = self.dense(theta, h, &st.y, &st.yd);
        // (in chunks on the run's threads: each value its own)
        let mut tasks = chunk_tasks(0, [&mut yi[..], &mut ydi[..]]);
        for_tasks(&mut tasks, |(first, [v, d])| {
            for (j, (v, d)) in v.iter_mut().zip(d.iter_mut()).enumerate() {
                (*v, *d) = dense.value_and_rate(*first + j);
            }
            false
        });
        drop(tasks);
        (self.yi, self.ydi) = (yi, ydi);
        self.zi.clear();
        if let Some(sp) = st.species.as_ref() {
            // amounts and the cells' transport volumes linearly: the observed concentration
            // z/V is a weighted mean of the two ends' (within their bounds), and the amounts'
            // balance with the linear accumulators holds
            let z0 = &self.z0;
            self.zi
                .extend(sp.z.iter().zip(z0).map(|(&b, &a)| a + theta * (b - a)));
            let v1 = sp.tr.cell_transport_volumes();
            self.vi.clear();
            self.vi
                .extend(v1.iter().zip(&self.v0).map(|(&b, &a)| a + theta * (b - a)));
        }
        (&self.yi, &self.ydi, &self.zi, &self.vi)
    }
}

/// The flow laws of the circuit's elements whose flow is an algebraic unknown, by that unknown.
fn algebraic_flow_laws(dae: &Dae) -> Vec<FlowLaw> {
    let mut laws: Vec<FlowLaw> = (dae.elements.iter())
        .filter_map(|el| el.flow_law())
        .filter(|l| dae.e[l.unknowns[0]] == 0.0)
        .collect();
    laws.sort_by_key(|l| l.unknowns[0]);
    laws
}

/// The vessel of every branch's flow (`NO_VESSEL` for the others').
pub(super) fn flow_groups(dae: &Dae) -> Vec<u32> {
    let names = &dae.names;
    (0..names.n_branches())
        .map(|b| {
            names
                .branch_vessel(b)
                .map_or(NO_VESSEL, |v| u32::try_from(v).expect("2^32 vessels"))
        })
        .collect()
}

/// The cells' concentrations (amount over transport volume) of every species into `out`.
fn concentrations(st: &State<'_, '_>, out: &mut Vec<f64>) {
    out.clear();
    let Some(sp) = st.species.as_ref() else {
        return;
    };
    let vol = sp.tr.cell_transport_volumes();
    let nc = vol.len();
    let n = nc * sp.tr.species_names().len();
    out.resize(n, 0.0);
    crate::threads::for_chunks(out, |a, c| {
        for (k, (c, &z)) in (a..).zip(c.iter_mut().zip(&sp.z[a..])) {
            *c = z / vol[k % nc];
        }
    });
}

/// The signal frequency's 1/ω_i·ACCUMULATION of an unknown with peaks |ẏ| and |ÿ| of
/// `rate_peak` and `accel_peak` (at least the fundamental's, `omega1` = ω₁/ACCUMULATION).
#[inline]
fn inv_omega(rate_peak: f64, accel_peak: f64, omega1: f64) -> f64 {
    if rate_peak > 0.0 {
        1.0 / (accel_peak / rate_peak / ACCUMULATION).max(omega1)
    } else {
        1.0 / omega1
    }
}

/// The constants of one step's fused estimate (see `Adaptive::fused_errors`).
struct Fused {
    l: [f64; 3],
    f: f64,
    inv_h: f64,
    inv_h1: f64,
    inv_span: f64,
}

/// Unknowns per group of the estimate's pass (see `Adaptive::fused_range`).
const LANES: usize = 4;

/// Unknowns per block of the record of where a step grows a peak (see
/// `Adaptive::grow_blocks`): a divisor of `CHUNK`, and a multiple of `LANES`. Small: the
/// tracking pass visits every unknown of a block where one grew (blocks of 256 sent it over
/// nearly every unknown of adan56's 1 987 in its first cycle, 12 % of that run's instructions).
const BLOCK: usize = 32;

/// The unknowns `r` cut at the boundaries of the blocks of `BLOCK`, in order.
fn blocks_of(r: Range<usize>) -> impl Iterator<Item = Range<usize>> {
    let starts = std::iter::successors(Some(r.start), move |&at| {
        let next = (at / BLOCK + 1) * BLOCK;
        (next < r.end).then_some(next)
    });
    starts
        .take_while(move |&at| at < r.end)
        .map(move |at| at..((at / BLOCK + 1) * BLOCK).min(r.end))
}

/// The vectors of one range of unknowns that the estimate's pass reads (see
/// `Adaptive::fused_range`), each the range's own slice: the states, the weights, the peaks
/// of |y|, |ẏ|, |ÿ| over the previous cycle and the current one (`pk`, `rp`, `ap`: a step
/// above one grows it) and over the current cycle (`cp`, `cr`, `ca`).
struct FusedSlices<'a> {
    y: &'a [f64],
    ym2: &'a [f64],
    ym1: &'a [f64],
    y0: &'a [f64],
    wu: &'a [f64],
    ws: &'a [f64],
    pk: &'a [f64],
    rp: &'a [f64],
    ap: &'a [f64],
    cp: &'a [f64],
    cr: &'a [f64],
    ca: &'a [f64],
}

impl FusedSlices<'_> {
    /// The unknowns `r` of the range.
    #[inline(always)]
    fn sub(&self, r: Range<usize>) -> FusedSlices<'_> {
        FusedSlices {
            y: &self.y[r.clone()],
            ym2: &self.ym2[r.clone()],
            ym1: &self.ym1[r.clone()],
            y0: &self.y0[r.clone()],
            wu: &self.wu[r.clone()],
            ws: &self.ws[r.clone()],
            pk: &self.pk[r.clone()],
            rp: &self.rp[r.clone()],
            ap: &self.ap[r.clone()],
            cp: &self.cp[r.clone()],
            cr: &self.cr[r.clone()],
            ca: &self.ca[r],
        }
    }

    /// Unknown `j`'s scaled local error (Milne's device on the last three states, per unit
    /// step or per step, the larger), whether it grows one of the peaks `track_peaks`
    /// follows (the same comparisons), and its maxima of |y|, |ẏ|, |ÿ| over the cycle with
    /// the step (`track_peaks`'s values: the rates from the same divided differences).
    #[inline(always)]
    fn term(&self, j: usize, c: &Fused) -> (f64, bool, [f64; 3]) {
        let ([la, lb, lc], f) = (c.l, c.f);
        let (y1, y0, ym) = (self.y[j], self.y0[j], self.ym1[j]);
        let e = f * (y1 - (la * self.ym2[j] + lb * ym + lc * y0));
        let scaled = e.abs() * larger(self.wu[j] * c.inv_h, self.ws[j]);
        let (s1, s0) = ((y1 - y0) * c.inv_h, (y0 - ym) * c.inv_h1);
        let (a, r, accel) = (y1.abs(), s1.abs(), ((s1 - s0) * c.inv_span).abs());
        let grows = (a > self.pk[j]) | (r > self.rp[j]) | (accel > self.ap[j]);
        let cycle = [
            larger(a, self.cp[j]),
            larger(r, self.cr[j]),
            larger(accel, self.ca[j]),
        ];
        (scaled, grows, cycle)
    }

    /// The block's largest scaled error and its unknowns that grow a peak (bit k: its k-th),
    /// in groups of `LANES` (see `Adaptive::fused_range`), its maxima over the cycle with the
    /// step into `out`.
    // (one lane index into the group and its maximum)
    #[allow(clippy::needless_range_loop)]
    #[inline(always)]
    fn block(&self, c: &Fused, out: [&mut [f64]; 3]) -> (f64, u32) {
        let n = self.y.len();
        let whole = n - n % LANES;
        let (mut m, mut mask) = ([0.0f64; LANES], 0u32);
        let [op, or, oa] = out;
        for j in (0..whole).step_by(LANES) {
            // (a group's own slices, of `LANES` values: its values are read without a bounds
            // check each, 9 a value before)
            let group = self.sub(j..j + LANES);
            let (gp, gr, ga) = (
                &mut op[j..j + LANES],
                &mut or[j..j + LANES],
                &mut oa[j..j + LANES],
            );
            for k in 0..LANES {
                let (e, g, cycle) = group.term(k, c);
                m[k] = larger(e, m[k]);
                mask |= u32::from(g) << (j + k);
                [gp[k], gr[k], ga[k]] = cycle;
            }
        }
        for j in whole..n {
            let (e, g, cycle) = self.term(j, c);
            m[0] = larger(e, m[0]);
            mask |= u32::from(g) << j;
            [op[j], or[j], oa[j]] = cycle;
        }
        (m.iter().fold(0.0f64, |a, &b| larger(b, a)), mask)
    }
}

/// `FusedSlices::block` with each group of `LANES` unknowns in one AVX2 vector per operation:
/// `FusedSlices::term`'s operations in its order on every unknown (the running maximum as
/// `vmaxpd`, which is `larger`), so the same numbers and the same growth bits, at a quarter of
/// the instructions. (The portable block, compiled for any x86-64, runs it in scalar or
/// two-lane registers: ~30 instructions an unknown on adan56.)
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn simd_block(
    simd: pulp::x86::V3,
    v: &FusedSlices<'_>,
    c: &Fused,
    out: [&mut [f64]; 3],
) -> (f64, u32) {
    use pulp::{cast, f64x4};
    let n = v.y.len();
    let groups = |x| groups_of(x, n);
    let y1s = groups(v.y);
    let g = y1s.len();
    let (y0s, yms, ym2s) = (&groups(v.y0)[..g], &groups(v.ym1)[..g], &groups(v.ym2)[..g]);
    let (wus, wss) = (&groups(v.wu)[..g], &groups(v.ws)[..g]);
    let (pks, rps, aps) = (&groups(v.pk)[..g], &groups(v.rp)[..g], &groups(v.ap)[..g]);
    let (cps, crs, cas) = (&groups(v.cp)[..g], &groups(v.cr)[..g], &groups(v.ca)[..g]);
    let [op, or, oa] = out;
    let (ops, ors, oas) = (
        &mut groups_of_mut(op, n)[..g],
        &mut groups_of_mut(or, n)[..g],
        &mut groups_of_mut(oa, n)[..g],
    );
    let splat = |x: f64| simd.splat_f64x4(x);
    let ([la, lb, lc], f) = (c.l.map(splat), splat(c.f));
    let (inv_h, inv_h1, inv_span) = (splat(c.inv_h), splat(c.inv_h1), splat(c.inv_span));
    let (mut m, mut mask) = (splat(0.0), 0u32);
    for k in 0..g {
        let at = |x: &[[f64; LANES]]| -> f64x4 { cast(x[k]) };
        let (y1, y0, ym) = (at(y1s), at(y0s), at(yms));
        let past = simd.add_f64x4(
            simd.add_f64x4(simd.mul_f64x4(la, at(ym2s)), simd.mul_f64x4(lb, ym)),
            simd.mul_f64x4(lc, y0),
        );
        let e = simd.mul_f64x4(f, simd.sub_f64x4(y1, past));
        let weight = simd.max_f64x4(simd.mul_f64x4(at(wus), inv_h), at(wss));
        m = simd.max_f64x4(simd.mul_f64x4(simd.abs_f64x4(e), weight), m);
        let s1 = simd.mul_f64x4(simd.sub_f64x4(y1, y0), inv_h);
        let s0 = simd.mul_f64x4(simd.sub_f64x4(y0, ym), inv_h1);
        let accel = simd.abs_f64x4(simd.mul_f64x4(simd.sub_f64x4(s1, s0), inv_span));
        let (a, r) = (simd.abs_f64x4(y1), simd.abs_f64x4(s1));
        let grows = simd.or_m64x4(
            simd.or_m64x4(simd.cmp_gt_f64x4(a, at(pks)), simd.cmp_gt_f64x4(r, at(rps))),
            simd.cmp_gt_f64x4(accel, at(aps)),
        );
        let bits = simd.avx._mm256_movemask_pd(cast(grows)) as u32;
        mask |= bits << (LANES * k);
        // (`vmaxpd(x, c)` is `larger(x, c)`: x where x > c, else c)
        ops[k] = cast(simd.max_f64x4(a, at(cps)));
        ors[k] = cast(simd.max_f64x4(r, at(crs)));
        oas[k] = cast(simd.max_f64x4(accel, at(cas)));
    }
    let lanes: [f64; LANES] = cast(m);
    let mut m = lanes.iter().fold(0.0f64, |a, &b| larger(b, a));
    for j in LANES * g..n {
        let (e, grows, cycle) = v.term(j, c);
        m = larger(e, m);
        mask |= u32::from(grows) << j;
        [op[j], or[j], oa[j]] = cycle;
    }
    (m, mask)
}

/// The first `n` values of `x` in whole groups of `LANES` (the rest left out).
#[inline(always)]
fn groups_of(x: &[f64], n: usize) -> &[[f64; LANES]] {
    pulp::as_arrays::<LANES, f64>(&x[..n]).0
}

/// The first `n` values of `x` in whole groups of `LANES`, to write (the rest left out).
#[inline(always)]
fn groups_of_mut(x: &mut [f64], n: usize) -> &mut [[f64; LANES]] {
    pulp::as_arrays_mut::<LANES, f64>(&mut x[..n]).0
}

/// The larger of `a` and `b`, `b` when they are unordered (a NaN `a` leaves a running maximum
/// `b` as `f64::max` does): one compare-and-select.
#[inline(always)]
fn larger(a: f64, b: f64) -> f64 {
    if a > b { a } else { b }
}

/// `dst` = `src` (copied in chunks on the run's threads for a long state).
fn copy_into(dst: &mut Vec<f64>, src: &[f64]) {
    if dst.len() != src.len() {
        dst.clear();
        dst.extend_from_slice(src);
        return;
    }
    crate::threads::for_chunks(dst, |a, c| c.copy_from_slice(&src[a..a + c.len()]));
}

/// The run's pool, if a pass over `len` elements is worth splitting over it (as the passes of
/// `crate::threads`).
fn pool_for(len: usize) -> Option<std::sync::Arc<rayon::ThreadPool>> {
    crate::threads::pool().filter(|_| len >= 2 * CHUNK)
}

/// `f` of the ranges of `CHUNK` elements of `0..len` in order (on the run's threads for a
/// long pass).
fn map_chunks<R: Send>(len: usize, f: impl Fn(Range<usize>) -> R + Sync + Send) -> Vec<R> {
    use rayon::prelude::*;
    let range = |c: usize| c * CHUNK..((c + 1) * CHUNK).min(len);
    let chunks = len.div_ceil(CHUNK);
    match pool_for(len) {
        Some(pool) => pool.install(|| (0..chunks).into_par_iter().map(|c| f(range(c))).collect()),
        None => (0..chunks).map(|c| f(range(c))).collect(),
    }
}

/// The slices `v` (of one length) cut into chunks of `CHUNK` elements: a task per chunk, with
/// the index of its first element (`first` that of `v`'s).
fn chunk_tasks<const K: usize>(first: usize, v: [&mut [f64]; K]) -> Vec<(usize, [&mut [f64]; K])> {
    let len = v.first().map_or(0, |s| s.len());
    let mut rest = v;
    let mut tasks = Vec::with_capacity(len.div_ceil(CHUNK));
    let mut at = 0;
    while at < len {
        let m = CHUNK.min(len - at);
        let mut head: [&mut [f64]; K] = std::array::from_fn(|_| <&mut [f64]>::default());
        for (h, r) in head.iter_mut().zip(rest.iter_mut()) {
            let (a, b) = std::mem::take(r).split_at_mut(m);
            (*h, *r) = (a, b);
        }
        tasks.push((first + at, head));
        at += m;
    }
    tasks
}

/// The largest of each of the two values `f` returns for every task (on the run's threads
/// when there are several, each task writing only its own chunks; maxima: the same in any
/// grouping).
fn fold_tasks<T: Send>(
    tasks: &mut [T],
    f: impl Fn(&mut T) -> (f64, f64) + Sync + Send,
) -> (f64, f64) {
    use rayon::prelude::*;
    let larger = |a: (f64, f64), b: (f64, f64)| (a.0.max(b.0), a.1.max(b.1));
    match crate::threads::pool().filter(|_| tasks.len() > 1) {
        Some(pool) => pool.install(|| tasks.par_iter_mut().map(f).reduce(|| (0.0, 0.0), larger)),
        None => tasks.iter_mut().map(f).fold((0.0, 0.0), larger),
    }
}

/// The largest of each kind's maximum `f` returns for every task, and whether any returned
/// true (on the run's threads when there are several, each task writing only its own chunks;
/// maxima: the same in any grouping).
fn kind_maxima<T: Send>(
    tasks: &mut [T],
    f: impl Fn(&mut T) -> ([f64; 3], bool) + Sync + Send,
) -> ([f64; 3], bool) {
    use rayon::prelude::*;
    let join = |a: ([f64; 3], bool), b: ([f64; 3], bool)| {
        let k = |i: usize| a.0[i].max(b.0[i]);
        ([k(0), k(1), k(2)], a.1 | b.1)
    };
    let none = ([0.0f64; 3], false);
    match crate::threads::pool().filter(|_| tasks.len() > 1) {
        Some(pool) => pool.install(|| tasks.par_iter_mut().map(f).reduce(|| none, join)),
        None => tasks.iter_mut().map(f).fold(none, join),
    }
}

/// `f` of every task (on the run's threads when there are several, each task writing only its
/// own chunks): whether any returned true (every task runs).
fn for_tasks<T: Send>(tasks: &mut [T], f: impl Fn(&mut T) -> bool + Sync + Send) -> bool {
    use rayon::prelude::*;
    match crate::threads::pool().filter(|_| tasks.len() > 1) {
        Some(pool) => pool.install(|| tasks.par_iter_mut().map(f).reduce(|| false, |a, b| a | b)),
        None => tasks.iter_mut().map(f).fold(false, |a, b| a | b),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values of mixed sign and magnitude (a fixed linear congruential sequence).
    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|_| {
                x = x
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let u = (x >> 11) as f64 / (1u64 << 53) as f64;
                (u - 0.4) * 10f64.powi((x % 7) as i32 - 3)
            })
            .collect()
    }

    /// Each unknown's scaled error, growth and maxima over the cycle from
    /// `FusedSlices::term` (the formula, one unknown at a time): the block's largest error,
    /// its growth bits and its maxima (|y|, |ẏ|, |ÿ|) as bits.
    fn one_by_one(v: &FusedSlices<'_>, c: &Fused) -> (f64, u32, Vec<[u64; 3]>) {
        let mut cycle = Vec::new();
        let (m, mask) = (0..v.y.len()).fold((0.0f64, 0u32), |(m, mask), j| {
            let (e, g, cy) = v.term(j, c);
            cycle.push(cy.map(f64::to_bits));
            (m.max(e), mask | (u32::from(g) << j))
        });
        (m, mask, cycle)
    }

    /// The maxima a block wrote, unknown by unknown, as bits.
    fn written(out: &[Vec<f64>; 3]) -> Vec<[u64; 3]> {
        (0..out[0].len())
            .map(|j| [0, 1, 2].map(|k| out[k][j].to_bits()))
            .collect()
    }

    /// Unknown `j`'s maxima over the cycle as the tracking pass takes them (`track_peaks`).
    fn tracked(s: &FusedSlices<'_>, c: &Fused, j: usize) -> [u64; 3] {
        let (s1, s0) = (
            (s.y[j] - s.y0[j]) * c.inv_h,
            (s.y0[j] - s.ym1[j]) * c.inv_h1,
        );
        let (r, acc) = (s1.abs(), ((s1 - s0) * c.inv_span).abs());
        let a = s.y[j].abs();
        let p = if a > s.cp[j] { a } else { s.cp[j] };
        [p, s.cr[j].max(r), s.ca[j].max(acc)].map(f64::to_bits)
    }

    #[test]
    fn a_blocks_estimate_and_growth_bits_are_each_unknowns_own_in_every_grouping() {
        let c = Fused {
            l: [0.3, -1.1, 1.8],
            f: 0.04,
            inv_h: 1.6e3,
            inv_h1: 1.5e3,
            inv_span: 1.55e3,
        };
        for n in 1..=BLOCK {
            let v: Vec<Vec<f64>> = (0..12).map(|k| values(n, 17 * n as u64 + k)).collect();
            // peaks and weights are magnitudes; a third of the peaks so large nothing grows
            let pos = |k: usize, big: f64| -> Vec<f64> {
                (v[k].iter().enumerate())
                    .map(|(j, x)| x.abs() * if j % 3 == 0 { big } else { 1.0 })
                    .collect()
            };
            let (wu, ws, pk, rp, ap) = (
                pos(4, 1.0),
                pos(5, 1.0),
                pos(6, 1e9),
                pos(7, 1e9),
                pos(8, 1e12),
            );
            // the cycle's maxima: at most the peaks, some above the step's values, some below;
            // the third with the large peaks has reached them (its maxima cannot grow), so
            // every block of three or more has maxima that grow and maxima that do not
            let below = |k: usize, peak: &[f64]| -> Vec<f64> {
                (v[k].iter().zip(peak).enumerate())
                    .map(|(j, (x, p))| if j % 3 == 0 { *p } else { x.abs().min(*p) })
                    .collect()
            };
            let (cp, cr, ca) = (below(9, &pk), below(10, &rp), below(11, &ap));
            let s = FusedSlices {
                y: &v[0],
                ym2: &v[1],
                ym1: &v[2],
                y0: &v[3],
                wu: &wu,
                ws: &ws,
                pk: &pk,
                rp: &rp,
                ap: &ap,
                cp: &cp,
                cr: &cr,
                ca: &ca,
            };
            let (m, mask, cycle) = one_by_one(&s, &c);
            assert!(
                mask != 0 && mask.count_ones() < n as u32 || n < 3,
                "n {n}: {mask:b}"
            );
            let own: Vec<[u64; 3]> = (0..n).map(|j| tracked(&s, &c, j)).collect();
            assert_eq!(cycle, own, "the formula's maxima, n {n}");
            let grew = (0..n).filter(|&j| cycle[j][0] != cp[j].to_bits()).count();
            assert!(grew > 0 && grew < n || n < 3, "n {n}: {grew} maxima grew");
            let mut out: [Vec<f64>; 3] = std::array::from_fn(|_| vec![f64::NAN; n]);
            let (pm, pmask) = {
                let [a, b, d] = &mut out;
                s.block(&c, [a, b, d])
            };
            assert_eq!(
                (pm.to_bits(), pmask, written(&out)),
                (m.to_bits(), mask, own.clone()),
                "portable, n {n}"
            );
            #[cfg(target_arch = "x86_64")]
            if let Some(simd) = pulp::x86::V3::try_new() {
                let mut out: [Vec<f64>; 3] = std::array::from_fn(|_| vec![f64::NAN; n]);
                let (vm, vmask) = {
                    let [a, b, d] = &mut out;
                    simd.vectorize(|| simd_block(simd, &s, &c, [a, b, d]))
                };
                assert_eq!(
                    (vm.to_bits(), vmask, written(&out)),
                    (m.to_bits(), mask, own),
                    "AVX2, n {n}"
                );
            }
        }
    }

    #[test]
    fn the_whole_states_cubic_is_each_unknowns_own_sum() {
        let w = [0.2, 0.8, 1.3e-4, -0.7e-4];
        for n in 0..41 {
            let v: Vec<Vec<f64>> = (0..4).map(|k| values(n, 5 * n as u64 + k)).collect();
            let mut state = vec![7.0; n % 5];
            cubic_all(w, [&v[0], &v[1], &v[2], &v[3]], &mut state);
            let own =
                (0..n).map(|i| w[0] * v[0][i] + w[1] * v[1][i] + w[2] * v[2][i] + w[3] * v[3][i]);
            let own: Vec<u64> = own.map(f64::to_bits).collect();
            assert_eq!(
                state.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                own,
                "n {n}"
            );
        }
    }
}
