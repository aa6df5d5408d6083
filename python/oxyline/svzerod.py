"""svZeroDSolver drop-in (public path ``oxyline.svzerod``): the importer and runner live in
:mod:`oxyline.io.svzerod`, beside the exporter :mod:`oxyline.io.svzerod_export`."""

from oxyline.io.svzerod import (
    RunSettings,
    run_settings,
    simulate,
    to_model,
    to_oxyline_dict,
)

__all__ = ["RunSettings", "run_settings", "simulate", "to_model", "to_oxyline_dict"]
