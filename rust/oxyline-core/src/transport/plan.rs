//! Elimination order of the implicit solve on a forest.

#[allow(unused_imports)]
use super::*;

/// One domain node in the elimination order of [`tree_order`]: its parent in the spanning
/// forest (`u32::MAX` for a root) and the face joining them.
#[derive(Debug, Clone, Copy)]
pub(super) struct Link {
    pub(super) node: u32,
    pub(super) parent: u32,
    pub(super) face: u32,
    /// The face points from this node to its parent (positive flow runs child → parent).
    pub(super) from_child: bool,
}

/// Children-before-parents order of the domain nodes when the undirected graph of the internal
/// faces is a forest (no loops, no parallel faces): then the upwind system can be eliminated
/// leaves first for any flow directions (`Transport::tree_solve`). None otherwise. Linear time.
pub(super) fn tree_order(nt: usize, domain: &[usize], internal: &[[u32; 3]]) -> Option<Vec<Link>> {
    let mut ptr = vec![0u32; nt + 1];
    for &[_, a, b] in internal {
        ptr[a as usize + 1] += 1;
        ptr[b as usize + 1] += 1;
    }
    for i in 0..nt {
        ptr[i + 1] += ptr[i];
    }
    let mut fill = ptr.clone();
    let mut adj = vec![(0u32, 0u32); ptr[nt] as usize];
    for &[f, a, b] in internal {
        adj[fill[a as usize] as usize] = (f, b);
        fill[a as usize] += 1;
        adj[fill[b as usize] as usize] = (f, a);
        fill[b as usize] += 1;
    }
    // nodes outside the domain count as seen: meeting one sends the solve to the general sweep
    let mut seen = vec![true; nt];
    for &n in domain {
        seen[n] = false;
    }
    let mut pre: Vec<Link> = Vec::with_capacity(domain.len());
    let mut stack: Vec<Link> = Vec::new();
    for &r in domain {
        if seen[r] {
            continue;
        }
        seen[r] = true;
        stack.push(Link {
            node: r as u32,
            parent: u32::MAX,
            face: u32::MAX,
            from_child: false,
        });
        while let Some(l) = stack.pop() {
            let n = l.node as usize;
            for &(f, o) in &adj[ptr[n] as usize..ptr[n + 1] as usize] {
                if f == l.face {
                    continue;
                }
                if seen[o as usize] {
                    return None; // a loop (or two faces between the same nodes)
                }
                seen[o as usize] = true;
                let from_child = internal_from(internal, f) == o;
                stack.push(Link {
                    node: o,
                    parent: l.node,
                    face: f,
                    from_child,
                });
            }
            pre.push(l);
        }
    }
    pre.reverse();
    Some(pre)
}

/// `from` node of internal face `f` (faces are listed in `internal` in face order, so a binary
/// search finds it).
pub(super) fn internal_from(internal: &[[u32; 3]], f: u32) -> u32 {
    let k = internal.partition_point(|e| e[0] < f);
    internal[k][1]
}
