"""The GRU baseline as ONNX: an fp32 graph on the ONNX ``GRU`` operator, an int8 graph in one ``Scan``.

fp32: x_norm -> Transpose to (W, B, C) -> GRU(linear_before_reset=1) -> last hidden -> head.
PyTorch's GRU multiplies the reset gate AFTER the recurrent product,
n = tanh(W_in x + b_in + r * (W_hn h + b_hn)), which is ONNX's ``linear_before_reset=1``; the
default 0 computes W_hn (r * h) instead, a different function (an exporter once wrote it).
ONNX orders the gates z, r, h where PyTorch orders them r, z, n: the rows are permuted here.

int8: ONNX Runtime has no quantized GRU operator (a ``GRU`` node stays fp32 whatever a quantizer
is told), so the int8 graph writes the W = 80 steps in operators that quantize, one ``Scan`` whose
body is one step (ONNX Runtime pays per node: unrolled it is 972 nodes, export/onnx_gru_unrolled.py,
bit-identical):

    GX = int8(x_norm) @ W_ih^T + b_ih (MatMulIntegerToFloat, rows r,z and rows n)  (W, B, 3H)
         (x_norm quantized per channel, the channel scales folded into W_ih)
    step t:  gh = int8(h) @ W_hh^T + b_hh (MatMulIntegerToFloat, W_hh stored once)  (B, 3H)
             [r, z] = sigmoid(gx_rz + gh_rz)   (one Add, one Sigmoid over 2H, one Split)
             n = tanh(gx_n + r * gh_n),  h' = (h - n) * z + n     (PyTorch's GRU cell, in that order)

Activations are uint8 with zero point 128 and 7-bit weights (GRU_ACT; the integer sums equal the
int8 ones, see export/quantize.py). h starts at 0 and is a convex combination of tanh outputs, so
|h| <= 1 (up to float32 rounding): its scale is the bound 1/127, no calibration needed; only
x_norm's scales are calibrated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from onnx import GraphProto, TensorProto, helper, numpy_helper

from quadfdi.export.graph import BATCH, Built, Graph, telemetry_input
from quadfdi.export.motor_graph import graph_outputs, motor_fp32_matmul, motor_int8
from quadfdi.export.quantize import (BOUND_SCALE, UINT8, QWeight, act_scale, int8_matmul, int8_weight, quantize,
                             quantize_channels, weight_qmax)

# Activation encoding of the int8 GRU: uint8 (zero point 128) with 7-bit weights takes ONNX Runtime's
# u8 x s8 kernel; measured on the trained paper-scale GRU (docs/formats.md, "int8 arithmetic").
GRU_ACT = UINT8


@dataclass(frozen=True)
class GruParams:
    """A GRUClassifier's float32 numbers in PyTorch's layouts (gate rows r, z, n)."""

    mean: np.ndarray  # (C,)
    std: np.ndarray  # (C,)
    w_ih: np.ndarray  # (3H, C)
    w_hh: np.ndarray  # (3H, H)
    b_ih: np.ndarray  # (3H,)
    b_hh: np.ndarray  # (3H,)
    head_w: np.ndarray  # (K, H)
    head_b: np.ndarray  # (K,)
    window: int
    motor_w: np.ndarray | None = None  # (4, H) the motor head (models.motor), None without one
    motor_b: np.ndarray | None = None  # (4,)

    @property
    def n_channels(self) -> int:
        return int(self.mean.shape[0])

    @property
    def hidden(self) -> int:
        return int(self.w_hh.shape[1])

    @property
    def n_classes(self) -> int:
        return int(self.head_b.shape[0])


def gru_params(model: torch.nn.Module) -> GruParams:
    """Read a models.networks.GRUClassifier's state dict (one layer, unidirectional)."""
    sd = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    return GruParams(mean=sd["mean"], std=sd["std"], w_ih=sd["gru.weight_ih_l0"], w_hh=sd["gru.weight_hh_l0"],
                     b_ih=sd["gru.bias_ih_l0"], b_hh=sd["gru.bias_hh_l0"], head_w=sd["head.weight"],
                     head_b=sd["head.bias"], window=int(model.window), motor_w=sd.get("motor_head.weight"),
                     motor_b=sd.get("motor_head.bias"))


@dataclass(frozen=True)
class GruQuant:
    """The int8 GRU: int8 weights (per output channel) and static activation scales."""

    w_ih: QWeight  # folded: W_ih diag(s_x)
    w_hh: QWeight
    head: QWeight
    s_x: np.ndarray  # (C,) x_norm per channel, calibrated, folded into w_ih
    s_h: np.ndarray  # () the hidden state, bound 1/127
    act: str = GRU_ACT  # activation encoding: "uint8" (zp 128, 7-bit weights) or "int8" (zp 0)
    motor: QWeight | None = None  # the motor head, reading the head's quantized h_W (scale s_h)


def quantize_gru(p: GruParams, ranges: dict[str, np.ndarray], act: str = GRU_ACT) -> GruQuant:
    s_x = act_scale(ranges["x_norm"])
    qmax = weight_qmax(act)
    return GruQuant(w_ih=QWeight.folded(p.w_ih, s_x, qmax), w_hh=QWeight.of(p.w_hh, qmax),
                    head=QWeight.of(p.head_w, qmax), s_x=s_x, s_h=np.asarray(BOUND_SCALE), act=act,
                    motor=None if p.motor_w is None else QWeight.of(p.motor_w, qmax))


CALIBRATION_PROBES = {"x_norm": "channel"}


def _onnx_gates(a: np.ndarray) -> np.ndarray:
    """PyTorch gate blocks (r, z, n) along axis 0 -> ONNX order (z, r, h)."""
    r, z, n = np.split(a, 3, axis=0)
    return np.concatenate([z, r, n], axis=0)


def _normalise(g: Graph, p: GruParams) -> str:
    xn = g.op("Div", g.op("Sub", "telemetry", g.const("norm.mean", p.mean)), g.const("norm.std", p.std), name="x_norm")
    g.probe("x_norm", xn, [BATCH, p.window, p.n_channels])
    return xn


def build_gru_fp32(p: GruParams, opset: int, linear_before_reset: int = 1) -> Built:
    """fp32 graph on the ONNX GRU operator. ``linear_before_reset`` is a parameter only so that a
    test can build the wrong graph and see the parity check fail; PyTorch's GRU is 1."""
    W, C, H, K = p.window, p.n_channels, p.hidden, p.n_classes
    g = Graph("gru")
    xn = _normalise(g, p)
    xs = g.op("Transpose", xn, perm=[1, 0, 2])  # (W, B, C): the GRU operator's default layout
    wb = np.concatenate([_onnx_gates(p.b_ih), _onnx_gates(p.b_hh)])[None]  # (1, 6H): Wb then Rb
    w_r_b = [g.const("gru.W", _onnx_gates(p.w_ih)[None]), g.const("gru.R", _onnx_gates(p.w_hh)[None]),
             g.const("gru.B", wb)]
    y, y_h = g.node("GRU", [xs, *w_r_b], out=["h_all", "h_last"], hidden_size=H, linear_before_reset=linear_before_reset)
    g.probe("h_all", y, [W, 1, BATCH, H])  # (W, num_directions, B, H)
    last = g.op("Squeeze", y_h, g.const("axis0", [0], np.int64))  # (B, H)
    out = g.op("Add", g.op("MatMul", last, g.const("head.weight_t", p.head_w.T)), g.const("head.bias", p.head_b),
               name="logits")
    g.op("Softmax", out, name="proba", axis=-1)
    if p.motor_w is not None:
        motor_fp32_matmul(g, last, p.motor_w, p.motor_b)
    doc = (f"quadfdi GRU (hidden {H}), fp32, ONNX GRU linear_before_reset={linear_before_reset}; "
           f"raw telemetry (batch, {W}, {C})")
    return g.finish([telemetry_input(W, C)], graph_outputs(K, p.motor_w is not None), opset, doc)



def input_part(g: Graph, p: GruParams, q: GruQuant) -> tuple[str, str]:
    """The gates' input part of every step, time-major: GX_rz (W, B, 2H) and GX_n (W, B, H).

    x_norm per channel -> int8, transposed to (W, B, C) so that each step's slice is contiguous; its
    scales are folded into W_ih (pattern B, s_a = 1). Two products (rows r,z and rows n) give the
    gates' input parts without a gate Split."""
    C, H = p.n_channels, p.hidden
    xn = _normalise(g, p)
    xq = quantize_channels(g, g.op("Transpose", xn, perm=[1, 0, 2]), g.const("act.x_norm.scale", q.s_x), C, q.act)
    wih_rz, wih_n = (g.const(f"gru.ih_{k}.weight_q", np.ascontiguousarray(q.w_ih.q[sl].T), np.int8)
                     for k, sl in (("rz", slice(0, 2 * H)), ("n", slice(2 * H, 3 * H))))
    gx_rz = int8_matmul(g, xq, None, wih_rz, g.const("gru.ih_rz.weight_scale", q.w_ih.scale[:2 * H]),
                        g.const("gru.bias_ih_rz", p.b_ih[:2 * H]), q.act)
    gx_n = int8_matmul(g, xq, None, wih_n, g.const("gru.ih_n.weight_scale", q.w_ih.scale[2 * H:]),
                       g.const("gru.bias_ih_n", p.b_ih[2 * H:]), q.act)
    return gx_rz, gx_n


def gru_step(g: Graph, p: GruParams, q: GruQuant, h: str, x_rz: str, x_n: str, name: str | None = None) -> str:
    """One int8 step, 12 nodes, PyTorch's GRU cell in this order: QuantizeLinear(h),
    MatMulIntegerToFloat (+ b_hh), Split(gh -> rz | n), Add and Sigmoid over the r and z gates
    together, Split(r | z), Mul, Add, Tanh (n = tanh(gx_n + gh_n * r)), Sub, Mul, Add
    (h' = (h - n) * z + n). The gate axis is the last one, whatever the rank of h."""
    H = p.hidden
    s_h = g.const("act.h.scale", q.s_h)
    whh, s_whh = int8_weight(g, "gru.hh", q.w_hh)
    gh = int8_matmul(g, quantize(g, h, s_h, q.act), s_h, whh, s_whh, g.const("gru.bias_hh", p.b_hh), q.act)
    gh_rz, gh_n = g.node("Split", [gh, g.const("split.rz_n", [2 * H, H], np.int64)], n_out=2, axis=-1)
    r, z = g.node("Split", [g.op("Sigmoid", g.op("Add", x_rz, gh_rz)), g.const("split.r_z", [H, H], np.int64)],
                  n_out=2, axis=-1)
    n = g.op("Tanh", g.op("Add", x_n, g.op("Mul", gh_n, r)))
    return g.op("Add", g.op("Mul", g.op("Sub", h, n), z), n, name=name)


def _step_body(g: Graph, p: GruParams, q: GruQuant, prefix: str, per_step: bool) -> GraphProto:
    """The Scan body: inputs h (B, H), gx_rz (B, 2H), gx_n (B, H); output h', and with ``per_step``
    h' again for the Scan's per-step output (through an Identity: a graph output name appears once).

    Its constants (W_hh^T, scales, zero point, b_hh, split sizes) are the body's own initializers,
    named ``<prefix>/<name>`` (no outer name is shadowed): read from the outer scope instead, the same
    graph took 1.23x the time at batch 1 (docs/bench.md, "The int8 GRU in one Scan"). Node and tensor
    names come from ``g``'s counters, so they are unique in the whole model."""
    H, f = p.hidden, TensorProto.FLOAT
    body = Graph(f"gru_int8_{prefix}", _count=g._count)
    h, x_rz, x_n = f"{prefix}.h", f"{prefix}.gx_rz", f"{prefix}.gx_n"
    h_new = gru_step(body, p, q, h, x_rz, x_n, name=f"{prefix}.h_new")
    outs = [h_new] + ([body.op("Identity", h_new, name=f"{prefix}.h_out")] if per_step else [])
    local = {k: f"{prefix}/{k}" for k in body.inits}
    for n in body.nodes:
        n.input[:] = [local.get(i, i) for i in n.input]
    shapes = {h: H, x_rz: 2 * H, x_n: H, **{o: H for o in outs}}
    info = [helper.make_tensor_value_info(k, f, [BATCH, shapes[k]]) for k in (h, x_rz, x_n, *outs)]
    inits = [numpy_helper.from_array(v, local[k]) for k, v in body.inits.items()]
    return helper.make_graph(body.nodes, f"gru_int8_{prefix}", info[:3], info[3:], inits)


def _zeros_bh(g: Graph, H: int) -> str:
    """h0: float32 zeros (B, H), B the input's batch size (a Scan's state keeps its shape)."""
    batch = g.op("Shape", "telemetry", start=0, end=1)
    shape = g.op("Concat", batch, g.const("gru.h_shape_tail", [H], np.int64), axis=0)
    return g.op("ConstantOfShape", shape, value=helper.make_tensor("zero", TensorProto.FLOAT, [1], [0.0]))


def build_gru_int8(p: GruParams, q: GruQuant, opset: int) -> Built:
    """int8 graph: the recurrence in ONE Scan node whose body is the 12-node step (``gru_step``), the
    hidden state its state variable, GX_rz and GX_n its scanned inputs; every product one
    MatMulIntegerToFloat. Bit-identical to the unrolled graph (export/onnx_gru_unrolled.py: the same
    float32 operations in the same order on every element). The probe ``h_all`` (W, B, H), every
    step's hidden state, is a second Scan whose body also outputs h' per step: it runs only in the
    probed copy (``Built.with_probes``), the shipped body has no per-step output (5 % faster at batch 1)."""
    W, C, H, K = p.window, p.n_channels, p.hidden, p.n_classes
    g = Graph("gru_int8")
    gx_rz, gx_n = input_part(g, p, q)
    h0 = _zeros_bh(g, H)
    (h,) = g.node("Scan", [h0, gx_rz, gx_n], out=["h_last"], body=_step_body(g, p, q, "step", False),
                  num_scan_inputs=2)
    g.probe_only("h_all", [W, BATCH, H], lambda: g.node(
        "Scan", [h0, gx_rz, gx_n], out=["h_last_probe", "h_all"], body=_step_body(g, p, q, "probe_step", True),
        num_scan_inputs=2)[1])
    s_h = g.const("act.h.scale", q.s_h)
    bh = g.const("head.bias", p.head_b)  # int8_linear's steps in its order (the graph's bytes), hq kept
    wh, s_wh = int8_weight(g, "head", q.head)
    hq = quantize(g, h, s_h, q.act)
    g.op("Softmax", int8_matmul(g, hq, s_h, wh, s_wh, bh, q.act, name="logits"), name="proba", axis=-1)
    if p.motor_w is not None:
        motor_int8(g, hq, s_h, q.motor, p.motor_b, q.act)
    doc = (f"quadfdi GRU (hidden {H}), int8 ({q.act} activations, MatMulIntegerToFloat, static scales), "
           f"the {W} steps in one Scan; raw telemetry (batch, {W}, {C})")
    return g.finish([telemetry_input(W, C)], graph_outputs(K, p.motor_w is not None), opset, doc)
