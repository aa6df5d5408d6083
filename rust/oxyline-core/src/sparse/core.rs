//! A pattern with loops as pendant trees on a small loop-carrying core. An arterial network
//! with a circle of Willis or another anastomosis is a few loops in its large vessels and trees
//! everywhere else (structured trees at the outlets: millions of unknowns). Peeling the
//! vertices of degree one until none is left leaves the 2-core of the matrix graph: the loops
//! and the paths between them, a few thousand unknowns at most. Every other vertex hangs off
//! it in a pendant tree, rooted at a core vertex.
//!
//! The pendant trees are eliminated leaves-to-roots exactly as a forest is ([`TreeLu`], its
//! blocks and its threads), except that their roots, the core vertices, are held: their
//! Schur-complemented pivots become the diagonal of the core's matrix, which the general LU
//! factorises with pivoting (its off-diagonal entries are the stamps joining two core
//! vertices, which no pendant elimination touches). A solve runs the trees' forward pass, the
//! core's LU on the core's right sides, then the trees' back substitution. The order of the
//! elimination differs from the general LU's over the whole pattern, so the result differs
//! from it at roundoff; a solve touches the trees' arrays once each way instead of the general
//! LU's permutations and scattered triangular columns, and the factors take the tree's ~50 B
//! per unknown.

use super::{GeneralLu, SKIP, Scalar, Stamp, TreeLu, csr, edges};
use crate::error::Result;

pub struct CoreLu<T: Scalar> {
    tree: TreeLu<T>,
    /// The core's vertices (increasing): the local index of a core vertex is its place here.
    core: Vec<u32>,
    /// The position of each core vertex in the trees' elimination order.
    core_pos: Vec<u32>,
    /// The stamps joining two core vertices, in stamp order: their index among the stamps
    /// and their (row, col).
    core_stamps: Vec<(u32, (u32, u32))>,
    lu: GeneralLu<T>,
    /// The core matrix's values: the core stamps', then each core vertex's diagonal.
    vals: Vec<T>,
    /// Vertices kept in the core although a pendant tree could take them (increasing): rows
    /// whose pivot vanishes when eliminated before their neighbour (see [`CoreLu::holding`]).
    hold: Vec<u32>,
}

/// At most this many vertices are held in the core for their zero pivots (each holds the
/// path from it to the core); more send the factorisation to the general LU.
const MAX_HELD: usize = 64;

/// Per vertex: whether it is in the 2-core of the graph of `n` vertices joined by `edges`
/// (what is left after removing vertices of degree at most one until there is none), where
/// only the vertices `peelable` allows are ever removed. The result does not depend on the
/// order of removal (each removal only lowers degrees), so one function serves the flow
/// matrix's pattern and the transport's faces alike.
pub(crate) fn two_core(
    n: usize,
    edges: &[(u32, u32)],
    peelable: impl Fn(usize) -> bool,
) -> Vec<bool> {
    let (start, adj) = csr(n, edges);
    let mut degree: Vec<u32> = (0..n).map(|v| start[v + 1] - start[v]).collect();
    let mut in_core = vec![true; n];
    let mut peel: Vec<u32> = (0..n as u32)
        .filter(|&v| degree[v as usize] <= 1 && peelable(v as usize))
        .collect();
    while let Some(v) = peel.pop() {
        let v = v as usize;
        if !in_core[v] {
            continue;
        }
        in_core[v] = false;
        for &w in &adj[start[v] as usize..start[v + 1] as usize] {
            let w = w as usize;
            if in_core[w] {
                degree[w] -= 1;
                if degree[w] == 1 && peelable(w) {
                    peel.push(w as u32);
                }
            }
        }
    }
    in_core
}

impl<T: Scalar> CoreLu<T> {
    /// None if the pattern has no pendant vertex to eliminate (all of it is core) or is too
    /// large for the trees' 32-bit slots.
    pub fn analyse<S: Stamp>(n: usize, stamps: &[S]) -> Result<Option<Self>> {
        Self::analyse_holding(n, stamps, Vec::new())
    }

    /// `analyse` with the vertices `hold` (increasing) never peeled: each stays in the core
    /// with the path joining it to the loops.
    fn analyse_holding<S: Stamp>(n: usize, stamps: &[S], hold: Vec<u32>) -> Result<Option<Self>> {
        if n >= (1 << 30) {
            return Ok(None);
        }
        let peelable = |v: usize| hold.binary_search(&(v as u32)).is_err();
        let in_core = two_core(n, &edges(stamps, |_, _| true), peelable);
        let core: Vec<u32> = (0..n as u32).filter(|&v| in_core[v as usize]).collect();
        if core.is_empty() || core.len() == n {
            return Ok(None);
        }
        let forest = csr(n, &edges(stamps, |r, c| !(in_core[r] && in_core[c])));
        let Some(tree) = TreeLu::analyse_forest(n, stamps, forest, Some(&in_core)) else {
            return Ok(None);
        };
        let mut local = vec![u32::MAX; n];
        for (i, &v) in core.iter().enumerate() {
            local[v as usize] = i as u32;
        }
        let core_stamps: Vec<(u32, (u32, u32))> = stamps
            .iter()
            .map(|s| s.at())
            .enumerate()
            .filter(|&(_, (r, c))| r != c && in_core[r] && in_core[c])
            .map(|(s, (r, c))| (s as u32, (r as u32, c as u32)))
            .collect();
        let mut pattern: Vec<(usize, usize)> = core_stamps
            .iter()
            .map(|&(_, (r, c))| (local[r as usize] as usize, local[c as usize] as usize))
            .collect();
        pattern.extend((0..core.len()).map(|i| (i, i)));
        let lu = GeneralLu::analyse(core.len(), &pattern)?;
        let mut pos = vec![0u32; n];
        for (k, &v) in tree.vertex.iter().enumerate() {
            pos[v as usize] = k as u32;
        }
        let core_pos = core.iter().map(|&v| pos[v as usize]).collect();
        Ok(Some(CoreLu {
            tree,
            vals: vec![T::ZERO; pattern.len()],
            core,
            core_pos,
            core_stamps,
            lu,
            hold,
        }))
    }

    /// The elimination again with the vertices of `zeros` (the pendant pivots that `vals`
    /// made (near-)zero) held in the core, factorised; None if there are none, too many, or
    /// that elimination meets a zero pivot too (the caller falls back to the general LU).
    ///
    /// Why: a row without storage whose one neighbour is a flow, e.g. a flow inlet's node
    /// without capacitance (the row is Q_in(t) = Q of the first segment), is a leaf of the
    /// graph and so a leaf of its pendant tree, eliminated first with its diagonal exactly
    /// zero. A tree without loops is rooted at that node and eliminates it last, onto the
    /// pivots its neighbour's subtree built; a core cannot root its pendant trees anywhere
    /// but at the core. Held, the row goes to the core's pivoting LU with the path to the
    /// loops (a few hundred unknowns of large vessels), and the trees stay O(n).
    pub(super) fn holding(
        &self,
        zeros: &[super::ZeroPivot],
        vals: &[T],
    ) -> std::result::Result<Option<Self>, String> {
        if zeros.is_empty() || zeros.len() + self.hold.len() > MAX_HELD {
            return Ok(None);
        }
        let mut hold = self.hold.clone();
        hold.extend(zeros.iter().map(|z| z.unknown as u32));
        hold.sort_unstable();
        hold.dedup();
        let stamps = self.stamps();
        let held = Self::analyse_holding(self.n(), &stamps, hold).map_err(|e| e.to_string())?;
        drop(stamps);
        let Some(mut held) = held else {
            return Ok(None);
        };
        Ok(held.factor(vals)?.then_some(held))
    }

    pub fn n(&self) -> usize {
        self.tree.n
    }

    /// Ok(false) at a (near-)zero pivot in a pendant tree (the caller falls back to the
    /// general LU); an error if the core's LU fails.
    pub fn factor(&mut self, vals: &[T]) -> std::result::Result<bool, String> {
        if !self.tree.eliminate(vals) {
            return Ok(false);
        }
        let m = self.core_stamps.len();
        for (slot, &(s, _)) in self.vals.iter_mut().zip(&self.core_stamps) {
            *slot = vals[s as usize];
        }
        for (slot, &k) in self.vals[m..].iter_mut().zip(&self.core_pos) {
            // the Schur-complemented diagonal goes to the core; the held root's own back
            // substitution then multiplies by one (its value is the core's solution)
            *slot = self.tree.pivot[k as usize];
            self.tree.pivot[k as usize] = T::ONE;
        }
        self.tree.invert_pivots();
        self.lu.factor(&self.vals)?;
        Ok(true)
    }

    /// The pendant trees' elimination (for the report of a zero pivot).
    pub(super) fn tree_mut(&mut self) -> &mut TreeLu<T> {
        &mut self.tree
    }

    /// Drop the factorisation's values (see [`TreeLu::release_values`]); the core's own
    /// factors are a few thousand unknowns' and stay.
    pub fn release_values(&mut self) {
        self.tree.release_values();
    }

    /// Solve in place; whether the solution is finite.
    pub fn solve_in_place(&self, b: &mut [T]) -> bool {
        match self.tree.partition.pool() {
            Some(pool) => pool.install(|| {
                self.tree.forward_parallel(b);
                let core_finite = self.solve_core(b);
                self.tree.backward_parallel(b) && core_finite
            }),
            None => {
                self.tree.forward(b);
                let core_finite = self.solve_core(b);
                self.tree.backward(b) && core_finite
            }
        }
    }

    /// The core's unknowns from their right sides after the trees' forward pass.
    fn solve_core(&self, b: &mut [T]) -> bool {
        let mut x: Vec<T> = self.core.iter().map(|&v| b[v as usize]).collect();
        let finite = self.lu.solve_in_place(&mut x);
        for (&v, &xv) in self.core.iter().zip(&x) {
            b[v as usize] = xv;
        }
        finite
    }

    /// The (row, col) stamps, in order (for the pivoting fallback).
    pub fn stamps(&self) -> Vec<(usize, usize)> {
        let mut core = self.core_stamps.iter();
        self.tree
            .slots
            .iter()
            .map(|&slot| {
                if slot & 3 == SKIP {
                    let &(_, (r, c)) = core.next().expect("one core stamp per skipped slot");
                    (r as usize, c as usize)
                } else {
                    self.tree.stamp_of(slot)
                }
            })
            .collect()
    }

    /// The number of unknowns in the loop-carrying core.
    pub fn core_len(&self) -> usize {
        self.core.len()
    }
}

#[cfg(test)]
mod tests {
    use super::super::{BLOCK, SparseLu};
    use super::*;

    /// A random tree pattern (positive diagonal, skew couplings: the circuits' shape) over `n`
    /// vertices, closed by `loops` extra couplings between vertices of its first 40 (the
    /// large vessels), with zero diagonal at vertex 0 (a junction without storage); and the
    /// right side of the solution x_i = sin(0.37 i).
    #[allow(clippy::type_complexity)]
    fn looped_case(
        n: usize,
        fan: usize,
        loops: usize,
        seed: u64,
    ) -> (Vec<(usize, usize)>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut seed = seed;
        let mut rnd = || crate::test_common::lcg(&mut seed);
        let (mut stamps, mut vals) = (Vec::new(), Vec::new());
        for i in 0..n {
            stamps.push((i, i));
            vals.push(if i == 0 { 0.0 } else { 0.1 + rnd() });
            if i > 0 {
                let p = match (i - 1).checked_div(fan) {
                    Some(p) => p,
                    None => (rnd() * i as f64) as usize,
                };
                let c = 0.5 + rnd();
                stamps.extend([(i, p), (p, i)]);
                vals.extend([c, -c]);
            }
        }
        for k in 0..loops {
            let (a, b) = (3 * k + 1, 39 - 5 * k);
            let c = 0.5 + rnd();
            stamps.extend([(a, b), (b, a)]);
            vals.extend([c, -c]);
        }
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b = vec![0.0; n];
        for (&(r, c), &v) in stamps.iter().zip(&vals) {
            b[r] += v * x[c];
        }
        (stamps, vals, x, b)
    }

    /// Pendant trees eliminated onto a core of one to three loops: the core is small, and the
    /// solve agrees with the general LU of the whole pattern and with the system's solution
    /// (to 1e-10: another elimination order, entries of order 1, |x| <= 1), on one block and
    /// on several blocks under vertices eliminated outside any block.
    #[test]
    fn core_elimination_matches_the_general_lu() {
        for n in [300, 3 * BLOCK + 17] {
            for loops in 1..=3 {
                let (stamps, vals, x, b) = looped_case(n, 0, loops, 12345 + loops as u64);
                let mut lu = SparseLu::analyse(n, &stamps).unwrap();
                let SparseLu::Core(c) = &lu else {
                    panic!("not eliminated onto a core")
                };
                assert!(c.core_len() >= 3 && c.core_len() <= 40, "{}", c.core_len());
                lu.factor(&vals).unwrap();
                assert!(matches!(lu, SparseLu::Core(_)), "no fallback");
                let mut bc = b.clone();
                assert!(lu.solve_in_place(&mut bc));
                let mut general = GeneralLu::analyse(n, &stamps).unwrap();
                general.factor(&vals).unwrap();
                let mut bg = b.clone();
                assert!(general.solve_in_place(&mut bg));
                for i in 0..n {
                    assert!((bc[i] - x[i]).abs() < 1e-10, "{n} {loops} {i}");
                    assert!((bc[i] - bg[i]).abs() < 1e-10, "{n} {loops} {i}");
                }
                // the pivoting fallback sees the same pattern
                let mut from_stamps = c_stamps(&stamps);
                from_stamps.sort_unstable();
                let mut want = stamps.clone();
                want.sort_unstable();
                assert_eq!(from_stamps, want);
            }
        }
    }

    /// The iteration matrix α_m E + c F of the smallest circuit with a flow inlet whose node
    /// has no storage on a network with a loop: inlet node p0 (no capacitance: its row is
    /// the inflow's, c q1) – inlet segment q1 – node p1 – two parallel segments qa, qb (the
    /// loop) – node p2 – outlet segment q3 to 0 Pa. Unknowns p0 q1 p1 qa qb p2 q3; physical
    /// scales (Pa, m³/s: R ~ 1e7–1e9 Pa s/m³, L ~ 1e5 Pa s²/m³, C ~ 1e-10 m³/Pa, c = 5e-4 s).
    fn inlet_without_storage() -> (Vec<(usize, usize)>, Vec<f64>) {
        let (am, c) = (1.0, 5e-4);
        let (p0, q1, p1, qa, qb, p2, q3) = (0, 1, 2, 3, 4, 5, 6);
        let mut stamps = Vec::new();
        let mut vals = Vec::new();
        let mut put = |r: usize, col: usize, v: f64| {
            stamps.push((r, col));
            vals.push(v);
        };
        // node rows: α_m C on the diagonal (none at the inlet), +c per outflow, −c per inflow
        put(p0, p0, 0.0);
        for (node, cap) in [(p1, 1.3e-10), (p2, 0.7e-10)] {
            put(node, node, am * cap);
        }
        // branch rows: α_m L + c R on the diagonal, −c at the inlet's pressure, +c at the
        // outlet's (none for q3: its outlet is held at 0 Pa)
        for (q, from, to, r, l) in [
            (q1, p0, Some(p1), 2e7, 1e5),
            (qa, p1, Some(p2), 3e8, 4e5),
            (qb, p1, Some(p2), 5e8, 2e5),
            (q3, p2, None, 1e9, 1e5),
        ] {
            put(q, q, am * l + c * r);
            put(q, from, -c);
            put(from, q, c);
            if let Some(to) = to {
                put(q, to, c);
                put(to, q, -c);
            }
        }
        (stamps, vals)
    }

    /// The inlet's node without storage is held in the core, not sent with the whole
    /// network to the general LU: the factorisation stays a core elimination (the core grows
    /// by the inlet's node and segment), and its solve agrees with the general LU's and with
    /// the constructed solution to 1e-12 relative to each unknown's scale (another
    /// elimination order of seven unknowns: rounding at 1e-16 times condition numbers well
    /// below 1e4 here; a wrong pivot or a lost update is off at order one).
    #[test]
    fn an_inlet_without_storage_is_held_in_the_core() {
        let (stamps, vals) = inlet_without_storage();
        let n = 7;
        // pressures of order 1e4 Pa, flows of order 1e-5 m³/s
        let x = [1.2e4, 3e-5, 1.1e4, 1.2e-5, 0.8e-5, 9e3, 1.9e-5];
        let mut b = vec![0.0; n];
        for (&(r, c), &v) in stamps.iter().zip(&vals) {
            b[r] += v * x[c];
        }
        let mut lu = SparseLu::analyse(n, &stamps).unwrap();
        let SparseLu::Core(c) = &lu else {
            panic!("not eliminated onto a core")
        };
        assert_eq!(c.core_len(), 4, "the loop: p1, qa, qb, p2");
        lu.factor(&vals).unwrap();
        let SparseLu::Core(c) = &lu else {
            panic!("fell back to the general LU")
        };
        assert_eq!(
            c.core_len(),
            6,
            "the loop with the inlet's node and segment"
        );
        let mut bc = b.clone();
        assert!(lu.solve_in_place(&mut bc));
        let mut general = GeneralLu::analyse(n, &stamps).unwrap();
        general.factor(&vals).unwrap();
        let mut bg = b.clone();
        assert!(general.solve_in_place(&mut bg));
        for i in 0..n {
            let scale = x[i].abs();
            assert!(
                (bc[i] - x[i]).abs() <= 1e-12 * scale,
                "{i}: {} vs {}",
                bc[i],
                x[i]
            );
            assert!(
                (bc[i] - bg[i]).abs() <= 1e-12 * scale,
                "{i}: {} vs {}",
                bc[i],
                bg[i]
            );
        }
    }

    /// A leaf without storage deep in a pendant tree of a large looped pattern is held with
    /// its path to the core (no fallback; the solution within 1e-10 of the constructed x:
    /// entries of order 1, |x| <= 1); more such leaves than [`MAX_HELD`] send the
    /// factorisation to the general LU of the whole pattern, which solves the system too;
    /// the 32-bit stamps the run analyses give the same elimination as `usize` ones (the
    /// same operations: the same bits).
    #[test]
    fn zero_pivots_in_pendant_trees_are_held_or_fall_back_to_the_general_lu() {
        let n = 3 * BLOCK + 17;
        let (stamps, vals, _, _) = looped_case(n, 0, 2, 99);
        let is_parent: Vec<bool> = {
            let mut p = vec![false; n];
            for &(r, c) in &stamps {
                if r > c {
                    p[c] = true;
                }
            }
            p
        };
        let leaves: Vec<usize> = (n / 2..n).filter(|&v| !is_parent[v]).collect();
        for (zeros, held) in [(1, true), (MAX_HELD + 1, false)] {
            let mut vals = vals.clone();
            // the last vertex is a leaf (no vertex after it picks it as parent): no storage
            for &v in leaves.iter().rev().take(zeros) {
                vals[stamps.iter().position(|&s| s == (v, v)).unwrap()] = 0.0;
            }
            let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
            let mut b = vec![0.0; n];
            for (&(r, c), &v) in stamps.iter().zip(&vals) {
                b[r] += v * x[c];
            }
            let narrow: Vec<(u32, u32)> =
                stamps.iter().map(|&(r, c)| (r as u32, c as u32)).collect();
            let mut solved = Vec::new();
            for mut lu in [
                SparseLu::analyse(n, &stamps).unwrap(),
                SparseLu::analyse(n, &narrow).unwrap(),
            ] {
                assert!(matches!(lu, SparseLu::Core(_)));
                lu.factor(&vals).unwrap();
                assert_eq!(matches!(lu, SparseLu::Core(_)), held, "{zeros} zero leaves");
                let mut out = b.clone();
                assert!(lu.solve_in_place(&mut out));
                for i in 0..n {
                    assert!((out[i] - x[i]).abs() < 1e-10, "{i}: {} vs {}", out[i], x[i]);
                }
                solved.push(out);
            }
            assert!(
                solved[0]
                    .iter()
                    .zip(&solved[1])
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
    }

    fn c_stamps(stamps: &[(usize, usize)]) -> Vec<(usize, usize)> {
        let n = stamps.iter().map(|&(r, _)| r + 1).max().unwrap();
        match SparseLu::<f64>::analyse(n, stamps).unwrap() {
            SparseLu::Core(c) => c.stamps(),
            _ => panic!("not a core"),
        }
    }

    /// The core solve on 1, 2 and 3 threads gives the same bits (the trees' passes do the same
    /// operations in the same order on any number of threads, the core is solved serially:
    /// exact equality is the claim), on a tree of several hundred blocks with three loops.
    #[test]
    fn core_solve_is_the_same_on_any_number_of_threads() {
        let n = 150_000;
        let (stamps, vals, x, b) = looped_case(n, 2, 3, 7);
        let solve = |threads: usize| {
            crate::threads::with_threads(Some(threads), || {
                let mut lu = SparseLu::analyse(n, &stamps).unwrap();
                let SparseLu::Core(c) = &lu else {
                    panic!("not a core")
                };
                assert_eq!(c.tree.partition.pool().is_some(), threads > 1);
                lu.factor(&vals).unwrap();
                let mut out = b.clone();
                assert!(lu.solve_in_place(&mut out));
                out
            })
            .unwrap()
        };
        super::super::tests::same_bits_on_any_number_of_threads(solve, &x);
    }
}
