//! Plausibility of a model's inputs: every quantity of the canonical SI model compared with
//! the range it takes in the human circulation (radius, length, wall, stiffness, blood,
//! boundary flows, pressures, resistances, compliances, inductances, periods). A value outside
//! its range is not an error (an animal model or a numerical experiment may want it) but a
//! warning, and the usual cause is a unit mix-up: a radius in cm in an SI file is 100 times too
//! large, a flow in mL/s a million times, a stiffness in MPa a million times too small, a cgs
//! value in an SI file off by the cgs factor. For each value out of range the warning names the
//! element, the key, the value and unit, the range and the mix-up whose factor brings the value
//! back into it (if one does). The ranges are wide on purpose: no built-in model, no
//! svZeroDSolver or openBF reference case and no network shipped with the tests warns.

use super::node::py_g;
use super::{BoundarySpec, LumpedSpec, NetworkSpec, VesselSpec};
use crate::waveform::WaveformSpec;
use std::collections::BTreeMap;

/// A unit mix-up: a value written in the wrong unit reaches the core multiplied by `factor`
/// (as written / as meant), for the reason `cause`.
type MixUp = (f64, &'static str);

/// The plausible range of one kind of input quantity, SI.
struct Range {
    unit: &'static str,
    low: f64,
    high: f64,
    /// A typical value: of several mix-ups that explain a value, the one that brings it
    /// closest to this (on a log scale) is named.
    typical: f64,
    mix_ups: &'static [MixUp],
}

const LENGTH_MIX_UPS: &[MixUp] = &[
    (100.0, "a value in cm in an SI file (SI expects m)"),
    (1000.0, "a value in mm in an SI file (SI expects m)"),
    (10.0, "a value in mm in a cgs file (cgs expects cm)"),
    (1e6, "a value in µm in an SI file (SI expects m)"),
    (0.01, "a value in m in a cgs file (cgs expects cm)"),
];
const RADIUS: Range = Range {
    unit: "m",
    low: 2e-6,
    high: 0.05,
    typical: 2e-3,
    mix_ups: LENGTH_MIX_UPS,
};
const LENGTH: Range = Range {
    unit: "m",
    low: 1e-5,
    high: 2.0,
    typical: 0.03,
    mix_ups: LENGTH_MIX_UPS,
};
const WALL_THICKNESS: Range = Range {
    unit: "m",
    low: 5e-7,
    high: 0.01,
    typical: 5e-4,
    mix_ups: LENGTH_MIX_UPS,
};
const MODULUS: Range = Range {
    unit: "Pa",
    low: 1e4,
    high: 1e8,
    typical: 5e5,
    mix_ups: &[
        (1e-6, "a value in MPa in an SI file (SI expects Pa)"),
        (1e-3, "a value in kPa in an SI file (SI expects Pa)"),
        (10.0, "a value in dyn/cm² in an SI file (SI expects Pa)"),
        (0.1, "a value in Pa in a cgs file (cgs expects dyn/cm²)"),
        (1e-7, "a value in MPa in a cgs file (cgs expects dyn/cm²)"),
    ],
};
const DENSITY: Range = Range {
    unit: "kg/m³",
    low: 900.0,
    high: 1200.0,
    typical: 1050.0,
    mix_ups: &[
        (1e-3, "a value in g/cm³ in an SI file (SI expects kg/m³)"),
        (1e3, "a value in kg/m³ in a cgs file (cgs expects g/cm³)"),
    ],
};
const VISCOSITY: Range = Range {
    unit: "Pa·s",
    low: 5e-4,
    high: 2e-2,
    typical: 3.5e-3,
    mix_ups: &[
        (10.0, "a value in poise in an SI file (SI expects Pa·s)"),
        (
            1000.0,
            "a value in cP (mPa·s) in an SI file (SI expects Pa·s)",
        ),
        (100.0, "a value in cP in a cgs file (cgs expects poise)"),
        (0.1, "a value in Pa·s in a cgs file (cgs expects poise)"),
    ],
};
const FLOW_MIX_UPS: &[MixUp] = &[
    (1e6, "a value in mL/s in an SI file (SI expects m³/s)"),
    (6e4, "a value in L/min in an SI file (SI expects m³/s)"),
    (6e7, "a value in mL/min in an SI file (SI expects m³/s)"),
    (1e-6, "a value in m³/s in a cgs file (cgs expects mL/s)"),
    (1e-3, "a value in L/s in a cgs file (cgs expects mL/s)"),
];
/// The peak of an inflow waveform: the flow into a modelled arterial network.
const INFLOW: Range = Range {
    unit: "m³/s",
    low: 1e-9,
    high: 2e-3,
    typical: 3e-5,
    mix_ups: FLOW_MIX_UPS,
};
const PRESSURE_MIX_UPS: &[MixUp] = &[
    (10.0, "a value in dyn/cm² in an SI file (SI expects Pa)"),
    (
        1.0 / 133.322,
        "a value in mmHg in an SI file (SI expects Pa)",
    ),
    (
        1.0 / 1333.22,
        "a value in mmHg in a cgs file (cgs expects dyn/cm²)",
    ),
    (1e-3, "a value in kPa in an SI file (SI expects Pa)"),
    (0.1, "a value in Pa in a cgs file (cgs expects dyn/cm²)"),
];
/// A pressure (of any boundary condition): only an upper bound, as zero and small venous
/// or reference pressures are usual (svZeroDSolver's test cases drive with fractions of a Pa).
const PRESSURE: Range = Range {
    unit: "Pa",
    low: 0.0,
    high: 5e4,
    typical: 1.3e4,
    mix_ups: PRESSURE_MIX_UPS,
};
/// The peak of a pressure prescribed at an inlet (a node vessels leave and none enters) of a
/// model without heart chambers: an artery driven by the heart sees more than 1 kPa (7.5 mmHg). Peaks under 1 Pa are left
/// alone: normalised test drives (svZeroDSolver's cases use fractions of a Pa).
const INLET_PRESSURE: Range = Range {
    unit: "Pa",
    low: 1e3,
    high: 5e4,
    typical: 1.3e4,
    mix_ups: PRESSURE_MIX_UPS,
};
const RESISTANCE_MIX_UPS: &[MixUp] = &[
    (
        1e-5,
        "a value in dyn·s/cm⁵ in an SI file (SI expects Pa·s/m³)",
    ),
    (
        1e5,
        "a value in Pa·s/m³ in a cgs file (cgs expects dyn·s/cm⁵)",
    ),
    (
        1.0 / 1.333_22e8,
        "a value in mmHg·s/mL in an SI file (SI expects Pa·s/m³)",
    ),
    (
        1.0 / 1333.22,
        "a value in mmHg·s/mL in a cgs file (cgs expects dyn·s/cm⁵)",
    ),
];
/// An outlet's (peripheral) resistance: from the whole body's to one small branch's.
const OUTLET_RESISTANCE: Range = Range {
    unit: "Pa·s/m³",
    low: 1e6,
    high: 1e15,
    typical: 1e9,
    mix_ups: RESISTANCE_MIX_UPS,
};
/// A vessel's or element's own resistance (a short segment of a large artery is small).
const RESISTANCE: Range = Range {
    unit: "Pa·s/m³",
    low: 1.0,
    high: 1e16,
    typical: 1e8,
    mix_ups: RESISTANCE_MIX_UPS,
};
const CAPACITANCE_MIX_UPS: &[MixUp] = &[
    (1e5, "a value in cm⁵/dyn in an SI file (SI expects m³/Pa)"),
    (1e-5, "a value in m³/Pa in a cgs file (cgs expects cm⁵/dyn)"),
    (
        1.333_22e8,
        "a value in mL/mmHg in an SI file (SI expects m³/Pa)",
    ),
    (
        1333.22,
        "a value in mL/mmHg in a cgs file (cgs expects cm⁵/dyn)",
    ),
];
/// An outlet's compliance: at most 100 times the whole arterial tree's (~1e-8 m³/Pa).
const OUTLET_CAPACITANCE: Range = Range {
    unit: "m³/Pa",
    low: 1e-18,
    high: 1e-6,
    typical: 1e-10,
    mix_ups: CAPACITANCE_MIX_UPS,
};
/// A lumped element's compliance: up to a closed loop's venous compartment (~1e-6 m³/Pa),
/// with room for svZeroDSolver's test values.
const CAPACITANCE: Range = Range {
    unit: "m³/Pa",
    low: 1e-18,
    high: 1e-4,
    typical: 1e-9,
    mix_ups: CAPACITANCE_MIX_UPS,
};
const INDUCTANCE: Range = Range {
    unit: "Pa·s²/m³",
    low: 1.0,
    high: 1e12,
    typical: 1e6,
    mix_ups: &[
        (
            1e-5,
            "a value in dyn·s²/cm⁵ in an SI file (SI expects Pa·s²/m³)",
        ),
        (
            1e5,
            "a value in Pa·s²/m³ in a cgs file (cgs expects dyn·s²/cm⁵)",
        ),
    ],
};
/// The cardiac period of a waveform or heart element (from a mouse's heart to 10 s: the
/// test cases of svZeroDSolver use 2π s).
const PERIOD: Range = Range {
    unit: "s",
    low: 0.05,
    high: 10.0,
    typical: 0.9,
    mix_ups: &[(1000.0, "a time in ms (the model expects s)")],
};

/// One input value outside its plausible range.
#[derive(Debug, Clone, PartialEq)]
pub struct Warning {
    /// The element, as errors name it (`vessel 'aorta'`, `boundary condition 'out1'`, `blood`).
    pub element: String,
    /// The key, as the model file writes it.
    pub key: String,
    /// The value (SI) and its unit.
    pub value: f64,
    pub unit: &'static str,
    /// The plausible range (SI; `low` 0: no lower bound).
    pub low: f64,
    pub high: f64,
    /// The unit mix-up that explains the value, if one does.
    pub likely_cause: Option<String>,
    /// How many more elements have the same key out of range (their warnings left out).
    pub more: usize,
}

impl Warning {
    /// One line: the element, the key, the value, the range and the likely mix-up.
    pub fn message(&self) -> String {
        let range = if self.low > 0.0 {
            format!("{} to {} {}", py_g(self.low), py_g(self.high), self.unit)
        } else {
            format!("at most {} {}", py_g(self.high), self.unit)
        };
        let mut m = format!(
            "{}: {} = {} {} is outside the physiological range ({range})",
            self.element,
            self.key,
            py_g(self.value),
            self.unit
        );
        let large = self.value.abs() > self.high;
        let (much, way) = if large {
            (self.value.abs() / self.high, "large")
        } else {
            (self.low / self.value.abs(), "small")
        };
        match &self.likely_cause {
            Some(cause) => m.push_str(&format!("; too {way}: likely {cause}")),
            None => m.push_str(&format!(
                "; {} times too {way}, more than a unit mix-up explains",
                py_g(much)
            )),
        }
        if self.more > 0 {
            m.push_str(&format!(
                " (and {} more element(s) with '{}' out of range)",
                self.more, self.key
            ));
        }
        m
    }
}

/// At most this many warnings per key (a whole tree written in the wrong unit gives one
/// warning per vessel otherwise); the first of them counts the rest.
const PER_KEY: usize = 3;

/// Collects the values out of range, `PER_KEY` per key.
#[derive(Default)]
struct Findings {
    out: Vec<Warning>,
    /// key -> (warnings kept, index of the first)
    count: BTreeMap<String, (usize, usize)>,
}

impl Findings {
    fn check(&mut self, element: &dyn Fn() -> String, key: &str, value: f64, r: &Range) {
        let v = value.abs();
        if !v.is_finite() || v == 0.0 || (v >= r.low && v <= r.high) {
            return;
        }
        let entry = self
            .count
            .entry(key.to_owned())
            .or_insert((0, self.out.len()));
        if entry.0 >= PER_KEY {
            self.out[entry.1].more += 1;
            return;
        }
        entry.0 += 1;
        self.out.push(Warning {
            element: element(),
            key: key.to_owned(),
            value,
            unit: r.unit,
            low: r.low,
            high: r.high,
            likely_cause: likely_cause(v, r),
            more: 0,
        });
    }
}

/// The mix-ups whose factor brings `v` into the range, nearest the typical value first, at
/// most two (a radius of 1.2 m may be 1.2 cm or 1.2 mm), joined by "or".
fn likely_cause(v: f64, r: &Range) -> Option<String> {
    let mut fits: Vec<&MixUp> = r
        .mix_ups
        .iter()
        .filter(|(f, _)| {
            let meant = v / f;
            meant >= r.low && meant <= r.high
        })
        .collect();
    let d = |f: f64| (v / f / r.typical).ln().abs();
    fits.sort_by(|a, b| d(a.0).total_cmp(&d(b.0)));
    let causes: Vec<&str> = fits.iter().take(2).map(|(_, cause)| *cause).collect();
    (!causes.is_empty()).then(|| causes.join(" or "))
}

/// The warnings of a canonical model, vessels first, then boundary conditions.
pub fn check(spec: &NetworkSpec) -> Vec<Warning> {
    let mut f = Findings::default();
    f.check(&|| "blood".into(), "density", spec.blood.density, &DENSITY);
    f.check(
        &|| "blood".into(),
        "viscosity",
        spec.blood.viscosity,
        &VISCOSITY,
    );
    for v in &spec.vessels {
        vessel(&mut f, v);
    }
    let entered: rustc_hash::FxHashSet<&str> = spec.vessels.iter().map(|v| v.to.as_str()).collect();
    // a model with a heart chamber fills it from its inlet at venous pressure (1-2 mmHg)
    let arterial_inlets = !spec
        .vessels
        .iter()
        .any(|v| v.chamber.is_some() || v.chamber_sphere.is_some() || v.heart_pulmonary.is_some());
    for (node, bc) in &spec.boundary_conditions {
        match bc {
            BoundarySpec::Pressure { pressure }
                if arterial_inlets && !entered.contains(node.as_str()) && peak(pressure) >= 1.0 =>
            {
                let el = || format!("boundary condition '{node}'");
                waveform(&mut f, &el, "pressure", pressure, &INLET_PRESSURE)
            }
            _ => condition(&mut f, node, bc),
        }
    }
    f.out
}

fn vessel(f: &mut Findings, v: &VesselSpec) {
    let el = || format!("vessel '{}'", v.name);
    if let Some(g) = &v.geometry {
        f.check(&el, "length", g.length, &LENGTH);
        if g.radius_in == g.radius_out {
            f.check(&el, "radius", g.radius_in, &RADIUS);
        } else {
            f.check(&el, "radius_in", g.radius_in, &RADIUS);
            f.check(&el, "radius_out", g.radius_out, &RADIUS);
        }
        if let Some(h) = g.wall_thickness {
            f.check(&el, "wall_thickness", h, &WALL_THICKNESS);
        }
        if let Some(e) = g.youngs_modulus {
            f.check(&el, "youngs_modulus", e, &MODULUS);
        }
    }
    if let Some(LumpedSpec {
        resistance,
        inductance,
        capacitance,
        ..
    }) = &v.lumped
    {
        f.check(&el, "resistance", *resistance, &RESISTANCE);
        f.check(&el, "inductance", *inductance, &INDUCTANCE);
        f.check(&el, "capacitance", *capacitance, &CAPACITANCE);
    }
    if let Some(rc) = &v.through_rc {
        f.check(&el, "resistance", rc.resistance, &RESISTANCE);
        f.check(&el, "capacitance", rc.capacitance, &CAPACITANCE);
    }
    if let Some(c) = &v.chamber {
        f.check(&el, "period", c.period, &PERIOD);
    }
    if let Some(h) = &v.heart_pulmonary {
        f.check(&el, "period", h.period, &PERIOD);
    }
    if let Some(s) = &v.chamber_sphere {
        f.check(&el, "period", s.period, &PERIOD);
    }
}

fn condition(f: &mut Findings, node: &str, bc: &BoundarySpec) {
    let el = || format!("boundary condition '{node}'");
    match bc {
        BoundarySpec::Flow { flow } => waveform(f, &el, "flow", flow, &INFLOW),
        BoundarySpec::Pressure { pressure } => waveform(f, &el, "pressure", pressure, &PRESSURE),
        BoundarySpec::Resistance {
            resistance,
            pressure,
        } => {
            f.check(&el, "resistance", *resistance, &OUTLET_RESISTANCE);
            outlet_pressure(f, &el, pressure.as_ref());
        }
        BoundarySpec::Rcr {
            proximal_resistance,
            capacitance,
            distal_resistance,
            pressure,
        } => {
            // the proximal resistance is often small or 0 (a two-element Windkessel)
            f.check(
                &el,
                "proximal_resistance",
                *proximal_resistance,
                &RESISTANCE,
            );
            f.check(
                &el,
                "distal_resistance",
                *distal_resistance,
                &OUTLET_RESISTANCE,
            );
            f.check(&el, "capacitance", *capacitance, &OUTLET_CAPACITANCE);
            outlet_pressure(f, &el, pressure.as_ref());
        }
        BoundarySpec::Coronary(c) => {
            f.check(
                &el,
                "arterial_resistance",
                c.arterial_resistance,
                &RESISTANCE,
            );
            f.check(
                &el,
                "microvascular_resistance",
                c.microvascular_resistance,
                &OUTLET_RESISTANCE,
            );
            f.check(&el, "venous_resistance", c.venous_resistance, &RESISTANCE);
            f.check(
                &el,
                "arterial_capacitance",
                c.arterial_capacitance,
                &OUTLET_CAPACITANCE,
            );
            f.check(
                &el,
                "intramyocardial_capacitance",
                c.intramyocardial_capacitance,
                &OUTLET_CAPACITANCE,
            );
            outlet_pressure(f, &el, c.pressure.as_ref());
        }
        BoundarySpec::SvzerodInlet(s) => {
            for (key, r) in [
                ("resistance", s.resistance),
                ("proximal_resistance", s.proximal_resistance),
                ("distal_resistance", s.distal_resistance),
            ] {
                if let Some(r) = r {
                    f.check(&el, key, r, &RESISTANCE);
                }
            }
            if let Some(c) = s.capacitance {
                f.check(&el, "capacitance", c, &CAPACITANCE);
            }
            outlet_pressure(f, &el, s.pressure.as_ref());
        }
    }
}

fn outlet_pressure(f: &mut Findings, el: &dyn Fn() -> String, p: Option<&WaveformSpec>) {
    if let Some(p) = p {
        waveform(f, el, "pressure", p, &PRESSURE);
    }
}

/// A waveform's peak magnitude against `range`, and its period (a table's time span).
/// The largest magnitude a waveform reaches (a bound for a Fourier series).
fn peak(w: &WaveformSpec) -> f64 {
    match w {
        WaveformSpec::Constant { value } => value.abs(),
        WaveformSpec::Table { value, .. } => value.iter().fold(0.0, |m: f64, x| m.max(x.abs())),
        WaveformSpec::Fourier { mean, cos, sin, .. } => {
            mean.abs() + cos.iter().chain(sin).map(|c| c.abs()).sum::<f64>()
        }
    }
}

fn waveform(f: &mut Findings, el: &dyn Fn() -> String, key: &str, w: &WaveformSpec, r: &Range) {
    f.check(el, key, peak(w), r);
    let period = match w {
        WaveformSpec::Table { time, .. } if time.len() > 1 => time[time.len() - 1] - time[0],
        WaveformSpec::Fourier { period, .. } => *period,
        _ => return,
    };
    f.check(el, &format!("{key} period"), period, &PERIOD);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_radius_in_cm_is_named_as_such() {
        let w = likely_cause(0.3, &RADIUS).unwrap();
        assert!(w.starts_with("a value in cm in an SI file (SI expects m)"));
        // 1.2 m: an aorta's 1.2 cm or an artery's 1.2 mm, both named
        let w = likely_cause(1.2, &RADIUS).unwrap();
        assert!(w.contains("in cm in an SI") && w.contains("in mm in an SI"));
    }

    #[test]
    fn a_stiffness_in_mpa_is_named_as_such() {
        let mpa = likely_cause(0.4, &MODULUS).unwrap();
        assert!(mpa.starts_with("a value in MPa in an SI file (SI expects Pa)"));
        let kpa = likely_cause(400.0, &MODULUS).unwrap();
        assert!(kpa.starts_with("a value in kPa in an SI file (SI expects Pa)"));
    }

    #[test]
    fn an_inlet_pressure_in_mmhg_is_named_as_such() {
        let w = likely_cause(120.0, &INLET_PRESSURE).unwrap();
        assert!(w.contains("in mmHg in an SI file"), "{w}");
    }

    #[test]
    fn a_value_no_mix_up_explains_says_so() {
        assert_eq!(likely_cause(1e30, &RADIUS), None);
    }

    #[test]
    fn warnings_per_key_are_capped_and_counted() {
        let mut f = Findings::default();
        for i in 0..10 {
            f.check(&|| format!("vessel 'v{i}'"), "radius", 1.0, &RADIUS);
        }
        assert_eq!(f.out.len(), PER_KEY);
        assert_eq!(f.out[0].more, 10 - PER_KEY);
        assert!(f.out[0].message().contains("7 more"));
    }
}
