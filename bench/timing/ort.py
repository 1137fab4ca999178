"""The ONNX Runtime adapter of the latency worker: an exported graph, and its per-operator profile."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Callable

from quadfdi.bench.timing.common import percentile
from quadfdi.runtimes.ort import session


def ort_runtime(args) -> tuple[Callable, Callable, dict]:
    import onnxruntime as ort

    sess = session(args.artifact, args.threads, spinning=args.spinning == "on")
    name = sess.get_inputs()[0].name

    def call(x):
        return sess.run(None, {name: x})

    return call, call, {"onnxruntime": ort.__version__, "convert": None}


SUBGRAPH_OPS = ("Scan", "Loop", "If")  # operators whose kernel time includes their subgraph's nodes


def summarise_ort_profile(path: str) -> dict:
    """Share of kernel time and nodes per call by operator type, from an ONNX Runtime profile.

    Node events are ``<node>_kernel_time`` with ``args.op_name``; ``model_run`` events are whole
    calls. Only shares are meaningful: the profiler itself costs several microseconds per node
    (it records memory statistics for each), so profiled calls are many times slower than
    unprofiled ones (``profiled_call_p50_us`` says how much). A node that runs a subgraph (the
    int8 GRU's ``Scan``) is left out: its time is its body's nodes' (profiled each step, counted
    here) and its own, which would count the body twice.
    """
    events = json.loads(Path(path).read_text())
    runs = [float(e["dur"]) for e in events if e.get("cat") == "Session" and e.get("name") == "model_run"]
    n_runs = max(1, len(runs))
    by_op: dict[str, dict] = {}
    for e in events:
        op = e.get("args", {}).get("op_name", "?")
        if e.get("cat") == "Node" and str(e.get("name", "")).endswith("_kernel_time") and op not in SUBGRAPH_OPS:
            d = by_op.setdefault(op, {"calls": 0, "us": 0.0})
            d["calls"] += 1
            d["us"] += float(e["dur"])
    total = sum(d["us"] for d in by_op.values()) or 1.0
    rows = sorted(({"op": op, "nodes_per_call": d["calls"] / n_runs, "kernel_share": d["us"] / total}
                   for op, d in by_op.items()), key=lambda r: -r["kernel_share"])
    return {"profiled_calls": len(runs), "profiled_call_p50_us": percentile(runs, 50) if runs else None,
            "nodes_per_call": sum(r["nodes_per_call"] for r in rows), "by_op": rows}


def profile(args) -> dict:
    """ORT batch-1 loop with the per-node profiler; the per-op-type summary."""
    import numpy as np

    x = np.load(args.windows)
    with tempfile.TemporaryDirectory(prefix="quadfdi-ortprof-") as tmp:
        sess = session(args.artifact, args.threads, spinning=args.spinning == "on",
                       profile_prefix=str(Path(tmp) / "ort"))
        name = sess.get_inputs()[0].name
        singles = [np.ascontiguousarray(x[i:i + 1]) for i in range(len(x))]
        for i in range(args.n):
            sess.run(None, {name: singles[i % len(singles)]})
        path = sess.end_profiling()
        summary = summarise_ort_profile(path)
    return {"batch": 1, **summary}
