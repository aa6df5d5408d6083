//! The bulk of a large native model, read by serde straight into the spec types: plain
//! geometric vessels and plain resistance/RCR outlets, converted to SI with the same unit
//! factors as the full check (each value multiplied once), with no canonical description in
//! between. Any front end that has a serde `Deserializer` over its values reads them here
//! (the binding's over Python objects). What is not plain (another key, a value of another
//! type, out of range) is `None`: the caller hands that element to the full check
//! ([`super::vessel`], [`super::boundary_condition`]), whose message names it.

use super::super::units::{Quantity, Units};
use super::super::{Arrangement, BoundarySpec, GeometrySpec, VesselSpec};
use crate::waveform::WaveformSpec;
use serde::de::IgnoredAny;
use serde::{Deserialize, Deserializer};

/// A value that must be there when its key is (`null` is not plain).
fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(d: D) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// `output`'s truth value as the full check takes it (`bool(x)`), for a bool or a number.
fn truthy<'de, D: Deserializer<'de>>(d: D) -> Result<Option<bool>, D::Error> {
    struct Truth;
    impl serde::de::Visitor<'_> for Truth {
        type Value = bool;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a bool or a number")
        }
        fn visit_bool<E>(self, b: bool) -> Result<bool, E> {
            Ok(b)
        }
        fn visit_i64<E>(self, x: i64) -> Result<bool, E> {
            Ok(x != 0)
        }
        fn visit_u64<E>(self, x: u64) -> Result<bool, E> {
            Ok(x != 0)
        }
        fn visit_f64<E>(self, x: f64) -> Result<bool, E> {
            Ok(x != 0.0)
        }
    }
    d.deserialize_any(Truth).map(Some)
}

/// A native vessel of geometry alone: `radius`, or `radius_in` and `radius_out`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlainVessel {
    name: String,
    from: String,
    to: String,
    length: f64,
    #[serde(default, deserialize_with = "present")]
    radius: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    radius_in: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    radius_out: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    wall_thickness: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    youngs_modulus: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    poisson_ratio: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    segments: Option<u64>,
    #[serde(default, deserialize_with = "present")]
    arrangement: Option<Arrangement>,
    #[serde(default, deserialize_with = "truthy")]
    output: Option<bool>,
    /// Free text for the reader of the file: any value, not kept.
    #[serde(default, rename = "description", deserialize_with = "present")]
    _description: Option<IgnoredAny>,
}

/// 0 < x < ∞ (false for NaN).
fn positive(x: f64) -> Option<f64> {
    (x > 0.0 && x < f64::INFINITY).then_some(x)
}

fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl PlainVessel {
    /// The vessel in SI (`units`: the model's), or None when a value is out of range.
    pub fn spec(self, units: Units) -> Option<VesselSpec> {
        let length = units.factor(Quantity::Length);
        let modulus = units.factor(Quantity::Modulus);
        let (radius_in, radius_out) = match (self.radius, self.radius_in, self.radius_out) {
            (Some(r), None, None) => (positive(r)?, positive(r)?),
            (None, Some(a), Some(b)) => (positive(a)?, positive(b)?),
            _ => return None,
        };
        let geometry = GeometrySpec {
            length: length * positive(self.length)?,
            radius_in: length * radius_in,
            radius_out: length * radius_out,
            wall_thickness: match self.wall_thickness {
                Some(h) => Some(length * positive(h)?),
                None => None,
            },
            youngs_modulus: match self.youngs_modulus {
                Some(e) => Some(modulus * positive(e)?),
                None => None,
            },
            poisson_ratio: match self.poisson_ratio {
                Some(nu) => finite(nu)?,
                None => 0.5,
            },
            wall_viscosity: 0.0,
        };
        let segments = match self.segments {
            Some(n) if n >= 1 => Some(usize::try_from(n).ok()?),
            Some(_) => return None,
            None => None,
        };
        Some(VesselSpec {
            name: self.name,
            from: self.from,
            to: self.to,
            segments,
            geometry: Some(geometry),
            arrangement: self.arrangement,
            output: self.output.unwrap_or(true),
            ..VesselSpec::blank()
        })
    }
}

/// A native `resistance` or `rcr` outlet with a constant (or no) distal pressure.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlainOutlet {
    #[serde(rename = "type")]
    kind: String,
    #[serde(default, deserialize_with = "present")]
    resistance: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    proximal_resistance: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    capacitance: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    distal_resistance: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    pressure: Option<f64>,
}

impl PlainOutlet {
    /// The condition in SI (`units`: the model's), or None when it is not plain.
    pub fn spec(self, units: Units) -> Option<BoundarySpec> {
        let r = units.factor(Quantity::Resistance);
        let c = units.factor(Quantity::Capacitance);
        let p = units.factor(Quantity::Pressure);
        let pressure = Some(WaveformSpec::Constant {
            value: p * finite(self.pressure.unwrap_or(0.0))?,
        });
        let rcr = (
            self.proximal_resistance,
            self.capacitance,
            self.distal_resistance,
        );
        match (self.kind.as_str(), self.resistance, rcr) {
            ("resistance", Some(x), (None, None, None)) => Some(BoundarySpec::Resistance {
                resistance: r * finite(x)?,
                pressure,
            }),
            ("rcr", None, (Some(rp), Some(cap), Some(rd))) => Some(BoundarySpec::Rcr {
                proximal_resistance: r * finite(rp)?,
                capacitance: c * finite(cap)?,
                distal_resistance: r * finite(rd)?,
                pressure,
            }),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::native::{boundary_condition, vessel};
    use crate::model::node::Fields;
    use serde_json::{Value, json};

    /// The full check's reading (canonical description, then the spec), the reference.
    fn full_vessel(v: &Value, units: Units) -> VesselSpec {
        let canonical = vessel(&Fields::new(v.clone()), 0, units).unwrap();
        serde_json::from_value(canonical).unwrap()
    }

    fn plain_vessel(v: &Value, units: Units) -> Option<VesselSpec> {
        PlainVessel::deserialize(v).ok()?.spec(units)
    }

    /// The same numbers by either route: each value times the same unit factor once.
    #[test]
    fn plain_elements_read_as_the_full_check_reads_them() {
        let vessels = [
            json!({"name": "a", "from": "in", "to": "j", "length": 5, "radius": 0.3}),
            json!({"name": "b", "from": "j", "to": "o", "length": 1.5, "radius_in": 0.3,
                   "radius_out": 0.2, "wall_thickness": 0.03, "youngs_modulus": 4e6,
                   "poisson_ratio": 0.49, "segments": 3, "arrangement": "pi", "output": 0,
                   "description": {"any": ["value"]}}),
        ];
        for units in [Units::Si, Units::Cgs] {
            for v in &vessels {
                let plain = plain_vessel(v, units).expect("plain");
                assert_eq!(format!("{plain:?}"), format!("{:?}", full_vessel(v, units)));
            }
            for bc in [
                json!({"type": "rcr", "proximal_resistance": 1e3, "capacitance": 1e-5,
                       "distal_resistance": 9e3, "pressure": 10}),
                json!({"type": "resistance", "resistance": 3}),
            ] {
                let plain = PlainOutlet::deserialize(&bc).unwrap().spec(units).unwrap();
                let full = boundary_condition(&Fields::new(bc), units, "x").unwrap();
                let full: BoundarySpec = serde_json::from_value(full).unwrap();
                assert_eq!(format!("{plain:?}"), format!("{full:?}"));
            }
        }
    }

    /// Anything not plain is left to the full check (which names the problem).
    #[test]
    fn anything_doubtful_is_not_plain() {
        let base = json!({"name": "a", "from": "in", "to": "j", "length": 5, "radius": 0.3});
        for (k, x) in [
            ("radius", json!(-1.0)),
            ("length", json!("1")),
            ("segments", json!(0)),
            ("segments", json!(2.5)),
            ("radius_in", json!(0.1)),
            ("wall_thickness", Value::Null),
            ("lumped", json!({"resistance": 1.0})),
            ("output", json!("yes")),
        ] {
            let mut v = base.clone();
            v[k] = x;
            assert!(plain_vessel(&v, Units::Si).is_none(), "{k}");
        }
        let rcr = json!({"type": "rcr", "proximal_resistance": 1.0, "capacitance": 1.0,
                         "distal_resistance": 1.0});
        for (k, x) in [
            ("type", json!("RCR")),
            ("resistance", json!(1.0)),
            ("pressure", json!({"kind": "constant", "value": 0.0})),
        ] {
            let mut bc = rcr.clone();
            bc[k] = x;
            let read = PlainOutlet::deserialize(&bc)
                .ok()
                .and_then(|p| p.spec(Units::Si));
            assert!(read.is_none(), "{k}");
        }
    }
}
