"""Global sensitivity analysis on SALib: Sobol' indices of any output of a network.

:func:`sobol` samples the parameters with SALib's Saltelli/Sobol' sequence, runs every sample
as one variant of an ensemble (:func:`oxyline.simulate_ensemble`: every core, or a Dask
cluster) and estimates first- and total-order indices with SALib's Sobol' analysis.
Parameters are dotted patch paths (``vessels.ICA.radius``, ``boundary_conditions.ica_out.
resistance``, ``oxygen.wall.k``, ``scale.resistance``), in the model's units. Needs SALib
(``pip install 'oxyline[ensemble]'``).
"""

from __future__ import annotations

import os
import re
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
    """Summary variables ``"var[vessel]"`` or ``(var, vessel)`` (one or a list), else None."""
    items = [quantity] if isinstance(quantity, (str, tuple)) else quantity
    if callable(items) or not isinstance(items, Sequence):
        return None
    out = []
    for q in items:
        if isinstance(q, tuple) and len(q) == 2:
            out.append((str(q[0]), str(q[1])))
            continue
        m = _NAMED.match(q) if isinstance(q, str) else None
        if m is None:
            raise ModelError(f"sobol: a quantity is a callable f(result), a summary variable "
                             f"'var[vessel]' or (var, vessel), got {q!r}")
        out.append((m["var"], m["vessel"]))
    return out


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
    """
    import pandas as pd

    from oxyline.ensemble import simulate_ensemble

    sample, analyze = _salib()
    problem = dict(problem)
    names = list(problem.get("names", []))
    problem.setdefault("num_vars", len(names))
    if not names or len(problem.get("bounds", [])) != len(names):
        raise ModelError("sobol: problem needs 'names' and one [low, high] 'bounds' per name")
    model = load_model(model)
    x = sample.sample(problem, n, calc_second_order=calc_second_order, seed=seed)
    output, read = _outputs(quantity)
    ds = simulate_ensemble(model, pd.DataFrame(x, columns=names), workers=workers,
                           client=client, output=output, progress=progress, **overrides)
    failed = np.flatnonzero(ds["status"].values != 0)
    if failed.size:
        raise ModelError(f"sobol: {failed.size} of {len(x)} variants failed, e.g. "
                         f"{ds['error'].values[failed[0]]}")
    out = {}
    for name, y in read(ds).items():
        si = analyze.analyze(problem, np.asarray(y, dtype=float),
                             calc_second_order=calc_second_order, num_resamples=num_resamples,
                             conf_level=conf_level, seed=seed)
        df = pd.DataFrame({k: np.asarray(si[k]) for k in ("S1", "S1_conf", "ST", "ST_conf")},
                          index=pd.Index(names, name="parameter"))
        if calc_second_order:
            df.attrs["S2"] = np.asarray(si["S2"])
        df.attrs["samples"] = x
        df.attrs["values"] = np.asarray(y, dtype=float)
        out[name] = df
    return out
