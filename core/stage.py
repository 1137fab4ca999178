"""Every stage commits as a unit: staged outputs, a stage record, a journaled publish.

``with stage(root, "train", config) as st:`` takes the run lock, recovers an interrupted publish,
and gives a fresh ``runs/R/.staging/train.<random>/`` (``st.out``): the stage writes every output
there under its final relative path. On success the publish runs:

1. the outputs' record goes to ``record.json`` and the staging folder is renamed to
   ``.publish/train`` -- the commit point: from here a complete set exists;
2. each output is moved to its final place (os.replace); outputs of the previous record the new
   one no longer has are removed;
3. the record replaces ``.stages/train.json``; 4. ``.publish/train`` is removed.

A crash before 1 leaves the old state untouched (the next command deletes the orphan staging
folder); a crash after 1 is rolled forward by the next command (core.records.recover). So a run
folder is always in its old or its new published state, never a mix.

``QUADFDI_FAULT_POINT=<stage>:<point>[:TERM|:INT|:STOP]`` sends SIGKILL (or SIGTERM, SIGINT as
Ctrl-C does, SIGSTOP) to the
process at a named point (staged, before-publish, mid-publish, after-publish): the fault-injection
tests use it because a signal at a named point is deterministic and a timer is not.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import os
import shutil
import signal
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterator

from quadfdi.core import records
from quadfdi.core.atomic import ensure_dir, write_text
from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jsonio import dumps_json
from quadfdi.core.runlock import run_lock


def fault_point(stage: str, point: str) -> None:
    """Kill this process when QUADFDI_FAULT_POINT names ``stage:point`` (tests only)."""
    want = os.environ.get("QUADFDI_FAULT_POINT", "")
    parts = want.split(":")
    if len(parts) >= 2 and parts[0] == stage and parts[1] == point:
        sig = {"TERM": signal.SIGTERM, "STOP": signal.SIGSTOP, "INT": signal.SIGINT}.get((parts[2:] or ["KILL"])[0],
                                                                                         signal.SIGKILL)
        sys.stdout.flush()
        os.kill(os.getpid(), sig)  # STOP: the process holds its lock until the test kills it


def check_target(path: Path) -> None:
    """Outputs replace only regular files: a symlink, FIFO, device or folder there is refused."""
    if path.is_symlink() or (path.exists() and not path.is_file()):
        kind = "symlink" if path.is_symlink() else "folder" if path.is_dir() else "special file (FIFO or device)"
        raise QuadfdiError(f"{path} is a {kind}, not a regular file: refusing to replace it (move it away first)")


def check_parents(root: Path, rel: str) -> None:
    """Every folder on the way to output ``rel`` is a folder or absent: a regular file or a symlink named
    like an output folder (``export`` or ``figures`` as a file) is refused, naming it."""
    p = Path(root)
    for part in Path(rel).parts[:-1]:
        p = p / part
        if p.is_symlink() or (p.exists() and not p.is_dir()):
            raise QuadfdiError(f"{p} is a {'symlink' if p.is_symlink() else 'file'}, but quadfdi writes into a "
                               f"folder there: move it away first")


def check_free_space(root: Path, need_bytes: int, what: str) -> None:
    free = shutil.disk_usage(root).free
    if need_bytes > free:
        raise QuadfdiError(f"{root}: {what} needs about {need_bytes / 1e6:.0f} MB, the file system has "
                           f"{free / 1e6:.0f} MB free")


def _intact(root: Path, entries: list[dict]) -> list[dict]:
    """The recorded outputs still in place with their recorded sha256 (the ones a stage may carry)."""
    return [e for e in entries if (root / e["path"]).is_file() and not (root / e["path"]).is_symlink()
            and records.sha256_file(root / e["path"]) == e["sha256"]]


class StageWriter:
    """The staging folder of one stage run and what it consumed; see the module docstring."""

    def __init__(self, root: Path, name: str, config: dict[str, dict], command: str, out: Path):
        self.root, self.name, self.config, self.command, self.out = root, name, config, command, out
        self.inputs: dict[str, dict] = {}
        self.previous = records.previous_record(root, name)

    def path(self, rel: str) -> Path:
        """Where the stage writes output ``rel`` (its parents made)."""
        p = self.out / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        return p

    def consume(self, rel: str, sections: tuple[str, ...] = ()) -> Path:
        """Verify input ``rel`` against its producer's record (hash, upstream, config sections)."""
        self.inputs[rel] = records.verify_input(self.root, rel, self.config, sections)
        return self.root / rel

    def carry_previous(self) -> bool:
        """Keep the previous record's outputs this run does not rewrite (``train --model cnode``
        keeps gru.pt) -- only when they were made from the same inputs; return whether kept."""
        prev = self.previous
        if prev is None:
            return False
        same = {(i["path"], i["sha256"]) for i in prev.get("inputs", [])} == \
               {(i["path"], i["sha256"]) for i in self.inputs.values()}
        if same:
            self._carried = _intact(self.root, prev["outputs"])
        return same

    def carry(self, rels: list[str]) -> list[str]:
        """Keep these outputs of the previous record (those still intact) although this run does not
        rewrite them (``quadfdi train --seed 1`` keeps seed 0's prediction sets); return those kept.
        The caller decides that they still hold (same inputs, same config)."""
        want = set(rels)
        keep = [e for e in _intact(self.root, self.previous["outputs"]) if e["path"] in want] if self.previous else []
        self._carried = getattr(self, "_carried", []) + keep
        return [e["path"] for e in keep]

    def uncarry(self, rels: list[str]) -> None:
        """Do not keep these outputs of the previous record after all (they leave on publish)."""
        self._carried = [e for e in getattr(self, "_carried", []) if e["path"] not in set(rels)]

    def redo_previous(self, reads: tuple[str, ...]) -> None:
        """Rewrite some outputs of the previous record from its published ``reads`` (``quadfdi report``
        redraws the bench figures from bench.json): its inputs and config stay, and so do its other
        outputs that are still intact (a deleted figure is redrawn or drops out of the record)."""
        if self.previous is None:
            raise QuadfdiError(f"{self.root} has no published {self.name} stage to redo (.stages/{self.name}.json)")
        for rel in reads:
            self.consume(rel)
        self.inputs = {i["path"]: i for i in self.previous.get("inputs", [])}
        self.config = self.previous.get("config", {})
        self._carried = _intact(self.root, self.previous["outputs"])

    def _outputs(self) -> list[dict[str, Any]]:
        outs = {}
        for dirpath, _, files in os.walk(self.out):
            for name in files:
                p = Path(dirpath) / name
                rel = p.relative_to(self.out).as_posix()
                if rel != records.RECORD:
                    outs[rel] = {"path": rel, "sha256": records.sha256_file(p), "bytes": p.stat().st_size}
        for e in getattr(self, "_carried", []):
            outs.setdefault(e["path"], {k: e[k] for k in ("path", "sha256", "bytes")})
        return [outs[k] for k in sorted(outs)]

    def publish(self) -> None:
        outputs = self._outputs()
        for e in outputs:
            check_parents(self.root, e["path"])
            check_target(self.root / e["path"])
        rec = {"schema_version": records.SCHEMA_VERSION, "stage": self.name, "outputs": outputs,
               "inputs": [self.inputs[k] for k in sorted(self.inputs)], "config": self.config,
               "command": self.command,
               "published_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")}
        write_text(self.out / records.RECORD, dumps_json(rec))  # fsynced, like every output
        fault_point(self.name, "before-publish")
        pub = self.root / records.PUBLISH / self.name
        pub.parent.mkdir(exist_ok=True)
        os.rename(self.out, pub)  # the commit point
        records.roll_forward(self.root, self.name, fault=lambda p: fault_point(self.name, p))
        fault_point(self.name, "after-publish")


def _command() -> str:
    return "quadfdi " + " ".join(sys.argv[1:]) if sys.argv[1:] else "quadfdi (library call)"


@contextlib.contextmanager
def stage(root: str | os.PathLike, name: str, config: dict[str, dict], *, targets: tuple[str, ...] = (),
          need_bytes: int = 0) -> Iterator[StageWriter]:
    """Stage ``name``'s outputs and publish them as a unit on success (see the module docstring).

    ``targets``: output paths known in advance, checked (regular file or absent) before the
    compute, as is ``need_bytes`` of free space.
    """
    root = ensure_dir(root)
    with run_lock(root):
        records.recover(root)
        previous = records.previous_record(root, name)
        for rel in (*targets, *(e["path"] for e in (previous or {}).get("outputs", []))):
            check_parents(root, rel)  # before the compute: the stage writes where it wrote last time
        for rel in targets:
            check_target(root / rel)
        if need_bytes:
            check_free_space(root, need_bytes, f"quadfdi {name}")
        ensure_dir(root / records.STAGING)
        try:
            out = Path(tempfile.mkdtemp(prefix=f"{name}.", dir=root / records.STAGING))
        except OSError as exc:
            raise QuadfdiError(f"cannot create a staging folder in {root}: {exc.strerror}") from None
        writer = StageWriter(root, name, config, _command(), out)
        try:
            fault_point(name, "staged")
            yield writer
            writer.publish()
        finally:
            if out.exists():  # compute failed or interrupted before the commit point: old state stays
                shutil.rmtree(out, ignore_errors=True)


def recover_run(root: str | os.PathLike) -> list[str]:
    """Recover ``root`` under its lock (every command that opens a run calls this)."""
    with run_lock(root):
        return records.recover(root)
