//! The closed-loop heart and pulmonary circulation of Sankaran et al. 2012 as one block
//! (svZeroDSolver's `ClosedLoopHeartAndPulmonary`, docs/physics.md §1.10): four chambers, four
//! on/off valves with inductors, a pulmonary capacitor with its drain resistance and the
//! aortic capacitor. The circuit holds the block's unknowns (`crate::assemble::heart`): the
//! chamber pressures and the aortic pressure as nodes, the valve flows as branches (R = 0 in
//! the constant matrix), the four chamber volumes and the pulmonary pressure as element
//! unknowns. This element adds everything that is not a constant circuit coefficient:
//!
//! * the chamber pressure laws, P_atrium = A(t) E_max (V − V_aso) + (1 − A(t)) K_p
//!   (e^{K_v (V − V_aso)} − 1) and P_ventricle = E_s e(t) (V − V_u), with A the wrapping-cosine
//!   atrial activation and e the 25-mode Fourier elastance series (unscaled);
//! * the on/off valves: a valve is closed (v = 0) when the pressure behind it does not exceed
//!   the pressure in front AND its flow is not positive, else open (v = 1); an open valve adds
//!   R Q to its inductor row and passes Q into the downstream volume; a closed valve's flow is
//!   left out of both volume balances. As in svZeroDSolver the valve state is read from the
//!   Newton iterate and held constant in the Jacobian, and the flow of a closed valve is reset
//!   to zero before each Newton correction ([`Element::after_correction`]).
//! * the pulmonary bed as svZeroDSolver writes it: C_p dP_pul/dt = v_PV Q_PV − (P_pul − P_LA)/R_pd,
//!   while the left atrium receives v_PV Q_PV (the right ventricle's outflow) directly. The
//!   pulmonary valve's branch therefore runs from the right ventricle to the left atrium and its
//!   row gets P_pul − P_LA added, so that it reads L dQ/dt + R v Q = P_RV − P_pul.

use super::activation::{Activation, fourier_raw};
use super::{Element, in_cycle};

/// An atrium's pressure law (an exponential passive part and a linear active one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Atrium {
    /// Active elastance E_max (Pa/m³).
    pub max_elastance: f64,
    /// Passive pressure scale K_p (Pa).
    pub passive_pressure: f64,
    /// Passive volume coefficient K_v (1/m³).
    pub passive_volume_coefficient: f64,
    /// Volume V_aso where both parts vanish (m³).
    pub rest_volume: f64,
}

impl Atrium {
    /// P(V) and dP/dV at activation `a`.
    fn pressure(&self, a: f64, v: f64) -> (f64, f64) {
        let ex = (self.passive_volume_coefficient * (v - self.rest_volume)).exp();
        let psi = self.passive_pressure * (ex - 1.0);
        let dpsi = self.passive_pressure * self.passive_volume_coefficient * ex;
        // svZeroDSolver's split: A E_max V − [A E_max V_aso + ψ (A − 1)]
        (
            a * self.max_elastance * v
                - (a * self.max_elastance * self.rest_volume + psi * (a - 1.0)),
            a * self.max_elastance - dpsi * (a - 1.0),
        )
    }

    /// ∂P/∂θ at activation `a` and volume `v` for the law's model key (`elastance`,
    /// `passive_pressure`, `passive_volume_coefficient`, `rest_volume`), and ∂P/∂a.
    fn pressure_derivative(&self, key: &str, a: f64, v: f64) -> Option<f64> {
        let (e, kp, kv) = (
            self.max_elastance,
            self.passive_pressure,
            self.passive_volume_coefficient,
        );
        let x = v - self.rest_volume;
        let ex = (kv * x).exp();
        // P = a E x − (a − 1) ψ, ψ = K_p (e^{K_v x} − 1)
        Some(match key {
            "elastance" => a * x,
            "passive_pressure" => -(a - 1.0) * (ex - 1.0),
            "passive_volume_coefficient" => -(a - 1.0) * kp * x * ex,
            "rest_volume" => -a * e + (a - 1.0) * kp * kv * ex,
            "activation" => e * x - kp * (ex - 1.0),
            _ => return None,
        })
    }
}

/// The block's parameters (SI).
#[derive(Debug, Clone, PartialEq)]
pub struct HeartParams {
    pub period: f64,
    /// The wrapping-cosine atrial activation (systole fraction T_sa/T, P-wave divisor).
    pub atrial_activation: Activation,
    pub right_atrium: Atrium,
    pub left_atrium: Atrium,
    /// Ventricular elastance scales E_s (Pa/m³) and rest volumes V_u (m³), [right, left].
    pub ventricle_elastance: [f64; 2],
    pub ventricle_rest_volume: [f64; 2],
    /// Open-valve resistances (Pa·s/m³): tricuspid, pulmonary, mitral, aortic.
    pub valve_resistance: [f64; 4],
    /// Pulmonary drain resistance R_pd (Pa·s/m³).
    pub pulmonary_resistance: f64,
}

/// DAE unknowns of the block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HeartUnknowns {
    /// Pressures: right atrium, right ventricle, left atrium, left ventricle, aorta.
    pub pressure: [usize; 5],
    /// Valve flows: tricuspid, pulmonary, mitral, aortic.
    pub flow: [usize; 4],
    /// Volumes (right atrium, right ventricle, left atrium, left ventricle); their rows hold
    /// the chambers' volume balances.
    pub volume: [usize; 4],
    /// Pulmonary pressure (its row: the pulmonary capacitor).
    pub pulmonary: usize,
}

const RA: usize = 0;
const RV: usize = 1;
const LA: usize = 2;
const LV: usize = 3;
const AO: usize = 4;

#[derive(Debug, Clone)]
pub struct HeartPulmonary {
    pub name: String,
    pub params: HeartParams,
    pub unknowns: HeartUnknowns,
    rows: Vec<usize>,
    pattern: Vec<(usize, usize)>,
}

impl HeartPulmonary {
    pub fn new(name: String, params: HeartParams, u: HeartUnknowns) -> Self {
        let (p, q, v, pul) = (u.pressure, u.flow, u.volume, u.pulmonary);
        let rows = vec![
            p[RA], p[RV], p[LA], p[LV], q[0], q[1], q[2], q[3], v[0], v[1], pul, v[2], v[3], p[AO],
        ];
        // in the order `jacobian` writes
        let pattern = vec![
            (p[RA], v[0]),
            (p[RV], v[1]),
            (p[LA], v[2]),
            (p[LV], v[3]),
            (q[0], q[0]),
            (q[1], q[1]),
            (q[1], pul),
            (q[1], p[LA]),
            (q[2], q[2]),
            (q[3], q[3]),
            (v[0], q[0]),
            (v[1], q[1]),
            (v[1], q[0]),
            (pul, q[1]),
            (pul, pul),
            (pul, p[LA]),
            (v[2], q[1]),
            (v[2], q[2]),
            (v[3], q[2]),
            (v[3], q[3]),
            (p[AO], q[3]),
        ];
        HeartPulmonary {
            name,
            params,
            unknowns: u,
            rows,
            pattern,
        }
    }

    /// Valve positions (1 open, 0 closed) at state `y`: tricuspid, pulmonary, mitral, aortic.
    pub fn valves(&self, y: &[f64]) -> [f64; 4] {
        let (p, q) = (self.unknowns.pressure, self.unknowns.flow);
        // the pressures behind and in front of each valve
        let ends = [
            (p[RA], p[RV]),
            (p[RV], self.unknowns.pulmonary),
            (p[LA], p[LV]),
            (p[LV], p[AO]),
        ];
        let mut v = [1.0; 4];
        for (k, (up, down)) in ends.into_iter().enumerate() {
            if y[up] <= y[down] && y[q[k]] <= 0.0 {
                v[k] = 0.0;
            }
        }
        v
    }

    /// ∂c/∂y at (y, t) with the valve positions `v` held.
    fn jacobian_at(&self, t: f64, y: &[f64], v: [f64; 4], j: &mut [f64]) {
        let (u, pr) = (&self.unknowns, &self.params);
        let (a, e) = self.activation(t);
        let rv = pr.valve_resistance;
        let g = 1.0 / pr.pulmonary_resistance;
        j.copy_from_slice(&[
            -pr.right_atrium.pressure(a, y[u.volume[0]]).1,
            -e * pr.ventricle_elastance[0],
            -pr.left_atrium.pressure(a, y[u.volume[2]]).1,
            -e * pr.ventricle_elastance[1],
            rv[0] * v[0],
            rv[1] * v[1],
            1.0,
            -1.0,
            rv[2] * v[2],
            rv[3] * v[3],
            v[0] - 1.0,
            v[1] - 1.0,
            1.0 - v[0],
            -v[1],
            g,
            -g,
            1.0 - v[1],
            v[2] - 1.0,
            1.0 - v[2],
            v[3] - 1.0,
            1.0 - v[3],
        ]);
    }

    /// Atrial activation and the unscaled ventricular elastance at time t.
    fn activation(&self, t: f64) -> (f64, f64) {
        let period = self.params.period;
        (
            self.params.atrial_activation.eval(t, period),
            fourier_raw(in_cycle(t, period), period),
        )
    }
}

impl Element for HeartPulmonary {
    element_fields!();
    fn residual(&self, t: f64, y: &[f64], c: &mut [f64]) {
        let (u, pr) = (&self.unknowns, &self.params);
        let (a, e) = self.activation(t);
        let v = self.valves(y);
        let q = u.flow.map(|i| y[i]);
        let vol = u.volume.map(|i| y[i]);
        let (p_pul, p_la) = (y[u.pulmonary], y[u.pressure[LA]]);
        c[0] = -pr.right_atrium.pressure(a, vol[0]).0;
        c[1] = -e * pr.ventricle_elastance[0] * (vol[1] - pr.ventricle_rest_volume[0]);
        c[2] = -pr.left_atrium.pressure(a, vol[2]).0;
        c[3] = -e * pr.ventricle_elastance[1] * (vol[3] - pr.ventricle_rest_volume[1]);
        for k in 0..4 {
            c[4 + k] = pr.valve_resistance[k] * v[k] * q[k];
        }
        c[5] += p_pul - p_la;
        c[8] = (v[0] - 1.0) * q[0];
        c[9] = (v[1] - 1.0) * q[1] + (1.0 - v[0]) * q[0];
        c[10] = -v[1] * q[1] + (p_pul - p_la) / pr.pulmonary_resistance;
        c[11] = (1.0 - v[1]) * q[1] + (v[2] - 1.0) * q[2];
        c[12] = (1.0 - v[2]) * q[2] + (v[3] - 1.0) * q[3];
        c[13] = (1.0 - v[3]) * q[3];
    }
    fn jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.jacobian_at(t, y, self.valves(y), j);
    }
    /// Every valve open: the resistances R/L damp the inductor rows, and the open valves couple
    /// the chambers to each other (RK4's stability bound, docs/physics.md §1.10).
    fn stiffest_jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        self.jacobian_at(t, y, [1.0; 4], j);
    }
    fn after_correction(&self, y_af: &[f64], y_new: &mut [f64]) {
        for (k, open) in self.valves(y_af).into_iter().enumerate() {
            if open < 0.5 {
                y_new[self.unknowns.flow[k]] = 0.0;
            }
        }
    }
    /// A closed valve's flow does not change (its inductor row would integrate the pressure
    /// difference; svZeroDSolver resets that flow to zero at every iteration instead).
    fn rk4_held(&self, y: &[f64], held: &mut dyn FnMut(usize)) {
        for (k, open) in self.valves(y).into_iter().enumerate() {
            if open < 0.5 {
                held(self.unknowns.flow[k]);
            }
        }
    }
    /// A valve the rule finds closed at the end of a step has its flow clamped at zero: the
    /// step at which a closing valve's flow would reverse.
    fn rk4_after_step(&self, y: &mut [f64]) -> bool {
        let mut changed = false;
        for (k, open) in self.valves(y).into_iter().enumerate() {
            let q = self.unknowns.flow[k];
            if open < 0.5 && y[q] != 0.0 {
                y[q] = 0.0;
                changed = true;
            }
        }
        changed
    }
    fn switched_unknowns(&self) -> Vec<usize> {
        self.unknowns.flow.to_vec()
    }
    /// The four on/off valves (tricuspid, pulmonary, mitral, aortic), read as [`Self::valves`].
    fn switches(&self) -> Vec<super::Switch> {
        let (p, q) = (self.unknowns.pressure, self.unknowns.flow);
        let ends = [
            (p[RA], p[RV]),
            (p[RV], self.unknowns.pulmonary),
            (p[LA], p[LV]),
            (p[LV], p[AO]),
        ];
        (0..4)
            .map(|k| super::Switch {
                unknowns: [ends[k].0, ends[k].1, q[k]],
                on_off: true,
                resistance: if self.params.valve_resistance[k] > 0.0 {
                    self.params.valve_resistance[k]
                } else {
                    1.0
                },
            })
            .collect()
    }
    /// ∂c/∂θ by the block's model key (`heart_pulmonary.<key>`): the chambers' laws
    /// (`right_atrium_elastance`, `left_ventricle_rest_volume`, …), the atrial timing
    /// (`atrial_systole_fraction`, `p_wave_divisor`), the open-valve resistances and the
    /// pulmonary drain resistance, with the valve positions read at `y` as in the residual
    /// (a closed valve's resistance has no term). Inductances and capacitances sit on the
    /// circuit's E and are no element term.
    fn parameter_derivative(&self, key: &str, t: f64, y: &[f64], dc: &mut [f64]) -> bool {
        let (u, pr) = (&self.unknowns, &self.params);
        let (a, e) = self.activation(t);
        dc.iter_mut().for_each(|d| *d = 0.0);
        if let Some((side, rest)) = key.split_once("_atrium_") {
            let (k, law) = match side {
                "right" => (0, &pr.right_atrium),
                "left" => (2, &pr.left_atrium),
                _ => return false,
            };
            let Some(dp) = law.pressure_derivative(rest, a, y[u.volume[k]]) else {
                return false;
            };
            dc[k] = -dp;
            return true;
        }
        let valve = ["tricuspid", "pulmonary_valve", "mitral", "aortic_valve"];
        if let Some(k) = valve.iter().position(|v| key == format!("{v}_resistance")) {
            dc[4 + k] = self.valves(y)[k] * y[u.flow[k]];
            return true;
        }
        match key {
            "right_ventricle_elastance" | "left_ventricle_elastance" => {
                let k = usize::from(key.starts_with("left"));
                let vol = y[u.volume[2 * k + 1]];
                dc[2 * k + 1] = -e * (vol - pr.ventricle_rest_volume[k]);
            }
            "right_ventricle_rest_volume" | "left_ventricle_rest_volume" => {
                let k = usize::from(key.starts_with("left"));
                dc[2 * k + 1] = e * pr.ventricle_elastance[k];
            }
            "pulmonary_resistance" => {
                let r = pr.pulmonary_resistance;
                dc[10] = -(y[u.pulmonary] - y[u.pressure[LA]]) / (r * r);
            }
            "atrial_systole_fraction" | "p_wave_divisor" => {
                let law_key = key.trim_start_matches("atrial_");
                let Some(da) = (pr.atrial_activation).derivative(law_key, t, pr.period) else {
                    return false;
                };
                for (k, law) in [(0, &pr.right_atrium), (2, &pr.left_atrium)] {
                    let dp = law.pressure_derivative("activation", a, y[u.volume[k]]);
                    dc[k] = -dp.unwrap_or(0.0) * da;
                }
            }
            _ => return false,
        }
        true
    }
    fn is_nonlinear(&self) -> bool {
        true
    }
    fn period(&self) -> Option<f64> {
        Some(self.params.period)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A state with the tricuspid and aortic valves open (forward pressure) and the
    /// pulmonary and mitral valves closed (backward pressure, backflow).
    const STATE: [f64; 14] = [
        1500.0, 900.0, 2000.0, 12000.0, 11000.0, 2e-5, -1e-7, -2e-7, 3e-4, 4e-5, 1.2e-4, 3e-5,
        1e-4, 1400.0,
    ];

    fn block() -> HeartPulmonary {
        let atrium = Atrium {
            max_elastance: 2e7,
            passive_pressure: 900.0,
            passive_volume_coefficient: 5e3,
            rest_volume: 5e-6,
        };
        let params = HeartParams {
            period: 1.0,
            atrial_activation: Activation::WrappingCosine {
                systole_fraction: 0.4,
                p_wave_divisor: 9.0,
            },
            right_atrium: atrium,
            left_atrium: atrium,
            ventricle_elastance: [2e7, 3e7],
            ventricle_rest_volume: [9e-6, 5e-6],
            valve_resistance: [8e5, 3e6, 5e5, 3e6],
            pulmonary_resistance: 1e7,
        };
        let u = HeartUnknowns {
            pressure: [0, 1, 2, 3, 4],
            flow: [5, 6, 7, 8],
            volume: [9, 10, 11, 12],
            pulmonary: 13,
        };
        HeartPulmonary::new("h".into(), params, u)
    }

    #[test]
    fn jacobian_is_the_derivative_of_the_residual_at_fixed_valves() {
        // tricuspid and aortic valves open (forward pressure), pulmonary and mitral closed
        // (backward pressure, backflow): central differences with the valve states unchanged
        let h = block();
        let y = STATE;
        assert_eq!(h.valves(&y), [1.0, 0.0, 0.0, 1.0]);
        let t = 0.95; // inside the atrial contraction
        let mut j = vec![0.0; h.pattern().len()];
        h.jacobian(t, &y, &mut j);
        for (k, &(row, col)) in h.pattern().iter().enumerate() {
            let r = h.rows().iter().position(|&i| i == row).unwrap();
            let step = 1e-6 * y[col].abs().max(1e-12);
            let (mut a, mut b) = (y, y);
            a[col] += step;
            b[col] -= step;
            let (mut ca, mut cb) = ([0.0; 14], [0.0; 14]);
            h.residual(t, &a, &mut ca);
            h.residual(t, &b, &mut cb);
            let fd = (ca[r] - cb[r]) / (2.0 * step);
            // O(step²) truncation of the exponential atrium law, round-off elsewhere
            assert!(
                (fd - j[k]).abs() <= 1e-6 * j[k].abs().max(1.0),
                "({row}, {col}): {fd} vs {}",
                j[k]
            );
        }
    }

    /// Set the block's parameter `key` to `x` (the model keys of `parameter_derivative`).
    fn with(mut h: HeartPulmonary, key: &str, x: f64) -> HeartPulmonary {
        let p = &mut h.params;
        let slot: &mut f64 = match key {
            "right_atrium_elastance" => &mut p.right_atrium.max_elastance,
            "left_atrium_passive_pressure" => &mut p.left_atrium.passive_pressure,
            "right_atrium_passive_volume_coefficient" => {
                &mut p.right_atrium.passive_volume_coefficient
            }
            "left_atrium_rest_volume" => &mut p.left_atrium.rest_volume,
            "right_ventricle_elastance" => &mut p.ventricle_elastance[0],
            "left_ventricle_elastance" => &mut p.ventricle_elastance[1],
            "left_ventricle_rest_volume" => &mut p.ventricle_rest_volume[1],
            "tricuspid_resistance" => &mut p.valve_resistance[0],
            "aortic_valve_resistance" => &mut p.valve_resistance[3],
            "pulmonary_resistance" => &mut p.pulmonary_resistance,
            _ => match &mut p.atrial_activation {
                Activation::WrappingCosine {
                    systole_fraction,
                    p_wave_divisor,
                } => {
                    if key == "atrial_systole_fraction" {
                        systole_fraction
                    } else {
                        p_wave_divisor
                    }
                }
                _ => unreachable!(),
            },
        };
        *slot = x;
        h
    }

    #[test]
    fn parameter_derivatives_are_the_residuals_central_differences() {
        // valves held (tricuspid and aortic open), inside the atrial contraction
        let y = STATE;
        let t = 0.95;
        let values = [
            ("right_atrium_elastance", 2e7),
            ("left_atrium_passive_pressure", 900.0),
            ("right_atrium_passive_volume_coefficient", 5e3),
            ("left_atrium_rest_volume", 5e-6),
            ("right_ventricle_elastance", 2e7),
            ("left_ventricle_elastance", 3e7),
            ("left_ventricle_rest_volume", 5e-6),
            ("tricuspid_resistance", 8e5),
            ("aortic_valve_resistance", 3e6),
            ("pulmonary_resistance", 1e7),
            ("atrial_systole_fraction", 0.4),
            ("p_wave_divisor", 9.0),
        ];
        for (key, x) in values {
            let mut dc = [0.0; 14];
            assert!(block().parameter_derivative(key, t, &y, &mut dc), "{key}");
            let h = 1e-5 * x;
            let (mut ca, mut cb) = ([0.0; 14], [0.0; 14]);
            with(block(), key, x + h).residual(t, &y, &mut ca);
            with(block(), key, x - h).residual(t, &y, &mut cb);
            for r in 0..14 {
                let fd = (ca[r] - cb[r]) / (2.0 * h);
                // O(h²) truncation of the exponential and cosine laws, and round-off of
                // residuals up to ~1e4 Pa differenced over h
                let tol = 1e-7 * (dc[r].abs() + ca[r].abs() / x);
                assert!(
                    (fd - dc[r]).abs() <= tol,
                    "{key} row {r}: {fd} vs {}",
                    dc[r]
                );
            }
        }
        let mut dc = [0.0; 14];
        assert!(!block().parameter_derivative("period", t, &y, &mut dc));
    }

    #[test]
    fn closed_valve_flows_are_reset_before_a_correction() {
        let h = block();
        let y = STATE;
        let mut y_new = y;
        h.after_correction(&y, &mut y_new);
        assert_eq!(&y_new[5..9], &[2e-5, 0.0, 0.0, 3e-4]);
    }

    #[test]
    fn atrium_law_and_its_derivative() {
        // closed form at activation a: a E (V − V0) + (1 − a) K_p (e^{K_v (V − V0)} − 1)
        let at = Atrium {
            max_elastance: 2.0,
            passive_pressure: 3.0,
            passive_volume_coefficient: 0.5,
            rest_volume: 1.0,
        };
        let (a, v) = (0.3, 2.2);
        let exact = a * 2.0 * (v - 1.0) + (1.0 - a) * 3.0 * ((0.5f64 * (v - 1.0)).exp() - 1.0);
        let (p, dp) = at.pressure(a, v);
        assert!((p - exact).abs() < 1e-14, "{p} vs {exact}");
        let h = 1e-6;
        let fd = (at.pressure(a, v + h).0 - at.pressure(a, v - h).0) / (2.0 * h);
        assert!((fd - dp).abs() < 1e-8, "{fd} vs {dp}");
    }
}
