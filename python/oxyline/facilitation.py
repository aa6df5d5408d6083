"""Haemoglobin facilitation of the wall boundary layer (docs/physics.md §3.4).

With binding equilibrium and oxyhaemoglobin diffusing with D_Hb, the O2 content is
C(P) = α P + H S(P) and the total flux −∇Φ with Φ(P) = α D P + D_Hb H S(P). In the Lévêque
layer (u = γ y) the PO2 is a similarity profile P = F(ζ), ζ = y (γ/(9 D x))^{1/3}:

    d/dζ (Φ'(F) F') = −3 D ζ² C'(F) F',     F(0) = P_w,  F(∞) = P_in,

and the wall flux is Φ'(F) F'(0) (γ/(9 D x))^{1/3}. For dissolved O2 alone
(Φ' = α D, C' = α) this is Lévêque's F' ∝ exp(−ζ³), flux α D (P_in − P_w)/Γ(4/3) (...); the
ratio of the two is the facilitation factor E_Hb that multiplies the dissolved-O2 closure.

* ``linearized`` haemoglobin has C' = α(1 + K̄), Φ' = α D (1 + K̄ D_Hb/D) with the secant K̄:
  the ODE is linear and E_Hb = (1 + K̄)^{1/3} (1 + K̄ D_Hb/D)^{2/3} in closed form.
* ``hill`` haemoglobin has K(P) = H S'(P)/α varying several-fold across the layer (26 at
  60 mmHg, 8 at 85 mmHg): the secant factor then overestimates the uptake by 7–12 % against
  the 2-D solution with Hill binding (docs/validation-oxygen.md §7), so E_Hb is the ratio of
  the nonlinear similarity solution's wall flux to Lévêque's, found here by shooting.
"""

from __future__ import annotations

import functools
import math

#: integration range in ζ for the largest diffusivity ratio D*/D = Φ'/(D C') ≤ 1 met: F' decays
#: at least as exp(−ζ³ D/D*max), so the profile is flat to < e^-27 at 3 (D*max/D)^{1/3}
ZETA_RANGE = 3.0
#: RK4 stability: the decay rate 3 ζ² D/D* times the step stays below this (RK4's real-axis
#: limit is 2.79); at least MIN_STEPS steps (300 change E_Hb by < 1e-7 from 600)
STEP_RATE = 1.5
MIN_STEPS = 300


def hill_saturation(p: float, p50: float, n: float) -> float:
    return 0.0 if p <= 0 else 1.0 / (1.0 + (p50 / p) ** n)


def _dsat(p: float, p50: float, n: float) -> float:
    if p <= 0:
        return 0.0
    s = hill_saturation(p, p50, n)
    return n * s * (1.0 - s) / p


def linear_factor(kbar: float, d: float, d_hb: float) -> float:
    """E_Hb of linearised binding with secant K̄."""
    return (1.0 + kbar) ** (1.0 / 3.0) * (1.0 + kbar * d_hb / d) ** (2.0 / 3.0)


def _end_value(g0: float, p_w: float, alpha: float, d: float, d_hb: float, cap: float,
               p50: float, n: float, grid: tuple[float, int]) -> float:
    """F(ζ_end) of the similarity ODE started at F(0) = P_w with Φ'F'(0) = g0 (RK4 with
    `grid` = (ζ_end, steps))."""
    zeta_end, steps = grid
    h = zeta_end / steps

    def rates(z: float, f: float, g: float) -> tuple[float, float]:
        ds = _dsat(f, p50, n)
        dphi = alpha * d + d_hb * cap * ds
        dc = alpha + cap * ds
        fp = g / dphi
        return fp, -3.0 * d * z * z * dc * fp

    f, g, z = p_w, g0, 0.0
    for _ in range(steps):
        k1 = rates(z, f, g)
        k2 = rates(z + h / 2, f + h / 2 * k1[0], g + h / 2 * k1[1])
        k3 = rates(z + h / 2, f + h / 2 * k2[0], g + h / 2 * k2[1])
        k4 = rates(z + h, f + h * k3[0], g + h * k3[1])
        f += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        g += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        z += h
    return f


@functools.lru_cache(maxsize=256)
def hill_factor(p_in: float, p_w: float, alpha: float, d: float, d_hb: float, capacity: float,
                p50: float, n: float) -> float:
    """E_Hb of Hill binding: the nonlinear Lévêque layer's wall flux over the dissolved one
    (1 when P_in = P_w: no layer). F(ζ_max) increases monotonically and smoothly with the
    wall flux: Illinois regula falsi on it, to 1e-10 of P_in − P_w."""
    if p_in == p_w:
        return 1.0
    dissolved = alpha * d * (p_in - p_w) / math.gamma(4.0 / 3.0)
    # the flux lies between the dissolved value scaled by the smallest and largest linear
    # factors over [P_w, P_in]; widened so that the bracket always holds
    ks = [capacity * _dsat(p, p50, n) / alpha
          for p in (p_w + (p_in - p_w) * i / 64 for i in range(65))]
    ratio = [(1.0 + k * d_hb / d) / (1.0 + k) for k in ks]  # D*/D
    zeta_end = ZETA_RANGE * max(ratio) ** (1.0 / 3.0)
    steps = max(MIN_STEPS, math.ceil(3.0 * zeta_end**3 / min(ratio) / STEP_RATE))
    grid = (zeta_end, steps)

    def miss(g0: float) -> float:
        return (_end_value(g0, p_w, alpha, d, d_hb, capacity, p50, n, grid) - p_in) / (
            p_in - p_w)

    a, b = 0.5 * dissolved * linear_factor(min(ks), d, d_hb), 2.0 * dissolved * linear_factor(
        max(ks), d, d_hb)
    fa, fb = miss(a), miss(b)
    side = 0
    for _ in range(100):
        c = (a * fb - b * fa) / (fb - fa)
        fc = miss(c)
        if abs(fc) < 1e-10:
            break
        if (fc > 0) == (fb > 0):
            b, fb = c, fc
            if side == -1:
                fa /= 2
            side = -1
        else:
            a, fa = c, fc
            if side == 1:
                fb /= 2
            side = 1
    return c / dissolved
