"""Stage records (``runs/R/.stages/<stage>.json``) and the recovery of an interrupted publish.

A record names every output of a published stage (relative path, sha256, bytes), every input it
consumed (with the sha256 its producer recorded), the config sections it used and the command.
Readers trust a file only when a record lists it with the hash the file has now
(``verify_input``); docs/formats.md, "Stage records", is the contract.

A run folder may come from someone else (a colleague's results, a downloaded benchmark), so a record
is input like any other: every path in it must be a relative path that stays inside the run folder
(no absolute path, no ``..``, no symlink leading out; ``confined``), or the record is refused as
damaged. A damaged record blocks only what reads its stage's outputs, and re-running that stage
replaces it.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
from pathlib import Path, PurePosixPath
from typing import Any

from quadfdi.core.errors import QuadfdiError

SCHEMA_VERSION = 1
STAGING, PUBLISH, STAGES = ".staging", ".publish", ".stages"
RECORD = "record.json"
_HASHES: dict[tuple, str] = {}  # (dev, inode, size, mtime_ns) -> sha256: hash each file once per process


def sha256_file(path: Path) -> str:
    st = os.stat(path)
    key = (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)
    if key not in _HASHES:
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        _HASHES[key] = h.hexdigest()
    return _HASHES[key]


MAX_RECORD_BYTES = 16 << 20  # a record lists file names and hashes: far below this


def record_path(root: Path, stage: str) -> Path:
    return Path(root) / STAGES / f"{stage}.json"


def relative_ok(rel: Any) -> bool:
    """Whether ``rel`` is a relative POSIX path of plain components: no absolute path, no ``..``."""
    if not isinstance(rel, str) or not rel or "\0" in rel or "\\" in rel:
        return False
    p = PurePosixPath(rel)
    return not p.is_absolute() and all(part not in ("", ".", "..") for part in p.parts) and p.as_posix() == rel


def confined(root: Path, rel: Any, where: str) -> Path:
    """``root / rel``, or a one-line error when ``rel`` would lead out of ``root`` (an absolute path,
    ``..``, or a symlinked folder on the way)."""
    if not relative_ok(rel):
        raise QuadfdiError(f"{where} names {rel!r}, which is not a relative path inside {root}: refused")
    base = Path(root).resolve()
    full = Path(root) / rel
    parent = full.parent.resolve()
    if parent != base and base not in parent.parents:
        raise QuadfdiError(f"{where} names {rel!r}, which leads out of {root} through a symlink: refused")
    return full


def read_record(path: Path) -> dict[str, Any]:
    """A record's content, or a one-line error naming the file (a record is small, strict JSON whose
    every path stays inside the run folder)."""
    try:
        if Path(path).stat().st_size > MAX_RECORD_BYTES:
            raise QuadfdiError(f"stage record {path} is larger than {MAX_RECORD_BYTES} bytes: re-run the stage")
        rec = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise QuadfdiError(f"stage record {path} cannot be read ({exc}): re-run the stage") from None
    if not isinstance(rec, dict) or rec.get("schema_version") != SCHEMA_VERSION or not isinstance(rec.get("outputs"), list) \
            or not isinstance(rec.get("inputs", []), list):
        raise QuadfdiError(f"stage record {path} is not a quadfdi stage record of schema {SCHEMA_VERSION}: re-run the stage")
    for entry in rec["outputs"] + rec.get("inputs", []):
        if not isinstance(entry, dict) or not relative_ok(entry.get("path")) or not isinstance(entry.get("sha256"), str):
            raise QuadfdiError(f"stage record {path} lists {entry.get('path') if isinstance(entry, dict) else entry!r}, "
                               "not a relative path inside the run folder with its sha256: refused (re-run the stage)")
    return rec


def load_record(root: Path, stage: str) -> dict[str, Any] | None:
    p = record_path(root, stage)
    return read_record(p) if p.is_file() else None


def previous_record(root: Path, stage: str) -> dict[str, Any] | None:
    """The stage's own published record for a re-run of it: None when absent or damaged (the re-run
    replaces a damaged record; the files it listed stay where they are)."""
    try:
        return load_record(root, stage)
    except QuadfdiError:
        return None


def all_records(root: Path) -> dict[str, dict[str, Any]]:
    """Every readable stage record; a damaged one is left out (``damaged_records`` names it)."""
    return scan_records(root)[0]


def damaged_records(root: Path) -> dict[str, str]:
    """{stage: why} of the records that cannot be read or trusted."""
    return scan_records(root)[1]


def scan_records(root: Path) -> tuple[dict[str, dict[str, Any]], dict[str, str]]:
    d = Path(root) / STAGES
    good: dict[str, dict[str, Any]] = {}
    bad: dict[str, str] = {}
    if not d.is_dir():
        return good, bad
    for p in sorted(d.glob("*.json")):
        try:
            good[p.stem] = read_record(p)
        except QuadfdiError as exc:
            bad[p.stem] = str(exc)
    return good, bad


def producer_of(root: Path, rel: str) -> tuple[str, dict, dict] | None:
    """(stage, record, output entry) of the published stage that lists ``rel``, or None."""
    for stage, rec in all_records(root).items():
        for entry in rec["outputs"]:
            if entry.get("path") == rel:
                return stage, rec, entry
    return None


def first_difference(recorded: dict, given: dict) -> tuple[str, Any, Any] | None:
    for key in sorted(set(recorded) | set(given)):
        if recorded.get(key) != given.get(key):
            return key, recorded.get(key), given.get(key)
    return None


def verify_input(root: Path, rel: str, config: dict[str, dict] | None = None,
                 sections: tuple[str, ...] = ()) -> dict[str, Any]:
    """Check ``root/rel`` against the record that published it; return the input entry.

    Refuses (one line) a file no record lists, a file whose sha256 differs from the recorded one,
    a producer whose own inputs were republished since (it was made from something else), and a
    ``config`` whose ``sections`` differ from those the producer recorded.
    """
    root = Path(root)
    path = confined(root, rel, "an input")
    found = producer_of(root, rel)
    if found is None:
        state = "does not exist" if not path.exists() else "is not a published output of any stage"
        bad = damaged_records(root)
        if bad:
            stage, why = next(iter(bad.items()))
            raise QuadfdiError(f"{path} {state} in a readable record, and .stages/{stage}.json is damaged ({why}): "
                               f"re-run quadfdi {stage}")
        raise QuadfdiError(f"{path} {state} (no record in {root / STAGES} lists it): run the stage that writes it")
    stage, rec, entry = found
    if not path.is_file() or path.is_symlink():
        raise QuadfdiError(f"{path} is missing or not a regular file, but .stages/{stage}.json lists it: "
                           f"re-run quadfdi {stage}")
    got = sha256_file(path)
    if got != entry["sha256"]:
        raise QuadfdiError(f"{path}: sha256 {got[:16]}... differs from {entry['sha256'][:16]}... recorded in "
                           f".stages/{stage}.json (changed after it was published): re-run quadfdi {stage}")
    check_upstream(root, stage, rec)
    for section in sections:
        if config is None or section not in rec.get("config", {}):
            continue
        diff = first_difference(rec["config"][section], config.get(section, {}))
        if diff is not None:
            key, was, now = diff
            raise QuadfdiError(f"config [{section}].{key} is {now!r} but {rel} was made with {was!r} "
                               f"(.stages/{stage}.json): re-run quadfdi {stage} with this config, or drop the change")
    return {"path": rel, "sha256": got, "stage": stage}


def check_upstream(root: Path, stage: str, rec: dict) -> None:
    """A published file is stale when an input it was made from has been republished since."""
    for inp in rec.get("inputs", []):
        now = producer_of(root, inp["path"])
        if now is None or now[2]["sha256"] != inp["sha256"]:
            raise QuadfdiError(f"the outputs of stage {stage} were made from {inp['path']} sha256 {inp['sha256'][:16]}..., "
                               f"which is no longer the published one: re-run quadfdi {stage}")


def _remove_file(path: Path) -> None:
    with contextlib.suppress(FileNotFoundError):
        if path.is_dir() and not path.is_symlink():
            return  # never delete a folder a user put there; publish refuses it beforehand
        path.unlink()


def _remove_output(root: Path, rel: str) -> None:
    """Remove a recorded output: only inside ``root`` (a record is checked when read; a symlinked
    folder on the way is refused here)."""
    _remove_file(confined(root, rel, "a stage record"))


def roll_forward(root: Path, stage: str, fault=lambda point: None) -> str:
    """Finish the publish of ``.publish/<stage>``: it holds a complete set (the commit point passed).
    A publish folder this quadfdi cannot have written (its record unreadable, a path leading out of
    the run folder, or the folder itself a symlink) is deleted, not rolled forward; what was done."""
    root = Path(root)
    pub = root / PUBLISH / stage
    try:
        if pub.is_symlink() or (root / PUBLISH).is_symlink():
            raise QuadfdiError(f"{pub} is a symlink")
        new = read_record(pub / RECORD) if (pub / RECORD).is_file() else previous_record(root, stage)
        for entry in (new or {}).get("outputs", []):
            confined(pub, entry["path"], str(pub / RECORD))
            confined(root, entry["path"], str(pub / RECORD))
    except QuadfdiError as exc:
        if pub.is_symlink():
            pub.unlink()
        else:
            shutil.rmtree(pub, ignore_errors=True)
        return f"removed a damaged publish of {stage} ({exc})"
    if new is None:  # record already placed and the folder half removed: nothing left to move
        shutil.rmtree(pub, ignore_errors=True)
        return f"rolled forward {stage}"
    old = previous_record(root, stage)
    keep = {e["path"] for e in new["outputs"]}
    for entry in (old or {}).get("outputs", []):
        if entry["path"] not in keep:  # e.g. the ONNX files of an earlier --steps
            _remove_output(root, entry["path"])
    moved = 0
    for entry in new["outputs"]:
        src = confined(pub, entry["path"], f"{pub / RECORD}")
        if src.is_file() and not src.is_symlink():  # absent: moved before an interruption, or carried in place
            dst = confined(root, entry["path"], f"{pub / RECORD}")
            dst.parent.mkdir(parents=True, exist_ok=True)
            os.replace(src, dst)
            moved += 1
            if moved == 1:
                fault("mid-publish")
    if (pub / RECORD).is_file():
        (root / STAGES).mkdir(exist_ok=True)
        os.replace(pub / RECORD, record_path(root, stage))
    shutil.rmtree(pub, ignore_errors=True)
    return f"rolled forward {stage}"


def recover(root: Path) -> list[str]:
    """Bring ``root`` to a published state (call under the run lock); what was done, for the log.

    A ``.publish/<stage>`` folder is complete, so it is rolled forward; a ``.staging`` folder is
    an orphan of a killed compute and is deleted, as are orphan ``*.tmp`` files of core.atomic.
    """
    root = Path(root)
    done = []
    pub = root / PUBLISH
    if pub.is_dir() and not pub.is_symlink():
        for d in sorted(pub.iterdir()):
            done.append(roll_forward(root, d.name))
    elif pub.is_symlink():
        pub.unlink()
        done.append(f"removed {PUBLISH}, a symlink")
    staging = root / STAGING
    if staging.is_dir():
        for d in sorted(staging.iterdir()):
            shutil.rmtree(d, ignore_errors=True) if d.is_dir() else _remove_file(d)
            done.append(f"removed orphan {d.name}")
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = [n for n in dirnames if n not in (STAGING, PUBLISH)]
        for name in filenames:
            if name.startswith(".") and name.endswith(".tmp"):
                _remove_file(Path(dirpath) / name)
                done.append(f"removed orphan {name}")
    return done
