//! Generalized-α for E ẏ + F y + c(y) = f(t): the scheme and parameters of svZeroDSolver
//! (Jansen–Whiting–Hulbert 2000, predictor ẏ⁰ = (1 − 1/γ) ẏₙ, Newton on ẏ).
//! For a linear circuit the iteration matrix is constant, so it is factorised once per run.
//! Time-varying coefficients (`Dae::varying`) make it change from step to step but not within
//! a step: it is refactorised once per step, and again per Newton iteration only when stenoses
//! make it depend on the iterate.

use super::leaves::Leaves;
use super::newton::{self, Magnitude, NewtonProblem, jacobian_pattern, jacobian_values_scaled};
use crate::circuit::{Csr, Dae, JacobianKind, Regime};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;
use crate::waveform::Waveform;
use rayon::prelude::*;
use std::borrow::Cow;

// moved to `newton`, kept here for the callers of `crate::genalpha::...`
pub use super::newton::{NewtonControl, scaled_increment, singular};

pub struct GenAlpha<'a> {
    dae: &'a Dae,
    /// The mass diagonal of the regime (the DAE's own for the transient one: not copied).
    e: Cow<'a, [f64]>,
    regime: Regime,
    pub dt: f64,
    am: f64,
    af: f64,
    gamma: f64,
    control: NewtonControl,
    lu: SparseLu,
    /// The trailing leaf unknowns (friction cells) of a linear circuit, condensed out of `lu`
    /// (`super::leaves`); None: `lu` is the whole iteration matrix.
    leaves: Option<Leaves>,
    /// Number of values of the iteration matrix (the stamps of `jacobian_stamps`).
    n_stamps: usize,
    /// For each chain-rule capacitor, the value index of its F entry (node row, flow column).
    chain_flow_entry: Vec<usize>,
    factored: bool,
    /// The forcing vector of a nonlinear step (empty for linear circuits: see `forcing`).
    f: Vec<f64>,
    /// The forcing of a linear step, by row: most rows have none, so a dense vector would be
    /// zeroed and read back every step for nothing.
    forcing: SparseForcing,
    r: Vec<f64>,
    /// Newton iterate and α_f level of a nonlinear step (empty for linear circuits, whose
    /// step needs neither: a million-segment tree saves three state vectors).
    y_new: Vec<f64>,
    yd_new: Vec<f64>,
    y_af: Vec<f64>,
    /// Running scale of the Newton increments (see `Magnitude`).
    magnitude: Magnitude,
    /// The unfiltered estimate of `filter_error` (empty until an error-controlled run).
    filter_scratch: Vec<f64>,
    /// The iteration matrix's values of the last factorisation, kept for the next once the
    /// step has changed (an error-controlled run refactorises at nearly every step: fresh
    /// vectors of a million-segment circuit's ~7 million values were pages to fault in and
    /// zero at each); empty while the step stays fixed (one factorisation).
    factor_scratch: Vec<f64>,
    /// The step has changed since the start (see `factor_scratch`).
    dt_changed: bool,
    /// The LU's map from the stamps to its values was dropped after a fixed step's one
    /// factorisation (`factor_ahead`); made again from the DAE's pattern before another.
    slots_released: bool,
    /// Newton with the natural-monotonicity line search (see `newton::solve`): set by an
    /// error-controlled run after a Newton failure (plain Newton cycles around a steep valve
    /// law's switch whatever the step, as the algebraic rows do not shrink with it).
    damped: bool,
}

impl<'a> GenAlpha<'a> {
    /// The running scale of the Newton increments (carried by a checkpoint).
    pub fn newton_scale(&self) -> &Magnitude {
        &self.magnitude
    }

    pub fn newton_scale_mut(&mut self) -> &mut Magnitude {
        &mut self.magnitude
    }

    pub fn new(
        dae: &'a Dae,
        regime: Regime,
        dt: f64,
        rho_inf: f64,
        control: NewtonControl,
    ) -> Result<Self> {
        if !(0.0..=1.0).contains(&rho_inf) {
            return Err(Error::model(
                "simulation",
                format!("rho_infty must be in [0, 1], got {rho_inf}"),
            ));
        }
        let am = 0.5 * (3.0 - rho_inf) / (1.0 + rho_inf);
        let af = 1.0 / (1.0 + rho_inf);
        let gamma = 0.5 + am - af;
        let stamps = jacobian_pattern(dae);
        // (the node row of a capacitor holds its R branch's flow: the incidence)
        let chain_flow_entry = dae
            .chain_rule
            .iter()
            .map(|c| {
                dae.f
                    .row(c.node)
                    .find(|&k| dae.f.col[k] as usize == c.flow)
                    .expect("a capacitor node's row holds its inflow")
            })
            .collect();
        let n = dae.n;
        let mut e = match regime {
            Regime::Transient => Cow::Borrowed(dae.e.as_slice()),
            _ => Cow::Owned(dae.mass(regime)),
        };
        if !dae.chain_rule.is_empty() {
            // a chain-rule capacitor's row has its E ẏ term on the inlet pressure and the flow
            let m = e.to_mut();
            for c in &dae.chain_rule {
                m[c.node] = 0.0;
            }
        }
        let nonlinear = if dae.is_linear() && dae.is_constant(regime) {
            0
        } else {
            n
        };
        let (leaves, lu) = match (nonlinear == 0)
            .then(|| Leaves::find(dae, &e, &stamps))
            .flatten()
        {
            Some((leaves, lu)) => (Some(leaves), lu),
            None => (None, SparseLu::analyse(dae.n, &stamps)?),
        };
        // (a condensed step's residual holds the reduced system's rows alone)
        let reduced_n = leaves.as_ref().map_or(n, |l| l.start);
        // the pattern was needed to analyse it: gone before the step's vectors are allocated
        let n_stamps = stamps.len();
        drop(stamps);
        Ok(GenAlpha {
            dae,
            e,
            regime,
            dt,
            am,
            af,
            gamma,
            control,
            lu,
            leaves,
            n_stamps,
            chain_flow_entry,
            factored: false,
            f: vec![0.0; nonlinear],
            forcing: SparseForcing::new(dae),
            r: vec![0.0; reduced_n],
            y_new: vec![0.0; nonlinear],
            yd_new: vec![0.0; nonlinear],
            y_af: vec![0.0; nonlinear],
            magnitude: Magnitude::new(dae),
            filter_scratch: Vec::new(),
            factor_scratch: Default::default(),
            dt_changed: false,
            slots_released: false,
            damped: false,
        })
    }

    /// Factorise the iteration matrix at the α_f level `y_af` (read for the stenosis slopes
    /// only) and the α_m level `yd_am` (read for chain-rule capacitors only). Its values are
    /// built here and dropped: a linear circuit factorises once.
    ///
    /// A chain-rule capacitor's row C (ẏ_in − (R + 2S|Q|) ẏ_Q) + Q_out − Q_in couples the node
    /// to the inlet pressure, which would break the tree pattern of the circuit. Newton solves
    /// instead with that row plus w = α_m C/(α_f γ Δt) times its R branch's row
    /// (−P_in + P_c + (R + S|Q|)Q): the same iterates, and the inlet coupling and the
    /// α_m C (R + 2S|Q|) terms cancel, leaving α_m C on the diagonal and
    /// −α_f γ Δt (1 + 2CS sgn(Q) ẏ_Q) at the flow (see `Iterate::solve` for the right side).
    fn factor(&mut self, time: f64, y_af: &[f64], yd_am: &[f64]) -> Result<()> {
        if self.slots_released {
            self.restore_slots();
        }
        let c = self.af * self.gamma * self.dt;
        let mut kvals = std::mem::take(&mut self.factor_scratch);
        // (the values before the elements' are all written below: only the elements' are
        // zeroed, as a fresh vector's)
        let nf = self.dae.f.val.len();
        kvals.resize(self.n_stamps, 0.0);
        kvals[nf + self.dae.n..].fill(0.0);
        // the line search's retry (an error-controlled run's answer to a Newton failure)
        // writes the valve rows in their flow form, whose exact matrix stays regular where the
        // pressure form's turns singular in backflow (1 + Q R′ → 0) at iterates away from the
        // solution (`element::valve`)
        let kind = if self.damped {
            JacobianKind::FlowForm
        } else {
            JacobianKind::Exact
        };
        // (α_m E written into the diagonal's values directly: no state-sized copy of it)
        jacobian_values_scaled(
            self.dae,
            (c, (self.am, &*self.e)),
            y_af,
            time,
            kind,
            &mut kvals,
        );
        for (cr, &k) in self.dae.chain_rule.iter().zip(&self.chain_flow_entry) {
            let q = y_af[cr.flow];
            let sign = f64::from(i8::from(q > 0.0) - i8::from(q < 0.0));
            kvals[nf + cr.node] += self.am * cr.capacitance;
            kvals[k] -= c * 2.0 * cr.capacitance * cr.stenosis * sign * yd_am[cr.flow];
        }
        self.dae
            .varying_jacobian(c, time, self.regime, &mut kvals[nf..nf + self.dae.n]);
        // (ẏ's weight in a linear step's residual, `step_linear`)
        let c_am = 1.0 + self.am * ((self.gamma - 1.0) / self.gamma - 1.0);
        let name = |i: usize| self.dae.names.unknown(i);
        let factored = match &mut self.leaves {
            Some(leaves) => leaves.factor(&mut self.lu, &kvals, (self.am, c, c_am), &name),
            None => self.lu.factor_naming(&kvals, &name),
        };
        if self.dt_changed {
            self.factor_scratch = kvals;
        }
        factored.map_err(|m| singular(time, &m))?;
        self.factored = true;
        Ok(())
    }

    /// The factorisation the first linear step from (`time`, `y`) makes, made now (see
    /// `Integrator::factor_ahead`): the same call with the same arguments; nothing for a
    /// nonlinear or time-varying circuit (it factorises in its Newton iterations).
    ///
    /// Only a fixed-step run asks for it, so its factors serve the whole run: the LU's map
    /// from the stamps to its values (4 bytes a stamp) is dropped then, and made again only if
    /// the step changes after all.
    pub fn factor_ahead(&mut self, time: f64, y: &[f64]) -> Result<()> {
        if self.dae.is_linear() && self.dae.is_constant(self.regime) && !self.factored {
            self.factor(time + self.af * self.dt, y, &[])?;
            self.slots_released = self.lu.release_slots();
        }
        Ok(())
    }

    /// The LU's map that `factor_ahead` dropped, made again from the pattern it was analysed
    /// with: the DAE's stamps (the reduced system's alone when leaves are condensed: in order,
    /// those between two of its unknowns, as `Leaves::find` lists them).
    fn restore_slots(&mut self) {
        let mut stamps = jacobian_pattern(self.dae);
        if let Some(leaves) = &self.leaves {
            let start = leaves.start as u32;
            stamps.retain(|&(r, c)| r < start && c < start);
        }
        self.lu.restore_slots(&stamps);
        self.slots_released = false;
    }

    /// Change the step (error-controlled runs): the iteration matrix depends on it, so a
    /// linear circuit refactorises at its next step; the same step keeps the factors.
    pub fn set_dt(&mut self, dt: f64) {
        if dt.to_bits() != self.dt.to_bits() {
            self.dt = dt;
            self.factored = false;
            self.dt_changed = true;
        }
    }

    /// Shampine's filter of a local error estimate (see `Integrator::filter_error`), with
    /// the factors of the step just taken (of its last Newton iteration for a nonlinear
    /// circuit); nothing before the first factorisation or if the solve fails.
    pub fn filter_error(&mut self, v: &mut [f64]) {
        if !self.factored {
            return;
        }
        // (the estimate is kept in the scratch vector, reused from step to step, in case the
        // solve fails)
        let mut saved = std::mem::take(&mut self.filter_scratch);
        saved.clear();
        saved.extend_from_slice(v);
        for (x, e) in v.iter_mut().zip(self.e.iter()) {
            *x *= self.am * e;
        }
        let solved = match &self.leaves {
            Some(leaves) => leaves.solve_in_place(&self.lu, v),
            None => self.lu.solve_in_place(v),
        };
        if !solved {
            v.copy_from_slice(&saved);
        }
        self.filter_scratch = saved;
    }

    /// Newton with (true) or without the line search of `newton::solve` from the next step.
    pub fn set_damped(&mut self, on: bool) {
        self.damped = on;
    }

    /// α_f: the level at which the residual (and so the face flows for transport) is enforced.
    pub fn alpha_f(&self) -> f64 {
        self.af
    }

    /// Advance (y, ẏ) from `time` to `time + dt` in place.
    pub fn step(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        if self.dae.is_linear() && self.dae.is_constant(self.regime) {
            return self.step_linear(time, None, y, yd);
        }
        self.step_nonlinear(time, y, yd)
    }

    /// Advance from the state `start` = (y, ẏ) at `time` to (y, ẏ) at `time + dt`, written
    /// into `y` and `yd` (whatever they held): the same values as [`GenAlpha::step`] from
    /// `start`. A linear step reads the start and writes the end in its own passes, so an
    /// error-controlled run, which keeps the step's start anyway, exchanges buffers instead
    /// of copying the state before each step; a nonlinear step starts from a copy.
    pub fn step_from(
        &mut self,
        time: f64,
        start: (&[f64], &[f64]),
        y: &mut [f64],
        yd: &mut [f64],
    ) -> Result<()> {
        if self.dae.is_linear() && self.dae.is_constant(self.regime) {
            return self.step_linear(time, Some(start), y, yd);
        }
        y.copy_from_slice(start.0);
        yd.copy_from_slice(start.1);
        self.step_nonlinear(time, y, yd)
    }

    /// A nonlinear (or time-varying) circuit's step in place: Newton on ẏ_{n+1}.
    fn step_nonlinear(&mut self, time: f64, y: &mut [f64], yd: &mut [f64]) -> Result<()> {
        let pred = (self.gamma - 1.0) / self.gamma;
        for (((ydn, yn), &ydi), &yi) in self
            .yd_new
            .iter_mut()
            .zip(&mut self.y_new)
            .zip(&*yd)
            .zip(&*y)
        {
            *ydn = ydi * pred;
            *yn = yi;
        }
        let t_af = time + self.af * self.dt;
        self.dae.forcing_into(t_af, self.regime, &mut self.f);
        self.magnitude.observe(y);
        let (mut r, mut scale, control) =
            (std::mem::take(&mut self.r), self.magnitude, self.control);
        let mut it = Iterate {
            ga: self,
            y,
            yd,
            t_af,
        };
        let done = newton::solve(&mut it, &mut r, &control, &mut scale, t_af);
        if let Err(e) = done {
            // the failed iterates stay out of the running scale (a retry starts from the
            // step's start); `r` holds the last correction: name its largest unknown
            let worst = self.worst_correction(&r, &scale);
            self.r = r;
            return Err(match (e, worst) {
                (Error::Solver { time, message }, Some(i)) => Error::solver(
                    time,
                    format!(
                        "{message} (largest correction at {})",
                        self.dae.names.unknown(i)
                    ),
                ),
                (e, _) => e,
            });
        }
        (self.r, self.magnitude) = (r, scale);
        y.copy_from_slice(&self.y_new);
        yd.copy_from_slice(&self.yd_new);
        Ok(())
    }
}

impl GenAlpha<'_> {
    /// The unknown of the largest correction in `r` relative to its kind's running scale.
    fn worst_correction(&self, r: &[f64], scale: &Magnitude) -> Option<usize> {
        let [p, q] = scale.peaks();
        let nn = self.dae.n_nodes;
        let rel = |(i, d): (usize, &f64)| {
            let s = if i < nn { p } else { q };
            (i, d.abs() / s.max(1e-300))
        };
        r.iter()
            .enumerate()
            .map(rel)
            .filter(|(_, v)| v.is_finite())
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i)
    }
}

/// The Newton problem of one nonlinear step: unknown ẏ_{n+1}, with y_{n+1} = y_n + γ Δt Δẏ
/// and the residual enforced at the intermediate levels y_{n+α_f}, ẏ_{n+α_m}.
struct Iterate<'s, 'a> {
    ga: &'s mut GenAlpha<'a>,
    y: &'s [f64],
    yd: &'s [f64],
    t_af: f64,
}

impl NewtonProblem for Iterate<'_, '_> {
    fn residual(&mut self, r: &mut [f64]) {
        let ga = &mut *self.ga;
        let (am, af) = (ga.am, ga.af);
        for ((ya, &yn), &yi) in ga.y_af.iter_mut().zip(&ga.y_new).zip(self.y) {
            *ya = yi + af * (yn - yi);
        }
        ga.dae.static_residual(&ga.y_af, &ga.f, r);
        ga.dae.varying_residual(self.t_af, ga.regime, &ga.y_af, r);
        ga.dae
            .element_residual_of(self.t_af, &ga.y_af, r, ga.damped);
        for (i, ri) in r.iter_mut().enumerate() {
            *ri -= ga.e[i] * (self.yd[i] + am * (ga.yd_new[i] - self.yd[i]));
        }
        // svZeroDSolver's capacitor rows: C (ẏ_in − (R + 2S|Q|) ẏ_Q) at (y_αf, ẏ_αm)
        let yd_am = |i: usize| self.yd[i] + am * (ga.yd_new[i] - self.yd[i]);
        for cr in &ga.dae.chain_rule {
            let slope = cr.resistance + 2.0 * cr.stenosis * ga.y_af[cr.flow].abs();
            r[cr.node] -= cr.capacitance * (yd_am(cr.inlet) - slope * yd_am(cr.flow));
        }
    }
    fn factor(&mut self, it: usize) -> Result<()> {
        // stenoses make the iteration matrix depend on the iterate; time-varying coefficients
        // only on the step's time, so without stenoses the step's first factorisation holds
        if it > 0 && self.ga.dae.is_linear() {
            return Ok(());
        }
        let y_af = std::mem::take(&mut self.ga.y_af);
        let yd_am: Vec<f64> = if self.ga.dae.chain_rule.is_empty() {
            Vec::new()
        } else {
            let am = self.ga.am;
            let (yd, yd_new) = (self.yd, &self.ga.yd_new);
            yd.iter()
                .zip(yd_new)
                .map(|(&a, &b)| a + am * (b - a))
                .collect()
        };
        let done = self.ga.factor(self.t_af, &y_af, &yd_am);
        self.ga.y_af = y_af;
        done
    }
    fn solve(&mut self, r: &mut [f64]) -> Result<()> {
        // the row combination of `GenAlpha::factor` on the right side
        let ga = &*self.ga;
        let w = ga.am / (ga.af * ga.gamma * ga.dt);
        for cr in &ga.dae.chain_rule {
            r[cr.node] += w * cr.capacitance * r[cr.flow];
        }
        if self.ga.lu.solve_in_place(r) {
            Ok(())
        } else {
            Err(singular(self.t_af, "non-finite solution"))
        }
    }
    fn update(&mut self, dx: &mut [f64]) {
        let ga = &mut *self.ga;
        // svZeroDSolver's post-solve hook acts on the iterate before the correction is added
        for el in &ga.dae.elements {
            el.after_correction(&ga.y_af, &mut ga.y_new);
        }
        let gdt = ga.gamma * ga.dt;
        for ((ydn, yn), d) in ga.yd_new.iter_mut().zip(&mut ga.y_new).zip(dx.iter_mut()) {
            *ydn += *d;
            *yn += gdt * *d;
            *d *= gdt;
        }
    }
    fn state(&self) -> &[f64] {
        &self.ga.y_new
    }
    fn unknowns(&self) -> Option<&[usize]> {
        None
    }
    fn is_linear(&self) -> bool {
        false
    }
    fn backtracks(&self) -> bool {
        self.ga.damped
    }
}

impl GenAlpha<'_> {
    /// Linear circuits: the first Newton iterate is exact, so a step is one fused residual pass,
    /// one solve with the matrix factorised once, and one update pass. With svZeroDSolver's
    /// absolute tolerance the step is skipped when the predictor already satisfies it, exactly
    /// as svZeroDSolver does; its post-solve check always passes for a linear system.
    ///
    /// `from`: the step's start (y, ẏ), the end written into `y`, `yd`; None: in place (the
    /// same sums either way, so the same bits).
    fn step_linear(
        &mut self,
        time: f64,
        from: Option<(&[f64], &[f64])>,
        y: &mut [f64],
        yd: &mut [f64],
    ) -> Result<()> {
        let (af, gamma, dt) = (self.af, self.gamma, self.dt);
        let pred = (gamma - 1.0) / gamma;
        let t_af = time + af * dt;
        self.forcing.eval(self.dae, t_af, self.regime);
        let start = self.leaves.as_ref().map_or(self.r.len(), |l| l.start);
        let pool = crate::threads::pool().filter(|_| start >= PARALLEL_ROWS);
        // the residual at the predictor, from the step's start
        let rmax = {
            let (y0, yd0) = from.unwrap_or((&*y, &*yd));
            if !self.factored {
                self.factor(t_af, y0, &[])?;
            }
            self.linear_residual(y0, yd0, start, pool.as_ref())
        };
        if let Some(atol) = self.control.atol {
            if rmax < atol {
                if let Some((y0, yd0)) = from {
                    y.copy_from_slice(y0);
                    yd.copy_from_slice(yd0);
                }
                yd.iter_mut().for_each(|v| *v *= pred);
                return Ok(());
            }
        }
        if !self.lu.solve_in_place(&mut self.r[..start]) {
            return Err(singular(t_af, "non-finite solution"));
        }
        let gdt = gamma * dt;
        if let Some(leaves) = &self.leaves {
            if !leaves.back_substitute_and_update(&self.r[..start], from, y, yd, gdt, pred) {
                return Err(singular(t_af, "non-finite solution"));
            }
        }
        let (y, yd, r) = (&mut y[..start], &mut yd[..start], &self.r[..start]);
        let from = from.map(|(y0, yd0)| (&y0[..start], &yd0[..start]));
        match &pool {
            Some(pool) => pool.install(|| {
                let tasks = y
                    .par_chunks_mut(ROWS_PER_TASK)
                    .zip(yd.par_chunks_mut(ROWS_PER_TASK));
                tasks
                    .zip(r.par_chunks(ROWS_PER_TASK))
                    .enumerate()
                    .for_each(|(c, ((y, yd), r))| {
                        let from = from.map(|(y0, yd0)| {
                            let k = c * ROWS_PER_TASK..c * ROWS_PER_TASK + y.len();
                            (&y0[k.clone()], &yd0[k])
                        });
                        linear_update(y, yd, from, r, gdt, pred);
                    })
            }),
            None => linear_update(y, yd, from, r, gdt, pred),
        }
        Ok(())
    }

    /// The residual of a linear step at its predictor from the start (y, ẏ) into the rows
    /// `..start` of `r` (the condensed leaves folded into their parents' rows); the largest
    /// |r| where an absolute tolerance judges it.
    fn linear_residual(
        &mut self,
        y: &[f64],
        yd: &[f64],
        start: usize,
        pool: Option<&std::sync::Arc<rayon::ThreadPool>>,
    ) -> f64 {
        let (am, gamma) = (self.am, self.gamma);
        let pred = (gamma - 1.0) / gamma;
        // with y_new = y and ẏ_new = pred·ẏ: y_αf = y, ẏ_αm = ẏ (1 + αm (pred − 1))
        let c_am = 1.0 + am * (pred - 1.0);
        // F without the condensed cells' columns (`Leaves::reduced_f`), unless an absolute
        // tolerance judges the whole rows' residuals
        let with_max = self.control.atol.is_some();
        let f = match &self.leaves {
            Some(l) if !with_max => &l.reduced_f,
            _ => &self.dae.f,
        };
        let residual = LinearResidual {
            e: &self.e,
            forcing: &self.forcing,
            y,
            yd,
            c_am,
            f,
        };
        let head = &mut self.r[..start];
        // each row is independent, and the largest |r| is the same in any grouping: the same
        // bits on any number of threads
        let mut rmax = match pool {
            Some(pool) => pool.install(|| {
                head.par_chunks_mut(ROWS_PER_TASK)
                    .enumerate()
                    .map(|(c, r)| residual.rows(c * ROWS_PER_TASK, r))
                    .reduce(|| 0.0, f64::max)
            }),
            None => residual.rows(0, head),
        };
        if let Some(leaves) = &self.leaves {
            rmax = rmax.max(leaves.residual_and_fold(y, yd, &mut self.r[..start], with_max));
        }
        rmax
    }
}

/// A linear step's update of the rows of `y`, `yd` from the solve's `r`: y + γΔt r and
/// pred·ẏ + r, of the start `from` (None: of `y`, `yd` themselves).
fn linear_update(
    y: &mut [f64],
    yd: &mut [f64],
    from: Option<(&[f64], &[f64])>,
    r: &[f64],
    gdt: f64,
    pred: f64,
) {
    match from {
        None => {
            for ((yi, ydi), ri) in y.iter_mut().zip(yd.iter_mut()).zip(r) {
                *yi += gdt * ri;
                *ydi = pred * *ydi + ri;
            }
        }
        Some((y0, yd0)) => {
            let start = y0.iter().zip(yd0);
            for (((yi, ydi), ri), (&y0, &yd0)) in y.iter_mut().zip(yd.iter_mut()).zip(r).zip(start)
            {
                *yi = y0 + gdt * ri;
                *ydi = pred * yd0 + ri;
            }
        }
    }
}

/// The least number of unknowns for which a linear step's residual and update are split over
/// the run's threads.
const PARALLEL_ROWS: usize = 1 << 15;

/// Rows per task of a linear step's residual and update on the run's threads. Small against
/// a pass (~20 µs of work): a pass ends when its last task does, and with tasks of 32 768 rows
/// (~0.15 ms) the thread that finished first waited up to one of them at the end of each
/// pass. Each row is independent, so the task size does not change a value.
const ROWS_PER_TASK: usize = 1 << 12;

/// The residual of a linear step at its predictor (see `step_linear`).
struct LinearResidual<'r> {
    e: &'r [f64],
    forcing: &'r SparseForcing,
    y: &'r [f64],
    yd: &'r [f64],
    c_am: f64,
    /// F's rows (`Dae::f`, or without the condensed cells' columns)
    f: &'r Csr,
}

impl LinearResidual<'_> {
    /// The rows `first..first + r.len()` into `r`; the largest |r|.
    fn rows(&self, first: usize, r: &mut [f64]) -> f64 {
        let (f, y, yd) = (self.f, self.y, self.yd);
        let (rows, values) = (&self.forcing.rows, &self.forcing.values);
        let mut next = rows.partition_point(|&row| (row as usize) < first);
        let mut next_row = rows.get(next).map_or(usize::MAX, |&r| r as usize);
        let mut rmax = 0.0f64;
        for (i, r) in (first..).zip(r.iter_mut()) {
            // f_i as `Dae::forcing_into` gives it (0 on a row without forcing)
            let fi = if i == next_row {
                next += 1;
                next_row = rows.get(next).map_or(usize::MAX, |&r| r as usize);
                values[next - 1]
            } else {
                0.0
            };
            let mut v = fi - self.e[i] * yd[i] * self.c_am;
            for k in f.row(i) {
                v -= f.val[k] * y[f.col[k] as usize];
            }
            rmax = rmax.max(v.abs());
            *r = v;
        }
        rmax
    }
}

/// The forcing rows of a circuit, each with its waveforms, and their values at one time: the
/// sparse form of `Dae::forcing_into`, summed in the same order (from 0.0, in the order of
/// `Dae::forcing`), so the same bits. A tree's outlets hold constant distal pressures (one row
/// each, thousands of them): their values are summed once, and a step evaluates the rows with
/// a waveform that changes in time only (a serial pass over every outlet per step was one of
/// the run's larger parts outside its parallel loops).
struct SparseForcing {
    /// Rows with forcing, increasing.
    rows: Vec<u32>,
    /// Row k sums the waveforms `Dae::forcing[entries[ptr[k]..ptr[k + 1]]]`.
    ptr: Vec<usize>,
    entries: Vec<usize>,
    /// The rows (indices into `rows`) with a waveform that is not constant.
    varying: Vec<u32>,
    /// The values at the last `eval`, by row.
    values: Vec<f64>,
}

impl SparseForcing {
    fn new(dae: &Dae) -> Self {
        let mut entries: Vec<usize> = (0..dae.forcing.len()).collect();
        // stable: a row's waveforms stay in their order
        entries.sort_by_key(|&k| dae.forcing[k].0);
        let (mut rows, mut ptr) = (Vec::new(), vec![0]);
        for (j, &k) in entries.iter().enumerate() {
            let row = dae.forcing[k].0 as u32;
            if rows.last() != Some(&row) {
                if j > 0 {
                    ptr.push(j);
                }
                rows.push(row);
            }
        }
        ptr.push(entries.len());
        let varying = (0..rows.len())
            .filter(|&k| {
                entries[ptr[k]..ptr[k + 1]]
                    .iter()
                    .any(|&e| !matches!(dae.forcing[e].1, Waveform::Constant(_)))
            })
            .map(|k| k as u32)
            .collect();
        let mut forcing = SparseForcing {
            values: vec![0.0; rows.len()],
            rows,
            ptr,
            entries,
            varying,
        };
        // a constant's value and mean are the same number: the constant rows hold it for
        // either regime from here on
        for k in 0..forcing.rows.len() {
            forcing.values[k] = forcing.row_value(dae, k, 0.0, Regime::Transient);
        }
        forcing
    }

    /// Row k's value at `t`: its waveforms summed from 0.0 in order.
    #[inline]
    fn row_value(&self, dae: &Dae, k: usize, t: f64, regime: Regime) -> f64 {
        let mut value = 0.0;
        for &e in &self.entries[self.ptr[k]..self.ptr[k + 1]] {
            let w = &dae.forcing[e].1;
            value += if regime == Regime::Transient {
                w.eval(t)
            } else {
                w.mean()
            };
        }
        value
    }

    fn eval(&mut self, dae: &Dae, t: f64, regime: Regime) {
        for &k in &self.varying {
            let k = k as usize;
            self.values[k] = self.row_value(dae, k, t, regime);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::parse;

    /// Outlets at constant pressures (evaluated once) beside an inlet and an outlet that
    /// change in time (evaluated every step).
    const MODEL: &str = r#"{
        "vessels": [
            {"name": "a", "from": "in", "to": "j", "segments": 3,
             "geometry": {"length": 0.1, "radius_in": 0.005, "radius_out": 0.004,
                          "wall_thickness": 0.0005, "youngs_modulus": 4e5}},
            {"name": "b", "from": "j", "to": "out", "segments": 2,
             "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002,
                          "wall_thickness": 0.0003, "youngs_modulus": 4e5}},
            {"name": "c", "from": "j", "to": "k", "segments": 2,
             "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002,
                          "wall_thickness": 0.0003, "youngs_modulus": 4e5}},
            {"name": "d", "from": "k", "to": "out2", "segments": 1,
             "geometry": {"length": 0.02, "radius_in": 0.001, "radius_out": 0.001,
                          "wall_thickness": 0.0002, "youngs_modulus": 4e5}},
            {"name": "e", "from": "k", "to": "out3", "segments": 1,
             "geometry": {"length": 0.02, "radius_in": 0.001, "radius_out": 0.001,
                          "wall_thickness": 0.0002, "youngs_modulus": 4e5}}],
        "boundary_conditions": {
            "in": {"type": "flow", "flow": {"kind": "fourier", "period": 0.8, "mean": 1e-6,
                                            "cos": [3e-7], "sin": [2e-7]}},
            "out": {"type": "pressure", "pressure": {"kind": "constant", "value": 1200.0}},
            "out2": {"type": "pressure", "pressure": {"kind": "constant", "value": -35.5}},
            "out3": {"type": "pressure", "pressure": {"kind": "table", "time": [0.0, 0.4, 0.8],
                                                     "value": [900.0, 1500.0, 900.0]}}}
    }"#;

    #[test]
    fn the_linear_steps_forcing_is_the_circuits_at_every_time_and_regime() {
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let mut sparse = SparseForcing::new(&dae);
        // the model has rows evaluated once and rows evaluated at every step
        assert!(!sparse.varying.is_empty() && sparse.varying.len() < sparse.rows.len());
        let mut dense = vec![f64::NAN; dae.n];
        for (k, &t) in [0.0, 0.13, 0.4, 0.71, 1.9].iter().enumerate() {
            let regime = if k == 2 {
                Regime::Steady
            } else {
                Regime::Transient
            };
            sparse.eval(&dae, t, regime);
            dae.forcing_into(t, regime, &mut dense);
            let mut from_sparse = vec![0.0; dae.n];
            for (&row, &v) in sparse.rows.iter().zip(&sparse.values) {
                from_sparse[row as usize] = v;
            }
            // the same waveforms summed from 0.0 in the same order as the circuit's forcing
            // vector: the same numbers (the fixed step's results depend on it bit for bit)
            for i in 0..dae.n {
                assert_eq!(
                    from_sparse[i].to_bits(),
                    dense[i].to_bits(),
                    "t {t} row {i}"
                );
            }
        }
    }
}
