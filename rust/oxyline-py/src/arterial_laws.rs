//! Binding of the core's arterial laws that the front end's model builders and importers use:
//! PWDB's wall law, geometry changes, inflow and Windkessels with their steady calibration
//! (`model::pwdb`), openBF's vessel laws (`model::openbf`), a vessel's thin-wall compliance,
//! and the replacement of terminal elements by structured trees
//! (`model::structured_tree::terminal`). A PWDB segment crosses as (inlet node, outlet node,
//! length, inlet radius, outlet radius).

use crate::errors::ModelError;
use crate::to_py;
use oxyline_core::model::pwdb::beds;
use oxyline_core::model::pwdb::wall::{self, SitePath};
use oxyline_core::model::pwdb::{DENSITY, Segment, geometry, inflow};
use oxyline_core::model::structured_tree::terminal::{self, End, Link};
use oxyline_core::model::structured_tree::{self as st, Stiffness};
use oxyline_core::model::{circulatory_autogen, openbf, sum};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyMapping};

/// A segment as it crosses: (inlet, outlet, length, radius_in, radius_out).
type SegmentRow = (usize, usize, f64, f64, f64);
/// A measurement path: (segments from the aortic root, site segment).
type PathRow = (Vec<usize>, usize);
/// A calibrated outlet: (terminal segment, R1, R2, C).
type OutletRow = (usize, f64, f64, f64);

fn segments(rows: Vec<SegmentRow>) -> Vec<Segment> {
    rows.into_iter()
        .map(|(inlet, outlet, length, radius_in, radius_out)| Segment {
            inlet,
            outlet,
            length,
            radius_in,
            radius_out,
        })
        .collect()
}

fn path(p: &PathRow) -> SitePath<'_> {
    SitePath {
        segments: &p.0,
        site: p.1,
    }
}

/// (wall thickness, Young's modulus) [m, Pa] of each segment of `subject`: h at the `base`
/// segment's mean radius, E from the wall law at the subject's.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_wall_properties(
    base: Vec<SegmentRow>,
    subject: Vec<SegmentRow>,
    k3_cgs: f64,
) -> Vec<(f64, f64)> {
    wall::wall_properties(&segments(base), &segments(subject), k3_cgs)
}

/// The wall-law k3 [g s⁻² cm⁻¹] whose cf-PWV along the two paths is `target` [m/s].
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (geometry, femoral, carotid, target, density = DENSITY))]
pub fn pwdb_fit_k3(
    geometry: Vec<SegmentRow>,
    femoral: PathRow,
    carotid: PathRow,
    target: f64,
    density: f64,
) -> PyResult<f64> {
    wall::fit_k3(
        &segments(geometry),
        path(&femoral),
        path(&carotid),
        target,
        density,
    )
    .map_err(to_py)
}

/// The calibrated terminal Windkessels of PWDB's vascular beds; returns ([(segment, R1, R2, C)] by segment, the calibration factor s) such that the steady
/// pressure at node `n<inlet>` is `target` [Pa] at inflow `inflow` [m³/s].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_outlets(
    py: Python<'_>,
    geometry: Vec<SegmentRow>,
    k3_cgs: f64,
    pvc: f64,
    inlet: usize,
    inflow: f64,
    target: f64,
) -> PyResult<(Vec<OutletRow>, f64)> {
    let geo = segments(geometry);
    let beds = beds::vascular_beds();
    py.detach(|| {
        let wks = beds::windkessels(&geo, &beds, k3_cgs, pvc)?;
        let walls = wall::wall_properties(&geo, &geo, k3_cgs);
        let s = beds::calibrate_scale(&geo, &walls, inlet, &wks, inflow, target)?;
        let mut out: Vec<OutletRow> = wks
            .iter()
            .map(|w| (w.segment, w.impedance, s * w.bed_resistance, w.capacitance))
            .collect();
        out.sort_by_key(|w| w.0);
        Ok((out, s))
    })
    .map_err(to_py)
}

fn rows(geo: &[Segment]) -> Vec<SegmentRow> {
    geo.iter()
        .map(|g| (g.inlet, g.outlet, g.length, g.radius_in, g.radius_out))
        .collect()
}

/// PWDB's geometry changes of a subject: large-artery radii × `dia`, proximal aortic
/// lengths × `length`.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_subject_geometry(base: Vec<SegmentRow>, dia: f64, length: f64) -> Vec<SegmentRow> {
    rows(&geometry::subject_geometry(&segments(base), dia, length))
}

/// The segments (from 1) whose radius PWDB's large-artery diameter changes.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_diameter_segments(base: Vec<SegmentRow>) -> Vec<usize> {
    geometry::diameter_segments(&segments(base))
        .into_iter()
        .collect()
}

/// Refuses a network whose terminal segments are not PWDB's vascular beds'.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_check_terminals(geometry: Vec<SegmentRow>) -> PyResult<()> {
    beds::check_terminals(&segments(geometry)).map_err(to_py)
}

/// The aortic root flow table (time [s], flow [m³/s]) of the template systole `q` for heart
/// rate `hr` [1/min], stroke volume `sv` [m³] and ejection time `lvet` [s].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn pwdb_aortic_inflow(
    q: Vec<f64>,
    hr: f64,
    sv: f64,
    lvet: f64,
) -> PyResult<(Vec<f64>, Vec<f64>)> {
    inflow::aortic_inflow(&q, hr, sv, lvet).map_err(to_py)
}

fn openbf_wall(
    length: f64,
    radius_in: f64,
    radius_out: f64,
    youngs_modulus: f64,
    wall_thickness: Option<f64>,
) -> openbf::Wall {
    openbf::Wall {
        length,
        radius: (radius_in, radius_out),
        youngs_modulus,
        wall_thickness,
    }
}

/// Characteristic impedance ρ c₀ / A₀ [Pa s/m³] at the outlet of an openBF vessel (R₀ from
/// `radius_in` to `radius_out`, h₀ = `wall_thickness` or openBF's ADAN law).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn openbf_characteristic_impedance(
    length: f64,
    radius_in: f64,
    radius_out: f64,
    youngs_modulus: f64,
    wall_thickness: Option<f64>,
    density: f64,
) -> f64 {
    openbf_wall(
        length,
        radius_in,
        radius_out,
        youngs_modulus,
        wall_thickness,
    )
    .characteristic_impedance(density)
}

/// Kelvin–Voigt wall viscosity η [Pa s] of openBF's visco-elastic wall on that vessel.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn openbf_wall_viscosity(
    length: f64,
    radius_in: f64,
    radius_out: f64,
    youngs_modulus: f64,
    wall_thickness: Option<f64>,
) -> f64 {
    openbf_wall(
        length,
        radius_in,
        radius_out,
        youngs_modulus,
        wall_thickness,
    )
    .kelvin_voigt_viscosity()
}

/// The linear model's (r_in, r_out, compliance-equivalent wall thickness) of an openBF
/// vessel at end pressures `p_in` → `p_out` (external pressure `pext`), or None and the
/// lowest pressure checked when the tube law collapses the vessel there.
#[oxyline_py_guard::guard]
#[pyfunction]
#[allow(clippy::too_many_arguments)]
pub fn openbf_linearised(
    length: f64,
    radius_in: f64,
    radius_out: f64,
    youngs_modulus: f64,
    wall_thickness: Option<f64>,
    pext: f64,
    p_in: f64,
    p_out: f64,
) -> (Option<(f64, f64, f64)>, f64) {
    match openbf_wall(
        length,
        radius_in,
        radius_out,
        youngs_modulus,
        wall_thickness,
    )
    .linearised(p_in, p_out, pext)
    {
        Ok(v) => (Some(v), f64::NAN),
        Err(p) => (None, p),
    }
}

/// The model viscosity [Pa s] of openBF's friction with velocity profile `gamma_profile`.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn openbf_friction_viscosity(viscosity: f64, gamma_profile: f64) -> f64 {
    openbf::friction_viscosity(viscosity, gamma_profile)
}

/// The distal radius [m] openBF v2 uses along a tapered vessel (its importer's
/// `taper="openbf"`): Rp + (Rd − Rp) L / (max(M, 5, ⌈L mm⌉) − 1), `m` the file's `M`.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn openbf_taper_distal_radius(rp: f64, rd: f64, length: f64, m: f64) -> f64 {
    openbf::taper_quirk_distal_radius(rp, rd, length, m)
}

/// A table's mean over its span, np.trapezoid(values, time) / (time[-1] − time[0]) in
/// numpy's summation order (an inflow table's cycle mean).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn cycle_mean(time: Vec<f64>, values: Vec<f64>) -> PyResult<f64> {
    same_length(&time, &values)?;
    Ok(sum::cycle_mean(&time, &values))
}

/// circulatory_autogen's inflow `flow` [m³/s] scaled so that its cycle mean over `time` is
/// `cardiac_output` [m³/s].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn circulatory_autogen_inflow(
    time: Vec<f64>,
    flow: Vec<f64>,
    cardiac_output: f64,
) -> PyResult<Vec<f64>> {
    same_length(&time, &flow)?;
    Ok(circulatory_autogen::inflow_at_cardiac_output(
        &time,
        &flow,
        cardiac_output,
    ))
}

/// The Young's modulus [Pa] of circulatory_autogen's wall law C = 2π r³ l/(E h) that gives a
/// vessel (`radius`, `length`, `thickness` [m]) the capacitance `capacitance` [m³/Pa].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn circulatory_autogen_youngs_modulus(
    radius: f64,
    length: f64,
    capacitance: f64,
    thickness: f64,
) -> f64 {
    circulatory_autogen::youngs_modulus_of_capacitance(radius, length, capacitance, thickness)
}

fn same_length(time: &[f64], values: &[f64]) -> PyResult<()> {
    if time.len() < 2 || time.len() != values.len() {
        return Err(ModelError::new_err(format!(
            "a table needs two or more times and one value per time, got {} times and {} \
             values",
            time.len(),
            values.len()
        )));
    }
    Ok(())
}

/// Wall thickness [m] of openBF's ADAN law at each lumen radius [m].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn openbf_wall_thickness(radii: Vec<f64>) -> Vec<f64> {
    radii.into_iter().map(openbf::adan_wall_thickness).collect()
}

/// Wall thickness [m] of the exponential law h = r (a e^(b r) + c e^(d r)) at `radius` [m].
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn wall_thickness_law(radius: f64, a: f64, b: f64, c: f64, d: f64) -> f64 {
    oxyline_core::segment::wall_thickness_law(radius, [a, b, c, d])
}

/// Thin-wall compliance [m³/Pa] of a uniform vessel (SI).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn thin_wall_compliance(
    radius: f64,
    length: f64,
    youngs_modulus: f64,
    wall_thickness: f64,
    poisson_ratio: f64,
) -> f64 {
    oxyline_core::segment::thin_wall_compliance(
        radius,
        length,
        youngs_modulus,
        wall_thickness,
        poisson_ratio,
    )
}

/// The condition at a node of a terminal compartment (None: no condition).
fn end(bc: Option<Bound<'_, PyAny>>) -> End {
    let Some(bc) = bc else {
        return End::Open;
    };
    let text = || End::Other(bc.repr().map_or_else(|_| "?".into(), |r| r.to_string()));
    let Ok(map) = bc.cast::<PyMapping>() else {
        return text();
    };
    let get = |k: &str| map.get_item(k).ok();
    let kind = get("type").and_then(|t| t.extract::<String>().ok());
    let value = get("value");
    match kind.as_deref() {
        Some("flow") if value.as_ref().and_then(|v| v.extract::<f64>().ok()) == Some(0.0) => {
            End::ZeroFlow
        }
        Some("pressure") => match value {
            None => End::Pressure(0.0),
            Some(v) => v.extract::<f64>().map_or_else(|_| text(), End::Pressure),
        },
        _ => text(),
    }
}

/// The lumped terminal compartment that starts with vessel `first` of the native `vessels`
/// list, under the native `conditions`: (its vessels, its nodes, steady resistance [Pa s/m³],
/// outlet pressure [Pa]).
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn terminal_compartment(
    first: &str,
    vessels: &Bound<'_, PyList>,
    conditions: &Bound<'_, PyDict>,
) -> PyResult<(Vec<String>, Vec<String>, f64, f64)> {
    let text = |d: &Bound<'_, PyAny>, k: &str| -> PyResult<String> {
        Ok(d.get_item(k)?.str()?.to_string())
    };
    let mut links = Vec::with_capacity(vessels.len());
    for v in vessels.iter() {
        let lumped = v
            .get_item("lumped")
            .ok()
            .filter(|l| l.cast::<PyMapping>().is_ok());
        let lumped_resistance = match lumped {
            None => None,
            Some(l) => Some(match l.get_item("resistance") {
                Ok(r) => r.extract::<f64>()?,
                Err(_) => 0.0,
            }),
        };
        links.push(Link {
            name: text(&v, "name")?,
            from: text(&v, "from")?,
            to: text(&v, "to")?,
            lumped_resistance,
        });
    }
    let ends = |node: &str| end(conditions.get_item(node).ok().flatten());
    let c = terminal::compartment(first, &links, &ends).map_err(to_py)?;
    Ok((
        c.vessels.into_iter().collect(),
        c.nodes.into_iter().collect(),
        c.resistance,
        c.pressure,
    ))
}

/// Murray's law: the root radius [m] of terminal `name` from its share of its parent's
/// steady flow.
#[oxyline_py_guard::guard]
#[pyfunction]
pub fn murray_radius(
    name: &str,
    parent: &str,
    parent_radius: f64,
    flow: f64,
    parent_flow: f64,
) -> PyResult<f64> {
    terminal::murray_radius(name, parent, parent_radius, flow, parent_flow).map_err(to_py)
}

/// The structured-tree root vessel of radius `root_radius` [m] replacing terminal `name`:
/// (length, Young's modulus, wall thickness, segments or None, steady resistance), SI.
#[oxyline_py_guard::guard]
#[pyfunction]
#[pyo3(signature = (name, root_radius, length_ratio, stiffness, max_length, viscosity))]
pub fn structured_tree_root(
    name: &str,
    root_radius: &Bound<'_, PyAny>,
    length_ratio: f64,
    stiffness: &Bound<'_, PyAny>,
    max_length: Option<f64>,
    viscosity: f64,
) -> PyResult<(f64, f64, f64, Option<usize>, f64)> {
    let number = (root_radius.is_instance_of::<PyFloat>() || root_radius.is_instance_of::<PyInt>())
        && !root_radius.is_instance_of::<PyBool>();
    let r0 = if number {
        root_radius.extract::<f64>()?
    } else {
        let shown = root_radius
            .repr()
            .map_or_else(|_| "?".into(), |r| r.to_string());
        return Err(to_py(oxyline_core::Error::model(
            st::element(name),
            format!("'root radius' must be in (0, inf), got {shown}"),
        )));
    };
    let law: Option<Stiffness> = crate::trees::stiffness(name, stiffness)?;
    let r =
        terminal::root_vessel(name, r0, length_ratio, law, max_length, viscosity).map_err(to_py)?;
    Ok((
        r.length,
        r.youngs_modulus,
        r.wall_thickness,
        r.segments,
        r.resistance,
    ))
}
