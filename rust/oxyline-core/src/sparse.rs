//! Linear solves with the iteration matrices of the circuit. Tree-structured circuits (the
//! usual arterial tree) are eliminated leaves-to-root and back in O(n) with no fill-in; circuits
//! with loops (anastomoses, circle of Willis) use faer's sparse LU with the symbolic analysis
//! done once. Both refactorise numerically on demand.

use crate::error::{Error, Result};
use faer::Par;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::solvers::Solve;
use faer::perm::PermRef;
use faer::sparse::linalg::lu::{factorize_symbolic_lu, simplicial};
use faer::sparse::linalg::solvers::{Lu, SymbolicLu};
use faer::sparse::{Argsort, Pair, SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use std::ops::{AddAssign, Div, Mul, MulAssign, Sub, SubAssign};

mod core;
pub(crate) use core::two_core;
mod parallel;

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

/// A stamp's (row, column). A run's own iteration matrix gives 32-bit pairs (8 bytes a stamp:
/// a million-segment circuit has ~8 million stamps, alive while its elimination is analysed,
/// the setup's peak); the other callers' patterns are `usize` pairs.
pub trait Stamp: Copy {
    fn at(self) -> (usize, usize);
}

impl Stamp for (usize, usize) {
    fn at(self) -> (usize, usize) {
        self
    }
}

impl Stamp for (u32, u32) {
    fn at(self) -> (usize, usize) {
        (self.0 as usize, self.1 as usize)
    }
}

/// Which elimination a matrix pattern gets.
// (one per run or per frequency: the tree's inline 232 bytes cost nothing, and the tree
// elimination, the common path, is reached without an indirection)
#[allow(clippy::large_enum_variant)]
pub enum SparseLu<T: Scalar = f64> {
    Tree(TreeLu<T>),
    /// Pendant trees eliminated onto a small core with loops (see [`core::CoreLu`]).
    Core(Box<core::CoreLu<T>>),
    General(Box<GeneralLu<T>>),
}

impl<T: Scalar> SparseLu<T> {
    /// `stamps` are the (row, col) positions of the values later passed to `factor`, in order;
    /// duplicates are summed. A forest pattern gets the O(n) tree elimination; a pattern with
    /// loops gets it on its pendant trees and the general LU on its loop-carrying core alone.
    pub fn analyse<S: Stamp>(n: usize, stamps: &[S]) -> Result<Self> {
        if let Some(t) = TreeLu::analyse(n, stamps) {
            return Ok(SparseLu::Tree(t));
        }
        match core::CoreLu::analyse(n, stamps)? {
            Some(c) => Ok(SparseLu::Core(Box::new(c))),
            None => Ok(SparseLu::General(Box::new(GeneralLu::analyse(n, stamps)?))),
        }
    }

    pub fn factor(&mut self, vals: &[T]) -> std::result::Result<(), String> {
        self.factor_naming(vals, &|i| format!("unknown {i}"))
    }

    /// `factor`, naming the unknowns by `name` in the report of a zero pivot that sends the
    /// elimination to the pivoting LU (written to stderr when `OXYLINE_REPORT_PIVOT` is set:
    /// a diagnosis of which row of a network breaks the O(n) elimination, not an output).
    pub fn factor_naming(
        &mut self,
        vals: &[T],
        name: &dyn Fn(usize) -> String,
    ) -> std::result::Result<(), String> {
        // a (near-)zero pivot, e.g. an ideal wire eliminated first or a pendant junction
        // without storage: fall back to the pivoting LU on the same pattern. Its symbolic
        // analysis is the largest allocation of a run's setup (~350 B per segment with loops),
        // so the elimination's values go first and the pattern is handed over as the one list
        // the analysis reads (at 306 000 segments the elimination's values, the pattern and
        // its copy beside the analysis were ~130 MB of the peak)
        let (n, stamps) = match self {
            SparseLu::Tree(t) => {
                if t.factor(vals) {
                    return Ok(());
                }
                if pivot_report_wanted() {
                    report_zero_pivots(&t.zero_pivots(vals), name);
                }
                t.release_values();
                (t.n, t.stamps())
            }
            SparseLu::Core(c) => {
                if c.factor(vals)? {
                    return Ok(());
                }
                let zeros = c.tree_mut().zero_pivots(vals);
                report_zero_pivots(&zeros, name);
                if let Some(held) = c.holding(&zeros, vals)? {
                    if pivot_report_wanted() {
                        eprintln!(
                            "zero pivot: {} row(s) held in the core, which grows from {} to {} \
                             unknowns (of {})",
                            zeros.len(),
                            c.core_len(),
                            held.core_len(),
                            held.n()
                        );
                    }
                    *self = SparseLu::Core(Box::new(held));
                    return Ok(());
                }
                c.release_values();
                (c.n(), c.stamps())
            }
            SparseLu::General(g) => return g.factor(vals),
        };
        // (the same 16 bytes a stamp: collected in place)
        let pairs = stamps.into_iter().map(|(r, c)| Pair::new(r, c)).collect();
        let g = GeneralLu::from_pairs(n, pairs).map_err(|e| e.to_string())?;
        *self = SparseLu::General(Box::new(g));
        let SparseLu::General(g) = self else {
            unreachable!("replaced by the general LU")
        };
        g.factor(vals)
    }

    /// Solve in place; returns false if the solution is not finite (singular matrix).
    pub fn solve_in_place(&self, rhs: &mut [T]) -> bool {
        match self {
            SparseLu::Tree(t) => t.solve_in_place(rhs),
            SparseLu::Core(c) => c.solve_in_place(rhs),
            SparseLu::General(g) => g.solve_in_place(rhs),
        }
    }

    pub fn is_tree(&self) -> bool {
        matches!(self, SparseLu::Tree(_))
    }

    /// Drop the tree elimination's map from the stamps to its values (4 bytes a stamp, ~36
    /// bytes per segment of a large tree) once the matrix has its factors for good: a fixed
    /// step's one factorisation of a linear circuit solves every step of the run with them.
    /// Whether it was dropped (the tree elimination only); [`SparseLu::restore_slots`] makes
    /// it again before another `factor`.
    pub fn release_slots(&mut self) -> bool {
        match self {
            SparseLu::Tree(t) => {
                t.slots = Vec::new();
                true
            }
            _ => false,
        }
    }

    /// The map [`SparseLu::release_slots`] dropped, made again from the same `stamps` as
    /// `analyse` was given (the same map: a `factor` after it sums the same values).
    pub fn restore_slots<S: Stamp>(&mut self, stamps: &[S]) {
        if let SparseLu::Tree(t) = self {
            t.restore_slots(stamps);
        }
    }
}

/// Whether a zero pivot's report is asked for (`OXYLINE_REPORT_PIVOT` set; read once).
fn pivot_report_wanted() -> bool {
    static WANTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *WANTED.get_or_init(|| std::env::var_os("OXYLINE_REPORT_PIVOT").is_some())
}

/// The report of the zero pivots that failed an elimination, if asked for: each unknown,
/// its pivot against the terms that formed it, its own diagonal, its parent and children in
/// the elimination.
fn report_zero_pivots(zeros: &[ZeroPivot], name: &dyn Fn(usize) -> String) {
    if !pivot_report_wanted() {
        return;
    }
    for z in zeros.iter().take(10) {
        let parent = match z.parent {
            Some(p) => name(p),
            None => "none (a root)".to_owned(),
        };
        let children: Vec<String> = z.children.iter().map(|&c| name(c)).collect();
        eprintln!(
            "zero pivot: {} (unknown {}): pivot {:e} against its row scale {:e} (own \
             diagonal {:e}); eliminated into {}; its children in the elimination: [{}]",
            name(z.unknown),
            z.unknown,
            z.pivot,
            z.scale,
            z.diagonal,
            parent,
            children.join("; ")
        );
    }
    if zeros.len() > 10 {
        eprintln!("zero pivot: and {} more", zeros.len() - 10);
    }
}

/// Where the tree elimination met a (near-)zero pivot (see [`TreeLu::zero_pivots`]).
pub(crate) struct ZeroPivot {
    pub unknown: usize,
    /// |pivot| after its children's updates, and the sum of the magnitudes that formed it.
    pub pivot: f64,
    pub scale: f64,
    /// |diagonal| before any update.
    pub diagonal: f64,
    pub parent: Option<usize>,
    pub children: Vec<usize>,
}

/// Where a stamped value goes in the tree factorisation, packed into 32 bits (a million-
/// segment circuit has ~7 million stamps): the vertex v times 4 plus the kind.
const DIAG: u32 = 0;
/// K[v, parent(v)]
const UP: u32 = 1;
/// K[parent(v), v]
const DOWN: u32 = 2;
/// A stamp outside the tree: a coupling between two vertices of the loop-carrying core, which
/// the core's own LU takes (see [`core::CoreLu`]).
const SKIP: u32 = 3;

/// Gaussian elimination without pivoting in post-order of a spanning forest of the matrix graph.
/// Stable here because the circuit matrices are diagonal-positive with skew-symmetric couplings
/// (node–branch incidence), so every Schur update adds c²/d > 0 to the parent's pivot.
///
/// Memory order: the forest is cut into blocks, subtrees of at most `BLOCK` vertices, taken in
/// depth-first post-order (the vertices above the blocks in that order too), each block
/// eliminated in reverse breadth-first order; every per-vertex value is stored at the vertex's
/// position in that order, so factor and solve stream their arrays and a block's right side
/// stays in cache. One breadth-first order over the whole forest, as before, visited a whole
/// generation of vessels together and touched each vessel's cache lines once per graph level
/// (at a million segments the solve was dominated by cache misses); a plain depth-first order
/// chains every vertex on the one before (its child), a store-to-load dependency per vertex
/// that made small trees ~20 % slower; within a block, breadth-first levels are independent.
/// The children of a vertex are eliminated in the same order as the one breadth-first
/// elimination did (the reverse of their adjacency order), so every pivot and right side
/// receives its updates in the same order: the same bits.
pub struct TreeLu<T: Scalar = f64> {
    n: usize,
    /// Packed slot (`k << 2 | kind`, k the position in the elimination order) of every stamp;
    /// the stamps themselves follow from the slots, `vertex` and `parent_pos` (see `stamps`).
    slots: Vec<u32>,
    /// The vertex (unknown) at each position of the elimination order (every vertex after all
    /// of its children).
    vertex: Vec<u32>,
    up: Vec<T>,
    /// K[parent(v), v], divided by the pivot after `factor`
    down: Vec<T>,
    /// The diagonal while `factor` sums the stamps, then the pivots, stored as reciprocals
    /// (one array: the diagonal is not needed after the elimination).
    pivot: Vec<T>,
    /// The position of each vertex's parent in the elimination order (NONE for a root); the
    /// parent vertex is `vertex[parent_pos[k]]` (`parent_vertex`: a table of parent vertices
    /// beside it was 4 bytes per unknown for the run's life).
    parent_pos: Vec<u32>,
    /// The blocks solved in parallel and the top tree solved serially (see `parallel`).
    partition: Box<parallel::Partition>,
    /// `factor`'s per-vertex magnitudes, kept from one factorisation to the next once the
    /// matrix has been factorised twice (an error-controlled run refactorises at nearly every
    /// step); dropped after the first (a fixed step factorises once: 8 bytes per unknown
    /// less under a large tree's running peak).
    magnitude: Vec<f64>,
    /// `eliminate` has run before (see `magnitude`).
    refactored: bool,
    /// Positions (increasing) of the roots that are held, not eliminated: the vertices of a
    /// loop-carrying core, whose Schur-complemented pivots and right sides the core's LU takes
    /// between the forward and the backward pass. Empty for a forest.
    held: Vec<u32>,
}

const NONE: u32 = u32::MAX;

/// The packed slot of stamp (r, c) (see `DIAG`): `pos` the position of each vertex in the
/// elimination order, `parent_of` each vertex's parent vertex, `in_core` whether a vertex is
/// a held root of a loop-carrying core.
fn slot_of(
    (r, c): (usize, usize),
    pos: &[u32],
    parent_of: impl Fn(usize) -> u32,
    in_core: impl Fn(usize) -> bool,
) -> u32 {
    if r == c {
        pos[r] << 2 | DIAG
    } else if in_core(r) && in_core(c) {
        SKIP
    } else if parent_of(r) == c as u32 {
        pos[r] << 2 | UP
    } else {
        pos[c] << 2 | DOWN
    }
}

/// Whether position `k` is among the `held` positions (increasing; a core's few vertices).
fn is_held(held: &[u32], k: usize) -> bool {
    !held.is_empty() && held.binary_search(&(k as u32)).is_ok()
}

/// Largest subtree eliminated breadth-first as one block: its right side and factors (~50 B
/// per vertex) stay in L2 between the vertices of a level and their parents.
const BLOCK: usize = 2048;

/// The undirected adjacency (CSR: start, neighbours) of the off-diagonal pattern, or None if
/// it has at least as many edges as vertices (then it cannot be a forest).
///
/// The edges and starts are u32 (a tree's `analyse` takes fewer than 2^30 vertices, so fewer
/// than 2^31 edge ends): this runs while a run sets up, beside the stamps, and its 16-byte
/// edges were ~80 bytes per segment of the setup's peak at a million segments.
fn adjacency<S: Stamp>(n: usize, stamps: &[S]) -> Option<(Vec<u32>, Vec<u32>)> {
    let edges = edges(stamps, |_, _| true);
    if edges.len() >= n {
        return None;
    }
    Some(csr(n, &edges))
}

/// The distinct undirected off-diagonal edges (low, high) of the stamps that `keep` accepts.
fn edges<S: Stamp>(stamps: &[S], keep: impl Fn(usize, usize) -> bool) -> Vec<(u32, u32)> {
    let mut edges: Vec<(u32, u32)> = stamps
        .iter()
        .map(|s| s.at())
        .filter(|&(r, c)| r != c && keep(r, c))
        .map(|(r, c)| (r.min(c) as u32, r.max(c) as u32))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    edges
}

/// The adjacency (CSR: start, neighbours) of `n` vertices joined by `edges`.
fn csr(n: usize, edges: &[(u32, u32)]) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; n + 1];
    for &(a, b) in edges {
        start[a as usize + 1] += 1;
        start[b as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut adj = vec![0u32; start[n] as usize];
    let mut fill = start.clone();
    for &(a, b) in edges {
        let (a, b) = (a as usize, b as usize);
        adj[fill[a] as usize] = b as u32;
        fill[a] += 1;
        adj[fill[b] as usize] = a as u32;
        fill[b] += 1;
    }
    (start, adj)
}

/// The elimination order: blocks of at most `BLOCK` vertices (each in reverse breadth-first
/// order, children in adjacency order) and the vertices above them, in the depth-first
/// post-order `post` (see `TreeLu`); with the blocks' position ranges.
fn blocked_order(
    start: &[u32],
    adj: &[u32],
    post: &[u32],
    parent: &[u32],
) -> (Vec<u32>, Vec<(u32, u32)>) {
    let n = post.len();
    // subtree sizes (below 2^30 vertices: u32, as every per-vertex index here)
    let mut size = vec![1u32; n];
    for &v in post {
        let p = parent[v as usize];
        if p != NONE {
            size[p as usize] += size[v as usize];
        }
    }
    let mut order: Vec<u32> = Vec::with_capacity(n);
    let mut blocks = Vec::new();
    let mut bfs: Vec<u32> = Vec::with_capacity(BLOCK);
    for &v in post {
        let p = parent[v as usize];
        let in_block = size[v as usize] as usize <= BLOCK;
        if !in_block {
            order.push(v);
        } else if p == NONE || size[p as usize] as usize > BLOCK {
            // a block root: its subtree breadth-first, reversed
            bfs.clear();
            bfs.push(v);
            let mut head = 0;
            while head < bfs.len() {
                let u = bfs[head] as usize;
                head += 1;
                for &w in &adj[start[u] as usize..start[u + 1] as usize] {
                    if w != parent[u] {
                        bfs.push(w);
                    }
                }
            }
            let first = order.len() as u32;
            order.extend(bfs.iter().rev());
            blocks.push((first, order.len() as u32));
        }
    }
    (order, blocks)
}

/// Depth-first post-order of the forest from every unvisited vertex in turn (the vertices
/// `roots` first, then the others in increasing order), each vertex's children taken in
/// reverse adjacency order; with the parent of every vertex. None if the graph has a loop (an
/// edge to a visited vertex other than the parent).
fn post_order(n: usize, start: &[u32], adj: &[u32], roots: &[u32]) -> Option<(Vec<u32>, Vec<u32>)> {
    let mut parent = vec![NONE; n];
    let mut seen = vec![false; n];
    let mut order: Vec<u32> = Vec::with_capacity(n);
    // (vertex, number of its neighbours still to visit, counted from the end of its list)
    let mut stack: Vec<(u32, usize)> = Vec::new();
    for root in roots.iter().map(|&r| r as usize).chain(0..n) {
        if seen[root] {
            continue;
        }
        seen[root] = true;
        stack.push((root as u32, (start[root + 1] - start[root]) as usize));
        while let Some(top) = stack.last_mut() {
            let v = top.0 as usize;
            if top.1 == 0 {
                order.push(v as u32);
                stack.pop();
                continue;
            }
            top.1 -= 1;
            let w = adj[start[v] as usize + top.1] as usize;
            if w as u32 == parent[v] {
                continue;
            }
            if seen[w] {
                return None;
            }
            seen[w] = true;
            parent[w] = v as u32;
            stack.push((w as u32, (start[w + 1] - start[w]) as usize));
        }
    }
    Some((order, parent))
}

impl<T: Scalar> TreeLu<T> {
    fn analyse<S: Stamp>(n: usize, stamps: &[S]) -> Option<Self> {
        // positions are packed with two tag bits into u32 slots
        if n >= (1 << 30) {
            return None;
        }
        let (start, adj) = adjacency(n, stamps)?;
        Self::analyse_forest(n, stamps, (start, adj), None)
    }

    /// The elimination of the forest `(start, adj)` (the stamps' graph, or the part of it
    /// outside a loop-carrying core). With `core` (per vertex: in the core), the core's vertices
    /// are the forest's held roots and the stamps joining two of them are left out (`SKIP`).
    fn analyse_forest<S: Stamp>(
        n: usize,
        stamps: &[S],
        (start, adj): (Vec<u32>, Vec<u32>),
        core: Option<&[bool]>,
    ) -> Option<Self> {
        let in_core = |v: usize| core.is_some_and(|c| c[v]);
        let roots: Vec<u32> = (0..n as u32).filter(|&v| in_core(v as usize)).collect();
        let (post, parent_of) = post_order(n, &start, &adj, &roots)?;
        let (vertex, blocks) = blocked_order(&start, &adj, &post, &parent_of);
        drop((start, adj, post));
        let mut pos = vec![0u32; n];
        for (k, &v) in vertex.iter().enumerate() {
            pos[v as usize] = k as u32;
        }
        let parent_pos: Vec<u32> = vertex
            .iter()
            .map(|&v| match parent_of[v as usize] {
                NONE => NONE,
                p => pos[p as usize],
            })
            .collect();
        let partition = Box::new(parallel::Partition::new(n, &blocks, &parent_pos));
        let slots = stamps
            .iter()
            .map(|s| slot_of(s.at(), &pos, |v| parent_of[v], in_core))
            .collect();
        let mut held: Vec<u32> = roots.iter().map(|&v| pos[v as usize]).collect();
        held.sort_unstable();
        Some(TreeLu {
            n,
            slots,
            vertex,
            up: vec![T::ZERO; n],
            down: vec![T::ZERO; n],
            pivot: vec![T::ZERO; n],
            parent_pos,
            partition,
            magnitude: Vec::new(),
            refactored: false,
            held,
        })
    }

    /// The parent vertex of the vertex at position `k` (NONE for a root).
    #[inline]
    fn parent_vertex(&self, k: usize) -> u32 {
        match self.parent_pos[k] {
            NONE => NONE,
            p => self.vertex[p as usize],
        }
    }

    /// Whether the root at position `k` is held for a core's LU.
    fn is_held(&self, k: usize) -> bool {
        is_held(&self.held, k)
    }

    /// Vertex `k`'s pivot (judged against its `magnitude` when `check`) eliminated into its
    /// parent's: the one step of the tree factorisation, serial or in the top tree.
    fn eliminate_into_parent(&mut self, k: usize, magnitude: &mut [f64], check: bool) -> bool {
        let d = self.pivot[k];
        let p = self.parent_pos[k];
        // a held root's pivot is a core's diagonal, judged by the core's pivoting LU
        if p == NONE && self.is_held(k) {
            return true;
        }
        if check && (d.modulus() <= 1e-12 * magnitude[k] || !d.finite()) {
            return false;
        }
        if p != NONE {
            let p = p as usize;
            let update = self.down[k] * self.up[k] / d;
            self.pivot[p] -= update;
            magnitude[p] += update.modulus();
        }
        true
    }

    fn factor(&mut self, vals: &[T]) -> bool {
        if !self.eliminate(vals) {
            return false;
        }
        self.invert_pivots();
        true
    }

    /// The stamps summed into the diagonal and the couplings (sized here: `release_values`
    /// may have dropped them).
    fn load(&mut self, vals: &[T]) {
        debug_assert!(
            !self.slots.is_empty() || vals.is_empty(),
            "a released slot map not restored"
        );
        for values in [&mut self.pivot, &mut self.up, &mut self.down] {
            values.clear();
            values.resize(self.n, T::ZERO);
        }
        for (&slot, &v) in self.slots.iter().zip(vals) {
            let k = (slot >> 2) as usize;
            match slot & 3 {
                DIAG => self.pivot[k] += v,
                UP => self.up[k] += v,
                DOWN => self.down[k] += v,
                _ => {}
            }
        }
    }

    /// Every vertex whose pivot `eliminate` judges (near-)zero, in the elimination order: a
    /// serial elimination of `vals` (the same operations as the parallel one: the same set on
    /// any number of threads) in which such a vertex is left out of its parent's pivot, as a
    /// held root is. A diagnosis after a failed factorisation, not a step's work.
    fn zero_pivots(&mut self, vals: &[T]) -> Vec<ZeroPivot> {
        self.load(vals);
        let diagonal: Vec<f64> = self.pivot.iter().map(|d| d.modulus()).collect();
        let mut magnitude = diagonal.clone();
        let failed: Vec<usize> = (0..self.n)
            .filter(|&k| !self.eliminate_into_parent(k, &mut magnitude, true))
            .collect();
        failed
            .into_iter()
            .map(|k| ZeroPivot {
                unknown: self.vertex[k] as usize,
                pivot: self.pivot[k].modulus(),
                scale: magnitude[k],
                diagonal: diagonal[k],
                parent: Some(self.parent_vertex(k))
                    .filter(|&p| p != NONE)
                    .map(|p| p as usize),
                children: (0..k)
                    .filter(|&j| self.parent_pos[j] == k as u32)
                    .map(|j| self.vertex[j] as usize)
                    .collect(),
            })
            .collect()
    }

    /// The stamps summed and the elimination leaves-to-roots (pivots not yet inverted); false
    /// at a (near-)zero pivot.
    fn eliminate(&mut self, vals: &[T]) -> bool {
        self.load(vals);
        // per-vertex magnitude: the units of pressure and flow rows differ by many decades, so a
        // pivot is judged against the terms that formed it, not a global scale
        let mut magnitude = std::mem::take(&mut self.magnitude);
        magnitude.clear();
        magnitude.extend(self.pivot.iter().map(|d| d.modulus()));
        let eliminated = match self.partition.pool() {
            Some(pool) => pool.install(|| self.eliminate_parallel(&mut magnitude)),
            None => (0..self.n).all(|k| self.eliminate_into_parent(k, &mut magnitude, true)),
        };
        if self.refactored {
            self.magnitude = magnitude;
        }
        self.refactored = true;
        eliminated
    }

    /// Store the multipliers and reciprocal pivots so that solves only multiply.
    fn invert_pivots(&mut self) {
        for (pivot, down) in self.pivot.iter_mut().zip(&mut self.down) {
            *pivot = T::ONE / *pivot;
            *down *= *pivot;
        }
    }

    /// Solve in place with the factors; whether the solution is finite. On more than one
    /// thread (the current rayon pool) a large tree's blocks are solved in parallel, with the
    /// same bits (see `parallel`).
    fn solve_in_place(&self, b: &mut [T]) -> bool {
        if let Some(pool) = self.partition.pool() {
            return pool.install(|| self.solve_parallel(b));
        }
        self.forward(b);
        self.backward(b)
    }

    /// The forward pass of a serial solve: every vertex's right side folded into its parent's.
    fn forward(&self, b: &mut [T]) {
        let vertex = &self.vertex;
        for ((&v, &pp), &down) in vertex.iter().zip(&self.parent_pos).zip(&self.down) {
            if pp != NONE {
                b[vertex[pp as usize] as usize] -= down * b[v as usize];
            }
        }
    }

    /// The back substitution of a serial solve, roots to leaves; whether it is finite.
    fn backward(&self, b: &mut [T]) -> bool {
        let mut finite = true;
        let vertex = &self.vertex;
        for (((&v, &pp), &up), &pivot) in vertex
            .iter()
            .zip(&self.parent_pos)
            .zip(&self.up)
            .zip(&self.pivot)
            .rev()
        {
            let v = v as usize;
            let up = if pp != NONE {
                up * b[vertex[pp as usize] as usize]
            } else {
                T::ZERO
            };
            b[v] = (b[v] - up) * pivot;
            finite &= b[v].finite();
        }
        finite
    }

    /// Drop the factorisation's values (the analysis stays: the next `factor` sizes them
    /// again), before the pivoting fallback builds its own.
    fn release_values(&mut self) {
        for values in [&mut self.pivot, &mut self.up, &mut self.down] {
            *values = Vec::new();
        }
        self.magnitude = Vec::new();
    }

    /// The slots made again from the `stamps` that `analyse` was given (after
    /// `SparseLu::release_slots`): the same map, from the order, the parents and the held
    /// roots the analysis left.
    fn restore_slots<S: Stamp>(&mut self, stamps: &[S]) {
        let mut pos = vec![0u32; self.n];
        for (k, &v) in self.vertex.iter().enumerate() {
            pos[v as usize] = k as u32;
        }
        let held = &self.held;
        let slots = stamps
            .iter()
            .map(|s| {
                let parent_of = |v: usize| self.parent_vertex(pos[v] as usize);
                let in_core = |v: usize| is_held(held, pos[v] as usize);
                slot_of(s.at(), &pos, parent_of, in_core)
            })
            .collect();
        self.slots = slots;
    }

    /// The (row, col) stamps the slots were made from, in order (for the pivoting fallback).
    fn stamps(&self) -> Vec<(usize, usize)> {
        self.slots.iter().map(|&slot| self.stamp_of(slot)).collect()
    }

    /// The (row, col) of a tree slot (not a `SKIP` one).
    fn stamp_of(&self, slot: u32) -> (usize, usize) {
        let k = (slot >> 2) as usize;
        let (v, p) = (self.vertex[k] as usize, self.parent_vertex(k) as usize);
        match slot & 3 {
            DIAG => (v, v),
            UP => (v, p),
            _ => (p, v),
        }
    }
}

pub struct GeneralLu<T: Scalar = f64> {
    n: usize,
    sym: SymbolicSparseColMat<usize>,
    order: Argsort<usize>,
    factors: Factors<T>,
}

/// How a pattern with loops is factorised: faer picks a simplicial or a supernodal LU from the
/// pattern. Simplicial factors (every circuit here so far: a few loops on a tree) are kept
/// and solved with by [`Simplicial`]; supernodal ones go through faer's solver.
enum Factors<T: Scalar> {
    Simplicial(Box<Simplicial<T>>),
    Faer(Box<FaerLu<T>>),
}

struct FaerLu<T: Scalar> {
    sym_lu: SymbolicLu<usize>,
    lu: Option<Lu<usize, T>>,
}

/// A simplicial sparse LU (P A Q = L U, faer's numeric factorisation on faer's column
/// ordering) with its own solve: the same operations as faer's `solve_in_place` in the same
/// order, so the same bits, without its per-solve scratch allocation and copies of the right
/// side (the permutations are applied in place along their cycles). The time stepping solves
/// once per step, and for a 500-segment network with a circle of Willis those copies cost as
/// much as the triangular solves.
struct Simplicial<T: Scalar> {
    col_perm_fwd: Vec<usize>,
    col_perm_inv: Vec<usize>,
    lu: simplicial::SimplicialLu<usize, T>,
    row_perm_fwd: Vec<usize>,
    row_perm_inv: Vec<usize>,
    /// x ← P x and x ← Q x as cycles (see [`Cycles`]); None before `factor`
    row_cycles: Cycles,
    col_cycles: Cycles,
    /// 1 / U[j, j] (faer's `recip`, as its solve computes it)
    u_recip: Vec<T>,
    factored: bool,
}

/// A permutation `x_new[i] = x[p[i]]` as its cycles: each cycle `c0 c1 ... ck` (with
/// `p[c_m] = c_{m+1}`, `p[c_k] = c0`) moves `x[c1]` to `c0`, ..., `x[c0]` to `ck`. Fixed points
/// are left out. 32-bit indices (the circuit refuses more than 2^32 unknowns) held at their
/// exact size: a network with loops keeps two of these beside its factors, one index per
/// moved unknown each (16 instead of up to 32 bytes per unknown grown by doubling).
#[derive(Default)]
struct Cycles {
    ptr: Vec<u32>,
    idx: Vec<u32>,
}

impl Cycles {
    fn of(p: &[usize]) -> Cycles {
        let mut seen = vec![false; p.len()];
        let moved = p.iter().enumerate().filter(|&(i, &j)| i != j).count();
        let mut c = Cycles {
            ptr: vec![0],
            idx: Vec::with_capacity(moved),
        };
        for s in 0..p.len() {
            if seen[s] || p[s] == s {
                continue;
            }
            let mut i = s;
            while !seen[i] {
                seen[i] = true;
                c.idx.push(i as u32);
                i = p[i];
            }
            c.ptr.push(c.idx.len() as u32);
        }
        c.ptr.shrink_to_fit();
        c
    }

    fn apply<T: Copy>(&self, x: &mut [T]) {
        for w in self.ptr.windows(2) {
            let cyc = &self.idx[w[0] as usize..w[1] as usize];
            let first = x[cyc[0] as usize];
            for m in 1..cyc.len() {
                x[cyc[m - 1] as usize] = x[cyc[m] as usize];
            }
            x[cyc[cyc.len() - 1] as usize] = first;
        }
    }
}

impl<T: Scalar> Simplicial<T> {
    fn factor(&mut self, a: SparseColMatRef<'_, usize, T>) -> std::result::Result<(), String> {
        let n = a.nrows();
        self.factored = false;
        self.row_perm_fwd.resize(n, 0);
        self.row_perm_inv.resize(n, 0);
        let mut mem = MemBuffer::new(simplicial::factorize_simplicial_numeric_lu_scratch::<
            usize,
            T,
        >(n, n));
        simplicial::factorize_simplicial_numeric_lu(
            &mut self.row_perm_fwd,
            &mut self.row_perm_inv,
            &mut self.lu,
            a,
            PermRef::new_checked(&self.col_perm_fwd, &self.col_perm_inv, n),
            MemStack::new(&mut mem),
        )
        .map_err(|e| format!("{e:?}"))?;
        let u = self.lu.u_factor_unsorted();
        // the diagonal is the last entry of each column of U
        self.u_recip = (0..n)
            .map(|j| T::recip_impl(u.val_of_col(j).last().expect("U has a diagonal")))
            .collect();
        self.row_cycles = Cycles::of(&self.row_perm_fwd);
        // faer applies Q through its inverse's forward array
        self.col_cycles = Cycles::of(&self.col_perm_inv);
        self.factored = true;
        Ok(())
    }

    /// faer's simplicial `solve_in_place_with_conj` (no conjugation, one right side).
    fn solve_in_place(&self, x: &mut [T]) {
        assert!(self.factored, "factor before solve");
        self.row_cycles.apply(x);
        let l = self.lu.l_factor_unsorted();
        for j in 0..x.len() {
            let xj = x[j];
            // unit diagonal, stored first
            let rows = &l.row_idx_of_col_raw(j)[1..];
            for (&i, &lij) in rows.iter().zip(&l.val_of_col(j)[1..]) {
                x[i] -= lij * xj;
            }
        }
        let u = self.lu.u_factor_unsorted();
        for j in (0..x.len()).rev() {
            let xj = x[j] * self.u_recip[j];
            x[j] = xj;
            let rows = u.row_idx_of_col_raw(j);
            let vals = u.val_of_col(j);
            let k = rows.len() - 1; // the diagonal, stored last
            for (&i, &uij) in rows[..k].iter().rev().zip(vals[..k].iter().rev()) {
                x[i] -= uij * xj;
            }
        }
        self.col_cycles.apply(x);
    }
}

impl<T: Scalar> GeneralLu<T> {
    pub fn analyse<S: Stamp>(n: usize, stamps: &[S]) -> Result<Self> {
        let pairs = stamps
            .iter()
            .map(|s| {
                let (r, c) = s.at();
                Pair::new(r, c)
            })
            .collect();
        Self::from_pairs(n, pairs)
    }

    /// [`GeneralLu::analyse`] of the stamps as faer's pairs, dropped once the pattern is built
    /// (before the symbolic analysis, the largest allocation).
    fn from_pairs(n: usize, pairs: Vec<Pair<usize, usize>>) -> Result<Self> {
        let (sym, order) = SymbolicSparseColMat::try_new_from_indices(n, n, &pairs)
            .map_err(|e| Error::solver(0.0, format!("sparse pattern: {e:?}")))?;
        drop(pairs);
        // faer's own choice (`SymbolicLu::try_new`: default parameters); its simplicial
        // factorisation is the one whose numeric scratch is exactly the simplicial one (the
        // supernodal one also holds a transposed copy of the matrix)
        let raw = factorize_symbolic_lu(sym.as_ref(), Default::default())
            .map_err(|e| Error::solver(0.0, format!("symbolic LU: {e:?}")))?;
        let simplicial_scratch =
            simplicial::factorize_simplicial_numeric_lu_scratch::<usize, T>(n, n);
        let factors = if raw.factorize_numeric_lu_scratch::<T>(Par::Seq, Default::default())
            == simplicial_scratch
        {
            let (fwd, inv) = raw.col_perm().arrays();
            Factors::Simplicial(Box::new(Simplicial {
                col_perm_fwd: fwd.to_vec(),
                col_perm_inv: inv.to_vec(),
                lu: simplicial::SimplicialLu::new(),
                row_perm_fwd: Vec::new(),
                row_perm_inv: Vec::new(),
                row_cycles: Cycles::default(),
                col_cycles: Cycles::default(),
                u_recip: Vec::new(),
                factored: false,
            }))
        } else {
            // the supernodal factorisation and solve multiply dense blocks: the linear
            // algebra's per-thread scratch, whose allocation cannot fail gracefully (faer
            // allocates its own numeric scratch fallibly)
            crate::run::memory::check_scratch()?;
            Factors::Faer(Box::new(FaerLu {
                sym_lu: SymbolicLu::try_new(sym.as_ref())
                    .map_err(|e| Error::solver(0.0, format!("symbolic LU: {e:?}")))?,
                lu: None,
            }))
        };
        Ok(GeneralLu {
            n,
            sym,
            order,
            factors,
        })
    }

    pub fn factor(&mut self, vals: &[T]) -> std::result::Result<(), String> {
        let a = SparseColMat::new_from_argsort(self.sym.clone(), &self.order, vals)
            .map_err(|e| format!("{e:?}"))?;
        match &mut self.factors {
            Factors::Simplicial(s) => s.factor(a.as_ref()),
            Factors::Faer(f) => {
                f.lu = Some(
                    Lu::try_new_with_symbolic(f.sym_lu.clone(), a.as_ref())
                        .map_err(|e| format!("{e:?}"))?,
                );
                Ok(())
            }
        }
    }

    pub fn solve_in_place(&self, rhs: &mut [T]) -> bool {
        debug_assert_eq!(rhs.len(), self.n);
        match &self.factors {
            Factors::Simplicial(s) => s.solve_in_place(rhs),
            Factors::Faer(f) => {
                let lu = f.lu.as_ref().expect("factor before solve");
                lu.solve_in_place(faer::ColMut::from_slice_mut(rhs));
            }
        }
        rhs.iter().all(|x| x.finite())
    }

    /// faer's own solve with the same factors (tests: the simplicial solve gives its bits).
    #[cfg(test)]
    fn solve_with_faer(&self, rhs: &mut [T]) {
        let Factors::Simplicial(s) = &self.factors else {
            panic!("not simplicial")
        };
        let n = self.n;
        let mut mem = MemBuffer::new(simplicial::solve_in_place_scratch::<usize, T>(
            n,
            1,
            Par::Seq,
        ));
        s.lu.solve_in_place_with_conj(
            PermRef::new_checked(&s.row_perm_fwd, &s.row_perm_inv, n),
            PermRef::new_checked(&s.col_perm_fwd, &s.col_perm_inv, n),
            faer::Conj::No,
            faer::MatMut::from_column_major_slice_mut(rhs, n, 1),
            Par::Seq,
            MemStack::new(&mut mem),
        );
    }
}

/// Solves the small dense system a · x = b (row-major n × n) in place by nalgebra's LU with
/// partial pivoting; false (b untouched) when a pivot is at most `tiny` in magnitude.
pub fn lu_solve(a: &[f64], b: &mut [f64], n: usize, tiny: f64) -> bool {
    let lu = nalgebra::DMatrix::from_row_slice(n, n, a).lu();
    if lu.u().diagonal().iter().any(|p| p.abs() <= tiny) {
        return false;
    }
    match lu.solve(&nalgebra::DVector::from_column_slice(b)) {
        Some(x) if x.iter().all(|v| v.is_finite()) => {
            b.copy_from_slice(x.as_slice());
            true
        }
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random tree-structured matrix with positive diagonal and skew couplings, plus a loop
    /// edge variant: tree elimination and faer's LU must agree with each other and with A x = b
    /// (one block, and several blocks under vertices eliminated outside any block).
    #[test]
    fn tree_elimination_matches_general_lu() {
        for n in [200, 3 * BLOCK + 17] {
            tree_elimination_case(n);
        }
    }

    fn tree_elimination_case(n: usize) {
        let mut stamps = Vec::new();
        let mut vals = Vec::new();
        let mut seed = 12345u64;
        let mut rnd = || crate::test_common::lcg(&mut seed);
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

    /// The tree elimination on 1, 2 and 3 threads gives the same bits (the same operations on
    /// every value in the same order: exact equality is the claim, not a tolerance) on trees of
    /// two shapes with several hundred blocks, and solves A x = b (to 1e-10: diagonally
    /// dominant entries of order 1, relative to |x| ≤ 1).
    #[test]
    fn tree_solve_is_the_same_on_any_number_of_threads() {
        for (n, fan) in [(150_000, 0usize), (100_000, 2)] {
            threads_case(n, fan);
        }
    }

    /// The tasks the threads take: every range once and in order, each task (but the last)
    /// at least `TASK_MIN` vertices and less than that plus its last range, so that the
    /// thread that finishes a pass first waits for at most about one task of the other.
    fn check_tasks(p: &parallel::Partition) {
        let tasks = p.tasks();
        let flat: Vec<(u32, u32)> = tasks.iter().flat_map(|t| t.iter().copied()).collect();
        assert_eq!(flat, p.ranges, "the tasks are the ranges in order");
        let size = |r: &[(u32, u32)]| r.iter().map(|&(a, b)| (b - a) as usize).sum::<usize>();
        assert!(
            tasks.len() > 2 * 4,
            "{} tasks: several for each of 4 threads",
            tasks.len()
        );
        for t in &tasks[..tasks.len() - 1] {
            let (n, last) = (size(t), size(&t[t.len() - 1..]));
            assert!(
                n >= parallel::TASK_MIN && n < parallel::TASK_MIN + last,
                "{n}"
            );
        }
    }

    /// A random recursive tree (`fan` 0) or a binary heap (`fan` 2) of `n` vertices.
    fn threads_case(n: usize, fan: usize) {
        let mut seed = 7u64;
        let mut rnd = || crate::test_common::lcg(&mut seed);
        let (mut stamps, mut vals) = (Vec::new(), Vec::new());
        for i in 0..n {
            stamps.push((i, i));
            vals.push(2.0 + rnd());
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
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut b = vec![0.0; n];
        for (&(r, c), &v) in stamps.iter().zip(&vals) {
            b[r] += v * x[c];
        }
        let solve = |threads: usize| {
            crate::threads::with_threads(Some(threads), || {
                let mut lu = SparseLu::analyse(n, &stamps).unwrap();
                let SparseLu::Tree(t) = &lu else {
                    panic!("not a tree")
                };
                assert_eq!(t.partition.pool().is_some(), threads > 1);
                assert!(t.partition.ranges.len() > 10);
                check_tasks(&t.partition);
                lu.factor(&vals).unwrap();
                let mut out = b.clone();
                assert!(lu.solve_in_place(&mut out));
                out
            })
            .unwrap()
        };
        same_bits_on_any_number_of_threads(solve, &x);
    }

    /// `solve(threads)` on one thread is the constructed solution `x` (to 1e-10: the
    /// elimination's rounding on these well-conditioned systems), and on 2 and 3 threads the
    /// serial solve's bits (a fixed partition and summation order).
    pub(super) fn same_bits_on_any_number_of_threads(solve: impl Fn(usize) -> Vec<f64>, x: &[f64]) {
        let serial = solve(1);
        for (i, (s, want)) in serial.iter().zip(x).enumerate() {
            assert!((s - want).abs() < 1e-10, "{i}: {s} vs {want}");
        }
        for threads in [2, 3] {
            let parallel = solve(threads);
            let same = serial
                .iter()
                .zip(&parallel)
                .all(|(s, p)| s.to_bits() == p.to_bits());
            assert!(same, "{threads} threads: not the serial bits");
        }
    }

    /// A tree-like pattern with loops (as a circle of Willis makes): the simplicial solve gives
    /// faer's solve bit for bit (same operations, same order) and solves A x = b (to 1e-12:
    /// well-conditioned, diagonally dominant entries of order 1).
    fn looped_solve_matches_faer<T: Scalar>(entry: impl Fn(f64, f64) -> T, n: usize) {
        let mut seed = 987654321u64;
        let mut rnd = || crate::test_common::lcg(&mut seed);
        let mut stamps = Vec::new();
        let mut vals = Vec::new();
        for i in 0..n {
            stamps.push((i, i));
            vals.push(entry(2.0 + rnd(), rnd()));
            let links = if i > 0 && i % 7 == 0 {
                2
            } else {
                usize::from(i > 0)
            };
            for _ in 0..links {
                let p = (rnd() * i as f64) as usize;
                let c = entry(0.5 + rnd(), rnd());
                stamps.extend([(i, p), (p, i)]);
                vals.extend([c, T::ZERO - c]);
            }
        }
        let x: Vec<T> = (0..n)
            .map(|i| entry((i as f64).sin(), (i as f64).cos()))
            .collect();
        let mut b = vec![T::ZERO; n];
        for (&(r, c), &v) in stamps.iter().zip(&vals) {
            b[r] += v * x[c];
        }
        let mut lu = GeneralLu::<T>::analyse(n, &stamps).unwrap();
        assert!(matches!(lu.factors, Factors::Simplicial(_)));
        for scale in [1.0, 3.0] {
            let scaled: Vec<T> = vals.iter().map(|&v| v * entry(scale, 0.0)).collect();
            lu.factor(&scaled).unwrap();
            let mut mine = b.clone();
            assert!(lu.solve_in_place(&mut mine));
            let mut theirs = b.clone();
            lu.solve_with_faer(&mut theirs);
            for i in 0..n {
                assert!(mine[i] == theirs[i], "{i}: not faer's bits");
                let want = x[i] * entry(1.0 / scale, 0.0);
                assert!((mine[i] - want).modulus() < 1e-12, "{i}");
            }
        }
    }

    #[test]
    fn simplicial_solve_is_fears_solve_real() {
        looped_solve_matches_faer(|re, _| re, 300);
    }

    #[test]
    fn simplicial_solve_is_fears_solve_complex() {
        looped_solve_matches_faer(faer::c64::new, 300);
    }

    #[test]
    fn permutation_cycles() {
        let p = [2, 0, 1, 3, 5, 4];
        let mut x = [10, 11, 12, 13, 14, 15];
        Cycles::of(&p).apply(&mut x);
        assert_eq!(x, [12, 10, 11, 13, 15, 14]); // x_new[i] = x[p[i]]
    }

    /// A tree elimination whose slot map was dropped after its factorisation still solves with
    /// its factors, and after the map is made again from the same stamps it factorises other
    /// values of the pattern: A x = b for a known x both times (to 1e-12: diagonally dominant
    /// entries of order 1), on a tree of several blocks with duplicated stamps.
    #[test]
    fn released_slots_made_again_factorise_the_same_pattern() {
        let n = 3 * BLOCK + 17;
        let mut seed = 777u64;
        let mut rnd = || crate::test_common::lcg(&mut seed);
        let mut stamps = Vec::new();
        for i in 0..n {
            stamps.push((i, i));
            if i > 0 {
                let p = (rnd() * i as f64) as usize;
                stamps.extend([(i, p), (p, i), (i, i)]);
            }
        }
        let values = |scale: f64, rnd: &mut dyn FnMut() -> f64| -> Vec<f64> {
            let mut vals = Vec::with_capacity(stamps.len());
            let mut k = 0;
            while k < stamps.len() {
                let (r, c) = stamps[k];
                if r == c {
                    vals.push(scale * (0.1 + rnd()));
                    k += 1;
                } else {
                    let v = scale * (0.5 + rnd());
                    vals.extend([v, -v, 0.25 * scale]);
                    k += 3;
                }
            }
            vals
        };
        let x: Vec<f64> = (0..n).map(|i| (i as f64).cos()).collect();
        let solves = |lu: &SparseLu, vals: &[f64]| {
            let mut b = vec![0.0; n];
            for (&(r, c), &v) in stamps.iter().zip(vals) {
                b[r] += v * x[c];
            }
            assert!(lu.solve_in_place(&mut b));
            for i in 0..n {
                assert!((b[i] - x[i]).abs() < 1e-12, "{i}: {} vs {}", b[i], x[i]);
            }
        };
        let mut lu = SparseLu::analyse(n, &stamps).unwrap();
        let first = values(1.0, &mut rnd);
        lu.factor(&first).unwrap();
        assert!(lu.release_slots());
        solves(&lu, &first);
        lu.restore_slots(&stamps);
        let second = values(3.0, &mut rnd);
        lu.factor(&second).unwrap();
        solves(&lu, &second);
        // the map made again is the analysis's own: the same factors, bit for bit
        let mut fresh = SparseLu::analyse(n, &stamps).unwrap();
        fresh.factor(&second).unwrap();
        let (mut a, mut b) = (x.clone(), x.clone());
        lu.solve_in_place(&mut a);
        fresh.solve_in_place(&mut b);
        assert!(a.iter().zip(&b).all(|(p, q)| p.to_bits() == q.to_bits()));
    }

    #[test]
    fn solves_a_small_system_and_reuses_the_pattern() {
        // [[4,1,0],[1,3,1],[0,1,2]]
        let stamps: [(usize, usize); 7] = [(0, 0), (0, 1), (1, 0), (1, 1), (1, 2), (2, 1), (2, 2)];
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
