//! Linear solves with the iteration matrices of the circuit. Tree-structured circuits (the
//! usual arterial tree) are eliminated leaves-to-root and back in O(n) with no fill-in; circuits
//! with loops (anastomoses, circle of Willis) use faer's sparse LU with the symbolic analysis
//! done once. Both refactorise numerically on demand.

use crate::error::{Error, Result};
use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use std::ops::{AddAssign, Div, Mul, MulAssign, Sub, SubAssign};

/// Entries of the matrices solved here: real for the time stepping, complex for the frequency
/// domain (iωE + F, docs/structured-tree.md). The same elimination serves both.
pub trait Scalar:
    faer::traits::ComplexField
    + Copy
    + Mul<Output = Self>
    + Div<Output = Self>
    + Sub<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    const ZERO: Self;
    const ONE: Self;
    fn modulus(self) -> f64;
    fn finite(self) -> bool;
}

impl Scalar for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    fn modulus(self) -> f64 {
        self.abs()
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Scalar for faer::c64 {
    const ZERO: faer::c64 = faer::c64::new(0.0, 0.0);
    const ONE: faer::c64 = faer::c64::new(1.0, 0.0);
    fn modulus(self) -> f64 {
        self.norm()
    }
    fn finite(self) -> bool {
        self.re.is_finite() && self.im.is_finite()
    }
}

/// Which elimination a matrix pattern gets.
pub enum SparseLu<T: Scalar = f64> {
    Tree(TreeLu<T>),
    General(Box<GeneralLu<T>>),
}

impl<T: Scalar> SparseLu<T> {
    /// `stamps` are the (row, col) positions of the values later passed to `factor`, in order;
    /// duplicates are summed. A forest pattern gets the O(n) tree elimination.
    pub fn analyse(n: usize, stamps: &[(usize, usize)]) -> Result<Self> {
        match TreeLu::analyse(n, stamps) {
            Some(t) => Ok(SparseLu::Tree(t)),
            None => Ok(SparseLu::General(Box::new(GeneralLu::analyse(n, stamps)?))),
        }
    }

    pub fn factor(&mut self, vals: &[T]) -> std::result::Result<(), String> {
        match self {
            SparseLu::Tree(t) => {
                if t.factor(vals) {
                    return Ok(());
                }
                // a (near-)zero pivot, e.g. an ideal wire eliminated first: fall back to
                // pivoting LU on the same pattern
                let mut g = GeneralLu::analyse(t.n, &t.stamps()).map_err(|e| e.to_string())?;
                g.factor(vals)?;
                *self = SparseLu::General(Box::new(g));
                Ok(())
            }
            SparseLu::General(g) => g.factor(vals),
        }
    }

    /// Solve in place; returns false if the solution is not finite (singular matrix).
    pub fn solve_in_place(&self, rhs: &mut [T]) -> bool {
        match self {
            SparseLu::Tree(t) => t.solve_in_place(rhs),
            SparseLu::General(g) => g.solve_in_place(rhs),
        }
    }

    pub fn is_tree(&self) -> bool {
        matches!(self, SparseLu::Tree(_))
    }
}

/// Where a stamped value goes in the tree factorisation, packed into 32 bits (a million-
/// segment circuit has ~7 million stamps): the vertex v times 4 plus the kind.
const DIAG: u32 = 0;
/// K[v, parent(v)]
const UP: u32 = 1;
/// K[parent(v), v]
const DOWN: u32 = 2;

/// Gaussian elimination without pivoting in post-order of a spanning forest of the matrix graph.
/// Stable here because the circuit matrices are diagonal-positive with skew-symmetric couplings
/// (node–branch incidence), so every Schur update adds c²/d > 0 to the parent's pivot.
pub struct TreeLu<T: Scalar = f64> {
    n: usize,
    /// Packed slot (`v << 2 | kind`) of every stamp; the stamps themselves follow from the
    /// slots and `parent` (see `stamps`).
    slots: Vec<u32>,
    /// Elimination order (every vertex after all of its children).
    order: Vec<u32>,
    parent: Vec<u32>,
    diag: Vec<T>,
    up: Vec<T>,
    /// K[parent(v), v], divided by the pivot after `factor`
    down: Vec<T>,
    /// pivots, stored as reciprocals after `factor`
    pivot: Vec<T>,
}

const NONE: u32 = u32::MAX;

impl<T: Scalar> TreeLu<T> {
    fn analyse(n: usize, stamps: &[(usize, usize)]) -> Option<Self> {
        // vertices are packed with two tag bits into u32 slots
        if n >= (1 << 30) {
            return None;
        }
        // undirected adjacency of the off-diagonal pattern (deduplicated)
        let mut edges: Vec<(usize, usize)> = stamps
            .iter()
            .filter(|(r, c)| r != c)
            .map(|&(r, c)| (r.min(c), r.max(c)))
            .collect();
        edges.sort_unstable();
        edges.dedup();
        if edges.len() >= n {
            return None;
        }
        let mut deg = vec![0usize; n + 1];
        for &(a, b) in &edges {
            deg[a] += 1;
            deg[b] += 1;
        }
        let mut start = vec![0usize; n + 1];
        for i in 0..n {
            start[i + 1] = start[i] + deg[i];
        }
        let mut adj = vec![0usize; start[n]];
        let mut fill = start.clone();
        for &(a, b) in &edges {
            adj[fill[a]] = b;
            fill[a] += 1;
            adj[fill[b]] = a;
            fill[b] += 1;
        }
        // BFS from every unvisited vertex; a non-tree edge means a loop
        let mut parent = vec![NONE; n];
        let mut seen = vec![false; n];
        let mut bfs: Vec<u32> = Vec::with_capacity(n);
        let mut tree_edges = 0usize;
        for root in 0..n {
            if seen[root] {
                continue;
            }
            seen[root] = true;
            let first = bfs.len();
            bfs.push(root as u32);
            let mut head = first;
            while head < bfs.len() {
                let v = bfs[head] as usize;
                head += 1;
                for &w in &adj[start[v]..start[v + 1]] {
                    if !seen[w] {
                        seen[w] = true;
                        parent[w] = v as u32;
                        tree_edges += 1;
                        bfs.push(w as u32);
                    }
                }
            }
        }
        if tree_edges != edges.len() {
            return None;
        }
        // reverse BFS order eliminates every vertex after all of its children
        let order: Vec<u32> = bfs.into_iter().rev().collect();
        let slots = stamps
            .iter()
            .map(|&(r, c)| {
                if r == c {
                    (r as u32) << 2 | DIAG
                } else if parent[r] == c as u32 {
                    (r as u32) << 2 | UP
                } else {
                    (c as u32) << 2 | DOWN
                }
            })
            .collect();
        Some(TreeLu {
            n,
            slots,
            order,
            parent,
            diag: vec![T::ZERO; n],
            up: vec![T::ZERO; n],
            down: vec![T::ZERO; n],
            pivot: vec![T::ZERO; n],
        })
    }

    fn factor(&mut self, vals: &[T]) -> bool {
        self.diag.iter_mut().for_each(|x| *x = T::ZERO);
        self.up.iter_mut().for_each(|x| *x = T::ZERO);
        self.down.iter_mut().for_each(|x| *x = T::ZERO);
        for (&slot, &v) in self.slots.iter().zip(vals) {
            let i = (slot >> 2) as usize;
            match slot & 3 {
                DIAG => self.diag[i] += v,
                UP => self.up[i] += v,
                _ => self.down[i] += v,
            }
        }
        self.pivot.copy_from_slice(&self.diag);
        // per-vertex magnitude: the units of pressure and flow rows differ by many decades, so a
        // pivot is judged against the terms that formed it, not a global scale
        let mut magnitude: Vec<f64> = self.diag.iter().map(|d| d.modulus()).collect();
        for &v in &self.order {
            let v = v as usize;
            let d = self.pivot[v];
            if d.modulus() <= 1e-12 * magnitude[v] || !d.finite() {
                return false;
            }
            let p = self.parent[v];
            if p != NONE {
                let p = p as usize;
                let update = self.down[v] * self.up[v] / d;
                self.pivot[p] -= update;
                magnitude[p] += update.modulus();
            }
        }
        // store the multipliers and reciprocal pivots so that solves only multiply
        for &v in &self.order {
            let v = v as usize;
            self.pivot[v] = T::ONE / self.pivot[v];
            self.down[v] *= self.pivot[v];
        }
        true
    }

    fn solve_in_place(&self, b: &mut [T]) -> bool {
        for &v in &self.order {
            let (v, p) = (v as usize, self.parent[v as usize]);
            if p != NONE {
                b[p as usize] -= self.down[v] * b[v];
            }
        }
        let mut finite = true;
        for &v in self.order.iter().rev() {
            let (v, p) = (v as usize, self.parent[v as usize]);
            let up = if p != NONE {
                self.up[v] * b[p as usize]
            } else {
                T::ZERO
            };
            b[v] = (b[v] - up) * self.pivot[v];
            finite &= b[v].finite();
        }
        finite
    }

    /// The (row, col) stamps the slots were made from, in order (for the pivoting fallback).
    fn stamps(&self) -> Vec<(usize, usize)> {
        self.slots
            .iter()
            .map(|&slot| {
                let v = (slot >> 2) as usize;
                let p = self.parent[v] as usize;
                match slot & 3 {
                    DIAG => (v, v),
                    UP => (v, p),
                    _ => (p, v),
                }
            })
            .collect()
    }
}

pub struct GeneralLu<T: Scalar = f64> {
    n: usize,
    sym: SymbolicSparseColMat<usize>,
    order: Argsort<usize>,
    sym_lu: SymbolicLu<usize>,
    lu: Option<Lu<usize, T>>,
}

impl<T: Scalar> GeneralLu<T> {
    pub fn analyse(n: usize, stamps: &[(usize, usize)]) -> Result<Self> {
        let pairs: Vec<Pair<usize, usize>> = stamps.iter().map(|&(r, c)| Pair::new(r, c)).collect();
        let (sym, order) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| Error::solver(0.0, format!("sparse pattern: {e:?}")))?;
        let sym_lu = SymbolicLu::try_new(sym.as_ref())
            .map_err(|e| Error::solver(0.0, format!("symbolic LU: {e:?}")))?;
        Ok(GeneralLu {
            n,
            sym,
            order,
            sym_lu,
            lu: None,
        })
    }

    pub fn factor(&mut self, vals: &[T]) -> std::result::Result<(), String> {
        let a = SparseColMat::new_from_argsort(self.sym.clone(), &self.order, vals)
            .map_err(|e| format!("{e:?}"))?;
        let lu = Lu::try_new_with_symbolic(self.sym_lu.clone(), a.as_ref())
            .map_err(|e| format!("{e:?}"))?;
        self.lu = Some(lu);
        Ok(())
    }

    pub fn solve_in_place(&self, rhs: &mut [T]) -> bool {
        debug_assert_eq!(rhs.len(), self.n);
        let lu = self.lu.as_ref().expect("factor before solve");
        lu.solve_in_place(faer::ColMut::from_slice_mut(rhs));
        rhs.iter().all(|x| x.finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random tree-structured matrix with positive diagonal and skew couplings, plus a loop
    /// edge variant: tree elimination and faer's LU must agree with each other and with A x = b.
    #[test]
    fn tree_elimination_matches_general_lu() {
        let n = 200;
        let mut stamps = Vec::new();
        let mut vals = Vec::new();
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 33) as f64) / (1u64 << 31) as f64
        };
        for i in 0..n {
            stamps.push((i, i));
            vals.push(0.1 + rnd());
            if i > 0 {
                let p = (rnd() * i as f64) as usize;
                let c = 0.5 + rnd();
                stamps.extend([(i, p), (p, i)]);
                vals.extend([c, -c]);
            }
        }
        let x: Vec<f64> = (0..n).map(|i| (i as f64).sin()).collect();
        let mut b = vec![0.0; n];
        for (&(r, c), &v) in stamps.iter().zip(&vals) {
            b[r] += v * x[c];
        }
        let mut tree = SparseLu::analyse(n, &stamps).unwrap();
        assert!(tree.is_tree());
        tree.factor(&vals).unwrap();
        let mut bt = b.clone();
        assert!(tree.solve_in_place(&mut bt));
        let mut general = GeneralLu::analyse(n, &stamps).unwrap();
        general.factor(&vals).unwrap();
        let mut bg = b.clone();
        general.solve_in_place(&mut bg);
        for i in 0..n {
            assert!((bt[i] - x[i]).abs() < 1e-12, "{i}");
            assert!((bg[i] - x[i]).abs() < 1e-12, "{i}");
        }
        // closing a loop switches to the general solver
        let mut looped = stamps.clone();
        looped.extend([(0, n - 1), (n - 1, 0)]);
        assert!(!SparseLu::<f64>::analyse(n, &looped).unwrap().is_tree());
    }

    #[test]
    fn solves_a_small_system_and_reuses_the_pattern() {
        // [[4,1,0],[1,3,1],[0,1,2]]
        let stamps = [(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)];
        let mut lu = SparseLu::analyse(3, &stamps).unwrap();
        lu.factor(&[4.0, 1.0, 1.0, 3.0, 1.0, 1.0, 2.0]).unwrap();
        let mut b = [5.0, 5.0, 3.0];
        assert!(lu.solve_in_place(&mut b));
        for (x, e) in b.iter().zip([1.0, 1.0, 1.0]) {
            assert!((x - e).abs() < 1e-14);
        }
        lu.factor(&[8.0, 2.0, 2.0, 6.0, 2.0, 2.0, 4.0]).unwrap();
        let mut b = [5.0, 5.0, 3.0];
        lu.solve_in_place(&mut b);
        assert!((b[0] - 0.5).abs() < 1e-14);
    }
}
