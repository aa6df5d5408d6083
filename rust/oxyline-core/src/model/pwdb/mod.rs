//! The Pulse Wave DataBase's arterial laws (Charlton et al. 2019, Am J Physiol Heart Circ
//! Physiol 317:H1062; geometry of Mynard & Smolich 2015): the wall law and its wave speed
//! (`wall`), and the vascular beds' Windkessels calibrated on the network's steady circuit
//! (`beds`, with PWDB's bed table), a subject's geometry changes (`geometry`) and its aortic
//! inflow from the Mynard template (`inflow`). The front end reads PWDB's segment table and
//! the template and names the subjects; the formulas are here (docs/populations.md).
//!
//! Units: SI, except the wall-law constants, which PWDB gives in cgs (1 g s⁻² cm⁻¹ = 0.1 Pa,
//! radii in the exponent in cm).

pub mod beds;
pub mod geometry;
pub mod inflow;
pub mod wall;

#[cfg(test)]
mod tests;

/// Pa per mmHg, PWDB's conversion factor.
pub const MMHG: f64 = 133.33;
/// Blood density [kg/m³] (PWDB).
pub const DENSITY: f64 = 1060.0;
/// Blood viscosity [Pa s] (PWDB).
pub const VISCOSITY: f64 = 2.5e-3;
/// Windkessel outflow pressure [Pa] (PWDB, Parazynski 1993).
pub const OUTFLOW_PRESSURE: f64 = 33.2 * MMHG;
/// Poisson ratio that makes the thin-wall c² = E h / (2 ρ r (1 − ν²)) PWDB's (2/3)(E h/r)/ρ.
pub const POISSON_RATIO: f64 = 0.5;

/// One segment of PWDB's network (SI): its end nodes (numbers) and geometry.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment {
    pub inlet: usize,
    pub outlet: usize,
    pub length: f64,
    pub radius_in: f64,
    pub radius_out: f64,
}

impl Segment {
    /// The radius PWDB takes for the whole segment: the mean of its end radii.
    pub fn mean_radius(&self) -> f64 {
        (self.radius_in + self.radius_out) / 2.0
    }

    /// The radius at the middle of the part from the inlet to `fraction` of the length (PWDB
    /// takes the half segment's wave speed at r_in − 0.25 (r_in − r_out)).
    pub fn site_radius(&self, fraction: f64) -> f64 {
        self.radius_in - fraction / 2.0 * (self.radius_in - self.radius_out)
    }
}

/// The element PWDB's errors name.
pub const ELEMENT: &str = "PWDB network";
