"""The CNODE as an ONNX graph: classic RK4 unrolled over N steps, fp32 or int8, built node by node.

Graph (batch-first; B the dynamic batch, W = 80 samples, C channels, L latent, H field width,
S = 2N + 1 stage times, K classes):

    x_norm = (telemetry - mean) / std                                  (B, W, C)
    U      = P @ x_norm                                                (B, S, C)   one constant matrix
    z0     = tanh(U[:, 0] @ We^T + be)                                 (B, L)      P's row 0 is sample 0
    V      = U @ W1u^T + b1                                            (B, S, H)   u-part of lin1, all stages
    f_e(z) = lin2(tanh(z @ W1z^T + V[:, idx(e)]))                      (B, L)      Gemm, Tanh, Gemm
    z1     = N classic RK4 steps of f over [0, 1] (core.rk4.rk4_step run on graph values)
    logits = z1 @ Wh^T + bh,  proba = softmax(logits)                  (B, K)

P = models.control.interp_matrix(models.solvers.stage_times("rk4", N)): the control path at every
stage time is one constant linear map of the window, so there is no Loop, If or data-dependent
indexing. Because f's first layer is linear in [z; u], its u-part for all S stage times is one
(B, S, C) x (C, H) product computed before the loop; each of the 4N stages then multiplies only
the latent state (L x H) and adds its precomputed row of V. Every weight is one initializer that
all 4N stages share. The int8 graph has the same topology with each product one
com.microsoft.MatMulIntegerToFloat on int8 activations (export/quantize.py; the row of V a separate
Add), the RK4 combination and the state kept in float32; it normalises only the samples P reads
(samples_read) and holds P_q as uint8 (interp_code_type). Per RK4 step the combination is 9 nodes:
three stage inputs (Mul, Add), one Sum ((k1 + 2 k2) + 2 k3) + k4, a Mul by h/6 and an Add; the
scaling of the field outputs lives in lin2's scales (exact, see GraphValue and field_scales); when
N is a power of two the combination is 7 nodes per step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from onnx import TensorProto

from quadfdi.core.rk4 import RK4_CONSTANT_NAMES, rk4_constants, rk4_step
from quadfdi.export.graph import BATCH, MS_DOMAIN, Built, Graph, telemetry_input
from quadfdi.export.motor_graph import graph_outputs, motor_fp32_gemm, motor_int8
from quadfdi.export.quantize import (BOUND_SCALE, UINT8, QWeight, act_scale, int8_matmul, int8_weight, quantize,
                             quantize_channels, quantize_interp, weight_qmax)
from quadfdi.models.control import interp_matrix
from quadfdi.models.solvers import fixed_method, nearest_index, stage_times

STAGES_PER_STEP = fixed_method("rk4").evals_per_step  # 4
# Activation encoding of the int8 CNODE after the control path: uint8 (zero point 128) with 7-bit
# weights, ONNX Runtime's u8 x s8 kernel. Measured on the trained paper-scale run (1188 test windows):
# macro-F1 drop 0.17 point (int8 / 8-bit: 0.09), target 0.5; batch-96 latency halved against int8
# activations (docs/formats.md, "Activation encoding"). x_norm and the exact P @ x_norm stay int8.
CNODE_ACT = UINT8


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
    motor_w: np.ndarray | None = None  # (4, L) the motor head (models.motor), None without one
    motor_b: np.ndarray | None = None  # (4,)

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


def is_pow2(x: float) -> bool:
    """x > 0 is a power of two (multiplying by it is exact in float32, barring under/overflow)."""
    return x > 0 and math.frexp(x)[0] == 0.5


class GraphValue:
    """A tensor of a graph under construction that core.rk4.rk4_step can compute with, so that the
    graph is RK4_PROGRAM evaluated operation by operation, in the program's order. How a value is
    represented may differ from the program's text, never its float32 results:

    - ``scale``: the tensor holds ``scale * value`` with ``scale`` a power of two (the field's lin2
      multiplied its scales and bias by a power of two, which is exact in float32).
    - ``value * c``: when c is a power of two the product is exact, so the same tensor is the
      result with scale ``scale / c`` (no node: ``k2 * two``, and ``k1 * half_h`` when N is a power
      of two); otherwise ``Mul(tensor, c / scale)`` (``c / scale`` exact) gives
      ``f32(scale v * c/scale) == f32(v * c)`` bit for bit, at scale 1.
    - ``a + b`` is kept pending and chained sums become ONE ``Sum`` node when the value is used
      (ONNX Runtime's Sum adds its inputs left to right: ``((k1 + two*k2) + two*k3) + k4`` exactly);
      a two-term sum is an ``Add``. Terms of one common scale are added as they are (a sum of
      values all scaled by the same power of two is that power times the sum, exactly), else each
      is brought to scale 1 first.
    - constants are float32 initializers (``consts``: value -> name; a constant divided by a
      scale is added under ``<name>/<scale>``).
    Exactness assumes no result underflows to a subnormal (|k| > 1e-37 or 0), as in any float32 run.
    """

    def __init__(self, g: Graph, consts: dict, name: str | None = None, terms: tuple = (), scale: float = 1.0):
        self.g, self.consts, self._name, self.terms, self.scale = g, consts, name, terms, scale
        if terms:
            same = all(t.scale == terms[0].scale for t in terms)
            self.scale = terms[0].scale if same else 1.0

    @property
    def name(self) -> str:
        """The tensor (materialising a pending sum once), holding ``scale * value``."""
        if self._name is None:
            op = "Add" if len(self.terms) == 2 else "Sum"
            same = all(t.scale == self.scale for t in self.terms)
            self._name = self.g.op(op, *((t.name if same else t.unit()) for t in self.terms))
            self.terms = ()
        return self._name

    def _const(self, value: float, label: str) -> str:
        v32 = float(np.float32(value))
        name = self.consts.get(v32) or self.g.const(label, np.float32(v32))
        self.consts.setdefault(v32, name)
        return name

    def unit(self) -> str:
        """A tensor holding the value itself (scale 1)."""
        if self.scale == 1.0:
            return self.name
        return self.g.op("Mul", self.name, self._const(1.0 / self.scale, f"rk4.unscale_{self.scale:g}"))

    def __add__(self, other: "GraphValue") -> "GraphValue":
        left = self.terms if self._name is None else (self,)
        return GraphValue(self.g, self.consts, terms=left + (other,))

    def __mul__(self, c: float) -> "GraphValue":
        c32 = float(np.float32(c))
        name = self.consts.get(c32)
        if name is None:
            raise ValueError(f"RK4 constant {c!r} is not one of rk4_constants (h)")
        if is_pow2(c32):  # v * c is exact: the same tensor, read at scale / c
            return GraphValue(self.g, self.consts, self.name, scale=self.scale / c32)
        if self.scale != 1.0:
            name = self._const(c32 / self.scale, f"{name}/{self.scale:g}")  # exact: the scale is a power of two
        return GraphValue(self.g, self.consts, self.g.op("Mul", self.name, name))


def field_scales(h: float) -> tuple[float, ...]:
    """The power of two each of a step's 4 field outputs is held at (lin2's scales and bias times it).

    rk4_step uses k1 as ``k1 * half_h`` and ``k1``, k2 as ``k2 * half_h`` and ``k2 * two``, k3 as
    ``k3 * h`` and ``k3 * two``, k4 as ``k4``. When h = 1/N is a power of two, holding (half_h k1,
    h k2, h k3, half_h k4) makes every one of these uses but ``k2 * half_h`` a free view, and the Sum
    of (k1, 2 k2, 2 k3, k4) is held at half_h: 7 nodes per step. Otherwise (k1, 2 k2, 2 k3, k4): 9."""
    half, full = (float(v) for v in rk4_constants(h)[:2])
    if is_pow2(half) and is_pow2(full):
        return (half, full, full, half)
    return (1.0, 2.0, 2.0, 1.0)


def rk4_stage_index(times: np.ndarray, steps: int) -> np.ndarray:
    """Row of the stage-time table for each of the 4N evaluations, in rk4_step's call order."""
    h = 1.0 / steps
    offsets = fixed_method("rk4").stage_offsets
    return np.array([nearest_index(times, k * h + c * h) for k in range(steps) for c in offsets], np.int32)


def cnode_params(model: torch.nn.Module, steps: int) -> CnodeParams:
    """Read a models.networks.CNODE's state dict (names are models/networks.py's contract)."""
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
        motor_w=sd.get("motor_head.weight"), motor_b=sd.get("motor_head.bias"),
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
    act: str = CNODE_ACT  # activations after the control path: "int8" (zp 0) or "uint8" (zp 128, 7-bit weights)
    motor: QWeight | None = None  # the motor head, reading the head's quantized z1 (scale s_z1)


def quantize_cnode(p: CnodeParams, ranges: dict[str, np.ndarray], act: str = "") -> CnodeQuant:
    """int8 weights of ``p`` and activation scales from calibrated ``ranges`` (max |x|); ``act`` the
    activation encoding of the products after the control path (CNODE_ACT by default)."""
    act = act or CNODE_ACT
    pq, ps, exact = quantize_interp(interp_matrix(p.times, p.window))  # float64: exactness is decidable
    s_u = act_scale(ranges["u"])
    qm = weight_qmax(act)
    return CnodeQuant(
        encoder=QWeight.folded(p.encoder_w, s_u, qm), lin1_z=QWeight.of(p.lin1_wz, qm),
        lin1_u=QWeight.folded(p.lin1_wu, s_u, qm), act=act,
        lin2=QWeight.of(p.lin2_w, qm), head=QWeight.of(p.head_w, qm), interp_q=pq, interp_scale=ps, interp_exact=exact,
        s_x=act_scale(ranges["x_norm"]), s_u=s_u,
        s_z=act_scale(np.array([ranges[f"stage{e}"] for e in range(p.n_stages)])),
        s_hid=np.asarray(BOUND_SCALE), s_z1=act_scale(ranges["z1"]),
        motor=None if p.motor_w is None else QWeight.of(p.motor_w, qm),
    )


def interp_code_type(interp_q: np.ndarray) -> type:
    """The element type of P_q in the graph: uint8 (zero point 0) when every code is >= 0, as for
    any interpolation matrix, else int8. The integers, and so the sums, are the same either way
    (weights.bin keeps int8), but u8 x s8 is ONNX Runtime's fast integer kernel and s8 x s8 its slow
    one (P @ x_norm at batch 96 took 16 % of the int8 CNODE's kernel time, now 6 %: docs/bench.md).
    Exact on AVX2's pairwise 16-bit products (vpmaddubsw): P_q <= 2N <= 126 for an exact P
    (quantize_interp), and 2 * 126 * 128 < 32767; a rounded P's codes reach 127: 2 * 127 * 128 < 32767."""
    return np.uint8 if int(interp_q.min()) >= 0 else np.int8


def samples_read(interp_q: np.ndarray) -> np.ndarray:
    """Indices (int64, ascending) of the window samples P has a nonzero weight for: at most 4N of the
    80 for classic RK4 (samples 0 and 79, and the two neighbours of each of the 2N - 1 stage times
    between: 32 for N = 8). The int8 graph normalises and quantizes only these: every value it uses is the same
    float32 operation on the same sample, the other samples had weight 0 (their integer products
    added 0), so the integers and outputs are unchanged; at batch 96 the int8 CNODE took 17 % less
    CPU time (docs/bench.md)."""
    return np.flatnonzero(np.any(np.asarray(interp_q) != 0, axis=0)).astype(np.int64)


def calibration_probes(p: CnodeParams) -> dict[str, str]:
    """Probe key -> reduction ('channel' over the last axis, or 'tensor') for calibration."""
    out = {"x_norm": "channel", "u": "channel", "z1": "tensor"}
    out.update({f"stage{e}": "tensor" for e in range(p.n_stages)})
    return out


def _control_path(g: Graph, p: CnodeParams, q: CnodeQuant | None, xn: str, row0: str) -> tuple[str, str, str]:
    """u = P @ x_norm (B, S, C), z0 = tanh(E u[:, 0] + b) (B, L) and V = u W1u^T + b1 (B, S, H): the
    part of the CNODE computed once per window, fp32 or int8."""
    C = p.n_channels
    if q is None:
        u = g.op("MatMul", g.const("interp", p.interp), xn, name="u")  # (B, S, C)
        u0 = g.op("Gather", u, row0, axis=1)  # (B, C) = x_norm[:, 0]: P's row 0 is sample 0
        z0 = g.op("Tanh", g.op("Gemm", u0, g.const("encoder.weight", p.encoder_w), g.const("encoder.bias", p.encoder_b),
                               transB=1), name="z0")
        v = g.op("Add", g.op("MatMul", u, g.const("lin1_u.weight_t", p.lin1_wu.T)), g.const("lin1.bias", p.lin1_b))
    else:
        # x_norm per channel -> int8; u[s, c] = f32(acc) * f32(s_P[s] * s_x[c]) (exact P when D <= 127):
        # one MatMulIntegerToFloat when s_P is one number (A = P_q, B = xq, per-column scale s_x).
        xq = quantize_channels(g, xn, g.const("act.x_norm.scale", q.s_x), C)  # xn: the samples P reads
        pq_read = np.ascontiguousarray(q.interp_q[:, samples_read(q.interp_q)])
        pq = g.const("interp.q", pq_read, interp_code_type(q.interp_q))
        if np.all(q.interp_scale == q.interp_scale[0]):
            u = g.op("MatMulIntegerToFloat", pq, xq, g.const("interp.scale", q.interp_scale[0]),
                     "act.x_norm.scale", domain=MS_DOMAIN, name="u")
        else:
            mult = (q.interp_scale[:, None] * q.s_x[None, :]).astype(np.float32)  # f32(s_P[s] * s_x[c])
            acc = g.op("MatMulInteger", pq, xq)  # (B, S, C) int32
            u = g.op("Mul", g.op("Cast", acc, to=TensorProto.FLOAT), g.const("interp.multiplier", mult), name="u")
        # U per channel -> int8, shared by the encoder and lin1_u (their weights carry s_u, folded)
        uq = quantize_channels(g, u, g.const("act.u.scale", q.s_u), C, q.act)
        enc_wq, enc_s = int8_weight(g, "encoder", q.encoder)
        z0 = g.op("Tanh", int8_matmul(g, g.op("Gather", uq, row0, axis=1), None, enc_wq, enc_s,
                                      g.const("encoder.bias", p.encoder_b), q.act), name="z0")
        w1u, s_w1u = int8_weight(g, "lin1_u", q.lin1_u)
        v = int8_matmul(g, uq, None, w1u, s_w1u, g.const("lin1.bias", p.lin1_b), q.act)
    return u, z0, v


def _head(g: Graph, p: CnodeParams, q: CnodeQuant | None, z: str) -> None:
    """logits = head(z1), fp32 Gemm or one int8 product; motor_logits likewise (export.motor_graph)."""
    if q is None:
        g.op("Gemm", z, g.const("head.weight", p.head_w), g.const("head.bias", p.head_b), transB=1, name="logits")
    else:
        wh, s_wh = int8_weight(g, "head", q.head)
        s_z1 = g.const("act.z1.scale", q.s_z1)
        zq = quantize(g, z, s_z1, q.act)
        int8_matmul(g, zq, s_z1, wh, s_wh, g.const("head.bias", p.head_b), q.act, name="logits")
    if p.motor_w is not None:
        motor_fp32_gemm(g, z, p.motor_w, p.motor_b) if q is None else motor_int8(g, zq, s_z1, q.motor, p.motor_b, q.act)


def build_cnode(p: CnodeParams, opset: int, q: CnodeQuant | None = None) -> Built:
    """The fp32 graph (``q`` None) or the int8 graph of ``p`` with N = p.steps RK4 steps.

    Batch-first 2-D tensors from the control path on: the state is (B, L), each stage's row of V
    (B, H) comes out of one Reshape and one Split, so that every fp32 product is a Gemm with its
    bias or row of V folded in, and every int8 product one MatMulIntegerToFloat."""
    W, C, L, K, S, H = p.window, p.n_channels, p.latent, p.n_classes, len(p.times), p.hidden
    g = Graph(f"cnode_rk4_{p.steps}" + ("_int8" if q else ""))
    mean, std = g.const("norm.mean", p.mean), g.const("norm.std", p.std)
    if q is None:
        xn = g.op("Div", g.op("Sub", "telemetry", mean), std, name="x_norm")
        g.probe("x_norm", xn, [BATCH, W, C])
    else:  # only the samples P reads (samples_read); the whole x_norm only where a probe asks for it
        read = g.op("Gather", "telemetry", g.const("window.samples_read", samples_read(q.interp_q), np.int64), axis=1)
        xn = g.op("Div", g.op("Sub", read, mean), std)
        g.probe_only("x_norm", [BATCH, W, C], lambda: g.op("Div", g.op("Sub", "telemetry", mean), std, name="x_norm"))
    row0 = g.const("gather.row0", np.int64(0), np.int64)
    v_shape = g.const("reshape.v", [0, S * H], np.int64)

    u, z0, v = _control_path(g, p, q, xn, row0)
    g.probe("u", u, [BATCH, S, C])
    g.probe("z0", z0, [BATCH, L])
    # (B, S, H) -> (B, S*H) -> S rows (B, H): one Reshape and one Split for the whole integration.
    v_rows = g.node("Split", [g.op("Reshape", v, v_shape), g.const("split.rows", np.full(S, H, np.int64), np.int64)],
                    n_out=S, axis=1)
    if q is not None:
        w1z, s_w1z = int8_weight(g, "lin1_z", q.lin1_z)
        w2, s_w2 = int8_weight(g, "lin2", q.lin2)
        s_hid = g.const("act.hidden.scale", q.s_hid)
    scales = field_scales(1.0 / p.steps)

    stage = [0]

    def f(z: str, row: int) -> tuple[str, float]:
        e = stage[0]
        stage[0] += 1
        scale = scales[e % STAGES_PER_STEP]
        g.probe(f"stage{e}", z, [BATCH, L])
        if q is None:
            a = g.op("Gemm", z, g.const("lin1_z.weight", p.lin1_wz), v_rows[row], transB=1)
            hid = g.op("Tanh", a)
            b2 = g.const("lin2.bias", p.lin2_b) if scale == 1.0 else g.const(f"lin2.bias_x{scale:g}",
                                                                              p.lin2_b * np.float32(scale))
            return g.op("Gemm", hid, g.const("lin2.weight", p.lin2_w), b2, transB=1, alpha=scale), scale
        s_z = g.const(f"act.stage{e}.scale", q.s_z[e])
        a = g.op("Add", int8_matmul(g, quantize(g, z, s_z, q.act), s_z, w1z, s_w1z, None, q.act), v_rows[row])
        hid_q = quantize(g, g.op("Tanh", a), s_hid, q.act)
        if scale == 1.0:
            return int8_matmul(g, hid_q, s_hid, w2, s_w2, g.const("lin2.bias", p.lin2_b), q.act), scale
        # f32(acc) * f32(s_hid * (c s_w)) + c b == c (f32(acc) * f32(s_hid * s_w) + b) for a power of two c
        s_w2c = g.const(f"lin2.weight_scale_x{scale:g}", q.lin2.scale * np.float32(scale))
        b2c = g.const(f"lin2.bias_x{scale:g}", p.lin2_b * np.float32(scale))
        return int8_matmul(g, hid_q, s_hid, w2, s_w2c, b2c, q.act), scale

    # core.rk4.rk4_step evaluated on graph values: the graph is RK4_PROGRAM by construction, with
    # its float32 constants as initializers named after RK4_CONSTANT_NAMES.
    h = 1.0 / p.steps
    consts = {float(v): g.const(f"rk4.{n}", v) for n, v in zip(RK4_CONSTANT_NAMES, rk4_constants(h))}
    rows = iter(p.stage_index.tolist())

    def field(t: float, z: GraphValue) -> GraphValue:
        row = next(rows)
        if abs(p.times[row] - t) > 1e-9:  # stage_index must follow rk4_step's calls
            raise ValueError(f"stage_index row {row} is time {p.times[row]}, rk4_step evaluates at {t}")
        k, scale = f(z.unit(), row)
        return GraphValue(g, consts, k, scale=scale)

    z = GraphValue(g, consts, z0)
    for k in range(p.steps):
        z = rk4_step(field, k * h, z, h)
    z = z.unit()
    g.probe("z1", z, [BATCH, L])

    _head(g, p, q, z)
    g.op("Softmax", "logits", name="proba", axis=-1)
    doc = (f"quadfdi CNODE, classic RK4 unrolled over N={p.steps} steps, "
           f"{'int8 (int8 activations, MatMulIntegerToFloat, static scales)' if q else 'fp32'}; "
           f"input raw telemetry (batch, {W}, {C})")
    return g.finish([telemetry_input(W, C)], graph_outputs(K, p.motor_w is not None), opset, doc)
