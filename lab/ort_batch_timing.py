"""ONNX Runtime int8 against fp32 at one batch size, on a run's exported graphs, for a shared machine.

    python lab/ort_batch_timing.py RUN [--batch 96] [--reps 60] [--models cnode,gru]
                                                        [--profile] [--extra NAME=FILE.onnx ...]

Every graph of a model is timed in the same loop, one call of each per round (interleaved, so that
a change of load hits all of them alike), one intra-op thread, spinning off. The figure is the
calling thread's CPU time (``time.thread_time``) per call, median over the rounds: on a machine
whose load average is several times its core count the wall time mostly measures waiting for a
core, the CPU time does not (cache and memory contention still show). Wall medians are printed
beside it. Only ratios within one invocation mean anything.

``--profile`` adds ONNX Runtime's per-node profile of each graph at that batch: the kernel time of
each operator type (10th percentile per node over the rounds, summed; the profiler's own cost per
node is left out), as a share of the sum over nodes. Input windows are the first ``--batch``
windows of 80 samples cut from the run's dataset (deterministic; timings do not depend on values).
``--extra NAME=FILE`` times another graph of the first model beside it (a prototype). "ORT nodes":
after ONNX Runtime's optimizer, the graph's own, and those of a Scan body (which run once per step)
said apart.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

from quadfdi.core.tables import md_table
from quadfdi.runtimes.ort import optimized_nodes, session


def windows(run: Path, batch: int, width: int) -> np.ndarray:
    """``batch`` windows (batch, width, C) of the run's telemetry, flights and offsets round-robin."""
    with np.load(run / "dataset.npz") as z:
        tel = z["telemetry"]
    n, t = tel.shape[:2]
    return np.stack([tel[i % n, (7 * i) % (t - width):(7 * i) % (t - width) + width]
                     for i in range(batch)]).astype(np.float32)


def time_graphs(files: dict[str, Path], x: np.ndarray, reps: int) -> dict[str, dict[str, float]]:
    """name -> {cpu_us, wall_us (medians), cpu_p10_us} over ``reps`` interleaved rounds."""
    sess = {k: session(f, 1, spinning=False) for k, f in files.items()}
    feed = {"telemetry": x}
    for s in sess.values():
        for _ in range(3):
            s.run(None, feed)
    cpu, wall = defaultdict(list), defaultdict(list)
    for _ in range(reps):
        for k, s in sess.items():
            c, w = time.thread_time(), time.perf_counter()
            s.run(None, feed)
            cpu[k].append(time.thread_time() - c)
            wall[k].append(time.perf_counter() - w)
    return {k: {"cpu_us": 1e6 * float(np.median(cpu[k])), "cpu_p10_us": 1e6 * float(np.percentile(cpu[k], 10)),
                "wall_us": 1e6 * float(np.median(wall[k]))} for k in files}


def profile_ops(file: Path, x: np.ndarray, reps: int) -> dict[str, float]:
    """Operator type -> share of kernel time (per node the 10th percentile over ``reps`` calls)."""
    with tempfile.TemporaryDirectory() as tmp:
        s = session(file, 1, spinning=False, profile_prefix=str(Path(tmp) / "prof"))
        for _ in range(reps):
            s.run(None, {"telemetry": x})
        events = json.loads(Path(s.end_profiling()).read_text())
    per_node, op_of = defaultdict(list), {}
    for e in events:
        if e.get("cat") == "Node" and e["name"].endswith("_kernel_time"):
            per_node[e["name"]].append(e["dur"])
            op_of[e["name"]] = e["args"]["op_name"]
    by_op = defaultdict(float)
    for name, durs in per_node.items():
        by_op[op_of[name]] += float(np.percentile(durs, 10))
    total = sum(by_op.values()) or 1.0
    return {op: v / total for op, v in sorted(by_op.items(), key=lambda kv: -kv[1])}


def nodes_text(n: dict[str, int]) -> str:
    """'972', or '14 + 12 in the body' (a Scan's or Loop's body: its nodes run once per step)."""
    return f"{n['total']}" + (f" + {n['body']} in the body" if n["body"] else "")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--batch", type=int, default=96)
    ap.add_argument("--reps", type=int, default=60)
    ap.add_argument("--models", default="cnode")
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--extra", action="append", default=[])
    a = ap.parse_args(argv)
    manifest = json.loads((a.run / "export" / "manifest.json").read_text())
    x = windows(a.run, a.batch, int(manifest["window"]))
    print(f"{a.run}: batch {a.batch}, {a.reps} interleaved rounds, 1 thread; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    for k, model in enumerate(a.models.split(",")):
        files = {p: a.run / "export" / manifest["artifacts"][f"{model}_{p}"] for p in ("fp32", "int8")}
        if k == 0:
            files.update({e.split("=", 1)[0]: Path(e.split("=", 1)[1]) for e in a.extra})
        t = time_graphs(files, x, a.reps)
        rows = [[model, name, nodes_text(optimized_nodes(f)), f"{v['cpu_us']:,.1f}", f"{v['cpu_p10_us']:,.1f}",
                 f"{v['wall_us']:,.1f}", f"{t['fp32']['cpu_us'] / v['cpu_us']:.2f}x"] for name, v in
                (it for it in t.items()) for f in [files[name]]]
        print("\n".join(md_table(["model", "graph", "ORT nodes", "CPU us (median)", "CPU us (p10)",
                                  "wall us (median)", "speed vs fp32 (CPU)"], rows)))
        if a.profile:
            for name, f in files.items():
                shares = profile_ops(f, x, a.reps)
                print(f"{model} {name} kernel-time shares: " +
                      ", ".join(f"{op} {100 * s:.1f} %" for op, s in list(shares.items())[:8]))


if __name__ == "__main__":
    main(sys.argv[1:])
