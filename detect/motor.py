"""The suspected motor in ``detect``'s outputs, from a model's motor head (train.motor).

Per window (windows.npz ``motor``, int8): 1..4 = the argmax of the window's motor probabilities
when the window is decided and its fault class (the argmax of ``proba`` over the fault columns,
Healthy left out, as core.alarm names an alarm's class) is rotor-side; 0 otherwise and for a model
without the head.

Per alarm (alarms.json ``motor``): for an alarm whose class is rotor-side, the argmax of the MEAN
motor probability over the alarm's active windows whose fault class is rotor-side (ties: the
lowest motor); None for other classes, for a model without the head, and when no such window
exists. Motors are numbered 1..4 (column m of ``motor_logits`` is motor m + 1: docs/ingest.md,
motor numbering).
"""

from __future__ import annotations

import numpy as np


def rotor_columns(names: list[str], rotor_side_classes: list[str]) -> np.ndarray:
    """(K,) bool: the rotor-side class columns."""
    return np.array([n in rotor_side_classes for n in names], dtype=bool)


def window_fault_class(proba: np.ndarray, healthy: int) -> np.ndarray:
    """(n,) the argmax of each window's probabilities over the fault columns (NaN rows: -1)."""
    p = np.where(np.isfinite(proba), proba, -np.inf)
    p[:, healthy] = -np.inf
    cls = np.argmax(p, axis=1)
    return np.where(np.isfinite(proba).all(axis=1), cls, -1)


def window_motor(proba: np.ndarray, motor_proba: np.ndarray | None, healthy: int, rotor: np.ndarray) -> np.ndarray:
    """(n,) int8 per-window motor 1..4 (0: none), the rule of the module docstring."""
    n = len(proba)
    if motor_proba is None:
        return np.zeros(n, np.int8)
    cls = window_fault_class(proba, healthy)
    ok = (cls >= 0) & rotor[np.maximum(cls, 0)] & np.isfinite(motor_proba).all(axis=1)
    return np.where(ok, np.argmax(np.nan_to_num(motor_proba, nan=-1.0), axis=1) + 1, 0).astype(np.int8)


def alarm_motor(alarm_cls: int, active: np.ndarray, proba: np.ndarray, motor_proba: np.ndarray | None,
                healthy: int, rotor: np.ndarray) -> int | None:
    """The motor 1..4 of one alarm (``active`` (n,) bool: its active windows), or None."""
    if motor_proba is None or alarm_cls < 0 or not rotor[alarm_cls]:
        return None
    cls = window_fault_class(proba, healthy)
    keep = active & (cls >= 0) & rotor[np.maximum(cls, 0)]
    if not keep.any():
        return None
    return int(np.argmax(motor_proba[keep].astype(np.float64).mean(axis=0))) + 1


def episode_spans(raised: np.ndarray, cleared: np.ndarray, active: np.ndarray) -> list[np.ndarray]:
    """Per alarm (in core.alarm.alarm_episodes' order) its active windows, (n,) bool each."""
    out = []
    for start in np.flatnonzero(raised):
        ends = np.flatnonzero(cleared[start + 1:])
        stop = start + 1 + int(ends[0]) if ends.size else active.size  # first inactive window
        span = np.zeros(active.size, bool)
        span[start:stop] = active[start:stop]
        out.append(span)
    return out
