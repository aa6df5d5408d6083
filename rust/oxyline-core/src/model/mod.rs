//! The one schema of a network model. `native` reads the model as a user writes it (the
//! README's YAML/dict form, any unit system: `units`) from the front end's values (`node`),
//! checks every key and value and writes the canonical SI description; the serde types here
//! are that canonical description (vessels joined at named nodes, boundary conditions at free
//! ends, blood, segmentation, and the species transport section: `transport`). Nothing here
//! builds a circuit: see `crate::assemble`. Structured-tree growth (`structured_tree`) and the
//! haemoglobin facilitation factor (`facilitation`) are computed here when a model is read.

use crate::segment::{InertanceProfile, WallFriction, WallModel};
use crate::waveform::WaveformSpec;
use serde::Deserialize;
use std::collections::BTreeMap;

use crate::error::{Error, Result};

pub mod circulatory_autogen;
pub mod facilitation;
pub mod native;
pub mod node;
pub mod openbf;
pub mod parameters;
pub mod patch;
pub mod path;
pub mod plausibility;
pub mod pwdb;
pub mod settings;
pub mod species;
pub mod structured_tree;
pub mod sum;
pub mod transport;
pub mod units;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
pub enum Arrangement {
    /// Capacitor at the proximal node, then R–L to the next node (default; flow-in/pressure-out).
    #[default]
    #[serde(rename = "inverted-L")]
    InvertedL,
    /// R–L, then the capacitor at the distal node.
    #[serde(rename = "L")]
    L,
    /// Half the capacitance at each end of the R–L branch.
    #[serde(rename = "pi")]
    Pi,
    /// svZeroDSolver's BloodVessel: R (and stenosis), then the capacitor, then L.
    #[serde(rename = "RCL")]
    Rcl,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BloodSpec {
    #[serde(default = "default_density")]
    pub density: f64,
    #[serde(default = "default_viscosity")]
    pub viscosity: f64,
}
fn default_density() -> f64 {
    1050.0
}
fn default_viscosity() -> f64 {
    3.5e-3
}
impl Default for BloodSpec {
    fn default() -> Self {
        BloodSpec {
            density: default_density(),
            viscosity: default_viscosity(),
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeometrySpec {
    pub length: f64,
    pub radius_in: f64,
    pub radius_out: f64,
    #[serde(default)]
    pub wall_thickness: Option<f64>,
    #[serde(default)]
    pub youngs_modulus: Option<f64>,
    #[serde(default = "default_poisson")]
    pub poisson_ratio: f64,
    /// Kelvin–Voigt wall viscosity η (Pa·s; 0: elastic wall), docs/physics.md §1.13.
    #[serde(default)]
    pub wall_viscosity: f64,
}
fn default_poisson() -> f64 {
    0.5
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LumpedSpec {
    pub resistance: f64,
    #[serde(default)]
    pub inductance: f64,
    #[serde(default)]
    pub capacitance: f64,
    #[serde(default)]
    pub stenosis_coefficient: f64,
    /// How generalized-α discretises the stenosis of an RCL vessel with a capacitor.
    #[serde(default)]
    pub stenosis_form: StenosisForm,
}

/// Where the stenosis term of an RCL vessel (R + S|Q|, then C, then L) enters its equations
/// under generalized-α (docs/svzerod.md, "C + stenosis"). Both forms are the same DAE; they
/// differ in the discrete derivative of the capacitor pressure, and so in RK4 not at all.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
pub enum StenosisForm {
    /// The stenosis sits in the algebraic R branch, P_in − P_c = (R + S|Q|)Q, and the
    /// capacitor row is C dP_c/dt = Q − Q_out: second order (default).
    #[default]
    #[serde(rename = "branch")]
    Branch,
    /// svZeroDSolver's BloodVessel: the capacitor row is written on the inlet pressure with the
    /// chain rule, C (dP_in/dt − (R + 2S|Q|) dQ/dt) = Q − Q_out, evaluated at the
    /// generalized-α stages; first order where Q changes sign, as svZeroDSolver computes it.
    #[serde(rename = "svzerod")]
    SvZeroD,
}

/// The heart elements' sections and the start values are boxed: a structured tree has up to
/// millions of vessels, nearly all of them geometric, and each box left empty costs 8 bytes
/// where the value it holds would cost 24–100 (the record is ~200 B instead of ~700 B).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct VesselSpec {
    pub name: String,
    pub from: String,
    pub to: String,
    #[serde(default)]
    pub segments: Option<usize>,
    /// `segments: auto`: the count from the wave speed and the forcing
    /// (`assemble::auto_segments`); `segments` is then None.
    #[serde(default)]
    pub segments_auto: bool,
    #[serde(default)]
    pub geometry: Option<GeometrySpec>,
    #[serde(default)]
    pub lumped: Option<LumpedSpec>,
    #[serde(default)]
    pub arrangement: Option<Arrangement>,
    /// This vessel's friction and inertia (default: the model's `wall_friction`).
    #[serde(default)]
    pub wall_friction: Option<WallFriction>,
    #[serde(default = "yes")]
    pub output: bool,
    /// A heart valve instead of a vessel (docs/physics.md §1.8).
    #[serde(default)]
    pub valve: Option<Box<ValveSpec>>,
    /// The closed-loop heart and pulmonary circulation block instead of a vessel
    /// (docs/physics.md §1.10).
    #[serde(default)]
    pub heart_pulmonary: Option<Box<HeartPulmonarySpec>>,
    /// A closed-loop coronary bed whose intramyocardial pressure follows a heart block's
    /// ventricle (docs/physics.md §1.10).
    #[serde(default)]
    pub coronary_bed: Option<Box<CoronaryBedSpec>>,
    /// A heart chamber instead of a vessel (docs/physics.md §1.8).
    #[serde(default)]
    pub chamber: Option<Box<ChamberSpec>>,
    /// A flow-through R–C element instead of a vessel (docs/physics.md §1.8).
    #[serde(default)]
    pub through_rc: Option<Box<ThroughRcSpec>>,
    /// A spherical chamber with wall mechanics instead of a vessel (docs/physics.md §1.11).
    #[serde(default)]
    pub chamber_sphere: Option<Box<ChamberSphereSpec>>,
    /// Start values of the vessel's end pressures and flows (docs/physics.md §1.9).
    #[serde(default)]
    pub initial: Option<Box<EndValues>>,
    /// Start values of their time derivatives (docs/physics.md §1.9).
    #[serde(default)]
    pub initial_rate: Option<Box<EndValues>>,
}

impl VesselSpec {
    /// A vessel with no name, ends or element yet (recorded in the output): what the binding's
    /// readers fill in key by key.
    pub fn blank() -> Self {
        VesselSpec {
            name: String::new(),
            from: String::new(),
            to: String::new(),
            segments: None,
            segments_auto: false,
            geometry: None,
            lumped: None,
            arrangement: None,
            wall_friction: None,
            output: true,
            valve: None,
            heart_pulmonary: None,
            coronary_bed: None,
            chamber: None,
            through_rc: None,
            chamber_sphere: None,
            initial: None,
            initial_rate: None,
        }
    }
}

/// Values at a vessel's ends, SI (Pa, m³/s, or their rates per second); any may be absent.
#[derive(Debug, Clone, Copy, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EndValues {
    #[serde(default)]
    pub pressure_in: Option<f64>,
    #[serde(default)]
    pub pressure_out: Option<f64>,
    #[serde(default)]
    pub flow_in: Option<f64>,
    #[serde(default)]
    pub flow_out: Option<f64>,
}

/// A valve between the element's `from` and `to` nodes: R(P_to − P_from) (Pa·s/m³).
#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "law", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ValveSpec {
    /// svZeroDSolver's `ValveTanh`; `steepness` in 1/Pa.
    Tanh {
        min_resistance: f64,
        max_resistance: f64,
        steepness: f64,
    },
    /// svZeroDSolver's `PiecewiseValve`.
    Piecewise {
        min_resistance: f64,
        max_resistance: f64,
    },
}

/// A chamber at the element's `from` node, with an optional inductor to its `to` node.
/// Elastances in Pa/m³, volumes in m³, times in s. (Unknown keys are refused by the Python
/// layer: serde cannot deny them next to the flattened law.)
#[derive(Debug, Clone, Deserialize)]
pub struct ChamberSpec {
    #[serde(flatten)]
    pub law: ChamberLawSpec,
    pub activation: ActivationSpec,
    /// The cardiac period of the activation (s).
    pub period: f64,
    /// Inductance between the chamber and its outlet node (Pa·s²/m³).
    #[serde(default)]
    pub inductance: f64,
    /// The volume at the start of a zero-start run (m³); default 0.
    #[serde(default)]
    pub initial_volume: f64,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "law", rename_all = "kebab-case")]
pub enum ChamberLawSpec {
    /// svZeroDSolver's `ChamberElastanceInductor` (with the half-cosine activation).
    ElastanceInductor {
        max_elastance: f64,
        min_elastance: f64,
        rest_volume_diastole: f64,
        rest_volume_systole: f64,
    },
    /// svZeroDSolver's `LinearElastanceChamber`: E = passive + max · φ(t).
    Linear {
        max_elastance: f64,
        passive_elastance: f64,
        rest_volume: f64,
    },
    /// svZeroDSolver's `ChamberElastanceInductorExponential`: P = φ E_max (V − V_rest)
    /// + (1 − φ) K_p (e^{K_v (V − V_rest)} − 1).
    Exponential {
        max_elastance: f64,
        passive_pressure: f64,
        passive_volume_coefficient: f64,
        rest_volume: f64,
    },
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
pub enum ActivationSpec {
    HalfCosine {
        t_active: f64,
        t_twitch: f64,
    },
    PiecewiseCosine {
        contract_start: f64,
        relax_start: f64,
        contract_duration: f64,
        relax_duration: f64,
    },
    TwoHill {
        t_shift: f64,
        tau_1: f64,
        tau_2: f64,
        m1: f64,
        m2: f64,
    },
    /// Atrial activation wrapping across the cycle end (svZeroDSolver's `wrapping_cosine`:
    /// `Tsa` = `systole_fraction`, `tpwave` = `p_wave_divisor`).
    WrappingCosine {
        systole_fraction: f64,
        p_wave_divisor: f64,
    },
    /// svZeroDSolver's 25-mode ventricular `fourier` activation (no parameters).
    Fourier {},
}

/// The closed-loop heart and pulmonary circulation (svZeroDSolver's
/// `ClosedLoopHeartAndPulmonary`, docs/physics.md §1.10) between the element's `from` node (the
/// venous return into the right atrium) and its `to` node (the aorta). SI: elastances Pa/m³,
/// volumes m³, resistances Pa·s/m³, inductances Pa·s²/m³, capacitances m³/Pa, times s.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeartPulmonarySpec {
    pub period: f64,
    /// Atrial systole duration as a fraction of the period (svZeroDSolver's `Tsa`).
    pub atrial_systole_fraction: f64,
    /// The atrial contraction ends at period / p_wave_divisor (svZeroDSolver's `tpwave`).
    pub p_wave_divisor: f64,
    pub right_ventricle_elastance: f64,
    pub left_ventricle_elastance: f64,
    pub right_ventricle_rest_volume: f64,
    pub left_ventricle_rest_volume: f64,
    pub right_atrium_elastance: f64,
    pub left_atrium_elastance: f64,
    pub right_atrium_passive_pressure: f64,
    pub left_atrium_passive_pressure: f64,
    /// 1/m³
    pub right_atrium_passive_volume_coefficient: f64,
    pub left_atrium_passive_volume_coefficient: f64,
    pub right_atrium_rest_volume: f64,
    pub left_atrium_rest_volume: f64,
    pub tricuspid_resistance: f64,
    pub tricuspid_inductance: f64,
    pub pulmonary_valve_resistance: f64,
    pub pulmonary_valve_inductance: f64,
    pub mitral_resistance: f64,
    pub mitral_inductance: f64,
    pub aortic_valve_resistance: f64,
    pub aortic_valve_inductance: f64,
    pub pulmonary_resistance: f64,
    pub pulmonary_capacitance: f64,
    pub aortic_capacitance: f64,
    /// Start values of a zero-start run (default 0).
    #[serde(default)]
    pub initial_right_atrium_volume: f64,
    #[serde(default)]
    pub initial_right_ventricle_volume: f64,
    #[serde(default)]
    pub initial_left_atrium_volume: f64,
    #[serde(default)]
    pub initial_left_ventricle_volume: f64,
    #[serde(default)]
    pub initial_pulmonary_pressure: f64,
}

/// Which ventricle of a heart block loads a closed-loop coronary bed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Ventricle {
    Left,
    Right,
}

/// A closed-loop coronary bed (svZeroDSolver's `ClosedLoopCoronaryLeft`/`Right`) from the
/// element's `from` node to its `to` node: R_a, the arterial capacitor C_a, R_am, the
/// intramyocardial capacitor C_im under `intramyocardial_factor` × the pressure of the heart
/// block `heart`'s `ventricle`, and R_v (docs/physics.md §1.10).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoronaryBedSpec {
    pub arterial_resistance: f64,
    pub arterial_capacitance: f64,
    pub microvascular_resistance: f64,
    pub intramyocardial_capacitance: f64,
    pub venous_resistance: f64,
    /// The name of the `heart_pulmonary` element whose ventricle squeezes the bed.
    pub heart: String,
    pub ventricle: Ventricle,
    pub intramyocardial_factor: f64,
}

/// svZeroDSolver's `ChamberSphere` (docs/physics.md §1.11), SI: a thin spherical shell whose
/// wall is pushed by the chamber pressure, resisted by a hyperelastic (W₁, W₂) and viscous (η)
/// stress and contracted by an active stress that follows a tanh-switched activation rate.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChamberSphereSpec {
    /// Wall density (kg/m³).
    pub density: f64,
    /// Reference wall thickness (m).
    pub wall_thickness: f64,
    /// Reference (unloaded) radius (m).
    pub reference_radius: f64,
    /// Hyperelastic constants (Pa).
    pub w1: f64,
    pub w2: f64,
    /// Wall viscosity (Pa·s).
    pub viscosity: f64,
    /// Maximum active stress (Pa).
    pub max_active_stress: f64,
    /// Activation rates in systole and diastole (1/s).
    pub max_activation_rate: f64,
    pub min_activation_rate: f64,
    /// Start of systole and of diastole within the cycle, and the switch width (s).
    pub systole_start: f64,
    pub diastole_start: f64,
    pub activation_steepness: f64,
    /// The cardiac period (s).
    pub period: f64,
}

/// svZeroDSolver's `BloodVesselRC`: C dP_from/dt + (P_from − P_to)/R = Q, Q the same at both
/// ends (the capacitor's flow passes through to the outlet: a flow-through Windkessel).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThroughRcSpec {
    pub resistance: f64,
    pub capacitance: f64,
}
fn yes() -> bool {
    true
}

#[derive(Debug, Clone, Deserialize)]
#[serde(tag = "type", rename_all = "kebab-case", deny_unknown_fields)]
pub enum BoundarySpec {
    Flow {
        flow: WaveformSpec,
    },
    Pressure {
        pressure: WaveformSpec,
    },
    Resistance {
        resistance: f64,
        #[serde(default)]
        pressure: Option<WaveformSpec>,
    },
    Rcr {
        proximal_resistance: f64,
        capacitance: f64,
        distal_resistance: f64,
        #[serde(default)]
        pressure: Option<WaveformSpec>,
    },
    /// A coronary bed with intramyocardial pressure (docs/physics.md §1.7).
    Coronary(Box<CoronarySpec>),
    /// svZeroDSolver's `RESISTANCE` or `RCR` block at a vessel inlet (docs/svzerod.md).
    SvzerodInlet(Box<SvzerodInletSpec>),
}

/// svZeroDSolver's `RESISTANCE` (`resistance`) or `RCR` (`proximal_resistance`,
/// `capacitance`, `distal_resistance`) block at a vessel inlet, with its equations as written
/// for an outlet: Q is the flow into the vessel, so P_in = P_d + R Q (resistance), and
/// P_in = P_c + R_p Q, C dP_c/dt = Q − (P_c − P_d)/R_d (RCR). Values in Pa·s/m³ and m³/Pa.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SvzerodInletSpec {
    #[serde(default)]
    pub resistance: Option<f64>,
    #[serde(default)]
    pub proximal_resistance: Option<f64>,
    #[serde(default)]
    pub capacitance: Option<f64>,
    #[serde(default)]
    pub distal_resistance: Option<f64>,
    #[serde(default)]
    pub pressure: Option<WaveformSpec>,
}

/// The `coronary` outlet: arterial resistance and capacitance, microvascular resistance,
/// intramyocardial capacitance under the intramyocardial pressure, venous resistance to the
/// venous pressure `pressure` (svZeroDSolver's `CORONARY`). With `microvascular_resistance_max`
/// the microvascular resistance follows the contraction law of `crate::coefficients` between
/// `microvascular_resistance` and that maximum (svZeroDSolver's `CORONARY_VAR_RES`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CoronarySpec {
    pub arterial_resistance: f64,
    pub arterial_capacitance: f64,
    pub microvascular_resistance: f64,
    pub intramyocardial_capacitance: f64,
    pub venous_resistance: f64,
    pub intramyocardial_pressure: WaveformSpec,
    #[serde(default)]
    pub pressure: Option<WaveformSpec>,
    #[serde(default)]
    pub microvascular_resistance_max: Option<f64>,
    #[serde(default)]
    pub contraction_time: Option<f64>,
    #[serde(default)]
    pub relaxation_time: Option<f64>,
    /// Period of the contraction law (default: that of the intramyocardial pressure table).
    #[serde(default)]
    pub cycle_period: Option<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NetworkSpec {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub blood: BloodSpec,
    /// The model-wide arrangement (None: not stated; a vessel's own wins, and a vessel that
    /// states none is cut as `assemble::segments::arrangement` says: π where the `auto` rule
    /// cuts it, else inverted-L).
    #[serde(default)]
    pub arrangement: Option<Arrangement>,
    #[serde(default)]
    pub wall_model: WallModel,
    #[serde(default)]
    pub inertance_profile: InertanceProfile,
    /// The vessels' friction and inertia (each vessel may override it).
    #[serde(default)]
    pub wall_friction: WallFriction,
    #[serde(default)]
    pub max_segment_length: Option<f64>,
    /// `segmentation: {segments: auto}`: every vessel that gives no `segments` is cut by the
    /// `auto` rule (`assemble::auto_segments`).
    #[serde(default)]
    pub segments_auto: bool,
    /// The `auto` rule's relative tolerance (None: `auto_segments::DEFAULT_RTOL`).
    #[serde(default)]
    pub segmentation_rtol: Option<f64>,
    pub vessels: Vec<VesselSpec>,
    pub boundary_conditions: BTreeMap<String, BoundarySpec>,
    #[serde(default = "yes")]
    pub output_segments: bool,
    /// Species transport (oxygen and other solutes); absent for flow-only models.
    #[serde(default)]
    pub transport: Option<transport::TransportSpec>,
    /// Refuse to assemble a model whose memory estimate exceeds this many bytes (see
    /// `run::memory`); None: no limit.
    #[serde(default)]
    pub max_memory: Option<f64>,
}

pub use serde::de::DeserializeOwned;

/// Read one part of a canonical model (e.g. a vessel's `valve`) from its JSON text.
pub fn from_json<T: DeserializeOwned>(json: &str) -> std::result::Result<T, String> {
    serde_json::from_str(json).map_err(|e| e.to_string())
}

/// Read a canonical SI JSON model.
pub fn parse(json: &str) -> Result<NetworkSpec> {
    serde_json::from_str(json).map_err(|e| Error::model("model", e.to_string()))
}
