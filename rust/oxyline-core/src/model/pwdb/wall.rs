//! PWDB's wall law E h/r₀ = k1 exp(k2 r₀) + k3 (Mynard & Smolich 2015 eq. 3; PWDB's k2 = 1.5 ×
//! Mynard's), its Moens–Korteweg wave speed c² = (2/3)(E h/r₀)/ρ, the wall thickness law of the
//! vessels, the theoretical carotid-femoral pulse wave velocity, and the k3 that gives one.

use super::{ELEMENT, Segment};
use crate::error::{Error, Result};

/// k1 [g s⁻² cm⁻¹] of the wall law.
pub const K1_CGS: f64 = 3.0e6;
/// k2 [cm⁻¹] of the wall law (PWDB's: 1.5 × Mynard's −9).
pub const K2_CGS: f64 = -9.0 * 1.5;
/// k3 [g s⁻² cm⁻¹] of PWDB's baseline subject.
pub const K3_CGS: f64 = 3.37e5;
/// Wall thickness h = r (a e^(b r) + c e^(d r)), r in cm: not PWDB's (its 1-D model takes E h)
/// but the law of circulatory_autogen's vessels; only E h enters the thin-wall compliance, so
/// h labels the wall and E carries the stiffness.
pub const THICKNESS: [f64; 4] = [0.2802, -5.053, 0.1324, -0.1114];

/// E h/r₀ [Pa] at radius `r` [m] with the constant `k3_cgs` [g s⁻² cm⁻¹].
pub fn eh_over_r(r: f64, k3_cgs: f64) -> f64 {
    0.1 * (K1_CGS * (K2_CGS * 100.0 * r).exp() + k3_cgs)
}

/// Moens–Korteweg wave speed [m/s] of the wall law: c = √((2/3) (E h/r₀) / ρ).
pub fn wave_speed(r: f64, k3_cgs: f64, density: f64) -> f64 {
    (2.0 / 3.0 * eh_over_r(r, k3_cgs) / density).sqrt()
}

/// Wall thickness [m] of a vessel of radius `r` [m] (the law of [`THICKNESS`]).
pub fn wall_thickness(r: f64) -> f64 {
    let [a, b, c, d] = THICKNESS;
    let rc = 100.0 * r;
    r * (a * (b * rc).exp() + c * (d * rc).exp())
}

/// (wall thickness, Young's modulus) of each segment: h by the thickness law at the baseline
/// segment's mean radius (kept as the subject's radii change), E = (E h/r₀)(r) r / h at the
/// subject's mean radius r, so that the wave speed at r is the wall law's.
pub fn wall_properties(base: &[Segment], subject: &[Segment], k3_cgs: f64) -> Vec<(f64, f64)> {
    base.iter()
        .zip(subject)
        .map(|(b, s)| {
            let h = wall_thickness(b.mean_radius());
            let r = s.mean_radius();
            (h, eh_over_r(r, k3_cgs) * r / h)
        })
        .collect()
}

/// A path to a measurement site: segment numbers (from 1) from the aortic root, then the site
/// at the middle of segment `site`.
#[derive(Debug, Clone, Copy)]
pub struct SitePath<'a> {
    pub segments: &'a [usize],
    pub site: usize,
}

/// The segment `s` (from 1) of `geo`, or an error naming it.
fn segment(geo: &[Segment], s: usize) -> Result<&Segment> {
    s.checked_sub(1).and_then(|i| geo.get(i)).ok_or_else(|| {
        Error::model(
            ELEMENT,
            format!("segment {s} is not in the network's {} segments", geo.len()),
        )
    })
}

/// (path length [m], transit time [s]) to the middle of the site segment: each segment's
/// L / c at its mean radius, the site's half at its half's radius.
fn transit(geo: &[Segment], path: SitePath<'_>, k3_cgs: f64, density: f64) -> Result<(f64, f64)> {
    let (mut length, mut time) = (0.0, 0.0);
    for &s in path.segments {
        let g = segment(geo, s)?;
        length += g.length;
        time += g.length / wave_speed(g.mean_radius(), k3_cgs, density);
    }
    let g = segment(geo, path.site)?;
    length += g.length / 2.0;
    time += g.length / 2.0 / wave_speed(g.site_radius(0.5), k3_cgs, density);
    Ok((length, time))
}

/// Theoretical carotid-femoral pulse wave velocity [m/s] of the wall law: the difference of
/// the path lengths to the femoral and carotid sites over the difference of their transit
/// times (PWDB's `calculate_theoretical_wave_speeds`).
pub fn cf_pwv(
    geo: &[Segment],
    femoral: SitePath<'_>,
    carotid: SitePath<'_>,
    k3_cgs: f64,
    density: f64,
) -> Result<f64> {
    let (lf, tf) = transit(geo, femoral, k3_cgs, density)?;
    let (lc, tc) = transit(geo, carotid, k3_cgs, density)?;
    Ok((lf - lc) / (tf - tc))
}

/// The k3 [g s⁻² cm⁻¹] whose cf-PWV is `target` [m/s]: the cf-PWV increases with k3, so
/// bisection over [0, 5e7] (E h/r₀ > 0 at the aortic radii needs k3 ≥ 0) to 1e-12 relative.
pub fn fit_k3(
    geo: &[Segment],
    femoral: SitePath<'_>,
    carotid: SitePath<'_>,
    target: f64,
    density: f64,
) -> Result<f64> {
    let pwv = |k3: f64| cf_pwv(geo, femoral, carotid, k3, density);
    let (mut lo, mut hi) = (0.0, 5e7);
    if !(pwv(lo)? < target && target < pwv(hi)?) {
        return Err(Error::model(
            ELEMENT,
            format!(
                "cf-PWV {} m/s out of reach of the wall law",
                crate::model::structured_tree::fmt_g(target)
            ),
        ));
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if pwv(mid)? < target {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-12 * f64::abs(hi) {
            break;
        }
    }
    Ok(0.5 * (lo + hi))
}
