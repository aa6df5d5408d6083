"""svZeroDSolver JSON models for the benchmarks (``docs/peers.md`` §4 of the shared material).

* ``chain(n)``: an r = 1 cm, 50 cm aorta-like tube split into ``n`` BloodVessels joined by
  1-in/1-out ``NORMAL_JUNCTION``s, FLOW inlet, one RESISTANCE outlet (1300 dyn s/cm^5).
* ``tree(n)``: a heap-ordered complete binary tree of ``n`` vessels (children of vessel i are
  2i+1 and 2i+2), Murray radii r = 2^(-d/3) cm at depth d, l = 10 r, a NORMAL_JUNCTION at every
  branch point, one RESISTANCE per leaf with a parallel total of 1300 dyn s/cm^5.

Both use CGS units: Poiseuille R = 8 mu l / (pi r^4), wall compliance C = 3 pi r^2 l / (2 Eh/r)
with Olufsen's Eh/r = k1 exp(k2 r) + k3, L = rho l / (pi r^2); FLOW inlet: a half-sine systolic
pulse with a time-mean of 90 mL/s, period T = 1 s. Run settings: 5 cycles x 1000 points per cycle,
all other svZeroDSolver defaults (steady initialisation, generalized-alpha rho = 0.5, tol 1e-8).
"""

from __future__ import annotations

import math
from typing import Any

MU = 0.04  # blood viscosity, P (g/(cm s))
RHO = 1.06  # blood density, g/cm^3
K1, K2, K3 = 2.0e7, -22.53, 8.65e5  # Olufsen et al. 2000: Eh/r = k1 exp(k2 r) + k3 (CGS)
PERIOD = 1.0  # s
T_SYSTOLE = 0.3  # s
MEAN_FLOW = 90.0  # mL/s
R_TOTAL = 1300.0  # dyn s/cm^5, outlet resistance (parallel total for trees)
INFLOW_SAMPLES = 201  # samples of the inflow table over one period (5 ms apart)
CYCLES = 5
PTS_PER_CYCLE = 1000


def vessel_values(r: float, length: float) -> dict[str, float]:
    """BloodVessel R, C, L (CGS) of a straight tube of radius ``r`` and length ``length`` (cm)."""
    eh_r = K1 * math.exp(K2 * r) + K3
    return {
        "R_poiseuille": 8.0 * MU * length / (math.pi * r**4),
        "C": 3.0 * math.pi * r**2 * length / (2.0 * eh_r),
        "L": RHO * length / (math.pi * r**2),
    }


def inflow() -> dict[str, Any]:
    """FLOW boundary condition: half-sine systole, zero in diastole, time-mean ``MEAN_FLOW``.

    The peak is chosen so that the mean of the piecewise-linear table (what the solvers
    integrate) is exactly ``MEAN_FLOW``.
    """
    n = INFLOW_SAMPLES
    t = [PERIOD * i / (n - 1) for i in range(n)]
    shape = [math.sin(math.pi * ti / T_SYSTOLE) if ti < T_SYSTOLE else 0.0 for ti in t]
    shape = [max(s, 0.0) for s in shape]
    trapezoid_mean = sum((shape[i] + shape[i + 1]) / 2.0 for i in range(n - 1)) / (n - 1)
    q = [MEAN_FLOW * s / trapezoid_mean for s in shape]
    return {"bc_name": "INFLOW", "bc_type": "FLOW", "bc_values": {"Q": q, "t": t}}


def _sim_params(cycles: int, pts_per_cycle: int) -> dict[str, Any]:
    return {"number_of_cardiac_cycles": cycles,
            "number_of_time_pts_per_cardiac_cycle": pts_per_cycle}


def _vessel(i: int, r: float, length: float, bcs: dict[str, str] | None = None) -> dict[str, Any]:
    v: dict[str, Any] = {
        "vessel_id": i, "vessel_name": f"V{i}", "vessel_length": length,
        "zero_d_element_type": "BloodVessel", "zero_d_element_values": vessel_values(r, length),
    }
    if bcs:
        v["boundary_conditions"] = bcs
    return v


def chain(n: int, cycles: int = CYCLES, pts_per_cycle: int = PTS_PER_CYCLE) -> dict[str, Any]:
    """Chain of ``n`` segments of a 50 cm, r = 1 cm tube."""
    if n < 1:
        raise ValueError("n must be >= 1")
    seg = 50.0 / n
    vessels = []
    for i in range(n):
        bcs = {}
        if i == 0:
            bcs["inlet"] = "INFLOW"
        if i == n - 1:
            bcs["outlet"] = "OUT"
        vessels.append(_vessel(i, 1.0, seg, bcs))
    junctions = [{"junction_name": f"J{i}", "junction_type": "NORMAL_JUNCTION",
                  "inlet_vessels": [i], "outlet_vessels": [i + 1]} for i in range(n - 1)]
    return {
        "description": f"chain {n}",
        "simulation_parameters": _sim_params(cycles, pts_per_cycle),
        "boundary_conditions": [
            inflow(),
            {"bc_name": "OUT", "bc_type": "RESISTANCE", "bc_values": {"R": R_TOTAL, "Pd": 0.0}},
        ],
        "vessels": vessels,
        "junctions": junctions,
    }


def tree(n: int, cycles: int = CYCLES, pts_per_cycle: int = PTS_PER_CYCLE) -> dict[str, Any]:
    """Heap-ordered complete binary tree of ``n`` vessels with Murray radii."""
    if n < 1:
        raise ValueError("n must be >= 1")
    leaves = [i for i in range(n) if 2 * i + 1 >= n]
    r_leaf = R_TOTAL * len(leaves)
    vessels, junctions, bcs = [], [], [inflow()]
    for i in range(n):
        depth = (i + 1).bit_length() - 1
        r = 2.0 ** (-depth / 3.0)
        vb = {}
        if i == 0:
            vb["inlet"] = "INFLOW"
        children = [c for c in (2 * i + 1, 2 * i + 2) if c < n]
        if children:
            junctions.append({"junction_name": f"J{i}", "junction_type": "NORMAL_JUNCTION",
                              "inlet_vessels": [i], "outlet_vessels": children})
        else:
            vb["outlet"] = f"OUT{i}"
            bcs.append({"bc_name": f"OUT{i}", "bc_type": "RESISTANCE",
                        "bc_values": {"R": r_leaf, "Pd": 0.0}})
        vessels.append(_vessel(i, r, 10.0 * r, vb))
    return {
        "description": f"tree {n}",
        "simulation_parameters": _sim_params(cycles, pts_per_cycle),
        "boundary_conditions": bcs,
        "vessels": vessels,
        "junctions": junctions,
    }


GENERATORS = {"chain": chain, "tree": tree}


def build(topology: str, n: int, cycles: int = CYCLES,
          pts_per_cycle: int = PTS_PER_CYCLE) -> dict[str, Any]:
    """``chain`` or ``tree`` model with ``n`` vessels."""
    return GENERATORS[topology](n, cycles, pts_per_cycle)
