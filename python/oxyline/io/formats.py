"""The model file formats, in one registry: which files each format reads (suffixes, and a rule
on the content of a YAML/JSON mapping), its reader (to a native model dict) and its writer.

Formats, by name (``format=``) or recognised from the file:

* ``native`` — oxyline YAML (``.yaml``/``.yml``) or JSON (``.json``), the README schema;
* ``svzerod`` — svZeroDSolver JSON (a mapping with ``simulation_parameters`` or a list of
  boundary conditions; written by :func:`oxyline.io.to_svzerod`);
* ``tables`` — CSV/TSV vessel table plus a boundary-condition table (:mod:`oxyline.io.tables`);
* ``openbf`` — openBF YAML input (read only; a mapping with a ``network:`` list and no
  ``vessels``).

Every reader returns a native model dict and where it came from; :func:`read_model` and
:func:`oxyline.load_model` build the :class:`~oxyline.Model`. A new format is one entry of
:data:`FORMATS` (``docs/developer.md``, "Add an importer").
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from oxyline import catalogue
from oxyline.errors import ModelError
from oxyline.io import openbf, tables
from oxyline.io._common import PathLike, build, check_path
from oxyline.io.native import dump_native, read_mapping, save_model
from oxyline.io.svzerod import reader as svzerod
from oxyline.io.svzerod import writer as svzerod_export
from oxyline.model import Model

#: suffixes read as a YAML/JSON mapping, whose content then names the format
MAPPING_SUFFIXES = (".yaml", ".yml", ".json")

#: a reader: the file -> (native model dict, where it came from for error messages)
Reader = Callable[[Path], tuple[dict[str, Any], str]]
#: a writer: (model, path, **options) -> the files written
Writer = Callable[..., list[Path]]


@dataclass(frozen=True)
class Format:
    """One model file format."""

    name: str
    #: suffixes that name this format alone (a ``.json`` file is native or svzerod: the
    #: content decides, :func:`sniff_format`)
    suffixes: tuple[str, ...]
    read: Reader | None
    write: Writer | None
    #: a parsed mapping -> the native model dict (formats whose files are YAML/JSON mappings
    #: and that need nothing but the mapping; ``load_model(dict)`` converts them too)
    from_mapping: Callable[[dict[str, Any]], dict[str, Any]] | None = None
    #: the keyword options its writer takes (:func:`write_model`)
    write_options: tuple[str, ...] = ()


def _mapping_reader(convert: Callable[[dict[str, Any]], dict[str, Any]]) -> Reader:
    def read(p: Path) -> tuple[dict[str, Any], str]:
        data = read_mapping(p)
        try:
            return convert(data), str(p)
        except ModelError as exc:  # the conversion's errors name the element, not the file
            raise type(exc)(f"{p}: {exc}") from None

    return read


def _write_native(model: Model, p: Path) -> list[Path]:
    if p.suffix.lower() not in MAPPING_SUFFIXES:
        raise ModelError(f"{p}: native models are .yaml, .yml or .json files")
    return [save_model(model, p)]


def _write_svzerod(model: Model, p: Path, **options: Any) -> list[Path]:
    """svZeroDSolver JSON; options as :func:`oxyline.io.to_svzerod` (``units``, ...)."""
    return [dump_native(svzerod_export.to_svzerod(model, **options),
                        p.with_suffix(".json") if not p.suffix else p)]


def _read_openbf(p: Path) -> tuple[dict[str, Any], str]:
    return openbf.to_native_dict(p), str(p)


def _as_native(data: dict[str, Any]) -> dict[str, Any]:
    return data


FORMATS: dict[str, Format] = {
    "native": Format("native", (), _mapping_reader(_as_native), _write_native, _as_native),
    "svzerod": Format("svzerod", (), _mapping_reader(svzerod.to_oxyline_dict), _write_svzerod,
                      svzerod.to_oxyline_dict,
                      ("units", "samples", "points_per_cycle", "cycles")),
    "tables": Format("tables", (".csv", ".tsv", ".txt"), tables.native_dict, tables.write_tables),
    "openbf": Format("openbf", (), _read_openbf, None),
}


def sniff_format(data: Mapping[str, Any]) -> str:
    """The one format rule for a parsed model mapping: ``svzerod`` (svZeroDSolver input: has
    ``simulation_parameters``, or a list of boundary conditions), ``openbf`` (a ``network:``
    list and no ``vessels``) or ``native``."""
    if "simulation_parameters" in data or isinstance(data.get("boundary_conditions"), list):
        return "svzerod"
    if "vessels" not in data and "network" in data:
        return "openbf"
    return "native"


def _format(name: str, p: Path) -> Format:
    if name not in FORMATS:
        raise ModelError(f"{p}: unknown format {name!r} (expected one of "
                         f"{', '.join(FORMATS)})")
    return FORMATS[name]


def claimed(path: PathLike) -> bool:
    """Whether the suffix of ``path`` is one the registry reads (YAML/JSON or a format's)."""
    suffix = Path(path).suffix.lower()
    return suffix in MAPPING_SUFFIXES or any(suffix in f.suffixes for f in FORMATS.values())


def detect_format(path: PathLike) -> str:
    """Format of an existing model file: native, svzerod, tables or openbf."""
    p = check_path(path)
    suffix = p.suffix.lower()
    for fmt in FORMATS.values():
        if suffix in fmt.suffixes:
            return fmt.name
    if suffix not in MAPPING_SUFFIXES:
        known = [*MAPPING_SUFFIXES, *(s for f in FORMATS.values() for s in f.suffixes)]
        raise ModelError(f"{p}: unknown model file type '{suffix}' (expected "
                         f"{', '.join(known)})")
    return sniff_format(read_mapping(p))


def read_native(path: PathLike, format: str | None = None) -> tuple[dict[str, Any], str]:
    """The native model dict of a model file in any format (the format recognised from the
    suffix and content, or ``format``), and the file(s) it came from."""
    p = check_path(path)
    if format is None and p.suffix.lower() in MAPPING_SUFFIXES:
        data = read_mapping(p)  # parsed once: the content names the format
        fmt = FORMATS[sniff_format(data)]
        if fmt.from_mapping is not None:
            try:
                return fmt.from_mapping(data), str(p)
            except ModelError as exc:
                msg = str(exc)
                raise type(exc)(msg if msg.startswith(str(p)) else f"{p}: {msg}") from None
    else:
        fmt = _format(format or detect_format(p), p)
    if fmt.read is None:
        raise ModelError(f"{p}: the {fmt.name} format cannot be read")
    if fmt.from_mapping is not None and p.suffix.lower() not in MAPPING_SUFFIXES:
        raise ModelError(f"{p}: a {fmt.name} model must be a .yaml/.yml/.json file")
    return fmt.read(p)


def from_mapping(data: dict[str, Any]) -> dict[str, Any] | None:
    """The native model dict of a parsed mapping in another format (svZeroDSolver), or None
    when it is native (or needs its file: openBF's inlet files are relative to it)."""
    fmt = FORMATS[sniff_format(data)]
    if fmt.name == "native" or fmt.from_mapping is None:
        return None
    return fmt.from_mapping(data)


def read_model(path: PathLike | str, format: str | None = None) -> Model:
    """Read a model from any supported file (see the module docstring), or a built-in by name.

    Errors are :class:`oxyline.ModelError` whose message starts with the file name, then names
    the vessel or node and the key.
    """
    p = Path(path)
    if not p.exists():
        if not p.suffix and format is None:  # a built-in model (oxyline.catalogue)
            return catalogue.load(str(path))
        raise ModelError(f"{p}: file not found")
    return build(*read_native(p, format), owned=True)


def as_model(model: Model | PathLike | Mapping[str, Any]) -> Model:
    """A :class:`Model` from a model, a native model dict, a file path or a built-in name."""
    if isinstance(model, Model):
        return model
    if isinstance(model, Mapping):
        return build(dict(model))
    return read_model(model)


#: the format a file is written in by its suffix (svZeroDSolver JSON is asked for by name)
WRITE_SUFFIXES = {".csv": "tables", ".tsv": "tables", **dict.fromkeys(MAPPING_SUFFIXES, "native")}


def output_format(path: PathLike) -> str | None:
    """The format :func:`write_model` writes ``path`` in when none is named (None: the suffix
    names none)."""
    return WRITE_SUFFIXES.get(Path(path).suffix.lower())


def write_model(model: Model | PathLike | Mapping[str, Any], path: PathLike,
                format: str | None = None, **options: Any) -> list[Path]:
    """Write ``model`` to ``path`` in ``format`` (guessed from the suffix when None:
    :data:`WRITE_SUFFIXES`, else native; svZeroDSolver JSON must be asked for with
    ``format="svzerod"``); ``options`` go to the format's writer (svzerod: ``units``).
    Returns the files written."""
    m = as_model(model)
    p = Path(path)
    fmt = _format(format or output_format(p) or "native", p)
    if fmt.write is None:
        raise ModelError(f"{p}: writing {fmt.name} files is not supported ({fmt.name} is an "
                         "input format)")
    unknown = sorted(set(options) - set(fmt.write_options))
    if unknown:
        raise ModelError(f"{p}: the {fmt.name} writer has no option {', '.join(unknown)} "
                         f"(options: {', '.join(fmt.write_options) or 'none'})")
    return fmt.write(m, p, **options)


__all__ = ["FORMATS", "WRITE_SUFFIXES", "Format", "as_model", "claimed", "detect_format",
           "from_mapping", "output_format", "read_model", "read_native", "sniff_format",
           "write_model"]
