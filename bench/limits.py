"""What this machine can do at best, measured in the same run as the latencies (SPEC section 6).

Three limits, each a *best-of* over repeated trials (a limit is what the hardware can reach; on a
shared machine interference only ever slows a trial down, so the fastest trial is the estimate):

- ``peak_gflops``: float32 matrix-product throughput on ONE core (numpy's OpenBLAS and torch's
  MKL sgemm, at the models' own sizes and at a large size; the best of all). One core because the
  batch-1 runtimes are single-threaded chains of small dependent products; the two-thread figure
  is reported beside it (``peak_gflops_2t``). ``peak_int8_gops``: ONNX Runtime's MatMulInteger
  (8-bit x int8 -> int32, MLAS, VNNI where the CPU has it) at a large size, one core, the faster of
  uint8 and int8 activations: the compute half of the int8 floors (``s8s8_int8_gops``: int8
  activations, the type of quadfdi's graphs).
- ``l1_gbps``, ``l2_gbps``: read bandwidth of one core from buffers of 1/4 and 1/2 of L1d and of
  L2 (``bench/cpp/l2bw.cpp``, compiled here per ISA with g++ -O2 -march=native -DVEC_BYTES=64|32|16,
  the host's widest variant whose hot loops pass ``check_vectorised``: objdump shows vector
  registers of that width and no stack access); best trial, best size. Sanity: L1 >= 1.5x L2
  (``bandwidth_sane``). ``fma_peak_gflops``: the same probe's FMA loop, part of ``peak_gflops``.
  numpy's ``dot`` when no compiler is found (call-overhead bound, an under-estimate, flagged).
- ``ort_call_us``: ONNX Runtime's fixed cost per ``run()`` call: the median of an Identity model on
  one (1, W, C) window, one intra-op thread; ``ort_node_us``: its cost per extra small node (a
  chain of 256 Add nodes on a (1, 64) tensor, minus the call, over 256).

``python -m quadfdi.bench.limits --threads T`` measures the in-process parts (matrix products, ORT) in a
fresh process and prints JSON; ``measure_limits`` runs it pinned to the benchmark cores for T = 1
and 2 and runs the bandwidth probe: one pass. ``bench.run`` makes a full pass before the latencies
and a 1-thread pass after them, and ``merge_limits`` keeps the best of the two.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable

from quadfdi.bench.probes import (L1_OVER_L2_MIN, bandwidth, build_checked_probe, cache_sizes, fma_peak, l2_probe_kib,
                          numpy_bandwidth, probe_sizes_kib, time_call)
from quadfdi.core.errors import QuadfdiError

# (label, M, K, N): the models' products at batch 1 and 96, plus a large one that reaches the peak.
#   cnode field lin1 (z and u concatenated: L + C = 63 -> H = 64), lin2 (64 -> 40);
#   gru input and recurrent products (C = 23 or H = 80 -> 3H = 240).

GEMM_SIZES = (
    ("cnode lin1 b1", 1, 63, 64),
    ("cnode lin1 b96", 96, 63, 64),
    ("gru hh b1", 1, 80, 240),
    ("gru hh b96", 96, 80, 240),
    ("large 512", 512, 512, 512),
    ("large 1024", 1024, 1024, 1024),
)
QUICK_SIZES = (GEMM_SIZES[1], ("large 256", 256, 256, 256))
INT8_SIZE = 1024
NODE_CHAIN = 256  # Add nodes in the ORT per-node cost probe


# ----------------------------------------------------------------------------- timing helpers


def gemm_rates(threads: int, quick: bool) -> list[dict]:
    """GFLOP/s (2 M K N / seconds) of numpy and torch float32 matmul at each size (quick: numpy only)."""
    import numpy as np

    libs = ["numpy"]
    if not quick:
        import torch

        torch.set_num_threads(threads)
        libs.append("torch")
    rng = np.random.default_rng(0)
    out = []
    min_s, trials = (0.01, 2) if quick else (0.08, 5)
    for label, m, k, n in (QUICK_SIZES if quick else GEMM_SIZES):
        a = rng.standard_normal((m, k), dtype=np.float32)
        b = rng.standard_normal((k, n), dtype=np.float32)
        c = np.empty((m, n), dtype=np.float32)
        calls = {"numpy": lambda: np.matmul(a, b, out=c)}
        if "torch" in libs:
            ta, tb, tc = torch.from_numpy(a), torch.from_numpy(b), torch.empty(m, n)
            calls["torch"] = lambda: torch.mm(ta, tb, out=tc)
        flop = 2.0 * m * k * n
        for lib, fn in calls.items():
            s = time_call(fn, min_s, trials)
            out.append({"label": label, "m": m, "k": k, "n": n, "library": lib, "threads": threads,
                        "seconds": s, "gflops": flop / s / 1e9})
    return out


def _ort_session(model_bytes: bytes, threads: int):
    from quadfdi.runtimes.ort import session

    return session(model_bytes, threads, spinning=False)


def int8_rate(threads: int, quick: bool) -> list[dict]:
    """GOP/s of ONNX Runtime MatMulInteger (8-bit x int8 weights -> int32) on a square product.

    Two activation types: uint8 (the combination MLAS's fast x86 kernels are written for) and int8
    (symmetric, zero point 0: the type quadfdi's exported graphs use). On x86 the two can differ
    by an order of magnitude; both are reported and the peak is the faster one.
    """
    import numpy as np
    from onnx import TensorProto, helper, numpy_helper

    size = 256 if quick else INT8_SIZE
    rng = np.random.default_rng(0)
    w = rng.integers(-127, 128, size=(size, size), dtype=np.int8)
    out = []
    for name, elem, dtype, lo, hi in (("u8s8", TensorProto.UINT8, np.uint8, 0, 256),
                                      ("s8s8", TensorProto.INT8, np.int8, -128, 128)):
        graph = helper.make_graph(
            [helper.make_node("MatMulInteger", ["a", "w"], ["y"])], "int8_peak",
            [helper.make_tensor_value_info("a", elem, [size, size])],
            [helper.make_tensor_value_info("y", TensorProto.INT32, [size, size])],
            [numpy_helper.from_array(w, "w")])
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
        sess = _ort_session(model.SerializeToString(), threads)
        a = rng.integers(lo, hi, size=(size, size)).astype(dtype)
        s = time_call(lambda: sess.run(None, {"a": a}), 0.01 if quick else 0.1, 2 if quick else 5)
        out.append({"types": name, "m": size, "k": size, "n": size, "threads": threads, "seconds": s,
                    "gops": 2.0 * size ** 3 / s / 1e9})
    return out


def _time_median_us(sess, feed: dict, n: int) -> float:
    for _ in range(min(200, n)):
        sess.run(None, feed)
    samples = []
    for _ in range(n):
        t0 = time.perf_counter_ns()
        sess.run(None, feed)
        samples.append(time.perf_counter_ns() - t0)
    return statistics.median(samples) / 1e3


def ort_call_cost(window: int, channels: int, quick: bool) -> dict:
    """ONNX Runtime's fixed cost per ``run()`` and its cost per node, one thread, median microseconds.

    Call: an Identity model on one (1, W, C) window. Node: a chain of NODE_CHAIN Add nodes on a
    (1, 64) tensor (each adds a constant), minus the call cost, over NODE_CHAIN: what ORT spends to
    dispatch one small elementwise node, which the unrolled graphs have hundreds of.
    """
    import numpy as np
    from onnx import TensorProto, helper, numpy_helper

    def session_of(nodes, inputs, outputs, inits=()):
        graph = helper.make_graph(nodes, "probe", inputs, outputs, list(inits))
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
        return _ort_session(model.SerializeToString(), 1)

    n = 500 if quick else 3000
    ident = session_of([helper.make_node("Identity", ["telemetry"], ["out"])],
                       [helper.make_tensor_value_info("telemetry", TensorProto.FLOAT, [1, window, channels])],
                       [helper.make_tensor_value_info("out", TensorProto.FLOAT, [1, window, channels])])
    call_us = _time_median_us(ident, {"telemetry": np.zeros((1, window, channels), dtype=np.float32)}, n)
    names = ["x"] + [f"a{i}" for i in range(NODE_CHAIN)]
    chain = session_of([helper.make_node("Add", [names[i], "c"], [names[i + 1]]) for i in range(NODE_CHAIN)],
                       [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 64])],
                       [helper.make_tensor_value_info(names[-1], TensorProto.FLOAT, [1, 64])],
                       [numpy_helper.from_array(np.full((1, 64), 1e-3, dtype=np.float32), "c")])
    chain_us = _time_median_us(chain, {"x": np.zeros((1, 64), dtype=np.float32)}, max(200, n // 5))
    return {"median_us": call_us, "node_us": max(0.0, (chain_us - call_us) / NODE_CHAIN), "chain_us": chain_us,
            "chain_nodes": NODE_CHAIN, "calls": n}


def worker_main(argv: list[str] | None = None) -> int:
    """``python -m quadfdi.bench.limits --threads T``: the in-process limits as one JSON line on stdout."""
    p = argparse.ArgumentParser(prog="python -m quadfdi.bench.limits")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--quick", action="store_true")
    p.add_argument("--window", type=int, default=80)
    p.add_argument("--channels", type=int, default=23)
    args = p.parse_args(argv)
    out = {"threads": args.threads, "gemm": gemm_rates(args.threads, args.quick),
           "int8": int8_rate(args.threads, args.quick)}
    if args.threads == 1:
        out["ort_call"] = ort_call_cost(args.window, args.channels, args.quick)
    print(json.dumps(out))
    return 0


# ----------------------------------------------------------------------------- cache and bandwidth


def cpu_prefix(cpus: str) -> list[str]:
    """``taskset -c <cpus>`` when taskset exists, else nothing (workers also pin themselves)."""
    exe = shutil.which("taskset")
    return [exe, "-c", cpus] if exe else []


def worker_env(threads: int) -> dict[str, str]:
    """Environment of a fresh benchmark process: every thread pool sized before any library loads."""
    env = dict(os.environ)
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        env[var] = str(threads)
    return env


def run_json(cmd: list[str], env: dict[str, str], what: str, timeout: float) -> dict:
    """Run a worker command and parse the last line of its stdout as JSON (one-line error otherwise)."""
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=timeout)
    except subprocess.TimeoutExpired:
        raise QuadfdiError(f"{what} did not finish within {timeout:.0f} s") from None
    if res.returncode != 0:
        last = (res.stderr.strip().splitlines() or [f"exit code {res.returncode}"])[-1]
        raise QuadfdiError(f"{what} failed: {last}")
    lines = [ln for ln in res.stdout.splitlines() if ln.strip()]
    try:
        return json.loads(lines[-1])
    except (IndexError, json.JSONDecodeError):
        raise QuadfdiError(f"{what} printed no JSON result") from None


def measure_limits(cpus: str = "0,1", quick: bool = False, window: int = 80, channels: int = 23,
                   log: Callable[[str], None] = print, threads: tuple[int, ...] = (1, 2)) -> dict:
    """One pass of bench.json's ``limits``: peak GFLOP/s, int8 GOP/s, L2 GB/s, ORT call and node cost.

    ``threads``: the thread counts of the in-process part; (1,) measures only what the batch-1
    floors use (``merge_limits`` combines such a pass with a full one).
    """
    t0 = time.perf_counter()
    prefix = cpu_prefix(cpus)
    per_threads = {}
    for t in threads:
        cmd = [*prefix, sys.executable, "-m", "quadfdi.bench.limits", "--threads", str(t),
               "--window", str(window), "--channels", str(channels)] + (["--quick"] if quick else [])
        per_threads[t] = run_json(cmd, worker_env(t), f"limits worker ({t} threads)", 600)
    caches = cache_sizes()
    kib = l2_probe_kib(caches)
    trials, min_s = (2, 0.01) if quick else (7, 0.08)
    sizes = probe_sizes_kib(caches)
    per_size: dict[str, float] = {}
    fma = None
    with tempfile.TemporaryDirectory(prefix="quadfdi-l2bw-") as tmp:
        exe, vector_check = build_checked_probe(Path(tmp))
        pin_one = prefix[:2] + [cpus.split(",")[0]] if prefix else []
        if exe is not None:
            for level in ("L1", "L2"):
                for k in sizes[level]:
                    per_size[f"{level} {k} KiB"] = bandwidth(exe, k, pin_one, trials, min_s)
            l1 = max(v for n, v in per_size.items() if n.startswith("L1"))
            l2 = max(v for n, v in per_size.items() if n.startswith("L2"))
            fma = fma_peak(exe, pin_one, trials, min_s)
            probe = (f"bench/cpp/l2bw.cpp (g++ -O2 -march=native -DVEC_BYTES={vector_check.get('vec_bytes')}), "
                     f"8 vector accumulators, one core; hot loops "
                     + ("checked vectorised" if vector_check.get("ok") else
                        "NOT checked" if not vector_check.get("checked") else "FAILED the vectorisation check"))
        else:
            l2, l1 = numpy_bandwidth(kib), None
            probe = "numpy dot (no C++ compiler found): includes call overhead, an under-estimate"
    sane = l1 is not None and l1 >= L1_OVER_L2_MIN * l2
    if not sane:
        log(f"bench limits: WARNING bandwidth probe implausible: L1 {l1 or 0:.1f} GB/s is not >= "
            f"{L1_OVER_L2_MIN}x L2 {l2:.1f} GB/s (a spilling or non-vectorised loop reads the same at every size)")
    one = per_threads[1]
    two = per_threads.get(2)
    gemm_peak = max(g["gflops"] for g in one["gemm"])
    limits = {
        # the roof: the best of the libraries' sgemm and the probe's own FMA loop (a floor must be a
        # lower bound, so the higher peak is the one it uses)
        "peak_gflops": max(gemm_peak, fma or 0.0),
        "gemm_peak_gflops": gemm_peak,
        "fma_peak_gflops": fma,
        "peak_gflops_2t": max(g["gflops"] for g in two["gemm"]) if two else None,
        "peak_int8_gops": max(r["gops"] for r in one["int8"]),
        "peak_int8_gops_2t": max(r["gops"] for r in two["int8"]) if two else None,
        "s8s8_int8_gops": next(r["gops"] for r in one["int8"] if r["types"] == "s8s8"),
        "l2_gbps": l2,
        "l1_gbps": l1,
        "ort_call_us": one["ort_call"]["median_us"],
        "ort_node_us": one["ort_call"]["node_us"],
        "caches": caches,
        "l2_probe_kib": kib,
        "bandwidth_by_size": per_size,
        "bandwidth_sane": sane,
        "vector_check": vector_check if exe is not None else None,
        "bandwidth_probe": probe,
        "gemm": [g for t in threads for g in per_threads[t]["gemm"]],
        "int8": [r for t in threads for r in per_threads[t]["int8"]],
        "cpus": cpus,
        "method": "peaks and bandwidths: best of trials (a limit); ORT call and node costs: medians",
        "seconds": time.perf_counter() - t0,
    }
    log(f"bench limits: peak {limits['peak_gflops']:.1f} GFLOP/s (1 thread)"
        + (f", {limits['peak_gflops_2t']:.1f} (2 threads)" if two else "")
        + f", int8 {limits['peak_int8_gops']:.0f} GOP/s (int8 x int8 {limits['s8s8_int8_gops']:.0f}), L2 {l2:.0f} GB/s "
        f"({kib} KiB buffer), ORT call {limits['ort_call_us']:.1f} us + {limits['ort_node_us']:.2f} us per node, "
        f"in {limits['seconds']:.0f} s")
    return limits


BEST_OF = ("peak_gflops", "gemm_peak_gflops", "fma_peak_gflops", "peak_gflops_2t", "peak_int8_gops",
           "peak_int8_gops_2t", "s8s8_int8_gops", "l2_gbps",
           "l1_gbps")
LEAST_OF = ("ort_call_us", "ort_node_us")


def merge_limits(passes: list[dict]) -> dict:
    """Several passes (the first a full one) -> one ``limits``: the best peak and bandwidth of all
    passes, the lowest ORT costs, every pass kept under ``passes``.

    On a shared machine a pass can be slowed throughout by another user; measuring before and
    after the latencies and keeping the best brings the floors closer to what the hardware can do.
    """
    out = dict(passes[0])
    for key in BEST_OF:
        vals = [p[key] for p in passes if p.get(key) is not None]
        out[key] = max(vals) if vals else None
    for key in LEAST_OF:
        vals = [p[key] for p in passes if p.get(key) is not None]
        out[key] = min(vals) if vals else None
    l1, l2 = out.get("l1_gbps"), out.get("l2_gbps")
    out["bandwidth_sane"] = bool(l1 is not None and l2 and l1 >= L1_OVER_L2_MIN * l2)
    out["gemm"] = [{**g, "pass": i} for i, p in enumerate(passes) for g in p["gemm"]]
    out["int8"] = [{**r, "pass": i} for i, p in enumerate(passes) for r in p["int8"]]
    out["passes"] = [{k: p.get(k) for k in (*BEST_OF, *LEAST_OF, "seconds")} for p in passes]
    out["seconds"] = sum(p["seconds"] for p in passes)
    out["method"] = (f"{len(passes)} passes (before and after the latencies); peaks and bandwidths: best of trials "
                     "and passes (a limit); ORT call and node costs: medians, the lower pass")
    return out


if __name__ == "__main__":
    sys.exit(worker_main())
