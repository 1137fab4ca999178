"""train.augment: the training-only motor-share wander (docs/training.md "Motor-share wander")."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from quadfdi.core.config import Config, load_config
from quadfdi.core.errors import QuadfdiError
from quadfdi.formats.dataset import Windows
from quadfdi.train.augment import SHARE_CHANNELS, ShareWander, share_columns, share_wander_for
from quadfdi.train.loop import train_model
from quadfdi.models.networks import build_model

NAMES = ["roll", "pitch", "p", "q", "r", "vx_h", "vy_h", "vz", "v_cell", "i_rel", *SHARE_CHANNELS, "vib"]


def test_off_by_default_and_refused_without_the_shares():
    cfg = Config().train
    assert cfg.share_wander == 0.0
    assert share_wander_for(cfg, NAMES, 0.04) is None
    on = share_wander_for(load_config(None, ["train.share_wander=0.1"]).train, NAMES, 0.04)
    assert on is not None and on.amplitude == 0.1 and abs(on.a - math.exp(-0.04 / 0.3)) < 1e-12
    cols = share_columns(NAMES)
    assert [NAMES[c] for c in cols] == list(SHARE_CHANNELS)
    with pytest.raises(QuadfdiError, match="lacks m3_rel"):
        share_columns([n for n in NAMES if n != "m3_rel"])


def test_noise_keeps_the_collective_and_is_reproducible():
    aug = ShareWander(0.1, 0.3 / 0.04, share_columns(NAMES), seed=3)
    f = aug.noise(64, 80, epoch=2, batch=5)
    assert f.shape == (64, 80, 4) and f.dtype == np.float32
    assert np.abs(f.sum(axis=2)).max() < 1e-6  # the four motors' mean is removed: thrust kept
    assert np.array_equal(f, aug.noise(64, 80, epoch=2, batch=5))
    assert not np.array_equal(f, aug.noise(64, 80, epoch=2, batch=6))
    assert not np.array_equal(f, ShareWander(0.1, 7.5, aug.columns, seed=4).noise(64, 80, 2, 5))


def test_noise_statistics_follow_the_ar1_and_the_amplitude():
    tau = 0.3 / 0.04
    aug = ShareWander(0.1, tau, [0, 1, 2, 3], seed=0)
    f = aug.noise(4000, 80, 0, 0).astype(np.float64)
    # each window's sigma <= amplitude: de-meaned unit-variance series have std sqrt(3/4) sigma
    per_window = f.std(axis=(1, 2))
    assert per_window.max() < 0.1 * 1.6
    assert 0.02 < np.median(per_window) < 0.06
    # lag-1 autocorrelation of the de-meaned AR(1) equals exp(-1/tau)
    lag1 = (f[:, 1:] * f[:, :-1]).sum() / (f[:, :-1] ** 2).sum()
    assert abs(lag1 - math.exp(-1 / tau)) < 0.01


def test_call_moves_only_the_shares_and_leaves_the_batch():
    aug = ShareWander(0.1, 7.5, share_columns(NAMES), seed=0)
    x = torch.ones(8, 80, len(NAMES))
    x[:, :, aug.columns] = 1.2
    before = x.clone()
    y = aug(x, epoch=0, batch=0)
    assert torch.equal(x, before)
    others = [j for j in range(len(NAMES)) if j not in aug.columns]
    assert torch.equal(y[:, :, others], x[:, :, others])
    moved = y[:, :, aug.columns]
    assert not torch.equal(moved, x[:, :, aug.columns])
    # multiplicative around the share: equal shares keep their collective exactly (to float rounding)
    assert torch.allclose(moved.mean(dim=2), torch.full((8, 80), 1.2), atol=1e-6)


@pytest.mark.parametrize("override", ["train.share_wander=-0.1", "train.share_wander_tau_s=0"])
def test_config_refuses_bad_values(override):
    with pytest.raises(QuadfdiError):
        load_config(None, [override])


def _windows(n: int = 48, w: int = 40, seed: int = 0) -> Windows:
    rng = np.random.default_rng(seed)
    x = rng.standard_normal((n, w, len(NAMES))).astype(np.float32)
    x[:, :, share_columns(NAMES)] = 1.0 + 0.05 * x[:, :, share_columns(NAMES)]
    y = rng.integers(0, 4, n)
    z = np.zeros(n, dtype=np.int64)
    return Windows(x=x, y=y, traj=np.arange(n), start=z, t_end=z.astype(np.float64))


def _trained(augment) -> dict:
    cfg = load_config(None, ["train.epochs=1", "train.gru_hidden=8", "train.batch_size=16"]).train
    torch.manual_seed(0)
    model = build_model("gru", len(NAMES), cfg, window=40, n_classes=4)
    model.set_normalisation(np.ones(len(NAMES), np.float32), np.ones(len(NAMES), np.float32))
    tr = _windows()
    train_model(model, tr, _windows(seed=1), cfg, np.ones(4, np.float32), log=lambda s: None, augment=augment)
    return model.state_dict()


def test_training_reads_the_augmented_batches():
    plain = _trained(None)
    zero = _trained(ShareWander(0.0, 7.5, share_columns(NAMES), seed=0))  # sigma = 0: the same batches
    moved = _trained(ShareWander(0.1, 7.5, share_columns(NAMES), seed=0))
    assert all(torch.equal(plain[k], zero[k]) for k in plain)
    assert any(not torch.equal(plain[k], moved[k]) for k in plain)
