//! Serde input types of species transport (the `transport` section of the canonical model):
//! validated against the assembled circuit by `transport::Transport::build`.

use crate::closure::WallSpec;
use crate::hemoglobin::BindingSpec;
use crate::waveform::WaveformSpec;
use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Formulation {
    /// State = amount per cell, upwind fluxes (docs/physics.md §2.5).
    #[default]
    Conservative,
    /// The paper taken literally (docs/physics.md §2.7): J_i = J_{i−1} − W_i along the flow, no storage.
    TlQuasisteady,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeciesSpec {
    pub name: String,
    /// Diffusivity in blood (m²/s): used by the Lévêque and Graetz closures.
    #[serde(default)]
    pub diffusivity: f64,
    /// First-order decay rate λ (1/s).
    #[serde(default)]
    pub decay: f64,
    #[serde(default)]
    pub binding: BindingSpec,
    /// Free concentration (mol/m³) carried in at every inlet boundary condition.
    pub inlet: WaveformSpec,
    /// Per inlet boundary condition overrides of `inlet`.
    #[serde(default)]
    pub inlets: BTreeMap<String, WaveformSpec>,
    /// Free concentration carried in by backflow at the named outlets; others are zero-gradient.
    #[serde(default)]
    pub backflow: BTreeMap<String, WaveformSpec>,
    /// Initial free concentration (default: the inlet value at t = 0).
    #[serde(default)]
    pub initial: Option<f64>,
    #[serde(default)]
    pub wall: WallSpec,
    #[serde(default)]
    pub per_vessel: BTreeMap<String, WallSpec>,
    /// Wall/tissue compartment behind the luminal closure `wall` (docs/physics.md §3.7).
    #[serde(default)]
    pub tissue: Option<TissueSpec>,
    /// Per vessel overrides of `tissue` (null: no tissue wall on that vessel).
    #[serde(default)]
    pub per_vessel_tissue: BTreeMap<String, Option<TissueSpec>>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TransportSpec {
    /// Pressure at which the given radii (and so V0) hold, Pa.
    #[serde(default)]
    pub reference_pressure: f64,
    #[serde(default)]
    pub formulation: Formulation,
    /// |v| below which the transmission-line elements L_i, R_i are reported as NaN (m/s).
    #[serde(default = "default_v_eps")]
    pub velocity_threshold: f64,
    /// Transport cells per flow segment m (integer >= 1; 1 = one cell per volume node). Every
    /// volume-holding node becomes a chain of m sub-cells, which sharpens upwind fronts
    /// (σ_x = sqrt(x dx/m)) without refining the flow circuit (docs/physics.md §5). Given as a number
    /// so that a bad value gets a message naming it.
    #[serde(default = "default_cells")]
    pub cells_per_segment: f64,
    /// Per vessel overrides of `cells_per_segment`.
    #[serde(default)]
    pub cells_per_vessel: BTreeMap<String, f64>,
    pub species: Vec<SpeciesSpec>,
}
fn default_v_eps() -> f64 {
    1e-6
}
fn default_cells() -> f64 {
    1.0
}

/// A radial wall/tissue layer behind the luminal closure (docs/physics.md §3.7). SI; wall
/// concentrations are per wall volume (mol/m³).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TissueSpec {
    /// Wall thickness h (m).
    pub thickness: f64,
    /// Diffusivity in the wall D_t (m²/s).
    pub diffusivity: f64,
    /// φ = u/c in equilibrium: wall concentration per lumen free concentration (for O2 the
    /// ratio of the wall's to the blood's solubility).
    #[serde(default = "one")]
    pub partition: f64,
    pub consumption: ConsumptionSpec,
    #[serde(default)]
    pub outer: OuterSpec,
    /// Finite volumes across the wall (an integer >= 1).
    #[serde(default = "default_radial_cells")]
    pub radial_cells: f64,
    /// Wall concentration (mol/m³ of wall) below which a wall cell counts as hypoxic.
    #[serde(default)]
    pub hypoxic_threshold: f64,
}

/// Consumption per wall volume: Michaelis–Menten vmax u/(km + u) or zero order (mol m⁻³ s⁻¹;
/// km in wall concentration).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ConsumptionSpec {
    MichaelisMenten { vmax: f64, km: f64 },
    ZeroOrder { rate: f64 },
}

/// Outer face of the wall: no flux, or a fixed wall concentration (e.g. vasa vasorum).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Default)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum OuterSpec {
    #[default]
    NoFlux,
    Concentration {
        value: f64,
    },
}

fn one() -> f64 {
    1.0
}
fn default_radial_cells() -> f64 {
    4.0
}
