"""A PWDB-like population's baseline subjects calibrated to in-vivo data (docs/populations.md,
"Calibration to in-vivo data"): :func:`calibrate_baseline` fits a decade's baseline subject
of :mod:`oxyline.populations` to McEniery 2005 (:func:`oxyline.populations.in_vivo`) with
:func:`oxyline.calibrate`, and :func:`apply_factors` carries its factors to any subject.

>>> from oxyline import population_fit, populations
>>> f = {"distal_resistance": 1.1, "proximal_resistance": 1.0, "capacitance": 0.8,
...      "inflow": 1.0}
>>> row, _ = population_fit.baseline_subject(45)
>>> patch = population_fit.apply_factors(populations.subject_patch(row), f)
>>> bool(patch["boundary_conditions"]["n11"]["capacitance"] > 0)
True
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any

from oxyline import pwdb
from oxyline.calibrate import calibrate
from oxyline.calibrate import sensitivities as exact
from oxyline.populations import VARIED, base_model, in_vivo, parameters, patched, subject_patch

#: the outputs of the calibration (names of :mod:`oxyline.targets`) and what they measure:
#: the aortic root (inlet of the ascending aorta) and the brachial site (end of the left
#: brachial artery, :data:`oxyline.pwdb.SITES`), and the cardiac output
_OUTPUTS = {"aortic_sbp": "ascending_aorta.pressure_in.max",
            "aortic_pp": "ascending_aorta.pressure_in.pulse",
            "brachial_sbp": "left_brachial_artery.pressure_out.max",
            "brachial_dbp": "left_brachial_artery.pressure_out.min",
            "co": "cardiac_output"}
#: the fitted variables: one factor on every outlet's distal resistance, proximal resistance
#: and capacitance (groups of :func:`oxyline.calibrate`), and the inflow scale
FACTORS = ("distal_resistance", "proximal_resistance", "capacitance")
#: the cardiac output is the subject's own design value (HR x SV): held to 1 %
CO_SIGMA = 0.01


def characteristics(values: Mapping[str, float]) -> dict[str, float]:
    """The compared characteristics [mmHg; L/min] from the outputs' values (SI)."""
    mm = {k: values[k] / pwdb.MMHG for k in _OUTPUTS if k != "co"}
    pp_b = mm["brachial_sbp"] - mm["brachial_dbp"]
    return {**mm, "brachial_pp": pp_b, "aortic_dbp": mm["aortic_sbp"] - mm["aortic_pp"],
            "pp_amplification": pp_b / mm["aortic_pp"], "co": values["co"] * 60000.0}


def baseline_subject(age: float) -> tuple[dict[str, float], dict[str, Any]]:
    """The baseline subject of ``age`` (every varied parameter at the age's mean) and its
    model dict (``pwdb-116`` with the subject's patch)."""
    table = parameters((age,), 3)
    row = table[(table[[f"{p}_sd" for p in VARIED]] == 0).all(axis=1)].iloc[0].to_dict()
    return row, patched(base_model(), subject_patch(row))


def calibrate_baseline(age: float, tol: float = 1e-8, **options: Any) -> dict[str, Any]:
    """Fit the baseline subject of ``age`` to McEniery 2005 (:func:`in_vivo`): aortic SBP and
    PP and brachial SBP and DBP weighed by their in-vivo SDs, and the subject's cardiac output
    (to :data:`CO_SIGMA`), by one factor on all outlets' distal and on all proximal
    resistances and capacitances and the inflow scale (:func:`oxyline.calibrate`; the wall
    stiffness stays the wall law's for the subject's cf-PWV). Returns the ``target``,
    ``before`` and ``after`` :func:`characteristics`, the ``factors`` and the ``fit``."""
    row, model = baseline_subject(age)
    stats = in_vivo(age)
    target = {k: stats[k][0] for k in ("aortic_sbp", "aortic_pp", "brachial_sbp",
                                       "brachial_dbp")}
    targets = {_OUTPUTS[k]: {"value": v * pwdb.MMHG, "sigma": stats[k][1] * pwdb.MMHG}
               for k, v in target.items()}
    co = float(row["co"]) / 60000.0
    targets[_OUTPUTS["co"]] = {"value": co, "sigma": CO_SIGMA * co}
    outlets = [n for n, bc in model["boundary_conditions"].items()
               if str(bc.get("type")) == "rcr"]
    groups = {f"outlets.{k}": [f"boundary_conditions.{n}.{k}" for n in outlets]
              for k in FACTORS}
    # the data are known to ~1 mmHg: a relative step of 1e-6 in the factors is plenty
    options = {"xtol": 1e-6, **options}
    fit = calibrate(model, targets, ["scale.inflow"], groups=groups, method="lm", tol=tol,
                    **options)
    names = list(_OUTPUTS)
    before = exact(model, [], [_OUTPUTS[k] for k in names], tol=tol).values
    after = exact(fit.model, [], [_OUTPUTS[k] for k in names], tol=tol).values
    target_all = {**{k: v * pwdb.MMHG for k, v in target.items()}, "co": co}
    return {"age": age, "target": characteristics(target_all),
            "before": characteristics(dict(zip(names, before, strict=True))),
            "after": characteristics(dict(zip(names, after, strict=True))),
            "factors": {**{k: fit.parameters[f"outlets.{k}"] for k in FACTORS},
                        "inflow": fit.parameters["scale.inflow"]},
            "fit": fit}


def apply_factors(patch: Mapping[str, Any], factors: Mapping[str, float]) -> dict[str, Any]:
    """A subject's patch with a decade's calibrated ``factors`` (:func:`calibrate_baseline`)
    applied: every outlet's R1, R2 and C and the inflow table's flow scaled."""
    out = copy.deepcopy(dict(patch))
    for node, bc in out["boundary_conditions"].items():
        if node == pwdb.INLET_NODE:
            bc["flow"] = [q * factors["inflow"] for q in bc["flow"]]
            continue
        for k in FACTORS:
            bc[k] = bc[k] * factors[k]
    return out
