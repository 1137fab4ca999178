"""One writer at a time per run folder: an advisory lock on ``runs/R/.lock`` (fcntl.flock).

Two overlapping writers (two ``quadfdi export`` on one run) once left a manifest describing
files the other had replaced. Every writing command holds this lock for its whole run; a second
one waits a short time (``QUADFDI_LOCK_WAIT_S``, default 3 s) and then refuses with one line
naming the holder, whose pid, command and start time are written into the lock file.
The lock is re-entrant within a process: ``quadfdi run`` holds it across all stages, and each
stage takes it again (flock on a second descriptor of the same file would deadlock).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import fcntl
import os
import sys
import time
from pathlib import Path
from typing import Iterator

from quadfdi.core.errors import QuadfdiError

LOCK_NAME = ".lock"
_HELD: dict[str, list[int]] = {}  # realpath of the run folder -> [fd, depth]


def _wait_s() -> float:
    try:
        return max(0.0, float(os.environ.get("QUADFDI_LOCK_WAIT_S", "3")))
    except ValueError:
        return 3.0


def _holder(fd: int) -> str:
    with contextlib.suppress(OSError):
        text = os.pread(fd, 4096, 0).decode("utf-8", "replace").strip()
        if text:
            return text
    return "unknown holder"


def _command() -> str:
    return "quadfdi " + " ".join(sys.argv[1:]) if sys.argv[1:] else "quadfdi"


@contextlib.contextmanager
def run_lock(root: str | os.PathLike, command: str | None = None) -> Iterator[None]:
    """Hold the run folder's writer lock for the body (re-entrant in one process)."""
    key = os.path.realpath(root)
    if key in _HELD:
        _HELD[key][1] += 1
        try:
            yield
        finally:
            _HELD[key][1] -= 1
        return
    path = Path(root) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
    except OSError as exc:
        raise QuadfdiError(f"cannot open the run lock {path}: {exc.strerror}") from None
    try:
        _acquire(fd, path)
        info = f"pid {os.getpid()}, command {command or _command()!r}, started {_dt.datetime.now(_dt.timezone.utc):%Y-%m-%d %H:%M:%S} UTC"
        with contextlib.suppress(OSError):  # a full disk: the lock holds without its holder's line
            os.ftruncate(fd, 0)
            os.pwrite(fd, (info + "\n").encode(), 0)
        _HELD[key] = [fd, 1]
        try:
            yield
        finally:
            del _HELD[key]
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
    finally:
        os.close(fd)  # closing the descriptor releases the flock


def _acquire(fd: int, path: Path) -> None:
    deadline = time.monotonic() + _wait_s()
    while True:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            if time.monotonic() >= deadline:
                raise QuadfdiError(f"{path.parent} is being written by another quadfdi command ({_holder(fd)}); "
                                   f"wait for it to finish (lock file {path})") from None
            time.sleep(0.1)
