//! A coronary bed in a closed loop whose intramyocardial pressure is a fraction of a ventricle's
//! pressure (svZeroDSolver's `ClosedLoopCoronaryLeft`/`Right`, docs/physics.md §1.10). The
//! circuit holds R_a, the arterial capacitor C_a, R_am and R_v as ordinary parts
//! (`crate::assemble::heart`); the intramyocardial compartment's volume V_im is an element
//! unknown whose row holds the compartment node's flow balance, and the node's own row is
//!
//!   P_im,node = V_im / C_im + k P_ventricle,
//!
//! the compartment's capacitor referenced to k·P_ventricle (k: svZeroDSolver's `iml`/`imr`),
//! written as svZeroDSolver writes it, C_im P_im,node − V_im − C_im k P_ventricle = 0: the node's
//! row holds P_im,node with coefficient 1, so the element adds (C_im − 1) P_im,node. The row's
//! scale matters with svZeroDSolver's absolute Newton tolerance (see `jacobian`).

use super::Element;

#[derive(Debug, Clone)]
pub struct ClosedLoopCoronary {
    pub name: String,
    pub capacitance: f64,
    pub factor: f64,
    rows: [usize; 1],
    /// (node, volume), (node, ventricle pressure), (node, node)
    pattern: [(usize, usize); 3],
}

impl ClosedLoopCoronary {
    pub fn new(
        name: String,
        capacitance: f64,
        factor: f64,
        node: usize,
        volume: usize,
        ventricle: usize,
    ) -> Self {
        ClosedLoopCoronary {
            name,
            capacitance,
            factor,
            rows: [node],
            pattern: [(node, volume), (node, ventricle), (node, node)],
        }
    }
}

impl Element for ClosedLoopCoronary {
    element_fields!();
    fn residual(&self, _t: f64, y: &[f64], c: &mut [f64]) {
        let [(_, v), (_, p), (_, m)] = self.pattern;
        let cim = self.capacitance;
        c[0] = (cim - 1.0) * y[m] - y[v] - cim * self.factor * y[p];
    }
    /// svZeroDSolver gives no ∂c/∂P_ventricle (its `dC_dy` stays empty for this block), so its
    /// Newton converges linearly on this row and stops by its absolute residual; with the
    /// heart's on/off valves the iterate it stops at decides the valve timing. The coupling is
    /// left out of the iteration matrix here too, and the row has svZeroDSolver's scale (the
    /// residual is exact, so a converged step satisfies the same equations). Measured on
    /// closedLoopHeart_withCoronaries: the exact Jacobian ends 1.5e-2 off svZeroDSolver.
    fn jacobian(&self, _t: f64, _y: &[f64], j: &mut [f64]) {
        j[0] = -1.0;
        j[1] = 0.0;
        j[2] = self.capacitance - 1.0;
    }
    /// Linear with constant coefficients, but its coupling to the ventricle lies outside the
    /// circuit's constant matrix: declared nonlinear so that every integrator evaluates it
    /// through the element path (it is only ever used next to the nonlinear heart block).
    fn is_nonlinear(&self) -> bool {
        true
    }
    fn period(&self) -> Option<f64> {
        None
    }
}
