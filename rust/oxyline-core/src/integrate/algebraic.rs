//! The algebraic rows of the circuit for explicit integration: the index reduction of
//! inductors whose flow a flow condition fixes (an overlay over the borrowed DAE, which is never
//! copied), and the elimination of the algebraic unknowns at fixed differential ones (one sparse
//! LU, the shared Newton solver when stenoses make the rows nonlinear).

use super::newton::{Magnitude, NewtonProblem, singular};
use crate::circuit::{Dae, JacobianKind, Regime};
use crate::error::{Error, Result};
use crate::sparse::SparseLu;

/// The index reduction of a circuit for explicit integration, as an overlay over the borrowed
/// DAE: the mass diagonal with the reduced inductors' E_jj zeroed, and the forcing-slope terms
/// added to their rows. The DAE itself is not copied.
pub(super) struct Reduction {
    /// E of the circuit in the run's regime, zero on reduced rows.
    pub(super) e: Vec<f64>,
    /// (row, scale, forcing entry k): f_row(t) += scale · w_k′(t).
    pub(super) rate: Vec<(usize, f64, usize)>,
}

/// Index reduction for explicit integration. A linear algebraic row whose unknowns are all
/// fixed by the forcing except one fixes that one too: y_j = (Σ f_r − Σ a_rk y_k)/a_rj. Known
/// values propagate row by row (a worklist, linear in the circuit size). When such a row fixes
/// an inductor flow — the KCL of a capacitance-free node between a flow condition and an
/// inductor, e.g. the inlet of an L-arrangement line (docs/physics.md §1.2: "first branch flow is
/// prescribed"), or every branch of a rigid tube fed by a flow — then ẏ_j is the same
/// combination of the forcing slopes, and the inductor's row E_jj ẏ_j + F_j y = f_j becomes
/// the algebraic F_j y = f_j − E_jj ẏ_j(t), which determines the node pressures
/// (P_0 = P_1 + R Q_in + L dQ_in/dt). Circuits with no such inductor get no rate terms.
pub(super) fn reduce_prescribed_inductors(dae: &Dae, regime: Regime) -> Reduction {
    let n = dae.n;
    let mut e = dae.mass(regime);
    let mut nonlinear = vec![false; n];
    // rows with a stenosis or a time-varying coefficient do not fix a constant combination
    for i in dae
        .stenosis
        .iter()
        .map(|s| s.0)
        .chain(dae.varying.iter().map(|v| v.0))
        .chain(dae.elements.iter().flat_map(|e| e.rows().to_vec()))
    {
        nonlinear[i] = true;
    }
    // (the work lists are flat and 32-bit: a list per unknown, as this reduction held them,
    // was ~290 B per segment on top of a large run's setup, its peak; see `ColumnRows`)
    let row_forcing = RowForcing::new(dae);
    let entries = |r: usize| {
        dae.f
            .row(r)
            .map(|k| (dae.f.col[k] as usize, dae.f.val[k]))
            .filter(|&(_, v)| v != 0.0)
    };
    let col_rows = ColumnRows::new(n, entries);
    // known[j]: y_j as Σ coefficient · (forcing entry k), the expression `exprs[known[j]]`
    // (NONE: not known; few unknowns are)
    let mut known: Vec<u32> = vec![NONE; n];
    let mut exprs: Vec<Vec<(usize, f64)>> = Vec::new();
    let mut used = vec![false; n];
    let mut rate = Vec::new();
    let mut work: Vec<u32> = (0..n as u32).rev().collect();
    while let Some(r) = work.pop() {
        let r = r as usize;
        if used[r] || e[r] != 0.0 || nonlinear[r] {
            continue;
        }
        let mut free = entries(r).filter(|&(c, _)| known[c] == NONE);
        let (Some((j, a)), None) = (free.next(), free.next()) else {
            continue;
        };
        let mut expr: Vec<(usize, f64)> = row_forcing.of(r).map(|k| (k, 1.0 / a)).collect();
        for (c, v) in entries(r).filter(|&(c, _)| c != j) {
            let known_c: &[(usize, f64)] = match known[c] {
                NONE => &[],
                x => &exprs[x as usize],
            };
            for &(k, s) in known_c {
                match expr.iter_mut().find(|(kk, _)| *kk == k) {
                    Some(term) => term.1 -= v * s / a,
                    None => expr.push((k, -v * s / a)),
                }
            }
        }
        used[r] = true;
        if e[j] != 0.0 {
            rate.extend(expr.iter().map(|&(k, s)| (j, -e[j] * s, k)));
            e[j] = 0.0;
            work.push(j as u32); // the inductor's row is now algebraic
        }
        known[j] = u32::try_from(exprs.len()).expect("fewer known unknowns than unknowns");
        exprs.push(expr);
        work.extend_from_slice(col_rows.rows(j));
    }
    Reduction { e, rate }
}

/// "None" in the reduction's 32-bit index lists.
const NONE: u32 = u32::MAX;

/// The forcing entries of each row, in entry order: (row, entry) sorted by row (a circuit has
/// few forcing entries; a list per unknown was 24 B per unknown for them).
struct RowForcing(Vec<(usize, usize)>);

impl RowForcing {
    fn new(dae: &Dae) -> Self {
        let mut v: Vec<(usize, usize)> = (dae.forcing.iter().enumerate())
            .map(|(k, (row, _))| (*row, k))
            .collect();
        // stable: a row's entries keep their order
        v.sort_by_key(|&(row, _)| row);
        RowForcing(v)
    }

    /// The forcing entries of row `r`, in entry order.
    fn of(&self, r: usize) -> impl Iterator<Item = usize> + '_ {
        let start = self.0.partition_point(|&(row, _)| row < r);
        self.0[start..]
            .iter()
            .take_while(move |&&(row, _)| row == r)
            .map(|&(_, k)| k)
    }
}

/// Per column of F, the rows with an entry in it, in row order (a row once per entry), as
/// compressed 32-bit lists (F's entries number below 2^32: its row starts are 32-bit).
struct ColumnRows {
    ptr: Vec<u32>,
    rows: Vec<u32>,
}

impl ColumnRows {
    fn new<I: Iterator<Item = (usize, f64)>>(n: usize, entries: impl Fn(usize) -> I) -> Self {
        let mut ptr = vec![0u32; n + 1];
        for r in 0..n {
            for (c, _) in entries(r) {
                ptr[c + 1] += 1;
            }
        }
        for c in 0..n {
            ptr[c + 1] += ptr[c];
        }
        let mut fill = ptr.clone();
        let mut rows = vec![0u32; ptr[n] as usize];
        for r in 0..n {
            for (c, _) in entries(r) {
                rows[fill[c] as usize] = r as u32;
                fill[c] += 1;
            }
        }
        ColumnRows { ptr, rows }
    }

    /// The rows with an entry in column `c`.
    fn rows(&self, c: usize) -> &[u32] {
        &self.rows[self.ptr[c] as usize..self.ptr[c + 1] as usize]
    }
}

/// The algebraic rows of the circuit and their elimination: a sparse LU of F restricted to the
/// algebraic rows and columns (plus the stenosis slopes 2S|Q| and the time-varying resistances
/// D(t) on their diagonal).
pub(super) struct Algebraic {
    /// Global unknown of each algebraic row/column.
    pub(super) rows: Vec<usize>,
    /// For each stamp, the index of its value in `F` (the stenosis diagonals follow).
    stamps_src: Vec<usize>,
    pub(super) lu: SparseLu,
    vals: Vec<f64>,
    /// (local row, global unknown, S) of stenoses on algebraic unknowns.
    stenosis: Vec<(usize, usize, f64)>,
    /// (local row, index into `Dae::varying`) of time-varying coefficients on algebraic rows.
    varying: Vec<(usize, usize)>,
    /// (stamp value index, index into `Dae::element_pattern`) of element Jacobian entries
    /// whose row and column are both algebraic.
    elements: Vec<(usize, usize)>,
    /// Element terms on algebraic rows are nonlinear / time-varying in the matrix.
    element_nonlinear: bool,
    element_varying: bool,
    /// Time of the last factorisation of a time-varying, stenosis-free part (its matrix then
    /// depends on the time only).
    factored_at: Option<f64>,
    /// Residual and correction of the algebraic rows.
    pub(super) r: Vec<f64>,
    /// Running scale of the Newton increments (see `Magnitude`).
    pub(super) magnitude: Magnitude,
}

impl Algebraic {
    /// None for a circuit without algebraic unknowns.
    pub(super) fn analyse(dae: &Dae, e: &[f64], regime: Regime) -> Result<Option<Self>> {
        let n = dae.n;
        let rows: Vec<usize> = (0..n).filter(|&i| e[i] == 0.0).collect();
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
            for k in dae.f.row(g) {
                let c = dae.f.col[k] as usize;
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
        let transient = regime == Regime::Transient;
        let varying: Vec<(usize, usize)> = if transient {
            (dae.varying.iter().enumerate())
                .filter(|(_, (g, _))| local[*g] != usize::MAX)
                .map(|(k, (g, _))| (local[*g], k))
                .collect()
        } else {
            Vec::new()
        };
        stamps.extend(varying.iter().map(|&(l, _)| (l, l)));
        let (mut elements, mut element_nonlinear, mut element_varying) = (Vec::new(), false, false);
        let mut k = 0;
        for el in &dae.elements {
            for &(r, c) in el.pattern() {
                if local[r] != usize::MAX && local[c] != usize::MAX {
                    elements.push((stamps.len(), k));
                    stamps.push((local[r], local[c]));
                    element_nonlinear |= el.is_nonlinear();
                    element_varying |= el.period().is_some();
                }
                k += 1;
            }
        }
        Ok(Some(Algebraic {
            elements,
            element_nonlinear,
            element_varying,
            lu: SparseLu::analyse(rows.len(), &stamps)?,
            vals: vec![0.0; stamps.len()],
            r: vec![0.0; rows.len()],
            magnitude: Magnitude::new(dae),
            rows,
            stamps_src,
            stenosis,
            varying,
            factored_at: None,
        }))
    }

    /// No stenosis and no nonlinear element on the algebraic rows: they are linear in the
    /// state.
    pub(super) fn is_linear(&self) -> bool {
        self.stenosis.is_empty() && !self.element_nonlinear
    }

    /// Linear with a constant matrix: factorised once per run.
    pub(super) fn is_constant(&self) -> bool {
        self.is_linear() && self.varying.is_empty() && !self.element_varying
    }

    /// Factorise at state `y` (the stenosis slopes depend on it) and time `t` (the
    /// time-varying coefficients do); elements at their stiffest state with `stiffest` (RK4's
    /// stability operator).
    pub(super) fn factor(
        &mut self,
        dae: &Dae,
        y: &[f64],
        t: f64,
        kind: JacobianKind,
    ) -> std::result::Result<(), String> {
        let nf = self.stamps_src.len();
        for (v, &k) in self.vals[..nf].iter_mut().zip(&self.stamps_src) {
            *v = dae.f.val[k];
        }
        for (j, &(_, g, s)) in self.stenosis.iter().enumerate() {
            self.vals[nf + j] = 2.0 * s * y[g].abs();
        }
        let nv = nf + self.stenosis.len();
        for (j, &(_, k)) in self.varying.iter().enumerate() {
            self.vals[nv + j] = dae.varying[k].1.delta(t);
        }
        if !self.elements.is_empty() {
            let mut j = vec![0.0; dae.element_pattern().len()];
            dae.element_jacobian(1.0, t, y, &mut j, kind);
            for &(v, k) in &self.elements {
                self.vals[v] = j[k];
            }
        }
        self.factored_at = Some(t);
        self.lu.factor(&self.vals)
    }

    /// Factorise at y = 0 and probe one solve: a singular algebraic part means an index-2 DAE.
    pub(super) fn check_index1(&mut self, dae: &Dae) -> Result<()> {
        let ok = (self.factor(dae, &vec![0.0; dae.n], 0.0, JacobianKind::Stiffest)).is_ok() && {
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
pub(super) struct Elimination<'s> {
    pub(super) dae: &'s Dae,
    pub(super) alg: &'s mut Algebraic,
    pub(super) f: &'s [f64],
    pub(super) y: &'s mut [f64],
    pub(super) time: f64,
}

impl NewtonProblem for Elimination<'_> {
    fn residual(&mut self, r: &mut [f64]) {
        for (rl, &g) in r.iter_mut().zip(&self.alg.rows) {
            *rl = self.f[g] - self.dae.f.row_dot(g, self.y);
        }
        for &(l, g, s) in &self.alg.stenosis {
            r[l] -= s * self.y[g].abs() * self.y[g];
        }
        for &(l, k) in &self.alg.varying {
            let (g, law) = &self.dae.varying[k];
            r[l] -= law.delta(self.time) * self.y[*g];
        }
        if !self.dae.elements.is_empty() {
            let rows = &self.alg.rows;
            let mut terms = Vec::new();
            self.dae
                .element_terms(self.time, self.y, |i, c| terms.push((i, c)));
            for (i, c) in terms {
                if let Ok(l) = rows.binary_search(&i) {
                    r[l] -= c;
                }
            }
        }
    }
    fn factor(&mut self, _: usize) -> Result<()> {
        // a constant algebraic part was factorised once, in `Rk4::new`; a linear time-varying
        // one once per stage time
        if self.alg.is_constant()
            || (self.alg.is_linear() && self.alg.factored_at == Some(self.time))
        {
            return Ok(());
        }
        self.alg
            .factor(self.dae, self.y, self.time, JacobianKind::Elimination)
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
    /// Valve laws are steep (a tanh switch of width 1/k, an exponential flow law when
    /// R_min = 0): plain Newton oscillates across the switch or overshoots into the exponential
    /// branch, so corrections that increase the residual are halved (docs/physics.md §1.8).
    fn backtracks(&self) -> bool {
        self.alg.element_nonlinear
    }
}
