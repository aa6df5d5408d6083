"""Virtual populations: PWDB-like subjects of the built-in ``pwdb-116`` network.

:func:`pwdb_like` reproduces the design of the Pulse Wave DataBase (Charlton et al. 2019, Am J
Physiol Heart Circ Physiol 317:H1062): per age decade, a full factorial of six parameters -
heart rate, stroke volume, ejection time (LVET), arterial stiffness (carotid-femoral PWV),
large-artery diameter and mean pressure (set through the peripheral resistance) - at the
age-specific mean and mean +- SD (``levels=3``: 3^6 = 729 subjects per age, 4,374 for six ages;
``levels=5`` adds +-0.5 SD). The age-specific means and SDs are recomputed from the literature
data PWDB's ``calculate_pwdb_input_parameters.m`` uses, by the same fits; every value and its
source is listed in ``docs/populations.md``.

Each subject is a patch in the native model format for ``oxyline.simulate_ensemble``
(vessels by name, boundary conditions by node; the inflow table is replaced whole):

>>> import oxyline
>>> from oxyline import populations
>>> table = populations.parameters()            # 4,374 subjects; pwdb_like() gives the patches
>>> len(table)
4374
>>> patch = populations.subject_patch(table.loc[0])
>>> res = oxyline.simulate(populations.patched("pwdb-116", patch), cycles=2)
>>> summary = populations.subject_summary(res)
>>> 60 < summary["aortic_root_dbp"] < summary["aortic_root_sbp"] < 160
True
"""

from __future__ import annotations

import copy
import itertools
import math
from collections.abc import Mapping, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from oxyline import _core, catalogue, pwdb
from oxyline.catalogue import shipped_data
from oxyline.ensemble import apply_patch
from oxyline.errors import ModelError

MODEL = "pwdb-116"
#: the six varied parameters, in the order of the factorial (the last varies fastest)
VARIED = ("hr", "sv", "lvet", "pwv", "dia", "mbp")
BASELINE_AGE = 25
LVET_MEAN, LVET_SD = 282.0, 282.0 * 24.43 / 295.29   # ms: Mynard 2015 mean, Gerstenblith SD ratio
#: Student t quantile t(1 - 0.3173/2, 19): Matlab ``predict(..., 'Alpha', 0.3173)`` (one SD)
#: for the 22-point LVET regression (3 coefficients); checked against scipy in the tests
T_ONE_SD_19 = 1.0270403026558605
Z90, Z80 = 1.6448536269514722, 1.2815515655446004   # norminv(0.95), norminv(0.9)

#: the oxygen section of ``base_model(oxygen=True)`` (the transmission-line paper's
#: carotid set-up: dissolved O2, Leveque wall at 55.5 mmHg, inlet 85.3 mmHg); makes
#: :func:`subject_summary` report ``ica_po2`` (about 3x the CPU time of the flow-only run)
OXYGEN = {"inlet": {"po2": 85.3}, "hemoglobin": "none", "solubility": 1.40e-3,
          "diffusivity": 1.2e-9, "wall": {"model": "leveque", "po2": 55.5, "shear": "cycle-mean"},
          "reference_pressure": 80.0}


# ------------------------------------------------------------- fits of the literature data


def pchip(x: Sequence[float], y: Sequence[float], xq: Any) -> np.ndarray:
    """Shape-preserving piecewise cubic Hermite interpolation with Matlab's ``pchip`` end
    slopes, extrapolating with the end cubics (as PWDB's ``interp1(..., 'pchip', 'extrap')``)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    h, delta = np.diff(x), np.diff(y) / np.diff(x)
    d = np.zeros_like(y)
    for k in range(1, len(x) - 1):
        if delta[k - 1] * delta[k] > 0:
            w1, w2 = 2 * h[k] + h[k - 1], h[k] + 2 * h[k - 1]
            d[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k])

    def end(h0: float, h1: float, d0: float, d1: float) -> float:
        s = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
        if np.sign(s) != np.sign(d0):
            return 0.0
        if np.sign(d0) != np.sign(d1) and abs(s) > abs(3 * d0):
            return 3 * d0
        return s

    d[0] = end(h[0], h[1], delta[0], delta[1])
    d[-1] = end(h[-1], h[-2], delta[-1], delta[-2])
    xq = np.asarray(xq, float)
    k = np.clip(np.searchsorted(x, xq, side="right") - 1, 0, len(x) - 2)
    t = (xq - x[k]) / h[k]
    h00, h10 = (1 + 2 * t) * (1 - t) ** 2, t * (1 - t) ** 2
    h01, h11 = t * t * (3 - 2 * t), t * t * (t - 1)
    return h00 * y[k] + h10 * h[k] * d[k] + h01 * y[k + 1] + h11 * h[k] * d[k + 1]


def _poly1(x: Sequence[float], y: Sequence[float], xq: float) -> float:
    p = np.polyfit(np.asarray(x, float), np.asarray(y, float), 1)
    return float(np.polyval(p, xq))


def _pooled_sd(means: Sequence[float], sds: Sequence[float], ns: Sequence[int]) -> float:
    n = sum(ns)
    m = sum(mi * ni for mi, ni in zip(means, ns, strict=True)) / n
    ss = sum(s * s * (k - 1) + k * (mi - m) ** 2 for mi, s, k in zip(means, sds, ns, strict=True))
    return math.sqrt(ss / (n - 1))


#: the literature data of the age-dependent inputs (``models_data/pwdb-inputs.yaml``)
_INPUTS = shipped_data("pwdb-inputs.yaml")
_HICKSON = _INPUTS["hickson2010"]
#: aortic diameters [mm] read off Hickson 2010 Fig. 4 by PWDB (ascending, descending thoracic,
#: abdominal) and carotid diameters of Hansen 1995 (ages 14..71)
_DIA = {"asc": 10 + 25 * np.array(_HICKSON["ascending"]) / 47,
        "desc_thor": 10 + 25 * np.array(_HICKSON["descending_thoracic"]) / 108,
        "abd": 10 + 25 * np.array(_HICKSON["abdominal"]) / 108}
_CAROTID = (_INPUTS["hansen1995"]["ages"], _INPUTS["hansen1995"]["diameter"])
_DIA_SD_RATIO = float(np.mean([sd / m for sd, m in _INPUTS["agmon2003"]]))  # Agmon 2003


def _dia_percent(age: float) -> float:
    vals = [_poly1(_HICKSON["ages"], v, age) / _poly1(_HICKSON["ages"], v, BASELINE_AGE)
            for v in _DIA.values()]
    vals.append(_poly1(*_CAROTID, age) / _poly1(*_CAROTID, BASELINE_AGE))
    return 100.0 * float(np.mean(vals))


def age_statistics(age: float) -> dict[str, tuple[float, float]]:
    """Mean and SD at ``age`` (25-75 y) of PWDB's age-dependent inputs: ``hr`` [1/min], ``sv``
    [mL], ``mbp`` [mmHg], ``dia`` [% of the 25-y diameter], ``len`` (proximal aortic length,
    ratio to 25 y; SD unused), ``pvc`` (peripheral compliance, ratio to 25 y; SD unused)."""
    if not BASELINE_AGE <= age <= 75:
        raise ModelError(f"age {age}: PWDB's parameters cover 25-75 years")
    ages = np.arange(20, 81)
    sv_u, sv_l = 102.35 - 0.3856 * ages, 42.94 - 0.1193 * ages        # Poppe 2015, 90 % range
    yashin = 66 + 12 * (np.array(_INPUTS["yashin"]) - 5) / 94
    mce_ages, mbp = np.arange(15.5, 86, 10), _MCENIERY["characteristics"]["brachial_map"]
    hickson, petersen = _INPUTS["hickson2010"], _INPUTS["petersen2017"]
    pvc = (0.113 - 0.001 * age) / (0.113 - 0.001 * BASELINE_AGE)       # McVeigh 1999
    dia = _dia_percent(age)
    return {
        "hr": (float(pchip(np.arange(32.5, 93, 5), yashin, age)),
               _pooled_sd(petersen["mean"], petersen["sd"], petersen["n"])),
        "sv": (_poly1(ages, (sv_u + sv_l) / 2, age), _poly1(ages, (sv_u - sv_l) / (2 * Z90), age)),
        # McEniery 2005, men
        "mbp": (float(pchip(mce_ages, mbp["men_mean"], age)), _poly1(mce_ages, mbp["men_sd"], age)),
        "dia": (dia, _DIA_SD_RATIO * dia),
        "len": (_poly1(hickson["ages"], hickson["length"], age)
                / _poly1(hickson["ages"], hickson["length"], BASELINE_AGE), 0.0),
        "pvc": (pvc, 0.0),
    }


# Weissler 1961: heart rate [1/min], stroke volume [mL], LVET [ms] of 22 subjects
_WEISSLER = np.array(_INPUTS["weissler1961"], float)


def lvet_values(hr: np.ndarray, sv: np.ndarray, z: np.ndarray) -> np.ndarray:
    """PWDB's LVET [ms] for subjects of one age: the Weissler regression LVET ~ 1 + HR + SV at
    each subject's HR and SV, plus z times its one-SD confidence half-width, then normalised to
    mean 282 ms and SD 23.3 ms over the subjects given (sample SD)."""
    X = np.column_stack([np.ones(len(_WEISSLER)), _WEISSLER[:, :2]])
    coef, res, *_ = np.linalg.lstsq(X, _WEISSLER[:, 2], rcond=None)
    mse = float(res[0]) / (len(X) - X.shape[1])
    x0 = np.column_stack([np.ones(len(hr)), hr, sv])
    half = T_ONE_SD_19 * np.sqrt(mse * np.einsum("ij,jk,ik->i", x0, np.linalg.inv(X.T @ X), x0))
    v = x0 @ coef + z * half
    v = LVET_MEAN * v / v.mean()
    if len(v) > 1 and v.std(ddof=1) > 0:
        v = v.mean() + LVET_SD * (v - v.mean()) / v.std(ddof=1)
    return v


# Mattace-Raso 2010 (Reference Values for Arterial Stiffness' Collaboration) Table 6:
# cf-PWV = A age + B age^2 + C per blood-pressure category, and Table 5 percentiles (10/50/90)
_MR = _INPUTS["mattace_raso2010"]
_MR_SBP, _MR_DBP = _MR["sbp"], _MR["dbp"]


def _extend(v: Sequence[float]) -> np.ndarray:
    """PWDB's extension of the 5 BP categories: 5 below (linear through categories 1-2) and 3
    above (through categories 4-5)."""
    v = np.asarray(v, float)
    low = v[0] + (np.arange(-4, 1) - 1) * (v[1] - v[0])
    high = v[-2] + (np.arange(3, 6) - 1) * (v[-1] - v[-2])
    return np.concatenate([low, v, high])


@lru_cache(maxsize=4096)
def cf_pwv(age: float, mbp: float, z: float) -> float:
    """PWDB's target carotid-femoral PWV [m/s] at ``age``, mean pressure ``mbp`` [mmHg] and
    ``z`` SDs (asymmetric SDs from the 10th/90th percentiles; ages between decades interpolate
    the percentile rows linearly, an extension of PWDB, which has decades only)."""
    sbp, dbp = _extend(_MR_SBP), _extend(_MR_DBP)
    mbps = dbp + 0.4 * (sbp - dbp)
    a = round(age)
    pwv = _extend(_MR["a"]) * a + _extend(_MR["b"]) * a * a + _extend(_MR["c"])
    ind = float(np.interp(mbp, mbps, np.arange(1, 14)))   # = PWDB's extrapolate + clip
    v = float(np.interp(ind, np.arange(1, 14), pwv))
    p10, p50, p90 = (np.asarray(_MR[t], float) for t in ("p10", "p50", "p90"))
    row = np.clip((age - 25) / 10, 0, 5)
    lo_i, w = int(min(math.floor(row), 4)), row - min(math.floor(row), 4)
    lower = 100 / Z80 * ((p50 - p10) / p50)
    upper = 100 / Z80 * ((p90 - p50) / p50)
    grid = np.concatenate([[0.0], _MR_DBP + 0.4 * (np.asarray(_MR_SBP) - _MR_DBP), [500.0]])

    def perc(tab: np.ndarray) -> float:
        r = (1 - w) * tab[lo_i] + w * tab[lo_i + 1]
        return float(np.interp(mbp, grid, np.concatenate([[r[0]], r, [r[-1]]])))

    return v * (1 + z * (perc(upper) if z >= 0 else perc(lower)) / 100)


# ------------------------------------------------------------- the population


def levels_sd(levels: int) -> np.ndarray:
    """The SD multiples of ``levels`` points: ``linspace(-1, 1, levels)`` (PWDB's rule), e.g.
    3 -> (-1, 0, 1), 5 -> (-1, -0.5, 0, 0.5, 1)."""
    if not isinstance(levels, int) or levels < 1 or levels % 2 == 0:
        raise ModelError(f"levels must be an odd integer >= 1 (the mean is a level), got "
                         f"{levels!r}")
    return np.linspace(-1.0, 1.0, levels) if levels > 1 else np.zeros(1)


def parameters(ages: Sequence[float] = (25, 35, 45, 55, 65, 75), levels: int = 3) -> Any:
    """The subjects' input parameters as a pandas DataFrame, one row per subject: ``age``,
    the SD multiples ``<p>_sd`` of the six varied parameters, and the values ``hr`` [1/min],
    ``sv`` [mL], ``lvet`` [ms], ``pwv`` (target cf-PWV, m/s), ``dia`` (large-artery diameter,
    ratio to the 25-y baseline), ``mbp`` [mmHg], plus the age-only ``length`` (proximal aorta)
    and ``pvc`` (peripheral compliance) ratios and ``co`` [L/min]. Full factorial per age,
    the last of :data:`VARIED` varying fastest."""
    import pandas as pd

    z = levels_sd(levels)
    rows = []
    for age in ages:
        st = age_statistics(age)
        block = np.array(list(itertools.product(z, repeat=len(VARIED))))
        d = {"age": np.full(len(block), age, dtype=float)}
        d.update({f"{p}_sd": block[:, i] for i, p in enumerate(VARIED)})
        for p in ("hr", "sv", "mbp"):
            d[p] = st[p][0] + d[f"{p}_sd"] * st[p][1]
        d["lvet"] = lvet_values(d["hr"], d["sv"], d["lvet_sd"])
        d["dia"] = (st["dia"][0] + d["dia_sd"] * st["dia"][1]) / 100
        d["pwv"] = np.array([cf_pwv(float(age), float(m), float(s))
                             for m, s in zip(d["mbp"], d["pwv_sd"], strict=True)])
        d["length"] = np.full(len(block), st["len"][0])
        d["pvc"] = np.full(len(block), st["pvc"][0])
        rows.append(pd.DataFrame(d))
    out = pd.concat(rows, ignore_index=True)
    out["co"] = out["hr"] * out["sv"] / 1000
    out.index.name = "subject"
    return out


@lru_cache(maxsize=1)
def _base() -> tuple[list[dict[str, Any]]]:
    """The built-in's segment table (cached; callers copy before changing it)."""
    return (pwdb.geometry_of(catalogue.load_dict(MODEL)),)


@lru_cache(maxsize=4096)
def _k3(dia: float, length: float, target: float) -> float:
    geo = pwdb.subject_geometry(_base()[0], dia, length)
    return pwdb.fit_k3(geo, target)


def subject_patch(row: Mapping[str, float], base: list[dict[str, Any]] | None = None
                  ) -> dict[str, Any]:
    """The native-format patch of one subject (a row of :func:`parameters`) against the
    built-in ``pwdb-116``: every vessel's Young's modulus (the wall law with the k3 that gives
    the subject's cf-PWV), the radii of the large arteries, the proximal aortic lengths, the
    inflow table, and every outlet's R1, R2 and C (calibrated to the subject's mean pressure)."""
    builtin = base is None
    base = _base()[0] if base is None else base
    geo = pwdb.subject_geometry(base, float(row["dia"]), float(row["length"]))
    k3 = (_k3(float(row["dia"]), float(row["length"]), float(row["pwv"])) if builtin
          else pwdb.fit_k3(geo, float(row["pwv"])))
    props = pwdb.vessel_properties(base, geo, k3)
    big = pwdb.diameter_segments(base)
    vessels: dict[str, dict[str, float]] = {}
    for g, p in zip(base, props, strict=True):
        v = {"youngs_modulus": p["youngs_modulus"]}
        if g["seg"] in big:
            v.update(radius_in=p["radius_in"], radius_out=p["radius_out"])
        if g["seg"] in pwdb.PROXIMAL_AORTA:
            v["length"] = p["length"]
        vessels[g["name"]] = v
    sv = float(row["sv"]) * 1e-6
    time, flow = pwdb.aortic_inflow(float(row["hr"]), sv, float(row["lvet"]) * 1e-3)
    q_mean = sv * float(row["hr"]) / 60
    outlets, _s = pwdb.outlet_conditions(geo, k3, float(row["pvc"]), q_mean,
                                         float(row["mbp"]) * pwdb.MMHG)
    bcs: dict[str, dict[str, Any]] = {pwdb.INLET_NODE: {"time": time, "flow": flow}}
    for n, bc in outlets.items():
        bcs[n] = {k: bc[k] for k in ("proximal_resistance", "distal_resistance", "capacitance")}
    return {"vessels": vessels, "boundary_conditions": bcs}


def base_model(oxygen: bool = False) -> dict[str, Any]:
    """The native dict of ``pwdb-116`` (the population's base model), with the :data:`OXYGEN`
    section when ``oxygen`` (then :func:`subject_summary` reports ``ica_po2``)."""
    data = catalogue.load_dict(MODEL)
    if oxygen:
        data["oxygen"] = copy.deepcopy(OXYGEN)
    return data


def pwdb_like(ages: Sequence[float] = (25, 35, 45, 55, 65, 75), levels: int = 3, *,
              frame: bool = False) -> Any:
    """PWDB-like virtual subjects of ``pwdb-116``: a list of native-format patches (one per
    row of :func:`parameters`, same order), or with ``frame=True`` a pandas DataFrame with one
    dotted-path column per patched value (``vessels.<name>.youngs_modulus``,
    ``boundary_conditions.<node>.distal_resistance``, ...; the inflow columns hold the
    tables) indexed by the subject's ``age`` and SD levels. For oxygen, run the patches on
    :func:`base_model` ``(oxygen=True)``: a patch changes a model's values, it does not add
    sections (the ensemble shares one transport plan between variants)."""
    table = parameters(ages, levels)
    patches = [subject_patch(r) for r in table.to_dict("records")]
    if not frame:
        return patches
    import pandas as pd

    flat = [{f"{grp}.{name}.{k}": v for grp in ("vessels", "boundary_conditions")
             for name, props in p[grp].items() for k, v in props.items()} for p in patches]
    index = pd.MultiIndex.from_frame(table[["age", *[f"{p}_sd" for p in VARIED]]])
    return pd.DataFrame(flat, index=index)


def patched(model: Any, patch: Mapping[str, Any]) -> dict[str, Any]:
    """A native model dict with ``patch`` deep-merged: :func:`oxyline.ensemble.apply_patch`
    (the patch semantics of :func:`oxyline.simulate_ensemble`, kept here under the name the
    population examples use)."""
    return apply_patch(model, patch)


#: the built-in's spatial and time resolution and run settings (docs/populations.md)
MAX_SEGMENT_LENGTH = 0.02
#: ``cycles`` is the minimum before the periodicity test: 2 instead of the default 10 lets the
#: stiff, low-compliance (old) subjects stop at 6 cycles (the summary moves by < 0.002 mmHg
#: against a run to 1e-7); young ones need 12-18 cycles either way
SIMULATION = {"cycles": 2, "until_periodic": 1e-4, "max_cycles": 60,
              "method": "generalized-alpha", "dt": 1e-3, "output": {"cycles": "last", "every": 1e-3}}


def baseline_row(age: float = BASELINE_AGE) -> dict[str, float]:
    """The PWDB baseline subject of ``age`` (default 25 years): every parameter at its mean
    (LVET as normalised in the 729-subject age group, as PWDB does)."""
    table = parameters((age,), 3)
    zero = (table[[f"{p}_sd" for p in VARIED]] == 0).all(axis=1)
    return table[zero].iloc[0].to_dict()


def model_dict(geometry: list[dict[str, Any]], row: Mapping[str, float] | None = None,
               name: str = MODEL) -> dict[str, Any]:
    """A native model dict of the PWDB network ``geometry`` (:func:`oxyline.pwdb.read_geometry`,
    the 25-y baseline) for the subject ``row`` of :func:`parameters` (default: the baseline
    subject). The built-in ``pwdb-116`` is ``model_dict(read_geometry(116_artery_model.txt))``."""
    pwdb.check_terminals(geometry)
    row = dict(row or baseline_row())
    patch = subject_patch(row, geometry)
    geo = pwdb.subject_geometry(geometry, row["dia"], row["length"])
    props = pwdb.vessel_properties(geometry, geo, 0.0)   # lengths, radii, thickness
    vessels = [{"name": g["name"], "from": pwdb.node(g["inlet"]), "to": pwdb.node(g["outlet"]),
                "length": p["length"], "radius_in": p["radius_in"],
                "radius_out": p["radius_out"], "wall_thickness": p["wall_thickness"],
                "youngs_modulus": patch["vessels"][g["name"]]["youngs_modulus"],
                "poisson_ratio": pwdb.POISSON} for g, p in zip(geometry, props, strict=True)]
    bcs = {n: {"type": "flow", **bc, "interpolation": "linear"} if n == pwdb.INLET_NODE
           else {"type": "rcr", **bc, "pressure": pwdb.P_OUT}
           for n, bc in patch["boundary_conditions"].items()}
    return {"name": name, "description": _describe(row), "units": "SI",
            "blood": {"density": pwdb.RHO, "viscosity": pwdb.MU}, "arrangement": "inverted-L",
            "segmentation": {"max_length": MAX_SEGMENT_LENGTH}, "vessels": vessels,
            "boundary_conditions": bcs, "simulation": copy.deepcopy(SIMULATION)}


def _describe(row: Mapping[str, float]) -> str:
    return (f"PWDB 116-artery network (Charlton et al. 2019; geometry Mynard & Smolich 2015), "
            f"PWDB baseline subject of age {row['age']:g}: HR {row['hr']:.2f}/min, SV "
            f"{row['sv']:.2f} mL, LVET {row['lvet']:.1f} ms, target cf-PWV {row['pwv']:.3f} m/s, "
            f"mean aortic root pressure {row['mbp']:.2f} mmHg (terminal resistances calibrated "
            f"to it), Mynard 2015 aortic inflow template; see docs/populations.md.")


# ------------------------------------------------------------- per-subject summary


def foot_time(time: Any, pressure: Any) -> float:
    """Foot of a periodic pressure wave by the intersecting-tangent method
    (:func:`oxyline._core.foot_time`, the feet of the ``pwv`` calibration outputs too): the
    intersection of the tangent at the steepest upstroke (largest forward difference, taken at
    the midpoint of its two samples) with the horizontal through the diastolic minimum (the
    lowest sample in the half period before the upstroke). ``time``/``pressure``: one cycle of
    uniform samples with both ends (t = 0 and t = T, as a result's last cycle; the t = T sample
    only closes the last difference). Returns the foot time in [0, T)."""
    return _core.foot_time(np.ascontiguousarray(time, dtype=float),
                           np.ascontiguousarray(pressure, dtype=float))


def transit_time(time: Any, proximal: Any, distal: Any) -> float:
    """Foot-to-foot transit time [s] from ``proximal`` to ``distal`` (one periodic cycle each),
    in [0, T)."""
    return _core.transit_time(*(np.ascontiguousarray(a, dtype=float)
                                for a in (time, proximal, distal)))


def _site(result: Any, seg: int, frac: float) -> tuple[np.ndarray, float]:
    """Pressure at a measurement site and its distance [m] from the segment's inlet: the inlet
    or outlet pressure, or (mid-vessel) the inlet pressure of the segment that starts nearest
    to frac x length (needs segment output)."""
    g = _base()[0][seg - 1]
    r = result.vessel(g["name"])
    if frac <= 0 or frac >= 1 or not result.has_segments:
        if 0 < frac < 1:
            raise ModelError(f"subject_summary: the site at {frac:g} of '{g['name']}' needs the "
                             f"segment output (segments=True)")
        return (r.pressure_out, g["length"]) if frac >= 1 else (r.pressure_in, 0.0)
    pos = np.asarray(r.segment_position)
    starts = pos - pos[0]                 # uniform segments: start = midpoint - dx/2
    j = int(np.argmin(np.abs(starts - frac * g["length"])))
    return r.segment_pressure_in[:, j], float(starts[j])


def _path_length(segments: Sequence[int]) -> float:
    return sum(_base()[0][s - 1]["length"] for s in segments)


def summary_vessels() -> list[str]:
    """Names of the vessels :func:`subject_summary` reads (sites and the ICA)."""
    geo = _base()[0]
    return [geo[s - 1]["name"] for s in sorted({s for s, _f in pwdb.SITES.values()}
                                                | {pwdb.ICA_SEGMENT})]


def subject_summary(result: Any) -> dict[str, float]:
    """Per-subject summary of a ``pwdb-116`` result (last cycle): ``<site>_sbp``, ``_dbp``,
    ``_map`` [mmHg] at the aortic root, carotid (mid left common carotid), brachial (end of
    the left brachial), radial (mid left radial) and femoral (mid left femoral) sites;
    ``cf_pwv`` [m/s] = carotid-to-femoral path length / foot-to-foot transit time
    (:func:`foot_time`, intersecting tangents), the path along PWDB's aorta-femoral and
    aorta-carotid segments; ``ica_po2`` [mmHg], the cycle-mean PO2 at the left internal carotid
    outlet, when the result has oxygen. The callable ``simulate_ensemble(..., output=...)``
    takes."""
    out: dict[str, float] = {}
    waves = {}
    for name, (seg, frac) in pwdb.SITES.items():
        p, x = _site(result, seg, frac)
        waves[name] = (p, x)
        cyc = np.asarray(p[:-1], float) / pwdb.MMHG     # last cycle, t = T dropped
        out[f"{name}_sbp"] = float(cyc.max())
        out[f"{name}_dbp"] = float(cyc.min())
        out[f"{name}_map"] = float(cyc.mean())
    (pc, xc), (pf, xf) = waves["carotid"], waves["femoral"]
    dist = (_path_length(pwdb.AORTA_FEMORAL) + xf) - (_path_length(pwdb.AORTA_CAROTID) + xc)
    tt = transit_time(result.time, pc, pf)
    out["cf_pwv"] = dist / tt if tt > 0 else math.nan   # feet at the same sample: no estimate
    if getattr(result, "oxygen", None):
        ica = _base()[0][pwdb.ICA_SEGMENT - 1]["name"]
        out["ica_po2"] = float(np.mean(result.po2_out[:-1, list(result.vessels).index(ica)]))
    return out


# ------------------------------------------------------------- calibration to in-vivo data

#: McEniery et al. 2005 (J Am Coll Cardiol 46:1753), Table 1 per decade (mid-ages 15…85 y):
#: (men mean, men SD, women mean, women SD) of each characteristic [mmHg; amplification a
#: ratio], as PWDB's plausibility check holds them (``models_data/mceniery2005.yaml``,
#: docs/populations.md)
_MCENIERY = shipped_data("mceniery2005.yaml")
MCENIERY_AGES = tuple(_MCENIERY["ages"])
MCENIERY_N = (tuple(_MCENIERY["n"]["men"]), tuple(_MCENIERY["n"]["women"]))
MCENIERY = {k: tuple(tuple(v[c]) for c in ("men_mean", "men_sd", "women_mean", "women_sd"))
            for k, v in _MCENIERY["characteristics"].items()}
_COLUMNS = ("men_mean", "men_sd", "women_mean", "women_sd")
#: the table with the values the calibration's targets take in place of a transcribed value
#: that contradicts its group's other characteristics (the data file's ``fit_values``)
MCENIERY_FIT = {k: tuple(tuple(float(_MCENIERY["fit_values"].get(k, {}).get(c, {}).get(a, x))
                               for a, x in zip(MCENIERY_AGES, col, strict=True))
                         for c, col in zip(_COLUMNS, cols, strict=True))
                for k, cols in MCENIERY.items()}
#: PWDB's 99 % plausibility range: mean ± 2.575 SD of the pooled men and women
Z99 = 2.575


def _pooled(m: tuple[float, float, int], f: tuple[float, float, int]) -> tuple[float, float]:
    """Mean and SD of two groups pooled (sums of x and x² of each)."""
    sx = m[0] * m[2] + f[0] * f[2]
    sxx = sum(sd**2 * (n - 1) + (mu * n) ** 2 / n for mu, sd, n in (m, f))
    n = m[2] + f[2]
    return sx / n, math.sqrt((sxx - sx**2 / n) / (n - 1))


def in_vivo(age: float, fit: bool = False) -> dict[str, tuple[float, float]]:
    """McEniery 2005's mean and SD of each characteristic at ``age`` (15-85 y), men and women
    pooled per decade and interpolated linearly between decades (as PWDB's check does);
    ``fit``: with the calibration's corrected values (:data:`MCENIERY_FIT`)."""
    if not MCENIERY_AGES[0] <= age <= MCENIERY_AGES[-1]:
        raise ModelError(f"age {age}: McEniery 2005's decades cover 15-85 years")
    out = {}
    for name, (mm, ms, fm, fs) in (MCENIERY_FIT if fit else MCENIERY).items():
        stats = [_pooled((a, b, n), (c, d, k)) for a, b, n, c, d, k in
                 zip(mm, ms, MCENIERY_N[0], fm, fs, MCENIERY_N[1], strict=True)]
        out[name] = (float(np.interp(age, MCENIERY_AGES, [s[0] for s in stats])),
                     float(np.interp(age, MCENIERY_AGES, [s[1] for s in stats])))
    return out


def plausible_ranges(age: float) -> dict[str, tuple[float, float]]:
    """PWDB's 99 % plausibility range of each characteristic at ``age``: mean ± 2.575 SD."""
    return {k: (m - Z99 * s, m + Z99 * s) for k, (m, s) in in_vivo(age).items()}
