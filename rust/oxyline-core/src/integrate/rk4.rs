//! Classical fixed-step RK4 on the differential unknowns (E_ii > 0); the algebraic unknowns
//! (capacitance-free nodes, inductance-free branches, prescribed pressures) are eliminated at
//! every stage by a sparse solve whose matrix is factorised once for linear circuits.

use super::newton::{self, Magnitude, NewtonControl, NewtonProblem, singular};
use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;

/// A state integrated together with the flow in the same RK4 step (species amounts): its
/// derivative is evaluated at every stage from that stage's consistent flow state, so the
/// coupled system is advanced as one ODE (physics spec §2.5, "monolithic").
pub trait Coupled {
    fn derivative(&mut self, time: f64, y: &[f64], z: &[f64], dz: &mut [f64]) -> Result<()>;
}

/// Flow only.
pub struct Uncoupled;
impl Coupled for Uncoupled {
    #[inline]
    fn derivative(&mut self, _: f64, _: &[f64], _: &[f64], _: &mut [f64]) -> Result<()> {
        Ok(())
    }
}

/// Stage storage of an RK4 step: the four stage derivatives and the stage state.
#[derive(Debug, Clone, Default)]
pub struct CoupledStages {
    k: [Vec<f64>; 4],
    stage: Vec<f64>,
}

impl CoupledStages {
    pub fn new(n: usize) -> Self {
        CoupledStages {
            k: [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            stage: vec![0.0; n],
        }
    }
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
    let increment = |i: usize| dt / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i]);
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

/// The index reduction of a circuit for explicit integration, as an overlay over the borrowed
/// DAE: the mass diagonal with the reduced inductors' E_jj zeroed, and the forcing-slope terms
/// added to their rows. The DAE itself is not copied.
struct Reduction {
    /// E of the circuit in the run's regime, zero on reduced rows.
    e: Vec<f64>,
    /// (row, scale, forcing entry k): f_row(t) += scale · w_k′(t).
    rate: Vec<(usize, f64, usize)>,
}

/// Index reduction for explicit integration. A linear algebraic row whose unknowns are all
/// fixed by the forcing except one fixes that one too: y_j = (Σ f_r − Σ a_rk y_k)/a_rj. Known
/// values propagate row by row (a worklist, linear in the circuit size). When such a row fixes
/// an inductor flow — the KCL of a capacitance-free node between a flow condition and an
/// inductor, e.g. the inlet of an L-arrangement line (physics §1.2: "first branch flow is
/// prescribed"), or every branch of a rigid tube fed by a flow — then ẏ_j is the same
/// combination of the forcing slopes, and the inductor's row E_jj ẏ_j + F_j y = f_j becomes
/// the algebraic F_j y = f_j − E_jj ẏ_j(t), which determines the node pressures
/// (P_0 = P_1 + R Q_in + L dQ_in/dt). Circuits with no such inductor get no rate terms.
fn reduce_prescribed_inductors(dae: &Dae, regime: Regime) -> Reduction {
    let n = dae.n;
    let mut e = dae.mass(regime);
    let mut nonlinear = vec![false; n];
    for &(i, _) in &dae.stenosis {
        nonlinear[i] = true;
    }
    let mut row_forcing: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (k, (row, _)) in dae.forcing.iter().enumerate() {
        row_forcing[*row].push(k);
    }
    let entries = |r: usize| {
        (dae.f.ptr[r]..dae.f.ptr[r + 1])
            .map(|k| (dae.f.col[k], dae.f.val[k]))
            .filter(|&(_, v)| v != 0.0)
    };
    let mut col_rows: Vec<Vec<usize>> = vec![Vec::new(); n];
    for r in 0..n {
        for (c, _) in entries(r) {
            col_rows[c].push(r);
        }
    }
    // known[j]: y_j as Σ coefficient · (forcing entry k)
    let mut known: Vec<Option<Vec<(usize, f64)>>> = vec![None; n];
    let mut used = vec![false; n];
    let mut rate = Vec::new();
    let mut work: Vec<usize> = (0..n).rev().collect();
    while let Some(r) = work.pop() {
        if used[r] || e[r] > 0.0 || nonlinear[r] {
            continue;
        }
        let mut free = entries(r).filter(|&(c, _)| known[c].is_none());
        let (Some((j, a)), None) = (free.next(), free.next()) else {
            continue;
        };
        let mut expr: Vec<(usize, f64)> = row_forcing[r].iter().map(|&k| (k, 1.0 / a)).collect();
        for (c, v) in entries(r).filter(|&(c, _)| c != j) {
            for &(k, s) in known[c].as_deref().unwrap_or_default() {
                match expr.iter_mut().find(|(kk, _)| *kk == k) {
                    Some(term) => term.1 -= v * s / a,
                    None => expr.push((k, -v * s / a)),
                }
            }
        }
        used[r] = true;
        if e[j] > 0.0 {
            rate.extend(expr.iter().map(|&(k, s)| (j, -e[j] * s, k)));
            e[j] = 0.0;
            work.push(j); // the inductor's row is now algebraic
        }
        known[j] = Some(expr);
        work.extend(col_rows[j].iter().copied());
    }
    Reduction { e, rate }
}

/// The algebraic rows of the circuit and their elimination: a sparse LU of F restricted to the
/// algebraic rows and columns (plus the stenosis slopes 2S|Q| on their diagonal).
struct Algebraic {
    /// Global unknown of each algebraic row/column.
    rows: Vec<usize>,
    /// For each stamp, the index of its value in `F` (the stenosis diagonals follow).
    stamps_src: Vec<usize>,
    lu: SparseLu,
    vals: Vec<f64>,
    /// (local row, global unknown, S) of stenoses on algebraic unknowns.
    stenosis: Vec<(usize, usize, f64)>,
    /// Residual and correction of the algebraic rows.
    r: Vec<f64>,
    /// Running scale of the Newton increments (see `Magnitude`).
    magnitude: Magnitude,
}

impl Algebraic {
    /// None for a circuit without algebraic unknowns.
    fn analyse(dae: &Dae, e: &[f64]) -> Result<Option<Self>> {
        let n = dae.n;
        let rows: Vec<usize> = (0..n).filter(|&i| e[i] <= 0.0).collect();
        if rows.is_empty() {
            return Ok(None);
        }
        let mut local = vec![usize::MAX; n];
        for (l, &g) in rows.iter().enumerate() {
            local[g] = l;
        }
        let mut stamps = Vec::new();
        let mut stamps_src = Vec::new();
        for (l, &g) in rows.iter().enumerate() {
            for k in dae.f.ptr[g]..dae.f.ptr[g + 1] {
                let c = dae.f.col[k];
                if local[c] != usize::MAX {
                    stamps.push((l, local[c]));
                    stamps_src.push(k);
                }
            }
        }
        let stenosis: Vec<(usize, usize, f64)> = dae
            .stenosis
            .iter()
            .filter(|(g, _)| local[*g] != usize::MAX)
            .map(|&(g, s)| (local[g], g, s))
            .collect();
        stamps.extend(stenosis.iter().map(|&(l, _, _)| (l, l)));
        Ok(Some(Algebraic {
            lu: SparseLu::analyse(rows.len(), &stamps)?,
            vals: vec![0.0; stamps.len()],
            r: vec![0.0; rows.len()],
            magnitude: Magnitude::new(dae),
            rows,
            stamps_src,
            stenosis,
        }))
    }

    fn is_linear(&self) -> bool {
        self.stenosis.is_empty()
    }

    /// Factorise at state `y` (the stenosis slopes depend on it).
    fn factor(&mut self, dae: &Dae, y: &[f64]) -> std::result::Result<(), String> {
        let nf = self.stamps_src.len();
        for (v, &k) in self.vals[..nf].iter_mut().zip(&self.stamps_src) {
            *v = dae.f.val[k];
        }
        for (j, &(_, g, s)) in self.stenosis.iter().enumerate() {
            self.vals[nf + j] = 2.0 * s * y[g].abs();
        }
        self.lu.factor(&self.vals)
    }

    /// Factorise at y = 0 and probe one solve: a singular algebraic part means an index-2 DAE.
    fn check_index1(&mut self, dae: &Dae) -> Result<()> {
        let ok = self.factor(dae, &vec![0.0; dae.n]).is_ok() && {
            let mut probe: Vec<f64> = (0..self.rows.len()).map(|i| 1.0 + (i % 7) as f64).collect();
            self.lu.solve_in_place(&mut probe)
        };
        if ok {
            return Ok(());
        }
        Err(Error::model(
            "circuit",
            "rk4 cannot integrate this circuit: its algebraic part is singular (an inductor whose flow is fixed by a flow condition or by other inductors through a capacitance-free node, i.e. an index-2 DAE); use method 'generalized-alpha'",
        ))
    }
}

/// The Newton problem of the algebraic rows at fixed differential unknowns: unknowns y_alg,
/// residual f − F y − c(y) on the algebraic rows.
struct Elimination<'s> {
    dae: &'s Dae,
    alg: &'s mut Algebraic,
    f: &'s [f64],
    y: &'s mut [f64],
    time: f64,
}

impl NewtonProblem for Elimination<'_> {
    fn residual(&mut self, r: &mut [f64]) {
        for (rl, &g) in r.iter_mut().zip(&self.alg.rows) {
            *rl = self.f[g] - self.dae.f.row_dot(g, self.y);
        }
        for &(l, g, s) in &self.alg.stenosis {
            r[l] -= s * self.y[g].abs() * self.y[g];
        }
    }
    fn factor(&mut self, _: usize) -> Result<()> {
        // a linear algebraic part was factorised once, in `Rk4::new`
        if self.alg.is_linear() {
            return Ok(());
        }
        self.alg
            .factor(self.dae, self.y)
            .map_err(|m| singular(self.time, &m))
    }
    fn solve(&mut self, r: &mut [f64]) -> Result<()> {
        if self.alg.lu.solve_in_place(r) {
            Ok(())
        } else {
            Err(singular(self.time, "algebraic elimination"))
        }
    }
    fn update(&mut self, dx: &mut [f64]) {
        for (&g, d) in self.alg.rows.iter().zip(dx.iter()) {
            self.y[g] += d;
        }
    }
    fn state(&self) -> &[f64] {
        self.y
    }
    fn unknowns(&self) -> Option<&[usize]> {
        Some(&self.alg.rows)
    }
    fn is_linear(&self) -> bool {
        self.alg.is_linear()
    }
}

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
}

impl<'a> Rk4<'a> {
    /// The integrator of `dae` in `regime` with step `dt`. A circuit whose algebraic part stays
    /// singular after the index reduction (index 2) is a model error.
    pub fn new(dae: &'a Dae, regime: Regime, dt: f64) -> Result<Self> {
        let Reduction { e, rate } = reduce_prescribed_inductors(dae, regime);
        let n = dae.n;
        let mut alg = Algebraic::analyse(dae, &e)?;
        if let Some(a) = alg.as_mut() {
            a.check_index1(dae)?;
        }
        Ok(Rk4 {
            dae,
            regime,
            dt,
            diff: (0..n).filter(|&i| e[i] > 0.0).collect(),
            e,
            rate,
            alg,
            f: vec![0.0; n],
            st: CoupledStages::new(n),
            lin_stenosis: Vec::new(),
        })
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
            if self.e[i] > 0.0 {
                k[i] -= s * y[i].abs() * y[i] / self.e[i];
            }
        }
        Ok(())
    }

    /// Time derivative of the differential unknowns at (t, y) (zero for algebraic ones);
    /// the algebraic unknowns of `y` are made consistent first.
    pub fn derivative(&mut self, time: f64, y: &mut [f64]) -> Result<Vec<f64>> {
        self.rhs(time, y, 0)?;
        let mut out = vec![0.0; self.dae.n];
        for &i in &self.diff {
            out[i] = self.st.k[0][i];
        }
        Ok(out)
    }

    /// Bring the algebraic unknowns of an initial state in line with the forcing at `time`.
    pub fn make_consistent(&mut self, time: f64, y: &mut [f64]) -> Result<()> {
        self.forcing(time);
        self.solve_algebraic(y, time)
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
        let mut stage = std::mem::take(&mut self.st.stage);
        stage.copy_from_slice(y);
        self.rhs(time, &mut stage, 0)?;
        if coupled_on {
            zk.stage.copy_from_slice(z);
            coupled.derivative(time, &stage, &zk.stage, &mut zk.k[0])?;
        }
        for (s, c) in RK4_STAGE.into_iter().enumerate() {
            rk4_stage(&mut stage, y, &self.st.k[s], c * dt, Rows::Only(&self.diff));
            let ts = time + c * dt;
            self.rhs(ts, &mut stage, s + 1)?;
            if coupled_on {
                rk4_stage(&mut zk.stage, z, &zk.k[s], c * dt, Rows::All);
                coupled.derivative(ts, &stage, &zk.stage, &mut zk.k[s + 1])?;
            }
        }
        rk4_combine(y, &self.st.k, dt, Rows::Only(&self.diff));
        if coupled_on {
            rk4_combine(z, &zk.k, dt, Rows::All);
        }
        // algebraic unknowns of the last stage are the best warm start
        if let Some(alg) = &self.alg {
            for &g in &alg.rows {
                y[g] = stage[g];
            }
        }
        self.st.stage = stage;
        self.forcing(time + dt);
        self.solve_algebraic(y, time + dt)
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
            .filter(|(i, _)| self.e[*i] > 0.0)
            .map(|&(i, s)| (i, 2.0 * s * y[i].abs()))
            .collect();
        if let Some(alg) = self.alg.as_mut().filter(|a| !a.is_linear()) {
            alg.factor(self.dae, y).map_err(|m| singular(0.0, &m))?;
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
        if let Some(alg) = self.alg.as_mut() {
            for (rl, &g) in alg.r.iter_mut().zip(&alg.rows) {
                *rl = -self.dae.f.row_dot(g, &y);
            }
            alg.lu.solve_in_place(&mut alg.r);
            for (rl, &g) in alg.r.iter().zip(&alg.rows) {
                y[g] = *rl;
            }
        }
        for (j, &i) in self.diff.iter().enumerate() {
            out[j] = -self.dae.f.row_dot(i, &y) / self.e[i];
        }
        if !self.lin_stenosis.is_empty() {
            for (j, &i) in self.diff.iter().enumerate() {
                if let Ok(k) = self.lin_stenosis.binary_search_by_key(&i, |&(u, _)| u) {
                    out[j] -= self.lin_stenosis[k].1 * y[i] / self.e[i];
                }
            }
        }
        Ok(())
    }
}
