"""C++ int8 against fp32, both precisions of a model in one fwref_pair process, taking turns: the ratios
the "C++ int8 at least as fast as fp32" targets are judged on (bench.json ``cpp_pairs``).

The reason is bench/ort_pairs.py's: a process on the shared machines lands in one of two speed modes and
stays there, and the latency table's C++ figures pool separate processes per precision
(bench/timing/cpp.py), so their ratio moves with how many of each landed in which mode. In one process
the mode hits both precisions alike (docs/bench.md "One process is one sample", lab/cpp_process_spread.py).

firmware_ref's ``fwref_pair`` (tools/fwref_pair.cpp) runs every window through each precision once (a
warm-up pass), then ``PER_ROUND`` consecutive windows of the bench's seeded sample per precision and round
(after one untimed call), fp32 first in even rounds, int8 first in odd ones, and writes every call's time;
a round's time per precision is the median of its calls, the figure the median of the rounds' int8 / fp32
ratios (``bench.timing.common.pair_summary``). Batch 1 only
(fwref_infer's batch figure is consecutive single-window calls anyway). Skipped, with the reason, when the
build has no fwref_pair.
"""

from __future__ import annotations

import subprocess
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from quadfdi.bench.limits import cpu_prefix
from quadfdi.bench.timing.common import pair_summary
from quadfdi.core.errors import QuadfdiError

PER_ROUND = 4  # timed calls per precision and round
MODELS = ("cnode", "gru")


def measure_cpp_pairs(build_dir: Path, weights: Path, x: np.ndarray, n: int, cpus: str, timeout_s: float,
                      log: Callable[[str], None] = print) -> dict:
    """{model: [batch-1 summary]} from fwref_pair on the first ``n`` windows of ``x`` (at least one round),
    or {"skipped": why}."""
    exe = build_dir / "fwref_pair"
    if not exe.is_file():
        return {"skipped": f"{exe} is missing: build firmware_ref (python -m quadfdi.runtimes.build)"}
    rounds = max(1, min(n, len(x)) // PER_ROUND)
    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="quadfdi-pair-") as tmp:
        windows, timings = Path(tmp) / "windows.f32", Path(tmp) / "t.f64"
        idx = np.arange(rounds * PER_ROUND) % len(x)
        np.ascontiguousarray(x[idx], dtype="<f4").tofile(windows)
        for model in MODELS:
            cmd = [*cpu_prefix(cpus), str(exe), "--weights", str(weights), "--model", model, "--in", str(windows),
                   "--per-round", str(PER_ROUND), "--timings", str(timings)]
            t0 = time.perf_counter()
            try:
                res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
            except subprocess.TimeoutExpired:
                raise QuadfdiError(f"fwref_pair ({model}) did not finish within {timeout_s:.0f} s") from None
            if res.returncode != 0:
                last = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
                raise QuadfdiError(f"fwref_pair ({model}) failed: {last}")
            per_call = np.fromfile(timings, dtype="<f8").reshape(rounds, 2, PER_ROUND) * 1e6
            med = np.median(per_call, axis=2)
            got = {**pair_summary(med[:, 0].tolist(), med[:, 1].tolist(), 1), "calls_per_round": PER_ROUND}
            out[model] = [got]
            log(f"bench cpp pairs: {model}: int8 / fp32 time, median of {rounds} rounds "
                f"{got['int8_over_fp32_median']:.2f} [{time.perf_counter() - t0:.1f} s]")
    return out
