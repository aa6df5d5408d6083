"""svZeroDSolver drop-in (public path ``oxyline.svzerod``); the importer is
:mod:`oxyline.io.svzerod.reader`, the runner :mod:`oxyline.io.svzerod.dropin`, the exporter
:mod:`oxyline.io.svzerod.writer`, the calibrator :mod:`oxyline.io.svzerod.calibrator`."""

from oxyline.io.svzerod import reader as _reader
from oxyline.io.svzerod.calibrator import calibrate
from oxyline.io.svzerod.dropin import simulate
from oxyline.io.svzerod.reader import (
    RunSettings,
    file_units,
    run_settings,
    to_model,
    to_oxyline_dict,
)

# the public module documents itself with the importer's docstring (its example is run by the
# tests)
__doc__ = _reader.__doc__

__all__ = ["RunSettings", "calibrate", "file_units", "run_settings", "simulate", "to_model",
           "to_oxyline_dict"]
