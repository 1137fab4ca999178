"""The streaming GRU's training-only motor head (train/stream_gru_motor.py): its step targets, that its
loss reaches the GRU's weights, and that the kept model is the plain stream (no head, same outputs' shape)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from quadfdi.core.errors import QuadfdiError


def test_step_motor_targets_name_the_rotor_on_rotor_side_steps_only():
    from quadfdi.train.stream_gru_motor import step_motor_targets

    names = ("Healthy", "BatteryFault", "MotorFault", "OverheatFault", "PropellerFault")
    lab = np.array([[0, 2, 2], [0, 0, 1], [4, 4, 0], [0, 0, 0]])
    fault_motor = np.array([9, 2, -1, 3, 1, -1])  # dataset rows; rows 1, 2, 4, 5 are trained
    got = step_motor_targets(lab, np.array([1, 2, 4, 5]), fault_motor, names)
    assert got.tolist() == [[-1, 2, 2], [-1, -1, -1], [1, 1, -1], [-1, -1, -1]]
    with pytest.raises(ValueError, match="fault_motor"):  # a rotor-side label without a motor
        step_motor_targets(lab, np.array([2, 2, 4, 5]), fault_motor, names)


def test_motor_loss_moves_the_gru_and_is_zero_without_targets():
    from quadfdi.models.stream_gru import StreamGRU
    from quadfdi.train.config import StreamFitConfig
    from quadfdi.train.stream_gru_fit import _batch_loss
    from quadfdi.train.stream_gru_motor import MotorAux

    cfg = StreamFitConfig(hidden=6, tbptt=5)
    x, y = torch.randn(3, 10, 4), torch.tensor([[0] * 5 + [1] * 5, [0] * 10, [2] * 10])
    mask, w = torch.ones(3, 10, dtype=torch.bool), torch.ones(3)
    ym = torch.tensor([[-1] * 5 + [2] * 5, [-1] * 10, [0] * 10])
    after = {}
    for name, weight, targets in [("plain", 0.0, None), ("aux", 1.0, ym), ("none", 1.0, torch.full_like(ym, -1))]:
        torch.manual_seed(0)
        model = StreamGRU(4, 6, 3)
        aux = None if name == "plain" else MotorAux(6, weight, np.zeros((3, 10), np.int64))
        params = list(model.parameters()) + ([] if aux is None else list(aux.parameters()))
        opt = torch.optim.SGD(params, lr=0.5)
        _batch_loss(model, opt, x, y, mask, torch.zeros(3, 6), w, cfg, aux=aux, ym=targets)
        after[name] = {k: v.clone() for k, v in model.state_dict().items()}
    keys = after["plain"].keys()
    assert after["aux"].keys() == keys and not any("motor" in k for k in keys)  # the kept model has no head
    assert not torch.equal(after["aux"]["gru.weight_hh_l0"], after["plain"]["gru.weight_hh_l0"])
    assert all(torch.equal(after["none"][k], after["plain"][k]) for k in keys)  # no rotor-side step: no motor loss


def test_bad_motor_aux_is_refused():
    from quadfdi.train.config import StreamFitConfig

    with pytest.raises(QuadfdiError, match="motor_aux"):
        StreamFitConfig(motor_aux=-0.5).validate()
