"""``oxyline.impedance``: the input impedance Z(ω) of a network seen from a node, from the
core's frequency-domain solve of the linear circuit (boundary pressures held at zero, inflows
open) by the time stepping's O(n) tree elimination (faer sparse LU where there are loops); see
docs/structured-tree.md."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, Literal, get_args

import numpy as np

from oxyline.errors import ModelError, core_errors
from oxyline.loader import load_model
from oxyline.model import Model, circuit_network

#: The views of :func:`impedance`: into the branches leaving the node (``"downstream"``), into
#: those entering it (``"upstream"``), or into every branch at the node (``"both"``).
Direction = Literal["downstream", "upstream", "both"]
DIRECTIONS: tuple[str, ...] = get_args(Direction)


def impedance(model: Model | str | os.PathLike[str] | Mapping[str, Any], node: str,
              frequencies: Any, *, direction: Direction = "downstream") -> np.ndarray:
    """Input impedance (Pa·s/m³, complex) seen from graph node ``node`` into the network
    downstream of it, at each of ``frequencies`` (Hz, >= 0; any shape, the result has the
    same): a unit flow injected at the node, every pressure boundary held at zero and every
    flow boundary open. Z(0) is the network's steady (Poiseuille) resistance.

    ``direction`` picks the view at the node: ``"downstream"`` (default) looks into the
    vessels that start at the node (and an outlet condition there), ``"upstream"`` into the
    vessels that end there (and an inlet condition), ``"both"`` into every branch at the node
    (the two in parallel: the impedance a flow injected into the junction itself meets). The
    node's capacitance is split by the segments it belongs to (an L or π vessel ending at the
    node counts upstream). A side with nothing on it (upstream of a network inlet) raises
    ``ModelError``; a side closed by a flow inlet (no pressure boundary on it) has no
    finite Z(0), so 0 Hz raises ``ModelError`` there.

    >>> import oxyline
    >>> z = oxyline.impedance("bifurcation", "inlet", [0.0, 1.0, 5.0])
    >>> z.shape, bool(abs(z[0].imag) < 1e-6 * z[0].real)
    ((3,), True)
    """
    if direction not in DIRECTIONS:
        raise ModelError(f"impedance: direction must be one of {', '.join(DIRECTIONS)}, "
                         f"got {direction!r}")
    m = load_model(model)
    f = _frequencies(frequencies)
    # one symbolic analysis, then O(n) per frequency in the core with the GIL released (the
    # core checks the frequencies)
    with core_errors("impedance"):
        re, im = circuit_network(m).input_impedances(str(node), f.ravel().tolist(), direction)
    return (re + 1j * im).reshape(f.shape)


def _frequencies(frequencies: Any) -> np.ndarray:
    """``frequencies`` as a float array: real numbers only (a complex, string, None or
    beyond-float entry is refused with :class:`ModelError` naming the argument)."""
    try:
        raw = np.asarray(frequencies)
    except (ValueError, TypeError, OverflowError) as exc:  # ragged lists and the like
        raise ModelError(f"impedance: frequencies must be an array of numbers (Hz): {exc}") \
            from None
    if raw.dtype.kind not in "iuf":  # complex, strings, objects (None, huge integers), ...
        raise ModelError(f"impedance: frequencies must be real numbers in Hz, got an array of "
                         f"{raw.dtype} (e.g. {raw.ravel()[0]!r:.40})" if raw.size else
                         f"impedance: frequencies must be real numbers in Hz, got {raw.dtype}")
    return raw.astype(float)


__all__ = ["DIRECTIONS", "Direction", "impedance"]
