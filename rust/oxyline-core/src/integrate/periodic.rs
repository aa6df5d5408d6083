//! The periodic state of a linear circuit at t = 0, from the harmonics of its forcing: the
//! `periodic` start (docs/physics.md §1.9). For E ẏ + F y = f(t) with f of period T, each
//! harmonic k of f gives (i k ω E + F) Y_k = F_k (ω = 2π/T) and y(0) = Y_0 + 2 Re Σ Y_k. The
//! mean Y_0 is the exact steady state (the `steady` start); the harmonics add the pulsatile
//! part, so a run to periodicity starts near its periodic state instead of decaying to it
//! over the Windkessels' time constants. The matrix has the pattern of the time stepping's,
//! so it gets the same elimination (`sparse::SparseLu`), analysed once and refactorised per
//! harmonic, as `impedance::input_impedances` does.

use crate::circuit::{Dae, Regime};
use crate::error::{Error, Result};
use crate::impedance::FrequencySystem;
use crate::sparse::SparseLu;
use faer::c64;
use std::f64::consts::PI;

/// Harmonics of the forcing summed. The slow decay a periodic run waits for is that of the
/// low harmonics' Windkessel charge; the higher ones decay within a cycle in the circuit
/// itself (and carry little of a pulse's energy), so they are left to the run.
pub const PERIODIC_HARMONICS: usize = 32;

/// Samples of the forcing over one period for its discrete Fourier transform: 16 per period
/// of the highest harmonic summed, so aliasing of a waveform table's kinks stays small.
const SAMPLES: usize = 16 * PERIODIC_HARMONICS;

/// Whether `dae` has the linear, time-invariant form the harmonic solve assumes (no
/// stenosis, nonlinear or periodic element, no time-varying resistance). Other circuits keep
/// the steady start.
pub fn applies(dae: &Dae) -> bool {
    dae.is_linear() && dae.is_constant(Regime::Transient) && !dae.has_chambers()
}

/// y(0) of the periodic solution of E ẏ + F y = f(t) (period `period`), given the steady
/// state `steady` of the mean forcing (the harmonic k = 0).
pub fn periodic_state(dae: &Dae, steady: &[f64], period: f64) -> Result<Vec<f64>> {
    let n = dae.n;
    let mut rows: Vec<usize> = dae.forcing.iter().map(|(r, _)| *r).collect();
    rows.sort_unstable();
    rows.dedup();
    // the forcing rows sampled over one period: samples[j * rows + r]
    let mut samples = vec![0.0; SAMPLES * rows.len()];
    let mut f = vec![0.0; n];
    for j in 0..SAMPLES {
        dae.forcing_into(
            period * j as f64 / SAMPLES as f64,
            Regime::Transient,
            &mut f,
        );
        for (r, &row) in rows.iter().enumerate() {
            samples[j * rows.len() + r] = f[row];
        }
    }
    let mut system = FrequencySystem::new(dae);
    let mut lu = SparseLu::<c64>::analyse(n, &system.stamps)?;
    let mut rhs = vec![c64::new(0.0, 0.0); n];
    let mut y = steady.to_vec();
    for k in 1..=PERIODIC_HARMONICS {
        let omega = 2.0 * PI * k as f64 / period;
        system.set_frequency(dae, omega);
        let singular =
            |why: String| Error::solver(0.0, format!("periodic start, harmonic {k}: {why}"));
        lu.factor(&system.vals).map_err(singular)?;
        rhs.iter_mut().for_each(|x| *x = c64::new(0.0, 0.0));
        // F_k = (1/M) Σ_j f(t_j) e^(−i k ω t_j), t_j = j T / M
        for j in 0..SAMPLES {
            let phase = -2.0 * PI * (k * j) as f64 / SAMPLES as f64;
            let w = c64::new(phase.cos(), phase.sin()) / SAMPLES as f64;
            for (r, &row) in rows.iter().enumerate() {
                rhs[row] += w * samples[j * rows.len() + r];
            }
        }
        if !lu.solve_in_place(&mut rhs) {
            return Err(singular("singular matrix".into()));
        }
        for (yi, yk) in y.iter_mut().zip(&rhs) {
            *yi += 2.0 * yk.re;
        }
    }
    Ok(y)
}
