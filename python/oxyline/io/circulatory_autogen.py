"""Import circulatory_autogen 0-D networks (``<model>_vessel_array.csv`` + ``<model>_parameters.csv``).

circulatory_autogen (F. Argus et al., https://github.com/FinbarArgus/circulatory_autogen,
Apache-2.0) generates CellML models from a vessel array whose rows are 0-D modules, each
module's circuit fixed by its ``vessel_type`` and ``BC_type``. The arterial tree is imported
(geometric modules as geometric vessels with Poisson ratio 0, ``*_simple`` and terminal
modules as lumped vessels; the ``BC_type`` picks the arrangement); the heart, veins and lungs
are replaced by an aortic inflow (the Mynard & Smolich 2015 template by default) scaled to the
cardiac output of ``<model>_obs_data.json``. The module-by-module mapping, what is dropped and
why, the inflow and the terminal-resistance calibration (``terminal_resistance_scale=
"calibrate"``, :func:`calibrate_terminal_resistance_scale`) are in docs/models.md
("whole-body-140").

>>> from oxyline.io.circulatory_autogen import read_circulatory_autogen  # doctest: +SKIP
>>> m = read_circulatory_autogen("FinalModel_vessel_array.csv", "FinalModel_parameters.csv",
...                              obs_data_json="FinalModel_obs_data.json")  # doctest: +SKIP
"""

from __future__ import annotations

import csv
import json
import math
import os
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError
from oxyline.io._common import build
from oxyline.model import Model, _build

PathLike = str | os.PathLike[str]

GEOMETRIC = {"arterial", "split_junction", "merge_junction", "2in2out_junction"}
SIMPLE = {"arterial_simple", "split_junction_simple", "merge_junction_simple"}
TERMINAL = {"terminal"}
#: BC_type -> (oxyline arrangement, segments)
ARRANGEMENT = {"pv": ("L", 1), "vp": ("inverted-L", 1), "vv": ("pi", 1), "pp": ("pi", 2)}
#: module types that are not part of the arterial tree (replaced by the inflow / outlet pressure)
NOT_IMPORTED = {"heart", "venous", "venous_simple"}

# CellML unit names of the parameters we read -> the SI unit they denote
SI_UNITS = {"metre": "m", "J_per_m3": "Pa", "Js_per_m6": "Pa s m^-3", "m6_per_J": "m^3 Pa^-1",
            "Js2_per_m6": "Pa s^2 m^-3", "Js_per_m3": "Pa s", "Js2_per_m5": "kg m^-3",
            "dimensionless": "1", "per_m": "m^-1", "second": "s", "m3_per_s": "m^3 s^-1"}

PWDB_ZERO_HEAD = 52       # PWDB AorticFlowWave.m: samples 1..52 zeroed, rotated to the end
PWDB_LAST_SYSTOLE = 361   # samples 362..880 (1-based) zeroed


class CirculatoryAutogenWarning(UserWarning):
    """A value of the source that the linear oxyline mapping changes or ignores."""


def _split(cell: str) -> list[str]:
    return [s for s in cell.replace(",", " ").split() if s]


def read_vessel_array(path: PathLike) -> list[dict[str, Any]]:
    """Rows of a ``*_vessel_array.csv`` with whitespace stripped and the input/output lists split."""
    rows: list[dict[str, Any]] = []
    with open(path, newline="") as f:
        reader = csv.reader(f)
        header = [h.strip() for h in next(reader)]
        want = ["name", "BC_type", "vessel_type", "inp_vessels", "out_vessels"]
        if header[:5] != want:
            raise ModelError(f"{path}: header must start with {', '.join(want)}, got {header}")
        for line, row in enumerate(reader, start=2):
            if not row or not "".join(row).strip():
                continue
            if len(row) < 5:
                raise ModelError(f"{path} line {line}: expected 5 fields, got {len(row)}")
            rows.append({"name": row[0].strip(), "BC_type": row[1].strip(),
                         "vessel_type": row[2].strip(), "inp": _split(row[3]),
                         "out": _split(",".join(row[4:]))})
    return rows


def read_parameters(path: PathLike) -> dict[str, tuple[float, str, str]]:
    """``variable_name -> (value, CellML unit name, data_reference)`` of a ``*_parameters.csv``."""
    out: dict[str, tuple[float, str, str]] = {}
    with open(path, newline="") as f:
        reader = csv.reader(f)
        next(reader)
        for line, row in enumerate(reader, start=2):
            if not row or not row[0].strip():
                continue
            try:
                value = float(row[2])
            except (IndexError, ValueError) as exc:
                raise ModelError(f"{path} line {line}: bad value for '{row[0].strip()}'") from exc
            out[row[0].strip()] = (value, row[1].strip(), row[3].strip() if len(row) > 3 else "")
    return out


def mynard_aortic_flow(template_csv: PathLike, period: float) -> tuple[np.ndarray, np.ndarray]:
    """The Mynard & Smolich 2015 aortic root flow [m^3/s] as PWDB prepares it (systolic samples
    53-361 kept, systole moved to t = 0), zero flow from the end of systole to ``period``."""
    t, q = np.loadtxt(template_csv, delimiter=",", comments="#", skiprows=2, unpack=True)
    if len(q) < PWDB_LAST_SYSTOLE or not np.allclose(np.diff(t), 1e-3):
        raise ModelError(f"{template_csv}: expected the 1 kHz Mynard template (880 samples)")
    systole = q[PWDB_ZERO_HEAD:PWDB_LAST_SYSTOLE] * 1e-6   # mL/s -> m^3/s
    ts = np.arange(len(systole)) * 1e-3
    if ts[-1] + 1e-3 >= period:
        raise ModelError(f"period {period} s is shorter than the template's systole")
    time = np.concatenate([ts, [ts[-1] + 1e-3, period]])
    flow = np.concatenate([systole, [0.0, systole[0]]])
    return time, flow


def _cycle_mean(time: np.ndarray, flow: np.ndarray) -> float:
    return _core.cycle_mean(np.asarray(time, float).tolist(), np.asarray(flow, float).tolist())


def cardiac_output_from_obs(obs_data_json: PathLike) -> float:
    """Sum of the mean terminal-region flows (``*_T/v``, m^3/s) in a circulatory_autogen
    ``*_obs_data.json``: the systemic flow the model is calibrated to."""
    data = json.loads(Path(obs_data_json).read_text())
    total = 0.0
    for item in data.get("data_items", []):
        if (str(item.get("variable", "")).endswith("_T/v") and item.get("obs_type") == "mean"
                and item.get("unit") == "m3_per_s"):
            total += float(item["value"])
    if total <= 0:
        raise ModelError(f"{obs_data_json}: no mean terminal flows (*_T/v, m3_per_s)")
    return total


def _value(params: dict[str, tuple[float, str, str]], key: str, unit: str, where: str) -> float:
    if key not in params:
        raise ModelError(f"{where}: parameter '{key}' missing from the parameters file")
    value, got, _ref = params[key]
    if got != unit:
        raise ModelError(f"{where}: '{key}' has unit {got}, expected {unit} ({SI_UNITS[unit]})")
    return value


def wall_thickness(r: float, params: dict[str, tuple[float, str, str]]) -> float:
    """circulatory_autogen's h(r) = r (a e^(b r) + c e^(d r)) with the file's global constants
    (the core's law)."""
    a = _value(params, "a_vessel", "dimensionless", "global")
    b = _value(params, "b_vessel", "per_m", "global")
    c = _value(params, "c_vessel", "dimensionless", "global")
    d = _value(params, "d_vessel", "per_m", "global")
    return _core.wall_thickness_law(r, a, b, c, d)


def _warn(msg: str) -> None:
    warnings.warn(msg, CirculatoryAutogenWarning, stacklevel=3)


def _resistance_scale(scale: float | str, vessel_array_csv: PathLike, parameters_csv: PathLike,
                      obs_data_json: PathLike | None, options: dict[str, Any]
                      ) -> tuple[float, str]:
    """The terminal resistance factor (``"calibrate"``: fitted to the observed mean pressure)
    and the description's note on its calibration."""
    if not isinstance(scale, str):
        return scale, ""
    if scale != "calibrate" or obs_data_json is None:
        raise ModelError("terminal_resistance_scale must be a number > 0, or 'calibrate' "
                         "with obs_data_json")
    raw = to_native_dict(vessel_array_csv, parameters_csv, obs_data_json=obs_data_json,
                         **options)
    factor, node, target = calibrate_terminal_resistance_scale(raw, obs_data_json)
    return factor, (f" (calibrated: the one factor that makes the steady-solve mean pressure "
                    f"at {node} equal the observed {target:g} Pa of "
                    f"{Path(obs_data_json).name} at the mean inflow)")


def _tree(rows: list[dict[str, Any]], vessel_array_csv: PathLike
          ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """The arterial modules to import, checked, and their root (fed by the heart)."""
    by_name = {r["name"]: r for r in rows}
    if len(by_name) != len(rows):
        raise ModelError(f"{vessel_array_csv}: duplicate module names")
    for r in rows:
        for other in r["inp"] + r["out"]:
            if other not in by_name:
                raise ModelError(f"{vessel_array_csv}: module '{r['name']}' refers to unknown "
                                 f"module '{other}'")
    tree = [r for r in rows if r["vessel_type"] not in NOT_IMPORTED]
    for r in tree:
        vt = r["vessel_type"]
        if vt not in GEOMETRIC | SIMPLE | TERMINAL:
            raise ModelError(f"module '{r['name']}': vessel_type '{vt}' is not supported "
                             f"(supported: {sorted(GEOMETRIC | SIMPLE | TERMINAL)})")
        if vt in TERMINAL and r["BC_type"] != "pp":
            raise ModelError(f"terminal '{r['name']}': BC_type '{r['BC_type']}' not supported (pp)")
        if vt not in TERMINAL and r["BC_type"] not in ARRANGEMENT:
            raise ModelError(f"module '{r['name']}': BC_type '{r['BC_type']}' not supported")
    in_tree = {r["name"] for r in tree}
    roots = [r for r in tree if not any(i in in_tree for i in r["inp"])]
    if len(roots) != 1:
        raise ModelError(f"expected one arterial root fed by the heart, found "
                         f"{[r['name'] for r in roots]}")
    return tree, roots[0]


def _node_names(tree: list[dict[str, Any]], root: dict[str, Any]) -> dict[tuple[str, str], str]:
    """The node name of every module end ``(module, "in"/"out")``: the ends a connection
    joins share one node (union of ends), named after the one module that ends there."""
    in_tree = {r["name"] for r in tree}
    parent: dict[tuple[str, str], tuple[str, str]] = {}

    def find(x: tuple[str, str]) -> tuple[str, str]:
        parent.setdefault(x, x)
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for r in tree:
        find((r["name"], "in"))
        find((r["name"], "out"))
        for o in r["out"]:
            if o in in_tree:
                parent[find((o, "in"))] = find((r["name"], "out"))
    members: dict[tuple[str, str], list[tuple[str, str]]] = {}
    for x in list(parent):
        members.setdefault(find(x), []).append(x)
    names: dict[tuple[str, str], str] = {}
    for ends in members.values():
        outs = sorted(n for n, side in ends if side == "out")
        ins = sorted(n for n, side in ends if side == "in")
        if len(outs) == 1:
            label = f"{outs[0]}.out"
        elif (root["name"], "in") in ends:
            label = "aortic_root"
        else:
            label = f"{ins[0]}.in"
        for end in ends:
            names[end] = label
    return names


def _terminal(nm: str, ends: tuple[str, str], params: dict[str, tuple[float, str, str]],
              scale: float, venous_pressure: float) -> tuple[dict[str, Any], dict[str, Any]]:
    """A terminal module (R_T/2, C_T, R_T/2): its vessel and its outlet condition."""
    R_T = _value(params, f"R_T_{nm}", "Js_per_m6", nm) * scale
    C_T = _value(params, f"C_T_{nm}", "m6_per_J", nm)
    vessel = {
        "name": nm, "from": ends[0], "to": ends[1], "arrangement": "L",
        "lumped": {"resistance": R_T / 2, "inductance": 0.0, "capacitance": C_T},
        "description": (f"circulatory_autogen terminal (pp_T_fixed_I_type): "
                        f"R_T {R_T:.6g} Pa s m^-3, C_T {C_T:.6g} m^3/Pa; first half "
                        f"R_T/2 + C_T here, second half R_T/2 = outlet resistance"),
    }
    return vessel, {"type": "resistance", "resistance": R_T / 2,
                    "pressure": float(venous_pressure)}


def _artery(r: dict[str, Any], ends: tuple[str, str], params: dict[str, tuple[float, str, str]]
            ) -> dict[str, Any]:
    """An arterial module: lumped (R, I, C) or geometric (r_0, l, E, h(r_0))."""
    nm, vt, bc = r["name"], r["vessel_type"], r["BC_type"]
    arrangement, segments = ARRANGEMENT[bc]
    v: dict[str, Any] = {"name": nm, "from": ends[0], "to": ends[1],
                         "arrangement": arrangement, "segments": segments}
    if vt in SIMPLE:
        v["lumped"] = {"resistance": _value(params, f"R_{nm}", "Js_per_m6", nm),
                       "inductance": _value(params, f"I_{nm}", "Js2_per_m6", nm),
                       "capacitance": _value(params, f"C_{nm}", "m6_per_J", nm)}
        v["description"] = f"circulatory_autogen {vt} ({bc})"
        return v
    r0 = _value(params, f"r_0_{nm}", "metre", nm)
    length = _value(params, f"l_{nm}", "metre", nm)
    E = _value(params, f"E_{nm}", "J_per_m3", nm)
    h = wall_thickness(r0, params)
    refs = sorted({params[k][2] for k in (f"r_0_{nm}", f"l_{nm}", f"E_{nm}")})
    v.update({"length": length, "radius": r0, "wall_thickness": h, "youngs_modulus": E,
              "poisson_ratio": 0.0,
              "description": (f"circulatory_autogen {vt} ({bc}); r_0 {r0:.6g} m, "
                              f"l {length:.6g} m, E {E:.6g} Pa, h(r_0) {h:.6g} m; "
                              f"source: {', '.join(refs)}")})
    return v


def _inflow(inflow: str | tuple[Any, Any] | PathLike, mynard_template: PathLike | None,
            period: float) -> tuple[np.ndarray, np.ndarray, str]:
    """The aortic inflow table (t, Q) and where it comes from."""
    if isinstance(inflow, tuple):
        t_in, q_in = (np.asarray(x, dtype=float) for x in inflow)
        return t_in, q_in, "user-given inflow table"
    if inflow == "mynard2015" or inflow is None:
        tpl = Path(mynard_template) if mynard_template else (
            Path(__file__).resolve().parents[4] / "shared" / "networks" / "pwdb"
            / "Mynard2015_aortic_flow_template.csv")
        if not tpl.is_file():
            raise ModelError(f"Mynard aortic flow template not found at {tpl} "
                             f"(pass mynard_template=...)")
        t_in, q_in = mynard_aortic_flow(tpl, period)
        return t_in, q_in, ("Mynard & Smolich 2015 aortic root flow template (PWDB "
                            "Mynard2015_aortic_flow_template.csv, MIT; systole 0-0.309 s, zero "
                            f"flow in diastole to T = {period:g} s)")
    raise ModelError(f"inflow must be 'mynard2015' or a (time, flow) pair, got {inflow!r}")


def _scaled_inflow(t_in: np.ndarray, q_in: np.ndarray, cardiac_output: float | None,
                   obs_data_json: PathLike | None) -> tuple[np.ndarray, str]:
    """The inflow scaled to the cardiac output (given, else the observations'), and the
    source of that output."""
    co_source = "unscaled"
    if cardiac_output is None and obs_data_json is not None:
        cardiac_output = cardiac_output_from_obs(obs_data_json)
        co_source = (f"the sum of the mean terminal-region flows of {Path(obs_data_json).name} "
                     f"(leg, arm, head, trunk)")
    elif cardiac_output is not None:
        co_source = "given"
    if cardiac_output is not None:
        q_in = np.asarray(_core.circulatory_autogen_inflow(t_in.tolist(), q_in.tolist(),
                                                          float(cardiac_output)))
    return q_in, co_source


def _description(vessel_array_csv: PathLike, rows: list[dict[str, Any]], counts: Counter[str],
                 root: str, source: str, q_mean: float, co_source: str, venous_pressure: float,
                 wall_viscosity: bool, scale: float, calibration: str) -> str:
    """The imported model's description: what was imported, mapped and dropped."""
    n_geo, n_simple = counts["geometric"], counts["simple"]
    n_heart = sum(r["vessel_type"] == "heart" for r in rows)
    skipped = sorted({r["vessel_type"] for r in rows if r["vessel_type"] in NOT_IMPORTED})
    return (
        f"Arterial tree of the circulatory_autogen model {Path(vessel_array_csv).name} "
        f"(FinbarArgus/circulatory_autogen, Apache-2.0): {n_geo + n_simple} arterial 0-D modules "
        f"({n_geo} geometric, {n_simple} lumped) and {counts['terminal']} terminals. Module "
        f"equations from "
        f"upstream module_config.json/BG_modules.cellml: pv = R-I then C (L), vv = C/2-R-I-C/2 "
        f"(pi), pp = T mapped to pi x 2 segments, terminal = R_T/2-C_T-R_T/2 to "
        f"{venous_pressure:g} Pa (venous pressure); h(r) from the global a..d_vessel law, "
        f"Poisson ratio 0 (C = 2 pi r^3 l/(E h)). Not imported: {', '.join(skipped)} modules "
        f"({n_heart} heart): inflow at the aortic root ({root} inlet) is the {source}, "
        f"scaled to a mean of {q_mean * 1e6:.2f} mL/s ({q_mean * 6e4:.2f} L/min; {co_source}). "
        f"Dropped: {'' if wall_viscosity else 'wall-viscosity R_v = 0.01 s/C, '}terminal "
        f"I_T = 1e-6, gravity (beta_g 0)."
        + ("" if scale == 1.0 else
           f" Terminal resistances R_T scaled by {scale:.6g}{calibration}."))


def to_native_dict(vessel_array_csv: PathLike, parameters_csv: PathLike, *,
                   obs_data_json: PathLike | None = None,
                   inflow: str | tuple[Any, Any] | PathLike = "mynard2015",
                   mynard_template: PathLike | None = None,
                   cardiac_output: float | None = None, venous_pressure: float = 0.0,
                   terminal_resistance_scale: float | str = 1.0, wall_viscosity: bool = False,
                   name: str | None = None) -> dict[str, Any]:
    """The arterial tree of a circulatory_autogen model as a native oxyline model dict (SI).

    ``inflow``: ``"mynard2015"`` (the template of ``mynard_template``, default
    ``../shared/networks/pwdb/Mynard2015_aortic_flow_template.csv`` next to the repository) or a
    ``(time [s], flow [m^3/s])`` pair; scaled to ``cardiac_output`` [m^3/s] (default: the sum of
    the mean terminal flows of ``obs_data_json``; unscaled when neither is given).
    ``venous_pressure`` [Pa]: the pressure the terminals drain to (the closed loop's veins).
    ``terminal_resistance_scale``: multiplies every R_T (1 = the source values), or
    ``"calibrate"``: the one uniform factor that makes the cycle-mean pressure at the mean-pressure
    observation of ``obs_data_json`` equal its value at the mean inflow
    (:func:`calibrate_terminal_resistance_scale`; FinalModel: 7.71 for 12.0 kPa at
    ``aortic_arch_C46``, the built-in ``whole-body-140``).
    ``wall_viscosity``: keep the source's R_v = 0.01 s/C in series with every capacitor, as a
    dead-end branch per capacitor (``<node>.wall...``: R_v, then C, closed by zero flow); vessels
    become rigid geometric tubes (same radius and length, hence the same R, I and lumen volume;
    their C moves to the wall branches), ``pp`` modules an exact T (``<name>.distal_half``), and a
    1 Pa s m^-3 connector ``aortic_inlet`` carries the inflow. Removes the ~50 Hz ringing.
    """
    scale, calibration = _resistance_scale(
        terminal_resistance_scale, vessel_array_csv, parameters_csv, obs_data_json,
        {"inflow": inflow, "mynard_template": mynard_template, "cardiac_output": cardiac_output,
         "venous_pressure": venous_pressure})
    if not (scale > 0 and math.isfinite(scale)):
        raise ModelError(f"terminal_resistance_scale must be > 0, got {scale}")
    rows = read_vessel_array(vessel_array_csv)
    params = read_parameters(parameters_csv)
    tree, root = _tree(rows, vessel_array_csv)
    nodes = _node_names(tree, root)
    rho = _value(params, "rho", "Js2_per_m5", "global")
    mu = _value(params, "mu", "Js_per_m3", "global")
    period = _value(params, "T", "second", "global") if "T" in params else 1.0
    if "beta_g" in params and params["beta_g"][0] != 0:
        _warn(f"beta_g = {params['beta_g'][0]}: gravity is not modelled by oxyline, ignored")

    vessels, bcs = _vessels_and_outlets(tree, nodes, params, scale, venous_pressure)
    counts = Counter("terminal" if r["vessel_type"] in TERMINAL else
                     "simple" if r["vessel_type"] in SIMPLE else "geometric" for r in tree)

    t_in, q_in, source = _inflow(inflow, mynard_template, period)
    q_in, co_source = _scaled_inflow(t_in, q_in, cardiac_output, obs_data_json)
    q_mean = _cycle_mean(t_in, q_in)
    bcs = {"aortic_root": {"type": "flow", "time": [float(x) for x in t_in],
                           "flow": [float(x) for x in q_in], "interpolation": "linear"}, **bcs}

    description = _description(vessel_array_csv, rows, counts, root["name"], source, q_mean,
                               co_source, venous_pressure, wall_viscosity, scale, calibration)
    if wall_viscosity:
        vessels, bcs = _with_wall_viscosity(vessels, bcs)
        description += (" Wall viscosity kept: R_v = 0.01 s/C in series with every capacitor "
                        "as dead-end '.wall' branches; vessels rigid tubes of the same radius "
                        "and length (C in the wall branches), pp as an exact T.")
    return {
        "name": name or Path(vessel_array_csv).name.replace("_vessel_array.csv", ""),
        "description": description,
        "units": "SI",
        "blood": {"density": rho, "viscosity": mu},
        "arrangement": "L",
        "inertance_profile": "flat",
        "period": period,
        "vessels": vessels,
        "boundary_conditions": bcs,
        # stiff (stable RK4 step ~1e-4 s): implicit steps of 1 ms; ~60 cycles to 1e-6
        "simulation": {"cycles": 10, "until_periodic": 1e-6, "max_cycles": 200, "dt": 0.001,
                       "method": "generalized-alpha",
                       "output": {"cycles": "last", "every": 0.001}},
    }


def _vessels_and_outlets(tree: list[dict[str, Any]], nodes: dict[tuple[str, str], str],
                         params: dict[str, tuple[float, str, str]], scale: float,
                         venous_pressure: float
                         ) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """The native vessels of the tree's modules (terminals as R_T/2, C_T, R_T/2 lumped vessels)
    and the terminals' outlet conditions."""
    vessels: list[dict[str, Any]] = []
    bcs: dict[str, dict[str, Any]] = {}
    for r in tree:
        nm = r["name"]
        ends = (nodes[(nm, "in")], nodes[(nm, "out")])
        u_ext = params.get(f"u_ext_{nm}", (0.0, "J_per_m3", ""))[0]
        if abs(u_ext) > 1.0:
            _warn(f"'{nm}': u_ext = {u_ext} Pa ignored (no external pressure on 0-D vessels)")
        if r["vessel_type"] in TERMINAL:
            vessel, bcs[ends[1]] = _terminal(nm, ends, params, scale, venous_pressure)
            vessels.append(vessel)
        else:
            vessels.append(_artery(r, ends, params))
    return vessels, bcs


def _with_wall_viscosity(vessels: list[dict[str, Any]], bcs: dict[str, dict[str, Any]]
                         ) -> tuple[list[dict[str, Any]], dict[str, dict[str, Any]]]:
    """Re-express every capacitor C as a branch R_v = 0.01 s / C -> C -> zero flow; geometric
    vessels become rigid tubes of the same radius and length (same R, I and lumen volume)."""
    out: list[dict[str, Any]] = []
    new_bcs: dict[str, dict[str, Any]] = {}

    def rl(name: str, a: str, b: str, r: float, ind: float) -> dict[str, Any]:
        return {"name": name, "from": a, "to": b, "arrangement": "L",
                "lumped": {"resistance": r, "inductance": ind, "capacitance": 0.0}}

    def rigid(name: str, a: str, b: str, v: dict[str, Any], fraction: float) -> dict[str, Any]:
        return {"name": name, "from": a, "to": b, "segments": 1,
                "length": v["length"] * fraction, "radius": v["radius"]}

    def wall(node: str, c: float, tag: str = "") -> None:
        nm = f"{node}.wall{tag}"
        out.append({"name": nm, "from": node, "to": f"{nm}.end", "arrangement": "L",
                    "lumped": {"resistance": 0.01 / c, "inductance": 0.0, "capacitance": c},
                    "description": "wall viscosity R_v = 0.01 s / C in series with C"})
        new_bcs[f"{nm}.end"] = {"type": "flow", "value": 0.0}

    for node, bc in bcs.items():
        if bc["type"] == "flow":
            out.append(rl("aortic_inlet", "aortic_inlet", node, 1.0, 0.0))
            new_bcs["aortic_inlet"] = bc
    for v in vessels:
        desc = {"description": v["description"]} if "description" in v else {}
        if "lumped" in v:                                  # terminal: R_T/2, C_T, R_T/2
            half = v["lumped"]["resistance"]
            mid = v["to"]
            out.append({**rl(v["name"], v["from"], mid, half, 0.0), **desc})
            wall(mid, v["lumped"]["capacitance"])
            out.append(rl(f"{v['name']}.distal_half", mid, f"{mid}.outlet", half, 0.0))
            new_bcs[f"{mid}.outlet"] = {"type": "pressure", "value": bcs[mid]["pressure"]}
            continue
        r, length = v["radius"], v["length"]
        C = _core.thin_wall_compliance(r, length, v["youngs_modulus"], v["wall_thickness"],
                                       v["poisson_ratio"])  # the vessel's own C
        # one rigid tube, or the two halves of a pp module: R/2, I/2 - C - R/2, I/2
        whole = v["arrangement"] != "pi" or v.get("segments", 1) == 1
        mid = v["to"] if whole else f"{v['name']}.mid"
        out.append({**rigid(v["name"], v["from"], mid, v, 1.0 if whole else 0.5), **desc})
        if v["arrangement"] == "L":
            wall(v["to"], C)
        elif v["arrangement"] == "inverted-L":
            wall(v["from"], C, f"_{v['name']}")
        elif whole:                                        # pi: C/2 - R-I - C/2
            wall(v["from"], C / 2, f"_in_{v['name']}")
            wall(v["to"], C / 2, f"_out_{v['name']}")
        else:
            out.append(rigid(f"{v['name']}.distal_half", mid, v["to"], v, 0.5))
            wall(mid, C)
    return out, new_bcs


def steady_pressures(d: dict[str, Any],
                     terminal_scale: float = 1.0) -> tuple[dict[str, float], float]:
    """Node pressures [Pa] of the steady state of a native model dict (capacitors open,
    inductors shorted) fed by the cycle-mean of each flow boundary: for a linear circuit with a
    periodic inflow these are exactly the cycle-mean pressures. The steady state is the core's
    (``Network.steady_state``), on the circuit it assembles. ``terminal_scale`` multiplies the
    resistance of every ``resistance`` outlet and of the lumped vessel feeding it (the two
    halves of a circulatory_autogen terminal). Returns (pressures, mean inflow)."""
    scaled = json.loads(json.dumps(d))
    bcs = scaled["boundary_conditions"]
    for v in scaled["vessels"]:
        if "lumped" in v and bcs.get(v["to"], {}).get("type") == "resistance":
            v["lumped"]["resistance"] *= terminal_scale
    q_in = 0.0
    for bc in bcs.values():
        if bc["type"] == "resistance":
            bc["resistance"] *= terminal_scale
        elif bc["type"] == "flow":
            q_in += (_cycle_mean(np.asarray(bc["time"], float), np.asarray(bc["flow"], float))
                     if "time" in bc else float(bc["value"]))
    # a trial point of the calibration, not the user's model: its terminal resistances may be
    # far from physiological on the way (the calibrated model is checked when it is loaded)
    st = _build(scaled, plausibility=False).network.steady_state()
    return dict(zip(st["nodes"], st["node_pressure"].tolist(), strict=True)), q_in


def mean_pressure_observations(obs_data_json: PathLike) -> dict[str, float]:
    """``module -> value [Pa]`` of the mean pressure observations (``<module>/u``, J_per_m3)."""
    data = json.loads(Path(obs_data_json).read_text())
    return {str(it["variable"])[:-2]: float(it["value"]) for it in data.get("data_items", [])
            if str(it.get("variable", "")).endswith("/u") and it.get("obs_type") == "mean"
            and it.get("unit") == "J_per_m3"}


def calibrate_terminal_resistance_scale(d: dict[str, Any], obs_data_json: PathLike
                                        ) -> tuple[float, str, float]:
    """The uniform factor s on every terminal resistance R_T of ``d`` (a native dict of
    :func:`to_native_dict` with scale 1 and without wall viscosity) that makes the cycle-mean
    pressure at the one mean-pressure observation of ``obs_data_json`` equal its value, at the
    model's mean inflow. Cycle means of the linear circuit are its steady resistive solution
    (:func:`steady_pressures`), so s solves P(s) = target, P increasing in s; found by a
    bracketed secant iteration on log P(log s) to 1e-11. The observed module's ``u`` is the pressure of its C node: the distal node
    of a ``pv`` (``L``) module. A uniform s keeps the source's ratios between the R_T (its
    distribution of peripheral resistance). Returns (s, module, target [Pa])."""
    obs = mean_pressure_observations(obs_data_json)
    if len(obs) != 1:
        raise ModelError(f"{obs_data_json}: expected one mean-pressure observation, got "
                         f"{sorted(obs)}")
    (module, target), = obs.items()
    vessel = next((v for v in d["vessels"] if v["name"] == module), None)
    if vessel is None or vessel.get("arrangement") != "L":
        raise ModelError(f"observed module '{module}' is not a pv (L) vessel of the model")

    def f(x: float) -> float:                     # log P(e^x) - log target, increasing
        P, _q = steady_pressures(d, math.exp(x))
        if P[vessel["to"]] <= 0:
            return -math.inf
        return math.log(P[vessel["to"]] / target)

    lo, hi = math.log(1e-3), math.log(1e3)
    f_hi = f(hi)
    if not f(lo) < 0 < f_hi:
        raise ModelError(f"the observed {target} Pa at '{module}' is out of reach of a terminal "
                         f"resistance scale in [1e-3, 1e3]")
    x_old, f_old = hi, f_hi
    x, fx = 0.0, f(0.0)
    for _ in range(100):                          # secant on the last two points, kept inside
        if abs(fx) < 1e-11:                       # the bracket (bisection otherwise)
            break
        lo, hi = (x, hi) if fx < 0 else (lo, x)
        step = x - fx * (x - x_old) / (fx - f_old) if fx != f_old else math.nan
        x_old, f_old = x, fx
        x = step if lo < step < hi else (lo + hi) / 2
        fx = f(x)
    else:
        raise ModelError("terminal resistance calibration did not converge")
    return math.exp(x), module, target


def read_circulatory_autogen(vessel_array_csv: PathLike, parameters_csv: PathLike,
                             **options: Any) -> Model:
    """Load a circulatory_autogen model's arterial tree as an :class:`oxyline.Model`; options as
    :func:`to_native_dict`."""
    return build(to_native_dict(vessel_array_csv, parameters_csv, **options), owned=True)


__all__ = ["CirculatoryAutogenWarning", "calibrate_terminal_resistance_scale",
           "cardiac_output_from_obs", "mean_pressure_observations", "mynard_aortic_flow",
           "read_circulatory_autogen", "read_parameters", "read_vessel_array", "steady_pressures",
           "to_native_dict", "wall_thickness"]
