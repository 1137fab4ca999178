"""The suspected motor in ``detect``'s outputs, from a model's motor head (models.motor).

Per window (windows.npz ``motor``, int8): 1..4 = the argmax of the window's motor probabilities
when the window is decided and its fault class (the argmax of ``proba`` over the fault columns,
Healthy left out, as core.alarm names an alarm's class) is rotor-side; 0 otherwise and for a model
without the head.

Per alarm (alarms.json ``motor``): core.alarm's rule (rules 4-5 of its docstring: the argmax of
the motor probabilities summed over the alarm's voting windows, reported for a rotor-side alarm
class only), the same code ``quadfdi evaluate`` scores; None where it names no motor. Motors are
numbered 1..4 (column m of ``motor_logits`` is motor m + 1: docs/ingest.md, motor numbering).
"""

from __future__ import annotations

import numpy as np


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
