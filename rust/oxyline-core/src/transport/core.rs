//! The implicit solve of a transport domain with loops (a circle of Willis, an anastomosis):
//! its pendant trees by the tree elimination, its loop-carrying core alone by the flow-order
//! sweep. Removing the nodes with a single internal face until none is left leaves the 2-core
//! of the domain graph (two faces between the same nodes count as a loop): the loops and the
//! paths between them, a few thousand nodes, while the structured trees at the outlets are
//! millions. Every other node hangs off the core in a pendant tree rooted at a core node.
//!
//! The solve is `Transport::tree_solve` with the core nodes as held roots: the pendant trees
//! are eliminated leaves first (each row becoming x_n = α_n + β_n x_parent, the terms of the
//! upwind children folded into their parents), the core's rows are then solved by the sweep
//! (which reads the pendant children upwind of a core node as known values, and counts the
//! flow out to the others in the node's outflow), and the back substitution goes out into the
//! trees. The same upwind system as the sweep over the whole domain, solved in another order:
//! the same values up to rounding, with one streaming pass over the trees instead of the
//! sweep's queue over every node.

use super::*;

/// The elimination of a domain with loops: the pendant trees' links in elimination order,
/// leaves first (the core nodes are their roots), and the core's nodes.
#[derive(Debug)]
pub(super) struct CoreOrder {
    pub(super) links: Vec<Link>,
    pub(super) nodes: Vec<usize>,
}

impl CoreOrder {
    /// None when the domain has no loop, no pendant node, or a face to a node outside it
    /// (then the sweep over the whole domain takes it, as before).
    pub(super) fn of(nt: usize, domain: &[usize], internal: &[[u32; 3]]) -> Option<CoreOrder> {
        let in_core = two_core(nt, domain, internal);
        let nodes: Vec<usize> = domain.iter().copied().filter(|&n| in_core[n]).collect();
        if nodes.is_empty() || nodes.len() == domain.len() {
            return None;
        }
        let links = tree_order_held(nt, domain, internal, &nodes, &in_core)?;
        Some(CoreOrder { links, nodes })
    }
}

/// Per node: whether it is in the 2-core of the graph of the internal faces (nodes outside
/// `domain` are never peeled).
fn two_core(nt: usize, domain: &[usize], internal: &[[u32; 3]]) -> Vec<bool> {
    let mut in_domain = vec![false; nt];
    for &n in domain {
        in_domain[n] = true;
    }
    let faces: Vec<(u32, u32)> = internal.iter().map(|&[_, a, b]| (a, b)).collect();
    crate::sparse::two_core(nt, &faces, |n| in_domain[n])
}

impl Transport {
    /// The upwind system of `sweep_solve` on the whole domain, solved with the pendant trees
    /// eliminated around the core (see the module doc). On entry `sweep.den`, `sweep.num` hold
    /// d and b, and `x` the previous values, as for `tree_solve`.
    pub(super) fn core_solve(&mut self, core: &CoreOrder, x: &mut [f64]) -> Result<()> {
        self.sweep.size_rows(self.plan.kind.len());
        // the core's own rows: the sweep adds their faces' and sources' terms itself
        let rows: Vec<(f64, f64)> = core
            .nodes
            .iter()
            .map(|&n| (self.sweep.den[n], self.sweep.num[n]))
            .collect();
        self.boundary_rows(x);
        let sw = &mut self.sweep;
        tree_forward(sw, &self.qf, &core.links, x, true);
        for (&n, &(d, b)) in core.nodes.iter().zip(&rows) {
            (sw.den[n], sw.num[n]) = (d, b);
        }
        let res = self.sweep_solve_loaded(&core.nodes, x);
        tree_backward(&self.sweep, &core.links, x);
        res
    }
}

/// The leaves-first pass of the tree solve over `links` (see `Transport::tree_solve`): every
/// node's row reduced to x_n = α_n + β_n x_parent (α_n into `x`, β_n into `sweep.beta`). With
/// `hold_roots` the roots are left alone (a core's nodes, solved between the two passes).
pub(super) fn tree_forward(
    sw: &mut Sweep,
    qf: &[f64],
    links: &[Link],
    x: &mut [f64],
    hold_roots: bool,
) {
    sw.beta.resize(links.len(), 0.0);
    // local slices: the loops keep their pointers in registers
    let (num, den) = (&mut sw.num[..], &mut sw.den[..]);
    for (l, beta) in links.iter().zip(sw.beta.iter_mut()) {
        let n = l.node as usize;
        let (mut aq, mut to_parent) = (0.0, false);
        if l.parent != u32::MAX {
            let q = qf[l.face() as usize];
            aq = q.abs();
            to_parent = (q >= 0.0) == l.face_from_child();
            if to_parent {
                den[n] += aq;
            } else {
                den[l.parent as usize] += aq;
            }
        } else if hold_roots {
            *beta = 0.0;
            continue;
        }
        let d = den[n];
        let solvable = d > 1e-300;
        let xn = if solvable { num[n] / d } else { x[n] };
        x[n] = xn;
        *beta = 0.0;
        if to_parent {
            num[l.parent as usize] += aq * xn;
        } else if solvable && aq != 0.0 {
            *beta = aq / d;
        }
    }
}

/// The back substitution of the tree solve, parents first: x_n += β_n x_parent.
pub(super) fn tree_backward(sw: &Sweep, links: &[Link], x: &mut [f64]) {
    for (l, &beta) in links.iter().zip(&sw.beta).rev() {
        if beta != 0.0 {
            x[l.node as usize] += beta * x[l.parent as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_common::{RING, build, lcg};

    /// The core solve (pendant trees eliminated, the sweep on the core alone; the primal's
    /// row-by-row step and the tangent's solve) against the flow-order sweep over the whole
    /// domain, an independent order of the same upwind system: face flows of random signs
    /// (pendant trees fed from the core, outlets running backwards into it) and flows all
    /// one way round the ring (both take Gauss–Seidel on the core), random rows and lagged
    /// values. Each value is a few dozen products of O(1) terms, solved to the sweep's
    /// 1e-15 on the circulating ring: agreement to 1e-12 of the largest value.
    #[test]
    fn the_core_solve_is_the_sweep_over_the_whole_domain() {
        let mut t = build(RING).transport.new_run();
        t.ensure_scratch();
        let plan = Arc::clone(&t.plan);
        let core = plan
            .core
            .as_ref()
            .expect("a ring with pendant trees has a core");
        assert!(core.nodes.len() < plan.domain.len(), "pendant nodes");
        let nn = plan.kind.len();
        let mut seed = 11u64;
        for case in 0..8 {
            for q in t.qf.iter_mut() {
                *q = 1e-6
                    * if case == 0 {
                        1.0 + lcg(&mut seed)
                    } else {
                        lcg(&mut seed) - 0.4
                    };
            }
            let mut rand = |scale: f64| (0..nn).map(|_| scale * lcg(&mut seed)).collect::<Vec<_>>();
            let (d, b, lag) = (rand(1e-6), rand(1e-6), rand(1.0));
            let mut whole = lag.clone();
            t.sweep_solve(&plan.domain, &d, &b, &mut whole).unwrap();
            // flows all one way round the ring: Kahn's pass leaves it to Gauss–Seidel
            let circulates = plan.domain.iter().any(|&n| t.sweep.pending[n] > 0);
            assert!(circulates || case > 0, "case {case}");
            (t.sweep.den, t.sweep.num) = (d.clone(), b.clone());
            let mut x = lag.clone();
            t.core_solve(core, &mut x).unwrap();
            let scale = plan
                .domain
                .iter()
                .map(|&n| whole[n].abs())
                .fold(0.0, f64::max);
            for &n in &plan.domain {
                let diff = (x[n] - whole[n]).abs();
                assert!(
                    diff <= 1e-12 * scale,
                    "case {case} node {n}: {} {}",
                    x[n],
                    whole[n]
                );
            }
        }
    }

    /// A loop 0–1–2–3–0, a path 2–4–5–9 to a pair of parallel faces between 9 and 10 (a loop
    /// of two faces), and pendant nodes 6 (off 4) and 7–8 (off 0): the core is the loops and
    /// the path between them; every pendant node is eliminated before its parent, through the
    /// face between them, and its parents lead to a core node; the core nodes are roots.
    #[test]
    fn the_core_is_the_loops_and_the_paths_between_them() {
        let edges = [
            (0, 1),
            (1, 2),
            (2, 3),
            (3, 0),
            (2, 4),
            (4, 5),
            (4, 6),
            (0, 7),
            (7, 8),
            (5, 9),
            (9, 10),
            (10, 9),
        ];
        let internal: Vec<[u32; 3]> = edges
            .iter()
            .enumerate()
            .map(|(f, &(a, b))| [f as u32, a, b])
            .collect();
        let domain: Vec<usize> = (0..11).collect();
        let core = CoreOrder::of(11, &domain, &internal).expect("loops with pendant nodes");
        assert_eq!(core.nodes, vec![0, 1, 2, 3, 4, 5, 9, 10]);
        assert_eq!(core.links.len(), 11);
        let pos = |n: u32| core.links.iter().position(|l| l.node == n).unwrap();
        for l in &core.links {
            let is_core = core.nodes.contains(&(l.node as usize));
            assert_eq!(l.parent == u32::MAX, is_core, "node {}", l.node);
            if !is_core {
                assert!(pos(l.node) < pos(l.parent));
                let [_, a, b] = internal[l.face() as usize];
                assert!((a, b) == (l.node, l.parent) || (a, b) == (l.parent, l.node));
            }
        }
        for (n, root) in [(6, 4), (8, 0), (7, 0)] {
            let mut m = n;
            while core.links[pos(m)].parent != u32::MAX {
                m = core.links[pos(m)].parent;
            }
            assert_eq!(m, root, "node {n}");
        }
        // a forest has no core, nor has a domain that is all loop
        assert!(CoreOrder::of(11, &domain, &internal[4..9]).is_none());
        assert!(CoreOrder::of(4, &domain[..4], &internal[..4]).is_none());
    }
}
