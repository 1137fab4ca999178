"""Fault class and split of every trajectory: exact counts, stratified, seeded.

``assign(seed, n_traj, fault_ratio, split)``:

1. counts: n_fault = round_half_up(fault_ratio * n_traj) fault trajectories, shared equally by
   the three fault classes; the remainder of n_fault / 3 goes one each to the lower class ids
   (Battery, then Motor). The other n_traj - n_fault are Healthy.
2. within each class (Healthy included), a stratified split: n_val = round_half_up(share_val *
   count), n_test = round_half_up(share_test * count), and the rest is train (so rounding
   remainders go to train; if the two rounded shares exceed the count, test then validation are
   reduced).
3. the labels are laid out in class order (class 0 train, val, test, class 1 train, ...) and
   placed by one permutation: trajectory perm[j] gets the j-th label, with
   perm = default_rng(SeedSequence(seed, spawn_key=(0xA55,))).permutation(n_traj).

The result depends only on (seed, n_traj, fault_ratio, split), never on which trajectories are
simulated, so any shard of a dataset gets the same labels as the full run.
Split codes: 0 train, 1 validation, 2 test.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from quadfdi.core.contracts import N_CLASSES, SPLIT_TEST, SPLIT_TRAIN, SPLIT_VALIDATION
from quadfdi.core.errors import QuadfdiError

ASSIGN_SPAWN_KEY = (0xA55,)
N_FAULT_CLASSES = N_CLASSES - 1  # every class but Healthy


def round_half_up(x: float) -> int:
    """Round to the nearest integer, halves up (Python's round() goes to even)."""
    return int(np.floor(x + 0.5 + 1e-9))


def class_counts(n_traj: int, fault_ratio: float, n_classes: int = N_CLASSES) -> np.ndarray:
    """Trajectories per class (Healthy, then the fault classes), (n_classes,) int64."""
    n_fault = round_half_up(fault_ratio * n_traj)
    base, rem = divmod(n_fault, n_classes - 1)
    faults = [base + (1 if k < rem else 0) for k in range(n_classes - 1)]
    return np.array([n_traj - n_fault, *faults], dtype=np.int64)


def split_counts(count: int, split: Sequence[float]) -> tuple[int, int, int]:
    """(train, validation, test) counts of one class of ``count`` trajectories."""
    n_val = round_half_up(split[1] * count)
    n_test = round_half_up(split[2] * count)
    while n_val + n_test > count:  # only for tiny counts with large shares
        if n_test >= n_val:
            n_test -= 1
        else:
            n_val -= 1
    return count - n_val - n_test, n_val, n_test


def assign(seed: int, n_traj: int, fault_ratio: float, split: Sequence[float], n_classes: int = N_CLASSES,
           spawn_key: tuple[int, ...] = ASSIGN_SPAWN_KEY) -> tuple[np.ndarray, np.ndarray]:
    """Fault class (n_traj,) int8 (0 Healthy, 1 Battery, 2 Motor, 3 Overheat[, 4 ...]) and split
    (n_traj,) int8 (0 train, 1 validation, 2 test) of every trajectory; see the module docstring."""
    if n_traj <= 0:
        raise QuadfdiError(f"sim.n_traj must be positive, found {n_traj}")
    if not 0.0 <= fault_ratio <= 1.0:
        raise QuadfdiError(f"sim.fault_ratio must be in [0, 1], found {fault_ratio}")
    if len(split) != 3 or min(split) < 0 or abs(sum(split) - 1.0) > 1e-9:
        raise QuadfdiError(f"sim.split must be three non-negative shares summing to 1, found {list(split)}")
    labels_cls, labels_split = [], []
    for cls, count in enumerate(class_counts(n_traj, fault_ratio, n_classes)):
        for code, k in zip((SPLIT_TRAIN, SPLIT_VALIDATION, SPLIT_TEST), split_counts(int(count), split)):
            labels_cls += [cls] * k
            labels_split += [code] * k
    perm = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=spawn_key)).permutation(n_traj)
    fault_class = np.empty(n_traj, dtype=np.int8)
    split_code = np.empty(n_traj, dtype=np.int8)
    fault_class[perm] = np.array(labels_cls, dtype=np.int8)
    split_code[perm] = np.array(labels_split, dtype=np.int8)
    return fault_class, split_code
