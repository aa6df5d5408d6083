"""Writing files so that a valid one exists at every moment.

Every writer of oxyline (NetCDF, CSV, Zarr, checkpoints) writes under a temporary name beside
the target (same directory, so the rename is atomic) and renames it over the target once the
new file is complete: the target is either the previous file or the whole new one. SIGINT and
SIGTERM arriving while a file is written and renamed into place, or while a Zarr chunk is
appended, are deferred to the end of that critical section and then delivered as usual, so no
signal leaves half a chunk or a temporary file behind. (SIGKILL cannot be deferred: the
target is still whole, and the next writer of the same path removes the temporary left.)
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

#: the signals a critical section defers
DEFERRED = tuple(s for s in (signal.SIGINT, getattr(signal, "SIGTERM", None)) if s is not None)

_depth = 0  # nesting of deferred_signals() in the main thread
_pending: list[tuple[int, Any]] = []
_saved: dict[int, Any] = {}


def _record(signum: int, frame: Any) -> None:
    _pending.append((signum, frame))


@contextlib.contextmanager
def deferred_signals() -> Iterator[None]:
    """SIGINT and SIGTERM received inside the block are delivered (to the handlers installed
    before it) once the block is left. Outside the main thread signals are not delivered to
    the thread anyway (Python runs handlers in the main thread): then it does nothing."""
    global _depth
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _depth == 0:
        _pending.clear()
        for s in DEFERRED:
            _saved[s] = signal.getsignal(s)
            signal.signal(s, _record)
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        if _depth == 0:
            for s in DEFERRED:
                signal.signal(s, _saved.pop(s))
            _deliver()


def _deliver() -> None:
    """Run the handler of each signal received while deferred (once per signal number: a
    second Ctrl-C while a file was written is the same request)."""
    seen: set[int] = set()
    pending, _pending[:] = list(_pending), []
    for signum, frame in pending:
        if signum in seen:
            continue
        seen.add(signum)
        handler = signal.getsignal(signum)
        if callable(handler):
            handler(signum, frame)
        elif handler == signal.SIG_DFL:
            signal.raise_signal(signum)


def temporary_sibling(path: Path, tag: str = "partial") -> Path:
    """A temporary name beside ``path`` (same file system: the rename is atomic), hidden, and
    marked with this process's id so that a later writer can remove one a killed process left."""
    return path.with_name(f".{path.name}.{os.getpid()}.{tag}")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def remove_stale(path: Path) -> None:
    """Remove temporaries beside ``path`` left by a process that no longer runs (SIGKILL, power
    loss): ``.<name>.<pid>.partial`` / ``.old`` whose process is gone."""
    prefix = f".{path.name}."
    try:
        entries = list(path.parent.iterdir()) if path.parent.is_dir() else []
    except OSError:
        return
    for entry in entries:
        rest = entry.name[len(prefix):] if entry.name.startswith(prefix) else ""
        pid, _, tag = rest.partition(".")
        if tag in ("partial", "old") and pid.isdigit() and int(pid) != os.getpid() \
                and not _alive(int(pid)):
            _remove(entry)


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            p.unlink()


def _fsync_file(p: Path) -> None:
    if p.is_file():
        with open(p, "rb") as fh:
            os.fsync(fh.fileno())


def replace_atomically(path: Path, write: Callable[[Path], Any], sync: bool = True) -> None:
    """Call ``write(tmp)`` to write a complete new file (or directory) at a temporary name
    beside ``path``, then put it at ``path``: the previous file stays until the new one is
    whole. SIGINT and SIGTERM are deferred until the file is in place (a long write delays
    Ctrl-C by its duration, and leaves no temporary behind); any exception removes the
    temporary. An existing directory at ``path`` is moved aside first and removed once the
    new one is in place."""
    remove_stale(path)
    tmp = temporary_sibling(path)
    with deferred_signals():
        try:
            write(tmp)
            if sync:
                _fsync_file(tmp)
            if path.is_dir() and not path.is_symlink():
                old = temporary_sibling(path, "old")
                os.replace(path, old)
                os.replace(tmp, path)
                _remove(old)
            else:
                os.replace(tmp, path)
        except BaseException:
            _remove(tmp)
            raise


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether two paths name one file: the same resolved path (symlinks, ``..``), or, both
    existing, the same inode (hard links, bind mounts)."""
    pa, pb = Path(a), Path(b)
    try:
        if pa.resolve() == pb.resolve():
            return True
        return pa.exists() and pb.exists() and os.path.samefile(pa, pb)
    except (OSError, RuntimeError):
        return False
