"""The streaming GRU as ONNX: one step, the state in and out.

Inputs ``sample`` (batch, C) float32 raw telemetry and ``h`` (batch, H) float32, the state the
previous step returned (zeros at take-off or after a reset); outputs ``logits``, ``proba``
(batch, K) and ``h_new`` (batch, H):

    x_norm = (sample - mean) / std
    h_new  = GRU(x_norm as a one-sample sequence, initial_h = h)   ONNX GRU, linear_before_reset=1
    logits = h_new @ head.weight^T + head.bias,  proba = Softmax(logits)

The GRU operator, gate permutation and weight layout are those of the windowed GRU's fp32 graph
(export/onnx_gru.py); only the sequence is one sample long and the initial state an input.
"""

from __future__ import annotations

import numpy as np
import torch
from onnx import TensorProto, helper

from quadfdi.export.graph import BATCH, Built, Graph
from quadfdi.export.onnx_gru import GruParams, _onnx_gates

INPUTS = ("sample", "h")
OUTPUTS = ("logits", "proba", "h_new")


def sgru_params(model: torch.nn.Module) -> GruParams:
    """A models.stream_gru.StreamGRU's float32 numbers in the windowed GRU's layout (window 1: one step)."""
    sd = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    return GruParams(mean=sd["mean"], std=sd["std"], w_ih=sd["gru.weight_ih_l0"], w_hh=sd["gru.weight_hh_l0"],
                     b_ih=sd["gru.bias_ih_l0"], b_hh=sd["gru.bias_hh_l0"], head_w=sd["head.weight"],
                     head_b=sd["head.bias"], window=1)


def step_io(C: int, H: int, K: int) -> tuple[list, list]:
    """The one-step graph's signature, both precisions: inputs sample (batch, C), h (batch, H);
    outputs logits, proba (batch, K), h_new (batch, H)."""
    inputs = [helper.make_tensor_value_info("sample", TensorProto.FLOAT, [BATCH, C]),
              helper.make_tensor_value_info("h", TensorProto.FLOAT, [BATCH, H])]
    outputs = [helper.make_tensor_value_info(n, TensorProto.FLOAT, [BATCH, d]) for n, d in
               (("logits", K), ("proba", K), ("h_new", H))]
    return inputs, outputs


def build_sgru_fp32(p: GruParams, opset: int) -> Built:
    """The fp32 one-step graph (module docstring)."""
    C, H, K = p.n_channels, p.hidden, p.n_classes
    g = Graph("sgru_step")
    xn = g.op("Div", g.op("Sub", "sample", g.const("norm.mean", p.mean)), g.const("norm.std", p.std), name="x_norm")
    g.probe("x_norm", xn, [BATCH, C])
    axis0 = g.const("axis0", [0], np.int64)
    xs = g.op("Unsqueeze", xn, axis0)  # (1, B, C): a sequence of one sample
    h0 = g.op("Unsqueeze", "h", axis0)  # (1, B, H): num_directions first
    wb = np.concatenate([_onnx_gates(p.b_ih), _onnx_gates(p.b_hh)])[None]
    _, y_h = g.node("GRU", [xs, g.const("gru.W", _onnx_gates(p.w_ih)[None]), g.const("gru.R", _onnx_gates(p.w_hh)[None]),
                            g.const("gru.B", wb), "", h0], out=["h_seq", "h_last"], hidden_size=H,
                    linear_before_reset=1)
    h_new = g.op("Squeeze", y_h, axis0, name="h_new")
    logits = g.op("Add", g.op("MatMul", h_new, g.const("head.weight_t", p.head_w.T)), g.const("head.bias", p.head_b),
                  name="logits")
    g.op("Softmax", logits, name="proba", axis=-1)
    inputs, outputs = step_io(C, H, K)
    doc = (f"quadfdi streaming GRU (hidden {H}), fp32, one step: sample (batch, {C}) raw telemetry and state "
           f"h (batch, {H}) -> logits, proba (batch, {K}), h_new (batch, {H}); ONNX GRU linear_before_reset=1")
    return g.finish(inputs, outputs, opset, doc)
