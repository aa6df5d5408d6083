"""Native model files (YAML/JSON) and the format dispatch used by ``oxyline convert``.

Formats, by name (``format=``) or guessed from the file:

* ``native`` — oxyline YAML (``.yaml``/``.yml``) or JSON (``.json``), the README schema;
* ``svzerod`` — svZeroDSolver JSON (read when the file has ``simulation_parameters``; written by
  :func:`oxyline.io.to_svzerod`);
* ``tables`` — CSV/TSV vessel table plus a boundary-condition table (:mod:`oxyline.io.tables`);
* ``openbf`` — openBF YAML input (read only; a YAML file with a ``network:`` list).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline.errors import ModelError
from oxyline.io._common import PathLike, as_model, check_path, load_with_context, plain
from oxyline.loader import load_model
from oxyline.model import Model

FORMATS = ("native", "svzerod", "tables", "openbf")


def dump_native(data: Mapping[str, Any], path: PathLike) -> Path:
    """Write a model dict as YAML or JSON (by suffix; anything but .yaml/.yml is JSON)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    data = plain(data)
    if p.suffix.lower() in (".yaml", ".yml"):
        import yaml

        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100,
                              allow_unicode=True)
    else:
        text = json.dumps(data, indent=2) + "\n"
    p.write_text(text)
    return p


def save_model(model: Model | Mapping[str, Any], path: PathLike) -> Path:
    """Write ``model`` as a native oxyline file: YAML for ``.yaml``/``.yml``, JSON otherwise.

    The file holds the model's own description (:meth:`Model.to_dict`, in the units it was written
    in), so ``load_model(save_model(load_model(f), g))`` is the same model as ``load_model(f)``.

    >>> import oxyline, oxyline.io, tempfile, os
    >>> m = oxyline.load_model("bifurcation")
    >>> p = oxyline.io.save_model(m, os.path.join(tempfile.mkdtemp(), "b.yaml"))
    >>> oxyline.load_model(p).canonical == m.canonical
    True
    """
    data = model.to_dict() if isinstance(model, Model) else dict(model)
    return dump_native(data, path)


def read_mapping(path: PathLike) -> dict[str, Any]:
    """The top-level mapping of a YAML (``.yaml``/``.yml``) or JSON (any other suffix) file."""
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: file not found")
    text = p.read_text()
    try:
        if p.suffix.lower() in (".yaml", ".yml"):
            import yaml

            data = yaml.safe_load(text)
        else:
            data = json.loads(text)
    except Exception as exc:  # parse errors carry line numbers
        raise ModelError(f"{p}: cannot parse: {exc}") from exc
    if not isinstance(data, dict):
        raise ModelError(f"{p}: top level must be a mapping")
    return data


def _read_raw(p: Path) -> dict[str, Any] | None:
    """Parsed YAML/JSON mapping, or None for other suffixes."""
    if p.suffix.lower() not in (".yaml", ".yml", ".json"):
        return None
    return read_mapping(p)


def sniff_format(data: Mapping[str, Any]) -> str:
    """The one format rule for a parsed model mapping: ``svzerod`` (svZeroDSolver input: has
    ``simulation_parameters``, or a list of boundary conditions), ``openbf`` (a ``network:``
    list and no ``vessels``) or ``native``."""
    if "simulation_parameters" in data or isinstance(data.get("boundary_conditions"), list):
        return "svzerod"
    if "vessels" not in data and "network" in data:
        return "openbf"
    return "native"


def detect_format(path: PathLike) -> str:
    """Format of an existing model file: native, svzerod, tables or openbf."""
    p = check_path(path)
    suffix = p.suffix.lower()
    if suffix in (".csv", ".tsv", ".txt"):
        return "tables"
    data = _read_raw(p)
    if data is None:
        raise ModelError(f"{p}: unknown model file type '{suffix}' (expected .yaml, .yml, .json, "
                         ".csv or .tsv)")
    return sniff_format(data)


def _read_openbf(p: Path) -> Model:
    try:
        from oxyline.io.openbf import read_openbf
    except ImportError:
        raise ModelError(f"{p}: looks like an openBF input file, but the openBF importer "
                         "(oxyline.io.openbf.read_openbf) is not available in this version") from None
    return read_openbf(p)


def read_model(path: PathLike | str, format: str | None = None) -> Model:
    """Read a model from any supported file (see the module docstring), or a built-in by name.

    Errors are :class:`oxyline.ModelError` whose message starts with the file name, then names
    the vessel or node and the key.
    """
    p = Path(path)
    if not p.exists():
        if not p.suffix and format is None:  # a built-in model (oxyline.models) or example
            return load_model(str(path))
        raise ModelError(f"{p}: file not found")
    fmt = format or detect_format(p)
    if fmt not in FORMATS:
        raise ModelError(f"{p}: unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
    if fmt == "tables":
        from oxyline.io.tables import read_tables

        return read_tables(p)
    if fmt == "openbf":
        return _read_openbf(p)
    data = _read_raw(p)
    if data is None:
        raise ModelError(f"{p}: a {fmt} model must be a .yaml/.yml/.json file")
    if fmt == "svzerod":
        from oxyline.io.svzerod import to_model

        try:
            return to_model(data)
        except ModelError as exc:
            raise type(exc)(f"{p}: {exc}") from None
    return load_with_context(data, str(p))


def write_model(model: Model | PathLike | Mapping[str, Any], path: PathLike,
                format: str | None = None) -> list[Path]:
    """Write ``model`` to ``path`` in ``format`` (guessed from the suffix when None: .csv/.tsv →
    tables, .yaml/.yml/.json → native; svZeroDSolver JSON must be asked for with
    ``format="svzerod"``). Returns the files written."""
    m = as_model(model)
    p = Path(path)
    fmt = format or ("tables" if p.suffix.lower() in (".csv", ".tsv") else "native")
    if fmt == "native":
        if p.suffix.lower() not in (".yaml", ".yml", ".json"):
            raise ModelError(f"{p}: native models are .yaml, .yml or .json files")
        return [save_model(m, p)]
    if fmt == "svzerod":
        from oxyline.io.svzerod_export import to_svzerod

        return [dump_native(to_svzerod(m), p.with_suffix(".json") if not p.suffix else p)]
    if fmt == "tables":
        from oxyline.io.tables import write_tables

        return write_tables(m, p)
    if fmt == "openbf":
        raise ModelError(f"{p}: writing openBF files is not supported (openBF is an input format)")
    raise ModelError(f"{p}: unknown format {fmt!r} (expected one of {', '.join(FORMATS)})")
