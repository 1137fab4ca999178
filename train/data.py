"""What training needs from the dataset: windows per split, normalisation, class weights, batches.

Normalisation statistics come from the TRAINING split only (SPEC section 3), over every sample
of its trajectories, so validation and test data never leak into the model.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from quadfdi.core.contracts import N_CLASSES, SPLIT_TRAIN, SPLIT_VALIDATION
from quadfdi.formats.dataset import Dataset, Windows, gather_windows, make_windows, split_rows, window_index
from quadfdi.models.inputs import decided


@dataclass(frozen=True)
class Splits:
    train: Windows
    validation: Windows
    test: Windows


def split_windows(ds: Dataset, max_train_windows: int = 0, seed: int = 0) -> Splits:
    """Train, validation and test windows; the training windows capped by ``capped_train_windows``."""
    val = make_windows(ds, "validation")
    return Splits(train=capped_train_windows(ds, max_train_windows, seed), validation=_decided_only(ds, val),
                  test=make_windows(ds, "test"))


def _decided_only(ds: Dataset, w: Windows) -> Windows:
    """The windows with a decision (models.inputs.decided): all of them without a hover estimate."""
    keep = decided(ds, w.traj, w.start)
    if keep.all():
        return w
    return Windows(x=w.x[keep], y=w.y[keep], traj=w.traj[keep], start=w.start[keep], t_end=w.t_end[keep])


def capped_train_windows(ds: Dataset, cap: int, seed: int) -> Windows:
    """The training windows, or (``cap`` > 0 and fewer than there are) ``cap`` of them drawn without
    replacement from the generator stream (seed, 0xCA9) and kept in dataset order. The draw has
    its own stream, so a cap changes no other random number (batches, initial weights); cap 0
    (the paper config) takes every window, as before the cap existed."""
    traj, start = window_index(ds, split_rows(ds, SPLIT_TRAIN))
    keep = decided(ds, traj, start)  # a profile with a hover estimate: windows before its freeze never decide
    traj, start = traj[keep], start[keep]
    if 0 < cap < len(traj):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0xCA9,)))
        keep = np.sort(rng.choice(len(traj), size=cap, replace=False))
        traj, start = traj[keep], start[keep]
    return gather_windows(ds, traj, start)


def evaluation_rows(ds: Dataset) -> np.ndarray:
    """Dataset rows of every evaluation flight: split code >= 1 (validation, test and the
    out-of-distribution test sets), in dataset order."""
    return np.flatnonzero(np.asarray(ds["split"]) >= SPLIT_VALIDATION)


def fit_normalisation(ds: Dataset) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel mean and std (C,) over every sample of the training trajectories."""
    tel = ds["telemetry"][ds["split"] == SPLIT_TRAIN].astype(np.float64)  # (n_train, T, C)
    flat = tel.reshape(-1, tel.shape[-1])
    return flat.mean(axis=0).astype(np.float32), flat.std(axis=0).astype(np.float32)


def class_weights(y: np.ndarray, n_classes: int = N_CLASSES) -> np.ndarray:
    """Inverse-frequency weights w_k = n / (K n_k) of Eq. (12); a class absent from y gets 0."""
    counts = np.bincount(y, minlength=n_classes).astype(np.float64)
    w = np.zeros(n_classes)
    present = counts > 0
    w[present] = len(y) / (present.sum() * counts[present])
    return w.astype(np.float32)


def batch_order(n: int, batch_size: int, seed: int, epoch: int) -> list[np.ndarray]:
    """The mini-batches of one epoch: a permutation drawn from (seed, epoch) alone, so the
    CNODE and the GRU see the same batches in the same order (SPEC section 3)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0xBA7C, epoch)))
    perm = rng.permutation(n)
    return [perm[i:i + batch_size] for i in range(0, n, batch_size)]
