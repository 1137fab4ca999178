"""The motor head: which of the four rotors a rotor-side fault is on.

A model with the head has one more linear layer, ``motor_head``, reading the same final hidden
representation as the class head (the CNODE's z1, (B, L); the GRU's last hidden state, (B, H)) and
giving 4 logits, ``motor_logits`` (B, 4). Column m is rotor m + 1 of the project numbering
(docs/ingest.md, "Motor order": rotor 1 on +x, 2 on +y, 3 on -x, 4 on -y, counter-clockwise
seen from above; a real quad X is renumbered by ingest's ``motor_map``), i.e. column m is the
dataset's ``fault_motor`` value m (0-based, -1 for a flight without a rotor-side fault).

Rotor-side classes are those whose fault sits on one rotor (core.contracts.CLASS_TABLE, the one
place that says which: MotorFault = lost effectiveness of rotor m, OverheatFault = the cooling /
heat of rotor m's motor, PropellerFault = the damaged propeller of rotor m); a BatteryFault has no
motor (fault_motor -1).
The head is trained with cross-entropy on the windows whose class label is rotor-side, added to
the class loss with weight ``train.motor_loss_weight``; ``train.motor_head`` = "auto" turns it on
when the data has a rotor-side class, "off" never. The paper config sets "off" (its outputs keep
every byte).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import torch
from torch import nn

from quadfdi.core.alarm import rotor_columns

N_MOTORS = 4
MOTOR_HEAD_SETTINGS = ("auto", "off")


def rotor_side(class_names: Sequence[str]) -> np.ndarray:
    """(K,) bool: which classes (label order) are rotor-side."""
    return rotor_columns(class_names)


def wants_motor_head(setting: str, class_names: Sequence[str]) -> bool:
    """Whether a model trained on data with ``class_names`` gets the head under ``setting``."""
    return setting == "auto" and bool(rotor_side(class_names).any())


def head_width(model: nn.Module) -> int:
    """Width of the representation the class head reads (its input features)."""
    return int(model.head.in_features)


def attach_motor_head(model: nn.Module) -> nn.Module:
    """Give ``model`` a fresh ``motor_head`` (Linear(width, 4)); returns the model. Initialised
    from the current torch generator, after every other layer (a model without the head draws the
    same numbers as one built with no head at all)."""
    model.motor_head = nn.Linear(head_width(model), N_MOTORS)
    return model


def has_motor_head(model: nn.Module) -> bool:
    return getattr(model, "motor_head", None) is not None


def motor_targets(y: np.ndarray, traj: np.ndarray, fault_motor: np.ndarray, class_names: Sequence[str]) -> np.ndarray:
    """(n,) int64 target motor of each window: the flight's ``fault_motor`` where the window's label
    is rotor-side, else -1 (no motor loss). A rotor-side label on a flight without a motor is a
    dataset error."""
    rotor = rotor_side(class_names)[np.asarray(y, dtype=np.int64)]
    m = np.asarray(fault_motor)[np.asarray(traj, dtype=np.int64)].astype(np.int64)
    if bool((rotor & ((m < 0) | (m >= N_MOTORS))).any()):
        raise ValueError("a window with a rotor-side label belongs to a flight whose fault_motor is not 0..3")
    return np.where(rotor, m, -1)


def motor_loss(motor_logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean cross-entropy over the windows with a target (>= 0); 0 when the batch has none."""
    keep = target >= 0
    if not bool(keep.any()):
        return motor_logits.sum() * 0.0
    return nn.functional.cross_entropy(motor_logits[keep], target[keep])


@torch.no_grad()
def predict_motor_proba(model: nn.Module, x: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Motor probabilities (n, 4) float64 of raw windows x (n, W, C), softmax of the head."""
    model.eval()
    out = []
    for i in range(0, len(x), batch_size):
        z = model.features(torch.from_numpy(np.ascontiguousarray(x[i:i + batch_size])))
        out.append(torch.softmax(model.motor_head(z).double(), dim=1).numpy())
    return np.concatenate(out) if out else np.zeros((0, N_MOTORS))
