//! Wall-exchange closures (docs/physics.md §3). Every closure is written per flow segment as
//!
//!   W = G (c − c_w) + q        (mol/s out of the blood; c = free concentration of the cell)
//!
//! with a conductance G (m³/s) and a fixed flux q (mol/s). G is constant (mass transfer,
//! permeability), depends on a cycle-mean |Q| fixed before the run (Lévêque, Graetz: the
//! concentration boundary layer adapts over many beats, §3.1 "Pulsatility"), or on the
//! instantaneous |Q| of the segment's branch (Lévêque, `shear: instantaneous`), or on a shear
//! that relaxes towards it on the boundary layer's time scale (`shear: relaxed`).

use crate::error::{Error, Result};
use serde::Deserialize;
use std::f64::consts::PI;

pub mod renewal;

/// Γ(4/3).
pub const GAMMA_4_3: f64 = 0.892_979_511_569_249_2;
/// Fully developed Graetz Sherwood number, constant wall concentration (OEIS A282581).
pub const SH_GRAETZ: f64 = 3.656_793_457_763_292;

#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Shear {
    /// Wall shear from the segment's cycle-mean |Q| of the periodic flow (two-pass run).
    #[default]
    CycleMean,
    /// Quasi-steady: wall shear from the instantaneous |Q| (floored at the Graetz value).
    Instantaneous,
    /// The boundary layer's shear γ̃ relaxes to the instantaneous |γ_w| on the layer's own
    /// time scale, dγ̃/dt = (|γ_w| − γ̃)/τ_BL (docs/physics.md §3.1 "Pulsatility"), from the cycle-mean
    /// value; see `relaxation_time`.
    Relaxed,
}

/// Which cycle mean of the segment flow drives a cycle-mean closure (docs/physics.md §3.7).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq, Eq, Default)]
#[serde(rename_all = "kebab-case")]
pub enum MeanFlow {
    /// ⟨|Q|⟩: forward and backward flow alike renew the boundary layer.
    CycleMean,
    /// ⟨max(±Q, 0)⟩ in the direction of the net flow: backflow returns fluid whose near-wall
    /// layer is already depleted, so only forward flow renews the layer. Equal to ⟨|Q|⟩
    /// without reversal; within 2 % of the 2-D solution with 10–30 % reversal, where ⟨|Q|⟩
    /// overestimates the uptake by up to 10 % (docs/validation-oxygen.md §6). The default
    /// before the inlet-renewal fit.
    ForwardMean,
    /// The Graetz law of the net mean flow |⟨Q⟩| plus the inlet renewal by the near-wall
    /// backward excursion of the Womersley profile (`renewal`, docs/physics.md §3.6), capped
    /// by complete renewal every period: within 2 % of the outlet-independent 2-D reference in
    /// the 47 rows of docs/validation-oxygen.md §13. Needs the vessel's flow harmonics
    /// (two-pass run; without them it reads the forward mean).
    #[default]
    InletRenewal,
}

/// A prescribed wall flux (mol m⁻² s⁻¹, positive out of the blood): one value, one value per
/// segment of the vessel (from its inlet), or a time table of either (linear in time,
/// repeating with its own length like the inlet tables).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(untagged)]
pub enum FluxSpec {
    Constant(f64),
    PerSegment(Vec<f64>),
    Table {
        time: Vec<f64>,
        /// Per table time: one value (uniform) or one per segment.
        values: Vec<Vec<f64>>,
    },
}

#[derive(Debug, Clone, Deserialize, PartialEq, Default)]
#[serde(tag = "model", rename_all = "kebab-case", deny_unknown_fields)]
pub enum WallSpec {
    /// C0: no exchange.
    #[default]
    None,
    /// C1: prescribed flux per lumen area (mol m⁻² s⁻¹, positive out of the blood), constant,
    /// per segment and/or tabulated in time (docs/physics.md §3.1).
    Flux { flux: FluxSpec },
    /// C3: constant mass-transfer coefficient k (m/s) against the wall concentration c_w.
    MassTransfer {
        k: f64,
        wall_concentration: f64,
        #[serde(default)]
        permeability: Option<f64>,
    },
    /// C5s: Lévêque developing boundary layer, integrated over each segment, x from the vessel inlet.
    Leveque {
        wall_concentration: f64,
        #[serde(default)]
        shear: Shear,
        /// Multiplier on k (Hb facilitation E_Hb of §3.4, Dean-flow enhancement, ...).
        #[serde(default = "one")]
        enhancement: f64,
        #[serde(default)]
        permeability: Option<f64>,
        /// The facilitation E_Hb included in `enhancement` (None: none).
        #[serde(default)]
        facilitation: Option<Facilitation>,
    },
    /// C6: exact Graetz series (Poiseuille, constant c_w) with a cycle-mean flow (`flow`:
    /// the forward-flow mean by default, docs/physics.md §3.6).
    Graetz {
        wall_concentration: f64,
        #[serde(default)]
        flow: MeanFlow,
        #[serde(default = "one")]
        enhancement: f64,
        #[serde(default)]
        permeability: Option<f64>,
        /// The facilitation E_Hb included in `enhancement` (None: none).
        #[serde(default)]
        facilitation: Option<Facilitation>,
        /// Blood kinematic viscosity μ/ρ (m²/s) for the Womersley numbers of the inlet renewal
        /// (the Python layer passes the model's blood; default the default blood's).
        #[serde(default = "default_kinematic_viscosity")]
        kinematic_viscosity: f64,
    },
    /// Wall-limited exchange q = P_w (c − c_t) with a fixed tissue concentration c_t.
    Permeability {
        permeability: f64,
        tissue_concentration: f64,
    },
}

/// The haemoglobin facilitation factor E_Hb (docs/physics.md §3.4) that a Lévêque or Graetz
/// wall's `enhancement` includes, with what it was computed from besides the species'
/// binding, diffusivity and the wall concentration: the oxygen sensitivities differentiate it
/// (`model::facilitation`).
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Facilitation {
    /// E_Hb (a factor of the wall's `enhancement`).
    pub factor: f64,
    /// The free concentration α P_in of the inlet PO2 the factor was taken at (mol/m³).
    pub inlet_concentration: f64,
    /// Oxyhaemoglobin diffusivity D_Hb (m²/s).
    pub d_hb: f64,
}

fn one() -> f64 {
    1.0
}
/// μ/ρ of the default blood (3.5 mPa s, 1050 kg/m³; `model::BloodSpec`).
fn default_kinematic_viscosity() -> f64 {
    3.5e-3 / 1050.0
}

/// Geometry of one flow segment as seen by a closure.
#[derive(Debug, Clone, Copy)]
pub struct SegmentWall {
    /// Mean lumen radius (m).
    pub radius: f64,
    /// Distance of the segment's ends from the vessel inlet (m).
    pub x0: f64,
    pub x1: f64,
}

impl SegmentWall {
    pub fn area(&self) -> f64 {
        2.0 * PI * self.radius * (self.x1 - self.x0)
    }
}

/// A closure evaluated for one segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SegmentLaw {
    /// W = g (c − cw) + q.
    Fixed { g: f64, cw: f64, q: f64 },
    /// Lévêque with a time-dependent shear: g = max(coef |Q|^{1/3}, floor), then in series
    /// with the wall permeability conductance `gp` (∞ if none). The transport passes |Q|: the
    /// instantaneous branch flow, or the relaxed equivalent flow Q̃ = π r³ γ̃/4.
    Instantaneous {
        coef: f64,
        floor: f64,
        gp: f64,
        cw: f64,
    },
}

fn series(g_blood: f64, gp: f64) -> f64 {
    if gp.is_infinite() {
        g_blood
    } else if g_blood <= 0.0 {
        0.0
    } else {
        1.0 / (1.0 / g_blood + 1.0 / gp)
    }
}

/// Local Sherwood number of the Lévêque layer at a constant wall flux over that at a constant
/// wall concentration, Γ(4/3)/F(0) with F'' = 3η(F − ηF'), F'(0) = −1, F(∞) = 0 (the
/// constant-flux similarity solution; `tests/test_tissue.py` re-derives it with scipy).
pub const LEVEQUE_FLUX_RATIO: f64 = 1.209_199_576;

/// Conjugate correction of a developing-layer conductance `g` (Lévêque, Graetz; derived for a
/// constant wall concentration) when the wall behind it sets its own interface concentration
/// through a conductance `g_wall` to a fixed value (docs/physics.md §3.7 "Conjugate closure").
/// The interface condition lies between the two exact limits of the thin layer: a wall that
/// conducts much better than the layer holds the interface concentration (g_wall → ∞: the
/// closure as derived), a wall that conducts much worse fixes the flux whatever the layer does
/// (g_wall → 0: the constant-flux layer, `LEVEQUE_FLUX_RATIO` × g). In between, the factor is
/// interpolated with the wall's share of the series resistance, ψ = g/(g + g_wall):
/// g_conj = g (1 + (LEVEQUE_FLUX_RATIO − 1) ψ). `g_wall` = ∞ leaves `g` unchanged (bit for bit).
pub fn conjugate_conductance(g: f64, g_wall: f64) -> f64 {
    if g <= 0.0 || g_wall.is_infinite() {
        return g;
    }
    g * (1.0 + (LEVEQUE_FLUX_RATIO - 1.0) * g / (g + g_wall))
}

/// Lévêque coefficient: ∫_seg k 2πr dx = coef · |Q|^{1/3} (docs/physics.md §3.1 C5s), with
/// a = (γ D²/9)^{1/3}/Γ(4/3), γ = 4|Q|/(π r³).
pub fn leveque_coef(seg: &SegmentWall, d: f64) -> f64 {
    let r = seg.radius;
    let a_per_q = (4.0 / (PI * r.powi(3)) * d * d / 9.0).cbrt() / GAMMA_4_3;
    2.0 * PI * r * 1.5 * a_per_q * (seg.x1.powf(2.0 / 3.0) - seg.x0.powf(2.0 / 3.0))
}

/// Boundary-layer relaxation time of a segment, τ_BL = δ²/D with the Lévêque thickness
/// δ = Γ(4/3) (9 D x/γ̄)^{1/3} (= D/k) at the segment mid-point x, γ̄ = 4 q_mean/(π r³) the
/// cycle-mean wall shear (docs/physics.md §3.1 "Pulsatility"). Infinite without mean flow (the layer
/// then never adapts: γ̃ keeps its initial value).
pub fn relaxation_time(seg: &SegmentWall, d: f64, q_mean: f64) -> f64 {
    let gamma = 4.0 * q_mean.abs() / (PI * seg.radius.powi(3));
    let x = 0.5 * (seg.x0 + seg.x1);
    let defined = gamma > 0.0 && d > 0.0; // false for NaN too
    if !defined {
        return f64::INFINITY;
    }
    let delta = GAMMA_4_3 * (9.0 * d * x / gamma).cbrt();
    delta * delta / d
}

/// Graetz mixed-cup θ_m(x*) (Poiseuille, constant c_w), exact at every x* (≤ 1e-7 of the
/// deficit; `crate::graetz`).
pub fn graetz_theta(xs: f64) -> f64 {
    crate::graetz::mixed_cup(xs)
}

/// Segment conductance of the Graetz closure for a steady flow |Q|: the 1-D model with the
/// local k integrated over the segment, ∫ k 2πr dx = |Q| (ln θ(x*_0) − ln θ(x*_1)),
/// x* = x/(d Pe) = π D x/(4|Q|).
pub fn graetz_conductance(seg: &SegmentWall, d: f64, q_abs: f64) -> f64 {
    if q_abs <= 0.0 {
        // no flow: fully developed transfer
        return SH_GRAETZ * d / (2.0 * seg.radius) * seg.area();
    }
    let xs = |x: f64| PI * d * x / (4.0 * q_abs);
    q_abs * (graetz_theta(xs(seg.x0)).ln() - graetz_theta(xs(seg.x1)).ln())
}

/// The derivatives of [`graetz_conductance`] by |Q| and by the logarithm of the segment's
/// distances from the inlet (x0, x1 ∝ the vessel's length), (∂G/∂|Q|, ∂G/∂ln x): with
/// φ = ln θ_m and x* = π D x/(4|Q|), G = |Q| (φ(x*_0) − φ(x*_1)), so ∂G/∂ln x =
/// |Q| (x*_0 φ′(x*_0) − x*_1 φ′(x*_1)) and |Q| ∂G/∂|Q| = G − ∂G/∂ln x (G is homogeneous of
/// degree one in |Q| and x). The radius does not enter (nor without flow, where
/// G = Sh π D Δx).
pub fn graetz_conductance_slopes(seg: &SegmentWall, d: f64, q_abs: f64) -> (f64, f64) {
    if q_abs <= 0.0 {
        return (0.0, graetz_conductance(seg, d, q_abs));
    }
    let xs = |x: f64| PI * d * x / (4.0 * q_abs);
    let (a0, a1) = (xs(seg.x0), xs(seg.x1));
    let slope = |a: f64| a * crate::graetz::log_mixed_cup_slope(a);
    let by_length = q_abs * (slope(a0) - slope(a1));
    let g = graetz_conductance(seg, d, q_abs);
    ((g - by_length) / q_abs, by_length)
}

/// The derivatives of a cycle-mean wall law's conductance g (a `Fixed` law of
/// [`WallSpec::segment_law_scaled`]) by the mean flow it reads and by the logarithms of the
/// segment's radius and of its distances from the vessel inlet (a vessel's radius and
/// length move them in proportion).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct LawSlopes {
    pub mean_flow: f64,
    pub ln_radius: f64,
    pub ln_length: f64,
    /// By the logarithm of the inlet renewal's factor (Graetz walls; 0 for the others).
    pub ln_renewal: f64,
}

/// `v` if it is a finite number > 0 (or >= 0 with `allow_zero`), else a model error naming
/// the element, what the value is (e.g. "wall k", "tissue wall thickness") and the value. The
/// one check of the wall numbers of every closure and of the tissue wall.
pub(crate) fn finite_number(element: &str, what: &str, v: f64, allow_zero: bool) -> Result<f64> {
    let ok = v.is_finite() && (v > 0.0 || (allow_zero && v == 0.0));
    if ok {
        Ok(v)
    } else {
        Err(Error::model(
            element,
            format!(
                "{what} must be a finite number {} 0, got {v}",
                if allow_zero { ">=" } else { ">" }
            ),
        ))
    }
}

fn check(element: &str, key: &str, v: f64, allow_zero: bool) -> Result<()> {
    finite_number(element, &format!("wall {key}"), v, allow_zero).map(|_| ())
}

impl WallSpec {
    pub fn needs_mean_flow(&self) -> bool {
        matches!(
            self,
            WallSpec::Graetz { .. }
                | WallSpec::Leveque {
                    shear: Shear::CycleMean | Shear::Relaxed,
                    ..
                }
        )
    }

    /// Lévêque with `shear: relaxed`: the transport carries γ̃ as extra state.
    pub fn is_relaxed(&self) -> bool {
        matches!(
            self,
            WallSpec::Leveque {
                shear: Shear::Relaxed,
                ..
            }
        )
    }

    pub fn validate(&self, element: &str) -> Result<()> {
        let perm = |p: &Option<f64>| p.map_or(Ok(()), |p| check(element, "permeability", p, false));
        match self {
            WallSpec::None => Ok(()),
            WallSpec::Flux { flux } => flux.validate(element),
            WallSpec::MassTransfer {
                k,
                wall_concentration,
                permeability,
            } => {
                check(element, "k", *k, true)?;
                check(element, "wall_concentration", *wall_concentration, true)?;
                perm(permeability)
            }
            WallSpec::Leveque {
                wall_concentration,
                enhancement,
                permeability,
                facilitation,
                ..
            }
            | WallSpec::Graetz {
                wall_concentration,
                enhancement,
                permeability,
                facilitation,
                ..
            } => {
                if let Some(f) = facilitation {
                    check(element, "facilitation factor", f.factor, false)?;
                    check(element, "facilitation inlet", f.inlet_concentration, true)?;
                    check(element, "facilitation d_hb", f.d_hb, true)?;
                }
                if let WallSpec::Graetz {
                    kinematic_viscosity,
                    ..
                } = self
                {
                    check(element, "kinematic_viscosity", *kinematic_viscosity, false)?;
                }
                check(element, "wall_concentration", *wall_concentration, true)?;
                check(element, "enhancement", *enhancement, true)?;
                perm(permeability)
            }
            WallSpec::Permeability {
                permeability,
                tissue_concentration,
            } => {
                check(element, "permeability", *permeability, true)?;
                check(element, "tissue_concentration", *tissue_concentration, true)
            }
        }
    }

    /// The cycle mean of the flow this wall's closure reads (see [`MeanFlow`]).
    pub fn mean_flow(&self) -> MeanFlow {
        match self {
            WallSpec::Graetz { flow, .. } => *flow,
            _ => MeanFlow::CycleMean,
        }
    }

    /// The law of one segment, `index` its position in its vessel (from the inlet). `d` is
    /// the species diffusivity, `q_mean` the segment's cycle-mean flow of the kind
    /// [`WallSpec::mean_flow`] asks for (only read by closures that need it). A time table of
    /// `flux` gives no fixed flux here: the transport applies it at every step.
    pub fn segment_law(
        &self,
        seg: &SegmentWall,
        index: usize,
        d: f64,
        q_mean: f64,
        element: &str,
    ) -> Result<SegmentLaw> {
        self.segment_law_scaled(seg, index, d, q_mean, 1.0, element)
    }

    /// [`WallSpec::segment_law`] with the Graetz conductance multiplied by `renewal` (before
    /// the permeability in series): the inlet renewal's factor over the law of `q_mean`
    /// (`renewal::segment_factors`); other closures ignore it.
    pub fn segment_law_scaled(
        &self,
        seg: &SegmentWall,
        index: usize,
        d: f64,
        q_mean: f64,
        renewal: f64,
        element: &str,
    ) -> Result<SegmentLaw> {
        let s = seg.area();
        let gp = |p: &Option<f64>| p.map_or(f64::INFINITY, |p| p * s);
        let need_d = || {
            if d.is_finite() && d > 0.0 {
                Ok(())
            } else {
                Err(Error::model(
                    element,
                    format!("this wall model needs the species diffusivity > 0, got {d}"),
                ))
            }
        };
        Ok(match self {
            WallSpec::None => SegmentLaw::Fixed {
                g: 0.0,
                cw: 0.0,
                q: 0.0,
            },
            WallSpec::Flux { flux } => SegmentLaw::Fixed {
                g: 0.0,
                cw: 0.0,
                q: flux.fixed(index) * s,
            },
            WallSpec::MassTransfer {
                k,
                wall_concentration,
                permeability,
            } => SegmentLaw::Fixed {
                g: series(k * s, gp(permeability)),
                cw: *wall_concentration,
                q: 0.0,
            },
            WallSpec::Permeability {
                permeability,
                tissue_concentration,
            } => SegmentLaw::Fixed {
                g: permeability * s,
                cw: *tissue_concentration,
                q: 0.0,
            },
            WallSpec::Leveque {
                wall_concentration,
                shear,
                enhancement,
                permeability,
                ..
            } => {
                need_d()?;
                let (gp, cw) = (gp(permeability), *wall_concentration);
                leveque_law(seg, d, q_mean, *shear, *enhancement, gp, cw)
            }
            WallSpec::Graetz {
                wall_concentration,
                enhancement,
                permeability,
                ..
            } => {
                need_d()?;
                SegmentLaw::Fixed {
                    g: series(
                        enhancement * renewal * graetz_conductance(seg, d, q_mean),
                        gp(permeability),
                    ),
                    cw: *wall_concentration,
                    q: 0.0,
                }
            }
        })
    }
}

impl WallSpec {
    /// The permeability in series with the blood side's conductance (mass-transfer, Lévêque
    /// and Graetz walls; None for the others or without one).
    pub fn series_permeability(&self) -> Option<f64> {
        match self {
            WallSpec::MassTransfer { permeability, .. }
            | WallSpec::Leveque { permeability, .. }
            | WallSpec::Graetz { permeability, .. } => *permeability,
            _ => None,
        }
    }

    /// d ln g/d ln G of a segment's conductance g = 1/(1/G + 1/G_p) by its blood side's G
    /// (G_p = P × the wall area `area`): g/G = 1 − g/G_p, 1 without a permeability in series.
    /// A factor of G (its coefficient k or enhancement, a facilitation E_Hb) moves g by
    /// this share of its own relative change.
    pub fn blood_side_share(&self, g: f64, area: f64) -> f64 {
        match self.series_permeability() {
            Some(p) if p * area > 0.0 => 1.0 - g / (p * area),
            _ => 1.0,
        }
    }
}

impl WallSpec {
    /// [`LawSlopes`] of the law [`WallSpec::segment_law_scaled`] gives a cycle-mean Lévêque
    /// or a Graetz wall at the same arguments (the inlet renewal's factor `renewal` held;
    /// its own derivative is `renewal::tangent`'s, taken by `ln_renewal`). None for every
    /// other wall, whose coefficients are proportional to the wall area 2π r Δx.
    pub fn mean_flow_law_slopes(
        &self,
        seg: &SegmentWall,
        d: f64,
        q_mean: f64,
        renewal: f64,
    ) -> Option<LawSlopes> {
        // the blood side's conductance and its slopes, then the permeability in series
        let (g, blood, permeability) = match self {
            WallSpec::Leveque {
                shear: Shear::CycleMean,
                enhancement,
                permeability,
                ..
            } => {
                let coef = enhancement * leveque_coef(seg, d);
                let floor = enhancement * SH_GRAETZ * d / (2.0 * seg.radius) * seg.area();
                let g = coef * q_mean.cbrt();
                // coef ∝ (x1^{2/3} − x0^{2/3}) and free of r; the floor ∝ Δx
                if g > floor {
                    let s = LawSlopes {
                        mean_flow: g / (3.0 * q_mean),
                        ln_length: 2.0 * g / 3.0,
                        ..LawSlopes::default()
                    };
                    (g, s, permeability)
                } else {
                    let s = LawSlopes {
                        ln_length: floor,
                        ..LawSlopes::default()
                    };
                    (floor, s, permeability)
                }
            }
            WallSpec::Graetz {
                enhancement,
                permeability,
                ..
            } => {
                let f = enhancement * renewal;
                let (dq, dl) = graetz_conductance_slopes(seg, d, q_mean);
                let g = f * graetz_conductance(seg, d, q_mean);
                let s = LawSlopes {
                    mean_flow: f * dq,
                    ln_radius: 0.0,
                    ln_length: f * dl,
                    ln_renewal: g,
                };
                (g, s, permeability)
            }
            _ => return None,
        };
        let Some(p) = permeability else {
            return Some(blood);
        };
        // g = 1/(1/G + 1/G_p), G_p = P 2π r Δx: dg = (g/G)² dG + (g/G_p)² dG_p
        let gp = p * seg.area();
        let total = series(g, gp);
        let (a, b) = if g > 0.0 {
            ((total / g).powi(2), (total / gp).powi(2) * gp)
        } else {
            (0.0, 0.0)
        };
        Some(LawSlopes {
            mean_flow: a * blood.mean_flow,
            ln_radius: a * blood.ln_radius + b,
            ln_length: a * blood.ln_length + b,
            ln_renewal: a * blood.ln_renewal,
        })
    }
}

impl FluxSpec {
    fn validate(&self, element: &str) -> Result<()> {
        let bad = |msg: String| Err(Error::model(element, msg));
        let values: Vec<f64> = match self {
            FluxSpec::Constant(v) => vec![*v],
            FluxSpec::PerSegment(v) if v.is_empty() => {
                return bad("wall flux per segment needs at least one value".into());
            }
            FluxSpec::PerSegment(v) => v.clone(),
            FluxSpec::Table { time, values } => {
                if time.len() < 2 || time.len() != values.len() {
                    return bad(format!(
                        "wall flux table needs >= 2 times and one row per time, got {} times \
                         and {} rows",
                        time.len(),
                        values.len()
                    ));
                }
                let increasing = |k: &usize| time[*k] > time[*k - 1] && time[*k].is_finite();
                if let Some(k) = (1..time.len()).find(|k| !increasing(k)) {
                    return bad(format!(
                        "wall flux table times must be finite and strictly increasing, got \
                         {} then {}",
                        time[k - 1],
                        time[k]
                    ));
                }
                let w = values[0].len();
                if w == 0 || values.iter().any(|r| r.len() != w) {
                    return bad("wall flux table rows must all have the same length >= 1 \
                                (one value, or one per segment)"
                        .into());
                }
                values.iter().flatten().copied().collect()
            }
        };
        match values.iter().find(|v| !v.is_finite()) {
            Some(v) => bad(format!("wall flux must be finite, got {v}")),
            None => Ok(()),
        }
    }

    /// Number of values per time (1: uniform along the vessel).
    pub fn width(&self) -> usize {
        match self {
            FluxSpec::Constant(_) => 1,
            FluxSpec::PerSegment(v) => v.len(),
            FluxSpec::Table { values, .. } => values[0].len(),
        }
    }

    /// The table's times and rows, if the flux varies in time.
    pub fn table(&self) -> Option<(&[f64], &[Vec<f64>])> {
        match self {
            FluxSpec::Table { time, values } => Some((time, values)),
            _ => None,
        }
    }

    /// Column of segment `index` in a row of `width()` values.
    pub fn column(&self, index: usize) -> usize {
        if self.width() == 1 { 0 } else { index }
    }

    /// The time-independent flux of segment `index` (0 for a table).
    fn fixed(&self, index: usize) -> f64 {
        match self {
            FluxSpec::Constant(v) => *v,
            FluxSpec::PerSegment(v) => v[self.column(index)],
            FluxSpec::Table { .. } => 0.0,
        }
    }
}

/// The Lévêque law of one segment (C5s): cycle-mean shear gives a fixed conductance, the
/// time-dependent shears the coefficient of |Q|^{1/3} and the Graetz floor.
fn leveque_law(
    seg: &SegmentWall,
    d: f64,
    q_mean: f64,
    shear: Shear,
    enhancement: f64,
    gp: f64,
    cw: f64,
) -> SegmentLaw {
    let coef = enhancement * leveque_coef(seg, d);
    // C4 floor: Sh = 3.66 (the boundary layer cannot be thicker than the lumen)
    let floor = enhancement * SH_GRAETZ * d / (2.0 * seg.radius) * seg.area();
    match shear {
        Shear::CycleMean => SegmentLaw::Fixed {
            g: series((coef * q_mean.cbrt()).max(floor), gp),
            cw,
            q: 0.0,
        },
        Shear::Instantaneous | Shear::Relaxed => SegmentLaw::Instantaneous {
            coef,
            floor,
            gp,
            cw,
        },
    }
}

impl SegmentLaw {
    /// (g, cw, q) at the current segment flow.
    #[inline]
    pub fn eval(&self, q_branch: f64) -> (f64, f64, f64) {
        self.eval_cbrt(q_branch.abs().cbrt())
    }

    /// (g, cw, q) given |Q|^{1/3}: the cube root is the costly part, so callers with several
    /// laws per segment (refined cells) take it once per segment.
    #[inline]
    pub fn eval_cbrt(&self, q_cbrt: f64) -> (f64, f64, f64) {
        match *self {
            SegmentLaw::Fixed { g, cw, q } => (g, cw, q),
            SegmentLaw::Instantaneous {
                coef,
                floor,
                gp,
                cw,
            } => (series((coef * q_cbrt).max(floor), gp), cw, 0.0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn graetz_mixed_cup_matches_physics_6c() {
        for (x, th) in [
            (0.005, 0.8362189),
            (0.01, 0.7511057),
            (0.02, 0.6280276),
            (0.05, 0.3952988),
            (0.1, 0.1897101),
            (0.001, 0.9403184),
            (0.002, 0.9073636),
        ] {
            assert!(
                (graetz_theta(x) - th).abs() < 6e-8,
                "θ({x}) = {}",
                graetz_theta(x)
            );
        }
    }

    /// (c1): the C6 closure as the local k of the 1-D model, θ_i = θ_{i−1}/(1 + β_i).
    #[test]
    fn graetz_closure_in_the_cell_balance_converges_c1() {
        let cases = [
            (
                0.05,
                [(10, 0.4131916), (50, 0.3991931), (200, 0.3963061)],
                0.3952988,
            ),
            (
                0.01,
                [(10, 0.7546276), (50, 0.7518648), (200, 0.7513019)],
                0.7511057,
            ),
        ];
        for (xl, rows, exact) in cases {
            let mut errs = Vec::new();
            for (n, expected) in rows {
                let mut theta = 1.0;
                for i in 0..n {
                    let (a, b) = (xl * i as f64 / n as f64, xl * (i + 1) as f64 / n as f64);
                    let beta = graetz_theta(a).ln() - graetz_theta(b).ln();
                    theta /= 1.0 + beta;
                }
                assert!((theta - expected).abs() < 1e-7, "x*={xl} N={n}: {theta}");
                errs.push((theta - exact, n));
            }
            // first order: error × N roughly constant
            let (e0, n0) = errs[0];
            let (e2, n2) = errs[2];
            let ratio = (e0 * n0 as f64) / (e2 * n2 as f64);
            assert!(
                (0.8..1.25).contains(&ratio),
                "first-order constant ratio {ratio}"
            );
        }
    }

    /// docs/physics.md §3.7: `flux` as one value, per segment, or a time table; bad tables
    /// are model errors naming the element.
    #[test]
    fn flux_spec_forms_and_errors() {
        let parse = |j: &str| serde_json::from_str::<WallSpec>(j).unwrap();
        let seg = SegmentWall {
            radius: 1e-3,
            x0: 0.0,
            x1: 0.01,
        };
        let q = |w: &WallSpec, k| match w.segment_law(&seg, k, 1e-9, 0.0, "v").unwrap() {
            SegmentLaw::Fixed { q, .. } => q,
            _ => f64::NAN,
        };
        let uniform = parse(r#"{"model": "flux", "flux": 2.0}"#);
        let per_seg = parse(r#"{"model": "flux", "flux": [1.0, 3.0]}"#);
        assert_eq!(q(&uniform, 1), 2.0 * seg.area());
        assert_eq!(q(&per_seg, 1), 3.0 * seg.area());
        let table = parse(r#"{"model": "flux", "flux": {"time": [0, 1], "values": [[1], [2]]}}"#);
        assert_eq!(q(&table, 0), 0.0); // applied by the transport at every step
        assert!(table.validate("v").is_ok());
        for bad in [
            r#"{"model": "flux", "flux": {"time": [0, 0], "values": [[1], [2]]}}"#,
            r#"{"model": "flux", "flux": {"time": [0, 1], "values": [[1], [2, 3]]}}"#,
            r#"{"model": "flux", "flux": {"time": [0], "values": [[1]]}}"#,
            r#"{"model": "flux", "flux": []}"#,
        ] {
            let e = parse(bad).validate("vessel 'v'").unwrap_err().to_string();
            assert!(e.contains("vessel 'v'") && e.contains("flux"), "{e}");
        }
        // the Graetz closure uses the inlet renewal unless told otherwise (the
        // forward mean before, still selectable by name)
        let g = parse(r#"{"model": "graetz", "wall_concentration": 1.0}"#);
        assert_eq!(g.mean_flow(), MeanFlow::InletRenewal);
        let g = parse(r#"{"model": "graetz", "wall_concentration": 1.0, "flow": "forward-mean"}"#);
        assert_eq!(g.mean_flow(), MeanFlow::ForwardMean);
        let g = parse(r#"{"model": "graetz", "wall_concentration": 1.0, "flow": "cycle-mean"}"#);
        assert_eq!(g.mean_flow(), MeanFlow::CycleMean);
    }

    #[test]
    fn graetz_conductance_uses_x_star() {
        // segment [0, L] of a tube with x*_L = 0.05: β = −ln θ_m(0.05)
        let (d, q, r) = (1.2e-9, 1e-6, 1e-3);
        let l = 0.05 * 4.0 * q / (PI * d);
        let seg = SegmentWall {
            radius: r,
            x0: 0.0,
            x1: l,
        };
        let g = graetz_conductance(&seg, d, q);
        assert!((g / q - (-(0.3952988f64).ln())).abs() < 1e-6);
    }

    /// docs/physics.md §3.5: τ_BL at mid-length ≈ 52 s (aorta), 3.0 s (coronary), 7.6 s (CCA).
    #[test]
    fn boundary_layer_relaxation_time_matches_physics_3_5() {
        let d = 1.2e-9;
        for (r, l, q, tau) in [
            (8e-3, 0.2, 2e-5, 52.0),
            (1.5e-3, 9.0 * 3.84e-3, 1.6e-6, 3.0),
            (3e-3, 10.0 * 6.45e-3, 6e-6, 7.6),
        ] {
            // a segment centred at mid-length
            let seg = SegmentWall {
                radius: r,
                x0: 0.25 * l,
                x1: 0.75 * l,
            };
            let t = relaxation_time(&seg, d, q);
            assert!((t / tau - 1.0).abs() < 0.03, "τ = {t} vs {tau}");
        }
        let seg = SegmentWall {
            radius: 1e-3,
            x0: 0.0,
            x1: 0.01,
        };
        assert!(relaxation_time(&seg, d, 0.0).is_infinite());
    }

    #[test]
    fn leveque_segments_sum_to_the_whole_vessel_c4() {
        let (d, q, r, l, n): (f64, f64, f64, f64, usize) = (1.2e-9, 2e-5, 8e-3, 0.2, 10);
        let whole = leveque_coef(
            &SegmentWall {
                radius: r,
                x0: 0.0,
                x1: l,
            },
            d,
        );
        let sum: f64 = (0..n)
            .map(|i| {
                leveque_coef(
                    &SegmentWall {
                        radius: r,
                        x0: l * i as f64 / n as f64,
                        x1: l * (i + 1) as f64 / n as f64,
                    },
                    d,
                )
            })
            .sum();
        assert!((sum / whole - 1.0).abs() < 1e-14);
        // docs/physics.md §3.5: aorta segment-integrated k̄_1 = 1.235e-5 m/s, k̄_10 = 3.89e-6 m/s
        let dx = l / n as f64;
        let k1 = leveque_coef(
            &SegmentWall {
                radius: r,
                x0: 0.0,
                x1: dx,
            },
            d,
        ) * q.cbrt()
            / (2.0 * PI * r * dx);
        let k10 = leveque_coef(
            &SegmentWall {
                radius: r,
                x0: l - dx,
                x1: l,
            },
            d,
        ) * q.cbrt()
            / (2.0 * PI * r * dx);
        assert!((k1 / 1.235e-5 - 1.0).abs() < 2e-3, "{k1}");
        assert!((k10 / 3.89e-6 - 1.0).abs() < 2e-3, "{k10}");
        // mean Sherwood 1.6150982 (Pe d/L)^{1/3}
        let pe = q / (PI * r * r) * 2.0 * r / d;
        let k_mean = whole * q.cbrt() / (2.0 * PI * r * l);
        let sh = k_mean * 2.0 * r / d;
        assert!((sh / (1.6150982 * (pe * 2.0 * r / l).cbrt()) - 1.0).abs() < 1e-6);
    }

    /// The cycle-mean laws' slopes against central differences of the law itself (by the
    /// mean flow, and by the radius and the distances from the inlet scaled together), for
    /// a Graetz wall in both of its series' ranges and a Lévêque wall above and at its
    /// floor, with and without a permeability in series. Relative step 1e-5: the quotient's
    /// truncation and rounding are ~1e-9 of the slope.
    #[test]
    fn cycle_mean_law_slopes_against_central_differences() {
        let d = 1.5e-9;
        let g_of = |w: &WallSpec, seg: &SegmentWall, q: f64| match w
            .segment_law(seg, 1, d, q, "v")
            .unwrap()
        {
            SegmentLaw::Fixed { g, .. } => g,
            _ => f64::NAN,
        };
        let graetz = |p: Option<f64>| WallSpec::Graetz {
            wall_concentration: 0.05,
            flow: MeanFlow::ForwardMean,
            enhancement: 3.0,
            permeability: p,
            facilitation: None,
            kinematic_viscosity: 3.3e-6,
        };
        let leveque = |p: Option<f64>| WallSpec::Leveque {
            wall_concentration: 0.05,
            shear: Shear::CycleMean,
            enhancement: 3.0,
            permeability: p,
            facilitation: None,
        };
        let h = 1e-5;
        // (wall, x1 = segment end, q): x* = π D x/(4q) from 1e-6 (series) to 0.05 (eigen)
        let cases = [
            (graetz(None), 0.05, 3e-6),
            (graetz(Some(2e-5)), 0.05, 3e-6),
            (graetz(None), 0.2, 5e-9),
            (leveque(None), 0.05, 3e-6),
            (leveque(Some(2e-5)), 0.05, 3e-6),
            (leveque(None), 0.05, 1e-16),
        ];
        for (wall, x1, q) in cases {
            let seg = |r: f64, l: f64| SegmentWall {
                radius: 2e-3 * r,
                x0: 0.5 * x1 * l,
                x1: x1 * l,
            };
            let s = wall
                .mean_flow_law_slopes(&seg(1.0, 1.0), d, q, 1.0)
                .unwrap();
            let fd_q = (g_of(&wall, &seg(1.0, 1.0), q * (1.0 + h))
                - g_of(&wall, &seg(1.0, 1.0), q * (1.0 - h)))
                / (2.0 * h * q);
            let fd_r = (g_of(&wall, &seg(1.0 + h, 1.0), q) - g_of(&wall, &seg(1.0 - h, 1.0), q))
                / (2.0 * h);
            let fd_l = (g_of(&wall, &seg(1.0, 1.0 + h), q) - g_of(&wall, &seg(1.0, 1.0 - h), q))
                / (2.0 * h);
            let g = g_of(&wall, &seg(1.0, 1.0), q);
            for (name, exact, fd, scale) in [
                ("q", s.mean_flow, fd_q, g / q),
                ("ln r", s.ln_radius, fd_r, g),
                ("ln L", s.ln_length, fd_l, g),
            ] {
                let e = (exact - fd).abs() / scale;
                assert!(
                    e < 1e-7,
                    "{wall:?} x1 {x1} q {q}: {name} {exact:e} vs {fd:e} ({e:e})"
                );
            }
        }
        // every other wall follows the wall area
        let mt = WallSpec::MassTransfer {
            k: 1e-4,
            wall_concentration: 0.05,
            permeability: None,
        };
        assert!(
            mt.mean_flow_law_slopes(
                &SegmentWall {
                    radius: 1e-3,
                    x0: 0.0,
                    x1: 0.01
                },
                d,
                1e-6,
                1.0
            )
            .is_none()
        );
    }
}
