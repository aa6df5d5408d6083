"""Exception types. Core errors come from the Rust extension; Python-side ones subclass them."""

from __future__ import annotations

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


class OutputSizeWarning(UserWarning):
    """The requested output is large (many GB): said before it is computed and written."""


class PeriodicityWarning(UserWarning):
    """A run ``until_periodic`` stopped at ``max_cycles`` with its cycle-to-cycle change still
    above the tolerance: the last cycle is not the periodic state it asked for (the result's
    ``settings["periodic_reached"]`` is False)."""


__all__ = [
    "CheckpointError",
    "ModelError",
    "OutputError",
    "OutputSizeWarning",
    "PeriodicityWarning",
    "ResourceError",
    "SimulationCancelled",
    "SimulationInterrupted",
    "SimulationTerminated",
    "SolverError",
    "UnstableTimeStep",
    "UnsupportedElement",
]
