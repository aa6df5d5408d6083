"""Model and result files: native YAML/JSON, CSV/TSV tables, networkx graphs, svZeroDSolver JSON
export; :mod:`oxyline.io.formats` is the registry of model file formats (``oxyline convert``,
``oxyline.load_model``). The openBF importer lives in :mod:`oxyline.io.openbf`."""

from __future__ import annotations

from oxyline.io.formats import detect_format, read_model, write_model
from oxyline.io.graph import from_networkx, to_networkx
from oxyline.io.native import dump_native, save_model
from oxyline.io.svzerod.writer import to_svzerod
from oxyline.io.tables import from_tables, read_tables, to_tables, write_tables

__all__ = [
    "detect_format",
    "dump_native",
    "from_networkx",
    "from_tables",
    "read_model",
    "read_tables",
    "save_model",
    "to_networkx",
    "to_svzerod",
    "to_tables",
    "write_model",
    "write_tables",
]
