//! circulatory_autogen's arithmetic as its importer and the built-in `whole-body-140` use it:
//! the aortic flow table scaled so that its cycle mean is the cardiac output (given, or the
//! sum of the observed mean terminal flows), and the Young's modulus of a wall branch's
//! capacitor. The importer reads the files; the arithmetic is here, in numpy's order
//! (`model::sum`) and the C library's `pow`, so the models it writes keep their bits.

use crate::model::sum;
use std::f64::consts::PI;

/// `flow` × (`cardiac_output` / its cycle mean over `time`), each sample scaled by the one
/// factor (as numpy's `q * (co / mean)`).
pub fn inflow_at_cardiac_output(time: &[f64], flow: &[f64], cardiac_output: f64) -> Vec<f64> {
    let factor = cardiac_output / sum::cycle_mean(time, flow);
    flow.iter().map(|q| q * factor).collect()
}

/// The Young's modulus [Pa] that gives a vessel of `radius` and `length` [m] and wall
/// `thickness` [m] the capacitance `capacitance` [m³/Pa] of circulatory_autogen's wall law
/// C = 2π r³ l/(E h) (Poisson ratio 0): E = 2π r³ l/(C h).
pub fn youngs_modulus_of_capacitance(
    radius: f64,
    length: f64,
    capacitance: f64,
    thickness: f64,
) -> f64 {
    2.0 * PI * radius.powf(3.0) * length / (capacitance * thickness)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scaled_triangle_has_the_cardiac_output_as_its_mean() {
        // a triangle of height 2 over [0, 1] on a 2 s cycle: mean 0.5; scaled to 7e-5 m³/s
        // every sample is multiplied by 1.4e-4 and the new mean is the target
        let time = [0.0, 0.5, 1.0, 2.0];
        let flow = [0.0, 2.0, 0.0, 0.0];
        let q = inflow_at_cardiac_output(&time, &flow, 7e-5);
        assert!((q[1] - 2.0 * 1.4e-4).abs() < 1e-18);
        assert!((sum::cycle_mean(&time, &q) - 7e-5).abs() < 1e-18);
    }

    #[test]
    fn the_modulus_gives_back_the_thin_wall_compliance() {
        // C = 2π r³ l (1 − ν²)/(E h) with ν = 0 (the core's segment law) from the E found
        let (r, l, h, c) = (3e-3, 0.05, 4e-4, 2.5e-10);
        let e = youngs_modulus_of_capacitance(r, l, c, h);
        let back = crate::segment::thin_wall_compliance(r, l, e, h, 0.0);
        assert!((back / c - 1.0).abs() < 1e-14, "{back}");
    }
}
