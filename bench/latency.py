"""Per-runtime latency: one fresh pinned process per setting (``bench.latency_worker``), in turn.

The settings (``plan``), SPEC section 6:

- torch: CNODE with fixed classic RK4 at the export's N (``rk4-N``) and adaptive dopri5 at
  train.rtol with the path's knots as ``jump_t`` (``dopri5-1e-3``); GRU. 1 and 2 intra-op threads.
- ort: the four files of the export manifest's ``artifacts`` (CNODE and GRU, fp32 and int8);
  1 and 2 intra-op threads, each with thread spinning on and off
  (``session.intra_op.allow_spinning``).
- cpp: firmware_ref's ``fwref_infer`` on the export's weights.bin, CNODE and GRU, fp32 and int8;
  single-threaded by design (threads 1, spinning n/a).

Every worker runs under ``taskset -c <cpus>`` (default 0,1) with its thread pools sized by
environment before any library loads, after warm-up, on the same sample of test windows (seeded;
cycled when the split is smaller). ``--quick`` keeps every runtime, model and precision but only
1 thread and spinning off, and few windows.

Workers run one after another, never side by side, so they do not compete for the two cores
(other users of the machine still can: compare within one run, quote medians).
"""

from __future__ import annotations

import math
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from quadfdi.bench.limits import cpu_prefix, run_json, worker_env
from quadfdi.bench.ort_pairs import measure_ort_pairs
from quadfdi.bench.config import BenchConfig
from quadfdi.core.errors import QuadfdiError

BENCH_PROGRAMS = ("fwref_infer", "fwref_pair")  # the C++ programs the latency tables time


@dataclass(frozen=True)
class Counts:
    """How much each worker measures: the [bench] config section, or tiny counts for ``--quick``."""

    n: int  # batch-1 windows, each timed once
    warmup: int
    warmup_s: float
    batches: int  # batched calls timed
    batch: int
    budget_s: float  # per timed loop; dopri5 is the one that hits it
    min_samples: int  # the budget never cuts a loop below this

    @staticmethod
    def of(bench: BenchConfig, quick: bool) -> "Counts":
        if quick:
            return Counts(n=20, warmup=3, warmup_s=bench.warmup_s, batches=2, batch=bench.batch, budget_s=0.5,
                          min_samples=2)
        return Counts(n=bench.windows, warmup=bench.warmup, warmup_s=bench.warmup_s, batches=bench.batches,
                      batch=bench.batch, budget_s=bench.budget_s, min_samples=bench.min_samples)


@dataclass(frozen=True)
class Spec:
    runtime: str
    model: str
    precision: str
    solver: str
    threads: int
    spinning: str  # on | off | na
    artifact: str
    extra: tuple[str, ...] = field(default=())

    @property
    def label(self) -> str:
        spin = "" if self.spinning == "na" else f", spinning {self.spinning}"
        return f"{self.runtime} {self.model} {self.precision} {self.solver} ({self.threads} thread(s){spin})"


def rtol_label(rtol: float) -> str:
    """1e-3 -> '1e-3', 5e-4 -> '5e-4', 0.0125 -> '0.0125' (for solver labels such as dopri5-1e-3)."""
    exp = math.floor(math.log10(rtol))
    mant = rtol / 10 ** exp
    if abs(mant - round(mant)) < 1e-9:
        return f"{int(round(mant))}e{exp}"
    return f"{rtol:g}"


def plan(run_root: Path, manifest: dict, rtol: float, quick: bool, fwref: str | None,
         threads: tuple[int, ...] | None = None) -> list[Spec]:
    """Every setting to measure, in order (torch, then ort, then cpp); ``threads``: the intra-op
    thread counts (default: [bench] threads, or 1 alone with ``quick``)."""
    export = run_root / "export"
    steps = int(manifest["solver"]["steps"])
    threads = threads or ((1,) if quick else BenchConfig().threads)
    spins = ("off",) if quick else ("off", "on")
    rk4, dopri = f"rk4-{steps}", f"dopri5-{rtol_label(rtol)}"
    specs = []
    for t in threads:
        specs += [Spec("torch", "cnode", "fp32", rk4, t, "na", str(run_root / "cnode.pt")),
                  Spec("torch", "cnode", "fp32", dopri, t, "na", str(run_root / "cnode.pt")),
                  Spec("torch", "gru", "fp32", "gru", t, "na", str(run_root / "gru.pt"))]
    for model in ("cnode", "gru"):
        for precision in ("fp32", "int8"):
            art = str(export / manifest["artifacts"][f"{model}_{precision}"])
            for t in threads:
                for spin in spins:
                    specs.append(Spec("ort", model, precision, rk4 if model == "cnode" else "gru", t, spin, art))
    if fwref:
        for model in ("cnode", "gru"):
            for precision in ("fp32", "int8"):
                specs.append(Spec("cpp", model, precision, rk4 if model == "cnode" else "gru", 1, "na",
                                  str(export / "weights.bin"), ("--fwref", fwref)))
    return specs


def sample_windows(x: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """``n`` windows of x in a seeded random order (cycling through a permutation when n > len(x))."""
    if len(x) == 0:
        raise QuadfdiError("the test split holds no windows to time")
    rng = np.random.default_rng(seed)
    reps = -(-n // len(x))
    idx = np.concatenate([rng.permutation(len(x)) for _ in range(reps)])[:n]
    return np.ascontiguousarray(x[idx], dtype=np.float32)


def find_fwref(explicit: str | None, log: Callable[[str], None]) -> tuple[str | None, str]:
    """(path to fwref_infer or None, how it was found or why not).

    An explicit ``--fwref`` must exist. Otherwise fwref_infer and fwref_pair are built (or found up to
    date) in the per-user build cache (runtimes.build: ``python -m quadfdi.runtimes.build`` prints it);
    without cmake or a compiler, or when the build fails, the C++ rows are skipped with the reason.
    """
    if explicit:
        p = Path(explicit)
        if not p.is_file() or not os.access(p, os.X_OK):
            raise QuadfdiError(f"--fwref {p}: no such executable (leave --fwref out to build firmware_ref in the "
                               "per-user cache, or print that build's folder: python -m quadfdi.runtimes.build)")
        return str(p), "given with --fwref"
    from quadfdi.runtimes.build import build_host

    missing = [t for t in ("cmake", "c++") if shutil.which(t) is None]
    if missing:
        return None, f"C++ reference not measured: {' and '.join(missing)} not found (they build firmware_ref)"
    log("bench: building the C++ reference in the per-user cache (CMake, Release) unless it is up to date")
    try:
        build = build_host(targets=BENCH_PROGRAMS, log=lambda _: None)
    except QuadfdiError as exc:
        return None, f"C++ reference not measured: building it failed: {exc}"
    return str(build / "fwref_infer"), f"{build / 'fwref_infer'} (per-user build cache)"


def check_cpus(cpus: str) -> str:
    """``cpus`` ('0,1') if this process may run on all of them, else a one-line error."""
    try:
        wanted = {int(c) for c in cpus.split(",") if c.strip()}
    except ValueError:
        raise QuadfdiError(f"--cpus must be a comma-separated list of CPU numbers, found {cpus!r}") from None
    allowed = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else wanted
    if not wanted or not wanted <= allowed:
        raise QuadfdiError(f"--cpus {cpus}: this process may only run on CPUs {sorted(allowed)}")
    return ",".join(str(c) for c in sorted(wanted))


def worker_cmd(spec: Spec, windows: Path, counts: Counts, cpus: str, time_exe: str | None) -> list[str]:
    cmd = [*cpu_prefix(cpus), sys.executable, "-m", "quadfdi.bench.latency_worker", "--runtime", spec.runtime,
           "--model", spec.model, "--precision", spec.precision, "--solver", spec.solver,
           "--threads", str(spec.threads), "--spinning", spec.spinning, "--windows", str(windows),
           "--artifact", spec.artifact, "--n", str(counts.n), "--warmup", str(counts.warmup),
           "--batch", str(counts.batch), "--batches", str(counts.batches), "--budget-s", str(counts.budget_s),
           "--min-samples", str(counts.min_samples), "--warmup-s", str(counts.warmup_s), "--cpus", cpus, *spec.extra]
    if spec.runtime == "cpp" and time_exe:
        cmd += ["--time-exe", time_exe]
    return cmd


def measure_latency(run_root: Path, manifest: dict, test_x: np.ndarray, rtol: float, bench: BenchConfig, *,
                    cpus: str = BenchConfig.cpus, quick: bool = False, fwref: str | None = None,
                    log: Callable[[str], None] = print) -> dict:
    """Run every worker of ``plan``; return {latency, ort_pairs, runtime_memory, workers, windows, ...}.

    ``fwref`` is the fwref_infer path (None: the C++ reference is skipped, with the reason in
    ``skipped``). A worker that fails raises a one-line QuadfdiError naming its setting.
    """
    cpus = check_cpus(cpus)
    counts = Counts.of(bench, quick)
    time_exe = "/usr/bin/time" if Path("/usr/bin/time").is_file() else None  # GNU time, for the C++ peak RSS
    specs = plan(run_root, manifest, rtol, quick, fwref, (1,) if quick else bench.threads)
    records, memory, workers = [], [], []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="quadfdi-bench-") as tmp:
        windows = Path(tmp) / "windows.npy"
        np.save(windows, sample_windows(test_x, max(counts.n, counts.batch)))
        for spec in specs:
            t0 = time.perf_counter()
            out = run_json(worker_cmd(spec, windows, counts, cpus, time_exe), worker_env(spec.threads),
                           f"latency worker {spec.label}", bench.worker_timeout_s)
            dt = time.perf_counter() - t0
            records += out["records"]
            memory.append(out["memory"])
            workers.append({"setting": spec.label, "seconds": dt, "info": out.get("info", {})})
            b1, bn = out["records"]
            log(f"bench latency: {spec.label}: batch 1 p50 {b1['p50_us']:.1f} us (p99 {b1['p99_us']:.1f}, "
                f"{b1['n_calls']} windows), batch {bn['batch']} {bn['throughput_wps']:.0f} windows/s [{dt:.1f} s]")
        # the ONNX Runtime int8/fp32 ratios: both graphs in one process (bench/ort_pairs.py says why)
        pairs = measure_ort_pairs(run_root / "export", manifest, windows, counts, cpus, bench.worker_timeout_s, quick,
                                  log)
    return {"latency": records, "ort_pairs": pairs, "runtime_memory": memory, "workers": workers,
            "windows": {"split": "test", "available": int(len(test_x)), "sampled": max(counts.n, counts.batch),
                        "seed": 0, "cycled": bool(len(test_x) < max(counts.n, counts.batch))},
            "counts": counts.__dict__, "cpus": cpus, "seconds": time.perf_counter() - t_all}
