"""train.baseline: logistic regression on per-window channel mean, slope and std."""

from __future__ import annotations

import numpy as np
import pytest

from quadfdi.train.baseline import fit_baseline, predict_proba_baseline, window_features

W, C = 80, 23


def synthetic_windows(n_per_class: int, seed: int, classes=(0, 1, 2, 3)):
    """Noisy windows; each fault class shifts a different statistic of a different channel."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, W, dtype=np.float32)[:, None]
    xs, ys = [], []
    for k in classes:
        x = rng.normal(0.0, 1.0, size=(n_per_class, W, C)).astype(np.float32)
        x += rng.normal(0.0, 0.3, size=(n_per_class, 1, C)).astype(np.float32)  # per-window offsets
        x[..., 5] += 100.0  # a channel far from zero scale: normalisation must handle it
        if k == 1:
            x[:, :, 0] -= 1.5  # battery: lower mean voltage
        elif k == 2:
            x[:, :, 3] += 2.0 * t[:, 0]  # motor: a drift (slope)
        elif k == 3:
            x[:, :, 7] *= 2.0  # overheat: more variance
        xs.append(x)
        ys.append(np.full(n_per_class, k))
    x = np.concatenate(xs)
    y = np.concatenate(ys)
    order = rng.permutation(len(y))
    return x[order], y[order]


def test_features_mean_slope_std():
    t = np.linspace(0.0, 1.0, W)
    x = np.zeros((1, W, 2))
    x[0, :, 0] = 3.0 + 2.0 * t
    x[0, :, 1] = np.where(np.arange(W) % 2 == 0, 1.0, -1.0)
    f = window_features(x)
    assert f.shape == (1, 6)
    np.testing.assert_allclose(f[0, :2], [4.0, 0.0], atol=1e-12)  # means
    assert f[0, 2] == pytest.approx(2.0)  # slope per unit window time
    assert f[0, 3] == pytest.approx(np.polyfit(t, x[0, :, 1], 1)[0])
    np.testing.assert_allclose(f[0, 4:], [x[0, :, 0].std(), 1.0], atol=1e-12)


def test_baseline_beats_chance_on_separable_set():
    x_tr, y_tr = synthetic_windows(60, seed=0)
    x_te, y_te = synthetic_windows(40, seed=1)
    assert x_tr.dtype == np.float32 and x_tr.shape[1:] == (W, C)
    model = fit_baseline(x_tr, y_tr, seed=0)
    p = predict_proba_baseline(model, x_te)
    assert p.shape == (len(y_te), 4)
    np.testing.assert_allclose(p.sum(axis=1), 1.0, atol=1e-9)
    acc = float((p.argmax(axis=1) == y_te).mean())
    assert acc > 0.85, acc  # chance is 0.25


def test_column_mapping_with_a_class_absent_from_training():
    x_tr, y_tr = synthetic_windows(50, seed=2, classes=(0, 1, 3))
    x_te, y_te = synthetic_windows(30, seed=3, classes=(0, 1, 3))
    model = fit_baseline(x_tr, y_tr, seed=0)
    assert list(model.classes_) == [0, 1, 3]
    p = predict_proba_baseline(model, x_te)
    assert p.shape == (len(y_te), 4)
    assert np.all(p[:, 2] == 0.0)  # MotorFault never seen: zero column
    np.testing.assert_allclose(p[:, [0, 1, 3]], model.predict_proba(x_te))
    assert float((p.argmax(axis=1) == y_te).mean()) > 0.85


def test_deterministic_and_errors():
    x_tr, y_tr = synthetic_windows(20, seed=4)
    p1 = predict_proba_baseline(fit_baseline(x_tr, y_tr, seed=5), x_tr[:10])
    p2 = predict_proba_baseline(fit_baseline(x_tr, y_tr, seed=5), x_tr[:10])
    np.testing.assert_array_equal(p1, p2)
    with pytest.raises(ValueError, match="two classes"):
        fit_baseline(x_tr, np.zeros(len(y_tr), dtype=int), seed=0)
    model = fit_baseline(x_tr, y_tr, seed=0)
    with pytest.raises(ValueError, match="channels"):
        predict_proba_baseline(model, x_tr[:, :, :10])
