//! PWDB's laws against closed forms: the Moens–Korteweg wave speed of the thin wall, the
//! cf-PWV of a uniform path, the area shares of a bed, and the calibration of one tapered
//! segment whose steady pressure is Poiseuille's law in series with its outlet.

use super::beds::{self, Bed};
use super::wall::{self, SitePath};
use super::{DENSITY, OUTFLOW_PRESSURE, POISSON_RATIO, Segment, VISCOSITY};
use std::f64::consts::PI;

fn uniform(n: usize, r: f64, length: f64) -> Vec<Segment> {
    (1..=n)
        .map(|i| Segment {
            inlet: i,
            outlet: i + 1,
            length,
            radius_in: r,
            radius_out: r,
        })
        .collect()
}

fn close(a: f64, b: f64, rtol: f64) -> bool {
    (a / b - 1.0).abs() < rtol
}

#[test]
fn wave_speed_is_moens_korteweg_of_the_thin_wall() {
    // c² = E h / (2 ρ r (1 − ν²)) with ν = 1/2 and the E, h that the wall law gives
    let geo = uniform(1, 4e-3, 0.1);
    let k3 = 3.37e5;
    let (h, e) = wall::wall_properties(&geo, &geo, k3)[0];
    let r = 4e-3;
    let c_thin = (e * h / (2.0 * DENSITY * r * (1.0 - POISSON_RATIO * POISSON_RATIO))).sqrt();
    // rounding of a few operations
    assert!(close(wall::wave_speed(r, k3, DENSITY), c_thin, 1e-14));
    // the law by hand: Eh/r = 0.1 (3e6 exp(−13.5 · 0.4) + 3.37e5) Pa
    let ehr = 0.1 * (3.0e6 * (-13.5f64 * 0.4).exp() + 3.37e5);
    assert!(close(wall::eh_over_r(r, k3), ehr, 1e-15));
    assert!(close(
        wall::wall_thickness(0.01),
        0.01 * (0.2802 * (-5.053f64).exp() + 0.1324 * (-0.1114f64).exp()),
        1e-15
    ));
}

#[test]
fn cf_pwv_of_a_uniform_path_is_its_wave_speed_and_fit_k3_inverts_it() {
    let geo = uniform(6, 5e-3, 0.05);
    let femoral = SitePath {
        segments: &[1, 2, 3, 4],
        site: 5,
    };
    let carotid = SitePath {
        segments: &[1],
        site: 6,
    };
    let k3 = 2.0e5;
    let c = wall::wave_speed(5e-3, k3, DENSITY);
    let pwv = wall::cf_pwv(&geo, femoral, carotid, k3, DENSITY).unwrap();
    assert!(close(pwv, c, 1e-13), "{pwv} {c}");
    let fitted = wall::fit_k3(&geo, femoral, carotid, pwv, DENSITY).unwrap();
    // bisection to 1e-12 relative in k3
    assert!(close(fitted, k3, 1e-11), "{fitted}");
    let far = wall::fit_k3(&geo, femoral, carotid, 1e3, DENSITY).unwrap_err();
    assert!(far.to_string().contains("out of reach"), "{far}");
    let bad = SitePath {
        segments: &[9],
        site: 1,
    };
    assert!(wall::cf_pwv(&geo, bad, carotid, k3, DENSITY).is_err());
}

#[test]
fn windkessels_share_a_bed_by_outlet_area() {
    let mut geo = uniform(3, 2e-3, 0.05);
    geo[2].radius_out = 4e-3;
    let bed = Bed {
        segments: vec![2, 3],
        resistance: 1e9,
        compliance: 1e-9,
    };
    let wks = beds::windkessels(&geo, &[bed], 3.37e5, 0.5).unwrap();
    assert_eq!(wks.len(), 2);
    // areas 1 : 4: the R2 in parallel are the bed's R, the C add up to pvc × the bed's C
    let parallel = 1.0 / (1.0 / wks[0].bed_resistance + 1.0 / wks[1].bed_resistance);
    assert!(close(parallel, 1e9, 1e-15));
    assert!(close(wks[0].bed_resistance, 5e9, 1e-15));
    assert!(close(
        wks[0].capacitance + wks[1].capacitance,
        0.5e-9,
        1e-15
    ));
    let r = 4e-3;
    let z = DENSITY * wall::wave_speed(r, 3.37e5, DENSITY) / (PI * r * r);
    assert!(close(wks[1].impedance, z, 1e-15));
}

#[test]
fn calibration_of_one_segment_matches_poiseuille_in_series() {
    // one tapered segment n1 → n2, outlet R1 + s R_bed to the outflow pressure: the steady
    // root pressure is P_out + Q (R_tube + R1 + s R_bed), R_tube = 8μ/(3πk)(r_in⁻³ − r_out⁻³)
    let geo = vec![Segment {
        inlet: 1,
        outlet: 2,
        length: 0.2,
        radius_in: 6e-3,
        radius_out: 4e-3,
    }];
    let bed = Bed {
        segments: vec![1],
        resistance: 1.5e8,
        compliance: 1e-8,
    };
    let k3 = 3.37e5;
    let wks = beds::windkessels(&geo, &[bed], k3, 1.0).unwrap();
    let walls = wall::wall_properties(&geo, &geo, k3);
    let (q, target) = (2e-5, 95.0 * super::MMHG);
    let s = beds::calibrate_scale(&geo, &walls, 1, &wks, q, target).unwrap();
    let k = (4e-3 - 6e-3) / 0.2;
    let tube = 8.0 * VISCOSITY / (3.0 * PI * k) * (6e-3f64.powi(-3) - 4e-3f64.powi(-3));
    let exact = ((target - OUTFLOW_PRESSURE) / q - tube - wks[0].impedance) / 1.5e8;
    // secant to 1e-10 relative in the pressure; the segment's closed form vs the core's
    // stable form of the same integral (rounding)
    assert!(close(s, exact, 1e-8), "{s} {exact}");
    // below the drop across the tube and R1: s < 0, refused (R1 + s R_bed still > 0)
    let below = OUTFLOW_PRESSURE + 0.999 * q * (tube + wks[0].impedance);
    let low = beds::calibrate_scale(&geo, &walls, 1, &wks, q, below).unwrap_err();
    assert!(low.to_string().contains("out of reach"), "{low}");
}

#[test]
fn template_lvet_is_the_linear_zero_crossing_after_the_peak() {
    // a triangle up to 3 at sample 3, down through zero between samples 5 (1) and 6 (−1):
    // crossing at 5.5 ms; the negative sample before the peak does not count
    let q = [-0.5, 1.0, 2.0, 3.0, 2.0, 1.0, -1.0, -0.5];
    let lvet = super::inflow::template_lvet(&q).unwrap();
    assert!(close(lvet, 5.5e-3, 1e-15), "{lvet}");
    assert!(super::inflow::template_lvet(&[0.0, 1.0, 2.0]).is_err());
}

#[test]
fn aortic_inflow_stretches_the_systole_and_keeps_the_stroke_volume() {
    // a sine over 320 samples, positive for its first 299 ms: template LVET ≈ 0.299 s
    let q: Vec<f64> = (0..320).map(|k| (PI * k as f64 / 299.0).sin()).collect();
    let (hr, sv, lvet) = (60.0, 70e-6, 0.4);
    let (t, f) = super::inflow::aortic_inflow(&q, hr, sv, lvet).unwrap();
    assert_eq!(t.len(), q.len() + 2);
    assert_eq!(*t.last().unwrap(), 1.0); // the period 60/hr
    let t_lvet = super::inflow::template_lvet(&q).unwrap();
    assert!(close(t[299], 0.299 * lvet / t_lvet, 1e-14));
    // the net volume by the trapezoid rule, summed here left to right (order: 1e-15)
    let v: f64 = t
        .windows(2)
        .zip(f.windows(2))
        .map(|(t, f)| (t[1] - t[0]) * (f[0] + f[1]) / 2.0)
        .sum();
    assert!(close(v, sv, 1e-14), "{v}");
    // flow ∝ the template: the shape is kept
    assert!(close(f[150] / f[75], q[150] / q[75], 1e-14));
    // a heart period shorter than the stretched systole is refused, naming both
    let err = super::inflow::aortic_inflow(&q, 200.0, sv, lvet).unwrap_err();
    assert!(err.to_string().contains("heart rate 200/min"), "{err}");
}

#[test]
fn subject_geometry_scales_the_large_arteries_and_the_proximal_aorta() {
    // 1 → 2 → 3 (large, 5 mm), 3 → 4 small (1 mm): segments 1, 2 large, segment 3 fed by 2
    let mut geo = uniform(3, 5e-3, 0.1);
    geo[2].radius_in = 1e-3;
    geo[2].radius_out = 1e-3;
    let sub = super::geometry::subject_geometry(&geo, 1.1, 0.8);
    assert_eq!(sub[0].radius_in, 5e-3 * 1.1);
    assert_eq!(sub[1].radius_out, 5e-3 * 1.1);
    assert_eq!(sub[2].radius_in, 1e-3 * 1.1); // its inlet is fed by a large artery
    assert_eq!(sub[2].radius_out, 1e-3); // its outlet is not large
    assert_eq!(sub[0].length, 0.1 * 0.8);
    assert_eq!(sub[1].length, 0.1 * 0.8);
    assert_eq!(sub[2].length, 0.1);
    let d: Vec<usize> = super::geometry::diameter_segments(&geo)
        .into_iter()
        .collect();
    assert_eq!(d, [1, 2, 3]);
}

#[test]
fn the_beds_are_in_si_and_a_network_must_end_in_them() {
    // brain: 6.904 mmHg s/mL = 6.904 · 133.33 · 1e6 Pa s/m³
    let beds = beds::vascular_beds();
    assert_eq!(beds.len(), 16);
    assert!(close(beds[0].resistance, 6.904 * 133.33e6, 1e-15));
    assert!(close(beds[0].compliance, 0.021726 / 133.33e6, 1e-15));
    let err = beds::check_terminals(&uniform(3, 1e-3, 0.1)).unwrap_err();
    assert!(
        err.to_string().contains("terminal segments [3, 10,"),
        "{err}"
    );
}
