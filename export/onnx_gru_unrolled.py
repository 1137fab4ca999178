"""The int8 GRU unrolled over the window, 12 nodes per step: the reference the Scan graph is checked against.

Kept, unchanged, as the reference the exported Scan graph (export/onnx_gru.py ``build_gru_int8``)
is bit-identical to (tests/test_export_graphs.py), and to time against it (docs/bench.md, "The int8
GRU in one Scan"; lab/gru_unrolled_graph.py writes a run's). 12 nodes per step x 80 steps + 12
= 972 nodes after ONNX Runtime's optimizer.
"""

from __future__ import annotations

import numpy as np

from quadfdi.export.graph import BATCH, Built, Graph, telemetry_input
from quadfdi.export.motor_graph import MOTOR_OUTPUT, graph_outputs, motor_int8
from quadfdi.export.onnx_gru import GruParams, GruQuant, _normalise
from quadfdi.export.quantize import int8_matmul, int8_weight, quantize, quantize_channels


def build_gru_int8_unrolled(p: GruParams, q: GruQuant, opset: int) -> Built:
    """int8 graph (not exported): the recurrence unrolled over the window, every product one
    MatMulIntegerToFloat.

    One step is 12 nodes: QuantizeLinear(h), MatMulIntegerToFloat (+ b_hh), Split(gh -> rz | n),
    Add and Sigmoid over the r and z gates together, Split(r | z), Mul, Add, Tanh, Sub, Mul, Add."""
    W, C, H, K = p.window, p.n_channels, p.hidden, p.n_classes
    g = Graph("gru_int8")
    xn = _normalise(g, p)
    # x_norm per channel -> int8, time-major (W, B, C) so that each step's slice is contiguous; its
    # scales are folded into W_ih (pattern B, s_a = 1). Two products (rows r,z and rows n) give the
    # gates' input parts without a gate Split.
    xq = quantize_channels(g, g.op("Transpose", xn, perm=[1, 0, 2]), g.const("act.x_norm.scale", q.s_x), C, q.act)
    rz_n = g.const("split.rz_n", [2 * H, H], np.int64)
    r_z = g.const("split.r_z", [H, H], np.int64)
    ones = g.const("split.steps", np.ones(W, np.int64), np.int64)
    wih_rz, wih_n = (g.const(f"gru.ih_{k}.weight_q", np.ascontiguousarray(q.w_ih.q[sl].T), np.int8)
                     for k, sl in (("rz", slice(0, 2 * H)), ("n", slice(2 * H, 3 * H))))
    gx_rz = int8_matmul(g, xq, None, wih_rz, g.const("gru.ih_rz.weight_scale", q.w_ih.scale[:2 * H]),
                        g.const("gru.bias_ih_rz", p.b_ih[:2 * H]), q.act)  # (W, B, 2H)
    gx_n = int8_matmul(g, xq, None, wih_n, g.const("gru.ih_n.weight_scale", q.w_ih.scale[2 * H:]),
                       g.const("gru.bias_ih_n", p.b_ih[2 * H:]), q.act)  # (W, B, H)
    # Each step's input part: two Split nodes for the whole window, (1, B, 2H) and (1, B, H) per step.
    x_rz, x_n = (g.node("Split", [t, ones], n_out=W, axis=0) for t in (gx_rz, gx_n))
    s_h = g.const("act.h.scale", q.s_h)
    whh, s_whh = int8_weight(g, "gru.hh", q.w_hh)
    b_hh = g.const("gru.bias_hh", p.b_hh)
    h = g.const("gru.h0", np.zeros((1, 1, H), np.float32))  # broadcasts against (1, B, H)
    for t in range(W):
        gh = int8_matmul(g, quantize(g, h, s_h, q.act), s_h, whh, s_whh, b_hh, q.act)
        gh_rz, gh_n = g.node("Split", [gh, rz_n], n_out=2, axis=2)
        r, z = g.node("Split", [g.op("Sigmoid", g.op("Add", x_rz[t], gh_rz)), r_z], n_out=2, axis=2)
        n = g.op("Tanh", g.op("Add", x_n[t], g.op("Mul", gh_n, r)))
        h = g.op("Add", g.op("Mul", g.op("Sub", h, n), z), n, name=f"h{t}")
        g.probe(f"h{t}", h, [1, BATCH, H])
    bh = g.const("head.bias", p.head_b)  # int8_linear's steps in its order (the graph's bytes), hq kept
    wh, s_wh = int8_weight(g, "head", q.head)
    hq = quantize(g, h, s_h, q.act)
    out = int8_matmul(g, hq, s_h, wh, s_wh, bh, q.act)
    g.op("Squeeze", out, g.const("axis0", [0], np.int64), name="logits")
    g.op("Softmax", "logits", name="proba", axis=-1)
    if p.motor_w is not None:
        g.op("Squeeze", motor_int8(g, hq, s_h, q.motor, p.motor_b, q.act, name=None), g.const("axis0", [0], np.int64),
             name=MOTOR_OUTPUT)
    doc = (f"quadfdi GRU (hidden {H}), int8 ({q.act} activations, MatMulIntegerToFloat, static scales), "
           f"unrolled over {W} steps; raw telemetry (batch, {W}, {C})")
    return g.finish([telemetry_input(W, C)], graph_outputs(K, p.motor_w is not None), opset, doc)
