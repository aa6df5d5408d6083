//! The unit systems a model file may use and their conversion to SI, per quantity. Inside the
//! core every value is SI; a `cgs` file (cm, dyn/cm², mL/s, as svZeroDSolver writes them) is
//! converted once, where it is read.

/// mmHg in Pa.
pub const MMHG: f64 = 133.322368;

/// A model file's unit system.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    Si,
    Cgs,
}

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

    /// The factor that turns a value of `q` in these units into SI.
    pub fn factor(self, q: Quantity) -> f64 {
        if self == Units::Si {
            return 1.0;
        }
        use Quantity::*;
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
