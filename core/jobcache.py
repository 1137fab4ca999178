"""Job keys and the result cache: a job's result is a file named by the hash of what made it.

A key is the sha256 of (kind, config dict, arguments, the sha256 of every input file, the code). The
code is a hash of the source files of the packages the job runs, always with the floors every stage
stands on (core, formats, models, runtimes), plus firmware_ref's C++ sources for the stages that
build them (parity, bench). So an uncommitted edit to ``sim/`` changes the key of a simulation job
while an edit to ``train/`` does not, and a commit that touches neither changes nothing. Each
package is found through the import system and hashed by paths relative to it, so the same sources
give the same key in a checkout and in an installed wheel. Execution settings (scheduler, number of
workers) are never part of a key: the same job gives the same bytes on any executor.

Results live in ``<run>/cache/<kind>/<key>.npz`` (arrays), ``<key>.json`` (metrics) or ``<key>.bin``
(opaque bytes, e.g. a saved model), written
atomically, so a job that ran twice (a worker presumed dead, then a retry) writes the same bytes
twice under the same name and a reader never sees half a file.
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from quadfdi.core.resources import firmware_digest, package_folder

CACHE_DIR = "cache"  # <run>/cache/<kind>/<key>.<ext>
FLOORS = ("core", "formats", "models", "runtimes")  # imported by every stage: part of every key
NATIVE = ("parity", "bench")  # stages whose jobs build and run firmware_ref's C++


def file_sha256(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def source_hash(packages: tuple[str, ...]) -> str:
    """sha256 over the .py files of ``packages`` (the project's folders: ``sim`` is ``quadfdi.sim``,
    ``quadfdi`` the app layer alone, its sub-packages hashed under their own names), by path relative
    to each package."""
    h = hashlib.sha256()
    for pkg in sorted(set(packages)):
        folder = package_folder("quadfdi" if pkg == "quadfdi" else f"quadfdi.{pkg}")
        files = folder.glob("*.py") if pkg == "quadfdi" else folder.rglob("*.py")
        for f in sorted(files, key=lambda f: f.relative_to(folder).as_posix()):
            h.update(f"{pkg}/{f.relative_to(folder).as_posix()}".encode() + b"\0")
            h.update(f.read_bytes() + b"\0")
    return h.hexdigest()


def code_version(packages: tuple[str, ...]) -> dict[str, str]:
    """What identifies the code a job runs: the hash of its packages' sources (``FLOORS`` always) and,
    for the stages in ``NATIVE``, of the C++ sources."""
    out = {"sources": source_hash(tuple(sorted({*FLOORS, *packages})))}
    if set(NATIVE) & set(packages):
        out["firmware_ref"] = firmware_digest()
    return out


def job_key(kind: str, config: dict, args: dict | None = None, inputs: dict[str, str | os.PathLike] | None = None,
            packages: tuple[str, ...] = ()) -> str:
    """The sha256 (hex) that names a job's result: same key, same result bytes."""
    doc = {
        "kind": kind,
        "config": config,
        "args": args or {},
        "inputs": {name: file_sha256(p) for name, p in sorted((inputs or {}).items())},
        "code": code_version(tuple(packages)),
    }
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), default=_jsonable)
    return hashlib.sha256(text.encode()).hexdigest()


def _jsonable(o: Any) -> Any:
    if isinstance(o, (np.integer, np.floating)):
        return o.item()
    if isinstance(o, (tuple, set)):
        return list(o)
    raise TypeError(f"job_key: cannot hash a {type(o).__name__}")


def cache_path(run_root: str | os.PathLike, kind: str, key: str, ext: str) -> Path:
    """Where job ``key`` of ``kind`` keeps its result (``ext``: 'npz' for arrays, 'json' for metrics)."""
    if ext not in ("npz", "json", "bin"):
        raise ValueError(f"cache_path: ext must be 'npz', 'json' or 'bin', not {ext!r}")
    return Path(run_root) / CACHE_DIR / kind / f"{key}.{ext}"


def is_cached(path: str | os.PathLike) -> bool:
    """True when a complete result is there. Files are renamed into place whole, so existence is
    enough; a foreign or damaged file is caught when it is read."""
    return Path(path).is_file()


def write_result(path: str | os.PathLike, value: Any) -> None:
    """Write a job's return value: a dict of arrays to ``.npz``, a JSON-able value to ``.json``."""
    from quadfdi.core.jsonio import write_json
    from quadfdi.core.npzio import write_npz

    from quadfdi.core.atomic import write_bytes

    p = Path(path)
    if p.suffix == ".bin":  # opaque bytes, e.g. a torch.save of a trained model
        if not isinstance(value, bytes):
            raise TypeError(f"a job cached as .bin must return bytes, not {type(value).__name__}")
        write_bytes(p, value)
    elif p.suffix == ".npz":
        if not isinstance(value, dict):
            raise TypeError(f"a job cached as .npz must return a dict of arrays, not {type(value).__name__}")
        write_npz(p, value)
    else:
        write_json(p, value)


def read_result(path: str | os.PathLike) -> Any:
    from quadfdi.core.jsonio import read_json
    from quadfdi.core.npzio import read_npz

    p = Path(path)
    if p.suffix == ".bin":
        return p.read_bytes()
    return read_npz(p, "cached job result") if p.suffix == ".npz" else read_json(p, "cached job result")


def remove_partial(folder: str | os.PathLike) -> int:
    """Delete the temp files a killed writer left in ``folder`` (core.atomic names them ``.<name>.*.tmp``);
    call only when no job is writing there. Returns how many were removed."""
    n = 0
    d = Path(folder)
    if d.is_dir():
        for f in d.glob(".*.tmp"):
            f.unlink(missing_ok=True)
            n += 1
    return n
