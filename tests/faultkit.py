"""Helpers of the fault-injection suite (tests/test_faults*.py): run the CLI with a fault, take a
snapshot of a run folder's published state, and check that it is the old or the new one."""

from __future__ import annotations

import hashlib
import json
import re
import os
import resource
import signal
import shutil
import subprocess
import sys
from pathlib import Path

from tests.conftest import ROOT

# Not published state: the lock, staging areas, and the executor's job cache (core.jobcache: results
# keyed by their inputs, reused across runs; a shard there is never read as an output of a stage).
HIDDEN = (".lock", ".staging", ".publish", "cache")
# Visible files no stage record lists, by design: the prediction index, which several stages (train,
# the study, the baselines) add entries to after their publish (formats.predictions). It is snapshotted
# like any file; only the "every file belongs to a record" check leaves it out.
UNRECORDED = ("predictions/index.json",)
TINY_SIM = ["--set", "sim.n_traj=4", "--set", "sim.duration_s=8.0", "--set", "sim.onset_frac=[0.1, 0.3]",
            "--set", "sim.ramp_frac=[0.2, 0.4]"]


def sim_cmd(out: Path, seed: int) -> list[str]:
    return ["sim", "--config", str(ROOT / "configs/paper.toml"), "--out", str(out), *TINY_SIM, "--set", f"sim.seed={seed}"]


def cli(*args: str, fault: str | None = None, fsize: int | None = None, env: dict | None = None,
        wait: bool = True) -> subprocess.CompletedProcess | subprocess.Popen:
    """``quadfdi ARGS`` in a subprocess; ``fault`` sets QUADFDI_FAULT_POINT, ``fsize`` caps the file
    size (RLIMIT_FSIZE, standing in for a full disk)."""
    full_env = dict(os.environ, QUADFDI_LOCK_WAIT_S="0.5", **(env or {}))
    full_env.pop("QUADFDI_FAULT_POINT", None)
    if fault:
        full_env["QUADFDI_FAULT_POINT"] = fault

    def limit() -> None:
        sigint_as_in_a_terminal()  # else the fault point's SIGINT could be lost
        if fsize is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    cmd = [sys.executable, "-m", "quadfdi.cli", *args]
    if not wait:
        return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                                env=full_env, preexec_fn=limit)
    return subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, env=full_env, preexec_fn=limit,
                          timeout=900)


def sigint_as_in_a_terminal() -> None:
    """A subprocess's ``preexec_fn``: SIGINT handled by default and not blocked, as in a terminal. Both the
    disposition and the signal mask survive exec: a test process that ignores or blocks SIGINT (a shell's
    background job without job control ignores it all the way down) makes a child Python that never raises
    KeyboardInterrupt, and a test of an interrupt would see the command finish instead."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def snapshot(root: Path) -> dict[str, str]:
    """Published state: every visible file's sha256, and each record's outputs and inputs (its
    time and command vary between equal runs, so they are left out)."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root).as_posix()
        if rel.split("/")[0] in HIDDEN or not p.is_file():
            continue
        if rel.startswith(".stages/"):
            try:
                rec = json.loads(p.read_text())
                out[rel] = json.dumps([rec["outputs"], rec["inputs"]], sort_keys=True)
            except (ValueError, KeyError, TypeError):  # a corrupt record, as a test case makes it
                out[rel] = sha(p)
        else:
            out[rel] = sha(p)
    return out


PROGRESS = re.compile(r"\d+/\d+ \[\d\d:\d\d")


def one_line_error(res: subprocess.CompletedProcess) -> None:
    """Non-zero exit, exactly one line on stderr, no traceback."""
    # tqdm progress lines ("sim: 100%|...| 4/4 [00:01<00:00, 3.1traj/s]") are not messages
    lines = [ln for ln in res.stderr.splitlines() if ln.strip() and not PROGRESS.search(ln)]
    assert res.returncode != 0, res.stdout[-500:]
    assert "Traceback" not in res.stderr, res.stderr[-3000:]
    assert len(lines) == 1, res.stderr[-3000:]


def assert_published(root: Path, *states: dict[str, str]) -> dict[str, str]:
    """Let the next command recover ``root`` (``quadfdi check``, which also verifies every record);
    then nothing may be left in .staging/.publish, every visible file must belong to a record, and
    the state must be one of ``states`` when given."""
    res = cli("check", "--run", str(root))
    assert res.returncode == 0 and "Traceback" not in res.stderr, res.stderr[-3000:]
    for d in (".staging", ".publish"):
        assert not any((root / d).iterdir()) if (root / d).is_dir() else True, d
    assert not list(root.rglob(".*.tmp"))
    snap = snapshot(root)
    listed = set()
    for rel, text in snap.items():
        if rel.startswith(".stages/"):
            listed |= {e["path"] for e in json.loads(text)[0]}
    stray = {rel for rel in snap if not rel.startswith(".stages/")} - listed - set(UNRECORDED)
    assert not stray, f"files no record lists: {sorted(stray)}"
    if states:
        assert snap in states, "run folder is neither the old nor the new published state"
    return snap


def copy_run(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns(".lock"))
    return dst
