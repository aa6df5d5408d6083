"""oxyline: blood flow and oxygen transport in arterial networks, as transmission-line
circuits integrated by a Rust core.

Quick use::

    import oxyline
    res = oxyline.simulate("bifurcation")       # built-in example, or a YAML/JSON path or dict
    ds = res.to_xarray()                         # dims time, vessel (and segment)
    back = oxyline.open_result("run.nc")         # a saved .nc/.zarr back as a Result
"""

from __future__ import annotations

from oxyline import _core, catalogue, errors, sensitivity
from oxyline.calibrate import CalibrationError, calibrate, sensitivities
from oxyline.convergence import convergence, estimate_space_error, forcing_harmonics
from oxyline.ensemble import simulate_ensemble
from oxyline.errors import *  # every public error and warning (errors.__all__)
from oxyline.frequency import impedance
from oxyline.io.result_reader import open_result
from oxyline.loader import load_model
from oxyline.model import Model
from oxyline.monitor import PhysicalBoundsWarning
from oxyline.result import Result, VesselResult
from oxyline.run import estimate_time_error, resume, simulate, simulate_to_zarr
from oxyline.structured_tree import structured_tree
from oxyline.time_error import TimeErrorEstimate

__version__: str = _core.__version__

__all__ = [
    "CalibrationError",
    "Model",
    "PhysicalBoundsWarning",
    "Result",
    "TimeErrorEstimate",
    "VesselResult",
    "__version__",
    "calibrate",
    "catalogue",
    "convergence",
    "estimate_space_error",
    "estimate_time_error",
    "forcing_harmonics",
    "impedance",
    "load_model",
    "open_result",
    "resume",
    "sensitivities",
    "sensitivity",
    "simulate",
    "simulate_ensemble",
    "simulate_to_zarr",
    "structured_tree",
]
__all__ += errors.__all__
