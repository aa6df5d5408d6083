//! The boundary faces' passes of a fused tree step on the run's threads: the gather of their
//! flows, their terms in their nodes' rows, and their species fluxes. A tree has one boundary
//! face per outlet (16 k on a 131 k-segment binary tree), three passes of it every step, which
//! ran on the calling thread while the pool waited.
//!
//! Split only when no two boundary faces meet at one node (every tree of the scale runs; a
//! node with two boundary faces keeps the serial passes): each face then writes its own flow,
//! and its node's accumulator and lagged value, so the chunks touch disjoint elements and
//! each value receives the serial pass's operations. The step's boundary fluxes are computed
//! per face in chunks and summed on the calling thread in face order — the serial pass's sum,
//! so the concentrations, amounts and fluxes are bit-identical to the serial passes on any
//! number of threads.

use super::parallel::SharedMut;
use super::plan::BoundaryLink;
use super::{account, inflow_value};
use rayon::ThreadPool;
use rayon::prelude::*;
use std::sync::Arc;

/// Boundary faces per chunk (a face takes a few ns, a task a few µs to start).
const CHUNK: usize = 4096;

/// The boundary faces' chunks of a tree whose faces meet at distinct nodes.
#[derive(Debug, Default, Clone)]
pub(super) struct BoundaryChunks {
    /// Per boundary face: its boundary is an inlet (I_in) or not (I_out), in face order.
    inlet: Vec<bool>,
    /// Per boundary face: the step's species flux into the domain (scratch).
    flux: Vec<f64>,
    /// Boundary faces per chunk.
    chunk: usize,
}

impl BoundaryChunks {
    /// The chunks of `links` if they are worth splitting and no two share a node.
    pub(super) fn of(links: &[BoundaryLink], nodes: usize, inlet: &[bool]) -> Option<Self> {
        Self::with_chunk(links, nodes, inlet, CHUNK)
    }

    /// As `of` with chunks of `chunk` faces (a smaller one for tests).
    pub(super) fn with_chunk(
        links: &[BoundaryLink],
        nodes: usize,
        inlet: &[bool],
        chunk: usize,
    ) -> Option<Self> {
        if links.len() < 2 * chunk {
            return None;
        }
        let mut seen = vec![false; nodes];
        for b in links {
            if std::mem::replace(&mut seen[b.node as usize], true) {
                return None;
            }
        }
        Some(BoundaryChunks {
            inlet: links.iter().map(|b| inlet[b.boundary as usize]).collect(),
            flux: vec![0.0; links.len()],
            chunk,
        })
    }

    /// The boundary faces' flows at the α_f level of a carried step, Q = Q_0 + α_f (Q_1 − Q_0),
    /// and Q_1 kept as the next step's start (`Transport::implicit_step_carried`).
    pub(super) fn gather(
        &self,
        pool: &ThreadPool,
        links: &[BoundaryLink],
        (y1, unknowns, alpha_f): (&[f64], &[u32], f64),
        qf: &mut [f64],
        q0: &mut [f64],
    ) {
        let (qf, q0) = (SharedMut::new(qf), SharedMut::new(q0));
        each(self.chunk, pool, links, |_, chunk| {
            for b in chunk {
                let f = b.face as usize;
                let q1 = y1[unknowns[f] as usize];
                // SAFETY: every boundary face is one link's
                let start = unsafe { q0.replace(f, q1) };
                unsafe { *qf.get_mut(f) = start + alpha_f * (q1 - start) };
            }
        });
    }

    /// The boundary faces' terms in their nodes' accumulators (outflow into d, inflow —
    /// prescribed, or the node's `old` value, recorded in `lag` — into b) and their flows
    /// into the net inflow: `Transport::fused_boundary_terms`'s loop over the faces.
    pub(super) fn terms(
        &self,
        pool: &ThreadPool,
        links: &[BoundaryLink],
        (qf, bval): (&[f64], &[Option<f64>]),
        old: impl Fn(usize) -> f64 + Sync + Send,
        acc: &mut [[f64; 3]],
        lag: &mut [f64],
    ) {
        let (acc, lag) = (SharedMut::new(acc), SharedMut::new(lag));
        each(self.chunk, pool, links, |_, chunk| {
            for b in chunk {
                let (n, q) = (b.node as usize, qf[b.face as usize]);
                // SAFETY: no two boundary faces share a node (`of`)
                let (acc, lag) = unsafe { (acc.get_mut(n), lag.get_mut(n)) };
                acc[0] += b.inflow(q);
                if b.boundary_upwind(q) {
                    *lag = old(n);
                    acc[2] += q.abs() * inflow_value(bval[b.boundary as usize], *lag);
                } else {
                    acc[1] += q.abs();
                }
            }
        });
    }

    /// The boundary faces' inflow (I_in) and outflow (I_out) rates of the solved field
    /// `conc`: each face's flux in chunks, summed here in face order (the serial sum).
    pub(super) fn fluxes(
        &mut self,
        pool: &ThreadPool,
        links: &[BoundaryLink],
        (qf, conc): (&[f64], &[f64]),
        boundary: impl Fn(usize, usize) -> f64 + Sync + Send,
    ) -> (f64, f64) {
        let (chunk, flux) = (self.chunk, SharedMut::new(&mut self.flux));
        each(chunk, pool, links, |first, chunk| {
            for (i, b) in chunk.iter().enumerate() {
                let (n, bb, q) = (b.node as usize, b.boundary as usize, qf[b.face as usize]);
                // SAFETY: each face's own element
                unsafe { *flux.get_mut(first + i) = b.flux_in(q, conc[n], || boundary(bb, n)) };
            }
        });
        let (mut i_in, mut i_out) = (0.0, 0.0);
        for (&f, &inlet) in self.flux.iter().zip(&self.inlet) {
            account(inlet, f, &mut i_in, &mut i_out);
        }
        (i_in, i_out)
    }
}

/// The chunks and the run's pool for the boundary passes, if the tree has chunks and the run
/// several threads (None: the serial passes).
pub(super) fn split(chunks: Option<&BoundaryChunks>) -> Option<(&BoundaryChunks, Arc<ThreadPool>)> {
    chunks.and_then(|c| crate::threads::pool().map(|p| (c, p)))
}

/// `f` on every chunk of `chunk` faces of `links` (its first index, the chunk), on `pool`.
fn each(
    chunk: usize,
    pool: &ThreadPool,
    links: &[BoundaryLink],
    f: impl Fn(usize, &[BoundaryLink]) + Sync + Send,
) {
    pool.install(|| {
        links
            .par_chunks(chunk)
            .enumerate()
            .for_each(|(c, l)| f(c * chunk, l))
    });
}
