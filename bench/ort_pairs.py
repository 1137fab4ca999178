"""ONNX Runtime int8 against fp32, both graphs of a model in one process, calls interleaved: the
ratios the ONNX Runtime int8 targets are judged on (bench.json ``ort_pairs``).

Why not the latency table's p50s: on the shared machines a process lands in one of two speed modes
and stays there (docs/bench.md "One process is one sample"); the slow mode takes about 2.2x as long
for every graph in that process. The latency workers time fp32 and int8 in separate processes, so
one of the two can land in the slow mode and the ratio of their p50s is off by that factor, while in
one process both graphs are slow or fast together and their ratio holds (lab/ort_process_modes.py). Here the two sessions share the process and take turns round by round (fp32
first in even rounds, int8 first in odd ones), so a mode or a burst of load hits both: each round's
ratio compares times a few milliseconds apart, and the figure is the median of the rounds' ratios.

The setting is the targets' like-for-like one: one intra-op thread, spinning off. In a round each
graph gets one untimed call and then ``PER_ROUND_1`` (batch 1) or ``PER_ROUND_N`` (batch
``counts.batch``) timed calls, the round's time their median, so that each graph is timed on its own
cache state (on the paper export, 1, 4, 16 and 64 calls per round give median ratios within 4 % of
each other: lab/ort_process_modes.py --per-round-sweep, docs/bench.md). Batch 1: ``counts.n / PER_ROUND_1``
rounds over the bench's seeded sample of windows (cycled); batch ``counts.batch``: ``PAIR_BATCH_ROUNDS`` rounds (at least ``counts.batches``;
``--quick`` keeps ``counts.batches``) of consecutive windows. Each loop also stops at twice
``counts.budget_s`` (two graphs), never below ``counts.min_samples`` rounds.

``python -m quadfdi.bench.ort_pairs --fp32 A.onnx --int8 B.onnx --windows W.npy ...`` is the worker; it
prints one JSON line. ``measure_ort_pairs`` runs one worker per model under taskset.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

from quadfdi.bench.limits import cpu_prefix, run_json, worker_env
from quadfdi.bench.timing.common import batches_of, pair_summary, percentile

PAIR_BATCH_ROUNDS = 30  # batch-96 rounds: the latency table's 10 batches are few for a median of ratios
PER_ROUND_1 = 4  # timed batch-1 calls per graph and round (the bench's n windows make n / 4 rounds)
PER_ROUND_N = 2  # timed batch-96 calls per graph and round
MODELS = ("cnode", "gru")


def paired_times(calls: tuple[Callable, Callable], inputs: list, rounds: int, per_round: int, warmup: int,
                 budget_s: float, min_samples: int) -> tuple[list[float], list[float]]:
    """Microseconds of (first, second) graph per round, the order alternating round by round.

    In a round each graph runs one untimed call (its weights and buffers back in cache after the other
    graph's turn) and then ``per_round`` timed calls on consecutive inputs; the round's time is their
    median.
    """
    for i in range(max(1, warmup)):
        for call in calls:
            call(inputs[i % len(inputs)])
    times: tuple[list[float], list[float]] = ([], [])
    t_end = time.perf_counter() + budget_s
    i = 0
    for r in range(rounds):
        for k in ((0, 1) if r % 2 == 0 else (1, 0)):
            calls[k](inputs[(i + per_round) % len(inputs)])
            got = []
            for j in range(per_round):
                x = inputs[(i + j) % len(inputs)]
                t0 = time.perf_counter_ns()
                calls[k](x)
                got.append((time.perf_counter_ns() - t0) / 1e3)
            times[k].append(percentile(got, 50))
        i += per_round
        if r + 1 >= min_samples and time.perf_counter() > t_end:
            break
    return times


def worker_main(argv: list[str] | None = None) -> int:
    import numpy as np

    from quadfdi.runtimes.ort import session

    ap = argparse.ArgumentParser(prog="python -m quadfdi.bench.ort_pairs")
    ap.add_argument("--fp32", required=True)
    ap.add_argument("--int8", required=True)
    ap.add_argument("--windows", required=True)
    for name in ("n", "warmup", "batch", "batch-rounds", "min-samples"):
        ap.add_argument(f"--{name}", type=int, required=True)
    ap.add_argument("--budget-s", type=float, required=True)
    a = ap.parse_args(argv)
    x = np.load(a.windows)
    sessions = [session(p, 1, spinning=False) for p in (a.fp32, a.int8)]
    names = [s.get_inputs()[0].name for s in sessions]
    calls = tuple((lambda v, s=s, n=n: s.run(None, {n: v})) for s, n in zip(sessions, names))
    singles = [np.ascontiguousarray(x[i:i + 1]) for i in range(len(x))]
    batches = batches_of(x, a.batch, min(a.batch_rounds, 10))
    out = []
    plans = ((singles, max(1, a.n // PER_ROUND_1), PER_ROUND_1, 1, a.warmup),
             (batches, a.batch_rounds, PER_ROUND_N, a.batch, 1))
    for inputs, rounds, per_round, batch, warmup in plans:
        f32, i8 = paired_times(calls, inputs, rounds, per_round, warmup, 2 * a.budget_s, a.min_samples)
        out.append({**pair_summary(f32, i8, batch), "calls_per_round": per_round})
    print(json.dumps({"pairs": out}))
    return 0


def measure_ort_pairs(export: Path, manifest: dict, windows: Path, counts, cpus: str, timeout_s: float,
                      quick: bool, log: Callable[[str], None] = print) -> dict:
    """{model: [batch-1 summary, batch-N summary]} for every model with both ONNX graphs exported."""
    rounds = counts.batches if quick else max(counts.batches, PAIR_BATCH_ROUNDS)
    out = {}
    for model in MODELS:
        arts = [manifest["artifacts"].get(f"{model}_{p}") for p in ("fp32", "int8")]
        if not all(arts):
            continue
        cmd = [*cpu_prefix(cpus), sys.executable, "-m", "quadfdi.bench.ort_pairs", "--fp32", str(export / arts[0]),
               "--int8", str(export / arts[1]), "--windows", str(windows), "--n", str(counts.n),
               "--warmup", str(counts.warmup), "--batch", str(counts.batch), "--batch-rounds", str(rounds),
               "--min-samples", str(counts.min_samples), "--budget-s", str(counts.budget_s)]
        t0 = time.perf_counter()
        got = run_json(cmd, worker_env(1), f"ORT int8/fp32 pair worker ({model})", timeout_s)["pairs"]
        out[model] = got
        log(f"bench ort pairs: {model}: int8 / fp32 time, median of rounds: "
            + ", ".join(f"batch {p['batch']} {p['int8_over_fp32_median']:.2f} ({p['rounds']} rounds)" for p in got)
            + f" [{time.perf_counter() - t0:.1f} s]")
    return out


if __name__ == "__main__":
    sys.exit(worker_main())
