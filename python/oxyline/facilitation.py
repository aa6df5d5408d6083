"""Haemoglobin facilitation of the wall boundary layer (docs/physics.md §3.4), computed by the
core (``rust/oxyline-core/src/model/facilitation.rs``): the factor E_Hb that multiplies the
dissolved-O2 Lévêque/Graetz closure.

* ``linearized`` haemoglobin: E_Hb = (1 + K̄)^{1/3} (1 + K̄ D_Hb/D)^{2/3} with the Hill secant
  K̄ over [P_w, P_in] (closed form);
* ``hill`` haemoglobin: the ratio of the nonlinear Lévêque similarity solution's wall flux to
  the dissolved one, found by shooting (validated against the 2-D solution with Hill binding,
  docs/validation-oxygen.md §7).
"""

from __future__ import annotations

import functools

from oxyline import _core


def linear_factor(kbar: float, d: float, d_hb: float) -> float:
    """E_Hb of linearised binding with secant K̄."""
    return float(_core.linear_facilitation_factor(kbar, d, d_hb))


@functools.lru_cache(maxsize=256)
def hill_factor(p_in: float, p_w: float, alpha: float, d: float, d_hb: float, capacity: float,
                p50: float, n: float) -> float:
    """E_Hb of Hill binding: the nonlinear Lévêque layer's wall flux over the dissolved one
    (1 when P_in = P_w: no layer)."""
    return float(_core.facilitation_factor(p_in, p_w, alpha, d, d_hb, capacity, p50, n, False))


def secant_factor(p_in: float, p_w: float, alpha: float, d: float, d_hb: float,
                  capacity: float, p50: float, n: float) -> float:
    """E_Hb of linearised binding with the Hill secant K̄ over [P_w, P_in] (K̄ = 0 when they
    are equal)."""
    return float(_core.facilitation_factor(p_in, p_w, alpha, d, d_hb, capacity, p50, n, True))
