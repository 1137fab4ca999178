"""Training data of the masked profile (``flightlog-mask``, core/channels.py): windows with the channels
real logs lack.

The dataset the masked models train on has every channel (models.inputs.profiled_dataset with
``patterns=False``); the masks come here, one mask pattern (core/channels.py MASK_PATTERNS) per window:

- training: ``MaskDraw`` draws a pattern for every window of every batch (``ALL_CHANNELS_PROBABILITY``
  "all", otherwise one of the others, uniformly) from its own stream (seed, 0x3A5C, epoch, batch), so
  a window meets several patterns over the epochs and every other random number (batches, initial
  weights) stays as it was;
- validation (the epoch's choice): one pattern per window, drawn once from (seed, 0x3A5D), the same
  for every epoch and both networks;
- ``pattern_scores``: the test and validation windows under each pattern in turn, macro F1 per
  pattern (metrics.json ``mask_patterns``); the test metrics themselves keep every channel.

A reference profile (``flightlog-ref``): on top of the pattern, a window loses its vehicle record with
``NO_REFERENCE_PROBABILITY`` (its own draw from the same stream; validation likewise, drawn once), so
one model decides with and without a reference; ``pattern_scores`` adds ``no_reference`` (every window
without its record, every channel).

Masking a window: the model columns of each group the pattern lacks take their fills, the group's
availability column 0; exactly what core.profiles.apply_profile gives a flight lacking the group
(the hover estimate stays the flight's: an absent pitch moves it by at most 0.77 % on the flights
core/hover.py names). Normalisation: the availability channels are fixed (mean 0, std 1: their 0/1
reaches the network as is), the others fitted on the unmasked training flights as for any profile.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import numpy as np
import torch
from sklearn.metrics import f1_score

from quadfdi.core.channels import ALL_CHANNELS_PROBABILITY, MASK_PATTERNS, NO_REFERENCE_PROBABILITY, REFERENCE_GROUP
from quadfdi.core.profiles import has_reference, is_masked, mask_layout
from quadfdi.formats.dataset import Windows

DRAW_KEY, VALIDATION_KEY = 0x3A5C, 0x3A5D


def draw_patterns(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n,) pattern indices: 0 ("all") with ALL_CHANNELS_PROBABILITY, else uniform over the others."""
    others = rng.integers(1, len(MASK_PATTERNS), size=n)
    return np.where(rng.random(n) < ALL_CHANNELS_PROBABILITY, 0, others).astype(np.int64)


def draw_no_reference(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n,) bool: True with NO_REFERENCE_PROBABILITY (drawn after the patterns, so theirs stay as they were)."""
    return rng.random(n) < NO_REFERENCE_PROBABILITY


class Masker:
    """The masked profile's columns: ``apply(x, patterns)`` masks windows (n, W, C) in place."""

    def __init__(self, profile: str, channel_names: Sequence[str]) -> None:
        from quadfdi.core.profiles import channel_names as profile_channels

        if list(channel_names) != profile_channels(profile, []):
            raise ValueError(f"the windows' channels are not profile {profile!r}'s")
        self.cols, self.fill, self.avail = mask_layout(profile)
        self.reference = has_reference(profile)

    def drop_reference(self, x: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Windows ``rows`` of ``x`` as without a vehicle record, in place (a no-op for other profiles)."""
        if self.reference and rows.size:
            cols = self.cols[REFERENCE_GROUP]
            x[np.ix_(rows, np.arange(x.shape[1]), cols)] = self.fill[cols]
            x[rows, :, self.avail[REFERENCE_GROUP]] = 0.0
        return x

    def apply(self, x: np.ndarray, patterns: np.ndarray, no_reference: np.ndarray | None = None) -> np.ndarray:
        if no_reference is not None:
            self.drop_reference(x, np.flatnonzero(no_reference))
        for k, pat in enumerate(MASK_PATTERNS):
            rows = np.flatnonzero(patterns == k)
            if rows.size == 0:
                continue
            for g in pat.groups:
                cols = self.cols[g]
                x[np.ix_(rows, np.arange(x.shape[1]), cols)] = self.fill[cols]
                x[rows, :, self.avail[g]] = 0.0
        return x


class MaskDraw:
    """The training augmentation (train.loop's ``augment``): a copy of the batch with one drawn pattern
    per window."""

    def __init__(self, masker: Masker, seed: int) -> None:
        self.masker, self.seed = masker, int(seed)

    def draws(self, n: int, epoch: int, batch: int) -> tuple[np.ndarray, np.ndarray | None]:
        """(n,) pattern indices and, for a reference profile, (n,) bool: the window loses its record."""
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(DRAW_KEY, epoch, batch)))
        return draw_patterns(rng, n), draw_no_reference(rng, n) if self.masker.reference else None

    def patterns(self, n: int, epoch: int, batch: int) -> np.ndarray:
        return self.draws(n, epoch, batch)[0]

    def __call__(self, x: torch.Tensor, epoch: int, batch: int) -> torch.Tensor:
        out = x.numpy().copy()
        return torch.from_numpy(self.masker.apply(out, *self.draws(len(out), epoch, batch)))


def chain(*augments: Callable | None) -> Callable | None:
    """The augmentations that are not None, applied in order (None if none is)."""
    live = [a for a in augments if a is not None]
    if not live:
        return None
    if len(live) == 1:
        return live[0]
    return lambda x, epoch, batch: _apply(live, x, epoch, batch)


def _apply(augments, x, epoch, batch):
    for a in augments:
        x = a(x, epoch, batch)
    return x


def mask_draw_for(profile: str, channel_names: Sequence[str], seed: int) -> MaskDraw | None:
    """The run's mask augmentation, or None for a profile without a mask."""
    return MaskDraw(Masker(profile, channel_names), seed) if is_masked(profile) else None


def masked_validation(val: Windows, profile: str, channel_names: Sequence[str], seed: int) -> Windows:
    """The validation windows, each under one pattern drawn once (module docstring)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(VALIDATION_KEY,)))
    masker = Masker(profile, channel_names)
    patterns = draw_patterns(rng, len(val))
    x = masker.apply(val.x.copy(), patterns, draw_no_reference(rng, len(val)) if masker.reference else None)
    return dataclasses.replace(val, x=x)


def fixed_availability(profile: str, mean: np.ndarray, std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The normalisation with every availability channel at mean 0, std 1."""
    mean, std = mean.copy(), std.copy()
    for j in mask_layout(profile)[2].values():
        mean[j], std[j] = 0.0, 1.0
    return mean, std


# pattern_scores masks and predicts this many windows at a time, in one reused buffer: a fresh copy of every
# window per pattern cost more than the predictions (page faults of a new allocation the size of the set). A
# multiple of predict_proba's batch of 512, so the batches and their probabilities stay those of one call.
PATTERN_CHUNK = 4096


def pattern_scores(predict: Callable[[np.ndarray], np.ndarray], windows: Windows, profile: str,
                   channel_names: Sequence[str], n_classes: int) -> dict[str, dict]:
    """pattern -> {"macro_f1", "windows"}: ``predict`` ((n, W, C) -> (n, K) probabilities) on every
    window under that pattern."""
    masker = Masker(profile, channel_names)
    buf = np.empty((min(PATTERN_CHUNK, len(windows)),) + windows.x.shape[1:], windows.x.dtype)
    labels = list(range(n_classes))

    def score(mask: Callable[[np.ndarray], np.ndarray]) -> dict:
        pred = np.concatenate([predict(mask(_chunk(buf, windows.x, i))).argmax(axis=1)
                               for i in range(0, len(windows), PATTERN_CHUNK)])
        f1 = f1_score(windows.y, pred, labels=labels, average="macro", zero_division=0)
        return {"macro_f1": round(float(f1), 6), "windows": int(len(windows))}

    out = {pat.name: score(lambda x, k=k: masker.apply(x, np.full(len(x), k))) for k, pat in enumerate(MASK_PATTERNS)}
    if masker.reference:
        out["no_reference"] = score(lambda x: masker.drop_reference(x, np.arange(len(x))))
    return out


def _chunk(buf: np.ndarray, x: np.ndarray, start: int) -> np.ndarray:
    """Windows ``start:start + len(buf)`` of ``x`` copied into ``buf`` (its first rows), which is returned."""
    part = x[start:start + len(buf)]
    np.copyto(buf[:len(part)], part)
    return buf[:len(part)]
