"""Measured alternatives to the exported int8 GRU Scan, made from it by graph surgery (docs/bench.md,
"The int8 GRU in one Scan"); each must give outputs bit-identical to it, else nothing is written:

- ``outer_constants.onnx``: the body reads W_hh, b_hh, the scales, zero point and split sizes from
  the outer graph's initializers instead of its own;
- ``loop.onnx``: that body as a ``Loop`` body (+ Gather of step t's input rows x 2, + Identity of
  the condition);
- ``per_step_output.onnx``: the shipped Scan with the body's h' also a per-step output (Identity).

With ``--truncated``, instead two timing-only graphs that split the Scan's batch-1 time (their
outputs mean nothing, only their time does): ``body_3.onnx``, the body cut after its first 3 nodes
(QuantizeLinear, MatMulIntegerToFloat, Split; the state becomes gh_n), and ``body_neg.onnx``, the
body replaced by one Neg of the state.

    python lab/gru_scan_variants.py RUN/export/gru.int8.onnx OUTDIR [--truncated]
    python lab/ort_batch_timing.py RUN --models gru --batch 1 --extra NAME=OUTDIR/FILE.onnx ...
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from quadfdi.runtimes.ort import session


def _scan_and_body(m: onnx.ModelProto):
    scan = next(n for n in m.graph.node if n.op_type == "Scan")
    return scan, next(a.g for a in scan.attribute if a.name == "body")


def outer_constants(model: onnx.ModelProto) -> onnx.ModelProto:
    m = onnx.ModelProto()
    m.CopyFrom(model)
    _, body = _scan_and_body(m)
    m.graph.initializer.extend(body.initializer)  # names "step/...": no clash with the outer graph's
    del body.initializer[:]
    return m


def per_step_output(model: onnx.ModelProto) -> onnx.ModelProto:
    m = onnx.ModelProto()
    m.CopyFrom(model)
    scan, body = _scan_and_body(m)
    out = body.output[0]
    body.node.append(helper.make_node("Identity", [out.name], ["variant.h_out"]))
    body.output.append(helper.make_tensor_value_info("variant.h_out", TensorProto.FLOAT, None))
    body.output[1].type.CopyFrom(out.type)
    scan.output.append("variant.h_all")
    return m


def loop(model: onnx.ModelProto, steps: int) -> onnx.ModelProto:
    m = outer_constants(model)
    scan, body = _scan_and_body(m)
    h0, gx_rz, gx_n = scan.input
    h_in, xrz_in, xn_in = (i.name for i in body.input)
    nodes = [helper.make_node("Gather", [gx_rz, "variant.t"], [xrz_in], axis=0),
             helper.make_node("Gather", [gx_n, "variant.t"], [xn_in], axis=0),
             helper.make_node("Identity", ["variant.cond"], ["variant.cond_out"]), *body.node]
    lb = helper.make_graph(nodes, "gru_int8_loop_step",
                           [helper.make_tensor_value_info("variant.t", TensorProto.INT64, []),
                            helper.make_tensor_value_info("variant.cond", TensorProto.BOOL, []), body.input[0]],
                           [helper.make_tensor_value_info("variant.cond_out", TensorProto.BOOL, []), body.output[0]])
    m.graph.initializer.append(numpy_helper.from_array(np.array(steps, np.int64), "variant.trip_count"))
    at = list(m.graph.node).index(scan)
    m.graph.node.remove(scan)
    m.graph.node.insert(at, helper.make_node("Loop", ["variant.trip_count", "", h0], list(scan.output), body=lb))
    return m


def truncated(model: onnx.ModelProto, keep: int | None) -> onnx.ModelProto:
    """A copy whose Scan body keeps its first ``keep`` nodes (the state = the last one's 2nd output),
    or, with ``keep`` None, is one Neg of the state."""
    m = onnx.ModelProto()
    m.CopyFrom(model)
    _, body = _scan_and_body(m)
    nodes = list(body.node)
    del body.node[:]
    if keep:
        body.node.extend(nodes[:keep])
        body.output[0].name = nodes[keep - 1].output[1]
    else:
        body.node.append(helper.make_node("Neg", [body.input[0].name], ["body.neg_h"]))
        body.output[0].name = "body.neg_h"
    return m


def main(argv: list[str]) -> int:
    timing_only = "--truncated" in argv
    argv = [a for a in argv if a != "--truncated"]
    if len(argv) != 2:
        print(__doc__.split("\n\n")[-1].strip(), file=sys.stderr)
        return 2
    src, out = Path(argv[0]), Path(argv[1])
    model = onnx.load(str(src))
    if not any(n.op_type == "Scan" for n in model.graph.node):
        print(f"error: {src} has no Scan node (an unrolled int8 GRU?)", file=sys.stderr)
        return 1
    if timing_only:
        out.mkdir(parents=True, exist_ok=True)
        for name, keep in (("body_3.onnx", 3), ("body_neg.onnx", None)):
            onnx.save(truncated(model, keep), str(out / name))
            print(f"wrote {out / name} (timing only)")
        return 0
    dims = [d.dim_value for d in model.graph.input[0].type.tensor_type.shape.dim[1:]]
    x = {"telemetry": np.random.default_rng(0).normal(0, 3, (16, *dims)).astype(np.float32)}
    ref = session(model.SerializeToString()).run(["logits", "proba"], x)
    variants = {"outer_constants.onnx": outer_constants(model), "loop.onnx": loop(model, dims[0]),
                "per_step_output.onnx": per_step_output(model)}
    for name, m in variants.items():
        got = session(m.SerializeToString()).run(["logits", "proba"], x)
        if not all(a.tobytes() == b.tobytes() for a, b in zip(ref, got)):
            print(f"error: {name} is not bit-identical to {src}; nothing written", file=sys.stderr)
            return 1
    out.mkdir(parents=True, exist_ok=True)
    for name, m in variants.items():
        onnx.save(m, str(out / name))
        print(f"wrote {out / name} (outputs bit-identical to {src.name} on 16 random windows)")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
