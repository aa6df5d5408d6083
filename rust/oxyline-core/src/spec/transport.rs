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
