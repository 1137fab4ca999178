"""The streaming GRU's optional onset emphasis (``--onset-weight``, ``--onset-span``): more loss weight
on the first steps of every fault-labelled run of a flight, i.e. just after the severity crosses the
label threshold, where the stream must move its probability from Healthy to the fault.

Step weight m_t = ``onset_weight`` for the first ``onset_span`` steps of each run of fault labels
(a flight's label turns to its fault class at ``severity >= severity_threshold``; an intermittent
fault starts a new run at every crossing), 1 elsewhere. The class weights are then the inverse
m-weighted frequencies, w_k = sum(m) / (K sum_{y=k} m), so each class keeps the same share of the
loss as without emphasis (Eq. (12)'s balance): the emphasis moves weight inside a class, towards
its onset, and does not tilt the classifier towards faults (which would trade false alarms for delay).
``onset_weight = 1`` (the default) is the unweighted training, bit for bit (``step_weights`` is None).
"""

from __future__ import annotations

import numpy as np
import torch

from quadfdi.train.loop import weighted_cross_entropy


def step_weights(lab: np.ndarray, onset_weight: float, onset_span: int) -> np.ndarray | None:
    """(n, T) float32 step weights m of the module docstring for the step labels ``lab`` (n, T) (0 = Healthy);
    None when ``onset_weight == 1`` (no emphasis)."""
    if onset_weight == 1.0:
        return None
    fault = lab != 0
    t = np.arange(lab.shape[1])[None, :]
    prev = np.concatenate([np.zeros((lab.shape[0], 1), bool), fault[:, :-1]], axis=1)
    run_start = np.maximum.accumulate(np.where(fault & ~prev, t, -1), axis=1)
    early = fault & (t - run_start < onset_span)
    return np.where(early, onset_weight, 1.0).astype(np.float32)


def weighted_class_weights(lab: np.ndarray, m: np.ndarray, n_classes: int) -> np.ndarray:
    """(K,) float32 w_k = sum(m) / (K' sum_{y=k} m) over the K' classes present (absent: 0)."""
    mass = np.bincount(lab.ravel(), weights=m.ravel().astype(np.float64), minlength=n_classes)
    w = np.zeros(n_classes)
    present = mass > 0
    w[present] = mass.sum() / (present.sum() * mass[present])
    return w.astype(np.float32)


def step_weighted_cross_entropy(logits: torch.Tensor, y: torch.Tensor, w: torch.Tensor, m: torch.Tensor | None,
                                eps: float) -> torch.Tensor:
    """Eq. (12) with a weight per step: -(1/B) sum_b m_b w_{y_b} log(p_{b, y_b} + eps); m None: Eq. (12) itself."""
    if m is None:
        return weighted_cross_entropy(logits, y, w, eps)
    picked = torch.softmax(logits, dim=1).gather(1, y[:, None]).squeeze(1)
    return -(m * w[y] * torch.log(picked + eps)).mean()
