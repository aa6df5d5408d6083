"""The ``oxygen:``, ``species:`` and ``transport:`` model sections. The core's schema
(``oxyline_core::model::species``, read by ``oxyline._core.transport_section``) checks every
key, unit and value, converts PO2 from mmHg to SI, computes the haemoglobin facilitation
factor of boundary-layer walls and samples a wall flux given as a Python callable (it calls
it); see docs/schema.md and docs/oxygen.md for the keys. This module keeps the warning the
core raises.
"""

from __future__ import annotations


class HemoglobinFacilitationWarning(UserWarning):
    """``hemoglobin: hill`` (or ``linearized``) with a boundary-layer wall closure whose
    haemoglobin facilitation is switched off: the wall flux then comes from the dissolved O2
    only and under-predicts the uptake 2.6–3.1× (docs/physics.md §3.4)."""

