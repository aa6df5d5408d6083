//! The unit systems a model file may use and their conversion to SI, per quantity. Inside the
//! core every value is SI; a `cgs` file (cm, dyn/cm², mL/s, as svZeroDSolver writes them) is
//! converted once, where it is read.

/// mmHg in Pa.
pub const MMHG: f64 = 133.322368;

/// A model file's unit system (`Si`, `Cgs`), or an element's own ([`Units::MmHgMl`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    Si,
    Cgs,
    /// mmHg, mL and s (resistance mmHg s/mL, elastance mmHg/mL, ...), the units of the
    /// lumped heart models' published parameters (svZeroDSolver's closed-loop heart cases);
    /// lengths, density and viscosity as in cgs. An element may give its values in them
    /// (`units: mmHg-mL` in its section).
    MmHgMl,
}

/// mL in m³.
const ML: f64 = 1e-6;

/// A physical quantity a model value carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quantity {
    Length,
    Pressure,
    Flow,
    Resistance,
    Capacitance,
    Inductance,
    Stenosis,
    Density,
    Viscosity,
    Modulus,
    Time,
    /// A pure number.
    Number,
    /// 1/pressure (a valve's steepness).
    PerPressure,
    /// Pressure per volume.
    Elastance,
    /// The flow factor times one second.
    Volume,
    PerVolume,
    PerTime,
}

impl Units {
    /// `SI` or `cgs`, any case.
    pub fn parse(name: &str) -> Option<Units> {
        match name.to_lowercase().as_str() {
            "si" => Some(Units::Si),
            "cgs" => Some(Units::Cgs),
            _ => None,
        }
    }

    /// `SI`, `cgs` (any case) or `mmHg-mL`: the unit systems an element's own `units` key
    /// may name.
    pub fn parse_element(name: &str) -> Option<Units> {
        if name == "mmHg-mL" {
            return Some(Units::MmHgMl);
        }
        Units::parse(name)
    }

    /// The factor that turns a value of `q` in these units into SI.
    pub fn factor(self, q: Quantity) -> f64 {
        use Quantity::*;
        match self {
            Units::Si => return 1.0,
            Units::Cgs => {}
            Units::MmHgMl => {
                return match q {
                    Pressure | Modulus => MMHG,
                    Flow | Volume => ML,
                    Resistance | Inductance | Elastance => MMHG / ML,
                    Capacitance => ML / MMHG,
                    Stenosis => MMHG / (ML * ML),
                    PerPressure => 1.0 / MMHG,
                    PerVolume => 1.0 / ML,
                    _ => Units::Cgs.factor(q),
                };
            }
        }
        match q {
            Length => 1e-2,
            Pressure | Modulus => 0.1,
            Flow | Volume => 1e-6,
            Resistance | Inductance => 1e5,
            Capacitance => 1e-5,
            Stenosis => 1e11,
            Density => 1e3,
            Viscosity => 0.1,
            Time | Number => 1.0,
            PerPressure => 1.0 / 0.1,
            Elastance => 1.0 / 1e-5,
            PerVolume => 1.0 / 1e-6,
            PerTime => 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mmhg_ml_factors_are_the_clinical_units_in_si() {
        // independent truths: 1 mmHg = 133.322368 Pa, 1 mL = 1e-6 m³
        let u = Units::MmHgMl;
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-15 * b.abs();
        assert!(close(u.factor(Quantity::Pressure), 133.322368));
        assert!(close(u.factor(Quantity::Resistance), 1.33322368e8)); // Pa s/m³
        assert!(close(u.factor(Quantity::Elastance), 1.33322368e8)); // Pa/m³
        assert!(close(u.factor(Quantity::Capacitance), 1e-6 / 133.322368));
        assert!(close(u.factor(Quantity::PerVolume), 1e6));
        assert!(close(u.factor(Quantity::Volume), 1e-6));
        assert_eq!(u.factor(Quantity::Time), 1.0);
        assert_eq!(u.factor(Quantity::Length), 1e-2);
        assert_eq!(Units::parse_element("mmHg-mL"), Some(Units::MmHgMl));
        assert_eq!(Units::parse_element("cgs"), Some(Units::Cgs));
        // a whole model is SI or cgs
        assert_eq!(Units::parse("mmHg-mL"), None);
    }
}
