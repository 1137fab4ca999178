"""What a file holds, from its first bytes rather than its name: a PX4 ULog, an ArduPilot DataFlash log,
a Crazyflie uSD event log, an ingested flight.npz, or none of these. Folder scans (batch detect, the
vehicle reference) and the log reader all decide with this one function."""

from __future__ import annotations

import zipfile
from pathlib import Path

LOG_KINDS = ("ulog", "dataflash", "crazyflie")


def head_kind(head: bytes) -> str | None:
    """"ulog", "dataflash", "crazyflie" or None from a file's first 8 bytes."""
    if head.startswith(b"ULog"):
        return "ulog"
    if head[:2] == b"\xa3\x95":  # DataFlash message header
        return "dataflash"
    if head[:1] == b"\xbc" and len(head) >= 5 and head[1:3] in (b"\x01\x00", b"\x02\x00"):  # event log v1/v2
        return "crazyflie"
    return None


def log_kind(path: Path) -> str | None:
    """One of LOG_KINDS, "flight.npz" (an ingested flight: a zip holding log_sha256) or None."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return None
    kind = head_kind(head)
    if kind is not None or head[:4] != b"PK\x03\x04":
        return kind
    try:
        with zipfile.ZipFile(path) as z:
            return "flight.npz" if "log_sha256.npy" in z.namelist() else None
    except (OSError, zipfile.BadZipFile):
        return None


def walk_logs(paths: list[str | Path]) -> list[tuple[Path, tuple[str, ...] | None]]:
    """Every file given, and every file a folder given holds (recursively, hidden files skipped) whose
    :func:`log_kind` is known, in a stable order, each file once (the first way it was reached). A found
    file comes with its folder's name and its path below it; a file given by name with None, whatever
    it holds (reading it then says why not)."""
    found: list[tuple[Path, tuple[str, ...] | None]] = []
    for given in paths:
        p = Path(given)
        if p.is_dir():
            for f in sorted(q for q in p.rglob("*") if q.is_file() and not q.name.startswith(".")):
                if log_kind(f) is not None:
                    found.append((f, (p.resolve().name,) + f.relative_to(p).parts))
        else:
            found.append((p, None))
    unique, seen = [], set()
    for f, parts in found:
        if f.resolve() not in seen:
            seen.add(f.resolve())
            unique.append((f, parts))
    return unique
