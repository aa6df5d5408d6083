"""Display conventions shared by the figure modules: SI prefixes, line styles, coinciding
curves (:mod:`oxyline.plot` and :mod:`oxyline.plot_oxygen` both draw with them)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

#: SI prefixes (power of ten, symbol), largest first: a quantity shown with the prefix that puts its largest
#: magnitude in [1, 1000) (no "nmol/s" values in the millions)
PREFIXES = ((3, "k"), (0, ""), (-3, "m"), (-6, "µ"), (-9, "n"), (-12, "p"), (-15, "f"))


def pyplot() -> Any:
    """``matplotlib.pyplot``, on the file backend (Agg) where there is no display and no
    ``MPLBACKEND`` says otherwise."""
    import matplotlib

    if os.environ.get("DISPLAY", "") == "" and os.environ.get("MPLBACKEND") is None:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def peak_magnitude(values: Any) -> float:
    a = np.abs(np.asarray(values, dtype=float))
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else 0.0


def prefixed(units: str, values: Any) -> tuple[str, float]:
    """``units`` with the SI prefix that puts the largest magnitude of ``values`` in
    [1, 1000), and the factor from ``units``: ``prefixed("mol/s", [2e-6])`` is
    ``("µmol/s", 1e6)``.

    >>> prefixed("mol/s", [2e-6, -5e-7])
    ('µmol/s', 1000000.0)
    """
    peak = peak_magnitude(values)
    for exponent, p in PREFIXES:
        if peak >= 10.0 ** exponent:
            break
    return p + units, 10.0 ** -exponent


#: line styles cycled over the colours: distinct vessels stay distinct beyond ten of them
STYLES = ("-", "--", ":", "-.")


def same_curves(series: Mapping[str, np.ndarray]) -> list[tuple[list[str], np.ndarray]]:
    """The curves of ``series`` (name -> values) with those that coincide merged, each with all
    its names: two vessels leaving one node read the same node pressure, and two lines drawn
    on top of each other would hide one of them. Coincide: equal to 1e-9 of the largest
    magnitude (round-off of one node's value read twice).

    >>> import numpy as np
    >>> [names for names, _ in same_curves({"a": np.ones(3), "b": np.ones(3), "c": np.zeros(3)})]
    [['a', 'b'], ['c']]
    """
    scale = max((peak_magnitude(v) for v in series.values()), default=0.0) or 1.0
    groups: list[tuple[list[str], np.ndarray]] = []
    for name, y in series.items():
        for names, y0 in groups:
            if y0.shape == y.shape and np.allclose(y, y0, rtol=0.0, atol=1e-9 * scale):
                names.append(name)
                break
        else:
            groups.append(([name], np.asarray(y)))
    return groups


def write_figures(figures: Mapping[str, Any], outdir: str | os.PathLike[str],
                  formats: Sequence[str], dpi: int) -> list[Path]:
    """Write each figure of ``figures`` (name -> Figure) as ``outdir/<name>.<format>`` and
    close it; returns the files written."""
    plt = pyplot()
    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, fig in figures.items():
        for fmt in formats:
            written.append(out / f"{name}.{fmt}")
            fig.savefig(written[-1], dpi=dpi)
        plt.close(fig)
    return written
