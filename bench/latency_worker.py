"""One latency measurement in a fresh process: ``python -m quadfdi.bench.latency_worker ...`` prints JSON.

``bench.latency`` starts one worker per (runtime, model, precision, solver, threads, spinning),
pinned to the benchmark cores with taskset, so that no runtime inherits another's thread pools,
allocator state, caches or imported libraries. A worker:

1. loads the windows (``--windows``, a .npy of (n, W, C) float32 test windows) and imports its
   runtime, then records its resident memory: the **baseline** (VmRSS);
2. resets the kernel's peak-RSS mark (``/proc/self/clear_refs`` 5) and loads the model;
3. batch 1: warms up (``--warmup`` calls, at most ~1 s), then times each window once
   (``time.perf_counter_ns`` around the call) for ``--n`` windows or until ``--budget-s``;
   reads the peak RSS (VmHWM);
4. batch 96: warms up on one batch, then times whole batches (``--batches``, same budget);
   reads the peak RSS again;
5. prints ``{"records": [batch-1 record, batch-96 record], "memory": {...}, "info": {...}}``.

Runtimes, one adapter module each (imported only by the worker that times it, so that no
runtime's library is in another's memory baseline): ``bench.timing.pytorch`` (the checkpoint,
CNODE with fixed classic RK4 ``rk4-N`` or adaptive ``dopri5-RTOL``), ``bench.timing.ort`` (an
exported ONNX file), ``bench.timing.cpp`` (firmware_ref's ``fwref_infer``, its own process);
``bench.timing.common`` holds the statistics and timing loops.

``--profile <path.json>`` (ort only): instead of timing, run the batch-1 loop with ONNX Runtime's
per-node profiler on and write the per-operator-type summary to ``path.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from quadfdi.bench.timing.common import MIN_SAMPLES, WARMUP_SECONDS, batches_of, peak_rss_kib, proc_status_kib, \
    reset_peak_rss, summarise, time_calls
from quadfdi.bench.timing.pytorch import parse_solver
from quadfdi.bench.config import BenchConfig

RUNTIMES = ("torch", "ort", "cpp")


def base_record(args) -> dict:
    return {"model": args.model, "runtime": args.runtime, "precision": args.precision, "solver": args.solver,
            "threads": args.threads, "spinning": None if args.spinning == "na" else args.spinning == "on"}


def measure(args) -> dict:
    import numpy as np

    x = np.load(args.windows)
    if x.ndim != 3 or x.dtype != np.float32:
        raise ValueError(f"{args.windows} must hold (n, W, C) float32 windows, found {x.shape} {x.dtype}")
    if args.runtime == "cpp":
        from quadfdi.bench.timing.cpp import cpp_measure

        got = cpp_measure(args, x)
        b1, bn, mem, info = got["batch1"], got["batchN"], got["memory"], got["info"]
    else:
        if args.runtime == "torch":
            from quadfdi.bench.timing.pytorch import torch_runtime as adapter  # imports torch: in the baseline
        else:
            from quadfdi.bench.timing.ort import ort_runtime as adapter  # imports onnxruntime: in the baseline
        baseline = proc_status_kib("VmRSS")
        reset = reset_peak_rss()
        if not reset:
            baseline = peak_rss_kib()
        call1, callb, info = adapter(args)
        convert = info.pop("convert")
        singles = [np.ascontiguousarray(x[i:i + 1]) for i in range(len(x))]
        batches = batches_of(x, args.batch, max(1, args.batches))
        if convert is not None:
            singles = [convert(s) for s in singles]
            batches = [convert(b) for b in batches]
        b1 = time_calls(call1, singles, args.n, args.warmup, args.budget_s, args.min_samples, args.warmup_s)
        peak1 = peak_rss_kib()
        bn = time_calls(callb, batches, args.batches, 1, args.budget_s, args.min_samples, args.warmup_s)
        peakn = peak_rss_kib()
        nfe = info.pop("nfe", None)
        if nfe:
            info["nfe_per_window"] = sum(nfe) / len(nfe)
        mem = {"baseline_kib": baseline, "peak_batch1_kib": peak1, "peak_batch_kib": peakn,
               "method": "VmRSS after imports; VmHWM " + ("reset to it (clear_refs)" if reset else "since start")}
    rec1 = {**base_record(args), "batch": 1, **summarise(b1, 1)}
    recn = {**base_record(args), "batch": args.batch, **summarise(bn, args.batch)}
    if "nfe_per_window" in info:
        rec1["nfe_per_window"] = info["nfe_per_window"]
    for key in ("peak_batch1_kib", "peak_batch_kib"):
        if mem.get(key) is not None and mem.get("baseline_kib") is not None:
            mem[key.replace("_kib", "_above_baseline_kib")] = mem[key] - mem["baseline_kib"]
    info["affinity"] = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
    return {"records": [rec1, recn], "memory": {**base_record(args), **mem}, "info": info}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m quadfdi.bench.latency_worker", description=__doc__.splitlines()[0])
    p.add_argument("--runtime", choices=RUNTIMES, required=True)
    p.add_argument("--model", choices=("cnode", "gru"), required=True)
    p.add_argument("--precision", choices=("fp32", "int8"), default="fp32")
    p.add_argument("--solver", default="rk4-8", help="gru, rk4-N or dopri5-RTOL (default: %(default)s)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--spinning", choices=("on", "off", "na"), default="na")
    p.add_argument("--windows", required=True, help=".npy of (n, W, C) float32 windows")
    p.add_argument("--artifact", required=True, help="checkpoint (torch), .onnx (ort) or weights.bin (cpp)")
    p.add_argument("--fwref", default=None, help="fwref_infer program (cpp)")
    # The defaults are the [bench] config section's (bench.latency passes the run's values).
    d = BenchConfig()
    p.add_argument("--n", type=int, default=d.windows, help="batch-1 windows timed (default: %(default)s)")
    p.add_argument("--warmup", type=int, default=d.warmup, help="warm-up calls (default: %(default)s)")
    p.add_argument("--batch", type=int, default=d.batch)
    p.add_argument("--batches", type=int, default=d.batches, help="batches timed (default: %(default)s)")
    p.add_argument("--budget-s", type=float, default=d.budget_s,
                   help="time budget of each timed loop (default: %(default)s)")
    p.add_argument("--warmup-s", type=float, default=WARMUP_SECONDS,
                   help="warm-up stops after this many seconds (default: %(default)s)")
    p.add_argument("--min-samples", type=int, default=MIN_SAMPLES,
                   help="the budget never cuts a loop below this many calls (default: %(default)s)")
    p.add_argument("--time-exe", default=None, help="GNU time, for the C++ program's peak RSS (cpp)")
    p.add_argument("--cpus", default=None, help="pin to these CPUs too (comma list), in case taskset is absent")
    p.add_argument("--profile", default=None, help="ort: write the per-op profile summary here instead of timing")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.cpus and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {int(c) for c in args.cpus.split(",")})
    if args.n < 1 or args.batches < 1 or args.batch < 1 or args.threads < 1:
        print("latency_worker: --n, --batch, --batches and --threads must be positive", file=sys.stderr)
        return 2
    if args.runtime == "cpp" and not args.fwref:
        print("latency_worker: --runtime cpp needs --fwref <fwref_infer>", file=sys.stderr)
        return 2
    try:
        parse_solver(args.solver)
        if args.profile:
            if args.runtime != "ort":
                raise ValueError("--profile is for --runtime ort")
            from quadfdi.bench.timing.ort import profile

            out = {**base_record(args), **profile(args)}
            Path(args.profile).write_text(json.dumps(out, indent=1) + "\n")
        else:
            out = measure(args)
    except Exception as exc:  # a worker reports any failure as one line; bench.latency shows it
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"latency_worker: error: {msg}", file=sys.stderr)
        return 2
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
