//! Oxygen around a closed circulation (docs/oxygen.md "Oxygen around a closed loop"): an organ
//! compartment's closed-form washout, the lung's equilibration solution (dissolved O2) and an
//! independent quadrature of Bohr's integral (Hill binding), the loop's exact mass balance and
//! Fick's principle at periodic steady state.

use oxyline_core::hemoglobin::{Binding, BindingSpec};
use oxyline_core::transport::closed_loop::{ClosedLoopSpec, run_periodic};
use oxyline_core::transport::compartment::{self, Consumption};
use oxyline_core::transport::lung::LungExchange;

const MMHG: f64 = 133.322368;
/// Blood O2: solubility 0.003 mL dL⁻¹ mmHg⁻¹ = 1.34e-3 mol m⁻³ mmHg⁻¹; Hb 150 g/L × 1.34 mL/g
/// = 201 mL/L = 8.97 mol/m³; P50 26.8 mmHg, n 2.7.
const ALPHA: f64 = 1.34e-3 / MMHG;
const CAP: f64 = 8.97;

fn hill() -> Binding {
    Binding::from_spec(&hill_spec(), "test").unwrap()
}

fn hill_spec() -> BindingSpec {
    BindingSpec::Hill {
        solubility: ALPHA,
        p50: 26.8 * MMHG,
        n: 2.7,
        capacity: CAP,
    }
}

#[test]
fn compartment_washout_follows_the_closed_form_to_first_order() {
    // V dC/dt = Q (C_in − C) − VO2 with constant Q, C_in, VO2: C(t) = C_ss + (C0 − C_ss) e^{−Qt/V},
    // C_ss = C_in − VO2/Q. Backward Euler: steady state exact, transient error O(dt).
    let (v, q, c_in, vo2, c0) = (1e-4, 1e-5, 8.0, 2e-5, 5.0);
    let c_ss = c_in - vo2 / q;
    let fixed = Consumption::Fixed { rate: vo2 };
    let err = |dt: f64| {
        let (mut c, mut e) = (c0, 0.0_f64);
        let steps = (20.0 / dt).round() as usize; // 2 time constants V/Q = 10 s
        for s in 1..=steps {
            c = compartment::step(&hill(), &fixed, ALPHA, (v, c), v, dt, q, q * c_in, 0.0).0;
            let exact = c_ss + (c0 - c_ss) * (-q * s as f64 * dt / v).exp();
            e = e.max((c - exact).abs());
        }
        (e / (c0 - c_ss).abs(), c)
    };
    let (e1, _) = err(1e-2);
    let (e2, _) = err(5e-3);
    assert!(e1 < 1e-3, "{e1}");
    assert!(
        (e1 / e2 - 2.0).abs() < 0.02,
        "first order: ratio {}",
        e1 / e2
    );
    // steady state: exact for any step
    let mut c = c_ss;
    for _ in 0..100 {
        c = compartment::step(&hill(), &fixed, ALPHA, (v, c), v, 0.37, q, q * c_in, 0.0).0;
    }
    assert!((c - c_ss).abs() <= 1e-14 * c_ss);
}

#[test]
fn michaelis_menten_compartment_reaches_its_steady_balance() {
    // steady state: Q (C_in − C) = vmax P/(km + P) at the compartment's own PO2
    let (v, q, c_in) = (2e-4, 1e-5, 8.5);
    let law = Consumption::MichaelisMenten {
        vmax: 3e-5,
        km: 1.0 * MMHG,
    };
    let b = hill();
    let mut c = c_in;
    let mut free = ALPHA * 90.0 * MMHG;
    for _ in 0..20000 {
        c = compartment::step(&b, &law, ALPHA, (v, c), v, 0.05, q, q * c_in, free).0;
        free = b.free(c, free);
    }
    let p = free / ALPHA;
    let vo2 = 3e-5 * p / (MMHG + p);
    assert!(
        (q * (c_in - c) - vo2).abs() <= 1e-12 * vo2,
        "{} vs {vo2}",
        q * (c_in - c)
    );
}

#[test]
fn lung_without_haemoglobin_is_the_equilibration_solution() {
    // C = αP: P_out = P_A − (P_A − P_in) exp(−D_L/(αQ))
    let (pa, dl, q, p_in) = (100.0 * MMHG, 1.5e-5 / MMHG, 8e-5, 40.0 * MMHG);
    let lung = LungExchange::new(pa, dl, "lungs").unwrap();
    let b = Binding::None;
    for &qq in &[q, 10.0 * q, 100.0 * q] {
        let out = lung.end_capillary(&b, ALPHA, ALPHA * p_in, qq) / ALPHA;
        let exact = pa - (pa - p_in) * (-dl / (ALPHA * qq)).exp();
        assert!((out - exact).abs() <= 1e-12 * pa, "{out} vs {exact}");
    }
}

#[test]
fn lung_with_hill_binding_solves_bohrs_integral() {
    // The capillary fraction needed to go from P_in to P_out is
    // s = ∫ Q dC_t/dP dP / (D_L (P_A − P)) (Bohr); the exchanger's P_out must give s = 1.
    // Independent evaluation: composite Simpson in u = ln(P_A − P), 20,000 intervals.
    let b = hill();
    let (pa, p_in) = (100.0 * MMHG, 40.0 * MMHG);
    let lung = LungExchange::new(pa, 1.56e-5 / MMHG, "lungs").unwrap();
    for &q in &[8.3e-5, 2.5e-4, 5e-4] {
        let ct = lung.end_capillary(&b, ALPHA, b.total(ALPHA * p_in), q);
        let p_out = b.free(ct, ALPHA * pa) / ALPHA;
        let (u0, u1) = ((pa - p_in).ln(), (pa - p_out).ln());
        let n = 20_000;
        let h = (u1 - u0) / n as f64;
        let g = |u: f64| {
            let p = pa - u.exp();
            // ds/du = −Q dC_t/dP / D_L  (dP = −y du, y = e^u)
            -q * ALPHA * b.capacity_slope(ALPHA * p) / lung.diffusing_capacity
        };
        let mut s = g(u0) + g(u1);
        for i in 1..n {
            s += if i % 2 == 1 { 4.0 } else { 2.0 } * g(u0 + i as f64 * h);
        }
        s *= h / 3.0;
        // an error δs in the capillary fraction is an error δs D_L (P_A − P_out)/Q in the
        // end-capillary content (the local exchange rate): within 1e-9 of the content
        let dc = (s - 1.0).abs() * lung.diffusing_capacity * (pa - p_out) / q;
        assert!(
            dc <= 1e-9 * ct,
            "Q {q}: capillary fraction {s}, content error {dc}"
        );
        assert!(p_out > p_in && p_out < pa);
    }
}

/// LV → arteries → {brain, muscle} → veins → RV → (lungs) → LV.
fn loop_spec(consumption: &str) -> ClosedLoopSpec {
    let json = format!(
        r#"{{"compartments": [
            {{"name": "lv", "volume": 1.2e-4, "initial_po2": 5000}},
            {{"name": "arteries", "volume": 1.0e-3, "initial_po2": 5000}},
            {{"name": "brain", "volume": 1.0e-4, "initial_po2": 5000, "consumption": {consumption}}},
            {{"name": "muscle", "volume": 4.0e-4, "initial_po2": 5000,
              "consumption": {{"kind": "michaelis-menten", "vmax": 8e-5, "km": 133.3}}}},
            {{"name": "veins", "volume": 3.0e-3, "initial_po2": 5000}},
            {{"name": "rv", "volume": 1.2e-4, "initial_po2": 5000}}],
          "branches": [
            {{"name": "aortic", "from": 0, "to": 1}},
            {{"name": "brain_in", "from": 1, "to": 2}},
            {{"name": "muscle_in", "from": 1, "to": 3}},
            {{"name": "brain_out", "from": 2, "to": 4}},
            {{"name": "muscle_out", "from": 3, "to": 4}},
            {{"name": "venous_return", "from": 4, "to": 5}},
            {{"name": "pulmonary", "from": 5, "to": 0,
              "lungs": {{"alveolar_po2": 13332.2, "diffusing_capacity": 1.17e-7}}}}],
          "binding": {{"kind": "hill", "solubility": {ALPHA}, "p50": {}, "n": 2.7,
                       "capacity": {CAP}}}}}"#,
        26.8 * MMHG
    );
    serde_json::from_str(&json).unwrap()
}

/// Pulsatile ejections (half-sines over 0.3 s of a 1 s cycle), steady organ flows and venous
/// return, mean 8.33e-5 m³/s (5 L/min); the chambers fill in diastole.
fn flows(steps: usize) -> Vec<f64> {
    let q = 8.333e-5;
    let shape: Vec<f64> = (0..steps)
        .map(|s| {
            let t = (s as f64 + 0.5) / steps as f64;
            if t < 0.3 {
                (std::f64::consts::PI * t / 0.3).sin()
            } else {
                0.0
            }
        })
        .collect();
    // half-sine ejection scaled so that its discrete mean is q: periodic volumes
    let mean = shape.iter().sum::<f64>() / steps as f64;
    let mut f = Vec::new();
    for s in shape {
        let ej = q * s / mean;
        f.extend_from_slice(&[ej, 0.25 * q, 0.75 * q, 0.25 * q, 0.75 * q, q, ej]);
    }
    f
}

#[test]
fn closed_loop_mass_balance_is_exact_and_fick_holds_at_periodic_steady_state() {
    let spec = loop_spec(r#"{"kind": "fixed", "rate": 3.7e-5}"#);
    let steps = 1000;
    let dt = 1.0 / steps as f64;
    let run = run_periodic(&spec, &flows(steps), dt, 200, 1e-13).unwrap();
    assert!(
        run.periodic_error <= 1e-13,
        "{} after {} cycles",
        run.periodic_error,
        run.cycles
    );
    let (nc, nb) = (6, 7);
    // per step: ΔN = dt (lung uptake − Σ VO2), to round-off of N
    let mut prev = run.amount_start;
    let (mut lung, mut vo2, mut fick) = (0.0, 0.0, 0.0);
    for s in 0..steps {
        let up: f64 = run.uptake[s * nb..(s + 1) * nb].iter().sum();
        let cons: f64 = run.vo2[s * nc..(s + 1) * nc].iter().sum();
        let d = run.amount[s] - prev;
        assert!(
            (d - dt * (up - cons)).abs() <= 1e-13 * run.amount[s],
            "step {s}: {d} vs {}",
            dt * (up - cons)
        );
        prev = run.amount[s];
        lung += dt * up;
        vo2 += dt * cons;
        // Fick: O2 ejected into the arteries minus O2 returned by the veins
        fick += dt * (run.flux[s * nb] - run.flux[s * nb + 5]);
    }
    assert!((fick - vo2).abs() <= 1e-9 * vo2, "Fick {fick} vs VO2 {vo2}");
    assert!(
        (lung - vo2).abs() <= 1e-9 * vo2,
        "lungs {lung} vs organs {vo2}"
    );
}

#[test]
fn closed_loop_errors_name_the_element() {
    let mut spec = loop_spec(r#"{"kind": "fixed", "rate": 3.7e-5}"#);
    spec.compartments[2].volume = -1.0;
    let e = run_periodic(&spec, &flows(10), 0.1, 1, 1e-12)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("compartment 'brain'") && e.contains("volume"),
        "{e}"
    );
    let spec = loop_spec(r#"{"kind": "fixed", "rate": 1.0}"#);
    let e = run_periodic(&spec, &flows(100), 0.01, 1, 1e-12)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("compartment 'brain'") && e.contains("fixed VO2"),
        "{e}"
    );
}
