"""Where the streaming GRU's training segments fall in a flight, and the class weights of what it
sees (train/stream_gru_fit.py; docs/training.md "Streaming GRU").

- ``draw_segments``: the start sample of every flight's segment in a batch. A segment starts at
  take-off with probability ``zero_start``, else at a uniformly drawn sample (the default). With
  ``onset_segments`` = q > 0, a fault flight's mid-flight segment instead falls, with probability q,
  so that its first fault-labelled step (``first_fault``) lies at a uniformly drawn offset of
  [``warmup``, ``segment``) inside it (clipped to the flight): the onset, which a 40 s segment of a
  75 s flight often misses, is then seen with a known probability. q = 0 draws exactly the random
  numbers of before (the default path, bit for bit).
- ``start_span``: a mid-flight segment starts where a whole segment fits ("fit", the default: the
  end of a 75 s flight is then drawn far less often than its middle: with the defaults a sample at
  60-70 s lies in 14 % of the segments, at 70-75 s in 4 %, at 30-40 s in 96 %), or at any sample that leaves ``warmup`` steps ("any"): a segment that runs past
  the flight's end is cut there (the missing steps carry no loss), so every sample past the first
  ``segment`` is drawn about equally often, as the evaluation reads every part of the flight.
- ``sampled_class_weights`` (``class_mix = "sampled"``): the inverse-frequency weights of Eq. (12)
  computed over the loss-bearing steps the segment sampler actually draws (estimated on ``draws``
  draws per flight from a generator stream of its own), instead of over every step of the training
  flights (``class_mix = "steps"``, the default). Segments from take-off cover the healthy first
  40 s of a flight more often than its faulty end, so the default weights leave Healthy with more
  than its 1/K share of the loss.
"""

from __future__ import annotations

import numpy as np

from quadfdi.train.config import StreamFitConfig


def first_fault(lab: np.ndarray) -> np.ndarray:
    """(n,) int64: the first fault-labelled step of every flight of the step labels ``lab`` (n, T); -1 if none."""
    fault = lab != 0
    return np.where(fault.any(axis=1), fault.argmax(axis=1), -1).astype(np.int64)


def draw_segments(rng: np.random.Generator, n_samples: int, onset: np.ndarray,
                  cfg: StreamFitConfig) -> tuple[np.ndarray, np.ndarray]:
    """(start sample, mid-flight) per flight of a batch; ``onset`` (n,): ``first_fault`` of those flights."""
    n = len(onset)
    seg = min(cfg.segment, n_samples)
    mid = rng.random(n) >= cfg.zero_start
    last = n_samples - seg if cfg.start_span == "fit" else n_samples - 1 - min(cfg.warmup, n_samples - 1)
    start = np.where(mid, rng.integers(0, last + 1, size=n), 0)
    if cfg.onset_segments > 0:
        lo = min(cfg.warmup, seg - 1)
        at_onset = mid & (onset >= 0) & (rng.random(n) < cfg.onset_segments)
        offset = rng.integers(lo, seg, size=n)
        start = np.where(at_onset, np.clip(onset - offset, 0, n_samples - seg), start)
    return start.astype(np.int64), mid & (start > 0)


def segment_columns(start: np.ndarray, seg: int, n_samples: int) -> np.ndarray:
    """(n, seg) sample index of every step of the segments; past the flight's end (``start_span =
    "any"``) the last sample is repeated, and ``loss_mask`` drops those steps."""
    return np.minimum(start[:, None] + np.arange(seg)[None, :], n_samples - 1)


def loss_mask(start: np.ndarray, mid: np.ndarray, seg: int, warmup: int, n_samples: int) -> np.ndarray:
    """(n, seg) bool: the steps that carry loss: not a mid-flight segment's first ``warmup`` steps,
    nor a step past the flight's end."""
    mask = start[:, None] + np.arange(seg)[None, :] < n_samples
    mask[mid, :warmup] = False
    return mask


def sampled_class_weights(lab: np.ndarray, cfg: StreamFitConfig, n_classes: int, draws: int = 16) -> np.ndarray:
    """(K,) float32 inverse-frequency class weights over the loss-bearing steps of ``draws`` segment
    draws per training flight (generator stream (seed, 0x5E6), so no other random number changes)."""
    rng = np.random.default_rng(np.random.SeedSequence(cfg.seed, spawn_key=(0x5E6,)))
    n, n_t = lab.shape
    seg = min(cfg.segment, n_t)
    onset = first_fault(lab)
    counts = np.zeros(n_classes, dtype=np.int64)
    for _ in range(draws):
        start, mid = draw_segments(rng, n_t, onset, cfg)
        cols = segment_columns(start, seg, n_t)
        y = lab[np.arange(n)[:, None], cols][loss_mask(start, mid, seg, cfg.warmup, n_t)]
        counts += np.bincount(y, minlength=n_classes)
    w = np.zeros(n_classes)  # train.data.class_weights' w_k = n / (K' n_k) on the counts
    present = counts > 0
    w[present] = counts.sum() / (present.sum() * counts[present])
    return w.astype(np.float32)
