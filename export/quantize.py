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
- Activation encoding, per model (``INT8`` or ``UINT8``): int8 codes with zero point 0, or uint8
  codes with zero point 128. ``QuantizeLinear`` to uint8 with zero point 128 gives
  ``clamp(rne(x / s), -128, 127) + 128``, so the integer a product sees, ``q - 128``, is the int8
  code, and the integer sums are identical: the C++ reference keeps int8 activations either way.
  uint8 activations take ONNX Runtime's fast u8 x s8 kernel; on AVX2 that kernel multiplies pairs
  in 16 bits with saturation (vpmaddubsw), so its weights must have 7 bits (|w| <= 63:
  255 * 63 * 2 < 32767) for the sums to be exact on every CPU. ``qmax`` is 63 for such weights.
- One product: ``q = QuantizeLinear(x, s_a, zp)`` (round(x / s_a) half to even, saturated), then
  ONE ``com.microsoft.MatMulIntegerToFloat(q, WqT, s_a, s_w, zp, -, b)`` node, which computes the
  int32 sum exactly and then, in float32, ``y = (f32(acc) * f32(s_a * s_w)) + b`` (the multiplier
  ``f32(s_a * s_w[o])`` formed first, one multiply, one add: ONNX Runtime's output processor, measured
  bit-identical on 24,576 outputs). A folded per-channel activation scale uses ``s_a = 1``:
  ``f32(1 * s_w') = s_w'`` exactly, so ``y = (f32(acc) * s_w') + b``. A per-stage addend that is
  not a per-output bias (the CNODE's row of V) is a separate Add after a bias-less product.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfdi.export.graph import MS_DOMAIN, Graph

QMAX = 127  # weights use [-127, 127] (symmetric); activations saturate to [-128, 127]
QMAX_7BIT = 63  # weights beside uint8 activations: [-63, 63] (see the module docstring)
INT8, UINT8 = "int8", "uint8"  # activation encodings (zero point 0 / 128)
ACT_ZERO_POINT = {INT8: 0, UINT8: 128}
BOUND_SCALE = np.float32(1.0 / QMAX)  # scale of activations bounded by 1 in magnitude (tanh, GRU h)


def rne_div(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """round_half_even(x / scale) in float32 arithmetic, as ONNX Runtime's QuantizeLinear does it."""
    return np.rint(np.asarray(x, np.float32) / np.asarray(scale, np.float32))


def quantize_act(x: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """QuantizeLinear(x, scale, zero point 0) to int8: float32 division, half-to-even, saturation."""
    return np.clip(rne_div(x, scale), -128, 127).astype(np.int8)


def quantize_weight(w: np.ndarray, qmax: int = QMAX) -> tuple[np.ndarray, np.ndarray]:
    """(out, in) float weight -> (Wq int8 (out, in), s_w float32 (out,)), per output channel, codes
    in [-qmax, qmax] (127, or 63 for 7-bit weights)."""
    w = np.asarray(w, np.float32)
    amax = np.abs(w).max(axis=1)
    scale = np.where(amax > 0, amax / np.float32(qmax), np.float32(1.0)).astype(np.float32)
    q = np.clip(rne_div(w, scale[:, None]), -qmax, qmax).astype(np.int8)
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
    def of(cls, w: np.ndarray, qmax: int = QMAX) -> "QWeight":
        return cls(*quantize_weight(w, qmax))

    @classmethod
    def folded(cls, w: np.ndarray, in_scale: np.ndarray, qmax: int = QMAX) -> "QWeight":
        """W diag(in_scale), quantized per row: multiplies int8 activations of per-channel scale
        ``in_scale`` directly (x = in_scale * q), so the float result is float(acc) * scale."""
        return cls(*quantize_weight(np.asarray(w, np.float32) * np.asarray(in_scale, np.float32)[None, :], qmax))

    def dequant(self) -> np.ndarray:
        return self.q.astype(np.float32) * self.scale[:, None]


def weight_qmax(act: str) -> int:
    """Largest weight code beside activations of encoding ``act`` (7 bits beside uint8)."""
    return QMAX_7BIT if act == UINT8 else QMAX


def zero_point(g: Graph, n: int | None = None, act: str = INT8) -> str:
    """The activation zero point: int8 0, or uint8 128 (scalar, or (n,) for a per-channel QuantizeLinear)."""
    dt = np.uint8 if act == UINT8 else np.int8
    zp = ACT_ZERO_POINT[act]
    if n is None:
        return g.const(f"q.zero_point.{act}", dt(zp), dt)
    return g.const(f"q.zero_point.{act}_{n}", np.full(n, zp, dt), dt)


def int8_weight(g: Graph, name: str, w: QWeight) -> tuple[str, str]:
    """Initializers of a weight used as the product's B: Wq^T (in, out) int8, and s_w (out,)."""
    return (g.const(f"{name}.weight_q", np.ascontiguousarray(w.q.T), np.int8),
            g.const(f"{name}.weight_scale", w.scale))


def quantize(g: Graph, x: str, scale: str, act: str = INT8) -> str:
    """QuantizeLinear(x, scale, zp) -> int8 (zp 0) or uint8 (zp 128) tensor (per-tensor scale)."""
    return g.op("QuantizeLinear", x, scale, zero_point(g, act=act))


def quantize_channels(g: Graph, x: str, scale: str, n: int, act: str = INT8) -> str:
    """Per-channel QuantizeLinear over the last axis, written as Div(x, scale (n,)) then a per-tensor
    QuantizeLinear with scale 1: the same integers (``x / s[c]`` is the same float32 division, and
    ``v / 1`` is exact), but ONNX Runtime's per-axis QuantizeLinear on the last axis quantizes
    element by element (measured: 23 ms for a batch of 96 windows against well under 1 ms)."""
    del n  # the scale's length is the channel count
    return g.op("QuantizeLinear", g.op("Div", x, scale), g.const("q.unit_scale", np.float32(1.0)),
                zero_point(g, act=act))


def int8_matmul(g: Graph, xq: str, a_scale: str | None, wq_t: str, w_scale: str, bias: str | None,
                act: str = INT8, name: str | None = None) -> str:
    """float y = (f32(xq @ WqT) * f32(s_a * s_w)) + b in ONE com.microsoft.MatMulIntegerToFloat;
    ``a_scale`` None for a folded per-channel activation scale (s_a = 1: y = (f32(acc) * s_w') + b);
    ``bias`` None for no addend."""
    a_s = a_scale if a_scale is not None else g.const("q.unit_scale", np.float32(1.0))
    ins = [xq, wq_t, a_s, w_scale]
    if act == UINT8 or bias is not None:
        ins.append(zero_point(g, act=act) if act == UINT8 else "")
    if bias is not None:
        ins += ["", bias]
    return g.op("MatMulIntegerToFloat", *ins, domain=MS_DOMAIN, name=name)


def int8_linear(g: Graph, x: str, a_scale: str, name: str, w: QWeight, bias: str | None, act: str = INT8) -> str:
    """Quantize ``x`` with the static scale ``a_scale`` and apply weight ``name`` in int8."""
    wq_t, w_scale = int8_weight(g, name, w)
    return int8_matmul(g, quantize(g, x, a_scale, act), a_scale, wq_t, w_scale, bias, act)
