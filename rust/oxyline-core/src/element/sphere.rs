//! A spherical heart chamber with wall mechanics (svZeroDSolver's `ChamberSphere`,
//! docs/physics.md §1.11). The chamber is a thin spherical shell of reference radius r₀ and
//! wall thickness d₀ around its pressure node P; its unknowns are the radial displacement r
//! (the radius is R = r₀ + r), the wall velocity v, the wall stress S, the active stress τ and
//! the volume change V. With C = (R/r₀)² the rows are
//!
//! * node:  Σ Q_out − Σ Q_in + 4π v R² = 0 (the growing sphere takes up blood);
//! * r:     ṙ − v = 0;
//! * v:     ρ d₀ v̇ + (R/r₀²)(d₀ S − P R) = 0 (momentum of the wall);
//! * S:     −S + τ + 4(1 − C⁻³)(W₁ + C W₂) + η Ċ (1 + 2C⁻⁶) = 0, Ċ = 2R v/r₀²
//!   (hyperelastic + viscous stress; upstream writes Ċ with ṙ, equal to v by the r row at
//!   every generalized-α level, so both give the same discrete solution);
//! * τ:     τ̇ + |a(t)| τ − σ_max max(a(t), 0) = 0, a = α_max f + α_min (1 − f),
//!   f = S₊S₋, S± = ½(1 ± tanh((t_c − t_sys/dias)/γ)), t_c the time within the cycle;
//! * V:     V̇ − 4π v R² = 0.
//!
//! Every ẏ term has a constant coefficient on its own row, so the mass matrix stays diagonal.

use super::{Element, in_cycle};
use std::f64::consts::PI;

/// The wall's material and activation constants (SI).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereParams {
    /// Wall density ρ (kg/m³).
    pub density: f64,
    /// Reference wall thickness d₀ (m).
    pub thickness: f64,
    /// Reference radius r₀ (m).
    pub radius: f64,
    /// Hyperelastic constants W₁, W₂ (Pa).
    pub w1: f64,
    pub w2: f64,
    /// Wall viscosity η (Pa·s).
    pub viscosity: f64,
    /// Maximum active stress σ_max (Pa).
    pub max_active_stress: f64,
    /// Activation rates α_max, α_min (1/s).
    pub alpha_max: f64,
    pub alpha_min: f64,
    /// Start of systole and of diastole within the cycle (s), and the switch width γ (s).
    pub t_systole: f64,
    pub t_diastole: f64,
    pub steepness: f64,
    /// The cardiac period (s).
    pub period: f64,
}

impl SphereParams {
    /// The activation rate a(t): (|a|, max(a, 0)).
    pub fn activation(&self, t: f64) -> (f64, f64) {
        let a = self.rate(self.switches(t).f);
        (a.abs(), a.max(0.0))
    }

    /// The systole and diastole switches at time t.
    fn switches(&self, t: f64) -> Switches {
        let tc = in_cycle(t, self.period);
        let g = self.steepness;
        let (zp, zm) = ((tc - self.t_systole) / g, (tc - self.t_diastole) / g);
        let s_plus = 0.5 * (1.0 + zp.tanh());
        let s_minus = 0.5 * (1.0 - zm.tanh());
        Switches {
            zp,
            zm,
            s_plus,
            s_minus,
            f: s_plus * s_minus,
        }
    }

    /// a = α_max f + α_min (1 − f) at the switches' product f.
    fn rate(&self, f: f64) -> f64 {
        self.alpha_max * f + self.alpha_min * (1.0 - f)
    }

    /// ∂a/∂θ of the activation rate a(t) for the activation key `key` (None: not one).
    fn activation_derivative(&self, key: &str, t: f64) -> Option<f64> {
        let g = self.steepness;
        let Switches {
            zp,
            zm,
            s_plus,
            s_minus,
            f,
        } = self.switches(t);
        // ∂S₊/∂z₊ = ½ sech² z₊, ∂S₋/∂z₋ = −½ sech² z₋
        let (dsp, dsm) = (0.5 / zp.cosh().powi(2), -0.5 / zm.cosh().powi(2));
        let df = match key {
            "max_activation_rate" => return Some(f),
            "min_activation_rate" => return Some(1.0 - f),
            "systole_start" => -dsp / g * s_minus,
            "diastole_start" => -dsm / g * s_plus,
            "activation_steepness" => -(dsp * zp * s_minus + dsm * zm * s_plus) / g,
            _ => return None,
        };
        Some((self.alpha_max - self.alpha_min) * df)
    }

    /// The passive stress 4(1 − C⁻³)(W₁ + C W₂) and its derivative in R.
    fn elastic(&self, big_r: f64) -> (f64, f64) {
        let r0 = self.radius;
        let c = (big_r / r0).powi(2);
        let c3 = c.powi(-3);
        let s = 4.0 * (1.0 - c3) * (self.w1 + c * self.w2);
        // dC/dR = 2R/r₀², d(C⁻³)/dC = −3C⁻⁴
        let dc = 2.0 * big_r / (r0 * r0);
        let ds = 4.0 * (3.0 * c3 / c * (self.w1 + c * self.w2) + (1.0 - c3) * self.w2) * dc;
        (s, ds)
    }

    /// g(R) = 2R(1 + 2C⁻⁶)/r₀² (the viscous stress η Ċ (1 + 2C⁻⁶) is η g v, as Ċ = 2Rṙ/r₀²)
    /// and its derivative in R.
    fn viscous(&self, big_r: f64) -> (f64, f64) {
        let r0 = self.radius;
        let c6 = (r0 / big_r).powi(12);
        let k = 2.0 / (r0 * r0);
        // d/dR [R + 2 r₀¹² R⁻¹¹] = 1 − 22 r₀¹² R⁻¹²
        (k * big_r * (1.0 + 2.0 * c6), k * (1.0 - 22.0 * c6))
    }
}

/// The activation's switches at one time: z± = (t_c − t_sys/dias)/γ, S₊ = ½(1 + tanh z₊),
/// S₋ = ½(1 − tanh z₋) and their product f.
struct Switches {
    zp: f64,
    zm: f64,
    s_plus: f64,
    s_minus: f64,
    f: f64,
}

/// Unknown indices of a spherical chamber: its pressure node and its five wall unknowns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SphereUnknowns {
    pub pressure: usize,
    pub displacement: usize,
    pub velocity: usize,
    pub stress: usize,
    pub active_stress: usize,
    pub volume: usize,
}

#[derive(Debug, Clone)]
pub struct ChamberSphere {
    pub name: String,
    pub params: SphereParams,
    u: SphereUnknowns,
    rows: [usize; 6],
    pattern: [(usize, usize); 13],
}

impl ChamberSphere {
    pub fn new(name: String, params: SphereParams, u: SphereUnknowns) -> Self {
        let (p, r, v, s, t, vol) = (
            u.pressure,
            u.displacement,
            u.velocity,
            u.stress,
            u.active_stress,
            u.volume,
        );
        ChamberSphere {
            name,
            params,
            u,
            rows: [p, r, v, s, t, vol],
            pattern: [
                (p, r),
                (p, v),
                (r, v),
                (v, r),
                (v, s),
                (v, p),
                (s, s),
                (s, t),
                (s, r),
                (s, v),
                (t, t),
                (vol, r),
                (vol, v),
            ],
        }
    }
}

impl ChamberSphere {
    /// The radius R = r₀ + r, the wall velocity, the stress, the active stress and the
    /// chamber pressure in state `y`.
    fn wall_state(&self, y: &[f64]) -> [f64; 5] {
        let u = &self.u;
        [
            self.params.radius + y[u.displacement],
            y[u.velocity],
            y[u.stress],
            y[u.active_stress],
            y[u.pressure],
        ]
    }
}

impl Element for ChamberSphere {
    element_fields!();
    fn residual(&self, t: f64, y: &[f64], c: &mut [f64]) {
        let q = &self.params;
        let [big_r, vel, stress, tau, p] = self.wall_state(y);
        let growth = 4.0 * PI * vel * big_r * big_r;
        let (abs_a, pos_a) = q.activation(t);
        c[0] = growth;
        c[1] = -vel;
        c[2] = big_r * (q.thickness * stress - p * big_r) / (q.radius * q.radius);
        c[3] = -stress + tau + q.elastic(big_r).0 + q.viscosity * q.viscous(big_r).0 * vel;
        c[4] = abs_a * tau - q.max_active_stress * pos_a;
        c[5] = -growth;
    }
    fn jacobian(&self, t: f64, y: &[f64], j: &mut [f64]) {
        let q = &self.params;
        let [big_r, vel, stress, _, p] = self.wall_state(y);
        let r02 = q.radius * q.radius;
        let (g, dg) = q.viscous(big_r);
        let dgrowth = [8.0 * PI * vel * big_r, 4.0 * PI * big_r * big_r];
        j[0] = dgrowth[0];
        j[1] = dgrowth[1];
        j[2] = -1.0;
        j[3] = (q.thickness * stress - 2.0 * p * big_r) / r02;
        j[4] = big_r * q.thickness / r02;
        j[5] = -big_r * big_r / r02;
        j[6] = -1.0;
        j[7] = 1.0;
        j[8] = q.elastic(big_r).1 + q.viscosity * dg * vel;
        j[9] = q.viscosity * g;
        j[10] = q.activation(t).0;
        j[11] = -dgrowth[0];
        j[12] = -dgrowth[1];
    }
    /// ∂c/∂θ for the wall's and the activation's constants (model keys of
    /// `chamber_sphere`); the density enters only the mass matrix (ρ d₀ on the velocity row,
    /// differentiated by the sensitivity's mass term), so its element term is zero.
    fn parameter_derivative(&self, key: &str, t: f64, y: &[f64], dc: &mut [f64]) -> bool {
        let (q, r0) = (&self.params, self.params.radius);
        let [big_r, vel, stress, tau, p] = self.wall_state(y);
        dc.iter_mut().for_each(|d| *d = 0.0);
        let r02 = r0 * r0;
        let c = (big_r / r0).powi(2);
        match key {
            "density" => {}
            "wall_thickness" => dc[2] = big_r * stress / r02,
            "w1" => dc[3] = 4.0 * (1.0 - c.powi(-3)),
            "w2" => dc[3] = 4.0 * (1.0 - c.powi(-3)) * c,
            "viscosity" => dc[3] = q.viscous(big_r).0 * vel,
            "max_active_stress" => dc[4] = -q.activation(t).1,
            "reference_radius" => {
                // R = r₀ + x moves with r₀ (the displacement x is the unknown)
                let growth = 8.0 * PI * vel * big_r;
                dc[0] = growth;
                dc[5] = -growth;
                dc[2] = (q.thickness * stress - 2.0 * p * big_r) / r02
                    - 2.0 * big_r * (q.thickness * stress - p * big_r) / (r02 * r0);
                // C = (R/r₀)²: dC/dr₀ = 2R(r₀ − R)/r₀³; the stress's derivative in C
                let dc_dr0 = 2.0 * big_r * (r0 - big_r) / (r02 * r0);
                let ds_dc =
                    4.0 * (3.0 * c.powi(-4) * (q.w1 + c * q.w2) + (1.0 - c.powi(-3)) * q.w2);
                // g = 2R/r₀² + 4 r₀¹⁰ R⁻¹¹
                let dg = 2.0 / r02 - 4.0 * big_r / (r02 * r0) + 40.0 * r0.powi(9) * big_r.powi(-11)
                    - 44.0 * r0.powi(10) * big_r.powi(-12);
                dc[3] = ds_dc * dc_dr0 + q.viscosity * dg * vel;
            }
            _ => {
                let Some(da) = q.activation_derivative(key, t) else {
                    return false;
                };
                let a = q.rate(q.switches(t).f);
                // c₄ = |a| τ − σ_max max(a, 0): ∂c₄/∂a = sign(a) τ − σ_max [a > 0]
                let dc_da = if a > 0.0 {
                    tau - q.max_active_stress
                } else if a < 0.0 {
                    -tau
                } else {
                    0.0
                };
                dc[4] = dc_da * da;
            }
        }
        true
    }
    fn is_nonlinear(&self) -> bool {
        true
    }
    fn period(&self) -> Option<f64> {
        Some(self.params.period)
    }
    fn breakpoints(&self) -> Vec<f64> {
        // the activation switches at t_sys and t_dias (tanh of width γ)
        vec![self.params.t_systole, self.params.t_diastole]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params() -> SphereParams {
        SphereParams {
            density: 1e3,
            thickness: 0.01,
            radius: 0.05,
            w1: 10e3,
            w2: 40.0,
            viscosity: 10.0,
            max_active_stress: 185e3,
            alpha_max: 30.0,
            alpha_min: -30.0,
            t_systole: 0.17,
            t_diastole: 0.484,
            steepness: 0.005,
            period: 1.0,
        }
    }

    /// The six unknowns in the order of the test states `y`.
    fn unknowns() -> SphereUnknowns {
        SphereUnknowns {
            pressure: 0,
            displacement: 1,
            velocity: 2,
            stress: 3,
            active_stress: 4,
            volume: 5,
        }
    }

    #[test]
    fn the_jacobian_is_the_derivative_of_the_residual() {
        let u = unknowns();
        let el = ChamberSphere::new("s".into(), params(), u);
        let y = [9e3, 0.004, -0.03, 2.5e4, 3e4, 1e-5];
        let mut j = vec![0.0; el.pattern().len()];
        el.jacobian(0.3, &y, &mut j);
        // central differences, relative steps of 1e-6 (errors O(h²) ≈ 1e-12 relative)
        for (k, &(row, col)) in el.pattern().iter().enumerate() {
            let h = 1e-6 * y[col].abs();
            let (mut yp, mut ym) = (y, y);
            yp[col] += h;
            ym[col] -= h;
            let (mut cp, mut cm) = ([0.0; 6], [0.0; 6]);
            el.residual(0.3, &yp, &mut cp);
            el.residual(0.3, &ym, &mut cm);
            let i = el.rows().iter().position(|&r| r == row).unwrap();
            let fd = (cp[i] - cm[i]) / (2.0 * h);
            assert!(
                (fd - j[k]).abs() <= 1e-6 * fd.abs().max(1e-9),
                "({row}, {col}): {fd} vs {}",
                j[k]
            );
        }
    }

    #[test]
    fn the_unloaded_sphere_is_at_rest_and_activation_follows_the_switches() {
        // at R = r₀, v = 0: no passive stress and no volume change
        let q = params();
        assert_eq!(q.elastic(q.radius).0, 0.0);
        // diastole: a = α_min (|a| = 30, no source); systole: a = α_max
        let (abs_a, pos_a) = q.activation(0.05);
        assert!((abs_a - 30.0).abs() < 1e-9 && pos_a == 0.0);
        let (abs_a, pos_a) = q.activation(0.3);
        assert!((abs_a - 30.0).abs() < 1e-9 && (pos_a - 30.0).abs() < 1e-9);
        // one period later the same (up to the round-off of the time within the cycle)
        assert!((q.activation(1.3).0 - q.activation(0.3).0).abs() < 1e-9);
    }

    /// ∂c/∂θ of every constant against central differences of the residual in θ (relative
    /// step 1e-6: O(h²) truncation), in systole, in diastole and inside both switches.
    #[test]
    fn parameter_derivatives_match_central_differences() {
        let u = unknowns();
        let y = [9e3, 0.004, -0.03, 2.5e4, 3e4, 1e-5];
        let keys = [
            "density",
            "wall_thickness",
            "reference_radius",
            "w1",
            "w2",
            "viscosity",
            "max_active_stress",
            "max_activation_rate",
            "min_activation_rate",
            "systole_start",
            "diastole_start",
            "activation_steepness",
        ];
        // the constant k of `keys`, by field
        fn field(p: &mut SphereParams, k: usize) -> &mut f64 {
            match k {
                0 => &mut p.density,
                1 => &mut p.thickness,
                2 => &mut p.radius,
                3 => &mut p.w1,
                4 => &mut p.w2,
                5 => &mut p.viscosity,
                6 => &mut p.max_active_stress,
                7 => &mut p.alpha_max,
                8 => &mut p.alpha_min,
                9 => &mut p.t_systole,
                10 => &mut p.t_diastole,
                _ => &mut p.steepness,
            }
        }
        for (k, key) in keys.iter().enumerate() {
            // (exact, difference) of every row at every time; compared on the key's scale
            let mut pairs = Vec::new();
            for t in [0.05, 0.168, 0.3, 0.487] {
                let base = ChamberSphere::new("s".into(), params(), u);
                let mut dc = [0.0; 6];
                assert!(base.parameter_derivative(key, t, &y, &mut dc), "{key}");
                let mut res = [[0.0; 6]; 2];
                let mut step = 0.0;
                for (side, sign) in [1.0, -1.0].into_iter().enumerate() {
                    let mut p = params();
                    let x = field(&mut p, k);
                    step = 1e-6 * x.abs();
                    *x += sign * step;
                    ChamberSphere::new("s".into(), p, u).residual(t, &y, &mut res[side]);
                }
                for i in 0..6 {
                    pairs.push((t, i, dc[i], (res[0][i] - res[1][i]) / (2.0 * step)));
                }
            }
            let scale = pairs.iter().fold(0.0f64, |m, p| m.max(p.2.abs()));
            // the density enters only the mass matrix: its element term is zero
            assert!(scale > 0.0 || *key == "density", "{key}");
            for (t, i, exact, fd) in pairs {
                assert!(
                    (fd - exact).abs() <= 1e-6 * scale,
                    "{key} row {i} at {t}: {fd} vs {exact}"
                );
            }
        }
    }
}
