"""The streaming CNODE (models/stream_cnode.py) as ONNX: one classic RK4 step, the state in and out.

Inputs ``z`` (batch, L) float32 (zeros at take-off or after a reset), ``prev`` and ``sample`` (batch, C)
float32 raw telemetry (the previous sample and the new one; at take-off the new one twice); outputs
``logits``, ``proba`` (batch, K) and ``z_new`` (batch, L):

    xp = (prev - mean) / std,  xn = (sample - mean) / std
    vp = xp @ W1u^T + b1,  vn = xn @ W1u^T + b1,  vm = (vp + vn) * 0.5     (batch, H)
    f(z, v) = lin2(tanh(z @ W1z^T + v)) - z * decay        (the leak; no term without one)
    z_new = core.rk4.rk4_step(f, 0, z, dt) with v = vp, vm, vm, vn at its 4 stages: the graph is
            RK4_PROGRAM with the float32 constants of rk4_constants(dt), built on graph values
            (export.onnx_cnode.GraphValue), as the windowed CNODE's graph
    logits = z_new @ Wh^T + bh,  proba = Softmax(logits)

int8 (``build_scnode(p, opset, q)``): every product one com.microsoft.MatMulIntegerToFloat on int8
activations (zero point 0, export/quantize.py), the RK4 combination, tanh and the control's midpoint in
float32: xp and xn quantized per channel (act.x_norm.scale folded into W1u); each stage's state with the
one calibrated act.z.scale (also the head's input); the field's hidden tanh with 1/127; vm, the bias-less
product W1z z_q and its Add of the stage's v as in the windowed CNODE's int8 graph. fwref/cnode_step.hpp
computes the same operations in the same order (int8 bit for bit).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from onnx import TensorProto, helper

from quadfdi.core.rk4 import RK4_CONSTANT_NAMES, rk4_constants, rk4_step
from quadfdi.export.graph import BATCH, Built, Graph
from quadfdi.export.onnx_cnode import GraphValue
from quadfdi.export.quantize import BOUND_SCALE, INT8, QWeight, act_scale, int8_matmul, int8_weight, quantize, quantize_channels

INPUTS = ("z", "prev", "sample")
OUTPUTS = ("logits", "proba", "z_new")


@dataclass(frozen=True)
class ScnodeParams:
    """A StreamCNODE's float32 numbers, PyTorch's (out, in) layouts."""

    mean: np.ndarray  # (C,)
    std: np.ndarray  # (C,)
    lin1_wz: np.ndarray  # (H, L)
    lin1_wu: np.ndarray  # (H, C)
    lin1_b: np.ndarray  # (H,)
    lin2_w: np.ndarray  # (L, H)
    lin2_b: np.ndarray  # (L,)
    head_w: np.ndarray  # (K, L)
    head_b: np.ndarray  # (K,)
    dt: float
    decay: np.ndarray | None = None  # (L,) softplus(decay_raw), float32; None: no leak

    @property
    def n_channels(self) -> int:
        return int(self.mean.shape[0])

    @property
    def latent(self) -> int:
        return int(self.lin2_b.shape[0])

    @property
    def hidden(self) -> int:
        return int(self.lin1_b.shape[0])

    @property
    def n_classes(self) -> int:
        return int(self.head_b.shape[0])

    @property
    def rk4(self) -> np.ndarray:
        """(4,) float32 [h/2, h, 2, h/6] of dt."""
        return rk4_constants(self.dt)


@dataclass(frozen=True)
class ScnodeQuant:
    """int8 weights (per-row scales) and static activation scales."""

    lin1_u: QWeight  # folded with s_x
    lin1_z: QWeight
    lin2: QWeight
    head: QWeight
    s_x: np.ndarray  # (C,) act.x_norm.scale
    s_z: np.ndarray  # () act.z.scale: every stage's state and the head's input
    s_hid: np.ndarray  # () 1/127: the field's tanh output


def scnode_params(model: torch.nn.Module) -> ScnodeParams:
    sd = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    lat = int(model.latent)
    decay = None if not model.leak else model.decay().detach().cpu().numpy().astype(np.float32)
    w1 = sd["field.lin1.weight"]  # (H, L + C): z's columns first
    return ScnodeParams(mean=sd["mean"], std=sd["std"], lin1_wz=np.ascontiguousarray(w1[:, :lat]),
                        lin1_wu=np.ascontiguousarray(w1[:, lat:]), lin1_b=sd["field.lin1.bias"],
                        lin2_w=sd["field.lin2.weight"], lin2_b=sd["field.lin2.bias"], head_w=sd["head.weight"],
                        head_b=sd["head.bias"], dt=float(model.dt), decay=decay)


@torch.no_grad()
def calibrate(model: torch.nn.Module, telemetry: np.ndarray) -> dict[str, np.ndarray]:
    """max |x_norm| per channel (C,) and max |state| over every RK4 stage and every step's result ()
    of streams from z = 0 on the flights ``telemetry`` (n, T, C), PyTorch float32."""
    x = torch.from_numpy(np.ascontiguousarray(telemetry, dtype=np.float32))
    x_norm = (x - model.mean) / model.std
    v = model.controls(x)
    z = torch.zeros(x.shape[0], model.latent)
    amax = torch.zeros(())
    at: dict = {}

    def f(t: float, zz: torch.Tensor) -> torch.Tensor:
        nonlocal amax
        amax = torch.maximum(amax, zz.abs().max())
        return model.vector_field(zz, at[t])

    v_prev = v[:, 0]
    for t in range(x.shape[1]):
        at.update({0.0: v_prev, 0.5 * model.dt: (v_prev + v[:, t]) * 0.5, model.dt: v[:, t]})
        z = rk4_step(f, 0.0, z, model.dt)
        amax = torch.maximum(amax, z.abs().max())
        v_prev = v[:, t]
    return {"x_norm": x_norm.abs().amax(dim=(0, 1)).numpy(), "z": amax.numpy()}


def quantize_scnode(p: ScnodeParams, ranges: dict[str, np.ndarray]) -> ScnodeQuant:
    s_x = act_scale(ranges["x_norm"])
    return ScnodeQuant(lin1_u=QWeight.folded(p.lin1_wu, s_x), lin1_z=QWeight.of(p.lin1_wz), lin2=QWeight.of(p.lin2_w),
                       head=QWeight.of(p.head_w), s_x=s_x, s_z=act_scale(ranges["z"]), s_hid=np.asarray(BOUND_SCALE))


def step_io(C: int, L: int, K: int) -> tuple[list, list]:
    inputs = [helper.make_tensor_value_info("z", TensorProto.FLOAT, [BATCH, L]),
              helper.make_tensor_value_info("prev", TensorProto.FLOAT, [BATCH, C]),
              helper.make_tensor_value_info("sample", TensorProto.FLOAT, [BATCH, C])]
    outputs = [helper.make_tensor_value_info(n, TensorProto.FLOAT, [BATCH, d]) for n, d in
               (("logits", K), ("proba", K), ("z_new", L))]
    return inputs, outputs


def _controls(g: Graph, p: ScnodeParams, q: ScnodeQuant | None) -> tuple[str, str, str]:
    """vp, vm, vn (batch, H): the u-part of lin1 at the previous sample, the midpoint and the new sample."""
    mean, std = g.const("norm.mean", p.mean), g.const("norm.std", p.std)
    vs = []
    for name in ("prev", "sample"):
        xn = g.op("Div", g.op("Sub", name, mean), std)
        if q is None:
            vs.append(g.op("Gemm", xn, g.const("lin1_u.weight", p.lin1_wu), g.const("lin1.bias", p.lin1_b), transB=1))
        else:
            w, s_w = int8_weight(g, "lin1_u", q.lin1_u)
            xq = quantize_channels(g, xn, g.const("act.x_norm.scale", q.s_x), p.n_channels, INT8)
            vs.append(int8_matmul(g, xq, None, w, s_w, g.const("lin1.bias", p.lin1_b), INT8))
    vm = g.op("Mul", g.op("Add", vs[0], vs[1]), g.const("control.half", np.float32(0.5)))
    return vs[0], vm, vs[1]


def build_scnode(p: ScnodeParams, opset: int, q: ScnodeQuant | None = None) -> Built:
    """The fp32 one-step graph (``q`` None) or the int8 one (module docstring)."""
    C, L, K = p.n_channels, p.latent, p.n_classes
    g = Graph("scnode_step" + ("_int8" if q else ""))
    vp, vm, vn = _controls(g, p, q)
    if q is None:
        w1z, w2 = g.const("lin1_z.weight", p.lin1_wz), g.const("lin2.weight", p.lin2_w)
    else:
        w1z, s_w1z = int8_weight(g, "lin1_z", q.lin1_z)
        w2, s_w2 = int8_weight(g, "lin2", q.lin2)
        s_z, s_hid = g.const("act.z.scale", q.s_z), g.const("act.hidden.scale", q.s_hid)
    b2 = g.const("lin2.bias", p.lin2_b)
    decay = None if p.decay is None else g.const("field.decay", p.decay)

    def f(z: str, v: str) -> str:
        if q is None:
            k = g.op("Gemm", g.op("Tanh", g.op("Gemm", z, w1z, v, transB=1)), w2, b2, transB=1)
        else:
            a = g.op("Add", int8_matmul(g, quantize(g, z, s_z, INT8), s_z, w1z, s_w1z, None, INT8), v)
            k = int8_matmul(g, quantize(g, g.op("Tanh", a), s_hid, INT8), s_hid, w2, s_w2, b2, INT8)
        return k if decay is None else g.op("Sub", k, g.op("Mul", z, decay))

    consts = {float(v): g.const(f"rk4.{n}", v) for n, v in zip(RK4_CONSTANT_NAMES, p.rk4)}
    at = {0.0: vp, 0.5 * p.dt: vm, p.dt: vn}  # rk4_step's stage times t, t + h/2, t + h

    def field(t: float, z: GraphValue) -> GraphValue:
        return GraphValue(g, consts, f(z.unit(), at[t]))

    z_new = g.op("Identity", rk4_step(field, 0.0, GraphValue(g, consts, "z"), p.dt).unit(), name="z_new")
    if q is None:
        g.op("Gemm", z_new, g.const("head.weight", p.head_w), g.const("head.bias", p.head_b), transB=1, name="logits")
    else:
        wh, s_wh = int8_weight(g, "head", q.head)
        int8_matmul(g, quantize(g, z_new, s_z, INT8), s_z, wh, s_wh, g.const("head.bias", p.head_b), INT8, name="logits")
    g.op("Softmax", "logits", name="proba", axis=-1)
    inputs, outputs = step_io(C, L, K)
    doc = (f"quadfdi streaming CNODE (latent {L}, field width {p.hidden}, dt {p.dt:g}), "
           f"{'int8 (MatMulIntegerToFloat, static scales)' if q else 'fp32'}, one classic RK4 step: z (batch, {L}), "
           f"prev, sample (batch, {C}) raw telemetry -> logits, proba (batch, {K}), z_new (batch, {L})")
    return g.finish(inputs, outputs, opset, doc)
