"""Exception types. Core errors come from the Rust extension; Python-side ones subclass them."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from oxyline._core import ModelError, ResourceError, SolverError, UnstableTimeStep


class UnsupportedElement(ModelError):
    """An svZeroDSolver element (block, BC or option) that oxyline does not implement."""


class OutputError(OSError):
    """A result file could not be written (disk full, no permission, an existing store, ...).
    The message names the file and what happened; ``result`` holds what was to be written (the
    in-memory :class:`~oxyline.Result`, or a streamed store opened with the rows written so
    far), so nothing computed is lost."""

    def __init__(self, message: str, result: object | None = None) -> None:
        super().__init__(message)
        self.result = result

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class SimulationInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run. ``result`` holds everything computed up to the interruption."""

    def __init__(self, message: str, result: object | None = None) -> None:
        super().__init__(message)
        self.result = result


class SimulationCancelled(SimulationInterrupted):
    """The run's ``cancel`` event was set (e.g. by another thread), or Ctrl-C reached the main
    thread while the run went on in a worker thread. ``result`` holds the partial result."""


class SimulationTerminated(SimulationInterrupted):
    """SIGTERM (a batch scheduler's stop) during a run of the ``oxyline`` command; ``result``
    holds the partial result."""


class CheckpointError(ModelError):
    """A checkpoint file that cannot be resumed: not a checkpoint, another format version, or
    written for another model or settings. The message names the file and what differs."""


class HemoglobinFacilitationWarning(UserWarning):
    """``hemoglobin: hill`` (or ``linearized``) with a boundary-layer wall closure whose
    haemoglobin facilitation is switched off: the wall flux then comes from the dissolved O2
    only and under-predicts the uptake 2.6–3.1× (docs/physics.md §3.4). The core raises it
    while it reads the ``oxygen`` section."""


class OutputSizeWarning(UserWarning):
    """The requested output is large (many GB): said before it is computed and written."""


# ---- a panic of the Rust core never reaches the caller as a panic ---------------------------
# PyO3 turns a Rust panic into ``pyo3_runtime.PanicException``, a ``BaseException`` that
# ``except Exception`` does not catch and whose message says nothing of what was being done.
# :func:`core_errors` wraps the calls into the core (the run, the model's assembly, the
# impedance solve, an ensemble) and raises SolverError with the panic's message instead;
# ``exc.__cause__`` keeps the panic for a bug report.

def is_panic(exc: BaseException) -> bool:
    """Whether ``exc`` is a Rust panic turned into a Python exception by PyO3."""
    t = type(exc)
    return t.__name__ == "PanicException" and t.__module__ in ("pyo3_runtime", "builtins")


@contextlib.contextmanager
def core_errors(what: str) -> Iterator[None]:
    """Raise :class:`SolverError` naming ``what`` for a panic of the core inside the block."""
    try:
        yield
    except BaseException as exc:
        if not is_panic(exc):
            raise
        msg = str(exc) or "(no message)"
        raise SolverError(f"{what}: internal error in the core (a Rust panic: {msg}); please "
                          "report it with the model that caused it") from exc


class PeriodicityWarning(UserWarning):
    """A run ``until_periodic`` stopped at ``max_cycles`` with its cycle-to-cycle change still
    above the tolerance: the last cycle is not the periodic state it asked for (the result's
    ``settings["periodic_reached"]`` is False)."""


class PlausibilityWarning(UserWarning):
    """A model value outside the range it takes in the human circulation, most often a unit
    mix-up (a radius in cm in an SI file, a flow in mL/s, a stiffness in MPa, cgs values in an
    SI file). The core's model checks the ranges (``oxyline_core::model::plausibility``); this
    warning carries what it found: ``element`` (``"vessel 'aorta'"``), ``key``, ``value`` and
    ``unit`` (SI), the range ``low``..``high`` (``low`` 0: no lower bound) and
    ``likely_cause`` (the mix-up whose factor explains the value, or None).

    Silence it with the standard warnings filter::

        import warnings, oxyline
        warnings.simplefilter("ignore", oxyline.PlausibilityWarning)

    Examples
    --------
    >>> import warnings, oxyline
    >>> bad = oxyline.catalogue.load_dict("bifurcation")
    >>> bad["vessels"][0]["radius"]               # SI: metres
    0.003
    >>> bad["vessels"][0]["radius"] = 0.3         # 3 mm written in cm in an SI file
    >>> with warnings.catch_warnings(record=True) as seen:
    ...     warnings.simplefilter("always")
    ...     _ = oxyline.load_model(bad)
    >>> w = seen[0].message
    >>> (w.element, w.key, w.value, w.unit)
    ("vessel 'parent'", 'radius', 0.3, 'm')
    >>> print(w.likely_cause)
    a value in cm in an SI file (SI expects m) or a value in mm in an SI file (SI expects m)

    The command line prints each as ``warning: ...``; ``oxyline --no-plausibility run ...``
    silences them.
    """

    def __init__(self, message: str, element: str = "", key: str = "", value: float = 0.0,
                 unit: str = "", low: float = 0.0, high: float = 0.0,
                 likely_cause: str | None = None, more: int = 0) -> None:
        super().__init__(message)
        self.element, self.key, self.value, self.unit = element, key, value, unit
        self.low, self.high, self.likely_cause, self.more = low, high, likely_cause, more

    def __reduce__(self) -> tuple[object, ...]:  # picklable (a Dask worker's warnings)
        return (type(self), (str(self), self.element, self.key, self.value, self.unit,
                             self.low, self.high, self.likely_cause, self.more))


def _caller_stacklevel() -> int:
    """The stack level of the first frame outside the oxyline package (a warning then points
    at the user's line that loaded the model)."""
    import sys
    from pathlib import Path

    package = str(Path(__file__).parent)
    frame, level = sys._getframe(1), 1
    while frame is not None and frame.f_code.co_filename.startswith(package):
        frame, level = frame.f_back, level + 1
    return level


def warn_implausible(found: list[dict[str, object]]) -> None:
    """Emit one :class:`PlausibilityWarning` per finding of the core's check (the network's
    ``plausibility()``); Python re-emits, it does not check again."""
    import warnings

    if not found:
        return
    level = _caller_stacklevel()
    for d in found:
        fields = {k: d[k] for k in ("element", "key", "value", "unit", "low", "high",
                                    "likely_cause", "more")}
        warnings.warn(PlausibilityWarning(str(d["message"]), **fields),  # type: ignore[arg-type]
                      stacklevel=level)


__all__ = [
    "CheckpointError",
    "HemoglobinFacilitationWarning",
    "ModelError",
    "OutputError",
    "OutputSizeWarning",
    "PeriodicityWarning",
    "PlausibilityWarning",
    "ResourceError",
    "SimulationCancelled",
    "SimulationInterrupted",
    "SimulationTerminated",
    "SolverError",
    "UnstableTimeStep",
    "UnsupportedElement",
]
