//! Smooth nonlinear and time-varying circuit elements with off-diagonal couplings: heart
//! chambers with a time-varying elastance E(t) and valves with a pressure-dependent resistance
//! (docs/physics.md §1.8, docs/svzerod.md "Chambers and valves").
//!
//! An element adds a residual contribution c(y, t) to some rows of the circuit DAE
//! E ẏ + F y + c(y) + c_el(y, t) = f(t) and supplies its Jacobian ∂c_el/∂y on a fixed sparsity
//! pattern, as svZeroDSolver's blocks do with their `C` vector and `dC_dy` matrix (they also
//! allow ∂c/∂ẏ; no element here needs it: every ẏ term stays on the constant diagonal E).
//! The integrators treat a circuit without elements exactly as before (generalized-α factorises
//! once, RK4 eliminates a constant algebraic part): elements only switch on the per-step
//! (time-varying) or per-iteration (nonlinear) refactorisation.

/// The three accessors of an [`Element`] that keeps its `name`, `rows` and `pattern` as fields
/// (every element here does): one definition instead of one copy per element.
macro_rules! element_fields {
    () => {
        fn name(&self) -> &str {
            &self.name
        }
        fn rows(&self) -> &[usize] {
            &self.rows
        }
        fn pattern(&self) -> &[(usize, usize)] {
            &self.pattern
        }
    };
}

pub mod activation;
pub mod chamber;
pub mod coronary;
pub mod heart;
pub mod sphere;
pub mod valve;

use std::fmt::Debug;

/// A switching law's event inputs (docs/physics.md §10.5): where a valve's status is read.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Switch {
    /// [pressure behind, pressure in front, flow] unknowns.
    pub unknowns: [usize; 3],
    /// The heart block's on/off rule (open also while its flow is forward; a closed valve's
    /// flow is held at zero); else the pressure rule (open while the pressure behind exceeds
    /// the pressure in front).
    pub on_off: bool,
    /// A resistance turning the flow into a pressure in the closing function of the on/off
    /// rule, max(ΔP, R Q) (any positive value locates the same root).
    pub resistance: f64,
}

/// A branch whose flow its element's law gives from the pressures at its two ends alone (a
/// `valve` element): where that flow is an algebraic unknown, the dense output between the
/// steps of an error-controlled run reads it from the law at the interpolated pressures
/// (docs/solvers.md, "Dense output").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowLaw {
    /// [flow, pressure at the branch's start, pressure at its end] unknowns.
    pub unknowns: [usize; 3],
    pub law: valve::ValveLaw,
}

impl FlowLaw {
    /// The law's flow at the pressures `p_from`, `p_to` of the branch's ends, and its
    /// derivative in the pressure difference P_to − P_from.
    pub fn flow(&self, p_from: f64, p_to: f64) -> (f64, f64) {
        let dp = p_to - p_from;
        (self.law.flow(dp), self.law.flow_slope(dp))
    }
}

/// A circuit element that is nonlinear in the state or varies in time. Row and column indices
/// are unknowns of the assembled DAE.
pub trait Element: Debug + Send + Sync {
    /// The element's name (for error messages).
    fn name(&self) -> &str;
    /// The rows it contributes to (c has one value per row, in this order).
    fn rows(&self) -> &[usize];
    /// The (row, column) entries of ∂c/∂y, in the order of [`Element::jacobian`].
    fn pattern(&self) -> &[(usize, usize)];
    /// c(y, t), one value per row of [`Element::rows`].
    fn residual(&self, t: f64, y: &[f64], c: &mut [f64]);
    /// ∂c/∂y at (y, t) in [`Element::pattern`] order.
    fn jacobian(&self, t: f64, y: &[f64], j: &mut [f64]);
    /// The Jacobian RK4's stability bound uses: the element in its stiffest state at time `t`
    /// (e.g. a valve fully open). Default: the Jacobian at (y, t).
    fn stiffest_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.jacobian(t, y, j);
    }
    /// The Jacobian of RK4's Newton elimination of the algebraic unknowns (the differential
    /// ones fixed): a matrix that keeps that iteration well defined away from the solution
    /// (see the valve's). Default: the Jacobian at (y, t).
    fn elimination_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.jacobian(t, y, j);
    }
    /// c(y, t) with the row written so that Newton converges from afar where its own form
    /// does not: a valve's row in its flow form (see the valve's). The same solutions.
    /// Default: [`Element::residual`].
    fn flow_form_residual(&self, t: f64, y: &[f64], c: &mut [f64]) {
        self.residual(t, y, c);
    }
    /// ∂c/∂y of [`Element::flow_form_residual`]. Default: [`Element::elimination_jacobian`]
    /// (the safeguarded matrix of a row kept in its own form).
    fn flow_form_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.elimination_jacobian(t, y, j);
    }
    /// The Jacobian with every valve closed (RK4's stability bound also takes this state: a
    /// closed valve's R_max behind an inductor sets the R/L rate). Default: the stiffest.
    fn closed_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.stiffest_jacobian(t, y, j);
    }
    /// Whether [`Element::closed_jacobian`] differs from the stiffest state.
    fn has_closed_state(&self) -> bool {
        false
    }
    /// Called by generalized-α before each Newton correction is added to the iterate
    /// `y_new`, with the α_f level `y_af` of the residual it corrects (svZeroDSolver's
    /// `post_solve`: the heart block resets the flows of its closed valves). Default: nothing.
    fn after_correction(&self, _y_af: &[f64], _y_new: &mut [f64]) {}
    /// Why RK4 cannot integrate this element (None: it can).
    fn rk4_unsupported(&self) -> Option<String> {
        None
    }
    /// The differential unknowns of a switching law (a valve's flow) that RK4 holds at zero
    /// rate at stage state `y` (a closed valve), reported through `held`: the explicit form of
    /// an on/off law (docs/physics.md §1.10). Default: none.
    fn rk4_held(&self, _y: &[f64], _held: &mut dyn FnMut(usize)) {}
    /// Project a completed RK4 step onto the switching law (a valve the law finds closed has
    /// its flow clamped at zero); true when the state changed. Default: nothing.
    fn rk4_after_step(&self, _y: &mut [f64]) -> bool {
        false
    }
    /// The unknowns [`Element::rk4_held`] may hold (each needs a differential row).
    fn switched_unknowns(&self) -> Vec<usize> {
        Vec::new()
    }
    /// A valve's branch: (its flow unknown, R_min, R_max). Behind an inductor (a chamber's
    /// outlet) such a branch relaxes at R(ΔP)/L, which RK4 treats as algebraic when that rate
    /// exceeds 1/Δt (docs/physics.md §1.8, "stiff branches"). Default: not a valve.
    fn valve_branch(&self) -> Option<(usize, f64, f64)> {
        None
    }
    /// The valve's resistance R(ΔP) at state `y` with its pressure drop P_from − P_to raised
    /// by `lift` (0: the valve's own reading; see [`Element::valve_branch`]).
    fn valve_resistance(&self, _y: &[f64], _lift: f64) -> f64 {
        0.0
    }
    /// The valve law's flow (P_from − P_to)/R(ΔP) at the pressures of `y` (see
    /// [`Element::valve_branch`]).
    fn valve_flow(&self, _y: &[f64]) -> f64 {
        0.0
    }
    /// The branch whose flow the element's law gives from its end pressures alone (see
    /// [`FlowLaw`]). Default: none.
    fn flow_law(&self) -> Option<FlowLaw> {
        None
    }
    /// The element's switches, whose status changes are located as events by the
    /// error-controlled runs (docs/physics.md §10.5). Default: none.
    fn switches(&self) -> Vec<Switch> {
        Vec::new()
    }
    /// ∂c/∂θ at (y, t) for the element's parameter `key` (its model key, e.g. a valve's
    /// `max_resistance`), one value per row of [`Element::rows`]: the source of a parameter
    /// sensitivity (`crate::sensitivity`). False when `key` names no parameter the element
    /// differentiates (the default: none).
    fn parameter_derivative(&self, _key: &str, _t: f64, _y: &[f64], _dc: &mut [f64]) -> bool {
        false
    }
    /// c depends on the state other than linearly (Newton refactorises per iteration).
    fn is_nonlinear(&self) -> bool;
    /// The period of c's time dependence (None: c does not depend on time).
    fn period(&self) -> Option<f64>;
    /// Times within a period where the time law has a kink or an extreme (sampled by RK4's
    /// stability bound besides an even grid).
    fn breakpoints(&self) -> Vec<f64> {
        Vec::new()
    }
}

/// Time within the cycle, as svZeroDSolver's `fmod(t, T)`.
pub(crate) fn in_cycle(t: f64, period: f64) -> f64 {
    t % period
}
