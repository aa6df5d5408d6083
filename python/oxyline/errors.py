"""Exception types. Core errors come from the Rust extension; Python-side ones subclass them."""

from __future__ import annotations

from oxyline._core import ModelError, SolverError, UnstableTimeStep


class UnsupportedElement(ModelError):
    """An svZeroDSolver element (block, BC or option) that oxyline does not implement."""


class SimulationInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run. ``result`` holds everything computed up to the interruption."""

    def __init__(self, message: str, result: object | None = None) -> None:
        super().__init__(message)
        self.result = result


__all__ = [
    "ModelError",
    "SimulationInterrupted",
    "SolverError",
    "UnstableTimeStep",
    "UnsupportedElement",
]
