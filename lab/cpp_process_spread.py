"""The spread of the C++ reference's batch-1 p50 from one process to the next (docs/bench.md,
"One process is one sample").

    python lab/cpp_process_spread.py RUN [N] [--exe FWREF_INFER]

Runs fwref_infer (default: the host build of ``quadfdi.runtimes.build.build_host``, built if missing)
N times (default 15) per model and precision on the same windows (20 warm-up, then the run's first
400 test windows, each timed once with ``--repeat 1`` as bench/timing/cpp.py times them) and prints
the median, min, max and every process's p50.
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from quadfdi.formats.dataset import load_dataset, make_windows
from quadfdi.runtimes.build import build_host


def main() -> None:
    ap = argparse.ArgumentParser(description="fwref_infer's batch-1 p50, process after process")
    ap.add_argument("run", type=Path)
    ap.add_argument("n", type=int, nargs="?", default=15)
    ap.add_argument("--exe", type=Path, default=None, help="fwref_infer (default: the host build, built if missing)")
    a = ap.parse_args()
    run, n = a.run, a.n
    exe = a.exe or build_host(log=lambda _: None) / "fwref_infer"
    x = make_windows(load_dataset(run / "dataset.npz"), "test").x
    idx = np.r_[np.arange(20), np.arange(400)] % len(x)
    with tempfile.TemporaryDirectory(prefix="quadfdi-spread-") as tmp:
        w, t = Path(tmp) / "w.f32", Path(tmp) / "t.f64"
        np.ascontiguousarray(x[idx], dtype="<f4").tofile(w)
        for model, extra in (("cnode", []), ("cnode", ["--int8"]), ("gru", []), ("gru", ["--int8"])):
            p = []
            for _ in range(n):
                subprocess.run([str(exe), "--weights", str(run / "export" / "weights.bin"), "--model", model, *extra,
                                "--in", str(w), "--out", str(Path(tmp) / "o.f32"), "--repeat", "1",
                                "--timings", str(t)], check=True)
                p.append(float(np.median(np.fromfile(t, "<f8")[20:] * 1e6)))
            q = np.sort(np.array(p))
            print(f"{model} {'int8' if extra else 'fp32'}: {n} processes, median p50 {np.median(q):.2f} us, "
                  f"min {q[0]:.2f}, max {q[-1]:.2f}: " + " ".join(f"{v:.1f}" for v in q))


if __name__ == "__main__":
    main()
