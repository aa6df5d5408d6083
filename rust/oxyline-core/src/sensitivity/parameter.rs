//! Scalar parameters of a model addressed by the ensemble patch paths
//! (`vessels.<name>.radius`, `boundary_conditions.<node>.capacitance`, `scale.resistance`, …),
//! and the exact derivative of the assembled DAE E ẏ + F y = f(t) with respect to each.
//!
//! The DAE is linear in its element values (node capacitances and branch inductances on the
//! diagonal of E, branch resistances on the diagonal of F's branch rows, the incidences are
//! constants), so its derivative is the derivative of those values stamped where they are.
//! Each element value is a power law in the parameters this module knows (docs/physics.md
//! §1.1): a segment's R, L and C are proportional to its length; its C to 1/E (thin and thick
//! walls alike); for a uniform radius r its R ∝ r⁻⁴, L ∝ r⁻², and thin-wall C ∝ r³ at a fixed
//! wall thickness; boundary and lumped values enter as themselves. The derivative of a power
//! law x = a pᵏ is k x / p: analytic, no differencing. A Womersley segment's friction cells
//! (`crate::womersley`) are linear in its Poiseuille R₀ and flat-profile L₀ (R_k = ρ_k R₀,
//! L_k = 8 ρ_k L₀/β_k), so they move with the segment's own derivatives, stamped on the
//! branch row, the cells' rows and their inertances ([`Stamps::segment_rl`]).
//!
//! A stenosis adds the nonlinear term c_i(y) = S |Q| Q to its branch row (S split evenly
//! over a lumped vessel's segments); its derivative with respect to S is |Q| Q at the step's
//! α_f level, recorded here as dS/dp per branch unknown ([`DaeTangent::dstenosis`]).
//!
//! Heart chambers and valves add element terms c_el(y, t) to their rows (`crate::element`):
//! a chamber's −P(V, t) (elastances, rest volumes, its activation's timing and shape), a
//! valve's R(ΔP) Q (its R_min, R_max and tanh steepness). Their derivative ∂c_el/∂θ is the
//! element's own ([`crate::element::Element::parameter_derivative`]), evaluated at each
//! step's α_f state ([`DaeTangent::delements`]).

use crate::circuit::CircuitElement;
use crate::circuit::{Circuit, Dae};
use crate::coefficients::ResistanceLaw;
use crate::error::{Error, Result};
use crate::model::path::{self, Scope};
use crate::model::{
    ActivationSpec, Arrangement, BoundarySpec, ChamberLawSpec, ChamberSpec, ChamberSphereSpec,
    HeartPulmonarySpec, NetworkSpec, StenosisForm, ValveSpec, VesselSpec,
};
use crate::segment::{
    Blood, InertanceProfile, Wall, WallFriction, WallModel, segment_rlc_radius_slopes,
};

/// What a parameter path names.
#[derive(Debug, Clone, PartialEq)]
pub enum Parameter {
    /// `boundary_conditions.<node>.<resistance|proximal_resistance|distal_resistance|capacitance>`,
    /// a coronary outlet's `arterial_resistance`, `microvascular_resistance`,
    /// `venous_resistance`, `arterial_capacitance`, `intramyocardial_capacitance` and
    /// `intramyocardial_pressure.scale` (a factor on its intramyocardial pressure waveform).
    Condition { node: String, key: String },
    /// `vessels.<name>.length`
    Length(usize),
    /// `vessels.<name>.radius` of a vessel of uniform radius.
    Radius(usize),
    /// `vessels.<name>.radius_in` (`outlet` false) or `.radius_out` (true): one end radius of
    /// a vessel's linear taper, the other held.
    EndRadius { vessel: usize, outlet: bool },
    /// `vessels.<name>.youngs_modulus`
    YoungsModulus(usize),
    /// `vessels.<name>.lumped.<resistance|capacitance|inductance|stenosis_coefficient>`
    Lumped(usize, String),
    /// `scale.resistance`: every resistance and RCR condition and lumped vessel resistance.
    ResistanceScale,
    /// `scale.compliance`: every capacitance of the network (C ∝ 1/E for geometric vessels).
    ComplianceScale,
    /// `scale.inflow`: every flow condition's waveform.
    InflowScale,
    /// `vessels.<name>.chamber.<key>` / `vessels.<name>.valve.<key>` /
    /// `vessels.<name>.chamber_sphere.<key>` / `vessels.<name>.heart_pulmonary.<key>`: a heart
    /// element's value, `key` as the element's model key (`activation.t_active`, …) and its
    /// SI value; `mass`: (position in the element's rows, derivative) of a mass-matrix entry
    /// the value sets (a spherical chamber's wall mass ρ d₀, a heart block's valve inductance
    /// or capacitor), if it sets one.
    Element {
        element: String,
        key: String,
        value: f64,
        mass: Option<(usize, f64)>,
    },
}

/// The derivative of the DAE with respect to one parameter, at the parameter's value.
#[derive(Debug, Clone)]
pub struct DaeTangent {
    /// The parameter's path as given.
    pub path: String,
    /// Its value (SI; 1 for a scale factor).
    pub value: f64,
    /// dE/dp by unknown.
    pub de: Vec<f64>,
    /// dF/dp by value of `Dae::f` (same pattern).
    pub df: Vec<f64>,
    /// d f_row / dp = factor · f_row(t), by index into `Dae::forcing`.
    pub dforcing: Vec<(usize, f64)>,
    /// (branch unknown i, dS_i/dp): the stenosis term S_i |y_i| y_i's coefficient.
    pub dstenosis: Vec<(usize, f64)>,
    /// (index into `Dae::elements`, key): ∂c_el/∂p is the element's derivative by its key.
    pub delements: Vec<(usize, String)>,
    /// (index into `Dae::varying`, which of its law's values): a time-varying resistance's
    /// R(t) moves by its law's slope by that value at each step's α_f time.
    pub dvarying: Vec<(usize, LawValue)>,
}

/// A varying resistance's law value a parameter is (`ResistanceLaw::Contraction`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LawValue {
    /// R_min (`microvascular_resistance`)
    Min,
    /// R_max (`microvascular_resistance_max`)
    Max,
    /// the contraction time T_c (`contraction_time`)
    Contraction,
    /// the relaxation time T_r (`relaxation_time`)
    Relaxation,
}

impl LawValue {
    fn of_key(key: &str) -> Option<Self> {
        match key {
            "microvascular_resistance" => Some(LawValue::Min),
            "microvascular_resistance_max" => Some(LawValue::Max),
            "contraction_time" => Some(LawValue::Contraction),
            "relaxation_time" => Some(LawValue::Relaxation),
            _ => None,
        }
    }

    /// ∂R(t)/∂(this value) of `law`.
    pub fn slope(self, law: &ResistanceLaw, t: f64) -> f64 {
        match self {
            LawValue::Min => law.slope(false, t),
            LawValue::Max => law.slope(true, t),
            LawValue::Contraction => law.timing_slope(false, t),
            LawValue::Relaxation => law.timing_slope(true, t),
        }
    }
}

fn unknown(path: &str, why: impl Into<String>) -> Error {
    Error::model(format!("parameter '{path}'"), why)
}

impl Parameter {
    /// Resolve `path` against `spec`: the vessel or condition must exist and hold the number.
    /// The path's shape and keys are read by the model's path resolver
    /// (`crate::model::path`), which words an unknown key the same way as the patch merge.
    /// A vessel or node name may itself hold dots: the longest name of the model that the
    /// path starts with wins (`crate::model::path::parameter_keys`).
    pub fn parse(spec: &NetworkSpec, path: &str) -> Result<Parameter> {
        let vessels: Vec<String> = spec.vessels.iter().map(|v| v.name.clone()).collect();
        let nodes: Vec<String> = spec.boundary_conditions.keys().cloned().collect();
        let names: [(&str, &[String]); 2] =
            [("vessels", &vessels), ("boundary_conditions", &nodes)];
        let parts = path::parameter_keys(path, &names);
        match parts.as_slice() {
            ["scale", "resistance"] => Ok(Parameter::ResistanceScale),
            ["scale", "compliance"] => Ok(Parameter::ComplianceScale),
            ["scale", "inflow"] => Ok(Parameter::InflowScale),
            // a coronary outlet's `intramyocardial_pressure.scale` is its one dotted key
            ["boundary_conditions", node, rest @ ..] if !rest.is_empty() => {
                condition(spec, path, node, &rest.join("."))
            }
            [
                "vessels",
                name,
                "chamber" | "valve" | "chamber_sphere" | "heart_pulmonary",
                ..,
            ] => heart_element(spec, path, name, &parts[2..]),
            ["vessels", name, rest @ ..] if !rest.is_empty() => vessel(spec, path, name, rest),
            _ => Err(unknown(path, path::parameter_shape(&parts))),
        }
    }
}

/// `vessels.<name>.chamber.<key>` or `vessels.<name>.valve.<key>` (`rest` after the name):
/// the element's SI value of a key its law has.
fn heart_element(spec: &NetworkSpec, path: &str, name: &str, rest: &[&str]) -> Result<Parameter> {
    let v = &spec.vessels[vessel_index(spec, path, name, rest)?];
    let key = rest[1..].join(".");
    let mut mass = None;
    let value = match (rest[0], &v.chamber, &v.valve, &v.chamber_sphere) {
        ("chamber", Some(c), ..) => chamber_value(c, &key),
        ("valve", _, Some(law), _) => valve_value(law, &key),
        ("chamber_sphere", .., Some(s)) => {
            // the wall's mass ρ d₀ on the velocity row: d/dρ = d₀, d/dd₀ = ρ
            mass = match key.as_str() {
                "density" => Some((2, s.wall_thickness)),
                "wall_thickness" => Some((2, s.density)),
                _ => None,
            };
            sphere_value(s, &key)
        }
        ("heart_pulmonary", ..) if v.heart_pulmonary.is_some() => {
            let h = v.heart_pulmonary.as_deref().expect("checked");
            mass = heart_mass(&key);
            heart_value(h, &key)
        }
        (kind, ..) => {
            return Err(unknown(path, format!("vessel '{name}' is not a {kind}")));
        }
    };
    let value = value.ok_or_else(|| {
        // the keys this element has a value for, named with the nearest of them
        let candidates = path::heart_paths(rest[0]);
        let has: Vec<&str> = candidates
            .iter()
            .map(String::as_str)
            .filter(|k| element_value(v, rest[0], k).is_some())
            .collect();
        unknown(
            path,
            format!(
                "the {} '{name}' has no differentiable value '{key}'{}",
                rest[0],
                path::heart_key_hint(&key, &has)
            ),
        )
    })?;
    Ok(Parameter::Element {
        element: format!("{} '{name}'", rest[0]),
        key,
        value,
        mass,
    })
}

/// The value of heart element `kind`'s `key` of vessel `v` (None: not such an element, or
/// no value there).
fn element_value(v: &VesselSpec, kind: &str, key: &str) -> Option<f64> {
    match kind {
        "chamber" => chamber_value(v.chamber.as_ref()?, key),
        "valve" => valve_value(v.valve.as_ref()?, key),
        "chamber_sphere" => sphere_value(v.chamber_sphere.as_ref()?, key),
        "heart_pulmonary" => heart_value(v.heart_pulmonary.as_deref()?, key),
        _ => None,
    }
}

/// A chamber's value by key: its law's elastances and volumes, and its activation's timing
/// and shape parameters (every law but the parameter-free Fourier series).
fn chamber_value(c: &ChamberSpec, key: &str) -> Option<f64> {
    use ChamberLawSpec as L;
    if let Some(timing) = key.strip_prefix("activation.") {
        return activation_value(&c.activation, timing);
    }
    match (&c.law, key) {
        (L::ElastanceInductor { max_elastance, .. }, "max_elastance")
        | (L::Linear { max_elastance, .. }, "max_elastance")
        | (L::Exponential { max_elastance, .. }, "max_elastance") => Some(*max_elastance),
        (L::ElastanceInductor { min_elastance, .. }, "min_elastance") => Some(*min_elastance),
        (
            L::ElastanceInductor {
                rest_volume_diastole,
                ..
            },
            "rest_volume_diastole",
        ) => Some(*rest_volume_diastole),
        (
            L::ElastanceInductor {
                rest_volume_systole,
                ..
            },
            "rest_volume_systole",
        ) => Some(*rest_volume_systole),
        (
            L::Linear {
                passive_elastance, ..
            },
            "passive_elastance",
        ) => Some(*passive_elastance),
        (L::Linear { rest_volume, .. }, "rest_volume")
        | (L::Exponential { rest_volume, .. }, "rest_volume") => Some(*rest_volume),
        (
            L::Exponential {
                passive_pressure, ..
            },
            "passive_pressure",
        ) => Some(*passive_pressure),
        (
            L::Exponential {
                passive_volume_coefficient,
                ..
            },
            "passive_volume_coefficient",
        ) => Some(*passive_volume_coefficient),
        _ => None,
    }
}

/// A heart block's value by its model key: every key but the period and the start values.
/// Inductances and capacitances are the circuit's (E), the rest the element's law.
fn heart_value(h: &HeartPulmonarySpec, key: &str) -> Option<f64> {
    Some(match key {
        "atrial_systole_fraction" => h.atrial_systole_fraction,
        "p_wave_divisor" => h.p_wave_divisor,
        "right_ventricle_elastance" => h.right_ventricle_elastance,
        "left_ventricle_elastance" => h.left_ventricle_elastance,
        "right_ventricle_rest_volume" => h.right_ventricle_rest_volume,
        "left_ventricle_rest_volume" => h.left_ventricle_rest_volume,
        "right_atrium_elastance" => h.right_atrium_elastance,
        "left_atrium_elastance" => h.left_atrium_elastance,
        "right_atrium_passive_pressure" => h.right_atrium_passive_pressure,
        "left_atrium_passive_pressure" => h.left_atrium_passive_pressure,
        "right_atrium_passive_volume_coefficient" => h.right_atrium_passive_volume_coefficient,
        "left_atrium_passive_volume_coefficient" => h.left_atrium_passive_volume_coefficient,
        "right_atrium_rest_volume" => h.right_atrium_rest_volume,
        "left_atrium_rest_volume" => h.left_atrium_rest_volume,
        "tricuspid_resistance" => h.tricuspid_resistance,
        "tricuspid_inductance" => h.tricuspid_inductance,
        "pulmonary_valve_resistance" => h.pulmonary_valve_resistance,
        "pulmonary_valve_inductance" => h.pulmonary_valve_inductance,
        "mitral_resistance" => h.mitral_resistance,
        "mitral_inductance" => h.mitral_inductance,
        "aortic_valve_resistance" => h.aortic_valve_resistance,
        "aortic_valve_inductance" => h.aortic_valve_inductance,
        "pulmonary_resistance" => h.pulmonary_resistance,
        "pulmonary_capacitance" => h.pulmonary_capacitance,
        "aortic_capacitance" => h.aortic_capacitance,
        _ => return None,
    })
}

/// The block's E entry a key sets (dE = 1 at that row): the valve inductances on the
/// valves' flow rows, the pulmonary capacitor on its pressure row and the aortic one on the
/// aorta's node, by their positions in the element's rows (`crate::element::heart`).
fn heart_mass(key: &str) -> Option<(usize, f64)> {
    let at = match key {
        "tricuspid_inductance" => 4,
        "pulmonary_valve_inductance" => 5,
        "mitral_inductance" => 6,
        "aortic_valve_inductance" => 7,
        "pulmonary_capacitance" => 10,
        "aortic_capacitance" => 13,
        _ => return None,
    };
    Some((at, 1.0))
}

/// A spherical chamber's constant by its model key (every one but the period).
fn sphere_value(s: &ChamberSphereSpec, key: &str) -> Option<f64> {
    Some(match key {
        "density" => s.density,
        "wall_thickness" => s.wall_thickness,
        "reference_radius" => s.reference_radius,
        "w1" => s.w1,
        "w2" => s.w2,
        "viscosity" => s.viscosity,
        "max_active_stress" => s.max_active_stress,
        "max_activation_rate" => s.max_activation_rate,
        "min_activation_rate" => s.min_activation_rate,
        "systole_start" => s.systole_start,
        "diastole_start" => s.diastole_start,
        "activation_steepness" => s.activation_steepness,
        _ => return None,
    })
}

/// An activation's parameter by its model key.
fn activation_value(a: &ActivationSpec, key: &str) -> Option<f64> {
    use ActivationSpec as A;
    let x = match (a, key) {
        (A::HalfCosine { t_active, .. }, "t_active") => t_active,
        (A::HalfCosine { t_twitch, .. }, "t_twitch") => t_twitch,
        (A::PiecewiseCosine { contract_start, .. }, "contract_start") => contract_start,
        (A::PiecewiseCosine { relax_start, .. }, "relax_start") => relax_start,
        (
            A::PiecewiseCosine {
                contract_duration, ..
            },
            "contract_duration",
        ) => contract_duration,
        (A::PiecewiseCosine { relax_duration, .. }, "relax_duration") => relax_duration,
        (A::TwoHill { t_shift, .. }, "t_shift") => t_shift,
        (A::TwoHill { tau_1, .. }, "tau_1") => tau_1,
        (A::TwoHill { tau_2, .. }, "tau_2") => tau_2,
        (A::TwoHill { m1, .. }, "m1") => m1,
        (A::TwoHill { m2, .. }, "m2") => m2,
        (
            A::WrappingCosine {
                systole_fraction, ..
            },
            "systole_fraction",
        ) => systole_fraction,
        (A::WrappingCosine { p_wave_divisor, .. }, "p_wave_divisor") => p_wave_divisor,
        _ => return None,
    };
    Some(*x)
}

/// A valve's value by key.
fn valve_value(law: &ValveSpec, key: &str) -> Option<f64> {
    match (law, key) {
        (ValveSpec::Tanh { min_resistance, .. }, "min_resistance")
        | (ValveSpec::Piecewise { min_resistance, .. }, "min_resistance") => Some(*min_resistance),
        (ValveSpec::Tanh { max_resistance, .. }, "max_resistance")
        | (ValveSpec::Piecewise { max_resistance, .. }, "max_resistance") => Some(*max_resistance),
        (ValveSpec::Tanh { steepness, .. }, "steepness") => Some(*steepness),
        _ => None,
    }
}

fn condition(spec: &NetworkSpec, path: &str, node: &str, key: &str) -> Result<Parameter> {
    let bc = spec.boundary_conditions.get(node).ok_or_else(|| {
        let known: Vec<String> = spec.boundary_conditions.keys().cloned().collect();
        let pieces: Vec<&str> = std::iter::once(node).chain(key.split('.')).collect();
        let near = path::nearest_hint(&path::nearest_name(&pieces, &known));
        unknown(
            path,
            format!(
                "no boundary condition at node '{node}' in model '{}'{near}",
                spec.name
            ),
        )
    })?;
    // the law's period sets when R(t) repeats, and the periodic solution is that of the
    // model's cycle: a period moved alone has no periodic solution to differentiate
    if let (BoundarySpec::Coronary(c), "cycle_period") = (bc, key)
        && c.microvascular_resistance_max.is_some()
    {
        return Err(unknown(
            path,
            format!(
                "the varying microvascular resistance at node '{node}' repeats with the \
                 cycle: its cycle_period is not differentiable (the periodic solution needs \
                 the model's period)"
            ),
        ));
    }
    if condition_value(bc, key).is_none() {
        return Err(unknown(path, no_condition_value(bc, node, key)));
    }
    // a varying microvascular resistance R(t) follows R_min and R_max through their square
    // roots (`ResistanceLaw::slope`), which have no derivative at zero
    if let (BoundarySpec::Coronary(c), "microvascular_resistance" | "microvascular_resistance_max") =
        (bc, key)
        && let Some(max) = c.microvascular_resistance_max
        && (c.microvascular_resistance <= 0.0 || max <= 0.0)
    {
        return Err(unknown(
            path,
            format!(
                "the condition at node '{node}' has a varying microvascular resistance with a \
                 zero end (microvascular_resistance {}, microvascular_resistance_max {max}): \
                 its law has no derivative there",
                c.microvascular_resistance
            ),
        ));
    }
    Ok(Parameter::Condition {
        node: node.to_owned(),
        key: key.to_owned(),
    })
}

/// The intramyocardial pressure's factor of a coronary outlet (1 at the model's waveform).
const PIM_SCALE: &str = "intramyocardial_pressure.scale";

/// A condition's differentiable value by key: its SI value and the label of the circuit part
/// that holds it (a branch's resistance, or a node's capacitance: see [`is_node_label`]; None
/// for the intramyocardial pressure's factor, a forcing) — None for a key it does not have.
fn condition_value(bc: &BoundarySpec, key: &str) -> Option<(f64, Option<&'static str>)> {
    let r = |x: f64, label| Some((x, Some(label)));
    match (bc, key) {
        (BoundarySpec::Resistance { resistance, .. }, "resistance") => r(*resistance, "resistance"),
        (
            BoundarySpec::Rcr {
                proximal_resistance: x,
                ..
            },
            "proximal_resistance",
        ) => r(*x, "proximal resistance"),
        (
            BoundarySpec::Rcr {
                distal_resistance: x,
                ..
            },
            "distal_resistance",
        ) => r(*x, "distal resistance"),
        (BoundarySpec::Rcr { capacitance: x, .. }, "capacitance") => r(*x, "capacitor"),
        (BoundarySpec::Coronary(c), _) => match key {
            "arterial_resistance" => r(c.arterial_resistance, "proximal resistance"),
            "microvascular_resistance" => r(c.microvascular_resistance, "microvascular resistance"),
            "microvascular_resistance_max" => {
                r(c.microvascular_resistance_max?, "microvascular resistance")
            }
            // the law's times (only with a law: R_max given)
            "contraction_time" if c.microvascular_resistance_max.is_some() => {
                r(c.contraction_time?, "microvascular resistance")
            }
            "relaxation_time" if c.microvascular_resistance_max.is_some() => {
                r(c.relaxation_time?, "microvascular resistance")
            }
            "venous_resistance" => r(c.venous_resistance, "distal resistance"),
            "arterial_capacitance" => r(c.arterial_capacitance, "capacitor"),
            "intramyocardial_capacitance" => {
                r(c.intramyocardial_capacitance, "intramyocardial compartment")
            }
            PIM_SCALE => Some((1.0, None)),
            _ => None,
        },
        _ => None,
    }
}

/// Every key a condition may hold a differentiable value under ([`condition_value`]).
const CONDITION_KEYS: &[&str] = &[
    "resistance",
    "proximal_resistance",
    "distal_resistance",
    "capacitance",
    "arterial_resistance",
    "microvascular_resistance",
    "microvascular_resistance_max",
    "contraction_time",
    "relaxation_time",
    "venous_resistance",
    "arterial_capacitance",
    "intramyocardial_capacitance",
    PIM_SCALE,
];

/// Why the condition at `node` has no differentiable value `key`: the values it has, and
/// the nearest of them (`crate::model::path::nearest`).
fn no_condition_value(bc: &BoundarySpec, node: &str, key: &str) -> String {
    let has: Vec<&str> = CONDITION_KEYS
        .iter()
        .copied()
        .filter(|k| condition_value(bc, k).is_some())
        .collect();
    let mut message = format!("the condition at node '{node}' has no differentiable value '{key}'");
    if has.is_empty() {
        message.push_str(" (it has none)");
        return message;
    }
    message.push_str(&format!(" (differentiable: {}", has.join(", ")));
    let near = path::nearest(key, &has);
    if !near.is_empty() {
        message.push_str(&format!("; nearest: {}", near.join(", ")));
    }
    message.push(')');
    message
}

/// Whether a condition's part label names a node (a capacitor) rather than a branch.
fn is_node_label(label: &str) -> bool {
    matches!(label, "capacitor" | "intramyocardial compartment")
}

/// The index of the vessel named `name` (`rest`: the path's pieces after it); for none, an
/// error naming the path, the name and the model's nearest vessel names.
fn vessel_index(spec: &NetworkSpec, path: &str, name: &str, rest: &[&str]) -> Result<usize> {
    spec.vessels
        .iter()
        .position(|v| v.name == name)
        .ok_or_else(|| {
            let known: Vec<String> = spec.vessels.iter().map(|v| v.name.clone()).collect();
            let pieces: Vec<&str> = std::iter::once(name).chain(rest.iter().copied()).collect();
            let near = path::nearest_hint(&path::nearest_name(&pieces, &known));
            unknown(
                path,
                format!("no vessel named '{name}' in model '{}'{near}", spec.name),
            )
        })
}

fn vessel(spec: &NetworkSpec, path: &str, name: &str, rest: &[&str]) -> Result<Parameter> {
    let vi = vessel_index(spec, path, name, rest)?;
    let v = &spec.vessels[vi];
    let p = match (rest, &v.geometry, &v.lumped) {
        (["length"], Some(_), _) => Parameter::Length(vi),
        (["youngs_modulus"], Some(g), _) if g.youngs_modulus.is_some() => {
            Parameter::YoungsModulus(vi)
        }
        (["radius"], Some(g), _) => {
            if g.radius_in != g.radius_out {
                return Err(unknown(
                    path,
                    "the vessel is tapered: its radius is not one number (its end radii \
                     radius_in and radius_out are parameters)",
                ));
            }
            Parameter::Radius(vi)
        }
        ([end @ ("radius_in" | "radius_out")], Some(_), _) => Parameter::EndRadius {
            vessel: vi,
            outlet: *end == "radius_out",
        },
        (["lumped", key], _, Some(l))
            if matches!(
                *key,
                "resistance" | "capacitance" | "inductance" | "stenosis_coefficient"
            ) =>
        {
            if let Some(why) = form_switch(spec, v, l, key) {
                return Err(unknown(path, why));
            }
            Parameter::Lumped(vi, (*key).to_owned())
        }
        _ => return Err(unknown(path, no_vessel_value(name, rest))),
    };
    Ok(p)
}

/// Why `rest` (after `vessels.<name>.`) names no differentiable value of the vessel: a key
/// the schema does not have (named by the path resolver, with the nearest), else a value
/// the vessel lacks or that has no derivative.
fn no_vessel_value(name: &str, rest: &[&str]) -> String {
    let known = match rest {
        [key] => Scope::Vessel.check(key),
        ["lumped", key] => Scope::Lumped.check(key),
        _ => Ok(()),
    };
    known.err().unwrap_or_else(|| {
        format!(
            "vessel '{name}' has no differentiable value '{}'",
            rest.join(".")
        )
    })
}

/// Which end radii of a vessel a radius parameter moves (by one per unit).
#[derive(Debug, Clone, Copy)]
enum RadiusEnds {
    Inlet,
    Outlet,
    Both,
}

/// Whether vessel `vi` has a wall whose compliance follows the thick (Lamé) wall model.
fn thick_wall(spec: &NetworkSpec, vi: usize) -> bool {
    let g = spec.vessels[vi].geometry.as_ref();
    spec.wall_model == WallModel::Thick && g.is_some_and(|g| g.wall_thickness.is_some())
}

/// Whether vessel `v`'s segments carry Womersley friction cells, whose values follow each
/// segment's R₀ and L₀ (`assemble::vessel`, [`Stamps::segment_rl`]).
fn friction_cells(spec: &NetworkSpec, v: &VesselSpec) -> bool {
    v.wall_friction.unwrap_or(spec.wall_friction) == WallFriction::Womersley
        && crate::assemble::segments::arrangement(spec, v) != Arrangement::Rcl
}

/// Why an RCL vessel's lumped value `key` has no derivative, if it has none: with
/// `stenosis_form: svzerod` its capacitor row takes the chain-rule form only while both its
/// stenosis coefficient and its capacitance are non-zero (`assemble::vessel`), so the run's
/// discrete equations switch form where either leaves zero, and the difference quotient there
/// is not the derivative of one scheme.
fn form_switch(
    spec: &NetworkSpec,
    v: &crate::model::VesselSpec,
    l: &crate::model::LumpedSpec,
    key: &str,
) -> Option<&'static str> {
    let rcl = crate::assemble::segments::arrangement(spec, v) == Arrangement::Rcl;
    if !rcl || l.stenosis_form != StenosisForm::SvZeroD {
        return None;
    }
    match key {
        "stenosis_coefficient" if l.stenosis_coefficient == 0.0 && l.capacitance > 0.0 => Some(
            "its svZeroDSolver-form stenosis (stenosis_form: svzerod) is zero, where the \
             capacitor's discrete form switches: start from a non-zero coefficient",
        ),
        "capacitance" if l.capacitance == 0.0 && l.stenosis_coefficient != 0.0 => Some(
            "its capacitance is zero, where the svZeroDSolver-form stenosis's (stenosis_form: \
             svzerod) capacitor form switches: start from a non-zero capacitance",
        ),
        _ => None,
    }
}

/// Refuse what the tangent does not cover: the closed-loop heart block's coronary beds (their
/// iteration matrix leaves out the ventricle coupling on purpose) and through_rc elements.
/// Stenoses of both forms (svZeroDSolver's: chain-rule capacitor rows, `super::tangent`), chambers, spherical chambers,
/// valves and the closed-loop heart block are covered (their terms are differentiated
/// exactly; the block's reset flows by a zero tangent row, `super::tangent`), as are coronary
/// outlets (constant circuit parts and forcing) and time-varying resistances (a varying
/// coronary microvascular resistance: its D(t) joins each step's matrix, `super::tangent`;
/// its own values are refused in [`Parameter::parse`]).
pub fn check_supported(circuit: &Circuit, _dae: &Dae) -> Result<()> {
    let other = circuit.elements.iter().find_map(|e| match e {
        CircuitElement::Valve { .. }
        | CircuitElement::Chamber { .. }
        | CircuitElement::Sphere { .. }
        | CircuitElement::Heart { .. } => None,
        CircuitElement::Coronary { name, .. } => Some(format!(
            "the closed-loop coronary bed {name} (the tangent needs its exact Jacobian, and \
             the bed's leaves out its coupling to the ventricle pressure on purpose)"
        )),
    });
    let why = if let Some(e) = other {
        Some(e)
    } else if !circuit.swapped_rows.is_empty() {
        Some("through_rc elements".to_owned())
    } else {
        None
    };
    match why {
        Some(w) => Err(Error::model(
            "sensitivities",
            format!("do not cover models with {w}"),
        )),
        None => Ok(()),
    }
}

/// Refuse a closed loop (a model with the closed-loop heart block and no boundary
/// condition) whose conserved blood volume was not found (`conserved`: its balance rows
/// cancel every flow term, `super::volume`): without that row the periodic tangent's fixed
/// point is not determined (the volume is a neutral mode of the cycle map).
pub fn check_closed_loop(spec: &NetworkSpec, conserved: bool) -> Result<()> {
    let heart = spec.vessels.iter().find(|v| v.heart_pulmonary.is_some());
    match heart {
        Some(v) if spec.boundary_conditions.is_empty() && !conserved => Err(Error::model(
            "sensitivities",
            format!(
                "do not cover this closed loop (the heart_pulmonary block '{}' without a \
                 boundary condition): its flow balances do not conserve the blood volume, \
                 the row that sets the periodic tangent",
                v.name
            ),
        )),
        _ => Ok(()),
    }
}

/// A viscoelastic vessel's wall as a parameter moves it ([`Stamps::onto_viscous_walls`]).
struct OwnWall {
    /// Its relaxation time η/E (s) and that time's derivative by the parameter.
    tau: f64,
    dtau: f64,
    /// Its capacitance share (m³/Pa) by node.
    shares: std::collections::HashMap<usize, f64>,
}

/// Where a circuit's element values sit in the DAE.
pub struct Stamps<'a> {
    circuit: &'a Circuit,
    dae: &'a Dae,
    /// The index into `dae.f.val` of each branch's resistance (its row's diagonal).
    branch_r: Vec<usize>,
    /// Node → its viscoelastic wall (index into `circuit.viscous_walls`).
    wall_of: std::collections::HashMap<usize, usize>,
    /// Per branch, its Womersley friction cells (a range of `circuit.friction_cells`, which
    /// holds each branch's cells together); empty for a circuit without cells.
    cells_of: Vec<std::ops::Range<usize>>,
}

impl<'a> Stamps<'a> {
    pub fn new(circuit: &'a Circuit, dae: &'a Dae) -> Stamps<'a> {
        let nn = circuit.nodes.len();
        let branch_r = (0..circuit.branches.len())
            .map(|b| {
                let row = nn + b;
                dae.f
                    .row(row)
                    .find(|&k| dae.f.col[k] as usize == row)
                    .expect("a branch row holds its resistance")
            })
            .collect();
        let wall_of = (circuit.viscous_walls.iter().enumerate())
            .map(|(k, w)| (w.node, k))
            .collect();
        let mut cells_of = Vec::new();
        if !circuit.friction_cells.is_empty() {
            cells_of = vec![0..0; circuit.branches.len()];
            for (k, c) in circuit.friction_cells.iter().enumerate() {
                let r = &mut cells_of[c.branch];
                if r.start == r.end {
                    r.start = k;
                }
                r.end = k + 1;
            }
        }
        Stamps {
            circuit,
            dae,
            branch_r,
            wall_of,
            cells_of,
        }
    }

    fn blank(&self, path: &str, value: f64) -> DaeTangent {
        DaeTangent {
            path: path.to_owned(),
            value,
            de: vec![0.0; self.dae.n],
            df: vec![0.0; self.dae.f.val.len()],
            dforcing: Vec::new(),
            dstenosis: Vec::new(),
            delements: Vec::new(),
            dvarying: Vec::new(),
        }
    }

    fn branch_named(&self, name: &str) -> Option<usize> {
        (0..self.circuit.branches.len()).find(|&b| self.circuit.names.branch(b) == name)
    }

    fn node_named(&self, name: &str) -> Option<usize> {
        (0..self.circuit.nodes.len()).find(|&i| self.circuit.names.node(i) == name)
    }

    /// Node i's capacitance as the DAE holds it (0 on a row a pressure condition took).
    fn node_c(&self, i: usize) -> f64 {
        self.dae.e[i]
    }

    /// The derivative of the DAE with respect to `p` (named `path`) of `spec`.
    pub fn tangent(&self, spec: &NetworkSpec, p: &Parameter, path: &str) -> Result<DaeTangent> {
        let nn = self.circuit.nodes.len();
        let missing = || unknown(path, "its element is not in the assembled circuit");
        let mut t;
        match p {
            Parameter::Condition { node, key } => {
                let bc = &spec.boundary_conditions[node];
                let (value, label) = condition_value(bc, key).ok_or_else(missing)?;
                t = self.blank(path, value);
                let name = |l: &str| format!("boundary condition '{node}' {l}");
                match label {
                    Some(l) if is_node_label(l) => {
                        t.de[self.node_named(&name(l)).ok_or_else(missing)?] = 1.0;
                    }
                    Some(l) => {
                        let b = self.branch_named(&name(l)).ok_or_else(missing)?;
                        // a varying resistance moves by its law's slope, step by step
                        let law = self.dae.varying.iter().position(|(i, _)| *i == nn + b);
                        match (law, LawValue::of_key(key)) {
                            (Some(law), Some(which)) => t.dvarying.push((law, which)),
                            (None, None | Some(LawValue::Min)) => t.df[self.branch_r[b]] = 1.0,
                            _ => return Err(missing()),
                        }
                    }
                    // P_im is the series source of the microvascular and venous branches
                    None => {
                        for l in ["microvascular resistance", "distal resistance"] {
                            let b = self.branch_named(&name(l)).ok_or_else(missing)?;
                            let row = nn + b;
                            let k = (self.dae.forcing.iter())
                                .position(|(r, _)| *r == row)
                                .ok_or_else(missing)?;
                            t.dforcing.push((k, 1.0));
                        }
                    }
                }
            }
            // a thick wall's C is no power law of the radius: both end radii's slopes
            Parameter::Radius(vi) if thick_wall(spec, *vi) => {
                let g = spec.vessels[*vi].geometry.as_ref().ok_or_else(missing)?;
                t = self.blank(path, g.radius_in);
                self.vessel_end_radius(&mut t, spec, *vi, RadiusEnds::Both)
                    .ok_or_else(missing)?;
            }
            Parameter::Length(vi) | Parameter::Radius(vi) | Parameter::YoungsModulus(vi) => {
                let g = spec.vessels[*vi].geometry.as_ref().ok_or_else(missing)?;
                // exponents of (R, L, C) in the parameter
                let (value, k) = match p {
                    Parameter::Length(_) => (g.length, [1.0, 1.0, 1.0]),
                    Parameter::Radius(_) => (g.radius_in, [-4.0, -2.0, 3.0]),
                    _ => (g.youngs_modulus.unwrap_or(f64::NAN), [0.0, 0.0, -1.0]),
                };
                t = self.blank(path, value);
                let v = &spec.vessels[*vi];
                self.vessel_power_law(&mut t, v, friction_cells(spec, v), k, value);
            }
            Parameter::EndRadius { vessel, outlet } => {
                let g = spec.vessels[*vessel]
                    .geometry
                    .as_ref()
                    .ok_or_else(missing)?;
                let value = if *outlet { g.radius_out } else { g.radius_in };
                t = self.blank(path, value);
                let ends = match outlet {
                    true => RadiusEnds::Outlet,
                    false => RadiusEnds::Inlet,
                };
                self.vessel_end_radius(&mut t, spec, *vessel, ends)
                    .ok_or_else(missing)?;
            }
            Parameter::Lumped(vi, key) => {
                let l = spec.vessels[*vi].lumped.as_ref().ok_or_else(missing)?;
                let name = &spec.vessels[*vi].name;
                // an RCL vessel (svZeroDSolver's BloodVessel) holds its R and stenosis on a
                // branch of their own, its C at its one interior point, its L on the segment's
                if let (Some(b), "resistance" | "stenosis_coefficient") = (
                    self.branch_named(&format!("vessel '{name}' resistance")),
                    key.as_str(),
                ) {
                    if key == "resistance" {
                        t = self.blank(path, l.resistance);
                        t.df[self.branch_r[b]] = 1.0;
                    } else {
                        t = self.blank(path, l.stenosis_coefficient);
                        t.dstenosis.push((nn + b, 1.0));
                    }
                    return Ok(t);
                }
                if key == "stenosis_coefficient" {
                    t = self.blank(path, l.stenosis_coefficient);
                    self.vessel_stenosis(&mut t, name);
                    return Ok(t);
                }
                let (value, k) = match key.as_str() {
                    "resistance" => (l.resistance, [1.0, 0.0, 0.0]),
                    "inductance" => (l.inductance, [0.0, 1.0, 0.0]),
                    _ => (l.capacitance, [0.0, 0.0, 1.0]),
                };
                t = self.blank(path, value);
                // split evenly over the segments: each value is value/n, d/dvalue = 1/n
                let v = &spec.vessels[*vi];
                self.vessel_linear(&mut t, v, friction_cells(spec, v), k);
            }
            Parameter::ResistanceScale => {
                t = self.blank(path, 1.0);
                self.resistance_scale(&mut t, spec);
            }
            Parameter::ComplianceScale => {
                t = self.blank(path, 1.0);
                for i in 0..nn {
                    t.de[i] = self.node_c(i);
                }
                // a viscoelastic wall holds its node's capacitance at its elastic pressure;
                // its R_v = τ/C stays, as the patch's E/s moves τ = η/E and C alike
                for &(_, wall) in &self.dae.walls {
                    t.de[wall] = self.dae.e[wall];
                }
                // the patch leaves a coronary bed's capacitors as they are
                for (node, bc) in &spec.boundary_conditions {
                    if matches!(bc, BoundarySpec::Coronary(_)) {
                        for l in ["capacitor", "intramyocardial compartment"] {
                            let name = format!("boundary condition '{node}' {l}");
                            if let Some(i) = self.node_named(&name) {
                                t.de[i] = 0.0;
                            }
                        }
                    }
                }
            }
            Parameter::Element {
                element,
                key,
                value,
                mass,
            } => {
                t = self.blank(path, *value);
                let e = (self.dae.elements.iter())
                    .position(|e| e.name() == element)
                    .ok_or_else(missing)?;
                match mass {
                    // an E entry only (a heart block's inductance or capacitor)
                    Some((at, dm)) if element.starts_with("heart_pulmonary") => {
                        t.de[self.dae.elements[e].rows()[*at]] = *dm;
                    }
                    _ => t.delements.push((e, key.clone())),
                }
                if let (Some((at, dm)), true) = (mass, element.starts_with("chamber_sphere")) {
                    // a spherical chamber's rows: pressure, displacement, velocity, …
                    t.de[self.dae.elements[e].rows()[*at]] = *dm;
                }
            }
            Parameter::InflowScale => {
                t = self.blank(path, 1.0);
                let fixed: Vec<usize> = self.circuit.fixed_pressures.iter().map(|f| f.0).collect();
                for (k, (row, _)) in self.dae.forcing.iter().enumerate() {
                    if *row < nn && !fixed.contains(row) {
                        t.dforcing.push((k, 1.0));
                    }
                }
                if t.dforcing.is_empty() {
                    return Err(unknown(path, "the model has no flow condition"));
                }
            }
        }
        // a vessel's capacitance at a viscoelastic wall's node sits at the wall's elastic
        // pressure, behind a conductance that follows it (`scale.compliance` places its own)
        if let Parameter::Length(vi)
        | Parameter::Radius(vi)
        | Parameter::YoungsModulus(vi)
        | Parameter::EndRadius { vessel: vi, .. }
        | Parameter::Lumped(vi, _) = p
            && !self.dae.walls.is_empty()
        {
            let own = self.own_relaxation(spec, *vi, matches!(p, Parameter::YoungsModulus(_)));
            self.onto_viscous_walls(&mut t, own);
        }
        Ok(t)
    }

    /// The relaxation time τ = η/E of viscoelastic vessel `vi` and its derivative by the
    /// parameter (−τ/E by the Young's modulus, 0 by its geometry), with the vessel's own
    /// capacitance share at each of its nodes; None for an elastic or lumped vessel.
    fn own_relaxation(&self, spec: &NetworkSpec, vi: usize, by_modulus: bool) -> Option<OwnWall> {
        let v = &spec.vessels[vi];
        let g = v.geometry.as_ref()?;
        let e = g.youngs_modulus?;
        if g.wall_viscosity <= 0.0
            || crate::assemble::segments::arrangement(spec, v) == Arrangement::Rcl
        {
            return None;
        }
        let tau = g.wall_viscosity / e;
        let mut shares = std::collections::HashMap::new();
        for s in self.segments_of(&v.name) {
            for &(node, share) in &s.nodes {
                *shares.entry(node).or_insert(0.0) += share * s.compliance;
            }
        }
        Some(OwnWall {
            tau,
            dtau: if by_modulus { -tau / e } else { 0.0 },
            shares,
        })
    }

    /// Move the node capacitance derivatives of `t` onto the viscoelastic walls that hold
    /// them (`Circuit::active_walls`): a wall keeps its node's capacitance C at its elastic
    /// pressure's unknown behind the conductance g = 1/R_v = C S/T, S = Σ c_i and
    /// T = Σ c_i τ_i over the node's viscoelastic shares. So dC moves from the node's E entry
    /// to the wall's, and g moves by dg = dC S/T + C (dS T − S dT)/T² on the wall's four F
    /// entries (+g, −g on the node's row, −g, +g on the wall's). The parameter's own
    /// viscoelastic vessel moves S by its shares' dc (the node's whole dC: a vessel
    /// parameter moves no other vessel's share) and T by dc τ + c dτ.
    fn onto_viscous_walls(&self, t: &mut DaeTangent, own: Option<OwnWall>) {
        for &(node, u) in &self.dae.walls {
            let dc = t.de[node];
            let own_share = own
                .as_ref()
                .and_then(|o| o.shares.get(&node).map(|&c| (o, c)));
            if dc == 0.0 && own_share.is_none() {
                continue;
            }
            let Some(w) = self
                .wall_of
                .get(&node)
                .map(|&k| &self.circuit.viscous_walls[k])
            else {
                continue;
            };
            let (c, s, tt) = (self.dae.e[u], w.capacitance, w.capacitance_time);
            let (ds, dt) = match own_share {
                Some((o, share)) => (dc, dc * o.tau + share * o.dtau),
                None => (0.0, 0.0),
            };
            let dg = dc * s / tt + c * (ds * tt - s * dt) / (tt * tt);
            t.de[node] = 0.0;
            t.de[u] += dc;
            for (row, col, sign) in [
                (node, node, 1.0),
                (node, u, -1.0),
                (u, node, -1.0),
                (u, u, 1.0),
            ] {
                if let Some(k) = self
                    .dae
                    .f
                    .row(row)
                    .find(|&k| self.dae.f.col[k] as usize == col)
                {
                    t.df[k] += sign * dg;
                }
            }
        }
    }

    /// The segments of vessel `name`: (branch, node shares, compliance).
    fn segments_of<'b>(
        &'b self,
        name: &'b str,
    ) -> impl Iterator<Item = &'b crate::circuit::SegmentGeom> + 'b {
        self.circuit
            .segments
            .iter()
            .filter(move |s| self.circuit.vessel_names[s.vessel] == name)
    }

    /// d/dp of a vessel whose segment values are power laws x ∝ p^k, k for (R, L, C) (a
    /// Womersley segment's cells follow its R₀ and L₀: [`Stamps::segment_rl`]).
    fn vessel_power_law(&self, t: &mut DaeTangent, v: &VesselSpec, w: bool, k: [f64; 3], p: f64) {
        for s in self.segments_of(&v.name) {
            let b = &self.circuit.branches[s.branch];
            let l0 = self.flat_inductance(s.branch, w);
            self.segment_rl(t, s.branch, w, k[0] * b.resistance / p, k[1] * l0 / p);
            for &(node, share) in &s.nodes {
                t.de[node] += k[2] * share * s.compliance / p;
            }
        }
    }

    /// d/d(end radius) of a tapered vessel `vi`: its segments cut the linear taper at k/n, so
    /// segment k's ends move by (1 − k/n, 1 − (k+1)/n) of the inlet radius and (k/n, (k+1)/n)
    /// of the outlet radius, and its R, L and C by the segment's own slopes
    /// ([`segment_rlc_radius_slopes`], at the wall thickness and modulus held; both ends by
    /// one for a uniform radius under the thick wall, whose C is no power law of it). None
    /// when the vessel's segments are not in the circuit.
    fn vessel_end_radius(
        &self,
        t: &mut DaeTangent,
        spec: &NetworkSpec,
        vi: usize,
        ends: RadiusEnds,
    ) -> Option<()> {
        let v = &spec.vessels[vi];
        let g = v.geometry.as_ref()?;
        let n = self.segments_of(&v.name).count();
        if n == 0 {
            return None;
        }
        let blood = Blood {
            density: spec.blood.density,
            viscosity: spec.blood.viscosity,
        };
        let wall = match (g.wall_thickness, g.youngs_modulus) {
            (Some(h), Some(e)) => Some(Wall {
                thickness: h,
                youngs_modulus: e,
                poisson_ratio: g.poisson_ratio,
                model: spec.wall_model,
            }),
            _ => None,
        };
        // the assembly's profile: a Womersley segment's series inertance is the flat one's
        let cells = friction_cells(spec, v);
        let profile = match cells {
            true => InertanceProfile::Flat,
            false => spec.inertance_profile,
        };
        let (dx, dr) = (g.length / n as f64, g.radius_out - g.radius_in);
        for (k, s) in self.segments_of(&v.name).enumerate() {
            let at = |j: usize| j as f64 / n as f64;
            let (r0, r1) = (g.radius_in + dr * at(k), g.radius_in + dr * at(k + 1));
            let [d0, d1] = segment_rlc_radius_slopes(dx, r0, r1, blood, wall, profile)?;
            let (w0, w1) = match ends {
                RadiusEnds::Outlet => (at(k), at(k + 1)),
                RadiusEnds::Inlet => (1.0 - at(k), 1.0 - at(k + 1)),
                RadiusEnds::Both => (1.0, 1.0),
            };
            let dr = w0 * d0.resistance + w1 * d1.resistance;
            let dl = w0 * d0.inductance + w1 * d1.inductance;
            self.segment_rl(t, s.branch, cells, dr, dl);
            let dc = w0 * d0.compliance + w1 * d1.compliance;
            for &(node, share) in &s.nodes {
                t.de[node] += share * dc;
            }
        }
        Some(())
    }

    /// d/dvalue of a lumped vessel's total R, L or C split evenly over its segments.
    fn vessel_linear(&self, t: &mut DaeTangent, v: &VesselSpec, w: bool, which: [f64; 3]) {
        let n = self.segments_of(&v.name).count() as f64;
        for s in self.segments_of(&v.name) {
            self.segment_rl(t, s.branch, w, which[0] / n, which[1] / n);
            for &(node, share) in &s.nodes {
                t.de[node] += which[2] * share / n;
            }
        }
    }

    /// Stamp the derivative (dR₀, dL₀) of a segment's Poiseuille resistance and series
    /// inertance on its branch `b`. Without friction cells they are the branch row's
    /// resistance and inductance. With cells (`crate::womersley`) the branch row holds
    /// (R₀ + Σ R_k) Q − Σ R_k i_k and the series inertance L₀ plus the folded cells', and
    /// each cell's row L_k di_k/dt + R_k i_k − R_k Q: every R_k and L_k follows R₀ and L₀
    /// ([`crate::womersley::cells_derivative`]), on the branch row, the cell's row and its E.
    /// `womersley`: whether the segment's vessel has cells (a segment whose every cell is
    /// folded has none in the circuit, and its inertance still holds theirs).
    fn segment_rl(&self, t: &mut DaeTangent, b: usize, womersley: bool, dr: f64, dl: f64) {
        let (nn, nb) = (self.circuit.nodes.len(), self.circuit.branches.len());
        if !womersley {
            t.df[self.branch_r[b]] += dr;
            t.de[nn + b] += dl;
            return;
        }
        let cells = self.cells_of.get(b).cloned().unwrap_or(0..0);
        let d = crate::womersley::cells_derivative(cells.len(), dr, dl);
        let r_cells: f64 = d.cells.iter().map(|c| c.0).sum();
        t.df[self.branch_r[b]] += d.resistance + r_cells;
        t.de[nn + b] += d.inductance;
        let row = nn + b;
        for (c, &(dr_k, dl_k)) in self.circuit.friction_cells[cells].iter().zip(&d.cells) {
            let x = nn + nb + c.extra;
            // −R_k on the branch row at i_k; −R_k at Q and +R_k at i_k on the cell's row
            for (r, col, sign) in [(row, x, -1.0), (x, row, -1.0), (x, x, 1.0)] {
                let k = self.f_entry(r, col);
                t.df[k] += sign * dr_k;
            }
            t.de[x] += dl_k;
        }
    }

    /// The index into `dae.f.val` of entry (row, col), which the pattern holds.
    fn f_entry(&self, row: usize, col: usize) -> usize {
        let f = &self.dae.f;
        f.row(row)
            .find(|&k| f.col[k] as usize == col)
            .expect("a friction cell's entries are in the flow matrix's pattern")
    }

    /// Branch `b`'s flat-profile inertance L₀ before its folded cells (its inductance
    /// without cells: `womersley` false).
    fn flat_inductance(&self, b: usize, womersley: bool) -> f64 {
        let l = self.circuit.branches[b].inductance;
        if !womersley {
            return l;
        }
        let kept = self.cells_of.get(b).map_or(0, |c| c.len());
        crate::womersley::flat_inductance(l, kept)
    }

    /// d/dS of a lumped vessel's stenosis coefficient split evenly over its segments' branches.
    fn vessel_stenosis(&self, t: &mut DaeTangent, name: &str) {
        let nn = self.circuit.nodes.len();
        let n = self.segments_of(name).count() as f64;
        for s in self.segments_of(name) {
            t.dstenosis.push((nn + s.branch, 1.0 / n));
        }
    }

    /// `scale.resistance` as the patch applies it: every resistance and RCR condition at a
    /// vessel end and every lumped vessel's resistance, multiplied (dR/ds = R at s = 1).
    fn resistance_scale(&self, t: &mut DaeTangent, spec: &NetworkSpec) {
        for (node, bc) in &spec.boundary_conditions {
            let labels: &[&str] = match bc {
                BoundarySpec::Resistance { .. } => &["resistance"],
                BoundarySpec::Rcr { .. } => &["proximal resistance", "distal resistance"],
                _ => &[],
            };
            for l in labels {
                if let Some(b) = self.branch_named(&format!("boundary condition '{node}' {l}")) {
                    t.df[self.branch_r[b]] += self.circuit.branches[b].resistance;
                }
            }
        }
        for v in spec.vessels.iter().filter(|v| v.lumped.is_some()) {
            let cells = friction_cells(spec, v);
            for s in self.segments_of(&v.name) {
                let r0 = self.circuit.branches[s.branch].resistance;
                self.segment_rl(t, s.branch, cells, r0, 0.0);
            }
            // an RCL vessel holds its R on a branch of its own (its segment's is the L)
            if let Some(b) = self.branch_named(&format!("vessel '{}' resistance", v.name)) {
                t.df[self.branch_r[b]] += self.circuit.branches[b].resistance;
            }
        }
    }
}
