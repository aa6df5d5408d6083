"""2-D axisymmetric reference solution of O2 transport in a straight rigid tube.

A validation tool, not part of the simulation path (docs/validation-oxygen.md). It solves, in
PO2 P (mmHg) on r ∈ [0, R] (blood) and optionally [R, R + h] (wall layer), x ∈ [0, L],

    κ_b (∂P/∂t + u(r, t) ∂P/∂x) = (1/r) ∂/∂r (r K_b ∂P/∂r)             (blood)
    κ_w ∂P/∂t = (1/r) ∂/∂r (r K_w ∂P/∂r) − m(P)                          (wall layer)

with κ the O2 capacity (mol m⁻³ mmHg⁻¹) and K = κ D the O2 conductivity. Axial diffusion is
neglected (Pe = v̄ d/D ~ 1e5–1e6 in large arteries: its effect on the wall flux is O(Pe⁻²)).
Dissolved O2: κ_b = α, K_b = α D. Linearised haemoglobin (docs/physics.md §4): κ_b = α(1 + K̄),
K_b = α D (1 + K̄ D_Hb/D) — Hb carried and, if D_Hb > 0, diffusing with the dissolved O2.

u(r, t) is Womersley's fully developed profile of a periodic flow Q(t) (reversal allowed).

Discretisation: finite volumes on a radial grid clustered at the wall (sinh map) and an axial
grid clustered at the inlet (x ∝ ξ^p, the boundary layer starts there); Strang splitting
per step: half a radial-diffusion step (exact: matrix exponential of the fixed radial operator,
which also integrates the wall uptake exactly), one axial advection step (second-order upwind,
θ-scheme, implicit so that the tiny inlet cells impose no step limit), half a diffusion step.
The periodic state is found as the fixed point of the one-period map (affine in the state:
GMRES, a few tens of periods instead of the hundreds the boundary layer needs to forget its
start). Steady flow has an exact x-marching form (`steady_march`): the radial operator's
generalised eigenvectors give the discrete Graetz series, exact in x.

Everything is SI except PO2 (mmHg).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

try:
    from scipy import linalg as sla
    from scipy import special
    from scipy.sparse.linalg import LinearOperator, gmres
except ImportError as exc:  # pragma: no cover - exercised only without scipy
    raise ImportError("validation needs scipy (pip install scipy)") from exc

__all__ = [
    "AxisymmetricSolver",
    "ConstantPO2",
    "Grid",
    "MassTransfer",
    "PeriodicFlow",
    "PeriodicResult",
    "SteadyResult",
    "Tube",
    "WallLayer",
    "backflow_excursion",
    "richardson",
    "steady_march",
    "womersley_shape",
]

LEVEQUE_SH_LOCAL = (8.0 / 9.0) ** (1.0 / 3.0) / math.gamma(4.0 / 3.0)  # Sh_x (x*)^{1/3}, 1.0767...


# ------------------------------------------------------------------------------------------------
# problem description

@dataclass(frozen=True)
class PeriodicFlow:
    """Q(t) = mean + Σ_k cos_k cos(kωt) + sin_k sin(kωt) (m³/s), the YAML `fourier` form."""

    period: float
    mean: float
    cos: tuple[float, ...] = ()
    sin: tuple[float, ...] = ()

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        w = 2.0 * math.pi / self.period
        q = np.full_like(np.asarray(t, dtype=float), self.mean)
        for k, (a, b) in enumerate(self._pairs(), start=1):
            q = q + a * np.cos(k * w * t) + b * np.sin(k * w * t)
        return q

    def _pairs(self) -> list[tuple[float, float]]:
        n = max(len(self.cos), len(self.sin))
        c = list(self.cos) + [0.0] * (n - len(self.cos))
        s = list(self.sin) + [0.0] * (n - len(self.sin))
        return list(zip(c, s, strict=True))

    def harmonics(self) -> list[tuple[int, complex]]:
        """(k, Q̂_k) with Q(t) = mean + Re Σ Q̂_k e^{ikωt}."""
        return [(k, complex(a, -b)) for k, (a, b) in enumerate(self._pairs(), start=1)
                if a != 0.0 or b != 0.0]

    @classmethod
    def sinusoid(cls, mean: float, period: float, reversal: float) -> PeriodicFlow:
        """Q = mean (1 + a sin ωt) with a chosen so that the backward volume per period is the
        fraction ``reversal`` of the forward volume (a = 1 when ``reversal`` = 0: Q just
        touches zero)."""
        a = 1.0 if reversal <= 0.0 else _amplitude_for_reversal(reversal)
        return cls(period=period, mean=mean, sin=(a * mean,))

    def reversal_fraction(self, samples: int = 20000) -> float:
        q = self(np.linspace(0.0, self.period, samples, endpoint=False))
        fwd = q[q > 0].sum()
        return float(-q[q < 0].sum() / fwd) if fwd > 0 else math.inf

    def mean_abs(self, samples: int = 20000) -> float:
        return float(np.abs(self(np.linspace(0.0, self.period, samples, endpoint=False))).mean())


def _amplitude_for_reversal(r: float) -> float:
    """a > 1 with V_back/V_fwd = r for 1 + a sin φ (closed form of both volumes)."""
    from scipy.optimize import brentq

    def ratio(a: float) -> float:
        phi0 = math.asin(1.0 / a)  # backward for φ ∈ (π + φ0, 2π − φ0)
        back = 2.0 * a * math.cos(phi0) - (math.pi - 2.0 * phi0)
        return back / (2.0 * math.pi + back) - r

    return brentq(ratio, 1.0 + 1e-12, 1e4)


@dataclass(frozen=True)
class Tube:
    radius: float
    length: float
    diffusivity: float = 1.2e-9  # m²/s, dissolved O2 in blood
    solubility: float = 1.40e-3  # α, mol m⁻³ mmHg⁻¹
    density: float = 1050.0
    viscosity: float = 3.5e-3
    #: linearised haemoglobin: capacity α(1 + K̄), conductivity α D (1 + K̄ D_Hb/D)
    capacity_factor: float = 1.0
    conductivity_factor: float = 1.0

    def womersley(self, period: float) -> float:
        return self.radius * math.sqrt(2.0 * math.pi / period * self.density / self.viscosity)


@dataclass(frozen=True)
class ConstantPO2:
    """Wall PO2 imposed at r = R (the paper's condition)."""

    po2: float


@dataclass(frozen=True)
class MassTransfer:
    """Wall flux per area k α (P(R) − P_w): a transmural mass-transfer coefficient k (m/s)."""

    k: float
    po2: float


@dataclass(frozen=True)
class WallLayer:
    """A wall of thickness h with its own diffusivity and solubility, coupled to the lumen
    (PO2 and flux continuous at r = R), consuming O2 at ``rate`` (mol m⁻³ s⁻¹; zero order,
    or Michaelis–Menten rate P/(km + P) when ``km`` is given); outer surface at ``outer_po2``
    or no-flux when None."""

    thickness: float
    diffusivity: float
    solubility: float
    rate: float = 0.0
    km: float | None = None
    outer_po2: float | None = None
    cells: int = 8


Wall = ConstantPO2 | MassTransfer | WallLayer


@dataclass(frozen=True)
class Grid:
    radial: int = 48  # blood cells
    axial: int = 64
    radial_stretch: float = 6.0  # sinh clustering at the wall (0: uniform)
    axial_power: float = 2.0  # x ∝ ξ^p near the inlet (1: uniform)
    steps_per_period: int = 200
    theta: float = 0.5  # advection θ-scheme (0.5: Crank–Nicolson)

    def refined(self, factor: int = 2, time: bool = True) -> Grid:
        return Grid(self.radial * factor, self.axial * factor, self.radial_stretch,
                    self.axial_power, self.steps_per_period * (factor if time else 1), self.theta)


# ------------------------------------------------------------------------------------------------
# velocity

def womersley_shape(rho: np.ndarray, alpha: float) -> np.ndarray:
    """Womersley profile of one harmonic divided by its area-mean velocity: u_k(ρ)/(Q̂_k/πR²)
    = (1 − J0(zρ)/J0(z)) / (1 − 2 J1(z)/(z J0(z))), z = α i^{3/2}; Poiseuille 2(1 − ρ²) as α → 0."""
    rho = np.asarray(rho, dtype=float)
    if alpha < 1e-3:
        return (2.0 * (1.0 - rho**2)).astype(complex)
    z = alpha * np.exp(0.75j * math.pi)
    j0 = special.jv(0, z)
    return (1.0 - special.jv(0, z * rho) / j0) / (1.0 - 2.0 * special.jv(1, z) / (z * j0))


def _cell_average(f, faces: np.ndarray, order: int = 6) -> np.ndarray:
    """∫ f(r) r dr / ∫ r dr over each cell (Gauss–Legendre), so Σ u_i w_i is the flow exactly."""
    xg, wg = np.polynomial.legendre.leggauss(order)
    a, b = faces[:-1, None], faces[1:, None]
    r = 0.5 * (a + b) + 0.5 * (b - a) * xg[None, :]
    vals = f(r) * r * (0.5 * (b - a)) * wg[None, :]
    return vals.sum(axis=1) / (0.5 * (faces[1:] ** 2 - faces[:-1] ** 2))


# ------------------------------------------------------------------------------------------------
# radial operator

@dataclass
class _Radial:
    faces: np.ndarray  # m, blood then wall cells
    centres: np.ndarray
    kappa: np.ndarray  # capacity per cell
    w: np.ndarray  # ∫ r dr per cell (m²)
    nb: int  # blood cells
    M: np.ndarray  # dP/dt = M P + b (n × n)
    b: np.ndarray
    uptake_row: np.ndarray  # uptake per unit length = 2π (uptake_row · P + uptake_const)
    uptake_const: float
    consumption: tuple[float, float | None] | None = None  # (rate, km) of the wall layer cells


def _radial_faces(n: int, stretch: float) -> np.ndarray:
    xi = np.linspace(0.0, 1.0, n + 1)
    if stretch <= 0.0:
        return xi
    return 1.0 - np.sinh(stretch * (1.0 - xi)) / math.sinh(stretch)


def _build_radial(tube: Tube, wall: Wall, grid: Grid) -> _Radial:
    R = tube.radius
    kb = tube.solubility * tube.capacity_factor
    Kb = tube.solubility * tube.diffusivity * tube.conductivity_factor
    faces = R * _radial_faces(grid.radial, grid.radial_stretch)
    kappa = [kb] * grid.radial
    cond = [Kb] * grid.radial
    nb = grid.radial
    if isinstance(wall, WallLayer):
        wf = R + wall.thickness * np.linspace(0.0, 1.0, wall.cells + 1)[1:]
        faces = np.concatenate([faces, wf])
        kappa += [wall.solubility] * wall.cells
        cond += [wall.solubility * wall.diffusivity] * wall.cells
    kappa, cond = np.asarray(kappa), np.asarray(cond)
    n = len(faces) - 1
    centres = 0.5 * (faces[1:] + faces[:-1])
    w = 0.5 * (faces[1:] ** 2 - faces[:-1] ** 2)
    # face conductances r_f / (Δ_l/K_l + Δ_r/K_r) between neighbouring cells (series, exact at
    # the blood/wall interface)
    rf = faces[1:-1]
    g = rf / ((rf - centres[:-1]) / cond[:-1] + (centres[1:] - rf) / cond[1:])
    A = np.zeros((n, n))
    i = np.arange(n - 1)
    A[i, i] -= g
    A[i + 1, i + 1] -= g
    A[i, i + 1] += g
    A[i + 1, i] += g
    b = np.zeros(n)
    last = n - 1
    outer_r = faces[-1]
    if isinstance(wall, (ConstantPO2, MassTransfer)):
        resist = (outer_r - centres[last]) / cond[last]
        if isinstance(wall, MassTransfer):
            resist += 1.0 / (wall.k * tube.solubility)
        gw = outer_r / resist
        A[last, last] -= gw
        b[last] += gw * wall.po2
        up_row = np.zeros(n)
        up_row[last] = gw
        up_const = -gw * wall.po2
        consumption = None
    else:
        if wall.outer_po2 is not None:
            gw = outer_r / ((outer_r - centres[last]) / cond[last])
            A[last, last] -= gw
            b[last] += gw * wall.outer_po2
        gi = g[nb - 1]  # the lumen/wall face
        up_row = np.zeros(n)
        up_row[nb - 1], up_row[nb] = gi, -gi
        up_const = 0.0
        consumption = (wall.rate, wall.km)
    cap = kappa * w
    return _Radial(faces, centres, kappa, w, nb, A / cap[:, None], b / cap, up_row, up_const,
                   consumption)


# ------------------------------------------------------------------------------------------------
# steady flow: exact x-marching (discrete Graetz series)

@dataclass
class SteadyResult:
    x_star: np.ndarray  # x/(d Pe)
    theta: np.ndarray  # mixed-cup (P_b − P_w)/(P_in − P_w)
    sherwood: np.ndarray  # local Sh_x = k d/D with k = wall flux/(c_b − c_w)


def steady_march(tube: Tube, wall: ConstantPO2 | MassTransfer, x_star: np.ndarray,
                 grid: Grid = Grid(), q: float = 1e-6) -> SteadyResult:
    """Steady Poiseuille flow, wall condition from x = 0: θ_m(x*) and Sh_x(x*), exact in x.

    B dP̃/dx = A P̃ (P̃ = P − P_w, B = κ u w, A the radial operator) is solved through the
    eigenvectors of the symmetric tridiagonal B^{-1/2} A B^{-1/2}: a finite Graetz series, so
    the only error is the radial grid's (second order; `richardson` removes the leading term).
    """
    rad = _build_radial(tube, wall, grid)
    R, D = tube.radius, tube.diffusivity
    vbar = q / (math.pi * R * R)
    u = _cell_average(lambda r: 2.0 * vbar * (1.0 - (r / R) ** 2), rad.faces)
    B = rad.kappa * u * rad.w
    A = rad.M * (rad.kappa * rad.w)[:, None]
    sb = np.sqrt(B)
    S = A / sb[:, None] / sb[None, :]
    # "stev" (implicit QL): the default bisection driver loses the small eigenvalues next to
    # the ~1e15 ones of the tiny near-wall cells
    lam, V = sla.eigh_tridiagonal(np.diag(S).copy(), np.diag(S, 1).copy(), lapack_driver="stev")
    x = np.asarray(x_star, dtype=float) * vbar * 4.0 * R * R / D
    proj = V.T @ sb  # y0 ∝ B^{1/2} 1
    e = np.exp(np.outer(x, lam))
    flux0 = sb @ sb
    theta = (e * proj**2).sum(axis=1) / flux0
    dtheta_dx = (e * proj**2 * lam).sum(axis=1) / flux0
    # ln θ = −4 ∫ Sh dx*  →  Sh = −(dθ/dx*)/(4 θ)
    dx_dxs = vbar * 4.0 * R * R / D
    sh = -dtheta_dx * dx_dxs / (4.0 * theta)
    return SteadyResult(np.asarray(x_star, dtype=float), theta, sh)


def richardson(coarse: np.ndarray, fine: np.ndarray, order: float = 2.0) -> np.ndarray:
    """Extrapolate a result of grid h and h/2 with error ∝ h^order."""
    f = 2.0**order
    return (f * fine - coarse) / (f - 1.0)


# ------------------------------------------------------------------------------------------------
# periodic flow

@dataclass
class PeriodicResult:
    """Cycle means of the periodic state (mol/s, mmHg)."""

    uptake: float  # wall uptake over [0, L] (through r = R), mol/s
    flux_in: float  # convective O2 flux through the inlet, mol/s
    flux_out: float  # through the outlet, mol/s
    outlet_po2: float  # ∫ J_out dt / (κ_b ∫ Q dt) over a period: flow-weighted outlet PO2
    mass_residual: float  # |in − out − uptake − consumption − Δstored| over the last cycle / in
    cycles: int  # one-period maps evaluated
    uptake_profile: np.ndarray = field(repr=False)  # cycle-mean uptake per axial cell, mol/s
    x_faces: np.ndarray = field(repr=False)
    state: np.ndarray = field(repr=False)  # periodic PO2 field (radial, axial) at t = 0 mod T
    uptake_extension: float = 0.0  # wall uptake of the downstream extension (not the vessel's)


class AxisymmetricSolver:
    """Periodic O2 field of a rigid tube (see the module doc). ``backflow``: PO2 re-entering
    through the outlet during reversal: "mixed" (the area-mean PO2 of the last axial cell,
    the 1-D model's zero-gradient value, with a flat profile), "profile" (each radius re-enters
    with its own last-cell PO2: zero axial gradient at every radius, as if the tube went on
    with its own boundary layer) or a number (mmHg).

    ``extension`` (m): the tube continues downstream of x = L by this length (``extension_
    cells`` uniform cells), with the same wall condition, and the artificial outlet
    (``backflow``) sits at L + extension. The wall
    uptake, the outlet flux and the outlet PO2 are still those of the vessel's own length
    [0, L]. Once the extension exceeds the distance the backflow travels upstream
    (`backflow_excursion`), nothing entering through the artificial outlet reaches x = L and
    the result no longer depends on ``backflow`` (docs/validation-oxygen.md §13)."""

    def __init__(self, tube: Tube, flow: PeriodicFlow, wall: Wall, inlet_po2: float,
                 grid: Grid = Grid(), backflow: str | float = "mixed",
                 extension: float = 0.0, extension_cells: int | None = None) -> None:
        self.tube, self.flow, self.wall, self.grid = tube, flow, wall, grid
        self.p_in, self.backflow = float(inlet_po2), backflow
        self.rad = _build_radial(tube, wall, grid)
        L = tube.length
        xi = np.linspace(0.0, 1.0, grid.axial + 1)
        self.xf = _extended_faces(L * xi**grid.axial_power, extension, extension_cells)
        self.n_own = grid.axial  # axial cells of the vessel itself; the rest is the extension
        self.dx = np.diff(self.xf)
        self.dt = flow.period / grid.steps_per_period
        self._coef_f = _upwind_coefficients(self.xf)
        self._coef_b = _upwind_coefficients(self.xf[-1] - self.xf[::-1])
        self._velocity_table()
        self._diffusion_propagator()

    # -- set-up ----------------------------------------------------------------------------------
    def _velocity_table(self) -> None:
        """u_i(t_n) of every blood cell at the step times t_n = n dt (one period)."""
        R, nb = self.tube.radius, self.rad.nb
        faces = self.rad.faces[: nb + 1]
        area = math.pi * R * R
        t = self.dt * np.arange(self.grid.steps_per_period + 1)
        steady = _cell_average(lambda r: 2.0 * (1.0 - (r / R) ** 2), faces)
        u = np.outer(np.full_like(t, self.flow.mean / area), steady)
        w = 2.0 * math.pi / self.flow.period
        for k, qk in self.flow.harmonics():
            alpha = self.tube.womersley(self.flow.period / k)
            shape = _cell_average(lambda r, a=alpha: womersley_shape(r / R, a), faces)
            u += np.real(np.outer(qk / area * np.exp(1j * k * w * t), shape))
        self.u = u  # (steps + 1, nb)

    def _diffusion_propagator(self) -> None:
        """exp of the augmented radial system [P, 1, U] over dt/2 (U = uptake integral)."""
        n = len(self.rad.kappa)
        Ma = np.zeros((n + 2, n + 2))
        Ma[:n, :n] = self.rad.M
        Ma[:n, n] = self.rad.b
        Ma[n + 1, :n] = 2.0 * math.pi * self.rad.uptake_row
        Ma[n + 1, n] = 2.0 * math.pi * self.rad.uptake_const
        E = sla.expm(Ma * (0.5 * self.dt))
        # entries below 1e-200 (stiff near-wall modes) are subnormal-prone and slow the
        # products down by orders of magnitude; they contribute nothing
        E[np.abs(E) < 1e-200] = 0.0
        self.E = E

    # -- one step / one period ---------------------------------------------------------------------
    def _diffuse(self, P: np.ndarray, acc: dict) -> np.ndarray:
        n = P.shape[0]
        Z = np.vstack([P, np.ones((1, P.shape[1])), np.zeros((1, P.shape[1]))])
        Z = self.E @ Z
        acc["uptake"] += Z[n + 1] * self.dx
        return Z[:n]

    def _consume(self, P: np.ndarray, acc: dict) -> np.ndarray:
        if self.rad.consumption is None:
            return P
        rate, km = self.rad.consumption
        nb, kw = self.rad.nb, self.rad.kappa[self.rad.nb:, None]
        pw = P[nb:]
        if km is None:  # zero order until the PO2 reaches 0
            new = np.maximum(pw - rate * self.dt / kw, 0.0)
        else:  # backward Euler of dP/dt = −(rate/κ) P/(km + P): the positive root
            a = rate * self.dt / kw
            bq = km + a - pw
            new = 0.5 * (-bq + np.sqrt(bq * bq + 4.0 * km * pw))
        acc["consumed"] += 2.0 * math.pi * ((pw - new) * kw * self.rad.w[nb:, None]).sum(0) \
            * self.dx
        P = P.copy()
        P[nb:] = new
        return P

    def _ghosts(self, P: np.ndarray) -> tuple[float, Any]:
        nb = self.rad.nb
        if self.backflow == "profile":
            return self.p_in, P[:nb, -1].copy()
        if self.backflow == "mixed":
            w = self.rad.w[:nb]
            back = float(w @ P[:nb, -1] / w.sum())
        else:
            back = float(self.backflow)
        return self.p_in, back

    def _advect(self, P: np.ndarray, n: int, acc: dict) -> np.ndarray:
        nb, th, dt = self.rad.nb, self.grid.theta, self.dt
        u0, u1 = self.u[n], self.u[n + 1]
        g_in, g_back = self._ghosts(P)
        Pb = P[:nb]
        rate0, fin0, fout0 = _advection_rate(Pb, u0, self._coef_f, self._coef_b, g_in, g_back)
        rhs = Pb - (1.0 - th) * dt * rate0
        new = _implicit_advection(rhs, th * dt, u1, self._coef_f, self._coef_b, g_in, g_back)
        _, fin1, fout1 = _advection_rate(new, u1, self._coef_f, self._coef_b, g_in, g_back)
        cw = 2.0 * math.pi * self.rad.kappa[:nb] * self.rad.w[:nb]
        acc["in"] += dt * cw @ (th * fin1 + (1.0 - th) * fin0)
        acc["out"] += dt * cw @ (th * fout1 + (1.0 - th) * fout0)
        P = P.copy()
        P[:nb] = new
        return P

    def period_map(self, P: np.ndarray) -> tuple[np.ndarray, dict]:
        nx = len(self.dx)
        acc = {"uptake": np.zeros(nx), "consumed": np.zeros(nx), "in": 0.0, "out": 0.0}
        for n in range(self.grid.steps_per_period):
            P = self._diffuse(P, acc)
            P = self._consume(P, acc)
            P = self._advect(P, n, acc)
            P = self._diffuse(P, acc)
        return P, acc

    def stored(self, P: np.ndarray, cells: slice = slice(None)) -> float:
        return float(2.0 * math.pi * ((self.rad.kappa * self.rad.w) @ P[:, cells])
                     @ self.dx[cells])

    # -- periodic state ----------------------------------------------------------------------------
    def initial_state(self) -> np.ndarray:
        """Inlet PO2 everywhere in the blood; the wall layer at its own steady state is not
        needed (the fixed-point solve removes any start)."""
        n = len(self.rad.kappa)
        return np.full((n, len(self.dx)), self.p_in)

    def periodic(self, tol: float = 1e-9, maxiter: int = 200) -> PeriodicResult:
        """Fixed point of the one-period map. Linear problems (no Michaelis–Menten or clipped
        consumption) use GMRES on (I − Φ) x = F(0); otherwise plain iteration."""
        shape = (len(self.rad.kappa), len(self.dx))
        count = 0
        linear = self.rad.consumption is None or self.rad.consumption[0] == 0.0
        if linear:
            f0, _ = self.period_map(np.zeros(shape))

            def matvec(v: np.ndarray) -> np.ndarray:
                nonlocal count
                count += 1
                fv, _ = self.period_map(v.reshape(shape))
                return v - (fv - f0).ravel()

            op = LinearOperator((f0.size, f0.size), matvec=matvec)
            x0 = self.initial_state().ravel()
            x, info = gmres(op, f0.ravel(), x0=x0, rtol=tol, restart=60, maxiter=maxiter)
            if info != 0:
                warnings.warn(f"periodic state: GMRES stopped after {count} periods without "
                              f"reaching rtol {tol}", RuntimeWarning, stacklevel=2)
            P = x.reshape(shape)
        else:
            P = self.initial_state()
            for _ in range(maxiter):
                new, _ = self.period_map(P)
                count += 1
                if np.max(np.abs(new - P)) < tol * max(abs(self.p_in), 1.0):
                    P = new
                    break
                P = new
        end, acc = self.period_map(P)
        T = self.flow.period
        stored = self.stored(end) - self.stored(P)
        resid = acc["in"] - acc["out"] - acc["uptake"].sum() - acc["consumed"].sum() - stored
        kb = self.tube.solubility * self.tube.capacity_factor
        own = slice(0, self.n_own)
        out = acc["out"]
        if self.n_own < len(self.dx):
            # the flux through x = L from the balance of [0, L] over the period (its storage
            # change is the periodic state's residual, ≤ 1e-13 of the inflow)
            out = acc["in"] - acc["uptake"][own].sum() - acc["consumed"][own].sum() \
                - self.stored(end, own) + self.stored(P, own)
        return PeriodicResult(
            uptake=float(acc["uptake"][own].sum() / T), flux_in=acc["in"] / T,
            flux_out=out / T,
            outlet_po2=out / (kb * self.flow.mean * T) if self.flow.mean > 0 else math.nan,
            mass_residual=abs(resid) / max(abs(acc["in"]), 1e-300), cycles=count + 1,
            uptake_profile=acc["uptake"][own] / T, x_faces=self.xf[: self.n_own + 1],
            state=end, uptake_extension=float(acc["uptake"][self.n_own:].sum() / T))


def _extended_faces(xf: np.ndarray, extension: float, cells: int | None) -> np.ndarray:
    """The vessel's axial faces followed by ``cells`` uniform cells up to L + extension; by
    default cells of the vessel's last cell size (its largest: the grid is clustered at the
    inlet), at most 32 of them (the layer there is nearly developed and varies slowly in x;
    only the part within the backflow excursion of x = L matters, §13 checks the count)."""
    if extension <= 0.0:
        return xf
    n = cells or min(32, max(1, math.ceil(extension / (xf[-1] - xf[-2]) - 1e-9)))
    return np.concatenate([xf, xf[-1] + extension * np.arange(1, n + 1) / n])


def backflow_excursion(tube: Tube, flow: PeriodicFlow, radial: int = 400,
                       samples: int = 4000) -> float:
    """How far (m) fluid travels upstream in the periodic Womersley flow: for every radius the
    largest backward displacement X(t₁) − X(t₂), t₁ < t₂, of a fluid particle held at that
    radius (X = ∫ u dt over two periods, so a backward stretch across the period boundary
    counts), maximised over the radius. Axial diffusion is neglected in the reference, so
    information from an outlet placed this far downstream of x = L never reaches x = L except
    by hopping radii through radial diffusion, which is slow against the period here (the
    boundary layer's time scale is 3–52 s, docs/validation-oxygen.md §3)."""
    R = tube.radius
    rho = (np.arange(radial) + 0.5) / radial
    t = np.linspace(0.0, 2.0 * flow.period, 2 * samples, endpoint=False)
    area = math.pi * R * R
    u = np.outer(np.full_like(t, flow.mean / area), 2.0 * (1.0 - rho**2))
    w = 2.0 * math.pi / flow.period
    for k, qk in flow.harmonics():
        shape = womersley_shape(rho, tube.womersley(flow.period / k))
        u = u + np.real(np.outer(qk / area * np.exp(1j * k * w * t), shape))
    x = np.cumsum(u, axis=0) * (t[1] - t[0])
    back = np.maximum.accumulate(x, axis=0) - x
    return float(back.max())


# ------------------------------------------------------------------------------------------------
# axial advection kernels

def _upwind_coefficients(xf: np.ndarray) -> np.ndarray:
    """Second-order upwind FV for flow towards +x on faces ``xf``: the cell's rate is
    c0 P_j + c1 P_{j−1} + c2 P_{j−2} (times the speed), P_{−1} the inflow value at x = xf[0].
    Face value at x_{j+1/2}: linear extrapolation from cells j−1 and j."""
    xc = 0.5 * (xf[1:] + xf[:-1])
    dx = np.diff(xf)
    prev = np.concatenate([[xf[0]], xc[:-1]])  # position of P_{j−1} (the inflow face for j = 0)
    s = (xf[1:] - xc) / (xc - prev)
    s_prev = np.concatenate([[0.0], s[:-1]])
    c0 = (1.0 + s) / dx
    c1 = -(s + 1.0 + s_prev) / dx
    c2 = s_prev / dx
    return np.vstack([c0, c1, c2, s])


def _shifted(Pl: np.ndarray, ghost: float) -> tuple[np.ndarray, np.ndarray]:
    s1 = np.empty_like(Pl)
    s1[:, 0] = ghost
    s1[:, 1:] = Pl[:, :-1]
    s2 = np.zeros_like(Pl)
    s2[:, 1] = ghost
    s2[:, 2:] = Pl[:, :-2]
    return s1, s2


def _advection_rate(P: np.ndarray, u: np.ndarray, cf: np.ndarray, cb: np.ndarray, g_in: float,
                    g_back: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """u ∂P/∂x per cell and the boundary fluxes per row (u·P_face; inflow through x = 0,
    outflow through x = L, both signed positive in +x)."""
    rate = np.zeros_like(P)
    fin = np.zeros(P.shape[0])
    fout = np.zeros(P.shape[0])
    fwd = u >= 0.0
    for mask, coef, ghost, flip in ((fwd, cf, g_in, False), (~fwd, cb, g_back, True)):
        if not mask.any():
            continue
        Pl = P[mask][:, ::-1] if flip else P[mask]
        ua = np.abs(u[mask])[:, None]
        ghost = ghost[mask] if np.ndim(ghost) else ghost  # per-row ghosts ("profile")
        s1, s2 = _shifted(Pl, ghost)
        r = ua * (coef[0] * Pl + coef[1] * s1 + coef[2] * s2)
        s_last = coef[3][-1]
        face_out = Pl[:, -1] + s_last * (Pl[:, -1] - Pl[:, -2])
        a = np.abs(u[mask])
        if flip:
            rate[mask] = r[:, ::-1]
            fin[mask] = -a * face_out  # leaves through x = 0
            fout[mask] = -a * ghost  # enters through x = L
        else:
            rate[mask] = r
            fin[mask] = a * ghost
            fout[mask] = a * face_out
    return rate, fin, fout


def _implicit_advection(rhs: np.ndarray, tdt: float, u: np.ndarray, cf: np.ndarray,
                        cb: np.ndarray, g_in: float, g_back: float) -> np.ndarray:
    """Solve P + tdt·u ∂P/∂x = rhs: every row is lower-triangular (bandwidth 2) in its own
    upwind order; all rows in one banded solve."""
    nr, nx = rhs.shape
    fwd = u >= 0.0
    coef = np.where(fwd[None, :, None], cf[:3, None, :], cb[:3, None, :])  # (3, nr, nx)
    ghost = np.where(fwd, g_in, g_back)
    b = np.where(fwd[:, None], rhs, rhs[:, ::-1]).copy()
    k = tdt * np.abs(u)[:, None]
    b[:, 0] -= k[:, 0] * coef[1][:, 0] * ghost
    b[:, 1] -= k[:, 0] * coef[2][:, 1] * ghost
    ab = np.zeros((3, nr * nx))
    ab[0] = (1.0 + k * coef[0]).ravel()
    sub1 = np.zeros((nr, nx))
    sub1[:, :-1] = (k * coef[1])[:, 1:]  # a[j, j−1] stored at column j−1
    sub2 = np.zeros((nr, nx))
    sub2[:, :-2] = (k * coef[2])[:, 2:]
    ab[1], ab[2] = sub1.ravel(), sub2.ravel()
    x = sla.solve_banded((2, 0), ab, b.ravel()).reshape(nr, nx)
    return np.where(fwd[:, None], x, x[:, ::-1])
