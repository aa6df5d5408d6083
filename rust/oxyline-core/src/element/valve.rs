//! Heart valves: a branch whose resistance depends on the pressure across it
//! (docs/physics.md §1.8). The branch row reads −P_from + P_to + R(P_to − P_from) Q = 0 with
//!
//! * `tanh`: R = (R_max + R_min)/2 + (R_max − R_min)/2 · tanh(k (P_to − P_from)), a smooth
//!   switch of steepness k (1/Pa) — svZeroDSolver's `ValveTanh`;
//! * `piecewise`: R = R_min while P_to < P_from (open), else R_max — svZeroDSolver's
//!   `PiecewiseValve`, whose Jacobian keeps only ∂c/∂Q = R (the jump's derivative is dropped,
//!   as there).

use super::Element;

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ValveLaw {
    Tanh {
        r_min: f64,
        r_max: f64,
        steepness: f64,
    },
    Piecewise {
        r_min: f64,
        r_max: f64,
    },
}

impl ValveLaw {
    /// R and ∂R/∂(P_to − P_from) at the pressure difference `dp` = P_to − P_from.
    pub fn resistance(&self, dp: f64) -> (f64, f64) {
        match *self {
            ValveLaw::Tanh {
                r_min,
                r_max,
                steepness,
            } => {
                let th = (steepness * dp).tanh();
                let half = 0.5 * (r_max - r_min);
                (
                    0.5 * (r_max + r_min) + half * th,
                    half * steepness * (1.0 - th * th),
                )
            }
            ValveLaw::Piecewise { r_min, r_max } => (if dp < 0.0 { r_min } else { r_max }, 0.0),
        }
    }
    /// The law's flow at `dp` = P_to − P_from: −ΔP/R(ΔP) (the branch row's solution).
    pub fn flow(&self, dp: f64) -> f64 {
        -dp / self.resistance(dp).0
    }
    /// dQ/d(ΔP) of the law's flow at `dp` = P_to − P_from: −1/R + ΔP R′/R² (the jump of the
    /// piecewise law left out, as in its Jacobian).
    pub fn flow_slope(&self, dp: f64) -> f64 {
        let (r, dr) = self.resistance(dp);
        (-r + dp * dr) / (r * r)
    }
    /// svZeroDSolver's `valve_status` at `dp` = P_to − P_from: the fraction of the way from
    /// R_min to R_max of the law's switch (0 open, 1 closed), 0.5 (1 + tanh(k dp)) for `tanh`
    /// (its `ValveTanh` outputs it as an internal variable) and 0 or 1 for `piecewise`.
    pub fn closure(&self, dp: f64) -> f64 {
        match *self {
            ValveLaw::Tanh { steepness, .. } => 0.5 * (1.0 + (steepness * dp).tanh()),
            ValveLaw::Piecewise { .. } => {
                if dp < 0.0 {
                    0.0
                } else {
                    1.0
                }
            }
        }
    }
    /// ∂R/∂θ at `dp` = P_to − P_from for the law's parameter `key` (`min_resistance`,
    /// `max_resistance`, the tanh law's `steepness`); None for a key the law does not have.
    /// The piecewise law's switch is a step: away from it R is R_min or R_max itself.
    pub fn parameter_derivative(&self, key: &str, dp: f64) -> Option<f64> {
        match *self {
            ValveLaw::Tanh {
                r_min,
                r_max,
                steepness,
                ..
            } => {
                let th = (steepness * dp).tanh();
                match key {
                    "min_resistance" => Some(0.5 * (1.0 - th)),
                    "max_resistance" => Some(0.5 * (1.0 + th)),
                    "steepness" => Some(0.5 * (r_max - r_min) * dp * (1.0 - th * th)),
                    _ => None,
                }
            }
            ValveLaw::Piecewise { .. } => {
                let open = f64::from(u8::from(dp < 0.0));
                match key {
                    "min_resistance" => Some(open),
                    "max_resistance" => Some(1.0 - open),
                    _ => None,
                }
            }
        }
    }
    pub fn r_min(&self) -> f64 {
        match *self {
            ValveLaw::Tanh { r_min, .. } | ValveLaw::Piecewise { r_min, .. } => r_min,
        }
    }
}

/// A valve on the branch whose flow is unknown `flow`, between pressure unknowns `from`, `to`.
#[derive(Debug, Clone)]
pub struct Valve {
    pub name: String,
    pub law: ValveLaw,
    rows: [usize; 1],
    /// (flow, flow), (flow, from), (flow, to)
    pattern: [(usize, usize); 3],
}

impl Valve {
    pub fn new(name: String, law: ValveLaw, from: usize, to: usize, flow: usize) -> Self {
        Valve {
            name,
            law,
            rows: [flow],
            pattern: [(flow, flow), (flow, from), (flow, to)],
        }
    }
    fn state(&self, y: &[f64]) -> (f64, f64) {
        let [(q, _), (_, from), (_, to)] = self.pattern;
        (y[q], y[to] - y[from])
    }
}

impl Element for Valve {
    element_fields!();
    fn residual(&self, _t: f64, y: &[f64], c: &mut [f64]) {
        let (q, dp) = self.state(y);
        c[0] = self.law.resistance(dp).0 * q;
    }
    fn jacobian(&self, _t: f64, y: &[f64], j: &mut [f64]) {
        let (q, dp) = self.state(y);
        let (r, dr) = self.law.resistance(dp);
        j[0] = r;
        j[1] = -q * dr;
        j[2] = q * dr;
    }
    fn parameter_derivative(&self, key: &str, _t: f64, y: &[f64], dc: &mut [f64]) -> bool {
        let (q, dp) = self.state(y);
        match self.law.parameter_derivative(key, dp) {
            Some(dr) => {
                dc[0] = dr * q;
                true
            }
            None => false,
        }
    }
    /// With an inductor (a chamber's outlet) fixing the valve's flow Q, RK4's elimination
    /// solves the valve row for the pressure difference ΔP = P_to − P_from: its derivative
    /// 1 + Q R′(ΔP) (per unit ΔP) vanishes in backflow where Q R′ = −1, which Newton's iterates
    /// reach away from the solution (the matrix turns singular). At the solution Q = −ΔP/R, so
    /// |Q R′| = |ΔP R′/R| ≤ max_u u sech²u / (1 + tanh u) = 0.28 for the tanh law (u = k ΔP,
    /// R_max ≥ R_min ≥ 0); capping Q R′ at −1/2 therefore leaves Newton exact near the solution
    /// and keeps the matrix regular away from it.
    fn elimination_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.jacobian(t, y, j);
        if j[2] < -0.5 {
            (j[1], j[2]) = (0.5, -0.5);
        }
    }
    /// The row in its flow form, R_min (Q + ΔP/R(ΔP)) = 0 (the F part −P_from + P_to = ΔP is
    /// the circuit's: c = R_min Q + ΔP (R_min/R − 1)): the same solutions as ΔP + R(ΔP) Q = 0,
    /// but monotone in ΔP. The pressure form's ∂/∂ΔP = 1 + Q R′ changes sign in backflow
    /// wherever |Q| R′ > 1 — a tanh law of steepness k reaches R′ = k (R_max − R_min)/2 (5e12
    /// Pa s/m³ per Pa for k = 1e5 /Pa, R_max = 1e8 Pa s/m³: any backflow above 2e-13 m³/s) —
    /// so Newton's linearisation at an iterate away from the solution points away from it
    /// (a closing mitral valve behind its atrium's inductor: Newton cycled through four
    /// iterates at every step length, and the safeguarded matrix gave no descent direction
    /// for the line search). The flow form's ∂/∂ΔP = R_min (R − ΔP R′)/R² ≥ 0.72 R_min/R
    /// (|ΔP R′/R| ≤ 0.28, see `elimination_jacobian`) never vanishes, and its flow −ΔP/R(ΔP)
    /// is convex in ΔP: with an inductor's linear relation between the flow and ΔP, Newton
    /// converges from any iterate. The factor R_min keeps the row in pressure units, equal
    /// to the pressure form while the valve is open. A law with R_min = 0 (an open valve
    /// without resistance: no flow form, its R underflows to 0) keeps the pressure form and
    /// its safeguarded matrix.
    fn flow_form_residual(&self, t: f64, y: &[f64], c: &mut [f64]) {
        let (q, dp) = self.state(y);
        let r_min = self.law.r_min();
        if r_min <= 0.0 {
            return self.residual(t, y, c);
        }
        c[0] = r_min * q + dp * (r_min / self.law.resistance(dp).0 - 1.0);
    }
    fn flow_form_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        let (_, dp) = self.state(y);
        let r_min = self.law.r_min();
        if r_min <= 0.0 {
            return self.elimination_jacobian(t, y, j);
        }
        let (r, dr) = self.law.resistance(dp);
        let by_dp = r_min * (r - dp * dr) / (r * r) - 1.0;
        j[0] = r_min;
        j[1] = -by_dp;
        j[2] = by_dp;
    }
    /// Fully open (R = R_min), with no switching term: the smallest resistance gives the
    /// fastest R–C time constants of the circuit around it.
    fn stiffest_jacobian(&self, _t: f64, _y: &[f64], j: &mut [f64]) {
        j[0] = self.law.r_min();
        j[1] = 0.0;
        j[2] = 0.0;
    }
    /// Fully closed (R = R_max): the fastest R/L rate when an inductor (a chamber's outlet)
    /// drives the valve's flow.
    fn closed_jacobian(&self, _t: f64, _y: &[f64], j: &mut [f64]) {
        j[0] = match self.law {
            ValveLaw::Tanh { r_max, .. } | ValveLaw::Piecewise { r_max, .. } => r_max,
        };
        j[1] = 0.0;
        j[2] = 0.0;
    }
    fn has_closed_state(&self) -> bool {
        true
    }
    fn valve_branch(&self) -> Option<(usize, f64, f64)> {
        let r_max = match self.law {
            ValveLaw::Tanh { r_max, .. } | ValveLaw::Piecewise { r_max, .. } => r_max,
        };
        Some((self.pattern[0].0, self.law.r_min(), r_max))
    }
    fn valve_resistance(&self, y: &[f64], lift: f64) -> f64 {
        // state's ΔP is P_to − P_from: a larger drop is a smaller ΔP
        self.law.resistance(self.state(y).1 - lift).0
    }
    fn valve_flow(&self, y: &[f64]) -> f64 {
        self.law.flow(self.state(y).1)
    }
    fn flow_law(&self) -> Option<super::FlowLaw> {
        let [(q, _), (_, from), (_, to)] = self.pattern;
        Some(super::FlowLaw {
            unknowns: [q, from, to],
            law: self.law,
        })
    }
    /// Open while P_from > P_to (the piecewise law's switch, the tanh law's midpoint).
    fn switches(&self) -> Vec<super::Switch> {
        let [(q, _), (_, from), (_, to)] = self.pattern;
        vec![super::Switch {
            unknowns: [from, to, q],
            on_off: false,
            resistance: self.law.r_min().max(f64::MIN_POSITIVE),
        }]
    }
    fn is_nonlinear(&self) -> bool {
        true
    }
    fn period(&self) -> Option<f64> {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tanh_jacobian_is_the_derivative_of_the_residual() {
        // central differences of c = R(ΔP) Q, step 1e-6 of the scale: truncation O(h²)
        let v = Valve::new(
            "v".into(),
            ValveLaw::Tanh {
                r_min: 1e6,
                r_max: 1e10,
                steepness: 1e-2,
            },
            0,
            1,
            2,
        );
        let y = [1.0e4, 1.0e4 + 37.0, 3e-5];
        let mut j = [0.0; 3];
        v.jacobian(0.0, &y, &mut j);
        for (k, (_, col)) in v.pattern().iter().enumerate() {
            let h = 1e-6 * y[*col].abs().max(1.0);
            let (mut a, mut b) = (y, y);
            a[*col] += h;
            b[*col] -= h;
            let (mut ca, mut cb) = ([0.0], [0.0]);
            v.residual(0.0, &a, &mut ca);
            v.residual(0.0, &b, &mut cb);
            let fd = (ca[0] - cb[0]) / (2.0 * h);
            assert!(
                (fd - j[k]).abs() <= 1e-6 * j[k].abs().max(1e-3),
                "{k}: {fd} vs {}",
                j[k]
            );
        }
    }

    #[test]
    fn flow_form_has_the_same_solutions_and_its_jacobian_is_its_derivative() {
        // the row ΔP + c with ΔP = y[1] − y[0]: at Q = the law's flow both forms vanish; the
        // flow form's ∂row/∂ΔP stays positive in backflow where the pressure form's is
        // negative (|Q| R′ > 1); central differences, truncation O(h²)
        let law = ValveLaw::Tanh {
            r_min: 5e2,
            r_max: 1e8,
            steepness: 1e5,
        };
        let v = Valve::new("v".into(), law, 0, 1, 2);
        let row = |y: &[f64; 3], flow_form: bool| {
            let mut c = [0.0];
            if flow_form {
                v.flow_form_residual(0.0, y, &mut c);
            } else {
                v.residual(0.0, y, &mut c);
            }
            y[1] - y[0] + c[0]
        };
        for dp in [-3.0, -1e-5, 2e-6, 1e-5, 0.4] {
            // (inlet pressure 0, so that ΔP is dp exactly: 1 + dp − 1 would carry a rounding
            // of 1e-16, far above these rows' 1e-12 |dp|)
            let y = [0.0, dp, law.flow(dp)];
            for form in [false, true] {
                assert!(
                    row(&y, form).abs() <= 1e-12 * dp.abs().max(1e-9),
                    "{dp} {form}"
                );
            }
        }
        let y = [0.0, 2e-6, -1e-7];
        let (mut jp, mut jf) = ([0.0; 3], [0.0; 3]);
        v.jacobian(0.0, &y, &mut jp);
        v.flow_form_jacobian(0.0, &y, &mut jf);
        assert!(1.0 + jp[2] < 0.0 && 1.0 + jf[2] > 0.0, "{jp:?} {jf:?}");
        for (k, (_, col)) in v.pattern().iter().enumerate() {
            let h = [1e-12, 1e-12, 1e-14][*col];
            let (mut a, mut b) = (y, y);
            a[*col] += h;
            b[*col] -= h;
            let (mut ca, mut cb) = ([0.0], [0.0]);
            v.flow_form_residual(0.0, &a, &mut ca);
            v.flow_form_residual(0.0, &b, &mut cb);
            let fd = (ca[0] - cb[0]) / (2.0 * h);
            assert!(
                (fd - jf[k]).abs() <= 1e-4 * jf[k].abs(),
                "{k}: {fd} vs {}",
                jf[k]
            );
        }
    }

    #[test]
    fn piecewise_valve_switches_at_zero_pressure_difference() {
        let law = ValveLaw::Piecewise {
            r_min: 1.0,
            r_max: 1e3,
        };
        assert_eq!(law.resistance(-1e-9).0, 1.0);
        assert_eq!(law.resistance(0.0).0, 1e3);
    }

    #[test]
    fn closure_is_the_fraction_of_the_resistance_switch() {
        // svZeroDSolver's valve_status: (R − R_min)/(R_max − R_min), 0 open, 1 closed
        let law = ValveLaw::Tanh {
            r_min: 2.0,
            r_max: 1e4,
            steepness: 0.3,
        };
        for dp in [-50.0, -1.0, 0.0, 0.7, 20.0] {
            let frac = (law.resistance(dp).0 - 2.0) / (1e4 - 2.0);
            assert!((law.closure(dp) - frac).abs() < 1e-12, "{dp}");
        }
        assert_eq!(law.closure(0.0), 0.5);
        let pw = ValveLaw::Piecewise {
            r_min: 1.0,
            r_max: 1e3,
        };
        assert_eq!((pw.closure(-1e-9), pw.closure(0.0)), (0.0, 1.0));
    }
}
