//! The haemoglobin facilitation of Lévêque and Graetz walls in the oxygen sensitivities: the
//! wall's conductance carries E_Hb (docs/physics.md §3.4), which reads the wall PO2 and the
//! Hill law, so a wall's PO2 or concentration and P50 move the conductance by
//! d ln G/dθ = d ln E_Hb/dθ of the blood side's conductance G ∝ E_Hb
//! ([`crate::model::facilitation`]'s exact derivatives); behind a permeability in series,
//! g = 1/(1/G + 1/G_p) moves by d ln g = (1 − g/G_p) d ln G
//! (`Transport::add_conductance_slopes`). The given enhancement is the wall's enhancement
//! over E_Hb.

use crate::closure::{Facilitation, WallSpec};
use crate::hemoglobin::BindingSpec;
use crate::model::facilitation::{
    FactorDerivatives, Layer, hill_factor_derivatives, secant_factor_derivatives,
};
use crate::transport::SpeciesSpec;

/// What a facilitated wall's E_Hb is differentiated by.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum By {
    /// The wall PO2 (Pa).
    WallPo2,
    /// The wall concentration α P_w (mol/m³).
    WallConcentration,
    /// Hill's P50 (Pa).
    P50,
}

/// A Lévêque or Graetz wall's facilitation record and wall concentration (None for any
/// other wall, or one without facilitation).
fn facilitated(wall: &WallSpec) -> Option<(&Facilitation, f64)> {
    match wall {
        WallSpec::Leveque {
            facilitation: Some(f),
            wall_concentration,
            ..
        }
        | WallSpec::Graetz {
            facilitation: Some(f),
            wall_concentration,
            ..
        } => Some((f, *wall_concentration)),
        _ => None,
    }
}

/// The enhancement the wall was given: its enhancement over its facilitation factor.
pub(super) fn given_enhancement(wall: &WallSpec, enhancement: f64) -> f64 {
    facilitated(wall).map_or(enhancement, |(f, ..)| enhancement / f.factor)
}

/// E_Hb and its derivatives of a facilitated wall at the species' binding (SI: the layer in
/// Pa, so the derivatives are per Pa).
fn derivatives(
    sp: &SpeciesSpec,
    f: &Facilitation,
    wall_concentration: f64,
) -> Result<FactorDerivatives, String> {
    let (alpha, p50, n, capacity, secant) = match sp.binding {
        BindingSpec::Hill {
            solubility,
            p50,
            n,
            capacity,
        } => (solubility, p50, n, capacity, false),
        BindingSpec::Linearized {
            solubility,
            p50,
            n,
            capacity,
            ..
        } => (solubility, p50, n, capacity, true),
        _ => return Err("a facilitated wall needs haemoglobin (hemoglobin: hill)".into()),
    };
    let layer = Layer {
        alpha,
        d: sp.diffusivity,
        d_hb: f.d_hb,
        capacity,
        p50,
        n,
    };
    let (p_in, p_w) = (f.inlet_concentration / alpha, wall_concentration / alpha);
    let d = if secant {
        secant_factor_derivatives(p_in, p_w, &layer)
    } else {
        hill_factor_derivatives(p_in, p_w, &layer)
    };
    d.ok_or_else(|| {
        "the wall PO2 equals the inlet PO2: the facilitation factor has no derivative there \
         (no boundary layer)"
            .into()
    })
}

/// d ln G/dθ of `wall`'s blood-side conductance G ∝ E_Hb through its facilitation (None:
/// not facilitated; a permeability in series takes its share where the slope is applied);
/// refused by P50 with linearised haemoglobin (whose binding P50 also sets).
pub(super) fn ln_conductance_slope(
    sp: &SpeciesSpec,
    wall: &WallSpec,
    by: By,
) -> Result<Option<f64>, String> {
    let Some((f, cw)) = facilitated(wall) else {
        return Ok(None);
    };
    let d = derivatives(sp, f, cw)?;
    let alpha = match sp.binding {
        BindingSpec::Hill { solubility, .. } => solubility,
        BindingSpec::Linearized { solubility, .. } if by != By::P50 => solubility,
        _ => {
            return Err(
                "P50 of linearised haemoglobin (its binding and facilitation) is not \
                 differentiated"
                    .into(),
            );
        }
    };
    Ok(Some(match by {
        By::WallPo2 => d.d_wall_po2 / d.factor,
        By::WallConcentration => d.d_wall_po2 / (alpha * d.factor),
        By::P50 => d.d_p50 / d.factor,
    }))
}

/// d ln g/d P50 of every facilitated wall: (None: the section's wall, Some(vessel): that
/// vessel's own wall; the slope).
pub(super) fn p50_slopes(sp: &SpeciesSpec) -> Result<Vec<(Option<String>, f64)>, String> {
    let mut out = Vec::new();
    if let Some(a) = ln_conductance_slope(sp, &sp.wall, By::P50)? {
        out.push((None, a));
    }
    for (name, wall) in &sp.per_vessel {
        if let Some(a) = ln_conductance_slope(sp, wall, By::P50)
            .map_err(|why| format!("the wall of vessel '{name}': {why}"))?
        {
            out.push((Some(name.clone()), a));
        }
    }
    Ok(out)
}

/// Per vessel (circuit order): the summed d ln g/dθ of the `slopes` that apply to its wall
/// (the section's on every vessel without a wall of its own).
pub(super) fn per_vessel_slopes(
    slopes: &[(Option<String>, f64)],
    sp: &SpeciesSpec,
    vessel_names: &[String],
) -> Vec<f64> {
    vessel_names
        .iter()
        .map(|v| {
            slopes
                .iter()
                .filter(|(scope, _)| match scope {
                    Some(own) => own == v,
                    None => !sp.per_vessel.contains_key(v),
                })
                .map(|(_, a)| a)
                .sum()
        })
        .collect()
}
