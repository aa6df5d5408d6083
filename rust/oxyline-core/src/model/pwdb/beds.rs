//! PWDB's terminal Windkessels: each vascular bed's resistance and compliance shared among
//! its terminal segments by outlet area, R1 = the segment's characteristic impedance, and the
//! one factor on the beds' resistances that gives the subject's mean aortic root pressure,
//! found on the network's steady circuit (the core's steady solve of the assembled model).

use super::wall::wave_speed;
use super::{DENSITY, ELEMENT, MMHG, OUTFLOW_PRESSURE, POISSON_RATIO, Segment, VISCOSITY};
use crate::error::{Error, Result};
use crate::model::structured_tree::fmt_g;
use crate::model::{BloodSpec, BoundarySpec, GeometrySpec, NetworkSpec, VesselSpec};
use crate::waveform::WaveformSpec;
use std::collections::{BTreeMap, BTreeSet};

/// A vascular bed: its terminal segments (numbers from 1), resistance [Pa s/m³] and
/// compliance [m³/Pa].
#[derive(Debug, Clone)]
pub struct Bed {
    pub segments: Vec<usize>,
    pub resistance: f64,
    pub compliance: f64,
}

/// PWDB's 16 vascular beds: name, terminal segments, R [mmHg s/mL], C [mL/mmHg]
/// (`add_wk_vascular_bed_parameters` / `calc_outflow` of PWDB, segment lists verbatim).
pub const VASCULAR_BEDS: [(&str, &[usize], f64, f64); 16] = [
    (
        "brain",
        &[62, 63, 69, 70, 72, 73, 74, 76, 93, 95],
        6.9040,
        0.021726,
    ),
    (
        "face_neck",
        &[78, 80, 82, 84, 86, 88, 89, 90, 91, 92],
        20.755,
        0.026499,
    ),
    (
        "right_shoulder_arm",
        &[10, 102, 103, 104, 105],
        16.852,
        0.032637,
    ),
    (
        "left_shoulder_arm",
        &[24, 112, 113, 114, 115],
        16.852,
        0.032637,
    ),
    ("chest", &[26], 10.824, 0.050811),
    ("right_kidney", &[36], 8.368, 0.065727),
    ("left_kidney", &[38], 8.368, 0.065727),
    ("liver", &[32], 21.252, 0.02606),
    ("spleen", &[33], 27.832, 0.019761),
    ("stomach", &[31], 54.084, 0.010169),
    ("intestines", &[34, 40], 10.374, 0.053018),
    ("pelvis", &[45, 51], 26.119, 0.021057),
    ("right_upper_leg", &[53], 32.29, 0.017033),
    ("left_upper_leg", &[47], 32.29, 0.017033),
    ("right_lower_leg", &[54, 55], 14.786, 0.037197),
    ("left_lower_leg", &[48, 49], 14.824, 0.037102),
];

/// PWDB's vascular beds in SI: R [mmHg s/mL] → [Pa s/m³], C [mL/mmHg] → [m³/Pa].
pub fn vascular_beds() -> Vec<Bed> {
    VASCULAR_BEDS
        .iter()
        .map(|&(_name, segments, r, c)| Bed {
            segments: segments.to_vec(),
            resistance: r * MMHG * 1e6,
            compliance: c / MMHG / 1e6,
        })
        .collect()
}

/// Refuses a network whose terminal segments (outlet node feeding no segment and ending no
/// other) are not exactly the vascular beds' segments, naming the ones that differ.
pub fn check_terminals(geo: &[Segment]) -> Result<()> {
    let inlets: BTreeSet<usize> = geo.iter().map(|g| g.inlet).collect();
    let free: BTreeSet<usize> = (1..=geo.len())
        .filter(|&s| {
            let out = geo[s - 1].outlet;
            !inlets.contains(&out) && geo.iter().filter(|h| h.outlet == out).count() == 1
        })
        .collect();
    let beds: BTreeSet<usize> = VASCULAR_BEDS
        .iter()
        .flat_map(|b| b.1.iter().copied())
        .collect();
    let odd: Vec<usize> = free.symmetric_difference(&beds).copied().collect();
    if odd.is_empty() {
        return Ok(());
    }
    Err(Error::model(
        ELEMENT,
        format!("terminal segments {odd:?} do not match the vascular beds"),
    ))
}

/// One terminal segment's Windkessel before calibration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Windkessel {
    /// The terminal segment (from 1).
    pub segment: usize,
    /// Characteristic impedance ρ c(r) / (π r²) at the outlet radius r: R1.
    pub impedance: f64,
    /// The bed's resistance over the segment's area share: R2 before the calibration factor.
    pub bed_resistance: f64,
    /// The bed's compliance × the area share × the peripheral compliance factor.
    pub capacitance: f64,
}

/// The segment `s` (from 1) of `geo`.
fn segment(geo: &[Segment], s: usize) -> Result<&Segment> {
    s.checked_sub(1).and_then(|i| geo.get(i)).ok_or_else(|| {
        Error::model(
            ELEMENT,
            format!("segment {s} is not in the network's {} segments", geo.len()),
        )
    })
}

/// The Windkessel of every terminal segment of `beds` (in the beds' order), with the wall law
/// of `k3_cgs` and the peripheral compliance factor `pvc`: each bed shared by outlet area
/// π r_out².
pub fn windkessels(
    geo: &[Segment],
    beds: &[Bed],
    k3_cgs: f64,
    pvc: f64,
) -> Result<Vec<Windkessel>> {
    let pi = std::f64::consts::PI;
    let mut out = Vec::new();
    for bed in beds {
        let mut areas = Vec::with_capacity(bed.segments.len());
        for &s in &bed.segments {
            areas.push(pi * segment(geo, s)?.radius_out.powi(2));
        }
        let total: f64 = areas.iter().fold(0.0, |a, b| a + b);
        for (&s, area) in bed.segments.iter().zip(&areas) {
            let share = area / total;
            let r = segment(geo, s)?.radius_out;
            out.push(Windkessel {
                segment: s,
                impedance: DENSITY * wave_speed(r, k3_cgs, DENSITY) / (pi * r * r),
                bed_resistance: bed.resistance / share,
                capacitance: pvc * bed.compliance * share,
            });
        }
    }
    Ok(out)
}

/// The network's steady circuit (SI): the segments with the wall law's wall (which a steady
/// state does not see), constant inflow `inflow` at node `n<inlet>`, each terminal segment
/// ending in its resistance to the outflow pressure (an RCR at steady state).
fn steady_network(
    geo: &[Segment],
    walls: &[(f64, f64)],
    inlet: usize,
    terminals: &[(usize, f64)],
    inflow: f64,
) -> Result<NetworkSpec> {
    let node = |i: usize| format!("n{i}");
    let vessels = geo
        .iter()
        .zip(walls)
        .enumerate()
        .map(|(i, (g, &(h, e)))| {
            let mut v = VesselSpec::blank();
            v.name = format!("segment {}", i + 1);
            v.from = node(g.inlet);
            v.to = node(g.outlet);
            // a steady state sees each vessel's total resistance only: one segment is exact
            v.segments = Some(1);
            v.geometry = Some(GeometrySpec {
                length: g.length,
                radius_in: g.radius_in,
                radius_out: g.radius_out,
                wall_thickness: Some(h),
                youngs_modulus: Some(e),
                poisson_ratio: POISSON_RATIO,
                wall_viscosity: 0.0,
            });
            v
        })
        .collect();
    let constant = |value: f64| WaveformSpec::Constant { value };
    let mut bcs = BTreeMap::new();
    bcs.insert(
        node(inlet),
        BoundarySpec::Flow {
            flow: constant(inflow),
        },
    );
    for &(s, resistance) in terminals {
        bcs.insert(
            node(segment(geo, s)?.outlet),
            BoundarySpec::Resistance {
                resistance,
                pressure: Some(constant(OUTFLOW_PRESSURE)),
            },
        );
    }
    Ok(NetworkSpec {
        name: "pwdb-steady".into(),
        blood: BloodSpec {
            density: DENSITY,
            viscosity: VISCOSITY,
        },
        arrangement: None,
        wall_model: Default::default(),
        inertance_profile: Default::default(),
        wall_friction: Default::default(),
        max_segment_length: None,
        segments_auto: false,
        segmentation_rtol: None,
        vessels,
        boundary_conditions: bcs,
        output_segments: true,
        transport: None,
        max_memory: None,
    })
}

/// The steady (= cycle-mean, the circuit being linear) pressure [Pa] at node `n<inlet>` of
/// the steady circuit of [`steady_network`]: the core's exact steady state.
pub fn inlet_mean_pressure(
    geo: &[Segment],
    walls: &[(f64, f64)],
    inlet: usize,
    terminals: &[(usize, f64)],
    inflow: f64,
) -> Result<f64> {
    let spec = steady_network(geo, walls, inlet, terminals, inflow)?;
    let assembled = spec.assemble()?;
    let dae = assembled.circuit.assemble()?;
    let y = crate::integrate::steady::steady_state(&dae)?;
    let name = format!("n{inlet}");
    (0..assembled.summary.nodes)
        .find(|&i| assembled.circuit.names.node(i) == name)
        .map(|i| y[i])
        .ok_or_else(|| Error::model(ELEMENT, format!("no node '{name}'")))
}

/// The factor s for which terminal resistances R1 + s R_bed (each Windkessel's) make the
/// steady aortic root pressure (node `n<inlet>`) equal `target` [Pa] at inflow `inflow`:
/// secant iteration on P(s), increasing and nearly linear, to 1e-10 relative, from the
/// estimate that ignores the arteries.
pub fn calibrate_scale(
    geo: &[Segment],
    walls: &[(f64, f64)],
    inlet: usize,
    wks: &[Windkessel],
    inflow: f64,
    target: f64,
) -> Result<f64> {
    let mut order: Vec<&Windkessel> = wks.iter().collect();
    order.sort_by_key(|w| w.segment);
    let f = |s: f64| -> Result<f64> {
        let r: Vec<(usize, f64)> = order
            .iter()
            .map(|w| (w.segment, w.impedance + s * w.bed_resistance))
            .collect();
        Ok(inlet_mean_pressure(geo, walls, inlet, &r, inflow)? - target)
    };
    let conductance = wks.iter().fold(0.0, |a, w| a + 1.0 / w.bed_resistance);
    let mut s0 = (target - OUTFLOW_PRESSURE) / inflow * conductance;
    let mut s1 = 0.95 * s0;
    let mut f0 = f(s0)?;
    let mut f1 = f(s1)?;
    let mut converged = false;
    for _ in 0..50 {
        if f1.abs() < 1e-10 * target {
            converged = true;
            break;
        }
        let next = s1 - f1 * (s1 - s0) / (f1 - f0);
        (s0, s1, f0) = (s1, next, f1);
        f1 = f(s1)?;
    }
    if !converged {
        return Err(Error::model(
            ELEMENT,
            format!(
                "terminal resistance calibration to {} Pa did not converge",
                fmt_g(target)
            ),
        ));
    }
    if s1 <= 0.0 {
        return Err(Error::model(
            ELEMENT,
            format!(
                "mean pressure {} mmHg is out of reach: below the outflow pressure plus the \
                 drop across the arteries and R1",
                fmt_g(target / super::MMHG)
            ),
        ));
    }
    Ok(s1)
}
