"""The streaming GRU's one step in int8 (inputs ``sample`` (B, C), ``h`` (B, H); outputs ``logits``,
``proba``, ``h_new``): the windowed int8 GRU's step (export/onnx_gru.py ``build_gru_int8``) with the
sequence one sample long and the start state an input.

    xq = quantize(x_norm / s_x) (per channel, folded into W_ih);  gx = MatMulIntegerToFloat(xq, W_ih') + b_ih
    gh = MatMulIntegerToFloat(quantize(h, 1/127), W_hh) + b_hh
    [r, z] = sigmoid(gx_rz + gh_rz);  n = tanh(gx_n + r * gh_n);  h_new = (h - n) * z + n
    logits = MatMulIntegerToFloat(quantize(h_new, 1/127), head) + head_b

s_x: max |x_norm| per channel over the calibration samples / 127 (``calibrate_x_norm``); h is a
convex combination of tanh outputs and of the input state, so |h| <= 1 holds only while the input
state does (a state the graph itself produced): its scale is the bound 1/127 as in the windowed graph.
"""

from __future__ import annotations

import numpy as np

from quadfdi.export.graph import BATCH, Built, Graph
from quadfdi.export.onnx_gru import GruParams, GruQuant
from quadfdi.export.onnx_sgru import step_io
from quadfdi.export.quantize import (
    int8_linear,
    int8_matmul,
    int8_weight,
    quantize,
    quantize_channels,
)


def calibrate_x_norm(p: GruParams, telemetry: np.ndarray) -> np.ndarray:
    """max |x_norm| per channel (C,) over raw samples ``telemetry`` (..., C), float32 arithmetic."""
    x = (np.asarray(telemetry, np.float32).reshape(-1, p.n_channels) - p.mean) / p.std
    return np.abs(x).max(axis=0)


def build_sgru_int8(p: GruParams, q: GruQuant, opset: int) -> Built:
    C, H, K = p.n_channels, p.hidden, p.n_classes
    g = Graph("sgru_step_int8")
    xn = g.op("Div", g.op("Sub", "sample", g.const("norm.mean", p.mean)), g.const("norm.std", p.std), name="x_norm")
    g.probe("x_norm", xn, [BATCH, C])
    xq = quantize_channels(g, xn, g.const("act.x_norm.scale", q.s_x), C, q.act)
    gx_rz, gx_n = (int8_matmul(g, xq, None, g.const(f"gru.ih_{k}.weight_q", np.ascontiguousarray(q.w_ih.q[sl].T), np.int8),
                               g.const(f"gru.ih_{k}.weight_scale", q.w_ih.scale[sl]), g.const(f"gru.bias_ih_{k}", p.b_ih[sl]),
                               q.act)
                   for k, sl in (("rz", slice(0, 2 * H)), ("n", slice(2 * H, 3 * H))))
    s_h = g.const("act.h.scale", q.s_h)
    whh, s_whh = int8_weight(g, "gru.hh", q.w_hh)
    gh = int8_matmul(g, quantize(g, "h", s_h, q.act), s_h, whh, s_whh, g.const("gru.bias_hh", p.b_hh), q.act)
    gh_rz, gh_n = g.node("Split", [gh, g.const("split.rz_n", [2 * H, H], np.int64)], n_out=2, axis=1)
    r, z = g.node("Split", [g.op("Sigmoid", g.op("Add", gx_rz, gh_rz)), g.const("split.r_z", [H, H], np.int64)],
                  n_out=2, axis=1)
    n = g.op("Tanh", g.op("Add", gx_n, g.op("Mul", gh_n, r)))
    h_new = g.op("Add", g.op("Mul", g.op("Sub", "h", n), z), n, name="h_new")
    out = int8_linear(g, h_new, s_h, "head", q.head, g.const("head.bias", p.head_b), q.act)
    g.op("Identity", out, name="logits")
    g.op("Softmax", "logits", name="proba", axis=-1)
    inputs, outputs = step_io(C, H, K)
    doc = (f"quadfdi streaming GRU (hidden {H}), int8 ({q.act} activations, MatMulIntegerToFloat, static scales), "
           f"one step: sample (batch, {C}), h (batch, {H}) -> logits, proba, h_new")
    return g.finish(inputs, outputs, opset, doc)
