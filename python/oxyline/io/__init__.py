"""Model and result files: native YAML/JSON, CSV/TSV tables, networkx graphs, svZeroDSolver JSON
export, and the format dispatch of ``oxyline convert``. The openBF importer lives in
:mod:`oxyline.io.openbf`."""

from __future__ import annotations

from oxyline.io.graph import from_networkx, to_networkx
from oxyline.io.native import detect_format, dump_native, read_model, save_model, write_model
from oxyline.io.svzerod_export import to_svzerod
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
