//! RK4's index reduction of inductors whose flow a flow condition fixes, against the closed
//! form of the circuit: a sine inflow q(t) through two inductive branches joined by a
//! capacitance-free node into a capacitor. Both flows are q(t) (Kirchhoff's current law at the
//! two capacitance-free nodes), so the pressures upstream of the capacitor are
//! P_mid = P_c + R₂ q + L₂ q′ and P_in = P_mid + R₁ q + L₁ q′, with no state of their own.

use oxyline_core::circuit::Circuit;
use oxyline_core::waveform::{Waveform, WaveformSpec};
use oxyline_core::{Regime, rk4::Rk4};
use std::f64::consts::PI;

#[test]
fn an_inflow_fixes_the_flows_and_pressures_of_a_capacitance_free_chain_of_inductors() {
    let (r1, l1, r2, l2, c, r3) = (1.0e6, 3.0e5, 2.0e6, 7.0e5, 1.0e-9, 1.0e8);
    let amplitude = 1.0e-6;
    let mut k = Circuit::default();
    let inlet = k.add_node("in", 0.0, 0.0);
    let mid = k.add_node("mid", 0.0, 0.0);
    let cap = k.add_node("cap", c, 0.0);
    let out = k.add_node("out", 0.0, 0.0);
    let first = k.add_branch("first", inlet, mid, r1, l1, 0.0);
    let second = k.add_branch("second", mid, cap, r2, l2, 0.0);
    k.add_branch("drain", cap, out, r3, 0.0, 0.0);
    let sine = WaveformSpec::Fourier {
        period: 1.0,
        mean: 0.0,
        cos: vec![],
        sin: vec![amplitude],
    };
    k.sources
        .push((inlet, Waveform::from_spec(&sine, "inflow").unwrap()));
    k.fixed_pressures.push((out, Waveform::constant(0.0)));
    let dae = k.assemble().unwrap();
    let (q1, q2) = (dae.n_nodes + first, dae.n_nodes + second);

    let t = 0.1;
    let (q, dq) = (
        amplitude * (2.0 * PI * t).sin(),
        amplitude * 2.0 * PI * (2.0 * PI * t).cos(),
    );
    let p_c = 1.3e4;
    let mut y = vec![0.0; dae.n];
    y[cap] = p_c;
    let mut rk = Rk4::new(&dae, Regime::Transient, 1e-3).unwrap();
    rk.make_consistent(t, &mut y).unwrap();

    // the flows are the inflow, the pressures the closed form's; the one state is P_c
    let p_mid = p_c + r2 * q + l2 * dq;
    let p_in = p_mid + r1 * q + l1 * dq;
    // round-off of the elimination: a few ulps of the largest term
    let close = |a: f64, b: f64, scale: f64| (a - b).abs() <= 1e-12 * scale;
    assert!(close(y[q1], q, amplitude), "first flow {} vs {q}", y[q1]);
    assert!(close(y[q2], q, amplitude), "second flow {} vs {q}", y[q2]);
    assert!(close(y[mid], p_mid, p_c), "P_mid {} vs {p_mid}", y[mid]);
    assert!(close(y[inlet], p_in, p_c), "P_in {} vs {p_in}", y[inlet]);
    assert_eq!(y[cap], p_c, "the capacitor's pressure is a state: kept");
    // the capacitor fills at q − P_c/R₃ (its only differential unknown)
    let rate = rk.derivative(t, &mut y).unwrap();
    let fill = (q - p_c / r3) / c;
    assert!(
        close(rate[cap], fill, fill.abs()),
        "dP_c/dt {} vs {fill}",
        rate[cap]
    );
}
