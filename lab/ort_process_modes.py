"""Does a process's speed mode hit both ONNX Runtime graphs of a model alike? (bench/ort_pairs.py)

    python lab/ort_process_modes.py RUN [--model cnode] [--processes 8]

Starts ``--processes`` fresh processes one after another, each pinned to CPUs 0,1 (taskset), each
timing the model's fp32 and int8 graphs of RUN/export at batch 1 (1 thread, spinning off), calls
taking turns (400 rounds, the first 50 dropped); prints each process's medians and their ratio. On
the shared 2-core machines some processes run every graph about 2.2x slower than others; if the
ratio stays put while the times move, interleaving within one process (what the bench's targets use)
cancels the mode and separate processes per graph (the latency table) do not.

``--per-round-sweep`` instead runs, in this one process, bench.ort_pairs.paired_times with 1, 4, 16
and 64 timed calls per graph and round (each after one untimed call) and prints the medians, also
split by which graph went first in the round: whether the two graphs evict each other's caches
enough to change the ratio, and whether the turn order biases it.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

CHILD = """
import sys, time, numpy as np
from quadfdi.runtimes.ort import session
paths = sys.argv[1:3]
x = np.random.default_rng(0).standard_normal((1, 80, 23)).astype(np.float32)
s = [session(p, 1, spinning=False) for p in paths]
n = [q.get_inputs()[0].name for q in s]
t = [[], []]
for r in range(400):
    for k in ((0, 1) if r % 2 == 0 else (1, 0)):
        a = time.perf_counter_ns(); s[k].run(None, {n[k]: x}); t[k].append(time.perf_counter_ns() - a)
print(float(np.median(t[0][50:])) / 1e3, float(np.median(t[1][50:])) / 1e3)
"""


def per_round_sweep(paths: list[str]) -> int:
    import numpy as np

    from quadfdi.bench.ort_pairs import paired_times
    from quadfdi.bench.timing.common import percentile
    from quadfdi.runtimes.ort import session

    x = np.random.default_rng(0).standard_normal((300, 1, 80, 23)).astype(np.float32)
    sessions = [session(p, 1, spinning=False) for p in paths]
    names = [q.get_inputs()[0].name for q in sessions]
    calls = tuple((lambda v, q=q, n=n: q.run(None, {n: v})) for q, n in zip(sessions, names))
    for per_round in (1, 4, 16, 64):
        f32, i8 = paired_times(calls, list(x), max(2, 320 // per_round), per_round, 30, 10.0, 2)
        ratios = [b / a for a, b in zip(f32, i8)]
        print(f"{per_round} calls per round: fp32 {percentile(f32, 50):.1f} us, int8 {percentile(i8, 50):.1f} us, "
              f"int8 / fp32 median {percentile(ratios, 50):.3f} (fp32-first rounds {percentile(ratios[0::2], 50):.3f}, "
              f"int8-first {percentile(ratios[1::2], 50):.3f})")
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("run", type=Path)
    ap.add_argument("--model", default="cnode", choices=("cnode", "gru"))
    ap.add_argument("--processes", type=int, default=8)
    ap.add_argument("--per-round-sweep", action="store_true")
    a = ap.parse_args()
    arts = json.loads((a.run / "export" / "manifest.json").read_text())["artifacts"]
    paths = [str(a.run / "export" / arts[f"{a.model}_{p}"]) for p in ("fp32", "int8")]
    if a.per_round_sweep:
        return per_round_sweep(paths)
    for i in range(a.processes):
        out = subprocess.run(["taskset", "-c", "0,1", sys.executable, "-c", CHILD, *paths], capture_output=True,
                             text=True, check=True).stdout.split()
        f32, i8 = float(out[0]), float(out[1])
        print(f"process {i + 1}: fp32 {f32:.1f} us, int8 {i8:.1f} us, int8 / fp32 {i8 / f32:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
