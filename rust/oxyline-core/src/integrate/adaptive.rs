//! Error control for generalized-α (docs/physics.md §10): the tolerances, the local error
//! estimate of a step, the step-size controller and the dense output between steps.
//!
//! * **Local error.** Generalized-α's principal root on ẏ = λy is e^z − C z³ + O(z⁴), z = λh,
//!   |C| = 1/12 + ¼((1 − ρ∞)/(1 + ρ∞))² (1/12 the trapezoidal rule at ρ∞ = 1, 1/9 at the
//!   default 0.5, 1/3 at 0). The quadratic through the last three accepted states, extrapolated
//!   to the new time, misses y(t + h) by y'''·h(h + h₁)(h + h₁ + h₂)/6; the difference between
//!   the step's result and that extrapolation is therefore (π/6 + |C|h³) y''' (π the product),
//!   and the step's local error |C|h³ y''' is that difference times |C|h³/(π/6 + |C|h³)
//!   (Milne's device: one extrapolation per step, no second solve).
//! * **Error per unit step.** A periodic forced response accumulates the local errors τ of
//!   its harmonic at ω into a global error τ/(h|iω − λ|) ≤ τ/(hω); the controlled quantity is
//!   therefore le/(h ω_i), ω_i the unknown's signal frequency peak|ÿ|/peak|ẏ| (at least the
//!   fundamental ω₁ = 2π/T; `run::adaptive`): an upper bound of the periodic response's error
//!   except near a resonance (|iω − λ| < ω, quality factor Q > 1, up to Q× more).
//! * **Species.** The split transport step is backward Euler (first order): its local error
//!   h²z̈/2 is h/(2h + h₁) times its difference from the linear extrapolation of the last two
//!   accepted amounts, weighted per cell by atol·V₀ + rtol·|N| (a concentration tolerance).
//! * **Dense output.** Generalized-α's carried ẏₙ is the rate at tₙ − δh, δ = γ − ½ (exact for
//!   the principal root to O(h²)); the cubic Hermite interpolant uses the rates shifted back to
//!   the step ends with the step's own ÿ, so output between steps keeps the method's order.

/// The kinds of unknowns an absolute tolerance is given for, in the order of [`Atol`] and of
/// the reported estimate.
pub const KINDS: [&str; 4] = ["pressure", "flow", "volume", "species"];

/// The smallest share of its kind's largest scale an unknown's default absolute tolerance is
/// scaled to (see [`Tolerances::atol_of`]): an unknown that is (nearly) zero so far is not held to a
/// vanishing tolerance.
pub const SHARE_FLOOR: f64 = 1e-4;

/// A kind's default absolute tolerance is at most this share of rtol times the kind's
/// characteristic magnitude (its largest |y| so far; see [`Tolerances::kind_atol`]): the
/// kind's largest unknown is then held within 1.3 rtol of its own size. Measured on
/// svZeroDSolver's heart cases in small numbers (cardiac output against a fine fixed step,
/// rtol 1e-2 … 1e-4): 1.6–2.6 rtol off at a cap of 1, 1.05–1.5 at 0.3, 1.0–1.2 at 0.1; the
/// physiological models keep their SI defaults at rtol 1e-2 and 1e-3 under any of these, and
/// at 1e-4 paper-bifurcated takes 1.26× the steps at 0.3, 1.43× at 0.1.
pub const SCALE_CAP: f64 = 0.3;

/// Absolute tolerances per kind, SI.
///
/// A kind's default atol belongs to its largest unknown, capped at rtol times that unknown's
/// magnitude (a model in small units is held to rtol as a physiological one is: see
/// [`Tolerances::kind_atol`]); every other unknown of the kind gets it scaled by its own scale
/// over that largest one's (at least [`SHARE_FLOOR`]), so that each is held to rtol of its
/// own size (a small vessel's flow, a low-pressure bed's pressure, a small concentration) and
/// not to the absolute error the largest one may make. A kind the user gives (`given`) is
/// absolute as given, the same for every unknown of the kind (as an atol vector's entries in
/// CVODE).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Atol {
    /// Pa (default 1 Pa = 0.0075 mmHg).
    pub pressure: f64,
    /// m³/s (default 1e-9 m³/s = 1 µL/s).
    pub flow: f64,
    /// m³, chamber volumes (default 1e-9 m³ = 1 µL).
    pub volume: f64,
    /// mol/m³, species concentration (default 1e-6 mol/m³).
    pub species: f64,
    /// The kinds (in the order of [`KINDS`]) whose atol the user gave.
    pub given: [bool; 4],
}

impl Default for Atol {
    fn default() -> Self {
        Atol {
            pressure: 1.0,
            flow: 1e-9,
            volume: 1e-9,
            species: 1e-6,
            given: [false; 4],
        }
    }
}

impl Atol {
    pub fn as_array(&self) -> [f64; 4] {
        [self.pressure, self.flow, self.volume, self.species]
    }
}

/// What an error-controlled run asks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    pub rtol: f64,
    pub atol: Atol,
}

impl Tolerances {
    /// The absolute tolerance of the largest unknown of kind `kind` (index into [`KINDS`]),
    /// of magnitude `largest` (the kind's characteristic magnitude: its largest |y| so far,
    /// seeded by the scout pass where there is one): the given atol as it is; the SI default
    /// capped at `SCALE_CAP`·rtol·largest, so that the kind's largest unknown is held within
    /// 1.3 rtol of its own size whatever the model's units (svZeroDSolver's cases in small
    /// numbers read as cgs reach 8 Pa and 4e-8 m³/s, within the SI defaults, which then
    /// left their signals uncontrolled); the whole default while the kind has no magnitude
    /// yet. A physiological model keeps the SI default (1 Pa is 7.7e-5 of 13 kPa).
    pub fn kind_atol(&self, kind: usize, largest: f64) -> f64 {
        let a = self.atol.as_array()[kind];
        if self.atol.given[kind] || largest <= 0.0 || !largest.is_finite() {
            return a;
        }
        a.min(SCALE_CAP * self.rtol * largest)
    }

    /// The absolute tolerance of an unknown of kind `kind` whose scale is `scale`, the
    /// largest scale of its kind being `largest`: the given atol as it is, the kind's
    /// ([`Tolerances::kind_atol`]) scaled by scale/largest (in [`SHARE_FLOOR`], 1]; the
    /// whole default while the kind has no scale yet).
    pub fn atol_of(&self, kind: usize, scale: f64, largest: f64) -> f64 {
        let a = self.kind_atol(kind, largest);
        if self.atol.given[kind] || largest <= 0.0 || !largest.is_finite() {
            return a;
        }
        a * (scale / largest).clamp(SHARE_FLOOR, 1.0)
    }
}

/// |C| of generalized-α's local error |C| h³ y''' (see the module comment).
pub fn local_error_constant(rho_inf: f64) -> f64 {
    let r = (1.0 - rho_inf) / (1.0 + rho_inf);
    1.0 / 12.0 + 0.25 * r * r
}

/// δ = γ − ½: the carried rate ẏₙ is the rate at tₙ − δh.
pub fn rate_shift(rho_inf: f64) -> f64 {
    let am = 0.5 * (3.0 - rho_inf) / (1.0 + rho_inf);
    let af = 1.0 / (1.0 + rho_inf);
    am - af
}

/// The step-size controller on the error per unit step (order 2 for the flow: the error falls
/// as h²; order 1 for the species), safety 0.9, growth at most 1.5× and shrinking at most 5×
/// per step.
///
/// * **PI control** (Gustafsson): after an accepted step the factor is
///   0.9 · err^(−0.4) · err_old^(0.1), err_old the previous accepted step's error. Against the
///   elementary err^(−1/2) it smooths the step sequence: on adan56 (rtol 1e-3, 3 cycles)
///   rejected steps 175 → 75 at the same error.
/// * **Dead band**: after a step that met its tolerances the step is kept unless the controller would grow it
///   by 1.25× or more (as CVODE keeps h under a growth of 1.5): a step that met its tolerance is
///   not shrunk on a rising error (the next one is rejected if it must), so a linear circuit
///   keeps its factorised iteration matrix instead of refactorising on every small change.
#[derive(Debug, Clone, Copy)]
pub struct StepControl {
    pub h_min: f64,
    pub h_max: f64,
}

pub const SAFETY: f64 = 0.9;
pub const GROW: f64 = 1.5;
pub const SHRINK: f64 = 0.2;
/// The PI controller's exponents of the current and the previous scaled error.
pub const PI_ERR: f64 = 0.4;
pub const PI_OLD: f64 = 0.1;
/// A growth below this keeps the step (the dead band).
pub const KEEP_BELOW: f64 = 1.25;
/// Scaled errors below this count as this in the PI factor (an exact step, err = 0, would
/// otherwise make the next factor 0 through err_old).
const ERR_FLOOR: f64 = 1e-4;

impl StepControl {
    /// The next step after an accepted step of `h` with the scaled errors (≤ 1 meets the
    /// tolerance), `err_old` the flow error of the accepted step before it.
    pub fn next(&self, h: f64, flow_err: f64, err_old: f64, species_err: f64) -> f64 {
        let mut factor =
            SAFETY * flow_err.max(ERR_FLOOR).powf(-PI_ERR) * err_old.max(ERR_FLOOR).powf(PI_OLD);
        if species_err > 0.0 {
            factor = factor.min(SAFETY / species_err);
        }
        let factor = factor.clamp(SHRINK, GROW);
        // (a step that missed a tolerance, kept at the smallest step or a species error
        // judged after the fact, still shrinks)
        let met = flow_err <= 1.0 && species_err <= 1.0;
        let factor = if met && factor < KEEP_BELOW {
            1.0
        } else {
            factor
        };
        (h * factor).clamp(self.h_min, self.h_max)
    }

    /// The step to try after a step of `h` was rejected with the scaled error `err` (> 1):
    /// the elementary controller's, at most half of `h`.
    pub fn after_rejection(&self, h: f64, err: f64) -> f64 {
        let factor = if err.is_finite() {
            (SAFETY * err.powf(-0.5)).max(SHRINK)
        } else {
            SHRINK
        };
        (h * factor.min(0.5)).max(self.h_min)
    }
}

/// Weights of the quadratic through (−h₁ − h₂, −h₁, 0) evaluated at h (Lagrange), for the
/// values (y_{n−2}, y_{n−1}, yₙ); and the factor |C|h³/(π/6 + |C|h³) from the difference to
/// the local error.
pub fn quadratic_extrapolation(h: f64, h1: f64, h2: f64, c: f64) -> ([f64; 3], f64) {
    let (a, b, x) = (-(h1 + h2), -h1, h);
    let la = (x - b) * x / ((a - b) * a);
    let lb = (x - a) * x / ((b - a) * b);
    let lc = (x - a) * (x - b) / (a * b);
    let pi = h * (h + h1) * (h + h1 + h2);
    let ch3 = c * h * h * h;
    ([la, lb, lc], ch3 / (pi / 6.0 + ch3))
}

/// Cubic Hermite basis at θ ∈ [0, 1] for (y₀, h d₀, y₁, h d₁), and its derivative (per unit θ).
pub fn hermite(theta: f64) -> ([f64; 4], [f64; 4]) {
    let (t2, t3) = (theta * theta, theta * theta * theta);
    (
        [
            2.0 * t3 - 3.0 * t2 + 1.0,
            t3 - 2.0 * t2 + theta,
            -2.0 * t3 + 3.0 * t2,
            t3 - t2,
        ],
        [
            6.0 * t2 - 6.0 * theta,
            3.0 * t2 - 4.0 * theta + 1.0,
            -6.0 * t2 + 6.0 * theta,
            3.0 * t2 - 2.0 * theta,
        ],
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Generalized-α's principal root on ẏ = λy (the amplification of (y, hẏ)).
    fn principal_root(z: f64, rho: f64) -> f64 {
        let am = 0.5 * (3.0 - rho) / (1.0 + rho);
        let af = 1.0 / (1.0 + rho);
        let g = 0.5 + am - af;
        let d = am - af * g * z;
        let (b_y, b_v) = (z / d, (af * (1.0 - g) * z - (1.0 - am)) / d);
        let (a00, a01) = (1.0 + g * b_y, (1.0 - g) + g * b_v);
        let (tr, det) = (a00 + b_v, a00 * b_v - a01 * b_y);
        let disc = (tr * tr - 4.0 * det).sqrt();
        let (l1, l2) = ((tr + disc) / 2.0, (tr - disc) / 2.0);
        if (l1 - 1.0).abs() < (l2 - 1.0).abs() {
            l1
        } else {
            l2
        }
    }

    #[test]
    fn the_error_constant_is_that_of_the_principal_root() {
        // (e^z − root)/z³ → −|C| as z → 0, for the trapezoidal end, the default and ρ∞ = 0
        for rho in [1.0, 0.5, 0.0] {
            let z: f64 = 1e-3;
            let c = (z.exp() - principal_root(z, rho)) / (z * z * z);
            let want = local_error_constant(rho);
            assert!((c + want).abs() < 2e-3 * want, "ρ∞ {rho}: {c} vs −{want}");
        }
        assert!((local_error_constant(0.5) - 1.0 / 9.0).abs() < 1e-15);
        assert!((rate_shift(0.5) - 1.0 / 6.0).abs() < 1e-15);
    }

    #[test]
    fn extrapolation_is_exact_for_quadratics_and_scales_the_cubic_error() {
        let (h, h1, h2) = (0.3, 0.2, 0.5);
        let ([la, lb, lc], _) = quadratic_extrapolation(h, h1, h2, 0.1);
        let q = |t: f64| 1.0 - 2.0 * t + 3.0 * t * t;
        let p = la * q(-h1 - h2) + lb * q(-h1) + lc * q(0.0);
        assert!((p - q(h)).abs() < 1e-12);
        // a cubic t³ is missed by h(h + h1)(h + h1 + h2) (y''' = 6)
        let p3 = la * (-h1 - h2).powi(3) + lb * (-h1).powi(3);
        let miss = h.powi(3) - p3;
        assert!((miss - h * (h + h1) * (h + h1 + h2)).abs() < 1e-12);
    }

    #[test]
    fn hermite_reproduces_cubics() {
        let y = |t: f64| 2.0 + t - 3.0 * t * t + 0.5 * t * t * t;
        let d = |t: f64| 1.0 - 6.0 * t + 1.5 * t * t;
        let (t0, h) = (0.4, 0.7);
        for theta in [0.0, 0.25, 0.6, 1.0] {
            let (b, db) = hermite(theta);
            let v = b[0] * y(t0) + b[1] * h * d(t0) + b[2] * y(t0 + h) + b[3] * h * d(t0 + h);
            let dv =
                (db[0] * y(t0) + db[1] * h * d(t0) + db[2] * y(t0 + h)) / h + db[3] * d(t0 + h);
            let t = t0 + theta * h;
            assert!((v - y(t)).abs() < 1e-12 && (dv - d(t)).abs() < 1e-12);
        }
    }

    #[test]
    fn a_default_atol_is_scaled_by_the_unknowns_share_and_a_given_one_is_kept() {
        let d = Tolerances {
            rtol: 1e-3,
            atol: Atol::default(),
        };
        // the kind's largest unknown keeps the default; a 1e-3 share gets 1e-3 of it; the
        // floor; no scale yet: the whole default
        assert_eq!(d.atol_of(1, 5e-4, 5e-4), 1e-9);
        assert!((d.atol_of(1, 5e-7, 5e-4) - 1e-12).abs() < 1e-24);
        assert!((d.atol_of(0, 0.0, 1e4) - SHARE_FLOOR).abs() < 1e-18);
        assert_eq!(d.atol_of(3, 0.0, 0.0), 1e-6);
        let given = Tolerances {
            atol: Atol {
                flow: 1e-8,
                given: [false, true, false, false],
                ..d.atol
            },
            ..d
        };
        assert_eq!(given.atol_of(1, 5e-7, 5e-4), 1e-8);
        assert!((given.atol_of(0, 10.0, 1e4) - 1e-3).abs() < 1e-15);
        // a given atol is kept below rtol of a small model's scale too
        assert_eq!(given.atol_of(1, 4e-8, 4e-8), 1e-8);
    }

    #[test]
    fn a_default_atol_follows_a_small_models_scale() {
        let d = Tolerances {
            rtol: 1e-3,
            atol: Atol::default(),
        };
        // a physiological scale keeps the SI default: 1e-3 of 13 kPa is 13 Pa > 1 Pa
        assert_eq!(d.kind_atol(0, 1.3e4), 1.0);
        // a model in small units (8.3 Pa, 4e-8 m³/s): rtol of its largest unknown, where
        // the SI default (1 Pa, 1e-9 m³/s) was an eighth of its pressures and its cardiac
        // output
        let p = d.kind_atol(0, 8.3);
        assert!((p - SCALE_CAP * 8.3e-3).abs() < 1e-15, "{p}");
        let q = d.kind_atol(1, 4e-8);
        assert!((q - SCALE_CAP * 4e-11).abs() < 1e-24, "{q}");
        // and its smaller unknowns their share of it
        let q = d.atol_of(1, 4e-9, 4e-8);
        assert!((q - SCALE_CAP * 4e-12).abs() < 1e-24, "{q}");
        // the same relative tolerance in any units: a model scaled by 1e-3 is held to 1e-3
        // of the absolute tolerance
        let (a, b) = (d.atol_of(0, 2.0, 8.3), d.atol_of(0, 2e-3, 8.3e-3));
        assert!((b / a - 1e-3).abs() < 1e-12, "{a} {b}");
    }

    #[test]
    fn the_controller_keeps_grows_and_shrinks_within_its_limits() {
        let c = StepControl {
            h_min: 1e-9,
            h_max: 1.0,
        };
        // a growth under 1.25× keeps the step, and so does a rising error that met the
        // tolerance (0.9·0.7^-0.4 = 1.04; 0.9·0.95^-0.4·0.5^0.1 = 0.86)
        assert_eq!(c.next(0.01, 0.7, 0.7, 0.0), 0.01);
        assert_eq!(c.next(0.01, 0.95, 0.5, 0.0), 0.01);
        assert!((c.next(0.01, 0.01, 0.01, 0.0) - 0.015).abs() < 1e-15); // capped at 1.5×
        // PI: a falling error grows the step less than a steady one of the same size
        let (steady, falling) = (c.next(0.01, 0.2, 0.2, 0.0), c.next(0.01, 0.2, 0.05, 0.0));
        assert!(falling < steady && steady < 0.015, "{falling} {steady}");
        // an exact step (err 0 now and before) grows at most 1.5×, never collapses
        assert!((c.next(0.01, 0.0, 0.0, 0.0) - 0.015).abs() < 1e-15);
        // species (first order) decide when their error is the larger: 0.9/2 shrinks
        assert!((c.next(0.01, 0.1, 0.1, 2.0) - 0.01 * 0.45).abs() < 1e-15);
        // after a rejection: at most half, at most 5× smaller, 5× on a failed solve
        assert!((c.after_rejection(0.01, 1.2) - 0.005).abs() < 1e-15);
        assert!((c.after_rejection(0.01, 1e6) - 0.002).abs() < 1e-15);
        assert!((c.after_rejection(0.01, f64::INFINITY) - 0.002).abs() < 1e-15);
    }
}
