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
  Poisson ratio 0.5 reproduces exactly (the core's ``model/pwdb/wall.rs``);
* 16 vascular beds (R, C) shared among their terminal segments by outlet area, R1 = the
  terminal segment's characteristic impedance, R2 = the bed's share x one factor calibrated to
  the mean aortic root pressure, outflow pressure 33.2 mmHg (the core's ``model/pwdb/beds.rs``,
  with PWDB's bed table, on its steady solve of the network);
* a subject's geometry changes (the core's ``model/pwdb/geometry.rs``) and its aortic inflow,
  the Mynard & Smolich 2015 template's systole scaled to the subject's ejection time and stroke
  volume (``model/pwdb/inflow.rs``);
* age-specific means and SDs: the literature data and fits of PWDB's
  ``calculate_pwdb_input_parameters.m`` (MIT), recomputed here (``docs/populations.md``).

All functions take and return SI units unless their name says otherwise. This module reads
PWDB's files and holds its measurement sites; every formula is the core's.
"""

from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError

MMHG = _core.PWDB_MMHG             # Pa per mmHg, PWDB's conversion factor
RHO = _core.PWDB_DENSITY           # blood density [kg/m^3] (PWDB)
MU = _core.PWDB_VISCOSITY          # blood viscosity [Pa s] (PWDB)
P_OUT = _core.PWDB_OUTFLOW_PRESSURE  # Windkessel outflow pressure [Pa] (PWDB, Parazynski 1993)
POISSON = _core.PWDB_POISSON_RATIO   # makes the thin-wall c^2 PWDB's (2/3)(Eh/r)/rho
#: segments whose length PWDB's aortic length changes
PROXIMAL_AORTA = tuple(_core.PWDB_PROXIMAL_AORTA)
#: PWDB's carotid-femoral path (segment numbers): femoral site = mid segment 46, carotid site =
#: mid segment 15; the path runs from the aortic root through these segments
AORTA_FEMORAL = (1, 2, 14, 18, 27, 28, 35, 37, 39, 41, 42, 44)
AORTA_CAROTID = (1, 2)
CAROTID_SEGMENT, FEMORAL_SEGMENT = 15, 46
#: measurement sites of the summary: name -> (segment, fraction of its length)
SITES = {"aortic_root": (1, 0.0), "carotid": (15, 0.5), "brachial": (21, 1.0),
         "radial": (22, 0.5), "femoral": (46, 0.5)}
ICA_SEGMENT = 16              # left internal carotid: its outlet is the "ICA outlet"

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

    with open(path, newline="") as f:
        out = [{"seg": int(row["Segment No"]), "inlet": int(row["Inlet node"]),
                "outlet": int(row["Outlet node"]), "length": float(row["Length [m]"]),
                "radius_in": float(row["Inlet Radius [m]"]),
                "radius_out": float(row["Outlet Radius [m]"]), "name": slug(row["Name"])}
               for row in csv.DictReader(f, delimiter="\t")]
    if [g["seg"] for g in out] != list(range(1, len(out) + 1)):
        raise ModelError(f"{path}: segments must be numbered 1..N in order")
    return out


def geometry_of(model: dict[str, Any]) -> list[dict[str, Any]]:
    """The segment table of a ``pwdb-116``-like native dict (the i-th vessel is segment i)."""
    return [{"seg": i, "inlet": int(v["from"][1:]), "outlet": int(v["to"][1:]),
             "length": float(v["length"]), "radius_in": float(v["radius_in"]),
             "radius_out": float(v["radius_out"]), "name": v["name"]}
            for i, v in enumerate(model["vessels"], start=1)]


def _rows(geo: list[dict[str, Any]]) -> list[tuple[int, int, float, float, float]]:
    """The segments as the core takes them: (inlet, outlet, length, radius_in, radius_out)."""
    return [(g["inlet"], g["outlet"], g["length"], g["radius_in"], g["radius_out"])
            for g in geo]


def fit_k3(geo: list[dict[str, Any]], target_pwv: float) -> float:
    """The wall-law k3 [g s^-2 cm^-1] giving ``target_pwv`` (cf-PWV, m/s) on ``geo`` (the
    core's bisection, to 1e-12 relative)."""
    return _core.pwdb_fit_k3(_rows(geo), (AORTA_FEMORAL, FEMORAL_SEGMENT),
                             (AORTA_CAROTID, CAROTID_SEGMENT), target_pwv)


# ---------------------------------------------------------------- inflow


@lru_cache(maxsize=1)
def mynard_systole() -> np.ndarray:
    """The systolic part of the Mynard & Smolich 2015 aortic flow [m^3/s], 1 kHz, as PWDB keeps
    it (samples 53..361 of the template, so that systole starts at t = 0)."""
    text = (resources.files("oxyline.models_data") / TEMPLATE).read_text()
    q = np.loadtxt(text.splitlines(), delimiter=",", comments="#", skiprows=2, usecols=1)
    return q[ZERO_HEAD:LAST_SYSTOLE] * 1e-6


def aortic_inflow(hr: float, sv: float, lvet: float) -> tuple[list[float], list[float]]:
    """Aortic root flow table for heart rate ``hr`` [1/min], stroke volume ``sv`` [m^3] and
    ejection time ``lvet`` [s]: the Mynard template's systole stretched in time by
    lvet / the template's ejection time, scaled so that its net volume is ``sv``, zero flow until the period
    60/hr (the core's). Returns (time [s], flow [m^3/s]) for a periodic ``linear`` table."""
    return _core.pwdb_aortic_inflow(mynard_systole().tolist(), hr, sv, lvet)


# ---------------------------------------------------------------- network


def check_terminals(geo: list[dict[str, Any]]) -> None:
    """Refuses a network whose terminal segments are not PWDB's vascular beds' (the core's
    check, naming the segments that differ)."""
    _core.pwdb_check_terminals(_rows(geo))


def diameter_segments(base: list[dict[str, Any]]) -> set[int]:
    """Segments with a radius that PWDB's large-artery diameter changes."""
    return set(_core.pwdb_diameter_segments(_rows(base)))


def subject_geometry(base: list[dict[str, Any]], dia: float = 1.0, length: float = 1.0
                     ) -> list[dict[str, Any]]:
    """PWDB's geometry changes (the core's): radii of the large arteries (mean radius >= 4.24
    mm, and the inlet radius of the segments they feed) x ``dia``, lengths of the proximal
    aorta x ``length``."""
    rows = _core.pwdb_subject_geometry(_rows(base), dia, length)
    return [{**g, "length": n, "radius_in": a, "radius_out": b}
            for g, (_i, _o, n, a, b) in zip(base, rows, strict=True)]


def vessel_properties(base: list[dict[str, Any]], geo: list[dict[str, Any]], k3_cgs: float
                      ) -> list[dict[str, float]]:
    """Per segment: radius_in/out, length, wall_thickness (the thickness law at the baseline
    mean radius, fixed) and youngs_modulus = (Eh/r0)(r) r / h at the subject's mean radius r,
    so that the wave speed at the mean radius is the wall law's (the core's)."""
    walls = _core.pwdb_wall_properties(_rows(base), _rows(geo), k3_cgs)
    return [{"length": g["length"], "radius_in": g["radius_in"], "radius_out": g["radius_out"],
             "wall_thickness": h, "youngs_modulus": e} for g, (h, e) in zip(geo, walls, strict=True)]


def outlet_conditions(geo: list[dict[str, Any]], k3_cgs: float, pvc: float, q_mean: float,
                      mbp: float) -> tuple[dict[str, dict[str, Any]], float]:
    """RCR outlets calibrated to the mean aortic root pressure ``mbp`` [Pa] at inflow
    ``q_mean``, by the core: per terminal segment R1 = Z = rho c(r_out) / (pi r_out^2), R2 = s
    x the bed's resistance over the segment's outlet-area share, C = pvc x the bed's
    compliance x that share, s such that the steady (= cycle-mean) root pressure of the
    network is ``mbp`` (PWDB scales Z + share, which can make R2 < 0 at small s). Returns
    (node -> condition, s)."""
    inlet = int(INLET_NODE[1:])
    rows, s = _core.pwdb_outlets(_rows(geo), k3_cgs, pvc, inlet, q_mean, mbp)
    return {node(geo[seg - 1]["outlet"]): {
        "type": "rcr", "proximal_resistance": z, "capacitance": c, "distal_resistance": r2,
        "pressure": P_OUT} for seg, z, r2, c in rows}, s
