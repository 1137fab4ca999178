"""The streaming GRU: one GRU step per new telemetry sample, the class read from the hidden state
at every step.

Where the windowed ``models.networks.GRUClassifier`` re-runs W = 80 steps on the latest window at every
stride, this model carries its hidden state h from sample to sample: a flight controller pushes each
25 Hz sample once, pays one GRU cell and (when it wants a decision) one head product.

    x_norm_t = (x_t - mean) / std                                    (B, C)
    h_t      = GRU_cell(x_norm_t, h_{t-1})     PyTorch's cell (reset after the recurrent product,
                                               ONNX ``linear_before_reset=1``; see GRUClassifier)
    logits_t = head(h_t)                                              (B, K)

Parameter names are a contract with export/onnx_sgru.py and firmware_ref: ``gru`` (an nn.GRU with one
layer, batch_first), ``head`` (nn.Linear), buffers ``mean``, ``std`` (C,).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from quadfdi.models.networks import STD_FLOOR

KIND = "sgru"


class StreamGRU(nn.Module):
    """x_raw (B, T, C) with an optional start state h0 (B, H) -> logits at every step (B, T, K), h_T (B, H)."""

    def __init__(self, n_channels: int, hidden: int = 60, n_classes: int = 5) -> None:
        super().__init__()
        if n_channels < 1 or hidden < 1 or n_classes < 2:
            raise ValueError(f"need n_channels >= 1, hidden >= 1, n_classes >= 2; found {n_channels}, {hidden}, {n_classes}")
        self.n_channels, self.hidden, self.n_classes = int(n_channels), int(hidden), int(n_classes)
        self.register_buffer("mean", torch.zeros(n_channels))
        self.register_buffer("std", torch.ones(n_channels))
        self.gru = nn.GRU(n_channels, hidden, batch_first=True)
        self.head = nn.Linear(hidden, n_classes)
        self.head_dropout = 0.0  # training only (dropout on h before the head): no parameter, no effect in eval

    def set_normalisation(self, mean: Any, std: Any) -> None:
        set_stream_normalisation(self, mean, std)

    def features(self, x_raw: torch.Tensor, h0: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The hidden state at every step (B, T, H) and h_T (B, H): what the head reads (and, in training
        only, the stream's auxiliary motor head: train/stream_gru_motor.py)."""
        if x_raw.ndim != 3 or x_raw.shape[2] != self.n_channels:
            raise ValueError(f"telemetry must be (batch, samples, {self.n_channels}), found {tuple(x_raw.shape)}")
        x = (x_raw.to(self.mean.dtype) - self.mean) / self.std
        hs, h_last = self.gru(x, None if h0 is None else h0[None])
        return hs, h_last[0]

    def classify(self, hs: torch.Tensor) -> torch.Tensor:
        """Logits (B, T, K) of hidden states (B, T, H); dropout on h before the head in training only."""
        if self.training and self.head_dropout > 0:
            hs = nn.functional.dropout(hs, self.head_dropout, training=True)
        return self.head(hs)

    def forward(self, x_raw: torch.Tensor, h0: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        hs, h_last = self.features(x_raw, h0)
        return self.classify(hs), h_last

    @torch.no_grad()
    def step(self, sample: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """One new sample (B, C) and the carried state (B, H) -> logits (B, K), the new state (B, H)."""
        logits, h_new = self(sample[:, None, :], h)
        return logits[:, 0], h_new

    def macs_per_step(self) -> int:
        """3H(C + H) (the three gates' input and recurrent products) + H*K (the head), per sample.

        Counted like ``GRUClassifier.macs_per_window``: weight-matrix products only."""
        c, h = self.n_channels, self.hidden
        return 3 * h * (c + h) + h * self.n_classes


class StreamGRUStep(nn.Module):
    """The exported unit: (sample (1, C) raw, h (1, H)) -> (logits (1, K), h_new (1, H)), written out
    gate by gate in PyTorch's order (r, z, n) so that the graph is what the C++ step computes."""

    def __init__(self, model: StreamGRU) -> None:
        super().__init__()
        self.model = model

    def forward(self, sample: torch.Tensor, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        m, g = self.model, self.model.gru
        x = (sample - m.mean) / m.std
        gx = x @ g.weight_ih_l0.T + g.bias_ih_l0
        gh = h @ g.weight_hh_l0.T + g.bias_hh_l0
        hid = m.hidden
        r = torch.sigmoid(gx[:, :hid] + gh[:, :hid])
        z = torch.sigmoid(gx[:, hid:2 * hid] + gh[:, hid:2 * hid])
        n = torch.tanh(gx[:, 2 * hid:] + r * gh[:, 2 * hid:])
        h_new = (h - n) * z + n
        return m.head(h_new), h_new


def stream_signature(model: StreamGRU) -> dict[str, int | str]:
    return {"kind": KIND, "n_channels": model.n_channels, "hidden": model.hidden, "n_classes": model.n_classes}


def stream_from_signature(sig: dict[str, Any]) -> StreamGRU:
    sig = dict(sig)
    if sig.pop("kind", None) != KIND or set(sig) != {"n_channels", "hidden", "n_classes"}:
        raise ValueError(f"not a streaming GRU signature: {sig}")
    return StreamGRU(**{k: int(v) for k, v in sig.items()})


def set_stream_normalisation(model: nn.Module, mean: Any, std: Any) -> None:
    """A streaming network's training-split per-channel mean and std (C,) into its ``mean`` and ``std`` buffers;
    std floored at STD_FLOOR like the windowed models."""
    m = torch.as_tensor(np.asarray(mean, dtype=np.float32))
    s = torch.as_tensor(np.asarray(std, dtype=np.float32))
    if m.shape != (model.n_channels,) or s.shape != (model.n_channels,):
        raise ValueError(f"normalisation must be ({model.n_channels},) each, found {tuple(m.shape)}, {tuple(s.shape)}")
    if not (torch.isfinite(m).all() and torch.isfinite(s).all()):
        raise ValueError("normalisation holds NaN or Inf")
    with torch.no_grad():
        model.mean.copy_(m)
        model.std.copy_(s.clamp_min(STD_FLOOR))
