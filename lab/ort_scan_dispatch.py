"""ONNX Runtime's dispatch cost alone, at the int8 GRU's sizes (80 steps, 80 floats): a Scan of 80
steps whose body is k chained Neg nodes against n Neg nodes in one graph, one thread, CPU time per
call, median of 400 interleaved rounds (docs/bench.md, "The int8 GRU in one Scan"):

    python lab/ort_scan_dispatch.py

A Neg on 80 floats costs next to nothing, so the figures are what ONNX Runtime spends around the
kernels: the floor of any graph with k nodes per step.
"""
from __future__ import annotations

import time

import numpy as np
import onnxruntime as ort
from onnx import TensorProto, helper

H, STEPS, ROUNDS = 80, 80, 400


def _vi(name: str, shape: list[int]):
    return helper.make_tensor_value_info(name, TensorProto.FLOAT, shape)


def _chain(src: str, dst: str, k: int, tag: str) -> list:
    """k Neg nodes from ``src`` to ``dst``."""
    names = [src] + [f"{tag}{i}" for i in range(k - 1)] + [dst]
    return [helper.make_node("Neg", [names[i]], [names[i + 1]]) for i in range(k)]


def _model(nodes: list):
    g = helper.make_graph(nodes, "g", [_vi("h0", [1, H]), _vi("xs", [STEPS, 1, H])], [_vi("hl", [1, H])])
    return helper.make_model(g, opset_imports=[helper.make_opsetid("", 18)], ir_version=10)


def scan_model(k: int):
    """A Scan over STEPS steps, its body k chained Neg nodes on the state (the scanned input unused)."""
    body = helper.make_graph(_chain("h", "hn", k, "b"), "body", [_vi("h", [1, H]), _vi("x", [1, H])], [_vi("hn", [1, H])])
    return _model([helper.make_node("Scan", ["h0", "xs"], ["hl"], body=body, num_scan_inputs=1)])


def flat_model(n: int):
    return _model(_chain("h0", "hl", n, "t"))


def _session(m) -> ort.InferenceSession:
    o = ort.SessionOptions()
    o.intra_op_num_threads, o.inter_op_num_threads, o.log_severity_level = 1, 1, 3
    o.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(m.SerializeToString(), o, providers=["CPUExecutionProvider"])


def main() -> None:
    models = {"Scan, body 1 node": scan_model(1), "Scan, body 12 nodes": scan_model(12), "flat, 1 node": flat_model(1),
              "flat, 80 nodes": flat_model(STEPS), "flat, 960 nodes": flat_model(12 * STEPS)}
    sess = {k: _session(m) for k, m in models.items()}
    feed = {"h0": np.zeros((1, H), np.float32), "xs": np.zeros((STEPS, 1, H), np.float32)}
    times: dict[str, list[float]] = {k: [] for k in sess}
    for s in sess.values():
        for _ in range(5):
            s.run(None, feed)
    for _ in range(ROUNDS):
        for k, s in sess.items():
            c = time.thread_time()
            s.run(None, feed)
            times[k].append(time.thread_time() - c)
    for k, t in times.items():
        print(f"{k:22s} {1e6 * float(np.median(t)):8.1f} us (CPU time per call, median of {ROUNDS} interleaved rounds)")


if __name__ == "__main__":
    main()
