"""A sweep's unit of work and what runs where it lands: ``Job``, ``JobResult``, the canary, ``execute_job``.

The worker side of ``core.executor`` (shared by its in-process and Dask paths). ``canary()`` is a
fixed small numpy (and torch) computation hashed to 12 hex digits: two processes with the same hash
computed the same BLAS products and transcendental functions to the last bit, which is what the
promise "same bytes whatever the parallelism" rests on (one numpy/torch build, one CPU type).
"""

from __future__ import annotations

import functools
import hashlib
import os
import platform
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from quadfdi.core.errors import QuadfdiError
from quadfdi.core.jobcache import is_cached, write_result

ATTEMPTS = 3  # a job failing this many times becomes a failed row


@dataclass(frozen=True)
class Job:
    """One unit of a sweep. ``fn(*args)`` returns a dict of arrays (out: .npz) or a JSON-able value
    (out: .json); ``fn`` must be a module-level function so that workers import it by name."""

    kind: str
    key: str
    fn: Callable[..., Any]
    args: tuple
    out: Path
    label: str = ""
    torch: bool = False  # the job imports torch: the canary checks torch too


@dataclass
class JobResult:
    job: Job
    status: str  # 'ran' | 'cached' | 'failed'
    error: str | None = None
    seconds: float = 0.0  # timing: never part of a result file
    worker: str = ""
    info: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.status != "failed"


def one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    msg = text[0] if text else ""
    return msg if isinstance(exc, QuadfdiError) else f"{type(exc).__name__}: {msg}".rstrip(": ")


@functools.lru_cache(maxsize=2)
def canary(with_torch: bool = False) -> dict[str, Any]:
    """A fixed small computation's hash and the build that made it. Two processes with the same hash
    computed the same BLAS products and transcendental functions to the last bit."""
    import numpy as np

    rng = np.random.default_rng(20261201)
    a = rng.standard_normal((48, 48))
    m = a @ a.T + 48.0 * np.eye(48)
    parts = [np.linalg.solve(m, rng.standard_normal(48)), np.exp(np.sin(a)).sum(axis=0), np.tanh(a @ a).ravel(),
             np.log1p(np.abs(a)).cumsum()]
    info: dict[str, Any] = {"numpy": np.__version__, "torch": None}
    if with_torch:
        import torch

        g = torch.Generator().manual_seed(7)
        w = torch.randn(32, 32, generator=g, dtype=torch.float32)
        parts.append((torch.tanh(w @ w) @ torch.sigmoid(w)).numpy().astype(np.float64))
        info["torch"] = torch.__version__
    h = hashlib.sha256(b"".join(p.tobytes() for p in parts)).hexdigest()[:12]
    return {"canary": h, **info, "python": platform.python_version(), "machine": platform.machine(),
            "cpu": _cpu_model(), "host": socket.gethostname()}


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def describe(name: str, info: dict) -> str:
    torch = f", torch {info['torch']}" if info.get("torch") else ""
    return f"{name} canary {info['canary']} (numpy {info['numpy']}{torch}, {info['machine']} {info['cpu']})"


def check_canaries(infos: dict[str, dict]) -> str:
    """The one canary every worker shares, or a one-line error naming who differs from whom."""
    groups: dict[str, list[str]] = {}
    for name, info in sorted(infos.items()):
        groups.setdefault(info["canary"], []).append(name)
    if len(groups) <= 1:
        return next(iter(groups), "")
    parts = [describe(f"{len(names)} worker(s) {', '.join(names)}:", infos[names[0]]) for names in groups.values()]
    raise QuadfdiError("mixed cluster: the workers compute different bits, results would not be reproducible; "
                       "install one numpy/torch build on one CPU type per cluster. " + "; ".join(parts))


def execute_job(fn: Callable[..., Any], args: tuple, out: str, with_torch: bool = False) -> dict:
    """Run one job where it lands (a worker, or this process) and write its result file atomically.

    A result already there (another attempt of the same job finished first) is not recomputed; a
    job that does run writes the same bytes under the same name, so a duplicate is harmless."""
    t0 = time.perf_counter()
    if not is_cached(out):
        write_result(out, fn(*args))
    return {"seconds": time.perf_counter() - t0, "canary": canary(with_torch)["canary"],
            "worker": f"{socket.gethostname()}:{os.getpid()}"}
