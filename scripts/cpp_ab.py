"""Batch-1 wall time of several fwref_infer builds / settings, interleaved (docs/bench.md).

    PYTHONPATH=. python scripts/cpp_ab.py RUN --rounds N --case LABEL=EXE:MODEL:PRECISION[:KERNEL] ...

Each round runs one process per case, in the order given (so slow phases of the shared machine hit
every case alike); a process times 20 warm-up windows then the run's first 400 test windows (cycled
when the run has fewer), each once with ``--repeat 1`` as bench/timing/cpp.py times them, and
its p50 is the median of those 400. Printed per case: the median, min and max of the N processes'
p50s. MODEL is cnode or gru, PRECISION fp32 or int8, KERNEL (optional) sets FWREF_I8_KERNEL.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from quadfdi.formats.dataset import load_dataset, make_windows


def parse_case(text: str) -> tuple[str, str, str, str, str]:
    label, sep, rest = text.partition("=")
    parts = rest.split(":")
    if not sep or len(parts) not in (3, 4) or parts[1] not in ("cnode", "gru") or parts[2] not in ("fp32", "int8"):
        raise SystemExit(f"cpp_ab.py: error: bad --case {text!r} (LABEL=EXE:cnode|gru:fp32|int8[:KERNEL])")
    return label, parts[0], parts[1], parts[2], parts[3] if len(parts) == 4 else ""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--rounds", type=int, default=15)
    ap.add_argument("--case", action="append", required=True, type=parse_case)
    args = ap.parse_args()
    x = make_windows(load_dataset(args.run / "dataset.npz"), "test").x
    idx = np.r_[np.arange(20), np.arange(400)] % len(x)
    p50: dict[str, list[float]] = {c[0]: [] for c in args.case}
    with tempfile.TemporaryDirectory(prefix="quadfdi-ab-") as tmp:
        w, t = Path(tmp) / "w.f32", Path(tmp) / "t.f64"
        np.ascontiguousarray(x[idx], dtype="<f4").tofile(w)
        for _ in range(args.rounds):
            for label, exe, model, precision, kernel in args.case:
                cmd = [exe, "--weights", str(args.run / "export" / "weights.bin"), "--model", model,
                       *(["--int8"] if precision == "int8" else []), "--in", str(w), "--out", str(Path(tmp) / "o.f32"),
                       "--repeat", "1", "--timings", str(t)]
                subprocess.run(cmd, check=True, env=dict(os.environ, FWREF_I8_KERNEL=kernel))
                p50[label].append(float(np.median(np.fromfile(t, "<f8")[20:] * 1e6)))
    print(f"{len(x)} test windows, {args.rounds} processes per case, interleaved")
    for label, v in p50.items():
        q = np.sort(np.array(v))
        print(f"{label}: median p50 {np.median(q):.2f} us, min {q[0]:.2f}, max {q[-1]:.2f}")


if __name__ == "__main__":
    main()
