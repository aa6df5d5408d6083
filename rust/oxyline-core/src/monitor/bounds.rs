//! The maximum-principle range of every species, computed once from the model's transport
//! section (docs/physics.md §2.8): [min, max] of its inlet, backflow, initial and wall values.

use crate::closure::WallSpec;
use crate::error::Result;
use crate::model::transport::SpeciesSpec;
use crate::waveform::{Waveform, WaveformSpec};

/// Samples of one period of a Fourier inlet whose extremes stand for the waveform's: the
/// sampled extremes are within ~1e-7 of the true ones, far inside the monitor's tolerance.
pub const FOURIER_SAMPLES: usize = 4097;

/// [min, max] of a waveform over time: a constant's value, a table's extreme values (linear
/// or periodic-spline tables stay inside them at the knots the core evaluates), a Fourier
/// series' extremes over one period sampled by the core's evaluator. NaN for a table holding
/// a NaN (left out of the range, as any value that is not finite).
pub fn waveform_range(spec: &WaveformSpec) -> Result<(f64, f64)> {
    Ok(match spec {
        WaveformSpec::Constant { value } => (*value, *value),
        WaveformSpec::Table { value, .. } => extremes(value.iter().copied()),
        WaveformSpec::Fourier { period, .. } => {
            let w = Waveform::from_spec(spec, "transport inlet")?;
            // the grid of numpy's linspace(0, period, n): i·(period/(n−1)), the end exact
            let step = period / (FOURIER_SAMPLES - 1) as f64;
            let t = |i: usize| {
                if i + 1 == FOURIER_SAMPLES {
                    *period
                } else {
                    i as f64 * step
                }
            };
            extremes((0..FOURIER_SAMPLES).map(|i| w.eval(t(i))))
        }
    })
}

/// (min, max) of `values`, NaN if any is NaN or there are none.
fn extremes(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let mut out: Option<(f64, f64)> = None;
    for v in values {
        if v.is_nan() {
            return (f64::NAN, f64::NAN);
        }
        out = Some(out.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))));
    }
    out.unwrap_or((f64::NAN, f64::NAN))
}

/// [min, max] of a species' boundary, initial and wall values (the maximum-principle range of
/// its free concentration, mol/m³), or None for a species with a prescribed source (a `flux`
/// wall: no maximum principle) or with no finite value. Decay pulls towards zero.
pub fn species_bounds(sp: &SpeciesSpec) -> Result<Option<(f64, f64)>> {
    let mut vals = Vec::new();
    for wall in std::iter::once(&sp.wall).chain(sp.per_vessel.values()) {
        match wall {
            // a prescribed flux is a source: no maximum principle
            WallSpec::Flux { .. } => return Ok(None),
            WallSpec::None => {}
            WallSpec::MassTransfer {
                wall_concentration, ..
            }
            | WallSpec::Leveque {
                wall_concentration, ..
            }
            | WallSpec::Graetz {
                wall_concentration, ..
            } => vals.push(*wall_concentration),
            WallSpec::Permeability {
                tissue_concentration,
                ..
            } => vals.push(*tissue_concentration),
        }
    }
    let waves = std::iter::once(&sp.inlet)
        .chain(sp.inlets.values())
        .chain(sp.backflow.values());
    for w in waves {
        let (lo, hi) = waveform_range(w)?;
        vals.extend([lo, hi]);
    }
    vals.extend(sp.initial);
    if sp.decay > 0.0 {
        vals.push(0.0);
    }
    let finite = vals.into_iter().filter(|v| v.is_finite());
    Ok(finite.fold(None, |acc: Option<(f64, f64)>, v| {
        Some(acc.map_or((v, v), |(lo, hi)| (lo.min(v), hi.max(v))))
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::closure::FluxSpec;

    fn species(json: &str) -> SpeciesSpec {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn the_range_of_a_fourier_inlet_is_its_closed_form_extremes() {
        // 90 + 10 cos(2πt/T) + 5 sin(4πt/T): extremes of the closed form on a fine grid of
        // 1e6 points (within ~1e-9 of the range); the monitor's 4097 samples within ~1e-4
        let sp = species(
            r#"{"name": "x", "inlet": {"kind": "fourier", "period": 0.8, "mean": 90.0,
                "cos": [10.0], "sin": [0.0, 5.0]}}"#,
        );
        let f = |t: f64| {
            let w = 2.0 * std::f64::consts::PI / 0.8;
            90.0 + 10.0 * (w * t).cos() + 5.0 * (2.0 * w * t).sin()
        };
        let n = 1_000_000;
        let (lo, hi) = extremes((0..=n).map(|i| f(0.8 * i as f64 / n as f64)));
        let (blo, bhi) = species_bounds(&sp).unwrap().unwrap();
        assert!(
            (blo - lo).abs() < 1e-4 && (bhi - hi).abs() < 1e-4,
            "{blo} {bhi} vs {lo} {hi}"
        );
        // and the sampled extremes never lie outside the true range
        assert!(blo >= lo - 1e-12 && bhi <= hi + 1e-12);
    }

    #[test]
    fn inlet_and_wall_po2_bound_a_linear_transport_line() {
        // a line of segments between an 85 mmHg inlet and a 48 mmHg wall relaxes
        // exponentially from the inlet towards the wall: c(x) = c_w + (c_in − c_w) e^{−x/λ}
        // lies in [c_w, c_in] for every x, the closed form of the range the monitor takes
        let alpha = 1.39e-3 / 1.0; // mol/m³ per mmHg (a solubility; any positive value)
        let (c_in, c_w) = (85.0 * alpha, 48.0 * alpha);
        let sp = species(&format!(
            r#"{{"name": "oxygen", "inlet": {{"kind": "constant", "value": {c_in}}},
                "wall": {{"model": "graetz", "wall_concentration": {c_w}, "enhancement": 1.0}}}}"#
        ));
        let (lo, hi) = species_bounds(&sp).unwrap().unwrap();
        assert_eq!((lo, hi), (c_w, c_in));
        for i in 0..=100 {
            let c = c_w + (c_in - c_w) * (-(i as f64) / 10.0).exp();
            assert!(lo <= c && c <= hi);
        }
    }

    #[test]
    fn bounds_take_tables_initial_backflow_tissue_and_decay() {
        let sp = species(
            r#"{"name": "x", "inlet": {"kind": "table", "time": [0, 1], "value": [2.0, 3.0]},
                "initial": 1.5, "wall": {"model": "permeability", "permeability": 1e-6,
                "tissue_concentration": 0.5},
                "backflow": {"out": {"kind": "constant", "value": 4.0}}}"#,
        );
        assert_eq!(species_bounds(&sp).unwrap(), Some((0.5, 4.0)));
        let decaying = SpeciesSpec {
            decay: 0.1,
            ..sp.clone()
        };
        assert_eq!(species_bounds(&decaying).unwrap(), Some((0.0, 4.0)));
        let mut source = sp;
        source.per_vessel.insert(
            "a".into(),
            WallSpec::Flux {
                flux: FluxSpec::Constant(1e-6),
            },
        );
        assert_eq!(species_bounds(&source).unwrap(), None);
    }
}
