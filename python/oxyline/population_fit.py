"""A PWDB-like population calibrated to in-vivo data (docs/populations.md, "Calibration to
in-vivo data"): :func:`calibrate_baseline` fits a decade's baseline subject of
:mod:`oxyline.populations` to McEniery 2005 (:func:`oxyline.populations.in_vivo`) and its
cf-PWV target with the core's exact sensitivities, :func:`apply_factors` carries the factors
to any subject, and :func:`population` runs subjects and lists those outside PWDB's 99 %
plausibility ranges with the value that failed, then either resamples each towards its
decade's baseline until it is inside (:func:`shrunk_row`) or applies PWDB's exclusion rule.

>>> from oxyline import population_fit, populations
>>> f = {"distal_resistance": 1.1, "proximal_resistance": 1.0, "capacitance": 0.8,
...      "inflow": 1.0, "arm_stiffness": 1.2, "aortic_stiffness": 1.0}
>>> row, _ = population_fit.baseline_subject(45)
>>> patch = population_fit.apply_factors(populations.subject_patch(row), f)
>>> bool(patch["boundary_conditions"]["n11"]["capacitance"] > 0)
True
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

import oxyline
from oxyline import pwdb
from oxyline.calibrate import Derived, _least_squares, _Problem
from oxyline.model import build_model
from oxyline.populations import (
    VARIED,
    _base,
    age_statistics,
    base_model,
    baseline_row,
    cf_pwv,
    in_vivo,
    parameters,
    patched,
    plausible_ranges,
    subject_patch,
    subject_summary,
    summary_vessels,
)
from oxyline.targets import CalibrationError, Target, signals_for

#: the fitted characteristics, in this order: McEniery 2005's aortic SBP and PP, brachial SBP
#: and DBP and PP amplification [mmHg, ratio], the subject's cf-PWV [m/s] (the wall law's
#: target, Mattace-Raso 2010) and cardiac output [L/min] (HR x SV)
CHARACTERISTICS = ("aortic_sbp", "aortic_pp", "brachial_sbp", "brachial_dbp",
                   "pp_amplification", "cf_pwv", "co")
#: the outlet groups: one factor on every outlet's distal resistance, proximal resistance
#: and capacitance
FACTORS = ("distal_resistance", "proximal_resistance", "capacitance")
#: the wall-stiffness groups: one factor on the Young's modulus of every vessel whose name
#: holds one of the words (the arms from the subclavians to the digital arteries; the aorta)
STIFFNESS = {"arm_stiffness": ("subclavian", "brachial", "radial", "ulnar", "interosseous",
                               "palmar", "digital"),
             "aortic_stiffness": ("aort",)}
#: every fitted variable (a factor, 1 = the population's own value)
VARIABLES = (*FACTORS, "inflow", *STIFFNESS)
#: the cardiac output is the subject's own design value (HR x SV): held to 1 %
CO_SIGMA = 0.01
#: the prior SD of every log factor: a factor of 2 either way is one SD. The seven
#: characteristics nearly determine the six factors, and without a prior the fit buys the
#: last mmHg with unphysical factors (the outlet capacitance x 34 at 45 y); with it, a factor
#: moves only as far as the in-vivo data ask
PRIOR_SIGMA = float(np.log(2.0))


def _seg(s: int) -> str:
    return str(_base()[0][s - 1]["name"])


def _outputs() -> dict[str, str]:
    """The core's outputs the characteristics are made of (names of :mod:`oxyline.targets`):
    the aortic root (inlet of the ascending aorta), the brachial site (end of the left
    brachial), the cardiac output, and four pulse-wave velocities from the aortic root to
    the inlets and outlets of PWDB's carotid and femoral segments (:data:`oxyline.pwdb.SITES`)."""
    root, brachial = _seg(1), _seg(pwdb.SITES["brachial"][0])
    return {"aortic_sbp": f"{root}.pressure_in.max", "aortic_pp": f"{root}.pressure_in.pulse",
            "brachial_sbp": f"{brachial}.pressure_out.max",
            "brachial_dbp": f"{brachial}.pressure_out.min", "co": "cardiac_output",
            "carotid_in": f"pwv.{root}.{_seg(pwdb.AORTA_CAROTID[-1])}",
            "carotid_out": f"pwv.{root}.{_seg(pwdb.CAROTID_SEGMENT)}",
            "femoral_in": f"pwv.{root}.{_seg(pwdb.AORTA_FEMORAL[-1])}",
            "femoral_out": f"pwv.{root}.{_seg(pwdb.FEMORAL_SEGMENT)}"}


def _path_lengths(model: Mapping[str, Any]) -> np.ndarray:
    """Lengths [m] from the aortic root to the four pulse-wave sites of :func:`_outputs`."""
    length = {str(v["name"]): float(v["length"]) for v in model["vessels"]}
    af, ac = pwdb.AORTA_FEMORAL, pwdb.AORTA_CAROTID
    return np.array([sum(length[_seg(s)] for s in path) for path in
                     (ac, (*ac, pwdb.CAROTID_SEGMENT), af, (*af, pwdb.FEMORAL_SEGMENT))])


def characteristics(values: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """The :data:`CHARACTERISTICS` from the values of :func:`_outputs` (SI, in its order) and
    :func:`_path_lengths`. cf-PWV by PWDB's path convention (aorta-femoral path minus
    aorta-carotid path) with mid-segment sites: the mean of the inlet and outlet sites'
    transit times and lengths. Written for complex values too (complex-step derivatives)."""
    sbp_a, pp_a, sbp_b, dbp_b = (values[k] / pwdb.MMHG for k in range(4))
    co = values[4] * 60000.0
    transit = lengths / values[5:9]          # root-to-site foot-to-foot times
    cf_len = (lengths[2] + lengths[3] - lengths[0] - lengths[1]) / 2
    cf_time = (transit[2] + transit[3] - transit[0] - transit[1]) / 2
    return np.array([sbp_a, pp_a, sbp_b, dbp_b, (sbp_b - dbp_b) / pp_a, cf_len / cf_time, co])


def _characteristics_jacobian(values: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """d characteristics / d outputs, exact by complex step (the characteristics are
    rational functions of the outputs)."""
    h = 1e-30 * np.maximum(np.abs(values), 1e-300)
    cols = []
    for k in range(len(values)):
        z = values.astype(complex)
        z[k] += 1j * h[k]
        cols.append(characteristics(z, lengths).imag / h[k])
    return np.column_stack(cols)


def baseline_subject(age: float) -> tuple[dict[str, float], dict[str, Any]]:
    """The baseline subject of ``age`` (every varied parameter at the age's mean) and its
    model dict (``pwdb-116`` with the subject's patch)."""
    row = baseline_row(age)
    return row, patched(base_model(), subject_patch(row))


def _group_paths(model: Mapping[str, Any]) -> dict[str, list[str]]:
    """The model paths each :data:`VARIABLES` factor moves."""
    outlets = [n for n, bc in model["boundary_conditions"].items()
               if str(bc.get("type")) == "rcr"]
    out = {k: [f"boundary_conditions.{n}.{k}" for n in outlets] for k in FACTORS}
    out["inflow"] = ["scale.inflow"]
    for g, words in STIFFNESS.items():
        out[g] = [f"vessels.{v['name']}.youngs_modulus" for v in model["vessels"]
                  if any(w in str(v["name"]) for w in words)]
    return out


def targets_of(age: float, row: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """The :data:`CHARACTERISTICS`' targets and SDs at ``age`` for the subject ``row``:
    McEniery 2005 (pooled, :func:`in_vivo` with the fit's values: the women's aortic PP at
    75 y 46 mmHg, the value their other characteristics give, not the transcribed 56, which
    no model can meet together with the brachial PP and the amplification); cf-PWV the subject's own target with the half
    width of its ±1 SD (:func:`oxyline.populations.cf_pwv`); the cardiac output HR x SV to
    :data:`CO_SIGMA`."""
    st = in_vivo(age, fit=True)
    pwv_sd = (cf_pwv(float(age), float(row["mbp"]), 1.0)
              - cf_pwv(float(age), float(row["mbp"]), -1.0)) / 2
    mean = [*(st[k][0] for k in CHARACTERISTICS[:5]), float(row["pwv"]), float(row["co"])]
    sd = [*(st[k][1] for k in CHARACTERISTICS[:5]), pwv_sd, CO_SIGMA * float(row["co"])]
    return np.array(mean), np.array(sd)


def _problem(age: float, tol: float) -> _Problem:
    """:func:`calibrate_baseline`'s fit as calibrate's least-squares problem
    (:class:`oxyline.calibrate._Problem`): the baseline subject's model, one group factor per
    :data:`VARIABLES` on the paths it moves (:func:`_group_paths`), the outputs of
    :func:`_outputs` reduced to the :data:`CHARACTERISTICS` (:class:`~oxyline.calibrate.
    Derived`) against :func:`targets_of`, the prior :data:`PRIOR_SIGMA` on each log factor,
    and the core's adjoint Jacobian (many paths, nine outputs: one backward sweep per output,
    in the same run as the primal, so a trial point's Jacobian costs no second run)."""
    row, model = baseline_subject(age)
    target, sigma = targets_of(age, row)
    lengths = _path_lengths(model)
    outputs = list(_outputs().values())
    signals = signals_for(outputs, build_model(model), CalibrationError)
    targets = [Target(o, None, signals=sig) for o, sig in zip(outputs, signals, strict=True)]

    def of(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return characteristics(values, lengths).real, \
            _characteristics_jacobian(values, lengths)

    return _Problem(model, list(VARIABLES), np.ones(len(VARIABLES)), targets,
                    {"steps_per_cycle": None, "tol": tol, "max_cycles": 2000},
                    groups=_group_paths(model), gradient="adjoint",
                    derived=Derived(of, target, sigma), prior=PRIOR_SIGMA)


def calibrate_baseline(age: float, tol: float = 1e-8, xtol: float = 1e-6,
                       max_evaluations: int = 60) -> dict[str, Any]:
    """Fit the baseline subject of ``age`` to its :func:`targets_of` (McEniery 2005's aortic
    SBP and PP, brachial SBP and DBP and PP amplification, the subject's cf-PWV and cardiac
    output, each weighed by its SD) by one factor on all outlets' distal resistances, one on
    all proximal resistances, one on all capacitances, the inflow scale, and one factor on
    the Young's modulus of the arm and one of the aortic vessels (:data:`STIFFNESS`):
    Levenberg-Marquardt on the log factors with the core's exact adjoint Jacobian and a
    prior on each log factor (:data:`PRIOR_SIGMA`; the default xtol of 1e-6: the data are
    known to a few per cent), as :func:`oxyline.calibrate` fits (:func:`_problem`). Returns
    the ``target``, ``sigma``, ``before`` and ``after`` characteristics (dicts by name), the
    ``factors``, the ``jacobian`` (d characteristic / d log factor at the start) and the
    ``report``."""
    problem = _problem(age, tol)
    data, sigma = problem.data, problem.sigma
    start = np.zeros(len(VARIABLES))
    before = problem.fitted(start)
    jac0 = problem.jac(start)[:len(data)] * sigma[:, None]
    fit = _least_squares(problem, np.full(len(start), -np.inf), np.full(len(start), np.inf),
                         "lm", max_evaluations, xtol, 1e-10, gtol=1e-10)
    assert problem.end is not None
    after = problem.fitted(problem.end)

    def named(v: np.ndarray) -> dict[str, float]:
        return dict(zip(CHARACTERISTICS, map(float, v), strict=True))

    return {"age": age, "target": named(data), "sigma": named(sigma),
            "before": named(before), "after": named(after),
            "factors": {k: float(v) for k, v in fit.parameters.items()},
            "jacobian": {c: dict(zip(VARIABLES, map(float, jac0[i]), strict=True))
                         for i, c in enumerate(CHARACTERISTICS)},
            "report": {"success": fit.success, "message": str(fit.report.get("message")),
                       "evaluations": problem.evaluations, "cost": fit.cost}}


def apply_factors(patch: Mapping[str, Any], factors: Mapping[str, float]) -> dict[str, Any]:
    """A subject's patch with a decade's calibrated ``factors`` (:func:`calibrate_baseline`)
    applied: every outlet's R1, R2 and C, the inflow table's flow and the Young's modulus of
    the :data:`STIFFNESS` groups' vessels scaled (a factor not given is 1)."""
    unknown = set(factors) - set(VARIABLES)
    if unknown:
        raise CalibrationError(f"apply_factors: unknown factors {sorted(unknown)} (expected "
                               f"some of {list(VARIABLES)})")
    f = {k: float(factors.get(k, 1.0)) for k in VARIABLES}
    out = copy.deepcopy(dict(patch))
    for node, bc in out["boundary_conditions"].items():
        if node == pwdb.INLET_NODE:
            bc["flow"] = [q * f["inflow"] for q in bc["flow"]]
            continue
        for k in FACTORS:
            bc[k] = bc[k] * f[k]
    for name, v in out.get("vessels", {}).items():
        for g, words in STIFFNESS.items():
            if "youngs_modulus" in v and any(w in name for w in words):
                v["youngs_modulus"] = v["youngs_modulus"] * f[g]
    return out


# ------------------------------------------------------------- PWDB's exclusion rule


def pwdb_characteristics(summary: Mapping[str, float]) -> dict[str, float]:
    """The characteristics PWDB checks against McEniery 2005 (those of
    :func:`oxyline.populations.plausible_ranges`) from a :func:`~oxyline.populations.
    subject_summary`."""
    pp_b = summary["brachial_sbp"] - summary["brachial_dbp"]
    pp_a = summary["aortic_root_sbp"] - summary["aortic_root_dbp"]
    return {"brachial_sbp": summary["brachial_sbp"], "brachial_dbp": summary["brachial_dbp"],
            "brachial_pp": pp_b, "brachial_map": summary["brachial_map"],
            "aortic_sbp": summary["aortic_root_sbp"], "aortic_pp": pp_a,
            "pp_amplification": pp_b / pp_a}


def implausible(age: float, summary: Mapping[str, float]) -> list[dict[str, Any]]:
    """The characteristics of a subject of ``age`` outside PWDB's 99 % ranges: one record
    (``characteristic``, ``value``, ``low``, ``high``) each; empty if it is plausible."""
    c = pwdb_characteristics(summary)
    return [{"characteristic": k, "value": c[k], "low": lo, "high": hi}
            for k, (lo, hi) in plausible_ranges(age).items() if not lo <= c[k] <= hi]


#: the fractions of its SD levels a subject outside the 99 % ranges is tried at, in this
#: order (:func:`shrunk_row`): the first plausible one is kept. 0 is the decade's baseline,
#: which the calibration puts within a fraction of an in-vivo SD of every target
SHRINK = (0.9, 0.8, 0.7, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.0)


def shrunk_row(row: Mapping[str, float], fraction: float) -> dict[str, float]:
    """The subject ``row`` (of :func:`~oxyline.populations.parameters`) moved towards its
    decade's baseline: every SD level times ``fraction`` (1: the subject, 0: the baseline),
    the values re-derived as :func:`~oxyline.populations.parameters` derives them (HR, SV,
    MBP and diameter at mean + level x SD; the cf-PWV target the wall law's at the new MBP
    and level; LVET, which PWDB normalises over the whole factorial, on the line from the
    baseline's to the subject's). ``fraction`` is kept in the row as ``fraction``."""
    if not 0.0 <= fraction <= 1.0:
        raise CalibrationError(f"shrunk_row: fraction {fraction!r} is not in [0, 1]")
    age = float(row["age"])
    st = age_statistics(age)
    out = dict(row)
    for p in VARIED:
        out[f"{p}_sd"] = float(row[f"{p}_sd"]) * fraction
    for p in ("hr", "sv", "mbp"):
        out[p] = st[p][0] + out[f"{p}_sd"] * st[p][1]
    out["dia"] = (st["dia"][0] + out["dia_sd"] * st["dia"][1]) / 100
    out["pwv"] = cf_pwv(age, float(out["mbp"]), float(out["pwv_sd"]))
    base = _baseline_lvet(age)
    out["lvet"] = base + fraction * (float(row["lvet"]) - base)
    out["co"] = out["hr"] * out["sv"] / 1000
    out["fraction"] = float(fraction)
    return out


@lru_cache(maxsize=16)
def _baseline_lvet(age: float) -> float:
    return float(baseline_row(age)["lvet"])


@dataclass
class Population:
    """Subjects run and screened: ``table`` (their :func:`~oxyline.populations.parameters`
    rows, kept ones only when screened; resampled ones with their moved values, every row
    with the ``fraction`` of its SD levels kept), ``summaries`` (one
    :func:`~oxyline.populations.subject_summary` per row of ``table``), ``patches``,
    ``excluded``: one row per failed characteristic of every subject outside the ranges as
    generated (``subject``, ``age``, ``characteristic``, ``value``, ``low``, ``high``), and
    ``resampled``: one row per subject moved inside (``subject``, ``age``, ``fraction``)."""

    table: Any
    summaries: Any
    patches: list[dict[str, Any]]
    excluded: Any
    resampled: Any = None


def _subject(row: Mapping[str, float], factors: Mapping[str, float] | None,
             run: Callable[[dict[str, Any]], Mapping[str, float]]
             ) -> tuple[dict[str, Any], dict[str, float]]:
    """A subject's patch (with its decade's ``factors``) and its run's summary."""
    patch = subject_patch(row)
    if factors is not None:
        patch = apply_factors(patch, factors)
    return patch, dict(run(patched(base_model(), patch)))


def _resample(row: Mapping[str, float], factors: Mapping[str, float] | None,
              run: Callable[[dict[str, Any]], Mapping[str, float]]
              ) -> tuple[dict[str, float], dict[str, Any], dict[str, float]] | None:
    """The first of :data:`SHRINK`'s moved subjects (:func:`shrunk_row`) inside every 99 %
    range: its row, patch and summary; None if none is (not even the baseline)."""
    for fraction in SHRINK:
        moved = shrunk_row(row, fraction)
        patch, summary = _subject(moved, factors, run)
        if not implausible(float(row["age"]), summary):
            return moved, patch, summary
    return None


def population(ages: Sequence[float] = (25, 35, 45, 55, 65, 75), levels: int = 3, *,
               subjects: Sequence[int] | None = None,
               factors: Mapping[float, Mapping[str, float]] | None = None,
               plausible_only: bool = False, resample: bool = False,
               run: Callable[[dict[str, Any]], Mapping[str, float]] | None = None
               ) -> Population:
    """Run the PWDB-like subjects of ``ages`` (``subjects``: their row numbers in
    :func:`~oxyline.populations.parameters`, default all), with each age's calibrated
    ``factors`` ({age: factors of :func:`calibrate_baseline`}) if given, and summarise each.
    ``excluded`` lists every subject outside McEniery 2005's 99 % ranges as generated, with
    each characteristic and value that failed. Then ``resample``: such a subject is replaced
    by the first of its moves towards the decade's baseline (:data:`SHRINK`,
    :func:`shrunk_row`) inside every range, listed in ``resampled`` (the population keeps
    its size, every subject plausible; a subject whose baseline too is outside stays out of
    ``table``); else ``plausible_only``: PWDB's rule (Charlton et al. 2019), such subjects
    leave ``table``. ``run``: model dict -> summary (default: :func:`oxyline.simulate` to
    periodicity 1e-4 and :func:`~oxyline.populations.subject_summary`)."""
    import pandas as pd

    table = parameters(tuple(ages), levels)
    picks = list(range(len(table))) if subjects is None else [int(i) for i in subjects]
    bad_pick = [i for i in picks if not 0 <= i < len(table)]
    if bad_pick:
        raise CalibrationError(f"population: subject {bad_pick[0]} is not one of the "
                               f"{len(table)} subjects of ages {list(ages)}")
    run = run or _simulate
    kept, rows, summaries, used, failed, moved = [], [], [], [], [], []
    for i in picks:
        row = {**table.iloc[i].to_dict(), "fraction": 1.0}
        age = float(row["age"])
        if factors is not None and age not in factors:
            raise CalibrationError(f"population: no calibrated factors for age {age:g} "
                                   f"(have {sorted(factors)})")
        fac = None if factors is None else factors[age]
        patch, summary = _subject(row, fac, run)
        bad = implausible(age, summary)
        failed += [{"subject": i, "age": age, **b} for b in bad]
        if bad and resample:
            found = _resample(row, fac, run)
            if found is None:
                continue
            row, patch, summary = found
            moved.append({"subject": i, "age": age, "fraction": row["fraction"]})
        elif bad and plausible_only:
            continue
        kept.append(i)
        rows.append(row)
        summaries.append(summary)
        used.append(patch)
    index = table.index[kept]
    excluded = pd.DataFrame(failed, columns=["subject", "age", "characteristic", "value",
                                             "low", "high"])
    return Population(pd.DataFrame(rows, index=index, columns=[*table.columns, "fraction"]),
                      pd.DataFrame(summaries, index=index), used, excluded,
                      pd.DataFrame(moved, columns=["subject", "age", "fraction"]))


def _simulate(model: dict[str, Any]) -> Mapping[str, float]:
    res = oxyline.simulate(model, until_periodic=1e-4, vessels=summary_vessels(),
                           variables=["pressure_in", "pressure_out", "segment_pressure_in"],
                           progress=False)
    return subject_summary(res)
