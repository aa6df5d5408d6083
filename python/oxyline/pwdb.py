"""The PWDB 116-artery network and the age-specific cardiovascular parameters of its virtual
subjects (Charlton et al. 2019, Am J Physiol Heart Circ Physiol 317:H1062; the Pulse Wave
DataBase), as formulas: the built-in ``pwdb-116`` and :mod:`oxyline.populations` use them.

Sources, each value's provenance in ``docs/populations.md``:

* geometry (lengths, inlet/outlet radii, connectivity of 116 segments): PWDB's
  ``116_artery_model.txt`` (Mynard & Smolich 2015 values, radii x sqrt(1.5)); it is stored in
  the built-in model file ``models_data/pwdb-116.yaml``, whose vessels are in the source's
  segment order (the i-th vessel, counting from 1, is segment i);
* wall law Eh/r0 = k1 exp(k2 r0) + k3 (Mynard & Smolich 2015 eq. 3; PWDB's k2 = 1.5 x Mynard's)
  with wave speed c^2 = (2/3) (Eh/r0) / rho, which oxyline's thin-wall compliance with
  Poisson ratio 0.5 reproduces exactly: c^2 = Eh / (2 rho r (1 - nu^2));
* 16 vascular beds (R, C) shared among their terminal segments by outlet area, R1 = the
  terminal segment's characteristic impedance, R2 = the bed's share x one factor calibrated to
  the mean aortic root pressure, outflow pressure 33.2 mmHg;
* age-specific means and SDs: the literature data and fits of PWDB's
  ``calculate_pwdb_input_parameters.m`` (MIT), recomputed here (``docs/populations.md``).

All functions take and return SI units unless their name says otherwise.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from oxyline.errors import ModelError

MMHG = 133.33                 # Pa per mmHg, PWDB's conversion factor
RHO = 1060.0                  # blood density [kg/m^3] (PWDB)
MU = 2.5e-3                   # blood viscosity [Pa s] (PWDB)
P_OUT = 33.2 * MMHG           # Windkessel outflow pressure [Pa] (PWDB, Parazynski 1993)
K1_CGS, K2_CGS, K3_CGS = 3.0e6, -9 * 1.5, 3.37e5   # wall law [g s^-2 cm^-1, cm^-1, g s^-2 cm^-1]
POISSON = 0.5                 # makes oxyline's c^2 = Eh/(2 rho r (1-nu^2)) PWDB's (2/3)(Eh/r)/rho
#: wall thickness h = r (a e^(b r) + c e^(d r)), r in cm: not PWDB's (its 1-D model takes Eh),
#: the law of circulatory_autogen's a..d_vessel (whole-body-140's source); only E h enters the
#: thin-wall compliance, so h is a labelling choice and E carries the stiffness
THICKNESS = (0.2802, -5.053, 0.1324, -0.1114)
#: the segments whose diameter PWDB's "large-artery diameter" scales: mean radius >= this
LARGE_ARTERY_RADIUS = 0.003462 * math.sqrt(1.5)
PROXIMAL_AORTA = (1, 2)       # segments whose length PWDB's aortic length changes
#: PWDB's carotid-femoral path (segment numbers): femoral site = mid segment 46, carotid site =
#: mid segment 15; the path runs from the aortic root through these segments
AORTA_FEMORAL = (1, 2, 14, 18, 27, 28, 35, 37, 39, 41, 42, 44)
AORTA_CAROTID = (1, 2)
CAROTID_SEGMENT, FEMORAL_SEGMENT = 15, 46
#: measurement sites of the summary: name -> (segment, fraction of its length)
SITES = {"aortic_root": (1, 0.0), "carotid": (15, 0.5), "brachial": (21, 1.0),
         "radial": (22, 0.5), "femoral": (46, 0.5)}
ICA_SEGMENT = 16              # left internal carotid: its outlet is the "ICA outlet"

#: PWDB's 16 vascular beds: name, terminal segments, R [mmHg s/mL], C [mL/mmHg]
#: (``add_wk_vascular_bed_parameters`` / ``calc_outflow`` of PWDB, segment lists verbatim)
VASCULAR_BEDS: tuple[tuple[str, tuple[int, ...], float, float], ...] = (
    ("brain", (62, 63, 69, 70, 72, 73, 74, 76, 93, 95), 6.9040, 0.021726),
    ("face_neck", (78, 80, 82, 84, 86, 88, 89, 90, 91, 92), 20.755, 0.026499),
    ("right_shoulder_arm", (10, 102, 103, 104, 105), 16.852, 0.032637),
    ("left_shoulder_arm", (24, 112, 113, 114, 115), 16.852, 0.032637),
    ("chest", (26,), 10.824, 0.050811),
    ("right_kidney", (36,), 8.368, 0.065727),
    ("left_kidney", (38,), 8.368, 0.065727),
    ("liver", (32,), 21.252, 0.02606),
    ("spleen", (33,), 27.832, 0.019761),
    ("stomach", (31,), 54.084, 0.010169),
    ("intestines", (34, 40), 10.374, 0.053018),
    ("pelvis", (45, 51), 26.119, 0.021057),
    ("right_upper_leg", (53,), 32.29, 0.017033),
    ("left_upper_leg", (47,), 32.29, 0.017033),
    ("right_lower_leg", (54, 55), 14.786, 0.037197),
    ("left_lower_leg", (48, 49), 14.824, 0.037102),
)
INLET_NODE = "n1"
TEMPLATE = "mynard2015_aortic_flow_template.csv"
ZERO_HEAD, LAST_SYSTOLE = 52, 361     # PWDB keeps samples 53..361 (1-based) of the template


def slug(name: str) -> str:
    """Vessel name of a PWDB segment name: lower case, runs of other characters -> ``_``."""
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def node(i: int) -> str:
    return f"n{i}"


# ---------------------------------------------------------------- geometry and wall


def read_geometry(path: Any) -> list[dict[str, Any]]:
    """PWDB's ``116_artery_model.txt`` (tab-separated) as a list of segments
    ``{seg, inlet, outlet, length, radius_in, radius_out, name}`` (SI), in file order."""
    import csv

    out = []
    with open(path, newline="") as f:
        for row in csv.DictReader(f, delimiter="\t"):
            out.append({"seg": int(row["Segment No"]), "inlet": int(row["Inlet node"]),
                        "outlet": int(row["Outlet node"]), "length": float(row["Length [m]"]),
                        "radius_in": float(row["Inlet Radius [m]"]),
                        "radius_out": float(row["Outlet Radius [m]"]),
                        "name": slug(row["Name"])})
    if [g["seg"] for g in out] != list(range(1, len(out) + 1)):
        raise ModelError(f"{path}: segments must be numbered 1..N in order")
    return out


def geometry_of(model: dict[str, Any]) -> list[dict[str, Any]]:
    """The segment table of a ``pwdb-116``-like native dict (the i-th vessel is segment i)."""
    out = []
    for i, v in enumerate(model["vessels"], start=1):
        out.append({"seg": i, "inlet": int(v["from"][1:]), "outlet": int(v["to"][1:]),
                    "length": float(v["length"]), "radius_in": float(v["radius_in"]),
                    "radius_out": float(v["radius_out"]), "name": v["name"]})
    return out


def eh_over_r(r: np.ndarray | float, k3_cgs: float) -> np.ndarray:
    """Wall law Eh/r0 [Pa] at radius r [m] (cgs constants; 1 g s^-2 cm^-1 = 0.1 Pa)."""
    return 0.1 * (K1_CGS * np.exp(K2_CGS * 100.0 * np.asarray(r)) + k3_cgs)


def wave_speed(r: np.ndarray | float, k3_cgs: float, rho: float = RHO) -> np.ndarray:
    """Moens-Korteweg wave speed of the wall law: c = sqrt((2/3) (Eh/r0) / rho) [m/s]."""
    return np.sqrt(2.0 / 3.0 * eh_over_r(r, k3_cgs) / rho)


def wall_thickness(r: np.ndarray | float) -> np.ndarray:
    a, b, c, d = THICKNESS
    rc = 100.0 * np.asarray(r)
    return np.asarray(r) * (a * np.exp(b * rc) + c * np.exp(d * rc))


def _mean_radius(geo: list[dict[str, Any]]) -> np.ndarray:
    return np.array([(g["radius_in"] + g["radius_out"]) / 2 for g in geo])


def _site_radius(g: dict[str, Any], frac: float) -> float:
    # PWDB takes the wave speed of the half segment at r_in - 0.25 (r_in - r_out)
    return g["radius_in"] - frac / 2 * (g["radius_in"] - g["radius_out"])


def theoretical_cf_pwv(geo: list[dict[str, Any]], k3_cgs: float, rho: float = RHO) -> float:
    """Carotid-femoral PWV [m/s] of the wall law along PWDB's path: path length over the
    difference of the transit times sum(L_i / c_i) to mid-femoral and to mid-carotid, each
    segment's c at its mean radius (PWDB's ``calculate_theoretical_wave_speeds``)."""
    c = wave_speed(_mean_radius(geo), k3_cgs, rho)

    def transit(path: Sequence[int], site: int) -> tuple[float, float]:
        g = geo[site - 1]
        length = sum(geo[s - 1]["length"] for s in path) + g["length"] / 2
        t = sum(geo[s - 1]["length"] / c[s - 1] for s in path)
        t += g["length"] / 2 / float(wave_speed(_site_radius(g, 0.5), k3_cgs, rho))
        return length, t

    lf, tf = transit(AORTA_FEMORAL, FEMORAL_SEGMENT)
    lc, tc = transit(AORTA_CAROTID, CAROTID_SEGMENT)
    return (lf - lc) / (tf - tc)


def fit_k3(geo: list[dict[str, Any]], target_pwv: float) -> float:
    """The wall-law k3 [g s^-2 cm^-1] giving ``target_pwv`` (cf-PWV, m/s) on ``geo``: the
    cf-PWV increases with k3: bisection to 1e-12 relative."""
    lo, hi = 0.0, 5e7             # Eh/r0 > 0 needs k3 >= 0 at the aortic radii
    if not theoretical_cf_pwv(geo, lo) < target_pwv < theoretical_cf_pwv(geo, hi):
        raise ModelError(f"cf-PWV {target_pwv} m/s out of reach of the wall law")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if theoretical_cf_pwv(geo, mid) < target_pwv:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-12 * abs(hi):
            break
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------- inflow


@lru_cache(maxsize=1)
def mynard_systole() -> np.ndarray:
    """The systolic part of the Mynard & Smolich 2015 aortic flow [m^3/s], 1 kHz, as PWDB keeps
    it (samples 53..361 of the template, so that systole starts at t = 0)."""
    text = (resources.files("oxyline.models_data") / TEMPLATE).read_text()
    q = np.loadtxt(text.splitlines(), delimiter=",", comments="#", skiprows=2, usecols=1)
    return q[ZERO_HEAD:LAST_SYSTOLE] * 1e-6


def template_lvet() -> float:
    """Ejection time of the template [s]: from t = 0 to the first zero crossing after the
    peak (the forward ejection; the closing backflow after it is kept and scaled with it)."""
    q = mynard_systole()
    k = int(np.argmax(q))
    j = k + int(np.argmax(q[k:] <= 0))
    return 1e-3 * (j - 1 + q[j - 1] / (q[j - 1] - q[j]))   # linear zero crossing


def aortic_inflow(hr: float, sv: float, lvet: float) -> tuple[list[float], list[float]]:
    """Aortic root flow table for heart rate ``hr`` [1/min], stroke volume ``sv`` [m^3] and
    ejection time ``lvet`` [s]: the Mynard template's systole stretched in time by
    lvet / template_lvet(), scaled so that its net volume is ``sv``, zero flow until the period
    60/hr. Returns (time [s], flow [m^3/s]) for a periodic ``linear`` table."""
    q = mynard_systole()
    scale_t = lvet / template_lvet()
    t = np.arange(len(q)) * 1e-3 * scale_t
    period = 60.0 / hr
    if t[-1] + 1e-3 * scale_t >= period:
        raise ModelError(f"heart rate {hr:g}/min: period {period:g} s is shorter than the "
                         f"systole ({t[-1]:g} s at LVET {lvet * 1e3:g} ms)")
    dt = 1e-3 * scale_t
    time = np.concatenate([t, [t[-1] + dt, period]])
    flow = np.concatenate([q, [0.0, q[0]]])
    flow *= sv / np.trapezoid(flow, time)
    return time.tolist(), flow.tolist()


# ---------------------------------------------------------------- network


def _outlets(geo: list[dict[str, Any]]) -> dict[int, tuple[str, float, float, float]]:
    """terminal segment -> (bed, area share, bed R [Pa s/m^3], bed C [m^3/Pa])."""
    out = {}
    for bed, segs, r_bed, c_bed in VASCULAR_BEDS:
        areas = {s: math.pi * geo[s - 1]["radius_out"] ** 2 for s in segs}
        total = sum(areas.values())
        for s in segs:
            out[s] = (bed, areas[s] / total, r_bed * MMHG * 1e6, c_bed / MMHG / 1e6)
    return out


def check_terminals(geo: list[dict[str, Any]]) -> None:
    inlets = {g["inlet"] for g in geo}
    free = {g["seg"] for g in geo if g["outlet"] not in inlets
            and sum(h["outlet"] == g["outlet"] for h in geo) == 1}
    beds = set(_outlets(geo))
    if free != beds:
        raise ModelError(f"PWDB network: terminal segments {sorted(free ^ beds)} do not match "
                         f"the vascular beds")


def windkessels(geo: list[dict[str, Any]], k3_cgs: float, pvc: float = 1.0
                ) -> dict[int, dict[str, float]]:
    """PWDB's terminal Windkessels before calibration: for each terminal segment R1 = Z =
    rho c(r_out) / (pi r_out^2), the bed's resistance share R_bed / (area share), C = pvc C_bed x
    area share. Returns segment -> {z, r_bed, capacitance}."""
    out = {}
    for s, (_bed, share, r_bed, c_bed) in _outlets(geo).items():
        r = geo[s - 1]["radius_out"]
        z = RHO * float(wave_speed(r, k3_cgs)) / (math.pi * r * r)
        out[s] = {"z": z, "r_bed": r_bed / share, "capacitance": pvc * c_bed * share}
    return out


def steady_model(geo: list[dict[str, Any]], k3_cgs: float, r_total: dict[int, float],
                 q_mean: float) -> dict[str, Any]:
    """The native model dict of the steady circuit of ``geo``: the segments with the wall law
    (its wall does not enter a steady state), constant inflow ``q_mean`` at the inlet, terminal
    segment i ending in the resistance ``r_total[i]`` to ``P_OUT`` (an RCR at steady state)."""
    base = vessel_properties(geo, geo, k3_cgs)
    vessels = [{"name": g["name"], "from": node(g["inlet"]), "to": node(g["outlet"]),
                **p, "poisson_ratio": POISSON} for g, p in zip(geo, base, strict=True)]
    bcs: dict[str, dict[str, Any]] = {INLET_NODE: {"type": "flow", "flow": q_mean}}
    for s, r in r_total.items():
        bcs[node(geo[s - 1]["outlet"])] = {"type": "resistance", "resistance": r,
                                           "pressure": P_OUT}
    return {"name": "pwdb-steady", "units": "SI", "blood": {"density": RHO, "viscosity": MU},
            "vessels": vessels, "boundary_conditions": bcs}


def root_mean_pressure(geo: list[dict[str, Any]], k3_cgs: float, r_total: dict[int, float],
                       q_mean: float) -> float:
    """Mean pressure [Pa] at the aortic root (node 1): the core's steady state of
    :func:`steady_model` (vessels as Poiseuille resistors; the cycle mean of the linear
    circuit)."""
    from oxyline.model import build_model

    st = build_model(steady_model(geo, k3_cgs, r_total, q_mean)).network.steady_state()
    return float(st["node_pressure"][st["nodes"].index(INLET_NODE)])


def calibrate_scale(geo: list[dict[str, Any]], k3_cgs: float, fixed: dict[int, float],
                    scaled: dict[int, float], q_mean: float, target: float) -> float:
    """The factor s such that terminal resistances fixed[i] + s scaled[i] make the steady
    (= cycle-mean) aortic root pressure equal ``target`` [Pa] at inflow ``q_mean``: secant
    iteration on P(s), increasing and nearly linear, to 1e-10 relative."""
    def f(s: float) -> float:
        r = {k: fixed[k] + s * scaled[k] for k in sorted(scaled)}
        return root_mean_pressure(geo, k3_cgs, r, q_mean) - target

    s0 = (target - P_OUT) / q_mean * sum(1.0 / r for r in scaled.values())  # arteries ignored
    s1, f0 = 0.95 * s0, f(s0)
    f1 = f(s1)
    for _ in range(50):
        if abs(f1) < 1e-10 * target:
            break
        s0, s1, f0 = s1, s1 - f1 * (s1 - s0) / (f1 - f0), f1
        f1 = f(s1)
    else:
        raise ModelError(f"terminal resistance calibration to {target:g} Pa did not converge")
    if s1 <= 0:
        raise ModelError(f"mean pressure {target / MMHG:g} mmHg is out of reach: below the "
                         f"outflow pressure plus the drop across the arteries and R1")
    return s1


def _large_arteries(base: list[dict[str, Any]]) -> tuple[set[int], set[int]]:
    big = {g["seg"] for g, r in zip(base, _mean_radius(base), strict=True)
           if r >= LARGE_ARTERY_RADIUS}
    fed = {g["outlet"] for g in base if g["seg"] in big}
    return big, {g["seg"] for g in base if g["seg"] in big or g["inlet"] in fed}


def diameter_segments(base: list[dict[str, Any]]) -> set[int]:
    """Segments with a radius that PWDB's large-artery diameter changes."""
    big, inlets = _large_arteries(base)
    return big | inlets


def subject_geometry(base: list[dict[str, Any]], dia: float = 1.0, length: float = 1.0
                     ) -> list[dict[str, Any]]:
    """PWDB's geometry changes: radii of the large arteries (mean radius >= 4.24 mm, and the
    inlet radius of the segments they feed) x ``dia``, lengths of the proximal aorta x
    ``length``."""
    geo = [dict(g) for g in base]
    big, inlets = _large_arteries(base)
    for g in geo:
        if g["seg"] in big:
            g["radius_out"] *= dia
        if g["seg"] in inlets:
            g["radius_in"] *= dia
        if g["seg"] in PROXIMAL_AORTA:
            g["length"] *= length
    return geo


def vessel_properties(base: list[dict[str, Any]], geo: list[dict[str, Any]], k3_cgs: float
                      ) -> list[dict[str, float]]:
    """Per segment: radius_in/out, length, wall_thickness (the thickness law at the baseline
    mean radius, fixed) and youngs_modulus = (Eh/r0)(r) r / h at the subject's mean radius r,
    so that the wave speed at the mean radius is the wall law's."""
    r0 = _mean_radius(base)
    r = _mean_radius(geo)
    h = wall_thickness(r0)
    e = eh_over_r(r, k3_cgs) * r / h
    return [{"length": g["length"], "radius_in": g["radius_in"], "radius_out": g["radius_out"],
             "wall_thickness": float(hi), "youngs_modulus": float(ei)}
            for g, hi, ei in zip(geo, h, e, strict=True)]


def outlet_conditions(geo: list[dict[str, Any]], k3_cgs: float, pvc: float, q_mean: float,
                      mbp: float) -> tuple[dict[str, dict[str, Any]], float]:
    """RCR outlets calibrated to the mean aortic root pressure ``mbp`` [Pa] at inflow
    ``q_mean``: R1 = Z, R2 = s x the bed's resistance share, C (see :func:`windkessels`; PWDB
    scales Z + share, which can make R2 < 0 at small s). Returns (node -> condition, s)."""
    wk = windkessels(geo, k3_cgs, pvc)
    s = calibrate_scale(geo, k3_cgs, {k: v["z"] for k, v in wk.items()},
                        {k: v["r_bed"] for k, v in wk.items()}, q_mean, mbp)
    out = {}
    for seg, w in sorted(wk.items()):
        out[node(geo[seg - 1]["outlet"])] = {
            "type": "rcr", "proximal_resistance": w["z"], "capacitance": w["capacitance"],
            "distal_resistance": s * w["r_bed"], "pressure": P_OUT}
    return out, s
