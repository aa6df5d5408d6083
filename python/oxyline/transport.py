"""The ``oxygen:`` and ``species:`` model sections: checking, unit conversion (mmHg at the file
boundary for oxygen, SI inside) and the canonical ``transport`` description for the core.

Oxygen (docs/physics.md §2-4)::

    oxygen:
      inlet: {po2: 85.0}                 # mmHg; or {time: [..], po2: [..]}, or {fourier: {..}} in mmHg
      inlets: {inlet_bc: {po2: 90}}      # optional per-inlet overrides
      hemoglobin: none                   # none | hill | linearized
      hill: {p50: 26.8, n: 2.7, hb: 150, huefner: 1.34}     # mmHg, -, g/L, mL O2/g
      linearized: {p_low: 60, p_high: 85}                    # secant end points (mmHg)
      solubility: 1.40e-3                # mol m^-3 mmHg^-1
      diffusivity: 1.2e-9                # m^2/s
      wall: {model: leveque, po2: 60.0, shear: cycle-mean}
      per_vessel: {ICA: {wall: {...}, cells_per_segment: 4}}
      cells_per_segment: 1               # transport cells per flow segment (sharper fronts)
      outlet_backflow: zero-gradient     # or {outlet_bc: {po2: ..}}
      formulation: conservative          # or tl-quasisteady (the paper's literal KCL form)
      reference_pressure: 0              # mmHg: pressure at which the vessel radii hold
      initial: {po2: 85}                 # default: the inlet value at t = 0

Wall models: ``none``; ``flux`` {flux: mol m^-2 s^-1}; ``mass-transfer`` {k: m/s, po2};
``tissue`` (oxygen only: a consuming wall layer behind a luminal closure, docs/oxygen.md
"Wall/tissue compartment");
``leveque`` {po2, shear: cycle-mean | instantaneous | relaxed, enhancement, hb_facilitation};
``graetz`` {po2, enhancement}; ``permeability`` {permeability: m/s, po2}. ``permeability`` in the
mass-transfer, Lévêque and Graetz models adds a wall resistance in series (physics C8).
``hb_facilitation: {d_hb: 5.5e-12}`` multiplies the Lévêque/Graetz coefficient by
E_Hb = (1 + K)^(1/3) (1 + K D_Hb/D)^(2/3), K the Hill secant between the inlet and wall PO2
(docs/physics.md §3.4).

Other species (docs/physics.md §5), all SI (concentrations in mol/m^3)::

    species:
      - name: ldl
        diffusivity: 5e-11
        decay: 0.0                       # 1/s
        binding: {kind: linear, partition: 2.0}   # none | linear | saturable {b_max, k_d, n}
        wall: {model: permeability, permeability: 2e-8, concentration: 0.0}
        inlet: {concentration: 1.0}      # or time/concentration tables, or
                                         # {bolus: {gamma_variate: {k: .., t0: .., a: .., b: ..}}}
        backflow: {outlet_bc: {concentration: 0.0}}
        initial: 0.0

All species share one grid of transport cells: ``transport: {cells_per_segment: m,
cells_per_vessel: {name: m}}`` (or the oxygen section's ``cells_per_segment`` and
``per_vessel: {name: {cells_per_segment: m}}``, which win) splits every volume node into m
cells in series (docs/physics.md §5: a front spreads by sqrt(x dx/m) instead of sqrt(x dx)).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Mapping
from typing import Any

from oxyline import facilitation
from oxyline.errors import ModelError
from oxyline.units import MMHG

MOLAR_VOLUME_ML = 22.414  # mL O2 (STPD) per mmol
OXYGEN_KEYS = {
    "inlet", "inlets", "hemoglobin", "hill", "linearized", "solubility", "diffusivity", "wall",
    "per_vessel", "outlet_backflow", "formulation", "reference_pressure", "initial", "name",
    "cells_per_segment",
}
WALL_KEYS = {
    "none": {"model"},
    "flux": {"model", "flux"},
    "mass-transfer": {"model", "k", "po2", "concentration", "permeability"},
    "leveque": {"model", "po2", "concentration", "shear", "enhancement", "permeability",
                "hb_facilitation"},
    "graetz": {"model", "po2", "concentration", "enhancement", "permeability", "hb_facilitation",
               "flow"},
    "permeability": {"model", "permeability", "po2", "concentration"},
}
SPECIES_KEYS = {"name", "diffusivity", "decay", "binding", "wall", "inlet", "inlets", "backflow",
                "initial", "per_vessel", "units"}
TRANSPORT_KEYS = {"reference_pressure", "formulation", "velocity_threshold", "cells_per_segment",
                  "cells_per_vessel"}
MAX_CELLS_PER_SEGMENT = 10_000
TISSUE_KEYS = {"model", "thickness", "diffusivity", "solubility", "consumption", "outer",
               "radial_cells", "hypoxic_po2", "boundary_layer"}
#: luminal closures a tissue wall accepts (a conductance against the wall's own innermost PO2)
TISSUE_BOUNDARY_LAYERS = ("leveque", "graetz", "mass-transfer", "permeability")
#: default hypoxia threshold (mmHg): hypoxia markers (pimonidazole adducts) form below ~10 mmHg,
#: the usual histological definition of hypoxic tissue (docs/physics.md §3.7)
HYPOXIC_PO2 = 10.0
TISSUE_RADIAL_CELLS = 4
FORMULATIONS = ("conservative", "tl-quasisteady")
#: `graetz` wall's flow: inlet-renewal (the default since the inlet-renewal fit, docs/physics.md §3.6), or
#: the cycle-mean closures of the forward flow (the default before) or of |Q|
MEAN_FLOWS = ("inlet-renewal", "forward-mean", "cycle-mean")
#: samples per period of a wall flux given as a Python callable (linear in between)
FLUX_SAMPLES_PER_PERIOD = 200
D_HB_DEFAULT = 5.5e-12  # m^2/s, facilitated diffusivity of HbO2 (docs/physics.md §3.4)


class HemoglobinFacilitationWarning(UserWarning):
    """``hemoglobin: hill`` (or ``linearized``) with a boundary-layer wall closure whose
    haemoglobin facilitation is switched off: the wall flux then comes from the dissolved O2
    only and under-predicts the uptake 2.6–3.1× (docs/physics.md §3.4)."""


def _err(element: str, message: str) -> ModelError:
    return ModelError(f"{element}: {message}")


def _check(d: Any, allowed: set[str], element: str) -> Mapping[str, Any]:
    if not isinstance(d, Mapping):
        raise _err(element, f"expected a mapping, got {d!r}")
    for k in d:
        if k not in allowed:
            raise _err(element, f"unknown key '{k}' (allowed: {', '.join(sorted(allowed))})")
    return d


def _num(v: Any, element: str, key: str, minimum: float | None = None,
         positive: bool = False) -> float:
    if isinstance(v, str):
        try:
            v = float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise _err(element, f"'{key}' must be a finite number, got {v!r}")
    x = float(v)
    if positive and x <= 0:
        raise _err(element, f"'{key}' must be > 0, got {x}")
    if minimum is not None and x < minimum:
        raise _err(element, f"'{key}' must be >= {minimum}, got {x}")
    return x


def _cells(v: Any, element: str) -> int:
    """``cells_per_segment``: an integer m >= 1 (transport cells per flow segment)."""
    ok = not isinstance(v, bool) and (
        isinstance(v, int) or (isinstance(v, float) and v.is_integer()))
    if not ok or not 1 <= v <= MAX_CELLS_PER_SEGMENT:
        raise _err(element, f"'cells_per_segment' must be an integer between 1 and "
                            f"{MAX_CELLS_PER_SEGMENT}, got {v!r}")
    return int(v)


def _wave(spec: Any, key: str, scale: float, element: str, period: float | None,
          duration: float | None = None) -> dict[str, Any]:
    """Canonical waveform of a concentration-like quantity given as a number, a
    {key: x} mapping, {time, key} tables, {fourier: ...} or a gamma-variate bolus."""
    if not isinstance(spec, Mapping):
        return {"kind": "constant", "value": scale * _num(spec, element, key, minimum=0.0)}
    if "bolus" in spec:
        return _bolus(spec["bolus"], scale, element, duration)
    if "fourier" in spec:
        fo = _check(spec["fourier"], {"period", "mean", "cos", "sin"}, f"{element} fourier")
        return {"kind": "fourier", "period": _num(fo.get("period", period or 1.0), element, "period",
                                                   positive=True),
                "mean": scale * _num(fo.get("mean", 0.0), element, "mean"),
                "cos": [scale * _num(x, element, "cos") for x in fo.get("cos", [])],
                "sin": [scale * _num(x, element, "sin") for x in fo.get("sin", [])]}
    if "time" in spec:
        t = [_num(x, element, "time") for x in spec["time"]]
        if key not in spec:
            raise _err(element, f"has 'time' but no '{key}' table")
        v = [scale * _num(x, element, key, minimum=0.0) for x in spec[key]]
        if len(t) != len(v) or len(t) < 2:
            raise _err(element, f"'time' and '{key}' need the same length >= 2")
        if any(b <= a for a, b in itertools.pairwise(t)):
            raise _err(element, "'time' must be strictly increasing")
        return {"kind": "table", "time": t, "value": v,
                "interpolation": spec.get("interpolation", "linear")}
    if key in spec:
        return {"kind": "constant", "value": scale * _num(spec[key], element, key, minimum=0.0)}
    raise _err(element, f"needs '{key}' (a number, 'time' + '{key}' tables, or 'fourier')")


def _bolus(spec: Any, scale: float, element: str, duration: float | None) -> dict[str, Any]:
    """Gamma-variate bolus c(t) = K (t − t0)^a exp(−(t − t0)/b), t > t0, sampled as a table
    that spans the whole run (tables repeat with their own length)."""
    el = f"{element} bolus"
    g = _check(_check(spec, {"gamma_variate"}, el).get("gamma_variate"), {"k", "t0", "a", "b"},
               f"{el} gamma_variate")
    k = _num(g.get("k"), el, "k", minimum=0.0)
    t0 = _num(g.get("t0", 0.0), el, "t0", minimum=0.0)
    a = _num(g.get("a"), el, "a", minimum=0.0)
    b = _num(g.get("b"), el, "b", positive=True)
    end = max(duration or 0.0, t0 + 40.0 * b * (1.0 + a)) + 1.0
    n = 4000
    times = [end * i / (n - 1) for i in range(n)]
    vals = [scale * (k * (t - t0) ** a * math.exp(-(t - t0) / b) if t > t0 else 0.0)
            for t in times]
    return {"kind": "table", "time": times, "value": vals, "interpolation": "linear"}


def _table_mean(w: Mapping[str, Any]) -> float:
    """Time mean of a linear table (the Hb facilitation secant of a tabulated inlet PO2)."""
    t, v = w["time"], w["value"]
    area = sum(0.5 * (b - a) * (x + y) for a, b, x, y in zip(t, t[1:], v, v[1:], strict=False))
    return area / (t[-1] - t[0])


def _hill(ox: Mapping[str, Any], alpha_mmhg: float) -> dict[str, float]:
    h = _check(ox.get("hill", {}) or {}, {"p50", "n", "hb", "huefner"}, "oxygen hill")
    p50 = _num(h.get("p50", 26.8), "oxygen hill", "p50", positive=True)
    n = _num(h.get("n", 2.7), "oxygen hill", "n", positive=True)
    hb = _num(h.get("hb", 150.0), "oxygen hill", "hb", positive=True)
    huefner = _num(h.get("huefner", 1.34), "oxygen hill", "huefner", positive=True)
    # g/L × mL/g = mL O2 per L blood; / 22.414 mL/mmol = mmol/L = mol/m^3
    capacity = hb * huefner / MOLAR_VOLUME_ML
    return {"p50": p50, "n": n, "capacity": capacity, "alpha": alpha_mmhg}


def _facilitation(spec: Any, h: dict[str, float] | None, d: float, p_in: float, p_w: float,
                  element: str) -> float:
    """E_Hb (docs/physics.md §3.4): (1 + K̄)^(1/3) (1 + K̄ D_Hb/D)^(2/3) for linearised binding
    with the Hill secant K̄; for Hill binding the nonlinear Lévêque layer's factor
    (`oxyline.facilitation`, validated against the 2-D solution with Hill binding)."""
    if spec is False:
        return 1.0
    if h is None:
        raise _err(element, "hb_facilitation needs hemoglobin: hill or linearized")
    f = _check(spec if isinstance(spec, Mapping) else {}, {"d_hb"}, f"{element} hb_facilitation")
    d_hb = _num(f.get("d_hb", D_HB_DEFAULT), element, "d_hb", minimum=0.0)
    law = (facilitation.secant_factor if h.get("linearized") else facilitation.hill_factor)
    return law(p_in, p_w, h["alpha"], d, d_hb, h["capacity"], h["p50"], h["n"])


def _flux_row(v: Any, element: str) -> list[float]:
    if isinstance(v, (int, float, str)) and not isinstance(v, bool):
        return [_num(v, element, "flux")]
    try:
        vals = list(v)
    except TypeError:
        raise _err(element, f"'flux' must be a number or a list of numbers, got {v!r}") from None
    if not vals:
        raise _err(element, "'flux' needs at least one value")
    return [_num(x, element, "flux") for x in vals]


def _flux(spec: Any, element: str, period: float | None, duration: float | None) -> Any:
    """Canonical prescribed wall flux (mol m^-2 s^-1): a number, one value per segment, a
    {time, flux} table (rows of one value or one per segment; linear in time, repeating with
    its own length) or a Python callable f(t) -> number or per-segment values, sampled every
    period/FLUX_SAMPLES_PER_PERIOD over the whole run (docs/physics.md §3.1 C1)."""
    if callable(spec):
        p = period or 1.0
        end = max(duration or p, p) + p
        n = math.ceil(end / p * FLUX_SAMPLES_PER_PERIOD) + 1
        times = [end * i / (n - 1) for i in range(n)]
        rows = [_flux_row(spec(t), element) for t in times]
        if len({len(r) for r in rows}) != 1:
            raise _err(element, "the flux callable must return the same number of values at "
                                "every time")
        return {"time": times, "values": rows}
    if isinstance(spec, Mapping):
        _check(spec, {"time", "flux"}, f"{element} flux")
        if "time" not in spec or "flux" not in spec:
            raise _err(element, "a flux table needs 'time' and 'flux'")
        t = [_num(x, element, "time") for x in spec["time"]]
        rows = [_flux_row(r, element) for r in spec["flux"]]
        if len(t) != len(rows) or len(t) < 2:
            raise _err(element, "flux 'time' and 'flux' need the same length >= 2")
        if any(b <= a for a, b in itertools.pairwise(t)):
            raise _err(element, "flux 'time' must be strictly increasing")
        if len({len(r) for r in rows}) != 1:
            raise _err(element, "every row of a flux table needs the same number of values")
        return {"time": t, "values": rows}
    row = _flux_row(spec, element)
    return row[0] if not isinstance(spec, (list, tuple)) and len(row) == 1 else row


def _wall(spec: Any, element: str, conc_of: Any, conc_key: str, h: dict[str, float] | None,
          d: float, p_in: float | None, period: float | None = None,
          duration: float | None = None) -> dict[str, Any]:
    """Canonical wall closure. ``conc_of(mapping)`` reads the wall concentration (PO2 for
    oxygen, concentration for other species)."""
    if spec is None or spec == "none":
        return {"model": "none"}
    if isinstance(spec, str):
        spec = {"model": spec}
    if not isinstance(spec, Mapping) or "model" not in spec:
        raise _err(element, "wall needs a 'model' (none, flux, mass-transfer, leveque, graetz, "
                            "permeability)")
    model = str(spec["model"])
    if model not in WALL_KEYS:
        raise _err(element, f"unknown wall model '{model}' (expected {', '.join(WALL_KEYS)})")
    _check(spec, WALL_KEYS[model], f"{element} wall")
    out: dict[str, Any] = {"model": model}
    if model == "none":
        return out
    if model == "flux":
        if "flux" not in spec:
            raise _err(element, "the flux wall model needs 'flux' (mol m^-2 s^-1)")
        out["flux"] = _flux(spec["flux"], element, period, duration)
        return out
    cw = conc_of(spec)
    if model == "permeability":
        out.update(permeability=_num(spec.get("permeability"), element, "permeability",
                                     minimum=0.0), tissue_concentration=cw)
        return out
    out["wall_concentration"] = cw
    if "permeability" in spec:
        out["permeability"] = _num(spec["permeability"], element, "permeability", positive=True)
    if model == "mass-transfer":
        out["k"] = _num(spec.get("k"), element, "k", minimum=0.0)
        return out
    enh = _num(spec.get("enhancement", 1.0), element, "enhancement", minimum=0.0)
    fac = spec.get("hb_facilitation")
    if fac is None and h is not None:
        fac = {}  # haemoglobin: facilitated boundary-layer transport by default (§3.4)
    if fac is False and h is not None:
        warnings.warn(f"{element}: hb_facilitation is off with haemoglobin: the {model} wall "
                      "flux comes from the dissolved O2 only and under-predicts the uptake "
                      "2.6-3.1x (docs/physics.md §3.4)", HemoglobinFacilitationWarning,
                      stacklevel=2)
    if fac not in (None, False):
        if p_in is None:
            raise _err(element, "hb_facilitation needs a constant inlet PO2")
        enh *= _facilitation(fac, h, d, p_in, cw / h["alpha"] if h else 0.0, element)
    out["enhancement"] = enh
    if model == "graetz" and "flow" in spec:
        if spec["flow"] not in MEAN_FLOWS:
            raise _err(element, f"flow must be one of {MEAN_FLOWS}, got {spec['flow']!r}")
        out["flow"] = spec["flow"]
    if model == "leveque":
        shear = spec.get("shear", "cycle-mean")
        if shear not in ("cycle-mean", "instantaneous", "relaxed"):
            raise _err(element, "shear must be 'cycle-mean', 'instantaneous' or 'relaxed', "
                                f"got {shear!r}")
        out["shear"] = shear
    return out


def _is_tissue(spec: Any) -> bool:
    return spec == "tissue" or (isinstance(spec, Mapping) and spec.get("model") == "tissue")


def _tissue(spec: Any, element: str, alpha: float, h: dict[str, float] | None, d: float,
            p_in: float | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """(canonical luminal closure, canonical tissue layer) of ``wall: {model: tissue}``.

    SI except PO2 (mmHg): thickness m, diffusivity m^2/s, solubility mol m^-3 mmHg^-1 (default:
    the blood's), consumption {vmax: mol m^-3 s^-1, km: mmHg} (Michaelis–Menten) or
    {rate: mol m^-3 s^-1} (zero order), outer {po2: mmHg} or no-flux, hypoxic_po2 mmHg. The
    core works in wall concentrations u = α_t P and the partition φ = α_t/α."""
    el = f"{element} wall (tissue)"
    t = _check({"model": "tissue"} if spec == "tissue" else spec, TISSUE_KEYS, el)
    for key in ("thickness", "diffusivity", "consumption"):
        if key not in t:
            raise _err(el, f"needs '{key}'")
    alpha_t = _num(t.get("solubility", alpha), el, "solubility", positive=True)
    cons = t["consumption"]
    if isinstance(cons, Mapping) and "rate" in cons:
        _check(cons, {"rate"}, f"{el} consumption")
        consumption = {"kind": "zero-order", "rate": _num(cons["rate"], el, "rate", minimum=0.0)}
    elif isinstance(cons, Mapping) and "vmax" in cons:
        _check(cons, {"vmax", "km"}, f"{el} consumption")
        consumption = {"kind": "michaelis-menten",
                       "vmax": _num(cons["vmax"], el, "vmax", minimum=0.0),
                       "km": alpha_t * _num(cons.get("km"), el, "km (mmHg)", minimum=0.0)}
    else:
        raise _err(el, "consumption must be {vmax, km} (Michaelis–Menten) or {rate} (zero "
                       f"order), got {cons!r}")
    outer = t.get("outer", "no-flux")
    if outer == "no-flux":
        outer_c: dict[str, Any] = {"kind": "no-flux"}
    elif isinstance(outer, Mapping) and set(outer) == {"po2"}:
        outer_c = {"kind": "concentration",
                   "value": alpha_t * _num(outer["po2"], el, "outer po2", minimum=0.0)}
    else:
        raise _err(el, f"outer must be 'no-flux' or {{po2: mmHg}}, got {outer!r}")
    cells = t.get("radial_cells", TISSUE_RADIAL_CELLS)
    if isinstance(cells, bool) or not isinstance(cells, (int, float)) or cells != int(cells) \
            or not 1 <= cells <= 1000:
        raise _err(el, f"'radial_cells' must be an integer between 1 and 1000, got {cells!r}")
    tissue = {
        "thickness": _num(t["thickness"], el, "thickness", positive=True),
        "diffusivity": _num(t["diffusivity"], el, "diffusivity", positive=True),
        "partition": alpha_t / alpha, "consumption": consumption, "outer": outer_c,
        "radial_cells": int(cells),
        "hypoxic_threshold": alpha_t * _num(t.get("hypoxic_po2", HYPOXIC_PO2), el,
                                            "hypoxic_po2", minimum=0.0),
    }
    bl = t.get("boundary_layer", {"model": "leveque"})
    if isinstance(bl, str):
        bl = {"model": bl}
    if not isinstance(bl, Mapping) or bl.get("model") not in TISSUE_BOUNDARY_LAYERS:
        raise _err(el, f"boundary_layer must be one of {', '.join(TISSUE_BOUNDARY_LAYERS)}, "
                       f"got {bl!r}")
    for key in ("po2", "concentration", "hb_facilitation"):
        if key in bl:
            raise _err(el, f"boundary_layer takes no '{key}' (the wall's innermost PO2 is the "
                           "wall value; give the enhancement directly)")
    if bl.get("shear", "cycle-mean") != "cycle-mean":
        raise _err(el, "boundary_layer shear must be cycle-mean with a tissue wall")
    lumen = _wall({**bl, "po2": 0.0}, el, lambda s: alpha * _num(s["po2"], el, "po2"), "po2", h,
                  d, p_in)
    return lumen, tissue


def _oxygen(ox: Mapping[str, Any], period: float | None, duration: float | None) -> dict[str, Any]:
    _check(ox, OXYGEN_KEYS, "oxygen")
    el = "oxygen"
    alpha = _num(ox.get("solubility", 1.40e-3), el, "solubility", positive=True)  # per mmHg
    d = _num(ox.get("diffusivity", 1.2e-9), el, "diffusivity", positive=True)
    if "inlet" not in ox:
        raise _err(el, "needs 'inlet' (e.g. {po2: 85})")
    inlet = _wave(ox["inlet"], "po2", alpha, f"{el} inlet", period, duration)
    p_in = inlet["value"] / alpha if inlet["kind"] == "constant" else (
        inlet["mean"] / alpha if inlet["kind"] == "fourier" else None)
    # the Hb facilitation secant's inlet PO2: a tabulated inlet's time mean
    p_fac = p_in if p_in is not None else _table_mean(inlet) / alpha
    mode = str(ox.get("hemoglobin", "none"))
    h: dict[str, float] | None = None
    binding: dict[str, Any] = {"kind": "none"}
    alpha_si = alpha / MMHG
    if mode in ("hill", "linearized"):
        h = _hill(ox, alpha)
        binding = {"kind": "hill", "solubility": alpha_si, "p50": h["p50"] * MMHG, "n": h["n"],
                   "capacity": h["capacity"]}
        if mode == "linearized":
            h["linearized"] = 1.0
            lin = _check(ox.get("linearized", {}) or {}, {"p_low", "p_high"}, "oxygen linearized")
            wall = ox.get("wall") if isinstance(ox.get("wall"), Mapping) else {}
            p_low = _num(lin.get("p_low", (wall or {}).get("po2", 60.0)), el, "p_low", positive=True)
            p_high = _num(lin.get("p_high", p_in if p_in is not None else 85.0), el, "p_high",
                          positive=True)
            binding = dict(binding, kind="linearized", p_low=p_low * MMHG, p_high=p_high * MMHG)
    elif mode != "none":
        raise _err(el, f"hemoglobin must be none, hill or linearized, got {mode!r}")

    def po2(spec: Mapping[str, Any]) -> float:
        if "po2" in spec:
            return alpha * _num(spec["po2"], el, "po2", minimum=0.0)
        if "concentration" in spec:
            return _num(spec["concentration"], el, "concentration", minimum=0.0)
        raise _err(el, "wall needs 'po2' (mmHg)")

    species: dict[str, Any] = {
        "name": str(ox.get("name", "o2")), "diffusivity": d, "binding": binding, "inlet": inlet,
    }
    if _is_tissue(ox.get("wall")):
        species["wall"], species["tissue"] = _tissue(ox["wall"], el, alpha, h, d, p_in)
    else:
        species["wall"] = _wall(ox.get("wall", "none"), f"{el}", po2, "po2", h, d, p_fac,
                                period, duration)
    if "inlets" in ox:
        species["inlets"] = {str(k): _wave(v, "po2", alpha, f"{el} inlet '{k}'", period, duration)
                             for k, v in _check(ox["inlets"], set(ox["inlets"]), el).items()}
    back = ox.get("outlet_backflow", "zero-gradient")
    if back != "zero-gradient":
        if not isinstance(back, Mapping):
            raise _err(el, "outlet_backflow must be 'zero-gradient' or {outlet: {po2: ..}}")
        species["backflow"] = {str(k): _wave(v, "po2", alpha, f"{el} backflow '{k}'", period,
                                             duration) for k, v in back.items()}
    if "initial" in ox:
        ini = ox["initial"]
        species["initial"] = alpha * _num(ini.get("po2") if isinstance(ini, Mapping) else ini,
                                          el, "initial po2", minimum=0.0)
    if "per_vessel" in ox:
        pv, pvt = {}, {}
        for name, over in ox["per_vessel"].items():
            _check(over, {"wall", "cells_per_segment"}, f"{el} per_vessel '{name}'")
            # an override with only cells_per_segment keeps the section's wall
            if "wall" in over or "cells_per_segment" not in over:
                vel = f"{el} per_vessel '{name}'"
                if _is_tissue(over.get("wall")):
                    pv[str(name)], pvt[str(name)] = _tissue(over["wall"], vel, alpha, h, d, p_in)
                else:
                    pv[str(name)] = _wall(over.get("wall"), vel, po2, "po2", h, d, p_fac, period,
                                          duration)
                    pvt[str(name)] = None  # no tissue wall on this vessel
        if pv:
            species["per_vessel"] = pv
        if any(v is not None for v in pvt.values()) or "tissue" in species:
            species["per_vessel_tissue"] = pvt
    return species


def _refinement(section: Mapping[str, Any], element: str, per_vessel_key: str
                ) -> tuple[int | None, dict[str, int]]:
    """(cells_per_segment, per-vessel overrides) of the oxygen or transport section."""
    m = _cells(section["cells_per_segment"], element) if "cells_per_segment" in section else None
    over: dict[str, int] = {}
    pv = section.get(per_vessel_key) or {}
    if not isinstance(pv, Mapping):
        raise _err(element, f"'{per_vessel_key}' must be a mapping, got {pv!r}")
    for name, v in pv.items():
        if per_vessel_key == "per_vessel":  # oxygen: per_vessel: {name: {cells_per_segment: m}}
            if not isinstance(v, Mapping) or "cells_per_segment" not in v:
                continue
            v = v["cells_per_segment"]
        over[str(name)] = _cells(v, f"{element} vessel '{name}'")
    return m, over


def _species(sp: Mapping[str, Any], i: int, period: float | None,
             duration: float | None) -> dict[str, Any]:
    el = f"species '{sp.get('name', f'#{i}')}'" if isinstance(sp, Mapping) else f"species #{i}"
    _check(sp, SPECIES_KEYS, el)
    if "name" not in sp:
        raise _err(el, "needs a 'name'")
    d = _num(sp.get("diffusivity", 0.0), el, "diffusivity", minimum=0.0)
    b = sp.get("binding", "none")
    if b in (None, "none"):
        binding: dict[str, Any] = {"kind": "none"}
    else:
        _check(b, {"kind", "partition", "b_max", "k_d", "n"}, f"{el} binding")
        kind = b.get("kind")
        if kind == "linear":
            binding = {"kind": "linear", "partition": _num(b.get("partition"), el, "partition",
                                                           minimum=0.0)}
        elif kind == "saturable":
            # C_t = c + B_max c^n/(c^n + K_d^n): the Hill law with α = 1
            binding = {"kind": "hill", "solubility": 1.0,
                       "p50": _num(b.get("k_d"), el, "k_d", positive=True),
                       "n": _num(b.get("n", 1.0), el, "n", positive=True),
                       "capacity": _num(b.get("b_max"), el, "b_max", positive=True)}
        else:
            raise _err(el, f"binding kind must be none, linear or saturable, got {kind!r}")

    def conc(spec: Mapping[str, Any]) -> float:
        return _num(spec.get("concentration", 0.0), el, "concentration", minimum=0.0)

    if "inlet" not in sp:
        raise _err(el, "needs 'inlet' (e.g. {concentration: 1.0})")
    out: dict[str, Any] = {
        "name": str(sp["name"]), "diffusivity": d,
        "decay": _num(sp.get("decay", 0.0), el, "decay", minimum=0.0), "binding": binding,
        "inlet": _wave(sp["inlet"], "concentration", 1.0, f"{el} inlet", period, duration),
        "wall": _wall(sp.get("wall", "none"), el, conc, "concentration", None, d, None, period,
                      duration),
    }
    if "inlets" in sp:
        out["inlets"] = {str(k): _wave(v, "concentration", 1.0, f"{el} inlet '{k}'", period,
                                       duration) for k, v in sp["inlets"].items()}
    if "backflow" in sp:
        out["backflow"] = {str(k): _wave(v, "concentration", 1.0, f"{el} backflow '{k}'", period,
                                         duration) for k, v in sp["backflow"].items()}
    if "initial" in sp:
        out["initial"] = _num(sp["initial"], el, "initial", minimum=0.0)
    if "per_vessel" in sp:
        out["per_vessel"] = {str(n): _wall(o.get("wall"), f"{el} per_vessel '{n}'", conc,
                                           "concentration", None, d, None, period, duration)
                             for n, o in sp["per_vessel"].items()}
    return out


def add_blood(section: dict[str, Any], blood: Mapping[str, float]) -> None:
    """Give every `graetz` wall of the canonical transport ``section`` the blood's kinematic
    viscosity μ/ρ (SI): the inlet renewal's Womersley numbers (docs/physics.md §3.6)."""
    nu = float(blood["viscosity"]) / float(blood["density"])
    for sp in section["species"]:
        for wall in [sp.get("wall"), *(sp.get("per_vessel") or {}).values()]:
            if isinstance(wall, dict) and wall.get("model") == "graetz":
                wall["kinematic_viscosity"] = nu


def canonical(data: Mapping[str, Any], pressure_factor: float, period: float | None,
              duration: float | None) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    """(canonical transport section or None, info for results: species names and the O2
    solubility per mmHg)."""
    ox = data.get("oxygen")
    sps = data.get("species")
    if ox is None and not sps:
        return None, {}
    tr = _check(data.get("transport", {}) or {}, TRANSPORT_KEYS, "transport")
    species: list[dict[str, Any]] = []
    info: dict[str, Any] = {"species": [], "oxygen": None, "solubility": None}
    formulation = tr.get("formulation", "conservative")
    p_ref = pressure_factor * _num(tr.get("reference_pressure", 0.0), "transport",
                                   "reference_pressure")
    if ox is not None:
        if not isinstance(ox, Mapping):
            raise _err("oxygen", f"expected a mapping, got {ox!r}")
        o2 = _oxygen(ox, period, duration)
        species.append(o2)
        info["oxygen"] = o2["name"]
        info["solubility"] = _num(ox.get("solubility", 1.40e-3), "oxygen", "solubility")
        formulation = ox.get("formulation", formulation)
        if "reference_pressure" in ox:
            p_ref = MMHG * _num(ox["reference_pressure"], "oxygen", "reference_pressure")
    if sps:
        if not isinstance(sps, list):
            raise _err("species", "must be a list")
        species.extend(_species(s, i, period, duration) for i, s in enumerate(sps))
    if formulation not in FORMULATIONS:
        raise _err("oxygen", f"formulation must be one of {FORMULATIONS}, got {formulation!r}")
    names = [s["name"] for s in species]
    if len(set(names)) != len(names):
        raise _err("species", f"names must be unique, got {names}")
    info["species"] = names
    out: dict[str, Any] = {"reference_pressure": p_ref, "formulation": formulation,
                           "species": species}
    # transport cells per flow segment: one grid for all species (oxygen's keys win)
    cells, cells_pv = _refinement(tr, "transport", "cells_per_vessel")
    if isinstance(ox, Mapping):
        m_ox, pv_ox = _refinement(ox, "oxygen", "per_vessel")
        cells = m_ox if m_ox is not None else cells
        cells_pv.update(pv_ox)
    if cells is not None:
        out["cells_per_segment"] = cells
    if cells_pv:
        out["cells_per_vessel"] = cells_pv
    if "velocity_threshold" in tr:
        out["velocity_threshold"] = _num(tr["velocity_threshold"], "transport",
                                         "velocity_threshold", minimum=0.0)
    return out, info
