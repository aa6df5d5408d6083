"""Checkpoint files: the state of a run at the end of a cycle, to resume it later.

``simulate(model, checkpoint="run.ckpt", checkpoint_every="10 cycles")`` writes one at the end
of every 10th cycle (or ``checkpoint_every=600``: of the first cycle ended 600 s of wall time
after the last); ``oxyline.resume("run.ckpt")`` and ``oxyline run --resume run.ckpt`` continue
the run, with results bit-identical to the run that wrote it had it gone on.

A file holds everything needed (one NumPy ``.npz`` archive, no pickles): the model (its
user-facing dict), the run settings, the flow state (y, ẏ), what the integrator and the
species transport carry between steps, the species amounts, and the output recorded so far.
It is written to a temporary file in the same directory and renamed, so a stop while writing
leaves the previous checkpoint. It carries two versions: of this file layout and of the core's
state layout (``oxyline._core.CHECKPOINT_VERSION``); another version is refused with
:class:`oxyline.CheckpointError`, as is a checkpoint that does not fit its model.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import CheckpointError, ModelError, OutputError

FORMAT = "oxyline-checkpoint"
#: layout of the file (meta keys and arrays)
FILE_VERSION = 1
_SCALARS = ("version", "cycles_run", "steps", "dt", "periodic_error")
#: settings of a run that control it, not its results: not stored, may change on resume
RUN_CONTROL = frozenset({"progress", "cancel", "checkpoint", "checkpoint_every", "max_memory"})


def parse_every(value: Any) -> dict[str, Any]:
    """The core's keywords of ``checkpoint_every``: seconds of wall time (a number, or a
    string ``"90 s"``), or ``"N cycles"``; None: every 300 s."""
    import numbers

    if value is None:
        return {}
    if isinstance(value, str):
        m = re.fullmatch(r"\s*(\d+)\s*cycles?\s*", value)
        if m and int(m.group(1)) >= 1:
            return {"checkpoint_every_cycles": int(m.group(1))}
        m = re.fullmatch(r"\s*([0-9.]+)\s*(s|sec|seconds?)\s*", value)
        if m:
            try:
                value = float(m.group(1))
            except ValueError:
                pass
    if isinstance(value, numbers.Real) and not isinstance(value, bool) \
            and np.isfinite(float(value)) and float(value) >= 0:
        return {"checkpoint_every_seconds": float(value)}
    raise ModelError(f"simulate: checkpoint_every must be seconds of wall time (a number >= 0) "
                     f"or 'N cycles', got {value!r}")


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def stored_settings(overrides: Mapping[str, Any]) -> dict[str, Any]:
    """The settings a checkpoint stores (those that decide the results), checked to be
    JSON-able."""
    settings = {k: v for k, v in overrides.items() if k not in RUN_CONTROL}
    try:
        json.dumps(settings, default=_json_default)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"simulate: with checkpoint, every setting must be a plain value: "
                         f"{exc}") from None
    return settings


def write(path: str | os.PathLike[str], meta: Mapping[str, Any],
          state: Mapping[str, Any]) -> None:
    """Write the core's ``state`` with ``meta`` (model, settings) to ``path`` atomically."""
    path = Path(path)
    full = dict(meta, format=FORMAT, version=FILE_VERSION,
                state={k: state[k] for k in _SCALARS})
    text = json.dumps(full, default=_json_default).encode()
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in state.items() if k not in _SCALARS}
    tmp = path.with_name(f".{path.name}.{os.getpid()}.partial")
    try:
        with open(tmp, "wb") as f:
            np.savez(f, meta=np.frombuffer(text, dtype=np.uint8), **arrays)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{path}: cannot write the checkpoint: {exc.strerror or exc}; the "
                          "previous checkpoint (if any) is kept") from exc


def read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(meta, state) of a checkpoint file; :class:`CheckpointError` naming the file if it is
    not one this version reads."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: checkpoint file not found")
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(bytes(z["meta"]).decode())
            arrays = {k: np.array(z[k]) for k in z.files if k != "meta"}
    except (OSError, ValueError, KeyError, UnicodeDecodeError, EOFError) as exc:
        raise CheckpointError(f"{path}: not an oxyline checkpoint ({exc})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise CheckpointError(f"{path}: not an oxyline checkpoint")
    if meta.get("version") != FILE_VERSION:
        raise CheckpointError(f"{path}: checkpoint file version {meta.get('version')}, this "
                              f"oxyline ({_core.__version__}) reads version {FILE_VERSION}")
    state = dict(meta.get("state") or {})
    if state.get("version") != _core.CHECKPOINT_VERSION:
        raise CheckpointError(f"{path}: run state version {state.get('version')}, this oxyline "
                              f"({_core.__version__}) reads version {_core.CHECKPOINT_VERSION}")
    state.update(arrays)
    return meta, state
