"""The streaming CNODE: the paper's controlled vector field run as a filter over the whole flight,
one classic RK4 step per new telemetry sample, the class read from the latent state at every sample.

Where the windowed ``models.networks.CNODE`` restarts from z0 = tanh(E x_0) at every window and
integrates over the window, this model carries z from sample to sample (z = 0 at take-off):

    x_norm_t = (x_t - mean) / std                                   (B, C)
    v_t      = x_norm_t @ W1u^T + b1                                (B, H)  u-part of lin1, per sample
    f(z, v)  = lin2(tanh(z @ W1z^T + v)) - decay * z                (B, L)  field = VectorField, [z, u] split
    z_t      = one classic RK4 step of dz/dt = f(z, v(s)) over s in [0, dt] (core.rk4.rk4_step),
               v(s) linear between v_{t-1} (s = 0) and v_t (s = dt): v at the two mid stages is
               (v_{t-1} + v_t) * 0.5
    logits_t = head(z_t)                                            (B, K)

``decay`` (L,) = softplus(``decay_raw``) >= 0 (``leak`` True; no term and no parameter with False): the
paper's field saturates in z (tanh), so far from the origin it has no restoring force and a state carried
over a 75 s flight drifts without bound; the leak lets each latent dimension forget at a learned rate.

Interpolating v instead of u is the same path: lin1 is affine in u, so lin1 of the linearly
interpolated control is the linear interpolation of lin1 at its ends; it costs one H x C product
per sample (v_t is the next step's v_{t-1}) instead of two. The first sample of a stream (or after
a reset) has no predecessor: it is held, v_{t-1} = v_t. ``dt`` is the integration time per sample
(a model constant, recorded in the signature): the RK4 constants are ``core.rk4.rk4_constants(dt)``.

Parameter names are a contract with export/onnx_scnode.py and firmware_ref (fwref/cnode_step.hpp):
``field.lin1`` (H, L + C) with z's columns first, ``field.lin2``, ``head``, buffers ``mean``, ``std``.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from quadfdi.core.rk4 import rk4_step
from quadfdi.models.networks import VectorField
from quadfdi.models.stream_gru import set_stream_normalisation

KIND = "scnode"
DT = 0.0625  # integration time per sample (1/16: a power of two, so h/2 and h are exact in float32)


class StreamCNODE(nn.Module):
    """x_raw (B, T, C), optional start state z0 (B, L) and previous raw sample (B, C) -> logits at
    every step (B, T, K), z_T (B, L)."""

    def __init__(self, n_channels: int, latent: int = 24, hidden: int = 48, n_classes: int = 5, dt: float = DT,
                 leak: bool = True) -> None:
        super().__init__()
        if n_channels < 1 or latent < 1 or hidden < 1 or n_classes < 2 or not 0.0 < dt <= 1.0:
            raise ValueError(f"need n_channels, latent, hidden >= 1, n_classes >= 2, 0 < dt <= 1; found "
                             f"{n_channels}, {latent}, {hidden}, {n_classes}, {dt}")
        self.n_channels, self.latent, self.hidden, self.n_classes = int(n_channels), int(latent), int(hidden), int(n_classes)
        self.dt = float(dt)
        self.register_buffer("mean", torch.zeros(n_channels))
        self.register_buffer("std", torch.ones(n_channels))
        self.field = VectorField(latent, n_channels, hidden)
        self.head = nn.Linear(latent, n_classes)
        self.leak = bool(leak)
        if self.leak:  # softplus(0.5413) = 1: a time constant of 1 (16 samples at dt 1/16) to start from
            self.decay_raw = nn.Parameter(torch.full((latent,), 0.5413))
        self.head_dropout = 0.0  # training only (dropout on z before the head)

    @property
    def state_size(self) -> int:
        return self.latent

    def set_normalisation(self, mean: Any, std: Any) -> None:
        set_stream_normalisation(self, mean, std)

    def controls(self, x_raw: torch.Tensor) -> torch.Tensor:
        """v = x_norm @ W1u^T + b1 for raw samples (..., C) -> (..., H)."""
        x = (x_raw.to(self.mean.dtype) - self.mean) / self.std
        w1 = self.field.lin1.weight
        return nn.functional.linear(x, w1[:, self.latent:], self.field.lin1.bias)

    def decay(self) -> torch.Tensor | None:
        """(L,) softplus(decay_raw), None without the leak."""
        return nn.functional.softplus(self.decay_raw) if self.leak else None

    def vector_field(self, z: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
        """f(z, v) (B, L): the field at state z (B, L) with the control's u-part v (B, H)."""
        w1 = self.field.lin1.weight
        k = self.field.lin2(torch.tanh(z @ w1[:, :self.latent].T + v))
        return k if not self.leak else k - z * self.decay()

    def rk4(self, z: torch.Tensor, v_prev: torch.Tensor, v_new: torch.Tensor) -> torch.Tensor:
        """One step: z (B, L), the controls' ends (B, H) each -> z' (B, L)."""
        v_mid = (v_prev + v_new) * 0.5
        at = {0.0: v_prev, 0.5 * self.dt: v_mid, self.dt: v_new}
        return rk4_step(lambda t, zz: self.vector_field(zz, at[t]), 0.0, z, self.dt)

    def features(self, x_raw: torch.Tensor, z0: torch.Tensor | None = None,
                 x_prev: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The state after every sample (B, T, L) and z_T (B, L); ``x_prev`` (B, C) the raw sample before
        ``x_raw``'s first (None: the first is held), ``z0`` the state before it (None: 0)."""
        if x_raw.ndim != 3 or x_raw.shape[2] != self.n_channels:
            raise ValueError(f"telemetry must be (batch, samples, {self.n_channels}), found {tuple(x_raw.shape)}")
        v = self.controls(x_raw)  # (B, T, H)
        v_first = v[:, 0] if x_prev is None else self.controls(x_prev)
        z = torch.zeros(x_raw.shape[0], self.latent, dtype=v.dtype) if z0 is None else z0.to(v.dtype)
        zs, v_prev = [], v_first
        for t in range(x_raw.shape[1]):
            z = self.rk4(z, v_prev, v[:, t])
            v_prev = v[:, t]
            zs.append(z)
        return torch.stack(zs, dim=1), z

    def classify(self, zs: torch.Tensor) -> torch.Tensor:
        """Logits (B, T, K) of states (B, T, L); dropout on z before the head in training only."""
        if self.training and self.head_dropout > 0:
            zs = nn.functional.dropout(zs, self.head_dropout, training=True)
        return self.head(zs)

    def forward(self, x_raw: torch.Tensor, z0: torch.Tensor | None = None,
                x_prev: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        zs, z_last = self.features(x_raw, z0, x_prev)
        return self.classify(zs), z_last

    def macs_per_step(self) -> int:
        """4 (L H + H L) (four field evaluations' z-products) + H C (the new sample's control) + L K (the
        head), per sample: weight-matrix products only, counted like ``CNODE.macs_breakdown`` (the leak's
        4 L element-wise products are not)."""
        c, l, h, k = self.n_channels, self.latent, self.hidden, self.n_classes
        return 4 * 2 * l * h + h * c + l * k


def stream_signature(model: StreamCNODE) -> dict[str, int | float | str]:
    return {"kind": KIND, "n_channels": model.n_channels, "latent": model.latent, "hidden": model.hidden,
            "n_classes": model.n_classes, "dt": model.dt, "leak": model.leak}


def stream_from_signature(sig: dict[str, Any]) -> StreamCNODE:
    sig = dict(sig)
    if sig.pop("kind", None) != KIND or set(sig) != {"n_channels", "latent", "hidden", "n_classes", "dt", "leak"}:
        raise ValueError(f"not a streaming CNODE signature: {sig}")
    dt, leak = float(sig.pop("dt")), bool(sig.pop("leak"))
    return StreamCNODE(**{k: int(v) for k, v in sig.items()}, dt=dt, leak=leak)
