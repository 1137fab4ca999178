"""The CNODE as an ONNX graph: classic RK4 unrolled over N steps, fp32 or int8, built node by node.

Graph (batch-first; B the dynamic batch, W = 80 samples, C channels, L latent, H field width,
S = 2N + 1 stage times, K classes):

    x_norm = (telemetry - mean) / std                                  (B, W, C)
    U      = P @ x_norm                                                (B, S, C)   one constant matrix
    z0     = tanh(U[:, 0:1] @ We^T + be)                               (B, 1, L)   P's row 0 is sample 0
    V      = U @ W1u^T + b1                                            (B, S, H)   u-part of lin1, all stages
    f_e(z) = lin2(tanh(z @ W1z^T + V[:, idx(e)]))                      (B, 1, L)
    z1     = N classic RK4 steps of f over [0, 1] (core.rk4.rk4_step run on graph values)
    logits = z1 @ Wh^T + bh,  proba = softmax(logits)                  (B, K)

P = train.control.interp_matrix(train.solvers.stage_times("rk4", N)): the control path at every
stage time is one constant linear map of the window, so there is no Loop, If or data-dependent
indexing. Because f's first layer is linear in [z; u], its u-part for all S stage times is one
(B, S, C) x (C, H) product computed before the loop; each of the 4N stages then multiplies only
the latent state (L x H) and adds its precomputed row of V. Every weight is one initializer that
all 4N stages share. The int8 graph has the same topology with each product on MatMulInteger
(export/quantize.py), the RK4 combination and the state kept in float32.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from onnx import TensorProto

from core.rk4 import RK4_CONSTANT_NAMES, rk4_constants, rk4_step
from export.graph import BATCH, Built, Graph, class_outputs, telemetry_input
from export.quantize import (BOUND_SCALE, QWeight, act_scale, int8_linear, int8_matmul, int8_weight,
                             quantize_channels, quantize_interp)
from train.control import interp_matrix
from train.solvers import fixed_method, nearest_index, stage_times

STAGES_PER_STEP = fixed_method("rk4").evals_per_step  # 4


@dataclass(frozen=True)
class CnodeParams:
    """A CNODE's float32 numbers for an N-step classic RK4 graph, in PyTorch's (out, in) layouts."""

    mean: np.ndarray  # (C,)
    std: np.ndarray  # (C,)
    encoder_w: np.ndarray  # (L, C)
    encoder_b: np.ndarray  # (L,)
    lin1_wz: np.ndarray  # (H, L)  columns of field.lin1.weight that multiply z
    lin1_wu: np.ndarray  # (H, C)  columns that multiply u
    lin1_b: np.ndarray  # (H,)
    lin2_w: np.ndarray  # (L, H)
    lin2_b: np.ndarray  # (L,)
    head_w: np.ndarray  # (K, L)
    head_b: np.ndarray  # (K,)
    steps: int  # N
    times: np.ndarray  # (S,) float64 stage times, S = 2N + 1
    interp: np.ndarray  # (S, W) float32, U = interp @ x_norm
    stage_index: np.ndarray  # (4N,) int32: row of interp used by stage e = 4k + i

    @property
    def n_channels(self) -> int:
        return int(self.mean.shape[0])

    @property
    def window(self) -> int:
        return int(self.interp.shape[1])

    @property
    def latent(self) -> int:
        return int(self.encoder_w.shape[0])

    @property
    def hidden(self) -> int:
        return int(self.lin1_b.shape[0])

    @property
    def n_classes(self) -> int:
        return int(self.head_b.shape[0])

    @property
    def n_stages(self) -> int:
        return STAGES_PER_STEP * self.steps


@dataclass(frozen=True)
class GraphValue:
    """A tensor of a graph under construction that core.rk4.rk4_step can compute with: ``+`` emits an
    Add node, ``*`` by a float a Mul node whose second input is the float32 constant of that value
    (``consts``: value -> initializer name). Evaluating rk4_step on it writes RK4_PROGRAM into the
    graph operation by operation, in the program's order."""

    g: Graph
    name: str
    consts: dict

    def __add__(self, other: "GraphValue") -> "GraphValue":
        return GraphValue(self.g, self.g.op("Add", self.name, other.name), self.consts)

    def __mul__(self, c: float) -> "GraphValue":
        name = self.consts.get(float(np.float32(c)))
        if name is None:
            raise ValueError(f"RK4 constant {c!r} is not one of rk4_constants (h)")
        return GraphValue(self.g, self.g.op("Mul", self.name, name), self.consts)


def rk4_stage_index(times: np.ndarray, steps: int) -> np.ndarray:
    """Row of the stage-time table for each of the 4N evaluations, in rk4_step's call order."""
    h = 1.0 / steps
    offsets = fixed_method("rk4").stage_offsets
    return np.array([nearest_index(times, k * h + c * h) for k in range(steps) for c in offsets], np.int32)


def cnode_params(model: torch.nn.Module, steps: int) -> CnodeParams:
    """Read a train.models.CNODE's state dict (names are train/models.py's contract)."""
    sd = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    latent = sd["encoder.weight"].shape[0]
    w1 = sd["field.lin1.weight"]  # (H, L + C): [z, u] concatenated in this order
    times = stage_times("rk4", steps)
    return CnodeParams(
        mean=sd["mean"], std=sd["std"], encoder_w=sd["encoder.weight"], encoder_b=sd["encoder.bias"],
        lin1_wz=np.ascontiguousarray(w1[:, :latent]), lin1_wu=np.ascontiguousarray(w1[:, latent:]),
        lin1_b=sd["field.lin1.bias"], lin2_w=sd["field.lin2.weight"], lin2_b=sd["field.lin2.bias"],
        head_w=sd["head.weight"], head_b=sd["head.bias"], steps=int(steps), times=times,
        interp=interp_matrix(times, int(model.window)).astype(np.float32),
        stage_index=rk4_stage_index(times, steps),
    )


@dataclass(frozen=True)
class CnodeQuant:
    """The int8 CNODE: int8 weights with per-output-channel scales, static activation scales."""

    encoder: QWeight  # folded: encoder.weight diag(s_u)
    lin1_z: QWeight
    lin1_u: QWeight  # folded: lin1_u weight diag(s_u)
    lin2: QWeight
    head: QWeight
    interp_q: np.ndarray  # (S, W) int8
    interp_scale: np.ndarray  # (S,) float32, P = interp_q * interp_scale[:, None]
    interp_exact: bool
    s_x: np.ndarray  # (C,) x_norm, per channel (P sums over time, so a channel scale factors out)
    s_u: np.ndarray  # (C,) the control U, per channel, folded into the encoder and lin1_u weights
    s_z: np.ndarray  # (4N,) the latent state entering each stage
    s_hid: np.ndarray  # () tanh output of the field's hidden layer: bound 1/127
    s_z1: np.ndarray  # () z1 entering the head


def quantize_cnode(p: CnodeParams, ranges: dict[str, np.ndarray]) -> CnodeQuant:
    """int8 weights of ``p`` and activation scales from calibrated ``ranges`` (max |x|)."""
    pq, ps, exact = quantize_interp(interp_matrix(p.times, p.window))  # float64: exactness is decidable
    s_u = act_scale(ranges["u"])
    return CnodeQuant(
        encoder=QWeight.folded(p.encoder_w, s_u), lin1_z=QWeight.of(p.lin1_wz), lin1_u=QWeight.folded(p.lin1_wu, s_u),
        lin2=QWeight.of(p.lin2_w), head=QWeight.of(p.head_w), interp_q=pq, interp_scale=ps, interp_exact=exact,
        s_x=act_scale(ranges["x_norm"]), s_u=s_u,
        s_z=act_scale(np.array([ranges[f"stage{e}"] for e in range(p.n_stages)])),
        s_hid=np.asarray(BOUND_SCALE), s_z1=act_scale(ranges["z1"]),
    )


def calibration_probes(p: CnodeParams) -> dict[str, str]:
    """Probe key -> reduction ('channel' over the last axis, or 'tensor') for calibration."""
    out = {"x_norm": "channel", "u": "channel", "z1": "tensor"}
    out.update({f"stage{e}": "tensor" for e in range(p.n_stages)})
    return out


def build_cnode(p: CnodeParams, opset: int, q: CnodeQuant | None = None) -> Built:
    """The fp32 graph (``q`` None) or the int8 graph of ``p`` with N = p.steps RK4 steps."""
    W, C, L, K, S = p.window, p.n_channels, p.latent, p.n_classes, len(p.times)
    g = Graph(f"cnode_rk4_{p.steps}" + ("_int8" if q else ""))
    xn = g.op("Div", g.op("Sub", "telemetry", g.const("norm.mean", p.mean)), g.const("norm.std", p.std), name="x_norm")
    g.probe("x_norm", xn, [BATCH, W, C])
    first = [g.const("slice.start0", [0], np.int64), g.const("slice.end1", [1], np.int64),
             g.const("axis1", [1], np.int64)]

    if q is None:
        u = g.op("MatMul", g.const("interp", p.interp), xn, name="u")  # (B, S, C)
        u0 = g.op("Slice", u, *first)  # (B, 1, C) = x_norm[:, 0:1]: P's row 0 is sample 0
        z0 = g.op("Tanh", g.op("Add", g.op("MatMul", u0, g.const("encoder.weight_t", p.encoder_w.T)),
                                g.const("encoder.bias", p.encoder_b)), name="z0")
        v = g.op("Add", g.op("MatMul", u, g.const("lin1_u.weight_t", p.lin1_wu.T)), g.const("lin1.bias", p.lin1_b))
    else:
        # x_norm per channel -> int8; U = (float(Pq @ xq) * s_P[s]) * s_x[c]  (exact P when D <= 127)
        xq = quantize_channels(g, xn, g.const("act.x_norm.scale", q.s_x), C)
        acc = g.op("MatMulInteger", g.const("interp.q", q.interp_q, np.int8), xq)  # (B, S, C) int32
        u = g.op("Cast", acc, to=TensorProto.FLOAT)
        u = g.op("Mul", u, g.const("interp.scale", q.interp_scale[:, None]))
        u = g.op("Mul", u, "act.x_norm.scale", name="u")
        # U per channel -> int8, shared by the encoder and lin1_u (their weights carry s_u, folded)
        uq = quantize_channels(g, u, g.const("act.u.scale", q.s_u), C)
        enc_wq, enc_s = int8_weight(g, "encoder", q.encoder)
        z0 = g.op("Tanh", int8_matmul(g, g.op("Slice", uq, *first), None, enc_wq, enc_s,
                                      g.const("encoder.bias", p.encoder_b)), name="z0")
        w1u, s_w1u = int8_weight(g, "lin1_u", q.lin1_u)
        v = int8_matmul(g, uq, None, w1u, s_w1u, g.const("lin1.bias", p.lin1_b))
    g.probe("u", u, [BATCH, S, C])
    g.probe("z0", z0, [BATCH, 1, L])
    # One Split gives the S rows of V as (B, 1, H) tensors; the state stays (B, 1, L) throughout.
    v_rows = g.node("Split", [v, g.const("split.ones", np.ones(S, np.int64), np.int64)], n_out=S, axis=1)

    stage = [0]

    def f(z: str, row: int) -> str:
        e = stage[0]
        stage[0] += 1
        g.probe(f"stage{e}", z, [BATCH, 1, L])
        if q is None:
            a = g.op("Add", g.op("MatMul", z, g.const("lin1_z.weight_t", p.lin1_wz.T)), v_rows[row])
            hid = g.op("Tanh", a)
            k = g.op("MatMul", hid, g.const("lin2.weight_t", p.lin2_w.T))
            return g.op("Add", k, g.const("lin2.bias", p.lin2_b))
        a = int8_linear(g, z, g.const(f"act.stage{e}.scale", q.s_z[e]), "lin1_z", q.lin1_z, v_rows[row])
        hid = g.op("Tanh", a)
        return int8_linear(g, hid, g.const("act.hidden.scale", q.s_hid), "lin2", q.lin2, g.const("lin2.bias", p.lin2_b))

    # core.rk4.rk4_step evaluated on graph values: the graph is RK4_PROGRAM by construction, with
    # its float32 constants as initializers named after RK4_CONSTANT_NAMES.
    h = 1.0 / p.steps
    consts = {float(v): g.const(f"rk4.{n}", v) for n, v in zip(RK4_CONSTANT_NAMES, rk4_constants(h))}
    rows = iter(p.stage_index.tolist())

    def field(t: float, z: GraphValue) -> GraphValue:
        row = next(rows)
        if abs(p.times[row] - t) > 1e-9:  # stage_index must follow rk4_step's calls
            raise ValueError(f"stage_index row {row} is time {p.times[row]}, rk4_step evaluates at {t}")
        return GraphValue(g, f(z.name, row), consts)

    z = GraphValue(g, z0, consts)
    for k in range(p.steps):
        z = rk4_step(field, k * h, z, h)
    z = z.name
    g.probe("z1", z, [BATCH, 1, L])

    if q is None:
        out = g.op("Add", g.op("MatMul", z, g.const("head.weight_t", p.head_w.T)), g.const("head.bias", p.head_b))
    else:
        out = int8_linear(g, z, g.const("act.z1.scale", q.s_z1), "head", q.head, g.const("head.bias", p.head_b))
    logits = g.op("Squeeze", out, "axis1", name="logits")
    g.op("Softmax", logits, name="proba", axis=-1)
    doc = (f"quadfdi CNODE, classic RK4 unrolled over N={p.steps} steps, "
           f"{'int8 (MatMulInteger, static scales)' if q else 'fp32'}; input raw telemetry (batch, {W}, {C})")
    return g.finish([telemetry_input(W, C)], class_outputs(K), opset, doc)
