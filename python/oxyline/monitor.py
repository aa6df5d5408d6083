"""Physical-bounds monitor of species transport (docs/physics.md §2.8): the core's
(``oxyline_core::monitor``) over the recorded output. The core computes every species' range
once from the model and scans each piece of output handed to it (a whole ``Result``, or each
chunk ``simulate_to_zarr`` streams, or an ensemble variant's rows), keeping only a few numbers
between pieces; this module hands the pieces over and issues the core's findings as
:class:`PhysicalBoundsWarning`."""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Mapping
from typing import Any

from oxyline import _core


class PhysicalBoundsWarning(UserWarning):
    """A transport result left its physical bounds (maximum principle, mass balance) or the
    validity range of its formulation. The message names the species, the vessel, the time and
    the value."""


def species_bounds(sp: Mapping[str, Any]) -> tuple[float, float] | None:
    """[min, max] of a species' boundary, initial and wall values (the maximum-principle range,
    computed by the core), or None for a species with a prescribed source (a ``flux`` wall).
    ``sp``: a species as the model's canonical transport section holds it (read as the core
    reads the model's species: a ``ModelError`` naming the key when it is not one)."""
    return _core.species_bounds(sp)


class Monitor:
    """The core's monitor of one run fed its output in consecutive pieces (``Result`` objects);
    fed the whole output at once it finds exactly what it finds fed the same rows in chunks.
    ``transport``: the model's canonical transport section."""

    def __init__(self, transport: Mapping[str, Any] | None) -> None:
        self._core = _core.BoundsMonitor(transport)

    def update(self, result: Any) -> None:
        """Take the next rows of the run's output (a ``Result`` holding them)."""
        species = [(name, sp.vessel_data, list(sp.vessel_variables), sp.segment_data,
                    list(sp.segment_variables), sp.balance_data, float(sp.initial_stored),
                    sp.po2_per_concentration) for name, sp in result.species.items()]
        recorded = {"flow_in", "flow_out"} <= set(result.vessel_variables)
        flows = (result.flow_in, result.flow_out) if recorded else None
        self._core.update(result.time, list(result.vessels), list(result.segment_count),
                          species, flows, result.oxygen)

    def messages(self) -> list[str]:
        """Every finding so far, species by species (bounds, then balance), then the
        tl-quasisteady validity."""
        return self._core.messages()


def warn(messages: Iterable[str], stacklevel: int = 2) -> None:
    """Each message as a :class:`PhysicalBoundsWarning`."""
    for msg in messages:
        warnings.warn(msg, PhysicalBoundsWarning, stacklevel=stacklevel + 1)
