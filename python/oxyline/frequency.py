"""``oxyline.impedance``: the input impedance Z(ω) of a network seen from a node, from the
core's frequency-domain solve of the linear circuit (boundary pressures held at zero, inflows
open) by the time stepping's O(n) tree elimination (faer sparse LU where there are loops); see
docs/structured-tree.md."""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from typing import Any

import numpy as np

from oxyline.errors import ModelError
from oxyline.loader import load_model
from oxyline.model import Model


def impedance(model: Model | str | os.PathLike[str] | Mapping[str, Any], node: str,
              frequencies: Any) -> np.ndarray:
    """Input impedance (Pa·s/m³, complex) seen from graph node ``node`` into the network
    downstream of it, at each of ``frequencies`` (Hz, >= 0; any shape, the result has the
    same): a unit flow injected at the node, every pressure boundary held at zero and every
    flow boundary open. Z(0) is the network's steady (Poiseuille) resistance.

    >>> import oxyline
    >>> z = oxyline.impedance("bifurcation", "inlet", [0.0, 1.0, 5.0])
    >>> z.shape, bool(abs(z[0].imag) < 1e-6 * z[0].real)
    ((3,), True)
    """
    m = load_model(model)
    f = np.asarray(frequencies, dtype=float)
    bad = ~np.isfinite(f) | (f < 0)
    if bad.any():
        raise ModelError(f"impedance: frequencies must be finite and >= 0 Hz, got "
                         f"{f[bad].ravel()[0]:g}")
    # one symbolic analysis, then O(n) per frequency in the core with the GIL released
    re, im = m.network.input_impedances(str(node), (2.0 * math.pi * f).ravel().tolist())
    return (re + 1j * im).reshape(f.shape)


__all__ = ["impedance"]
