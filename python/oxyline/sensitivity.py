"""Global sensitivity analysis on SALib: Sobol' indices of any output of a network.

:func:`sobol` samples the parameters with SALib's Saltelli/Sobol' sequence, runs every sample
as one variant of an ensemble (:func:`oxyline.simulate_ensemble`: every core, or a Dask
cluster) and estimates first- and total-order indices with SALib's Sobol' analysis.
Parameters are dotted patch paths (``vessels.ICA.radius``, ``boundary_conditions.ica_out.
resistance``, ``oxygen.wall.k``, ``scale.resistance``), in the model's units. Needs SALib
(``pip install 'oxyline[ensemble]'``).
"""

from __future__ import annotations

import math
import operator
import os
import re
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from oxyline.ensemble.collect import FACTS
from oxyline.errors import ModelError
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.result import Result

Quantity = (str | tuple[str, str] | Callable[[Result], float | Mapping[str, float]]
            | Sequence[str | tuple[str, str]])
_NAMED = re.compile(r"^(?P<var>[A-Za-z0-9_]+)\[(?P<vessel>.+)\]$")


def _salib() -> tuple[Any, Any]:
    try:
        from SALib.analyze import sobol as analyze
        from SALib.sample import sobol as sample
    except ImportError:
        raise ImportError("oxyline.sensitivity needs SALib: pip install 'oxyline[ensemble]'") \
            from None
    return sample, analyze


def _named(quantity: Any) -> list[tuple[str, str]] | None:
    """Summary variables ``"var[vessel]"`` or ``(var, vessel)`` (one or a list), or None for
    a callable; anything else raises, naming it."""
    items = [quantity] if isinstance(quantity, (str, tuple)) else quantity
    if callable(items):
        return None
    out = []
    for q in items if isinstance(items, Sequence) else [items]:
        if isinstance(q, tuple) and len(q) == 2:
            out.append((str(q[0]), str(q[1])))
            continue
        m = _NAMED.match(q) if isinstance(q, str) else None
        if m is None:
            raise ModelError(f"sobol: a quantity is a callable f(result), a summary variable "
                             f"'var[vessel]' or (var, vessel), got {q!r}")
        out.append((m["var"], m["vessel"]))
    return out


#: SALib problem keys sobol() passes on (``groups`` is refused: SALib 1.x's Sobol' sampler
#: ignores them while its analysis counts groups, a sample-count mismatch)
PROBLEM_KEYS = {"names", "bounds", "num_vars", "dists"}
#: distributions whose two bounds are [low, high] with low < high (SALib's default: unif)
INTERVALS = ("unif", "logunif")


def _check_problem(problem: Any) -> dict[str, Any]:
    """SALib's problem dict, checked: one finite bound pair per distinct name (a NaN sample
    would be an empty cell, i.e. the base value, and every index a silent 0)."""
    if not isinstance(problem, Mapping):
        raise ModelError("sobol: problem must be a mapping {'names': [dotted paths], 'bounds': "
                         f"[[low, high], ...]}}, got {problem!r}")
    extra = set(problem) - PROBLEM_KEYS
    if extra:
        raise ModelError(f"sobol: problem key(s) {', '.join(sorted(map(str, extra)))} not "
                         f"supported (allowed: {', '.join(sorted(PROBLEM_KEYS))})")
    names = problem.get("names")
    if isinstance(names, str) or not isinstance(names, Sequence) or not names:
        raise ModelError(f"sobol: problem needs 'names', a list of dotted patch paths, got "
                         f"{names!r}")
    names = [str(n) for n in names]
    seen = {n for i, n in enumerate(names) if n in names[:i]}
    if seen:
        raise ModelError(f"sobol: parameter(s) {', '.join(sorted(seen))} named twice")
    bounds = problem.get("bounds")
    if not isinstance(bounds, Sequence) or len(bounds) != len(names):
        raise ModelError(f"sobol: problem needs one 'bounds' entry per name ({len(names)}), got "
                         f"{bounds!r}")
    dists = problem.get("dists", ["unif"] * len(names))
    if isinstance(dists, str) or len(dists) != len(names):
        raise ModelError(f"sobol: problem 'dists' needs one distribution per name, got {dists!r}")
    if problem.get("num_vars", len(names)) != len(names):
        raise ModelError(f"sobol: problem 'num_vars' is {problem['num_vars']!r} but there are "
                         f"{len(names)} names")
    checked = []
    for name, b, dist in zip(names, bounds, dists, strict=True):
        try:
            b = [float(x) for x in b]
        except (TypeError, ValueError):
            raise ModelError(f"sobol: parameter {name!r}: bounds must be numbers, got {b!r}") \
                from None
        if not all(map(math.isfinite, b)):
            raise ModelError(f"sobol: parameter {name!r}: bounds must be finite, got {b!r}")
        if dist in INTERVALS and (len(b) != 2 or not b[0] < b[1]):
            raise ModelError(f"sobol: parameter {name!r}: bounds of a {dist} distribution are "
                             f"[low, high] with low < high, got {b!r}")
        checked.append(b)
    return {**problem, "names": names, "bounds": checked, "num_vars": len(names)}


def _check_n(n: Any) -> int:
    """The base sample size: a power of 2 (the balance of Sobol' points)."""
    try:
        m = 0 if isinstance(n, bool) else operator.index(n)
    except TypeError:
        m = 0
    if m < 1 or m & (m - 1):
        raise ModelError(f"sobol: n must be a power of 2 (the base sample size of Saltelli's "
                         f"scheme on Sobol' points), got {n!r}")
    return m


def _check_values(name: str, y: np.ndarray, x: np.ndarray, names: Sequence[str]) -> None:
    """Every sample's quantity must be a finite number: a NaN would turn every index into
    a meaningless number."""
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        k = int(bad[0])
        at = ", ".join(f"{p}={v:g}" for p, v in zip(names, x[k], strict=True))
        raise ModelError(f"sobol: quantity {name!r} is {y[k]} for {bad.size} of {len(y)} "
                         f"samples, e.g. variant {k} ({at})")


def _analyze(analyze: Any, problem: Mapping[str, Any], name: str, y: np.ndarray,
             **kwargs: Any) -> dict[str, Any]:
    """SALib's Sobol' analysis; a quantity that no parameter changes (zero variance: the
    indices are 0/0) gets indices 0 and a warning instead of numpy's division warnings."""
    if np.ptp(y) == 0:
        warnings.warn(f"sobol: quantity {name!r} is the same ({y[0]:g}) for every sample: no "
                      "parameter changes it, its indices are set to 0", UserWarning,
                      stacklevel=3)
        d = problem["num_vars"]
        zeros = np.zeros(d)
        return {"S1": zeros, "S1_conf": zeros, "ST": zeros, "ST_conf": zeros,
                "S2": np.zeros((d, d))}
    return analyze.analyze(problem, y, **kwargs)


def _outputs(quantity: Any) -> tuple[Any, Callable[[Any], dict[str, np.ndarray]]]:
    """The ensemble ``output`` for ``quantity`` and the function that reads the per-variant
    values of every quantity from the ensemble's dataset."""
    named = _named(quantity)
    if named is not None:
        def read(ds: Any) -> dict[str, np.ndarray]:
            out = {}
            for var, vessel in named:
                if var not in ds:
                    raise ModelError(f"sobol: no summary variable {var!r} (have "
                                     f"{', '.join(sorted(v for v in ds.data_vars if '_' in v))})")
                out[f"{var}[{vessel}]"] = ds[var].sel(vessel=vessel).values
            return out
        return "summary", read

    def output(res: Result) -> Mapping[str, float]:
        value = quantity(res)
        return value if isinstance(value, Mapping) else {"quantity": float(value)}

    output.__name__ = getattr(quantity, "__name__", "quantity")

    def read_callable(ds: Any) -> dict[str, np.ndarray]:
        return {str(n): ds[n].values for n in ds.data_vars if n not in FACTS}
    return output, read_callable


def sobol(model: Model | str | os.PathLike[str] | Mapping[str, Any], problem: Mapping[str, Any],
          n: int, quantity: Quantity, *, calc_second_order: bool = False, seed: int = 0,
          num_resamples: int = 100, conf_level: float = 0.95, workers: int | None = None,
          client: Any = None, progress: Any = True, **overrides: Any) -> dict[str, Any]:
    """First- and total-order Sobol' indices of ``quantity`` with respect to the parameters of
    ``problem``, by SALib (Saltelli sampling, Sobol' analysis).

    ``problem``: SALib's problem dict, ``{"names": [dotted patch paths], "bounds": [[lo, hi],
    ...]}`` (``num_vars`` and ``dists`` optional). ``n``: base sample size (a power of 2);
    the ensemble has ``n (D + 2)`` variants (``n (2D + 2)`` with ``calc_second_order``).
    ``quantity``: a callable ``f(result) -> float`` or ``-> {name: float}`` (several
    quantities at once), or a summary variable ``"pressure_in_max[aorta]"`` / ``("po2_out_mean",
    "ICA")`` or a list of them. ``workers``, ``client``, ``progress`` and ``overrides`` are
    :func:`oxyline.simulate_ensemble`'s.

    Returns ``{quantity name: pandas.DataFrame}`` indexed by parameter with columns ``S1``,
    ``S1_conf``, ``ST``, ``ST_conf``; ``.attrs["S2"]`` holds the second-order matrix when
    asked for, ``.attrs["samples"]`` the parameter samples and ``.attrs["values"]`` the
    quantity per sample. Raises :class:`~oxyline.ModelError` if a variant failed (its values
    would bias every index).

    >>> import oxyline
    >>> problem = {"names": ["boundary_conditions.ica_out.resistance"],
    ...            "bounds": [[2.5e9, 3.5e9]]}
    >>> s = oxyline.sensitivity.sobol("bifurcation", problem, 8, "pressure_in_mean[parent]",
    ...                               cycles=1, progress=False)
    >>> list(s["pressure_in_mean[parent]"].columns)
    ['S1', 'S1_conf', 'ST', 'ST_conf']
    """
    import pandas as pd

    from oxyline.ensemble import simulate_ensemble

    sample, analyze = _salib()
    problem = _check_problem(problem)
    names = problem["names"]
    n = _check_n(n)
    model = load_model(model)
    for var, vessel in _named(quantity) or ():  # checked before the ensemble runs
        if vessel not in model.vessel_names:
            raise ModelError(f"sobol: quantity '{var}[{vessel}]': no vessel named {vessel!r} in "
                             f"model '{model.name}'")
    try:
        x = sample.sample(problem, n, calc_second_order=calc_second_order, seed=seed)
    except ValueError as e:  # e.g. an unknown distribution name: SALib's message names them
        raise ModelError(f"sobol: SALib refused the problem: {e}") from e
    bad = np.flatnonzero(~np.isfinite(x).all(axis=0))
    if bad.size:  # a NaN cell would leave the base model's value
        raise ModelError(f"sobol: SALib drew non-finite samples of {names[bad[0]]!r} (bounds "
                         f"{problem['bounds'][bad[0]]}, distribution "
                         f"{problem.get('dists', ['unif'] * len(names))[bad[0]]})")
    output, read = _outputs(quantity)
    ds = simulate_ensemble(model, pd.DataFrame(x, columns=names), workers=workers,
                           client=client, output=output, progress=progress, **overrides)
    failed = np.flatnonzero(ds["status"].values != 0)
    if failed.size:
        raise ModelError(f"sobol: {failed.size} of {len(x)} variants failed, e.g. "
                         f"{ds['error'].values[failed[0]]}")
    out = {}
    for name, y in read(ds).items():
        y = np.asarray(y, dtype=float)
        _check_values(name, y, x, names)
        si = _analyze(analyze, problem, name, y, calc_second_order=calc_second_order,
                      num_resamples=num_resamples, conf_level=conf_level, seed=seed)
        df = pd.DataFrame({k: np.asarray(si[k]) for k in ("S1", "S1_conf", "ST", "ST_conf")},
                          index=pd.Index(names, name="parameter"))
        if calc_second_order:
            df.attrs["S2"] = np.asarray(si["S2"])
        df.attrs["samples"] = x
        df.attrs["values"] = y
        out[name] = df
    return out
