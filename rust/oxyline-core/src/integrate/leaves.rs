//! Leaf unknowns condensed out of a linear generalized-α step.
//!
//! A Womersley friction cell (`crate::womersley`) is an unknown i whose row is
//! L di/dt + R i − R Q = 0 and whose only other appearance is the −R i of its branch's row: a
//! leaf hanging off the flow Q. The assembly puts the cells after every other unknown, so a
//! circuit's trailing unknowns of that shape (one row E_j ẏ_j + a_j y_j + b_j y_p, column j
//! used by row p alone, no forcing) can be eliminated per leaf in closed form: the Schur
//! complement of the iteration matrix M on them is M_pp − M_pj M_jp / M_jj on the parent's
//! diagonal, and after the reduced solve Δ_j = (r_j − M_jp Δ_p)/M_jj. The step then runs its
//! generic residual, elimination and update over the other unknowns only, and one fused
//! pass over the leaves (their residual folded into the parents before the solve, their
//! update after it): about half the memory traffic of a leaf in the generic loops. The
//! arithmetic is that of the tree elimination of the same leaf (`crate::sparse::TreeLu`), so
//! the result is the same up to rounding.

use crate::circuit::Dae;
use crate::sparse::SparseLu;

/// The trailing leaves of a DAE and the iteration matrix reduced to the other unknowns.
pub struct Leaves {
    /// First leaf unknown: unknowns `start..n` are leaves, `0..start` the reduced system.
    pub start: usize,
    /// Per leaf, its row and (after `factor`) its elimination, together: one stream.
    leaf: Vec<Leaf>,
    /// The α_m weight folded into the leaves' `mass` (`factor`).
    c_am: f64,
    /// Per row of the reduced system: the end of its F entries without the leaves' columns
    /// (a branch's row ends with its cells' entries), so the step's residual pass reads
    /// neither them nor the leaves' values; the leaves add F_pj y_j to their fold instead.
    pub row_end: Vec<usize>,
    /// Whether `row_end` cuts anything (else it is F's own row ends).
    rows_cut: bool,
    /// Per full stamp: its index among the reduced stamps, or `NONE` (a leaf's stamp).
    reduced_slot: Vec<u32>,
    /// The leaf stamps: (stamp index, leaf << 2 | kind), kind `JJ`, `JP` or `PJ`.
    leaf_stamps: Vec<(u32, u32)>,
    /// Per leaf: the reduced stamp of its parent's diagonal.
    parent_diag: Vec<u32>,
    n_reduced_stamps: usize,
    /// Scratch of the reduced values.
    vals: Vec<f64>,
}

/// A leaf j with parent p: row E_j ẏ_j − b y_j + b y_p (a friction cell's R(i − Q), a
/// viscoelastic wall's (P_e − P)/R_v) and the term b y_j in its parent's row, so that the
/// iteration matrix is symmetric on it: M_jp = M_pj = c b. 40 bytes: the leaf pass streams
/// it twice per step.
#[derive(Clone, Copy, Default)]
struct Leaf {
    parent: u32,
    b: f64,
    /// E_j times the step's α_m weight of ẏ in its residual (`factor`'s `c_am`).
    mass: f64,
    /// M_pj / M_jj (= M_jp / M_jj) and 1/M_jj, after `factor`.
    down: f64,
    inv_pivot: f64,
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
    pub fn find(dae: &Dae, mass: &[f64], stamps: &[(usize, usize)]) -> Option<(Self, SparseLu)> {
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
            let (lo, hi) = (dae.f.ptr[j], dae.f.ptr[j + 1]);
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
        loop {
            let parent_of = |j: usize| {
                (dae.f.ptr[j]..dae.f.ptr[j + 1])
                    .map(|k| dae.f.col[k] as usize)
                    .find(|&c| c != j)
                    .expect("a leaf row has its parent")
            };
            match (start..n).filter(|&j| parent_of(j) >= start).max() {
                Some(j) => start = j + 1,
                None => break,
            }
        }
        if start == n
            || !dae.stenosis.is_empty()
            || !dae.varying.is_empty()
            || !dae.elements.is_empty()
            || !dae.chain_rule.is_empty()
        {
            return None;
        }
        let m = n - start;
        let mut leaf = vec![Leaf::default(); m];
        let mut own = vec![0.0; m];
        for (j, l) in (start..n).zip(&mut leaf) {
            l.mass = mass[j];
            for k in dae.f.ptr[j]..dae.f.ptr[j + 1] {
                let c = dae.f.col[k] as usize;
                if c == j {
                    own[j - start] = dae.f.val[k];
                } else {
                    l.parent = c as u32;
                    l.b = dae.f.val[k];
                }
            }
        }
        // the parent's term, and the symmetric form the condensation is written for
        let mut f_pj = vec![f64::NAN; m];
        for i in 0..start {
            for k in dae.f.ptr[i]..dae.f.ptr[i + 1] {
                let c = dae.f.col[k] as usize;
                if c >= start {
                    f_pj[c - start] = dae.f.val[k];
                }
            }
        }
        let symmetric = (0..m).all(|j| own[j] == -leaf[j].b && f_pj[j] == leaf[j].b);
        if !symmetric {
            return None;
        }
        let mut reduced = Vec::with_capacity(stamps.len());
        let mut reduced_slot = vec![NONE; stamps.len()];
        let mut leaf_stamps = Vec::with_capacity(4 * m);
        let mut diag = vec![NONE; start];
        for (s, &(r, c)) in stamps.iter().enumerate() {
            if r < start && c < start {
                reduced_slot[s] = reduced.len() as u32;
                if r == c && diag[r] == NONE {
                    diag[r] = reduced.len() as u32;
                }
                reduced.push((r, c));
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
        let parent_diag: Vec<u32> = leaf.iter().map(|l| diag[l.parent as usize]).collect();
        // a row's leaf entries must be its last ones (and single) to be cut off its end
        let mut row_end = dae.f.ptr[1..=start].to_vec();
        let mut cut = true;
        for (i, end) in row_end.iter_mut().enumerate() {
            let lo = dae.f.ptr[i];
            while *end > lo && dae.f.col[*end - 1] as usize >= start {
                *end -= 1;
            }
            cut &= (lo..*end).all(|k| (dae.f.col[k] as usize) < start);
        }
        if cut {
            for (i, &end) in row_end.iter().enumerate() {
                cut &= (end..dae.f.ptr[i + 1])
                    .all(|k| leaf[dae.f.col[k] as usize - start].parent as usize == i);
            }
        }
        if !cut {
            row_end.copy_from_slice(&dae.f.ptr[1..=start]);
        }
        let lu = SparseLu::analyse(start, &reduced).ok()?;
        let leaves = Leaves {
            start,
            leaf,
            c_am: 1.0,
            rows_cut: cut,
            row_end,
            reduced_slot,
            leaf_stamps,
            parent_diag,
            n_reduced_stamps: reduced.len(),
            vals: Vec::new(),
        };
        Some((leaves, lu))
    }

    /// Factorise the reduced matrix into `lu` from the full iteration matrix's values `kvals`
    /// (in the order of the stamps given to `find`); `c_am` weighs ẏ in the step's residual.
    pub fn factor(
        &mut self,
        lu: &mut SparseLu,
        kvals: &[f64],
        c_am: f64,
    ) -> std::result::Result<(), String> {
        let m = self.leaf.len();
        let mut vals = std::mem::take(&mut self.vals);
        vals.clear();
        vals.resize(self.n_reduced_stamps, 0.0);
        for (&slot, &v) in self.reduced_slot.iter().zip(kvals) {
            if slot != NONE {
                vals[slot as usize] += v;
            }
        }
        let mut entries = vec![[0.0; 3]; m];
        for &(s, code) in &self.leaf_stamps {
            entries[(code >> 2) as usize][(code & 3) as usize] += kvals[s as usize];
        }
        let rescale = c_am / self.c_am;
        for (j, (l, &[mjj, mjp, mpj])) in self.leaf.iter_mut().zip(&entries).enumerate() {
            if !(mjj.is_finite() && mjj.abs() > 0.0) || mjp != mpj {
                return Err(format!("pivot {mjj} of unknown {}", self.start + j));
            }
            l.inv_pivot = 1.0 / mjj;
            l.down = mpj * l.inv_pivot;
            l.mass *= rescale;
            vals[self.parent_diag[j] as usize] -= l.down * mjp;
        }
        self.c_am = c_am;
        let done = lu.factor(&vals);
        self.vals = vals;
        done
    }

    /// Solve M x = b in place with the factors of `factor`.
    pub fn solve_in_place(&self, lu: &SparseLu, b: &mut [f64]) -> bool {
        let (head, tail) = b.split_at_mut(self.start);
        for (l, &bj) in self.leaf.iter().zip(&*tail) {
            head[l.parent as usize] -= l.down * bj;
        }
        if !lu.solve_in_place(head) {
            return false;
        }
        let mut finite = true;
        for (bj, l) in tail.iter_mut().zip(&self.leaf) {
            *bj = *bj * l.inv_pivot - l.down * head[l.parent as usize];
            finite &= bj.is_finite();
        }
        finite
    }

    /// The leaves' residuals −E ẏ c_am − F y (no forcing on a leaf row; c_am as given to
    /// `factor`) into `r[start..]`, folded into their parents' residuals, which `r[..start]`
    /// must hold: over whole rows if `with_max`, else over `row_end` (the leaves' own terms
    /// F_pj y_j are then added here). Returns the largest magnitude of the leaves' residuals
    /// if `with_max` (else 0: the running maximum is a serial chain the step only needs for
    /// an absolute tolerance).
    pub fn residual_and_fold(&self, y: &[f64], yd: &[f64], r: &mut [f64], with_max: bool) -> f64 {
        let (head, tail) = r.split_at_mut(self.start);
        let (yl, ydl) = (&y[self.start..], &yd[self.start..]);
        let mut rmax = 0.0f64;
        // the cells of one branch are consecutive: their fold is summed before it is stored
        // (one store per parent instead of a store-to-load chain through it)
        let (mut parent, mut fold) = (usize::MAX, 0.0);
        let cut = if self.rows_cut && !with_max { 1.0 } else { 0.0 };
        for (((rj, l), &yj), &ydj) in tail.iter_mut().zip(&self.leaf).zip(yl).zip(ydl) {
            let p = l.parent as usize;
            let v = l.b * (yj - y[p]) - l.mass * ydj;
            if p != parent {
                if parent != usize::MAX {
                    head[parent] -= fold;
                }
                (parent, fold) = (p, 0.0);
            }
            fold += cut * l.b * yj + l.down * v;
            *rj = v;
        }
        if parent != usize::MAX {
            head[parent] -= fold;
        }
        if with_max {
            rmax = tail.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        }
        rmax
    }

    /// After the reduced solve of `r[..start]`: each leaf's increment Δ_j from its folded
    /// residual, and its update y_j += gdt Δ_j, ẏ_j ← pred ẏ_j + Δ_j (generalized-α's).
    pub fn back_substitute_and_update(
        &self,
        r: &[f64],
        y: &mut [f64],
        yd: &mut [f64],
        gdt: f64,
        pred: f64,
    ) -> bool {
        let (head, tail) = r.split_at(self.start);
        let (yl, ydl) = (&mut y[self.start..], &mut yd[self.start..]);
        let mut finite = true;
        for (((&rj, l), yj), ydj) in tail.iter().zip(&self.leaf).zip(yl).zip(ydl) {
            let d = rj * l.inv_pivot - l.down * head[l.parent as usize];
            finite &= d.is_finite();
            *yj += gdt * d;
            *ydj = pred * *ydj + d;
        }
        finite
    }
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
        leaves.factor(&mut lu, &kvals, 1.0).unwrap();
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
}
