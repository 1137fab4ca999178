"""One latency measurement in a fresh process: ``python -m bench.latency_worker ...`` prints JSON.

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

Runtimes: ``torch`` (the checkpoint, CNODE with fixed classic RK4 ``rk4-N`` or adaptive
``dopri5-RTOL``), ``ort`` (an exported ONNX file), ``cpp`` (firmware_ref's ``fwref_infer``, which
runs windows one at a time and times each call with std::chrono::steady_clock; its batch-96
figure is 96 consecutive single-window calls, the program has no batched path). The C++ program's
memory is its own process's: peak RSS (GNU time's %M) of a one-window run minus that of
``fwref_infer --help`` (the loaded program and its libraries).

``--profile <path.json>`` (ort only): instead of timing, run the batch-1 loop with ONNX Runtime's
per-node profiler on and write the per-operator-type summary to ``path.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

RUNTIMES = ("torch", "ort", "cpp")
WARMUP_SECONDS = 1.0  # warm-up stops after this long even when fewer than --warmup calls ran
MIN_SAMPLES = 5  # a time budget never cuts a measurement below this many calls


# ----------------------------------------------------------------------------- statistics


def percentile(values: Sequence[float], q: float) -> float:
    """The q-th percentile (0..100) by linear interpolation between order statistics.

    The same definition as ``numpy.percentile``'s default (method "linear"): position
    (n - 1) * q / 100 in the sorted values, interpolated between its two neighbours.
    """
    if not values:
        raise ValueError("percentile of no values")
    if not 0.0 <= q <= 100.0:
        raise ValueError(f"percentile q must be in [0, 100], found {q}")
    v = sorted(values)
    pos = (len(v) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (pos - lo)


def summarise(samples_us: Sequence[float], batch: int) -> dict:
    """p50/p90/p99, mean, min, max (microseconds per call) and throughput = batch * 1e6 / p50."""
    p50 = percentile(samples_us, 50)
    return {
        "p50_us": p50,
        "p90_us": percentile(samples_us, 90),
        "p99_us": percentile(samples_us, 99),
        "mean_us": sum(samples_us) / len(samples_us),
        "min_us": min(samples_us),
        "max_us": max(samples_us),
        "n_calls": len(samples_us),
        "throughput_wps": batch * 1e6 / p50 if p50 > 0 else None,
    }


# ----------------------------------------------------------------------------- process memory


def proc_status_kib(field: str) -> int | None:
    """A ``/proc/self/status`` field in KiB (VmRSS, VmHWM); None where /proc is not available."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def reset_peak_rss() -> bool:
    """Reset VmHWM to the current RSS (Linux: write 5 to /proc/self/clear_refs); False if refused."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_kib() -> int | None:
    """Peak RSS of this process in KiB: VmHWM, else getrusage's ru_maxrss (KiB on Linux)."""
    hwm = proc_status_kib("VmHWM")
    if hwm is not None:
        return hwm
    import resource

    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


# ----------------------------------------------------------------------------- timing loops


def time_calls(call: Callable[[object], object], inputs: Sequence[object], n: int, warmup: int,
               budget_s: float, min_samples: int = MIN_SAMPLES) -> list[float]:
    """Microseconds of each of up to ``n`` calls ``call(inputs[i % len(inputs)])``, after warm-up.

    Warm-up: ``warmup`` calls or WARMUP_SECONDS, whichever ends first (at least one call). The
    timed loop stops after ``n`` calls or once ``budget_s`` has elapsed (never below ``min_samples``).
    """
    t_end = time.perf_counter() + WARMUP_SECONDS
    for i in range(max(1, warmup)):
        call(inputs[i % len(inputs)])
        if time.perf_counter() > t_end:
            break
    samples: list[float] = []
    deadline = time.perf_counter() + budget_s
    clock = time.perf_counter_ns
    for i in range(n):
        x = inputs[i % len(inputs)]
        t0 = clock()
        call(x)
        samples.append((clock() - t0) / 1e3)
        if i + 1 >= min_samples and time.perf_counter() > deadline:
            break
    return samples


def batches_of(x, batch: int, count: int) -> list:
    """``count`` batches of ``batch`` consecutive windows of ``x`` (cycling over x)."""
    import numpy as np

    idx = np.arange(batch * count) % len(x)
    return [np.ascontiguousarray(x[idx[k * batch:(k + 1) * batch]]) for k in range(count)]


# ----------------------------------------------------------------------------- runtimes


def parse_solver(solver: str) -> tuple[str, float | int | None]:
    """'rk4-8' -> ('rk4', 8); 'dopri5-1e-3' -> ('dopri5', 0.001); 'gru' -> ('gru', None)."""
    if solver == "gru":
        return "gru", None
    method, _, value = solver.partition("-")
    try:
        if method in ("rk4", "euler", "midpoint"):
            return method, int(value)
        if method in ("dopri5", "bosh3"):
            return method, float(value)
    except ValueError:
        pass
    raise ValueError(f"solver must be gru, rk4-N, euler-N, midpoint-N, dopri5-RTOL or bosh3-RTOL; found {solver!r}")


def torch_runtime(args) -> tuple[Callable, Callable, dict]:
    """(batch-1 call, batch call, info) for a checkpoint; the CNODE's solver set from ``--solver``."""
    import torch

    from train.checkpoint import load_checkpoint
    from train.models import SolverSpec

    torch.set_num_threads(args.threads)
    model, _ = load_checkpoint(args.artifact, args.model)
    method, value = parse_solver(args.solver)
    info: dict = {"torch": torch.__version__}
    if args.model == "cnode":
        if method in ("dopri5", "bosh3"):
            # atol = rtol / 10, the solver study's convention (bench/solvers.py ATOL_RATIO); jump_t on.
            model.solver = SolverSpec(method, rtol=float(value), atol=float(value) / 10, jump_t=True)
        else:
            model.solver = SolverSpec(method, steps=int(value))
        info["solver"] = {k: getattr(model.solver, k) for k in ("method", "steps", "rtol", "atol", "jump_t")}
    nfe: list[int] = []

    def call1(x):
        with torch.inference_mode():
            out = model(x)
        if args.model == "cnode":
            nfe.append(model.nfe)
        return out

    def callb(x):
        with torch.inference_mode():
            return model(x)

    info["nfe"] = nfe
    info["convert"] = torch.from_numpy
    return call1, callb, info


def ort_session(path: str, threads: int, spinning: bool, profile_prefix: str | None = None):
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.add_session_config_entry("session.intra_op.allow_spinning", "1" if spinning else "0")
    if profile_prefix:
        so.enable_profiling = True
        so.profile_file_prefix = profile_prefix
    return ort.InferenceSession(path, so, providers=["CPUExecutionProvider"])


def ort_runtime(args) -> tuple[Callable, Callable, dict]:
    import onnxruntime as ort

    sess = ort_session(args.artifact, args.threads, args.spinning == "on")
    name = sess.get_inputs()[0].name

    def call(x):
        return sess.run(None, {name: x})

    return call, call, {"onnxruntime": ort.__version__, "convert": None}


def summarise_ort_profile(path: str) -> dict:
    """Share of kernel time and nodes per call by operator type, from an ONNX Runtime profile.

    Node events are ``<node>_kernel_time`` with ``args.op_name``; ``model_run`` events are whole
    calls. Only shares are meaningful: the profiler itself costs several microseconds per node
    (it records memory statistics for each), so profiled calls are many times slower than
    unprofiled ones (``profiled_call_p50_us`` says how much).
    """
    events = json.loads(Path(path).read_text())
    runs = [float(e["dur"]) for e in events if e.get("cat") == "Session" and e.get("name") == "model_run"]
    n_runs = max(1, len(runs))
    by_op: dict[str, dict] = {}
    for e in events:
        if e.get("cat") == "Node" and str(e.get("name", "")).endswith("_kernel_time"):
            d = by_op.setdefault(e.get("args", {}).get("op_name", "?"), {"calls": 0, "us": 0.0})
            d["calls"] += 1
            d["us"] += float(e["dur"])
    total = sum(d["us"] for d in by_op.values()) or 1.0
    rows = sorted(({"op": op, "nodes_per_call": d["calls"] / n_runs, "kernel_share": d["us"] / total}
                   for op, d in by_op.items()), key=lambda r: -r["kernel_share"])
    return {"profiled_calls": len(runs), "profiled_call_p50_us": percentile(runs, 50) if runs else None,
            "nodes_per_call": sum(r["nodes_per_call"] for r in rows), "by_op": rows}


def run_child(cmd: list[str], time_exe: str | None = None) -> tuple[int, str, int | None]:
    """(exit code, stderr, peak RSS KiB or None) of a child process.

    The peak comes from GNU time's %M when ``time_exe`` is given. Not from this process's own
    wait4: Linux carries the parent's RSS high-water mark into a forked child through exec, so a
    child of a 200 MB Python process would "peak" at 200 MB; GNU time forks from its own small
    image, which is far below the program's.
    """
    with tempfile.TemporaryDirectory(prefix="quadfdi-child-") as tmp:
        rss_file = Path(tmp) / "rss"
        full = [time_exe, "-f", "%M", "-o", str(rss_file), *cmd] if time_exe else cmd
        res = subprocess.run(full, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        rss = None
        if time_exe and rss_file.is_file():
            lines = [ln for ln in rss_file.read_text().splitlines() if ln.strip()]
            rss = int(lines[-1]) if lines and lines[-1].strip().isdigit() else None
        return res.returncode, res.stderr, rss


def cpp_measure(args, x) -> dict:
    """Time fwref_infer on the windows; return records, memory and info (see the module doc)."""
    import numpy as np

    exe = args.fwref
    base = [exe, "--weights", args.artifact, "--model", args.model] + (["--int8"] if args.precision == "int8" else [])
    with tempfile.TemporaryDirectory(prefix="quadfdi-fwref-") as tmp:
        tmpd = Path(tmp)
        code, err, rss_base = run_child([exe, "--help"], args.time_exe)
        if code != 0:
            raise RuntimeError(f"{exe} --help failed: {err.strip()}")
        one = tmpd / "one.f32"
        np.ascontiguousarray(x[:1], dtype="<f4").tofile(one)
        code, err, rss_peak = run_child(base + ["--in", str(one), "--out", str(tmpd / "one.out"), "--repeat", "20",
                                                "--timings", str(tmpd / "one.t")], args.time_exe)
        if code != 0:
            raise RuntimeError(err.strip().splitlines()[-1] if err.strip() else f"{exe} exit code {code}")
        # Input: warm-up windows, then the timed batch-1 windows, then the batch-96 blocks; each
        # window is run once (--repeat 1), so every window is timed once, after the warm-up.
        warm = max(1, args.warmup)
        idx = np.concatenate([np.arange(warm), np.arange(args.n), np.arange(args.batch * args.batches)]) % len(x)
        windows = tmpd / "windows.f32"
        np.ascontiguousarray(x[idx], dtype="<f4").tofile(windows)
        timings = tmpd / "t.f64"
        t0 = time.perf_counter()
        code, err, _ = run_child(base + ["--in", str(windows), "--out", str(tmpd / "out.f32"), "--repeat", "1",
                                         "--timings", str(timings)])
        wall = time.perf_counter() - t0
        if code != 0:
            raise RuntimeError(err.strip().splitlines()[-1] if err.strip() else f"{exe} exit code {code}")
        sec = np.fromfile(timings, dtype="<f8")
    b1 = (sec[warm:warm + args.n] * 1e6).tolist()
    blocks = sec[warm + args.n:].reshape(args.batches, args.batch).sum(axis=1) * 1e6
    return {
        "batch1": b1,
        "batchN": blocks.tolist(),
        "memory": {"baseline_kib": rss_base, "peak_batch1_kib": rss_peak, "peak_batch_kib": None,
                   "method": "GNU time %M: one-window run (20 repeats) minus `fwref_infer --help`"
                             if args.time_exe else "not measured: GNU time (/usr/bin/time) not found"},
        "info": {"fwref": exe, "wall_s": wall, "note": "batch figure = consecutive single-window calls"},
    }


# ----------------------------------------------------------------------------- main


def base_record(args) -> dict:
    return {"model": args.model, "runtime": args.runtime, "precision": args.precision, "solver": args.solver,
            "threads": args.threads, "spinning": None if args.spinning == "na" else args.spinning == "on"}


def measure(args) -> dict:
    import numpy as np

    x = np.load(args.windows)
    if x.ndim != 3 or x.dtype != np.float32:
        raise ValueError(f"{args.windows} must hold (n, W, C) float32 windows, found {x.shape} {x.dtype}")
    if args.runtime == "cpp":
        got = cpp_measure(args, x)
        b1, bn, mem, info = got["batch1"], got["batchN"], got["memory"], got["info"]
    else:
        if args.runtime == "torch":
            import torch  # noqa: F401  (the baseline includes the runtime library)
        else:
            import onnxruntime  # noqa: F401
        baseline = proc_status_kib("VmRSS")
        reset = reset_peak_rss()
        if not reset:
            baseline = peak_rss_kib()
        call1, callb, info = (torch_runtime if args.runtime == "torch" else ort_runtime)(args)
        convert = info.pop("convert")
        singles = [np.ascontiguousarray(x[i:i + 1]) for i in range(len(x))]
        batches = batches_of(x, args.batch, max(1, args.batches))
        if convert is not None:
            singles = [convert(s) for s in singles]
            batches = [convert(b) for b in batches]
        b1 = time_calls(call1, singles, args.n, args.warmup, args.budget_s, args.min_samples)
        peak1 = peak_rss_kib()
        bn = time_calls(callb, batches, args.batches, 1, args.budget_s, args.min_samples)
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


def profile(args) -> dict:
    """ORT batch-1 loop with the per-node profiler; the per-op-type summary."""
    import numpy as np

    x = np.load(args.windows)
    with tempfile.TemporaryDirectory(prefix="quadfdi-ortprof-") as tmp:
        sess = ort_session(args.artifact, args.threads, args.spinning == "on", str(Path(tmp) / "ort"))
        name = sess.get_inputs()[0].name
        singles = [np.ascontiguousarray(x[i:i + 1]) for i in range(len(x))]
        for i in range(args.n):
            sess.run(None, {name: singles[i % len(singles)]})
        path = sess.end_profiling()
        summary = summarise_ort_profile(path)
    return {**base_record(args), "batch": 1, **summary}


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m bench.latency_worker", description=__doc__.splitlines()[0])
    p.add_argument("--runtime", choices=RUNTIMES, required=True)
    p.add_argument("--model", choices=("cnode", "gru"), required=True)
    p.add_argument("--precision", choices=("fp32", "int8"), default="fp32")
    p.add_argument("--solver", default="rk4-8", help="gru, rk4-N or dopri5-RTOL (default: %(default)s)")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--spinning", choices=("on", "off", "na"), default="na")
    p.add_argument("--windows", required=True, help=".npy of (n, W, C) float32 windows")
    p.add_argument("--artifact", required=True, help="checkpoint (torch), .onnx (ort) or weights.bin (cpp)")
    p.add_argument("--fwref", default=None, help="fwref_infer program (cpp)")
    p.add_argument("--n", type=int, default=300, help="batch-1 windows timed (default: %(default)s)")
    p.add_argument("--warmup", type=int, default=30, help="warm-up calls (default: %(default)s)")
    p.add_argument("--batch", type=int, default=96)
    p.add_argument("--batches", type=int, default=10, help="batches timed (default: %(default)s)")
    p.add_argument("--budget-s", type=float, default=10.0, help="time budget of each timed loop (default: %(default)s)")
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
            out = profile(args)
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
