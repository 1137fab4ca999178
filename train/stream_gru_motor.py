"""The streaming GRU's auxiliary motor head (``--motor-aux W``; 0.5 by default, 0: off): a training-only
Linear(H, 4) that reads the stream's hidden state at every step and is trained to name the faulty rotor
at the steps whose label is rotor-side (Motor, Overheat, Propeller: models/motor.py), its cross-entropy
added to the class loss with weight W (the windowed networks' ``train.motor_loss_weight`` is 0.5).

Like the windowed networks' motor head, it asks the hidden state to carry which rotor is affected,
which the rotor-side classes are about; unlike theirs, it is dropped after training: the kept model,
its checkpoint, ONNX graphs and C++ step are the plain stream's (the compute per sample is unchanged).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import nn

from quadfdi.models.motor import N_MOTORS, motor_loss, motor_targets


class MotorAux(nn.Module):
    """The head and its weight in the loss; ``targets`` (n, T): the step motor targets (-1: none)."""

    def __init__(self, hidden: int, weight: float, targets: np.ndarray) -> None:
        super().__init__()
        self.head = nn.Linear(hidden, N_MOTORS)
        self.weight = float(weight)
        self.targets = targets

    def loss(self, hs: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """W times the mean motor cross-entropy over the steps of ``hs`` (N, H) with a target (N,) >= 0."""
        return self.weight * motor_loss(self.head(hs), target)


def step_motor_targets(lab: np.ndarray, rows: np.ndarray, fault_motor: np.ndarray,
                       class_names: Sequence[str]) -> np.ndarray:
    """(n, T) int64: the flight's ``fault_motor`` at every step labelled with a rotor-side class, else -1."""
    n, n_t = lab.shape
    traj = np.repeat(np.asarray(rows, dtype=np.int64), n_t)
    return motor_targets(lab.ravel(), traj, fault_motor, class_names).reshape(n, n_t)
