//! The fused tree step (`fused.rs`) on the run's threads: the partition of a tree solve
//! (as the flow's tree elimination, `sparse::parallel`). The tree is cut into blocks —
//! subtrees of at most `BLOCK` nodes — which share no node, cell or face, so the forward and
//! backward passes eliminate and substitute them in parallel; the few nodes above them (the
//! top tree) and the terms each block root leaves in its parent's row are done serially, in
//! elimination order.
//!
//! A block's nodes are taken in elimination order, so every node's row receives its
//! children's terms in the serial pass's order, whichever thread eliminated them: the
//! concentrations and amounts are bit-identical to the serial pass's. The step's wall and
//! decay fluxes are sums over the cells: with a partition they are summed block by block (and
//! Σ wconst of a binding's linearisation chunk by chunk) in the partition's fixed order, on
//! one thread as on several, so a run's results are bit-identical for any number of threads
//! (they differ from a pass without a partition in the last bits of those two sums only).

use super::fused::{
    BackwardArrays, Cells, Exact, FaceFlows, ForwardArrays, Inversion, NodeBack, NodeRows,
    ParentTerms, Step,
};
use super::plan::Link;
use crate::hemoglobin::{Binding, HillAnchor};
use rayon::ThreadPool;
use rayon::prelude::*;
use std::marker::PhantomData;
use std::sync::Arc;

/// Largest block: its nodes' rows stay in L2 between a node and its parent.
const BLOCK: usize = 2048;
/// Least number of tree nodes for a partition: below it a pass takes tens of microseconds
/// and the threads' start costs more than they save.
const PARALLEL_MIN: usize = 1 << 14;
/// Least number of nodes (or cells) one task takes (several small blocks go to one thread).
/// Half a block (a task of about one block): the pass ends with its last task, and the other
/// thread waits for it (as the flow's tree elimination, `sparse::parallel`). Tasks group whole
/// blocks, whose sums are added block by block in order, so the task size changes no value.
const TASK_MIN: usize = BLOCK / 2;
/// Cells per chunk of the binding's linearisation (each chunk's Σ wconst in cell order).
const CHUNK: usize = 4096;

/// Tag of a block root in `TreePartition::serial` (positions are below 2³¹).
const ROOT: u32 = 1 << 31;

/// The blocks of a tree's elimination order (`Plan::tree`) and its serial remainder.
#[derive(Debug)]
pub(super) struct TreePartition {
    /// The positions of every block, block after block, each block's increasing.
    positions: Vec<u32>,
    /// Block b is `positions[ends[b]..ends[b + 1]]`; its root is its last position.
    ends: Vec<u32>,
    /// Runs of whole blocks of at least `task_min` positions (half-open block ranges).
    tasks: Vec<(u32, u32)>,
    /// In elimination order: the top tree's positions, and the block roots that have a
    /// parent (tagged `ROOT`, by block index), whose terms are added to it serially.
    serial: Vec<u32>,
    /// Cells per chunk of the linearisation.
    chunk: usize,
}

impl TreePartition {
    /// The partition of a tree of `nodes` domain nodes with blocks of at most `BLOCK` nodes,
    /// if it is large enough to be split at all.
    pub(super) fn of(tree: &[Link], nodes: usize) -> Option<Arc<Self>> {
        (tree.len() >= PARALLEL_MIN && tree.len() < ROOT as usize)
            .then(|| Arc::new(Self::new(tree, nodes, BLOCK, TASK_MIN, CHUNK)))
    }

    /// The partition into blocks of at most `block` nodes (a smaller one for tests).
    pub(super) fn new(
        tree: &[Link],
        nodes: usize,
        block: usize,
        task_min: usize,
        chunk: usize,
    ) -> Self {
        const NONE: u32 = u32::MAX;
        let n = tree.len();
        let mut pos = vec![NONE; nodes];
        for (k, l) in tree.iter().enumerate() {
            pos[l.node as usize] = k as u32;
        }
        let parent_pos: Vec<u32> = tree
            .iter()
            .map(|l| {
                if l.parent == u32::MAX {
                    NONE
                } else {
                    pos[l.parent as usize]
                }
            })
            .collect();
        drop(pos);
        // subtree sizes, children first
        let mut size = vec![1u32; n];
        for k in 0..n {
            if parent_pos[k] != NONE {
                size[parent_pos[k] as usize] += size[k];
            }
        }
        // block of every position, parents first (NONE: the top tree)
        let in_block = |k: usize| size[k] as usize <= block;
        let mut block_of = vec![NONE; n];
        let mut roots = 0u32;
        for k in (0..n).rev() {
            if !in_block(k) {
                continue;
            }
            let p = parent_pos[k];
            block_of[k] = if p != NONE && in_block(p as usize) {
                block_of[p as usize]
            } else {
                roots += 1;
                roots - 1
            };
        }
        // blocks numbered by their roots' positions, increasing (roots were met decreasing)
        for b in block_of.iter_mut().filter(|b| **b != NONE) {
            *b = roots - 1 - *b;
        }
        let mut ends = vec![0u32; roots as usize + 1];
        for &b in block_of.iter().filter(|&&b| b != NONE) {
            ends[b as usize + 1] += 1;
        }
        for b in 0..roots as usize {
            ends[b + 1] += ends[b];
        }
        let mut fill = ends.clone();
        let mut positions = vec![0u32; ends[roots as usize] as usize];
        let mut serial = Vec::new();
        for k in 0..n {
            match block_of[k] {
                NONE => serial.push(k as u32),
                b => {
                    positions[fill[b as usize] as usize] = k as u32;
                    fill[b as usize] += 1;
                    // (the last position of a block is its root)
                    if fill[b as usize] == ends[b as usize + 1] && parent_pos[k] != NONE {
                        serial.push(b | ROOT);
                    }
                }
            }
        }
        let mut tasks = Vec::new();
        let mut first = 0u32;
        for b in 0..roots {
            if (ends[b as usize + 1] - ends[first as usize]) as usize >= task_min {
                tasks.push((first, b + 1));
                first = b + 1;
            }
        }
        if first < roots {
            tasks.push((first, roots));
        }
        TreePartition {
            positions,
            ends,
            tasks,
            serial,
            chunk,
        }
    }

    /// The run's pool (`crate::threads`), if it has more than one thread and the tree more
    /// than one task.
    pub(super) fn pool(&self) -> Option<Arc<ThreadPool>> {
        if self.tasks.len() > 1 {
            crate::threads::pool()
        } else {
            None
        }
    }

    fn block(&self, b: usize) -> &[u32] {
        &self.positions[self.ends[b] as usize..self.ends[b + 1] as usize]
    }

    /// The forward pass: the blocks in parallel (each root's terms kept), then the top tree
    /// and the roots' terms in elimination order. Whether every new volume is positive.
    pub(super) fn forward<F: FaceFlows + Clone + Send + Sync>(
        &self,
        tree: &[Link],
        node: &NodeRows,
        shared: SharedForward,
        flows: &F,
    ) -> bool {
        let blocks: Vec<(bool, Vec<Option<ParentTerms>>)> = self
            .tasks
            .par_iter()
            .map(|&(b0, b1)| {
                let (mut a, mut flows) = (shared, flows.clone());
                let mut positive = true;
                let roots = (b0..b1)
                    .map(|b| {
                        self.forward_block(
                            b as usize,
                            tree,
                            node,
                            &mut a,
                            &mut flows,
                            &mut positive,
                        )
                    })
                    .collect();
                (positive, roots)
            })
            .collect();
        let mut positive = blocks.iter().all(|b| b.0);
        let roots: Vec<Option<ParentTerms>> = blocks.into_iter().flat_map(|b| b.1).collect();
        let (mut a, mut flows) = (shared, flows.clone());
        let steps = self.serial.iter().map(|&item| {
            if item & ROOT != 0 {
                let b = (item & !ROOT) as usize;
                let k = self.block(b).last().copied().unwrap_or(0) as usize;
                Step::Eliminated(k, roots[b])
            } else {
                Step::Eliminate(item as usize)
            }
        });
        // (the last item is a root of the tree: no terms are left over)
        let left = node.eliminate_run(&mut a, &mut flows, tree, steps, &mut positive);
        debug_assert!(left.is_none());
        positive
    }

    /// One block's forward elimination; the terms its root leaves in its parent's row.
    fn forward_block<F: FaceFlows>(
        &self,
        b: usize,
        tree: &[Link],
        node: &NodeRows,
        a: &mut SharedForward,
        flows: &mut F,
        positive: &mut bool,
    ) -> Option<ParentTerms> {
        let steps = self.block(b).iter().map(|&k| Step::Eliminate(k as usize));
        node.eliminate_run(a, flows, tree, steps, positive)
    }

    /// The backward pass: the top tree parents first, then the blocks in parallel; the wall
    /// and decay fluxes summed top tree first, then block by block in order.
    pub(super) fn backward(
        &self,
        tree: &[Link],
        node: &NodeBack,
        mut shared: SharedBackward,
    ) -> (f64, f64) {
        let mut sums = (0.0, 0.0);
        for &item in self.serial.iter().rev() {
            if item & ROOT == 0 {
                let k = item as usize;
                node.substitute(&mut shared, (k, &tree[k]), &mut sums);
            }
        }
        let one = |&(b0, b1): &(u32, u32)| {
            let mut a = shared;
            (b0..b1)
                .map(|b| {
                    let mut s = (0.0, 0.0);
                    for &k in self.block(b as usize).iter().rev() {
                        node.substitute(&mut a, (k as usize, &tree[k as usize]), &mut s);
                    }
                    s
                })
                .collect()
        };
        // on the run's pool when called inside it; otherwise (one thread) on this thread, not
        // on rayon's global pool (which would take every core of a `threads = 1` run)
        let blocks: Vec<Vec<(f64, f64)>> = if rayon::current_thread_index().is_some() {
            self.tasks.par_iter().map(one).collect()
        } else {
            self.tasks.iter().map(one).collect()
        };
        for s in blocks.iter().flatten() {
            sums.0 += s.0;
            sums.1 += s.1;
        }
        sums
    }

    /// A binding's wall linearised in chunks of cells (on the run's threads when it has
    /// them); Σ wconst summed chunk by chunk in order.
    pub(super) fn linearise_chunks(
        &self,
        cells: Cells,
        binding: Binding,
        free: &[f64],
        anchors: &mut [HillAnchor],
        wlin: &mut [f64],
        wconst: &mut [f64],
    ) -> f64 {
        let nc = cells.cells.len();
        let chunk = self.chunk;
        let anchors = SharedMut::new(anchors);
        let hill = matches!(binding, Binding::Hill { .. });
        let one = |(c, (wl, wc)): (usize, (&mut [f64], &mut [f64]))| {
            let (a, e) = (c * chunk, (c * chunk + wl.len()).min(nc));
            let part = Cells {
                first: a,
                cells: &cells.cells[a..e],
                zs: &cells.zs[a..e],
                wvol: &cells.wvol[a..e],
                laws: cells.laws,
            };
            if hill {
                part.linearise(
                    SharedAnchored {
                        binding,
                        free,
                        anchors,
                    },
                    wl,
                    wc,
                )
            } else {
                part.linearise(Exact { binding, free }, wl, wc)
            }
        };
        let per_task = TASK_MIN.div_ceil(chunk).max(1);
        let sums: Vec<f64> = match self.pool() {
            Some(pool) => pool.install(|| {
                wlin.par_chunks_mut(chunk)
                    .zip(wconst.par_chunks_mut(chunk))
                    .enumerate()
                    .with_min_len(per_task)
                    .map(one)
                    .collect()
            }),
            None => wlin
                .chunks_mut(chunk)
                .zip(wconst.chunks_mut(chunk))
                .enumerate()
                .map(one)
                .collect(),
        };
        sums.iter().fold(0.0, |s, &c| s + c)
    }
}

/// Hill's law with the anchors shared by the chunks of cells (each cell's node is its own).
struct SharedAnchored<'a> {
    binding: Binding,
    free: &'a [f64],
    anchors: SharedMut<'a, HillAnchor>,
}

impl Inversion for SharedAnchored<'_> {
    #[inline(always)]
    fn free_and_inv_slope(&mut self, n: usize, c: f64) -> (f64, f64) {
        // SAFETY: node n is one cell's, and each cell is in one chunk
        let anchor = unsafe { self.anchors.get_mut(n) };
        self.binding
            .free_and_inv_slope_anchored(c, self.free[n], anchor)
    }
}

/// A slice shared by the threads of one pass, each of which reads and writes its own
/// elements only (the nodes, cells or faces of its blocks). Indices are checked.
pub(super) struct SharedMut<'a, T> {
    ptr: *mut T,
    len: usize,
    _slice: PhantomData<&'a mut [T]>,
}

impl<T> Clone for SharedMut<'_, T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for SharedMut<'_, T> {}

// SAFETY: the threads of a pass touch disjoint elements (see the users); T is plain data
unsafe impl<T: Send> Send for SharedMut<'_, T> {}
unsafe impl<T: Send> Sync for SharedMut<'_, T> {}

impl<'a, T> SharedMut<'a, T> {
    pub(super) fn new(s: &'a mut [T]) -> Self {
        SharedMut {
            ptr: s.as_mut_ptr(),
            len: s.len(),
            _slice: PhantomData,
        }
    }

    /// # Safety
    /// No other thread touches element `i` meanwhile.
    #[inline(always)]
    pub(super) unsafe fn get_mut(&self, i: usize) -> &'a mut T {
        assert!(i < self.len);
        // SAFETY: in bounds; exclusive by the caller's contract
        unsafe { &mut *self.ptr.add(i) }
    }

    /// # Safety
    /// No other thread writes element `i` meanwhile.
    #[inline(always)]
    pub(super) unsafe fn read(&self, i: usize) -> T
    where
        T: Copy,
    {
        assert!(i < self.len);
        // SAFETY: in bounds; not written meanwhile by the caller's contract
        unsafe { self.ptr.add(i).read() }
    }

    /// # Safety
    /// As `get_mut`.
    #[inline(always)]
    pub(super) unsafe fn replace(&self, i: usize, v: T) -> T {
        // SAFETY: the caller's
        std::mem::replace(unsafe { self.get_mut(i) }, v)
    }
}

/// The forward pass's arrays shared by the blocks' threads (node-, position- and
/// cell-indexed: a block's nodes, positions and cells are its own).
#[derive(Clone, Copy)]
pub(super) struct SharedForward<'a> {
    acc: SharedMut<'a, [f64; 3]>,
    beta: SharedMut<'a, f64>,
    x: SharedMut<'a, f64>,
    wnew: SharedMut<'a, f64>,
}

impl<'a> SharedForward<'a> {
    pub(super) fn new(
        acc: &'a mut [[f64; 3]],
        beta: &'a mut [f64],
        x: &'a mut [f64],
        wnew: &'a mut [f64],
    ) -> Self {
        SharedForward {
            acc: SharedMut::new(acc),
            beta: SharedMut::new(beta),
            x: SharedMut::new(x),
            wnew: SharedMut::new(wnew),
        }
    }
}

// SAFETY (every method): a block's thread passes its own nodes, positions and cells, or
// (for a parent's accumulator) a node of its block; the serial phases run alone
impl ForwardArrays for SharedForward<'_> {
    #[inline(always)]
    fn take_acc(&mut self, n: usize) -> [f64; 3] {
        unsafe { self.acc.replace(n, [0.0; 3]) }
    }
    #[inline(always)]
    fn add_to_acc(&mut self, n: usize, t: &ParentTerms) {
        t.add_to(unsafe { self.acc.get_mut(n) });
    }
    #[inline(always)]
    fn set_beta(&mut self, k: usize, v: f64) {
        unsafe { *self.beta.get_mut(k) = v };
    }
    #[inline(always)]
    fn x(&self, n: usize) -> f64 {
        unsafe { self.x.read(n) }
    }
    #[inline(always)]
    fn set_x(&mut self, n: usize, v: f64) {
        unsafe { *self.x.get_mut(n) = v };
    }
    #[inline(always)]
    fn wnew(&self, cell: usize) -> f64 {
        unsafe { self.wnew.read(cell) }
    }
    #[inline(always)]
    fn set_wnew(&mut self, cell: usize, v: f64) {
        unsafe { *self.wnew.get_mut(cell) = v };
    }
}

/// The backward pass's arrays shared by the blocks' threads (a block reads its root's
/// parent, a top-tree node no thread writes in the parallel phase).
#[derive(Clone, Copy)]
pub(super) struct SharedBackward<'a> {
    x: SharedMut<'a, f64>,
    zs: SharedMut<'a, f64>,
}

impl<'a> SharedBackward<'a> {
    pub(super) fn new(x: &'a mut [f64], zs: &'a mut [f64]) -> Self {
        SharedBackward {
            x: SharedMut::new(x),
            zs: SharedMut::new(zs),
        }
    }
}

// SAFETY (every method): as for `SharedForward`
impl BackwardArrays for SharedBackward<'_> {
    #[inline(always)]
    fn x(&self, n: usize) -> f64 {
        unsafe { self.x.read(n) }
    }
    #[inline(always)]
    fn set_x(&mut self, n: usize, v: f64) {
        unsafe { *self.x.get_mut(n) = v };
    }
    #[inline(always)]
    fn set_z(&mut self, cell: usize, v: f64) {
        unsafe { *self.zs.get_mut(cell) = v };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_common::{Built, build, lcg, random_tree};
    use crate::transport::Transport;
    use crate::transport::boundary_chunks::BoundaryChunks;

    struct Case {
        transport: Transport,
        /// The flow states at the steps' ends.
        states: Vec<Vec<f64>>,
    }

    fn case(json: &str, seed: &mut u64) -> Case {
        let Built { dae, transport, .. } = build(json);
        // flows of either sign (reversals at junctions), pressures irrelevant
        let states = (0..12)
            .map(|_| (0..dae.n).map(|_| 2e-6 * (lcg(seed) - 0.3)).collect())
            .collect();
        Case { transport, states }
    }

    /// Run the steps (carried start flows, and the loaded-flows path on every third step)
    /// with the partition `part` (None: the serial pass) on `threads` threads; the state z.
    fn run(c: &mut Case, part: Option<TreePartition>, threads: usize) -> Vec<f64> {
        run_with(c, part, None, threads)
    }

    /// `run` with the boundary faces in chunks of `boundary_chunk` faces (None: serial).
    fn run_with(
        c: &mut Case,
        part: Option<TreePartition>,
        boundary_chunk: Option<usize>,
        threads: usize,
    ) -> Vec<f64> {
        let t = &mut c.transport;
        let mut z = t.initial_state(&c.states[0]).unwrap();
        t.set_step_start(&c.states[0]);
        if let Some(part) = part {
            // (sized as `fused_tree_step` would, so that it keeps this partition)
            t.sweep.acc = vec![[0.0; 3]; t.plan.kind.len()];
            t.sweep.partition = Some(Arc::new(part));
            let p = &t.plan;
            t.sweep.boundary = boundary_chunk.map(|chunk| {
                let nn = p.kind.len();
                BoundaryChunks::with_chunk(&p.boundary_links, nn, &p.boundary_inlet, chunk)
                    .expect("a tree's outlets are distinct nodes")
            });
        }
        let dt = 2e-3;
        crate::threads::with_threads(Some(threads), || {
            for (k, w) in c.states.windows(2).enumerate() {
                let time = k as f64 * dt;
                if k % 3 == 2 {
                    t.implicit_step(time, dt, 0.6, &w[0], &w[1], &mut z)
                        .unwrap();
                    t.set_step_start(&w[1]);
                } else {
                    t.implicit_step_carried(time, dt, 0.6, &w[1], &mut z)
                        .unwrap();
                }
            }
        })
        .unwrap();
        z
    }

    /// The blocks of a random tree (small blocks, so that a small tree has many) against the
    /// serial pass: the same amounts bit for bit on 1 and 3 threads, the fluxes' sums the
    /// same bits on any number of threads and the serial sums' to round-off, and the oxygen
    /// balance of the steps (Σ N moved by exactly the integrated boundary, wall and decay
    /// fluxes) closed.
    #[test]
    fn the_blocks_give_the_serial_sweep() {
        let mut seed = 7u64;
        for vessels in [40, 400] {
            let json = random_tree(vessels, &mut seed);
            let s0 = seed;
            let make = || case(&json, &mut s0.clone());
            let mut serial = make();
            assert!(serial.transport.fused_applies() && serial.transport.gathers_in_forward());
            let tree = serial.transport.plan.tree.clone().unwrap();
            let nn = serial.transport.plan.kind.len();
            let part = || TreePartition::new(&tree, nn, 8, 16, 32);
            check_partition(&part(), &tree);
            let z_serial = run(&mut serial, None, 1);
            let z_one = run(&mut make(), Some(part()), 1);
            let z_three = run(&mut make(), Some(part()), 3);
            let nc = serial.transport.plan.cells.len();
            assert_eq!(z_one[..nc], z_serial[..nc], "amounts, {vessels} vessels");
            assert_eq!(z_three, z_one, "state on 3 threads, {vessels} vessels");
            let (acc_s, acc_p) = (&z_serial[nc..nc + 4], &z_one[nc..nc + 4]);
            for (a, b) in acc_s.iter().zip(acc_p) {
                assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-30), "{a} vs {b}");
            }
            // the balance: the amounts' change is the integrated in − out − wall − decay
            let z0 = make().transport.initial_state(&serial.states[0]).unwrap();
            let change: f64 = z_one[..nc].iter().sum::<f64>() - z0[..nc].iter().sum::<f64>();
            let [i_in, i_out, i_wall, i_decay] = [acc_p[0], acc_p[1], acc_p[2], acc_p[3]];
            let flux = i_in - i_out - i_wall - i_decay;
            let scale = i_in.abs() + i_out.abs() + i_wall.abs();
            assert!(
                scale > 0.0 && (change - flux).abs() <= 1e-10 * scale,
                "{change} {flux}"
            );
        }
    }

    /// The boundary faces' passes in chunks (small chunks, so that a small tree has many)
    /// against the serial passes: the whole state — amounts and the accumulated boundary,
    /// wall and decay fluxes — the same bits on 1 and 3 threads, with and without the
    /// chunks, and the oxygen balance closed.
    #[test]
    fn the_boundary_chunks_give_the_serial_passes() {
        let mut seed = 11u64;
        // (at least two segments a vessel: with one-segment leaves this tree has cells with
        // two outlet faces, for which the chunks are refused and the serial passes kept)
        let json = random_tree(400, &mut seed).replace(r#""segments": 1,"#, r#""segments": 2,"#);
        let s0 = seed;
        let make = || case(&json, &mut s0.clone());
        let probe = make();
        let tree = probe.transport.plan.tree.clone().unwrap();
        let nn = probe.transport.plan.kind.len();
        let outlets = probe.transport.plan.boundary_links.len();
        assert!(outlets > 40, "{outlets} boundary faces: many chunks of 4");
        let part = || Some(TreePartition::new(&tree, nn, 8, 16, 32));
        let serial = run_with(&mut make(), part(), None, 3);
        let chunked = run_with(&mut make(), part(), Some(4), 3);
        let one = run_with(&mut make(), part(), Some(4), 1);
        assert_eq!(chunked, serial, "chunked boundary passes on 3 threads");
        assert_eq!(one, serial, "1 thread");
        let nc = probe.transport.plan.cells.len();
        let z0 = make().transport.initial_state(&probe.states[0]).unwrap();
        let change: f64 = chunked[..nc].iter().sum::<f64>() - z0[..nc].iter().sum::<f64>();
        let acc = &chunked[nc..nc + 4];
        let flux = acc[0] - acc[1] - acc[2] - acc[3];
        let scale = acc[0].abs() + acc[1].abs() + acc[2].abs();
        assert!(
            scale > 0.0 && (change - flux).abs() <= 1e-10 * scale,
            "{change} {flux}"
        );
    }

    /// The tasks of a partition (the units the threads take): whole blocks in order, every
    /// block in exactly one task, each task at least `task_min` nodes (the last may be less)
    /// and less than `task_min` plus one block, so the thread that finishes a pass first
    /// waits at most about one block for the other. The run's tasks are about one block.
    #[test]
    fn the_tasks_are_whole_blocks_of_about_the_least_size() {
        const { assert!(TASK_MIN <= BLOCK && TASK_MIN >= BLOCK / 4) };
        let mut seed = 5u64;
        let json = random_tree(400, &mut seed);
        let c = case(&json, &mut seed);
        let tree = c.transport.plan.tree.clone().unwrap();
        let nn = c.transport.plan.kind.len();
        for (block, task_min) in [(8, 4), (8, 16), (16, 8), (32, 100)] {
            let p = TreePartition::new(&tree, nn, block, task_min, 32);
            let nodes = |&(b0, b1): &(u32, u32)| p.ends[b1 as usize] - p.ends[b0 as usize];
            assert!(p.tasks.len() > 2, "{} tasks", p.tasks.len());
            assert_eq!(p.tasks[0].0, 0);
            for w in p.tasks.windows(2) {
                assert_eq!(w[0].1, w[1].0, "tasks follow each other");
            }
            assert_eq!(p.tasks.last().unwrap().1 as usize, p.ends.len() - 1);
            for t in &p.tasks[..p.tasks.len() - 1] {
                let n = nodes(t) as usize;
                assert!(
                    n >= task_min && n < task_min + block,
                    "{n} nodes, {block} {task_min}"
                );
            }
        }
    }

    /// Every position once, blocks whole subtrees below the top tree, the serial items in
    /// elimination order.
    fn check_partition(p: &TreePartition, tree: &[Link]) {
        let n = tree.len();
        let mut seen = vec![false; n];
        let mut block_of = vec![usize::MAX; n];
        for b in 0..p.ends.len() - 1 {
            for &k in p.block(b) {
                assert!(!seen[k as usize]);
                (seen[k as usize], block_of[k as usize]) = (true, b);
            }
        }
        assert!(p.ends.len() > 10, "a few blocks");
        let mut last = None;
        for &item in &p.serial {
            let k = if item & ROOT != 0 {
                *p.block((item & !ROOT) as usize).last().unwrap() as usize
            } else {
                assert!(!seen[item as usize]);
                seen[item as usize] = true;
                item as usize
            };
            assert!(last.is_none_or(|l| l < k));
            last = Some(k);
        }
        assert!(seen.iter().all(|&s| s));
        let pos = |node: u32| tree.iter().position(|l| l.node == node).unwrap();
        for b in 0..p.ends.len() - 1 {
            let ps = p.block(b);
            for &k in &ps[..ps.len() - 1] {
                let parent = pos(tree[k as usize].parent);
                assert_eq!(block_of[parent], b, "a block is a whole subtree");
            }
        }
    }
}
