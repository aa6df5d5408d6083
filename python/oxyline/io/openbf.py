"""Import openBF network files (YAML ``network:`` list + inlet ``.dat`` table).

openBF (INSIGNEO, https://github.com/INSIGNEO/openBF) solves the nonlinear 1-D equations; this
module turns its input into an oxyline native model (a linear R-L-C network, inverted-L
segments of at most 1 cm by default). The key-by-key mapping and the reason for each choice
are in docs/validation.md ("Method" and "Findings"); the tube-law formulas are the core's
(``oxyline_core::model::openbf``). In short: nodes ``sn``/``tn`` become ``n<id>`` (node 1, or
the only node that starts vessels and ends none, is the inlet; a repeated ``label`` gets
``_2``, ``_3``...); ``linearize`` picks the pressure at which each vessel's radius and
compliance are taken from openBF's tube law (``"mean"``: the steady mean-flow network, the
default; ``"pext"``: the file's radii; or a pressure in Pa); ``taper``, ``wk2`` and
``openbf_compat`` choose between the file's intent and what openBF v2 actually computes;
``viscoelastic`` and ``wall_friction`` pick the wall and friction laws; a corrupted ADAN56
inflow is repaired unless ``repair_inlet=False``.
"""

from __future__ import annotations

import math
import os
import warnings
from collections import Counter
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError, UnsupportedElement
from oxyline.io._common import build
from oxyline.io.native import read_mapping  # YAML 1.2, duplicate keys and bombs refused
from oxyline.model import Model

PathLike = str | os.PathLike[str]

POISSON = _core.OPENBF_POISSON_RATIO  # openBF's sigma
# ADAN56 inflow: the two corrupted rows of the openBF copy and the clean STARFiSh/pylsewave values
ADAN56_INLET_REPAIR = {0.437555: (-2.10178e-55, -2.10178e-05), 0.515992: (5.25444e-66, 5.25444e-06)}

# openBF v2's wall viscosity law Gamma = b0 + b1/(2 R0) [kg/s] (Mynard & Smolich 2015)
VISCO_B0 = _core.OPENBF_VISCO_B0
VISCO_B1 = _core.OPENBF_VISCO_B1

VESSEL_KEYS = {
    "label", "sn", "tn", "L", "M", "R0", "Rp", "Rd", "E", "h0", "Pext", "Pout", "gamma_profile",
    "gamma profile", "R1", "R2", "Cc", "Rt", "inlet_impedance_matching", "to_save",
    "initial_pressure", "initial_flow", "visco-elastic", "inlet", "inlet file", "inlet number",
    "outlet",
}
TOP_KEYS = {"project_name", "inlet_file", "write_results", "blood", "solver", "network",
            "output_directory", "inlet"}


class OpenBFWarning(UserWarning):
    """A value in an openBF file was repaired, ignored or approximated."""


def adan_wall_thickness(radius: float | np.ndarray) -> float | np.ndarray:
    """Wall thickness [m] from the lumen radius [m] by the ADAN law used by openBF.

    h = r (0.2802 exp(-5.053 r[cm]) + 0.1324 exp(-0.1114 r[cm])) (``docs/networks.md`` §3).

    >>> round(adan_wall_thickness(0.01) * 1e3, 4)   # 1 cm radius -> mm
    1.2023
    """
    r = np.asarray(radius, dtype=float)
    h = np.asarray(_core.openbf_wall_thickness(r.ravel().tolist())).reshape(r.shape)
    return float(h) if h.ndim == 0 else h


def _num(value: Any, where: str, key: str) -> float:
    if isinstance(value, str):  # YAML 1.1 reads 1e-13 (no dot) as a string
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ModelError(f"{where}: '{key}' must be a finite number, got {value!r}")
    return float(value)


def _warn(msg: str) -> None:
    warnings.warn(msg, OpenBFWarning, stacklevel=3)


def read_inlet(path: PathLike, *, repair: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Read an openBF inlet table: (time [s], flow [m^3/s]) arrays.

    Repairs the two corrupted exponents of openBF's ``adan56_inlet.dat`` (with a warning) when
    ``repair`` is true.

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "in.dat"
    >>> _ = p.write_text("0 1e-6\\n0.5 2e-6\\n1.0 1e-6\\n")
    >>> t, q = read_inlet(p)
    >>> float(t[-1]), float(q[1])
    (1.0, 2e-06)
    """
    p = Path(path)
    if not p.is_file():
        raise ModelError(f"{p}: inlet file not found")
    import io

    from oxyline.io._common import read_regular_text

    text = read_regular_text(p, "openBF inlet table")
    try:
        data = np.loadtxt(io.StringIO(text), ndmin=2)
    except ValueError as exc:
        raise ModelError(f"{p}: cannot read the inlet table: {exc}") from None
    if data.shape[1] < 2 or data.shape[0] < 2:
        raise ModelError(f"{p}: inlet table needs two columns (time, flow) and >= 2 rows, "
                         f"got shape {data.shape}")
    t, q = data[:, 0].copy(), data[:, 1].copy()
    if not np.all(np.isfinite(data[:, :2])):
        raise ModelError(f"{p}: inlet table has non-finite values")
    if np.any(np.diff(t) <= 0):
        bad = int(np.argmax(np.diff(t) <= 0)) + 1
        order = np.argsort(t, kind="stable")
        t, q = t[order], q[order]
        if np.any(np.diff(t) <= 0):
            raise ModelError(f"{p}: inlet times repeat (row {bad + 1}: t = {t[bad]})")
        _warn(f"{p.name}: inlet times not increasing at row {bad + 1} (t = {data[bad, 0]} after "
              f"{data[bad - 1, 0]}); rows sorted by time")
    hits = [(i, new) for i in range(len(t)) for tt, (bad, new) in ADAN56_INLET_REPAIR.items()
            if abs(t[i] - tt) < 1e-9 and q[i] == bad]
    if repair and len(hits) == len(ADAN56_INLET_REPAIR):
        for i, new in hits:
            q[i] = new
        _warn(f"{p.name}: recognised openBF's ADAN56 inflow with two corrupted exponents; "
              "repaired with the STARFiSh/pylsewave values (t=0.437555: -2.10178e-05, "
              "t=0.515992: 5.25444e-06 m^3/s)")
    return t, q


def _radii(v: Mapping[str, Any], where: str) -> tuple[float, float]:
    if "R0" in v:
        r = _num(v["R0"], where, "R0")
        rp = _num(v.get("Rp", r), where, "Rp")
        rd = _num(v.get("Rd", rp), where, "Rd")
    elif "Rp" in v:
        rp = _num(v["Rp"], where, "Rp")
        rd = _num(v.get("Rd", rp), where, "Rd")
    else:
        raise ModelError(f"{where}: needs 'R0' or 'Rp'/'Rd' (lumen radius, m)")
    if rp <= 0 or rd <= 0:
        keys = "R0" if "R0" in v and "Rp" not in v and "Rd" not in v else "Rp/Rd"
        raise ModelError(f"{where}: radii must be > 0, got {keys}: Rp={rp}, Rd={rd}")
    return rp, rd


def _file_cells(v: Mapping[str, Any]) -> float:
    """The file's ``M`` (openBF's cells; 5 when absent): the core takes max(M, 5, ceil(L mm))."""
    m = v.get("M", 5)
    return 5.0 if isinstance(m, bool) else float(int(m))


class _Vessel:
    """openBF vessel parameters and its tube law, along x in [0, L]."""

    def __init__(self, v: Mapping[str, Any], where: str, taper: str, gamma_key: bool,
                 rho: float) -> None:
        self.where = where
        self.label = str(v["label"])
        self.sn, self.tn = v["sn"], v["tn"]
        self.length = _num(v.get("L"), where, "L") if "L" in v else None
        if self.length is None or self.length <= 0:
            raise ModelError(f"{where}: needs 'L' > 0 (length, m), got {v.get('L')!r}")
        if "E" not in v:
            raise ModelError(f"{where}: needs 'E' (Young's modulus, Pa)")
        self.E = _num(v["E"], where, "E")
        if self.E <= 0:
            raise ModelError(f"{where}: 'E' must be > 0, got {self.E}")
        rp, rd = _radii(v, where)
        self.rp_file, self.rd_file = rp, rd
        if taper == "openbf" and rd != rp:  # openBF v2's R0_i at x = L (the core's)
            rd = _core.openbf_taper_distal_radius(rp, rd, self.length, _file_cells(v))
        self.r0 = (rp, rd)
        self.h0_given = _num(v["h0"], where, "h0") if "h0" in v else None
        if self.h0_given is not None and self.h0_given <= 0:
            raise ModelError(f"{where}: 'h0' must be > 0, got {self.h0_given}")
        self.pext = _num(v.get("Pext", 0.0), where, "Pext")
        g = v.get("gamma_profile")
        if g is None and gamma_key and "gamma profile" in v:
            g = v["gamma profile"]
        self.gamma = _num(g, where, "gamma_profile") if g is not None else 2.0
        self.rho = rho
        ve = v.get("visco-elastic", False)
        if not isinstance(ve, bool):
            raise ModelError(f"{where}: 'visco-elastic' must be true or false, got {ve!r}")
        self.viscoelastic = ve

    def _wall(self) -> tuple[float, float, float, float, float | None]:
        return self.length, self.r0[0], self.r0[1], self.E, self.h0_given

    def z0(self) -> float:
        """Characteristic impedance rho c0 / A0 of the last cell (openBF's WK2 correction),
        the core's."""
        return _core.openbf_characteristic_impedance(*self._wall(), self.rho)

    def wall_viscosity(self) -> float:
        """Kelvin-Voigt viscosity eta [Pa s] of openBF's viscoelastic wall (the core's): E
        times the compliance-weighted mean of tau = 2 Gamma/(beta' sqrt(A0)) along the
        vessel."""
        return _core.openbf_wall_viscosity(*self._wall())

    def linearised(self, p_in: float, p_out: float) -> tuple[float, float, float]:
        """(r_in, r_out, compliance-equivalent wall thickness) at pressures p_in -> p_out on
        openBF's tube law (the core's): the thin-wall C of the linear taper equals openBF's
        tangent compliance integrated over the vessel."""
        got, p_low = _core.openbf_linearised(*self._wall(), self.pext, p_in, p_out)
        if got is None:
            raise ModelError(f"{self.where}: the tube law collapses the vessel at the "
                             f"linearisation pressure ({p_low:.4g} Pa, Pext "
                             f"{self.pext:.4g} Pa)")
        return got


def _load_yaml(p: Path) -> dict[str, Any]:
    data = read_mapping(p)
    if not isinstance(data.get("network"), list):
        raise ModelError(f"{p}: not an openBF file (needs a top-level 'network:' list)")
    return data


def _check_options(linearize: str | float, taper: str, wk2: str) -> None:
    if taper not in ("linear", "openbf"):
        raise ModelError(f"read_openbf: taper must be 'linear' or 'openbf', got {taper!r}")
    if wk2 not in ("parallel", "openbf"):
        raise ModelError(f"read_openbf: wk2 must be 'parallel' or 'openbf', got {wk2!r}")
    if not (isinstance(linearize, (int, float)) and not isinstance(linearize, bool)) \
            and linearize not in ("mean", "pext"):
        raise ModelError(f"read_openbf: linearize must be 'mean', 'pext' or a pressure in Pa, "
                         f"got {linearize!r}")


def _blood(data: Mapping[str, Any], p: Path) -> tuple[float, float]:
    """The file's blood density and viscosity (openBF's defaults when it has none)."""
    blood = data.get("blood") or {}
    if not blood:
        _warn(f"{p.name}: no 'blood:' section; using rho = 1060 kg/m^3 and mu = 4.0e-3 Pa s")
    if not isinstance(blood, Mapping):
        raise ModelError(f"{p}: 'blood' must be a mapping with rho and mu")
    rho = _num(blood.get("rho", 1060.0), f"{p}: blood", "rho")
    mu = _num(blood.get("mu", 4.0e-3), f"{p}: blood", "mu")
    for key, value in (("rho", rho), ("mu", mu)):
        if value <= 0:  # named as the file names it (the model's check says density)
            raise ModelError(f"{p}: blood: '{key}' must be > 0, got {value!r}")
    return rho, mu


def _vessels(data: Mapping[str, Any], p: Path, taper: str, openbf_compat: bool, rho: float
             ) -> tuple[list[_Vessel], list[Mapping[str, Any]]]:
    """The network's vessels (labels made unique) and their raw entries."""
    vessels: list[_Vessel] = []
    raw: list[Mapping[str, Any]] = []
    seen: Counter[str] = Counter()
    spaced: list[str] = []
    for i, v in enumerate(data["network"]):
        if not isinstance(v, Mapping):
            raise ModelError(f"{p}: network entry #{i} is not a mapping")
        label = str(v.get("label", f"vessel_{i + 1}"))
        where = f"{p.name}: vessel '{label}'"
        for k in ("sn", "tn"):
            if k not in v:
                raise ModelError(f"{where}: missing '{k}' (node id)")
        for k in v:
            if k not in VESSEL_KEYS:
                _warn(f"{where}: key '{k}' is not an openBF key; ignored")
        if "gamma profile" in v and "gamma_profile" not in v:
            spaced.append(label)
        seen[label] += 1
        if seen[label] > 1:
            new = f"{label}_{seen[label]}"
            _warn(f"{where}: label used twice; renamed '{new}'")
            label = new
            where = f"{p.name}: vessel '{label}'"
        vv = dict(v)
        vv["label"] = label
        vessels.append(_Vessel(vv, where, taper, not openbf_compat, rho))
        raw.append(vv)
    if spaced:
        _warn(f"{p.name}: 'gamma profile' (with a space) in {len(spaced)} vessel(s) ("
              f"{', '.join(spaced[:3])}{', ...' if len(spaced) > 3 else ''}) is " + (
                  "ignored, as openBF does (openbf_compat): gamma_profile = 2" if openbf_compat
                  else "read as gamma_profile (openBF itself ignores it and uses 2)"))
    return vessels, raw


def _inlet_node(vessels: list[_Vessel], p: Path) -> Any:
    """openBF's inlet node: node 1, or the one node that starts vessels but ends none."""
    starts = Counter(v.sn for v in vessels)
    ends = Counter(v.tn for v in vessels)
    sources = [n for n in starts if n not in ends]
    if 1 in sources:
        inlet_node = 1
    elif len(sources) == 1:
        inlet_node = sources[0]
    else:
        raise ModelError(f"{p}: cannot find the inlet node (openBF's node 1); nodes that start "
                         f"vessels but end none: {sources}")
    for n in sources:
        if n != inlet_node:
            bad = [v.label for v in vessels if v.sn == n]
            raise ModelError(f"{p}: vessel '{bad[0]}' starts at node {n}, which has no inflow "
                             f"and no upstream vessel (only node {inlet_node} is an inlet)")
    if starts[inlet_node] != 1:
        raise ModelError(f"{p}: the inlet node {inlet_node} must start exactly one vessel")
    return inlet_node


def _inlet_table(data: Mapping[str, Any], raw: list[Mapping[str, Any]], p: Path,
                 repair: bool) -> tuple[np.ndarray, np.ndarray]:
    """The inflow table (t, Q) of the file's ``inlet_file`` (or ``<project>_inlet.dat``)."""
    inlet_file = data.get("inlet_file")
    if inlet_file is None:
        for v in raw:
            if "inlet file" in v:
                inlet_file = v["inlet file"]
    if inlet_file is None:
        guess = p.with_name(f"{data.get('project_name', p.stem)}_inlet.dat")
        if not guess.is_file():
            raise ModelError(f"{p}: no 'inlet_file' given and {guess.name} not found")
        inlet_file = guess.name
    t, q = read_inlet(p.parent / str(inlet_file), repair=repair)
    if abs(t[0]) > 1e-12:
        _warn(f"{inlet_file}: the inlet table starts at t = {t[0]} s, not 0; openBF assumes 0")
    return t, q


def _gamma(vessels: list[_Vessel], p: Path) -> float:
    """The one velocity-profile gamma of the model (the most common one)."""
    gammas = Counter(v.gamma for v in vessels)
    gamma, _ = gammas.most_common(1)[0]
    if len(gammas) > 1:
        odd = [v.label for v in vessels if v.gamma != gamma]
        _warn(f"{p.name}: mixed gamma_profile values {dict(gammas)}; oxyline has one viscosity "
              f"per model, gamma = {gamma:g} used for all (differs for: {', '.join(odd[:8])}"
              f"{', ...' if len(odd) > 8 else ''})")
    return gamma


def _missing_outlet(v: _Vessel, r: Mapping[str, Any], vessels: list[_Vessel],
                    raw: list[Mapping[str, Any]], starts: Counter[Any]) -> Exception:
    """The error of a terminal vessel without a Windkessel (a reflection-coefficient outlet
    is not supported)."""
    if "Rt" not in r:
        return ModelError(f"{v.where}: terminal vessel (node {v.tn}) without an outlet "
                          "condition (R1/R2/Cc or Rt)")
    rt = _num(r["Rt"], v.where, "Rt")
    others = [x.label for x, y in zip(vessels, raw)
              if x is not v and "Rt" in y and "R1" not in y and x.tn not in starts]
    also = f" (also Rt outlets: {', '.join(others)})" if others else ""
    return UnsupportedElement(
        f"{v.where}: reflection-coefficient outlet (Rt = {rt:g}) is not supported by the 0-D "
        f"importer; give a Windkessel (R1, R2, Cc) instead (a linear equivalent is a "
        f"resistance Z0 (1 + Rt)/(1 - Rt), Z0 = {v.z0():.4g} Pa s m^-3){also}")


def _windkessel(v: _Vessel, r: Mapping[str, Any], wk2: str) -> dict[str, Any]:
    """The native outlet condition of a terminal vessel's Windkessel (R1, R2, Cc, Pout)."""
    pout = _num(r.get("Pout", 0.0), v.where, "Pout")
    r1 = _num(r["R1"], v.where, "R1")
    cc = _num(r.get("Cc", 0.0), v.where, "Cc")
    if "R2" in r and _num(r["R2"], v.where, "R2") != 0.0:
        r2 = _num(r["R2"], v.where, "R2")
    elif wk2 == "openbf":
        r2 = r1 - v.z0()  # openBF v2: R2 = R1 - rho c0/A0, R1 stays proximal
    else:
        r1, r2 = 0.0, r1  # two-element Windkessel: R1 parallel to Cc
    if r.get("inlet_impedance_matching"):
        z0 = v.z0()
        _warn(f"{v.where}: inlet_impedance_matching: proximal resistance set to Z0 = "
              f"{z0:.4g} Pa s m^-3 at A0 (openBF updates it with A(t))")
        r1, r2 = z0, r1 + r2 - z0
    if r2 <= 0 or r1 < 0 or cc < 0:
        raise ModelError(f"{v.where}: Windkessel needs R2 > 0, R1 >= 0, Cc >= 0 "
                         f"(got R1={r1:g}, R2={r2:g}, Cc={cc:g})")
    if cc == 0.0:
        return {"type": "resistance", "resistance": r1 + r2, "pressure": pout}
    return {"type": "rcr", "proximal_resistance": r1, "capacitance": cc,
            "distal_resistance": r2, "pressure": pout}


def _outlets(vessels: list[_Vessel], raw: list[Mapping[str, Any]], wk2: str
             ) -> tuple[dict[str, Any], dict[Any, tuple[float, float]]]:
    """The outlet conditions by node name, and each outlet node's (total resistance, Pout)."""
    starts = Counter(v.sn for v in vessels)
    ends = Counter(v.tn for v in vessels)
    bcs: dict[str, Any] = {}
    terminal_resistance: dict[Any, tuple[float, float]] = {}
    for v, r in zip(vessels, raw):
        if v.tn in starts:
            if any(k in r for k in ("R1", "R2", "Cc", "Rt")):
                _warn(f"{v.where}: outlet parameters on an inner vessel (node {v.tn}) ignored")
            continue
        if ends[v.tn] > 1:
            raise ModelError(f"{v.where}: outlet node {v.tn} is shared by several vessels")
        if "R1" not in r:
            _num(r.get("Pout", 0.0), v.where, "Pout")
            raise _missing_outlet(v, r, vessels, raw, starts)
        bc = bcs[f"n{v.tn}"] = _windkessel(v, r, wk2)
        total = bc["resistance"] if bc["type"] == "resistance" \
            else bc["proximal_resistance"] + bc["distal_resistance"]
        terminal_resistance[v.tn] = (total, bc["pressure"])
    return bcs, terminal_resistance


def _native_vessel(v: _Vessel, p_in: float, p_out: float,
                   viscoelastic: bool | None = None) -> dict[str, Any]:
    """The native vessel of ``v`` linearised at the end pressures ``p_in``, ``p_out``; with
    a viscoelastic wall (the file's ``visco-elastic``, or ``viscoelastic`` when not None)
    openBF's wall viscosity."""
    r_in, r_out, h_eff = v.linearised(p_in, p_out)
    if v.h0_given is not None:
        h_file = f"h0 {v.h0_given:.4g} m"
    else:
        ha, hb = adan_wall_thickness(np.array(v.r0)).tolist()  # at both ends
        h_file = f"h0 from the ADAN law ({ha:.4g}-{hb:.4g} m)"
    desc = (f"openBF: Rp {v.rp_file:.6g} m, Rd {v.rd_file:.6g} m, {h_file}, E {v.E:.6g} Pa, "
            f"Pext {v.pext:.6g} Pa, gamma_profile {v.gamma:g}; linearised at "
            f"{p_in:.6g}->{p_out:.6g} Pa (radii and compliance-equivalent wall thickness)")
    nv: dict[str, Any] = {"name": v.label, "from": f"n{v.sn}", "to": f"n{v.tn}",
                          "length": v.length}
    if abs(r_in - r_out) <= 1e-12 * r_in:
        nv["radius"] = r_in
    else:
        nv["radius_in"], nv["radius_out"] = r_in, r_out
    nv.update(wall_thickness=h_eff, youngs_modulus=v.E, poisson_ratio=POISSON, description=desc)
    if v.viscoelastic if viscoelastic is None else viscoelastic:
        nv["wall_viscosity"] = v.wall_viscosity()
        nv["description"] += (f"; visco-elastic wall (Gamma = {VISCO_B0:g} + {VISCO_B1:g}/(2 R0) "
                              f"kg/s): wall_viscosity {nv['wall_viscosity']:.6g} Pa s")
    return nv


def to_native_dict(path: PathLike, *, linearize: str | float = "mean", taper: str = "linear",
                   wk2: str = "parallel", openbf_compat: bool = False, repair_inlet: bool = True,
                   max_segment_length: float = 0.01, name: str | None = None,
                   wall_friction: str = "poiseuille", viscoelastic: bool | None = None
                   ) -> dict[str, Any]:
    """Convert an openBF YAML file (and its inlet table) into an oxyline native model dict (SI).

    Parameters: ``linearize`` ("mean", "pext" or a pressure in Pa: where each vessel's radius
    and compliance are evaluated on openBF's tube law), ``taper`` ("linear" or "openbf"),
    ``wk2`` ("parallel" or "openbf"), ``openbf_compat`` (all of openBF v2's behaviours: taper,
    WK2 and ignored ``gamma profile`` keys), ``repair_inlet`` (fix the ADAN56 inflow),
    ``max_segment_length`` [m], ``name``, ``wall_friction`` ("poiseuille" or "womersley"),
    ``viscoelastic`` (None: each vessel's ``visco-elastic`` key; True/False: openBF's
    viscoelastic wall on every vessel / on none). See the module docstring for the mapping.

    >>> from pathlib import Path
    >>> f = Path("../shared/networks/openbf/models/boileau2015/cca/cca.yaml")
    >>> d = to_native_dict(f) if f.exists() else {"vessels": [{"name": "common_carotid_artery"}]}
    >>> d["vessels"][0]["name"]
    'common_carotid_artery'
    """
    p = Path(path)
    if openbf_compat:
        taper, wk2 = "openbf", "openbf"
    _check_options(linearize, taper, wk2)
    if wall_friction not in ("poiseuille", "womersley"):
        raise ModelError(f"read_openbf: wall_friction must be 'poiseuille' or 'womersley', "
                         f"got {wall_friction!r}")
    if viscoelastic is not None and not isinstance(viscoelastic, bool):
        raise ModelError(f"read_openbf: viscoelastic must be None, True or False, got "
                         f"{viscoelastic!r}")
    data = _load_yaml(p)
    for k in data:
        if k not in TOP_KEYS:
            _warn(f"{p.name}: top-level key '{k}' is not used by the importer")
    rho, mu = _blood(data, p)
    vessels, raw = _vessels(data, p, taper, openbf_compat, rho)
    inlet_node = _inlet_node(vessels, p)
    t, q = _inlet_table(data, raw, p, repair_inlet)
    period = float(t[-1] - t[0])
    q_mean = _core.cycle_mean(t.tolist(), q.tolist())
    gamma = _gamma(vessels, p)
    mu_eff = _core.openbf_friction_viscosity(mu, gamma)  # openBF's friction 2 (gamma + 2) pi mu
    outlets, terminal_resistance = _outlets(vessels, raw, wk2)

    # linearisation pressures at the vessel ends
    if linearize == "pext":
        p_ends = {id(v): (v.pext, v.pext) for v in vessels}
    elif linearize == "mean":
        p_ends = _mean_pressures(vessels, inlet_node, q_mean, terminal_resistance, mu_eff)
    else:
        pl = float(linearize)
        p_ends = {id(v): (pl, pl) for v in vessels}
    bcs = {f"n{inlet_node}": {"type": "flow", "time": t.tolist(), "flow": q.tolist(),
                              "interpolation": "linear"}, **outlets}
    return {
        "name": name or str(data.get("project_name", p.stem)),
        "description": (
            f"Imported from openBF file {p.name} (Apache-2.0 openBF model library). Blood "
            f"viscosity {mu:g} Pa s x (gamma_profile {gamma:g} + 2)/4 = {mu_eff:g} Pa s "
            f"(openBF friction 2(gamma+2) pi mu); linearize={linearize!r}, taper={taper!r}, "
            f"wk2={wk2!r}."),
        "units": "SI",
        "blood": {"density": rho, "viscosity": mu_eff},
        "arrangement": "inverted-L",
        "inertance_profile": "flat",
        **({"wall_friction": wall_friction} if wall_friction != "poiseuille" else {}),
        "segmentation": {"max_length": float(max_segment_length)},
        "period": period,
        "vessels": [_native_vessel(v, *p_ends[id(v)], viscoelastic) for v in vessels],
        "boundary_conditions": bcs,
        "simulation": {"cycles": 10, "until_periodic": 1e-6, "max_cycles": 200,
                       "dt": "auto", "method": "auto",
                       "output": {"cycles": "last", "every": period / 1000.0}},
    }


def _mean_pressures(vessels: list[_Vessel], inlet: Any, q_mean: float,
                    terminals: dict[Any, tuple[float, float]],
                    mu: float) -> dict[int, tuple[float, float]]:
    """Steady pressures at both ends of every vessel for the mean inflow: the core's fixed
    point of the steady network and the tube law (``oxyline_core::model::openbf::steady``)."""
    rows = [(f"n{v.sn}", f"n{v.tn}", *v._wall(), v.pext, v.where, v.label) for v in vessels]
    outlets = [(f"n{node}", r, pout) for node, (r, pout) in terminals.items()]
    ends = _core.openbf_mean_pressures(rows, f"n{inlet}", q_mean, outlets, mu)
    return {id(v): (p_in, p_out) for v, (p_in, p_out) in zip(vessels, ends, strict=True)}


def read_openbf(path: PathLike, **options: Any) -> Model:
    """Read an openBF YAML network (and its inlet table) as a validated :class:`oxyline.Model`.

    ``options`` are those of :func:`to_native_dict` (``linearize``, ``taper``, ``wk2``,
    ``openbf_compat``, ``repair_inlet``, ``max_segment_length``, ``name``, ``wall_friction``,
    ``viscoelastic``).

    >>> from pathlib import Path
    >>> import oxyline
    >>> f = Path("../shared/networks/openbf/models/boileau2015/ibif/ibif.yaml")
    >>> m = read_openbf(f) if f.exists() else oxyline.load_model("bifurcation")
    >>> len(m.vessel_names)
    3
    """
    import inspect

    known = [k for k in inspect.signature(to_native_dict).parameters if k != "path"]
    unknown = sorted(set(options) - set(known))
    if unknown:  # before: a raw TypeError of the converter
        raise ModelError(f"read_openbf: unknown option(s) {', '.join(map(repr, unknown))} "
                         f"(allowed: {', '.join(known)})")
    return build(to_native_dict(path, **options), owned=True)


__all__ = ["OpenBFWarning", "adan_wall_thickness", "read_inlet", "read_openbf", "to_native_dict"]
