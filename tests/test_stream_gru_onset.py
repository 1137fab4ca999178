"""The streaming GRU's onset emphasis (train/stream_gru_onset.py): which steps get the weight, that the
class shares of the loss are kept, and that the default is the unweighted loss. Arrays only (no training)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from quadfdi.core.errors import QuadfdiError


def test_onset_weight_one_is_no_emphasis():
    from quadfdi.train.loop import weighted_cross_entropy
    from quadfdi.train.stream_gru_onset import step_weighted_cross_entropy, step_weights

    lab = np.array([[0, 0, 2, 2, 2]])
    assert step_weights(lab, 1.0, 3) is None
    logits, y, w = torch.randn(5, 4), torch.tensor([0, 1, 2, 3, 1]), torch.tensor([0.5, 1.0, 2.0, 3.0])
    assert torch.equal(step_weighted_cross_entropy(logits, y, w, None, 1e-8), weighted_cross_entropy(logits, y, w, 1e-8))


def test_step_weights_mark_the_first_steps_of_every_fault_run():
    from quadfdi.train.stream_gru_onset import step_weights

    lab = np.array([[0, 0, 3, 3, 3, 3, 0, 3, 3, 0],    # an intermittent fault: two runs, each restarts the span
                    [4, 4, 4, 4, 0, 0, 0, 0, 0, 0],    # a fault from the first step (take-off)
                    [0, 0, 0, 0, 0, 0, 0, 0, 0, 0]])   # healthy
    m = step_weights(lab, 5.0, 2)
    assert m.dtype == np.float32
    assert m[0].tolist() == [1, 1, 5, 5, 1, 1, 1, 5, 5, 1]
    assert m[1].tolist() == [5, 5, 1, 1, 1, 1, 1, 1, 1, 1]
    assert (m[2] == 1).all()


def test_class_shares_of_the_loss_are_kept():
    from quadfdi.train.data import class_weights
    from quadfdi.train.stream_gru_onset import step_weights, weighted_class_weights

    lab = np.zeros((6, 200), np.int64)
    for i, (c, t0) in enumerate([(1, 50), (2, 120), (3, 10), (4, 190), (1, 150), (0, 0)]):
        lab[i, t0:] = c
    m = step_weights(lab, 4.0, 25)
    w = weighted_class_weights(lab, m, 5)
    share = np.bincount(lab.ravel(), weights=(m * w[lab]).ravel(), minlength=5)
    assert share == pytest.approx(np.full(5, share.mean()), rel=1e-5)  # every class the same share, as Eq. (12)
    ones = np.ones_like(m)
    assert weighted_class_weights(lab, ones, 5) == pytest.approx(class_weights(lab.ravel(), 5), rel=1e-6)
    # the emphasis moves weight inside a class: class 4's only run is 10 steps, all emphasised
    assert np.unique(m[3][lab[3] == 4]).tolist() == [4.0]


def test_bad_onset_settings_are_refused():
    from quadfdi.train.config import StreamFitConfig

    with pytest.raises(QuadfdiError, match="onset_weight"):
        StreamFitConfig(onset_weight=0.0).validate()
    with pytest.raises(QuadfdiError, match="onset_span"):
        StreamFitConfig(onset_span=0).validate()
