"""Helpers shared by the readers and writers of :mod:`oxyline.io`."""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from oxyline.errors import ModelError
from oxyline.memory import gc_paused
from oxyline.model import Model, _build, build_model

PathLike = str | os.PathLike[str]

# keys whose values are identifiers or words, never numbers
WORD_KEYS = {"name", "from", "to", "type", "interpolation", "description", "units", "arrangement",
             "method", "start", "wall_model", "inertance_profile", "cycles", "model"}
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?$")

VESSEL_COLUMNS = ("name", "from", "to", "length", "radius", "radius_in", "radius_out",
                  "wall_thickness", "youngs_modulus", "poisson_ratio", "segments", "arrangement",
                  "output", "description")
LUMPED_COLUMNS = ("resistance", "inductance", "capacitance", "stenosis_coefficient")
ALIASES = {
    "source": "from", "target": "to", "thickness": "wall_thickness", "h": "wall_thickness",
    "e": "youngs_modulus", "youngs": "youngs_modulus", "nu": "poisson_ratio",
    "lumped_resistance": "resistance", "lumped_inductance": "inductance",
    "lumped_capacitance": "capacitance", "lumped_stenosis_coefficient": "stenosis_coefficient",
}


def plain(value: Any, key: str | None = None) -> Any:
    """``value`` as plain JSON/YAML data: numpy scalars and arrays become Python numbers and
    lists, numeric strings (YAML 1.1 reads ``5.0e5`` as a string) become floats."""
    if isinstance(value, Mapping):
        return {str(k): plain(v, str(k)) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v, key) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return plain(value.tolist(), key)
    if isinstance(value, str) and key not in WORD_KEYS and _NUMBER.match(value.strip()):
        return float(value)
    if isinstance(value, float) and value.is_integer() and key == "segments":
        return int(value)
    return value


def is_missing(value: Any) -> bool:
    """True for None, NaN and empty strings (empty table cells)."""
    if value is None or (isinstance(value, float) and math.isnan(value)) \
            or (isinstance(value, str) and not value.strip()):
        return True
    try:
        import pandas as pd

        return bool(pd.isna(value)) if not isinstance(value, (list, tuple, dict)) else False
    except (TypeError, ValueError):
        return False


def build(data: dict[str, Any], where: str | None = None, *, owned: bool = False) -> Model:
    """The :class:`Model` of the native model dict ``data`` (copied first unless the caller
    ``owned`` it: the dict becomes the model's ``source``). A :class:`ModelError` is re-raised
    prefixed with ``where`` (the file or table it came from)."""
    try:
        with gc_paused():
            return _build(data) if owned else build_model(data)
    except ModelError as exc:
        msg = str(exc)
        if where is None or msg.startswith(where):
            raise
        raise type(exc)(f"{where}: {msg}") from None


def model_source(model: Model) -> dict[str, Any]:
    """The model's user-facing dict with plain values."""
    return plain(model.to_dict())


def check_path(path: PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise ModelError(f"{p}: file not found")
    return p


#: a table or waveform file larger than this is refused before it is read (a waveform of a
#: million rows is ~40 MB); the limit is a module attribute so that a caller may raise it
MAX_TABLE_BYTES = 256 << 20
#: file systems of the operating system, whose files are no tables (sizes 0, endless or
#: blocking contents)
_SYSTEM_TREES = ("/proc", "/sys", "/dev")


def _file_kind(mode: int) -> str:
    import stat

    for test, kind in ((stat.S_ISDIR, "directory"), (stat.S_ISFIFO, "named pipe (FIFO)"),
                       (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"),
                       (stat.S_ISSOCK, "socket")):
        if test(mode):
            return kind
    return "special file"


def read_regular_file(path: PathLike, what: str, limit: int | None = None) -> bytes:
    """The bytes of ``path``, which must be a regular file of at most ``limit`` bytes (default
    :data:`MAX_TABLE_BYTES`): a directory, FIFO, device or a file under /proc, /sys or /dev
    is refused with :class:`ModelError` naming it and ``what`` it was to be, without blocking
    (opened non-blocking, checked on the open descriptor) or reading more than the limit."""
    import stat

    limit = MAX_TABLE_BYTES if limit is None else limit
    p = Path(path)
    try:
        real = str(p.resolve())
    except (OSError, RuntimeError):
        real = str(p)
    if any(real == t or real.startswith(t + "/") for t in _SYSTEM_TREES) \
            and not real.startswith("/dev/shm/"):  # shared-memory files are plain files
        raise ModelError(f"{p}: the {what} must be a regular file, not a file of the operating "
                         f"system ({real})")
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    except FileNotFoundError:
        raise ModelError(f"{p}: {what} not found") from None
    except OSError as exc:
        raise ModelError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):
        os.close(fd)
        raise ModelError(f"{p}: the {what} must be a regular file, not a "
                         f"{_file_kind(st.st_mode)}")
    with os.fdopen(fd, "rb") as fh:
        if st.st_size > limit:
            raise ModelError(f"{p}: the {what} has {st.st_size} bytes, more than the {limit} "
                             "a table may have (oxyline.io._common.MAX_TABLE_BYTES)")
        try:
            data = fh.read(limit + 1)
        except OSError as exc:
            raise ModelError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    if len(data) > limit:
        raise ModelError(f"{p}: the {what} has more than the {limit} bytes a table may have")
    return data


def read_regular_text(path: PathLike, what: str, limit: int | None = None) -> str:
    """:func:`read_regular_file` decoded as UTF-8 (a byte-order mark is dropped)."""
    data = read_regular_file(path, what, limit)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ModelError(f"{path}: the {what} is not UTF-8 text (byte {exc.start})") from None


def confined_file(directory: Path, name: Any, suffix: str, where: str) -> Path:
    """``directory / (name + suffix)`` for a name taken from the model (a node, a vessel):
    a name with a path separator, ``..``, a drive, a NUL or nothing at all is refused with
    :class:`ModelError`, so a file derived from a model never lands outside ``directory``."""
    from pathlib import PureWindowsPath

    s = str(name)
    if not s.strip() or s in (".", "..") or "\0" in s or "/" in s or "\\" in s \
            or (os.altsep is not None and os.altsep in s) or PureWindowsPath(s).drive:
        raise ModelError(f"{where}: the name {s!r} cannot be a file name (it has a path "
                         "separator, '..', a drive or nothing): rename it")
    p = directory / f"{s}{suffix}"
    if p.resolve().parent != directory.resolve():
        raise ModelError(f"{where}: the name {s!r} would write {p} outside {directory}")
    return p
