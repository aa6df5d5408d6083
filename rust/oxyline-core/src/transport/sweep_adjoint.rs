//! The flow-order sweep's system transposed (`implicit.rs`' `sweep_solve` over the whole
//! domain, the species step of a network whose flow graph has loops), for the species
//! adjoint. The sweep solves the upwind rows
//!
//!   D_n x_n − Σ_{u → n} |Q| x_u = r_n,   D_n = d_n + Σ_out |Q| (+ outflowing sources),
//!
//! r_n = b_n + the inflows from boundaries and sources (prescribed, or the node's lagged
//! value at zero gradient), and x_n = lag_n where D_n vanishes. What is transposed is that
//! matrix, not the algorithm that solves it: Aᵀμ = λ_x reads μ_u = (λ_u + Σ_{u → m} |Q| μ_m)
//! / D_u, so it is solved downstream first, by Kahn's order on the reversed faces, and by
//! Gauss–Seidel on what is left (directed flow cycles). A is column diagonally dominant
//! (a node's outflows to the domain are at most its D), so Aᵀ is row diagonally dominant
//! and Gauss–Seidel converges for it whenever the primal's does.

#[allow(unused_imports)]
use super::*;

/// The transposed rows' coupling: per domain node, its downstream unknowns' faces.
struct Transposed {
    mark: Vec<bool>,
    /// The row's diagonal (1 where the row keeps its lagged value).
    diag: Vec<f64>,
    solvable: Vec<bool>,
    /// Per node: downstream domain neighbours not yet solved (the reversed Kahn order).
    pending: Vec<u32>,
    /// Per node: Σ |Q| μ_m of its solved downstream neighbours.
    acc: Vec<f64>,
}

impl Transport {
    /// `sweep_solve` over the domain, transposed: the contract of `tree_solve_adjoint`
    /// (from λ of the solution `lx` the λ of the right sides and the P50 term of the
    /// prescribed inflows `bd`, returned, and of the lagged values, added to `lprior`);
    /// `den` holds the rows' own d.
    pub(super) fn sweep_solve_adjoint(
        &self,
        den: &[f64],
        lx: &[f64],
        lprior: &mut [f64],
        bd: &[Option<f64>],
    ) -> (Vec<f64>, f64) {
        let plan = &*self.plan;
        let mut t = self.transposed_rows(den);
        let mu = self.transposed_solve(&mut t, lx);
        let mut lnum = vec![0.0; plan.kind.len()];
        let mut p50 = 0.0;
        for &n in &plan.domain {
            if !t.solvable[n] {
                // x_n = lag_n: the row's right side is never read
                lprior[n] += mu[n];
                continue;
            }
            lnum[n] = mu[n];
            // the inflows into the row from outside the unknowns (`sweep_rows`)
            for fi in plan.faces_at(n) {
                let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
                if down != End::Node(n) || q == 0.0 {
                    continue;
                }
                match up {
                    End::Node(u) if t.mark[u] => {}
                    End::Node(u) => lprior[u] += q.abs() * mu[n],
                    End::Boundary(bb) => match self.bval[bb] {
                        None => lprior[n] += q.abs() * mu[n],
                        Some(_) => p50 += q.abs() * mu[n] * bd[bb].unwrap_or(0.0),
                    },
                }
            }
            for &k in plan.node_sources(n) {
                let (q, bb) = (self.qs[k as usize], plan.sources[k as usize].2);
                if q < 0.0 {
                    continue;
                }
                match self.bval[bb] {
                    None => lprior[n] += q * mu[n],
                    Some(_) => p50 += q * mu[n] * bd[bb].unwrap_or(0.0),
                }
            }
        }
        (lnum, p50)
    }

    /// The diagonals of the sweep's rows (their own d, outflows and outflowing sources, as
    /// `sweep_rows` adds them) and the count of each node's downstream unknowns.
    fn transposed_rows(&self, den: &[f64]) -> Transposed {
        let plan = &*self.plan;
        let nn = plan.kind.len();
        let mut t = Transposed {
            mark: vec![false; nn],
            diag: vec![1.0; nn],
            solvable: vec![false; nn],
            pending: vec![0; nn],
            acc: vec![0.0; nn],
        };
        for &n in &plan.domain {
            t.mark[n] = true;
        }
        for &n in &plan.domain {
            let mut d = den[n];
            for fi in plan.faces_at(n) {
                let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
                if up != End::Node(n) {
                    continue;
                }
                d += q.abs();
                if let End::Node(m) = down {
                    if t.mark[m] && q != 0.0 {
                        t.pending[n] += 1;
                    }
                }
            }
            for &k in plan.node_sources(n) {
                let q = self.qs[k as usize];
                if q < 0.0 {
                    d -= q;
                }
            }
            t.solvable[n] = d > 1e-300;
            if t.solvable[n] {
                t.diag[n] = d;
            }
        }
        t
    }

    /// μ = A⁻ᵀ λ_x over the domain: downstream nodes first, then Gauss–Seidel on the
    /// directed cycles left.
    fn transposed_solve(&self, t: &mut Transposed, lx: &[f64]) -> Vec<f64> {
        let plan = &*self.plan;
        let mut mu = vec![0.0; plan.kind.len()];
        let mut queue: Vec<usize> = (plan.domain.iter().copied())
            .filter(|&n| t.pending[n] == 0)
            .collect();
        let mut head = 0;
        while head < queue.len() {
            let m = queue[head];
            head += 1;
            mu[m] = (lx[m] + t.acc[m]) / t.diag[m];
            // m's row reads its upwind unknowns (unless it keeps its lagged value)
            for fi in plan.faces_at(m) {
                let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
                let End::Node(u) = up else { continue };
                if down != End::Node(m) || q == 0.0 || !t.mark[u] {
                    continue;
                }
                if t.solvable[m] {
                    t.acc[u] += q.abs() * mu[m];
                }
                t.pending[u] -= 1;
                if t.pending[u] == 0 {
                    queue.push(u);
                }
            }
        }
        if head < plan.domain.len() {
            self.transposed_cycles(t, lx, &mut mu);
        }
        mu
    }

    /// Gauss–Seidel on the transposed rows of the nodes on directed flow cycles (those the
    /// reversed Kahn pass left), to the primal sweep's own tolerance.
    fn transposed_cycles(&self, t: &Transposed, lx: &[f64], mu: &mut [f64]) {
        let plan = &*self.plan;
        let rest: Vec<usize> = (plan.domain.iter().copied())
            .filter(|&n| t.pending[n] > 0)
            .collect();
        for _ in 0..10_000 {
            let (mut change, mut scale) = (0.0f64, 0.0f64);
            for &u in &rest {
                let mut sum = lx[u] + t.acc[u];
                for fi in plan.faces_at(u) {
                    let (q, up, down) = oriented(&plan.faces, &self.qf, fi);
                    if up != End::Node(u) {
                        continue;
                    }
                    if let End::Node(m) = down {
                        if t.mark[m] && t.pending[m] > 0 && t.solvable[m] {
                            sum += q.abs() * mu[m];
                        }
                    }
                }
                let v = sum / t.diag[u];
                change = change.max((v - mu[u]).abs());
                scale = scale.max(v.abs());
                mu[u] = v;
            }
            if change <= 1e-15 * scale.max(1e-300) {
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    // the ring of `test_common::RING`: a few cells and mixing points around a loop
    use crate::test_common::{RING, build, lcg};

    /// The dot-product test of the transpose: for the sweep's solution x of right sides b
    /// and lagged values ℓ (the boundaries' prescribed values zero, so x is linear in both),
    /// ⟨λ, x⟩ = ⟨μ_b, b⟩ + ⟨μ_ℓ, ℓ⟩ with the transposed sweep's (μ_b, μ_ℓ), for face flows
    /// of random signs and for flows all around the ring (a directed cycle: the primal and
    /// the transpose both take their Gauss–Seidel pass). Both sides are sums of ~50 terms
    /// of O(1) solved to the sweep's 1e-15: 1e-12 relative.
    #[test]
    fn transposed_sweep_is_the_sweeps_transpose() {
        let mut t = build(RING).transport.new_run();
        t.ensure_scratch();
        assert!(t.plan.tree.is_none(), "a ring is not a forest");
        let nn = t.plan.kind.len();
        let domain = t.plan.domain.clone();
        for b in t.bval.iter_mut() {
            *b = b.map(|_| 0.0);
        }
        let bd = vec![None; t.bval.len()];
        let mut seed = 7u64;
        for case in 0..6 {
            for q in t.qf.iter_mut() {
                *q = 1e-6
                    * if case == 0 {
                        1.0 + lcg(&mut seed)
                    } else {
                        lcg(&mut seed) - 0.4
                    };
            }
            let mut rand = |scale: f64| (0..nn).map(|_| scale * lcg(&mut seed)).collect::<Vec<_>>();
            let (d, b, lag, lam) = (rand(1e-6), rand(1.0), rand(1.0), rand(1.0));
            let mut x = lag.clone();
            t.sweep_solve(&domain, &d, &b, &mut x).unwrap();
            // flows all one way round: Kahn's pass leaves the ring to Gauss–Seidel
            let circulates = domain.iter().any(|&n| t.sweep.pending[n] > 0);
            assert_eq!(circulates, case == 0, "case {case}");
            let mut lprior = vec![0.0; nn];
            let (lnum, p50) = t.sweep_solve_adjoint(&d, &lam, &mut lprior, &bd);
            assert_eq!(p50, 0.0);
            let lhs: f64 = domain.iter().map(|&n| lam[n] * x[n]).sum();
            let rhs: f64 = (0..nn).map(|n| lnum[n] * b[n] + lprior[n] * lag[n]).sum();
            assert!(
                (lhs - rhs).abs() <= 1e-12 * lhs.abs(),
                "case {case}: {lhs} {rhs}"
            );
        }
    }
}
