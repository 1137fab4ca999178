"""Batch-1 p50 of several fwref_infer builds, each timed by the bench's own C++ worker, interleaved.

    PYTHONPATH=. python scripts/cpp_bench_ab.py RUN --rounds N --case LABEL=EXE:MODEL:PRECISION[:ENV=VALUE] ...

Each round runs, per case in the order given, ``taskset -c CPUS python -m quadfdi.bench.latency_worker --runtime
cpp`` as `quadfdi bench` does (bench/timing/cpp.py: CPP_PROCESSES processes per setting, their
per-window times pooled; the windows: bench.latency.sample_windows of the test split, the bench's
count and warm-up), so a slow phase of the shared machine hits every case alike. Printed per case: the
median, min and max over the rounds of the worker's p50 (the bench's figure). The optional ENV=VALUE
sets one environment variable for that case (e.g. FWREF_F32_KERNEL=avx2). Bad input: one line, exit 2.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from quadfdi.bench.latency import sample_windows
from quadfdi.formats.dataset import load_dataset, make_windows


def parse_case(text: str) -> tuple[str, str, str, str, dict]:
    label, sep, rest = text.partition("=")
    parts = rest.split(":")
    if not sep or len(parts) not in (3, 4) or parts[1] not in ("cnode", "gru") or parts[2] not in ("fp32", "int8"):
        raise argparse.ArgumentTypeError(f"bad --case {text!r} (LABEL=EXE:cnode|gru:fp32|int8[:ENV=VALUE])")
    env = dict([parts[3].split("=", 1)]) if len(parts) == 4 and "=" in parts[3] else {}
    if len(parts) == 4 and not env:
        raise argparse.ArgumentTypeError(f"bad --case {text!r}: the 4th field must be ENV=VALUE")
    return label, parts[0], parts[1], parts[2], env


def worker_p50(windows: Path, weights: Path, case: tuple, cpus: str, n: int) -> float:
    _, exe, model, precision, env = case
    cmd = ["taskset", "-c", cpus, sys.executable, "-m", "quadfdi.bench.latency_worker", "--runtime", "cpp", "--model", model,
           "--precision", precision, "--solver", "rk4-8" if model == "cnode" else "gru", "--windows", str(windows),
           "--artifact", str(weights), "--fwref", exe, "--n", str(n)]
    res = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, **env), check=False)
    if res.returncode != 0:
        raise SystemExit(f"cpp_bench_ab.py: error: {' '.join(cmd)}: {res.stderr.strip().splitlines()[-1:]}")
    recs = json.loads(res.stdout.strip().splitlines()[-1])["records"]
    return float(next(r["p50_us"] for r in recs if r["batch"] == 1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--cpus", default="0,1", help="taskset CPU list, as bench.cpus (default: %(default)s)")
    ap.add_argument("--n", type=int, default=300, help="batch-1 windows per process (default: %(default)s)")
    ap.add_argument("--case", action="append", required=True, type=parse_case)
    args = ap.parse_args()
    weights = args.run / "export" / "weights.bin"
    for exe in {c[1] for c in args.case}:
        if not Path(exe).is_file():
            ap.error(f"{exe} does not exist")
    if not weights.is_file():
        ap.error(f"{weights} does not exist")
    x = sample_windows(make_windows(load_dataset(args.run / "dataset.npz"), "test").x, args.n)
    p50: dict[str, list[float]] = {c[0]: [] for c in args.case}
    with tempfile.TemporaryDirectory(prefix="quadfdi-benchab-") as tmp:
        windows = Path(tmp) / "windows.npy"
        np.save(windows, x)
        for _ in range(args.rounds):
            for case in args.case:
                p50[case[0]].append(worker_p50(windows, weights, case, args.cpus, args.n))
    print(f"{len(x)} windows, {args.rounds} rounds, bench.latency_worker (cpp) per case per round, interleaved")
    for label, v in p50.items():
        q = np.sort(np.array(v))
        print(f"{label}: median p50 {np.median(q):.2f} us, min {q[0]:.2f}, max {q[-1]:.2f}")


if __name__ == "__main__":
    main()
