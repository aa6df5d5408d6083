"""The ``oxygen:``, ``species:`` and ``transport:`` model sections. The core's schema
(``oxyline_core::model::species``) checks every key, unit and value, converts PO2 from mmHg to
SI, computes the haemoglobin facilitation factor of boundary-layer walls and samples a wall
flux given as a Python callable (it calls it); see docs/schema.md and docs/oxygen.md for the
keys. This module keeps the key sets (the ensemble's patches check names against them) and
the warning the core raises.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from oxyline import _core

#: the keys of the ``oxygen`` section, of each wall closure, of a ``species`` entry and of the
#: ``transport`` section, as the core checks them
OXYGEN_KEYS = frozenset(_core.OXYGEN_KEYS)
WALL_KEYS = {model: frozenset(keys) for model, keys in _core.WALL_KEYS.items()}
SPECIES_KEYS = frozenset(_core.SPECIES_KEYS)
TRANSPORT_KEYS = frozenset(_core.TRANSPORT_KEYS)


class HemoglobinFacilitationWarning(UserWarning):
    """``hemoglobin: hill`` (or ``linearized``) with a boundary-layer wall closure whose
    haemoglobin facilitation is switched off: the wall flux then comes from the dissolved O2
    only and under-predicts the uptake 2.6–3.1× (docs/physics.md §3.4)."""


def canonical(data: Mapping[str, Any], pressure_factor: float, period: float | None,
              duration: float | None) -> tuple[dict[str, Any] | None, dict[str, Any]]:
    """(canonical transport section or None, facts for results: species names, the oxygen
    species and its solubility per mmHg) of the ``oxygen``/``species``/``transport`` sections
    of ``data``, read by the core against a pressure unit factor (Pa per the model's unit), the
    model period and the run duration (s)."""
    return _core.transport_section(data, pressure_factor, period, duration)
