"""The int8 scheme: how weights and activations become int8, and the node pattern of one product.

One scheme for both models, written so that a C++ reference can redo it integer for integer
(docs/formats.md, "int8 arithmetic"):

- Weights: symmetric, per output channel (a row of PyTorch's (out, in) matrix), zero point 0:
  ``s_w[o] = max_i |W[o, i]| / 127`` (1.0 for an all-zero row), ``Wq = clip(rne(W / s_w), -127, 127)``
  with float32 division and round-half-to-even, the rounding of ONNX ``QuantizeLinear``.
- The CNODE's interpolation matrix P (rows of at most two weights ``1 - w`` and ``w``, with w a
  multiple of 1/(2N) for classic RK4 over the 79 sample intervals): stored EXACTLY as
  ``P = Pq / D`` when a denominator D <= 127 exists (D = 2N or a divisor of it), so the control
  path costs no rounding; otherwise per-row symmetric like a weight.
- Activations: symmetric, zero point 0, int8 with saturation to [-128, 127], static scales so a
  window's result never depends on its batch. Bounded activations (tanh outputs, the GRU's
  hidden state, all in [-1, 1]) use ``1/127``; the others use ``max|x| / 127`` over the
  calibration windows (export/calibrate.py), per tensor or per channel.
- Per-channel activations (the normalised telemetry and the control path, whose channels span
  very different ranges: body rates reach 20 sigma in a fault, most channels stay within 5):
  a product that sums over channels cannot apply a per-channel scale after the integer sum, so
  the scale is folded into the weight instead, ``W' = W diag(s_x)``, which is then quantized per
  output row like any weight; the int8 activation multiplies W'q directly. (Measured on a
  trained GRU: one per-tensor scale for x cost 0.84 macro-F1 points, the folded per-channel
  scales none.)
- One product: ``q = QuantizeLinear(x, s_a, 0)`` (round(x / s_a) half to even, saturated),
  ``acc = MatMulInteger(q, WqT)`` (int32, exact), then in float32
  ``y = ((float(acc) * s_a) * s_w) + b`` for a per-tensor s_a (two Muls and an Add, in that
  order), or ``y = (float(acc) * s_w') + b`` for a folded per-channel s_a.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from onnx import TensorProto

from export.graph import Graph

QMAX = 127  # weights use [-127, 127] (symmetric); activations saturate to [-128, 127]
BOUND_SCALE = np.float32(1.0 / QMAX)  # scale of activations bounded by 1 in magnitude (tanh, GRU h)


def rne_div(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """round_half_even(x / scale) in float32 arithmetic, as ONNX Runtime's QuantizeLinear does it."""
    return np.rint(np.asarray(x, np.float32) / np.asarray(scale, np.float32))


def quantize_act(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """QuantizeLinear(x, scale, zero point 0) to int8: float32 division, half-to-even, saturation."""
    return np.clip(rne_div(x, scale), -128, 127).astype(np.int8)


def quantize_weight(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(out, in) float weight -> (Wq int8 (out, in), s_w float32 (out,)), per output channel."""
    w = np.asarray(w, np.float32)
    amax = np.abs(w).max(axis=1)
    scale = np.where(amax > 0, amax / np.float32(QMAX), np.float32(1.0)).astype(np.float32)
    q = np.clip(rne_div(w, scale[:, None]), -QMAX, QMAX).astype(np.int8)
    return q, scale


def quantize_interp(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """(S, W) interpolation matrix -> (Pq int8, per-row scale float32 (S,), exact?).

    Exact when every entry is a multiple of 1/D for one D <= 127 (classic RK4 with N <= 63: D
    divides 2N); the scale is then float32(1/D) for every row.
    """
    p = np.asarray(p, np.float64)
    for d in range(1, QMAX + 1):
        scaled = p * d
        if np.abs(scaled - np.rint(scaled)).max() < 1e-9 and np.abs(scaled).max() <= QMAX:
            return np.rint(scaled).astype(np.int8), np.full(p.shape[0], 1.0 / d, np.float32), True
    q, s = quantize_weight(p.astype(np.float32))
    return q, s, False


def act_scale(amax: np.ndarray | float) -> np.ndarray:
    """Static activation scale from a calibrated max |x| (per tensor or per channel)."""
    a = np.asarray(amax, np.float64)
    return np.where(a > 0, a / QMAX, 1.0).astype(np.float32)


@dataclass(frozen=True)
class QWeight:
    """An int8 weight: ``q`` (out, in) int8 in PyTorch's layout, ``scale`` (out,) float32."""

    q: np.ndarray
    scale: np.ndarray

    @classmethod
    def of(cls, w: np.ndarray) -> "QWeight":
        return cls(*quantize_weight(w))

    @classmethod
    def folded(cls, w: np.ndarray, in_scale: np.ndarray) -> "QWeight":
        """W diag(in_scale), quantized per row: multiplies int8 activations of per-channel scale
        ``in_scale`` directly (x = in_scale * q), so the float result is float(acc) * scale."""
        return cls(*quantize_weight(np.asarray(w, np.float32) * np.asarray(in_scale, np.float32)[None, :]))

    def dequant(self) -> np.ndarray:
        return self.q.astype(np.float32) * self.scale[:, None]


def zero_point(g: Graph, n: int | None = None) -> str:
    """The int8 zero point 0 (scalar, or (n,) for a per-channel QuantizeLinear)."""
    if n is None:
        return g.const("q.zero_point", np.int8(0), np.int8)
    return g.const(f"q.zero_point_{n}", np.zeros(n, np.int8), np.int8)


def int8_weight(g: Graph, name: str, w: QWeight) -> tuple[str, str]:
    """Initializers of a weight used as MatMulInteger's B: Wq^T (in, out) int8, and s_w (out,)."""
    return (g.const(f"{name}.weight_q", np.ascontiguousarray(w.q.T), np.int8),
            g.const(f"{name}.weight_scale", w.scale))


def quantize(g: Graph, x: str, scale: str) -> str:
    """QuantizeLinear(x, scale, 0) -> int8 tensor (per-tensor scale)."""
    return g.op("QuantizeLinear", x, scale, zero_point(g))


def quantize_channels(g: Graph, x: str, scale: str, n: int) -> str:
    """QuantizeLinear(x, scale (n,), 0) over the last axis of a (B, T, n) tensor -> int8."""
    return g.op("QuantizeLinear", x, scale, zero_point(g, n), axis=2)


def int8_matmul(g: Graph, xq: str, a_scale: str | None, wq_t: str, w_scale: str, bias: str | None) -> str:
    """float y = ((float(xq @ WqT) * s_a) * s_w) + b on MatMulInteger (int32); ``a_scale`` None
    for a folded per-channel activation scale: y = (float(acc) * s_w') + b."""
    acc = g.op("MatMulInteger", xq, wq_t)
    y = g.op("Cast", acc, to=TensorProto.FLOAT)
    if a_scale is not None:
        y = g.op("Mul", y, a_scale)
    y = g.op("Mul", y, w_scale)
    return g.op("Add", y, bias) if bias is not None else y


def int8_linear(g: Graph, x: str, a_scale: str, name: str, w: QWeight, bias: str | None) -> str:
    """Quantize ``x`` with the static scale ``a_scale`` and apply weight ``name`` in int8."""
    wq_t, w_scale = int8_weight(g, name, w)
    return int8_matmul(g, quantize(g, x, a_scale), a_scale, wq_t, w_scale, bias)
