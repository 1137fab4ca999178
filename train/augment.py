"""Training-only augmentation: the motor-command shares of real healthy vehicles wander more.

Why (docs/training.md, "Motor-share wander"): on the shared real quad flights the four
motor commands' shares (command / mean of the four, each 3.2 s window's mean removed) move with a
within-window standard deviation of 0.025 (GPS-interference hover) to 0.054 (UAVCAN mission),
against 0.016-0.017 on the realistic suite's healthy hover and survey flights (lab/share_wander_stats.py); flattening the
shares of a real flight removed half of the networks' false alarms. The augmentation adds what the
simulator lacks to the ``m1_rel``..``m4_rel`` inputs of each training batch, never to validation
or test windows:

    m_k <- m_k * (1 + sigma * (e_k - mean_j e_j))

``e_k`` is a unit-variance AR(1) series per window and motor with correlation time ``tau`` (the
real shares' autocorrelation at 0.2 s is 0.34-0.56, at 0.4 s 0.19-0.39: tau ~ 0.3 s), started in
its stationary distribution; removing the four motors' mean keeps the collective command, so the
noise moves the shares and not the thrust. ``sigma`` is drawn per window, uniform on
[0, share_wander], so calm and busy flights both appear. The draws come from their own stream
(seed, 0x5A7E, epoch, batch): every other random number (batches, initial weights) is unchanged,
and ``share_wander = 0`` (the default) trains exactly as before.
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import torch

from quadfdi.core.errors import QuadfdiError

SHARE_CHANNELS = ("m1_rel", "m2_rel", "m3_rel", "m4_rel")


def share_columns(channel_names: Sequence[str]) -> list[int]:
    """Column of each of ``SHARE_CHANNELS`` in the model's inputs; refused if one is missing."""
    names = list(channel_names)
    missing = [c for c in SHARE_CHANNELS if c not in names]
    if missing:
        raise QuadfdiError(f"train.share_wander needs the motor shares {', '.join(SHARE_CHANNELS)} among the inputs; "
                           f"this profile lacks {', '.join(missing)} (use a flightlog-* profile or share_wander = 0)")
    return [names.index(c) for c in SHARE_CHANNELS]


class ShareWander:
    """The augmentation for one training run: ``amplitude`` = train.share_wander, ``tau_samples`` =
    train.share_wander_tau_s / the sample interval, ``columns`` from ``share_columns``."""

    def __init__(self, amplitude: float, tau_samples: float, columns: list[int], seed: int) -> None:
        self.amplitude, self.columns, self.seed = float(amplitude), list(columns), int(seed)
        self.a = math.exp(-1.0 / tau_samples)

    def noise(self, n: int, w: int, epoch: int, batch: int) -> np.ndarray:
        """(n, w, 4) float32 multiplicative factors - 1 for one batch."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(0x5A7E, epoch, batch)))
        sigma = rng.uniform(0.0, self.amplitude, size=(n, 1, 1))
        drive = rng.standard_normal((n, w, 4))
        e = np.empty_like(drive)
        e[:, 0] = drive[:, 0]  # the stationary distribution of a unit-variance AR(1)
        b = math.sqrt(1.0 - self.a * self.a)
        for t in range(1, w):
            e[:, t] = self.a * e[:, t - 1] + b * drive[:, t]
        e -= e.mean(axis=2, keepdims=True)
        return (sigma * e).astype(np.float32)

    def __call__(self, x: torch.Tensor, epoch: int, batch: int) -> torch.Tensor:
        """A copy of the raw batch ``x`` (B, W, C) with its shares moved; ``x`` is not changed."""
        f = torch.from_numpy(self.noise(x.shape[0], x.shape[1], epoch, batch))
        out = x.clone()
        cols = torch.as_tensor(self.columns)
        out[:, :, cols] = x[:, :, cols] * (1.0 + f)
        return out


def share_wander_for(cfg, channel_names: Sequence[str], dt_s: float) -> ShareWander | None:
    """The run's augmentation, or None when ``cfg.share_wander`` (a TrainConfig) is 0."""
    if cfg.share_wander <= 0:
        return None
    return ShareWander(cfg.share_wander, cfg.share_wander_tau_s / dt_s, share_columns(channel_names), cfg.seed)
