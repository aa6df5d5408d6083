//! PWDB's aortic inflow: the systole of the Mynard & Smolich 2015 aortic flow template
//! stretched in time to the subject's ejection time and scaled to its stroke volume, zero
//! flow until the end of the heart period (docs/populations.md).

use super::ELEMENT;
use crate::error::{Error, Result};
use crate::model::structured_tree::fmt_g;
use crate::model::sum;

/// Sampling step of the template [s] (1 kHz).
pub const TEMPLATE_STEP: f64 = 1e-3;

/// Ejection time [s] of the template systole `q` (1 kHz samples from t = 0): from t = 0 to
/// its first zero crossing after the peak, interpolated linearly (the forward ejection; the
/// closing backflow after it is kept and scaled with it).
pub fn template_lvet(q: &[f64]) -> Result<f64> {
    // the first maximum, as numpy's argmax
    let peak = (0..q.len()).fold(0, |k, i| if q[i] > q[k] { i } else { k });
    let j = (peak..q.len())
        .find(|&i| q[i] <= 0.0)
        .filter(|&j| j > 0)
        .ok_or_else(|| {
            Error::model(
                ELEMENT,
                "the aortic flow template never returns to zero after its peak",
            )
        })?;
    let (a, b) = (q[j - 1], q[j]);
    Ok(TEMPLATE_STEP * ((j - 1) as f64 + a / (a - b)))
}

/// Aortic root flow table for heart rate `hr` [1/min], stroke volume `sv` [m³] and ejection
/// time `lvet` [s] from the template systole `q` [m³/s]: the samples stretched in time by
/// lvet / template_lvet, zero flow one stretched step after the last and until the period
/// 60/hr, where the first sample repeats (a periodic linear table), the flow scaled so that
/// its net volume (trapezoid rule) is `sv`. Returns (time [s], flow [m³/s]).
pub fn aortic_inflow(q: &[f64], hr: f64, sv: f64, lvet: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let scale_t = lvet / template_lvet(q)?;
    let mut time: Vec<f64> = (0..q.len())
        .map(|k| k as f64 * TEMPLATE_STEP * scale_t)
        .collect();
    let period = 60.0 / hr;
    let last = time[time.len() - 1];
    let dt = TEMPLATE_STEP * scale_t;
    if last + dt >= period {
        return Err(Error::model(
            ELEMENT,
            format!(
                "heart rate {}/min: period {} s is shorter than the systole ({} s at LVET {} ms)",
                fmt_g(hr),
                fmt_g(period),
                fmt_g(last),
                fmt_g(lvet * 1e3)
            ),
        ));
    }
    time.extend([last + dt, period]);
    let mut flow = q.to_vec();
    flow.extend([0.0, q[0]]);
    let scale = sv / sum::trapezoid(&time, &flow);
    for f in &mut flow {
        *f *= scale;
    }
    Ok((time, flow))
}
