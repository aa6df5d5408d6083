"""oxyline: blood flow and oxygen transport in arterial networks, as transmission-line
circuits integrated by a Rust core.

Quick use::

    import oxyline
    res = oxyline.simulate("bifurcation")       # built-in example, or a YAML/JSON path or dict
    ds = res.to_xarray()                         # dims time, vessel (and segment)
    back = oxyline.open_result("run.nc")         # a saved .nc/.zarr back as a Result
"""

from __future__ import annotations

from oxyline import _core, catalogue, sensitivity
from oxyline.ensemble import simulate_ensemble
from oxyline.errors import (
    CheckpointError,
    ModelError,
    OutputError,
    OutputSizeWarning,
    PeriodicityWarning,
    PlausibilityWarning,
    ResourceError,
    SimulationCancelled,
    SimulationInterrupted,
    SimulationTerminated,
    SolverError,
    UnstableTimeStep,
    UnsupportedElement,
)
from oxyline.frequency import impedance
from oxyline.io.result_reader import open_result
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.monitor import PhysicalBoundsWarning
from oxyline.result import Result, VesselResult
from oxyline.run import resume, simulate, simulate_to_zarr
from oxyline.structured_tree import structured_tree
from oxyline.transport import HemoglobinFacilitationWarning

__version__: str = _core.__version__

__all__ = [
    "CheckpointError",
    "HemoglobinFacilitationWarning",
    "Model",
    "ModelError",
    "OutputError",
    "OutputSizeWarning",
    "PeriodicityWarning",
    "PhysicalBoundsWarning",
    "PlausibilityWarning",
    "ResourceError",
    "Result",
    "SimulationCancelled",
    "SimulationInterrupted",
    "SimulationTerminated",
    "SolverError",
    "UnstableTimeStep",
    "UnsupportedElement",
    "VesselResult",
    "__version__",
    "catalogue",
    "impedance",
    "load_model",
    "open_result",
    "resume",
    "sensitivity",
    "simulate",
    "simulate_ensemble",
    "simulate_to_zarr",
    "structured_tree",
]
