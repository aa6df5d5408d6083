"""svZeroDSolver drop-in (public path ``oxyline.svzerod``); the importer and runner live in
:mod:`oxyline.io.svzerod`, beside the exporter :mod:`oxyline.io.svzerod_export`."""

from oxyline.io import svzerod as _impl
from oxyline.io.svzerod import (
    RunSettings,
    file_units,
    run_settings,
    simulate,
    to_model,
    to_oxyline_dict,
)

# the public module documents itself with the implementation's docstring (its example is run
# by the tests)
__doc__ = _impl.__doc__

__all__ = ["RunSettings", "file_units", "run_settings", "simulate", "to_model",
           "to_oxyline_dict"]
