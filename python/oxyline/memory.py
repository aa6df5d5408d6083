"""Memory limits and estimates, checked before anything large is allocated.

A model too large for the memory allowed (``segments: 10**9``, ``max_length: 1e-9``) or a
requested output too large to hold (every cycle of a long run, ``output_every=1e-7``) is
refused with :class:`oxyline.ResourceError`, which gives the estimate and the setting to
change, instead of taking all RAM until the process is killed.

The limit is the setting ``max_memory`` (bytes, or a string such as ``"8 GB"``, ``"512 MiB"``;
``"none"`` for no limit): ``simulate(max_memory=...)``, or ``simulation: max_memory`` in the
model file (which also applies when the model is assembled), else the environment variable
``OXYLINE_MAX_MEMORY``, else 80 % of the memory available when the check runs
(``MemAvailable`` of ``/proc/meminfo``, else ``os.sysconf``), and at most 80 % of the
process's address-space limit (``ulimit -v``) if one is set.

The model estimate is the core's (`oxyline_core::run::memory`): the bytes its layout allocates
per segment, per transport cell and species, and per vessel and boundary condition, times the
resident share measured at a whole run's peak; an error-controlled run adds its controller's
state per unknown and per transport cell (:func:`run_estimate`). Python only compares it with
the limit. The output estimate counts the rows and columns the run will hold (8 bytes each).
``benches/bench_memory.py`` compares both with the measured peak resident memory.
"""

from __future__ import annotations

import contextlib
import gc
import math
import os
import re
from collections.abc import Iterator, Mapping
from typing import Any

from oxyline.errors import ModelError, ResourceError

#: share of the available memory a run may take by default
DEFAULT_FRACTION = 0.8
#: more output rows per cycle than this is no output anyone can hold (1e12 rows of one column
#: are 8 TB)
MAX_ROWS_PER_CYCLE = 1e12
#: outputs above this many bytes are announced (OutputSizeWarning) before they are computed
WARN_BYTES = 2e9

_UNITS = {"": 1.0, "b": 1.0, "kb": 1e3, "mb": 1e6, "gb": 1e9, "tb": 1e12,
          "kib": 2.0**10, "mib": 2.0**20, "gib": 2.0**30, "tib": 2.0**40}


def human(nbytes: float) -> str:
    """``nbytes`` as "1.234 GB" (decimal units)."""
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3f} {unit}"
    return f"{nbytes:.0f} B"


def parse(value: Any, where: str) -> float | None:
    """A ``max_memory`` value in bytes (None: no limit): a number > 0, or a string with a unit
    (``"8 GB"``, ``"512MiB"``), or ``"none"``."""
    import numbers

    if isinstance(value, str):
        text = value.strip().lower().replace("_", "")
        if text in ("none", "off", "unlimited"):
            return None
        m = re.fullmatch(r"([0-9.]+(?:e[+-]?[0-9]+)?)\s*([a-z]*)", text)
        if m and m.group(2) in _UNITS:
            try:
                value = float(m.group(1)) * _UNITS[m.group(2)]
            except ValueError:
                pass
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(float(value)) or float(value) <= 0:
        raise ModelError(f"{where} must be a number of bytes > 0 or a size such as '8 GB' "
                         f"(or 'none'), got {value!r}")
    return float(value)


def available() -> float | None:
    """Bytes of memory available now (``MemAvailable``; else free pages), None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024.0
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def default_limit() -> float | None:
    """The limit when none is set: ``OXYLINE_MAX_MEMORY``, else 80 % of the available memory
    and of the address-space limit."""
    env = os.environ.get("OXYLINE_MAX_MEMORY")
    if env:
        return parse(env, "OXYLINE_MAX_MEMORY")
    caps = []
    avail = available()
    if avail is not None:
        caps.append(DEFAULT_FRACTION * avail)
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            caps.append(DEFAULT_FRACTION * soft)
    except (ImportError, ValueError, OSError):
        pass
    return min(caps) if caps else None


def limit(value: Any, where: str) -> float | None:
    """The limit of a ``max_memory`` setting (None: the default)."""
    return default_limit() if value is None else parse(value, where)


def run_estimate(network: Any, settings: Mapping[str, Any]) -> float:
    """Estimated peak bytes of a run of ``network`` (a ``_core.Network``) with ``settings``,
    its output aside: the core's count from the sizes it allocated (segments, vessels and
    boundary conditions, transport cells and species, and for an error-controlled run its
    controller's state per unknown and cell; ``oxyline_core::run::memory::run_bytes``).
    ``auto`` may pick either integrator: the larger (the explicit pair's) is counted."""
    controlled = None if settings.get("rtol") is None \
        else settings.get("method") in ("dopri5", "auto")
    return float(network.memory_estimate(transport=bool(settings.get("transport", True)),
                                         controlled=controlled))


def output_estimate(layout: dict[str, Any], period: float, every: float, cycles: int,
                    all_cycles: bool) -> tuple[float, int, int]:
    """(bytes, rows, columns) of the output a run holds: rows of time, flow columns and
    species columns, 8 bytes each."""
    ratio = period / every if every > 0 else math.inf
    if not ratio <= MAX_ROWS_PER_CYCLE:
        raise ResourceError(f"simulate: output_every = {every:g} s gives {ratio:.3g} output rows "
                            f"per cycle of {period:g} s, more than {MAX_ROWS_PER_CYCLE:.0e}; "
                            "choose a longer output_every")
    per_cycle = max(1, round(ratio))
    rows = per_cycle * cycles + 1 if all_cycles else per_cycle + 1
    cols = 1 + int(layout["n_columns"])
    tl = layout.get("transport")
    if tl:
        cols += len(tl["species"]) * int(tl["columns_per_species"])
    return 8.0 * rows * cols, rows, cols


#: the memory a streamed store's chunk of output rows may take while it is written
#: (``simulate_to_zarr`` without ``time_chunk``): the rows per chunk are chosen to stay under it
STREAM_BUDGET = 256 * 2**20
#: copies of a chunk of rows alive at once while it is written: the core's buffer, the rows
#: handed over to Python, and the arrays the chunk's dataset writes from (measured with
#: ``benches/bench_zarr_scale.py``: docs/performance.md)
STREAM_COPIES = 3
#: rows per chunk at most when chosen from the budget (the former fixed default)
STREAM_MAX_ROWS = 1024
#: a streaming run's output table first makes room for this many rows (or its chunk's, if
#: fewer), then doubles
_FIRST_ROWS = 64


def stream_rows(columns: int, budget: float | None = None) -> int:
    """Rows per chunk of a streamed store of ``columns`` values per row (time included): as
    many as keep ``STREAM_COPIES`` copies of the chunk (8 bytes a value) within ``budget``,
    at least 1, at most ``STREAM_MAX_ROWS``; above 64 a power of two, so that the core's
    table, which grows by doubling from 64 rows, holds exactly one chunk."""
    budget = STREAM_BUDGET if budget is None else budget
    rows = int(budget // (STREAM_COPIES * 8.0 * max(1, columns)))
    rows = max(1, min(STREAM_MAX_ROWS, rows))
    if rows > _FIRST_ROWS:
        rows = 1 << (rows.bit_length() - 1)
    return rows


def table_rows(rows: int, chunk: int) -> int:
    """Rows a streaming run's output table makes room for to hold ``rows`` rows: from
    ``min(chunk, 64)`` rows, doubled until they fit."""
    held = max(1, min(chunk, _FIRST_ROWS))
    while held < rows:
        held *= 2
    return held


def stream_estimate(chunk: int, columns: int, cycle_rows: int = 0,
                    rows: int | None = None) -> float:
    """Bytes of a streamed run's output held in memory: ``STREAM_COPIES`` copies of a chunk of
    ``chunk`` rows (or of all the output's ``rows``, if fewer) of ``columns`` values, plus the
    core's table of a whole cycle of ``cycle_rows`` rows when the run keeps its current cycle
    before the last (last-cycle output)."""
    in_flight = chunk if rows is None else max(1, min(chunk, rows))
    per_chunk = STREAM_COPIES * 8.0 * table_rows(in_flight, chunk) * columns
    cycle = 8.0 * table_rows(cycle_rows, chunk) * columns if cycle_rows else 0.0
    return per_chunk + cycle


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector while a model is copied and checked: a 1e6-segment
    model allocates millions of small dicts (none of them cyclic), and every full collection
    walks all live objects again, which makes loading grow faster than linearly."""
    enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if enabled:
            gc.enable()
