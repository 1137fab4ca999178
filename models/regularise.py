"""Dropout for training only: identity (no operation at all) in eval mode or at p = 0.

In eval mode both functions return their input object itself, so a model's eval forward, its
traced and exported graphs, its weights and its state dict do not depend on the rates.
"""

from __future__ import annotations

import torch


def drop_channels(x: torch.Tensor, p: float, training: bool) -> torch.Tensor:
    """x (B, W, C): each channel of each window zeroed with probability p over the whole window,
    the others scaled by 1 / (1 - p). Zero is the channel's training mean after normalisation."""
    if not training or p <= 0.0:
        return x
    keep = torch.bernoulli(torch.full((x.shape[0], 1, x.shape[2]), 1.0 - p, dtype=x.dtype, device=x.device))
    return x * keep / (1.0 - p)


def drop_latent(z: torch.Tensor, p: float, training: bool) -> torch.Tensor:
    """z (B, width): element-wise dropout before the heads."""
    if not training or p <= 0.0:
        return z
    return torch.nn.functional.dropout(z, p, training=True)
