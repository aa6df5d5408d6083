"""Calibration targets and outputs by name, and their derivatives from the core's tangent.

An output names a quantity of the periodic cycle:

* ``"<vessel>.<variable>.<statistic>"``: ``variable`` one of ``pressure_in``,
  ``pressure_out``, ``flow_in``, ``flow_out``; ``statistic`` one of ``min``, ``max``,
  ``mean``, ``pulse`` (max − min);
* ``"flow_split.<vessel>.<parent>"``: mean flow into ``vessel`` over mean flow into ``parent``;
* ``"cardiac_output"``: the mean inflow of the model's flow conditions (through the vessels
  that start at them), or in a closed loop the mean flow through its heart blocks' aortic
  valves;
* ``"<vessel>:<valve>.<variable>.<statistic>"``: a ``heart_pulmonary`` block's valve
  (``tricuspid``, ``pulmonary``, ``mitral``, ``aortic``): ``pressure_in`` behind it,
  ``pressure_out`` in front, ``flow_in``/``flow_out`` its flow (``CLH:aortic.pressure_in.max``
  is the left ventricle's peak pressure);
* ``"pwv.<proximal>.<distal>"``: pulse-wave velocity from the inlet of ``proximal`` to the
  outlet of ``distal`` (downstream of it): the path length over the foot-to-foot transit
  time (feet by intersecting tangents, :func:`oxyline._core.foot_time`);
* ``"amplification.<central>.<peripheral>"``: pulse-pressure amplification, the pulse
  pressure at the outlet of ``peripheral`` over that at the inlet of ``central``;
* ``"augmentation_index.<vessel>"``: the augmentation index at the inlet of ``vessel``,
  (P_sys − P_i)/PP with P_i the pressure at the inflection of the systolic upstroke
  (the first local minimum of its slope after the diastolic minimum, found by the core);
  a type C wave (no such inflection: the reflection arrives after the peak) reads its
  shoulder after the peak instead, (P_i − P_sys)/PP < 0;
* ``"<vessel>.<variable>.series"``: the signal over the cycle, compared with data at given
  times (targets only).

Oxygen outputs (a model with an ``oxygen`` section; derivatives by the oxygen parameters
and by the flow parameters, the core's species tangent in the same
:func:`oxyline._core.tangent_sensitivities` call):

* ``"<vessel>.<variable>.<statistic>"`` with ``variable`` one of ``po2_out`` (Pa),
  ``saturation_out`` (haemoglobin saturation, 0–1) and ``wall_uptake`` (mol/s through the
  vessel's wall, positive out of the blood);
* ``"SvO2.<vessel>"``: the outflow saturation of a vessel (a bed's or terminal's venous
  saturation), flow-weighted over the cycle, Σ Q S / Σ Q;
* ``"VO2"``: the network's oxygen consumption, the cycle mean of its total wall uptake
  (mol/s); ``"VO2.<vessel>[.<vessel>...]"``: that of the named vessels (an organ or region).

The core gives the signals over the periodic cycle and their exact derivatives, and reduces
them to each output's value and derivatives (:func:`oxyline._core.target_tangents`,
``oxyline_core::sensitivity::targets`` and ``target_runs``), or builds each output's weights
on the signals for its adjoint (:func:`oxyline._core.target_gradients`): a mean is the
mean of the derivatives, a maximum the derivative at the step of the maximum (the derivative
of the discrete maximum, exact wherever the maximum is unique). A pulse-wave velocity's feet
are differentiated likewise at their samples (the steepest upstroke and the diastolic
minimum), and its path length (found by the core in the model) by the lengths of the
vessels on the path. The core also finds the signals each name reads, checked against the
model (:func:`oxyline._core.target_signals`); here the user's targets are read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import ModelError


class CalibrationError(ModelError):
    """A calibration that cannot be set up: a target, datum, bound or parameter that does not
    fit the model. The message names it."""


@dataclass
class Target:
    """One output and what it should be: ``value`` (a number, or the data of a series at
    ``times`` in s from the cycle's start), weighed by ``1/sigma``."""

    output: str
    value: Any
    sigma: Any = None
    times: Any = None
    #: the signals the output reads, as (vessel, variable)
    signals: list[tuple[str, str]] = field(default_factory=list)

    @property
    def size(self) -> int:
        return len(np.atleast_1d(self.value))


def signals_for(outputs: Sequence[str], model: Any, error: type[ModelError] = ModelError
                ) -> list[list[tuple[str, str]]]:
    """The signals of each of ``outputs``, found by the core against ``model`` in one read of
    it (``oxyline_core::sensitivity::target_signals``: its vessels, heart valves, flow inlets
    and oxygen section); the first output that does not fit raises ``error`` naming it."""
    return [_signals(found, error) for found in _core.target_signals(model.canonical,
                                                                     list(outputs))]


def _signals(found: tuple[Any, str | None], error: type[ModelError]
             ) -> list[tuple[str, str]]:
    """The signals of one of :func:`oxyline._core.target_signals`' answers, or its error."""
    signals, why = found
    if why is not None:
        raise error(why)
    return [(str(v), str(x)) for v, x in signals]


def parse_targets(targets: Any, model: Any) -> list[Target]:
    """The targets of a mapping ``{output: value | {value, sigma | weight, times}}`` or a list
    of such mappings with an ``output`` key; every number checked finite."""
    if isinstance(targets, Mapping):
        items = [{"output": k, **(v if isinstance(v, Mapping) else {"value": v})}
                 for k, v in targets.items()]
    elif isinstance(targets, Sequence) and not isinstance(targets, str):
        items = [dict(t) for t in targets]
    else:
        raise CalibrationError(f"targets: expected a mapping or a list, got {targets!r}")
    if not items:
        raise CalibrationError("targets: none given")
    # every target's signals in one read of the model (an error is raised at its target)
    found = _core.target_signals(model.canonical, [str(i.get("output", "?")) for i in items])
    out: list[Target] = []
    for item in items:
        name = str(item.get("output", "?"))
        unknown = set(item) - {"output", "value", "sigma", "weight", "times"}
        if unknown:
            raise CalibrationError(f"target '{name}': unknown keys {sorted(unknown)}")
        if "value" not in item:
            raise CalibrationError(f"target '{name}': no value")
        series = name.endswith(".series")
        value = _finite(name, "value", item["value"], series)
        times = None
        if series:
            if "times" not in item:
                raise CalibrationError(f"target '{name}': a series needs its data's times")
            times = _finite(name, "times", item["times"], True)
            if times.shape != value.shape:
                raise CalibrationError(f"target '{name}': {times.size} times for "
                                       f"{value.size} values")
        sigma = _sigma(name, item, value)
        out.append(Target(name, value, sigma, times, _signals(found[len(out)], CalibrationError)))
    return out


def _finite(name: str, key: str, x: Any, series: bool) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise CalibrationError(f"target '{name}': {key} {x!r} is not a number") from None
    if (a.ndim != 1 if series else a.ndim != 0) or a.size == 0:
        raise CalibrationError(f"target '{name}': {key} must be "
                               f"{'a list of numbers' if series else 'one number'}")
    bad = ~np.isfinite(a)
    if bad.any():
        raise CalibrationError(f"target '{name}': {key} holds a non-finite value "
                               f"{float(a.ravel()[np.argmax(bad.ravel())])!r}")
    return np.atleast_1d(a)


def _sigma(name: str, item: Mapping[str, Any], value: np.ndarray) -> np.ndarray:
    """The residual's scale: ``sigma``, or 1/``weight``, or 1 % of the value's magnitude."""
    if "sigma" in item and "weight" in item:
        raise CalibrationError(f"target '{name}': give sigma or weight, not both")
    if "sigma" in item:
        s = np.broadcast_to(_finite(name, "sigma", item["sigma"], np.ndim(item["sigma"]) == 1),
                            value.shape).astype(float)
    elif "weight" in item:
        w = np.broadcast_to(_finite(name, "weight", item["weight"],
                                    np.ndim(item["weight"]) == 1), value.shape)
        s = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0), math.inf)
    else:
        s = np.full(value.shape, 0.01 * max(float(np.abs(value).max()), 1e-300))
    if (s <= 0).any():
        raise CalibrationError(f"target '{name}': sigma must be positive")
    return s
