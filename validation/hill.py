"""2-D reference with Hill binding in the fluid: steady O2 uptake of blood in a straight rigid
tube with facilitated transport by oxyhaemoglobin (validation tool, docs/validation-oxygen.md §7).

Local binding equilibrium everywhere, HbO2 carried with the blood and diffusing with D_Hb
(the red cells' facilitated diffusivity), no axial diffusion. With the content
C(P) = α P + H S(P) and the Kirchhoff potential Φ(P) = α D P + D_Hb H S(P) (S Hill's
saturation, H the binding capacity) the total O2 flux is −∇Φ, so the steady problem is

    u(r) ∂C(P)/∂x = (1/r) ∂/∂r (r ∂Φ(P)/∂r),   P(R) = P_w,   ∂/∂r = 0 at r = 0,

nonlinear in P through C and Φ only. The wall condition imposes P (and so binding equilibrium)
at the wall: the reaction sublayer where HbO2 unloads next to the wall is sqrt(D_Hb/k_off)
≈ 0.3 µm thick, a thousandth of the concentration boundary layer (~100 µm in the paper's
vessels), so the wall receives the facilitated flux. This is the model behind the 1-D
facilitation factor E_Hb (docs/physics.md §3.4), which linearises S between the inlet and wall
PO2; here S is Hill's curve itself.

Discretisation: the radial finite volumes of `axisymmetric` (sinh-clustered at the wall;
Poiseuille velocity averaged over each cell so Σ u w = Q/2π exactly), implicit Euler in x on a
grid clustered at the inlet (x ∝ ξ²), Newton per step (tridiagonal). The wall uptake up to x
is the convective deficit Q C_in − ∫ u C 2πr dr, which the scheme conserves exactly. First
order in the axial step and second order in the radial cells: `hill_uptake` extrapolates both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_banded

from validation.axisymmetric import _cell_average, _radial_faces, richardson


@dataclass(frozen=True)
class HillBlood:
    """Blood O2 properties: solubility α (mol m⁻³ mmHg⁻¹), diffusivity D (m²/s), Hill P50
    (mmHg) and n, binding capacity H (mol/m³), HbO2 diffusivity D_Hb (m²/s)."""

    solubility: float = 1.40e-3
    diffusivity: float = 1.2e-9
    p50: float = 26.8
    n: float = 2.7
    capacity: float = 150.0 * 1.34 / 22.414
    d_hb: float = 5.5e-12

    def saturation(self, p: np.ndarray) -> np.ndarray:
        pp = np.maximum(p, 0.0)
        return pp**self.n / (pp**self.n + self.p50**self.n)

    def dsaturation(self, p: np.ndarray) -> np.ndarray:
        pp = np.maximum(p, 1e-300)
        s = self.saturation(pp)
        return self.n * s * (1.0 - s) / pp

    def content(self, p: np.ndarray) -> np.ndarray:
        return self.solubility * p + self.capacity * self.saturation(p)

    def potential(self, p: np.ndarray) -> np.ndarray:
        return (self.solubility * self.diffusivity * p
                + self.d_hb * self.capacity * self.saturation(p))


def _radial(radius: float, cells: int, stretch: float) -> tuple[np.ndarray, ...]:
    """Faces, ∫ r dr per cell, face conductances r_f/Δ (interior faces, then the wall face)."""
    faces = radius * _radial_faces(cells, stretch)
    centres = 0.5 * (faces[1:] + faces[:-1])
    w = 0.5 * (faces[1:] ** 2 - faces[:-1] ** 2)
    g = faces[1:-1] / (centres[1:] - centres[:-1])
    g_wall = radius / (radius - centres[-1])
    return faces, w, g, g_wall


def hill_march(blood: HillBlood, radius: float, length: float, flow: float, p_in: float,
               p_wall: float, cells: int = 200, steps: int = 400, stretch: float = 8.0,
               power: float = 2.0) -> float:
    """Steady wall uptake (mol/s) of a tube of `length` with Poiseuille flow `flow` (m³/s),
    uniform inlet PO2 `p_in` and wall PO2 `p_wall` (mmHg), on one grid."""
    faces, w, g, g_wall = _radial(radius, cells, stretch)
    vbar = flow / (math.pi * radius**2)
    u = _cell_average(lambda r: 2.0 * vbar * (1.0 - (r / radius) ** 2), faces)
    uw = u * w
    phi_w = float(blood.potential(np.array([p_wall]))[0])
    x = length * np.linspace(0.0, 1.0, steps + 1) ** power
    p = np.full(cells, float(p_in))
    c_old = blood.content(p)
    for dx in np.diff(x):
        a = uw / dx
        for _ in range(50):
            phi = blood.potential(p)
            flux = np.zeros(cells)  # Σ g (Φ_nb − Φ_i) per cell
            flux[:-1] += g * (phi[1:] - phi[:-1])
            flux[1:] -= g * (phi[1:] - phi[:-1])
            flux[-1] += g_wall * (phi_w - phi[-1])
            res = a * (blood.content(p) - c_old) - flux
            dphi = (blood.solubility * blood.diffusivity
                    + blood.d_hb * blood.capacity * blood.dsaturation(p))
            dc = blood.solubility + blood.capacity * blood.dsaturation(p)
            diag = a * dc
            diag[:-1] += g * dphi[:-1]
            diag[1:] += g * dphi[1:]
            diag[-1] += g_wall * dphi[-1]
            ab = np.zeros((3, cells))
            ab[0, 1:] = -g * dphi[1:]  # super-diagonal: ∂res_i/∂P_{i+1}
            ab[1] = diag
            ab[2, :-1] = -g * dphi[:-1]  # sub-diagonal: ∂res_{i+1}/∂P_i
            step = solve_banded((1, 1), ab, -res)
            p = p + step
            if np.abs(step).max() < 1e-11 * max(abs(p_in), 1.0):
                break
        else:  # pragma: no cover - Newton converges in a few iterations here
            raise RuntimeError("hill_march: Newton did not converge")
        c_old = blood.content(p)
    # uptake = inflow − outflow of content (2π Σ u C w is the convective flux)
    c_in = float(blood.content(np.array([p_in]))[0])
    return 2.0 * math.pi * float(np.sum(uw * (c_in - c_old)))


def hill_uptake(blood: HillBlood, radius: float, length: float, flow: float, p_in: float,
                p_wall: float, cells: int = 160, steps: int = 200) -> tuple[float, float]:
    """Wall uptake extrapolated in the radial grid (order 2) and the axial step (order 1),
    and the size of the extrapolation (an error estimate), from three solutions."""
    base = hill_march(blood, radius, length, flow, p_in, p_wall, cells, steps)
    fine_r = hill_march(blood, radius, length, flow, p_in, p_wall, 2 * cells, steps)
    fine_x = hill_march(blood, radius, length, flow, p_in, p_wall, cells, 2 * steps)
    radial = float(richardson(np.array(base), np.array(fine_r), 2.0)) - base
    axial = float(richardson(np.array(base), np.array(fine_x), 1.0)) - base
    best = base + radial + axial
    return best, abs(radial) + abs(axial)


# ------------------------------------------------------------------------------------------------
# pulsatile flow (docs/validation-oxygen.md §9)

@dataclass
class HillPeriodic:
    """Cycle means of the periodic state with Hill binding: wall uptake (mol/s), the periods
    run, the last period's relative change of the uptake, the mass residual of the last
    period (fraction of the inflow)."""

    uptake: float
    periods: int
    change: float
    mass_residual: float


@dataclass
class _Column:
    """The radial finite volumes of `hill_periodic` (blood cells of the dissolved solver)."""

    w: np.ndarray  # ∫ r dr per cell
    g: np.ndarray  # interior face conductances r_f/Δ
    g_wall: float
    phi_w: float  # Φ(P_wall)
    dx: np.ndarray  # axial cell lengths
    p_scale: float  # Newton's step tolerance reference (mmHg)


def _diffuse(blood: HillBlood, col: _Column, c_old: np.ndarray, p: np.ndarray, h: float
             ) -> tuple[np.ndarray, float]:
    """Backward Euler over h of every radial column at once: w (C(P) − C_old) = h Σ g ΔΦ per
    cell, Newton on P; returns P and the wall uptake (mol) of the step."""
    w, g, g_wall, phi_w = col.w, col.g, col.g_wall, col.phi_w
    nb, nx = p.shape
    for _ in range(50):
        phi = blood.potential(p)
        d = phi[1:] - phi[:-1]
        flux = np.zeros_like(p)
        flux[:-1] += g[:, None] * d
        flux[1:] -= g[:, None] * d
        flux[-1] += g_wall * (phi_w - phi[-1])
        res = w[:, None] * (blood.content(p) - c_old) - h * flux
        ds = blood.dsaturation(p)
        dphi = blood.solubility * blood.diffusivity + blood.d_hb * blood.capacity * ds
        diag = w[:, None] * (blood.solubility + blood.capacity * ds)
        diag[:-1] += h * g[:, None] * dphi[:-1]
        diag[1:] += h * g[:, None] * dphi[1:]
        diag[-1] += h * g_wall * dphi[-1]
        # one banded system: the columns (axial cells) one after the other, radius fastest
        ab = np.zeros((3, nb * nx))
        sup = np.zeros((nb, nx))
        sup[1:] = -h * g[:, None] * dphi[1:]
        sub = np.zeros((nb, nx))
        sub[:-1] = -h * g[:, None] * dphi[:-1]
        ab[0] = sup.T.ravel()
        ab[1] = diag.T.ravel()
        ab[2] = sub.T.ravel()
        step = solve_banded((1, 1), ab, -res.T.ravel()).reshape(nx, nb).T
        p = p + step
        if np.abs(step).max() < 1e-10 * col.p_scale:
            break
    else:  # pragma: no cover - Newton converges in a few iterations here
        raise RuntimeError("hill_periodic: Newton did not converge")
    wall = 2.0 * math.pi * h * g_wall * (blood.potential(p[-1]) - phi_w)
    return p, float(wall @ col.dx)


def hill_periodic(blood: HillBlood, tube: Any, flow: Any, p_in: float, p_wall: float,
                  grid: Any, tol: float = 2e-5, max_periods: int = 400) -> HillPeriodic:
    """Periodic O2 uptake of a rigid tube with Womersley flow ``flow`` (PeriodicFlow) and Hill
    binding in the blood: the content C(P) is advected with the profile of
    `axisymmetric.AxisymmetricSolver` (same grid, kernels and backflow rule: the area-mean
    content of the last cell re-enters), and the Kirchhoff potential Φ(P) diffuses radially
    (backward Euler, Newton per half step on every column at once), Strang-split as in the
    dissolved solver. The state is the content, so the scheme conserves O2 exactly. The
    periodic state is reached by running periods from the inlet state until the cycle-mean
    uptake changes by less than ``tol`` (relative) between periods: the layer forgets its
    start on the boundary-layer time, so this is slow for the aorta but needs no linearity."""
    from validation.axisymmetric import (
        AxisymmetricSolver,
        ConstantPO2,
        _advection_rate,
        _implicit_advection,
    )

    base = AxisymmetricSolver(tube, flow, ConstantPO2(p_wall), p_in, grid)
    nb, nx = base.rad.nb, grid.axial
    faces = base.rad.faces[: nb + 1]
    centres = 0.5 * (faces[1:] + faces[:-1])
    w = 0.5 * (faces[1:] ** 2 - faces[:-1] ** 2)
    g = faces[1:-1] / (centres[1:] - centres[:-1])
    g_wall = faces[-1] / (faces[-1] - centres[-1])
    col = _Column(w, g, g_wall, float(blood.potential(np.array([p_wall]))[0]), base.dx,
                  max(abs(p_in), 1.0))
    c_in = float(blood.content(np.array([p_in]))[0])
    dx, dt = base.dx, base.dt

    def diffuse(c_old: np.ndarray, p: np.ndarray, h: float) -> tuple[np.ndarray, float]:
        return _diffuse(blood, col, c_old, p, h)

    p = np.full((nb, nx), float(p_in))
    c = blood.content(p)
    last, change, periods, resid = math.nan, math.inf, 0, math.nan
    cw = 2.0 * math.pi * w
    while periods < max_periods:
        stored0 = float((cw @ c) @ dx)
        uptake = inflow = outflow = 0.0
        for n in range(grid.steps_per_period):
            p, up = diffuse(c, p, 0.5 * dt)
            c = blood.content(p)
            uptake += up
            u0, u1 = base.u[n], base.u[n + 1]
            back = float(w @ c[:, -1] / w.sum())
            th = grid.theta
            r0, fi0, fo0 = _advection_rate(c, u0, base._coef_f, base._coef_b, c_in, back)
            c = _implicit_advection(c - (1.0 - th) * dt * r0, th * dt, u1, base._coef_f,
                                    base._coef_b, c_in, back)
            _, fi1, fo1 = _advection_rate(c, u1, base._coef_f, base._coef_b, c_in, back)
            inflow += dt * cw @ (th * fi1 + (1.0 - th) * fi0)
            outflow += dt * cw @ (th * fo1 + (1.0 - th) * fo0)
            p, up = diffuse(c, p, 0.5 * dt)
            c = blood.content(p)
            uptake += up
        periods += 1
        stored1 = float((cw @ c) @ dx)
        resid = abs(inflow - outflow - uptake - (stored1 - stored0)) / abs(inflow)
        mean = uptake / flow.period
        change = abs(mean / last - 1.0) if math.isfinite(last) else math.inf
        last = mean
        if change < tol:
            break
    return HillPeriodic(last, periods, change, resid)
