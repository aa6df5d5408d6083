//! svZeroDSolver-form stenoses (`stenosis_form: svzerod`, docs/svzerod.md "C + stenosis") in
//! the tangent and the adjoint.
//!
//! The capacitor node's row of such an RCL vessel reads, at the converged step,
//!
//!   f − F y_αf − C (ẏ_αm,in − σ ẏ_αm,Q) = 0,   σ = R + 2 S |Q_αf|
//!
//! (the chain rule of d/dt [P_in − (R + S|Q|) Q]) instead of f − F y_αf − C ẏ_αm,node. With
//! y_αf' = s + α_f γ Δt dΔ and ẏ_αm' = c ṡ + α_m dΔ its derivative has
//!
//!   matrix row:  α_f γ Δt F_node + α_m C (e_in − σ e_Q) − α_f γ Δt g e_Q,
//!   right side:  − F_node s − c C (ṡ_in − σ ṡ_Q) + g s_Q + source,
//!   source:      − dC (ẏ_αm,in − σ ẏ_αm,Q) + C (dR + 2 dS |Q_αf|) ẏ_αm,Q (+ dF, df as any row),
//!
//! g = 2 C S sgn(Q_αf) ẏ_αm,Q. The row couples the node to the inlet pressure; as the run's
//! Newton step does (`GenAlpha::factor`), the tangent solves with that row plus
//! w = α_m C / (α_f γ Δt) times its R branch's row (−P_in + P_node + (R + S|Q|) Q), which
//! cancels the inlet coupling and leaves α_m C on the node's diagonal and −α_f γ Δt g at the
//! flow: the matrix keeps the circuit's pattern. The adjoint solves with the transpose of that
//! matrix and takes the combination back (u_Q += w u_node) before its sums.

use super::*;

/// A capacitor's parameter derivatives (dC, dR, dS) and where its node row sits in a source.
pub(super) struct ChainSource {
    /// (position of the node's row in the source's rows, capacitor index, [dC, dR, dS])
    pub(super) terms: Vec<(usize, usize, [f64; 3])>,
}

impl ChainSource {
    /// The derivatives of `t` touching each capacitor of `dae` (its node's E, its R branch's
    /// diagonal in F, its stenosis), the node row placed by `at`.
    pub(super) fn of(dae: &Dae, t: &DaeTangent, mut at: impl FnMut(usize) -> usize) -> Self {
        let mut terms = Vec::new();
        for (m, cr) in dae.chain_rule.iter().enumerate() {
            let dc = t.de[cr.node];
            let dr = diagonal(dae, cr.flow).map_or(0.0, |k| t.df[k]);
            let ds: f64 = (t.dstenosis.iter())
                .filter(|(i, _)| *i == cr.flow)
                .map(|(_, d)| d)
                .sum();
            if dc != 0.0 || dr != 0.0 || ds != 0.0 {
                terms.push((at(cr.node), m, [dc, dr, ds]));
            }
        }
        ChainSource { terms }
    }

    /// Add a step's source on the capacitor rows to `v` (the source's values on its rows),
    /// replacing the generic −dC ẏ_αm,node the E loop wrote.
    pub(super) fn capture(&self, pr: &Primal, v: &mut [f64]) {
        let (s, c) = (&pr.scheme, pr.c);
        let a = s.af * s.gamma * s.dt;
        let yd_am = |i: usize| c * pr.yd[i] + s.am * pr.r[i];
        for &(pos, m, [dc, dr, ds]) in &self.terms {
            let cr = &pr.dae.chain_rule[m];
            let q = pr.y[cr.flow] + a * pr.r[cr.flow];
            let sigma = cr.resistance + 2.0 * cr.stenosis * q.abs();
            v[pos] += dc * yd_am(cr.node);
            v[pos] -= dc * (yd_am(cr.inlet) - sigma * yd_am(cr.flow));
            v[pos] += cr.capacitance * (dr + 2.0 * ds * q.abs()) * yd_am(cr.flow);
        }
    }
}

/// The index in `dae.f` of row i's diagonal, if it has one.
fn diagonal(dae: &Dae, i: usize) -> Option<usize> {
    dae.f.row(i).find(|&k| dae.f.col[k] as usize == i)
}

impl Primal<'_> {
    /// The index in `dae.f` of each capacitor's (node, inflow) entry.
    pub(super) fn chain_entries(dae: &Dae) -> Vec<usize> {
        (dae.chain_rule.iter())
            .map(|c| {
                dae.f
                    .row(c.node)
                    .find(|&k| dae.f.col[k] as usize == c.flow)
                    .expect("a capacitor node's row holds its inflow")
            })
            .collect()
    }

    /// The weight w = α_m C / (α_f γ Δt) of capacitor `m`'s R-branch row in its node's.
    fn chain_weight(&self, m: usize) -> f64 {
        let s = &self.scheme;
        s.am * self.dae.chain_rule[m].capacitance / (s.af * s.gamma * s.dt)
    }

    /// Append this step's (σ, g) of each capacitor (after `increment`, before `advance`).
    pub(super) fn record_chain(&mut self) {
        let s = &self.scheme;
        let a = s.af * s.gamma * s.dt;
        for cr in &self.dae.chain_rule {
            let (y, yd, d) = (&self.y, &self.yd, &self.r);
            let q = y[cr.flow] + a * d[cr.flow];
            let yd_q = self.c * yd[cr.flow] + s.am * d[cr.flow];
            let sign = f64::from(i8::from(q > 0.0) - i8::from(q < 0.0));
            let sigma = cr.resistance + 2.0 * cr.stenosis * q.abs();
            self.chain
                .push([sigma, 2.0 * cr.capacitance * cr.stenosis * sign * yd_q]);
        }
    }

    /// Step k's (σ, g) by capacitor.
    fn chain_at(&self, k: usize) -> &[[f64; 2]] {
        let m = self.dae.chain_rule.len();
        self.chain.get(k * m..(k + 1) * m).unwrap_or(&[])
    }

    /// Step k's combined capacitor rows in the iteration matrix's values (`step_values`).
    pub(super) fn chain_values(&self, k: usize, vals: &mut [f64]) {
        let s = &self.scheme;
        let a = s.af * s.gamma * s.dt;
        let nf = self.dae.f.val.len();
        let rows = self.dae.chain_rule.iter().zip(&self.chain_entry);
        for ((cr, &entry), [_, g]) in rows.zip(self.chain_at(k)) {
            // (the base holds α_m E_node, which is C for an RCL vessel's interior point)
            vals[nf + cr.node] += s.am * (cr.capacitance - self.dae.e[cr.node]);
            vals[entry] -= a * g;
        }
    }

    /// The tangent's right side of step k on the capacitor rows: the chain-rule terms in
    /// place of −c E ṡ_node, then the R-branch row combined in (after the sources are added).
    pub(super) fn chain_tangent(&self, k: usize, s: &[f64], sd: &[f64], rs: &mut [f64]) {
        for (m, (cr, [sigma, g])) in self.dae.chain_rule.iter().zip(self.chain_at(k)).enumerate() {
            let c = self.c;
            let e = self.dae.e[cr.node];
            rs[cr.node] += c * e * sd[cr.node]
                - c * cr.capacitance * (sd[cr.inlet] - sigma * sd[cr.flow])
                + g * s[cr.flow];
            rs[cr.node] += self.chain_weight(m) * rs[cr.flow];
        }
    }

    /// The adjoint of the row combination: `u` solved with the combined matrix's transpose
    /// becomes the adjoint of the uncombined right side.
    pub(super) fn chain_uncombine(&self, u: &mut [f64]) {
        for (m, cr) in self.dae.chain_rule.iter().enumerate() {
            u[cr.flow] += self.chain_weight(m) * u[cr.node];
        }
    }

    /// The transpose of [`Primal::chain_tangent`]'s terms in s and ṡ, added to the adjoint
    /// (a, b) of step k's start.
    pub(super) fn chain_adjoint(&self, k: usize, u: &[f64], a: &mut [f64], b: &mut [f64]) {
        for (cr, [sigma, g]) in self.dae.chain_rule.iter().zip(self.chain_at(k)) {
            let (c, un) = (self.c, u[cr.node]);
            a[cr.flow] += g * un;
            b[cr.node] += c * self.dae.e[cr.node] * un;
            b[cr.inlet] -= c * cr.capacitance * un;
            b[cr.flow] += c * cr.capacitance * sigma * un;
        }
    }
}
