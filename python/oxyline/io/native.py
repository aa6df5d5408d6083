"""Native model files: oxyline YAML (``.yaml``/``.yml``) or JSON (any other suffix), the README
schema. :func:`read_mapping` is the one safe reader of YAML/JSON model files (every format built
on them uses it); :func:`dump_native` and :func:`save_model` write them. The other formats and
the dispatch between them are in :mod:`oxyline.io.formats`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline.errors import ModelError
from oxyline.io._common import PathLike, plain
from oxyline.model import Model


def dump_native(data: Mapping[str, Any], path: PathLike) -> Path:
    """Write a model dict as YAML or JSON (by suffix; anything but .yaml/.yml is JSON)."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    data = plain(data)
    if p.suffix.lower() in (".yaml", ".yml"):
        import io

        from ruamel.yaml import YAML

        # the YAML 1.2 writer quotes strings that YAML 1.2 would read as numbers ('1e5')
        yaml = YAML(typ="safe", pure=True)
        yaml.default_flow_style = None
        yaml.width = 100
        yaml.allow_unicode = True
        yaml.sort_base_mapping_type_on_output = False  # keep the schema's key order
        buf = io.StringIO()
        yaml.dump(data, buf)
        text = buf.getvalue()
    else:
        text = json.dumps(data, indent=2) + "\n"
    p.write_text(text, encoding="utf-8")
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


# Limits of what a model file may hold. A YAML alias expands to its anchor's whole subtree
# wherever it is used, so 1 KB of nested aliases can stand for 10^9 values (a "billion laughs"
# file); the values are counted before anything walks them.
MAX_YAML_BYTES = 64 << 20  # the pure-Python YAML parser reads ~0.1 MB/s: use JSON beyond this
MAX_JSON_BYTES = 2 << 30
MAX_VALUES_MIN = 1_000_000  # aliases may expand to max(this, 10 values per byte of the file)


def _decode(raw: bytes, p: Path) -> str:
    """The text of a model file: UTF-8 (a BOM is dropped), or UTF-16/32 with a BOM as YAML
    allows; anything else is a :class:`ModelError` naming the file and the first bad byte."""
    import codecs

    for bom, codec in ((codecs.BOM_UTF32_LE, "utf-32"), (codecs.BOM_UTF32_BE, "utf-32"),
                       (codecs.BOM_UTF8, "utf-8-sig"), (codecs.BOM_UTF16_LE, "utf-16"),
                       (codecs.BOM_UTF16_BE, "utf-16")):
        if raw.startswith(bom):
            break
    else:
        codec = "utf-8"
    try:
        text = raw.decode(codec)
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ModelError(f"{p}: not {codec.upper().removesuffix('-SIG')} text: byte "
                         f"0x{raw[exc.start]:02x} at line {line} (offset {exc.start}) cannot be "
                         "decoded; save the file as UTF-8") from None
    if "\x00" in text:
        raise ModelError(f"{p}: binary file (contains NUL characters), not a YAML/JSON model")
    return text


def _count_values(data: Any, limit: int, p: Path) -> None:
    """Refuse a parsed document that stands for more than ``limit`` values once its aliases
    are expanded, or that contains itself (a recursive alias). Each distinct container is
    visited once (its expanded size is remembered), so a billion-laughs file costs as much as
    its text."""
    sizes: dict[int, int] = {}
    open_: set[int] = set()

    def size(x: Any) -> int:
        if not isinstance(x, (dict, list)):
            return 1
        key = id(x)
        if key in sizes:
            return sizes[key]
        if key in open_:
            raise ModelError(f"{p}: a YAML alias refers to a value that contains it "
                             "(a recursive structure)")
        open_.add(key)
        items = x.values() if isinstance(x, dict) else x
        n = 1 + sum(size(v) for v in items)
        open_.discard(key)
        if n > limit:
            raise ModelError(f"{p}: the YAML aliases expand to more than {limit} values (an "
                             "alias bomb?); write the repeated parts out or use fewer aliases")
        sizes[key] = n
        return n

    size(data)


def _yaml_error(exc: Exception) -> str:
    """A ruamel.yaml error as one readable message (line numbers 1-based, no link)."""
    problem = getattr(exc, "problem", None)
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    if problem is None:
        return str(exc).split("\nTo suppress")[0].strip()
    where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
    context = getattr(exc, "context", None)
    return f"{where}{problem}" + (f" ({context})" if context else "")


def _parse_yaml(text: str, p: Path) -> Any:
    """YAML 1.2 (core schema: ``5.0e5`` is a number, ``yes`` a string), safe types only,
    duplicate keys an error."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    yaml = YAML(typ="safe", pure=True)
    yaml.allow_duplicate_keys = False
    try:
        data = yaml.load(text)
    except (YAMLError, ValueError, TypeError) as exc:  # also bad !!timestamp, !!binary values
        raise ModelError(f"{p}: cannot parse YAML: {_yaml_error(exc)}") from None
    _count_values(data, max(MAX_VALUES_MIN, 10 * len(text)), p)
    return data


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object whose keys are unique. Keys starting with ``_`` are comments (JSON has none;
    svZeroDSolver's files repeat ``"_comment_"``): a repeated one keeps its last value."""
    out = dict(pairs)  # in C; a repeated key shows as fewer entries than pairs
    if len(out) == len(pairs):
        return out
    out = {}
    for k, v in pairs:
        if k in out and not k.startswith("_"):
            raise ValueError(f"duplicate key {k!r}")
        out[k] = v
    return out


def read_mapping(path: PathLike) -> dict[str, Any]:
    """The top-level mapping of a YAML (``.yaml``/``.yml``) or JSON (any other suffix) file.

    YAML is read as YAML 1.2 with safe types only; duplicate keys, undecodable bytes, files over
    :data:`MAX_YAML_BYTES`/:data:`MAX_JSON_BYTES` and aliases that expand to too many values
    are each a :class:`ModelError` naming the file.
    """
    if not isinstance(path, (str, os.PathLike)):
        raise ModelError(f"a model file must be a path, got {type(path).__name__} {path!r}")
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: file not found")
    if not p.is_file():
        raise ModelError(f"{p}: not a file")
    is_yaml = p.suffix.lower() in (".yaml", ".yml")
    limit = MAX_YAML_BYTES if is_yaml else MAX_JSON_BYTES
    size = p.stat().st_size
    if size > limit:
        raise ModelError(f"{p}: {size / 2**20:.0f} MiB is more than the {limit / 2**20:.0f} MiB "
                         f"a {'YAML' if is_yaml else 'JSON'} model file may have "
                         f"(oxyline.io.native.MAX_{'YAML' if is_yaml else 'JSON'}_BYTES)")
    from oxyline.io._common import read_regular_file

    text = _decode(read_regular_file(p, "model file", limit), p)
    try:
        data = _parse_yaml(text, p) if is_yaml else json.loads(text, object_pairs_hook=_unique_keys)
    except ModelError:
        raise
    except RecursionError:
        raise ModelError(f"{p}: nested too deeply to read") from None
    except ValueError as exc:  # JSON syntax errors and duplicate keys carry line numbers
        raise ModelError(f"{p}: cannot parse JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ModelError(f"{p}: top level must be a mapping, got "
                         f"{'nothing' if data is None else type(data).__name__}")
    return data
