//! The tree elimination on several threads: the classic partition of a tree solve (Hines'
//! method on a parallel machine). The blocks of [`TreeLu`] — subtrees of at most `BLOCK`
//! vertices, each contiguous in the elimination order — share no vertex, so they are
//! eliminated and substituted in parallel; the few vertices above them (the top tree) and the
//! couplings of each block root to its parent are done serially, in the elimination order.
//!
//! Every value receives the same operations in the same order as in the serial elimination
//! (a vertex's pivot and right side are updated by its children in elimination order, whichever
//! thread eliminated the children), so the results are bit-identical for any number of threads.

use super::{NONE, Scalar, TreeLu, is_held};
use rayon::ThreadPool;
use rayon::prelude::*;
use std::sync::Arc;

/// Least number of vertices in blocks for the parallel path: below it a solve takes a few
/// microseconds and the threads' start costs more than they save.
const PARALLEL_MIN: usize = 1 << 14;

/// Least number of vertices one task eliminates (several small ranges go to one thread). Half
/// a block (a task of about one block, ~20 µs a pass): a pass ends with its last task, so the
/// thread that finished first waits up to one task; with tasks of four blocks that wait was
/// up to a tenth of a 131 k-segment tree's pass on two threads. Tasks group whole ranges, so
/// their size changes no value.
pub(super) const TASK_MIN: usize = super::BLOCK / 2;

/// The partition of the elimination order into parallel ranges and the serial remainder.
pub(super) struct Partition {
    /// Maximal runs of whole blocks, as half-open position ranges, in elimination order.
    pub ranges: Vec<(u32, u32)>,
    /// Positions done serially, in elimination order: the top tree's vertices, and the block
    /// roots (tagged with `ROOT`) whose coupling to a top-tree parent is applied serially.
    pub serial: Vec<u32>,
    /// Vertices inside the ranges.
    pub in_ranges: usize,
}

/// Tag of a block root in `Partition::serial` (positions are below 2³⁰).
pub(super) const ROOT: u32 = 1 << 31;

impl Partition {
    /// From the blocks (half-open position ranges, increasing) of an elimination order of `n`
    /// vertices whose parent positions are `parent_pos`.
    pub fn new(n: usize, blocks: &[(u32, u32)], parent_pos: &[u32]) -> Self {
        let mut ranges: Vec<(u32, u32)> = Vec::new();
        let mut serial = Vec::new();
        let mut next = 0u32;
        for &(a, b) in blocks {
            serial.extend(next..a);
            match ranges.last_mut() {
                Some(last) if last.1 == a => last.1 = b,
                _ => ranges.push((a, b)),
            }
            if parent_pos[b as usize - 1] != NONE {
                serial.push((b - 1) | ROOT);
            }
            next = b;
        }
        serial.extend(next..n as u32);
        let in_ranges = blocks.iter().map(|&(a, b)| (b - a) as usize).sum();
        Partition {
            ranges,
            serial,
            in_ranges,
        }
    }

    /// The run's pool (`crate::threads`) if a solve of this tree is worth splitting over it.
    pub fn pool(&self) -> Option<Arc<ThreadPool>> {
        if self.ranges.len() > 1 && self.in_ranges >= PARALLEL_MIN {
            crate::threads::pool()
        } else {
            None
        }
    }

    /// The ranges grouped into tasks of at least `TASK_MIN` vertices (in order).
    pub(super) fn tasks(&self) -> Vec<&[(u32, u32)]> {
        let mut tasks = Vec::new();
        let (mut first, mut size) = (0, 0usize);
        for (i, &(a, b)) in self.ranges.iter().enumerate() {
            size += (b - a) as usize;
            if size >= TASK_MIN {
                tasks.push(&self.ranges[first..=i]);
                (first, size) = (i + 1, 0);
            }
        }
        if first < self.ranges.len() {
            tasks.push(&self.ranges[first..]);
        }
        tasks
    }
}

/// A right side shared by the threads of one solve. Each thread reads and writes only the
/// vertices of its own blocks (disjoint sets), and the serial phases run while no thread does.
struct Shared<T>(*mut T);

// SAFETY: the pointer is used only by `forward_blocks` and `backward_blocks`, whose threads
// touch disjoint sets of elements (see `Shared`); T is plain data.
unsafe impl<T: Send> Send for Shared<T> {}
unsafe impl<T: Send> Sync for Shared<T> {}

impl<T: Scalar> TreeLu<T> {
    /// `factor`'s elimination (pivots and magnitudes as there) with the blocks in parallel;
    /// false at a (near-)zero pivot, as the serial one.
    pub(super) fn eliminate_parallel(&mut self, magnitude: &mut [f64]) -> bool {
        let part = &self.partition;
        // the blocks: every value a block updates lies inside it, so the ranges are disjoint
        // slices of the per-position arrays
        let mut pieces = Vec::with_capacity(part.ranges.len());
        let (mut pivot, mut mag) = (&mut self.pivot[..], &mut magnitude[..]);
        let mut at = 0usize;
        for &(a, b) in &part.ranges {
            let (a, b) = (a as usize, b as usize);
            let (_, rest) = std::mem::take(&mut pivot).split_at_mut(a - at);
            let (piece, rest) = rest.split_at_mut(b - a);
            pivot = rest;
            let (_, mrest) = std::mem::take(&mut mag).split_at_mut(a - at);
            let (mpiece, mrest) = mrest.split_at_mut(b - a);
            mag = mrest;
            pieces.push((a, piece, mpiece));
            at = b;
        }
        let (up, down, parent_pos) = (&self.up, &self.down, &self.parent_pos);
        let held = &self.held;
        let ok = pieces
            .into_par_iter()
            .with_min_len(TASK_MIN / super::BLOCK)
            .all(|(a, pivot, mag)| {
                let end = a + pivot.len();
                for k in a..end {
                    let d = pivot[k - a];
                    // a held root (see `TreeLu::held`): left to the core's LU
                    if parent_pos[k] == NONE && is_held(held, k) {
                        continue;
                    }
                    if d.modulus() <= 1e-12 * mag[k - a] || !d.finite() {
                        return false;
                    }
                    let p = parent_pos[k] as usize;
                    if p < end {
                        let update = down[k] * up[k] / d;
                        pivot[p - a] -= update;
                        mag[p - a] += update.modulus();
                    }
                }
                true
            });
        if !ok {
            return false;
        }
        // the top tree, and each block root's update of its parent, in elimination order
        for i in 0..self.partition.serial.len() {
            let item = self.partition.serial[i];
            let k = (item & !ROOT) as usize;
            if !self.eliminate_into_parent(k, magnitude, item & ROOT == 0) {
                return false;
            }
        }
        true
    }

    /// `solve_in_place` with the blocks in parallel: the same operations on every value in the
    /// same order, so the same bits.
    pub(super) fn solve_parallel(&self, b: &mut [T]) -> bool {
        self.forward_parallel(b);
        self.backward_parallel(b)
    }

    /// The forward pass of `solve_parallel`.
    pub(super) fn forward_parallel(&self, b: &mut [T]) {
        let part = &self.partition;
        let tasks = part.tasks();
        let shared = Shared(b.as_mut_ptr());
        let shared = &shared;
        // forward: the blocks, then the top tree (and the block roots' couplings to it)
        tasks.par_iter().for_each(|ranges| {
            for &(a, e) in *ranges {
                // SAFETY: the vertices of the blocks in `a..e` (and their in-block parents)
                // belong to this task alone
                unsafe { self.forward_blocks(a as usize, e as usize, shared.0) };
            }
        });
        for &item in &part.serial {
            let k = (item & !ROOT) as usize;
            let p = self.parent_vertex(k);
            if p != NONE {
                b[p as usize] -= self.down[k] * b[self.vertex[k] as usize];
            }
        }
    }

    /// The back substitution of `solve_parallel`: the top tree from its roots, then the blocks;
    /// whether the solution is finite.
    pub(super) fn backward_parallel(&self, b: &mut [T]) -> bool {
        let part = &self.partition;
        let tasks = part.tasks();
        let mut finite = true;
        for &item in part.serial.iter().rev() {
            if item & ROOT != 0 {
                continue;
            }
            finite &= self.back_substitute(item as usize, b);
        }
        let shared = Shared(b.as_mut_ptr());
        let shared = &shared;
        let blocks_finite = tasks.par_iter().all(|ranges| {
            let mut ok = true;
            for &(a, e) in *ranges {
                // SAFETY: as for the forward pass; a block root reads its top-tree parent,
                // which no thread writes in this pass
                ok &= unsafe { self.backward_blocks(a as usize, e as usize, shared.0) };
            }
            ok
        });
        finite && blocks_finite
    }

    /// One position's back substitution (as in `solve_in_place`); whether the value is finite.
    fn back_substitute(&self, k: usize, b: &mut [T]) -> bool {
        let (v, p) = (self.vertex[k] as usize, self.parent_vertex(k));
        let up = if p != NONE {
            self.up[k] * b[p as usize]
        } else {
            T::ZERO
        };
        b[v] = (b[v] - up) * self.pivot[k];
        b[v].finite()
    }

    /// Forward elimination of the positions `a..e` (whole blocks), leaving the block roots'
    /// couplings to their parents to the serial pass.
    ///
    /// # Safety
    /// `b` points at the right side; no other thread touches the vertices of these blocks.
    unsafe fn forward_blocks(&self, a: usize, e: usize, b: *mut T) {
        for k in a..e {
            let pp = self.parent_pos[k] as usize;
            if pp < e {
                let (v, p) = (self.vertex[k] as usize, self.vertex[pp] as usize);
                // SAFETY: v and p are vertices of these blocks (see the caller)
                unsafe { *b.add(p) -= self.down[k] * *b.add(v) };
            }
        }
    }

    /// Back substitution of the positions `a..e` (whole blocks), after their parents'.
    ///
    /// # Safety
    /// As `forward_blocks`; the top tree's values are final and not written meanwhile.
    unsafe fn backward_blocks(&self, a: usize, e: usize, b: *mut T) -> bool {
        let mut finite = true;
        for k in (a..e).rev() {
            let (v, p) = (self.vertex[k] as usize, self.parent_vertex(k));
            // SAFETY: v is a vertex of these blocks, p its parent (in them or the top tree)
            unsafe {
                let up = if p != NONE {
                    self.up[k] * *b.add(p as usize)
                } else {
                    T::ZERO
                };
                let x = (*b.add(v) - up) * self.pivot[k];
                *b.add(v) = x;
                finite &= x.finite();
            }
        }
        finite
    }
}
