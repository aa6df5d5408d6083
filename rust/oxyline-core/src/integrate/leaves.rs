//! Leaf unknowns condensed out of a linear generalized-α step.
//!
//! A Womersley friction cell (`crate::womersley`) is an unknown i whose row is
//! L di/dt + R i − R Q = 0 and whose only other appearance is the −R i of its branch's row: a
//! leaf hanging off the flow Q. The assembly puts the cells after every other unknown, so a
//! circuit's trailing unknowns of that shape (one row E_j ẏ_j − b_j y_j + b_j y_p, column j
//! used by row p alone with the same b_j, no forcing) can be eliminated per leaf in closed
//! form: the Schur complement of the iteration matrix M on them is M_pp − M_pj M_jp / M_jj on
//! the parent's diagonal, and after the reduced solve Δ_j = (r_j − M_jp Δ_p)/M_jj. The step
//! then runs its generic residual, elimination and update over the other unknowns only (with
//! their own copy of F, without the leaves' columns, so the residual pass streams exactly what
//! a circuit without leaves would), and two passes over the leaves: one folds their residuals
//! into their parents' before the solve, one updates them after it.
//!
//! The leaf passes are memory-bound, so a leaf keeps only what they read (struct of arrays):
//! its parent, b_j and g_j = b_j / M_jj, 20 bytes. With M_jj = α_m E_j − c b_j (c = α_f γ Δt,
//! the iteration matrix's weight of F) the scaled residual w_j = r_j / M_jj is
//! g_j (y_j − y_p) − h_j ẏ_j with h_j = c_am E_j / M_jj = (1 + c g_j) c_am / α_m (c_am: ẏ's
//! weight in the step's residual), the fold into the parent is M_pj w_j = c b_j w_j, and the
//! increment Δ_j = w_j − c g_j Δ_p. The second pass recomputes w_j from the state (which the
//! reduced solve does not touch) instead of storing it. The arithmetic is that of the tree
//! elimination of the same leaf (`crate::sparse::TreeLu`) rearranged: the result is the same
//! up to rounding.

use crate::circuit::{Csr, Dae};
use crate::sparse::{SparseLu, Stamp};

/// The trailing leaves of a DAE and the iteration matrix reduced to the other unknowns.
pub struct Leaves {
    /// First leaf unknown: unknowns `start..n` are leaves, `0..start` the reduced system.
    pub start: usize,
    /// F's rows `0..start` without the leaves' columns (the step's residual pass; the leaves'
    /// terms b_j y_j in their parents' rows are added by the fold).
    pub reduced_f: Csr,
    /// Per leaf: its parent.
    parent: Vec<u32>,
    /// Per leaf: b_j (F_jp = F_pj = −F_jj).
    b: Vec<f64>,
    /// Per leaf, after `factor`: g_j = b_j / M_jj.
    g: Vec<f64>,
    /// Per leaf: E_j, the regime's mass (read when the step's residual is judged by an
    /// absolute tolerance, and by `factor`'s check of the pivot).
    mass: Vec<f64>,
    /// Per leaf, after `factor`: the pivot M_jj (for the solves outside the step).
    pivot: Vec<f64>,
    /// The step's weights after `factor`: α_m, c = α_f γ Δt and c_am (ẏ's in the residual).
    am: f64,
    c: f64,
    c_am: f64,
    /// Per full stamp: its index among the reduced stamps, or `NONE` (a leaf's stamp).
    reduced_slot: Vec<u32>,
    /// The leaf stamps: (stamp index, leaf << 2 | kind), kind `JJ`, `JP` or `PJ`.
    leaf_stamps: Vec<(u32, u32)>,
    /// Per leaf: the reduced stamp of its parent's diagonal.
    parent_diag: Vec<u32>,
    n_reduced_stamps: usize,
    /// Scratch of the reduced values.
    vals: Vec<f64>,
    /// Scratch of the leaves' entries M_jj, M_jp, M_pj (kept: an error-controlled run
    /// refactorises at nearly every step).
    entries: Vec<[f64; 3]>,
}

const NONE: u32 = u32::MAX;
/// M_jj, M_jp, M_pj: where a leaf stamp goes.
const JJ: u32 = 0;
const JP: u32 = 1;
const PJ: u32 = 2;

impl Leaves {
    /// The trailing leaves of `dae` (mass diagonal `mass`: the integrator's regime's) with
    /// the reduced pattern of `stamps` (the full iteration matrix's,
    /// `newton::jacobian_stamps`) analysed in the returned LU; None if it has none.
    pub fn find<S: Stamp>(dae: &Dae, mass: &[f64], stamps: &[S]) -> Option<(Self, SparseLu)> {
        let n = dae.n;
        let start = leaf_start(dae);
        if start == n
            || !dae.stenosis.is_empty()
            || !dae.varying.is_empty()
            || !dae.elements.is_empty()
            || !dae.chain_rule.is_empty()
        {
            return None;
        }
        let m = n - start;
        let (mut parent, mut b, mut own) = (vec![0u32; m], vec![0.0; m], vec![0.0; m]);
        for j in start..n {
            for k in dae.f.row(j) {
                let c = dae.f.col[k] as usize;
                if c == j {
                    own[j - start] = dae.f.val[k];
                } else {
                    parent[j - start] = c as u32;
                    b[j - start] = dae.f.val[k];
                }
            }
        }
        // the parent's term, and the symmetric form the condensation is written for
        let mut f_pj = vec![f64::NAN; m];
        let mut reduced_f = Csr {
            ptr: Vec::with_capacity(start + 1),
            col: Vec::new(),
            val: Vec::new(),
        };
        reduced_f.ptr.push(0);
        for i in 0..start {
            for k in dae.f.row(i) {
                let c = dae.f.col[k] as usize;
                if c >= start {
                    f_pj[c - start] = dae.f.val[k];
                } else {
                    reduced_f.col.push(c as u32);
                    reduced_f.val.push(dae.f.val[k]);
                }
            }
            reduced_f.end_row();
        }
        let symmetric = (0..m).all(|j| own[j] == -b[j] && f_pj[j] == b[j] && b[j] != 0.0);
        if !symmetric {
            return None;
        }
        let mut reduced = Vec::with_capacity(stamps.len());
        let mut reduced_slot = vec![NONE; stamps.len()];
        let mut leaf_stamps = Vec::with_capacity(4 * m);
        let mut diag = vec![NONE; start];
        for (s, (r, c)) in stamps.iter().map(|s| s.at()).enumerate() {
            if r < start && c < start {
                reduced_slot[s] = reduced.len() as u32;
                if r == c && diag[r] == NONE {
                    diag[r] = reduced.len() as u32;
                }
                reduced.push((r as u32, c as u32));
            } else {
                let (leaf, kind) = if r == c {
                    (r, JJ)
                } else if r >= start {
                    (r, JP)
                } else {
                    (c, PJ)
                };
                leaf_stamps.push((s as u32, ((leaf - start) as u32) << 2 | kind));
            }
        }
        let parent_diag: Vec<u32> = parent.iter().map(|&p| diag[p as usize]).collect();
        let lu = SparseLu::analyse(start, &reduced).ok()?;
        let leaves = Leaves {
            start,
            reduced_f,
            parent,
            b,
            g: vec![0.0; m],
            mass: mass[start..].to_vec(),
            pivot: vec![0.0; m],
            am: 1.0,
            c: 0.0,
            c_am: 1.0,
            reduced_slot,
            leaf_stamps,
            parent_diag,
            n_reduced_stamps: reduced.len(),
            vals: Vec::new(),
            entries: Vec::new(),
        };
        Some((leaves, lu))
    }

    /// Factorise the reduced matrix into `lu` from the full iteration matrix's values `kvals`
    /// (in the order of the stamps given to `find`: α_m E + c F); `c_am` weighs ẏ in the
    /// step's residual.
    pub fn factor(
        &mut self,
        lu: &mut SparseLu,
        kvals: &[f64],
        (am, c, c_am): (f64, f64, f64),
        name: &dyn Fn(usize) -> String,
    ) -> std::result::Result<(), String> {
        let m = self.parent.len();
        let mut vals = std::mem::take(&mut self.vals);
        vals.clear();
        vals.resize(self.n_reduced_stamps, 0.0);
        for (&slot, &v) in self.reduced_slot.iter().zip(kvals) {
            if slot != NONE {
                vals[slot as usize] += v;
            }
        }
        let mut entries = std::mem::take(&mut self.entries);
        entries.clear();
        entries.resize(m, [0.0; 3]);
        for &(s, code) in &self.leaf_stamps {
            entries[(code >> 2) as usize][(code & 3) as usize] += kvals[s as usize];
        }
        for (j, &[mjj, mjp, mpj]) in entries.iter().enumerate() {
            // the passes' h_j = (1 + c g_j) c_am/α_m holds for M_jj = α_m E_j − c b_j alone
            let expected = am * self.mass[j] - c * self.b[j];
            let consistent = (mjj - expected).abs() <= 1e-12 * expected.abs();
            if !(mjj.is_finite() && mjj.abs() > 0.0) || mjp != mpj || !consistent {
                return Err(format!("pivot {mjj} of unknown {}", self.start + j));
            }
            self.pivot[j] = mjj;
            self.g[j] = self.b[j] / mjj;
            vals[self.parent_diag[j] as usize] -= (mpj / mjj) * mjp;
        }
        (self.am, self.c, self.c_am) = (am, c, c_am);
        self.entries = entries;
        // (the reduced system's unknowns are the circuit's first `start`: the same names)
        let done = lu.factor_naming(&vals, name);
        self.vals = vals;
        done
    }

    /// Solve M x = b in place with the factors of `factor`.
    pub fn solve_in_place(&self, lu: &SparseLu, b: &mut [f64]) -> bool {
        let (head, tail) = b.split_at_mut(self.start);
        for ((&p, &g), &bj) in self.parent.iter().zip(&self.g).zip(&*tail) {
            head[p as usize] -= self.c * g * bj;
        }
        if !lu.solve_in_place(head) {
            return false;
        }
        let mut finite = true;
        for (((bj, &p), &g), &pivot) in tail
            .iter_mut()
            .zip(&self.parent)
            .zip(&self.g)
            .zip(&self.pivot)
        {
            *bj = *bj / pivot - self.c * g * head[p as usize];
            finite &= bj.is_finite();
        }
        finite
    }

    /// The leaves' residuals −E ẏ c_am − F y (no forcing on a leaf row; c_am as given to
    /// `factor`) folded into their parents' residuals `r_head`, which must hold the parents'
    /// rows over `reduced_f` (the leaves' terms F_pj y_j are added here) or, if `with_max`,
    /// over F's whole rows. Returns the largest magnitude of the leaves' residuals if
    /// `with_max` (else 0: the running maximum is a serial chain the step only needs for an
    /// absolute tolerance).
    pub fn residual_and_fold(
        &self,
        y: &[f64],
        yd: &[f64],
        r_head: &mut [f64],
        with_max: bool,
    ) -> f64 {
        let (yl, ydl) = (&y[self.start..], &yd[self.start..]);
        let (c, h0) = (self.c, self.c_am / self.am);
        let h1 = c * h0;
        let cut = if with_max { 0.0 } else { 1.0 };
        // the cells of one branch are consecutive: their fold is summed before it is stored
        // (one store per parent instead of a store-to-load chain through it)
        let (mut parent, mut fold) = (usize::MAX, 0.0);
        for ((((&p, &b), &g), &yj), &ydj) in self
            .parent
            .iter()
            .zip(&self.b)
            .zip(&self.g)
            .zip(yl)
            .zip(ydl)
        {
            let p = p as usize;
            let w = g * (yj - y[p]) - (h0 + h1 * g) * ydj;
            if p != parent {
                if parent != usize::MAX {
                    r_head[parent] -= fold;
                }
                (parent, fold) = (p, 0.0);
            }
            fold += b * (cut * yj + c * w);
        }
        if parent != usize::MAX {
            r_head[parent] -= fold;
        }
        if !with_max {
            return 0.0;
        }
        let mut rmax = 0.0f64;
        for ((((&p, &b), &e), &yj), &ydj) in self
            .parent
            .iter()
            .zip(&self.b)
            .zip(&self.mass)
            .zip(yl)
            .zip(ydl)
        {
            let v = b * (yj - y[p as usize]) - self.c_am * e * ydj;
            rmax = rmax.max(v.abs());
        }
        rmax
    }

    /// After the reduced solve of `r_head` (the increments Δ of the other unknowns, whose
    /// values `y[..start]` must still be the step's start): each leaf's increment Δ_j, and
    /// its update y_j += gdt Δ_j, ẏ_j ← pred ẏ_j + Δ_j (generalized-α's). With `from`, the
    /// step's start is read there (and `y`, `yd` only written).
    pub fn back_substitute_and_update(
        &self,
        r_head: &[f64],
        from: Option<(&[f64], &[f64])>,
        y: &mut [f64],
        yd: &mut [f64],
        gdt: f64,
        pred: f64,
    ) -> bool {
        let (head_y, yl) = y.split_at_mut(self.start);
        let ydl = &mut yd[self.start..];
        let (c, h0) = (self.c, self.c_am / self.am);
        let h1 = c * h0;
        let mut finite = true;
        let cells = self.parent.iter().zip(&self.g);
        match from {
            None => {
                for (((&p, &g), yj), ydj) in cells.zip(yl).zip(ydl) {
                    let p = p as usize;
                    let w = g * (*yj - head_y[p]) - (h0 + h1 * g) * *ydj;
                    let d = w - c * g * r_head[p];
                    finite &= d.is_finite();
                    *yj += gdt * d;
                    *ydj = pred * *ydj + d;
                }
            }
            // (the step's start read from `from`, its end written into `y`, `yd`: the same
            // expressions)
            Some((y0, yd0)) => {
                let start = y0[self.start..].iter().zip(&yd0[self.start..]);
                for ((((&p, &g), yj), ydj), (&y0j, &yd0j)) in cells.zip(yl).zip(ydl).zip(start) {
                    let p = p as usize;
                    let w = g * (y0j - y0[p]) - (h0 + h1 * g) * yd0j;
                    let d = w - c * g * r_head[p];
                    finite &= d.is_finite();
                    *yj = y0j + gdt * d;
                    *ydj = pred * yd0j + d;
                }
            }
        }
        finite
    }
}

/// The first of the trailing leaf unknowns of `dae` (`dae.n` if none): rows
/// E_j ẏ_j + a_j y_j + b_j y_p with column j used by row p alone, no forcing, every parent
/// before the first leaf.
fn leaf_start(dae: &Dae) -> usize {
    let n = dae.n;
    let mut forced = vec![false; n];
    for &(row, _) in &dae.forcing {
        forced[row] = true;
    }
    // how often each column is used by F (a leaf's column: by its own row and its parent's)
    let mut uses = vec![0u32; n];
    for &c in &dae.f.col {
        uses[c as usize] += 1;
    }
    let mut start = n;
    while start > 0 {
        let j = start - 1;
        let (lo, hi) = (dae.f.row(j).start, dae.f.row(j).end);
        let ok = !forced[j]
            && hi - lo == 2
            && uses[j] == 2
            && (lo..hi).any(|k| dae.f.col[k] as usize == j)
            && (lo..hi).all(|k| (dae.f.col[k] as usize) <= j);
        if !ok {
            break;
        }
        start = j;
    }
    // every parent must be in the reduced system
    let parent_of = |j: usize| {
        dae.f
            .row(j)
            .map(|k| dae.f.col[k] as usize)
            .find(|&c| c != j)
            .expect("a leaf row has its parent")
    };
    while let Some(j) = (start..n).filter(|&j| parent_of(j) >= start).max() {
        start = j + 1;
    }
    start
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::integrate::newton::jacobian_stamps;
    use crate::model::parse;

    /// A Womersley bifurcation (cells on every segment of the 5 mm and 2 mm vessels, all
    /// folded on the 0.2 mm one) with an RCR outlet.
    const MODEL: &str = r#"{
        "wall_friction": "womersley",
        "vessels": [
            {"name": "a", "from": "in", "to": "j", "segments": 4,
             "geometry": {"length": 0.1, "radius_in": 0.005, "radius_out": 0.004,
                          "wall_thickness": 0.0005, "youngs_modulus": 4e5}},
            {"name": "b", "from": "j", "to": "out", "segments": 3,
             "geometry": {"length": 0.05, "radius_in": 0.002, "radius_out": 0.002,
                          "wall_thickness": 0.0003, "youngs_modulus": 4e5}},
            {"name": "c", "from": "j", "to": "out2", "segments": 2,
             "geometry": {"length": 0.01, "radius_in": 0.0002, "radius_out": 0.0002,
                          "wall_thickness": 0.00005, "youngs_modulus": 4e5}}],
        "boundary_conditions": {
            "in": {"type": "flow", "flow": {"kind": "constant", "value": 1e-6}},
            "out": {"type": "resistance", "resistance": 1e9},
            "out2": {"type": "rcr", "proximal_resistance": 1e8, "capacitance": 1e-9,
                     "distal_resistance": 1e9}}
    }"#;

    #[test]
    fn cells_are_the_trailing_leaves_and_the_condensed_solve_solves_the_full_system() {
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let cells = a.circuit.friction_cells.len();
        assert!(cells >= 14, "{cells}");
        let dae = a.circuit.assemble().unwrap();
        let stamps = jacobian_stamps(&dae);
        let (mut leaves, mut lu) = Leaves::find(&dae, &dae.e, &stamps).expect("leaves");
        assert_eq!(dae.n - leaves.start, cells);
        // an iteration matrix of generalized-α's form, α_m E + α_f γ Δt F, at Δt = 1 ms
        let c = 0.5e-3;
        let mut kvals = vec![0.0; stamps.len()];
        let am_e: Vec<f64> = dae.e.iter().map(|e| 0.9 * e).collect();
        crate::integrate::newton::jacobian_values(&dae, c, &am_e, &[], 0.0, &mut kvals);
        leaves
            .factor(&mut lu, &kvals, (0.9, c, 1.0), &|i| i.to_string())
            .unwrap();
        let b: Vec<f64> = (0..dae.n)
            .map(|i| ((i * 7919) % 113) as f64 - 56.0)
            .collect();
        let mut x = b.clone();
        assert!(leaves.solve_in_place(&lu, &mut x));
        // the residual of the full system, each row against the size of its own terms
        let (mut kx, mut size) = (
            vec![0.0; dae.n],
            b.iter().map(|v| v.abs()).collect::<Vec<_>>(),
        );
        for (&(r, c), &k) in stamps.iter().zip(&kvals) {
            kx[r] += k * x[c];
            size[r] += (k * x[c]).abs();
        }
        for i in 0..dae.n {
            assert!(
                (kx[i] - b[i]).abs() <= 1e-10 * size[i],
                "row {i}: {} vs {}",
                kx[i],
                b[i]
            );
        }
    }

    /// Generalized-α steps of the full (uncondensed) system, solved by a sparse LU on every
    /// unknown: the independent reference of the condensed step.
    fn full_steps(dae: &crate::circuit::Dae, dt: f64, rho: f64, steps: usize) -> Vec<Vec<f64>> {
        let am = 0.5 * (3.0 - rho) / (1.0 + rho);
        let af = 1.0 / (1.0 + rho);
        let gamma = 0.5 + am - af;
        let (c, pred) = (af * gamma * dt, (gamma - 1.0) / gamma);
        let c_am = 1.0 + am * (pred - 1.0);
        let stamps = jacobian_stamps(dae);
        let am_e: Vec<f64> = dae.e.iter().map(|e| am * e).collect();
        let mut kvals = vec![0.0; stamps.len()];
        crate::integrate::newton::jacobian_values(dae, c, &am_e, &[], 0.0, &mut kvals);
        let mut lu = SparseLu::analyse(dae.n, &stamps).unwrap();
        lu.factor(&kvals).unwrap();
        let (mut y, mut yd, mut f) = (vec![0.0; dae.n], vec![0.0; dae.n], vec![0.0; dae.n]);
        let mut out = Vec::new();
        for i in 0..steps {
            dae.forcing_into(
                (i as f64 + af) * dt,
                crate::circuit::Regime::Transient,
                &mut f,
            );
            let mut r: Vec<f64> = (0..dae.n)
                .map(|k| f[k] - dae.e[k] * yd[k] * c_am - dae.f.row_dot(k, &y))
                .collect();
            assert!(lu.solve_in_place(&mut r));
            for k in 0..dae.n {
                y[k] += gamma * dt * r[k];
                yd[k] = pred * yd[k] + r[k];
            }
            out.push(y.clone());
        }
        out
    }

    #[test]
    fn the_condensed_step_is_the_full_systems_step_with_and_without_an_absolute_tolerance() {
        use crate::integrate::genalpha::{GenAlpha, NewtonControl};
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let (dt, rho, steps) = (1e-3, 0.5, 60);
        let reference = full_steps(&dae, dt, rho, steps);
        // each unknown against its own largest magnitude over the run (flows and pressures
        // differ by nine decades): the two eliminations differ in their order of rounding only
        let scale: Vec<f64> = (0..dae.n)
            .map(|k| reference.iter().fold(0.0f64, |m, y| m.max(y[k].abs())))
            .collect();
        for atol in [None, Some(1e-300)] {
            let control = NewtonControl { atol, max_iter: 30 };
            let mut ga =
                GenAlpha::new(&dae, crate::circuit::Regime::Transient, dt, rho, control).unwrap();
            let (mut y, mut yd) = (vec![0.0; dae.n], vec![0.0; dae.n]);
            for (i, yref) in reference.iter().enumerate() {
                ga.step(i as f64 * dt, &mut y, &mut yd).unwrap();
                for k in 0..dae.n {
                    assert!(
                        (y[k] - yref[k]).abs() <= 1e-10 * scale[k],
                        "{atol:?} step {i} unknown {k}: {} vs {}",
                        y[k],
                        yref[k]
                    );
                }
            }
        }
    }

    #[test]
    fn a_step_changed_after_the_factorisation_ahead_is_the_full_systems_step() {
        // a fixed step's factorisation made ahead drops the reduced LU's stamp map; a step
        // changed after it makes the map again from the reduced pattern and refactorises:
        // the full system's steps at the new step, to the rounding of the two eliminations
        use crate::integrate::Integrator;
        use crate::integrate::genalpha::{GenAlpha, NewtonControl};
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let (dt, rho, steps) = (5e-4, 0.5, 60);
        let reference = full_steps(&dae, dt, rho, steps);
        let scale: Vec<f64> = (0..dae.n)
            .map(|k| reference.iter().fold(0.0f64, |m, y| m.max(y[k].abs())))
            .collect();
        let control = NewtonControl::default();
        let mut ga = GenAlpha::new(
            &dae,
            crate::circuit::Regime::Transient,
            2.0 * dt,
            rho,
            control,
        )
        .unwrap();
        let (mut y, mut yd) = (vec![0.0; dae.n], vec![0.0; dae.n]);
        Integrator::factor_ahead(&mut ga, 0.0, &y).unwrap();
        ga.set_dt(dt);
        for (i, yref) in reference.iter().enumerate() {
            ga.step(i as f64 * dt, &mut y, &mut yd).unwrap();
            for k in 0..dae.n {
                assert!(
                    (y[k] - yref[k]).abs() <= 1e-10 * scale[k],
                    "step {i} unknown {k}: {} vs {}",
                    y[k],
                    yref[k]
                );
            }
        }
    }

    #[test]
    fn a_step_from_a_kept_start_is_the_full_systems_step_whatever_its_buffers_held() {
        // an error-controlled run keeps each step's start and exchanges buffers: the step
        // reads its start there and writes its end over the state before it (here NaN)
        use crate::integrate::genalpha::{GenAlpha, NewtonControl};
        let a = parse(MODEL).unwrap().assemble().unwrap();
        let dae = a.circuit.assemble().unwrap();
        let (dt, rho, steps) = (1e-3, 0.5, 60);
        let reference = full_steps(&dae, dt, rho, steps);
        // (the tolerance of the in-place test above: the two eliminations' rounding)
        let scale: Vec<f64> = (0..dae.n)
            .map(|k| reference.iter().fold(0.0f64, |m, y| m.max(y[k].abs())))
            .collect();
        for atol in [None, Some(1e-300)] {
            let control = NewtonControl { atol, max_iter: 30 };
            let mut ga =
                GenAlpha::new(&dae, crate::circuit::Regime::Transient, dt, rho, control).unwrap();
            let (mut y0, mut yd0) = (vec![0.0; dae.n], vec![0.0; dae.n]);
            let (mut y, mut yd) = (vec![f64::NAN; dae.n], vec![f64::NAN; dae.n]);
            for (i, yref) in reference.iter().enumerate() {
                ga.step_from(i as f64 * dt, (&y0, &yd0), &mut y, &mut yd)
                    .unwrap();
                for k in 0..dae.n {
                    assert!(
                        (y[k] - yref[k]).abs() <= 1e-10 * scale[k] && yd[k].is_finite(),
                        "{atol:?} step {i} unknown {k}: {} vs {}",
                        y[k],
                        yref[k]
                    );
                }
                std::mem::swap(&mut y0, &mut y);
                std::mem::swap(&mut yd0, &mut yd);
                y.fill(f64::NAN);
                yd.fill(f64::NAN);
            }
        }
    }
}
