//! Classical fixed-step RK4 on the differential unknowns (E_ii > 0); the algebraic unknowns
//! (capacitance-free nodes, inductance-free branches, prescribed pressures) are eliminated at
//! every stage by a sparse solve whose matrix is factorised once for linear circuits.

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

/// Stage storage of the coupled state.
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

/// Stage times (fractions of dt) of classical RK4 stages 2–4.
const STAGE: [f64; 3] = [0.5, 0.5, 1.0];

/// The RK4 increment of entry `i` from the four stage slopes `k`.
#[inline]
fn rk4_increment(k: &[Vec<f64>; 4], i: usize, dt: f64) -> f64 {
    dt / 6.0 * (k[0][i] + 2.0 * k[1][i] + 2.0 * k[2][i] + k[3][i])
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
    for s in 0..3 {
        let (done, next) = st.k.split_at_mut(s + 1);
        for ((zs, z0), k) in st.stage.iter_mut().zip(z.iter()).zip(&done[s]) {
            *zs = z0 + STAGE[s] * dt * k;
        }
        f(time + STAGE[s] * dt, &st.stage, &mut next[0])?;
    }
    for (i, zi) in z.iter_mut().enumerate() {
        *zi += rk4_increment(&st.k, i, dt);
    }
    Ok(())
}

/// Index reduction for explicit integration. A linear algebraic row whose unknowns are all
/// fixed by the forcing except one fixes that one too: y_j = (Σ f_r − Σ a_rk y_k)/a_rj. Known
/// values propagate row by row (a worklist, linear in the circuit size). When such a row fixes
/// an inductor flow — the KCL of a capacitance-free node between a flow condition and an
/// inductor, e.g. the inlet of an L-arrangement line (physics §1.2: "first branch flow is
/// prescribed"), or every branch of a rigid tube fed by a flow — then ẏ_j is the same
/// combination of the forcing slopes, and the inductor's row E_jj ẏ_j + F_j y = f_j becomes
/// the algebraic F_j y = f_j − E_jj ẏ_j(t), which determines the node pressures
/// (P_0 = P_1 + R Q_in + L dQ_in/dt). Circuits with no such inductor are returned unchanged.
fn reduce_prescribed_inductors(dae: &Dae, regime: Regime) -> CircuitRef<'_> {
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
    let mut reduced: Option<Dae> = None;
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
            let out = reduced.get_or_insert_with(|| dae.clone());
            for &(k, s) in &expr {
                out.rate_forcing
                    .push((j, -e[j] * s, dae.forcing[k].1.clone()));
            }
            out.e[j] = 0.0;
            e[j] = 0.0;
            work.push(j); // the inductor's row is now algebraic
        }
        known[j] = Some(expr);
        work.extend(col_rows[j].iter().copied());
    }
    match reduced {
        Some(d) => CircuitRef::Reduced(Box::new(d)),
        None => CircuitRef::Given(dae),
    }
}

/// The circuit an `Rk4` integrates: the caller's, or its boxed index-reduced copy.
enum CircuitRef<'a> {
    Given(&'a Dae),
    Reduced(Box<Dae>),
}

impl std::ops::Deref for CircuitRef<'_> {
    type Target = Dae;
    fn deref(&self) -> &Dae {
        match self {
            CircuitRef::Given(d) => d,
            CircuitRef::Reduced(d) => d,
        }
    }
}

pub struct Rk4<'a> {
    /// The circuit, or its index-reduced copy (see `reduce_prescribed_inductors`).
    dae: CircuitRef<'a>,
    regime: Regime,
    pub dt: f64,
    e: Vec<f64>,
    pub diff: Vec<usize>,
    alg: Vec<usize>,
    /// For each algebraic row, its F entries that fall on algebraic columns: (value index, local col).
    alg_stamps_src: Vec<usize>,
    alg_lu: Option<SparseLu>,
    alg_vals: Vec<f64>,
    alg_stenosis: Vec<(usize, usize, f64)>, // (local row, global unknown, S)
    f: Vec<f64>,
    ra: Vec<f64>,
    k: [Vec<f64>; 4],
    stage: Vec<f64>,
    /// 2 S |Q| of stenoses on differential unknowns at the linearisation point of
    /// `linear_operator` (zero: the linear circuit).
    lin_stenosis: Vec<(usize, f64)>,
}

impl<'a> Rk4<'a> {
    pub fn new(dae: &'a Dae, regime: Regime, dt: f64) -> Result<Self> {
        let dae = reduce_prescribed_inductors(dae, regime);
        let e = dae.mass(regime);
        let n = dae.n;
        let diff: Vec<usize> = (0..n).filter(|&i| e[i] > 0.0).collect();
        let alg: Vec<usize> = (0..n).filter(|&i| e[i] <= 0.0).collect();
        let mut local = vec![usize::MAX; n];
        for (l, &g) in alg.iter().enumerate() {
            local[g] = l;
        }
        let mut stamps = Vec::new();
        let mut src = Vec::new();
        for (l, &g) in alg.iter().enumerate() {
            for k in dae.f.ptr[g]..dae.f.ptr[g + 1] {
                let c = dae.f.col[k];
                if local[c] != usize::MAX {
                    stamps.push((l, local[c]));
                    src.push(k);
                }
            }
        }
        let alg_stenosis: Vec<(usize, usize, f64)> = dae
            .stenosis
            .iter()
            .filter(|(g, _)| local[*g] != usize::MAX)
            .map(|&(g, s)| (local[g], g, s))
            .collect();
        for &(l, _, _) in &alg_stenosis {
            stamps.push((l, l));
        }
        let mut me = Rk4 {
            dae,
            regime,
            dt,
            e,
            diff,
            alg_stamps_src: src,
            alg_lu: None,
            alg_vals: vec![0.0; stamps.len()],
            alg_stenosis,
            f: vec![0.0; n],
            ra: vec![0.0; alg.len()],
            k: [vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            stage: vec![0.0; n],
            lin_stenosis: Vec::new(),
            alg,
        };
        if !me.alg.is_empty() {
            me.alg_lu = Some(SparseLu::analyse(me.alg.len(), &stamps)?);
            let y0 = vec![0.0; n];
            let ok = me.factor_algebraic(&y0).is_ok() && {
                let mut probe: Vec<f64> = (0..me.alg.len()).map(|i| 1.0 + (i % 7) as f64).collect();
                me.alg_lu.as_ref().unwrap().solve_in_place(&mut probe)
            };
            if !ok {
                return Err(Error::model(
                    "circuit",
                    "rk4 cannot integrate this circuit: its algebraic part is singular (an inductor whose flow is fixed by a flow condition or by other inductors through a capacitance-free node, i.e. an index-2 DAE); use method 'generalized-alpha'",
                ));
            }
        }
        Ok(me)
    }

    fn factor_algebraic(&mut self, y: &[f64]) -> std::result::Result<(), String> {
        let nf = self.alg_stamps_src.len();
        for (v, &k) in self.alg_vals[..nf].iter_mut().zip(&self.alg_stamps_src) {
            *v = self.dae.f.val[k];
        }
        for (j, &(_, g, s)) in self.alg_stenosis.iter().enumerate() {
            self.alg_vals[nf + j] = 2.0 * s * y[g].abs();
        }
        self.alg_lu.as_mut().unwrap().factor(&self.alg_vals)
    }

    /// Make the algebraic unknowns of `y` consistent with its differential ones at forcing `f`.
    fn solve_algebraic(&mut self, y: &mut [f64], time: f64) -> Result<()> {
        if self.alg.is_empty() {
            return Ok(());
        }
        let nonlinear = !self.alg_stenosis.is_empty();
        for it in 0..30 {
            let mut rmax = 0.0f64;
            for (l, &g) in self.alg.iter().enumerate() {
                self.ra[l] = self.f[g] - self.dae.f.row_dot(g, y);
            }
            for &(l, g, s) in &self.alg_stenosis {
                self.ra[l] -= s * y[g].abs() * y[g];
            }
            if nonlinear {
                self.factor_algebraic(y)
                    .map_err(|m| crate::genalpha::singular(time, &m))?;
            }
            if !self.alg_lu.as_ref().unwrap().solve_in_place(&mut self.ra) {
                return Err(crate::genalpha::singular(time, "algebraic elimination"));
            }
            // pressures and flows differ by many decades in SI: judge each kind on its own scale
            let nn = self.dae.n_nodes;
            let (mut pmax, mut qmax, mut dp, mut dq) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
            for (l, &g) in self.alg.iter().enumerate() {
                y[g] += self.ra[l];
                if g < nn {
                    dp = dp.max(self.ra[l].abs());
                    pmax = pmax.max(y[g].abs());
                } else {
                    dq = dq.max(self.ra[l].abs());
                    qmax = qmax.max(y[g].abs());
                }
            }
            rmax = rmax.max((dp / pmax.max(1e-300)).max(dq / qmax.max(1e-300)));
            if !nonlinear || rmax <= 1e-13 || it == 29 {
                break;
            }
        }
        Ok(())
    }

    /// ẏ of the differential unknowns at (t, y); algebraic unknowns of `y` are updated.
    fn rhs(&mut self, time: f64, y: &mut [f64], out: usize) -> Result<()> {
        self.dae.forcing_into(time, self.regime, &mut self.f);
        self.solve_algebraic(y, time)?;
        let k = &mut self.k[out];
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
            out[i] = self.k[0][i];
        }
        Ok(out)
    }

    /// Bring the algebraic unknowns of an initial state in line with the forcing at `time`.
    pub fn make_consistent(&mut self, time: f64, y: &mut [f64]) -> Result<()> {
        self.dae.forcing_into(time, self.regime, &mut self.f);
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
        let nz = z.len();
        let mut stage = std::mem::take(&mut self.stage);
        stage.copy_from_slice(y);
        self.rhs(time, &mut stage, 0)?;
        if nz > 0 {
            zk.stage.copy_from_slice(z);
            coupled.derivative(time, &stage, &zk.stage, &mut zk.k[0])?;
        }
        for s in 0..3 {
            for &i in &self.diff {
                stage[i] = y[i] + STAGE[s] * dt * self.k[s][i];
            }
            let ts = time + STAGE[s] * dt;
            self.rhs(ts, &mut stage, s + 1)?;
            if nz > 0 {
                let (done, next) = zk.k.split_at_mut(s + 1);
                for ((zs, z0), k) in zk.stage.iter_mut().zip(z.iter()).zip(&done[s]) {
                    *zs = z0 + STAGE[s] * dt * k;
                }
                coupled.derivative(ts, &stage, &zk.stage, &mut next[0])?;
            }
        }
        for &i in &self.diff {
            y[i] += rk4_increment(&self.k, i, dt);
        }
        for (i, zi) in z.iter_mut().enumerate() {
            *zi += rk4_increment(&zk.k, i, dt);
        }
        // algebraic unknowns of the last stage are the best warm start
        for &g in &self.alg {
            y[g] = stage[g];
        }
        self.stage = stage;
        self.dae.forcing_into(time + dt, self.regime, &mut self.f);
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
        if !self.alg_stenosis.is_empty() {
            self.factor_algebraic(y)
                .map_err(|m| crate::genalpha::singular(0.0, &m))?;
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
        self.f.iter_mut().for_each(|v| *v = 0.0);
        if !self.alg.is_empty() {
            for (l, &g) in self.alg.iter().enumerate() {
                self.ra[l] = -self.dae.f.row_dot(g, &y);
            }
            self.alg_lu.as_ref().unwrap().solve_in_place(&mut self.ra);
            for (l, &g) in self.alg.iter().enumerate() {
                y[g] = self.ra[l];
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
