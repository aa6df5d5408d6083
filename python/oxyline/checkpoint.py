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
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from oxyline import _core
from oxyline.errors import CheckpointError, ModelError, OutputError
from oxyline.io.atomic import replace_atomically

#: the file's schema is the core's (``oxyline_core::run::checkpoint::meta``): its format name,
#: layout version (meta keys and arrays) and the run state's numbers kept in the metadata
FORMAT = _core.CHECKPOINT_FORMAT
FILE_VERSION = _core.CHECKPOINT_FILE_VERSION
_SCALARS = tuple(_core.CHECKPOINT_STATE_SCALARS)
#: settings a resumed run may change: they change how it runs, not its results (``threads``:
#: the same bits on any number of threads)
RUN_CONTROL = frozenset(_core.RUN_CONTROL)


def json_default(obj: Any) -> Any:
    """A numpy number or array as JSON (its Python value, a list); TypeError for anything else."""
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
        json.dumps(settings, default=json_default)
    except (TypeError, ValueError) as exc:
        raise ModelError(f"simulate: with checkpoint, every setting must be a plain value: "
                         f"{exc}") from None
    return settings


def check_writable(path: str | os.PathLike[str]) -> None:
    """Before the run: a checkpoint can be written at ``path`` (its directory exists and takes
    a new file, and ``path`` is no directory), so that a bad path fails at once, not at the
    first checkpoint with the run's output lost."""
    import tempfile

    p = Path(path)
    if p.is_dir():
        raise ModelError(f"simulate: checkpoint {os.fspath(path)!r} is a directory")
    try:
        with tempfile.TemporaryFile(dir=p.parent):
            pass
    except OSError as exc:
        raise ModelError(f"simulate: checkpoint {os.fspath(path)!r}: cannot write into "
                         f"'{p.parent}': {exc.strerror or exc}") from None


def write(path: str | os.PathLike[str], meta: Mapping[str, Any],
          state: Mapping[str, Any]) -> None:
    """Write the core's ``state`` with ``meta`` (model, settings) to ``path`` atomically."""
    path = Path(path)
    full = dict(meta, format=FORMAT, version=FILE_VERSION,
                state={k: state[k] for k in _SCALARS})
    text = json.dumps(full, default=json_default).encode()
    arrays = {k: np.asarray(v, dtype=np.float64) for k, v in state.items() if k not in _SCALARS}

    def write_archive(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            np.savez(f, meta=np.frombuffer(text, dtype=np.uint8), **arrays)

    try:
        replace_atomically(path, write_archive)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write the checkpoint: {exc.strerror or exc}; the "
                          "previous checkpoint (if any) is kept") from exc


def read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, Any]]:
    """(meta, state) of a checkpoint file; :class:`CheckpointError` naming the file, and the
    field, if it is not one this version reads (truncated, corrupted, another format, a field
    of the wrong type)."""
    import stat

    path = Path(path)
    try:
        mode = path.stat().st_mode
    except OSError:
        raise CheckpointError(f"{path}: checkpoint file not found") from None
    if not stat.S_ISREG(mode):
        raise CheckpointError(f"{path}: a checkpoint must be a regular file")
    try:
        with np.load(path, allow_pickle=False) as z:
            if not hasattr(z, "files") or "meta" not in z.files:
                raise CheckpointError(f"{path}: not an oxyline checkpoint (no 'meta' record)")
            meta = json.loads(bytes(z["meta"]).decode())
            arrays = {k: np.array(z[k]) for k in z.files if k != "meta"}
    except CheckpointError:
        raise
    except (Exception, MemoryError) as exc:  # noqa: BLE001 - any damage: zip, zlib, npy, JSON
        raise CheckpointError(f"{path}: not an oxyline checkpoint or damaged "
                              f"({type(exc).__name__}: {str(exc)[:200]})") from None
    # every field present and of its type, both versions and the arrays, before any is used
    _core.check_checkpoint_meta(str(path), meta, arrays)
    state = dict(meta["state"])
    state.update(arrays)
    return meta, state
